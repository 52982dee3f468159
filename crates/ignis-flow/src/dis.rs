//! Dense Inverse Search: the flow estimator behind [`crate::flow`].
//!
//! Source: Kroeger, Timofte, Dai, Van Gool, "Fast Optical Flow using Dense Inverse Search",
//! ECCV 2016, §2.1 (inverse search per patch), §2.2 (densification), §2.3 (variational
//! refinement), Alg. 1 (coarse-to-fine loop).
//!
//! Per scale, coarse to fine: a grid of `patch × patch` patches every `stride` pixels is
//! placed on the first image; each patch's displacement starts from the dense field of the
//! coarser scale at its centre and is refined by inverse-compositional Gauss–Newton on
//! zero-mean patches (the Hessian is built once from the first image's gradients); a
//! patch whose final zero-mean SSD is worse than at its start keeps its start. The dense
//! field is the average of the displacements of every patch covering a pixel, each
//! weighted by `1 / max(1, |I1(x + u) − I0(x) − mean residual|)` (intensities scaled to
//! 0..255 as in the paper). An optional light refinement follows at each scale (see
//! `refine`; off by default).
//!
//! Departures from the paper: the brightness is mean-normalised per patch (the paper's
//! optional variant, kept on because fire flickers); the variational refinement is a
//! Horn–Schunck-style Jacobi smoothing with a robust data weight, a few sweeps per scale,
//! instead of the paper's SOR on a gradient-constancy energy: cheaper, and enough to
//! remove the patch grid's blockiness.

use crate::image::Img;
use rayon::prelude::*;

/// Largest supported patch side.
pub(crate) const MAX_PATCH: usize = 32;

/// `x.floor()` for |x| < 2³¹ without a libm call (baseline x86-64 has no `roundss`).
#[inline(always)]
pub(crate) fn ffloor(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// Parameters after validation, in the units the estimator uses.
pub(crate) struct Dis {
    pub patch: usize,
    pub stride: usize,
    pub iterations: u32,
    pub finest: u32,
    pub refine_iterations: u32,
    pub smoothness: f32,
}

/// The dense flow from `i0` to `i1` (same size, intensities ~0..255) at pyramid level
/// `finest` of `i0`, returned with that level's size.
pub(crate) fn dis(i0: &Img, i1: &Img, p: &Dis) -> (usize, usize, Vec<[f32; 2]>) {
    let (w, h) = (i0.w, i0.h);
    let patch = p.patch.min(w).min(h);
    if patch < 2 {
        return (w, h, vec![[0.0; 2]; w * h]);
    }
    // Coarsest scale: about 4 patches across the longest side (as OpenCV's DIS), but never
    // a level whose short side is below the patch.
    let mut coarsest = ((w.max(h) as f64 / (4.0 * patch as f64)).log2() + 0.5)
        .floor()
        .max(0.0) as u32;
    let level_size = |l: u32| -> (usize, usize) {
        let (mut lw, mut lh) = (w, h);
        for _ in 0..l {
            lw = lw.div_ceil(2);
            lh = lh.div_ceil(2);
        }
        (lw, lh)
    };
    while coarsest > 0 && {
        let (lw, lh) = level_size(coarsest);
        lw.min(lh) < patch
    } {
        coarsest -= 1;
    }
    let finest = p.finest.min(coarsest);
    // Pyramids, level 0 = the input.
    let mut p0 = vec![i0.clone()];
    let mut p1 = vec![i1.clone()];
    for l in 1..=coarsest {
        let (lw, lh) = level_size(l);
        let (a, b) = rayon::join(
            || p0[l as usize - 1].area_resize(lw, lh),
            || p1[l as usize - 1].area_resize(lw, lh),
        );
        p0.push(a);
        p1.push(b);
    }
    let mut flow: Vec<[f32; 2]> = Vec::new();
    let mut fsize = (0usize, 0usize);
    for l in (finest..=coarsest).rev() {
        let (a, b) = (&p0[l as usize], &p1[l as usize]);
        let init = if flow.is_empty() {
            vec![[0.0; 2]; a.w * a.h]
        } else {
            upsample(&flow, fsize, (a.w, a.h))
        };
        let (gx, gy) = a.gradients();
        let patches = inverse_search(a, b, &gx, &gy, &init, patch, p.stride, p.iterations);
        let mut dense = densify(a, b, &patches, patch);
        if p.refine_iterations > 0 {
            dense = refine(a, b, &gx, &gy, dense, p.refine_iterations, p.smoothness);
        }
        flow = dense;
        fsize = (a.w, a.h);
    }
    (fsize.0, fsize.1, flow)
}

/// Bilinear resample of a dense field from `from` to `to`, vectors scaled per axis.
pub(crate) fn upsample(f: &[[f32; 2]], from: (usize, usize), to: (usize, usize)) -> Vec<[f32; 2]> {
    let size = |(w, h): (usize, usize)| ignis_core::Size {
        width: w as u32,
        height: h as u32,
    };
    let field = crate::FlowField::from_parts(size(from), f.to_vec());
    field.resized(size(to)).into_vec()
}

/// The patch grid along one axis: `0, stride, 2·stride, …` and a last patch flush with the
/// far edge, so every pixel is covered.
fn grid(n: usize, patch: usize, stride: usize) -> Vec<usize> {
    let last = n - patch;
    let mut v: Vec<usize> = (0..=last).step_by(stride).collect();
    if *v.last().unwrap_or(&usize::MAX) != last {
        v.push(last);
    }
    v
}

/// One patch's result: top-left corner, displacement and mean residual at it.
#[derive(Clone, Copy)]
struct Patch {
    u: [f32; 2],
    mean_res: f32,
}

/// Patch displacements on the grid (row-major over `grid(h) × grid(w)`).
struct Patches {
    xs: Vec<usize>,
    ys: Vec<usize>,
    p: Vec<Patch>,
}

/// Fills `out` (patch × patch) with `img` sampled bilinearly at the patch with top-left
/// `(px, py)` displaced by `u`, edge-clamped. The fractional weights are shared by the
/// whole patch; patches that lie inside the image take a contiguous (vectorisable) path.
#[inline]
fn warp_patch(img: &Img, px: usize, py: usize, u: [f32; 2], patch: usize, out: &mut [f32]) {
    let (w, h) = (img.w as i64, img.h as i64);
    // Displacements are bounded by the caller; clamp anyway so the casts cannot overflow.
    let sx = (px as f32 + u[0]).clamp(-2.0 * MAX_PATCH as f32 - 1.0, w as f32 + 1.0);
    let sy = (py as f32 + u[1]).clamp(-2.0 * MAX_PATCH as f32 - 1.0, h as f32 + 1.0);
    let (fx0, fy0) = (ffloor(sx), ffloor(sy));
    let (fx, fy) = (sx - fx0, sy - fy0);
    let (ix, iy) = (fx0 as i64, fy0 as i64);
    let (w00, w01, w10, w11) = (
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    );
    let p = patch as i64;
    if ix >= 0 && iy >= 0 && ix + p < w && iy + p < h {
        let (ix, iy, w) = (ix as usize, iy as usize, w as usize);
        for (j, o) in out[..patch * patch].chunks_exact_mut(patch).enumerate() {
            let b0 = (iy + j) * w + ix;
            let r0 = &img.data[b0..b0 + patch + 1];
            let r1 = &img.data[b0 + w..b0 + w + patch + 1];
            for k in 0..patch {
                o[k] = w00 * r0[k] + w01 * r0[k + 1] + w10 * r1[k] + w11 * r1[k + 1];
            }
        }
        return;
    }
    let mut cols = [0usize; MAX_PATCH + 1];
    for (k, c) in cols.iter_mut().enumerate().take(patch + 1) {
        *c = (ix + k as i64).clamp(0, w - 1) as usize;
    }
    for j in 0..patch {
        let r0 = img.row((iy + j as i64).clamp(0, h - 1) as usize);
        let r1 = img.row((iy + j as i64 + 1).clamp(0, h - 1) as usize);
        let o = &mut out[j * patch..(j + 1) * patch];
        for k in 0..patch {
            let (c0, c1) = (cols[k], cols[k + 1]);
            o[k] = w00 * r0[c0] + w01 * r0[c1] + w10 * r1[c0] + w11 * r1[c1];
        }
    }
}

fn inverse_search(
    i0: &Img,
    i1: &Img,
    gx: &Img,
    gy: &Img,
    init: &[[f32; 2]],
    patch: usize,
    stride: usize,
    iterations: u32,
) -> Patches {
    let xs = grid(i0.w, patch, stride);
    let ys = grid(i0.h, patch, stride);
    let n = patch * patch;
    let nf = n as f32;
    let max_disp = (i0.w.max(i0.h)) as f32;
    let p: Vec<Patch> = ys
        .par_iter()
        .flat_map_iter(|&py| {
            let xs = &xs;
            // Scratch for one patch, reused along the row.
            let mut t = vec![0.0f32; n];
            let mut tx = vec![0.0f32; n];
            let mut ty = vec![0.0f32; n];
            let mut wb = vec![0.0f32; n];
            xs.iter().map(move |&px| {
                // Template and zero-mean gradients.
                let (mut mx, mut my) = (0.0f32, 0.0f32);
                for j in 0..patch {
                    let o = (py + j) * i0.w + px;
                    t[j * patch..(j + 1) * patch].copy_from_slice(&i0.data[o..o + patch]);
                    tx[j * patch..(j + 1) * patch].copy_from_slice(&gx.data[o..o + patch]);
                    ty[j * patch..(j + 1) * patch].copy_from_slice(&gy.data[o..o + patch]);
                }
                for k in 0..n {
                    mx += tx[k];
                    my += ty[k];
                }
                let (mx, my) = (mx / nf, my / nf);
                let (mut hxx, mut hxy, mut hyy) = (0.0f32, 0.0f32, 0.0f32);
                for k in 0..n {
                    tx[k] -= mx;
                    ty[k] -= my;
                    hxx += tx[k] * tx[k];
                    hxy += tx[k] * ty[k];
                    hyy += ty[k] * ty[k];
                }
                let c = (py + patch / 2).min(i0.h - 1) * i0.w + (px + patch / 2).min(i0.w - 1);
                let start = init[c];
                // Zero-mean SSD of the residual at displacement u.
                let cost = |u: [f32; 2], wb: &mut [f32]| -> (f32, f32) {
                    warp_patch(i1, px, py, u, patch, wb);
                    let mut s = 0.0f32;
                    let mut s2 = 0.0f32;
                    for k in 0..n {
                        let r = wb[k] - t[k];
                        s += r;
                        s2 += r * r;
                    }
                    let m = s / nf;
                    (s2 - s * m, m)
                };
                let det = hxx * hyy - hxy * hxy;
                let tr = hxx + hyy;
                let (c0, m0) = cost(start, &mut wb);
                if !(det > 1e-4 * tr * tr && tr > 1e-3 * nf) {
                    // Textureless patch: no information, keep the coarser estimate.
                    return Patch {
                        u: start,
                        mean_res: m0,
                    };
                }
                let (ixx, ixy, iyy) = (hyy / det, -hxy / det, hxx / det);
                let mut u = start;
                for it in 0..iterations {
                    if it > 0 {
                        warp_patch(i1, px, py, u, patch, &mut wb);
                    }
                    let (mut bx, mut by) = (0.0f32, 0.0f32);
                    for k in 0..n {
                        let r = wb[k] - t[k];
                        bx += tx[k] * r;
                        by += ty[k] * r;
                    }
                    let dx = ixx * bx + ixy * by;
                    let dy = ixy * bx + iyy * by;
                    u = [u[0] - dx, u[1] - dy];
                    if !(u[0].is_finite() && u[1].is_finite())
                        || (u[0] - start[0]).abs() > patch as f32
                        || (u[1] - start[1]).abs() > patch as f32
                        || u[0].abs() > max_disp
                        || u[1].abs() > max_disp
                    {
                        // Diverged: the linearisation does not hold here.
                        return Patch {
                            u: start,
                            mean_res: m0,
                        };
                    }
                    if dx * dx + dy * dy < 1e-4 {
                        break;
                    }
                }
                let (c1, m1) = cost(u, &mut wb);
                if c1 <= c0 {
                    Patch { u, mean_res: m1 }
                } else {
                    Patch {
                        u: start,
                        mean_res: m0,
                    }
                }
            })
        })
        .collect();
    Patches { xs, ys, p }
}

/// Per-pixel photometric-error-weighted average of the covering patches' displacements.
fn densify(i0: &Img, i1: &Img, patches: &Patches, patch: usize) -> Vec<[f32; 2]> {
    let (w, h) = (i0.w, i0.h);
    let mut out = vec![[0.0f32; 2]; w * h];
    let nx = patches.xs.len();
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let mut acc = vec![[0.0f32; 3]; w];
        for (j, &py) in patches.ys.iter().enumerate() {
            if y < py || y >= py + patch {
                continue;
            }
            let r0i = i0.row(y);
            for (k, &px) in patches.xs.iter().enumerate() {
                let p = patches.p[j * nx + k];
                let sx = (px as f32 + p.u[0]).clamp(-(w as f32) - 2.0, 2.0 * w as f32 + 2.0);
                let sy = (y as f32 + p.u[1]).clamp(-(h as f32) - 2.0, 2.0 * h as f32 + 2.0);
                let (fx0, fy0) = (sx.floor(), sy.floor());
                let (fx, fy) = (sx - fx0, sy - fy0);
                let (ix, iy) = (fx0 as i64, fy0 as i64);
                let ra = i1.row(iy.clamp(0, h as i64 - 1) as usize);
                let rb = i1.row((iy + 1).clamp(0, h as i64 - 1) as usize);
                for (q, a) in acc[px..px + patch].iter_mut().enumerate() {
                    let c0 = (ix + q as i64).clamp(0, w as i64 - 1) as usize;
                    let c1 = (ix + q as i64 + 1).clamp(0, w as i64 - 1) as usize;
                    let top = ra[c0] + (ra[c1] - ra[c0]) * fx;
                    let bot = rb[c0] + (rb[c1] - rb[c0]) * fx;
                    let v = top + (bot - top) * fy;
                    let d = (v - r0i[px + q] - p.mean_res).abs();
                    let wt = 1.0 / d.max(1.0);
                    a[0] += wt * p.u[0];
                    a[1] += wt * p.u[1];
                    a[2] += wt;
                }
            }
        }
        for (o, a) in row.iter_mut().zip(&acc) {
            if a[2] > 0.0 {
                *o = [a[0] / a[2], a[1] / a[2]];
            }
        }
    });
    out
}

/// Light variational refinement: `iterations` sweeps, each re-linearising the brightness
/// constancy around the current field (`I1` and its gradients warped by it) and taking one
/// Jacobi step of `min Σ ψ·(Iz + Ix·du + Iy·dv)² + α·|∇(u + du)|²`, with
/// `ψ = 1/√(Iz² + ε²)` a robust (Charbonnier) data weight, `(Ix, Iy)` the mean of both
/// images' gradients and `α = smoothness`. Deterministic: each sweep reads the previous
/// field only.
fn refine(
    i0: &Img,
    i1: &Img,
    gx0: &Img,
    gy0: &Img,
    mut f: Vec<[f32; 2]>,
    iterations: u32,
    smoothness: f32,
) -> Vec<[f32; 2]> {
    let (w, h) = (i0.w, i0.h);
    if w < 3 || h < 3 {
        return f;
    }
    const EPS: f32 = 2.0;
    let (gx1, gy1) = i1.gradients();
    let mut next = vec![[0.0f32; 2]; w * h];
    let (wm, hm) = ((w - 1) as f32, (h - 1) as f32);
    for _ in 0..iterations {
        let fr = &f;
        next.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let up = &fr[y.saturating_sub(1) * w..][..w];
            let dn = &fr[(y + 1).min(h - 1) * w..][..w];
            let me = &fr[y * w..][..w];
            let (r0, rgx, rgy) = (i0.row(y), gx0.row(y), gy0.row(y));
            for (x, o) in row.iter_mut().enumerate() {
                let l = me[x.saturating_sub(1)];
                let r = me[(x + 1).min(w - 1)];
                let c = me[x];
                let ua = 0.25 * (l[0] + r[0] + up[x][0] + dn[x][0]);
                let va = 0.25 * (l[1] + r[1] + up[x][1] + dn[x][1]);
                // Bilinear taps of I1 at x + u, shared by the image and its gradients.
                let sx = (x as f32 + c[0]).clamp(0.0, wm);
                let sy = (y as f32 + c[1]).clamp(0.0, hm);
                let (fx0, fy0) = (ffloor(sx), ffloor(sy));
                let (ax, ay) = (sx - fx0, sy - fy0);
                let (x0, y0) = (fx0 as usize, fy0 as usize);
                let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
                let (i00, i01, i10, i11) = (y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1);
                let bil = |d: &[f32]| {
                    let top = d[i00] + (d[i01] - d[i00]) * ax;
                    let bot = d[i10] + (d[i11] - d[i10]) * ax;
                    top + (bot - top) * ay
                };
                let iz = bil(&i1.data) - r0[x];
                let ix = 0.5 * (rgx[x] + bil(&gx1.data));
                let iy = 0.5 * (rgy[x] + bil(&gy1.data));
                let psi = 1.0 / (iz * iz + EPS * EPS).sqrt();
                let (du, dv) = (ua - c[0], va - c[1]);
                let k = psi * (ix * du + iy * dv + iz) / (smoothness + psi * (ix * ix + iy * iy));
                *o = [ua - ix * k, va - iy * k];
            }
        });
        std::mem::swap(&mut f, &mut next);
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_covers_every_pixel() {
        assert_eq!(grid(20, 8, 4), vec![0, 4, 8, 12]);
        assert_eq!(grid(21, 8, 4), vec![0, 4, 8, 12, 13]);
        assert_eq!(grid(8, 8, 4), vec![0]);
    }

    #[test]
    fn warp_patch_matches_bilinear_sampling() {
        let img = Img::new(9, 7, (0..63).map(|v| ((v * 37) % 11) as f32).collect());
        let mut out = [0.0f32; 16];
        warp_patch(&img, 2, 1, [1.25, -0.5], 4, &mut out);
        for j in 0..4 {
            for k in 0..4 {
                let want = img.sample(2.0 + k as f32 + 1.25, 1.0 + j as f32 - 0.5);
                assert!((out[j * 4 + k] - want).abs() < 1e-5);
            }
        }
        // Far outside: clamped, finite.
        warp_patch(&img, 0, 0, [-1e9, 1e9], 4, &mut out);
        assert!(out.iter().all(|v| v.is_finite()));
    }
}
