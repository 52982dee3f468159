//! `ignis-flow`: the workspace's one dense optical flow, and the warps and
//! motion-compensated morphs built on it (loop/transition morphs, motion-vector export).
//!
//! - [`flow`] / [`flow_pair`]: DIS (Kroeger et al., ECCV 2016; see [`mod@dis`]) on grey
//!   frames, computed at a reduced working size (longest side ≤ [`FlowParams::max_side`])
//!   and returned at the first frame's size with the vectors scaled; [`flow_reduced`] /
//!   [`flow_pair_reduced`] return the working-size field (cheaper; every function here
//!   accepts fields of any size).
//! - [`warp_gray`] / [`warp_rgba`]: `out(x) = src(x + t·F(x))`; [`WarpRows`] gives rows of
//!   the colour warp premultiplied, for callers that fuse it into their own row pass.
//! - [`morph_gray`] / [`morph_rgba`]: the in-between frame along both flows;
//!   [`morph_gray_with`] / [`morph_rgba_with`] add optional occlusion-aware weights from
//!   forward–backward consistency ([`MorphParams`]).
//! - [`fill_unseen`]: a field's vectors where its frame's alpha is 0 (a matted frame's
//!   empty background, where DIS has nothing to match) filled smoothly from where it is seen;
//!   [`flow_pair_matted_rgba`]: both flows of a matted pair, filled so.
//! - [`luma`]: the grey input for flow from a colour frame; [`flow_pair_reduced_rgba`] takes
//!   it inside the resize to the working size.
//! - [`motion_vector_pair`]: both flows of a pair kept only where they are reliable
//!   (forward–backward consistent, and explaining the change between the frames), the
//!   input of flipbook motion-vector sheets.
//!
//! Convention: for `flow(a, b)`, `a(x) ≈ b(x + F(x))`, vectors in pixels of the field's
//! own size, pixel centres at integer coordinates, row 0 at the top. Frames are linear
//! light; flow is estimated on the square root of the intensity normalised by the pair's
//! maximum, so dim detail counts as well as the bright core.
//!
//! Why hand-written: the `opencv` crate's DIS would need `libopencv-dev` and clang, and the
//! README promises `cargo test --workspace --release` works with only the Rust toolchain.
//! DIS is small (a pyramid, a per-patch 2×2 Gauss–Newton, a weighted average), fast on a
//! CPU and deterministic when each patch and each output row is computed independently,
//! which is what this crate does: the same inputs give the same bytes on any thread count.
//!
//! **Invariant:** depends on `ignis-core`, `rayon` and `thiserror` only; knows nothing of
//! files, video or generators.

pub mod bench;
pub mod camera;
pub mod dis;
pub mod error;
mod field;
mod fill;
mod image;
mod vectors;
mod warp;

pub use error::{FlowError, Result};
pub use field::FlowField;
pub use fill::fill_unseen;
pub use ignis_core::{GrayFrame, RgbaFrame, Size};
pub use vectors::{motion_vector_pair, VectorParams};
pub use warp::{
    luma, morph_gray, morph_gray_with, morph_rgba, morph_rgba_with, warp_gray, warp_rgba,
    MorphParams, WarpRows, WarpScratch,
};

use image::Img;

/// Parameters of [`flow`]. The defaults suit fire footage and synthetic frames alike.
#[derive(Clone, Debug, PartialEq)]
pub struct FlowParams {
    /// Longest side of the working size, in pixels: larger frames are area-averaged down
    /// to it and the field upsampled back. Range 8..=16384; default 512.
    pub max_side: u32,
    /// Patch side in working pixels. Range 4..=32; default 8.
    pub patch: u32,
    /// Distance between patch origins in working pixels. Range 1..=`patch`; default 4.
    pub stride: u32,
    /// Finest pyramid level computed (0 = the working size, 1 = half of it, …); the field
    /// is upsampled from there. Range 0..=6; default 1.
    pub finest_scale: u32,
    /// Gauss–Newton iterations per patch and scale. Range 1..=200; default 16.
    pub iterations: u32,
    /// Variational refinement sweeps per scale; 0 (the default) turns it off. It lowers
    /// the warp error on footage but not the error of interpolated frames, and costs about
    /// as much as the patch search, so it is opt-in. Range 0..=100.
    pub refine_iterations: u32,
    /// Smoothness weight α of the refinement (intensities scaled to 0..255). Range
    /// (0, 1e6]; default 30.
    pub smoothness: f32,
}

impl Default for FlowParams {
    fn default() -> Self {
        FlowParams {
            max_side: 512,
            patch: 8,
            stride: 4,
            finest_scale: 1,
            iterations: 16,
            refine_iterations: 0,
            smoothness: 30.0,
        }
    }
}

impl FlowParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<()> {
        let range = |name: &'static str, v: u32, lo: u32, hi: u32| {
            if v < lo || v > hi {
                Err(FlowError::bad(
                    name,
                    format!("{v} is outside {lo}..={hi}; the default works for most footage"),
                ))
            } else {
                Ok(())
            }
        };
        range("max_side", self.max_side, 8, ignis_core::frame::MAX_SIDE)?;
        range("patch", self.patch, 4, dis::MAX_PATCH as u32)?;
        range("stride", self.stride, 1, self.patch)?;
        range("finest_scale", self.finest_scale, 0, 6)?;
        range("iterations", self.iterations, 1, 200)?;
        range("refine_iterations", self.refine_iterations, 0, 100)?;
        if !(self.smoothness.is_finite() && self.smoothness > 0.0 && self.smoothness <= 1e6) {
            return Err(FlowError::bad(
                "smoothness",
                format!("{} must be in (0, 1e6]; default 30", self.smoothness),
            ));
        }
        Ok(())
    }

    /// The working size for frames of `size`: longest side at most `max_side`, aspect kept.
    pub fn working_size(&self, size: Size) -> Size {
        let long = size.width.max(size.height);
        if long <= self.max_side {
            return size;
        }
        let s = self.max_side as f64 / long as f64;
        let side = |v: u32| ((v as f64 * s).round() as u32).clamp(1, self.max_side);
        Size {
            width: side(size.width),
            height: side(size.height),
        }
    }

    fn dis(&self) -> dis::Dis {
        dis::Dis {
            patch: self.patch as usize,
            stride: self.stride as usize,
            iterations: self.iterations,
            finest: self.finest_scale,
            refine_iterations: self.refine_iterations,
            smoothness: self.smoothness,
        }
    }
}

/// Checks the pair and returns both frames at the working size, normalised and
/// perceptually compressed to 0..255, or `None` when the pair holds no texture at all.
fn prepare(a: &GrayFrame, b: &GrayFrame, p: &FlowParams) -> Result<(Size, Option<(Img, Img)>)> {
    check_pair(a.size(), b.size(), p)?;
    let ws = p.working_size(a.size());
    let (w, h) = (a.width() as usize, a.height() as usize);
    let (nw, nh) = (ws.width as usize, ws.height as usize);
    let (ia, ib) = rayon::join(
        || image::area_resize(a.data(), w, h, nw, nh),
        || image::area_resize(b.data(), w, h, nw, nh),
    );
    let frames = [a, b];
    finish_prepare(ws, w, (ia, ib), |k| {
        frames[k].data().iter().position(|v| !v.is_finite())
    })
}

/// [`prepare`] of the luminance of two colour frames ([`luma`]), without the full-size grey
/// frames: the same images, bit for bit.
fn prepare_rgba(
    a: &RgbaFrame,
    b: &RgbaFrame,
    p: &FlowParams,
) -> Result<(Size, Option<(Img, Img)>)> {
    check_pair(a.size(), b.size(), p)?;
    let ws = p.working_size(a.size());
    let (w, h) = (a.width() as usize, a.height() as usize);
    let (nw, nh) = (ws.width as usize, ws.height as usize);
    let (ia, ib) = rayon::join(
        || image::area_resize_luma(a.data(), w, h, nw, nh),
        || image::area_resize_luma(b.data(), w, h, nw, nh),
    );
    let frames = [a, b];
    finish_prepare(ws, w, (ia, ib), |k| {
        frames[k]
            .data()
            .iter()
            .position(|v| !warp::luma_of(v).is_finite())
    })
}

/// Checks the parameters and that the frames have one, non-empty size.
fn check_pair(a: Size, b: Size, p: &FlowParams) -> Result<()> {
    p.validate()?;
    if a != b {
        return Err(FlowError::SizeMismatch(format!(
            "flow between a {a} and a {b} frame; resize one so both have the same size"
        )));
    }
    if a.pixels() == 0 {
        return Err(FlowError::bad(
            "frame size",
            format!("{a} has a zero side; frames need at least 1x1 pixels"),
        ));
    }
    Ok(())
}

/// Checks the working-size images for non-finite values (a non-finite pixel leaves a
/// non-finite average, as every covered pixel has a positive weight, so the full frames
/// are searched only then: `bad(k)` finds frame `k`'s first non-finite pixel) and
/// normalises them.
fn finish_prepare(
    ws: Size,
    w: usize,
    (ia, ib): (Img, Img),
    bad: impl Fn(usize) -> Option<usize>,
) -> Result<(Size, Option<(Img, Img)>)> {
    for (k, (name, small)) in [("first", &ia), ("second", &ib)].into_iter().enumerate() {
        if small.data.iter().any(|v| !v.is_finite()) {
            return Err(FlowError::BadInput(match bad(k) {
                Some(i) => format!(
                    "the {name} frame has a NaN or infinite pixel at ({}, {}); clamp or \
                     replace non-finite values before computing flow",
                    i % w,
                    i / w
                ),
                None => format!(
                    "the {name} frame's values overflow when averaged (magnitudes near \
                     {:e}); scale the frame to a sane range first",
                    f32::MAX
                ),
            }));
        }
    }
    let hi = ia
        .data
        .iter()
        .chain(&ib.data)
        .fold(0.0f32, |m, &v| m.max(v));
    if hi <= 1e-12 {
        return Ok((ws, None));
    }
    let k = 1.0 / hi;
    let norm = |img: Img| {
        let data = img
            .data
            .iter()
            .map(|&v| 255.0 * (v.max(0.0) * k).sqrt())
            .collect();
        Img::new(img.w, img.h, data)
    };
    let (ia, ib) = rayon::join(|| norm(ia), || norm(ib));
    Ok((ws, Some((ia, ib))))
}

/// DIS on prepared images, returned at the working size `ws`.
fn dis_field(ia: &Img, ib: &Img, ws: Size, p: &FlowParams) -> FlowField {
    let (fw, fh, v) = dis::dis(ia, ib, &p.dis());
    let f = FlowField::from_parts(
        Size {
            width: fw as u32,
            height: fh as u32,
        },
        v,
    );
    f.resized(ws)
}

/// The flow from `a` to `b` at the working size [`FlowParams::working_size`].
pub fn flow_reduced(a: &GrayFrame, b: &GrayFrame, p: &FlowParams) -> Result<FlowField> {
    let (ws, imgs) = prepare(a, b, p)?;
    Ok(match imgs {
        Some((ia, ib)) => dis_field(&ia, &ib, ws, p),
        None => FlowField::zero(ws),
    })
}

/// The flow from `a` to `b` (`a(x) ≈ b(x + F(x))`) at `a`'s size. `a` and `b` must have
/// the same size ([`FlowError::SizeMismatch`] otherwise) and finite pixels
/// ([`FlowError::BadInput`]). Frames with no texture at all give the zero field.
pub fn flow(a: &GrayFrame, b: &GrayFrame, p: &FlowParams) -> Result<FlowField> {
    Ok(flow_reduced(a, b, p)?.resized(a.size()))
}

/// Both directions `(a→b, b→a)` at the working size, computed in parallel.
pub fn flow_pair_reduced(
    a: &GrayFrame,
    b: &GrayFrame,
    p: &FlowParams,
) -> Result<(FlowField, FlowField)> {
    let (ws, imgs) = prepare(a, b, p)?;
    Ok(dis_pair(ws, imgs, p))
}

/// [`flow_pair_reduced`] of two colour frames' luminance ([`luma`]): the same fields, bit
/// for bit, without building the full-size grey frames (the luminance is taken inside the
/// resize to the working size).
pub fn flow_pair_reduced_rgba(
    a: &RgbaFrame,
    b: &RgbaFrame,
    p: &FlowParams,
) -> Result<(FlowField, FlowField)> {
    let (ws, imgs) = prepare_rgba(a, b, p)?;
    Ok(dis_pair(ws, imgs, p))
}

/// Both directions of DIS between two prepared working images, in parallel; the zero fields
/// when [`prepare`] found no texture.
fn dis_pair(ws: Size, imgs: Option<(Img, Img)>, p: &FlowParams) -> (FlowField, FlowField) {
    match imgs {
        Some((ia, ib)) => rayon::join(|| dis_field(&ia, &ib, ws, p), || dis_field(&ib, &ia, ws, p)),
        None => (FlowField::zero(ws), FlowField::zero(ws)),
    }
}

/// [`flow_pair_reduced_rgba`] of two matted frames, each field then filled over its own
/// frame's keyed-out background ([`fill_unseen`]): where a frame's alpha is 0 DIS has
/// nothing to match, and a morph along the raw vectors would drag the flame's fringe over
/// the empty background in the patch grid's blocks. Fully opaque frames give
/// [`flow_pair_reduced_rgba`]'s fields bit for bit. The flow of the loop closings' and the
/// transitions' morphs.
pub fn flow_pair_matted_rgba(
    a: &RgbaFrame,
    b: &RgbaFrame,
    p: &FlowParams,
) -> Result<(FlowField, FlowField)> {
    let (f, g) = flow_pair_reduced_rgba(a, b, p)?;
    Ok(rayon::join(|| fill_unseen(&f, a), || fill_unseen(&g, b)))
}

/// Both directions `(a→b, b→a)` at `a`'s size, computed in parallel.
pub fn flow_pair(a: &GrayFrame, b: &GrayFrame, p: &FlowParams) -> Result<(FlowField, FlowField)> {
    let (f, g) = flow_pair_reduced(a, b, p)?;
    let size = a.size();
    let (f, g) = rayon::join(|| f.resized(size), || g.resized(size));
    Ok((f, g))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_are_validated() {
        assert!(FlowParams::default().validate().is_ok());
        let bad = [
            FlowParams {
                patch: 2,
                ..Default::default()
            },
            FlowParams {
                patch: 64,
                ..Default::default()
            },
            FlowParams {
                stride: 9,
                ..Default::default()
            },
            FlowParams {
                stride: 0,
                ..Default::default()
            },
            FlowParams {
                max_side: 4,
                ..Default::default()
            },
            FlowParams {
                max_side: u32::MAX,
                ..Default::default()
            },
            FlowParams {
                iterations: 0,
                ..Default::default()
            },
            FlowParams {
                iterations: 100_000,
                ..Default::default()
            },
            FlowParams {
                finest_scale: 40,
                ..Default::default()
            },
            FlowParams {
                smoothness: f32::NAN,
                ..Default::default()
            },
            FlowParams {
                smoothness: 0.0,
                ..Default::default()
            },
        ];
        for p in bad {
            let e = p.validate().unwrap_err();
            assert!(matches!(e, FlowError::BadParameter { .. }), "{e}");
        }
    }

    #[test]
    fn rgba_flow_is_the_flow_of_the_luma() {
        let s = Size::new(700, 300).unwrap();
        let frame = |k: f32| {
            let d = (0..s.pixels())
                .map(|i| {
                    let (x, y) = ((i % 700) as f32, (i / 700) as f32);
                    let v = ((x * 0.05 + k).sin() * (y * 0.07 - k).cos()).abs();
                    [v, 0.5 * v, 0.2, (i % 7) as f32 / 6.0]
                })
                .collect();
            RgbaFrame::from_vec(s, d).unwrap()
        };
        let (a, b) = (frame(0.0), frame(0.4));
        let p = FlowParams::default();
        let want = flow_pair_reduced(&luma(&a), &luma(&b), &p).unwrap();
        assert_eq!(flow_pair_reduced_rgba(&a, &b, &p).unwrap(), want);
        // Small frames (no resize) too, and the same errors.
        let small = FlowParams {
            max_side: 1000,
            ..p.clone()
        };
        let want = flow_pair_reduced(&luma(&a), &luma(&b), &small).unwrap();
        assert_eq!(flow_pair_reduced_rgba(&a, &b, &small).unwrap(), want);
        let mut nan = a.clone();
        nan.set(5, 9, [0.0, f32::NAN, 0.0, 1.0]);
        let e = flow_pair_reduced_rgba(&a, &nan, &p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("(5, 9)") && e.contains("second"), "{e}");
        let other = RgbaFrame::new(Size::new(8, 16).unwrap());
        assert!(matches!(
            flow_pair_reduced_rgba(&a, &other, &p),
            Err(FlowError::SizeMismatch(_))
        ));
    }

    #[test]
    fn working_size_keeps_aspect() {
        let p = FlowParams::default();
        assert_eq!(
            p.working_size(Size::new(1920, 1080).unwrap()),
            Size::new(512, 288).unwrap()
        );
        assert_eq!(
            p.working_size(Size::new(300, 200).unwrap()),
            Size::new(300, 200).unwrap()
        );
        assert_eq!(
            p.working_size(Size::new(16_384, 1).unwrap()),
            Size::new(512, 1).unwrap()
        );
    }

    #[test]
    fn tiny_flat_and_nan_frames_never_panic() {
        let p = FlowParams::default();
        for (w, h) in [(1, 1), (1, 9), (9, 1), (3, 3), (5, 17)] {
            let s = Size::new(w, h).unwrap();
            let a = GrayFrame::from_fn(s, |x, y| ((x * 7 + y * 3) % 5) as f32);
            let b = GrayFrame::from_fn(s, |x, y| ((x * 5 + y * 7) % 4) as f32);
            let f = flow(&a, &b, &p).unwrap();
            assert_eq!(f.size(), s);
            assert!(f
                .data()
                .iter()
                .all(|v| v[0].is_finite() && v[1].is_finite()));
        }
        let s = Size::new(16, 16).unwrap();
        let flat = GrayFrame::new(s);
        assert_eq!(flow(&flat, &flat, &p).unwrap(), FlowField::zero(s));
        let mut nan = GrayFrame::new(s);
        nan.set(3, 2, f32::NAN);
        let e = flow(&flat, &nan, &p).unwrap_err().to_string();
        assert!(e.contains("(3, 2)") && e.contains("second"), "{e}");
        // Values at the edge of f32 are averaged without overflow: a finite field.
        let huge = GrayFrame::from_fn(s, |x, y| if (x + y) % 3 == 0 { f32::MAX } else { 0.0 });
        let small = FlowParams {
            max_side: 8,
            ..p.clone()
        };
        let f = flow(&huge, &flat, &small).unwrap();
        assert!(f
            .data()
            .iter()
            .all(|v| v[0].is_finite() && v[1].is_finite()));
        // Sizes built without `Size::new` (public fields) are refused or passed through.
        let empty = GrayFrame::new(Size {
            width: 0,
            height: 5,
        });
        assert!(flow(&empty, &empty, &p).is_err());
        let ez = FlowField::zero(empty.size());
        assert_eq!(ez.at(1.0, 1.0), [0.0, 0.0]);
        assert_eq!(ez.resized(s), FlowField::zero(s));
        assert_eq!(warp_gray(&empty, &ez, 1.0), empty);
        assert_eq!(morph_gray(&empty, &empty, &ez, &ez, 0.5).unwrap(), empty);
        let mid = morph_rgba_with(
            &flat.to_rgba(),
            &flat.to_rgba(),
            &ez,
            &ez,
            0.5,
            &MorphParams {
                occlusion_px: Some(1.0),
            },
        )
        .unwrap();
        assert_eq!(mid.size(), s);
        assert_eq!(warp_gray(&flat, &ez, 1.0), flat);
        let other = GrayFrame::new(Size::new(8, 16).unwrap());
        assert!(matches!(
            flow(&flat, &other, &p),
            Err(FlowError::SizeMismatch(_))
        ));
    }

    /// A textured flame moving 4 px over a keyed-out surround (alpha 0, noise colours that
    /// the flow cannot match): the matted pair's flow over the surround moves with the
    /// flame, the flame's own vectors are DIS's, and an opaque pair keeps DIS's fields bit
    /// for bit. Without the fill the surround reads 0.
    #[test]
    fn a_matted_pairs_flow_over_a_keyed_out_background_follows_the_flame() {
        let size = Size::new(160, 120).unwrap();
        let mut state = 7u32;
        let mut noise = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let inside =
            |x: f32, y: f32, dx: f32| (x - 60.0 - dx).abs() < 24.0 && (y - 60.0).abs() < 30.0;
        let frame = |dx: f32, surround_alpha: f32, noise: &mut dyn FnMut() -> f32| {
            let data = (0..size.pixels())
                .map(|i| {
                    let (x, y) = ((i % 160) as f32, (i / 160) as f32);
                    if inside(x, y, dx) {
                        let t = 0.5 + 0.4 * ((x - dx) * 0.45).sin() * (y * 0.37).cos();
                        [t, 0.6 * t, 0.2 * t, 1.0]
                    } else {
                        [noise(), noise(), noise(), surround_alpha]
                    }
                })
                .collect();
            RgbaFrame::from_vec(size, data).unwrap()
        };
        let params = FlowParams::default();
        let (a, b) = (frame(0.0, 0.0, &mut noise), frame(4.0, 0.0, &mut noise));
        let (f, _) = flow_pair_matted_rgba(&a, &b, &params).unwrap();
        let raw = flow_pair_reduced_rgba(&a, &b, &params).unwrap().0;
        assert_eq!(f.size(), size, "a small frame's flow is at its own size");
        let mut far = 0;
        for (i, (v, r)) in f.data().iter().zip(raw.data()).enumerate() {
            let (x, y) = ((i % 160) as f32, (i / 160) as f32);
            let (ex, ey) = ((x - 60.0).abs(), (y - 60.0).abs());
            if ex < 23.0 && ey < 29.0 {
                assert_eq!(v, r, "a seen vector is DIS's own at ({x}, {y})");
            } else if ex >= 26.0 || ey >= 32.0 {
                far += 1;
                assert!(
                    (v[0] - 4.0).abs() < 1.0 && v[1].abs() < 1.0,
                    "the keyed-out surround at ({x}, {y}) moves by {v:?}, not with the flame"
                );
            }
        }
        assert!(far > 10_000);
        let (a, b) = (frame(0.0, 1.0, &mut noise), frame(4.0, 1.0, &mut noise));
        let (f, g) = flow_pair_matted_rgba(&a, &b, &params).unwrap();
        let (rf, rg) = flow_pair_reduced_rgba(&a, &b, &params).unwrap();
        assert!(
            f == rf && g == rg,
            "an opaque pair's fields are DIS's, bit for bit"
        );
    }
}
