//! Motion vectors for flipbooks: where they come from ([`MotionSource`]), how a sheet
//! stores them (RG, 16 bits, 32768 = no motion) and the engines' frame blend that uses them
//! ([`mv_blend`]), ported from the reference shaders in `engines/`.
//!
//! Convention (Unity VFX Graph's "Flipbook Motion Blend", which Unreal's and SideFX's
//! material functions share): the cell of frame `k` holds the motion of frame `k` per
//! frame, `F_k(x)` (content at `x` moves to about `x + F_k(x)` by the next frame; Ignis
//! writes the velocity, see [`MotionSource`]), in tile-UV units (a fraction of
//! one cell's width and height: the UV range an engine maps onto one sub-image). Between frames `k` and `k+1` at blend `t ∈ [0, 1)`:
//!
//! ```text
//! prev = frame_k    (uv - F_k(uv)     * t)
//! next = frame_k+1  (uv + F_k+1(uv)   * (1 - t))
//! out  = lerp(prev, next, t)
//! ```
//!
//! Stored: `rg = 0.5 + F / (2 * scale)`, so `F = (rg * 2 - 1) * scale`, with `scale` (the
//! material's "motion vector strength") written in the JSON. 16-bit channels put zero
//! motion at exactly 32768 (= 128 in 8 bits, what Unreal users require of empty cells);
//! `rg * 2 - 1` then reads 1.5e-5 × scale, far below a pixel.

use std::fmt;
use std::sync::Arc;

use ignis_core::RgbaFrame;

/// Forward flow between two frames of the same size: one `[dx, dy]` per pixel of `a`
/// (row-major, pixels, +y down) with `a(x) ≈ b(x + F(x))`.
pub type FlowFn = dyn Fn(&RgbaFrame, &RgbaFrame) -> Result<Vec<[f32; 2]>, String> + Send + Sync;

/// Both flows of a pair, `(a→b, b→a)`, each as a [`FlowFn`] gives it.
pub type FlowPairFn =
    dyn Fn(&RgbaFrame, &RgbaFrame) -> Result<(Vec<[f32; 2]>, Vec<[f32; 2]>), String> + Send + Sync;

/// Where a flipbook's motion vectors come from: a dense optical flow (the CLI passes
/// `ignis_flow`), or a generator that knows its own motion. Compared by identity.
///
/// The writer stores each frame's **velocity**: the mean of its forward motion (to the
/// next frame) and its reversed backward motion (from the previous frame), because an
/// engine reads a frame's one vector both when the frame is `prev` of a blend (sampled at
/// `−mv·t`) and when it is `next` (sampled at `+mv·(1−t)`).
#[derive(Clone)]
pub struct MotionSource(pub Arc<FlowPairFn>);

impl MotionSource {
    /// Wraps a one-direction flow function (called twice per pair of frames).
    pub fn new(
        f: impl Fn(&RgbaFrame, &RgbaFrame) -> Result<Vec<[f32; 2]>, String> + Send + Sync + 'static,
    ) -> MotionSource {
        MotionSource(Arc::new(move |a, b| Ok((f(a, b)?, f(b, a)?))))
    }

    /// Wraps a function giving both directions of a pair at once (cheaper when the two
    /// share work, e.g. a forward–backward consistency check).
    pub fn pair(
        f: impl Fn(&RgbaFrame, &RgbaFrame) -> Result<(Vec<[f32; 2]>, Vec<[f32; 2]>), String>
            + Send
            + Sync
            + 'static,
    ) -> MotionSource {
        MotionSource(Arc::new(f))
    }
}

impl fmt::Debug for MotionSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("MotionSource(..)")
    }
}

impl PartialEq for MotionSource {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

/// The 16-bit code of zero motion.
pub const MV_NEUTRAL: u16 = 32768;

/// A frame's velocity: the mean of its flow to the next frame (`ahead`) and its reversed
/// flow to the previous frame (`behind` is the pair (previous, frame)'s backward flow, frame
/// → previous), one side at the ends of a one-shot; `None` without either.
pub fn frame_velocity(
    ahead: Option<&[[f32; 2]]>,
    behind: Option<&[[f32; 2]]>,
) -> Option<Vec<[f32; 2]>> {
    match (ahead, behind) {
        (Some(f), Some(b)) => Some(
            f.iter()
                .zip(b)
                .map(|(f, b)| [0.5 * (f[0] - b[0]), 0.5 * (f[1] - b[1])])
                .collect(),
        ),
        (Some(f), None) => Some(f.to_vec()),
        (None, Some(b)) => Some(b.iter().map(|b| [-b[0], -b[1]]).collect()),
        (None, None) => None,
    }
}

/// Encodes one motion component `m` (tile-UV units) at strength `scale` as 16 bits:
/// `32768 + round(m / scale * 32767)`, clamped to `[1, 65535]` (symmetric around zero).
pub fn encode_mv16(m: f32, scale: f32) -> u16 {
    let q = (m / scale * 32767.0).round().clamp(-32767.0, 32767.0);
    (MV_NEUTRAL as f32 + q) as u16
}

/// Inverse of [`encode_mv16`] (exact for 32768 → 0).
pub fn decode_mv16(v: u16, scale: f32) -> f32 {
    (v as f32 - MV_NEUTRAL as f32) / 32767.0 * scale
}

/// The smallest "nice" strength (1, 2 or 5 × a power of ten, times 1.25 steps) at least
/// `max_abs`, so the largest vector uses most of the 16-bit range; 1e-3 at least.
pub fn mv_scale_for(max_abs: f32) -> f32 {
    let m = max_abs.max(1e-3) as f64;
    let e = m.log10().floor();
    let base = 10f64.powf(e);
    for step in [1.0, 1.25, 1.6, 2.0, 2.5, 3.2, 4.0, 5.0, 6.4, 8.0, 10.0] {
        if base * step >= m {
            return (base * step) as f32;
        }
    }
    (base * 10.0) as f32
}

/// Bilinear sample of a frame at pixel-centre coordinates `(x, y)` (pixel `i` covers
/// `[i, i+1)`, its centre at `i + 0.5`), clamping to the edge (what an extruded padding
/// gives a texture sampler near a cell's border).
pub fn sample_bilinear(frame: &RgbaFrame, x: f32, y: f32) -> [f32; 4] {
    let (w, h) = (frame.width() as i64, frame.height() as i64);
    let fx = x - 0.5;
    let fy = y - 0.5;
    let x0 = fx.floor();
    let y0 = fy.floor();
    let (ax, ay) = (fx - x0, fy - y0);
    let cx = |v: i64| v.clamp(0, w - 1) as usize;
    let cy = |v: i64| v.clamp(0, h - 1) as usize;
    let (x0, y0) = (x0 as i64, y0 as i64);
    let d = frame.data();
    let wu = w as usize;
    let p00 = d[cy(y0) * wu + cx(x0)];
    let p10 = d[cy(y0) * wu + cx(x0 + 1)];
    let p01 = d[cy(y0 + 1) * wu + cx(x0)];
    let p11 = d[cy(y0 + 1) * wu + cx(x0 + 1)];
    let mut out = [0.0; 4];
    for c in 0..4 {
        let top = p00[c] + (p10[c] - p00[c]) * ax;
        let bot = p01[c] + (p11[c] - p01[c]) * ax;
        out[c] = top + (bot - top) * ay;
    }
    out
}

/// The engines' motion-vector frame blend (see the module docs), in pixels: `mv_prev` and
/// `mv_next` are the stored motion of `prev` and `next` (per frame, one `[dx, dy]` per
/// pixel, +y down; Ignis stores each frame's velocity), `t` the blend (0 = `prev`,
/// 1 = `next`). The same formula as `engines/*`.
pub fn mv_blend(
    prev: &RgbaFrame,
    next: &RgbaFrame,
    mv_prev: &[[f32; 2]],
    mv_next: &[[f32; 2]],
    t: f32,
) -> RgbaFrame {
    let size = prev.size();
    assert_eq!(next.size(), size, "mv_blend: frames of different sizes");
    assert_eq!(mv_prev.len(), size.pixels(), "mv_blend: mv_prev size");
    assert_eq!(mv_next.len(), size.pixels(), "mv_blend: mv_next size");
    let w = size.width as usize;
    let mut out = RgbaFrame::new(size);
    for (i, o) in out.data_mut().iter_mut().enumerate() {
        let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        let [pu, pv] = mv_prev[i];
        let [nu, nv] = mv_next[i];
        let a = sample_bilinear(prev, x - pu * t, y - pv * t);
        let b = sample_bilinear(next, x + nu * (1.0 - t), y + nv * (1.0 - t));
        for c in 0..4 {
            o[c] = a[c] + (b[c] - a[c]) * t;
        }
    }
    out
}

/// A plain cross-fade of two frames, the blend engines do without motion vectors.
pub fn linear_blend(prev: &RgbaFrame, next: &RgbaFrame, t: f32) -> RgbaFrame {
    let mut out = prev.clone();
    for (o, b) in out.data_mut().iter_mut().zip(next.data()) {
        for c in 0..4 {
            o[c] += (b[c] - o[c]) * t;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::Size;

    #[test]
    fn mv16_roundtrip_and_neutral() {
        assert_eq!(encode_mv16(0.0, 0.05), MV_NEUTRAL);
        assert_eq!(decode_mv16(MV_NEUTRAL, 0.05), 0.0);
        assert_eq!(MV_NEUTRAL >> 8, 128);
        for m in [-0.05f32, -0.0123, 0.0004, 0.049] {
            let back = decode_mv16(encode_mv16(m, 0.05), 0.05);
            assert!((back - m).abs() < 0.05 / 32767.0, "{m} → {back}");
        }
        assert_eq!(encode_mv16(1.0, 0.05), 65535);
        assert_eq!(encode_mv16(-1.0, 0.05), 1);
    }

    #[test]
    fn scale_is_nice_and_covers() {
        for m in [0.0001f32, 0.013, 0.05, 0.051, 0.3, 2.0] {
            let s = mv_scale_for(m);
            assert!(s >= m && s <= m.max(1e-3) * 1.3, "{m} → {s}");
        }
    }

    /// A blob translated by (3, -2) px per frame: the blend at t = 0.5 puts it half-way,
    /// where a cross-fade shows two half-bright copies.
    #[test]
    fn blend_moves_content_half_way() {
        let size = Size::new(32, 32).unwrap();
        let blob = |cx: f32, cy: f32| {
            let px = (0..size.pixels())
                .map(|i| {
                    let (x, y) = ((i % 32) as f32 + 0.5, (i / 32) as f32 + 0.5);
                    let v = (-((x - cx).powi(2) + (y - cy).powi(2)) / 8.0).exp();
                    [v, v, v, 1.0]
                })
                .collect();
            RgbaFrame::from_vec(size, px).unwrap()
        };
        let a = blob(12.0, 16.0);
        let b = blob(15.0, 14.0);
        let truth = blob(13.5, 15.0);
        let mv = vec![[3.0f32, -2.0]; size.pixels()];
        let m = mv_blend(&a, &b, &mv, &mv, 0.5);
        let l = linear_blend(&a, &b, 0.5);
        let err = |f: &RgbaFrame| {
            f.data()
                .iter()
                .zip(truth.data())
                .map(|(p, q)| (p[0] - q[0]).abs())
                .sum::<f32>()
        };
        assert!(err(&m) < 0.1 * err(&l), "{} vs {}", err(&m), err(&l));
        // t = 0 and t = 1 reproduce the key frames exactly.
        let maxdiff = |p: &RgbaFrame, q: &RgbaFrame| {
            p.data()
                .iter()
                .zip(q.data())
                .map(|(x, y)| (x[0] - y[0]).abs())
                .fold(0f32, f32::max)
        };
        assert!(maxdiff(&mv_blend(&a, &b, &mv, &mv, 0.0), &a) < 1e-6);
        assert!(maxdiff(&mv_blend(&a, &b, &mv, &mv, 1.0), &b) < 1e-6);
    }
}
