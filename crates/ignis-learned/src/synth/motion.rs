//! Model motion of a learned flame: where the flame's texture under each pixel of one
//! rendered frame lies in another.
//!
//! The renderer ([`crate::shape::render_into`]) maps every output pixel through the frame's
//! placement (centroid, tilt, `σ_v` in pixels) and the state's row profiles (path and width
//! of each normalised row) to the flame's canonical coordinates `(u', v)`: `v` up the main
//! axis in `σ_v`, `u'` across it in slice widths. Treating the texture as attached to the
//! flame, a pixel's model motion between two frames is where its canonical point lands
//! under the second frame's warp minus the pixel: the geometry of the learned process
//! (sway, bending, stretching, height) without the change of the texture itself (the
//! eigenflame weights), which a motion-vector blend leaves to its cross-fade.
//!
//! The map is the renderer's, step by step (profiles linear between row centres, clamped
//! at the first and last row, the inverse width interpolated as the renderer does), so a
//! flame that only moves is matched pixel for pixel. A pixel beyond the canonical range
//! (`v` outside `[−below, above]`, `u'` outside `±half_width`), where the renderer draws
//! nothing, moves as the range's nearest point in canonical coordinates does (its
//! coordinates clamped): continuous at the range's edge, and bounded where the map itself
//! is not (a slice width near its floor in one state and wide in the other sends distant
//! pixels thousands of pixels away).

use super::Synthesiser;
use crate::shape::{row_profiles, Placement, Shape, ShapeParams};
use ignis_core::{GrayFrame, Size};

/// How one rendered frame maps its pixels to the flame's canonical coordinates: the
/// state's shape (after controls) and where it was drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct Warp {
    /// Path, widths and height `σ_v` (a fraction of `frame_height`) of the drawn state.
    pub shape: Shape,
    /// Centroid (output pixels) and tilt of the drawing.
    pub place: Placement,
    /// Height of the frame the flame was drawn in, pixels (sets `σ_v` in pixels).
    pub frame_height: f64,
}

/// A warp's per-row tables and transforms, ready to map pixels.
struct Mapper {
    path: Vec<f64>,
    width_inv: Vec<f64>,
    sv: f64,
    place: Placement,
}

impl Mapper {
    fn new(w: &Warp, p: &ShapeParams) -> Mapper {
        let (path, width) = row_profiles(&w.shape, p);
        // the renderer interpolates f32 tables: the same values, in f64
        let path = path.iter().map(|&v| f64::from(v as f32)).collect();
        let width_inv = width.iter().map(|&v| f64::from((1.0 / v) as f32)).collect();
        Mapper {
            path,
            width_inv,
            sv: (w.shape.height * w.frame_height).max(1e-3),
            place: w.place,
        }
    }

    /// Path and inverse width at normalised row coordinate `rr`, as the renderer reads
    /// them: linear between row centres, clamped to the first and last row.
    fn profile(&self, rr: f64) -> (f64, f64) {
        let ns = self.path.len();
        let rc = rr.clamp(0.0, (ns - 1) as f64);
        let r0 = rc as usize;
        let r1 = (r0 + 1).min(ns - 1);
        let t = rc - r0 as f64;
        let lerp = |v: &[f64]| v[r0] + (v[r1] - v[r0]) * t;
        (lerp(&self.path), lerp(&self.width_inv))
    }

    /// `(u, v)` (`σ_v` units about the centroid, `u` across the axis) of the pixel-centre
    /// position `(x, y)`.
    fn uv(&self, x: f64, y: f64) -> (f64, f64) {
        let (s, c) = self.place.tilt.sin_cos();
        let dx = (x - self.place.cx) / self.sv;
        let dy = (y - self.place.cy) / self.sv;
        (dx * c + dy * s, dx * s - dy * c)
    }

    /// The pixel-centre position of `(u, v)`: the inverse of [`Mapper::uv`].
    fn xy(&self, u: f64, v: f64) -> (f64, f64) {
        let (s, c) = self.place.tilt.sin_cos();
        (
            self.place.cx + self.sv * (u * c + v * s),
            self.place.cy + self.sv * (u * s - v * c),
        )
    }
}

/// The model motion from the frame drawn with `from` to the frame drawn with `to` (see the
/// module docs): for each pixel of a `size` frame, row-major, `[dx, dy]` in pixels (+y
/// down) from the pixel to where its canonical point is drawn by `to`. `p` is the model's
/// shape settings (both warps must be of the same model).
pub fn model_motion(p: &ShapeParams, from: &Warp, to: &Warp, size: Size) -> Vec<[f32; 2]> {
    let (a, b) = (Mapper::new(from, p), Mapper::new(to, p));
    let ns = p.norm_size as f64;
    let kr = ns / (p.above + p.below);
    let mut out = Vec::with_capacity(size.pixels());
    for y in 0..size.height {
        let yc = f64::from(y) + 0.5;
        for x in 0..size.width {
            let xc = f64::from(x) + 0.5;
            let (u, v) = a.uv(xc, yc);
            // the canonical point, clamped to the canonical range
            let v = v.clamp(-p.below, p.above);
            let rr = (p.above - v) * kr - 0.5;
            let (pa, wa) = a.profile(rr);
            let across = ((u - pa) * wa).clamp(-p.half_width, p.half_width);
            let (sx, sy) = a.xy(pa + across / wa, v);
            let (pb, wb) = b.profile(rr);
            let (tx, ty) = b.xy(pb + across / wb, v);
            out.push([(tx - sx) as f32, (ty - sy) as f32]);
        }
    }
    out
}

impl Synthesiser<'_> {
    /// The warp of the frame last rendered by [`Synthesiser::next_frame_into`] into a frame
    /// of `size` (the state as drawn, controls applied, and its placement): pass two of
    /// them to [`model_motion`]. Before the first frame, the warp of an all-zero state.
    pub fn warp(&self, size: Size) -> Warp {
        let (shape, _) = self.model.split(&self.shown);
        Warp {
            shape,
            place: self.place(size),
            frame_height: f64::from(size.height),
        }
    }
}

impl Synthesiser<'_> {
    /// Renders into `out` the state half-way in time between the frame last rendered by
    /// [`Synthesiser::next_frame_into`] and the next one (controls as they apply there: the
    /// wind half-way between the two frames'), and returns its warp, without advancing:
    /// the next frame, and [`Synthesiser::warp`], are as without this call. A loop's frame
    /// after its last is its first, so after the last frame this is the frame half-way
    /// across the loop's wrap. For a flipbook's motion vectors: the true in-between frame
    /// of each pair of consecutive frames. Before the first frame, the first frame's
    /// state.
    pub fn between_into(&mut self, out: &mut GrayFrame) -> Warp {
        let size = out.size();
        let (raw, shown) = (self.raw.clone(), self.shown.clone());
        let at = (self.frame as f64 - 0.5).max(0.0);
        if self.looped.is_some() {
            // the loop's own times of the two frames (timing it for this size if needed)
            self.loop_frame_state(size);
            let times = &self.loop_times.as_ref().expect("just timed").1;
            let steps = self.looped.as_ref().map_or(0, |s| s.len()) as f64;
            let n = u64::from(self.loop_frames);
            let b = times[(self.frame % n) as usize];
            let a = times[((self.frame + n - 1) % n) as usize];
            let b = if b < a { b + steps } else { b };
            let tau = if self.frame == 0 { b } else { 0.5 * (a + b) };
            self.set_loop_state(tau);
        } else {
            self.process_state_at(at * self.rate);
        }
        self.render_raw(at, out);
        let warp = self.warp(size);
        (self.raw, self.shown) = (raw, shown);
        warp
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::{render_into, RenderScratch};
    use ignis_core::GrayFrame;

    fn params() -> ShapeParams {
        ShapeParams {
            norm_size: 32,
            ..Default::default()
        }
    }

    fn warp(tilt: f64) -> Warp {
        Warp {
            shape: Shape {
                path: (0..10).map(|i| 0.1 * (i as f64 * 0.7).sin()).collect(),
                width: (0..10).map(|i| 0.4 + 0.03 * i as f64).collect(),
                height: 0.12,
            },
            place: Placement {
                cx: 30.3,
                cy: 35.1,
                tilt,
            },
            frame_height: 64.0,
        }
    }

    fn size() -> Size {
        Size::new(64, 64).unwrap()
    }

    fn max_error(m: &[[f32; 2]], want: impl Fn(usize) -> [f64; 2]) -> f64 {
        m.iter()
            .enumerate()
            .map(|(i, v)| {
                let w = want(i);
                (v[0] as f64 - w[0]).abs().max((v[1] as f64 - w[1]).abs())
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn identical_warps_do_not_move() {
        for tilt in [0.0, 0.2] {
            let w = warp(tilt);
            let m = model_motion(&params(), &w, &w, size());
            assert_eq!(m.len(), 64 * 64);
            assert!(max_error(&m, |_| [0.0; 2]) < 1e-4, "tilt {tilt}");
        }
    }

    /// The path moved by `d` `σ_v` across an upright flame: every pixel moves `d·σ_v`
    /// pixels to the right; moving the placement moves every pixel by as much.
    #[test]
    fn path_and_placement_shifts_are_the_displacement() {
        let a = warp(0.0);
        let d = 0.25;
        let mut b = a.clone();
        b.shape.path.iter_mut().for_each(|v| *v += d);
        let sv = a.shape.height * a.frame_height;
        let m = model_motion(&params(), &a, &b, size());
        assert!(max_error(&m, |_| [d * sv, 0.0]) < 0.01);
        let mut c = a.clone();
        c.place.cx += 3.0;
        c.place.cy -= 1.5;
        let m = model_motion(&params(), &a, &c, size());
        assert!(max_error(&m, |_| [3.0, -1.5]) < 0.01);
    }

    /// Pixels well inside the canonical range of `w`: where an all-ones normalised image
    /// renders at full value.
    fn inside(w: &Warp, p: &ShapeParams) -> Vec<bool> {
        let ones = vec![1.0; (p.norm_size * p.norm_size) as usize];
        let mut f = GrayFrame::new(size());
        render_into(
            &ones,
            &w.shape,
            &w.place,
            p,
            &mut RenderScratch::default(),
            &mut f,
        );
        f.data().iter().map(|&v| v > 0.999).collect()
    }

    /// A taller `σ_v` about the same centroid scales every pixel's offset from it, inside
    /// the flame's canonical range; outside it, pixels move as the range's edge.
    #[test]
    fn a_height_change_scales_about_the_centroid() {
        let a = warp(0.3);
        let mut b = a.clone();
        b.shape.height *= 1.2;
        let m = model_motion(&params(), &a, &b, size());
        let (cx, cy) = (a.place.cx, a.place.cy);
        let inner = inside(&a, &params());
        assert!(
            inner.iter().filter(|&&i| i).count() > 200,
            "a sizeable flame"
        );
        let want = |i: usize| {
            let (x, y) = ((i % 64) as f64 + 0.5, (i / 64) as f64 + 0.5);
            [0.2 * (x - cx), 0.2 * (y - cy)]
        };
        let inside_only: Vec<[f32; 2]> = m
            .iter()
            .zip(&inner)
            .map(|(v, &i)| if i { *v } else { [0.0; 2] })
            .collect();
        let want_inside = |i: usize| if inner[i] { want(i) } else { [0.0; 2] };
        assert!(max_error(&inside_only, want_inside) < 0.01);
        // the farthest corner from the centroid moves less than it would if attached
        let far = m[63 * 64 + 63];
        let would = want(63 * 64 + 63);
        assert!(far[0].hypot(far[1]) < 0.9 * would[0].hypot(would[1]) as f32);
    }

    /// A slice width at its floor in one state and wide in the next: the map sends far
    /// pixels far off, the motion stays within the flame's own extent.
    #[test]
    fn motion_outside_the_flame_stays_bounded() {
        let p = params();
        let mut a = warp(0.0);
        a.shape.width[9] = 0.02;
        let mut b = a.clone();
        b.shape.width[9] = 2.0;
        let m = model_motion(&p, &a, &b, size());
        let reach = 2.0 * p.half_width * 2.0 * a.shape.height * a.frame_height;
        let worst = m.iter().map(|v| v[0].hypot(v[1])).fold(0.0, f32::max);
        assert!(worst.is_finite() && (worst as f64) < reach, "{worst} px");
        assert!(worst > 1.0, "the widening moves the tip ({worst} px)");
    }

    /// Against the renderer: one normalised image drawn by two different shapes
    /// (bent, widened, tilted, moved). The first frame's value at each pixel is the second's
    /// at the pixel plus its model motion, where the flame is lit.
    #[test]
    fn the_renderer_draws_each_point_where_the_motion_says() {
        let p = params();
        let ns = p.norm_size as usize;
        let img: Vec<f32> = (0..ns * ns)
            .map(|i| {
                let (r, c) = ((i / ns) as f32, (i % ns) as f32);
                let e = |v: f32, m: f32| (-(v - m) * (v - m) / 60.0).exp();
                e(r, 14.0) * e(c, 16.0) + 0.5 * e(r, 22.0) * e(c, 12.0)
            })
            .collect();
        let a = warp(0.1);
        let mut b = a.clone();
        b.shape
            .path
            .iter_mut()
            .enumerate()
            .for_each(|(i, v)| *v += 0.03 * i as f64);
        b.shape.width.iter_mut().for_each(|v| *v *= 1.15);
        b.shape.height *= 0.95;
        b.place = Placement {
            cx: 32.8,
            cy: 33.6,
            tilt: -0.05,
        };
        let draw = |w: &Warp| {
            let mut f = GrayFrame::new(size());
            render_into(
                &img,
                &w.shape,
                &w.place,
                &p,
                &mut RenderScratch::default(),
                &mut f,
            );
            f
        };
        let (fa, fb) = (draw(&a), draw(&b));
        let m = model_motion(&p, &a, &b, size());
        let peak = fa.max();
        let mut worst: f32 = 0.0;
        let mut moved: f32 = 0.0;
        for (i, &va) in fa.data().iter().enumerate() {
            if va < 0.2 * peak {
                continue;
            }
            let (x, y) = ((i % 64) as f32, (i / 64) as f32);
            let vb = bilinear(&fb, x + m[i][0], y + m[i][1]);
            worst = worst.max((va - vb).abs());
            moved = moved.max(m[i][0].abs().max(m[i][1].abs()));
        }
        assert!(moved > 2.0, "the test moves the flame ({moved} px)");
        // bilinear reads of a smooth image: small against the peak
        assert!(worst < 0.03 * peak, "worst {worst} of peak {peak}");
    }

    /// A synthesiser's warp is the one its frame was drawn with: drawing the frame's
    /// state again at the warp gives the same pixels (wind and scale on, so the controls
    /// and the base-anchored placement are part of it).
    #[test]
    fn the_synthesisers_warp_redraws_its_frame() {
        let size = Size::new(72, 60).unwrap();
        let model = crate::synthetic::small_model(4);
        let controls = crate::Controls {
            wind: crate::Wind::Constant(0.4),
            scale: 1.3,
            ..Default::default()
        };
        let mut s = Synthesiser::new(&model, controls, 9).unwrap();
        let mut frame = GrayFrame::new(size);
        for _ in 0..3 {
            s.next_frame_into(&mut frame);
        }
        let w = s.warp(size);
        assert_eq!(w.frame_height, 60.0);
        let (_, weights) = model.split(s.shown.as_slice());
        let mut img = vec![0.0; model.pca.n_pixels()];
        model
            .pca
            .reconstruct_into(&weights, weights.len(), &mut img);
        let mut again = GrayFrame::new(size);
        let mut scratch = RenderScratch::default();
        render_into(
            &img,
            &w.shape,
            &w.place,
            &model.shape,
            &mut scratch,
            &mut again,
        );
        let e = super::super::exposure(&model);
        again.data_mut().iter_mut().for_each(|v| *v *= e);
        assert!(frame.max() > 0.0, "a lit frame");
        assert_eq!(frame.data(), again.data());
    }

    /// The frame between two frames is the one a render at twice the rate draws there
    /// (wind as it applies, placement, exposure), and rendering it changes neither the
    /// frames after it nor their warps.
    #[test]
    fn the_frame_between_is_the_one_at_twice_the_rate() {
        let model = crate::synthetic::small_model(2);
        let size = Size::new(48, 40).unwrap();
        let controls = crate::Controls {
            wind: crate::Wind::Constant(0.3),
            ..Default::default()
        };
        let mut once = Synthesiser::new_at(&model, controls.clone(), 5, Some(30.0)).unwrap();
        let mut plain = Synthesiser::new_at(&model, controls.clone(), 5, Some(30.0)).unwrap();
        let mut twice = Synthesiser::new_at(&model, controls, 5, Some(60.0)).unwrap();
        let (mut f, mut g, mut mid) = (
            GrayFrame::new(size),
            GrayFrame::new(size),
            GrayFrame::new(size),
        );
        for k in 0..5 {
            once.next_frame_into(&mut f);
            plain.next_frame_into(&mut g);
            assert_eq!(f.data(), g.data(), "frame {k}");
            assert_eq!(once.warp(size), plain.warp(size));
            twice.next_frame_into(&mut g);
            assert_eq!(f.data(), g.data(), "frame {k} at twice the rate");
            let warp = once.between_into(&mut mid);
            assert_eq!(
                once.warp(size),
                plain.warp(size),
                "the frame's warp is kept"
            );
            twice.next_frame_into(&mut g);
            assert_eq!(mid.data(), g.data(), "between {k} and {}", k + 1);
            assert_eq!(warp, twice.warp(size));
            assert_ne!(mid.data(), f.data());
        }
    }

    /// In a loop the frame after the last is the first: the frame between them is a new
    /// state (not either end), and rendering the frames between leaves the loop's frames
    /// as they were.
    #[test]
    fn a_loop_has_a_frame_across_its_wrap() {
        let model = crate::synthetic::small_model(2);
        let size = Size::new(40, 40).unwrap();
        let n = 6;
        let render = |between: bool| {
            let mut s =
                Synthesiser::looping_at(&model, Default::default(), 3, n, Some(30.0)).unwrap();
            let (mut f, mut m) = (GrayFrame::new(size), GrayFrame::new(size));
            let mut frames = Vec::new();
            let mut mids = Vec::new();
            for _ in 0..n {
                s.next_frame_into(&mut f);
                frames.push(f.clone());
                if between {
                    s.between_into(&mut m);
                    mids.push(m.clone());
                }
            }
            s.next_frame_into(&mut f);
            frames.push(f.clone());
            (frames, mids)
        };
        let (plain, _) = render(false);
        let (frames, mids) = render(true);
        assert_eq!(plain.len(), frames.len());
        for (a, b) in plain.iter().zip(&frames) {
            assert_eq!(a.data(), b.data());
        }
        // frame n is frame 0 again
        assert_eq!(frames[n as usize].data(), frames[0].data());
        let wrap = &mids[n as usize - 1];
        assert!(wrap.max() > 0.0);
        assert_ne!(wrap.data(), frames[0].data());
        assert_ne!(wrap.data(), frames[n as usize - 1].data());
    }

    fn bilinear(f: &GrayFrame, x: f32, y: f32) -> f32 {
        let (x0, y0) = (x.floor(), y.floor());
        let (tx, ty) = (x - x0, y - y0);
        let at = |dx: f32, dy: f32| {
            let (xi, yi) = ((x0 + dx) as i64, (y0 + dy) as i64);
            if xi < 0 || yi < 0 || xi >= f.width() as i64 || yi >= f.height() as i64 {
                0.0
            } else {
                f.data()[yi as usize * f.width() as usize + xi as usize]
            }
        };
        let top = at(0.0, 0.0) * (1.0 - tx) + at(1.0, 0.0) * tx;
        let bot = at(0.0, 1.0) * (1.0 - tx) + at(1.0, 1.0) * tx;
        top * (1.0 - ty) + bot * ty
    }
}
