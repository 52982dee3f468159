//! Binning: every lattice cell goes to the 16×16-pixel tiles its projected bounding box
//! touches, with its box and visible part inline for the per-pixel slab tests.

use super::visible::{visible_parts, AffineDisc};
use super::{Camera, FireInstance, RenderParams, MAX_CANDIDATES, MAX_SAMPLES, TILE};
use crate::error::{Result, VolumeError};
use crate::lattice::{dot, sub, V3};

/// A tile's candidate cell, with its bounding box inline so the per-pixel slab tests read
/// contiguous memory.
#[derive(Clone, Copy, Debug)]
pub(super) struct Candidate {
    pub(super) fire: u32,
    pub(super) cell: u32,
    /// The cell's bounding box, relative to the camera position (as the slab tests use it).
    pub(super) min: V3,
    pub(super) max: V3,
    /// Bounding box of the part of the cell that can be visible ([`visible_parts`]),
    /// relative to the camera; empty (`visible_min > visible_max`) when none can be.
    pub(super) visible_min: V3,
    pub(super) visible_max: V3,
    /// The tighter description of that part for a nearly affine cell.
    pub(super) disc: Option<AffineDisc>,
    /// Pixel rectangle `[x0, x1] × [y0, y1]` (inclusive) containing the cell's projection,
    /// with a pixel of margin: rays of other pixels cannot meet the cell (it lies in the
    /// convex hull of its corners, whose projection is inside this rectangle), so their
    /// slab test is skipped.
    pub(super) pixel_rect: [i32; 4],
}

/// Bins every cell of `fires` into the 16×16-pixel tiles its projected bounding box touches
/// (all tiles for a cell reaching behind the camera), in fire then cell order, refusing a
/// frame over [`MAX_SAMPLES`] estimated samples or [`MAX_CANDIDATES`] candidates.
/// `basis`: the camera's forward, right and up vectors; `tan`: tan(fov / 2).
pub(super) fn bin_cells(
    fires: &[FireInstance],
    camera: &Camera,
    params: &RenderParams,
    time: f32,
    [forward, right, up]: [V3; 3],
    tan: f32,
    aspect: f32,
) -> Result<Vec<Vec<Candidate>>> {
    let (w, h) = (params.size.width, params.size.height);
    let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let mut bins: Vec<Vec<Candidate>> = vec![Vec::new(); (tx * ty) as usize];
    let (mut est_samples, mut candidates) = (0f64, 0u64);
    let too_much = |what: String| {
        VolumeError::LimitExceeded(format!(
            "{what}; raise render.slice_spacing (the paper uses 0.2 for a unit-radius fire), \
             shrink the fire (radius, points, lifetime) or the output size"
        ))
    };
    for (fi, f) in fires.iter().enumerate() {
        let visible = visible_parts(
            f,
            camera.position,
            params.exact_inverse,
            params.mix(f, time),
        );
        for (ci, c) in f.lattice.cells().iter().enumerate() {
            let vis = visible[ci];
            let rect = pixel_rect(
                c.min,
                c.max,
                camera.position,
                [forward, right, up],
                tan,
                aspect,
                w,
                h,
            );
            let behind = rect.is_none();
            let px = rect.unwrap_or([i32::MIN, i32::MAX, i32::MIN, i32::MAX]);
            let (x0, x1, y0, y1) = if behind {
                (0, tx as i64 - 1, 0, ty as i64 - 1)
            } else {
                (
                    (px[0] as i64).div_euclid(TILE as i64),
                    (px[1] as i64).div_euclid(TILE as i64),
                    (px[2] as i64).div_euclid(TILE as i64),
                    (px[3] as i64).div_euclid(TILE as i64),
                )
            };
            let (cx0, cx1) = (px[0].max(0) as f64, (px[1] as f64).min(w as f64));
            let (cy0, cy1) = (px[2].max(0) as f64, (px[3] as f64).min(h as f64));
            let covered = if behind {
                w as f64 * h as f64
            } else {
                (cx1 - cx0).max(0.0) * (cy1 - cy0).max(0.0)
            };
            let d = sub(c.max, c.min);
            let diag = (dot(d, d) as f64).sqrt();
            est_samples += covered * (diag / params.slice_spacing as f64).ceil();
            if !(est_samples <= MAX_SAMPLES) {
                return Err(too_much(format!(
                    "a frame needs more than {MAX_SAMPLES:e} samples (slice spacing {}, {} cells)",
                    params.slice_spacing,
                    f.lattice.cells().len()
                )));
            }
            let ntiles = ((y1.min(ty as i64 - 1) - y0.max(0) + 1).max(0)
                * (x1.min(tx as i64 - 1) - x0.max(0) + 1).max(0)) as u64;
            candidates += ntiles;
            if candidates > MAX_CANDIDATES {
                return Err(too_much(format!(
                    "a frame needs more than {MAX_CANDIDATES} tile candidates ({} cells)",
                    f.lattice.cells().len()
                )));
            }
            for y in y0.max(0)..=y1.min(ty as i64 - 1) {
                for x in x0.max(0)..=x1.min(tx as i64 - 1) {
                    bins[(y as u32 * tx + x as u32) as usize].push(Candidate {
                        fire: fi as u32,
                        cell: ci as u32,
                        min: sub(c.min, camera.position),
                        max: sub(c.max, camera.position),
                        visible_min: sub(vis.min, camera.position),
                        visible_max: sub(vis.max, camera.position),
                        disc: vis.disc,
                        pixel_rect: px,
                    });
                }
            }
        }
    }
    Ok(bins)
}

/// The pixel rectangle `[x0, x1, y0, y1]` (inclusive, with a pixel of margin) containing
/// the projection of the box `[min, max]` on a `w`×`h` image, or `None` when a corner of
/// the box is not in front of the camera (then any pixel may see it).
fn pixel_rect(
    min: V3,
    max: V3,
    camera: V3,
    [forward, right, up]: [V3; 3],
    tan: f32,
    aspect: f32,
    w: u32,
    h: u32,
) -> Option<[i32; 4]> {
    let mut lo = [f32::INFINITY; 2];
    let mut hi = [f32::NEG_INFINITY; 2];
    for k in 0..8 {
        let q = [
            if k & 1 == 0 { min[0] } else { max[0] },
            if k & 2 == 0 { min[1] } else { max[1] },
            if k & 4 == 0 { min[2] } else { max[2] },
        ];
        let rel = sub(q, camera);
        let z = dot(rel, forward);
        if z <= 1e-3 {
            return None;
        }
        let sx = (dot(rel, right) / (z * tan * aspect) + 1.0) * 0.5 * w as f32;
        let sy = (1.0 - dot(rel, up) / (z * tan)) * 0.5 * h as f32;
        lo = [lo[0].min(sx), lo[1].min(sy)];
        hi = [hi[0].max(sx), hi[1].max(sy)];
    }
    let clamp = |v: f32| v.clamp(-1e9, 1e9) as i64;
    Some(
        [
            clamp((lo[0] - 1.0).floor()),
            clamp((hi[0] + 1.0).ceil()),
            clamp((lo[1] - 1.0).floor()),
            clamp((hi[1] + 1.0).ceil()),
        ]
        .map(|v| v.clamp(-(1 << 30), 1 << 30) as i32),
    )
}
