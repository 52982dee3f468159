//! The joins' colour in-between ([`super::inbetween_rgba`]) at full resolution in two row
//! passes with no full-size intermediate, so a 1080p in-between costs little more than the
//! plain morph.
//!
//! It computes what [`super::detail_blend_rgba`] of the two warped frames computes (the
//! module doc of `morph`): both frames `a`, `b` warped along the flow, the local mean `ma`,
//! `mb` of each from its block means (blocks of `k = r / 4`, box mean of radius `r / k`,
//! bilinear upsampling), and per premultiplied pixel
//! `s·ma + t·mb + g·(s(a − ma) + t(b − mb)) = g·P + (1 − g)·(s·ma + t·mb)` with `P = s·a + t·b`
//! the plain blend and one gain `g` per frame from the detail energies
//! `Σ(a − ma)²`, `Σ(b − mb)²`, `Σ(s(a − ma) + t(b − mb))²`. Only the order of work changes:
//! 1. per band of `k` rows (kept in the cache): both warps, the band's block means, `P`
//!    written to the output, and per block the gain is estimated from (`super::gain_rows`:
//!    every `stride`-th along diagonals) the sums the energies need (below);
//! 2. the box means of the small frames, the energies from the per-block sums, the gain;
//! 3. per row, in place: `g·P` plus the upsampled `(1 − g)(s·Sa + t·Sb)` (upsampling is
//!    linear, so one mean row instead of two), unpremultiplied.
//!
//! **Energies without a second look at the pixels.** In block `β` with block mean `c`, write
//! `q = a − c` (so `Σq = 0` there) and the local mean `ma(x) = Σₙ wₙ(x)·Sₙ` (bilinear
//! weights `w` on the box-mean nodes `S`, `Σₙ wₙ = 1`), so `a − ma = q − Σₙ wₙ·Eₙ` with
//! `Eₙ = Sₙ − c`. Then `Σ_β (a − ma)² = Σq² − 2 Σₙ Eₙ·Aₙ + Eᵀ G E`, with `Aₙ = Σ_β wₙ q` and the
//! weights' Gram matrix `G = Σ_β w wᵀ` (separable: the 3 × 3 column and row Grams of the
//! 3 × 3 nodes a block's pixels touch); likewise the cross term `Σ(a − ma)(b − mb)`, and
//! `Σ(s(a − ma) + t(b − mb))² = s²ea + t²eb + 2st·cross`. Pass 1 gathers `Σq²` and the `A`
//! per block while the band is in the cache; centring on the block mean keeps the sums the
//! size of the detail, so the difference of sums loses no precision worth mentioning.
//!
//! Differences from the reference: rounding (the sums are grouped per block, f32 within a
//! block row, f64 across), and pixels whose warped alpha is at most 1e-8 keep their
//! premultiplied colour instead of 0 (the reference unpremultiplies in between) — within
//! 1e-4 of the reference on every premultiplied channel (tested). Every sum runs in a fixed
//! order and rows are independent, so the result does not depend on the thread count.

use std::time::{Duration, Instant};

use ignis_core::{RgbaFrame, Size};
use ignis_flow::{FlowField, WarpRows};
use rayon::prelude::*;

use super::{box_mean, detail_radius};

/// Wall time of each pass of one in-between (see the module doc).
pub type Stages = [(&'static str, Duration); 3];

/// 3 × 3 values per channel: one per node a block's pixels touch (rows, then columns).
type Nodes = [[[f32; 4]; 3]; 3];

/// What pass 1 keeps per block: `Σq²` of a and b and `Σ qa·qb` (all channels), and the
/// node sums `A` of a and b.
#[derive(Clone, Copy, Default)]
struct BlockSums {
    qq: [f64; 3],
    aa: Nodes,
    ab: Nodes,
}

/// Where the bilinear mean upsampling reads, per column and per row: the two nodes and the
/// weight of the second; and the 3 × 3 Gram matrix of each block column and block row.
struct Grid {
    w: usize,
    k: usize,
    sw: usize,
    sh: usize,
    xs: Vec<(usize, usize, f32)>,
    /// Per column, its weights on the nodes left and right of its own block's (slots 0 and
    /// 2 of [`slot_weights`]; the middle one is 1 minus both).
    side: Vec<[f32; 2]>,
    ys: Vec<(usize, usize, f32)>,
    gx: Vec<[[f64; 3]; 3]>,
    gy: Vec<[[f64; 3]; 3]>,
}

impl Grid {
    fn new(size: Size, small: Size, k: usize) -> Grid {
        let (w, h) = (size.width as usize, size.height as usize);
        let (sw, sh) = (small.width as usize, small.height as usize);
        let xs: Vec<_> = (0..w).map(|x| coord(x, sw, k)).collect();
        let ys: Vec<_> = (0..h).map(|y| coord(y, sh, k)).collect();
        let gram = |cs: &[(usize, usize, f32)], n: usize| -> Vec<[[f64; 3]; 3]> {
            (0..n)
                .map(|b| {
                    let mut g = [[0.0f64; 3]; 3];
                    for &c in &cs[b * k..((b + 1) * k).min(cs.len())] {
                        let v = slot_weights(c, b);
                        for (gi, &vi) in g.iter_mut().zip(&v) {
                            for (gij, &vj) in gi.iter_mut().zip(&v) {
                                *gij += f64::from(vi) * f64::from(vj);
                            }
                        }
                    }
                    g
                })
                .collect()
        };
        let (gx, gy) = (gram(&xs, sw), gram(&ys, sh));
        let side = (0..w)
            .map(|x| {
                let v = slot_weights(xs[x], x / k);
                [v[0], v[2]]
            })
            .collect();
        Grid {
            w,
            k,
            sw,
            sh,
            xs,
            side,
            ys,
            gx,
            gy,
        }
    }
}

/// Bilinear coordinate of full-size pixel `x` on `n` blocks of `k`: the two nodes and the
/// weight of the second (block centres at `((b + ½)·k − ½)`, clamped at the edges).
fn coord(x: usize, n: usize, k: usize) -> (usize, usize, f32) {
    let u = ((x as f32 + 0.5) / k as f32 - 0.5).clamp(0.0, (n - 1) as f32);
    let i = (u as usize).min(n - 1);
    (i, (i + 1).min(n - 1), u - i as f32)
}

/// A pixel of block `b`'s weights on the nodes `b − 1, b, b + 1` (its nodes are among
/// them: see [`coord`]).
#[inline(always)]
fn slot_weights((n0, n1, f): (usize, usize, f32), b: usize) -> [f32; 3] {
    let mut v = [0.0f32; 3];
    v[n0 + 1 - b] += 1.0 - f;
    v[n1 + 1 - b] += f;
    v
}

/// The fused in-between, or `None` when the frame is too small for the reduced local mean
/// (`r / 4 < 2`) or the sizes differ — the caller then takes the reference path.
pub(super) fn inbetween_rgba(
    a: &RgbaFrame,
    b: &RgbaFrame,
    fw: &FlowField,
    bw: &FlowField,
    t: f32,
    stages: Option<&mut Stages>,
) -> Option<RgbaFrame> {
    let stride = super::gain_rows(a.size()).1;
    fused(a, b, fw, bw, t, stages, stride).map(|(f, _)| f)
}

/// [`inbetween_rgba`] with the gain estimated from every `stride`-th block
/// (`super::gain_block`); also returns the gain.
fn fused(
    a: &RgbaFrame,
    b: &RgbaFrame,
    fw: &FlowField,
    bw: &FlowField,
    t: f32,
    mut stages: Option<&mut Stages>,
    stride: usize,
) -> Option<(RgbaFrame, f32)> {
    let size = a.size();
    let (w, h) = (size.width as usize, size.height as usize);
    let r = detail_radius(size);
    let k = r / 4;
    if b.size() != size || k < 2 || w < 2 * k || h < 2 * k {
        return None;
    }
    let small = Size::new(w.div_ceil(k) as u32, h.div_ceil(k) as u32).ok()?;
    let clock = Instant::now();
    let mut since = Duration::ZERO;
    let mut lap = |i: usize, name: &'static str| {
        if let Some(s) = stages.as_deref_mut() {
            let now = clock.elapsed();
            s[i] = (name, now - since);
            since = now;
        }
    };
    let grid = Grid::new(size, small, k);
    let s = 1.0 - t;
    let (wa, wb) = (WarpRows::new(a, fw, -t), WarpRows::new(b, bw, -(1.0 - t)));
    // The output is written whole by pass 1 (no zero-filling of 33 MB at 1080p).
    let mut out: Vec<[f32; 4]> = Vec::with_capacity(w * h);
    let (mut ca, mut cb) = (
        vec![[0.0f32; 4]; small.pixels()],
        vec![[0.0f32; 4]; small.pixels()],
    );
    let sw = grid.sw;
    // Per band, the sums of its sampled blocks (`sampled`).
    let sums: Vec<Vec<BlockSums>> = out.spare_capacity_mut()[..w * h]
        .par_chunks_mut(k * w)
        .zip(ca.par_chunks_mut(sw).zip(cb.par_chunks_mut(sw)))
        .enumerate()
        .map_init(
            || (Vec::new(), Vec::new(), wa.scratch()),
            |(ra, rb, ws), (by, (o, (sa, sb)))| {
                ra.resize(o.len(), [0.0f32; 4]);
                rb.resize(o.len(), [0.0f32; 4]);
                wa.rows_with(ws, by * k, ra);
                wb.rows_with(ws, by * k, rb);
                block_means(ra, w, k, sa);
                block_means(rb, w, k, sb);
                let mut st = vec![BlockSums::default(); sampled(sw, by, stride).len()];
                band_sums(&grid, by, stride, (ra, rb), (sa, sb), &mut st);
                for ((o, p), q) in o.iter_mut().zip(ra.iter()).zip(rb.iter()) {
                    o.write([
                        s * p[0] + t * q[0],
                        s * p[1] + t * q[1],
                        s * p[2] + t * q[2],
                        s * p[3] + t * q[3],
                    ]);
                }
                st
            },
        )
        .collect();
    // SAFETY: the bands above cover `0..w·h` (chunks of the spare capacity's first `w·h`
    // elements) and every element of each band was written (`ra`, `rb` have its length).
    unsafe { out.set_len(w * h) };
    lap(0, "warps, plain blend, block sums");
    let (ma, mb) = rayon::join(
        || box_mean(&ca, small, r / k),
        || box_mean(&cb, small, r / k),
    );
    let [ea, eb, cross] = energies(&grid, stride, (&ca, &cb), (&ma, &mb), &sums);
    let em = f64::from(s * s) * ea + f64::from(t * t) * eb + 2.0 * f64::from(s * t) * cross;
    let gain = super::detail_gain([ea, eb, em], t);
    lap(1, "box means, energies");
    let mixed: Vec<[f32; 4]> = ma
        .iter()
        .zip(&mb)
        .map(|(p, q)| std::array::from_fn(|c| (1.0 - gain) * (s * p[c] + t * q[c])))
        .collect();
    let mean = MeanRows {
        sm: mixed,
        grid: &grid,
    };
    out.par_chunks_mut(w).enumerate().for_each_init(
        || (Vec::new(), vec![[0.0f32; 4]; w]),
        |(v, m), (y, o)| {
            mean.row(y, v, m);
            finish_row(o, m, gain);
        },
    );
    lap(2, "mean, gain, unpremultiply");
    Some((RgbaFrame::from_vec(size, out).ok()?, gain))
}

/// Block means of a band of rows (`rows.len() / w` of them) in blocks of `k` columns, into
/// `out` (one per block): each column summed down the band in f32 (at most `k` rows, in
/// order; contiguous, so it vectorises), then a block's columns in order in f64.
fn block_means(rows: &[[f32; 4]], w: usize, k: usize, out: &mut [[f32; 4]]) {
    let n_rows = rows.len() / w;
    let mut col = vec![[0.0f32; 4]; w];
    for row in rows.chunks_exact(w) {
        for (c, p) in col.iter_mut().zip(row) {
            *c = [c[0] + p[0], c[1] + p[1], c[2] + p[2], c[3] + p[3]];
        }
    }
    for (o, run) in out.iter_mut().zip(col.chunks(k)) {
        let mut a = [0.0f64; 4];
        for p in run {
            for c in 0..4 {
                a[c] += f64::from(p[c]);
            }
        }
        let n = (run.len() * n_rows).max(1) as f64;
        *o = std::array::from_fn(|c| (a[c] / n) as f32);
    }
}

/// The blocks of band `by` (of `sw`) the gain is estimated from (`super::gain_block`).
fn sampled(sw: usize, by: usize, stride: usize) -> std::iter::StepBy<std::ops::Range<usize>> {
    let first = (stride - by % stride) % stride;
    debug_assert!(super::gain_block(first, by, stride));
    (first..sw).step_by(stride)
}

/// The per-block sums of band `by` (rows `ra`, `rb` of the two warped frames, block means
/// `ca`, `cb`) into `out`, one per block of [`sampled`]: see the module doc.
fn band_sums(
    g: &Grid,
    by: usize,
    stride: usize,
    (ra, rb): (&[[f32; 4]], &[[f32; 4]]),
    (ca, cb): (&[[f32; 4]], &[[f32; 4]]),
    out: &mut [BlockSums],
) {
    let (w, k) = (g.w, g.k);
    for (j, (row_a, row_b)) in ra.chunks_exact(w).zip(rb.chunks_exact(w)).enumerate() {
        let wy = slot_weights(g.ys[by * k + j], by);
        for (st, bx) in out.iter_mut().zip(sampled(g.sw, by, stride)) {
            let span = bx * k..((bx + 1) * k).min(w);
            let (c_a, c_b) = (ca[bx], cb[bx]);
            // Per channel: Σq, Σ w₀q, Σ w₂q of a (rows 0..3) and b (rows 3..6); the middle
            // node's sum is Σq minus the other two (the weights sum to 1).
            let mut h = [[0.0f32; 4]; 6];
            let mut e = [[0.0f32; 4]; 3];
            let cols = g.side[span.clone()].iter();
            for ((pa, pb), &[w0, w2]) in row_a[span.clone()].iter().zip(&row_b[span]).zip(cols) {
                for c in 0..4 {
                    let (qa, qb) = (pa[c] - c_a[c], pb[c] - c_b[c]);
                    e[0][c] += qa * qa;
                    e[1][c] += qb * qb;
                    e[2][c] += qa * qb;
                    h[0][c] += qa;
                    h[1][c] += w0 * qa;
                    h[2][c] += w2 * qa;
                    h[3][c] += qb;
                    h[4][c] += w0 * qb;
                    h[5][c] += w2 * qb;
                }
            }
            let node = |o: usize| -> [[f32; 4]; 3] {
                [
                    h[o + 1],
                    std::array::from_fn(|c| h[o][c] - h[o + 1][c] - h[o + 2][c]),
                    h[o + 2],
                ]
            };
            let (ha, hb) = (node(0), node(3));
            for (q, e) in st.qq.iter_mut().zip(&e) {
                *q += e.iter().map(|&v| f64::from(v)).sum::<f64>();
            }
            for ((ra, rb), &wj) in st.aa.iter_mut().zip(st.ab.iter_mut()).zip(&wy) {
                for i in 0..3 {
                    for c in 0..4 {
                        ra[i][c] += wj * ha[i][c];
                        rb[i][c] += wj * hb[i][c];
                    }
                }
            }
        }
    }
}

/// `Σ(a − ma)²`, `Σ(b − mb)²` and `Σ(a − ma)(b − mb)` over the sampled blocks (`sums[by]`
/// holds the sums of band `by`'s [`sampled`] blocks) from those sums, the block means `c`
/// and the box means `m` (module doc); block rows in parallel, added in order.
fn energies(
    g: &Grid,
    stride: usize,
    (ca, cb): (&[[f32; 4]], &[[f32; 4]]),
    (ma, mb): (&[[f32; 4]], &[[f32; 4]]),
    sums: &[Vec<BlockSums>],
) -> [f64; 3] {
    let (sw, sh) = (g.sw, g.sh);
    let parts: Vec<[f64; 3]> = (0..sh)
        .into_par_iter()
        .map(|by| {
            let mut e = [0.0f64; 3];
            for (st, bx) in sums[by].iter().zip(sampled(sw, by, stride)) {
                let i = by * sw + bx;
                // E = S − c at the 3 × 3 nodes (clamped: nodes off the grid have weight 0).
                let node = |m: &[[f32; 4]], c: [f32; 4]| -> [[[f64; 4]; 3]; 3] {
                    std::array::from_fn(|jj| {
                        let ny = (by + jj).saturating_sub(1).min(sh - 1);
                        std::array::from_fn(|ii| {
                            let nx = (bx + ii).saturating_sub(1).min(sw - 1);
                            let s = m[ny * sw + nx];
                            std::array::from_fn(|ch| f64::from(s[ch]) - f64::from(c[ch]))
                        })
                    })
                };
                let (xa, xb) = (node(ma, ca[i]), node(mb, cb[i]));
                let quad = |p: &[[[f64; 4]; 3]; 3], q: &[[[f64; 4]; 3]; 3]| {
                    gram_form(&g.gy[by], &g.gx[bx], p, q)
                };
                e[0] += st.qq[0] - 2.0 * dot(&xa, &st.aa) + quad(&xa, &xa);
                e[1] += st.qq[1] - 2.0 * dot(&xb, &st.ab) + quad(&xb, &xb);
                e[2] += st.qq[2] - dot(&xb, &st.aa) - dot(&xa, &st.ab) + quad(&xa, &xb);
            }
            e
        })
        .collect();
    parts
        .iter()
        .fold([0.0; 3], |s, p| [s[0] + p[0], s[1] + p[1], s[2] + p[2]])
}

/// `Σ E·A` over the 3 × 3 nodes and the channels.
fn dot(x: &[[[f64; 4]; 3]; 3], a: &Nodes) -> f64 {
    let mut s = 0.0;
    for (xr, ar) in x.iter().zip(a) {
        for (xn, an) in xr.iter().zip(ar) {
            for c in 0..4 {
                s += xn[c] * f64::from(an[c]);
            }
        }
    }
    s
}

/// `Σ pᵀ (Gy ⊗ Gx) q` over the channels: `Σ Gy[j][j']·Gx[i][i']·p[j][i]·q[j'][i']`.
fn gram_form(
    gy: &[[f64; 3]; 3],
    gx: &[[f64; 3]; 3],
    p: &[[[f64; 4]; 3]; 3],
    q: &[[[f64; 4]; 3]; 3],
) -> f64 {
    // h[j'][i] = Σ_i' Gx[i][i'] q[j'][i'].
    let h: [[[f64; 4]; 3]; 3] = std::array::from_fn(|jj| {
        std::array::from_fn(|i| {
            std::array::from_fn(|c| (0..3).map(|ii| gx[i][ii] * q[jj][ii][c]).sum())
        })
    });
    let mut s = 0.0;
    for (j, gyj) in gy.iter().enumerate() {
        for (jj, &gyv) in gyj.iter().enumerate() {
            if gyv == 0.0 {
                continue;
            }
            let mut d = 0.0;
            for i in 0..3 {
                for c in 0..4 {
                    d += p[j][i][c] * h[jj][i][c];
                }
            }
            s += gyv * d;
        }
    }
    s
}

/// A small-grid field upsampled a row at a time (bilinear, as the local mean).
struct MeanRows<'a> {
    sm: Vec<[f32; 4]>,
    grid: &'a Grid,
}

impl MeanRows<'_> {
    /// Row `y`: the two node rows blended vertically (into `v`, one entry per block), then
    /// horizontally per pixel.
    fn row(&self, y: usize, v: &mut Vec<[f32; 4]>, out: &mut [[f32; 4]]) {
        let g = self.grid;
        let (y0, y1, fy) = g.ys[y];
        let sw = g.sw;
        let (r0, r1) = (
            &self.sm[y0 * sw..(y0 + 1) * sw],
            &self.sm[y1 * sw..(y1 + 1) * sw],
        );
        v.clear();
        v.extend(
            r0.iter()
                .zip(r1)
                .map(|(p, q)| std::array::from_fn(|c| p[c] + fy * (q[c] - p[c]))),
        );
        for (o, &(x0, x1, fx)) in out.iter_mut().zip(&g.xs) {
            let (p, q) = (v[x0], v[x1]);
            *o = std::array::from_fn(|c| p[c] + fx * (q[c] - p[c]));
        }
    }
}

/// One output row in place: `gain·P + m` on premultiplied values, then alpha clamped to
/// `0..=1`, colour to at least 0, unpremultiplied.
///
/// Written without branches (a pixel at most 1e-6 opaque gets the factor 0, i.e. all zero,
/// as the reference), so the loop vectorises.
fn finish_row(out: &mut [[f32; 4]], m: &[[f32; 4]], gain: f32) {
    for (o, m) in out.iter_mut().zip(m) {
        let p: [f32; 4] = std::array::from_fn(|c| gain * o[c] + m[c]);
        let al = p[3].clamp(0.0, 1.0);
        let keep = al > 1e-6;
        let inv = if keep { 1.0 / al } else { 0.0 };
        *o = [
            p[0].max(0.0) * inv,
            p[1].max(0.0) * inv,
            p[2].max(0.0) * inv,
            if keep { al } else { 0.0 },
        ];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The energies from the per-block sums equal the direct sums over the pixels with the
    /// upsampled local means, on correlated frames with gradients (where the centred sums
    /// cancel most), ragged sizes included.
    #[test]
    fn block_energies_equal_the_direct_sums() {
        for (w, h, k) in [(101usize, 67usize, 7usize), (64, 40, 4), (33, 90, 5)] {
            let size = Size::new(w as u32, h as u32).unwrap();
            let small = Size::new(w.div_ceil(k) as u32, h.div_ceil(k) as u32).unwrap();
            let mut rng = ignis_core::Rng::new(w as u64);
            let pa: Vec<[f32; 4]> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    std::array::from_fn(|c| {
                        3.0 + 0.05 * x - 0.02 * y * c as f32 + 0.1 * rng.uniform(0.0, 1.0) as f32
                    })
                })
                .collect();
            let pb: Vec<[f32; 4]> = pa
                .iter()
                .map(|p| std::array::from_fn(|c| 0.8 * p[c] + 0.05 * rng.uniform(0.0, 1.0) as f32))
                .collect();
            let grid = Grid::new(size, small, k);
            let sw = grid.sw;
            let mut ca = vec![[0.0f32; 4]; small.pixels()];
            let mut cb = ca.clone();
            let mut sums = Vec::new();
            for by in 0..grid.sh {
                let rows = by * k * w..((by + 1) * k).min(h) * w;
                let band = by * sw..(by + 1) * sw;
                block_means(&pa[rows.clone()], w, k, &mut ca[band.clone()]);
                block_means(&pb[rows.clone()], w, k, &mut cb[band.clone()]);
                let (sa, sb) = (&ca[band.clone()], &cb[band]);
                let mut st = vec![BlockSums::default(); sw];
                band_sums(
                    &grid,
                    by,
                    1,
                    (&pa[rows.clone()], &pb[rows]),
                    (sa, sb),
                    &mut st,
                );
                sums.push(st);
            }
            let radius = 2;
            let (ma, mb) = (box_mean(&ca, small, radius), box_mean(&cb, small, radius));
            let got = energies(&grid, 1, (&ca, &cb), (&ma, &mb), &sums);
            // Direct: the full-size local means, then the sums in f64.
            let up = |m: &[[f32; 4]]| {
                let rows = MeanRows {
                    sm: m.to_vec(),
                    grid: &grid,
                };
                let mut full = vec![[0.0f32; 4]; w * h];
                let mut v = Vec::new();
                for (y, o) in full.chunks_exact_mut(w).enumerate() {
                    rows.row(y, &mut v, o);
                }
                full
            };
            let (fa, fb) = (up(&ma), up(&mb));
            let mut want = [0.0f64; 3];
            for i in 0..w * h {
                for c in 0..4 {
                    let da = f64::from(pa[i][c]) - f64::from(fa[i][c]);
                    let db = f64::from(pb[i][c]) - f64::from(fb[i][c]);
                    want[0] += da * da;
                    want[1] += db * db;
                    want[2] += da * db;
                }
            }
            for j in 0..3 {
                let rel = (got[j] - want[j]).abs() / want[0].max(want[1]);
                assert!(rel < 1e-4, "{w}x{h}/{k} sum {j}: {} vs {}", got[j], want[j]);
            }
            // The detail is a small part of the energy here, so the check has teeth.
            let total: f64 = pa.iter().flatten().map(|&v| f64::from(v).powi(2)).sum();
            assert!(want[0] < 1e-2 * total, "{} vs {total}", want[0]);
        }
    }

    /// The gain estimated from every `stride`-th block (`super::gain_rows`) is within 1 % of
    /// the gain from every block, on a campfire pair large enough to be subsampled, aligned
    /// by its flow (gain near 1) and not aligned (gain well above 1), at three times.
    #[test]
    fn subsampled_gain_matches_the_whole_frame() {
        use crate::synthetic::{synthetic_frame, FlameStyle, SyntheticParams};
        let p = SyntheticParams {
            size: Size::new(1280, 720).unwrap(),
            frames: 8,
            style: FlameStyle::Campfire,
            seed: 3,
        };
        let (a, b) = (
            synthetic_frame(&p, 1).unwrap(),
            synthetic_frame(&p, 4).unwrap(),
        );
        let stride = super::super::gain_rows(p.size).1;
        assert_eq!(stride, 4, "a 720p frame is subsampled");
        let fp = ignis_flow::FlowParams {
            max_side: crate::render::MORPH_FLOW_SIDE,
            ..Default::default()
        };
        let (fw, bw) = ignis_flow::flow_pair_reduced_rgba(&a, &b, &fp).unwrap();
        let still = FlowField::from_vec(Size::new(1, 1).unwrap(), vec![[0.0; 2]]).unwrap();
        let (mut gains, mut worst) = (Vec::new(), 0.0f32);
        for (f, g) in [(&fw, &bw), (&still, &still)] {
            for t in [0.25f32, 0.5, 0.8] {
                let (_, all) = fused(&a, &b, f, g, t, None, 1).unwrap();
                let (_, some) = fused(&a, &b, f, g, t, None, stride).unwrap();
                assert!(
                    (some / all - 1.0).abs() < 0.01,
                    "t={t}: gain {some} from every {stride}th block vs {all} from all"
                );
                gains.push(all);
                worst = worst.max((some / all - 1.0).abs());
            }
        }
        eprintln!("gain from every {stride}th block: worst relative difference {worst:.5}");
        // The cases span the gain's range, so the comparison is not between two 1s.
        let top = gains.iter().fold(0.0f32, |m, &g| m.max(g));
        assert!(top > 1.05, "{gains:?}");
    }
}
