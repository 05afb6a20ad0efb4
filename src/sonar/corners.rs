//! Walls near a point, from the sonar arcs tangent to them, and room corners as their crossings.
//!
//! A sonar echo off a flat wall comes from the foot of the perpendicular, so the wall is tangent
//! to the reading's arc: for each direction `a` inside the cone, the reading votes for the line
//! with normal `a` at distance `range` from the sensor (a line Hough transform, as in Tardós et
//! al., "Robust mapping and localization in indoor environments using sonar data", 2002). Every
//! reading of one wall votes for the same line, whatever the robot's position along it; the
//! line's position is as precise as the ranges, not the 30 degree beam.
//!
//! The point Hough transform ([`crate::sonar::hough`]) finds *where* something reflects from many
//! directions; around a room corner its peak sits on one of the walls 0.2-0.6 m from the corner,
//! because the robot rounds the corner close to both walls. [`place_peak`] looks for two walls
//! near such a peak and, when they cross near it and both reach the crossing, moves the feature
//! there. A peak on a wall where the grid shows free space on one side is the wall's end (a door
//! jamb); one with the wall going on to both sides is dropped, unless the robot went through the
//! wall's line on one side and the wall's echoes stop there: a doorway the wide cone painted
//! closed in the grid.

use crate::sonar::grid::OccupancyMap;
use crate::sonar::tangent::{
    cone_range, fast_acos, fast_atan2, steps_between, LineVotes, Strongest, ANGLE_STEP_DEG,
    DIST_STEP_M, FAST_ACOS_ERROR,
};
use crate::sonar::PlacedReading;
use std::collections::HashMap;

/// Tangent points farther than this from the candidate are ignored: 1.5 m.
const SEARCH_RADIUS_M: f64 = 1.5;
/// A wall needs this many votes (readings): 6.
const MIN_WALL_VOTES: u32 = 6;
/// Walls closer than this in angle (and [`SUPPRESS_DIST_M`] in distance) are one.
const SUPPRESS_ANGLE_DEG: f64 = 15.0;
/// ... and closer than this in distance.
const SUPPRESS_DIST_M: f64 = 0.15;
/// Two walls make a corner when they meet at this angle or more: 60 degrees (the cone's edge
/// echoes make weak false walls 10-35 degrees off the true ones).
const MIN_CORNER_ANGLE_DEG: f64 = 60.0;
/// A corner further than this from the candidate is not its corner: 1 m.
const MAX_SNAP_M: f64 = 1.0;
/// Each wall must have been seen this close to the crossing: 1 m (the robot turns 0.5-0.9 m
/// before a corner; no corner where two walls' extensions meet in open space).
const MAX_WALL_GAP_M: f64 = 1.0;
/// A wall ends at a crossing when it was seen no further than this past it: 15 cm.
const END_SLACK_M: f64 = 0.15;
/// Walls searched per candidate.
const MAX_WALLS: usize = 6;

/// A wall line near a point: `n . (p - centre) = offset_m`, `n = (cos a, sin a)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalWall {
    /// Normal direction, radians, in [0, pi).
    pub normal_rad: f64,
    /// Signed distance of the line from the centre it was found around, metres.
    pub offset_m: f64,
    /// Readings that voted for it.
    pub votes: u32,
}

/// Adds to `out` the tangent lines one reading votes for: for each accumulator angle inside the
/// cone whose tangent point lies within [`SEARCH_RADIUS_M`] of `centre`, the line (normal in
/// [0, pi), offset from the centre) and the point.
fn push_tangents(
    r: &PlacedReading,
    beam: &Beam,
    half_cone_rad: f64,
    centre: (f64, f64),
    out: &mut Vec<Tangent>,
) {
    let (range, p) = (r.range_m.unwrap_or(f64::NAN), r.world_from_sensor);
    if !(range.is_finite() && range >= 0.0) {
        return;
    }
    for cs in steps_between(near_steps(r, beam, range, half_cone_rad, centre)) {
        let (s, c) = (cs.sin, cs.cos);
        let t = (p.x + range * c, p.y + range * s);
        let (dx, dy) = (t.0 - centre.0, t.1 - centre.1);
        if dx * dx + dy * dy > SEARCH_RADIUS_M * SEARCH_RADIUS_M {
            continue;
        }
        let offset = c * (t.0 - centre.0) + s * (t.1 - centre.1);
        out.push(Tangent {
            normal: cs.normal,
            cell: cs.normal_cell,
            offset: if cs.flipped { -offset } else { offset },
            point: t,
        });
    }
}

/// The steps of a reading's cone ([`cone_range`]) whose arc points may lie within
/// [`SEARCH_RADIUS_M`] of `centre` (all that do, and a step more each side): by the law of
/// cosines, the point at direction `a` does when `cos(a - phi) >= (D^2 + r^2 - R^2) / (2 r D)`,
/// `phi` and `D` the direction and distance from the sensor to the centre. Only those are worth
/// the exact test.
fn near_steps(
    r: &PlacedReading,
    beam: &Beam,
    range: f64,
    half_cone_rad: f64,
    centre: (f64, f64),
) -> std::ops::RangeInclusive<i64> {
    let step = ANGLE_STEP_DEG.to_radians();
    let p = r.world_from_sensor;
    let cone = beam.cone.clone();
    let (dx, dy) = (centre.0 - p.x, centre.1 - p.y);
    let d = (dx * dx + dy * dy).sqrt();
    if (range * d <= 1e-9) || (range * d).is_nan() {
        return cone;
    }
    let q = (d * d + range * range - SEARCH_RADIUS_M * SEARCH_RADIUS_M) / (2.0 * range * d);
    // Any window holding the near steps will do (the exact test follows), so the arccosine
    // need not be exact: widened by its error, a cheap one serves.
    let half_window = fast_acos(q.clamp(-1.0, 1.0)) + FAST_ACOS_ERROR;
    // Past half a turn between the cone and the window, the window would wrap: take the cone.
    if half_window + half_cone_rad + 2.0 * step >= std::f64::consts::PI {
        return cone;
    }
    // The centre's direction seen from the beam's axis (to within 2e-5 rad: the step more each
    // side covers it).
    let (sin, cos) = beam.sin_cos;
    let phi = p.theta + fast_atan2(cos * dy - sin * dx, cos * dx + sin * dy);
    let lo = ((phi - half_window) / step).floor() as i64 - 1;
    let hi = ((phi + half_window) / step).ceil() as i64 + 1;
    (*cone.start()).max(lo)..=(*cone.end()).min(hi)
}

/// One reading's vote for a wall near the centre: the tangent line (normal in [0, pi), offset
/// from the centre) and the point where it touches the reading's arc.
#[derive(Debug, Clone, Copy)]
struct Tangent {
    normal: f64,
    /// The normal's nearest whole step (180 for a normal just short of pi).
    cell: usize,
    offset: f64,
    point: (f64, f64),
}

/// Side of an [`Arcs`] bucket: 1 m.
const BUCKET_M: f64 = 1.0;

/// The bucket of a point.
fn bucket_of(p: (f64, f64)) -> (i64, i64) {
    (
        (p.0 / BUCKET_M).floor() as i64,
        (p.1 / BUCKET_M).floor() as i64,
    )
}

/// A run's readings with their arcs bucketed by where they lie, so that the readings whose arcs
/// pass near a point are found without looking at the whole run: placing each Hough peak once
/// read every reading, and a map's time grew with its peaks times its readings (44 µs a reading
/// on a real building's log).
#[derive(Debug, Clone)]
pub struct Arcs<'a> {
    readings: &'a [PlacedReading],
    half_cone_rad: f64,
    /// Indices of the readings whose arc's middle (the sensor plus the range along its axis)
    /// lies in each bucket, ascending.
    buckets: HashMap<(i64, i64), Vec<usize>>,
    /// The farthest any point of an arc lies from the arc's middle, metres.
    reach_m: f64,
    /// Indices of the readings whose sensor lies in each bucket, ascending.
    sensors: HashMap<(i64, i64), Vec<usize>>,
    /// Each reading's cone and beam direction, worked out once rather than at every peak.
    beams: Vec<Beam>,
}

/// What every placement needs of a reading's beam: its cone's whole steps ([`cone_range`]) and
/// the sine and cosine of its direction.
#[derive(Debug, Clone)]
struct Beam {
    cone: std::ops::RangeInclusive<i64>,
    sin_cos: (f64, f64),
}

/// A robot that passed through a wall's line this far beyond a peak on it (metres, along the
/// wall) went through an opening: 0.2 to 1.0 m (a door's jamb is its edge).
const DOORWAY_M: (f64, f64) = (0.2, 1.0);
/// ... with a sensor this close to the line: 0.1 m.
const DOORWAY_ACROSS_M: f64 = 0.1;

impl<'a> Arcs<'a> {
    /// Buckets the arcs of `readings` (cones of half-width `half_cone_rad`). Readings without a
    /// usable echo touch nothing and are left out.
    pub fn new(readings: &'a [PlacedReading], half_cone_rad: f64) -> Self {
        // A point of the arc at angle a off the axis lies 2 r sin(a / 2) from its middle.
        let chord = 2.0 * (0.5 * half_cone_rad.clamp(0.0, std::f64::consts::PI)).sin();
        let mut buckets: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        let mut sensors: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        let mut reach_m = 0.0f64;
        for (i, r) in readings.iter().enumerate() {
            let p = r.world_from_sensor;
            if p.x.is_finite() && p.y.is_finite() {
                sensors.entry(bucket_of((p.x, p.y))).or_default().push(i);
            }
            let Some(range) = r.range_m.filter(|x| x.is_finite() && *x >= 0.0) else {
                continue;
            };
            let p = r.world_from_sensor;
            let middle = (p.x + range * p.theta.cos(), p.y + range * p.theta.sin());
            if middle.0.is_finite() && middle.1.is_finite() {
                reach_m = reach_m.max(chord * range);
                buckets.entry(bucket_of(middle)).or_default().push(i);
            }
        }
        let beams = readings
            .iter()
            .map(|r| Beam {
                cone: cone_range(r.world_from_sensor.theta, half_cone_rad),
                sin_cos: r.world_from_sensor.theta.sin_cos(),
            })
            .collect();
        Self {
            readings,
            half_cone_rad,
            buckets,
            reach_m,
            sensors,
            beams,
        }
    }

    /// Whether one of the first `upto` readings was taken on the line through `point` along
    /// `dir` (a unit vector), [`DOORWAY_M`] beyond it: the robot passed through there.
    fn passed_along(&self, point: (f64, f64), dir: (f64, f64), upto: usize) -> bool {
        let (lo, hi) = DOORWAY_M;
        let middle = 0.5 * (lo + hi);
        let at = (point.0 + middle * dir.0, point.1 + middle * dir.1);
        let radius = 0.5 * (hi - lo) + DOORWAY_ACROSS_M;
        let (b0, b1) = (
            bucket_of((at.0 - radius, at.1 - radius)),
            bucket_of((at.0 + radius, at.1 + radius)),
        );
        (b0.0..=b1.0).any(|bx| {
            (b0.1..=b1.1).any(|by| {
                self.sensors.get(&(bx, by)).is_some_and(|ids| {
                    ids[..ids.partition_point(|&i| i < upto)].iter().any(|&i| {
                        let p = self.readings[i].world_from_sensor;
                        let (dx, dy) = (p.x - point.0, p.y - point.1);
                        let along = dx * dir.0 + dy * dir.1;
                        let across = -dx * dir.1 + dy * dir.0;
                        (lo..=hi).contains(&along) && across.abs() <= DOORWAY_ACROSS_M
                    })
                })
            })
        })
    }

    /// Indices, ascending, of the readings among the first `upto` whose arcs may come within
    /// [`SEARCH_RADIUS_M`] of `centre` (all that do, and some that do not).
    fn near(&self, centre: (f64, f64), upto: usize) -> Vec<usize> {
        let radius = SEARCH_RADIUS_M + self.reach_m;
        let lo = bucket_of((centre.0 - radius, centre.1 - radius));
        let hi = bucket_of((centre.0 + radius, centre.1 + radius));
        let inside = |b: &(i64, i64)| (lo.0..=hi.0).contains(&b.0) && (lo.1..=hi.1).contains(&b.1);
        let span = (hi.0.saturating_sub(lo.0) as u64 + 1)
            .saturating_mul(hi.1.saturating_sub(lo.1) as u64 + 1);
        let mut found = Vec::new();
        let mut take = |ids: &Vec<usize>| {
            found.extend_from_slice(&ids[..ids.partition_point(|&i| i < upto)]);
        };
        if span > self.buckets.len() as u64 {
            // Far-reaching arcs (a long range): fewer buckets held than the box spans.
            self.buckets
                .iter()
                .filter(|(b, _)| inside(b))
                .for_each(|(_, ids)| take(ids));
        } else {
            for bx in lo.0..=hi.0 {
                for by in lo.1..=hi.1 {
                    if let Some(ids) = self.buckets.get(&(bx, by)) {
                        take(ids);
                    }
                }
            }
        }
        found.sort_unstable();
        found
    }

    /// The tangents of the readings among the first `upto` within [`SEARCH_RADIUS_M`] of
    /// `centre`, in the readings' order, into `out` (cleared first).
    fn tangents_near(&self, centre: (f64, f64), upto: usize, out: &mut Vec<Tangent>) {
        out.clear();
        for i in self.near(centre, upto) {
            let r = &self.readings[i];
            if may_touch(r, centre) {
                push_tangents(r, &self.beams[i], self.half_cone_rad, centre, out);
            }
        }
    }
}

/// Whether a reading's arc can reach within [`SEARCH_RADIUS_M`] of `centre` (squared, with a
/// micrometre to spare: the exact test is [`push_tangents`]'s).
fn may_touch(r: &PlacedReading, centre: (f64, f64)) -> bool {
    r.range_m.is_some_and(|range| {
        let p = r.world_from_sensor;
        let (dx, dy) = (p.x - centre.0, p.y - centre.1);
        let reach = range + SEARCH_RADIUS_M + 1e-6;
        dx * dx + dy * dy <= reach * reach
    })
}

/// Walls near `centre`, strongest first, from the readings' tangent lines.
pub fn local_walls(arcs: &Arcs<'_>, centre: (f64, f64)) -> Vec<LocalWall> {
    with_tangents(arcs, centre, arcs.readings.len(), |tangents| {
        walls_from(tangents)
    })
}

thread_local! {
    /// The tangents of the last placement on this thread: a placement reads thousands, and
    /// growing a new list each time was a tenth of the tangents' cost.
    static TANGENTS: std::cell::Cell<Vec<Tangent>> = const { std::cell::Cell::new(Vec::new()) };
}

/// `f` of the tangents of the first `upto` readings within [`SEARCH_RADIUS_M`] of `centre`
/// ([`Arcs::tangents_near`]), in this thread's kept list.
fn with_tangents<T>(
    arcs: &Arcs<'_>,
    centre: (f64, f64),
    upto: usize,
    f: impl FnOnce(&[Tangent]) -> T,
) -> T {
    // Taken out while in use: a nested call would find an empty list and grow its own.
    let mut tangents = TANGENTS.take();
    arcs.tangents_near(centre, upto, &mut tangents);
    let out = f(&tangents);
    TANGENTS.set(tangents);
    out
}

/// The line grid of [`walls_from`] with the offsets summed per cell and the cells voted for, kept
/// from one call to the next on each thread (a map places a few thousand peaks; a fresh grid
/// each time was a tenth of its time).
struct LocalGrid {
    votes: LineVotes,
    sum_offset: Vec<f64>,
    /// The cells voted for, in the order first voted for: the first `n_touched` (one slot more
    /// than the cells, so that a vote writes its cell there before knowing whether it is new,
    /// without a branch the processor mispredicts half the time).
    touched: Vec<usize>,
    n_touched: usize,
}

impl LocalGrid {
    fn new() -> Self {
        let n_angle = (180.0 / ANGLE_STEP_DEG).round() as usize;
        // Cells symmetric about zero offset, so flipping a line's side flips its cell.
        let n_dist = (2.0 * (SEARCH_RADIUS_M + DIST_STEP_M) / DIST_STEP_M).ceil() as usize;
        let reach = 0.5 * n_dist as f64 * DIST_STEP_M;
        Self {
            votes: LineVotes::new(n_angle, n_dist, reach),
            sum_offset: vec![0.0; n_angle * n_dist],
            touched: vec![0; n_angle * n_dist + 1],
            n_touched: 0,
        }
    }

    fn clear(&mut self) {
        for &i in &self.touched[..self.n_touched] {
            self.votes.counts[i] = 0;
            self.sum_offset[i] = 0.0;
        }
        self.n_touched = 0;
    }
}

thread_local! {
    static LOCAL_GRID: std::cell::RefCell<LocalGrid> = std::cell::RefCell::new(LocalGrid::new());
}

/// Walls, strongest first, from tangents found around one centre.
fn walls_from(tangents: &[Tangent]) -> Vec<LocalWall> {
    LOCAL_GRID.with(|grid| {
        let mut grid = grid.borrow_mut();
        let walls = walls_on(&mut grid, tangents);
        grid.clear();
        walls
    })
}

/// [`walls_from`] on an empty grid.
fn walls_on(local: &mut LocalGrid, tangents: &[Tangent]) -> Vec<LocalWall> {
    let LocalGrid {
        votes: grid,
        sum_offset,
        touched,
        n_touched,
    } = local;
    let (n_angle, n_dist, reach) = (grid.n_angle, grid.n_dist, grid.reach_m);
    let step = ANGLE_STEP_DEG.to_radians();
    // The grid's parts as plain slices and the count in a local, so that the loop keeps them in
    // registers.
    let (counts, sums, cells) = (&mut grid.counts[..], &mut sum_offset[..], &mut touched[..]);
    let mut n = *n_touched;
    for t in tangents {
        // A normal that rounds to 180 degrees is the 0 degree cell, seen from the other side.
        let (ia, offset) = if t.cell >= n_angle {
            (t.cell - n_angle, -t.offset)
        } else {
            (t.cell, t.offset)
        };
        let id = (((offset + reach) / DIST_STEP_M) as usize).min(n_dist - 1);
        let i = ia * n_dist + id;
        cells[n] = i;
        n += usize::from(counts[i] == 0);
        counts[i] += 1;
        sums[i] += offset;
    }
    *n_touched = n;
    let mut walls: Vec<LocalWall> = Vec::new();
    let mut strongest = Strongest::of_cells(grid, &touched[..*n_touched], MIN_WALL_VOTES);
    while walls.len() < MAX_WALLS {
        // The most votes, the first cell with them on a tie.
        let Some((best, v)) = strongest.next(grid) else {
            break;
        };
        if v < MIN_WALL_VOTES {
            break;
        }
        // Angle and offset refined over the 3 x 3 neighbourhood.
        let (ia, id) = ((best / n_dist) as i64, (best % n_dist) as i64);
        let (mut w, mut sa, mut so) = (0.0, 0.0, 0.0);
        for da in -1..=1i64 {
            for dd in -1..=1i64 {
                let d = id + dd;
                if d < 0 || d >= n_dist as i64 {
                    continue;
                }
                // Wrapping past 0 or 180 degrees flips the offset's sign.
                let (a, flip) = match ia + da {
                    a if a < 0 => (a + n_angle as i64, true),
                    a if a >= n_angle as i64 => (a - n_angle as i64, true),
                    a => (a, false),
                };
                let d = if flip { n_dist as i64 - 1 - d } else { d };
                let j = a as usize * n_dist + d as usize;
                if grid.counts[j] == 0 {
                    continue;
                }
                let off = sum_offset[j] / grid.counts[j] as f64;
                let vj = grid.counts[j] as f64;
                w += vj;
                sa += vj * (ia + da) as f64 * step;
                so += vj * if flip { -off } else { off };
            }
        }
        let normal = (sa / w).rem_euclid(std::f64::consts::PI);
        let offset = if (sa / w) < 0.0 || (sa / w) >= std::f64::consts::PI {
            -so / w
        } else {
            so / w
        };
        walls.push(LocalWall {
            normal_rad: normal,
            offset_m: offset,
            votes: v,
        });
        // Suppress the wall's neighbourhood (both representations near 0 / 180 degrees), row by
        // row of angle, skipping the rows too far round to hold any of it.
        let suppress = SUPPRESS_ANGLE_DEG.to_radians();
        for ia in 0..n_angle {
            let a = grid.angle_rad(ia);
            let da = (a - normal).abs();
            if da > suppress && std::f64::consts::PI - da > suppress {
                continue;
            }
            // The offsets within reach of the wall's either way round, a cell more each side.
            for centre in [offset, -offset] {
                let cell = |o: f64| (o + reach) / DIST_STEP_M - 0.5;
                let lo = (cell(centre - SUPPRESS_DIST_M).floor() as i64 - 1).max(0) as usize;
                let hi = (cell(centre + SUPPRESS_DIST_M).ceil() as i64 + 1).min(n_dist as i64 - 1);
                for id in lo..(hi + 1).max(0) as usize {
                    if same_wall(a, grid.offset_m(id), normal, offset) {
                        grid.counts[ia * n_dist + id] = 0;
                    }
                }
            }
        }
    }
    walls
}

/// Whether the lines (normal `a`, offset `o`) and (`b`, `p`) agree within `angle_rad` and
/// `dist_m`, either way round 0 / 180 degrees.
fn close_lines(a: f64, o: f64, b: f64, p: f64, angle_rad: f64, dist_m: f64) -> bool {
    let da = (a - b).abs();
    (da <= angle_rad && (o - p).abs() <= dist_m)
        || (std::f64::consts::PI - da <= angle_rad && (o + p).abs() <= dist_m)
}

/// Whether two lines are one wall, within the suppression bounds.
fn same_wall(a: f64, o: f64, b: f64, p: f64) -> bool {
    close_lines(a, o, b, p, SUPPRESS_ANGLE_DEG.to_radians(), SUPPRESS_DIST_M)
}

/// Crossing of two walls, in the frame of the centre they were found around.
fn crossing(a: &LocalWall, b: &LocalWall) -> Option<(f64, f64)> {
    let (s1, c1) = a.normal_rad.sin_cos();
    let (s2, c2) = b.normal_rad.sin_cos();
    let det = c1 * s2 - s1 * c2;
    if det.abs() < 1e-9 {
        return None;
    }
    Some((
        (a.offset_m * s2 - b.offset_m * s1) / det,
        (c1 * b.offset_m - c2 * a.offset_m) / det,
    ))
}

/// Where a wall was seen: the tangent points of its voters, as distances along the wall
/// (direction `(-sin a, cos a)`) from the foot of `point` on it, smallest and largest.
fn seen_along(tangents: &[Tangent], wall: &LocalWall, point: (f64, f64)) -> Option<(f64, f64)> {
    let (s, c) = wall.normal_rad.sin_cos();
    let mut span: Option<(f64, f64)> = None;
    for t in tangents {
        if on_wall(t, wall) {
            let u = -s * (t.point.0 - point.0) + c * (t.point.1 - point.1);
            span = Some(span.map_or((u, u), |(lo, hi)| (lo.min(u), hi.max(u))));
        }
    }
    span
}

/// Past a jamb along its wall, no echo's tangent point on the wall this far: 0.45 to 0.9 m. Up
/// to 0.35-0.4 m past it there are some: echoes off the jamb's edge, smeared along the wall by
/// the cone (the office's door, 1.2 m wide: tangent points 0-0.35 m into it from each side).
const JAMB_CLEAR_M: (f64, f64) = (0.45, 0.9);
/// ... and on the wall's side, at least this many over the same distances: 10.
const JAMB_WALL_POINTS: usize = 10;

/// How many tangent points of `wall`'s line lie [`JAMB_CLEAR_M`] beyond `point` along `dir` (a
/// unit vector along the wall).
fn seen_near(tangents: &[Tangent], wall: &LocalWall, point: (f64, f64), dir: (f64, f64)) -> usize {
    tangents
        .iter()
        .filter(|t| {
            let along = (t.point.0 - point.0) * dir.0 + (t.point.1 - point.1) * dir.1;
            (JAMB_CLEAR_M.0..=JAMB_CLEAR_M.1).contains(&along) && on_wall(t, wall)
        })
        .count()
}

/// Whether a tangent is a vote for `wall`: its line within an angle cell and 1.5 offset cells.
fn on_wall(t: &Tangent, wall: &LocalWall) -> bool {
    close_lines(
        t.normal,
        t.offset,
        wall.normal_rad,
        wall.offset_m,
        ANGLE_STEP_DEG.to_radians(),
        1.5 * DIST_STEP_M,
    )
}

/// Distance from `point` to the nearest place `wall` was seen.
fn gap_to(span: Option<(f64, f64)>) -> f64 {
    match span {
        Some((lo, hi)) if lo <= 0.0 && hi >= 0.0 => 0.0,
        Some((lo, hi)) => lo.abs().min(hi.abs()),
        None => f64::INFINITY,
    }
}

/// What the walls around a Hough peak say it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PeakPlace {
    /// Two walls cross near it: the corner where they meet.
    Corner(f64, f64),
    /// It lies on a wall that the grid shows going on to one side and free space to the other:
    /// the wall's end (a door jamb), the peak moved onto the wall.
    WallEnd(f64, f64),
    /// It lies on a wall that the grid shows going on to both sides: not a feature.
    MidWall,
    /// No wall through it (a pillar, clutter, too few readings): the walls cannot tell.
    Unknown,
}

/// A peak lies on a wall when it is this close to its line: 15 cm.
const ON_WALL_M: f64 = 0.15;

/// Places a Hough peak at `centre` among the walls around it. A corner is the crossing of two
/// walls that meet at 60 degrees or more, within 1 m of the peak, each seen within 1 m of the
/// crossing and at least one ending there (seen no more than 15 cm past it), with an occupied
/// grid cell within one cell of the crossing.
/// Only the first `upto` readings of `arcs` are used (an online window sees the readings up to
/// its end).
pub fn place_peak(
    arcs: &Arcs<'_>,
    upto: usize,
    centre: (f64, f64),
    map: &OccupancyMap,
) -> PeakPlace {
    with_tangents(arcs, centre, upto, |tangents| {
        place_among(arcs, upto, centre, map, tangents)
    })
}

/// [`place_peak`] with the tangents near the peak found.
fn place_among(
    arcs: &Arcs<'_>,
    upto: usize,
    centre: (f64, f64),
    map: &OccupancyMap,
    tangents: &[Tangent],
) -> PeakPlace {
    let walls = walls_from(tangents);
    if let Some((x, y)) = corner(tangents, centre, map, &walls) {
        return PeakPlace::Corner(x, y);
    }
    let Some(wall) = walls
        .iter()
        .filter(|w| w.offset_m.abs() <= ON_WALL_M)
        .max_by_key(|w| w.votes)
    else {
        return PeakPlace::Unknown;
    };
    let (s, c) = wall.normal_rad.sin_cos();
    let foot = (centre.0 + wall.offset_m * c, centre.1 + wall.offset_m * s);
    let sides = [1.0, -1.0].map(|sign| beyond(map, foot, (-s * sign, c * sign)));
    match sides {
        [Beyond::Wall, Beyond::Wall] => {
            // The robot went through the wall's line on one side, and the wall was seen (its
            // echoes' tangent points) just past the peak on the other side only: a doorway the
            // cone painted closed, and the peak is its jamb.
            let dirs = [1.0, -1.0].map(|sign| (-s * sign, c * sign));
            let seen = dirs.map(|dir| match seen_near(tangents, wall, foot, dir) {
                0 => Some(false),
                n if n >= JAMB_WALL_POINTS => Some(true),
                _ => None,
            });
            let through = dirs.map(|dir| arcs.passed_along(foot, dir, upto));
            match (seen, through) {
                ([Some(true), Some(false)], [false, true])
                | ([Some(false), Some(true)], [true, false]) => PeakPlace::WallEnd(foot.0, foot.1),
                _ => PeakPlace::MidWall,
            }
        }
        [Beyond::Wall, Beyond::Free] | [Beyond::Free, Beyond::Wall] => {
            PeakPlace::WallEnd(foot.0, foot.1)
        }
        _ => PeakPlace::Unknown,
    }
}

/// What the grid shows along a wall beyond a point.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Beyond {
    /// The wall goes on.
    Wall,
    /// Free space: the wall ends.
    Free,
    /// Not known, or mixed.
    Unknown,
}

/// Distances beyond a point at which [`beyond`] looks along a wall: 0.3, 0.45 and 0.6 m.
const BEYOND_M: [f64; 3] = [0.3, 0.45, 0.6];

/// What the grid shows along direction `dir` (a unit vector) from `point`: the wall goes on when
/// at least two of the [`BEYOND_M`] points have an occupied cell within half a cell across the
/// wall, it ends when at least two of them are known free.
fn beyond(map: &OccupancyMap, point: (f64, f64), dir: (f64, f64)) -> Beyond {
    let g = &map.geometry;
    let (mut wall, mut free) = (0, 0);
    let half = 0.5 * g.resolution_m;
    for d in BEYOND_M {
        let q = (point.0 + d * dir.0, point.1 + d * dir.1);
        // The wall's cells may lie either side of its line: look half a cell across it.
        let across = [-half, 0.0, half].map(|e| g.cell_of(q.0 - e * dir.1, q.1 + e * dir.0));
        let cells = across.iter().flatten().map(|&(c, r)| r * g.width + c);
        if cells.clone().any(|i| map.is_occupied(i)) {
            wall += 1;
        } else if let Some((c, r)) = g.cell_of(q.0, q.1) {
            free += map.is_free(r * g.width + c) as usize;
        }
    }
    if wall >= 2 {
        Beyond::Wall
    } else if free >= 2 {
        Beyond::Free
    } else {
        Beyond::Unknown
    }
}

/// The corner of [`place_peak`], if any: pairs of walls, the stronger with at least half the
/// votes of the strongest wall around, tried in order of the product of their votes (a strong
/// wall with a weak one ranks below two fair ones).
fn corner(
    tangents: &[Tangent],
    centre: (f64, f64),
    map: &OccupancyMap,
    walls: &[LocalWall],
) -> Option<(f64, f64)> {
    let strongest = walls.iter().map(|w| w.votes).max().unwrap_or(0);
    let mut pairs = Vec::new();
    for (i, a) in walls.iter().enumerate() {
        for b in &walls[i + 1..] {
            let angle = (a.normal_rad - b.normal_rad).abs();
            let angle = angle.min(std::f64::consts::PI - angle);
            // Two weak walls beside a strong one are the cone's edge echoes, not a corner.
            let strong = 2 * a.votes.max(b.votes) >= strongest;
            if angle >= MIN_CORNER_ANGLE_DEG.to_radians() && strong {
                pairs.push((a.votes * b.votes, *a, *b));
            }
        }
    }
    pairs.sort_by_key(|p| std::cmp::Reverse(p.0));
    pairs.into_iter().find_map(|(_, a, b)| {
        let (dx, dy) = crossing(&a, &b)?;
        if dx.hypot(dy) > MAX_SNAP_M {
            return None;
        }
        let point = (centre.0 + dx, centre.1 + dy);
        let spans = [a, b].map(|w| seen_along(tangents, &w, point));
        // Both walls seen near the crossing, one at least only on one side of it (an L or a
        // T; two walls that each run on past the crossing are a false pair).
        let ends = |span: &Option<(f64, f64)>| {
            span.is_some_and(|(lo, hi)| lo >= -END_SLACK_M || hi <= END_SLACK_M)
        };
        let walls_meet =
            spans.iter().all(|s| gap_to(*s) <= MAX_WALL_GAP_M) && spans.iter().any(ends);
        (walls_meet && occupied_near(map, point)).then_some(point)
    })
}

/// Whether the grid has an occupied cell within one cell of `point` (which may lie just outside
/// the grid: a wall on its edge).
fn occupied_near(map: &OccupancyMap, point: (f64, f64)) -> bool {
    map.geometry
        .cells_around(point, 1)
        .any(|i| map.is_occupied(i))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;
    use crate::sonar::grid::{CountingGrid, GridConfig, OccupancyGrid};

    /// Readings of a wall `y = wall_y` taken from a robot driving along it at `standoff`.
    fn along_wall(wall_y: f64, standoff: f64, xs: std::ops::Range<i32>) -> Vec<PlacedReading> {
        xs.map(|k| {
            let x = k as f64 * 0.05;
            PlacedReading {
                t_s: 0.0,
                world_from_sensor: Pose2::new(
                    x,
                    wall_y - standoff,
                    std::f64::consts::FRAC_PI_2 + 0.1,
                ),
                range_m: Some(standoff),
            }
        })
        .collect()
    }

    /// Readings of wall `x = wall_x` from a robot driving along it at `standoff`.
    fn along_wall_x(wall_x: f64, standoff: f64, ys: std::ops::Range<i32>) -> Vec<PlacedReading> {
        ys.map(|k| PlacedReading {
            t_s: 0.0,
            world_from_sensor: Pose2::new(wall_x - standoff, k as f64 * 0.05, -0.1),
            range_m: Some(standoff),
        })
        .collect()
    }

    #[test]
    fn a_peak_beside_a_room_corner_moves_into_it() {
        // The corner (2, 2): walls y = 2 (x < 2) and x = 2 (y < 2), each followed to 0.35 m of it.
        let mut readings = along_wall(2.0, 0.5, 0..34);
        readings.extend(along_wall_x(2.0, 0.5, 0..34));
        let mut grid = CountingGrid::new(GridConfig::default(), 30f64.to_radians(), 5.0).unwrap();
        grid.insert_all(&readings);
        let map = grid.map();
        let arcs = Arcs::new(&readings, 15f64.to_radians());
        let place = place_peak(&arcs, readings.len(), (1.45, 1.98), &map);
        let PeakPlace::Corner(x, y) = place else {
            panic!("{place:?}")
        };
        assert!((x - 2.0).hypot(y - 2.0) < 0.03, "({x}, {y})");
        // A peak in the middle of the wall y = 2 is no feature.
        let place = place_peak(&arcs, readings.len(), (0.6, 2.0), &map);
        assert!(
            matches!(place, PeakPlace::MidWall | PeakPlace::Unknown),
            "{place:?}"
        );
    }

    #[test]
    fn a_wall_is_found_where_the_arcs_touch_it() {
        let readings = along_wall(2.0, 0.6, 0..40);
        let walls = local_walls(&Arcs::new(&readings, 15f64.to_radians()), (1.0, 1.8));
        assert!(!walls.is_empty());
        let w = walls[0];
        assert!(
            (w.normal_rad - std::f64::consts::FRAC_PI_2).abs() < 0.02,
            "{w:?}"
        );
        assert!((w.offset_m - 0.2).abs() < 0.02, "{w:?}");
    }
}
