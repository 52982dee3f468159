//! Training a flame model from frames, and its small versioned file.
//!
//! Source: stich-magnor-learning-flames.txt §3 (flame model), §3.2 (eigenflames by PCA via
//! `ignis-pca`), §4 (ARP), §5 (skipping frames with several plumes).
//!
//! Data flow: frames are normalised one at a time as they stream in (only the
//! `norm_size²` normalised image and 21 shape values are kept per frame); the normalised
//! images of all usable frames form the PCA data matrix (`norm_size² × M` `f32`, 16 KiB
//! per frame at the default 64²); the state series `[path, width, height, weights]` of the
//! longest run of consecutive usable frames trains the ARP.

use crate::arp::Arp;
use crate::em::{learn, EmParams, EmReport};
use crate::error::{LearnedError, Result};
use crate::moments::Pose;
use crate::shape::{normalise, render_into, Placement, RenderScratch, Shape, ShapeParams, Skip};
use faer::Mat;
use ignis_core::progress::Progress;
use ignis_core::{GrayFrame, Size};
use ignis_pca::{Keep, Pca, PcaOptions};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// The model file format version this build reads and writes.
pub const MODEL_VERSION: u32 = 1;
const MAGIC: &str = "IGNIS-LEARNED-FLAME";
/// Largest model file [`FlameModel::load`] reads (models are a few MB).
pub const MAX_MODEL_BYTES: u64 = 1 << 30;

/// SHA-256 of `bytes`, lowercase hex (the checksum in a model's header line).
fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Settings of [`train`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainParams {
    pub shape: ShapeParams,
    pub em: EmParams,
}

/// The [`Progress`] stage of [`train`] in which frames are normalised (one step a frame;
/// the length is unknown up front: 0).
pub const STAGE_NORMALISE: &str = "normalising";
/// The [`Progress`] stage of [`train`] in which EM runs: one step and one message
/// (`EM iteration <i>: log-likelihood <ll>`) per iteration, at most `max_iterations`.
pub const STAGE_EM: &str = "EM";

/// Counts of what the fit used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitSummary {
    /// Frames read.
    pub frames: usize,
    /// Frames with no flame.
    pub skipped_dark: usize,
    /// Frames with more than one disjoint flame (§5).
    pub skipped_multiple: usize,
    /// First frame index and length of the longest run of consecutive usable frames, on
    /// which the dynamics were learned.
    pub run_start: usize,
    pub run_len: usize,
    /// Fraction of the normalised images' variance the kept eigenflames explain.
    pub explained_variance: f64,
    /// Source frame size.
    pub source_size: Size,
    /// Frame rate of the footage (one process step per footage frame), when known:
    /// synthesis at another output rate resamples the process in time
    /// ([`crate::Synthesiser::new_at`]). Set by the caller that read the footage.
    #[serde(default)]
    pub fps: Option<f64>,
}

/// A trained flame model: shape settings, eigenflames and the learned ARP.
#[derive(Clone, Debug)]
pub struct FlameModel {
    /// Shape settings (`n_eigen` is the number of eigenflames actually kept).
    pub shape: ShapeParams,
    /// Mean normalised image and eigenflames (`norm_size²` pixels).
    pub pca: Pca,
    /// The learned process on the state `[path (N_p), width (N_w), height, weights (N_e)]`.
    pub arp: Arp,
    /// How learning went (likelihood per iteration, stability).
    pub report: EmReport,
    /// What the fit used.
    pub summary: FitSummary,
    /// Mean centroid as a fraction of the frame size, and mean tilt (radians).
    pub placement: Placement,
    /// The last `K` training states (oldest first): where synthesis starts.
    pub init: Vec<Vec<f64>>,
    /// Per-parameter mean and deviation of the training states.
    pub state_mean: Vec<f64>,
    pub state_std: Vec<f64>,
}

/// The result of [`train`]: the model and the fitted training data it came from.
#[derive(Clone, Debug)]
pub struct Training {
    pub model: FlameModel,
    /// Source frame index of each usable frame.
    pub frame_index: Vec<usize>,
    /// Pose of each usable frame.
    pub poses: Vec<Pose>,
    /// State of each usable frame (`[path, width, height, weights]`).
    pub states: Vec<Vec<f64>>,
    /// Indices into `states` of the run the dynamics were learned on.
    pub run: std::ops::Range<usize>,
}

/// Fits the flame model to `frames` and learns its dynamics (§3–§4).
pub fn train(
    frames: impl IntoIterator<Item = GrayFrame>,
    p: &TrainParams,
    progress: &mut dyn Progress,
) -> Result<Training> {
    p.shape.validate()?;
    p.em.validate()?;
    let sp = &p.shape;
    let ns2 = (sp.norm_size * sp.norm_size) as usize;
    let (mut images, mut shapes, mut poses, mut index) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut n_frames, mut dark, mut multi) = (0, 0, 0);
    let mut source_size: Option<Size> = None;
    progress.stage(STAGE_NORMALISE, 0);
    for (i, frame) in frames.into_iter().enumerate() {
        n_frames += 1;
        match source_size {
            None => source_size = Some(frame.size()),
            Some(s) if s != frame.size() => {
                return Err(LearnedError::Unsupported(format!(
                    "frame {i} is {} but earlier frames are {s}; all frames must have one size",
                    frame.size()
                )))
            }
            _ => {}
        }
        match normalise(&frame, sp) {
            Ok(n) => {
                images.push(n.image);
                shapes.push(n.shape);
                poses.push(n.pose);
                index.push(i);
            }
            Err(Skip::Dark) => dark += 1,
            Err(Skip::Multiple) => multi += 1,
        }
        progress.inc(1);
    }
    progress.finish_stage();
    let k = p.em.order;
    // what to do about the skipped frames (the CLI's flags; `keep_multiple` in the API)
    let fix = if multi > 0 {
        "crop to one flame (`--crop X,Y,W,H`) or model the main flame of each frame \
         (`--keep-multiple`)"
    } else {
        "use footage of a single bright flame on a dark background"
    };
    if images.is_empty() {
        return Err(LearnedError::Unsupported(format!(
            "no flame found in {n_frames} frames ({dark} dark, {multi} with several flames); {fix}"
        )));
    }
    // Longest run of consecutive usable frames.
    let (mut best, mut start) = (0..1, 0);
    for j in 1..=index.len() {
        if j == index.len() || index[j] != index[j - 1] + 1 {
            if j - start > best.len() {
                best = start..j;
            }
            start = j;
        }
    }
    if best.len() < k + 2 {
        return Err(LearnedError::Unsupported(format!(
            "only {} consecutive usable frames (of {n_frames}; {dark} dark, {multi} with several flames); \
             an ARP of order {k} needs at least {}: {fix}",
            best.len(),
            k + 2
        )));
    }
    // §3.1: every normalised image gets the clip's average intensity.
    let means: Vec<f64> = images
        .iter()
        .map(|im| im.iter().map(|&v| v as f64).sum::<f64>() / ns2 as f64)
        .collect();
    let avg = means.iter().sum::<f64>() / means.len() as f64;
    for (im, &m) in images.iter_mut().zip(&means) {
        let g = if m > 0.0 { (avg / m) as f32 } else { 1.0 };
        im.iter_mut().for_each(|v| *v *= g);
    }
    // §3.2: eigenflames with ignis-pca.
    let m = images.len();
    let data = Mat::<f32>::from_fn(ns2, m, |i, j| images[j][i]);
    drop(images);
    let opts = PcaOptions {
        keep: Keep::Count(sp.n_eigen),
        ..Default::default()
    };
    let (pca, weights) = Pca::fit_owned_with_weights(data, &opts)
        .map_err(|e| LearnedError::Numerical(format!("eigenflames: {e}")))?;
    let ne = pca.n_components();
    let explained = pca.explained_variance_ratio().iter().sum::<f64>();
    let mut shape = sp.clone();
    shape.n_eigen = ne;
    let states: Vec<Vec<f64>> = (0..m)
        .map(|j| {
            let mut s = shapes[j].to_vec();
            s.extend((0..ne).map(|e| weights[(e, j)] as f64));
            s
        })
        .collect();
    let run_states = &states[best.clone()];
    progress.stage(STAGE_EM, p.em.max_iterations as u64);
    let learned = learn(run_states, &p.em, progress)?;
    progress.finish_stage();
    let n = shape.n_state();
    let state_mean: Vec<f64> = (0..n)
        .map(|i| states.iter().map(|s| s[i]).sum::<f64>() / m as f64)
        .collect();
    let state_std: Vec<f64> = (0..n)
        .map(|i| {
            (states
                .iter()
                .map(|s| (s[i] - state_mean[i]).powi(2))
                .sum::<f64>()
                / m as f64)
                .sqrt()
        })
        .collect();
    let src = source_size.expect("at least one frame");
    let placement = Placement {
        cx: poses.iter().map(|p| p.cx).sum::<f64>() / m as f64 / src.width as f64,
        cy: poses.iter().map(|p| p.cy).sum::<f64>() / m as f64 / src.height as f64,
        tilt: poses.iter().map(|p| p.tilt).sum::<f64>() / m as f64,
    };
    let model = FlameModel {
        shape,
        pca,
        arp: learned.arp,
        report: learned.report,
        summary: FitSummary {
            frames: n_frames,
            skipped_dark: dark,
            skipped_multiple: multi,
            run_start: index[best.start],
            run_len: best.len(),
            explained_variance: explained,
            source_size: src,
            fps: None,
        },
        placement,
        init: run_states[run_states.len() - k..].to_vec(),
        state_mean,
        state_std,
    };
    Ok(Training {
        model,
        frame_index: index,
        poses,
        states,
        run: best,
    })
}

impl FlameModel {
    /// Number of state parameters (26 with the defaults).
    pub fn n_state(&self) -> usize {
        self.shape.n_state()
    }

    /// Splits a state into its shape and eigenflame weights.
    pub fn split(&self, state: &[f64]) -> (Shape, Vec<f32>) {
        let (np, nw) = (self.shape.n_path, self.shape.n_width);
        let shape = Shape {
            path: state[..np].to_vec(),
            width: state[np..np + nw].to_vec(),
            height: state[np + nw],
        };
        let w = state[np + nw + 1..].iter().map(|&v| v as f32).collect();
        (shape, w)
    }

    /// Renders `state` at `place` (output pixels) into `out` (§3 reversed). `normalised`
    /// is scratch of `norm_size²` values.
    pub fn render_state_into(
        &self,
        state: &[f64],
        place: &Placement,
        normalised: &mut Vec<f32>,
        scratch: &mut RenderScratch,
        out: &mut GrayFrame,
    ) {
        let (shape, w) = self.split(state);
        normalised.resize(self.pca.n_pixels(), 0.0);
        self.pca.reconstruct_into(&w, w.len(), normalised);
        render_into(normalised, &shape, place, &self.shape, scratch, out);
    }

    /// The default placement for an output of `size`: the mean training tilt, centred
    /// across, at the mean training centroid's height (as a fraction of the frame) unless
    /// that cuts the mean flame off. Footage is often cropped close to the flame (its base
    /// on the crop's edge) and the output's aspect may differ from the footage's, so the
    /// centroid's fractions alone can put the flame half outside the frame; the mean
    /// flame's extent along its axis ([`FlameModel::mean_extent`]) is kept inside the
    /// frame with a margin of 4% of the frame height (centred when it is taller).
    pub fn placement_for(&self, size: Size) -> Placement {
        self.placement_within(size, self.mean_extent())
    }

    /// [`FlameModel::placement_for`] with the mean flame's extent given (`(below, above)`,
    /// as [`FlameModel::mean_extent`] measures it), for callers that place many frames.
    pub(crate) fn placement_within(&self, size: Size, (below, above): (f64, f64)) -> Placement {
        let h = size.height as f64;
        let sv = self.state_mean[self.shape.n_path + self.shape.n_width] * h;
        let margin = 0.04 * h;
        let (lo, hi) = (margin + above * sv, h - margin - below * sv);
        let cy = self.placement.cy * h;
        Placement {
            cx: 0.5 * size.width as f64,
            cy: if lo <= hi {
                cy.clamp(lo, hi)
            } else {
                0.5 * (lo + hi)
            },
            tilt: self.placement.tilt,
        }
    }

    /// How far the mean flame reaches below and above its centroid along its axis, in
    /// `σ_v`: the outermost rows of the mean normalised image holding at least 2% of the
    /// brightest row's light.
    pub fn mean_extent(&self) -> (f64, f64) {
        let ns = self.shape.norm_size as usize;
        let rows: Vec<f64> = self
            .pca
            .mean
            .chunks(ns)
            .map(|r| r.iter().map(|&v| v.max(0.0) as f64).sum())
            .collect();
        let peak = rows.iter().copied().fold(0.0, f64::max);
        let lit: Vec<usize> = (0..rows.len())
            .filter(|&r| peak > 0.0 && rows[r] >= 0.02 * peak)
            .collect();
        match (lit.first(), lit.last()) {
            (Some(&top), Some(&bottom)) => (
                -self.shape.row_v(bottom as f64 + 0.5),
                self.shape.row_v(top as f64 - 0.5),
            ),
            _ => (self.shape.below, self.shape.above),
        }
    }

    /// Eigenflame `e` (0 = the mean image) as a frame scaled to `0..=1` for viewing.
    pub fn eigenflame_image(&self, e: usize) -> Option<GrayFrame> {
        let ns = self.shape.norm_size;
        let v: Vec<f32> = if e == 0 {
            self.pca.mean.clone()
        } else if e <= self.pca.n_components() {
            (0..self.pca.n_pixels())
                .map(|i| self.pca.components[(i, e - 1)])
                .collect()
        } else {
            return None;
        };
        let (lo, hi) = v
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        let (lo, span) = if e == 0 {
            (0.0, hi.max(1e-12))
        } else {
            (lo, (hi - lo).max(1e-12))
        };
        GrayFrame::from_vec(
            Size {
                width: ns,
                height: ns,
            },
            v.iter().map(|x| (x - lo) / span).collect(),
        )
        .ok()
    }

    /// Writes the model atomically (temporary file in the same folder, then rename).
    /// Format: one line `IGNIS-LEARNED-FLAME <version>`, then JSON.
    pub fn save(&self, path: &Path) -> Result<()> {
        let file = ModelFile {
            shape: self.shape.clone(),
            mean: self.pca.mean.clone(),
            eigenflames: (0..self.pca.n_components())
                .map(|e| {
                    (0..self.pca.n_pixels())
                        .map(|i| self.pca.components[(i, e)])
                        .collect()
                })
                .collect(),
            eigenvalues: self.pca.eigenvalues.clone(),
            total_variance: self.pca.total_variance,
            n_samples: self.pca.n_samples,
            arp: self.arp.clone(),
            report: self.report.clone(),
            summary: self.summary.clone(),
            placement: self.placement,
            init: self.init.clone(),
            state_mean: self.state_mean.clone(),
            state_std: self.state_std.clone(),
        };
        let io = |source| LearnedError::Io {
            path: path.to_path_buf(),
            source,
        };
        let body = serde_json::to_vec(&file)
            .map_err(|e| LearnedError::Numerical(format!("serialising: {e}")))?;
        // Written beside the target and renamed (ignis_core::atomic): a failure leaves the
        // old model, or none.
        ignis_core::atomic::check_regular_target(path)
            .map_err(|e| LearnedError::bad("output", e.to_string()))?;
        ignis_core::atomic::write_file(path, |f| {
            f.write_all(
                format!("{MAGIC} {MODEL_VERSION} sha256:{}\n", sha256_hex(&body)).as_bytes(),
            )?;
            f.write_all(&body)
        })
        .map_err(io)
    }

    /// Reads a model written by [`FlameModel::save`]; a file of another format version is
    /// a [`LearnedError::BadModelFile`] naming both versions.
    pub fn load(path: &Path) -> Result<FlameModel> {
        let bad = |reason: String| LearnedError::BadModelFile {
            path: path.to_path_buf(),
            reason,
        };
        let ioerr = |source| LearnedError::Io {
            path: path.to_path_buf(),
            source,
        };
        ignis_core::atomic::record_input(path);
        // Only a regular file, opened without blocking (a FIFO would hang a read), and of
        // a bounded size.
        let bytes = ignis_core::textfile::read_bytes(path, MAX_MODEL_BYTES).map_err(|e| {
            use std::io::ErrorKind;
            match e.kind() {
                ErrorKind::NotFound => ioerr(ignis_core::textfile::explain_missing(
                    e,
                    "there is no such model; check the path (a model is the .flame file \
                     `ignis learned train ... -o FILE` writes)",
                )),
                ErrorKind::IsADirectory => bad(
                    "a directory, not a model: a model is the .flame file `ignis learned train \
                     FOOTAGE -o FILE` writes"
                        .into(),
                ),
                ErrorKind::InvalidInput | ErrorKind::InvalidData => bad(e.to_string()),
                _ => ioerr(e),
            }
        })?;
        let nl = bytes
            .iter()
            .position(|&b| b == b'\n')
            .unwrap_or(bytes.len().min(64));
        let head = String::from_utf8_lossy(&bytes[..nl]);
        let mut parts = head.split_whitespace();
        if parts.next() != Some(MAGIC) {
            return Err(bad(format!(
                "not an Ignis learned-flame model (no `{MAGIC}` header); a model is the \
                 .flame file `ignis learned train FOOTAGE -o FILE` writes from footage"
            )));
        }
        let version: u32 = parts
            .next()
            .and_then(|v| v.parse().ok())
            .ok_or_else(|| bad("the header has no version number".into()))?;
        if version != MODEL_VERSION {
            return Err(bad(format!(
                "format version {version}, but this build of Ignis reads version {MODEL_VERSION}; \
                 retrain it with `ignis learned train`"
            )));
        }
        let body = bytes.get(nl + 1..).unwrap_or_default();
        let want = parts
            .next()
            .and_then(|t| t.strip_prefix("sha256:"))
            .ok_or_else(|| {
                bad(
                    "the header has no checksum (written by an older Ignis?); retrain it with \
                     `ignis learned train`"
                        .into(),
                )
            })?;
        let got = sha256_hex(body);
        if got != want {
            return Err(bad(format!(
                "checksum mismatch (corrupt or edited): sha256 {got}, the header says {want}; \
                 restore the file or retrain it with `ignis learned train`"
            )));
        }
        let f: ModelFile =
            serde_json::from_slice(body).map_err(|e| bad(format!("corrupt model body: {e}")))?;
        if let Some(fps) = f.summary.fps {
            if !(fps > 0.0 && fps <= 1000.0) {
                return Err(bad(format!(
                    "footage frame rate {fps} is outside (0, 1000]"
                )));
            }
        }
        if f.arp.order() == 0 {
            return Err(bad(
                "the ARP has order 0 (no dynamics to synthesise from); retrain the model".into(),
            ));
        }
        f.shape.validate()?;
        let (ns2, ne, n) = (
            (f.shape.norm_size * f.shape.norm_size) as usize,
            f.eigenflames.len(),
            f.shape.n_state(),
        );
        if f.mean.len() != ns2
            || f.eigenflames.iter().any(|e| e.len() != ns2)
            || ne != f.shape.n_eigen
            || f.arp.dim() != n
            || f.arp.a.iter().any(|a| a.len() != n * n)
            || f.arp.b.len() != n * n
            || f.init.len() != f.arp.order()
            || f.init.iter().any(|x| x.len() != n)
            || f.state_mean.len() != n
            || f.state_std.len() != n
        {
            return Err(bad("inconsistent sizes inside the model".into()));
        }
        let components = Mat::from_fn(ns2, ne, |i, e| f.eigenflames[e][i]);
        let pca = Pca {
            mean: f.mean,
            components,
            eigenvalues: f.eigenvalues,
            total_variance: f.total_variance,
            n_samples: f.n_samples,
        };
        Ok(FlameModel {
            shape: f.shape,
            pca,
            arp: f.arp,
            report: f.report,
            summary: f.summary,
            placement: f.placement,
            init: f.init,
            state_mean: f.state_mean,
            state_std: f.state_std,
        })
    }
}

/// On-disk body of a model (after the header line).
#[derive(Serialize, Deserialize)]
struct ModelFile {
    shape: ShapeParams,
    mean: Vec<f32>,
    eigenflames: Vec<Vec<f32>>,
    eigenvalues: Vec<f64>,
    total_variance: f64,
    n_samples: usize,
    arp: Arp,
    report: EmReport,
    summary: FitSummary,
    placement: Placement,
    init: Vec<Vec<f64>>,
    state_mean: Vec<f64>,
    state_std: Vec<f64>,
}

impl Training {
    /// Renders the fitted state of usable frame `j` at its own pose (for the
    /// reproduction check): the inverse of the normalisation, at the source size.
    pub fn render_fitted(&self, j: usize) -> GrayFrame {
        let m = &self.model;
        let mut out = GrayFrame::new(m.summary.source_size);
        let pose = &self.poses[j];
        let place = Placement {
            cx: pose.cx,
            cy: pose.cy,
            tilt: pose.tilt,
        };
        m.render_state_into(
            &self.states[j],
            &place,
            &mut Vec::new(),
            &mut RenderScratch::default(),
            &mut out,
        );
        out
    }
}
