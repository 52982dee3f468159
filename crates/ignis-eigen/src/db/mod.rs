//! The Eigenfire database on disk (thesis §4.1 "off-line mode", §4.8 packs).
//!
//! A directory:
//! ```text
//! fire.db/
//!   manifest.json        readable: format version, clips (source, range, stride, fps,
//!                        resolution, pose, thresholds), pre-processing settings, E for
//!                        detection and rendering, SHA-256 and size of every data file
//!   mean.npy             Ψ, eq. (12): (H, W) f32 at the training size
//!   eigenvalues.npy      (k,) f64, descending
//!   weights.npy          Ω, eq. (18): (M, k) f32, one row per training frame
//!   angles.npy           (M,) f32, rotation applied by pose normalisation (radians)
//!   packs/pack_001.npy   Eigenfires 1..=P as (P, H, W) f32, then pack_002.npy, ...
//!   frames/<clip>.npy    optional full-resolution pre-processed frames (F, H', W') f32
//! ```
//! Every array is a NumPy `.npy` file. Dropping the last packs is the compression of §4.8:
//! the database then offers fewer Eigenfires. Loading memory-maps each file lazily; a
//! pack's checksum is verified the first time it is used, and a missing, truncated or
//! corrupt pack is reported by file name and never used. Writing is atomic: everything
//! goes to a temporary directory beside the target, which then replaces the target by
//! rename (the previous database is moved aside first and deleted last, so a crash leaves
//! either the old or the new database, never a mixture).
//!
//! Departure: the thesis writes an XML file plus binary packages; JSON + `.npy` are used
//! so that numpy and any JSON reader can open the database.

use crate::error::{EigenError, Result};
use crate::pose::ClipPose;
use crate::preprocess::PreprocessParams;
use ignis_core::{GrayFrame, Size};
use ignis_pca::npy::{self, Header};
use memmap2::Mmap;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Name of the format in the manifest.
pub const FORMAT: &str = "ignis-eigenfires";
/// Current format version; databases with a larger version are refused.
pub const VERSION: u32 = 1;

/// One data file listed in the manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Path relative to the database directory.
    pub file: String,
    /// Size in bytes.
    pub bytes: u64,
    /// SHA-256 of the whole file, lowercase hex.
    pub sha256: String,
}

/// A pack of Eigenfires.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PackEntry {
    #[serde(flatten)]
    pub entry: FileEntry,
    /// Index (0-based) of the first Eigenfire in the pack.
    pub first: usize,
    /// Number of Eigenfires in the pack.
    pub count: usize,
}

/// Consecutive-frame distances of a clip in PCA space (§4.5–4.6) and the thresholds
/// suggested from them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
pub struct Thresholds {
    /// Components used for the distances (E for detection).
    pub e: usize,
    /// Mean distance between consecutive training frames.
    pub mean: f64,
    pub min: f64,
    pub max: f64,
    /// Indices (within the clip) of frames whose distance to the next one is a local
    /// maximum above mean + one standard deviation (jumps in the motion).
    pub peaks: Vec<usize>,
    /// Suggested θ_min: the 10th percentile of the consecutive distances (candidates
    /// nearer than this are "the same frame", §4.5).
    pub theta_min: f64,
    /// Suggested θ_average: the mean consecutive distance (§4.6).
    pub theta_average: f64,
}

/// One training clip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClipEntry {
    /// Name used on the command line (`--clip candle`).
    pub name: String,
    /// Where the frames came from (a path or `synthetic:<style>`).
    pub source: String,
    /// Source frame range `[start, end)` and stride actually used.
    pub start: usize,
    pub end: usize,
    pub stride: usize,
    /// Frames per second of the source (divide by `stride` for the training rate).
    pub fps: f64,
    /// Resolution of the source.
    pub source_size: Size,
    /// Row of `weights.npy` holding this clip's first frame.
    pub first_row: usize,
    /// Number of training frames.
    pub frames: usize,
    /// Centring and scaling applied (§3.4).
    pub pose: ClipPose,
    /// Suggested thresholds (§4.5–4.6).
    pub thresholds: Thresholds,
    /// `frames/<name>.npy` when the full-resolution pre-processed frames are stored.
    pub frames_file: Option<FileEntry>,
    /// What the source video was at training (size in bytes, SHA-256, frame count), so a
    /// changed or replaced source is caught before its frames are used; `None` for
    /// sources that are not files (synthetic clips).
    #[serde(default)]
    pub source_check: Option<SourceCheck>,
    /// Fraction of the clip's lit pixels that were static (lit surroundings), which
    /// decided flame isolation (`pose.isolate`).
    #[serde(default)]
    pub static_lit: Option<f64>,
}

/// A source file's fingerprint.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SourceCheck {
    pub bytes: u64,
    pub sha256: String,
    /// Frames in the source when its container says.
    #[serde(default)]
    pub frame_count: Option<usize>,
}

/// The fingerprint of `source` when it is a file (`None` otherwise).
pub fn source_check(source: &str, frame_count: Option<usize>) -> Result<Option<SourceCheck>> {
    let p = Path::new(source);
    if !p.is_file() {
        return Ok(None);
    }
    let (bytes, sha256) = file_fingerprint(p)?;
    Ok(Some(SourceCheck {
        bytes,
        sha256,
        frame_count,
    }))
}

/// Size and SHA-256 of a file, read in 1 MiB blocks.
pub fn file_fingerprint(p: &Path) -> Result<(u64, String)> {
    use std::io::Read;
    let mut f = std::fs::File::open(p).map_err(|e| EigenError::io(p, e))?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut n = 0u64;
    loop {
        let k = f.read(&mut buf).map_err(|e| EigenError::io(p, e))?;
        if k == 0 {
            break;
        }
        h.update(&buf[..k]);
        n += k as u64;
    }
    Ok((n, h.finalize().iter().map(|b| format!("{b:02x}")).collect()))
}

impl SourceCheck {
    /// Compares `path` (now) with the fingerprint; an error names the clip, what changed
    /// and the ways out.
    pub fn verify(&self, clip: &str, path: &Path, frame_count: Option<usize>) -> Result<()> {
        if !path.is_file() {
            return Err(EigenError::clip(
                clip,
                format!(
                    "the source video {} is missing; give its new place with --relink {clip}=PATH, or render reconstructed frames with --from-database",
                    path.display()
                ),
            ));
        }
        let (bytes, sha) = file_fingerprint(path)?;
        let frames_differ = matches!((self.frame_count, frame_count), (Some(a), Some(b)) if a != b);
        if bytes != self.bytes || sha != self.sha256 || frames_differ {
            return Err(EigenError::clip(
                clip,
                format!(
                    "the source video {} changed since training ({} bytes, sha256 {}…{}; at training {} bytes, sha256 {}…{}); relink the original with --relink {clip}=PATH, retrain, or render reconstructed frames with --from-database",
                    path.display(),
                    bytes,
                    &sha[..8],
                    frame_count.map_or(String::new(), |n| format!(", {n} frames")),
                    self.bytes,
                    &self.sha256[..8.min(self.sha256.len())],
                    self.frame_count.map_or(String::new(), |n| format!(", {n} frames")),
                ),
            ));
        }
        Ok(())
    }
}

/// The readable description of a database.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    /// Program that wrote it.
    pub created_by: String,
    /// Size of the training frames (and of the mean and every Eigenfire).
    pub train_size: Size,
    /// Common frame size of the pre-processed frames (§3.4).
    pub frame_size: Size,
    /// M, training frames over all clips.
    pub frames: usize,
    /// k, Eigenfires stored.
    pub components: usize,
    /// Eigenfires per pack.
    pub pack_size: usize,
    /// Sum of all eigenvalues, retained or not (for retained-variance fractions).
    pub total_variance: f64,
    /// E used for recognition/detection (§4.8, §5.1.2).
    pub e_detect: usize,
    /// E used for rendering/reconstruction.
    pub e_render: usize,
    pub clips: Vec<ClipEntry>,
    pub preprocess: PreprocessParams,
    pub mean: FileEntry,
    pub eigenvalues: FileEntry,
    pub weights: FileEntry,
    pub angles: FileEntry,
    pub packs: Vec<PackEntry>,
    /// What common frame and training size were chosen and why.
    #[serde(default)]
    pub framing: String,
}

/// SHA-256 of a byte slice, lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    let d = Sha256::digest(bytes);
    d.iter().map(|b| format!("{b:02x}")).collect()
}

/// Name of the manifest's checksum sidecar, in `sha256sum` format
/// (`<hex>  manifest.json`), so `sha256sum -c manifest.sha256` checks it too. A sidecar
/// rather than a field: fields can be added to the manifest without changing how it is
/// hashed.
pub const MANIFEST_SUM: &str = "manifest.sha256";

/// The sidecar's text for manifest bytes `bytes`.
pub fn manifest_sum_text(bytes: &[u8]) -> String {
    format!("{}  manifest.json\n", sha256_hex(bytes))
}

/// Whether `rel` is a plain relative name inside the database directory: `/`-separated
/// parts of letters, digits, `-`, `_` and `.`, none empty, none starting with `.` (so no
/// `..`, no absolute path, no hidden file), at most two parts (`mean.npy`,
/// `packs/pack_001.npy`).
pub fn check_rel_name(rel: &str) -> std::result::Result<(), String> {
    let parts: Vec<&str> = rel.split('/').collect();
    let ok = !rel.is_empty()
        && rel.len() <= 255
        && parts.len() <= 2
        && parts.iter().all(|p| {
            !p.is_empty()
                && !p.starts_with('.')
                && p.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
        });
    if ok {
        Ok(())
    } else {
        Err(format!(
            "file name `{rel}` is not a plain name inside the database (no absolute paths, \
             no `..`, no hidden files); retrain the database or restore its manifest"
        ))
    }
}

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

impl Manifest {
    /// Checks every field against the others (counts, rows, packs, sizes, file names,
    /// numbers finite and in range). [`EigenfireDb::open`] calls it, then checks the files
    /// against it; `Err` names the first problem found.
    pub fn validate(&self) -> std::result::Result<(), String> {
        fn size_ok(what: &str, s: Size) -> std::result::Result<(), String> {
            Size::new(s.width, s.height)
                .map(|_| ())
                .map_err(|e| format!("{what} {}x{}: {e}", s.width, s.height))
        }
        let fin = |what: &str, v: f64| -> std::result::Result<(), String> {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("{what} is {v}, expected a finite number"))
            }
        };
        if self.format != FORMAT {
            return Err(format!("format is `{}`, expected `{FORMAT}`", self.format));
        }
        if self.version > VERSION {
            return Err(format!(
                "format version {} is newer than this program reads ({VERSION})",
                self.version
            ));
        }
        size_ok("train_size", self.train_size)?;
        size_ok("frame_size", self.frame_size)?;
        let (m, k) = (self.frames, self.components);
        if m == 0 || k == 0 || k > m {
            return Err(format!(
                "frames = {m}, components = {k}: need 1 <= components <= frames"
            ));
        }
        if self.pack_size == 0 {
            return Err("pack_size is 0, expected at least 1".into());
        }
        if self.e_detect == 0 || self.e_detect > k || self.e_render == 0 || self.e_render > k {
            return Err(format!(
                "e_detect = {}, e_render = {}: each must be in 1..={k} (components)",
                self.e_detect, self.e_render
            ));
        }
        fin("total_variance", self.total_variance)?;
        if self.total_variance < 0.0 {
            return Err(format!(
                "total_variance is {}, expected >= 0",
                self.total_variance
            ));
        }
        if self.clips.is_empty() {
            return Err("no clips".into());
        }
        let mut row = 0usize;
        for (i, c) in self.clips.iter().enumerate() {
            let bad = |r: String| Err(format!("clips[{i}] (`{}`): {r}", c.name));
            if c.name.is_empty()
                || c.name.starts_with('.')
                || !c
                    .name
                    .chars()
                    .all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch))
            {
                return bad(
                    "the name may contain only letters, digits, `-`, `_` and `.` (not first)"
                        .into(),
                );
            }
            if self.clips[..i].iter().any(|d| d.name == c.name) {
                return bad("two clips have this name".into());
            }
            if c.stride == 0 {
                return bad("stride is 0, expected at least 1".into());
            }
            if c.start >= c.end {
                return bad(format!("range {}..{} is empty", c.start, c.end));
            }
            let expect = (c.end - c.start).div_ceil(c.stride);
            if c.frames != expect {
                return bad(format!(
                    "frames = {}, but {}..{} every {} is {expect} frames",
                    c.frames, c.start, c.end, c.stride
                ));
            }
            if c.first_row != row {
                return bad(format!(
                    "first_row = {}, expected {row} (clips' rows are consecutive)",
                    c.first_row
                ));
            }
            row = match row.checked_add(c.frames) {
                Some(r) if r <= m => r,
                _ => return bad(format!("rows past frames = {m}")),
            };
            if !(c.fps.is_finite() && c.fps > 0.0) {
                return bad(format!("fps is {}, expected a finite number > 0", c.fps));
            }
            size_ok("source_size", c.source_size).or_else(&bad)?;
            let p = c.pose;
            if !(p.fuel_x.is_finite()
                && p.base_y.is_finite()
                && p.scale.is_finite()
                && p.scale > 0.0)
            {
                return bad(format!("pose {p:?} is not finite with scale > 0"));
            }
            let t = &c.thresholds;
            for (w, v) in [
                ("mean", t.mean),
                ("min", t.min),
                ("max", t.max),
                ("theta_min", t.theta_min),
                ("theta_average", t.theta_average),
            ] {
                fin(&format!("thresholds.{w}"), v).or_else(&bad)?;
            }
            if let Some(&pk) = t.peaks.iter().find(|&&pk| pk >= c.frames) {
                return bad(format!(
                    "thresholds.peaks has {pk}, past the clip's {} frames",
                    c.frames
                ));
            }
            if let Some(f) = &c.frames_file {
                check_rel_name(&f.file)?;
                if !f.file.starts_with("frames/") {
                    return bad(format!("frames_file `{}` is not in frames/", f.file));
                }
            }
        }
        if row != m {
            return Err(format!(
                "the clips hold {row} frames, the manifest says frames = {m}"
            ));
        }
        let mut first = 0;
        for (i, p) in self.packs.iter().enumerate() {
            let want = self.pack_size.min(k.saturating_sub(first));
            if p.first != first || p.count != want || want == 0 {
                return Err(format!(
                    "packs[{i}] holds {}..{}, expected {first}..{} (pack_size {})",
                    p.first,
                    p.first.saturating_add(p.count),
                    first + want,
                    self.pack_size
                ));
            }
            check_rel_name(&p.entry.file)?;
            if !p.entry.file.starts_with("packs/") {
                return Err(format!(
                    "packs[{i}] file `{}` is not in packs/",
                    p.entry.file
                ));
            }
            first += p.count;
        }
        if first != k {
            return Err(format!(
                "packs hold {first} Eigenfires, the manifest says {k}"
            ));
        }
        let mut names: Vec<&str> = Vec::new();
        let files = [&self.mean, &self.eigenvalues, &self.weights, &self.angles]
            .into_iter()
            .chain(self.packs.iter().map(|p| &p.entry))
            .chain(self.clips.iter().filter_map(|c| c.frames_file.as_ref()));
        for f in files {
            check_rel_name(&f.file)?;
            if f.sha256.len() != 64 || !f.sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
                return Err(format!(
                    "`{}`: sha256 `{}` is not 64 hex digits",
                    f.file, f.sha256
                ));
            }
            if names.contains(&f.file.as_str())
                || f.file == "manifest.json"
                || f.file == MANIFEST_SUM
            {
                return Err(format!("`{}` is listed twice", f.file));
            }
            names.push(&f.file);
        }
        self.preprocess
            .validate()
            .map_err(|e| format!("preprocess: {e}"))?;
        Ok(())
    }
}

/// Hashes a file and returns its manifest entry.
pub fn file_entry(dir: &Path, rel: &str) -> Result<FileEntry> {
    let p = dir.join(rel);
    let bytes = std::fs::read(&p).map_err(|e| EigenError::io(&p, e))?;
    Ok(FileEntry {
        file: rel.into(),
        bytes: bytes.len() as u64,
        sha256: sha256_hex(&bytes),
    })
}

/// Atomically replaces `target` by the directory `tmp` (same parent): one
/// `renameat2(RENAME_EXCHANGE)` where available (the name always holds a complete
/// database), else two renames with recovery on the next run; see
/// [`ignis_core::tempfiles::replace_dir`]. Refuses to replace a non-empty directory that
/// is not an Eigenfire database, and anything that is not a directory.
pub fn commit_dir(tmp: &Path, target: &Path) -> Result<()> {
    if let Ok(md) = std::fs::symlink_metadata(target) {
        let not_db = !md.is_dir()
            || (!target.join("manifest.json").exists()
                && target
                    .read_dir()
                    .map(|mut d| d.next().is_some())
                    .unwrap_or(true));
        if not_db {
            return Err(EigenError::bad(
                "output",
                format!(
                    "{} exists and is not an Eigenfire database; refusing to replace it \
                     (choose another output name)",
                    target.display()
                ),
            ));
        }
    }
    ignis_core::tempfiles::replace_dir(tmp, target).map_err(|e| EigenError::io(target, e))
}

/// A temporary directory beside `target` for an atomic write
/// (`.<name>.ignis-tmp-<pid>.dir`). Stale temporaries of killed runs in that directory are
/// removed first (and a database moved aside by an interrupted replacement is recovered).
pub fn temp_dir_for(target: &Path) -> Result<PathBuf> {
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| EigenError::io(&parent, e))?;
    ignis_core::tempfiles::recover_and_clean(&parent);
    let name = target
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "db".into());
    let tmp = parent.join(ignis_core::tempfiles::temp_name(&name, "dir"));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| EigenError::io(&tmp, e))?;
    }
    std::fs::create_dir_all(tmp.join("packs")).map_err(|e| EigenError::io(&tmp, e))?;
    std::fs::create_dir_all(tmp.join("frames")).map_err(|e| EigenError::io(&tmp, e))?;
    Ok(tmp)
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
            .filter_map(|c| c.frames_file.as_ref())
            .map(|f| f.bytes)
            .sum::<u64>();
        b + std::fs::metadata(self.dir.join("manifest.json"))
            .map(|m| m.len())
            .unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::{synthetic_clips, train, NoProgress, TrainParams};

    /// A small database: 2 × 24 frames of 20×32, 5 Eigenfires per pack (the last pack
    /// partly filled), so reconstructions cross pack boundaries.
    fn small_db(dir: &Path) -> EigenfireDb {
        let clips = synthetic_clips(Size::new(40, 64).unwrap(), 24, 3);
        let mut pre = PreprocessParams::with_sizes(
            Size::new(40, 64).unwrap(),
            Some(Size::new(20, 32).unwrap()),
        );
        pre.pose_samples = 6;
        let p = TrainParams {
            pack_size: 5,
            ..Default::default()
        };
        let out = dir.join("db");
        train(&clips, &pre, &p, &out, &mut NoProgress).unwrap();
        EigenfireDb::open(&out).unwrap()
    }

    /// Eq. (22) one Eigenfire at a time, the order `reconstruct` promises.
    fn naive(db: &EigenfireDb, w: &[f32], e: usize) -> Vec<f32> {
        let mut out = db.mean().data().to_vec();
        for (i, &wi) in w.iter().enumerate().take(e.min(db.n_components())) {
            for (o, &v) in out.iter_mut().zip(db.eigenfire_vec(i).unwrap().iter()) {
                *o += wi * v;
            }
        }
        out
    }

    #[test]
    fn reconstruct_batch_matches_reconstruct() {
        let tmp = tempfile::tempdir().unwrap();
        let db = small_db(tmp.path());
        let k = db.n_components();
        assert!(k > 10, "k = {k}");
        assert_eq!(db.weights_row_major().len(), db.n_frames() * k);
        assert_eq!(db.weights_row_major()[k + 2], db.weights()[(1, 2)]);
        let rows: Vec<Vec<f32>> = (0..db.n_frames())
            .step_by(5)
            .map(|r| db.frame_weights(r))
            .collect();
        let mut refs: Vec<&[f32]> = rows.iter().map(|v| v.as_slice()).collect();
        refs.push(&rows[1][..3]); // fewer weights than e: uses its own 3
        for e in [0, 1, 7, k, k + 10] {
            let batch = db.reconstruct_batch(&refs, e).unwrap();
            assert_eq!(batch.len(), refs.len());
            for (w, b) in refs.iter().zip(&batch) {
                let single = db.reconstruct(w, e).unwrap();
                assert_eq!(single.data(), naive(&db, w, e.min(w.len())).as_slice());
                let scale = single.data().iter().fold(0f32, |a, v| a.max(v.abs()));
                let diff = single
                    .data()
                    .iter()
                    .zip(b.data())
                    .fold(0f32, |a, (x, y)| a.max((x - y).abs()));
                assert!(diff <= 1e-4 * scale, "e = {e}: {diff} vs scale {scale}");
            }
        }
        assert!(db.reconstruct_batch(&[], 5).unwrap().is_empty());
    }

    #[test]
    fn reconstruction_does_not_depend_on_the_thread_count() {
        let tmp = tempfile::tempdir().unwrap();
        let db = small_db(tmp.path());
        let rows: Vec<Vec<f32>> = (0..6).map(|r| db.frame_weights(r * 7)).collect();
        let refs: Vec<&[f32]> = rows.iter().map(|v| v.as_slice()).collect();
        let k = db.n_components();
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let three = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let run = || {
            (
                db.reconstruct_batch(&refs, k).unwrap(),
                db.reconstruct(refs[2], k).unwrap(),
            )
        };
        let a = one.install(run);
        let b = three.install(run);
        assert_eq!(a, b);
        assert_eq!(a, run());
    }

    #[test]
    fn reconstruct_names_a_corrupt_pack() {
        let tmp = tempfile::tempdir().unwrap();
        let db = small_db(tmp.path());
        let w = db.frame_weights(0);
        let pack2 = db.path().join("packs/pack_002.npy");
        let mut bytes = std::fs::read(&pack2).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 0x40;
        std::fs::write(&pack2, bytes).unwrap();
        // Eigenfires 0..5 are in the intact first pack.
        assert!(db.reconstruct(&w, 5).is_ok());
        assert!(db.reconstruct_batch(&[&w], 5).is_ok());
        for r in [
            db.reconstruct(&w, 6).map(|_| ()),
            db.reconstruct_batch(&[&w], 6).map(|_| ()),
        ] {
            let e = r.unwrap_err().to_string();
            assert!(e.contains("pack_002.npy"), "{e}");
        }
    }

    /// Rewrites `db/manifest.json` through `f`; `resum` also rewrites its checksum (to get
    /// past it and reach validation).
    fn edit(db: &Path, resum: bool, f: impl FnOnce(&mut serde_json::Value)) {
        let mp = db.join("manifest.json");
        let mut v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&mp).unwrap()).unwrap();
        f(&mut v);
        let text = serde_json::to_string_pretty(&v).unwrap();
        std::fs::write(&mp, &text).unwrap();
        if resum {
            std::fs::write(db.join(MANIFEST_SUM), manifest_sum_text(text.as_bytes())).unwrap();
        }
    }

    /// Issue 18 defects 1 and 2: every edited field is refused on open, by the checksum or
    /// (with the checksum rewritten) by validation, without a panic or a huge allocation.
    #[test]
    fn edited_manifest_fields_are_refused_on_open() {
        let tmp = tempfile::tempdir().unwrap();
        let db = small_db(tmp.path());
        let dir = db.path().to_path_buf();
        drop(db);
        let orig_m = std::fs::read(dir.join("manifest.json")).unwrap();
        let orig_s = std::fs::read(dir.join(MANIFEST_SUM)).unwrap();
        let restore = || {
            std::fs::write(dir.join("manifest.json"), &orig_m).unwrap();
            std::fs::write(dir.join(MANIFEST_SUM), &orig_s).unwrap();
        };
        let big = serde_json::json!(1_000_000_000u64);
        type Edit = Box<dyn Fn(&mut serde_json::Value)>;
        let pack1 = "packs/pack_001.npy";
        let cases: Vec<(&str, Edit)> = vec![
            ("stride", Box::new(|v| v["clips"][0]["stride"] = 0.into())),
            (
                "first_row",
                Box::new(|v| v["clips"][0]["first_row"] = 1.into()),
            ),
            (
                "first_row",
                Box::new({
                    let b = big.clone();
                    move |v| v["clips"][0]["first_row"] = b.clone()
                }),
            ),
            (
                "frames",
                Box::new(|v| {
                    let f = v["clips"][0]["frames"].as_u64().unwrap();
                    v["clips"][0]["frames"] = (f + 1).into()
                }),
            ),
            (
                "frames",
                Box::new({
                    let b = big.clone();
                    move |v| v["clips"][0]["frames"] = b.clone()
                }),
            ),
            ("pack_size", Box::new(|v| v["pack_size"] = 0.into())),
            (
                "frame_size",
                Box::new(|v| {
                    v["frame_size"] = serde_json::json!({"width": 100000, "height": 100000})
                }),
            ),
            (
                "fps",
                Box::new(|v| v["clips"][0]["fps"] = serde_json::json!(-1.0)),
            ),
            ("e_render", Box::new(|v| v["e_render"] = 100000.into())),
            (
                "/etc/shadow",
                Box::new(|v| v["mean"]["file"] = "/etc/shadow".into()),
            ),
            (
                "plain name",
                Box::new(|v| v["packs"][0]["file"] = "../other.db/packs/pack_001.npy".into()),
            ),
            (
                "listed twice",
                Box::new(move |v| v["mean"]["file"] = pack1.into()),
            ),
        ];
        for (want, f) in &cases {
            // Without the checksum rewritten, the edit itself is named.
            edit(&dir, false, f);
            let e = EigenfireDb::open(&dir).unwrap_err().to_string();
            assert!(
                e.contains("checksum mismatch") && e.contains("edited"),
                "{want}: {e}"
            );
            restore();
            edit(&dir, true, f);
            let e = EigenfireDb::open(&dir).unwrap_err().to_string();
            assert!(e.contains(want), "expected `{want}` in: {e}");
            restore();
        }
        // A stored-frames file pointing at a pack: shape refused on use, not a panic.
        EigenfireDb::open(&dir).unwrap();
        // A missing checksum sidecar is an error naming it.
        std::fs::remove_file(dir.join(MANIFEST_SUM)).unwrap();
        let e = EigenfireDb::open(&dir).unwrap_err().to_string();
        assert!(e.contains(MANIFEST_SUM), "{e}");
        restore();
    }

    /// Issue 18 defect 2: symbolic links and FIFOs are refused, never followed or opened
    /// for a read that would block.
    #[cfg(unix)]
    #[test]
    fn links_and_fifos_in_a_database_are_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let db = small_db(tmp.path());
        let dir = db.path().to_path_buf();
        drop(db);
        let mean = dir.join("mean.npy");
        let saved = tmp.path().join("mean.saved");
        std::fs::rename(&mean, &saved).unwrap();
        std::os::unix::fs::symlink(&saved, &mean).unwrap();
        let e = EigenfireDb::open(&dir).unwrap_err().to_string();
        assert!(e.contains("symbolic link"), "{e}");
        std::fs::remove_file(&mean).unwrap();
        let c = std::ffi::CString::new(mean.to_str().unwrap()).unwrap();
        // SAFETY: a valid path string.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
        let e = EigenfireDb::open(&dir).unwrap_err().to_string();
        assert!(e.contains("not a regular file"), "{e}");
        std::fs::remove_file(&mean).unwrap();
        std::fs::rename(&saved, &mean).unwrap();
        EigenfireDb::open(&dir).unwrap();
    }
}
