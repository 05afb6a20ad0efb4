//! A uniform grid over the walls seen from above, so that a ray tests only the walls of the cells
//! it crosses, nearest first, and stops at the first cell that holds a hit: a building traced from
//! a laser map has thousands of wall segments, of which a ray meets a handful of cells' worth.

use super::scene::WallSpan;

/// Worlds with more walls than this are rendered through the grid; fewer are tested one by one
/// (the office's 8 and the museum's 18, where the grid would only add its walk; willow, traced
/// from a building map, has 805).
pub(super) const GRID_FROM_WALLS: usize = 64;
/// Worlds with more walls than this leave the edges hidden behind floor-to-ceiling walls out of
/// the detail mask ([`Occlusion`]): a building traced from a laser map (freiburg-079: 1,800).
/// The pictures change by at most a grey level where a pixel is traced with one ray instead of
/// all its samples, so the sample worlds (willow: 805) stay below it and render as before, to
/// the byte.
pub(super) const OCCLUSION_FROM_WALLS: usize = 1000;

/// The grid's cells are at least this big, metres: 0.5 m.
const MIN_CELL_M: f64 = 0.5;
/// ... and the grid at most this many cells on a side.
const MAX_SIDE_CELLS: usize = 512;
/// A wall is listed in every cell it passes within this of, metres (rounding at cell edges).
const LIST_MARGIN_M: f64 = 1e-6;

/// Walls binned by the cells their floor segments cross.
#[derive(Debug, Clone)]
pub(super) struct WallGrid {
    origin: (f64, f64),
    cell_m: f64,
    cols: usize,
    rows: usize,
    /// Cell `i`'s walls are `items[starts[i]..starts[i + 1]]`, in increasing index.
    starts: Vec<u32>,
    items: Vec<CellWall>,
}

/// A wall as a cell lists it: its index and a copy of what a ray tests (so that a cell's walls
/// lie together in memory).
#[derive(Debug, Clone, Copy)]
pub(super) struct CellWall {
    /// The wall's index in the scene.
    pub(super) k: u32,
    /// Its floor segment `a + u e`.
    pub(super) a: (f64, f64),
    pub(super) e: (f64, f64),
    /// Its height.
    pub(super) height_m: f64,
}

/// One cell a ray crosses and the ray parameter where it leaves it.
#[derive(Debug, Clone, Copy)]
pub(super) struct CellVisit {
    /// The cell's walls.
    pub(super) start: usize,
    pub(super) end: usize,
    /// The ray parameter at which the ray leaves the cell.
    pub(super) exit_t: f64,
}

impl WallGrid {
    /// The grid over `walls`; `None` without walls.
    pub(super) fn new(walls: &[WallSpan]) -> Option<Self> {
        let mut lo = (f64::INFINITY, f64::INFINITY);
        let mut hi = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        for w in walls {
            for p in [w.a, (w.a.0 + w.e.0, w.a.1 + w.e.1)] {
                lo = (lo.0.min(p.0), lo.1.min(p.1));
                hi = (hi.0.max(p.0), hi.1.max(p.1));
            }
        }
        if !(lo.0.is_finite() && lo.1.is_finite() && hi.0.is_finite() && hi.1.is_finite()) {
            return None;
        }
        let margin = 2.0 * LIST_MARGIN_M + 1e-9;
        let origin = (lo.0 - margin, lo.1 - margin);
        let extent = (hi.0 - lo.0 + 2.0 * margin).max(hi.1 - lo.1 + 2.0 * margin);
        let cell_m = (extent / MAX_SIDE_CELLS as f64).max(MIN_CELL_M);
        let cols = ((hi.0 + margin - origin.0) / cell_m).ceil().max(1.0) as usize;
        let rows = ((hi.1 + margin - origin.1) / cell_m).ceil().max(1.0) as usize;
        let mut lists: Vec<Vec<CellWall>> = vec![Vec::new(); cols * rows];
        for (k, w) in walls.iter().enumerate() {
            let b = (w.a.0 + w.e.0, w.a.1 + w.e.1);
            let cell = |x: f64, y: f64| {
                (
                    (((x - origin.0) / cell_m).floor().max(0.0) as usize).min(cols - 1),
                    (((y - origin.1) / cell_m).floor().max(0.0) as usize).min(rows - 1),
                )
            };
            let (c0, r0) = cell(
                w.a.0.min(b.0) - LIST_MARGIN_M,
                w.a.1.min(b.1) - LIST_MARGIN_M,
            );
            let (c1, r1) = cell(
                w.a.0.max(b.0) + LIST_MARGIN_M,
                w.a.1.max(b.1) + LIST_MARGIN_M,
            );
            for r in r0..=r1 {
                for c in c0..=c1 {
                    let x0 = origin.0 + c as f64 * cell_m - LIST_MARGIN_M;
                    let y0 = origin.1 + r as f64 * cell_m - LIST_MARGIN_M;
                    let side = cell_m + 2.0 * LIST_MARGIN_M;
                    if segment_meets_box(w.a, b, (x0, y0), (x0 + side, y0 + side)) {
                        lists[r * cols + c].push(CellWall {
                            k: k as u32,
                            a: w.a,
                            e: w.e,
                            height_m: w.height_m,
                        });
                    }
                }
            }
        }
        let mut starts = Vec::with_capacity(lists.len() + 1);
        let mut items = Vec::new();
        for list in &lists {
            starts.push(items.len() as u32);
            items.extend_from_slice(list);
        }
        starts.push(items.len() as u32);
        Some(Self {
            origin,
            cell_m,
            cols,
            rows,
            starts,
            items,
        })
    }

    /// The walls of a visited cell, in increasing index.
    pub(super) fn walls(&self, visit: &CellVisit) -> &[CellWall] {
        &self.items[visit.start..visit.end]
    }

    /// Calls `visit` for the cells the ray `origin + t dir` (seen from above, `t` >= 0) crosses,
    /// nearest first, until it returns `false` or the ray leaves the grid.
    pub(super) fn walk(
        &self,
        origin: (f64, f64),
        dir: (f64, f64),
        mut visit: impl FnMut(&CellVisit) -> bool,
    ) {
        // The part of the ray inside the grid's box (slabs).
        let size = (
            self.cols as f64 * self.cell_m,
            self.rows as f64 * self.cell_m,
        );
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for (o, d, lo, len) in [
            (origin.0, dir.0, self.origin.0, size.0),
            (origin.1, dir.1, self.origin.1, size.1),
        ] {
            if d == 0.0 {
                if o < lo || o > lo + len {
                    return;
                }
            } else {
                let (a, b) = ((lo - o) / d, (lo + len - o) / d);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        if t0 > t1 {
            return;
        }
        let p = (origin.0 + t0 * dir.0, origin.1 + t0 * dir.1);
        let clamp = |v: f64, n: usize| (v.floor().max(0.0) as usize).min(n - 1) as i64;
        let mut c = clamp((p.0 - self.origin.0) / self.cell_m, self.cols);
        let mut r = clamp((p.1 - self.origin.1) / self.cell_m, self.rows);
        let step = |d: f64| if d > 0.0 { 1 } else { -1 };
        let (sc, sr) = (step(dir.0), step(dir.1));
        // The ray parameter of the next column and row edges.
        let edge = |i: i64, s: i64, lo: f64, o: f64, d: f64| {
            if d == 0.0 {
                f64::INFINITY
            } else {
                (lo + (i + (s > 0) as i64) as f64 * self.cell_m - o) / d
            }
        };
        let mut tx = edge(c, sc, self.origin.0, origin.0, dir.0);
        let mut ty = edge(r, sr, self.origin.1, origin.1, dir.1);
        let (dtx, dty) = (
            if dir.0 == 0.0 {
                f64::INFINITY
            } else {
                self.cell_m / dir.0.abs()
            },
            if dir.1 == 0.0 {
                f64::INFINITY
            } else {
                self.cell_m / dir.1.abs()
            },
        );
        while c >= 0 && r >= 0 && (c as usize) < self.cols && (r as usize) < self.rows {
            let i = r as usize * self.cols + c as usize;
            let cell = CellVisit {
                start: self.starts[i] as usize,
                end: self.starts[i + 1] as usize,
                exit_t: tx.min(ty),
            };
            if !visit(&cell) {
                return;
            }
            if tx < ty {
                c += sc;
                tx += dtx;
            } else {
                r += sr;
                ty += dty;
            }
        }
    }
}

/// Azimuth step of [`Occlusion`]'s table of nearest walls: 0.05 degrees.
const OCCLUSION_STEP_RAD: f64 = 0.05 * std::f64::consts::PI / 180.0;
/// A point is hidden only when it lies this much beyond the wall in front of it, metres.
const OCCLUSION_MARGIN_M: f64 = 0.01;

/// What a camera cannot see behind the walls that reach the ceiling, seen from above: a point
/// is hidden when the rays at both ends of its azimuth step (of [`OCCLUSION_STEP_RAD`]) meet the
/// same such wall nearer than it. A straight wall met by two rays from one eye is met by every
/// ray between them, no further than the further of the two, so nothing visible is called
/// hidden; a floor-to-ceiling wall hides every height.
pub(super) struct Occlusion<'a> {
    grid: &'a WallGrid,
    full_height_m: f64,
    eye: (f64, f64),
    /// Per azimuth step edge, once walked: the nearest full-height wall and its distance.
    nearest: Vec<Option<Option<(usize, f64)>>>,
}

impl<'a> Occlusion<'a> {
    /// The occlusion seen from `eye` by walls at least `full_height_m` high.
    pub(super) fn new(grid: &'a WallGrid, full_height_m: f64, eye: (f64, f64)) -> Self {
        let steps = (std::f64::consts::TAU / OCCLUSION_STEP_RAD).ceil() as usize + 1;
        Self {
            grid,
            full_height_m,
            eye,
            nearest: vec![None; steps],
        }
    }

    /// Whether the point `p` (seen from above) is hidden from the eye.
    pub(super) fn hidden(&mut self, p: (f64, f64)) -> bool {
        let d = (p.0 - self.eye.0).hypot(p.1 - self.eye.1);
        if d.is_nan() || d <= OCCLUSION_MARGIN_M {
            return false;
        }
        let azimuth = (p.1 - self.eye.1)
            .atan2(p.0 - self.eye.0)
            .rem_euclid(std::f64::consts::TAU);
        let i = ((azimuth / OCCLUSION_STEP_RAD) as usize).min(self.nearest.len() - 2);
        match (self.edge(i), self.edge(i + 1)) {
            (Some((k0, d0)), Some((k1, d1))) => k0 == k1 && d > d0.max(d1) + OCCLUSION_MARGIN_M,
            _ => false,
        }
    }

    /// Whether the whole segment `a`-`b` (seen from above) is hidden: the rays to both its ends
    /// meet the same full-height wall nearer than it. Two straight segments, one behind the
    /// other at both ends of an angle from the eye, do not cross within it, so the wall hides
    /// the whole of it.
    pub(super) fn hides_segment(&self, a: (f64, f64), b: (f64, f64)) -> bool {
        let behind = |p: (f64, f64)| {
            let d = (p.0 - self.eye.0).hypot(p.1 - self.eye.1);
            if d.is_nan() || d <= OCCLUSION_MARGIN_M {
                return None;
            }
            let dir = ((p.0 - self.eye.0) / d, (p.1 - self.eye.1) / d);
            self.nearest_along(dir)
                .filter(|&(_, t)| d > t + OCCLUSION_MARGIN_M)
                .map(|(k, _)| k)
        };
        matches!((behind(a), behind(b)), (Some(k0), Some(k1)) if k0 == k1)
    }

    /// The nearest full-height wall along the ray at azimuth step edge `i`.
    fn edge(&mut self, i: usize) -> Option<(usize, f64)> {
        if let Some(known) = self.nearest[i] {
            return known;
        }
        let (s, c) = (i as f64 * OCCLUSION_STEP_RAD).sin_cos();
        let best = self.nearest_along((c, s));
        self.nearest[i] = Some(best);
        best
    }

    /// The nearest full-height wall along the unit direction `(c, s)` from the eye, and its
    /// distance.
    fn nearest_along(&self, (c, s): (f64, f64)) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        let (full, eye) = (self.full_height_m, self.eye);
        self.grid.walk(eye, (c, s), |cell| {
            for w in self.grid.walls(cell) {
                let k = w.k;
                if w.height_m < full {
                    continue;
                }
                // eye + t (c, s) = a + u e.
                let denom = c * w.e.1 - s * w.e.0;
                if denom.abs() < 1e-12 {
                    continue;
                }
                let (wx, wy) = (w.a.0 - eye.0, w.a.1 - eye.1);
                let t = (wx * w.e.1 - wy * w.e.0) / denom;
                let u = (wx * s - wy * c) / denom;
                if t > 0.0
                    && (0.0..=1.0).contains(&u)
                    && t <= cell.exit_t
                    && best.is_none_or(|(_, b)| t < b)
                {
                    best = Some((k as usize, t));
                }
            }
            best.is_none_or(|(_, b)| b > cell.exit_t)
        });
        best
    }
}

/// Whether the segment `a`-`b` meets the box `lo`-`hi` (Liang-Barsky clipping).
fn segment_meets_box(a: (f64, f64), b: (f64, f64), lo: (f64, f64), hi: (f64, f64)) -> bool {
    let d = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-d.0, a.0 - lo.0),
        (d.0, hi.0 - a.0),
        (-d.1, a.1 - lo.1),
        (d.1, hi.1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    t0 <= t1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(a: (f64, f64), b: (f64, f64)) -> WallSpan {
        WallSpan::new(&crate::world::Wall {
            segment: crate::geometry::Segment::new(
                nalgebra::Point2::new(a.0, a.1),
                nalgebra::Point2::new(b.0, b.1),
            ),
            height_m: 2.5,
        })
    }

    #[test]
    fn a_ray_visits_the_cells_of_the_walls_it_crosses_nearest_first() {
        let walls = vec![
            span((0.0, 0.0), (100.0, 0.0)),
            span((50.0, -5.0), (50.0, 5.0)),
        ];
        let grid = WallGrid::new(&walls).unwrap();
        assert!(grid.cell_m >= MIN_CELL_M && grid.cols <= MAX_SIDE_CELLS);
        let mut seen = Vec::new();
        let mut last_t = 0.0;
        grid.walk((1.0, 1.0), (1.0, -0.1), |cell| {
            assert!(cell.exit_t >= last_t);
            last_t = cell.exit_t;
            seen.extend(grid.walls(cell).iter().map(|w| w.k));
            cell.exit_t < 10.0
        });
        // The ray from (1, 1) down at a tenth meets y = 0 at t = 10 (x = 11): walked up to
        // there, it has passed the floor wall's cells and none of the wall at x = 50.
        assert!(seen.contains(&0) && !seen.contains(&1));
        // Along the x axis it passes the vertical wall's cells.
        let mut seen = Vec::new();
        grid.walk((1.0, 0.5), (1.0, 0.0), |cell| {
            seen.extend(grid.walls(cell).iter().map(|w| w.k));
            true
        });
        assert!(seen.contains(&1));
    }
}
