//! Minimal `.npy` (NumPy format 1.0) reading and writing for little-endian `f32`/`f64`
//! C-order arrays, so numpy can open every array of the database
//! (`numpy.load("fire.db/weights.npy", mmap_mode="r")`).
//!
//! Headers are padded so the data starts at a multiple of 64 bytes; a memory-mapped file
//! can then be viewed as `&[f32]` in place.

use crate::error::{EigenError, Result};
use std::io::Write;
use std::path::Path;

/// Element types the database stores.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    F32,
    F64,
}

impl Dtype {
    fn descr(self) -> &'static str {
        match self {
            Dtype::F32 => "<f4",
            Dtype::F64 => "<f8",
        }
    }
    pub fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F64 => 8,
        }
    }
}

/// The header of an array: element type, shape, byte offset of the data.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub dtype: Dtype,
    pub shape: Vec<usize>,
    pub data_offset: usize,
}

impl Header {
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Expected file size.
    pub fn file_len(&self) -> usize {
        self.data_offset + self.len() * self.dtype.size()
    }
}

/// Encodes a header for `shape` (data offset a multiple of 64).
pub fn encode_header(dtype: Dtype, shape: &[usize]) -> Vec<u8> {
    let shape_s = match shape.len() {
        1 => format!("({},)", shape[0]),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let dict = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}",
        dtype.descr(),
        shape_s
    );
    let unpadded = 10 + dict.len() + 1;
    let total = unpadded.div_ceil(64) * 64;
    let mut h = Vec::with_capacity(total);
    h.extend_from_slice(b"\x93NUMPY\x01\x00");
    h.extend_from_slice(&((total - 10) as u16).to_le_bytes());
    h.extend_from_slice(dict.as_bytes());
    h.resize(total - 1, b' ');
    h.push(b'\n');
    h
}

/// Parses a header from the start of a file.
pub fn parse_header(bytes: &[u8]) -> std::result::Result<Header, String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a .npy file (bad magic)".into());
    }
    let (major, hlen, start) = match bytes[6] {
        1 => (1, u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            2,
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let _ = major;
    let end = start + hlen;
    if bytes.len() < end {
        return Err("truncated header".into());
    }
    let dict = std::str::from_utf8(&bytes[start..end]).map_err(|_| "header is not text")?;
    let dtype = if dict.contains("'<f4'") {
        Dtype::F32
    } else if dict.contains("'<f8'") {
        Dtype::F64
    } else {
        return Err(format!(
            "unsupported dtype in header {dict:?} (only little-endian f4/f8)"
        ));
    };
    if dict.contains("'fortran_order': True") {
        return Err("Fortran-order arrays are not supported".into());
    }
    let s = dict.find("'shape':").ok_or("header has no shape")? + 8;
    let open = dict[s..].find('(').ok_or("bad shape")? + s + 1;
    let close = dict[open..].find(')').ok_or("bad shape")? + open;
    let shape = dict[open..close]
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<usize>()
                .map_err(|_| format!("bad shape entry `{t}`"))
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    Ok(Header {
        dtype,
        shape,
        data_offset: end,
    })
}

/// Streams an array to a file: header first, then rows as they come.
pub struct NpyWriter {
    file: std::io::BufWriter<std::fs::File>,
    path: std::path::PathBuf,
    expected: usize,
    written: usize,
    dtype: Dtype,
}

impl NpyWriter {
    pub fn create(path: &Path, dtype: Dtype, shape: &[usize]) -> Result<NpyWriter> {
        let f = std::fs::File::create(path).map_err(|e| EigenError::io(path, e))?;
        let mut file = std::io::BufWriter::with_capacity(1 << 20, f);
        file.write_all(&encode_header(dtype, shape))
            .map_err(|e| EigenError::io(path, e))?;
        Ok(NpyWriter {
            file,
            path: path.into(),
            expected: shape.iter().product(),
            written: 0,
            dtype,
        })
    }
    pub fn write_f32(&mut self, v: &[f32]) -> Result<()> {
        assert_eq!(self.dtype, Dtype::F32, "writing f32 into a non-f32 array");
        let mut buf = Vec::with_capacity(v.len() * 4);
        for x in v {
            buf.extend_from_slice(&x.to_le_bytes());
        }
        self.file
            .write_all(&buf)
            .map_err(|e| EigenError::io(&self.path, e))?;
        self.written += v.len();
        Ok(())
    }
    pub fn write_f64(&mut self, v: &[f64]) -> Result<()> {
        assert_eq!(self.dtype, Dtype::F64, "writing f64 into a non-f64 array");
        let mut buf = Vec::with_capacity(v.len() * 8);
        for x in v {
            buf.extend_from_slice(&x.to_le_bytes());
        }
        self.file
            .write_all(&buf)
            .map_err(|e| EigenError::io(&self.path, e))?;
        self.written += v.len();
        Ok(())
    }
    /// Flushes and syncs; fails if fewer or more values were written than the shape says.
    pub fn finish(mut self) -> Result<()> {
        if self.written != self.expected {
            return Err(EigenError::bad(
                "npy",
                format!(
                    "{}: wrote {} values for a shape of {}",
                    self.path.display(),
                    self.written,
                    self.expected
                ),
            ));
        }
        self.file
            .flush()
            .map_err(|e| EigenError::io(&self.path, e))?;
        self.file
            .get_ref()
            .sync_all()
            .map_err(|e| EigenError::io(&self.path, e))?;
        Ok(())
    }
}

/// Writes a whole f32 array.
pub fn write_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    let mut w = NpyWriter::create(path, Dtype::F32, shape)?;
    w.write_f32(data)?;
    w.finish()
}

/// Writes a whole f64 array.
pub fn write_f64(path: &Path, shape: &[usize], data: &[f64]) -> Result<()> {
    let mut w = NpyWriter::create(path, Dtype::F64, shape)?;
    w.write_f64(data)?;
    w.finish()
}

/// Views the data of an f32 array held in `bytes` (e.g. a memory map). Copies only if the
/// data is not 4-byte aligned.
pub fn f32_data<'a>(bytes: &'a [u8], h: &Header) -> std::borrow::Cow<'a, [f32]> {
    let d = &bytes[h.data_offset..h.data_offset + h.len() * 4];
    // SAFETY: any bit pattern is a valid f32; alignment is checked by align_to.
    let (pre, mid, post) = unsafe { d.align_to::<f32>() };
    if pre.is_empty() && post.is_empty() && cfg!(target_endian = "little") {
        std::borrow::Cow::Borrowed(mid)
    } else {
        std::borrow::Cow::Owned(
            d.chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        )
    }
}

/// Reads the data of an f64 array held in `bytes` (copies).
pub fn f64_data(bytes: &[u8], h: &Header) -> Vec<f64> {
    bytes[h.data_offset..h.data_offset + h.len() * 8]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        let data: Vec<f32> = (0..12).map(|i| i as f32 * 0.5).collect();
        write_f32(&p, &[3, 4], &data).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let h = parse_header(&bytes).unwrap();
        assert_eq!(h.shape, vec![3, 4]);
        assert_eq!(h.data_offset % 64, 0);
        assert_eq!(h.file_len(), bytes.len());
        assert_eq!(&*f32_data(&bytes, &h), &data[..]);
        let q = dir.path().join("b.npy");
        write_f64(&q, &[2], &[1.5, -2.0]).unwrap();
        let b = std::fs::read(&q).unwrap();
        let h = parse_header(&b).unwrap();
        assert_eq!(f64_data(&b, &h), vec![1.5, -2.0]);
    }
}
