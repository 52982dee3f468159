//! Contours as a tree with depth levels and areas; hole removal; Douglas–Peucker
//! simplification; filling the kept contours back into a mask.
//!
//! Source: eigenfires-thesis.txt §3.2.1 (border following, Suzuki & Abe, via
//! `imageproc::contours`), §3.2.2 (hole removal by depth and/or area, Figure 18), §3.2.3
//! (Douglas–Peucker, Figure 19, via `imageproc::geometry::approximate_polygon_dp`).
//!
//! Depth follows the thesis: 0 = an outer border not inside anything, 1 = a hole inside a
//! depth-0 region, 2 = a region inside that hole, and so on.

use crate::error::{EigenError, Result};
use image::GrayImage;
use imageproc::contours::{find_contours, BorderType};
use imageproc::point::Point;
use serde::{Deserialize, Serialize};

/// One border with its place in the tree.
#[derive(Clone, Debug, PartialEq)]
pub struct ContourNode {
    /// Border pixels in order (x right, y down).
    pub points: Vec<Point<i32>>,
    /// `true` for a hole border (encloses background).
    pub is_hole: bool,
    /// Index of the enclosing contour in the same list.
    pub parent: Option<usize>,
    /// Depth level (0 = outermost).
    pub depth: u32,
    /// Enclosed area in pixels (shoelace formula on the border polygon).
    pub area: f64,
}

/// Settings of [`remove_holes`] and [`simplify`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContourParams {
    /// Keep contours of depth ≤ this (0 = outer borders only, which fills every hole).
    /// `None` keeps every depth. Default 0.
    pub max_depth: Option<u32>,
    /// Drop contours (and everything inside them) enclosing fewer pixels than this
    /// fraction of the frame area. Default 0.0005 (0.05 %).
    pub min_area: f64,
    /// Douglas–Peucker tolerance in pixels (0 = no simplification). Default 0.
    pub simplify_epsilon: f64,
}

impl Default for ContourParams {
    fn default() -> Self {
        ContourParams {
            max_depth: Some(0),
            min_area: 0.0005,
            simplify_epsilon: 0.0,
        }
    }
}

impl ContourParams {
    pub fn validate(&self) -> Result<()> {
        if !(0.0..1.0).contains(&self.min_area) {
            return Err(EigenError::bad(
                "contours.min_area",
                "must be a fraction of the frame area in 0..1",
            ));
        }
        if !(0.0..=1000.0).contains(&self.simplify_epsilon) {
            return Err(EigenError::bad(
                "contours.simplify_epsilon",
                "must be within 0..=1000 pixels",
            ));
        }
        Ok(())
    }
}

/// Polygon area by the shoelace formula (absolute value).
pub fn polygon_area(points: &[Point<i32>]) -> f64 {
    if points.len() < 3 {
        return points.len() as f64; // a 1–2 pixel border still covers its pixels
    }
    let mut s = 0i64;
    for i in 0..points.len() {
        let (a, b) = (points[i], points[(i + 1) % points.len()]);
        s += a.x as i64 * b.y as i64 - b.x as i64 * a.y as i64;
    }
    (s as f64 / 2.0).abs()
}

/// All borders of the mask as a tree (depth and area filled in).
pub fn contour_tree(mask: &GrayImage) -> Vec<ContourNode> {
    let raw = find_contours::<i32>(mask);
    let mut nodes: Vec<ContourNode> = raw
        .into_iter()
        .map(|c| ContourNode {
            area: polygon_area(&c.points),
            is_hole: c.border_type == BorderType::Hole,
            parent: c.parent,
            depth: 0,
            points: c.points,
        })
        .collect();
    for i in 0..nodes.len() {
        let mut d: u32 = 0;
        let mut p = nodes[i].parent;
        while let Some(j) = p {
            d += 1;
            p = nodes[j].parent;
            if d as usize > nodes.len() {
                break; // defensive: a malformed parent chain
            }
        }
        nodes[i].depth = d;
    }
    nodes
}

/// Hole removal (§3.2.2): which contours survive `p` (a contour whose parent is dropped is
/// dropped too). `frame_area` is width × height.
pub fn remove_holes(nodes: &[ContourNode], p: &ContourParams, frame_area: f64) -> Vec<bool> {
    let min_area = p.min_area * frame_area;
    let mut keep = vec![false; nodes.len()];
    // Parents always come before children in find_contours' output.
    for i in 0..nodes.len() {
        let n = &nodes[i];
        let depth_ok = p.max_depth.is_none_or(|d| n.depth <= d);
        let parent_ok = n.parent.is_none_or(|j| j < i && keep[j]);
        keep[i] = depth_ok && parent_ok && n.area >= min_area;
    }
    keep
}

/// Douglas–Peucker simplification of a closed contour (§3.2.3).
pub fn simplify(points: &[Point<i32>], epsilon: f64) -> Vec<Point<i32>> {
    if epsilon <= 0.0 || points.len() < 4 {
        return points.to_vec();
    }
    imageproc::geometry::approximate_polygon_dp(points, epsilon, true)
}

/// Fills the kept contours into a new mask with the even–odd rule, so kept holes stay
/// empty and dropped holes are filled; border pixels of kept contours are set too (they
/// are foreground pixels by construction). With `epsilon > 0` the simplified polygons
/// are filled instead (and borders are not drawn).
pub fn fill_contours(
    width: u32,
    height: u32,
    nodes: &[ContourNode],
    keep: &[bool],
    epsilon: f64,
) -> GrayImage {
    let polys = kept_polygons(nodes, keep, epsilon);
    let mut out = GrayImage::new(width, height);
    // An edge (a, b) crosses the centre line of row y, `y + 0.5`, exactly when y lies in
    // `min(a.y, b.y)..max(a.y, b.y)` (horizontal edges never do). Edges are bucketed by
    // their first row in the image and kept in an active list while they cross, so a row
    // visits only the edges that cross it, not every edge of every polygon (an unsimplified
    // 1080p contour has thousands of border pixels). Each crossing's x is computed as
    // before, and the row's crossings are sorted (a total order), so the fill is the same.
    let (h, w) = (height as i64, width as usize);
    let mut starts: Vec<Vec<(Point<i32>, Point<i32>)>> = vec![Vec::new(); height as usize];
    for poly in polys.iter().filter(|p| p.len() >= 3) {
        let n = poly.len();
        for i in 0..n {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            let (lo, hi) = (i64::from(a.y.min(b.y)), i64::from(a.y.max(b.y)));
            if lo == hi || hi <= 0 || lo >= h {
                continue;
            }
            starts[lo.max(0) as usize].push((a, b));
        }
    }
    let mut active: Vec<(Point<i32>, Point<i32>)> = Vec::new();
    let mut xs: Vec<f64> = Vec::new();
    for (y, new_edges) in starts.into_iter().enumerate() {
        let yi = y as i64;
        active.retain(|(a, b)| i64::from(a.y.max(b.y)) > yi);
        active.extend(new_edges);
        let yc = y as f64 + 0.5;
        xs.clear();
        for &(a, b) in &active {
            let (ay, by) = (a.y as f64 + 0.5, b.y as f64 + 0.5);
            let t = (yc - ay) / (by - ay);
            xs.push(a.x as f64 + 0.5 + t * (b.x - a.x) as f64);
        }
        fill_spans(&mut out.as_mut()[y * w..(y + 1) * w], &mut xs);
    }
    if epsilon <= 0.0 {
        draw_borders(&mut out, &polys);
    }
    out
}

/// The kept contours' polygons, simplified with `epsilon` (none at 0).
fn kept_polygons(nodes: &[ContourNode], keep: &[bool], epsilon: f64) -> Vec<Vec<Point<i32>>> {
    nodes
        .iter()
        .zip(keep)
        .filter(|(_, &k)| k)
        .map(|(n, _)| simplify(&n.points, epsilon))
        .collect()
}

/// Fills a row between the pairs of its sorted crossings (even–odd rule).
fn fill_spans(row: &mut [u8], xs: &mut [f64]) {
    xs.sort_by(|a, b| a.total_cmp(b));
    let width = row.len() as i64;
    for pair in xs.chunks_exact(2) {
        let x0 = (pair[0] - 0.5).ceil().max(0.0) as usize;
        let x1 = ((pair[1] - 0.5).floor() as i64).min(width - 1);
        if x1 >= x0 as i64 {
            row[x0..=x1 as usize].fill(255);
        }
    }
}

/// Sets the polygons' own points that lie in the image (border pixels).
fn draw_borders(out: &mut GrayImage, polys: &[Vec<Point<i32>>]) {
    let (width, height) = out.dimensions();
    for pt in polys.iter().flatten() {
        if pt.x >= 0 && pt.y >= 0 && (pt.x as u32) < width && (pt.y as u32) < height {
            out.put_pixel(pt.x as u32, pt.y as u32, image::Luma([255]));
        }
    }
}

/// Draws the outlines of the kept contours in white on black (the `contours` stage
/// image), brighter for depth 0.
pub fn draw_contours(width: u32, height: u32, nodes: &[ContourNode], keep: &[bool]) -> GrayImage {
    let mut out = GrayImage::new(width, height);
    for (n, &k) in nodes.iter().zip(keep) {
        let v = if !k {
            60
        } else if n.depth == 0 {
            255
        } else {
            160
        };
        for pt in &n.points {
            if pt.x >= 0 && pt.y >= 0 && (pt.x as u32) < width && (pt.y as u32) < height {
                out.put_pixel(pt.x as u32, pt.y as u32, image::Luma([v]));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 20x20 square with a 6x6 hole and a 2x2 speck outside.
    fn ring() -> GrayImage {
        GrayImage::from_fn(32, 32, |x, y| {
            let sq = (4..24).contains(&x) && (4..24).contains(&y);
            let hole = (11..17).contains(&x) && (11..17).contains(&y);
            let speck = (28..30).contains(&x) && (28..30).contains(&y);
            image::Luma([if (sq && !hole) || speck { 255 } else { 0 }])
        })
    }

    #[test]
    fn tree_depths_and_hole_removal() {
        let m = ring();
        let nodes = contour_tree(&m);
        assert_eq!(nodes.len(), 3);
        let hole = nodes.iter().find(|n| n.is_hole).unwrap();
        assert_eq!(hole.depth, 1);
        assert!(hole.area > 20.0 && hole.area < 60.0);
        // Keep everything: the fill reproduces the mask exactly.
        let all = ContourParams {
            max_depth: None,
            min_area: 0.0,
            simplify_epsilon: 0.0,
        };
        let keep = remove_holes(&nodes, &all, 1024.0);
        assert_eq!(fill_contours(32, 32, &nodes, &keep, 0.0), m);
        // Depth 0 + area filter: hole filled, speck gone.
        let keep = remove_holes(
            &nodes,
            &ContourParams {
                max_depth: Some(0),
                min_area: 0.01,
                simplify_epsilon: 0.0,
            },
            1024.0,
        );
        let f = fill_contours(32, 32, &nodes, &keep, 0.0);
        assert_eq!(f.get_pixel(13, 13)[0], 255);
        assert_eq!(f.get_pixel(28, 28)[0], 0);
        assert_eq!(f.get_pixel(4, 4)[0], 255);
        assert_eq!(crate::mask::mask_area(&f), 400);
    }

    #[test]
    fn douglas_peucker_reduces_points() {
        let nodes = contour_tree(&ring());
        let outer = nodes
            .iter()
            .max_by(|a, b| a.area.total_cmp(&b.area))
            .unwrap();
        let s = simplify(&outer.points, 1.0);
        assert!(s.len() <= 6 && s.len() >= 4, "{} points", s.len());
    }

    /// The fill as first written: every edge of every polygon tested on every row.
    fn fill_contours_every_edge(
        width: u32,
        height: u32,
        nodes: &[ContourNode],
        keep: &[bool],
        epsilon: f64,
    ) -> GrayImage {
        let polys = kept_polygons(nodes, keep, epsilon);
        let mut out = GrayImage::new(width, height);
        let mut xs: Vec<f64> = Vec::new();
        for y in 0..height {
            let yc = y as f64 + 0.5;
            xs.clear();
            for poly in &polys {
                let n = poly.len();
                if n < 3 {
                    continue;
                }
                for i in 0..n {
                    let (a, b) = (poly[i], poly[(i + 1) % n]);
                    let (ay, by) = (a.y as f64 + 0.5, b.y as f64 + 0.5);
                    if (ay <= yc && by > yc) || (by <= yc && ay > yc) {
                        let t = (yc - ay) / (by - ay);
                        xs.push(a.x as f64 + 0.5 + t * (b.x - a.x) as f64);
                    }
                }
            }
            fill_spans(
                &mut out.as_mut()[(y * width) as usize..((y + 1) * width) as usize],
                &mut xs,
            );
        }
        if epsilon <= 0.0 {
            draw_borders(&mut out, &polys);
        }
        out
    }

    /// The edge-table fill equals the every-edge fill on every row: random masks (specks,
    /// holes, rings, shapes touching the borders), all contours and a kept subset, with and
    /// without simplification, and polygons reaching outside the image.
    #[test]
    fn edge_table_fill_equals_every_edge_fill() {
        let mut x = 0x2545_f491_u32;
        let mut rnd = move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        };
        for (w, h) in [(1u32, 1u32), (5, 3), (64, 48), (97, 131), (200, 40)] {
            for _ in 0..12 {
                // Blobs: a few random discs, some with holes, over a sparse speckle.
                let blobs: Vec<(i64, i64, i64, i64)> = (0..1 + rnd() % 6)
                    .map(|_| {
                        let r = 1 + i64::from(rnd() % (w.max(h) / 3 + 1));
                        let hole = i64::from(rnd() % 3) * r / 3;
                        (i64::from(rnd() % w), i64::from(rnd() % h), r, hole)
                    })
                    .collect();
                let speck = rnd() % 40;
                let m = GrayImage::from_fn(w, h, |px, py| {
                    let (px, py) = (i64::from(px), i64::from(py));
                    let inside = blobs.iter().any(|&(cx, cy, r, hole)| {
                        let d = (px - cx).pow(2) + (py - cy).pow(2);
                        d <= r * r && d >= hole * hole
                    });
                    let s = (px * 7 + py * 13 + i64::from(speck)) % 41 == 0;
                    image::Luma([if inside || s { 255 } else { 0 }])
                });
                let nodes = contour_tree(&m);
                let all = vec![true; nodes.len()];
                let some: Vec<bool> = (0..nodes.len()).map(|_| rnd() % 3 != 0).collect();
                for keep in [&all, &some] {
                    for eps in [0.0, 0.7, 2.5] {
                        assert_eq!(
                            fill_contours(w, h, &nodes, keep, eps),
                            fill_contours_every_edge(w, h, &nodes, keep, eps),
                            "{w}x{h} epsilon {eps}"
                        );
                    }
                }
            }
        }
        // Polygons partly or wholly outside the image, and degenerate ones.
        let node = |pts: &[(i32, i32)]| ContourNode {
            points: pts.iter().map(|&(x, y)| Point::new(x, y)).collect(),
            is_hole: false,
            parent: None,
            depth: 0,
            area: 0.0,
        };
        let nodes = vec![
            node(&[(-5, -5), (20, -3), (30, 25), (-2, 40)]),
            node(&[(10, 10), (50, 12), (12, 60)]),
            node(&[(3, 3), (9, 3)]),
            node(&[(-9, 50), (-1, 50), (-4, 70)]),
            node(&[(4, 100), (8, 120), (2, 130)]),
        ];
        let keep = vec![true; nodes.len()];
        for eps in [0.0, 1.0] {
            assert_eq!(
                fill_contours(24, 36, &nodes, &keep, eps),
                fill_contours_every_edge(24, 36, &nodes, &keep, eps)
            );
        }
    }
}
