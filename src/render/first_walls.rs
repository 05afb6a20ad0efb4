//! From one eye, the wall that every ray of a narrow wedge of azimuths meets first, seen from
//! above: found once per picture for the wedges a camera sees, so that a ray in a wedge whose
//! first wall is proven tests that one wall instead of walking the wall grid.
//!
//! The proof, per wedge: the rays along both its sides first cross the same wall `k`, strictly
//! inside its ends, with no other wall crossed near that distance; and no wall's end lies in
//! the triangle of the eye and those two crossings. A wall that no side ray crosses before `k`
//! and that has no end in the triangle cannot cross it (a straight segment entering it must
//! leave it through a side, before `k`, or through `k`'s piece, which it could cross only once),
//! so every ray between the sides crosses `k` first. When `k` reaches the ceiling, a ray in the
//! wedge meets the floor, the ceiling or `k`, whichever comes first: one test, with the same
//! arithmetic as the walk's (so the pictures are the same to the byte). Wedges without a proof
//! (a wall's end in them, a low wall, a tie) are walked as before.

use super::scene::WallSpan;
use super::walls_grid::WallGrid;
use crate::geometry::Segment;
use nalgebra::Point2;
use nalgebra::Vector3;
use rayon::prelude::*;

/// A wedge spans this much azimuth straight ahead of the camera (a pixel column or so of the
/// default rig), radians: 0.1 degrees.
const WEDGE_RAD: f64 = 0.1 * std::f64::consts::PI / 180.0;
/// Margins of the proof: crossings closer than this part of their distance are ties, and a
/// wall's end this close to a wedge counts as in it, metres.
const RELATIVE_MARGIN: f64 = 1e-6;
const MARGIN_M: f64 = 1e-6;
/// No table when a wall passes this close to the eye, metres.
const EYE_CLEARANCE_M: f64 = 1e-3;
/// No table for a camera whose view spans more than this either side of its heading.
const MAX_HALF_VIEW_RAD: f64 = 80.0 * std::f64::consts::PI / 180.0;
/// A wedge without a proven first wall.
const UNPROVEN: u32 = u32::MAX;

/// The proven first walls of the wedges one camera sees, from its eye.
#[derive(Debug, Clone)]
pub(super) struct FirstWalls {
    eye: Vector3<f64>,
    /// The camera's heading seen from above and its left, unit vectors: a ray's wedge is found
    /// from the tangent of its azimuth off the heading, `s = (dir . left) / (dir . forward)`.
    forward: (f64, f64),
    left: (f64, f64),
    /// Wedge `j` spans `s` in `[s0 + j step, s0 + (j + 1) step)`.
    s0: f64,
    inverse_step: f64,
    /// Per wedge: the wall (its place in the scene) its rays meet first, or [`UNPROVEN`].
    first: Vec<u32>,
}

/// Along one side ray: the nearest wall crossed, whether the crossing is clean (inside the
/// wall's ends, no other wall near it), and its distance.
#[derive(Debug, Clone, Copy)]
struct SideHit {
    wall: u32,
    clean: bool,
    t: f64,
}

impl FirstWalls {
    /// The table for a camera at `eye` looking along `axis`, whose rays lie within `off_axis_rad`
    /// of it; `None` when there is nothing to gain (a view taking in the vertical or too wide, a
    /// wall at the eye).
    pub(super) fn new(
        grid: &WallGrid,
        walls: &[WallSpan],
        ceiling_m: f64,
        eye: &Vector3<f64>,
        axis: &Vector3<f64>,
        off_axis_rad: f64,
    ) -> Option<Self> {
        let level = axis.x.hypot(axis.y);
        if level < 1e-6 {
            return None;
        }
        let forward = (axis.x / level, axis.y / level);
        let left = (-forward.1, forward.0);
        // The azimuths the cone of rays covers either side of the heading (as the view wedges
        // reckon them), with a degree of margin.
        let elevation = axis.z.clamp(-1.0, 1.0).asin();
        let cone = off_axis_rad + 1f64.to_radians();
        if cone >= std::f64::consts::FRAC_PI_2 - elevation.abs() {
            return None;
        }
        let half = (cone.sin() / elevation.cos()).min(1.0).asin() + 1f64.to_radians();
        if half > MAX_HALF_VIEW_RAD {
            return None;
        }
        let e = (eye.x, eye.y);
        if walls.iter().any(|w| {
            let a = Point2::new(w.a.0, w.a.1);
            let segment = Segment::new(a, a + nalgebra::Vector2::new(w.e.0, w.e.1));
            segment.distance_to(Point2::new(e.0, e.1)) < EYE_CLEARANCE_M
        }) {
            return None;
        }
        let step = WEDGE_RAD.tan();
        let s_max = half.tan();
        let wedges = (2.0 * s_max / step).ceil() as usize;
        let s0 = -s_max;
        let sides: Vec<Option<SideHit>> = (0..=wedges)
            .into_par_iter()
            .map(|j| {
                let s = s0 + j as f64 * step;
                let (x, y) = (forward.0 + left.0 * s, forward.1 + left.1 * s);
                let norm = x.hypot(y);
                side_hit(grid, e, (x / norm, y / norm))
            })
            .collect();
        let mut first: Vec<u32> = sides
            .windows(2)
            .map(|pair| match (pair[0], pair[1]) {
                (Some(a), Some(b))
                    if a.clean
                        && b.clean
                        && a.wall == b.wall
                        && walls[a.wall as usize].height_m >= ceiling_m =>
                {
                    a.wall
                }
                _ => UNPROVEN,
            })
            .collect();
        // A wall's end in a wedge's triangle (or at its edge) leaves it unproven.
        let reach = |j: usize| match (sides[j], sides[j + 1]) {
            (Some(a), Some(b)) => a.t.max(b.t) * (1.0 + RELATIVE_MARGIN) + MARGIN_M,
            _ => f64::INFINITY,
        };
        for w in walls {
            for p in [w.a, (w.a.0 + w.e.0, w.a.1 + w.e.1)] {
                let rel = (p.0 - e.0, p.1 - e.1);
                let ahead = rel.0 * forward.0 + rel.1 * forward.1;
                let distance = rel.0.hypot(rel.1);
                if ahead <= 0.0 {
                    continue;
                }
                let s = (rel.0 * left.0 + rel.1 * left.1) / ahead;
                // The end's direction, to within twice the margin over its distance (an angle;
                // `s`, its tangent off the heading, moves 1 + s^2 times as much).
                let slack = (1.0 + s * s) * 2.0 * MARGIN_M / distance.max(MARGIN_M) + 1e-9;
                let lo = ((s - slack - s0) / step).floor();
                let hi = ((s + slack - s0) / step).floor();
                if hi < 0.0 || lo >= wedges as f64 {
                    continue;
                }
                let (lo, hi) = (lo.max(0.0) as usize, hi.min(wedges as f64 - 1.0) as usize);
                for (j, wall) in first.iter_mut().enumerate().take(hi + 1).skip(lo) {
                    if *wall != UNPROVEN && distance <= reach(j) {
                        *wall = UNPROVEN;
                    }
                }
            }
        }
        Some(Self {
            eye: *eye,
            forward,
            left,
            s0,
            inverse_step: 1.0 / step,
            first,
        })
    }

    /// The wall every ray from `origin` along `dir` in its wedge meets first, when proven
    /// (`None`: walk the grid). `origin` must be the table's eye.
    #[inline]
    pub(super) fn lookup(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> Option<usize> {
        if *origin != self.eye {
            return None;
        }
        let ahead = dir.x * self.forward.0 + dir.y * self.forward.1;
        if ahead <= 1e-9 {
            return None;
        }
        let s = (dir.x * self.left.0 + dir.y * self.left.1) / ahead;
        let x = (s - self.s0) * self.inverse_step;
        // Also refuses NaN.
        if x.is_nan() || x < 0.0 {
            return None;
        }
        match self.first.get(x as usize) {
            Some(&k) if k != UNPROVEN => Some(k as usize),
            _ => None,
        }
    }

    /// The share of wedges with a proven first wall (for measuring).
    #[cfg(test)]
    pub(super) fn proven_share(&self) -> f64 {
        let proven = self.first.iter().filter(|&&k| k != UNPROVEN).count();
        proven as f64 / self.first.len().max(1) as f64
    }
}

/// The nearest wall the ray `eye + t dir` (unit `dir`, seen from above) crosses, walking the grid
/// a margin past it so that a crossing tied with it is seen; `None` when it crosses none.
fn side_hit(grid: &WallGrid, eye: (f64, f64), dir: (f64, f64)) -> Option<SideHit> {
    let mut best: Option<SideHit> = None;
    let beyond = |t: f64| t * (1.0 + RELATIVE_MARGIN) + MARGIN_M;
    grid.walk(eye, dir, |cell| {
        for w in grid.walls(cell) {
            let denom = dir.0 * w.e.1 - dir.1 * w.e.0;
            let length = w.e.0.hypot(w.e.1);
            if denom.abs() < 1e-12 * length {
                continue; // along the ray: never its first crossing, as the walk's test says
            }
            let (wx, wy) = (w.a.0 - eye.0, w.a.1 - eye.1);
            let t = (wx * w.e.1 - wy * w.e.0) / denom;
            let u = (wx * dir.1 - wy * dir.0) / denom;
            // Ends widened by the margin: a crossing near an end counts, and is not clean.
            let slack = MARGIN_M / length.max(1e-12);
            if t <= 0.0 || u < -slack || u > 1.0 + slack {
                continue;
            }
            let inside = u > slack && u < 1.0 - slack;
            best = Some(match best {
                None => SideHit {
                    wall: w.k,
                    clean: inside,
                    t,
                },
                Some(b) if t < b.t => SideHit {
                    wall: w.k,
                    clean: inside && beyond(t) < b.t,
                    t,
                },
                Some(b) => SideHit {
                    clean: b.clean && (w.k == b.wall || beyond(b.t) < t),
                    ..b
                },
            });
        }
        best.is_none_or(|b| beyond(b.t) >= cell.exit_t)
    });
    best
}
