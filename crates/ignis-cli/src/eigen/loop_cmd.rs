//! `ignis loop footage.mp4 --length 4s -o loop.png` (issue 15): the one-step loop of a stock
//! clip, and the pieces `ignis eigen loop --length` and `ignis bench loops` share.
//!
//! Steps: (1) a cache entry for the clip (an Eigenfire database trained on it at a modest
//! size, plus the 128-px metric frames of every frame), keyed by the file's SHA-256 and the
//! settings, verified on every use and rebuilt when corrupt; (2) the loop search in PCA
//! weight space ([`ignis_eigen::loops::search`]) — for a matted loop only inside stretches
//! whose matte shows fire, as a dark stretch is a perfectly even loop of nothing; (3) every
//! candidate closed every way (cut, crossfade, motion-compensated morph) on the metric
//! frames (matted as rendered), the best by seam and ghost chosen
//! ([`ignis_eigen::loops::evaluate`]); (4) the chosen loop rendered from the
//! source video at its own resolution and colours, decoding only the frames it needs, and
//! measured on the frames written.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use ignis_core::fireblend::Ramp;
use ignis_core::loopq::{self, LoopQuality};
use ignis_core::{GrayFrame, RgbaFrame, Size};
use ignis_eigen::loops::{self, Candidate, Closing, Evaluated, PairMorph, Planned, SearchParams};
use ignis_eigen::{ClipInput, ClipSpec, EigenfireDb, PreprocessParams, Progress as _, TrainParams};
use ignis_flow::camera::{CameraPath, Steadying, Track, TrackGray, Tracker};
use sha2::{Digest, Sha256};

use crate::global::Global;

/// Version of the cache layout and of what training stores; part of the key (2: still
/// lights left out of the masks; 3: colourless parts left out of them; 4: windows read
/// through ffmpeg from a frame after 0 no longer start with a doubled frame, and footage
/// over 1080p is trained at [`TRAIN_MAX_SIDE`]; 5: footage read as players show it —
/// square pixels, HDR and BT.2020 as SDR BT.709, deinterlaced, the stream's own matrix and
/// range on the pure path, the largest video stream that is not an attached picture; 6: the
/// camera's track of every frame, `camera.f32`, for `--stabilise`; 7: tracked against the
/// first of the window's first frames with detail, not a fade's black first frame; 8:
/// whether the footage has its own alpha, for `--alpha auto`).
const CACHE_VERSION: u32 = 8;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis loop campfire.mp4 --length 4s -o loop.png\n  ignis loop candle.mp4 --length 120 -o loop.mp4\n  ignis loop fire.mov --length 2s --range 100..400 --method morph -o frames/%04d.png\n  ignis loop fire.mp4 --length 3s --cache /tmp/ignis-cache -o loop.gif\n  ignis loop bonfire.mp4 --length 4s --seconds 12..20.5 -o loop.png    (only that stretch of the clip, as a player's clock shows it)\n  ignis loop plates/%04d.exr --sequence-fps 24 --length 4s -o loop.png    (an image sequence stores no rate: give the one it was shot or rendered at, or it is read at 30)\n  ignis loop campfire.mp4 --length 4s --every 2 --motion-vectors --engine unity -o loop.png    (half the cells; the engine's motion-vector blend fills in)\n  ignis loop fireball.mp4 --length 2s --alpha emissive -o loop.png    (to composite over light backgrounds: the fire adds its light)\n  ignis loop campfire.mp4 --length 4s -o loop.mov    (ProRes 4444 with the matte as alpha, for compositing tools; needs ffmpeg)\n  ignis loop handheld.mp4 --length 3s --stabilise on -o loop.png    (hold the camera still even where auto would not; auto steadies a clear shake)\n  ignis loop bonfire.mp4 --length 4s --crop 640,120,720,900 -o loop.png    (only that part of the frame: one fire of several, or a picture inside letterbox bars)\n\nThe first run on a clip trains an Eigenfire database on it (about 20 s for 500 frames of 960x540 on 2 cores, 2 to 3 min for a minute of 1080p; footage over 1080p is trained at 1920 px on its longest side) and keeps it in the cache ($XDG_CACHE_HOME/ignis or ~/.cache/ignis, or --cache); later runs reuse it. The output has the footage's own size (or --crop's), colours and frame rate (1/N of it with --every N; --fps is refused), with the pre-processing mask's matte as alpha (a keyed element with its own alpha keeps that; --alpha opaque: none; --alpha emissive: the matted flame's own light as alpha, no dark fringe over light backgrounds); a .png flipbook's JSON records the measured loop_quality."
)]
pub struct Args {
    /// The footage (any video or frame sequence `ignis info` reads).
    pub input: PathBuf,
    #[command(flatten)]
    pub sequence: crate::args::SequenceFps,
    /// Loop length: seconds (`4s`, at the clip's fps; for a variable-frame-rate clip, at
    /// the nominal rate `ignis info` prints, from stretches of frames at that rate) or
    /// frames (`120`); the loop found is within ±20% of it.
    #[arg(long)]
    pub length: String,
    /// Only look in source frames START..END (END excluded).
    #[arg(long, value_parser = crate::args::frame_span)]
    pub range: Option<Range<usize>>,
    /// Only look in this stretch of the clip, in seconds as a player's clock shows them:
    /// START..END (END excluded), START.. or ..END; for a variable-frame-rate clip, by the
    /// frames' own timestamps. Example: --seconds 12..20.5
    #[arg(long, value_parser = crate::args::seconds_range, conflicts_with = "range")]
    pub seconds: Option<(f64, Option<f64>)>,
    /// How to close the loop: auto (the best of the others by measured seam and ghost),
    /// cut, crossfade or morph (motion-compensated).
    #[arg(long, default_value = "auto", value_parser = ["auto", "cut", "crossfade", "morph"])]
    pub method: String,
    /// Candidates to print.
    #[arg(long, default_value_t = 5)]
    pub top: usize,
    /// Cache directory (default $XDG_CACHE_HOME/ignis or ~/.cache/ignis). Where it cannot be
    /// written (a read-only or full disk, no HOME), the clip's database is built for this
    /// run only, in the temporary directory.
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// Loop only this rectangle X,Y,WIDTH,HEIGHT of the frame (source pixels, top-left
    /// origin): one fire of several, a flame away from a lit wall or a timecode, a picture
    /// without its letterbox bars. Everything (the database, the search, the matte, the
    /// camera's steadying) works on that part alone, and it is the output's own size.
    /// Also as WIDTHxHEIGHT+X+Y, or ffmpeg cropdetect's crop=W:H:X:Y pasted as is.
    /// Example: --crop 240,60,480,420
    #[arg(long, value_parser = crate::args::crop)]
    pub crop: Option<ignis_media::Rect>,
    /// Training size of the cached database (modest: the search only needs the weights).
    #[arg(long, default_value = "32x48")]
    pub train_size: Size,
    /// Eigenfires kept in the cached database.
    #[arg(long, default_value_t = 40)]
    pub keep: usize,
    /// Output frame size WIDTHxHEIGHT (default: the footage's own, or --crop's; for a .png flipbook
    /// whose full-size cells do not fit the sheet limit, the largest size with the
    /// footage's aspect that fits). A size of another aspect gets the footage fitted inside
    /// it, centred, with transparent borders (never stretched). Example: --size 960x540
    #[arg(long, value_parser = crate::eigen::animate::parse_size)]
    pub size: Option<Size>,
    /// Alpha: `auto` (default: the footage's own alpha when it has one, a keyed element
    /// from a PNG, EXR or ProRes 4444; else `matte`), `matte` (the pre-processing mask of
    /// each frame, feathered: the flame keyed out of its surroundings; times the footage's
    /// own alpha, so it never shows what that hides), `emissive` (the matted flame's own
    /// light as alpha, the "unmultiply" of compositing tools: over black the same picture,
    /// over a light background no dark fringe; what a fire shot on black needs over
    /// anything else) or `opaque` (the footage as it is, its own alpha included).
    #[arg(long, default_value = "auto", value_parser = LOOP_ALPHA_CHOICES)]
    pub alpha: String,
    /// Write every Nth frame of the loop, at 1/N of the clip's frame rate (a flipbook of
    /// fewer cells for an engine to blend between); the loop is chosen among those whose
    /// length is a multiple of N, so its wrap is an ordinary step. With --motion-vectors
    /// and an even N, each vector is chosen by the frame half-way between two written
    /// ones (as `volume render` does). Example: --every 2
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub every: u32,
    /// Hold a hand-held camera still: `auto` (default) when the whole view shifts with the
    /// camera (tracked against one of the clip's first frames, translation only) by more than a
    /// pixel or a quarter of a percent of the frame; `on` whenever the camera can be
    /// tracked; `off` never. A steadied loop is zoomed just enough (at most ×1.25) that no
    /// frame shows past its edge.
    #[arg(long, alias = "stabilize", default_value = "auto", value_parser = ["auto", "on", "off"])]
    pub stabilise: String,
    #[command(flatten)]
    pub out: crate::output::OutputArgs,
}

/// The method asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    Auto,
    Cut,
    Crossfade,
    Morph,
}

impl Method {
    pub fn parse(s: &str) -> Result<Method> {
        Ok(match s {
            "auto" => Method::Auto,
            "cut" => Method::Cut,
            "crossfade" => Method::Crossfade,
            "morph" => Method::Morph,
            o => bail!("unknown method `{o}`; choose auto, cut, crossfade or morph"),
        })
    }
    fn admits(&self, c: &Closing) -> bool {
        match self {
            Method::Auto => true,
            Method::Cut => matches!(c, Closing::Cut),
            Method::Crossfade => matches!(c, Closing::Crossfade(_)),
            Method::Morph => matches!(c, Closing::Morph(_)),
        }
    }
}

// ---------------------------------------------------------------------------------------
// Cache
// ---------------------------------------------------------------------------------------

/// Settings that change a cache entry.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CacheSettings {
    pub version: u32,
    pub train_size: String,
    pub keep: usize,
    /// Source frames of the window.
    pub start: usize,
    pub end: usize,
    /// `--crop` as `[x, y, width, height]`; left out of the key when the whole frame is
    /// used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop: Option<[u32; 4]>,
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
struct EntryMeta {
    source_sha256: String,
    settings: CacheSettings,
    metric_width: u32,
    metric_height: u32,
    metric_frames: usize,
    metric_sha256: String,
    /// SHA-256 of `camera.f32`: per window frame the camera's track against the window's
    /// reference frame ([`ignis_flow::camera::choose_reference`]; `Track`: offset x, y,
    /// peak, explains; 4 × f32 LE).
    camera_sha256: String,
    /// SHA-256 of `aligned.f32`: the metric frames of the window each moved by the whole
    /// pixels of its camera track (`ignis_flow::camera::whole_pixels`), the frames a
    /// steadied loop is chosen on without resampling them. Empty, and no file, when no
    /// frame moved a whole pixel or the camera could not be tracked (they would be the
    /// metric frames, or never used).
    aligned_sha256: String,
    fps: f64,
    source_size: String,
    /// Whether some frame of the window has its own alpha below 1 (`--alpha auto` keeps it).
    #[serde(default)]
    translucent: bool,
    /// The source it was made of, as the path that built it (absolute where it can be
    /// made so), for `ignis cache`'s listing; entries made before it was recorded have none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    source: Option<String>,
}

/// A verified cache entry: the database, the metric frames of the window, its fps.
pub struct Cached {
    pub dir: PathBuf,
    pub db: EigenfireDb,
    pub metric: Vec<GrayFrame>,
    /// The camera's track over the window (`--stabilise`).
    pub camera: CameraPath,
    /// The metric frames moved by their tracks' whole pixels (`--stabilise`); `None` when
    /// they are the metric frames or the camera was not tracked.
    pub aligned: Option<Vec<GrayFrame>>,
    pub fps: f64,
    /// Whether this run built it.
    pub built: bool,
    /// The part of the frame it was made of (`--crop`; `None`: the whole frame).
    pub crop: Option<ignis_media::Rect>,
    /// Whether the footage has its own alpha (a keyed element) in the window.
    pub translucent: bool,
    /// When the cache could not hold the entry ([`cached_or_scratch`]): the scratch
    /// directory it was built in for this run (removed when this is dropped; last, so the
    /// database is closed first) and why the cache could not hold it.
    pub scratch: Option<(ignis_core::atomic::StagingDir, String)>,
}

/// The default cache directory.
pub fn default_cache_dir() -> Result<PathBuf> {
    if let Some(x) = std::env::var_os("XDG_CACHE_HOME").filter(|v| !v.is_empty()) {
        return Ok(PathBuf::from(x).join("ignis"));
    }
    if let Some(h) = std::env::var_os("HOME").filter(|v| !v.is_empty()) {
        return Ok(PathBuf::from(h).join(".cache").join("ignis"));
    }
    bail!("no cache directory: set XDG_CACHE_HOME or HOME, or give --cache DIR")
}

/// Creates the cache directory `dir` and its parents. When a file is in the way (`--cache`
/// given a file, or a file where a parent should be) the error names it and the fix; the
/// system's own "File exists" would not.
pub fn create_cache_dir(dir: &Path) -> Result<()> {
    let Err(e) = std::fs::create_dir_all(dir) else {
        return Ok(());
    };
    if let Some(q) = crate::args::file_in_the_way(dir) {
        bail!(
            "cannot make the cache directory {}: {} is not a directory; give --cache a \
             directory (or leave it out for $XDG_CACHE_HOME/ignis or ~/.cache/ignis)",
            dir.display(),
            q.display()
        );
    }
    Err(e).with_context(|| format!("creating the cache directory {}", dir.display()))
}

/// SHA-256 of a source, hex (`ignis_media::source_fingerprint`: a file's content, or an
/// image sequence's frames in order).
pub fn source_sha256(path: &Path) -> Result<String> {
    let (_, sha) = ignis_media::source_fingerprint(path)
        .with_context(|| format!("reading {}", path.display()))?;
    Ok(sha)
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn camera_bytes(tracks: &[Track]) -> Vec<u8> {
    tracks
        .iter()
        .flat_map(|t| [t.offset[0], t.offset[1], t.peak, t.explains])
        .flat_map(f32::to_le_bytes)
        .collect()
}

/// Little-endian `f32`s of `bytes` (a trailing partial value is dropped).
fn f32s_le(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

fn camera_from_bytes(bytes: &[u8]) -> Vec<Track> {
    f32s_le(bytes)
        .chunks_exact(4)
        .map(|v| Track {
            offset: [v[0], v[1]],
            peak: v[2],
            explains: v[3],
        })
        .collect()
}

fn metric_bytes(frames: &[GrayFrame]) -> Vec<u8> {
    frames
        .iter()
        .flat_map(|f| f.data().iter().flat_map(|v| v.to_le_bytes()))
        .collect()
}

/// The footage a loop is cut from: a file, and the part of its frame used (`--crop`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clip<'a> {
    pub path: &'a Path,
    pub crop: Option<ignis_media::Rect>,
}

impl<'a> Clip<'a> {
    /// The whole frame of `path`.
    pub fn whole(path: &'a Path) -> Clip<'a> {
        Clip { path, crop: None }
    }

    /// The file as probed, its size the crop's (checked against the frame).
    pub fn probe(&self) -> Result<ignis_media::SourceInfo> {
        let mut info = ignis_media::probe(self.path)
            .with_context(|| format!("reading {}", self.path.display()))?;
        if let Some(r) = &self.crop {
            info.size = crate::args::crop_inside(r, info.size, self.path)?;
        }
        Ok(info)
    }

    /// Reading source frames `frames` of it, scaled to `scale` after the crop.
    fn read(&self, frames: Range<usize>, scale: Option<Size>) -> ignis_media::ReadOptions {
        ignis_media::ReadOptions {
            range: Some(ignis_media::FrameRange::frames(
                frames.start as u64,
                Some(frames.end as u64),
            )),
            crop: self.crop,
            scale,
        }
    }
}

/// The window of source frames: `range` checked against the source's frame count.
pub fn resolve_window(path: &Path, range: Option<Range<usize>>) -> Result<(Range<usize>, f64)> {
    let info = ignis_media::probe(path).with_context(|| format!("reading {}", path.display()))?;
    let count = info.frame_count.map(|n| n as usize);
    let window = match (range, count) {
        (Some(r), _) if r.start >= r.end => bail!("--range {}..{} is empty", r.start, r.end),
        (Some(r), Some(n)) if r.end > n => bail!(
            "--range {}..{} ends past the clip's last frame ({n} frames: 0..{n}); use an END ≤ {n}{}",
            r.start,
            r.end,
            ignis_media::file_numbers_hint(path, r.start as u64, Some(r.end as u64))
                .map_or(String::new(), |h| format!("; {h}"))
        ),
        (Some(r), _) => r,
        (None, Some(n)) => 0..n,
        (None, None) => bail!(
            "{} does not say how many frames it has; give --range START..END",
            path.display()
        ),
    };
    Ok((window, info.fps))
}

/// The frames of `path` shown from `start` to `end` seconds (`None`: to its end), as a
/// player's clock counts them: at its rate, or by its frames' own timestamps when the rate
/// varies ([`ignis_media::FrameTiming::frame_at`]). An end up to a frame past the clip's
/// last is its end; further, or a stretch holding no frame, is refused in seconds.
pub fn seconds_window(path: &Path, start: f64, end: Option<f64>) -> Result<Range<usize>> {
    let info = ignis_media::probe(path).with_context(|| format!("reading {}", path.display()))?;
    let timing = ignis_media::frame_timing(path)
        .ok()
        .flatten()
        .filter(|t| t.is_variable());
    let frame = |s: f64| match &timing {
        Some(t) => t.frame_at(s),
        None => (s * info.fps).round() as u64,
    } as usize;
    let Some(n) = info.frame_count.map(|n| n as usize) else {
        bail!(
            "{} does not say how many frames it has; give --range START..END in frames",
            path.display()
        );
    };
    let length = match &timing {
        Some(t) => t.times()[t.len() - 1] - t.times()[0] + t.nominal_step(),
        None => n as f64 / info.fps,
    };
    let a = frame(start);
    let b = end.map_or(n, frame);
    let span = format!(
        "--seconds {start}..{}",
        end.map_or(String::new(), |e| e.to_string())
    );
    if a >= n {
        bail!("{span} starts past the clip's end ({length:.2} s, {n} frames); use a START below {length:.2}");
    }
    if b > n + 1 {
        bail!("{span} ends past the clip's end ({length:.2} s, {n} frames); use an END of at most {length:.2}");
    }
    if b.min(n) <= a {
        bail!("{span} holds no frame (frames {a}..{b}); give a longer stretch");
    }
    Ok(a..b.min(n))
}

/// [`cached`] in `cache_dir`; or, when that cannot hold the entry — no cache directory
/// (`Err`: no `HOME`), or one that cannot be written (no permission, a read-only or full
/// disk, a quota: a render-farm node, a locked-down container) — built for this run only
/// in a hidden scratch directory in the system's temporary directory (removed when the
/// result is dropped, on an interrupt, or by the next run there if this one is killed).
/// The cache only saves the next run's time, so it is never a reason to fail.
pub fn cached_or_scratch(
    clip: Clip,
    window: Range<usize>,
    train_size: Size,
    keep: usize,
    cache_dir: Result<PathBuf>,
    g: &Global,
) -> Result<Cached> {
    let why = match cache_dir {
        Ok(dir) => match cached(clip, window.clone(), train_size, keep, &dir, g) {
            Err(e) if cannot_be_written(&e, &dir) => format!("{e:#}"),
            r => return r,
        },
        Err(e) => format!("{e:#}"),
    };
    let scratch = ignis_core::atomic::StagingDir::create(&std::env::temp_dir().join("ignis-loop"))
        .with_context(|| {
            format!(
                "the cache cannot hold the clip's database ({why}), nor can a scratch directory"
            )
        })?;
    let mut c = cached(clip, window, train_size, keep, scratch.path(), g).with_context(|| {
        format!(
            "the cache cannot hold the clip's database ({why}), so it was built in {}",
            scratch.path().display()
        )
    })?;
    c.scratch = Some((scratch, why));
    Ok(c)
}

/// Whether `e` comes from the cache directory `dir` that cannot be written: a full disk or
/// a quota, or no permission or a read-only disk where a file cannot be made in `dir` (the
/// footage itself may be what could not be read).
fn cannot_be_written(e: &anyhow::Error, dir: &Path) -> bool {
    use std::io::ErrorKind as K;
    let kinds: Vec<K> = e
        .chain()
        .filter_map(|c| c.downcast_ref::<std::io::Error>())
        .map(std::io::Error::kind)
        .collect();
    let unwritable =
        || std::fs::create_dir_all(dir).is_err() || tempfile::tempfile_in(dir).is_err();
    kinds
        .iter()
        .any(|k| matches!(k, K::StorageFull | K::QuotaExceeded))
        || (kinds
            .iter()
            .any(|k| matches!(k, K::PermissionDenied | K::ReadOnlyFilesystem))
            && unwritable())
}

/// Opens (verifying) or builds the cache entry of `path` over `window`. An image
/// sequence's entry plays at the rate the sequence is read at now (`--sequence-fps`): its
/// files hold pictures, not times, so one entry serves every rate.
pub fn cached(
    clip: Clip,
    window: Range<usize>,
    train_size: Size,
    keep: usize,
    cache_dir: &Path,
    g: &Global,
) -> Result<Cached> {
    let path = clip.path;
    // a video is a file and keeps the rate it was cached with: only a directory or a
    // pattern is probed for it
    let sequence_fps = (!path.is_file())
        .then(|| ignis_media::probe(path).ok())
        .flatten()
        .filter(|i| i.decoder == ignis_media::Decoder::ImageSequence)
        .map(|i| i.fps);
    let at_todays_rate = |mut c: Cached| {
        c.fps = sequence_fps.unwrap_or(c.fps);
        c
    };
    let sp = g.spinner("hashing the footage");
    let sha = source_sha256(path)?;
    sp.finish_and_clear();
    let settings = CacheSettings {
        version: CACHE_VERSION,
        train_size: train_size.to_string(),
        keep,
        start: window.start,
        end: window.end,
        crop: clip.crop.map(|r| [r.x, r.y, r.width, r.height]),
    };
    let skey = hex(&Sha256::digest(serde_json::to_vec(&settings)?))[..12].to_string();
    let dir = cache_dir.join(format!("{}-{skey}", &sha[..24]));
    if dir.exists() {
        match open_entry(&dir, &sha, &settings) {
            Ok(c) => return Ok(at_todays_rate(c)),
            Err(e) => {
                eprintln!(
                    "cache entry {} is unusable ({e:#}); rebuilding it",
                    dir.display()
                );
                match std::fs::remove_dir_all(&dir) {
                    // gone meanwhile (`ignis cache` trimmed it): built anew below
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                    r => r.with_context(|| {
                        format!("removing the bad cache entry {}", dir.display())
                    })?,
                }
            }
        }
    }
    build_entry(clip, &sha, &settings, window, train_size, keep, &dir, g)?;
    let mut c = open_entry(&dir, &sha, &settings)
        .with_context(|| format!("re-opening the cache entry just built at {}", dir.display()))?;
    c.built = true;
    crate::cache_cmd::note_if_large(cache_dir, g);
    Ok(at_todays_rate(c))
}

/// The largest `entry.json` read (a real one is a few hundred bytes): a damaged or foreign
/// entry is never read whole.
const ENTRY_JSON_MAX: u64 = 1 << 20;

fn open_entry(dir: &Path, sha: &str, settings: &CacheSettings) -> Result<Cached> {
    let Some(json) = ignis_core::atomic::read_at_most(&dir.join("entry.json"), ENTRY_JSON_MAX)
        .context("reading entry.json")?
    else {
        bail!("entry.json is larger than {ENTRY_JSON_MAX} bytes");
    };
    let meta: EntryMeta = serde_json::from_slice(&json).context("entry.json is not valid")?;
    if meta.source_sha256 != sha || &meta.settings != settings {
        bail!("entry.json is for another file or other settings");
    }
    let size = Size::new(meta.metric_width, meta.metric_height)?;
    let per = size.pixels() * 4;
    // each file's length, from entry.json, checked before anything is read
    let read_frames = |name: &str, sha: &str| -> Result<Vec<GrayFrame>> {
        let p = dir.join(name);
        let len = std::fs::metadata(&p)
            .with_context(|| format!("reading {name}"))?
            .len();
        if per.checked_mul(meta.metric_frames).map(|n| n as u64) != Some(len) {
            bail!("{name} has the wrong length");
        }
        let bytes = std::fs::read(&p).with_context(|| format!("reading {name}"))?;
        if hex(&Sha256::digest(&bytes)) != sha {
            bail!("{name} does not match its checksum");
        }
        Ok(bytes
            .chunks_exact(per)
            .map(|c| GrayFrame::from_vec(size, f32s_le(c)).expect("length checked"))
            .collect())
    };
    let metric = read_frames("metric.f32", &meta.metric_sha256)?;
    let aligned = if meta.aligned_sha256.is_empty() {
        None
    } else {
        Some(read_frames("aligned.f32", &meta.aligned_sha256)?)
    };
    let camera_path = dir.join("camera.f32");
    let clen = std::fs::metadata(&camera_path)
        .context("reading camera.f32")?
        .len();
    if meta.metric_frames.checked_mul(16).map(|n| n as u64) != Some(clen) {
        bail!("camera.f32 has the wrong length");
    }
    let cbytes = std::fs::read(&camera_path).context("reading camera.f32")?;
    if hex(&Sha256::digest(&cbytes)) != meta.camera_sha256 {
        bail!("camera.f32 does not match its checksum");
    }
    let camera = CameraPath {
        tracks: camera_from_bytes(&cbytes),
        source: meta
            .source_size
            .parse()
            .context("entry.json's source_size")?,
    };
    let db = EigenfireDb::open(&dir.join("fire.db")).context("opening the cached database")?;
    let problems = db.verify();
    if let Some((f, why)) = problems.first() {
        bail!("the cached database's {f} is damaged: {why}");
    }
    if db.source_mask(0)?.is_none() {
        bail!("the cached database has no pre-processing masks (made by an older Ignis)");
    }
    let clip = db.clip("clip")?;
    if clip.stride != 1 || clip.frames != meta.metric_frames {
        bail!(
            "the cached database has {} frames (stride {}), the metric frames {}",
            clip.frames,
            clip.stride,
            meta.metric_frames
        );
    }
    // used now: `ignis cache` trims the least recently used first
    crate::cache_cmd::touch(&dir.join("entry.json"));
    Ok(Cached {
        dir: dir.to_path_buf(),
        db,
        metric,
        camera,
        aligned,
        fps: meta.fps,
        built: false,
        crop: settings.crop.map(crate::eigen::rect),
        translucent: meta.translucent,
        scratch: None,
    })
}

fn build_entry(
    clip: Clip,
    sha: &str,
    settings: &CacheSettings,
    window: Range<usize>,
    train_size: Size,
    keep: usize,
    dir: &Path,
    g: &Global,
) -> Result<()> {
    let path = clip.path;
    create_cache_dir(dir.parent().unwrap_or(Path::new(".")))?;
    // Built in a hidden staging directory beside the entry (removed if anything fails) and
    // swapped in whole, so a reader never sees half an entry.
    let mut staging = ignis_core::atomic::StagingDir::create(dir)
        .with_context(|| format!("creating a directory beside {}", dir.display()))?;
    let tmp = staging.path().to_path_buf();
    let result = (|| -> Result<()> {
        // Metric frames of every frame of the window, as a writer would measure them.
        let info = clip.probe()?;
        let Measured {
            metric,
            aligned,
            tracks,
            translucent,
        } = metric_frames(clip, &window, true, g)?;
        if metric.len() != window.len() || tracks.len() != window.len() {
            bail!(
                "read {} frames of {}..{}",
                metric.len(),
                window.start,
                window.end
            );
        }
        let bytes = metric_bytes(&metric);
        std::fs::write(tmp.join("metric.f32"), &bytes)?;
        let cbytes = camera_bytes(&tracks);
        std::fs::write(tmp.join("camera.f32"), &cbytes)?;
        let tracked = CameraPath {
            tracks,
            source: info.size,
        }
        .tracked_share()
            >= ignis_flow::camera::TRACKED_MIN;
        let aligned_sha256 = if tracked && aligned.iter().any(Option::is_some) {
            let frames: Vec<GrayFrame> = aligned
                .into_iter()
                .zip(&metric)
                .map(|(a, m)| a.unwrap_or_else(|| m.clone()))
                .collect();
            let abytes = metric_bytes(&frames);
            std::fs::write(tmp.join("aligned.f32"), &abytes)?;
            hex(&Sha256::digest(&abytes))
        } else {
            String::new()
        };
        // The database.
        let mut spec = ClipSpec::new("clip");
        spec.path = Some(path.to_path_buf());
        spec.start = window.start;
        spec.end = Some(window.end);
        spec.stride = 1;
        let mut footage = ignis_eigen::MediaFootage::open(path)?;
        if let Some(r) = clip.crop {
            footage = footage.cropped(r)?;
        }
        let work = training_size(info.size);
        if work != info.size {
            g.say(format!(
                "training at {work} (the footage is {}; its masks are scaled to the output)",
                info.size
            ));
            footage = footage.scaled(work);
        }
        let clips = vec![ClipInput::new(spec, footage)];
        let pre = PreprocessParams {
            train_size: Some(train_size),
            ..Default::default()
        };
        let tp = TrainParams {
            keep: Some(ignis_eigen::ESelect::Count(keep.max(2))),
            ..Default::default()
        };
        let mut bars = crate::global::StageBars::new(g);
        ignis_eigen::train(&clips, &pre, &tp, &tmp.join("fire.db"), &mut bars)
            .context("training the clip's database")?;
        bars.finish_stage();
        let ms = metric[0].size();
        let meta = EntryMeta {
            source_sha256: sha.to_string(),
            settings: settings.clone(),
            metric_width: ms.width,
            metric_height: ms.height,
            metric_frames: metric.len(),
            metric_sha256: hex(&Sha256::digest(&bytes)),
            camera_sha256: hex(&Sha256::digest(&cbytes)),
            aligned_sha256,
            fps: info.fps,
            source_size: info.size.to_string(),
            translucent,
            source: Some(
                std::path::absolute(path)
                    .unwrap_or_else(|_| path.to_path_buf())
                    .display()
                    .to_string(),
            ),
        };
        ignis_core::atomic::write_bytes(
            &tmp.join("entry.json"),
            &serde_json::to_vec_pretty(&meta)?,
        )?;
        Ok(())
    })();
    if let Err(e) = result {
        return Err(e.context(format!("building the cache entry for {}", path.display())));
    }
    staging.into_place();
    ignis_core::tempfiles::replace_dir(&tmp, dir)
        .with_context(|| format!("moving the cache entry to {}", dir.display()))
}

/// Longest side of the frames a loop's database is trained on. Pre-processing (masks,
/// their distance transforms, contours) costs in proportion to the pixels, and a 4K clip
/// took 2.4 s a frame to train (a 6-s clip over 6 minutes); the masks it stores only become
/// the loop's matte, feathered and resized to the output. Footage up to 1080p trains at its
/// own size.
pub const TRAIN_MAX_SIDE: u32 = 1920;

/// The size a clip of `size` is trained at: itself, or scaled to [`TRAIN_MAX_SIDE`] on its
/// longest side, keeping its aspect (each side at least 2 px).
pub fn training_size(size: Size) -> Size {
    let long = size.width.max(size.height);
    if long <= TRAIN_MAX_SIDE {
        return size;
    }
    let k = f64::from(TRAIN_MAX_SIDE) / f64::from(long);
    let side = |v: u32| ((f64::from(v) * k).round() as u32).max(2);
    Size::new(side(size.width), side(size.height)).unwrap_or(size)
}

// ---------------------------------------------------------------------------------------
// Search, choice, render
// ---------------------------------------------------------------------------------------

/// The motion-compensated morph of `ignis_flow` (DIS flow both ways at a reduced working
/// size, occlusion-aware warp-and-blend).
pub struct FlowMorph {
    pub params: ignis_flow::FlowParams,
}

impl FlowMorph {
    /// Flow at most `max_side` pixels on the longest side.
    pub fn new(max_side: u32) -> FlowMorph {
        FlowMorph {
            params: ignis_flow::FlowParams {
                max_side,
                ..Default::default()
            },
        }
    }
}

impl PairMorph for FlowMorph {
    fn motion(&self) -> bool {
        true
    }
    fn prepare<'a>(
        &'a self,
        a: &'a GrayFrame,
        b: &'a GrayFrame,
    ) -> Box<dyn Fn(f32) -> GrayFrame + Send + Sync + 'a> {
        // Metric frames of one window: same size, finite; the flow cannot fail on them.
        // Should it anyway, the pair is blended (and measured as such).
        match ignis_flow::flow_pair_reduced(a, b, &self.params) {
            Ok((f, g)) => Box::new(move |w| {
                ignis_flow::morph_gray(a, b, &f, &g, w).unwrap_or_else(|_| loops::blend(a, b, w))
            }),
            Err(_) => Box::new(move |w| loops::blend(a, b, w)),
        }
    }
}

/// Longest side of the flow's working size for full-resolution frames.
pub const RENDER_FLOW_SIDE: u32 = 384;

/// Candidates also closed with the (costlier) morph.
pub const MORPH_CANDIDATES: usize = 4;

/// The morph used for closings.
pub fn morpher() -> Box<dyn PairMorph> {
    Box::new(FlowMorph::new(256))
}

/// A searched and chosen loop over a window of a source.
pub struct Chosen {
    pub evaluated: Vec<Evaluated>,
    pub best: Evaluated,
    pub why: String,
    pub search_s: f64,
    pub evaluate_s: f64,
    /// The shortest candidate (the written loop is never shorter, see
    /// [`loops::evaluate_with`]).
    pub min_len: usize,
    /// Closings rendered at the output's size and measured before choosing.
    pub rendered: usize,
    /// Seconds spent rendering and measuring them.
    pub verify_s: f64,
    /// Loops whose written length is not a multiple of this are left out
    /// ([`Chosen::keep_multiples_of`]; 1: none).
    pub every: usize,
}

impl Chosen {
    /// Keeps only the loops whose written length ([`planned_frames`]) is a multiple of
    /// `every` (for `--every`: written every `every`-th frame, their wrap is then an
    /// ordinary step) and at least two such steps long, and chooses again among them;
    /// `first`: the window's first source frame. Errors when none is left.
    pub fn keep_multiples_of(&mut self, every: usize, first: usize) -> Result<()> {
        self.every = every.max(1);
        if self.every == 1 {
            return Ok(());
        }
        let every = self.every;
        self.evaluated.retain(|e| writable_every(e, every));
        let (best, why) = loops::choose(&self.evaluated, first).ok_or_else(|| {
            anyhow::anyhow!(
                "no loop of about this length has a multiple of {every} frames with at least two of them written (--every {every}); ask for a longer --length or a smaller --every"
            )
        })?;
        self.best = best;
        self.why = format!("{why}; among loops of a multiple of {every} frames (--every {every})");
        Ok(())
    }

    /// The best loop as predicted on the footage's metric frames (the first evaluated),
    /// before closings were rendered and measured ([`verify_closings`]).
    pub fn predicted_best(&self) -> Evaluated {
        self.evaluated.first().copied().unwrap_or(self.best)
    }

    /// `e`'s loop as the search predicted it on the footage's metric frames (`e` itself
    /// when it is not among the evaluated).
    pub fn predicted_of(&self, e: &Evaluated) -> Evaluated {
        self.evaluated
            .iter()
            .find(|p| same_loop(p, e))
            .copied()
            .unwrap_or(*e)
    }
}

/// Whether `e`'s loop can be written every `every`-th frame: a multiple of `every` frames
/// (so the wrap is an ordinary step), at least two of them written.
fn writable_every(e: &Evaluated, every: usize) -> bool {
    let n = planned_frames(e);
    n.is_multiple_of(every) && n / every >= 2
}

/// Whether two evaluated loops are the same loop closed the same way (their measures and
/// left-out frames aside).
fn same_loop(a: &Evaluated, b: &Evaluated) -> bool {
    a.candidate == b.candidate && a.closing == b.closing
}

/// Searches the n×k weights (one row per window frame; window frame 0 = source frame
/// `first`) for loops of about `length`
/// frames, evaluates every closing on `metric` and chooses with `method`.
///
/// With `lit` (one flag per window frame: does its matte show any fire), a loop is looked
/// for only inside stretches of lit frames, so every footage frame it shows is lit (a
/// closing may blend in frames after the stretch, always mixed with the lit head): a
/// matted loop never shows a frame whose fire is keyed out entirely — a dark
/// stretch of the footage is a calm, perfectly even "loop" of nothing, which the search
/// would otherwise rank first. Errors, naming the stretches, when no lit stretch holds a
/// loop of that length.
///
/// With `uneven` steps (a variable frame rate: [`WindowTiming::uneven`]), a loop is looked
/// for only inside stretches without one (and lit, with `lit`), and kept only when none
/// is among the frames its closing reads; an [`Uneven`] error when no such loop exists.
#[allow(clippy::too_many_arguments)]
pub fn search_and_choose(
    first: usize,
    weights: &[f32],
    k: usize,
    e: usize,
    metric: &[GrayFrame],
    lit: Option<&[bool]>,
    uneven: &[usize],
    length: usize,
    method: Method,
) -> Result<Chosen> {
    let n = metric.len();
    if weights.len() != n * k {
        bail!("{} weight rows for {n} frames", weights.len() / k.max(1));
    }
    if length > n {
        bail!(
            "--length of {length} frames is longer than the clip or window ({n} frames); ask for at most {} frames",
            n.saturating_sub(3) * 10 / 12
        );
    }
    if let Some(lit) = lit.filter(|l| l.len() != n) {
        bail!("{} lit flags for {n} frames", lit.len());
    }
    let win = loops::MetricWindow::new(metric)?;
    let t = Instant::now();
    let params = SearchParams::new(length, e);
    // a variable frame rate: the stretches (lit, for a matte) at the nominal rate
    let timed = (!uneven.is_empty()).then(|| {
        let runs = lit.map_or_else(|| std::iter::once(0..n).collect(), lit_runs);
        even_runs(runs, uneven)
    });
    let cands = match (lit, &timed) {
        (None, None) => loops::search(weights, n, k, &params, Some(win.body_stats()))?,
        (Some(lit), None) => search_lit(weights, k, &win, metric, lit, &params, first)?,
        (_, Some(runs)) => {
            let found = search_runs(weights, k, &win, metric, runs, &params)?;
            if found.is_empty() {
                return Err(Uneven::new(runs, n, first, &params).into());
            }
            found
        }
    };
    let search_s = t.elapsed().as_secs_f64();
    let min_len = cands.iter().map(Candidate::len).min().unwrap_or(0);
    let t = Instant::now();
    let m = morpher();
    let evaluated: Vec<Evaluated> = loops::evaluate(&win, &cands, m.as_ref(), MORPH_CANDIDATES)
        .into_iter()
        .filter(|e| method.admits(&e.closing))
        .filter(|e| evenly_timed(e, uneven))
        .collect();
    if let Some(runs) = timed.as_ref().filter(|_| evaluated.is_empty()) {
        return Err(Uneven::new(runs, n, first, &params).into());
    }
    let evaluate_s = t.elapsed().as_secs_f64();
    let (best, why) = loops::choose(&evaluated, first).ok_or_else(|| {
        anyhow::anyhow!(
            "no loop closing fits in the window; use a longer window or a shorter --length"
        )
    })?;
    Ok(Chosen {
        evaluated,
        best,
        why,
        search_s,
        evaluate_s,
        min_len,
        rendered: 0,
        verify_s: 0.0,
        every: 1,
    })
}

/// Maximal runs of consecutive `true` flags (window indices).
fn lit_runs(lit: &[bool]) -> Vec<Range<usize>> {
    let mut runs = Vec::new();
    let mut i = 0;
    while i < lit.len() {
        if lit[i] {
            let s = i;
            while i < lit.len() && lit[i] {
                i += 1;
            }
            runs.push(s..i);
        } else {
            i += 1;
        }
    }
    runs
}

/// The whole window's [`loops::search`] candidates that lie inside a run of lit frames
/// (their filter taps included), then each long enough run's own search (its own body
/// statistics: where dark candidates crowd the window's ranked list, this still finds the
/// lit loops), in window indices; the window's search alone when every frame is lit.
/// Errors when no run is long enough.
fn search_lit(
    weights: &[f32],
    k: usize,
    win: &loops::MetricWindow,
    metric: &[GrayFrame],
    lit: &[bool],
    p: &SearchParams,
    first: usize,
) -> Result<Vec<Candidate>> {
    let n = metric.len();
    if lit.iter().all(|&l| l) {
        return Ok(loops::search(weights, n, k, p, Some(win.body_stats()))?);
    }
    let runs = lit_runs(lit);
    let out = search_runs(weights, k, win, metric, &runs, p)?;
    if out.is_empty() {
        let ask = Keyed::Length {
            length: p.length,
            need: loops::min_window(p),
        };
        bail!("{}", keyed_out_message(&runs, n, &|i| first + i, ask));
    }
    Ok(out)
}

/// The whole window's [`loops::search`] candidates that lie inside one of `runs` (their
/// filter taps included), then each long enough run's own search (its own body
/// statistics: where candidates outside the runs crowd the window's ranked list, this
/// still finds those inside), in window indices; empty when no run is long enough.
fn search_runs(
    weights: &[f32],
    k: usize,
    win: &loops::MetricWindow,
    metric: &[GrayFrame],
    runs: &[Range<usize>],
    p: &SearchParams,
) -> Result<Vec<Candidate>> {
    let n = metric.len();
    let need = loops::min_window(p);
    let inside = |c: &Candidate| {
        runs.iter()
            .any(|r| r.start + 2 <= c.start && c.end + 1 < r.end)
    };
    let mut out: Vec<Candidate> = loops::search(weights, n, k, p, Some(win.body_stats()))?
        .into_iter()
        .filter(inside)
        .collect();
    for r in runs.iter().filter(|r| r.len() >= need) {
        let sub = loops::MetricWindow::new(&metric[r.clone()])?;
        let x = &weights[r.start * k..r.end * k];
        let found = loops::search(x, r.len(), k, p, Some(sub.body_stats()))?;
        for c in found {
            let c = Candidate {
                start: c.start + r.start,
                end: c.end + r.start,
                ..c
            };
            if !out.iter().any(|o| (o.start, o.end) == (c.start, c.end)) {
                out.push(c);
            }
        }
    }
    Ok(out)
}

/// `runs` split at the `uneven` steps (step `i` joins window frames `i` and `i + 1`,
/// which end up in different runs).
fn even_runs(runs: Vec<Range<usize>>, uneven: &[usize]) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    for r in runs {
        let mut start = r.start;
        for &i in uneven.iter().filter(|&&i| i >= r.start && i + 1 < r.end) {
            out.push(start..i + 1);
            start = i + 1;
        }
        out.push(start..r.end);
    }
    out
}

/// The longest of `runs` (the first of the longest).
fn longest_run(runs: &[Range<usize>]) -> Option<Range<usize>> {
    runs.iter()
        .max_by_key(|r| (r.len(), std::cmp::Reverse(r.start)))
        .cloned()
}

/// Whether `e` reads only evenly timed footage: no `uneven` step among the frames its
/// search filter, its body and its closing read (two before its start to one past its
/// end, and the closing's tail).
fn evenly_timed(e: &Evaluated, uneven: &[usize]) -> bool {
    let c = &e.candidate;
    let last = loops::plan_end(c, e.closing).max(c.end + 2);
    let steps = c.start.saturating_sub(2)..last - 1;
    !uneven.iter().any(|i| steps.contains(i))
}

/// No stretch of evenly timed frames (of a variable-frame-rate clip) holds the loop asked
/// for: the caller looks in the whole window instead ([`make_loop_sized`]).
#[derive(Debug)]
pub struct Uneven {
    /// Source frames of the longest evenly timed stretch (with fire, for a matted loop).
    pub longest: Range<usize>,
    pub length: usize,
}

impl Uneven {
    fn new(runs: &[Range<usize>], n: usize, first: usize, p: &SearchParams) -> Uneven {
        let r = longest_run(runs).unwrap_or(0..n.min(1));
        Uneven {
            longest: first + r.start..first + r.end,
            length: p.length,
        }
    }
}

impl std::fmt::Display for Uneven {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "no evenly timed stretch holds a loop of about {} frames (the longest is source frames {}..{}, {} frames)",
            self.length,
            self.longest.start,
            self.longest.end,
            self.longest.len()
        )
    }
}

impl std::error::Error for Uneven {}

/// What a matted loop that would show frames of nothing was asked for.
#[derive(Clone, Copy)]
enum Keyed {
    /// A loop of about `length` frames searched for (`--length`), which needs `need`
    /// consecutive frames with fire.
    Length { length: usize, need: usize },
    /// The loop of exactly the window (`eigen loop --range` without `--length`).
    Range,
}

/// Why no matted loop fits: where the fire is (`runs`, the stretches with fire among the
/// window's `n` frames; `src` turns a window index into a source frame number), and what
/// to ask instead.
fn keyed_out_message(
    runs: &[Range<usize>],
    n: usize,
    src: &dyn Fn(usize) -> usize,
    ask: Keyed,
) -> String {
    let dark = n - runs.iter().map(|r| r.len()).sum::<usize>();
    let what = match ask {
        Keyed::Length { length, need } => format!(
            "a loop of about {length} frames (it needs {need} consecutive frames with fire)"
        ),
        Keyed::Range => "the loop of exactly this range".to_string(),
    };
    // Source frames first..end of window indices r.
    let span = |r: &Range<usize>| (src(r.start), src(r.end - 1) + 1);
    let (w0, w1) = span(&(0..n.max(1)));
    let head = format!(
        "the matte keys out all the fire in {dark} of the window's {n} frames (source frames {w0}..{w1}), \
         so {what} would show frames of nothing"
    );
    match runs.iter().max_by_key(|r| (r.len(), std::cmp::Reverse(r.start))) {
        Some(r) => {
            let (a, b) = span(r);
            let fix = match (ask, longest_length(r.len())) {
                (Keyed::Range, Some(l)) => format!(
                    "loop it with --range {a}..{b}, or search it with --range {a}..{b} --length {l} or less"
                ),
                (Keyed::Length { .. }, Some(l)) => {
                    format!("ask for --length {l} or less there (--range {a}..{b})")
                }
                (_, None) => {
                    "too short for any loop; choose a --range where the fire burns longer".to_string()
                }
            };
            format!(
                "{head}; the longest stretch with fire is source frames {a}..{b} ({} frames): {fix}, \
                 or give --alpha opaque to loop the footage as it is",
                r.len()
            )
        }
        None => format!(
            "{head}; no frame of it shows fire: choose a --range where the fire burns, or give --alpha opaque to loop the footage as it is"
        ),
    }
}

/// Refuses the matted loop of exactly the database rows `rows` (`eigen loop --range`)
/// when the matte keys out all the fire of any of their frames — the loop would blink to
/// nothing there every cycle —, naming the stretches with fire (source frame of row `r`:
/// `src(r - rows.start)`) as `ignis loop` does. Databases that store no masks (made anew
/// at render) are not checked.
pub fn refuse_keyed_out_range(
    db: &EigenfireDb,
    rows: Range<usize>,
    src: &dyn Fn(usize) -> usize,
) -> Result<()> {
    if rows.is_empty() || db.source_mask(rows.start)?.is_none() {
        return Ok(());
    }
    let lit = FootageMatte::new(db, rows.start, rows.len()).lit()?;
    if lit.iter().all(|&l| l) {
        return Ok(());
    }
    bail!(
        "{}",
        keyed_out_message(&lit_runs(&lit), lit.len(), src, Keyed::Range)
    )
}

/// The best closing of each of the first `top` distinct candidates, in rank order.
pub fn top_candidates(ev: &[Evaluated], top: usize) -> Vec<Evaluated> {
    let mut seen: Vec<Candidate> = Vec::new();
    let mut out = Vec::new();
    for e in ev {
        if out.len() >= top {
            break;
        }
        if !seen.contains(&e.candidate) {
            seen.push(e.candidate);
            out.push(*e);
        }
    }
    out
}

/// Frames [`render`] writes for `best`.
pub fn planned_frames(best: &Evaluated) -> usize {
    loops::plan_with(&best.candidate, best.closing, &best.skips).len()
}

/// Renders `best` from the source `path` (window index 0 = source frame `first`) at the
/// source's resolution or, given `scale`, with every source frame resized to it as it is
/// decoded (before the closing's blend or morph), passing each output frame to `sink` in
/// order. Decodes only source frames `start..end + m`; keeps the m head frames in memory.
/// With `matte`, every source frame's alpha is its pre-processing matte before it is
/// blended or morphed; with `steady`, the frame (matte and all) is then held still.
/// Crossfades and morphs blend on the fire's colour ramp ([`closing_frame`]).
pub fn render(
    clip: Clip,
    first: usize,
    best: &Evaluated,
    scale: Option<Size>,
    matte: Option<&FootageMatte>,
    steady: Option<&Steadying>,
    sink: &mut dyn FnMut(&RgbaFrame) -> Result<()>,
) -> Result<()> {
    render_with(clip, first, best, scale, (matte, steady), true, sink)
}

/// [`render`] of a crossfade peer's loop (Unity's, Houdini's, an ffmpeg script's): opaque,
/// its crossfade the plain blend `(1 − w)·a + w·b` the peers make.
pub fn render_peer(
    clip: Clip,
    first: usize,
    peer: &Evaluated,
    scale: Option<Size>,
    sink: &mut dyn FnMut(&RgbaFrame) -> Result<()>,
) -> Result<()> {
    render_with(clip, first, peer, scale, (None, None), false, sink)
}

/// [`render`], its crossfades on the fire's colour ramp or plain (`on_ramp`; peers never
/// morph).
fn render_with(
    clip: Clip,
    first: usize,
    best: &Evaluated,
    scale: Option<Size>,
    (matte, steady): (Option<&FootageMatte>, Option<&Steadying>),
    on_ramp: bool,
    sink: &mut dyn FnMut(&RgbaFrame) -> Result<()>,
) -> Result<()> {
    let c = best.candidate;
    let m = best.closing.frames();
    let plan = loops::plan_with(&c, best.closing, &best.skips);
    let end = loops::plan_end(&c, best.closing);
    let path = clip.path;
    let opts = clip.read(first + c.start..first + end, scale);
    let reader =
        ignis_media::open(path, &opts).with_context(|| format!("reading {}", path.display()))?;
    // Decoding (and resizing) runs on its own thread, a few frames ahead of the blends and
    // the writer; dropping the receiver (an error here) stops it.
    std::thread::scope(|scope| {
        let (tx, rx) = std::sync::mpsc::sync_channel::<ignis_media::Result<RgbaFrame>>(3);
        scope.spawn(move || {
            for f in reader {
                let failed = f.is_err();
                if tx.send(f).is_err() || failed {
                    break;
                }
            }
        });
        // Window frame the reader gives next (left-out frames are read past).
        let mut at = c.start;
        let mut masks = MaskCache::default();
        let mut next = |want: usize| -> Result<RgbaFrame> {
            loop {
                let f = rx.recv().ok().transpose()?.with_context(|| {
                    format!("{} ended before frame {}", path.display(), first + want)
                })?;
                at += 1;
                if at > want {
                    let mut f = f;
                    if let Some(m) = matte {
                        m.apply(want, &mut f, &mut masks)?;
                    }
                    steady_frame(steady, want, &mut f);
                    return Ok(f);
                }
            }
        };
        let mut head: Vec<RgbaFrame> = Vec::with_capacity(m);
        for i in c.start..c.start + m {
            head.push(next(i)?);
        }
        for p in &plan {
            match *p {
                Planned::Src(i) => sink(&next(i)?)?,
                Planned::Mix { from, to, w } => {
                    let a = next(from)?;
                    let b = &head[to - c.start];
                    let f = match best.closing {
                        Closing::Morph(_) => closing_frame(&a, b, Some(&render_flow(&a, b)?), w),
                        _ if on_ramp => closing_frame(&a, b, None, w),
                        _ => blend_rgba(&a, b, w),
                    };
                    sink(&f)?;
                }
            }
        }
        Ok(())
    })
}

/// Loops whose closings (crossfades and morphs) are rendered and measured at most before
/// one is chosen; cuts show only footage frames, so their prediction is their measure and
/// costs nothing.
pub const VERIFY_LOOPS: usize = 4;

/// Morphs of one loop (of different lengths) rendered and measured at most, the best
/// predicted first.
pub const MORPHS_PER_LOOP: usize = 2;

/// Re-ranks the best-predicted loops on their closings as they will be written. The search
/// predicts every closing on the footage's 128-px metric frames (in-betweens and their flow
/// made at that size); the render makes them at the output's size, in linear light, and a
/// morph's flow there can tear where the small one did not (a 540×960 clip's 12-frame
/// morph: predicted seam 1.11, written 1.38). Going down `chosen.evaluated` (best predicted
/// first), each loop's closings that could still win are rendered exactly as [`render`]
/// makes them (its head and tail decoded once for all of them), reduced to metric frames
/// and measured with the footage's own frames around them ([`loops::evaluate_rendered`]),
/// until the next prediction cannot beat the best measured score (predictions are taken as
/// optimistic) or [`VERIFY_LOOPS`] loops have been rendered. `chosen.best` becomes the best
/// measured ([`Chosen::predicted_best`] still gives the best predicted). `metric` is the window's metric
/// frames the search ranked (matted when `matte` is).
pub fn verify_closings(
    chosen: &mut Chosen,
    clip: Clip,
    first: usize,
    metric: &[GrayFrame],
    scale: Option<Size>,
    matte: Option<&FootageMatte>,
    steady: Option<&Steadying>,
    g: &Global,
) -> Result<()> {
    let t = Instant::now();
    let win = loops::MetricWindow::new(metric)?;
    let size = metric[0].size();
    let pb = g.progress(VERIFY_LOOPS as u64, "checking closings");
    let p = chosen.predicted_best();
    let mut best: Option<Evaluated> = None;
    // What the best predicted measured as rendered.
    let mut top: Option<Evaluated> = None;
    let mut done: Vec<Candidate> = Vec::new();
    let mut rendered = 0;
    for e in &chosen.evaluated {
        let bound = best.map_or(f64::INFINITY, |b| b.score);
        if e.score >= bound {
            break;
        }
        let measured: Vec<Evaluated> = if e.closing.frames() == 0 {
            vec![*e]
        } else if done.contains(&e.candidate) || done.len() == VERIFY_LOOPS {
            continue;
        } else {
            done.push(e.candidate);
            // Its crossfades that could still win (a blend per frame), and its best
            // MORPHS_PER_LOOP morphs (a warp of the full frame per frame each).
            let mut morphs = 0;
            let group: Vec<Evaluated> = chosen
                .evaluated
                .iter()
                .filter(|x| x.candidate == e.candidate && x.closing.frames() > 0 && x.score < bound)
                .filter(|x| {
                    let morph = matches!(x.closing, Closing::Morph(_));
                    morphs += usize::from(morph);
                    !morph || morphs <= MORPHS_PER_LOOP
                })
                .copied()
                .collect();
            let closings: Vec<Closing> = group.iter().map(|x| x.closing).collect();
            let mids = rendered_mids(
                clip,
                first,
                &e.candidate,
                &closings,
                scale,
                (matte, steady),
                size,
            )?;
            pb.inc(1);
            rendered += group.len();
            group
                .iter()
                .zip(&mids)
                .map(|(x, m)| {
                    loops::evaluate_rendered(&win, &x.candidate, x.closing, m, chosen.min_len)
                })
                .collect::<std::result::Result<_, _>>()?
        };
        // a rendered closing keeps its length, but a loop of another length cannot be
        // written every `every`-th frame
        for v in measured
            .into_iter()
            .filter(|v| writable_every(v, chosen.every))
        {
            if same_loop(&v, &p) {
                top = Some(v);
            }
            if best.is_none_or(|b| v.score < b.score) {
                best = Some(v);
            }
        }
    }
    pb.finish_and_clear();
    let Some(best) = best else {
        return Ok(());
    };
    let at = |e: &Evaluated| {
        format!(
            "{} at {}..{}",
            e.closing,
            first + e.candidate.start,
            first + e.candidate.end
        )
    };
    if same_loop(&best, &p) {
        if p.closing.frames() > 0 {
            chosen.why.push_str(&format!(
                "; rendered at the output's size, its closing measures seam {:.2}, ghost {:.2}",
                best.quality.seam, best.quality.ghost
            ));
        }
    } else if let Some(top) = top {
        chosen.why = format!(
            "{} scores {:.3} (seam {:.2}, ghost {:.2}) with its closing rendered at the output's size; \
             the best predicted, {} ({:.3} predicted), scores {:.3} rendered (seam {:.2}, ghost {:.2})",
            at(&best),
            best.score,
            best.quality.seam,
            best.quality.ghost,
            at(&p),
            p.score,
            top.score,
            top.quality.seam,
            top.quality.ghost,
        );
    }
    chosen.best = best;
    chosen.rendered = rendered;
    chosen.verify_s = t.elapsed().as_secs_f64();
    Ok(())
}

/// Per closing of `c` (each a crossfade or morph), the metric frames (`size`, over black,
/// as the window's) of its transition frames rendered as [`render`] renders them: decoded
/// at `scale`, matted, blended or morphed (one flow per frame pair, shared by the morphs).
/// The head and the tail are read side by side, two frames held at a time.
fn rendered_mids(
    clip: Clip,
    first: usize,
    c: &Candidate,
    closings: &[Closing],
    scale: Option<Size>,
    (matte, steady): (Option<&FootageMatte>, Option<&Steadying>),
    size: Size,
) -> Result<Vec<Vec<GrayFrame>>> {
    let n = closings.iter().map(Closing::frames).max().unwrap_or(0);
    let mut out: Vec<Vec<GrayFrame>> = closings
        .iter()
        .map(|k| Vec::with_capacity(k.frames()))
        .collect();
    if n == 0 {
        return Ok(out);
    }
    let path = clip.path;
    let reader = |start: usize| -> Result<_> {
        let opts = clip.read(first + start..first + start + n, scale);
        ignis_media::open(path, &opts).with_context(|| format!("reading {}", path.display()))
    };
    let (mut tails, mut heads) = (reader(c.end)?, reader(c.start)?);
    let (mut tail_masks, mut head_masks) = (MaskCache::default(), MaskCache::default());
    for t in 0..n {
        // As `plan_with`'s mixes: window frame c.end + t into c.start + t.
        let (from, to) = (c.end + t, c.start + t);
        let ended = |i: usize| format!("{} ended before frame {}", path.display(), first + i);
        let mut a = tails.next().transpose()?.with_context(|| ended(from))?;
        let mut b = heads.next().transpose()?.with_context(|| ended(to))?;
        if let Some(m) = matte {
            m.apply(from, &mut a, &mut tail_masks)?;
            m.apply(to, &mut b, &mut head_masks)?;
        }
        steady_frame(steady, from, &mut a);
        steady_frame(steady, to, &mut b);
        let morphs = closings
            .iter()
            .any(|k| matches!(k, Closing::Morph(m) if *m > t));
        let flow = if morphs {
            Some(render_flow(&a, &b)?)
        } else {
            None
        };
        let ramp = Ramp::of(&[&a, &b]);
        for (k, mids) in closings.iter().zip(out.iter_mut()) {
            let m = k.frames();
            if t >= m {
                continue;
            }
            let w = (t + 1) as f32 / (m + 1) as f32;
            let f = match k {
                Closing::Morph(_) => closing_frame_on(ramp.as_ref(), &a, &b, flow.as_ref(), w),
                _ => closing_frame_on(ramp.as_ref(), &a, &b, None, w),
            };
            let q = loopq::metric_frame_rgba(&f, [0.0; 3]);
            mids.push(if q.size() == size {
                q
            } else {
                loopq::area_resize(&q, size)
            });
        }
    }
    Ok(out)
}

/// `(1 - w)·a + w·b` on premultiplied values (linear light, straight alpha in and out),
/// as the morph blends: where one frame's matte keys a pixel out, its colour there (the
/// footage's dark surroundings) does not darken the other's flame — the crossfade composites
/// over any background as the crossfade of the two composites. Opaque frames blend
/// per channel, bit for bit.
pub fn blend_rgba(a: &RgbaFrame, b: &RgbaFrame, w: f32) -> RgbaFrame {
    let data = a
        .data()
        .iter()
        .zip(b.data())
        .map(|(p, q)| {
            let alpha = p[3] + (q[3] - p[3]) * w;
            if alpha <= 1e-8 {
                // Keyed out in both: their colours as they are (what a straight-alpha
                // sheet's filtering bleeds in), alpha 0.
                let mut o: [f32; 4] = std::array::from_fn(|c| p[c] + (q[c] - p[c]) * w);
                o[3] = 0.0;
                return o;
            }
            let mut o: [f32; 4] = std::array::from_fn(|c| {
                let (x, y) = (p[c] * p[3], q[c] * q[3]);
                (x + (y - x) * w) / alpha
            });
            o[3] = alpha;
            o
        })
        .collect();
    RgbaFrame::from_vec(a.size(), data).expect("same size")
}

/// A closing's frame `w` of the way from `a` to `b`: a crossfade, or with `flow` (a→b and
/// b→a, from [`render_flow`]) the motion-compensated in-between (both frames warped toward
/// it along the flow, as `ignis_flow::morph_rgba` with plain weights), blended on the fire's
/// colour ramp (`ignis_core::fireblend`: a bright tongue fading into the dark cools to red
/// instead of dimming to olive; luminance and alpha are the plain blend's). A crossfade's
/// keyed-out pixels, and frames with no light, blend as [`blend_rgba`]; a morph leaves its
/// keyed-out pixels black, as `ignis_flow::morph_rgba` does.
fn closing_frame(
    a: &RgbaFrame,
    b: &RgbaFrame,
    flow: Option<&(ignis_flow::FlowField, ignis_flow::FlowField)>,
    w: f32,
) -> RgbaFrame {
    closing_frame_on(Ramp::of(&[a, b]).as_ref(), a, b, flow, w)
}

/// [`closing_frame`] with the pair's ramp measured once (`Ramp::of` the two frames as they
/// are: the warps move their light, they do not recolour it).
fn closing_frame_on(
    ramp: Option<&Ramp>,
    a: &RgbaFrame,
    b: &RgbaFrame,
    flow: Option<&(ignis_flow::FlowField, ignis_flow::FlowField)>,
    w: f32,
) -> RgbaFrame {
    use rayon::prelude::*;
    let Some((f, g)) = flow else {
        return ignis_core::fireblend::blend_with(ramp, a, b, w)
            .unwrap_or_else(|| blend_rgba(a, b, w));
    };
    let width = a.size().width as usize;
    if width == 0 || b.size() != a.size() {
        // a closing's frames share one size; an empty frame is its own in-between
        return a.clone();
    }
    // Both warps row by row, premultiplied, blended as they are made: no warped frames.
    let (wa, wb) = (
        ignis_flow::WarpRows::new(a, f, -w),
        ignis_flow::WarpRows::new(b, g, -(1.0 - w)),
    );
    let mut out = vec![[0.0f32; 4]; a.data().len()];
    out.par_chunks_mut(width).enumerate().for_each_init(
        || {
            let row = vec![[0.0f32; 4]; width];
            (wa.scratch(), wb.scratch(), row.clone(), row)
        },
        |(sa, sb, ra, rb), (y, line)| {
            wa.rows_with(sa, y, ra);
            wb.rows_with(sb, y, rb);
            for ((o, &p), &q) in line.iter_mut().zip(ra.iter()).zip(rb.iter()) {
                *o = ignis_core::fireblend::blend_pm_to_straight(ramp, p, q, w);
            }
        },
    );
    RgbaFrame::from_vec(a.size(), out).expect("sized from a")
}

/// The forward and backward flow between two full-size frames as the render's morph
/// computes it: on their luma, at most [`RENDER_FLOW_SIDE`] pixels on the longest side
/// (`ignis_flow::flow_pair_reduced_rgba`: the luma taken inside the resize, no full-size
/// grey frames). Where a frame is keyed out (its matte's alpha 0: nothing for the flow to
/// match) its field is filled from where it is seen (`ignis_flow::flow_pair_matted_rgba`),
/// so the morph does not drag the flame's fringe over the empty background along the patch
/// grid's vectors; opaque frames keep their fields as computed.
fn render_flow(
    a: &RgbaFrame,
    b: &RgbaFrame,
) -> Result<(ignis_flow::FlowField, ignis_flow::FlowField)> {
    let p = FlowMorph::new(RENDER_FLOW_SIDE).params;
    Ok(ignis_flow::flow_pair_matted_rgba(a, b, &p)?)
}

/// Text lines for the candidate table.
pub fn describe(e: &Evaluated, first: usize) -> String {
    format!(
        "frames {}..{} ({} frames), {}: predicted seam {:.2}, ghost {:.2} (search cost {:.3})",
        first + e.candidate.start,
        first + e.candidate.end,
        e.candidate.len(),
        e.closing,
        e.quality.seam,
        e.quality.ghost,
        e.candidate.cost
    )
}

/// What a finished loop reports.
pub struct Done {
    pub chosen: Chosen,
    pub measured: LoopQuality,
    /// Frames written (every `chosen.every`-th of the loop's).
    pub frames: usize,
    pub size: Size,
    pub render_s: f64,
}

/// The footage a loop is searched in and rendered from: the source video, the window's
/// first frame, the window's weight rows (row-major, `k` per frame, the first `e` compared),
/// its metric frames and frame rate.
#[derive(Clone, Copy)]
pub struct LoopFootage<'a> {
    pub clip: Clip<'a>,
    pub first: usize,
    pub weights: &'a [f32],
    pub k: usize,
    pub e: usize,
    pub metric: &'a [GrayFrame],
    pub fps: f64,
    /// Where the frames' alpha comes from; `None` writes the footage opaque.
    pub matte: Option<FootageMatte<'a>>,
    /// The matted frames' light as alpha (`--alpha emissive`, [`emissive`]).
    pub emissive: bool,
    /// How each window frame is held still (`--stabilise`); `None` leaves the footage as
    /// it is.
    pub steady: Option<Held<'a>>,
    /// A variable frame rate in the window: the loop comes from evenly timed frames and
    /// is written at their rate; `None` for a constant rate (or no frame times).
    pub timing: Option<&'a WindowTiming>,
}

/// A window whose frame rate varies ([`ignis_media::FrameTiming`]): a phone's clip that
/// slows down in low light or drops frames.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowTiming {
    /// The rate most of the window plays at.
    pub nominal_fps: f64,
    /// Frames over the time they span.
    pub average_fps: f64,
    /// The steps not at the nominal rate (window indices: step `i` joins window frames `i`
    /// and `i + 1`), ascending.
    pub uneven: Vec<usize>,
    /// The shortest and longest step, seconds.
    pub steps: (f64, f64),
    /// Frames in the window (at least two).
    pub frames: usize,
    /// The times are an image sequence's frame numbers, frames missing from it
    /// ([`ignis_media::FrameTiming::from_frame_numbers`]): its uneven steps are gaps.
    pub numbered: bool,
}

impl WindowTiming {
    /// `path`'s frame timing over `window` (clamped to the clip) when its rate varies
    /// there, or an image sequence's when frames are missing there; `None` for a constant
    /// rate, a sequence without gaps or a source without frame times (GIFs) or whose times
    /// cannot be read (the frames then play at the average rate).
    pub fn of(path: &Path, window: Range<usize>) -> Option<WindowTiming> {
        let t = ignis_media::frame_timing(path)
            .ok()
            .flatten()?
            .window(window)?;
        t.is_variable().then(|| WindowTiming {
            nominal_fps: t.nominal_fps(),
            average_fps: t.average_fps(),
            uneven: t.uneven_steps().to_vec(),
            steps: t.step_range(),
            frames: t.len(),
            numbered: t.from_frame_numbers(),
        })
    }

    /// The rate the window's frames play at when taken one after another as if evenly
    /// spaced: a video's average over the time they span (its container's rate), a
    /// sequence's own rate.
    pub fn played_fps(&self) -> f64 {
        if self.numbered {
            self.nominal_fps
        } else {
            self.average_fps
        }
    }

    /// The longest stretch of window frames joined by nominal steps alone (the first of
    /// the longest).
    pub fn longest_even(&self) -> Range<usize> {
        longest_run(&even_runs(
            std::iter::once(0..self.frames).collect(),
            &self.uneven,
        ))
        .unwrap_or(0..self.frames)
    }

    /// A warning (without its `warning: `) for a command that takes every frame once, as if
    /// evenly spaced (`eigen train`, `learned train`): what varies, `effect`, and the longest evenly timed
    /// stretch of source frames (the window starting at source frame `first`) as `fix`
    /// writes the argument that asks for it.
    pub fn warning(
        &self,
        first: usize,
        effect: &str,
        fix: impl Fn(Range<usize>) -> String,
    ) -> String {
        let r = self.longest_even();
        format!(
            "{}; {effect}; {} (the longest evenly timed stretch, {} frames) avoids it",
            self.describe(),
            fix(first + r.start..first + r.end),
            r.len()
        )
    }

    /// What the timing is, said in a clause.
    fn describe(&self) -> String {
        if self.numbered {
            return format!(
                "frames are missing from the sequence ({})",
                self.steps_off()
            );
        }
        format!(
            "the frame rate varies ({:.3} fps nominal, {:.3} on average; {})",
            self.nominal_fps,
            self.average_fps,
            self.steps_off()
        )
    }

    /// How many steps are off the nominal rate, and how far apart the frames are (a
    /// sequence: how many steps jump over missing frames, and the most in a row).
    pub fn steps_off(&self) -> String {
        if self.numbered {
            let most = ((self.steps.1 * self.nominal_fps).round() as u64).saturating_sub(1);
            return format!(
                "{} of {} steps jump over missing frames, at most {most} in a row",
                self.uneven.len(),
                self.frames - 1,
            );
        }
        format!(
            "{} of {} steps off it, frames {:.1}–{:.1} ms apart",
            self.uneven.len(),
            self.frames - 1,
            self.steps.0 * 1e3,
            self.steps.1 * 1e3
        )
    }
}

/// A window held still: the steadying of each frame, and what the cache keeps for it (the
/// camera's tracks, the metric frames moved by their whole pixels).
#[derive(Clone, Copy)]
pub struct Held<'a> {
    pub steady: &'a Steadying,
    pub aligned: &'a [GrayFrame],
    pub camera: &'a CameraPath,
}

impl<'a> LoopFootage<'a> {
    /// A cached clip's window (its database holds exactly the window's frames), with its
    /// pre-processing matte as alpha.
    /// The cache entry's `--crop`, if any, is the part of the frame looped.
    pub fn cached(path: &'a Path, first: usize, c: &'a Cached) -> LoopFootage<'a> {
        LoopFootage {
            clip: Clip { path, crop: c.crop },
            first,
            weights: c.db.weights_row_major(),
            k: c.db.n_components(),
            e: c.db.manifest().e_detect.max(1),
            metric: &c.metric,
            fps: c.fps,
            matte: Some(FootageMatte::new(&c.db, 0, c.metric.len())),
            emissive: false,
            steady: None,
            timing: None,
        }
    }

    /// The same footage with its variable frame rate (`None`: a constant one).
    pub fn timed(self, timing: Option<&'a WindowTiming>) -> LoopFootage<'a> {
        LoopFootage { timing, ..self }
    }

    /// The same footage held still by `steady` (one shift per window frame of `c`).
    pub fn steadied(self, steady: &'a Steadying, c: &'a Cached) -> LoopFootage<'a> {
        LoopFootage {
            steady: Some(Held {
                steady,
                aligned: c.aligned.as_deref().unwrap_or(&c.metric),
                camera: &c.camera,
            }),
            ..self
        }
    }

    /// The same footage written opaque (`--alpha opaque`).
    pub fn opaque(self) -> LoopFootage<'a> {
        LoopFootage {
            matte: None,
            emissive: false,
            ..self
        }
    }

    /// The same footage, matted, with the matted light as alpha (`--alpha emissive`).
    pub fn emissive(self) -> LoopFootage<'a> {
        LoopFootage {
            emissive: self.matte.is_some(),
            ..self
        }
    }
}

/// Window frame `i` held still by `steady` (its shift scaled to the frame's size, the
/// run's zoom); nothing without.
fn steady_frame(steady: Option<&Steadying>, i: usize, f: &mut RgbaFrame) {
    if let Some(s) = steady {
        let shift = s.shifts.get(i).copied().unwrap_or_default();
        let at = ignis_flow::camera::shift_at(shift, s.source, f.size());
        *f = ignis_flow::camera::steady_rgba(f, at, s.zoom);
    }
}

/// The window's metric frames held still as [`steady_frame`] holds the footage, from
/// `aligned` (the metric frames moved by their tracks' whole pixels, so what is left to
/// move is under a pixel and the run's common centre and zoom: every frame is resampled
/// alike, none softer than its neighbours).
fn steady_metric(held: &Held, aligned: &[GrayFrame]) -> Vec<GrayFrame> {
    use rayon::prelude::*;
    let s = held.steady;
    aligned
        .par_iter()
        .enumerate()
        .map(|(i, m)| {
            let shift = s.shifts.get(i).copied().unwrap_or_default();
            let whole = held
                .camera
                .tracks
                .get(i)
                .map_or([0, 0], ignis_flow::camera::whole_pixels);
            let rest = [shift[0] - whole[0] as f32, shift[1] - whole[1] as f32];
            let at = ignis_flow::camera::shift_at(rest, s.source, m.size());
            ignis_flow::camera::steady_gray(m, at, s.zoom)
        })
        .collect()
}

/// `--alpha`: the pre-processing matte (default) or opaque footage.
pub const ALPHA_CHOICES: [&str; 2] = ["matte", "opaque"];

/// `ignis loop --alpha`: also `emissive`, and `auto` (the footage's own alpha if it has
/// one, else the matte).
pub const LOOP_ALPHA_CHOICES: [&str; 4] = ["auto", "matte", "emissive", "opaque"];

/// A matted frame with its light as alpha (`--alpha emissive`), the "unmultiply" of
/// compositing tools for fire shot on black: per pixel the premultiplied light `P = c·a`
/// (linear) is kept, alpha becomes its brightest channel and the colour `P / alpha`. Over
/// black it is the same picture; over anything else it adds the fire's light and covers
/// the background only as much as the fire is bright, so the matte's dark, half-keyed
/// edges (the footage's black background mixed in) no longer show as a dark fringe. A
/// pixel without light is transparent black.
pub fn emissive(frame: &RgbaFrame) -> RgbaFrame {
    let data = frame
        .data()
        .iter()
        .map(|p| {
            let a = p[3].clamp(0.0, 1.0);
            let light = [p[0] * a, p[1] * a, p[2] * a];
            let alpha = light[0].max(light[1]).max(light[2]).clamp(0.0, 1.0);
            if alpha > 0.0 {
                [light[0] / alpha, light[1] / alpha, light[2] / alpha, alpha]
            } else {
                [0.0; 4]
            }
        })
        .collect();
    RgbaFrame::from_vec(frame.size(), data).expect("same size")
}

/// The alpha of a loop's frames: each window frame's pre-processing mask (stored by
/// training at the source size, in the source's own framing), steadied over time by a
/// majority vote with its two neighbours in the footage (`ignis_eigen::mask::majority3`
/// over `ignis_eigen::animate::matte_vote_rows`, the vote the footage render of `eigen
/// loop --range` and `eigen animate` makes: a mask that collapses or flares on a single
/// frame does not flash in the loop), feathered as the footage render feathers database
/// frames (`ignis_eigen::preprocess::feather_half_in`) and resized to the output. The
/// colour stays the footage's own (straight alpha), so formats without alpha (MP4, GIF)
/// show the flame over black and a flipbook keys it out.
#[derive(Clone, Copy)]
pub struct FootageMatte<'a> {
    db: &'a EigenfireDb,
    /// Database row of window frame 0.
    first_row: usize,
    /// Window frames.
    frames: usize,
}

impl<'a> FootageMatte<'a> {
    pub fn new(db: &'a EigenfireDb, first_row: usize, frames: usize) -> FootageMatte<'a> {
        FootageMatte {
            db,
            first_row,
            frames,
        }
    }

    /// The stored mask of database row `row`.
    fn mask(&self, row: usize) -> Result<image::GrayImage> {
        self.db
            .source_mask(row)
            .context("reading the pre-processing masks for the matte (--alpha opaque loops without them)")?
            .with_context(|| no_mask(row))
    }

    /// The rows whose masks vote on window frame `i` (see `matte_vote_rows`).
    fn votes(&self, i: usize) -> [usize; 3] {
        ignis_eigen::animate::matte_vote_rows(
            self.db,
            self.first_row + i.min(self.frames.max(1) - 1),
        )
    }

    /// The matte of window frame `i` at `size`; `cache` keeps the last few decoded masks,
    /// so frames rendered in order decode each mask once, not once per vote.
    pub fn at(&self, i: usize, size: Size, cache: &mut MaskCache) -> Result<GrayFrame> {
        let rows = self.votes(i);
        for j in rows {
            if !cache.0.iter().any(|(k, _)| *k == j) {
                let m = self.mask(j)?;
                if cache.0.len() == 4 {
                    cache.0.remove(0);
                }
                cache.0.push((j, m));
            }
        }
        let get = |j: usize| {
            &cache
                .0
                .iter()
                .find(|(k, _)| *k == j)
                .expect("just cached")
                .1
        };
        let m = voted_feather(get(rows[0]), get(rows[1]), get(rows[2]));
        Ok(if m.size() == size {
            m
        } else {
            ignis_eigen::pose::resize(&m, size)
        })
    }

    /// The voted masks (unfeathered, at the source size) of window frames `r`
    /// (`ignis_eigen::animate::voted_masks`, the footage render's vote: each stored mask
    /// decoded once).
    fn voted_run(&self, r: Range<usize>) -> Result<Vec<image::GrayImage>> {
        let rows: Vec<usize> = r.map(|i| self.first_row + i).collect();
        let mut voted = ignis_eigen::animate::voted_masks(self.db, &rows).context(
            "reading the pre-processing masks for the matte (--alpha opaque loops without them)",
        )?;
        rows.iter()
            .map(|row| voted.remove(row).with_context(|| no_mask(*row)))
            .collect()
    }

    /// `f` on the voted mask of each of the first `n` window frames, in order; runs of 16
    /// frames done in parallel.
    fn by_runs<T: Send>(
        &self,
        n: usize,
        f: impl Fn(usize, image::GrayImage) -> T + Sync,
    ) -> Result<Vec<T>> {
        use rayon::prelude::*;
        const RUN: usize = 16;
        if n > self.frames {
            bail!("{n} frames asked of a matte of {} frames", self.frames);
        }
        let runs: Vec<Range<usize>> = (0..n).step_by(RUN).map(|s| s..(s + RUN).min(n)).collect();
        let parts: Vec<Vec<T>> = runs
            .into_par_iter()
            .map(|r| {
                let s = r.start;
                let voted = self.voted_run(r)?;
                Ok(voted
                    .into_iter()
                    .enumerate()
                    .map(|(j, m)| f(s + j, m))
                    .collect())
            })
            .collect::<Result<_>>()?;
        Ok(parts.into_iter().flatten().collect())
    }

    /// The window's metric frames as the matted loop will show them: each multiplied by
    /// its frame's matte exactly as [`FootageMatte::at`] renders it (voted, feathered at
    /// the source size), area-averaged to the metric size — so the loop is chosen on what
    /// it writes, the feather's band of lit surroundings included. Runs of frames are
    /// done in parallel, each mask decoded once per run.
    /// With `camera`, each mask is first moved by its track's whole pixels (scaled to the
    /// mask's size: footage over 1080p is trained smaller), as the aligned metric frames
    /// were (`--stabilise`).
    pub fn matted_metric(
        &self,
        metric: &[GrayFrame],
        camera: Option<&CameraPath>,
    ) -> Result<Vec<GrayFrame>> {
        self.by_runs(metric.len(), |i, mask| {
            let mut full =
                ignis_eigen::preprocess::feather_half_in(&mask, mask.width().max(mask.height())).0;
            if let Some((t, cam)) = camera.and_then(|c| Some((c.tracks.get(i)?, c))) {
                let w = ignis_flow::camera::whole_pixels(t);
                let d = ignis_flow::camera::shift_at(
                    [w[0] as f32, w[1] as f32],
                    cam.source,
                    full.size(),
                )
                .map(|v| v.round() as i32);
                if d != [0, 0] {
                    let (w, h) = (full.width() as usize, full.height() as usize);
                    let moved = ignis_flow::camera::shift_whole(full.data(), w, h, 1, d);
                    full = GrayFrame::from_vec(full.size(), moved).expect("same size");
                }
            }
            let soft = ignis_core::loopq::area_resize(&full, metric[i].size());
            let mut out = metric[i].clone();
            for (o, &a) in out.data_mut().iter_mut().zip(soft.data()) {
                *o *= a;
            }
            out
        })
    }

    /// Per window frame: does its voted mask keep any pixel (is any fire left in the
    /// matte)? What the footage render's matte shows, without decoding the footage.
    pub fn lit(&self) -> Result<Vec<bool>> {
        self.by_runs(self.frames, |_, mask| {
            ignis_eigen::mask::mask_area(&mask) > 0
        })
    }

    /// Multiplies `f`'s alpha by the matte of window frame `i` (see [`FootageMatte::at`]):
    /// the matte itself for opaque footage; footage with its own alpha keeps hidden what
    /// that hides.
    pub fn apply(&self, i: usize, f: &mut RgbaFrame, cache: &mut MaskCache) -> Result<()> {
        let m = self.at(i, f.size(), cache)?;
        for (p, &a) in f.data_mut().iter_mut().zip(m.data()) {
            p[3] *= a;
        }
        Ok(())
    }
}

/// Why a matte cannot be made for database row `row`, and the fix.
fn no_mask(row: usize) -> String {
    format!(
        "the database stores no pre-processing mask for row {row} (trained by an older Ignis); \
         retrain it, or give --alpha opaque"
    )
}

/// The last few masks [`FootageMatte::at`] decoded, by database row.
#[derive(Default)]
pub struct MaskCache(Vec<(usize, image::GrayImage)>);

/// The matte of a frame from its own mask `b` and its neighbours' `a`, `c`: their
/// majority (`ignis_eigen::mask::majority3`), feathered as the footage render feathers
/// database frames.
fn voted_feather(a: &image::GrayImage, b: &image::GrayImage, c: &image::GrayImage) -> GrayFrame {
    let mask = ignis_eigen::mask::majority3(a, b, c);
    ignis_eigen::preprocess::feather_half_in(&mask, mask.width().max(mask.height())).0
}

/// What loop to make: about `length` frames, closed by `method`; the best `top`
/// candidates are listed.
#[derive(Clone, Copy)]
pub struct LoopAsk {
    pub length: usize,
    pub method: Method,
    pub top: usize,
    /// Write every `every`-th frame (1: all), at 1/`every` of the clip's rate; the loop's
    /// length is then a multiple of it.
    pub every: usize,
}

/// Searches, renders and writes a loop of window `first..` of `path` to `out`, at the
/// source's size ([`make_loop_sized`] with no `--size`).
pub fn make_loop(
    src: &LoopFootage,
    ask: &LoopAsk,
    out: &crate::output::OutputArgs,
    g: &Global,
) -> Result<Done> {
    make_loop_sized(src, ask, None, out, g)
}

/// [`make_loop`] rendering the frames at `size` (the user's `--size`) or, without it, at
/// the source's size, scaled down for a flipbook whose full-size cells do not fit the
/// sheet limit ([`crate::output::OutputArgs::fit_flipbook`]). The frames are resized as
/// they are decoded, before any blend or morph, and the size is settled (or refused)
/// before anything is rendered.
pub fn make_loop_sized(
    src: &LoopFootage,
    ask: &LoopAsk,
    size: Option<Size>,
    out: &crate::output::OutputArgs,
    g: &Global,
) -> Result<Done> {
    let LoopFootage {
        clip,
        first,
        weights,
        k,
        e,
        metric,
        fps,
        matte,
        emissive: light_alpha,
        steady,
        timing,
    } = *src;
    let LoopAsk {
        length,
        method,
        top,
        every,
    } = *ask;
    let every = every.max(1);
    let (matted, lit);
    let base = steady.map_or(metric, |h| h.aligned);
    let (metric, lit) = match &matte {
        Some(m) => {
            matted = m.matted_metric(base, steady.map(|h| h.camera))?;
            lit = matted
                .iter()
                .map(|f| f.data().iter().any(|&v| v > 0.0))
                .collect::<Vec<bool>>();
            (&matted[..], Some(&lit[..]))
        }
        None => (base, None),
    };
    // held still as the footage will be: the loop is chosen on what is written
    let held;
    let metric = match &steady {
        Some(h) => {
            held = steady_metric(h, metric);
            &held[..]
        }
        None => metric,
    };
    let steady = steady.map(|h| h.steady);
    let (mut chosen, fps) = match timing {
        None => (
            search_and_choose(first, weights, k, e, metric, lit, &[], length, method)?,
            fps,
        ),
        Some(t) => {
            let even =
                search_and_choose(first, weights, k, e, metric, lit, &t.uneven, length, method);
            match even {
                Ok(c) => {
                    g.say(format!(
                        "timing: {}; the loop comes from evenly timed frames and is written at {:.3} fps",
                        t.describe(),
                        t.nominal_fps
                    ));
                    (c, t.nominal_fps)
                }
                Err(err) => match err.downcast_ref::<Uneven>() {
                    Some(u) => {
                        g.say(format!(
                            "warning: {}, and {u}; looking in the whole window, written at the average {:.3} fps, \
                             so parts of the loop may play faster or slower than they were shot (a shorter --length \
                             fits an even stretch)",
                            t.describe(),
                            fps
                        ));
                        let any = search_and_choose(
                            first,
                            weights,
                            k,
                            e,
                            metric,
                            lit,
                            &[],
                            length,
                            method,
                        )?;
                        (any, fps)
                    }
                    None => return Err(err),
                },
            }
        }
    };
    chosen.keep_multiples_of(every, first)?;
    g.say("best candidates (predicted on the footage's 128-px frames):");
    for (i, c) in top_candidates(&chosen.evaluated, top).iter().enumerate() {
        g.say(format!("  {}. {}", i + 1, describe(c, first)));
    }
    let info = clip.probe()?;
    let mut opts = out.write_options();
    opts.fps = fps / every as f64;
    opts.loop_ = true;
    if let Some(s) = size {
        Size::new(s.width, s.height).context("--size")?;
    }
    // The closings are checked at the size the predicted best would be written at; a
    // different choice with another frame count is fitted again (a sheet's cells may
    // change by a few pixels, which the 128-px measure does not see).
    let fit = |n: usize, opts: &mut ignis_media::WriteOptions| {
        out.fit_flipbook(n, size.unwrap_or(info.size), size.is_some(), opts)
    };
    // A --size of another aspect than the footage: the frames are scaled to fit inside it
    // and centred, with transparent borders, never stretched. (A size fitted to the sheet
    // limit has the footage's aspect, to the 4-px blocks its cells are rounded to.)
    let inner = |fitted: Size| match size {
        Some(_) => info.size.fitted_inside(fitted),
        None => fitted,
    };
    let mut fitted = fit(planned_frames(&chosen.best) / every, &mut opts.clone())?;
    let scale = (inner(fitted.size) != info.size).then_some(inner(fitted.size));
    verify_closings(
        &mut chosen,
        clip,
        first,
        metric,
        scale,
        matte.as_ref(),
        steady,
        g,
    )?;
    let n = planned_frames(&chosen.best);
    fitted = fit(n / every, &mut opts)?;
    // --every with an even step: the frame half-way between two written ones is rendered
    // anyway, so the motion vectors are chosen by it (as generators do)
    let in_between =
        (every.is_multiple_of(2) && opts.flipbook.motion.is_some() && !opts.flipbook.fit_frames)
            .then(|| crate::inbetween::InBetween::new(true));
    if let Some(m) = &in_between {
        m.start_row();
        opts.flipbook.motion = Some(m.source());
    }
    if let Some(note) = fitted.note() {
        g.say(note);
    }
    let inside = inner(fitted.size);
    if inside != fitted.size {
        g.say(format!(
            "size: the {} footage fitted inside {} at {inside}, centred, with transparent \
             borders (never stretched; --crop a part of the frame with the cell's aspect to \
             fill it)",
            info.size, fitted.size
        ));
    }
    let scale = (inside != info.size).then_some(inside);
    // the chosen loop is written centred on the middle of its own frames' views and zoomed only
    // as far as they need (the search and the checks used the window's)
    let c = chosen.best.candidate;
    let run = steady.map(|s| s.for_run(c.start..loops::plan_end(&c, chosen.best.closing)));
    if let Some(r) = &run {
        g.say(format!(
            "camera: the loop's frames held still, zoomed ×{:.3} (the window needed ×{:.3})",
            r.zoom,
            steady.map_or(1.0, |s| s.zoom)
        ));
    }
    let t = Instant::now();
    let mut w = out.create_with(fitted.size, &opts)?;
    let pb = g.progress(n as u64, "rendering");
    let mut i = 0;
    render(
        clip,
        first,
        &chosen.best,
        scale,
        matte.as_ref(),
        run.as_ref(),
        &mut |f| {
            pb.inc(1);
            i += 1;
            let padded;
            let f = if f.size() == fitted.size {
                f
            } else {
                padded = f.centred_in(fitted.size);
                &padded
            };
            // the frame as written (with --alpha emissive, its light as alpha), made only for
            // the frames written or kept as in-between frames
            let written = |f: &RgbaFrame| if light_alpha { emissive(f) } else { f.clone() };
            match (i - 1) % every {
                0 if light_alpha => out.push(&mut w, &emissive(f)),
                0 => out.push(&mut w, f),
                j => {
                    if let Some(m) = in_between.as_ref().filter(|_| 2 * j == every) {
                        m.record(written(f));
                    }
                    Ok(())
                }
            }
        },
    )?;
    pb.finish_and_clear();
    let measured = w
        .loop_quality()
        .context("the loop has fewer than two frames")?;
    let frames = w.frames() as usize;
    out.finish(w, g)?;
    let render_s = t.elapsed().as_secs_f64();
    Ok(Done {
        chosen,
        measured,
        frames,
        size: fitted.size,
        render_s,
    })
}

/// Prints what a loop did. `files`: an image sequence's files in the order read, so the
/// loop's frames are also named by file (`shot.1066.exr`), as a compositor numbers them.
pub fn report(d: &Done, first: usize, files: Option<&[PathBuf]>, g: &Global) {
    let b = &d.chosen.best;
    let (a, z) = (first + b.candidate.start, first + b.candidate.end);
    let named = files
        .and_then(|f| {
            Some((
                f.get(a)?.file_name()?,
                f.get(z.checked_sub(1)?)?.file_name()?,
            ))
        })
        .map_or(String::new(), |(x, y)| {
            format!(
                " (files {} to {})",
                x.to_string_lossy(),
                y.to_string_lossy()
            )
        });
    let every = match d.chosen.every {
        1 => String::new(),
        k => format!(
            ", every {} of its {}",
            crate::args::nth(k as u32),
            planned_frames(b)
        ),
    };
    g.say(format!(
        "loop: source frames {a}..{z}{named}, {} ({} frames at {}{every})",
        b.closing, d.frames, d.size
    ));
    g.say(format!("why: {}", d.chosen.why));
    let p = d.chosen.predicted_of(b).quality;
    g.say(format!(
        "measured on the frames written{}: seam {:.2}, ghost {:.2} (predicted {:.2}, {:.2}; with the closing rendered {:.2}, {:.2}); search {:.3} s, closings {:.3} s, {} closing(s) checked as rendered {:.2} s, render {:.2} s",
        if d.chosen.every > 1 {
            " (their own steps; the predictions are per source frame)"
        } else {
            ""
        },
        d.measured.seam,
        d.measured.ghost,
        p.seam,
        p.ghost,
        b.quality.seam,
        b.quality.ghost,
        d.chosen.search_s,
        d.chosen.evaluate_s,
        d.chosen.rendered,
        d.chosen.verify_s,
        d.render_s
    ));
    if let Some(w) = seam_warning(d.measured.seam) {
        g.say(w);
    }
}

/// Seam (wrap step ÷ the footage's median step) from which a loop's jump is as large as a
/// plain cut between different flames (typically 3 or more): worth a warning.
const VISIBLE_SEAM: f64 = 3.0;

/// The warning for a loop whose measured seam is a visible jump, if it is one.
fn seam_warning(seam: f64) -> Option<String> {
    (seam >= VISIBLE_SEAM).then(|| {
        format!(
            "warning: the seam is {seam:.2}× the footage's median step, as large as a cut between \
             different flames and will show every cycle; try a longer clip or --range, another \
             --length, or --method auto"
        )
    })
}

/// `ignis loop`.
pub fn run(a: &Args, g: &Global) -> Result<()> {
    let method = Method::parse(&a.method)?;
    a.sequence.apply(&[&a.input])?;
    let range = match a.seconds {
        Some((start, end)) => {
            let r = seconds_window(&a.input, start, end)?;
            g.say(format!(
                "--seconds {start}..{}: frames {}..{}",
                end.map_or(String::new(), |e| e.to_string()),
                r.start,
                r.end
            ));
            Some(r)
        }
        None => a.range.clone(),
    };
    let (window, fps) = resolve_window(&a.input, range.clone())?;
    let clip = Clip {
        path: &a.input,
        crop: a.crop,
    };
    // a crop past the frame is refused before anything is read
    let info = clip.probe()?;
    if let Some(note) = a.sequence.default_rate_note(&info) {
        g.say(note);
    }
    // a variable rate: seconds are counted at the rate the loop will be written at
    let timing = WindowTiming::of(&a.input, window.clone());
    let fps = timing.as_ref().map_or(fps, |t| t.nominal_fps);
    // A sequence's missing frames are single jumps, not stretches played at another
    // speed: the search's own measure (the loop's largest step on the footage's frames)
    // judges each gap by the jump it makes, where keeping to the stretches without one
    // loses loops across gaps nobody sees (a slow flame's step over a lost frame can be
    // smaller than its median step).
    let timing = match timing {
        Some(t) if t.numbered => {
            g.say(format!(
                "timing: {}; the loop is chosen by its frames' steps, a gap counting as the \
                 jump it makes",
                t.describe()
            ));
            None
        }
        t => t,
    };
    let length = loops::parse_length(&a.length, fps)?;
    let need = loops::min_window(&SearchParams::new(length, 1));
    if length > window.len() || window.len() < need {
        bail!(
            "--length {} ({length} frames) does not fit in {} frames {}..{}: a loop of about {length} frames needs at least {need}; {}",
            a.length,
            if range.is_some() { "the window's" } else { "the clip's" },
            window.start,
            window.end,
            longest_hint(window.len(), fps, match (a.seconds, &a.range) {
                (Some(_), _) => "a longer --seconds",
                (None, Some(_)) => "a longer --range",
                _ => "a longer clip",
            })
        );
    }
    check_output_early(&a.out, fps)?;
    let cache_dir = match &a.cache {
        Some(d) => Ok(d.clone()),
        None => default_cache_dir(),
    };
    let c = cached_or_scratch(clip, window.clone(), a.train_size, a.keep, cache_dir, g)?;
    match &c.scratch {
        Some((_, why)) => g.say(format!(
            "note: the clip's database is kept for this run only, as the cache cannot hold it \
             ({why}); give --cache DIR on a writable disk to keep it for the next run"
        )),
        None if c.built => g.say(format!("cached the clip's database in {}", c.dir.display())),
        None => {}
    }
    let ask = LoopAsk {
        length,
        method,
        top: a.top,
        every: a.every as usize,
    };
    let mut src = LoopFootage::cached(&a.input, window.start, &c).timed(timing.as_ref());
    let steadying = steadying(&c.camera, &a.stabilise, g)?;
    if let Some(s) = &steadying {
        src = src.steadied(s, &c);
    }
    let alpha = match a.alpha.as_str() {
        "auto" if c.translucent => {
            g.say(
                "alpha: the footage has its own (a keyed element), kept as it is; --alpha matte keys \
                 the flame out of its colours instead (within that alpha)",
            );
            "opaque"
        }
        "auto" => "matte",
        other => other,
    };
    match alpha {
        "opaque" => src = src.opaque(),
        "emissive" => src = src.emissive(),
        _ => {}
    }
    let d = make_loop_sized(&src, &ask, a.size, &a.out, g)?;
    let files = (info.decoder == ignis_media::Decoder::ImageSequence)
        .then(|| ignis_media::source_files(&a.input).ok())
        .flatten();
    report(&d, window.start, files.as_deref(), g);
    // keyed by the matte, or by the footage's own alpha
    if (alpha != "opaque" || c.translucent)
        && matches!(
            a.out.output_format(),
            Some(ignis_media::Format::Mp4 | ignis_media::Format::Gif)
        )
    {
        g.say(
            "alpha: MP4 and GIF have none, so the keyed flame is composited over black; \
             -o loop.mov (ProRes 4444), loop.webm, loop.png (flipbook) or frames/%04d.png \
             keep it as alpha",
        );
    }
    if alpha != "opaque" {
        if let Some(clip) = c.db.manifest().clips.first() {
            let n = clip.pose.still_lights.boxes().len();
            if n > 0 {
                g.say(format!(
                    "matte: {n} still light(s) left out (bright and steady all clip long, away from \
                     the fire: a lamp, a lit window; `ignis eigen info {}` lists them); \
                     --alpha opaque writes the whole frame",
                    c.dir.join("fire.db").display()
                ));
            }
        }
    }
    Ok(())
}

/// `--stabilise`: how the window is held still, if at all, said in a line (`auto` says
/// nothing of a still camera); `on` refuses a camera it cannot steady.
fn steadying(camera: &CameraPath, mode: &str, g: &Global) -> Result<Option<Steadying>> {
    if mode == "off" || camera.tracks.is_empty() {
        return Ok(None);
    }
    match camera.decide(mode == "on") {
        Ok(s) => {
            let most = s
                .shifts
                .iter()
                .map(|v| v[0].hypot(v[1]))
                .fold(0.0f32, f32::max);
            g.say(format!(
                "camera: the view shifts up to {most:.1} px with the camera; held still (zoomed ×{:.3}; --stabilise off keeps it as shot)",
                s.zoom
            ));
            Ok(Some(s))
        }
        Err(why) if mode == "on" => bail!("--stabilise on: {why}; use --stabilise auto or off"),
        Err(why) => {
            if !why.starts_with("the camera is still") {
                g.say(format!("camera: left as shot ({why})"));
            }
            Ok(None)
        }
    }
}

/// `ignis eigen loop DB --clip C --length L [--range A..B]`: the search over a trained
/// database's clip, rendered from its source video.
pub fn eigen_length_loop(a: &crate::eigen::LoopArgs, g: &Global) -> Result<()> {
    let db = crate::eigen::open_db(&a.db)?;
    let method = match a.method.as_str() {
        "end-growing" | "direct" | "low-pass" => bail!(
            "--method {} closes an exact --range; with --length choose auto, cut, crossfade or morph",
            a.method
        ),
        m => Method::parse(m)?,
    };
    let c = db.clip(&a.clip)?.clone();
    if c.stride != 1 {
        bail!(
            "clip `{}` was trained with --stride {}; the loop search needs every frame (retrain with --stride 1) or use --range alone",
            a.clip,
            c.stride
        );
    }
    let length = loops::parse_length(a.length.as_deref().unwrap_or_default(), c.fps)?;
    let clip_frames = c.start..c.start + c.frames;
    let window = match &a.range {
        Some(r) if r.start < clip_frames.start || r.end > clip_frames.end || r.start >= r.end => {
            bail!(
                "--range {}..{} is not inside clip `{}`'s trained frames {}..{}",
                r.start,
                r.end,
                a.clip,
                clip_frames.start,
                clip_frames.end
            )
        }
        Some(r) => r.clone(),
        None => clip_frames,
    };
    let need = loops::min_window(&SearchParams::new(length, 1));
    if length > window.len() || window.len() < need {
        bail!(
            "--length {} ({length} frames) does not fit in the {} frames {}..{}: a loop of about {length} frames needs at least {need}; {}",
            a.length.as_deref().unwrap_or_default(),
            window.len(),
            window.start,
            window.end,
            longest_hint(window.len(), c.fps, "a wider window")
        );
    }
    if a.footage.from_database {
        bail!("--length renders the loop from the clip's source footage; --from-database applies to --range alone");
    }
    check_output_early(&a.out, c.fps)?;
    let mut sources = a.footage.sources(&db)?;
    if let Some(q) = beside_db(&c.source, &a.db) {
        sources.relink.entry(a.clip.clone()).or_insert(q);
    }
    let source = sources
        .checked_path(&c)
        .context("a --length loop is rendered from the clip's source footage (give its place with --relink; reconstructed frames with --from-database need --range instead of --length)")?;
    // the part of the frame the clip was trained on
    let footage = Clip {
        path: &source,
        crop: c.crop.map(crate::eigen::rect),
    };
    // Metric frames of the window, as the writer will measure them.
    let metric = metric_frames(footage, &window, false, g)
        .with_context(|| format!("reading {}", source.display()))?
        .metric;
    if metric.len() != window.len() {
        bail!(
            "{} has fewer frames than the database says",
            source.display()
        );
    }
    let k = db.n_components();
    let rows = ignis_eigen::animate::clip_rows(&db, &a.clip, window.clone())?;
    let weights = &db.weights_row_major()[rows.start * k..rows.end * k];
    let e = db.manifest().e_detect.max(1);
    let src = LoopFootage {
        clip: footage,
        first: window.start,
        weights,
        k,
        e,
        metric: &metric,
        fps: c.fps,
        matte: (a.alpha == "matte").then(|| FootageMatte::new(&db, rows.start, rows.len())),
        emissive: false,
        steady: None,
        timing: None,
    };
    let ask = LoopAsk {
        length,
        method,
        top: a.top,
        every: 1,
    };
    let d = make_loop_sized(&src, &ask, a.footage.size, &a.out, g)?;
    report(&d, window.start, None, g);
    Ok(())
}

/// The longest `--length` (frames) whose search fits in a window of `n` frames, if any.
fn longest_length(n: usize) -> Option<usize> {
    (2..=n)
        .rev()
        .find(|&l| loops::min_window(&SearchParams::new(l, 1)) <= n)
}

/// What to do when a `--length` does not fit a window of `n` frames at `fps`: the longest
/// that does (in frames, and seconds when the fps is known), or `wider` alone.
fn longest_hint(n: usize, fps: f64, wider: &str) -> String {
    match longest_length(n) {
        Some(l) if fps.is_finite() && fps > 0.0 => format!(
            "the longest that fits is --length {l} ({:.2} s at {} fps); ask for that or less, or use {wider}",
            l as f64 / fps,
            crate::args::fps_text(fps)
        ),
        Some(l) => format!("the longest that fits is --length {l}; ask for that or less, or use {wider}"),
        None if n == 1 => format!("1 frame is too few for any loop; use {wider}"),
        None => format!("{n} frames are too few for any loop; use {wider}"),
    }
}

/// Refuses a bad `-o` (unknown format, flags the format does not take, a directory that
/// cannot be made or written) before the cache is built or the footage decoded, with the
/// options the render will use.
fn check_output_early(out: &crate::output::OutputArgs, fps: f64) -> Result<()> {
    let mut opts = out.write_options();
    opts.fps = fps;
    opts.loop_ = true;
    out.check_with(&opts)
}

/// Where a clip's source recorded as a relative path that does not resolve here lies
/// relative to the database's directory, if it is there (a `--relink` of it).
fn beside_db(recorded: &str, db: &Path) -> Option<PathBuf> {
    let p = Path::new(recorded);
    if p.exists() || ignis_media::probe(p).is_ok() {
        return None;
    }
    let q = db.parent()?.join(p);
    (q.exists() || ignis_media::probe(&q).is_ok()).then_some(q)
}

/// Metric frames ([`loopq::metric_frame_rgba`], as a writer measures them) of the source
/// frames in `window`, with a progress bar, and with `track` the camera's track of each
/// against a reference among the window's first frames
/// ([`ignis_flow::camera::choose_reference`]) and the metric frame of each
/// moved by its track's whole pixels (`None` where that is no move; both empty without).
/// May return fewer frames than asked when the video is shorter.
struct Measured {
    metric: Vec<GrayFrame>,
    aligned: Vec<Option<GrayFrame>>,
    tracks: Vec<Track>,
    /// Whether some frame has its own alpha below 1 (a keyed element: a PNG, EXR or
    /// ProRes 4444 with alpha).
    translucent: bool,
}
/// One frame's part of [`Measured`]: its metric frame, and with tracking its aligned frame
/// (if moved) and track.
type MeasuredFrame = (GrayFrame, Option<(Option<GrayFrame>, Track)>);
fn metric_frames(clip: Clip, window: &Range<usize>, track: bool, g: &Global) -> Result<Measured> {
    let path = clip.path;
    let opts = clip.read(window.clone(), None);
    let pb = g.progress(window.len() as u64, "measuring");
    let translucent = std::sync::atomic::AtomicBool::new(false);
    // reserved up to a bound: the window's length comes from the container's word
    let mut metric = Vec::with_capacity(window.len().min(1 << 14));
    let mut tracks = Vec::with_capacity(if track { window.len().min(1 << 14) } else { 0 });
    let mut aligned = Vec::with_capacity(tracks.capacity());
    // 8-bit decoders hand over their bytes: the metric straight from them is the same
    // grey, bit for bit, without a 16-byte linear pixel per pixel (`metric_frame_srgba8`).
    let gray = |f: &ignis_media::DecodedFrame| match f {
        ignis_media::DecodedFrame::Srgba8 { size, bytes } => TrackGray::from_srgba8(*size, bytes),
        ignis_media::DecodedFrame::Linear(f) => Some(TrackGray::from_rgba(f)),
    };
    // the reference: one of the first frames (the first, unless it is flat or soft next
    // to those after it: a fade in from black)
    let tracker = if track {
        let n = window.len().min(ignis_flow::camera::REFERENCE_FRAMES);
        let head = clip.read(window.start..window.start + n, None);
        let mut first = ignis_media::open_keeping_8bit(path, &head)?;
        let mut heads = Vec::with_capacity(n);
        while let Some(f) = first.next_decoded() {
            heads.extend(gray(&f?));
        }
        ignis_flow::camera::choose_reference(&heads).map(|r| Tracker::new(&heads[r]))
    } else {
        None
    };
    let mut reader = ignis_media::open_keeping_8bit(path, &opts)?;
    let batch = ignis_core::stream::batch_len(reader.info().size.pixels() * 16, 256 << 20);
    let frames = std::iter::from_fn(move || reader.next_decoded());
    ignis_core::stream::map_in_order(
        frames.map(|f| f.map_err(anyhow::Error::from)),
        batch,
        |f| {
            let measure = |f: &ignis_media::DecodedFrame| match f {
                ignis_media::DecodedFrame::Srgba8 { size, bytes } => {
                    loopq::metric_frame_srgba8(*size, bytes).with_context(|| {
                        format!(
                            "{} decoded {} bytes for a {size} frame",
                            path.display(),
                            bytes.len()
                        )
                    })
                }
                ignis_media::DecodedFrame::Linear(f) => Ok(loopq::metric_frame_rgba(f, [0.0; 3])),
            };
            let m = measure(f)?;
            if f.see_through() > 0 {
                translucent.store(true, std::sync::atomic::Ordering::Relaxed);
            }
            let Some(tr) = &tracker else {
                return Ok((m, None));
            };
            let t = gray(f).map_or(Track::LOST, |g| tr.track(&g));
            let d = ignis_flow::camera::whole_pixels(&t);
            let a = if d == [0, 0] {
                None
            } else {
                Some(measure(&moved(f, d))?)
            };
            Ok((m, Some((a, t))))
        },
        |_, m: Result<MeasuredFrame>| {
            let (m, at) = m?;
            metric.push(m);
            if let Some((a, t)) = at {
                aligned.push(a);
                tracks.push(t);
            }
            pb.inc(1);
            Ok(())
        },
    )?;
    pb.finish_and_clear();
    Ok(Measured {
        metric,
        aligned,
        tracks,
        translucent: translucent.into_inner(),
    })
}

/// A decoded frame moved by whole pixels (`out(x) = f(x + d)`, edge-clamped).
fn moved(f: &ignis_media::DecodedFrame, d: [i32; 2]) -> ignis_media::DecodedFrame {
    use ignis_flow::camera::shift_whole;
    match f {
        ignis_media::DecodedFrame::Srgba8 { size, bytes } => {
            let (w, h) = (size.width as usize, size.height as usize);
            ignis_media::DecodedFrame::Srgba8 {
                size: *size,
                bytes: shift_whole(bytes, w, h, 4, d),
            }
        }
        ignis_media::DecodedFrame::Linear(fr) => {
            let (w, h) = (fr.width() as usize, fr.height() as usize);
            let data = shift_whole(fr.data(), w, h, 1, d);
            ignis_media::DecodedFrame::Linear(
                RgbaFrame::from_vec(fr.size(), data).expect("same size"),
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::loops::{video_texture, xfade, K};

    #[test]
    fn large_footage_trains_at_1080p() {
        let s = |w, h| Size::new(w, h).unwrap();
        assert_eq!(training_size(s(1920, 1080)), s(1920, 1080));
        assert_eq!(training_size(s(480, 480)), s(480, 480));
        assert_eq!(training_size(s(3840, 2160)), s(1920, 1080));
        assert_eq!(training_size(s(2160, 3840)), s(1080, 1920));
        assert_eq!(training_size(s(4096, 1716)), s(1920, 804));
        assert_eq!(training_size(s(8192, 6)), s(1920, 2));
    }

    #[test]
    fn a_visible_seam_is_warned_about() {
        assert!(seam_warning(1.2).is_none());
        assert!(seam_warning(2.99).is_none());
        let w = seam_warning(3.34).unwrap();
        assert!(w.starts_with("warning: the seam is 3.34×"), "{w}");
        assert!(w.contains("--length"), "{w}");
    }

    fn clip(name: &str) -> Option<PathBuf> {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data")
            .join(name);
        if !p.exists() {
            eprintln!("skipped: ../shared/data/{name} not present");
            return None;
        }
        if ignis_media::probe(&p).is_err() {
            eprintln!("skipped: {name} cannot be read here (no ffmpeg?)");
            return None;
        }
        Some(p)
    }

    /// A hand-held shot made from `campfire.mp4` (a 440×240 window moved by known whole
    /// pixels each frame, written as a PNG sequence) is tracked in the cache within a
    /// fraction of a pixel, steadied by `auto`, and its loop written with the view still;
    /// the same shot fading in from black is tracked and steadied too; the same frames
    /// unmoved are left as shot.
    #[test]
    fn a_hand_held_shot_loops_with_the_camera_held_still() {
        let Some(src) = clip("campfire.mp4") else {
            return;
        };
        let quiet = Global { quiet: true };
        let dir = tempfile::tempdir().unwrap();
        let opts = ignis_media::ReadOptions {
            range: Some(ignis_media::FrameRange::frames(200, Some(260))),
            scale: Some(Size::new(480, 270).unwrap()),
            ..Default::default()
        };
        let frames: Vec<RgbaFrame> = ignis_media::open(&src, &opts)
            .unwrap()
            .map(|f| f.unwrap())
            .collect();
        let shake = |i: usize| {
            let t = i as f32 / 25.0;
            [
                (20.0 + 9.0 * (t * 4.4).sin() + 4.0 * (t * 11.9 + 1.0).sin()).round() as i32,
                (15.0 + 6.0 * (t * 3.1 + 2.0).sin() + 3.0 * (t * 14.5).sin()).round() as i32,
            ]
        };
        let crop = |f: &RgbaFrame, o: [i32; 2]| {
            RgbaFrame::from_vec(
                Size::new(440, 240).unwrap(),
                (0..240)
                    .flat_map(|y| (0..440).map(move |x| (x, y)))
                    .map(|(x, y)| f.get(x + o[0] as u32, y + o[1] as u32))
                    .collect(),
            )
            .unwrap()
        };
        // `faded`: the shaky shot fading in from black over its first 6 frames
        for (name, moving, fade) in [("shaky", true, 0), ("faded", true, 6), ("still", false, 0)] {
            let seq = dir.path().join(name);
            std::fs::create_dir_all(&seq).unwrap();
            for (i, f) in frames.iter().enumerate() {
                let o = if moving { shake(i) } else { [20, 15] };
                let mut f = crop(f, o);
                if i < fade {
                    for p in f.data_mut() {
                        for c in &mut p[..3] {
                            *c *= i as f32 / fade as f32;
                        }
                    }
                }
                ignis_media::write_png(&seq.join(format!("{i:04}.png")), &f).unwrap();
            }
            let input = seq.join("%04d.png");
            let open = || {
                cached(
                    Clip::whole(&input),
                    0..60,
                    "32x48".parse().unwrap(),
                    20,
                    dir.path(),
                    &quiet,
                )
            };
            let c = open().unwrap();
            let decided = c.camera.decide(false);
            if !moving {
                assert!(
                    c.aligned.is_none(),
                    "a still camera keeps no aligned frames"
                );
                let why = decided.unwrap_err();
                assert!(why.contains("still"), "{why}");
                assert!(steadying(&c.camera, "auto", &quiet).unwrap().is_none());
                continue;
            }
            if fade > 0 {
                // tracked against a frame of the fade with detail, not the black first
                // one (against which no frame matched): the moves since frame 30 as shot
                assert!(
                    c.camera.tracked_share() >= 0.9,
                    "{}",
                    c.camera.tracked_share()
                );
                let t30 = c.camera.tracks[30].offset;
                let mut errs: Vec<f32> = (fade..60)
                    .map(|i| {
                        let (o, o30, t) = (shake(i), shake(30), c.camera.tracks[i].offset);
                        (t[0] - t30[0] + (o[0] - o30[0]) as f32)
                            .hypot(t[1] - t30[1] + (o[1] - o30[1]) as f32)
                    })
                    .collect();
                errs.sort_by(f32::total_cmp);
                assert!(errs[errs.len() / 2] < 0.4, "track errors {errs:?}");
                assert!(decided.is_ok(), "{decided:?}");
                continue;
            }
            // content moved by minus the window's move since frame 0
            let mut errs: Vec<f32> = (0..60)
                .map(|i| {
                    let (o, o0, t) = (shake(i), shake(0), c.camera.tracks[i].offset);
                    (t[0] + (o[0] - o0[0]) as f32).hypot(t[1] + (o[1] - o0[1]) as f32)
                })
                .collect();
            errs.sort_by(f32::total_cmp);
            assert!(errs[30] < 0.25 && errs[59] < 0.8, "track errors {errs:?}");
            let s = decided.unwrap();
            assert!(s.zoom > 1.02 && s.zoom < 1.15, "zoom {}", s.zoom);
            assert!(c.aligned.is_some());
            // reopened from the cache, the same tracks
            let again = open().unwrap();
            assert!(!again.built && again.camera == c.camera && again.aligned == c.aligned);
            let held = steadying(&c.camera, "auto", &quiet).unwrap().unwrap();
            let src = LoopFootage::cached(&input, 0, &c)
                .opaque()
                .steadied(&held, &c);
            let ask = LoopAsk {
                length: 36,
                method: Method::Auto,
                top: 1,
                every: 1,
            };
            let out = dir.path().join("loop");
            std::fs::create_dir_all(&out).unwrap();
            let d = make_loop(&src, &ask, &out_args(out.join("%04d.png")), &quiet).unwrap();
            // matted (the default), the masks are moved with the frames
            let matted = LoopFootage::cached(&input, 0, &c).steadied(&held, &c);
            let m = make_loop(&matted, &ask, &out_args(dir.path().join("m.png")), &quiet).unwrap();
            assert!(
                m.measured.seam.is_finite() && m.frames > 20,
                "{:?}",
                m.measured
            );
            // the written loop tracked against its first frame: the view stays put
            let read = |i: usize| {
                let f =
                    ignis_media::open(&out.join(format!("{:04}.png", i + 1)), &Default::default())
                        .or_else(|_| {
                            ignis_media::open(&out.join(format!("{i:04}.png")), &Default::default())
                        })
                        .unwrap()
                        .next()
                        .unwrap()
                        .unwrap();
                ignis_flow::camera::TrackGray::from_rgba(&f)
            };
            let tracker = Tracker::new(&read(0));
            let tracks: Vec<Track> = (0..d.frames).map(|i| tracker.track(&read(i))).collect();
            let wander = CameraPath {
                tracks,
                source: Size::new(440, 240).unwrap(),
            }
            .wander();
            let shot = c.camera.wander();
            assert!(
                shot > 8.0 && wander < 0.75,
                "view wanders {wander} px steadied, {shot} px as shot"
            );
        }
    }

    /// `--crop`: the cache entry, the search and the render use only that part of the
    /// frame (a key of its own beside the whole frame's), the loop is written at its size,
    /// and a footage frame of the loop is that frame's crop; a rectangle past the frame is
    /// refused, naming the frame's size.
    #[test]
    fn a_cropped_loop_is_made_of_that_part_of_the_frame() {
        let Some(path) = clip("campfire.mp4") else {
            return;
        };
        let quiet = Global { quiet: true };
        let cache = tempfile::tempdir().unwrap();
        let rect = ignis_media::Rect {
            x: 240,
            y: 60,
            width: 480,
            height: 420,
        };
        let cropped = Clip {
            path: &path,
            crop: Some(rect),
        };
        let past = Clip {
            path: &path,
            crop: Some(ignis_media::Rect { y: 130, ..rect }),
        };
        let e = past.probe().unwrap_err().to_string();
        assert!(
            e.contains("crop 240,130,480,420 reaches past the 960x540 frame"),
            "{e}"
        );
        assert_eq!(cropped.probe().unwrap().size, Size::new(480, 420).unwrap());
        let window = 200..280;
        let entry = |clip| {
            cached(
                clip,
                window.clone(),
                "32x48".parse().unwrap(),
                40,
                cache.path(),
                &quiet,
            )
            .unwrap()
        };
        let c = entry(cropped);
        assert_eq!(c.crop, Some(rect));
        // the metric frames have the crop's shape, not the frame's
        let m = c.metric[0].size();
        assert_eq!((m.width, m.height), (128, 112), "metric frames {m}");
        let whole = entry(Clip::whole(&path));
        assert_ne!(
            whole.dir, c.dir,
            "the crop shares the whole frame's cache entry"
        );
        assert!(whole.crop.is_none() && whole.metric[0].size() != m);
        // the entry is found again with its crop
        let again = entry(cropped);
        assert!(!again.built && again.crop == Some(rect) && again.dir == c.dir);
        let out = cache.path().join("frames");
        let ask = LoopAsk {
            length: 40,
            method: Method::Cut,
            top: 1,
            every: 1,
        };
        let src = LoopFootage::cached(&path, window.start, &c).opaque();
        let d = make_loop(&src, &ask, &out_args(out.join("%04d.png")), &quiet).unwrap();
        assert_eq!(d.size, Size::new(480, 420).unwrap());
        let b = d.chosen.best;
        let Some(&Planned::Src(i)) = loops::plan_with(&b.candidate, b.closing, &b.skips).first()
        else {
            panic!("a cut's loop starts with a blend");
        };
        let written = ignis_media::open(&out, &Default::default())
            .unwrap()
            .next()
            .unwrap()
            .unwrap();
        let opts = ignis_media::ReadOptions {
            range: Some(ignis_media::FrameRange::frames(
                (window.start + i) as u64,
                Some((window.start + i + 1) as u64),
            )),
            crop: Some(rect),
            ..Default::default()
        };
        let want = ignis_media::open(&path, &opts)
            .unwrap()
            .next()
            .unwrap()
            .unwrap();
        assert_eq!(written.size(), want.size());
        let worst = written
            .data()
            .iter()
            .zip(want.data())
            .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
            .fold(0.0f32, f32::max);
        assert!(
            worst < 0.01,
            "the written frame is {worst} off the source's crop"
        );
    }

    /// `--seconds` at a constant rate: the frame shown at each time (25 fps), an end up
    /// to a frame past the clip is its end, and a start or end past it, or a stretch
    /// between two frames, is refused in seconds.
    #[test]
    fn seconds_are_the_frames_shown_then() {
        let Some(path) = clip("campfire.mp4") else {
            return;
        };
        assert_eq!(seconds_window(&path, 8.0, Some(9.0)).unwrap(), 200..225);
        assert_eq!(seconds_window(&path, 12.0, None).unwrap(), 300..512);
        assert_eq!(seconds_window(&path, 0.0, Some(20.5)).unwrap(), 0..512);
        for (a, b, says) in [
            (
                0.0,
                Some(20.6),
                "ends past the clip's end (20.48 s, 512 frames)",
            ),
            (
                21.0,
                None,
                "starts past the clip's end (20.48 s, 512 frames)",
            ),
            (8.01, Some(8.015), "holds no frame (frames 200..200)"),
        ] {
            let e = seconds_window(&path, a, b).unwrap_err().to_string();
            assert!(e.contains(says), "{a}..{b:?}: {e}");
        }
    }

    fn out_args(path: PathBuf) -> crate::output::OutputArgs {
        crate::output::OutputArgs::for_path(path)
    }

    /// The issue's loop goal on each dev clip, on a 120-frame window of its middle (cheap
    /// training): the 2-s loop written at the source size has a seam no worse than the
    /// crossfade peer's and a ghost no worse than the best peer's, the peers computed on
    /// the same window's metric frames as `shared/tools/loop_metrics.py` does.
    #[test]
    fn loop_goals_on_dev_clips() {
        let quiet = Global { quiet: true };
        let cache = tempfile::tempdir().unwrap();
        for (name, window) in [
            ("candle.mp4", 340..460),
            ("campfire.mp4", 200..320),
            ("fireball.mp4", 165..285),
        ] {
            let Some(path) = clip(name) else { continue };
            let c = cached(
                Clip::whole(&path),
                window.clone(),
                "32x48".parse().unwrap(),
                40,
                cache.path(),
                &quiet,
            )
            .unwrap();
            let length = loops::parse_length("2s", c.fps).unwrap();
            let n = c.metric.len();
            let a = (n - length - K) / 2;
            let xf = loopq::loop_quality(&xfade(&c.metric, a, a + length + K, K)).unwrap();
            let (vtf, _, _) = video_texture(&c.metric, length, K).unwrap();
            let vt = loopq::loop_quality(&vtf).unwrap();
            let out = cache.path().join(format!("{name}.png"));
            let ask = LoopAsk {
                length,
                method: Method::Auto,
                top: 3,
                every: 1,
            };
            // Opaque, like the peers' frames.
            let src = LoopFootage::cached(&path, window.start, &c).opaque();
            let d = make_loop(&src, &ask, &out_args(out.clone()), &quiet).unwrap();
            // The flipbook's JSON records what was measured, and the source size when the
            // sheet could not hold full-size cells.
            let meta: serde_json::Value =
                serde_json::from_slice(&std::fs::read(out.with_extension("json")).unwrap())
                    .unwrap();
            let source = ignis_media::probe(&path).unwrap().size;
            if d.size != source {
                assert_eq!(
                    (
                        meta["scaled_from"]["width"].as_u64(),
                        meta["scaled_from"]["height"].as_u64()
                    ),
                    (Some(source.width as u64), Some(source.height as u64)),
                    "{name}: {} written, source {source}, not recorded as scaled",
                    d.size
                );
            }
            let seam = meta["loop_quality"]["seam"].as_f64().unwrap();
            assert!((seam - d.measured.seam).abs() < 1e-9);
            // The loop was chosen on its closing as rendered, so what it expected is what
            // was written (at the source's size; a scaled sheet's cells measure a little
            // differently from the footage's own metric frames).
            if d.size == source {
                let e = d.chosen.best.quality;
                assert!(
                    (e.seam - d.measured.seam).abs() < 1e-6
                        && (e.ghost - d.measured.ghost).abs() < 1e-6,
                    "{name}: expected seam {} / ghost {}, written {} / {}",
                    e.seam,
                    e.ghost,
                    d.measured.seam,
                    d.measured.ghost
                );
            }
            eprintln!(
                "{name}: ignis seam {:.3} ghost {:.3} ({}); xfade {:.3} / {:.3}; vt {:.3} / {:.3}",
                d.measured.seam,
                d.measured.ghost,
                d.chosen.best.closing,
                xf.seam,
                xf.ghost,
                vt.seam,
                vt.ghost
            );
            assert!(
                d.measured.seam <= xf.seam,
                "{name}: seam {} > crossfade's {}",
                d.measured.seam,
                xf.seam
            );
            assert!(
                d.measured.ghost >= xf.ghost.max(vt.ghost),
                "{name}: ghost {} < best peer's {}",
                d.measured.ghost,
                xf.ghost.max(vt.ghost)
            );
            if name == "candle.mp4" {
                the_default_loop_carries_the_matte(&path, window.start, &c, &ask, &out);
            }
        }
    }

    /// The default loop (alpha from the pre-processing matte, chosen on the matted
    /// frames): each cell's alpha is the voted, feathered mask training stored for its
    /// source frame (to one 8-bit level); the candle's jar and table (the sheet's corners)
    /// are keyed out and the flame kept; the colour of source frames is the footage's own;
    /// and the seam is no visible jump.
    fn the_default_loop_carries_the_matte(
        path: &Path,
        first: usize,
        c: &Cached,
        ask: &LoopAsk,
        opaque_out: &Path,
    ) {
        let quiet = Global { quiet: true };
        let out = opaque_out.with_file_name("matte.png");
        let src = LoopFootage::cached(path, first, c);
        let d = make_loop(&src, ask, &out_args(out.clone()), &quiet).unwrap();
        eprintln!(
            "candle.mp4 matted: seam {:.3} ghost {:.3} ({})",
            d.measured.seam, d.measured.ghost, d.chosen.best.closing
        );
        assert!(
            seam_warning(d.measured.seam).is_none(),
            "seam {}",
            d.measured.seam
        );
        let best = &d.chosen.best;
        let sheet = ignis_media::read_image(&out).unwrap();
        let (w, h) = (d.size.width as usize, d.size.height as usize);
        let cols = sheet.width() as usize / w;
        let matte = src.matte.unwrap();
        let plan = loops::plan_with(&best.candidate, best.closing, &best.skips);
        let mut checked = 0;
        for (j, p) in plan.iter().enumerate() {
            let (x0, y0) = ((j % cols) * w, (j / cols) * h);
            let at = |x: usize, y: usize| sheet.data()[(y0 + y) * sheet.width() as usize + x0 + x];
            for (x, y) in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
                assert_eq!(
                    at(x, y)[3],
                    0.0,
                    "cell {j}: corner ({x}, {y}) not keyed out"
                );
            }
            let Planned::Src(i) = *p else { continue };
            let want = matte.at(i, d.size, &mut MaskCache::default()).unwrap();
            let mut lit = 0;
            for y in 0..h {
                for x in 0..w {
                    let a = at(x, y)[3];
                    assert!((a - want.get(x as u32, y as u32)).abs() <= 1.0 / 255.0 + 1e-6);
                    lit += usize::from(a > 0.5);
                }
            }
            // The flame (the brightest pixel) is inside the matte, which is a small part
            // of the frame.
            let grey = |q: [f32; 4]| 0.2126 * q[0] + 0.7152 * q[1] + 0.0722 * q[2];
            let brightest = (0..w * h)
                .max_by(|&a, &b| grey(at(a % w, a / w)).total_cmp(&grey(at(b % w, b / w))))
                .unwrap();
            assert!(
                at(brightest % w, brightest / w)[3] > 0.99,
                "cell {j}: the flame is keyed out"
            );
            assert!(
                lit * 5 < w * h,
                "cell {j}: the matte covers {lit} of {} pixels",
                w * h
            );
            // The colour is the source frame's own (straight alpha), on a few cells.
            if checked % 16 == 0 {
                let opts = ignis_media::ReadOptions {
                    range: Some(ignis_media::FrameRange::frames(
                        (first + i) as u64,
                        Some((first + i + 1) as u64),
                    )),
                    ..Default::default()
                };
                let f = ignis_media::open(path, &opts)
                    .unwrap()
                    .next()
                    .unwrap()
                    .unwrap();
                for k in (0..w * h).step_by(997) {
                    let (a, b) = (at(k % w, k / w), f.data()[k]);
                    assert!(
                        (0..3).all(|c| (a[c] - b[c]).abs() < 1e-6),
                        "cell {j}: colour changed at {k}"
                    );
                }
            }
            checked += 1;
        }
        assert!(checked > d.frames / 2);
    }

    /// The matte's vote: a mask that collapses on one frame is restored by its two
    /// neighbours, one that flares on one frame is cut back; agreeing masks pass as they are.
    #[test]
    fn the_matte_votes_over_three_frames() {
        let full =
            image::GrayImage::from_fn(8, 6, |x, _| image::Luma([if x < 6 { 255 } else { 0 }]));
        let collapsed = image::GrayImage::from_fn(8, 6, |x, y| {
            image::Luma([if x < 2 && y < 2 { 255 } else { 0 }])
        });
        let flared = image::GrayImage::from_pixel(8, 6, image::Luma([255]));
        assert_eq!(ignis_eigen::mask::majority3(&full, &collapsed, &full), full);
        assert_eq!(ignis_eigen::mask::majority3(&full, &flared, &full), full);
        assert_eq!(
            ignis_eigen::mask::majority3(&collapsed, &full, &collapsed),
            collapsed
        );
        assert_eq!(ignis_eigen::mask::majority3(&full, &full, &flared), full);
    }

    /// A damaged cache entry is detected and rebuilt; a good one is reused.
    #[test]
    fn corrupt_cache_entry_is_rebuilt() {
        let Some(path) = clip("candle.mp4") else {
            return;
        };
        let quiet = Global { quiet: true };
        let cache = tempfile::tempdir().unwrap();
        let size: Size = "16x24".parse().unwrap();
        let c = cached(Clip::whole(&path), 0..30, size, 8, cache.path(), &quiet).unwrap();
        assert!(c.built);
        let dir = c.dir.clone();
        drop(c);
        let again = cached(Clip::whole(&path), 0..30, size, 8, cache.path(), &quiet).unwrap();
        assert!(!again.built, "a good entry is reused");
        let metric = dir.join("metric.f32");
        let mut bytes = std::fs::read(&metric).unwrap();
        bytes[100] ^= 0x55;
        std::fs::write(&metric, &bytes).unwrap();
        let settings = CacheSettings {
            version: CACHE_VERSION,
            train_size: size.to_string(),
            keep: 8,
            start: 0,
            end: 30,
            crop: None,
        };
        match open_entry(&dir, &source_sha256(&path).unwrap(), &settings) {
            Ok(_) => panic!("a damaged metric.f32 was accepted"),
            Err(e) => assert!(e.to_string().contains("checksum"), "{e}"),
        }
        let rebuilt = cached(Clip::whole(&path), 0..30, size, 8, cache.path(), &quiet).unwrap();
        assert!(rebuilt.built, "the damaged entry was rebuilt");
        assert_eq!(rebuilt.metric.len(), 30);
        // Grown files are refused by their length, before they are read whole.
        let sha = source_sha256(&path).unwrap();
        let good = std::fs::read(&metric).unwrap();
        let mut grown = good.clone();
        grown.extend_from_slice(&[0; 4]);
        std::fs::write(&metric, &grown).unwrap();
        match open_entry(&dir, &sha, &settings) {
            Ok(_) => panic!("a grown metric.f32 was accepted"),
            Err(e) => assert!(e.to_string().contains("wrong length"), "{e}"),
        }
        std::fs::write(&metric, &good).unwrap();
        let entry = dir.join("entry.json");
        let json = std::fs::read(&entry).unwrap();
        let mut padded = json.clone();
        padded.resize(ENTRY_JSON_MAX as usize + 1, b' ');
        std::fs::write(&entry, &padded).unwrap();
        match open_entry(&dir, &sha, &settings) {
            Ok(_) => panic!("an entry.json past the bound was read"),
            Err(e) => assert!(e.to_string().contains("larger than"), "{e}"),
        }
        std::fs::write(&entry, &json).unwrap();
        assert!(open_entry(&dir, &sha, &settings).is_ok());
        // A damaged database pack or entry.json is caught too (not rebuilt here: training
        // is the slow part).
        drop(rebuilt);
        let pack = std::fs::read_dir(dir.join("fire.db/packs"))
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let mut p = std::fs::read(&pack).unwrap();
        let last = p.len() - 1;
        p[last] ^= 0x55;
        std::fs::write(&pack, &p).unwrap();
        assert!(
            open_entry(&dir, &sha, &settings).is_err(),
            "a damaged pack was accepted"
        );
        std::fs::write(dir.join("entry.json"), b"{").unwrap();
        assert!(
            open_entry(&dir, &sha, &settings).is_err(),
            "a damaged entry.json was accepted"
        );
    }

    /// A synthetic window: `lit` frames show a drifting bright blob (weights along a
    /// circle, jittered), the others are black (keyed out: all-zero weights and frames).
    fn window(lit: &[bool]) -> (Vec<f32>, Vec<GrayFrame>) {
        let k = 3;
        let size = Size::new(24, 16).unwrap();
        let mut weights = vec![0.0f32; lit.len() * k];
        let mut frames = Vec::new();
        for (i, &l) in lit.iter().enumerate() {
            let mut f = GrayFrame::new(size);
            if l {
                let a = i as f32 * 0.37;
                let j = ((i * 7919) % 13) as f32 / 13.0 - 0.5;
                weights[i * k..i * k + k].copy_from_slice(&[a.cos(), a.sin(), 0.3 * j]);
                let (cx, cy) = (12.0 + 6.0 * a.cos(), 8.0 + 4.0 * a.sin());
                for (n, v) in f.data_mut().iter_mut().enumerate() {
                    let (x, y) = ((n % 24) as f32, (n / 24) as f32);
                    *v = (-((x - cx).powi(2) + (y - cy).powi(2)) / 8.0).exp();
                }
            }
            frames.push(f);
        }
        (weights, frames)
    }

    #[test]
    fn lit_runs_are_maximal() {
        let l = [
            false, true, true, false, false, true, false, true, true, true,
        ];
        assert_eq!(lit_runs(&l), vec![1..3, 5..6, 7..10]);
        assert_eq!(lit_runs(&[false; 4]), Vec::<Range<usize>>::new());
        assert_eq!(lit_runs(&[true; 3]), vec![0..3]);
    }

    #[test]
    fn a_matted_loop_is_never_a_loop_of_nothing() {
        // 20 lit frames, then 100 keyed out: unfiltered, the search loops the dark stretch
        // (even, calm, of nothing); with the lit flags it refuses, naming the fire's stretch.
        let lit: Vec<bool> = (0..120).map(|i| i < 20).collect();
        let (w, m) = window(&lit);
        let blind = search_and_choose(100, &w, 3, 3, &m, None, &[], 40, Method::Auto).unwrap();
        assert!(
            blind.best.candidate.start >= 20,
            "{:?}",
            blind.best.candidate
        );
        let err = search_and_choose(100, &w, 3, 3, &m, Some(&lit), &[], 40, Method::Auto)
            .err()
            .expect("a loop of keyed-out frames was chosen");
        let msg = format!("{err:#}");
        for want in [
            "keys out all the fire in 100 of the window's 120 frames",
            "100..120 (20 frames)",
            "--alpha opaque",
        ] {
            assert!(msg.contains(want), "{want:?} not in: {msg}");
        }
        // No fire at all.
        let none = vec![false; 120];
        let (w, m) = window(&none);
        let err = search_and_choose(0, &w, 3, 3, &m, Some(&none), &[], 40, Method::Auto)
            .err()
            .expect("a loop of a window without fire was chosen");
        assert!(
            format!("{err:#}").contains("no frame of it shows fire"),
            "{err:#}"
        );
    }

    #[test]
    fn a_matted_loop_shows_only_lit_footage_frames() {
        // Fire in frames 0..70 and 90..160 (two stretches, a dark gap between); a 40-frame
        // loop is found inside one stretch, its taps included.
        let lit: Vec<bool> = (0..200).map(|i| i < 70 || (90..160).contains(&i)).collect();
        let (w, m) = window(&lit);
        let c = search_and_choose(0, &w, 3, 3, &m, Some(&lit), &[], 40, Method::Auto).unwrap();
        for e in &c.evaluated {
            let (s, t) = (e.candidate.start, e.candidate.end);
            assert!(
                (s - 2..=t + 1).all(|i| lit[i]),
                "candidate {s}..{t} reads keyed-out frames"
            );
            for p in loops::plan_with(&e.candidate, e.closing, &e.skips) {
                if let Planned::Src(i) = p {
                    assert!(lit[i], "{s}..{t} ({}) shows keyed-out frame {i}", e.closing);
                }
            }
        }
        // Every frame lit: the window's own search, unchanged.
        let all = vec![true; 200];
        let (w, m) = window(&all);
        let a = search_and_choose(0, &w, 3, 3, &m, Some(&all), &[], 40, Method::Auto).unwrap();
        let b = search_and_choose(0, &w, 3, 3, &m, None, &[], 40, Method::Auto).unwrap();
        assert_eq!(a.best.candidate, b.best.candidate);
        assert_eq!(a.evaluated.len(), b.evaluated.len());
    }

    #[test]
    #[allow(clippy::single_range_in_vec_init)] // one run of frames, as `lit_runs` gives
    fn even_runs_split_at_the_uneven_steps() {
        // step 4 joins frames 4 and 5; step 9 lies outside the run 5..9; step 0 at its start
        assert_eq!(even_runs(vec![0..12], &[4, 7]), vec![0..5, 5..8, 8..12]);
        assert_eq!(
            even_runs(vec![1..3, 5..9], &[0, 4, 6, 9]),
            vec![1..3, 5..7, 7..9]
        );
        assert_eq!(even_runs(vec![0..6], &[]), vec![0..6]);
    }

    #[test]
    fn a_variable_rate_loop_reads_only_evenly_timed_frames() {
        // Steps 60..=84 are off the nominal rate (a stretch shot at half the rate): every
        // evaluated loop, its taps and its closing's tail included, lies on one side.
        let all = vec![true; 200];
        let (w, m) = window(&all);
        let uneven: Vec<usize> = (60..85).collect();
        for lit in [None, Some(&all[..])] {
            let c = search_and_choose(0, &w, 3, 3, &m, lit, &uneven, 40, Method::Auto).unwrap();
            assert!(!c.evaluated.is_empty());
            for e in &c.evaluated {
                let (s, t) = (e.candidate.start, e.candidate.end);
                let last = loops::plan_end(&e.candidate, e.closing).max(t + 2);
                assert!(
                    last <= 61 || s >= 87,
                    "{s}..{t} ({}) reads frames up to {last} across steps 60..=84",
                    e.closing
                );
            }
        }
        // the whole window unrestricted finds loops across the uneven steps
        let any = search_and_choose(0, &w, 3, 3, &m, None, &[], 40, Method::Auto).unwrap();
        assert!(any.evaluated.iter().any(|e| {
            let c = &e.candidate;
            c.start < 87 && loops::plan_end(c, e.closing).max(c.end + 2) > 61
        }));
        // no even stretch long enough: an `Uneven` error naming the longest
        let every_30th: Vec<usize> = (0..199).filter(|i| i % 30 == 29).collect();
        let err = search_and_choose(0, &w, 3, 3, &m, None, &every_30th, 40, Method::Auto)
            .err()
            .expect("a loop across uneven steps");
        let u = err.downcast_ref::<Uneven>().expect("an Uneven error");
        assert_eq!(u.longest.len(), 30, "{u}");
        assert!(format!("{u}").contains("about 40 frames"), "{u}");
    }

    #[test]
    fn the_search_sees_the_matte_as_rendered() {
        let Some(path) = clip("candle.mp4") else {
            return;
        };
        let quiet = Global { quiet: true };
        let cache = tempfile::tempdir().unwrap();
        let c = cached(
            Clip::whole(&path),
            0..40,
            "16x24".parse().unwrap(),
            8,
            cache.path(),
            &quiet,
        )
        .unwrap();
        let matte = FootageMatte::new(&c.db, 0, c.metric.len());
        let matted = matte.matted_metric(&c.metric, None).unwrap();
        let source = ignis_media::probe(&path).unwrap().size;
        let mut band = 0;
        for i in [0, 1, 17, 38, 39] {
            let full = matte.at(i, source, &mut MaskCache::default()).unwrap();
            let soft = ignis_core::loopq::area_resize(&full, c.metric[i].size());
            for ((&m, &g), &a) in matted[i]
                .data()
                .iter()
                .zip(c.metric[i].data())
                .zip(soft.data())
            {
                assert!((m - g * a).abs() <= 1e-6, "frame {i}: {m} vs {}", g * a);
                band += usize::from(a > 0.0 && a < 1.0 && g > 0.0);
            }
        }
        // The feather's soft band (lit surroundings at part alpha) is part of what is seen.
        assert!(band > 0, "no soft matte edge in the metric frames");
    }

    #[test]
    fn the_crossfade_blends_premultiplied() {
        let size = Size::new(2, 1).unwrap();
        // Pixel 0: flame in `a`, keyed-out dark surroundings in `b`; pixel 1: both opaque.
        let a =
            RgbaFrame::from_vec(size, vec![[1.0, 0.6, 0.2, 1.0], [0.3, 0.2, 0.1, 1.0]]).unwrap();
        let b =
            RgbaFrame::from_vec(size, vec![[0.05, 0.04, 0.03, 0.0], [0.7, 0.5, 0.3, 1.0]]).unwrap();
        let f = blend_rgba(&a, &b, 0.75);
        let p = f.data()[0];
        // The flame's colour at a quarter of its alpha (not darkened by b's hidden colour).
        for c in 0..3 {
            assert!((p[c] - a.data()[0][c]).abs() < 1e-6, "{p:?}");
        }
        assert!((p[3] - 0.25).abs() < 1e-6);
        // Over black it is the crossfade of the two composites.
        assert!((p[0] * p[3] - 0.25 * 1.0).abs() < 1e-6);
        let q = f.data()[1];
        for (c, &v) in q.iter().enumerate() {
            let want = a.data()[1][c] + (b.data()[1][c] - a.data()[1][c]) * 0.75;
            assert_eq!(v, want, "opaque pixels blend per channel");
        }
        // Both keyed out: transparent.
        let z = RgbaFrame::from_vec(size, vec![[0.5, 0.5, 0.5, 0.0]; 2]).unwrap();
        assert_eq!(blend_rgba(&z, &z, 0.5).data()[0], [0.5, 0.5, 0.5, 0.0]);
    }

    /// A closing's frames blend on the fire's colour ramp: where a bright yellow tongue of
    /// one frame meets the dark of the other, the crossfade and the morph (here with no
    /// motion, so the same frame) are redder than the plain blend, with its luminance and
    /// alpha; a keyed-out pixel stays as the plain crossfade makes it.
    #[test]
    fn closing_frames_cool_as_they_fade() {
        let (w, h) = (64u32, 4u32);
        let size = Size::new(w, h).unwrap();
        // a fire ramp across the frame (dim red to bright yellow), the same in both frames
        // but for pixel 0, bright yellow in `a` and dark in `b`, and pixel 1, keyed out
        let fire = |y: f32| {
            let t = (y / 0.8).clamp(0.0, 1.0);
            let raw = [1.0, 0.15 + 0.75 * t, 0.02 + 0.2 * t * t];
            let l = 0.2126 * raw[0] + 0.7152 * raw[1] + 0.0722 * raw[2];
            [raw[0] * y / l, raw[1] * y / l, raw[2] * y / l, 1.0]
        };
        let ramp: Vec<[f32; 4]> = (0..w * h)
            .map(|i| fire(0.002 * 1.025f32.powi(i as i32 % 256)))
            .collect();
        let (mut a, mut b) = (ramp.clone(), ramp);
        a[0] = fire(0.8);
        b[0] = [0.01, 0.01, 0.01, 1.0];
        a[1] = [0.3, 0.2, 0.1, 0.0];
        b[1] = [0.1, 0.2, 0.3, 0.0];
        let (a, b) = (
            RgbaFrame::from_vec(size, a).unwrap(),
            RgbaFrame::from_vec(size, b).unwrap(),
        );
        let zero = ignis_flow::FlowField::from_vec(size, vec![[0.0; 2]; (w * h) as usize]).unwrap();
        let l = ignis_core::frame::LUMA;
        let luma = |p: [f32; 4]| l[0] * p[0] + l[1] * p[1] + l[2] * p[2];
        for t in [0.3f32, 0.5, 0.7] {
            let plain = blend_rgba(&a, &b, t).data()[0];
            let cross = closing_frame(&a, &b, None, t);
            let morph = closing_frame(&a, &b, Some(&(zero.clone(), zero.clone())), t);
            // the same light and alpha (a keyed-out pixel's hidden colour aside: the morph,
            // as `ignis_flow::morph_rgba`, leaves it black)
            let pm = |p: &[f32; 4]| [p[0] * p[3], p[1] * p[3], p[2] * p[3], p[3]];
            for (x, y) in cross.data().iter().zip(morph.data()) {
                let (x, y) = (pm(x), pm(y));
                assert!((0..4).all(|c| (x[c] - y[c]).abs() < 1e-5), "{x:?} {y:?}");
            }
            let p = cross.data()[0];
            assert!((luma(p) - luma(plain)).abs() < 1e-4, "{p:?} {plain:?}");
            assert_eq!(p[3], plain[3]);
            assert!(
                p[1] / p[0] < 0.9 * (plain[1] / plain[0]),
                "t {t}: {p:?} is not redder than the plain blend {plain:?}"
            );
            assert_eq!(cross.data()[1], blend_rgba(&a, &b, t).data()[1]);
        }
    }

    /// The render's morph flow is the matted pair's (`ignis_flow::flow_pair_matted_rgba`,
    /// at [`RENDER_FLOW_SIDE`]): filled over a keyed-out background (every other pixel here),
    /// not DIS's raw vectors there.
    #[test]
    fn the_render_flow_is_filled_over_a_keyed_out_background() {
        let size = Size::new(80, 48).unwrap();
        let frame = |shift: f32| {
            let px = (0..size.pixels()).map(|i| {
                let (x, y) = ((i % 80) as f32 - shift, (i / 80) as f32);
                let v = 0.5 + 0.4 * (x * 0.5).sin() * (y * 0.3).cos();
                [v, 0.7 * v, 0.3 * v, (i % 2) as f32]
            });
            RgbaFrame::from_vec(size, px.collect()).unwrap()
        };
        let (a, b) = (frame(0.0), frame(3.0));
        let p = FlowMorph::new(RENDER_FLOW_SIDE).params;
        let got = render_flow(&a, &b).unwrap();
        assert!(got == ignis_flow::flow_pair_matted_rgba(&a, &b, &p).unwrap());
        let raw = ignis_flow::flow_pair_reduced_rgba(&a, &b, &p).unwrap();
        assert!(got != raw, "the fill changed nothing");
    }
}
