//! The headline timings of `ignis bench flow` (the issues' speed goals), on seeded
//! synthetic textured pairs related by a known translation, so each timing comes with the
//! accuracy of what was timed.

use crate::{flow, flow_pair_reduced, luma, morph_rgba, FlowParams};
use ignis_core::{GrayFrame, RgbaFrame, Rng, Size};
use std::time::Instant;

/// Goal: flow of a 512×512 pair, in ms.
pub const GOAL_FLOW_512_MS: f64 = 15.0;
/// Goal: flow of a 1920×1080 pair (reduced size + upsample), in ms.
pub const GOAL_FLOW_1080P_MS: f64 = 60.0;
/// Goal: motion-compensated mid frame of a 1920×1080 RGBA pair (both flows, warps and
/// blend), in ms.
pub const GOAL_MORPH_1080P_MS: f64 = 50.0;

/// One timed case: the median and minimum over the repetitions, and the mean error of
/// the recovered translation (px, at the frames' size).
#[derive(Clone, Debug)]
pub struct Timing {
    pub name: &'static str,
    pub size: Size,
    pub median_ms: f64,
    pub min_ms: f64,
    pub goal_ms: f64,
    pub mean_error_px: f64,
}

impl Timing {
    /// Whether the median meets the goal.
    pub fn goal_met(&self) -> bool {
        self.median_ms <= self.goal_ms
    }
}

/// A smooth seeded random texture (sum of 12 sinusoids, wavelengths `k`·6..40 px)
/// evaluated at `(x − d.x, y − d.y)`, values about 0.1..1: the same picture moved by `d`.
pub fn texture(size: Size, seed: u64, d: [f32; 2], k: f32) -> GrayFrame {
    let mut rng = Rng::new(seed);
    let waves: Vec<[f32; 4]> = (0..12)
        .map(|_| {
            let lambda = k * rng.uniform(6.0, 40.0) as f32;
            let angle = rng.uniform(0.0, std::f64::consts::TAU) as f32;
            let kk = std::f32::consts::TAU / lambda;
            [
                kk * angle.cos(),
                kk * angle.sin(),
                rng.uniform(0.0, std::f64::consts::TAU) as f32,
                rng.uniform(0.5, 1.0) as f32,
            ]
        })
        .collect();
    let norm: f32 = waves.iter().map(|w| w[3]).sum();
    GrayFrame::from_fn(size, |x, y| {
        let (px, py) = (x as f32 - d[0], y as f32 - d[1]);
        let s: f32 = waves
            .iter()
            .map(|w| w[3] * (w[0] * px + w[1] * py + w[2]).sin())
            .sum();
        0.55 + 0.45 * s / norm
    })
}

/// A fire-coloured RGBA version of a grey texture (for the colour morph).
fn colour(g: &GrayFrame) -> RgbaFrame {
    let data = g
        .data()
        .iter()
        .map(|&v| [v * 1.2, v * v * 0.8, v * v * v * 0.4, 1.0])
        .collect();
    RgbaFrame::from_vec(g.size(), data).expect("same size")
}

fn time<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, f64, T) {
    let mut out = f(); // warm-up (page faults, thread pool start)
    let mut ms = Vec::with_capacity(reps);
    for _ in 0..reps {
        let t = Instant::now();
        out = f();
        ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    ms.sort_by(|a, b| a.total_cmp(b));
    (ms[ms.len() / 2], ms[0], out)
}

fn mean_error(f: &crate::FlowField, d: [f32; 2]) -> f64 {
    let m = f.mean();
    ((m[0] - d[0] as f64).powi(2) + (m[1] - d[1] as f64).powi(2)).sqrt()
}

/// Times the three goal cases with default parameters; `quick` uses 3 repetitions
/// instead of 15.
pub fn figures(quick: bool) -> crate::Result<Vec<Timing>> {
    let reps = if quick { 3 } else { 15 };
    let p = FlowParams::default();
    let mut out = Vec::new();

    let s512 = Size::new(512, 512)?;
    let d = [2.5, -1.5];
    let (a, b) = (texture(s512, 1, [0.0; 2], 1.5), texture(s512, 1, d, 1.5));
    let (med, min, f) = time(reps, || flow(&a, &b, &p));
    out.push(Timing {
        name: "flow_512",
        size: s512,
        median_ms: med,
        min_ms: min,
        goal_ms: GOAL_FLOW_512_MS,
        mean_error_px: mean_error(&f?, d),
    });

    let hd = Size::new(1920, 1080)?;
    let d = [7.5, -4.0];
    let (a, b) = (texture(hd, 2, [0.0; 2], 4.0), texture(hd, 2, d, 4.0));
    let (med, min, f) = time(reps, || flow(&a, &b, &p));
    out.push(Timing {
        name: "flow_1080p",
        size: hd,
        median_ms: med,
        min_ms: min,
        goal_ms: GOAL_FLOW_1080P_MS,
        mean_error_px: mean_error(&f?, d),
    });

    let (ca, cb) = (colour(&a), colour(&b));
    let (med, min, r) = time(reps, || -> crate::Result<_> {
        let (la, lb) = rayon::join(|| luma(&ca), || luma(&cb));
        let (f, g) = flow_pair_reduced(&la, &lb, &p)?;
        let mid = morph_rgba(&ca, &cb, &f, &g, 0.5)?;
        Ok((f, mid))
    });
    let (f, _) = r?;
    let scale = hd.width as f32 / f.size().width as f32;
    out.push(Timing {
        name: "morph_1080p",
        size: hd,
        median_ms: med,
        min_ms: min,
        goal_ms: GOAL_MORPH_1080P_MS,
        mean_error_px: mean_error(&f, [d[0] / scale, d[1] / scale]) * scale as f64,
    });
    Ok(out)
}

/// How well the motion-compensated mid frame of `(a, b)` predicts the real frame `mid`
/// between them, against the plain 50/50 blend: mean absolute error of the grey
/// (alpha-weighted luma) frames, linear light.
#[derive(Clone, Copy, Debug)]
pub struct MidFrameError {
    pub morph_mae: f64,
    pub blend_mae: f64,
}

impl MidFrameError {
    /// `morph_mae / blend_mae`: below 1 means the morph predicts the real frame better.
    pub fn ratio(&self) -> f64 {
        self.morph_mae / self.blend_mae.max(1e-12)
    }
}

/// The errors of [`MidFrameError`] for three consecutive frames `a, mid, b`.
pub fn mid_frame_error(
    a: &RgbaFrame,
    mid: &RgbaFrame,
    b: &RgbaFrame,
    p: &FlowParams,
) -> crate::Result<MidFrameError> {
    let (la, lm, lb) = (luma(a), luma(mid), luma(b));
    if la.size() != lm.size() || la.size() != lb.size() {
        return Err(crate::FlowError::SizeMismatch(format!(
            "frames of {}, {} and {}; give three frames of one clip",
            la.size(),
            lm.size(),
            lb.size()
        )));
    }
    let (f, g) = flow_pair_reduced(&la, &lb, p)?;
    let m = crate::morph_gray(&la, &lb, &f, &g, 0.5)?;
    let n = lm.data().len() as f64;
    let mut em = 0.0f64;
    let mut eb = 0.0f64;
    for (((&x, &y), &z), &t) in m.data().iter().zip(la.data()).zip(lb.data()).zip(lm.data()) {
        em += (x - t).abs() as f64;
        eb += (0.5 * (y + z) - t).abs() as f64;
    }
    Ok(MidFrameError {
        morph_mae: em / n,
        blend_mae: eb / n,
    })
}
