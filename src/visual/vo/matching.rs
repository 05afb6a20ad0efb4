//! Points matched: along the epipolar line in the same frame's right image (then triangulated),
//! and tracked into the next frame's left image around where the wheels put them; coarse to
//! fine, each accepted only when its correlation peak stands out.

use super::*;
use crate::camera::StereoRig;
use crate::visual::stereo::triangulate_point;
use nalgebra::{Point2, Point3, Vector3};

/// The pyramid levels: half resolution ...
const HALF: u32 = 1;
/// ... and quarter resolution.
const QUARTER: u32 = 2;
/// Full-resolution pixels per quarter-resolution pixel.
const QUARTER_PX: f64 = 4.0;
/// Half-width of the patches compared at quarter resolution, pixels of that level (7 x 7).
const QUARTER_PATCH: i64 = 3;
/// Half-width of the patches compared at half resolution when tracking (9 x 9).
const HALF_PATCH: i64 = 4;
/// Half-width of the full-resolution patches matched along the epipolar line (11 x 11).
const EPIPOLAR_PATCH: i64 = 5;
/// Half-width of the full-resolution patches tracked into the next frame (15 x 15).
const TRACK_PATCH: i64 = 7;
/// A rival correlation peak lies this far from the best along the epipolar line, pixels ...
const RIVAL_APART_PX: f64 = 12.0;
/// ... or, when tracking, this far at quarter resolution (more than a patch's half-width).
const RIVAL_APART_QUARTER_PX: i64 = QUARTER_PATCH;
/// Fine search along the epipolar line around the coarse match: ± this many pixels.
const EPIPOLAR_FINE_PX: i64 = 6;
/// Tracking: the half-resolution search around the quarter-resolution match, ± pixels ...
const HALF_SEARCH_PX: i64 = 2;
/// ... and the full-resolution search around the half-resolution match, ± pixels.
const FULL_SEARCH_PX: i64 = 3;
/// Side of the full-resolution tracking search.
const FULL_SEARCH_SIDE: usize = 2 * FULL_SEARCH_PX as usize + 1;

/// The right-image pixel matching left pixel `p`, searched along its epipolar line from the far
/// to the near end of the depth range, first at a quarter of the resolution, then in quarter
/// pixels at full resolution; `None` when no match stands out.
pub(super) fn epipolar_match(
    rig: &StereoRig,
    left: &VoImage,
    right: &VoImage,
    p: Point2<f64>,
    config: &VoConfig,
) -> Option<Point2<f64>> {
    let n = rig.left.unproject(&p)?;
    let ray = Vector3::new(n.x, n.y, 1.0);
    let right_px = |inverse_depth: f64| -> Option<Point2<f64>> {
        let x = Point3::from(ray / inverse_depth.max(1e-9));
        rig.right.project(&(rig.right_from_left * x).coords)
    };
    let (near, far) = (1.0 / config.depth_range_m.0, 1.0 / config.depth_range_m.1);
    let span_px = (right_px(near)?.coords - right_px(far)?.coords).norm();
    // Coarse: a step of one quarter-resolution pixel along the line.
    let a = to_level(p, QUARTER);
    let (ax, ay) = (a.x.round() as i64, a.y.round() as i64);
    if !left.quarter.inside(ax, ay, QUARTER_PATCH) {
        return None;
    }
    let reference = patch_at(&left.quarter, ax, ay, QUARTER_PATCH)?;
    let steps = (span_px / QUARTER_PX).ceil().max(2.0) as usize;
    let along: Vec<(f64, Point2<f64>)> = (0..=steps)
        .filter_map(|k| {
            let inverse_depth = far + (near - far) * k as f64 / steps as f64;
            Some((inverse_depth, right_px(inverse_depth)?))
        })
        .collect();
    let at: Vec<(i64, i64)> = along
        .iter()
        .map(|(_, q)| {
            let c = to_level(*q, QUARTER);
            (c.x.round() as i64, c.y.round() as i64)
        })
        .collect();
    let scores: Vec<(f64, Point2<f64>, f32)> = along
        .iter()
        .zip(right.quarter.correlate_at(&reference, &at, QUARTER_PATCH))
        .filter(|(_, s)| s.is_finite())
        .map(|(&(inverse_depth, q), s)| (inverse_depth, q, s))
        .collect();
    let &(best_rho, best_px, best) = scores.iter().max_by(|a, b| a.2.total_cmp(&b.2))?;
    if best < config.min_correlation {
        return None;
    }
    let rival = scores
        .iter()
        .filter(|s| (s.1 - best_px).norm() > RIVAL_APART_PX)
        .map(|s| s.2)
        .fold(f32::NEG_INFINITY, f32::max);
    if rival > best - config.min_margin {
        return None;
    }
    // Fine: whole pixels along the line at full resolution, ±6 px around the coarse match (each
    // on the pixel row nearest the line), then a parabola through the peak.
    let (px, py) = (p.x.round() as i64, p.y.round() as i64);
    let reference = patch_at(&left.full, px, py, EPIPOLAR_PATCH)?;
    let per_px = (near - far) / span_px.max(1e-9);
    let along: Vec<(f64, (i64, i64))> = (-EPIPOLAR_FINE_PX..=EPIPOLAR_FINE_PX)
        .filter_map(|k| {
            let rho = best_rho + per_px * k as f64;
            let q = right_px(rho).filter(|_| rho > 0.0)?;
            Some((rho, (q.x.round() as i64, q.y.round() as i64)))
        })
        .collect();
    let at: Vec<(i64, i64)> = along.iter().map(|a| a.1).collect();
    let fine: Vec<(f64, f32)> = along
        .iter()
        .zip(right.full.correlate_at(&reference, &at, EPIPOLAR_PATCH))
        .filter(|(_, s)| s.is_finite())
        .map(|(&(rho, _), s)| (rho, s))
        .collect();
    let (i, &(rho, peak)) = fine
        .iter()
        .enumerate()
        .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1))?;
    if i == 0 || i + 1 == fine.len() || peak < config.min_correlation - 0.1 {
        return None;
    }
    let offset = vertex(fine[i - 1].1, peak, fine[i + 1].1) as f64;
    right_px(rho + (fine[i + 1].0 - rho) * offset)
}

/// Where left pixel `p` of frame `a` is in frame `b`'s left image, looked for around `guess`:
/// at half resolution over the search radius, then at full resolution around the best; `None`
/// when no match stands out.
pub(super) fn track(
    a: &VoImage,
    b: &VoImage,
    p: Point2<f64>,
    guess: Point2<f64>,
    scale: f64,
    config: &VoConfig,
) -> Option<Point2<f64>> {
    // The reference patches are taken from `a` as they will look in `b`: magnified `scale` times.
    let step = 1.0 / scale;
    // Quarter resolution over the whole search radius.
    let pa = to_level(p, QUARTER);
    let (qx, qy) = (pa.x.round() as i64, pa.y.round() as i64);
    let reference = patch_scaled(&a.quarter, qx, qy, QUARTER_PATCH, step)?;
    let g = to_level(guess, QUARTER);
    let (gx, gy) = (g.x.round() as i64, g.y.round() as i64);
    let r = (config.search_radius_px / QUARTER_PX).ceil() as i64;
    let at = square((gx, gy), r);
    let scores: Vec<(i64, i64, f32)> = at
        .iter()
        .zip(b.quarter.correlate_at(&reference, &at, QUARTER_PATCH))
        .filter(|(_, s)| s.is_finite())
        .map(|(&(x, y), s)| (x - gx, y - gy, s))
        .collect();
    let &(bx, by, best) = scores.iter().max_by(|a, b| a.2.total_cmp(&b.2))?;
    if best < config.min_correlation {
        return None;
    }
    let rival = scores
        .iter()
        .filter(|(dx, dy, _)| {
            (dx - bx).abs() > RIVAL_APART_QUARTER_PX || (dy - by).abs() > RIVAL_APART_QUARTER_PX
        })
        .map(|s| s.2)
        .fold(f32::NEG_INFINITY, f32::max);
    if rival > best - config.min_margin {
        return None;
    }
    // Half resolution: ±2 px around the quarter-resolution match.
    let pa = to_level(p, HALF);
    let (ax, ay) = (pa.x.round() as i64, pa.y.round() as i64);
    let reference = patch_scaled(&a.half, ax, ay, HALF_PATCH, step)?;
    let centre = to_level(
        from_level(Point2::new((gx + bx) as f64, (gy + by) as f64), QUARTER)
            + (p - from_level(Point2::new(qx as f64, qy as f64), QUARTER)),
        HALF,
    );
    let (hx, hy) = (centre.x.round() as i64, centre.y.round() as i64);
    let at = square((hx, hy), HALF_SEARCH_PX);
    let (mut best, mut bx, mut by) = (f32::NEG_INFINITY, hx, hy);
    for (&(x, y), s) in at
        .iter()
        .zip(b.half.correlate_at(&reference, &at, HALF_PATCH))
    {
        if s > best {
            (best, bx, by) = (s, x, y);
        }
    }
    if best < config.min_correlation {
        return None;
    }
    // Full resolution: the pixel the half-resolution match lands on (`p`'s offset from its
    // half-resolution pixel kept), ±3 px around it, then a parabola each way through the peak.
    let coarse = from_level(Point2::new(bx as f64, by as f64), HALF)
        + (p - from_level(Point2::new(ax as f64, ay as f64), HALF));
    let (cx, cy) = (coarse.x.round() as i64, coarse.y.round() as i64);
    let (px, py) = (p.x.round() as i64, p.y.round() as i64);
    let reference = patch_scaled(&a.full, px, py, TRACK_PATCH, step)?;
    let at = square((cx, cy), FULL_SEARCH_PX);
    let scores = b.full.correlate_at(&reference, &at, TRACK_PATCH);
    let grid: Vec<&[f32]> = scores.chunks_exact(FULL_SEARCH_SIDE).collect();
    let centre = FULL_SEARCH_PX as usize;
    let cells = (0..FULL_SEARCH_SIDE).flat_map(|j| (0..FULL_SEARCH_SIDE).map(move |i| (i, j)));
    let (peak, i, j) = cells.fold((f32::NEG_INFINITY, centre, centre), |top, (i, j)| {
        if grid[j][i] > top.0 {
            (grid[j][i], i, j)
        } else {
            top
        }
    });
    let edge = FULL_SEARCH_SIDE - 1;
    if i == 0 || j == 0 || i == edge || j == edge || peak < config.min_correlation - 0.1 {
        return None;
    }
    let ox = vertex(grid[j][i - 1], peak, grid[j][i + 1]) as f64;
    let oy = vertex(grid[j - 1][i], peak, grid[j + 1][i]) as f64;
    Some(Point2::new(
        (cx + i as i64 - FULL_SEARCH_PX) as f64 + ox,
        (cy + j as i64 - FULL_SEARCH_PX) as f64 + oy,
    ))
}

/// A corner of frame `a`'s left image with its 3D position in that camera's frame.
#[derive(Debug, Clone, Copy)]
pub(super) struct StereoPoint {
    pub(super) px: Point2<f64>,
    pub(super) in_left: Vector3<f64>,
}

/// Corners of the left image found again in the right image, triangulated.
pub(super) fn stereo_points(
    rig: &StereoRig,
    left: &VoImage,
    right: &VoImage,
    config: &VoConfig,
) -> Vec<StereoPoint> {
    corners(left, config)
        .into_iter()
        .filter_map(|px| {
            let q = epipolar_match(rig, left, right, px, config)?;
            let in_left = triangulate_point(rig, &px, &q)?;
            let (near, far) = config.depth_range_m;
            (in_left.z >= near && in_left.z <= far).then_some(StereoPoint { px, in_left })
        })
        .collect()
}
