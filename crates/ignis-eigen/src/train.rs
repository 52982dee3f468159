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
use crate::db::{self, ClipEntry, FileEntry, Manifest, PackEntry};
use crate::error::{EigenError, Result};
use crate::mask::{static_fraction, value8, Isolate, STATIC_LIT};
use crate::pose::{auto_framing, clip_pose, ClipPose};
use crate::preprocess::{
    frame_mask, preprocess_frame, preprocess_stages, FrameStages, PreprocessParams,
};
use crate::synthetic::{synthetic_frame, FlameStyle, SyntheticParams};
use ignis_core::{RgbaFrame, Size};
use ignis_pca::npy::{self, Dtype, NpyWriter};
use ignis_pca::{Keep, Method, Pca, PcaOptions};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A stream of decoded frames; errors are the source's messages.
pub type FrameIter<'a> = Box<dyn Iterator<Item = std::result::Result<RgbaFrame, String>> + 'a>;

/// Where a clip's frames come from: something that can be opened (more than once) at frame
/// 0. The library knows nothing of video files; the CLI wraps `ignis-media` in this.
pub struct ClipSource<'a> {
    /// Description for the manifest (a path or `synthetic:candle`).
    pub source: String,
    pub fps: f64,
    /// Frame size of the source.
    pub size: Size,
    /// Number of frames when known (containers usually say).
    pub frame_count: Option<usize>,
    /// Opens the clip positioned at frame `start` (0-based): the iterator's first item is
    /// frame `start`, or nothing when the clip is shorter.
    pub open: Box<dyn Fn(usize) -> std::result::Result<FrameIter<'a>, String> + 'a>,
}

impl<'a> ClipSource<'a> {
    /// A synthetic clip (see [`crate::synthetic`]), frames made on demand.
    pub fn synthetic(p: SyntheticParams, fps: f64) -> ClipSource<'static> {
        let n = p.frames;
        ClipSource {
            source: crate::synthetic::source_name(&p),
            fps,
            size: p.size,
            frame_count: Some(n),
            open: Box::new(move |start| {
                let p = p.clone();
                Ok(Box::new(
                    (start..p.frames)
                        .map(move |t| synthetic_frame(&p, t).map_err(|e| e.to_string())),
                ) as FrameIter<'static>)
            }),
        }
    }

    /// Frames already in memory.
    pub fn from_frames(source: &str, frames: &'a [RgbaFrame], fps: f64) -> ClipSource<'a> {
        let size = frames.first().map(|f| f.size()).unwrap_or(Size {
            width: 1,
            height: 1,
        });
        ClipSource {
            source: source.into(),
            fps,
            size,
            frame_count: Some(frames.len()),
            open: Box::new(move |start| {
                Ok(Box::new(frames.iter().skip(start).cloned().map(Ok)) as FrameIter<'a>)
            }),
        }
    }
}

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

/// Progress reporting: the workspace's one progress type.
pub use ignis_core::progress::{NoProgress, Progress};

/// A clip with its source, ready to train.
pub struct ClipInput<'a> {
    pub spec: ClipSpec,
    pub source: ClipSource<'a>,
}

/// The two built-in synthetic clips, `candle` and `campfire` (30 fps), that the demo and
/// tests train on so they need no footage.
pub fn synthetic_clips(size: Size, frames: usize, seed: u64) -> Vec<ClipInput<'static>> {
    [
        ("candle", FlameStyle::Candle),
        ("campfire", FlameStyle::Campfire),
    ]
    .into_iter()
    .map(|(name, style)| ClipInput {
        spec: ClipSpec::new(name),
        source: ClipSource::synthetic(
            SyntheticParams {
                size,
                frames,
                style,
                seed,
            },
            30.0,
        ),
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
) -> Result<impl Iterator<Item = (usize, std::result::Result<RgbaFrame, String>)> + 's> {
    let it = (c.source.open)(start).map_err(|reason| EigenError::Decode {
        clip: c.spec.name.clone(),
        reason,
    })?;
    let stride = c.spec.stride;
    Ok(it
        .enumerate()
        .map(move |(i, f)| (i + start, f))
        .take_while(move |(i, _)| *i < end)
        .filter(move |(i, _)| (i - start).is_multiple_of(stride)))
}

/// Checks the clip's range against what is known before decoding; returns `[start, end)`
/// with `end` possibly `usize::MAX` (unknown).
fn plan_range(c: &ClipInput<'_>) -> Result<(usize, usize)> {
    let s = &c.spec;
    if s.stride == 0 {
        return Err(EigenError::clip(&s.name, "stride must be at least 1"));
    }
    if c.source.frame_count == Some(0) {
        return Err(EigenError::clip(
            &s.name,
            format!("{} has zero frames", c.source.source),
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
    if let Some(n) = c.source.frame_count {
        let end = s.end.unwrap_or(n);
        if s.start >= n || end > n {
            return Err(EigenError::clip(
                &s.name,
                format!(
                    "the range {}..{end} goes past the end of {} ({n} frames)",
                    s.start, c.source.source
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
        let f = f.map_err(|reason| EigenError::Decode {
            clip: name.clone(),
            reason: format!("frame {i}: {reason}"),
        })?;
        if count % every == 0 {
            if f.size() != c.source.size {
                return Err(EigenError::clip(
                    name,
                    format!(
                        "frame {i} is {}, the source says {}; a clip must keep one frame size",
                        f.size(),
                        c.source.size
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
        return Err(match c.source.frame_count {
            _ if start > 0 => EigenError::clip(
                name,
                format!(
                    "the range starts at frame {start}, past the end of {}",
                    c.source.source
                ),
            ),
            _ => EigenError::clip(name, format!("{} has zero frames", c.source.source)),
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
                    "the range {start}..{end} goes past the end of {} (only {} frames decoded)",
                    c.source.source,
                    start + (count - 1) * c.spec.stride + 1
                ),
            ));
        }
    }
    let static_lit = static_fraction(&values, pre.mask.isolate_floor);
    let isolate = match pre.mask.isolate {
        Isolate::On => true,
        Isolate::Off => false,
        Isolate::Auto => static_lit > STATIC_LIT,
    };
    let mut pose = match (c.spec.pose, auto_pose) {
        (Some(p), _) => p,
        (None, Some(p)) => p,
        (None, None) => clip_pose(
            name,
            if isolate { &extents_isolated } else { &extents },
            &pre.pose,
        )?,
    };
    pose.isolate = isolate;
    Ok(Planned {
        start,
        end,
        frames: count,
        pose,
        static_lit,
    })
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
/// there is replaced only once the new one is complete).
pub fn train(
    clips: &[ClipInput<'_>],
    pre: &PreprocessParams,
    p: &TrainParams,
    out: &Path,
    progress: &mut dyn Progress,
) -> Result<TrainReport> {
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
    let sizes: Vec<Size> = clips.iter().map(|c| c.source.size).collect();
    let (resolved, auto_poses, framing) = resolve_sizes(pre, &sizes);
    let pre = &resolved;
    pre.validate()?;
    let train_size = pre.training_size();
    let n = train_size.pixels();
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
            plan_clip(c, pre, ap, progress)
        })
        .collect::<Result<Vec<_>>>()?;
    let m: usize = plans.iter().map(|q| q.frames).sum();
    check_memory(n, m, p)?;

    let tmp = db::temp_dir_for(out)?;
    let result = train_into(clips, &plans, pre, p, &tmp, (n, m), &framing, progress);
    match result {
        Ok((manifest, weights)) => {
            progress.stage("commit", 0);
            db::commit_dir(&tmp, out)?;
            progress.finish_stage();
            Ok(TrainReport {
                manifest,
                weights,
                path: out.to_path_buf(),
            })
        }
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            Err(e)
        }
    }
}

fn train_into(
    clips: &[ClipInput<'_>],
    plans: &[Planned],
    pre: &PreprocessParams,
    p: &TrainParams,
    tmp: &Path,
    (n, m): (usize, usize),
    framing: &str,
    progress: &mut dyn Progress,
) -> Result<(Manifest, Vec<f32>)> {
    let frame_size = pre.pose.frame();
    let mut angles = Vec::with_capacity(m);
    let mut frames_files = Vec::new();
    // The data matrix, in memory (column j = training frame j) or on disk (row j).
    let mut data = if p.streaming {
        None
    } else {
        Some(
            ignis_pca::alloc_data_matrix(n, m, &Method::Snapshot, p.memory_limit)
                .map_err(|e| EigenError::LimitExceeded(e.to_string()))?,
        )
    };
    let stream_path = tmp.join("data.tmp.npy");
    let mut stream = if p.streaming {
        Some(NpyWriter::create(&stream_path, Dtype::F32, &[m, n]).map_err(EigenError::npy)?)
    } else {
        None
    };
    let mut j = 0;
    for (c, plan) in clips.iter().zip(plans) {
        let name = &c.spec.name;
        progress.stage(&format!("pre-process {name}"), plan.frames as u64);
        let rel = format!("frames/{name}.npy");
        let mut fw = if p.store_frames {
            Some(
                NpyWriter::create(
                    &tmp.join(&rel),
                    Dtype::F32,
                    &[
                        plan.frames,
                        frame_size.height as usize,
                        frame_size.width as usize,
                    ],
                )
                .map_err(EigenError::npy)?,
            )
        } else {
            None
        };
        let mut done = 0;
        let mut lit = 0;
        for (i, f) in training_frames(c, plan.start, plan.end)? {
            if done == plan.frames {
                break;
            }
            let f = f.map_err(|reason| EigenError::Decode {
                clip: name.clone(),
                reason: format!("frame {i}: {reason}"),
            })?;
            let pr = preprocess_frame(&f, &plan.pose, pre);
            if pr.mask_pixels > 0 {
                lit += 1;
            }
            if let Some(d) = data.as_mut() {
                let col = pr.train.data();
                for (r, &v) in col.iter().enumerate() {
                    d[(r, j)] = v;
                }
            }
            if let Some(s) = stream.as_mut() {
                s.write_f32(pr.train.data()).map_err(EigenError::npy)?;
            }
            if let Some(w) = fw.as_mut() {
                w.write_f32(pr.frame.data()).map_err(EigenError::npy)?;
            }
            angles.push(pr.angle);
            j += 1;
            done += 1;
            progress.inc(1);
        }
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
            return Err(EigenError::clip(name, "the mask removes every pixel in every frame; widen the HSV ranges (e.g. lower the V minimum of [[preprocess.mask.layers]])"));
        }
        if let Some(w) = fw {
            w.finish().map_err(EigenError::npy)?;
            frames_files.push(Some(db::file_entry(tmp, &rel)?));
        } else {
            frames_files.push(None);
        }
    }

    progress.stage("PCA", 0);
    let keep = match p.keep {
        None => Keep::All,
        Some(ESelect::Count(k)) => Keep::Count(k),
        Some(ESelect::Variance(v)) => Keep::Variance(v),
    };
    let pca_err = |e: ignis_pca::PcaError| match e {
        ignis_pca::PcaError::LimitExceeded { .. } => EigenError::LimitExceeded(e.to_string()),
        other => EigenError::Pca(other.to_string()),
    };
    // weights: k×M column-major = M×k row-major.
    let (pca, weights): (Pca, Vec<f32>) = if let Some(d) = data.take() {
        let (pca, w) = Pca::fit_owned_with_weights(
            d,
            &PcaOptions {
                keep,
                method: Method::Snapshot,
                memory_limit: p.memory_limit,
            },
        )
        .map_err(pca_err)?;
        let k = pca.n_components();
        let mut flat = Vec::with_capacity(k * m);
        for col in 0..m {
            for r in 0..k {
                flat.push(w[(r, col)]);
            }
        }
        (pca, flat)
    } else {
        stream
            .take()
            .expect("streaming")
            .finish()
            .map_err(EigenError::npy)?;
        let mut src = ignis_pca::NpySource::open(&stream_path).map_err(pca_err)?;
        let kk = p.streaming_components.min(m.saturating_sub(1)).max(1);
        let opts = ignis_pca::StreamingOptions {
            keep,
            memory_limit: p.memory_limit,
            ..Default::default()
        };
        let pca = ignis_pca::fit_streaming(&mut src, kk, &opts).map_err(pca_err)?;
        let k = pca.n_components();
        drop(src);
        // Project the frames in place from a read-only map of the streamed data.
        let map = npy::mmap_f32(&stream_path).map_err(EigenError::npy)?;
        let all = map.as_slice();
        let mut flat = Vec::with_capacity(k * m);
        for col in 0..m {
            flat.extend(pca.project(&all[col * n..(col + 1) * n]));
        }
        drop(map);
        let _ = std::fs::remove_file(&stream_path);
        (pca, flat)
    };
    progress.finish_stage();
    let k = pca.n_components();
    if k == 0 {
        return Err(EigenError::Pca(
            "no component retained (are all training frames identical?)".into(),
        ));
    }

    let pack_count = k.div_ceil(p.pack_size);
    progress.stage("write", pack_count as u64 + 3);
    let ts = pre.training_size();
    let (h, w) = (ts.height as usize, ts.width as usize);
    npy::write_f32(&tmp.join("mean.npy"), &pca.mean, &[h, w], false).map_err(EigenError::npy)?;
    npy::write_f64(&tmp.join("eigenvalues.npy"), &pca.eigenvalues, &[k], false)
        .map_err(EigenError::npy)?;
    npy::write_f32(&tmp.join("weights.npy"), &weights, &[m, k], false).map_err(EigenError::npy)?;
    npy::write_f32(&tmp.join("angles.npy"), &angles, &[m], false).map_err(EigenError::npy)?;
    progress.inc(3);
    let mut packs = Vec::new();
    for pi in 0..pack_count {
        let first = pi * p.pack_size;
        let count = p.pack_size.min(k - first);
        let rel = format!("packs/pack_{:03}.npy", pi + 1);
        let mut wr = NpyWriter::create(&tmp.join(&rel), Dtype::F32, &[count, h, w])
            .map_err(EigenError::npy)?;
        for i in first..first + count {
            let col = pca.components.col(i);
            let v: Vec<f32> = (0..n).map(|r| col[r]).collect();
            wr.write_f32(&v).map_err(EigenError::npy)?;
        }
        wr.finish().map_err(EigenError::npy)?;
        packs.push(PackEntry {
            entry: db::file_entry(tmp, &rel)?,
            first,
            count,
        });
        progress.inc(1);
    }
    let e_detect = p.e_detect.resolve(&pca.eigenvalues, pca.total_variance);
    let e_render = p.e_render.resolve(&pca.eigenvalues, pca.total_variance);
    let wref = faer::MatRef::from_row_major_slice(&weights, m, k);
    let mut first_row = 0;
    let mut entries = Vec::new();
    for ((c, plan), ff) in clips.iter().zip(plans).zip(frames_files) {
        entries.push(ClipEntry {
            name: c.spec.name.clone(),
            source: c.source.source.clone(),
            start: plan.start,
            end: plan.end,
            stride: c.spec.stride,
            fps: c.source.fps,
            source_size: c.source.size,
            first_row,
            frames: plan.frames,
            pose: plan.pose,
            thresholds: thresholds(wref, first_row..first_row + plan.frames, e_detect),
            frames_file: ff,
            source_check: db::source_check(&c.source.source, c.source.frame_count)?,
            static_lit: Some(plan.static_lit),
        });
        first_row += plan.frames;
    }
    let entry = |f: &str| -> Result<FileEntry> { db::file_entry(tmp, f) };
    let manifest = Manifest {
        format: db::FORMAT.into(),
        version: db::VERSION,
        created_by: format!("ignis-eigen {}", env!("CARGO_PKG_VERSION")),
        train_size: ts,
        frame_size,
        frames: m,
        components: k,
        pack_size: p.pack_size,
        total_variance: pca.total_variance,
        e_detect,
        e_render,
        clips: entries,
        preprocess: pre.clone(),
        mean: entry("mean.npy")?,
        eigenvalues: entry("eigenvalues.npy")?,
        weights: entry("weights.npy")?,
        angles: entry("angles.npy")?,
        packs,
        framing: framing.to_string(),
    };
    let text = serde_json::to_string_pretty(&manifest)
        .map_err(|e| EigenError::bad("manifest", e.to_string()))?;
    let mp = tmp.join("manifest.json");
    std::fs::write(&mp, &text).map_err(|e| EigenError::io(&mp, e))?;
    let sp = tmp.join(db::MANIFEST_SUM);
    std::fs::write(&sp, db::manifest_sum_text(text.as_bytes()))
        .map_err(|e| EigenError::io(&sp, e))?;
    progress.finish_stage();
    Ok((manifest, weights))
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
    let (resolved, auto_poses, _) = resolve_sizes(pre, &[c.source.size]);
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
            let f = f.map_err(|reason| EigenError::Decode {
                clip: c.spec.name.clone(),
                reason: format!("frame {i}: {reason}"),
            })?;
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
