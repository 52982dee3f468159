//! The training stage (thesis §4.1): decode each clip, pre-process every frame (ch. 3),
//! fit the PCA (§4.2, in `ignis-pca`), project the training frames (§4.3), analyse the
//! weights (§4.5–4.6) and write the database (§4.1 off-line mode, §4.8 packs).
//!
//! Each clip is read twice: a first pass finds its pose (§3.4) and checks its range; the
//! second pre-processes every frame into one column of the data matrix. The data matrix
//! (N training pixels × M frames, f32) is the only large allocation; its size is checked
//! against the memory available before anything is allocated. With `streaming = true` the
//! columns go to a temporary `.npy` file instead and `ignis_pca::fit_streaming` reads them
//! in blocks (randomized, top `streaming_components` Eigenfires).

use crate::analysis::{thresholds, ESelect};
use crate::db::{self, ClipEntry, DbWriter, FileEntry, Manifest};
use crate::error::{EigenError, Result};
use crate::footage::{Footage, SyntheticFootage};
use crate::mask::{clip_white, static_fraction, value8, Isolate, MaskParams, BLACK, STATIC_LIT};
use crate::pose::{auto_framing, clip_pose, ClipPose};
use crate::preprocess::{
    frame_mask, frame_mask_without, preprocess_frame, preprocess_stages, FrameStages,
    PreprocessParams,
};
use crate::still::{still_lights, StillLights};
use crate::synthetic::{FlameStyle, SyntheticParams};
use ignis_core::{RgbaFrame, Size};
use ignis_pca::npy::{self, Dtype, NpyWriter};
use ignis_pca::{Keep, Method, Pca, PcaOptions};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One clip of a training configuration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipSpec {
    /// Name used in the database and on the command line (letters, digits, `-`, `_`, `.`).
    pub name: String,
    /// Video or image-sequence path (relative paths are relative to the config file).
    #[serde(default)]
    pub path: Option<PathBuf>,
    /// A built-in synthetic clip instead of a file.
    #[serde(default)]
    pub synthetic: Option<FlameStyle>,
    /// First source frame used (0-based). Default 0.
    #[serde(default)]
    pub start: usize,
    /// One past the last source frame used. Default: the end of the clip.
    #[serde(default)]
    pub end: Option<usize>,
    /// Use every `stride`-th frame. Default 1.
    #[serde(default = "one")]
    pub stride: usize,
    /// Overrides the automatic centring and scaling (§3.4).
    #[serde(default)]
    pub pose: Option<ClipPose>,
    /// Only this rectangle `[x, y, width, height]` of every frame (source pixels, top-left
    /// origin): one fire of several, a flame away from a lit wall. The clip's footage must
    /// already be cut to it (`MediaFootage::cropped`; `ignis eigen train --crop` and a
    /// config's `crop = [x, y, w, h]` do that); it is recorded in the database, so renders
    /// from the footage cut it again.
    #[serde(default)]
    pub crop: Option<[u32; 4]>,
}

fn one() -> usize {
    1
}

impl ClipSpec {
    /// A clip of a whole source named `name`.
    pub fn new(name: &str) -> ClipSpec {
        ClipSpec {
            name: name.into(),
            path: None,
            synthetic: None,
            start: 0,
            end: None,
            stride: 1,
            pose: None,
            crop: None,
        }
    }
}

/// Training settings (everything except the clips).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainParams {
    /// Eigenfires to keep: `None` keeps all meaningful ones (M − 1, thesis §4.2), or a
    /// count / retained variance such as `"200"` or `"99%"`.
    pub keep: Option<ESelect>,
    /// E for recognition (§4.8, §5.1.2). Default `"95%"`.
    pub e_detect: ESelect,
    /// E for rendering. Default `"99%"`.
    pub e_render: ESelect,
    /// Eigenfires per pack file (§4.8 `packSize`). Default 100.
    pub pack_size: usize,
    /// Also store the full-resolution pre-processed frames (`frames/<clip>.npy`) for the
    /// fast path of §7.1.2. Default false.
    pub store_frames: bool,
    /// Memory budget for the data matrix and PCA workspace in bytes; `None` = what the
    /// machine reports available.
    pub memory_limit: Option<u64>,
    /// Out-of-core training: the data matrix goes to disk and a randomized PCA reads it in
    /// blocks. Default false.
    pub streaming: bool,
    /// Eigenfires computed by the streaming path. Default 200.
    pub streaming_components: usize,
}

impl Default for TrainParams {
    fn default() -> Self {
        TrainParams {
            keep: None,
            e_detect: ESelect::Variance(0.95),
            e_render: ESelect::Variance(0.99),
            pack_size: 100,
            store_frames: false,
            memory_limit: None,
            streaming: false,
            streaming_components: 200,
        }
    }
}

/// A whole training configuration file (`ignis eigen train clips.toml`):
/// ```toml
/// [[clip]]
/// name = "candle"
/// path = "candle.mp4"
/// start = 0
/// end = 400
/// stride = 2
/// crop = [100, 40, 280, 400]   # optional: x, y, width, height of the part used
///
/// [preprocess]
/// train_size = "102x168"
/// [preprocess.hermite]
/// i_min = 0.15
///
/// [train]
/// pack_size = 100
/// e_detect = "95%"
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    #[serde(rename = "clip")]
    pub clips: Vec<ClipSpec>,
    #[serde(default)]
    pub preprocess: PreprocessParams,
    #[serde(default)]
    pub train: TrainParams,
}

impl TrainConfig {
    /// Parses and validates a configuration; relative clip paths are resolved against
    /// `base_dir`.
    pub fn from_toml(text: &str, base_dir: &Path) -> Result<TrainConfig> {
        let mut c: TrainConfig =
            toml::from_str(text).map_err(|e| EigenError::bad("training config", e.to_string()))?;
        for clip in &mut c.clips {
            if let Some(p) = &clip.path {
                if p.is_relative() {
                    clip.path = Some(base_dir.join(p));
                }
            }
            if clip.path.is_some() == clip.synthetic.is_some() {
                return Err(EigenError::clip(
                    &clip.name,
                    "give exactly one of `path` or `synthetic`",
                ));
            }
        }
        c.preprocess.validate()?;
        Ok(c)
    }
}

pub use ignis_core::progress::{NoProgress, Progress};

/// A clip with its footage, ready to train.
pub struct ClipInput<'a> {
    pub spec: ClipSpec,
    pub footage: Box<dyn Footage + 'a>,
}

impl<'a> ClipInput<'a> {
    pub fn new(spec: ClipSpec, footage: impl Footage + 'a) -> ClipInput<'a> {
        ClipInput {
            spec,
            footage: Box::new(footage),
        }
    }
}

/// The two built-in synthetic clips, `candle` and `campfire` (30 fps), that the demo and
/// tests train on so they need no footage.
pub fn synthetic_clips(size: Size, frames: usize, seed: u64) -> Vec<ClipInput<'static>> {
    [
        ("candle", FlameStyle::Candle),
        ("campfire", FlameStyle::Campfire),
    ]
    .into_iter()
    .map(|(name, style)| {
        ClipInput::new(
            ClipSpec::new(name),
            SyntheticFootage::new(
                SyntheticParams {
                    size,
                    frames,
                    style,
                    seed,
                },
                30.0,
            ),
        )
    })
    .collect()
}

struct Planned {
    start: usize,
    end: usize,
    frames: usize,
    pose: ClipPose,
    /// [`static_fraction`] of the sampled frames.
    static_lit: f64,
    /// [`clip_white`] of the sampled frames.
    white: f32,
}

/// Settings with the automatic sizes resolved for clips of `sizes`: the common frame
/// size, the training size, and (automatic framing) one pose per clip; plus a sentence
/// saying what was chosen and why (`ignis eigen info` prints it).
pub fn resolve_sizes(
    pre: &PreprocessParams,
    sizes: &[Size],
) -> (PreprocessParams, Option<Vec<ClipPose>>, String) {
    let mut r = pre.clone();
    match pre.pose.frame_size {
        None => {
            let (f, poses) = auto_framing(sizes);
            let t = pre.auto_train_size(f);
            r.pose.frame_size = Some(f);
            r.pose.base_margin = 0.0;
            r.train_size = Some(t);
            let list: Vec<String> = sizes.iter().map(|s| s.to_string()).collect();
            let why = format!(
                "frame {f}: the smallest frame holding every clip at its own resolution ({}), each bottom-centred at scale 1 (nothing clipped or resampled); training {t}: the frame's aspect at about {} pixels",
                list.join(", "),
                pre.train_pixels
            );
            (r, Some(poses), why)
        }
        Some(f) => {
            let t = pre.auto_train_size(f);
            r.train_size = Some(t);
            let why = format!(
                "frame {f} (fixed in the settings): each clip centred on its fuel and scaled so its tall flame fills {:.0}% of the height; training {t}",
                pre.pose.fill * 100.0
            );
            (r, None, why)
        }
    }
}

fn check_name(name: &str) -> Result<()> {
    if name.is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
        || name.starts_with('.')
    {
        return Err(EigenError::clip(
            name,
            "names may contain only letters, digits, `-`, `_` and `.` (not first)",
        ));
    }
    Ok(())
}

/// Iterates a clip's training frames: source frames `start, start+stride, ..` below `end`.
fn training_frames<'s>(
    c: &'s ClipInput<'_>,
    start: usize,
    end: usize,
) -> Result<impl Iterator<Item = (usize, Result<RgbaFrame>)> + 's> {
    let name = &c.spec.name;
    let it = c.footage.frames(start).map_err(|e| e.in_clip(name))?;
    let stride = c.spec.stride;
    Ok(it
        .enumerate()
        .map(move |(i, f)| (i + start, f))
        .take_while(move |(i, _)| *i < end)
        .filter(move |(i, _)| (i - start).is_multiple_of(stride))
        .map(move |(i, f)| (i, f.map_err(|e| e.in_clip(name)))))
}

/// Checks the clip's range against what is known before decoding; returns `[start, end)`
/// with `end` possibly `usize::MAX` (unknown).
fn plan_range(c: &ClipInput<'_>) -> Result<(usize, usize)> {
    let s = &c.spec;
    if s.stride == 0 {
        return Err(EigenError::clip(&s.name, "stride must be at least 1"));
    }
    if let Some([x, y, w, h]) = s.crop {
        let size = c.footage.info().size;
        if (size.width, size.height) != (w, h) {
            return Err(EigenError::clip(
                &s.name,
                format!(
                    "crop = [{x}, {y}, {w}, {h}] is {w}x{h}, but its footage is {size}; cut the \
                     footage to the crop (MediaFootage::cropped) before training"
                ),
            ));
        }
    }
    if c.footage.info().frame_count == Some(0) {
        return Err(EigenError::clip(
            &s.name,
            format!("{} has zero frames", c.footage.info().source),
        ));
    }
    if let Some(e) = s.end {
        if e <= s.start {
            return Err(EigenError::clip(
                &s.name,
                format!("the range {}..{e} is empty", s.start),
            ));
        }
    }
    if let Some(n) = c.footage.info().frame_count {
        let end = s.end.unwrap_or(n);
        if s.start >= n || end > n {
            return Err(EigenError::clip(
                &s.name,
                format!(
                    "the range {}..{end} goes past the end of {} ({n} frames)",
                    s.start,
                    c.footage.info().source
                ),
            ));
        }
        return Ok((s.start, end));
    }
    Ok((s.start, s.end.unwrap_or(usize::MAX)))
}

fn human(b: u64) -> String {
    ignis_pca::memory::human_bytes(b)
}

/// Refuses a data matrix that would not fit, before anything is allocated.
pub fn check_memory(n: usize, m: usize, p: &TrainParams) -> Result<()> {
    if p.streaming {
        return Ok(());
    }
    let need = ignis_pca::required_bytes(n, m, &Method::Snapshot);
    let avail = p.memory_limit.unwrap_or_else(ignis_pca::available_bytes);
    if need > avail {
        return Err(EigenError::LimitExceeded(format!(
            "training on {m} frames of {n} pixels needs {} (data matrix {} plus PCA workspace) but {} is available; \
             use a smaller train_size (pre-processing, §7.1.2), fewer frames (stride), or the streaming path \
             (`streaming = true` under [train], or --streaming), which keeps the data matrix on disk",
            human(need),
            human(ignis_pca::memory::data_bytes(n, m)),
            human(avail)
        )));
    }
    Ok(())
}

/// Pass 1 over a clip: counts its training frames and finds its pose.
fn plan_clip(
    c: &ClipInput<'_>,
    pre: &PreprocessParams,
    auto_pose: Option<ClipPose>,
    progress: &mut dyn Progress,
) -> Result<Planned> {
    let name = &c.spec.name;
    let (start, end) = plan_range(c)?;
    let expected = if end == usize::MAX {
        None
    } else {
        Some((end - start).div_ceil(c.spec.stride))
    };
    let every = expected.map(|n| (n / pre.pose_samples).max(1)).unwrap_or(4);
    progress.stage(&format!("scan {name}"), expected.unwrap_or(0) as u64);
    let (mut count, mut last) = (0usize, None);
    let mut extents = Vec::new();
    let mut extents_isolated = Vec::new();
    let mut values = Vec::new();
    let need_extents = c.spec.pose.is_none() && auto_pose.is_none();
    for (i, f) in training_frames(c, start, end)? {
        let f = f?;
        if count % every == 0 {
            if f.size() != c.footage.info().size {
                return Err(EigenError::clip(
                    name,
                    format!(
                        "frame {i} is {}, the source says {}; a clip must keep one frame size",
                        f.size(),
                        c.footage.info().size
                    ),
                ));
            }
            if values.len() < 4 * pre.pose_samples {
                values.push(value8(&f));
            }
            if need_extents {
                extents.push(frame_mask(&f, pre, false).extent);
                if pre.mask.isolate != Isolate::Off {
                    extents_isolated.push(frame_mask(&f, pre, true).extent);
                }
            }
        }
        count += 1;
        last = Some(i);
        progress.inc(1);
    }
    progress.finish_stage();
    if count == 0 {
        return Err(match c.footage.info().frame_count {
            _ if start > 0 => EigenError::clip(
                name,
                format!(
                    "the range starts at frame {start}, past the end of {}",
                    c.footage.info().source
                ),
            ),
            _ => EigenError::clip(name, format!("{} has zero frames", c.footage.info().source)),
        });
    }
    let end = if end == usize::MAX {
        last.expect("count > 0") + 1
    } else {
        end
    };
    if let Some(n) = expected {
        if count < n {
            return Err(EigenError::clip(
                name,
                format!(
                    "the range {start}..{end} goes past the end of {} (only {} frames decoded; \
                     if its header promised more, the file may be truncated or damaged, e.g. an \
                     incomplete download or copy: copy it again, or end the range there)",
                    c.footage.info().source,
                    start + (count - 1) * c.spec.stride + 1
                ),
            ));
        }
    }
    let white = clip_white(&values);
    let static_lit = static_fraction(&values, pre.mask.isolate_floor);
    let isolate = match pre.mask.isolate {
        Isolate::On => true,
        Isolate::Off => false,
        Isolate::Auto => static_lit > STATIC_LIT,
    };
    let size = c.footage.info().size;
    let still = match c.spec.pose {
        Some(p) if !p.still_lights.is_empty() => p.still_lights,
        _ if pre.mask.still_lights => {
            still_lights(&values, size.width, size.height, pre.mask.isolate_floor)
        }
        _ => StillLights::default(),
    };
    if need_extents && !still.is_empty() {
        // The scan's extents saw the still lights as flame: measure them again without.
        extents = rescan_extents(c, (start, end, every), pre, isolate, &still, progress)?;
    }
    let mut pose = match (c.spec.pose, auto_pose) {
        (Some(p), _) => p,
        (None, Some(p)) => p,
        (None, None) => {
            let e = if isolate && still.is_empty() {
                &extents_isolated
            } else {
                &extents
            };
            if e.iter().all(Option::is_none) {
                return Err(EigenError::clip(
                    name,
                    nothing_masked("sampled frame", white, &pre.mask),
                ));
            }
            clip_pose(name, e, &pre.pose)?
        }
    };
    pose.isolate = isolate;
    pose.still_lights = still;
    Ok(Planned {
        start,
        end,
        frames: count,
        pose,
        static_lit,
        white,
    })
}

/// Why the mask kept nothing in any frame (`which`: "frame", "sampled frame") of a clip
/// whose sampled frames' white ([`clip_white`]) is `white`, and what to do: a black clip
/// (the wrong footage or range), a clip too dark for the mask's `V` minimum (its brightest
/// pixels under 1.5 times it: brighten it, with a command that maps its white to white),
/// or a flame the mask's ranges do not cover.
///
/// The clip is not brightened here: tried (a gain in linear light bringing the white to 1
/// for the mask and the grey frames), the flame isolation's levels then depend on where
/// that white lands — on `campfire.mp4` 4.4 stops darker and re-encoded, a gain to the
/// 16th-brightest pixel isolated specks of the fire, twice that gain the fire but on
/// `candle.mp4` as dark the lit jar with it — so the user brightens it and looks.
fn nothing_masked(which: &str, white: f32, mask: &MaskParams) -> String {
    // the value the broadest layer starts at (by default 0.3, any hue)
    let v_min = mask
        .layers
        .iter()
        .map(|l| l.range.v[0])
        .fold(0.0f32, f32::max);
    let config = "with `ignis eigen train`, a config can widen the HSV ranges (e.g. lower the \
                  V minimum of [[preprocess.mask.layers]])";
    let why = if white < BLACK {
        "a black clip: is it the right footage and range?".to_string()
    } else if white < 1.5 * v_min {
        format!(
            "too dark for the mask, which keeps values from {v_min:.2}: brighten the clip so its \
             brightest pixels reach white (e.g. `ffmpeg -i IN -vf \"curves=all='0/0 {white:.2}/1'\" OUT`), or {config}"
        )
    } else {
        format!("not a flame the mask tells from its surroundings; {config}")
    };
    format!(
        "the mask removes every pixel in every {which}; its brightest pixels reach {white:.2} \
         (sRGB value): {why}"
    )
}

/// The mask extents of the frames [`plan_clip`] samples (every `every`-th training frame
/// of `start..end`), measured again with the clip's `still` lights left out.
fn rescan_extents(
    c: &ClipInput<'_>,
    (start, end, every): (usize, usize, usize),
    pre: &PreprocessParams,
    isolate: bool,
    still: &StillLights,
    progress: &mut dyn Progress,
) -> Result<Vec<Option<crate::pose::MaskExtent>>> {
    progress.stage(
        &format!("rescan {} without its still lights", c.spec.name),
        0,
    );
    let mut out = Vec::new();
    for (count, (_, f)) in training_frames(c, start, end)?.enumerate() {
        let f = f?;
        if count % every == 0 {
            out.push(frame_mask_without(&f, pre, isolate, still).extent);
        }
    }
    progress.finish_stage();
    Ok(out)
}

/// What [`train`] did.
#[derive(Clone, Debug)]
pub struct TrainReport {
    pub manifest: Manifest,
    /// The weights as computed (M×k, row-major), before they were written.
    pub weights: Vec<f32>,
    /// Where the database was written.
    pub path: PathBuf,
}

/// Trains a database from `clips` and writes it atomically to `out` (an existing database
/// there is replaced only once the new one is complete): plan (pass 1) → collect (pass 2,
/// the data matrix) → fit (PCA and weights) → [`DbWriter::finish`].
pub fn train(
    clips: &[ClipInput<'_>],
    pre: &PreprocessParams,
    p: &TrainParams,
    out: &Path,
    progress: &mut dyn Progress,
) -> Result<TrainReport> {
    // before the clips are scanned: an output the database may not replace is refused
    db::check_replaceable(out)?;
    let (pre, framing, plans) = plan_training(clips, pre, p, progress)?;
    let n = pre.training_size().pixels();
    let m: usize = plans.iter().map(|q| q.frames).sum();
    let writer = DbWriter::create(out)?;
    let collected = collect(clips, &plans, &pre, p, &writer, (n, m), progress)?;
    progress.stage("PCA", 0);
    let (pca, weights) = fit(collected.data, p, (n, m))?;
    progress.finish_stage();
    let fitted = Fitted {
        pca,
        weights,
        angles: collected.angles,
        frames_files: collected.frames_files,
    };
    let k = fitted.pca.n_components();
    progress.stage("write", k.div_ceil(p.pack_size) as u64 + 4);
    let manifest = write_model(&writer, clips, &plans, &pre, p, &fitted, framing, progress)?;
    progress.stage("commit", 0);
    let path = writer.finish(&manifest)?;
    progress.finish_stage();
    Ok(TrainReport {
        manifest,
        weights: fitted.weights,
        path,
    })
}

/// Checks the clips and settings, resolves the automatic sizes and runs pass 1 over every
/// clip (range, pose); refuses a data matrix that would not fit before and after.
fn plan_training(
    clips: &[ClipInput<'_>],
    pre: &PreprocessParams,
    p: &TrainParams,
    progress: &mut dyn Progress,
) -> Result<(PreprocessParams, String, Vec<Planned>)> {
    pre.validate()?;
    if clips.is_empty() {
        return Err(EigenError::bad("clips", "no clips to train on"));
    }
    if p.pack_size == 0 {
        return Err(EigenError::bad("pack_size", "must be at least 1"));
    }
    for (i, c) in clips.iter().enumerate() {
        check_name(&c.spec.name)?;
        if clips[..i].iter().any(|d| d.spec.name == c.spec.name) {
            return Err(EigenError::clip(&c.spec.name, "two clips have this name"));
        }
        plan_range(c)?;
    }
    let sizes: Vec<Size> = clips.iter().map(|c| c.footage.info().size).collect();
    let (pre, auto_poses, framing) = resolve_sizes(pre, &sizes);
    pre.validate()?;
    let n = pre.training_size().pixels();
    // Early refusal from what is known before decoding.
    let known: usize = clips
        .iter()
        .filter_map(|c| {
            let (s, e) = plan_range(c).ok()?;
            (e != usize::MAX).then(|| (e - s).div_ceil(c.spec.stride))
        })
        .sum();
    check_memory(n, known.max(1), p)?;
    let plans = clips
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let ap = auto_poses.as_ref().map(|p| p[i]);
            plan_clip(c, &pre, ap, progress)
        })
        .collect::<Result<Vec<_>>>()?;
    let m: usize = plans.iter().map(|q| q.frames).sum();
    check_memory(n, m, p)?;
    Ok((pre, framing, plans))
}

/// The data matrix: in memory (column j = training frame j) or streamed to a scratch
/// `.npy` file in the database's temporary directory (row j).
enum DataMatrix {
    Memory(faer::Mat<f32>),
    Streamed(PathBuf),
}

/// What pass 2 produced besides the data matrix.
struct Collected {
    data: DataMatrix,
    /// Rotation of every training frame (pose normalisation).
    angles: Vec<f32>,
    /// Per clip, its stored files.
    frames_files: Vec<ClipFiles>,
}

/// A clip's own database files: its pre-processed frames (`store_frames`) and masks.
#[derive(Clone)]
struct ClipFiles {
    frames: Option<FileEntry>,
    masks: FileEntry,
    /// The flame's own colour over the clip's training frames.
    flame_colour: Option<[f32; 3]>,
}

/// The fitted model: PCA, weights (M×k row-major), angles, stored frames per clip.
struct Fitted {
    pca: Pca,
    weights: Vec<f32>,
    angles: Vec<f32>,
    frames_files: Vec<ClipFiles>,
}

/// Where pass 2 puts each training frame.
enum Sink {
    Memory(faer::Mat<f32>),
    Stream(NpyWriter, PathBuf),
}

/// Decoded frames one pre-processing batch may hold (two batches are in memory at once:
/// one decoded while the other is processed): 256 MiB, eight 1080p frames.
const PREPROCESS_BATCH_BYTES: usize = 256 << 20;

/// Pass 2: pre-processes every training frame into the data matrix (and the stored frames).
fn collect(
    clips: &[ClipInput<'_>],
    plans: &[Planned],
    pre: &PreprocessParams,
    p: &TrainParams,
    writer: &DbWriter,
    (n, m): (usize, usize),
    progress: &mut dyn Progress,
) -> Result<Collected> {
    let mut sink = if p.streaming {
        let rel = "data.tmp.npy";
        Sink::Stream(
            writer.array(rel, Dtype::F32, &[m, n])?,
            writer.dir().join(rel),
        )
    } else {
        Sink::Memory(ignis_pca::alloc_data_matrix(
            n,
            m,
            &Method::Snapshot,
            p.memory_limit,
        )?)
    };
    let mut angles = Vec::with_capacity(m);
    let mut frames_files = Vec::new();
    for (c, plan) in clips.iter().zip(plans) {
        let ff = collect_clip(
            c,
            plan,
            pre,
            p.store_frames,
            writer,
            &mut sink,
            &mut angles,
            progress,
        )?;
        frames_files.push(ff);
    }
    let data = match sink {
        Sink::Memory(d) => DataMatrix::Memory(d),
        Sink::Stream(w, path) => {
            w.finish()?;
            DataMatrix::Streamed(path)
        }
    };
    Ok(Collected {
        data,
        angles,
        frames_files,
    })
}

/// Pass 2 over one clip: its frames go to `sink` (column/row `angles.len()` on), their
/// angles to `angles`, their masks to `masks/<clip>.rle`; returns the clip's files.
#[allow(clippy::too_many_arguments)]
fn collect_clip(
    c: &ClipInput<'_>,
    plan: &Planned,
    pre: &PreprocessParams,
    store_frames: bool,
    writer: &DbWriter,
    sink: &mut Sink,
    angles: &mut Vec<f32>,
    progress: &mut dyn Progress,
) -> Result<ClipFiles> {
    let name = &c.spec.name;
    let frame_size = pre.pose.frame();
    progress.stage(&format!("pre-process {name}"), plan.frames as u64);
    let rel = format!("frames/{name}.npy");
    let mut fw = if store_frames {
        let shape = [
            plan.frames,
            frame_size.height as usize,
            frame_size.width as usize,
        ];
        Some(writer.array(&rel, Dtype::F32, &shape)?)
    } else {
        None
    };
    let src = c.footage.info().size;
    let mut masks = crate::db::masks::MaskWriter::new(src.width, src.height);
    let (mut done, mut lit) = (0, 0);
    let mut colour = crate::preprocess::FlameColour::default();
    // Frames are independent once the pose is known: pre-processed on the pool, a batch at
    // a time while the next is decoded, and stored in clip order (the same bytes at any
    // thread count).
    let frames = training_frames(c, plan.start, plan.end)?
        .take(plan.frames)
        .map(|(_, f)| f);
    let batch = ignis_core::stream::batch_len(src.pixels() * 16, PREPROCESS_BATCH_BYTES);
    ignis_core::stream::map_in_order(
        frames,
        batch,
        |f| preprocess_frame(f, &plan.pose, pre),
        |f, pr| {
            colour.add(&f, &pr.mask);
            if pr.mask_pixels > 0 {
                lit += 1;
            }
            match sink {
                Sink::Memory(d) => {
                    let j = angles.len();
                    for (r, &v) in pr.train.data().iter().enumerate() {
                        d[(r, j)] = v;
                    }
                }
                Sink::Stream(s, _) => s.write_f32(pr.train.data())?,
            }
            if let Some(w) = fw.as_mut() {
                w.write_f32(pr.frame.data())?;
            }
            masks
                .push(&pr.mask)
                .map_err(|r| EigenError::clip(name, format!("frame {done}: {r}")))?;
            angles.push(pr.angle);
            done += 1;
            progress.inc(1);
            Ok(())
        },
    )?;
    progress.finish_stage();
    if done != plan.frames {
        return Err(EigenError::clip(
            name,
            format!(
                "decoded {done} frames on the second pass, {} on the first",
                plan.frames
            ),
        ));
    }
    if lit == 0 {
        return Err(EigenError::clip(
            name,
            nothing_masked("frame", plan.white, &pre.mask),
        ));
    }
    let frames = match fw {
        Some(w) => {
            w.finish()?;
            Some(writer.entry(&rel)?)
        }
        None => None,
    };
    let masks = writer.write_bytes(&format!("masks/{name}.rle"), &masks.into_bytes())?;
    Ok(ClipFiles {
        frames,
        masks,
        flame_colour: colour.colour(),
    })
}

/// Fits the PCA to the data matrix and projects every training frame: the weights are
/// M×k row-major. Fails when no component is retained.
fn fit(data: DataMatrix, p: &TrainParams, (n, m): (usize, usize)) -> Result<(Pca, Vec<f32>)> {
    let keep = match p.keep {
        None => Keep::All,
        Some(ESelect::Count(k)) => Keep::Count(k),
        Some(ESelect::Variance(v)) => Keep::Variance(v),
    };
    let (pca, weights) = match data {
        DataMatrix::Memory(d) => {
            let opts = PcaOptions {
                keep,
                method: Method::Snapshot,
                memory_limit: p.memory_limit,
            };
            let (pca, w) = Pca::fit_owned_with_weights(d, &opts)?;
            // w: k×M column-major = M×k row-major.
            let k = pca.n_components();
            let mut flat = Vec::with_capacity(k * m);
            for col in 0..m {
                for r in 0..k {
                    flat.push(w[(r, col)]);
                }
            }
            (pca, flat)
        }
        DataMatrix::Streamed(path) => {
            let mut src = ignis_pca::NpySource::open(&path)?;
            let kk = p.streaming_components.min(m.saturating_sub(1)).max(1);
            let opts = ignis_pca::StreamingOptions {
                keep,
                memory_limit: p.memory_limit,
                ..Default::default()
            };
            let pca = ignis_pca::fit_streaming(&mut src, kk, &opts)?;
            drop(src);
            // Project the frames in place from a read-only map of the streamed data.
            let map = npy::mmap_f32(&path)?;
            let all = map.as_slice();
            let mut flat = Vec::with_capacity(pca.n_components() * m);
            for col in 0..m {
                flat.extend(pca.project(&all[col * n..(col + 1) * n]));
            }
            drop(map);
            let _ = std::fs::remove_file(&path);
            (pca, flat)
        }
    };
    if pca.n_components() == 0 {
        return Err(EigenError::NoComponents);
    }
    Ok((pca, weights))
}

/// Writes the arrays and packs of the fitted model and returns the manifest listing them.
#[allow(clippy::too_many_arguments)]
fn write_model(
    writer: &DbWriter,
    clips: &[ClipInput<'_>],
    plans: &[Planned],
    pre: &PreprocessParams,
    p: &TrainParams,
    fitted: &Fitted,
    framing: String,
    progress: &mut dyn Progress,
) -> Result<Manifest> {
    let Fitted {
        pca,
        weights,
        angles,
        frames_files,
    } = fitted;
    let (m, k) = (angles.len(), pca.n_components());
    let ts = pre.training_size();
    let (h, w) = (ts.height as usize, ts.width as usize);
    let mean = writer.write_f32("mean.npy", &pca.mean, &[h, w])?;
    let eigenvalues = writer.write_f64("eigenvalues.npy", &pca.eigenvalues, &[k])?;
    let weights_entry = writer.write_f32("weights.npy", weights, &[m, k])?;
    let angles = writer.write_f32("angles.npy", angles, &[m])?;
    progress.inc(4);
    let packs = writer.write_packs(pca.components.as_ref(), p.pack_size, ts, progress)?;
    let e_detect = p.e_detect.resolve(&pca.eigenvalues, pca.total_variance);
    let e_render = p.e_render.resolve(&pca.eigenvalues, pca.total_variance);
    let wref = faer::MatRef::from_row_major_slice(weights, m, k);
    let mut first_row = 0;
    let mut entries = Vec::new();
    for ((c, plan), ff) in clips.iter().zip(plans).zip(frames_files) {
        let info = c.footage.info();
        entries.push(ClipEntry {
            name: c.spec.name.clone(),
            source: info.source.clone(),
            start: plan.start,
            end: plan.end,
            stride: c.spec.stride,
            fps: info.fps,
            source_size: info.size,
            first_row,
            frames: plan.frames,
            pose: plan.pose,
            thresholds: thresholds(wref, first_row..first_row + plan.frames, e_detect),
            frames_file: ff.frames.clone(),
            mask_file: Some(ff.masks.clone()),
            source_check: db::source_check(&info.source, info.frame_count)?,
            static_lit: Some(plan.static_lit),
            flame_colour: ff.flame_colour,
            crop: c.spec.crop,
        });
        first_row += plan.frames;
    }
    progress.finish_stage();
    Ok(Manifest {
        format: db::FORMAT.into(),
        version: db::VERSION,
        created_by: format!("ignis-eigen {}", env!("CARGO_PKG_VERSION")),
        train_size: ts,
        frame_size: pre.pose.frame(),
        frames: m,
        components: k,
        pack_size: p.pack_size,
        total_variance: pca.total_variance,
        e_detect,
        e_render,
        clips: entries,
        preprocess: pre.clone(),
        mean,
        eigenvalues,
        weights: weights_entry,
        angles,
        packs,
        framing,
    })
}

/// `ignis eigen preprocess`: finds the clip's pose (pass 1) and returns every stage of
/// the pipeline for the training frames whose position in the clip is in `which` (0-based
/// training-frame indices; empty = the first, middle and last).
pub fn preprocess_clip(
    c: &ClipInput<'_>,
    pre: &PreprocessParams,
    which: &[usize],
    progress: &mut dyn Progress,
) -> Result<Vec<(usize, FrameStages)>> {
    pre.validate()?;
    check_name(&c.spec.name)?;
    let (resolved, auto_poses, _) = resolve_sizes(pre, &[c.footage.info().size]);
    let pre = &resolved;
    let plan = plan_clip(c, pre, auto_poses.map(|p| p[0]), progress)?;
    let wanted: Vec<usize> = if which.is_empty() {
        vec![0, plan.frames / 2, plan.frames - 1]
    } else {
        which.to_vec()
    };
    if let Some(&bad) = wanted.iter().find(|&&i| i >= plan.frames) {
        return Err(EigenError::clip(
            &c.spec.name,
            format!(
                "training frame {bad} does not exist ({} training frames)",
                plan.frames
            ),
        ));
    }
    let mut out = Vec::new();
    progress.stage(&format!("stages {}", c.spec.name), wanted.len() as u64);
    for (j, (i, f)) in training_frames(c, plan.start, plan.end)?.enumerate() {
        if wanted.contains(&j) {
            let f = f?;
            out.push((i, preprocess_stages(&f, &plan.pose, pre)));
            progress.inc(1);
        }
        if j >= *wanted.iter().max().expect("non-empty") {
            break;
        }
    }
    progress.finish_stage();
    Ok(out)
}
