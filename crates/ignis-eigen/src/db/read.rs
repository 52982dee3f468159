//! Reading a database: [`EigenfireDb`] maps the files the manifest lists, checks them and
//! reconstructs frames (eq. 22).

use super::{
    check_rel_name, manifest_sum_text, sha256_hex, ClipEntry, FileEntry, Manifest, MANIFEST_SUM,
};
use crate::error::{EigenError, Result};
use ignis_core::{GrayFrame, Size};
use ignis_pca::npy::{self, Header};
use memmap2::Mmap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Opens `db/rel` for reading only if it is a regular file reached without symbolic links
/// (below `db`) and never blocks (a FIFO or device is refused, not opened for a read that
/// could hang).
pub fn open_regular(db: &Path, rel: &str) -> std::result::Result<std::fs::File, String> {
    check_rel_name(rel)?;
    let mut p = db.to_path_buf();
    for part in rel.split('/') {
        p.push(part);
        let md =
            std::fs::symlink_metadata(&p).map_err(|e| format!("missing or unreadable ({e})"))?;
        if md.file_type().is_symlink() {
            return Err(format!(
                "`{}` is a symbolic link; database files must be regular files inside the database",
                p.display()
            ));
        }
    }
    let mut o = std::fs::OpenOptions::new();
    o.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        o.custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK);
    }
    let f = o
        .open(&p)
        .map_err(|e| format!("missing or unreadable ({e})"))?;
    let md = f.metadata().map_err(|e| e.to_string())?;
    if !md.is_file() {
        return Err(format!(
            "`{}` is not a regular file (a FIFO, device or directory); database files must be regular files",
            p.display()
        ));
    }
    Ok(f)
}

/// Pixels per rayon task in [`EigenfireDb::reconstruct`] (16 KiB of output, in L1).
const RECON_BLOCK: usize = 4096;
/// Pixels (rows of the N×B output) per rayon task in [`EigenfireDb::reconstruct_batch`].
const BATCH_BLOCK: usize = 2048;

/// Packs in use by a reconstruction: (first Eigenfire, how many of them, the pack's data).
type PackData<'a> = Vec<(usize, usize, std::borrow::Cow<'a, [f32]>)>;

/// A memory-mapped, checked `.npy` file.
struct Mapped {
    map: Mmap,
    header: Header,
}

impl Mapped {
    fn f32(&self) -> std::borrow::Cow<'_, [f32]> {
        npy::f32_data(&self.map, &self.header)
    }
}

/// An opened Eigenfire database. Cheap to open: only the manifest, mean, eigenvalues,
/// weights and angles are read (and their checksums verified); packs and stored frames are
/// mapped and verified on first use.
pub struct EigenfireDb {
    dir: PathBuf,
    manifest: Manifest,
    mean: Vec<f32>,
    eigenvalues: Vec<f64>,
    weights: Mapped,
    /// A copy of the weights when the file's data is not 4-byte aligned (not written by
    /// us); otherwise the map is used in place.
    weights_copy: Option<Vec<f32>>,
    angles: Vec<f32>,
    packs: Vec<OnceLock<std::result::Result<Mapped, String>>>,
    frames: Vec<OnceLock<std::result::Result<Mapped, String>>>,
    /// Per clip, its stored masks (read and checked on first use).
    masks: Vec<OnceLock<std::result::Result<super::masks::MaskFile, String>>>,
}

impl std::fmt::Debug for EigenfireDb {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EigenfireDb")
            .field("dir", &self.dir)
            .field("frames", &self.manifest.frames)
            .field("components", &self.manifest.components)
            .finish()
    }
}

fn map_checked(db: &Path, entry: &FileEntry, verify: bool) -> std::result::Result<Mapped, String> {
    let p = db.join(&entry.file);
    let f = open_regular(db, &entry.file)?;
    let len = f.metadata().map_err(|e| e.to_string())?.len();
    if len != entry.bytes {
        return Err(format!(
            "truncated or resized: {len} bytes, the manifest says {}",
            entry.bytes
        ));
    }
    // SAFETY: the database is written once (atomically) and treated as read-only; a
    // concurrent external modification could change the mapped bytes, which at worst
    // gives wrong numbers, never unsoundness for plain f32 data.
    let map = unsafe { Mmap::map(&f) }.map_err(|e| format!("cannot map ({e})"))?;
    if verify {
        let h = sha256_hex(&map);
        if h != entry.sha256 {
            return Err(format!(
                "checksum mismatch (corrupt): sha256 {h}, the manifest says {}",
                entry.sha256
            ));
        }
    }
    let header = npy::parse_header(&p, &map).map_err(|e| match e {
        ignis_pca::PcaError::Unsupported { reason, .. } => reason,
        other => other.to_string(),
    })?;
    if header.fortran_order {
        return Err("Fortran-order arrays are not supported".into());
    }
    if header.file_len() != map.len() {
        return Err(format!(
            "array header says {} bytes, file has {}",
            header.file_len(),
            map.len()
        ));
    }
    Ok(Mapped { map, header })
}

impl EigenfireDb {
    /// Opens the database at `dir`. Fails (naming the file) when the manifest, mean,
    /// eigenvalues, weights or angles are missing or corrupt; packs are checked lazily (see
    /// [`EigenfireDb::verify`] to check everything now).
    pub fn open(dir: &Path) -> Result<EigenfireDb> {
        let dberr = |file: &str, reason: String| EigenError::Database {
            db: dir.to_path_buf(),
            file: file.into(),
            reason,
        };
        match std::fs::metadata(dir) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                let why = "there is no such database; check the path (a database is the \
                           directory `ignis eigen train ... -o DIR` writes)";
                return Err(EigenError::io(
                    dir,
                    ignis_core::textfile::explain_missing(e, why),
                ));
            }
            // footage (or any file) where the database goes
            Ok(m) if !m.is_dir() => {
                return Err(EigenError::io(
                    dir,
                    std::io::Error::new(
                        std::io::ErrorKind::InvalidInput,
                        "a file, not a database: a database is the directory `ignis eigen \
                         train FOOTAGE -o DIR` writes (to loop footage as it is: `ignis loop \
                         FOOTAGE --length 4s -o loop.png`)",
                    ),
                ));
            }
            _ => {}
        }
        // Read with a bound (a manifest is a few kB; 16 MiB allows thousands of clips).
        let read_small = |name: &str| -> Result<Vec<u8>> {
            use std::io::Read;
            let f = open_regular(dir, name)
                .map_err(|r| dberr(name, format!("{r}; is this an Eigenfire database?")))?;
            let mut bytes = Vec::new();
            f.take(16 << 20)
                .read_to_end(&mut bytes)
                .map_err(|e| dberr(name, format!("cannot read ({e})")))?;
            if bytes.len() >= 16 << 20 {
                return Err(dberr(
                    name,
                    "larger than 16 MiB; not an Eigenfire manifest".into(),
                ));
            }
            Ok(bytes)
        };
        let bytes = read_small("manifest.json")?;
        let sum = read_small(MANIFEST_SUM)?;
        if sum != manifest_sum_text(&bytes).as_bytes() {
            return Err(dberr(
                "manifest.json",
                format!(
                    "checksum mismatch: the manifest was edited or is corrupt (sha256 {}, \
                     {MANIFEST_SUM} says `{}`); restore it or retrain the database",
                    sha256_hex(&bytes),
                    String::from_utf8_lossy(&sum[..sum.len().min(64)])
                ),
            ));
        }
        let manifest: Manifest = serde_json::from_slice(&bytes)
            .map_err(|e| dberr("manifest.json", format!("malformed: {e}")))?;
        manifest
            .validate()
            .map_err(|r| dberr("manifest.json", format!("invalid: {r}")))?;
        // Renders read the clips' source videos: no output of this command may replace one.
        for c in &manifest.clips {
            ignis_core::atomic::record_input(Path::new(&c.source));
        }
        let n = manifest.train_size.pixels();
        let (m, k) = (manifest.frames, manifest.components);
        let load = |e: &FileEntry, shape: &[usize]| -> Result<Mapped> {
            let mp = map_checked(dir, e, true).map_err(|r| dberr(&e.file, r))?;
            let want = if std::ptr::eq(e, &manifest.eigenvalues) {
                npy::Dtype::F64
            } else {
                npy::Dtype::F32
            };
            if mp.header.dtype != want {
                return Err(dberr(
                    &e.file,
                    format!("dtype {:?}, expected {want:?}", mp.header.dtype),
                ));
            }
            if mp.header.len() != shape.iter().product::<usize>() {
                return Err(dberr(
                    &e.file,
                    format!(
                        "shape {:?} does not match the manifest ({shape:?})",
                        mp.header.shape
                    ),
                ));
            }
            Ok(mp)
        };
        let mean = load(&manifest.mean, &[n])?.f32().into_owned();
        let ev = load(&manifest.eigenvalues, &[k])?;
        let eigenvalues = npy::f64_data(&ev.map, &ev.header);
        let weights = load(&manifest.weights, &[m, k])?;
        let weights_copy = match weights.f32() {
            std::borrow::Cow::Borrowed(_) => None,
            std::borrow::Cow::Owned(v) => Some(v),
        };
        let angles = load(&manifest.angles, &[m])?.f32().into_owned();
        let packs = manifest.packs.iter().map(|_| OnceLock::new()).collect();
        let frames = manifest.clips.iter().map(|_| OnceLock::new()).collect();
        let masks = manifest.clips.iter().map(|_| OnceLock::new()).collect();
        Ok(EigenfireDb {
            dir: dir.to_path_buf(),
            manifest,
            mean,
            eigenvalues,
            weights,
            weights_copy,
            angles,
            packs,
            frames,
            masks,
        })
    }

    /// The database directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }
    pub fn clips(&self) -> &[ClipEntry] {
        &self.manifest.clips
    }
    /// Size of the mean and of every Eigenfire.
    pub fn train_size(&self) -> Size {
        self.manifest.train_size
    }
    /// Ψ, the mean training frame.
    pub fn mean(&self) -> GrayFrame {
        GrayFrame::from_vec(self.manifest.train_size, self.mean.clone()).expect("checked at open")
    }
    /// Eigenvalues, descending (length k).
    pub fn eigenvalues(&self) -> &[f64] {
        &self.eigenvalues
    }
    /// M, number of training frames.
    pub fn n_frames(&self) -> usize {
        self.manifest.frames
    }
    /// k, number of Eigenfires stored (some may be in unusable packs).
    pub fn n_components(&self) -> usize {
        self.manifest.components
    }
    /// All weights, M×k, row `i` = training frame `i` (see [`EigenfireDb::frame_index`]).
    pub fn weights(&self) -> faer::MatRef<'_, f32> {
        let s: &[f32] = match (&self.weights_copy, self.weights.f32()) {
            (Some(v), _) => v,
            (None, std::borrow::Cow::Borrowed(s)) => s,
            (None, std::borrow::Cow::Owned(_)) => unreachable!("alignment was checked at open"),
        };
        faer::MatRef::from_row_major_slice(s, self.manifest.frames, self.manifest.components)
    }
    /// All weights as one M×k row-major slice (row `i` = training frame `i`), without a
    /// copy: what [`crate::transition::WeightSpace::new`] takes.
    pub fn weights_row_major(&self) -> &[f32] {
        match (&self.weights_copy, self.weights.f32()) {
            (Some(v), _) => v,
            (None, std::borrow::Cow::Borrowed(s)) => s,
            (None, std::borrow::Cow::Owned(_)) => unreachable!("alignment was checked at open"),
        }
    }
    /// Weights of training frame `i` (length k).
    pub fn frame_weights(&self, i: usize) -> Vec<f32> {
        let w = self.weights();
        (0..w.ncols()).map(|j| w[(i, j)]).collect()
    }
    /// Rotation (radians) pose normalisation applied to training frame `i`.
    pub fn angle(&self, i: usize) -> f32 {
        self.angles[i]
    }
    /// Row of clip `clip`'s source frame `frame`, if that frame was trained on.
    pub fn frame_index(&self, clip: &str, frame: usize) -> Result<usize> {
        let c = self.clip(clip)?;
        if frame < c.start || frame >= c.end || !(frame - c.start).is_multiple_of(c.stride) {
            return Err(EigenError::bad(
                "frame",
                format!("clip `{clip}` was trained on frames {}..{} every {}; frame {frame} is not one of them", c.start, c.end, c.stride),
            ));
        }
        let j = (frame - c.start) / c.stride;
        if j >= c.frames {
            return Err(EigenError::bad(
                "frame",
                format!("clip `{clip}` has {} training frames", c.frames),
            ));
        }
        Ok(c.first_row + j)
    }
    /// The clip called `name`.
    pub fn clip(&self, name: &str) -> Result<&ClipEntry> {
        self.manifest
            .clips
            .iter()
            .find(|c| c.name == name)
            .ok_or_else(|| {
                let names: Vec<&str> = self
                    .manifest
                    .clips
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect();
                EigenError::bad(
                    "clip",
                    format!(
                        "no clip `{name}` in the database (clips: {})",
                        names.join(", ")
                    ),
                )
            })
    }
    /// Which clip and source frame training row `i` is.
    pub fn row_origin(&self, i: usize) -> Option<(&ClipEntry, usize)> {
        self.manifest
            .clips
            .iter()
            .find(|c| i >= c.first_row && i < c.first_row + c.frames)
            .map(|c| (c, c.start + (i - c.first_row) * c.stride))
    }

    fn pack(&self, p: usize) -> Result<&Mapped> {
        let e = &self.manifest.packs[p];
        let r = self.packs[p].get_or_init(|| {
            let mp = map_checked(&self.dir, &e.entry, true)?;
            if mp.header.len() != e.count * self.manifest.train_size.pixels()
                || mp.header.dtype != npy::Dtype::F32
            {
                return Err(format!(
                    "shape {:?} does not match the manifest",
                    mp.header.shape
                ));
            }
            Ok(mp)
        });
        r.as_ref().map_err(|reason| EigenError::Database {
            db: self.dir.clone(),
            file: e.entry.file.clone(),
            reason: reason.clone(),
        })
    }

    /// Eigenfire `i` (0-based) as a raw vector of length N. Fails, naming the pack file,
    /// when its pack is missing, truncated or corrupt.
    pub fn eigenfire_vec(&self, i: usize) -> Result<std::borrow::Cow<'_, [f32]>> {
        if i >= self.manifest.components {
            return Err(EigenError::bad(
                "eigenfire",
                format!("index {i} out of range (k = {})", self.manifest.components),
            ));
        }
        let p = i / self.manifest.pack_size;
        let mp = self.pack(p)?;
        let n = self.manifest.train_size.pixels();
        let off = (i - self.manifest.packs[p].first) * n;
        Ok(match mp.f32() {
            std::borrow::Cow::Borrowed(s) => std::borrow::Cow::Borrowed(&s[off..off + n]),
            std::borrow::Cow::Owned(v) => std::borrow::Cow::Owned(v[off..off + n].to_vec()),
        })
    }

    /// Eigenfire `i` (0-based) as a frame (raw values, not scaled for display; see
    /// [`crate::analysis::eigenfire_image`]).
    pub fn eigenfire(&self, i: usize) -> Result<GrayFrame> {
        Ok(GrayFrame::from_vec(
            self.manifest.train_size,
            self.eigenfire_vec(i)?.into_owned(),
        )?)
    }

    /// Eigenfires that can be used: the leading ones whose packs are all intact (checks and
    /// caches every pack up to the first bad one).
    pub fn usable_components(&self) -> usize {
        let mut n = 0;
        for (p, e) in self.manifest.packs.iter().enumerate() {
            if self.pack(p).is_err() {
                break;
            }
            n += e.count;
        }
        n
    }

    /// Checks every file now; returns the problems found (file, reason), empty when the
    /// database is intact.
    pub fn verify(&self) -> Vec<(String, String)> {
        let mut bad = Vec::new();
        for (p, e) in self.manifest.packs.iter().enumerate() {
            if let Err(EigenError::Database { reason, .. }) = self.pack(p) {
                bad.push((e.entry.file.clone(), reason));
            }
        }
        for (c, clip) in self.manifest.clips.iter().enumerate() {
            if let Some(f) = &clip.mask_file {
                if let Err(e) = self.mask_file(c) {
                    bad.push((f.file.clone(), e.to_string()));
                }
            }
            if clip.frames_file.is_some() {
                if let Err(e) = self.frames_map(c) {
                    bad.push((
                        clip.frames_file
                            .as_ref()
                            .map(|f| f.file.clone())
                            .unwrap_or_default(),
                        e.to_string(),
                    ));
                }
            }
        }
        bad
    }

    /// Reconstructs a frame from weights with the first `e` Eigenfires, eq. (22):
    /// I = Ψ + Σ_{i<e} ωᵢ uᵢ. `e` is clamped to the weights' length; fails, naming the pack,
    /// if a needed pack is unusable.
    ///
    /// Pixels are split into fixed blocks on rayon's pool; within a pixel the sum runs over
    /// i in order, so the result does not depend on the thread count.
    pub fn reconstruct(&self, weights: &[f32], e: usize) -> Result<GrayFrame> {
        use rayon::prelude::*;
        let e = e.min(weights.len()).min(self.manifest.components);
        let packs = self.pack_data(e)?;
        let n = self.manifest.train_size.pixels();
        let mut out = self.mean.clone();
        out.par_chunks_mut(RECON_BLOCK)
            .enumerate()
            .for_each(|(b, o)| {
                let (r0, len) = (b * RECON_BLOCK, o.len());
                fn seg(data: &[f32], start: usize, len: usize) -> &[f32] {
                    &data[start..start + len]
                }
                for (first, count, data) in &packs {
                    let w = &weights[*first..first + count];
                    // Four Eigenfires per pass over the block (same order of operations
                    // as one at a time: ((o + w0·u0) + w1·u1) + ...).
                    let mut j = 0;
                    while j + 4 <= w.len() {
                        let (u0, u1, u2, u3) = (
                            seg(data, j * n + r0, len),
                            seg(data, (j + 1) * n + r0, len),
                            seg(data, (j + 2) * n + r0, len),
                            seg(data, (j + 3) * n + r0, len),
                        );
                        let (w0, w1, w2, w3) = (w[j], w[j + 1], w[j + 2], w[j + 3]);
                        for (p, o) in o.iter_mut().enumerate() {
                            *o = *o + w0 * u0[p] + w1 * u1[p] + w2 * u2[p] + w3 * u3[p];
                        }
                        j += 4;
                    }
                    for (j, &wj) in w.iter().enumerate().skip(j) {
                        for (o, &v) in o.iter_mut().zip(seg(data, j * n + r0, len)) {
                            *o += wj * v;
                        }
                    }
                }
            });
        Ok(GrayFrame::from_vec(self.manifest.train_size, out)?)
    }

    /// Reconstructs many frames at once, eq. (22) for each: frame `b` uses the first
    /// `min(e, weights[b].len())` Eigenfires. One matrix product per pack (B×e weights
    /// times e×N Eigenfires), so every Eigenfire is read once per batch instead of once per
    /// frame. Equal to [`EigenfireDb::reconstruct`] up to rounding (≈ 1e-6 relative; the
    /// product sums in another order). Fails, naming the pack, if a needed pack is
    /// unusable.
    ///
    /// Parallelism follows `ignis-pca`'s policy: fixed blocks of pixels on rayon's pool,
    /// each a sequential faer product (`Par::Seq`), so the result does not depend on the
    /// thread count.
    pub fn reconstruct_batch(&self, weights: &[&[f32]], e: usize) -> Result<Vec<GrayFrame>> {
        use rayon::prelude::*;
        let b = weights.len();
        let longest = weights.iter().map(|w| w.len()).max().unwrap_or(0);
        let e = e.min(longest).min(self.manifest.components);
        if b == 0 {
            return Ok(Vec::new());
        }
        let packs = self.pack_data(e)?;
        let n = self.manifest.train_size.pixels();
        // e×B weights; a frame with fewer weights gets zeros past its own length.
        let w = faer::Mat::<f32>::from_fn(e, b, |i, j| weights[j].get(i).copied().unwrap_or(0.0));
        let mut out = faer::Mat::<f32>::zeros(n, b);
        out.as_mut()
            .par_row_chunks_mut(BATCH_BLOCK)
            .enumerate()
            .for_each(|(blk, mut dst)| {
                let r0 = blk * BATCH_BLOCK;
                let len = dst.nrows();
                for j in 0..b {
                    for (r, m) in self.mean[r0..r0 + len].iter().enumerate() {
                        dst[(r, j)] = *m;
                    }
                }
                for (first, count, data) in &packs {
                    let u = faer::MatRef::from_column_major_slice(&data[..count * n], n, *count);
                    faer::linalg::matmul::matmul(
                        dst.as_mut(),
                        faer::Accum::Add,
                        u.subrows(r0, len),
                        w.subrows(*first, *count),
                        1.0f32,
                        faer::Par::Seq,
                    );
                }
            });
        (0..b)
            .map(|j| {
                let col = out.col(j);
                let v: Vec<f32> = match col.try_as_col_major() {
                    Some(c) => c.as_slice().to_vec(),
                    None => (0..n).map(|r| col[r]).collect(),
                };
                Ok(GrayFrame::from_vec(self.manifest.train_size, v)?)
            })
            .collect()
    }

    /// The packs holding Eigenfires `0..e`: (first Eigenfire, how many of them are below
    /// `e`, the pack's data). Fails, naming the first unusable pack.
    fn pack_data(&self, e: usize) -> Result<PackData<'_>> {
        let mut v = Vec::new();
        for (p, entry) in self.manifest.packs.iter().enumerate() {
            if entry.first >= e {
                break;
            }
            let count = entry.count.min(e - entry.first);
            v.push((entry.first, count, self.pack(p)?.f32()));
        }
        Ok(v)
    }

    /// Euclidean distance between training frames `i` and `j` over the first `e`
    /// components, eq. (21).
    pub fn distance(&self, i: usize, j: usize, e: usize) -> f64 {
        let w = self.weights();
        let e = e.min(w.ncols());
        (0..e)
            .map(|c| ((w[(i, c)] - w[(j, c)]) as f64).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    fn frames_map(&self, c: usize) -> Result<&Mapped> {
        let clip = &self.manifest.clips[c];
        let e = clip.frames_file.as_ref().ok_or_else(|| {
            EigenError::bad(
                "frames",
                format!(
                    "clip `{}` has no stored pre-processed frames (train with store_frames = true)",
                    clip.name
                ),
            )
        })?;
        let want = clip
            .frames
            .saturating_mul(self.manifest.frame_size.pixels());
        let r = self.frames[c].get_or_init(|| {
            let mp = map_checked(&self.dir, e, true)?;
            if mp.header.len() != want || mp.header.dtype != npy::Dtype::F32 {
                return Err(format!(
                    "shape {:?} does not match the manifest ({} frames of {})",
                    mp.header.shape, clip.frames, self.manifest.frame_size
                ));
            }
            Ok(mp)
        });
        r.as_ref().map_err(|reason| EigenError::Database {
            db: self.dir.clone(),
            file: e.file.clone(),
            reason: reason.clone(),
        })
    }

    /// Clip `c`'s stored masks, read and checked (size, SHA-256, layout) on first use;
    /// `None` when the database has none for it.
    fn mask_file(&self, c: usize) -> Result<Option<&super::masks::MaskFile>> {
        let clip = &self.manifest.clips[c];
        let Some(e) = clip.mask_file.as_ref() else {
            return Ok(None);
        };
        let r = self.masks[c].get_or_init(|| {
            use std::io::Read;
            let f = open_regular(&self.dir, &e.file)?;
            let mut bytes = Vec::new();
            f.take(e.bytes.saturating_add(1))
                .read_to_end(&mut bytes)
                .map_err(|e| format!("cannot read ({e})"))?;
            if bytes.len() as u64 != e.bytes {
                return Err(format!(
                    "truncated or resized: {} bytes, the manifest says {}",
                    bytes.len(),
                    e.bytes
                ));
            }
            let h = sha256_hex(&bytes);
            if h != e.sha256 {
                return Err(format!(
                    "checksum mismatch (corrupt): sha256 {h}, the manifest says {}",
                    e.sha256
                ));
            }
            let s = clip.source_size;
            super::masks::MaskFile::parse(bytes, s.width, s.height, clip.frames)
        });
        match r {
            Ok(m) => Ok(Some(m)),
            Err(reason) => Err(EigenError::Database {
                db: self.dir.clone(),
                file: e.file.clone(),
                reason: reason.clone(),
            }),
        }
    }

    /// The pre-processing mask training made for database row `row` (0/255 at the clip's
    /// source size), `None` when the database does not store masks or has no such row.
    pub fn source_mask(&self, row: usize) -> Result<Option<image::GrayImage>> {
        let Some((clip, _)) = self.row_origin(row) else {
            return Ok(None);
        };
        let c = self
            .manifest
            .clips
            .iter()
            .position(|x| x.name == clip.name)
            .expect("row_origin's clip");
        let Some(mf) = self.mask_file(c)? else {
            return Ok(None);
        };
        let j = row - clip.first_row;
        mf.mask(j).map(Some).map_err(|reason| EigenError::Database {
            db: self.dir.clone(),
            file: clip
                .mask_file
                .as_ref()
                .map(|f| f.file.clone())
                .unwrap_or_default(),
            reason,
        })
    }

    /// The stored full-resolution pre-processed frame (§7.1.2 fast path) of clip `clip`,
    /// source frame `frame`.
    pub fn preprocessed_frame(&self, clip: &str, frame: usize) -> Result<GrayFrame> {
        let row = self.frame_index(clip, frame)?;
        let c = self
            .manifest
            .clips
            .iter()
            .position(|c| c.name == clip)
            .expect("found by frame_index");
        let mp = self.frames_map(c)?;
        let n = self.manifest.frame_size.pixels();
        let j = row - self.manifest.clips[c].first_row;
        let data = mp.f32();
        Ok(GrayFrame::from_vec(
            self.manifest.frame_size,
            data[j * n..(j + 1) * n].to_vec(),
        )?)
    }

    /// Total size of the database files in bytes.
    pub fn bytes_on_disk(&self) -> u64 {
        let m = &self.manifest;
        let mut b = m.mean.bytes + m.eigenvalues.bytes + m.weights.bytes + m.angles.bytes;
        b += m.packs.iter().map(|p| p.entry.bytes).sum::<u64>();
        b += m
            .clips
            .iter()
            .flat_map(|c| c.frames_file.iter().chain(&c.mask_file))
            .map(|f| f.bytes)
            .sum::<u64>();
        b + std::fs::metadata(self.dir.join("manifest.json"))
            .map(|m| m.len())
            .unwrap_or(0)
    }
}
