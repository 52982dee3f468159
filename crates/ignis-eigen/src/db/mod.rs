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

pub mod masks;
mod read;
mod write;

pub use read::{open_regular, EigenfireDb};
pub use write::{check_replaceable, commit_dir, file_entry, temp_dir_for, DbWriter};

use crate::error::{EigenError, Result};
use crate::pose::ClipPose;
use crate::preprocess::PreprocessParams;
use ignis_core::Size;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::Path;

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
    /// `masks/<name>.rle`: every training frame's pre-processing mask at the source size
    /// ([`masks`]), so rendering from the footage reads it instead of making it again.
    /// `None` in databases from before it was stored (rendering then makes the masks).
    #[serde(default)]
    pub mask_file: Option<FileEntry>,
    /// What the source video was at training (size in bytes, SHA-256, frame count), so a
    /// changed or replaced source is caught before its frames are used; `None` for
    /// sources that are not files (synthetic clips).
    #[serde(default)]
    pub source_check: Option<SourceCheck>,
    /// Fraction of the clip's lit pixels that were static (lit surroundings), which
    /// decided flame isolation (`pose.isolate`).
    #[serde(default)]
    pub static_lit: Option<f64>,
    /// The flame's own colour (linear RGB, brightest channel 1): the sum of the footage's
    /// colour over every training frame's masked pixels that are not clipped
    /// ([`crate::preprocess::FlameColour`]). Original colouring tints the bloom with it
    /// unless the scenario sets `tint`, so a blue or white flame does not get an orange
    /// halo. `None` in databases from before it was measured (the bloom then keeps the
    /// default tint) and for clips with no lit pixel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flame_colour: Option<[f32; 3]>,
    /// The rectangle `[x, y, width, height]` of the source's frames the clip was trained
    /// on ([`crate::ClipSpec::crop`]; `source_size` is its size); `None`: the whole frame.
    /// Renders from the footage cut the same rectangle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop: Option<[u32; 4]>,
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

/// The fingerprint of `source` when it is a file or an image sequence (`None` otherwise).
pub fn source_check(source: &str, frame_count: Option<usize>) -> Result<Option<SourceCheck>> {
    let Some((bytes, sha256)) = source_fingerprint(Path::new(source))? else {
        return Ok(None);
    };
    Ok(Some(SourceCheck {
        bytes,
        sha256,
        frame_count,
    }))
}

/// Size and SHA-256 of a source: a file ([`file_fingerprint`]) or, with the `media`
/// feature, an image sequence (a directory or `frames/%04d.png`: its frame files in order,
/// `ignis_media::source_fingerprint`); `None` when `p` is neither (a synthetic clip's name,
/// a sequence with no frames left).
fn source_fingerprint(p: &Path) -> Result<Option<(u64, String)>> {
    if p.is_file() {
        return file_fingerprint(p).map(Some);
    }
    #[cfg(feature = "media")]
    if let Ok(files) = ignis_media::source_files(p) {
        if files.len() != 1 || files[0] != p {
            return ignis_media::source_fingerprint(p)
                .map(Some)
                .map_err(|e| EigenError::io(p, std::io::Error::other(e.to_string())));
        }
    }
    Ok(None)
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
        let Some((bytes, sha)) = source_fingerprint(path)? else {
            return Err(EigenError::clip(
                clip,
                format!(
                    "the source video {} is missing; give its new place with --relink {clip}=PATH, or render reconstructed frames with --from-database",
                    path.display()
                ),
            ));
        };
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

impl Manifest {
    /// Checks every field against the others (counts, rows, packs, sizes, file names,
    /// numbers finite and in range). [`EigenfireDb::open`] calls it, then checks the files
    /// against it; `Err` names the first problem found.
    // Long on purpose: one flat list of independent checks in manifest order, each with
    // its own message; split up, the order a reader checks them in would be lost.
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
            if let Some([x, y, w, h]) = c.crop {
                let s = c.source_size;
                if (w, h) != (s.width, s.height)
                    || x.checked_add(w).is_none()
                    || y.checked_add(h).is_none()
                {
                    return bad(format!(
                        "crop = [{x}, {y}, {w}, {h}] does not match source_size {s}"
                    ));
                }
            }
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
            if let Some(f) = &c.mask_file {
                check_rel_name(&f.file)?;
                if !f.file.starts_with("masks/") {
                    return bad(format!("mask_file `{}` is not in masks/", f.file));
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
            .chain(self.clips.iter().filter_map(|c| c.frames_file.as_ref()))
            .chain(self.clips.iter().filter_map(|c| c.mask_file.as_ref()));
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

    /// A database being written is a temporary an interrupt removes (see
    /// `ignis_core::tempfiles::remove_live`) until it is committed; dropped unfinished, it
    /// is gone and no longer registered.
    #[test]
    fn a_database_being_written_is_live_until_committed() {
        let d = tempfile::tempdir().unwrap();
        let w = DbWriter::create(&d.path().join("x.db")).unwrap();
        let tmp = w.dir().to_path_buf();
        assert!(tmp.is_dir() && ignis_core::tempfiles::is_live(&tmp));
        drop(w);
        assert!(!tmp.exists() && !ignis_core::tempfiles::is_live(&tmp));
        // committed by training: the temporary is neither live nor left
        let _db = small_db(d.path());
        let left: Vec<_> = std::fs::read_dir(d.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(left, ["db"]);
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
