//! `.npy` files (NumPy format 1.0/2.0/3.0): save and load `f32`/`f64` little-endian arrays in
//! Fortran (column-major, faer's layout) or C order, and memory-map an `f32` file read-only.
//!
//! Written by hand rather than with `npyz`: the header is one short Python-dict line, we need the
//! exact data offset and alignment to memory-map the payload as `&[f32]` (which `npyz` does not
//! expose), and writing Fortran order lets a faer matrix go to disk without a transpose.
//! Writers are atomic (temp file in the same folder, then rename); [`NpyWriter`] streams a C-order
//! array piece by piece. [`parse_header`], [`f32_data`] and [`f64_data`] read a file already in
//! memory (e.g. a memory map). Numpy opens these files with `np.load(path)` (and
//! `np.load(path, mmap_mode="r")`).

use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use faer::{Mat, MatRef};

use crate::PcaError;
use ignis_core::atomic::AtomicFile;

/// Element type of an `.npy` file we read or write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// `<f4`
    F32,
    /// `<f8`
    F64,
}

impl Dtype {
    fn descr(self) -> &'static str {
        match self {
            Dtype::F32 => "<f4",
            Dtype::F64 => "<f8",
        }
    }
    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F64 => 8,
        }
    }
}

/// A parsed `.npy` header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Header {
    pub dtype: Dtype,
    /// True when the array is stored column-major.
    pub fortran_order: bool,
    pub shape: Vec<usize>,
    /// Byte offset of the payload in the file.
    pub data_offset: usize,
}

impl Header {
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }
    /// True for zero elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Size in bytes of a complete file with this header (header plus payload).
    pub fn file_len(&self) -> usize {
        self.data_offset + self.len() * self.dtype.size()
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> PcaError + '_ {
    move |source| PcaError::Io {
        path: path.to_owned(),
        source,
    }
}

fn unsupported(path: &Path, reason: impl Into<String>) -> PcaError {
    PcaError::Unsupported {
        path: path.to_owned(),
        reason: reason.into(),
    }
}

/// Header bytes (magic, version 1.0, length, dict padded so the payload starts at a multiple of 64).
fn header_bytes(dtype: Dtype, fortran: bool, shape: &[usize]) -> Vec<u8> {
    let shape_s = match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut dict = format!(
        "{{'descr': '{}', 'fortran_order': {}, 'shape': {}, }}",
        dtype.descr(),
        if fortran { "True" } else { "False" },
        shape_s
    );
    let total = 10 + dict.len() + 1;
    dict.push_str(&" ".repeat((64 - total % 64) % 64));
    dict.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}

/// Parses the header at the start of `bytes` (at least the first few KB of the file).
pub fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, PcaError> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(unsupported(path, "not an .npy file (bad magic)"));
    }
    let (hlen, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => {
            return Err(unsupported(
                path,
                format!(".npy version {v} (need 1, 2 or 3)"),
            ))
        }
    };
    let dict = bytes
        .get(start..start + hlen)
        .and_then(|d| std::str::from_utf8(d).ok())
        .ok_or_else(|| unsupported(path, "truncated or non-UTF-8 header"))?;
    let value = |key: &str| -> Option<&str> {
        let i = dict.find(&format!("'{key}'"))? + key.len() + 2;
        Some(dict[i..].trim_start().strip_prefix(':')?.trim_start())
    };
    let descr = value("descr")
        .and_then(|v| v.strip_prefix('\''))
        .and_then(|v| v.split('\'').next())
        .ok_or_else(|| unsupported(path, "header has no 'descr'"))?;
    let dtype = match descr {
        "<f4" | "f4" => Dtype::F32,
        "<f8" | "f8" => Dtype::F64,
        other => {
            return Err(unsupported(
                path,
                format!(
                    "dtype {other:?}: only little-endian float32 '<f4' and float64 '<f8' are read"
                ),
            ))
        }
    };
    let fortran_order = match value("fortran_order") {
        Some(v) if v.starts_with("True") => true,
        Some(v) if v.starts_with("False") => false,
        _ => return Err(unsupported(path, "header has no 'fortran_order'")),
    };
    let shape_s = value("shape")
        .and_then(|v| v.strip_prefix('('))
        .and_then(|v| v.split(')').next())
        .ok_or_else(|| unsupported(path, "header has no 'shape'"))?;
    let shape = shape_s
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.trim_end_matches('L').parse::<usize>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|_| unsupported(path, format!("bad shape ({shape_s})")))?;
    // The byte size must be representable (a shape like (2^64 - 1,) would wrap around and
    // pass later size checks).
    let bytes = shape
        .iter()
        .try_fold(dtype.size(), |a, &d| a.checked_mul(d))
        .and_then(|b| b.checked_add(start + hlen))
        .filter(|&b| b <= isize::MAX as usize);
    if bytes.is_none() {
        return Err(unsupported(
            path,
            format!("shape ({shape_s}) is too large to address"),
        ));
    }
    Ok(Header {
        dtype,
        fortran_order,
        shape,
        data_offset: start + hlen,
    })
}

/// Reads just the header of `path`.
pub fn read_header(path: &Path) -> Result<Header, PcaError> {
    let mut f = std::fs::File::open(path).map_err(io(path))?;
    let mut buf = Vec::new();
    Read::by_ref(&mut f)
        .take(1 << 16)
        .read_to_end(&mut buf)
        .map_err(io(path))?;
    parse_header(path, &buf)
}

trait Elem: Copy + 'static {
    const DTYPE: Dtype;
    fn to_le(self, out: &mut Vec<u8>);
    fn from_f32(x: f32) -> Self;
    fn from_f64(x: f64) -> Self;
}
impl Elem for f32 {
    const DTYPE: Dtype = Dtype::F32;
    fn to_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes())
    }
    fn from_f32(x: f32) -> Self {
        x
    }
    fn from_f64(x: f64) -> Self {
        x as f32
    }
}
impl Elem for f64 {
    const DTYPE: Dtype = Dtype::F64;
    fn to_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes())
    }
    fn from_f32(x: f32) -> Self {
        x as f64
    }
    fn from_f64(x: f64) -> Self {
        x
    }
}

/// Writes atomically ([`ignis_core::atomic::write_file`]): `write` fills a temp file next
/// to `path`, which is then renamed.
fn atomic_write(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), PcaError> {
    ignis_core::atomic::write_file(path, write).map_err(io(path))
}

fn write_columns<T: Elem>(path: &Path, m: MatRef<'_, T>) -> Result<(), PcaError> {
    let header = header_bytes(T::DTYPE, true, &[m.nrows(), m.ncols()]);
    atomic_write(path, |w| {
        w.write_all(&header)?;
        let mut bytes = Vec::with_capacity(m.nrows() * T::DTYPE.size());
        for j in 0..m.ncols() {
            bytes.clear();
            for x in m.col(j).iter() {
                x.to_le(&mut bytes);
            }
            w.write_all(&bytes)?;
        }
        Ok(())
    })
}

/// Saves an f32 matrix as a 2-D `.npy` of shape (nrows, ncols), Fortran order.
pub fn write_mat_f32(path: &Path, m: MatRef<'_, f32>) -> Result<(), PcaError> {
    write_columns(path, m)
}

/// Saves an f64 matrix as a 2-D `.npy` of shape (nrows, ncols), Fortran order.
pub fn write_mat_f64(path: &Path, m: MatRef<'_, f64>) -> Result<(), PcaError> {
    write_columns(path, m)
}

fn write_slice<T: Elem>(
    path: &Path,
    data: &[T],
    shape: &[usize],
    fortran: bool,
) -> Result<(), PcaError> {
    if shape.iter().product::<usize>() != data.len() {
        return Err(crate::bad(
            "shape",
            format!("shape {shape:?} does not hold {} elements", data.len()),
        ));
    }
    let header = header_bytes(T::DTYPE, fortran, shape);
    atomic_write(path, |w| {
        w.write_all(&header)?;
        let mut bytes = Vec::with_capacity(1 << 16);
        for chunk in data.chunks(1 << 14) {
            bytes.clear();
            for x in chunk {
                x.to_le(&mut bytes);
            }
            w.write_all(&bytes)?;
        }
        Ok(())
    })
}

/// Saves a flat f32 slice with any `shape` (product must equal the length) and order.
pub fn write_f32(
    path: &Path,
    data: &[f32],
    shape: &[usize],
    fortran: bool,
) -> Result<(), PcaError> {
    write_slice(path, data, shape, fortran)
}

/// Saves a flat f64 slice with any `shape` and order.
pub fn write_f64(
    path: &Path,
    data: &[f64],
    shape: &[usize],
    fortran: bool,
) -> Result<(), PcaError> {
    write_slice(path, data, shape, fortran)
}

/// Decodes the first `len` elements of `payload` (stored as `dtype`), converting to `T`.
fn decode<T: Elem>(payload: &[u8], dtype: Dtype, len: usize) -> Vec<T> {
    match dtype {
        Dtype::F32 => payload
            .chunks_exact(4)
            .take(len)
            .map(|c| T::from_f32(f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
            .collect(),
        Dtype::F64 => payload
            .chunks_exact(8)
            .take(len)
            .map(|c| T::from_f64(f64::from_le_bytes(c.try_into().expect("8 bytes"))))
            .collect(),
    }
}

/// The payload bytes of `h` within a whole file held in `bytes`.
///
/// # Panics
/// If `bytes` is shorter than `h.file_len()`.
fn payload<'a>(bytes: &'a [u8], h: &Header) -> &'a [u8] {
    assert!(
        bytes.len() >= h.file_len(),
        ".npy payload truncated: shape {:?} needs {} bytes, have {}",
        h.shape,
        h.file_len(),
        bytes.len()
    );
    &bytes[h.data_offset..h.file_len()]
}

/// The data of a whole `.npy` file held in memory (e.g. a memory map) whose header `h` came from
/// [`parse_header`], as f32 in file order. Borrows in place when the file is f32 and the payload
/// is 4-byte aligned; copies otherwise (f64 files are converted).
///
/// # Panics
/// If `bytes` is shorter than `h.file_len()` (check that first for untrusted files).
pub fn f32_data<'a>(bytes: &'a [u8], h: &Header) -> std::borrow::Cow<'a, [f32]> {
    let d = payload(bytes, h);
    if h.dtype == Dtype::F32 && cfg!(target_endian = "little") {
        // SAFETY: every bit pattern is a valid f32; `align_to` only yields aligned elements.
        let (pre, mid, post) = unsafe { d.align_to::<f32>() };
        if pre.is_empty() && post.is_empty() {
            return std::borrow::Cow::Borrowed(mid);
        }
    }
    std::borrow::Cow::Owned(decode(d, h.dtype, h.len()))
}

/// Like [`f32_data`], as f64 (always a copy; f32 files are converted).
///
/// # Panics
/// If `bytes` is shorter than `h.file_len()`.
pub fn f64_data(bytes: &[u8], h: &Header) -> Vec<f64> {
    decode(payload(bytes, h), h.dtype, h.len())
}

/// Streams a C-order array to `path` piece by piece (e.g. one video frame at a time), so it
/// never has to be in memory whole: the header is written first, then the values in file order
/// (last index fastest). Atomic like the other writers: the data goes to a temp file next to
/// `path`, which [`NpyWriter::finish`] renames once exactly `shape.product()` values were
/// written; dropping an unfinished writer deletes the temp file.
pub struct NpyWriter {
    file: Option<AtomicFile>,
    path: PathBuf,
    dtype: Dtype,
    expected: usize,
    written: usize,
}

impl NpyWriter {
    /// Starts `path` as an array of `dtype` with `shape` (C order).
    pub fn create(path: &Path, dtype: Dtype, shape: &[usize]) -> Result<NpyWriter, PcaError> {
        let f = AtomicFile::create(path).map_err(io(path))?;
        let mut w = NpyWriter {
            file: Some(f),
            path: path.to_owned(),
            dtype,
            expected: shape.iter().product(),
            written: 0,
        };
        let header = header_bytes(dtype, false, shape);
        w.put(&header)?;
        Ok(w)
    }

    /// The destination path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn put(&mut self, bytes: &[u8]) -> Result<(), PcaError> {
        let f = self.file.as_mut().expect("NpyWriter used after finish");
        f.writer().write_all(bytes).map_err(io(&self.path))
    }

    fn push<T: Elem>(&mut self, v: &[T]) -> Result<(), PcaError> {
        if T::DTYPE != self.dtype {
            return Err(crate::bad(
                "dtype",
                format!(
                    "{}: writing {:?} values into a {:?} array",
                    self.path.display(),
                    T::DTYPE,
                    self.dtype
                ),
            ));
        }
        if self.written + v.len() > self.expected {
            return Err(crate::bad(
                "shape",
                format!(
                    "{}: {} values written would exceed the shape's {}",
                    self.path.display(),
                    self.written + v.len(),
                    self.expected
                ),
            ));
        }
        let mut bytes = Vec::with_capacity(v.len().min(1 << 14) * T::DTYPE.size());
        for chunk in v.chunks(1 << 14) {
            bytes.clear();
            for x in chunk {
                x.to_le(&mut bytes);
            }
            self.put(&bytes)?;
        }
        self.written += v.len();
        Ok(())
    }

    /// Appends f32 values (the array must be f32).
    pub fn write_f32(&mut self, v: &[f32]) -> Result<(), PcaError> {
        self.push(v)
    }

    /// Appends f64 values (the array must be f64).
    pub fn write_f64(&mut self, v: &[f64]) -> Result<(), PcaError> {
        self.push(v)
    }

    /// Flushes, syncs and renames the temp file to the destination. Fails (and deletes the temp
    /// file) if fewer values were written than the shape holds.
    pub fn finish(mut self) -> Result<(), PcaError> {
        if self.written != self.expected {
            return Err(crate::bad(
                "shape",
                format!(
                    "{}: wrote {} values for a shape of {}",
                    self.path.display(),
                    self.written,
                    self.expected
                ),
            ));
        }
        // Dropping an unfinished AtomicFile (here or on an error) removes the temp file.
        let f = self.file.take().expect("NpyWriter used after finish");
        f.commit().map_err(io(&self.path))
    }
}

fn read_all<T: Elem>(path: &Path) -> Result<(Vec<T>, Header), PcaError> {
    let bytes = std::fs::read(path).map_err(io(path))?;
    let h = parse_header(path, &bytes)?;
    let have = bytes.len() - h.data_offset.min(bytes.len());
    if bytes.len() < h.file_len() {
        return Err(unsupported(
            path,
            format!(
                "truncated: shape {:?} needs {} bytes of data, file has {}",
                h.shape,
                h.len() * h.dtype.size(),
                have
            ),
        ));
    }
    Ok((decode(payload(&bytes, &h), h.dtype, h.len()), h))
}

/// Reads a flat array (any shape, converting f64↔f32) in file order, with its header.
pub fn read_f32(path: &Path) -> Result<(Vec<f32>, Header), PcaError> {
    read_all(path)
}

/// Reads a flat array as f64, with its header.
pub fn read_f64(path: &Path) -> Result<(Vec<f64>, Header), PcaError> {
    read_all(path)
}

fn to_mat<T: Elem + Default>(path: &Path, data: Vec<T>, h: &Header) -> Result<Mat<T>, PcaError> {
    let (r, c) = match h.shape.as_slice() {
        [r, c] => (*r, *c),
        [r] => (*r, 1),
        s => {
            return Err(unsupported(
                path,
                format!("shape {s:?}: need a 1-D or 2-D array"),
            ))
        }
    };
    Ok(if h.fortran_order || c == 1 {
        Mat::from_fn(r, c, |i, j| data[i + j * r])
    } else {
        Mat::from_fn(r, c, |i, j| data[i * c + j])
    })
}

/// Reads a 1-D (as a column) or 2-D `.npy` in either order into an f32 matrix.
pub fn read_mat_f32(path: &Path) -> Result<Mat<f32>, PcaError> {
    let (d, h) = read_all::<f32>(path)?;
    to_mat(path, d, &h)
}

/// Reads a 1-D (as a column) or 2-D `.npy` in either order into an f64 matrix.
pub fn read_mat_f64(path: &Path) -> Result<Mat<f64>, PcaError> {
    let (d, h) = read_all::<f64>(path)?;
    to_mat(path, d, &h)
}

/// A read-only memory map of an f32 `.npy` file.
pub struct MmapF32 {
    map: memmap2::Mmap,
    header: Header,
}

impl MmapF32 {
    /// The header (shape, order).
    pub fn header(&self) -> &Header {
        &self.header
    }
    /// The payload, in file order.
    pub fn as_slice(&self) -> &[f32] {
        let bytes = &self.map[self.header.data_offset..];
        // SAFETY: `mmap_f32` checked that the payload is 4-byte aligned and long enough;
        // every bit pattern is a valid f32.
        unsafe { std::slice::from_raw_parts(bytes.as_ptr().cast::<f32>(), self.header.len()) }
    }
    /// A 2-D (or 1-D, as a column) view with the file's shape and order.
    pub fn as_mat(&self) -> MatRef<'_, f32> {
        let s = self.as_slice();
        match (self.header.shape.as_slice(), self.header.fortran_order) {
            ([r, c], true) => MatRef::from_column_major_slice(s, *r, *c),
            ([r, c], false) => MatRef::from_row_major_slice(s, *r, *c),
            _ => MatRef::from_column_major_slice(s, s.len(), 1),
        }
    }
}

/// Memory-maps an `.npy` of little-endian f32 read-only. The file must not be modified while
/// mapped (we cannot prevent another process from doing so; that is memmap2's caveat).
pub fn mmap_f32(path: &Path) -> Result<MmapF32, PcaError> {
    let f = std::fs::File::open(path).map_err(io(path))?;
    // SAFETY: read-only map; see the doc comment about concurrent modification.
    let map = unsafe { memmap2::Mmap::map(&f) }.map_err(io(path))?;
    let header = parse_header(path, &map)?;
    if header.dtype != Dtype::F32 {
        return Err(unsupported(
            path,
            "dtype '<f8': only float32 files can be memory-mapped as f32",
        ));
    }
    if header.shape.len() > 2 {
        return Err(unsupported(
            path,
            format!("shape {:?}: need 1-D or 2-D", header.shape),
        ));
    }
    if header.data_offset % 4 != 0 {
        return Err(unsupported(path, "payload not 4-byte aligned"));
    }
    if map.len() < header.data_offset + header.len() * 4 {
        return Err(unsupported(path, "truncated payload"));
    }
    Ok(MmapF32 { map, header })
}

#[cfg(test)]
mod unit {
    use super::*;

    #[test]
    fn header_round_trip_and_numpy_spellings() {
        let p = Path::new("x.npy");
        for (shape, fortran) in [
            (vec![3usize, 4], true),
            (vec![5], false),
            (vec![2, 3, 4], false),
        ] {
            let b = header_bytes(Dtype::F32, fortran, &shape);
            assert_eq!(b.len() % 64, 0);
            let h = parse_header(p, &b).unwrap();
            assert_eq!(
                (h.shape, h.fortran_order, h.data_offset),
                (shape, fortran, b.len())
            );
        }
        // What numpy itself writes (version 1.0, C order, no trailing comma after a 2-tuple).
        let dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }          \n";
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(dict.len() as u16).to_le_bytes());
        b.extend_from_slice(dict.as_bytes());
        let h = parse_header(p, &b).unwrap();
        assert_eq!(
            (h.dtype, h.shape.as_slice(), h.fortran_order),
            (Dtype::F64, &[2usize, 3][..], false)
        );
        let be = b
            .iter()
            .map(|&c| if c == b'<' { b'>' } else { c })
            .collect::<Vec<_>>();
        assert!(matches!(
            parse_header(p, &be),
            Err(PcaError::Unsupported { .. })
        ));
    }

    fn no_temp_files(dir: &Path) -> bool {
        !dir.read_dir()
            .unwrap()
            .any(|e| e.unwrap().file_name().to_string_lossy().starts_with('.'))
    }

    #[test]
    fn streaming_writer_and_in_memory_views() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("frames.npy");
        let data: Vec<f32> = (0..24).map(|i| i as f32 * 0.5 - 3.0).collect();
        let mut w = NpyWriter::create(&p, Dtype::F32, &[2, 3, 4]).unwrap();
        assert_eq!(w.path(), p.as_path());
        for frame in data.chunks(12) {
            w.write_f32(frame).unwrap();
        }
        // Nothing appears at the destination before `finish`.
        assert!(!p.exists());
        w.finish().unwrap();
        assert!(no_temp_files(dir.path()));

        let bytes = std::fs::read(&p).unwrap();
        let h = parse_header(&p, &bytes).unwrap();
        assert_eq!(
            (h.dtype, h.shape.as_slice(), h.fortran_order),
            (Dtype::F32, &[2usize, 3, 4][..], false)
        );
        assert_eq!(h.data_offset % 64, 0);
        assert_eq!(h.file_len(), bytes.len());
        let view = f32_data(&bytes, &h);
        assert_eq!(&*view, &data[..]);
        assert_eq!(read_f32(&p).unwrap().0, data);
        assert_eq!(
            f64_data(&bytes, &h),
            data.iter().map(|&x| x as f64).collect::<Vec<_>>()
        );
        // A payload that is not 4-byte aligned is copied, with the same values.
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&bytes);
        let hs = Header {
            data_offset: h.data_offset + 1,
            ..h.clone()
        };
        let v = f32_data(&shifted, &hs);
        assert!(matches!(v, std::borrow::Cow::Owned(_)));
        assert_eq!(&*v, &data[..]);

        // f64 streaming, read back as f64 and (converted) as f32.
        let q = dir.path().join("ev.npy");
        let mut w = NpyWriter::create(&q, Dtype::F64, &[3]).unwrap();
        w.write_f64(&[1.5, -2.0]).unwrap();
        w.write_f64(&[0.25]).unwrap();
        w.finish().unwrap();
        let b = std::fs::read(&q).unwrap();
        let h = parse_header(&q, &b).unwrap();
        assert_eq!(h.dtype, Dtype::F64);
        assert_eq!(f64_data(&b, &h), vec![1.5, -2.0, 0.25]);
        assert_eq!(&*f32_data(&b, &h), &[1.5f32, -2.0, 0.25][..]);
    }

    #[test]
    fn streaming_writer_rejects_wrong_counts_and_types_and_cleans_up() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        // Too few values: finish fails, naming the file; nothing is left behind.
        let mut w = NpyWriter::create(&p, Dtype::F32, &[2, 2]).unwrap();
        w.write_f32(&[1.0, 2.0, 3.0]).unwrap();
        let e = w.finish().unwrap_err().to_string();
        assert!(e.contains("a.npy") && e.contains("wrote 3 values"), "{e}");
        assert!(!p.exists());
        assert!(no_temp_files(dir.path()));
        // Too many values, or the wrong element type: refused at the write, naming the file.
        let mut w = NpyWriter::create(&p, Dtype::F32, &[2]).unwrap();
        let e = w.write_f32(&[1.0, 2.0, 3.0]).unwrap_err().to_string();
        assert!(e.contains("a.npy") && e.contains("exceed"), "{e}");
        let e = w.write_f64(&[1.0]).unwrap_err().to_string();
        assert!(e.contains("a.npy") && e.contains("F64"), "{e}");
        // Dropped unfinished: no file, no temp file.
        drop(w);
        assert!(!p.exists());
        assert!(no_temp_files(dir.path()));
        // A destination whose folder does not exist is an I/O error naming it.
        let bad = dir.path().join("missing/b.npy");
        let e = NpyWriter::create(&bad, Dtype::F32, &[1]).err().unwrap();
        assert!(
            matches!(&e, PcaError::Io { path, .. } if path == &bad),
            "{e}"
        );
    }
}
