//! Corner features from sonar arcs by a Hough transform, as in the paper.
//!
//! The parameter space is a polar grid about the global origin (100 mm x 1 degree by default).
//! Every reading with an echo votes along its arc: the arc across the beam is sampled every
//! [`HoughConfig::arc_sample_m`] and each sample adds one vote to the cell it falls in, so a
//! reading gives about as many votes to a cell as the cell is wide, whatever its range.
//! A point reflector (a room corner, a pillar's edge, a door jamb) lies on the arcs of every
//! reading that sees it, so its cell collects votes from many places; a flat wall only collects
//! votes near the foot of each perpendicular.
//!
//! **Peak rule.** A cell is a candidate when (1) its votes reach the threshold (70 in the paper's
//! office, 50 in the museum) and (2) it is the maximum of its (2r+1) x (2r+1) neighbourhood in
//! the accumulator. Around a room corner the strongest cells are on the walls 0.2-0.6 m from
//! it (the robot rounds the corner close to both walls, and at 50 cm a sonar arc hugs a wall
//! over +-26 degrees), so (3) each candidate is placed among the walls that the readings' arcs
//! touch near it ([`crate::sonar::corners::place_peak`], a line Hough transform on the arcs' tangents):
//! where two walls cross near it the feature moves to the crossing (a room corner, a T); on a
//! wall that the grid shows ending beside it, onto the wall (a door jamb); in the middle of a
//! wall, it is dropped. (4) A candidate with no wall through it (a pillar, clutter) is kept only
//! when its votes came from positions spread around it (the directions from the cell to the
//! voting sensors, in 5 degree sectors, span at least [`HoughConfig::min_spread_deg`], 30
//! degrees by default) and the grid does not put it in the middle of a straight run of
//! occupied cells ([`is_mid_wall`]). (5) Every feature must stand on something static: a cell
//! near it that the grid holds firmly occupied ([`STATIC_OCCUPANCY`]), which a person walking by
//! never makes. (6) Offline, a feature with a straight wall face ([`crate::sonar::walls`]) near it
//! must lie on one's line, within its ends extended a little ([`off_the_walls`]): a room corner, a
//! T and a door jamb all do; where a person walked, no wall is fitted.
//!
//! **Windows.** Online, votes are gathered over windows of 70 cm of travel or 70 degrees of turn
//! (the paper's), each window starting half a window after the previous one so a corner on a
//! window boundary is not cut in two; features found in several windows are merged. Offline, one
//! accumulator collects the whole run.

use crate::geometry::{pose_at, StampedPose};
use crate::sonar::corners::{place_peak, Arcs, PeakPlace};
use crate::sonar::grid::OccupancyMap;
use crate::sonar::tangent::{fast_atan2, FAST_ATAN2_ERROR};
use crate::sonar::PlacedReading;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Settings of the Hough transform. Defaults are the paper's office experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct HoughConfig {
    /// Radial cell size: 100 mm in the paper.
    pub rho_step_m: f64,
    /// Angular cell size: 1 degree in the paper.
    pub phi_step_deg: f64,
    /// Largest radius covered, metres (ours: 40 m, any home).
    pub rho_max_m: f64,
    /// Spacing of vote samples along an arc (ours: 10 mm, a tenth of a cell).
    pub arc_sample_m: f64,
    /// A window ends after this much travel: 70 cm in the paper.
    pub window_travel_m: f64,
    /// ... or this much turning: 70 degrees in the paper.
    pub window_turn_deg: f64,
    /// Votes a feature needs: 70 in the paper's office, 50 in the museum.
    pub threshold: u32,
    /// Votes a feature of the offline pass needs; defaults to the online threshold.
    pub offline_threshold: Option<u32>,
    /// Half size of the local-maximum neighbourhood, in cells (ours: 2).
    pub peak_radius_cells: usize,
    /// Least angular spread of the voting positions as seen from the feature (ours: 30 degrees).
    pub min_spread_deg: f64,
    /// Features closer than this are one (ours: 25 cm).
    pub merge_radius_m: f64,
    /// Rule 6: drop the offline features near straight walls but on none's line
    /// ([`off_the_walls`]; ours: on).
    pub features_on_walls: bool,
}

impl Default for HoughConfig {
    fn default() -> Self {
        Self {
            rho_step_m: 0.1,
            phi_step_deg: 1.0,
            rho_max_m: 40.0,
            arc_sample_m: 0.01,
            window_travel_m: 0.7,
            window_turn_deg: 70.0,
            threshold: 70,
            offline_threshold: None,
            peak_radius_cells: 2,
            min_spread_deg: 30.0,
            merge_radius_m: 0.25,
            features_on_walls: true,
        }
    }
}

/// A corner feature.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Feature {
    /// Position, metres.
    pub x_m: f64,
    /// Position, metres.
    pub y_m: f64,
    /// Votes of the strongest sighting.
    pub votes: u32,
    /// Windows in which it was found (1 for the offline pass).
    pub sightings: u32,
    /// Spread of the voting directions, degrees.
    pub spread_deg: f64,
    /// What the grid says about it.
    pub kind: FeatureKind,
}

/// What kind of point a feature is, judged from the free space around it in the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FeatureKind {
    /// Free space on less than 40% of the ring around it: a room corner (concave).
    Corner,
    /// Free space on more than 60% of the ring: an edge (convex corner, pillar, jamb).
    Edge,
    /// In between, or too little known around it.
    Unknown,
}

impl FeatureKind {
    /// Name as written in `corners.csv`.
    pub fn as_str(&self) -> &'static str {
        match self {
            FeatureKind::Corner => "corner",
            FeatureKind::Edge => "edge",
            FeatureKind::Unknown => "unknown",
        }
    }
}

/// Sectors used for the spread rule.
const SPREAD_SECTORS: usize = 72;

/// How clearly inside a cell a point must lie for [`CellRun::holds`] to say so: a billionth of
/// the cell's outer radius, far above the rounding of [`Accumulator::cell`]'s own arithmetic.
const CELL_MARGIN: f64 = 1e-9;

/// Where the direction from a vote at arc direction `a` back to the sensor lies, in spread
/// sectors (unwrapped: its floor, taken modulo [`SPREAD_SECTORS`], is the sector).
fn sector_position(a: f64) -> f64 {
    (a + std::f64::consts::PI) / std::f64::consts::TAU * SPREAD_SECTORS as f64
}

/// The bit of the sector whose unwrapped index is `floor` (a whole number).
fn sector_bit(floor: f64) -> u128 {
    1u128 << (floor as i64).rem_euclid(SPREAD_SECTORS as i64)
}

/// One accumulator cell while an arc runs through it: its bounds, to tell cheaply whether the
/// next sample lies in it too, and its sums so far.
#[derive(Debug, Clone, Copy)]
struct CellRun {
    i: usize,
    /// Squared radii the cell spans, shrunk by the margin.
    r2_lo: f64,
    r2_hi: f64,
    /// Unit vectors along the cell's low and high angular edges.
    lo: (f64, f64),
    hi: (f64, f64),
    /// The margin as a distance from either angular edge, metres.
    margin_m: f64,
    votes: u32,
    sum_x: f32,
    sum_y: f32,
    sectors: u128,
}

impl CellRun {
    /// Whether `(x, y)` lies in the cell by more than the margin: within its radii, and on the
    /// inner side of both angular edges (a cell spans under half a turn).
    fn holds(&self, x: f64, y: f64) -> bool {
        let r2 = x * x + y * y;
        r2 > self.r2_lo
            && r2 < self.r2_hi
            && self.lo.0 * y - self.lo.1 * x > self.margin_m
            && self.hi.0 * y - self.hi.1 * x < -self.margin_m
    }

    fn add(&mut self, x: f64, y: f64, sector_bit: u128) {
        self.votes += 1;
        self.sum_x += x as f32;
        self.sum_y += y as f32;
        self.sectors |= sector_bit;
    }
}

/// The polar vote accumulator.
#[derive(Debug, Clone)]
pub struct Accumulator {
    /// Radial bins.
    pub n_rho: usize,
    /// Angular bins.
    pub n_phi: usize,
    /// Votes, row-major by radius (`rho_bin * n_phi + phi_bin`).
    pub votes: Vec<u32>,
    sum_x: Vec<f32>,
    sum_y: Vec<f32>,
    sectors: Vec<u128>,
    touched: Vec<usize>,
    rho_step: f64,
    phi_step: f64,
    /// Unit vectors (cos, sin) along the angular cells' edges: cell `ip` spans `edges[ip]` to
    /// `edges[ip + 1]`, the last up to a whole turn (as [`Self::cell`] clamps).
    edges: Vec<(f64, f64)>,
}

impl Accumulator {
    /// An empty accumulator.
    pub fn new(config: &HoughConfig) -> Self {
        let n_rho = (config.rho_max_m / config.rho_step_m).ceil().max(1.0) as usize;
        let n_phi = (360.0 / config.phi_step_deg).round().max(1.0) as usize;
        let n = n_rho * n_phi;
        let phi_step = config.phi_step_deg.to_radians();
        Self {
            n_rho,
            n_phi,
            votes: vec![0; n],
            sum_x: vec![0.0; n],
            sum_y: vec![0.0; n],
            sectors: vec![0; n],
            touched: Vec::new(),
            rho_step: config.rho_step_m,
            phi_step,
            edges: (0..=n_phi)
                .map(|ip| {
                    let a = if ip == n_phi {
                        std::f64::consts::TAU
                    } else {
                        ip as f64 * phi_step
                    };
                    let (s, c) = a.sin_cos();
                    (c, s)
                })
                .collect(),
        }
    }

    /// Width of a radial bin, metres.
    pub fn rho_step_m(&self) -> f64 {
        self.rho_step
    }

    /// Width of an angular bin, degrees.
    pub fn phi_step_deg(&self) -> f64 {
        self.phi_step.to_degrees()
    }

    fn cell(&self, x: f64, y: f64) -> Option<usize> {
        let rho = x.hypot(y);
        let ir = (rho / self.rho_step) as usize;
        if ir >= self.n_rho || !rho.is_finite() {
            return None;
        }
        let phi = y.atan2(x).rem_euclid(std::f64::consts::TAU);
        let ip = ((phi / self.phi_step) as usize).min(self.n_phi - 1);
        Some(ir * self.n_phi + ip)
    }

    /// [`Self::cell`], the same cell, found cheaply: the radius by a square root and the angle by
    /// [`fast_atan2`], each checked against the cell's edges and taken again exactly when it lies
    /// within the approximation's error of one. The votes are most of a map's time.
    fn cell_fast(&self, x: f64, y: f64) -> Option<usize> {
        // How far a value lies from the nearest whole number (for values >= 0).
        let off_edge = |v: f64| {
            let f = v - (v as u64) as f64;
            f.min(1.0 - f)
        };
        let r = (x * x + y * y).sqrt() / self.rho_step;
        if !(r.is_finite() && off_edge(r) > 1e-9 * r.max(1.0)) {
            return self.cell(x, y);
        }
        let ir = r as usize;
        if ir >= self.n_rho {
            return None;
        }
        let mut phi = fast_atan2(y, x);
        if phi < 0.0 {
            phi += std::f64::consts::TAU;
        }
        let p = phi / self.phi_step;
        if off_edge(p) < FAST_ATAN2_ERROR / self.phi_step + 1e-9 * p.max(1.0) {
            return self.cell(x, y);
        }
        let ip = (p as usize).min(self.n_phi - 1);
        Some(ir * self.n_phi + ip)
    }

    /// A run over cell `i`, its sums as they stand, with the bounds [`CellRun::holds`] tests.
    /// Cells too wide for that test (an angular cell of a radian or more) get bounds that hold
    /// nothing, so each sample is looked up afresh.
    fn cell_run(&self, i: usize) -> CellRun {
        let (ir, ip) = (i / self.n_phi, i % self.n_phi);
        let (r_lo, r_hi) = (ir as f64 * self.rho_step, (ir + 1) as f64 * self.rho_step);
        let (r2_lo, r2_hi) = if self.phi_step < 1.0 {
            (
                r_lo * r_lo * (1.0 + CELL_MARGIN),
                r_hi * r_hi * (1.0 - CELL_MARGIN),
            )
        } else {
            (f64::INFINITY, f64::NEG_INFINITY)
        };
        CellRun {
            i,
            r2_lo,
            r2_hi,
            lo: self.edges[ip],
            hi: self.edges[ip + 1],
            margin_m: CELL_MARGIN * r_hi,
            votes: self.votes[i],
            sum_x: self.sum_x[i],
            sum_y: self.sum_y[i],
            sectors: self.sectors[i],
        }
    }

    /// Writes a run's sums back to its cell.
    fn flush(&mut self, run: &CellRun) {
        let i = run.i;
        if self.votes[i] == 0 && run.votes > 0 {
            self.touched.push(i);
        }
        self.votes[i] = run.votes;
        self.sum_x[i] = run.sum_x;
        self.sum_y[i] = run.sum_y;
        self.sectors[i] = run.sectors;
    }

    /// Votes along the arc of one reading. Consecutive samples mostly fall in the same cell, so
    /// the cell is found afresh (`cell_fast`) only where a sample is not clearly inside
    /// the previous one's, and its sums are held until the arc leaves it (the same additions in
    /// the same order: the same sums).
    pub fn vote(&mut self, reading: &PlacedReading, half_cone_rad: f64, arc_sample_m: f64) {
        let Some(range) = reading.range_m else { return };
        if !(range.is_finite() && range >= 0.0) {
            return;
        }
        let p = reading.world_from_sensor;
        let n = ((2.0 * half_cone_rad * range / arc_sample_m).ceil() as usize).max(1);
        // A laser return (range zero, [`crate::sonar::point_echoes`]) is one point: one vote.
        let last = if range > 0.0 { n } else { 0 };
        // The samples' directions, turned one step at a time (the rounding this adds over a
        // few hundred steps is some 1e-14 rad).
        let (a0, da) = (p.theta - half_cone_rad, 2.0 * half_cone_rad / n as f64);
        let (mut s, mut c) = a0.sin_cos();
        let (ds, dc) = da.sin_cos();
        let mut run: Option<CellRun> = None;
        // The sector of the last sample (the floor of its `back`, below) and its bit.
        let (mut sector_floor, mut bit) = (f64::NAN, 0u128);
        for k in 0..=last {
            let a = a0 + da * k as f64;
            let (x, y) = (p.x + range * c, p.y + range * s);
            (s, c) = (s * dc + c * ds, c * dc - s * ds);
            if !run.as_ref().is_some_and(|r| r.holds(x, y)) {
                if let Some(r) = run.take() {
                    self.flush(&r);
                }
                let Some(i) = self.cell_fast(x, y) else {
                    continue;
                };
                run = Some(self.cell_run(i));
            }
            // Direction from the voted point back to the sensor: the last sample's sector
            // while it stays in it.
            let back = sector_position(a);
            if !(back >= sector_floor && back < sector_floor + 1.0) {
                sector_floor = back.floor();
                bit = sector_bit(sector_floor);
            }
            if let Some(r) = run.as_mut() {
                r.add(x, y, bit);
            }
        }
        if let Some(r) = run {
            self.flush(&r);
        }
    }

    /// Forgets all votes.
    pub fn clear(&mut self) {
        for &i in &self.touched {
            self.votes[i] = 0;
            self.sum_x[i] = 0.0;
            self.sum_y[i] = 0.0;
            self.sectors[i] = 0;
        }
        self.touched.clear();
    }

    /// Spread of the voting directions of a cell, degrees: the widest run of voted sectors,
    /// bridging single empty sectors. A thin wall voted from both sides has two short runs, not
    /// one wide one.
    fn spread_deg(&self, i: usize) -> f64 {
        let mask = self.sectors[i];
        if mask == 0 {
            return 0.0;
        }
        let on = |k: usize| mask & (1u128 << (k % SPREAD_SECTORS)) != 0;
        if (0..SPREAD_SECTORS).all(on) {
            return 360.0;
        }
        let mut best = 0;
        for start in 0..SPREAD_SECTORS {
            // Runs start at a voted sector after an empty one.
            if !on(start) || on(start + SPREAD_SECTORS - 1) {
                continue;
            }
            let mut end = start;
            let mut k = start + 1;
            while k < start + SPREAD_SECTORS {
                if on(k) {
                    end = k;
                } else if !on(k + 1) {
                    break;
                }
                k += 1;
            }
            best = best.max(end - start + 1);
        }
        best as f64 * 360.0 / SPREAD_SECTORS as f64
    }

    /// Local maxima at or above `threshold` (rules 1 and 2), strongest first, with their spread.
    pub fn peaks(&self, threshold: u32, peak_radius: usize) -> Vec<Feature> {
        let mut out = Vec::new();
        let r = peak_radius as i64;
        for &i in &self.touched {
            let v = self.votes[i];
            if v < threshold {
                continue;
            }
            let (ir, ip) = ((i / self.n_phi) as i64, (i % self.n_phi) as i64);
            let mut is_max = true;
            'nb: for dr in -r..=r {
                let rr = ir + dr;
                if rr < 0 || rr >= self.n_rho as i64 {
                    continue;
                }
                for dp in -r..=r {
                    if dr == 0 && dp == 0 {
                        continue;
                    }
                    let pp = (ip + dp).rem_euclid(self.n_phi as i64);
                    let j = rr as usize * self.n_phi + pp as usize;
                    // Ties go to the lower index so a flat top gives one peak.
                    if self.votes[j] > v || (self.votes[j] == v && j < i) {
                        is_max = false;
                        break 'nb;
                    }
                }
            }
            if !is_max {
                continue;
            }
            let spread = self.spread_deg(i);
            out.push(Feature {
                x_m: (self.sum_x[i] / v as f32) as f64,
                y_m: (self.sum_y[i] / v as f32) as f64,
                votes: v,
                sightings: 1,
                spread_deg: spread,
                kind: FeatureKind::Unknown,
            });
        }
        out.sort_by_key(|f| std::cmp::Reverse(f.votes));
        out
    }
}

/// Merges features closer than `radius_m`: the strongest keeps its position, sightings add up.
pub fn merge_features(mut features: Vec<Feature>, radius_m: f64) -> Vec<Feature> {
    features.sort_by_key(|f| std::cmp::Reverse(f.votes));
    let mut out: Vec<Feature> = Vec::new();
    for f in features {
        if let Some(m) = out
            .iter_mut()
            .find(|m| (m.x_m - f.x_m).hypot(m.y_m - f.y_m) < radius_m)
        {
            m.sightings += f.sightings;
            m.spread_deg = m.spread_deg.max(f.spread_deg);
        } else {
            out.push(f);
        }
    }
    out
}

/// Features from the peaks of an accumulator, placed among the walls found in `readings`
/// ([`place_peak`]): a peak with two walls crossing near it moves to their crossing, a peak at a
/// wall's end onto the wall, a peak in a wall's middle is dropped; a peak with no wall through it
/// must pass the spread rule and the grid's mid-wall veto ([`is_mid_wall`]).
/// Only the first `upto` readings of `arcs` are used.
pub fn locate_features(
    peaks: Vec<Feature>,
    arcs: &Arcs<'_>,
    upto: usize,
    map: &OccupancyMap,
    config: &HoughConfig,
) -> Vec<Feature> {
    // Each peak on its own (in parallel, in order: the same features on any number of threads).
    peaks
        .into_par_iter()
        .filter_map(|f| {
            let f = match place_peak(arcs, upto, (f.x_m, f.y_m), map) {
                PeakPlace::Corner(x_m, y_m) | PeakPlace::WallEnd(x_m, y_m) => {
                    Feature { x_m, y_m, ..f }
                }
                PeakPlace::MidWall => return None,
                PeakPlace::Unknown => {
                    if f.spread_deg >= config.min_spread_deg && !is_mid_wall(&f, map) {
                        f
                    } else {
                        return None;
                    }
                }
            };
            (firmest_near(map, (f.x_m, f.y_m)) >= STATIC_OCCUPANCY).then_some(f)
        })
        .collect()
}

/// Rule 6: a feature lies within this distance of a fitted wall face's line: 0.2 m (a corner
/// placed among the arcs' walls lies within a few centimetres of them; a Hough cell is 0.1 m).
pub const WALL_LINE_REACH_M: f64 = 0.2;
/// ... between the face's ends extended this far: 1.0 m (the robot turns 0.5-0.9 m before a
/// corner, so a face's echoes stop short of it; a door jamb ends its face).
pub const WALL_END_REACH_M: f64 = 1.0;

/// Rule 6 holds for features with fewer than this many times the threshold's votes: 4. A
/// reflector heard this often, from around it, is not a person passing; willow's raster walls,
/// too jagged for straight faces, have their corners at 4-17 times the threshold, the office's
/// walking person at 1.1-3.0 times.
pub const STRONG_PEAK: u32 = 4;

/// Rule 6 judges a feature only with a wall face this close: 2 m. Where the run fitted no face
/// nearby (a sparse run's unwalled stretches, a pillar's faces too short for a wall: 3 m from the
/// museum's hall walls) there is nothing to judge it by.
pub const WALL_JUDGE_REACH_M: f64 = 2.0;

/// Rule 6: whether `f` is off the walls: a face of `walls` lies within [`WALL_JUDGE_REACH_M`] of
/// it, yet it lies on no face's line ([`on_a_wall`]). A corner is where walls meet or end. On the
/// office's default exploration with ground-truth poses (seeds 1-5), every offline feature off the
/// walls was on the path of the sample's walking person or outside the building.
pub fn off_the_walls(f: &Feature, walls: &[crate::sonar::walls::WallSegment]) -> bool {
    let p = nalgebra::Point2::new(f.x_m, f.y_m);
    let near = |w: &crate::sonar::walls::WallSegment| {
        let face = crate::geometry::Segment::new(w.from_m.into(), w.to_m.into());
        (face.closest_point(p) - p).norm() <= WALL_JUDGE_REACH_M
    };
    walls.iter().any(near) && !on_a_wall(f, walls)
}

/// Whether `f` lies on the line of one of `walls`, within [`WALL_LINE_REACH_M`] of it and
/// [`WALL_END_REACH_M`] of its extent.
pub fn on_a_wall(f: &Feature, walls: &[crate::sonar::walls::WallSegment]) -> bool {
    walls
        .iter()
        .any(|w| w.holds_near([f.x_m, f.y_m], WALL_LINE_REACH_M, WALL_END_REACH_M))
}

/// Rule 5: a feature stands on something that does not move: a cell within [`STATIC_REACH_M`]
/// whose echoes outnumber the beams that passed through it 4 to 1. A wall is hit whenever a
/// beam reaches it; where a person walked, the sonar saw free space as often as the person, and
/// the Hough transform makes corners of the path (the office's default run: 5 false corners of
/// 11, occupancy 0.54-0.75 around them, 0.92-1.0 at the room's corners).
pub const STATIC_OCCUPANCY: f64 = 0.8;
/// ... within this distance of the feature: 0.3 m.
pub const STATIC_REACH_M: f64 = 0.3;

/// The highest occupancy among the cells within [`STATIC_REACH_M`] (in whole cells, rounded up)
/// of `point`'s cell (0 where none is known).
fn firmest_near(map: &OccupancyMap, point: (f64, f64)) -> f64 {
    let reach = (STATIC_REACH_M / map.geometry.resolution_m).ceil() as i64;
    map.geometry
        .cells_around(point, reach)
        .filter_map(|i| map.occupancy[i])
        .fold(0.0, f64::max)
}

/// Online features: windows of travel or turn along `trajectory`, each window's peaks located
/// with the readings up to its end, merged.
pub fn features_online(
    readings: &[PlacedReading],
    trajectory: &[StampedPose],
    half_cone_rad: f64,
    map: &OccupancyMap,
    config: &HoughConfig,
) -> Vec<Feature> {
    // Cumulative travel and turn of the robot at each reading.
    let mut travel = Vec::with_capacity(readings.len());
    let mut turn = Vec::with_capacity(readings.len());
    let (mut s, mut a) = (0.0, 0.0);
    let mut prev = readings.first().and_then(|r| pose_at(trajectory, r.t_s));
    for r in readings {
        if let (Some(p), Some(q)) = (prev, pose_at(trajectory, r.t_s)) {
            s += (q.x - p.x).hypot(q.y - p.y);
            a += crate::geometry::wrap_angle(q.theta - p.theta)
                .abs()
                .to_degrees();
            prev = Some(q);
        }
        travel.push(s);
        turn.push(a);
    }
    // The windows first (each starts half a window after the last), then their peaks, each
    // window on its own accumulator and in parallel: they share nothing.
    let mut windows = Vec::new();
    let mut start = 0;
    while start < readings.len() {
        let within = |i: usize| {
            travel[i] - travel[start] <= config.window_travel_m
                && turn[i] - turn[start] <= config.window_turn_deg
        };
        let mut end = start;
        while end < readings.len() && within(end) {
            end += 1;
        }
        windows.push(start..end);
        if end >= readings.len() {
            break;
        }
        let mut next = start + 1;
        while next < end
            && travel[next] - travel[start] < 0.5 * config.window_travel_m
            && turn[next] - turn[start] < 0.5 * config.window_turn_deg
        {
            next += 1;
        }
        start = next;
    }
    let arcs = Arcs::new(readings, half_cone_rad);
    let found: Vec<Vec<Feature>> = windows
        .into_par_iter()
        .map_init(
            || Accumulator::new(config),
            |acc, window| {
                acc.clear();
                for r in &readings[window.clone()] {
                    acc.vote(r, half_cone_rad, config.arc_sample_m);
                }
                let peaks = acc.peaks(config.threshold, config.peak_radius_cells);
                locate_features(peaks, &arcs, window.end, map, config)
            },
        )
        .collect();
    let found = found.into_iter().flatten().collect();
    merge_features(found, config.merge_radius_m)
}

/// The offline pass: one accumulator over the whole run, its peaks located with all readings.
#[derive(Debug, Clone)]
pub struct OfflineFeatures {
    /// The features.
    pub features: Vec<Feature>,
    /// What the threshold hid: the features its peaks with at least half the threshold's votes,
    /// but fewer than it, would have given, located and merged the same way, away from every
    /// feature kept (a lower threshold would show these).
    pub below_threshold: Vec<Feature>,
    /// The accumulator (for display).
    pub accumulator: Accumulator,
}

/// Offline features: one accumulator over the whole run, its peaks located with all readings;
/// also those its threshold hid ([`OfflineFeatures::below_threshold`]).
pub fn features_offline(
    readings: &[PlacedReading],
    half_cone_rad: f64,
    map: &OccupancyMap,
    config: &HoughConfig,
) -> OfflineFeatures {
    let mut acc = Accumulator::new(config);
    for r in readings {
        acc.vote(r, half_cone_rad, config.arc_sample_m);
    }
    let threshold = config.offline_threshold.unwrap_or(config.threshold);
    // Being a local maximum does not depend on the threshold: one pass at half of it.
    let (peaks, weak): (Vec<Feature>, Vec<Feature>) = acc
        .peaks(threshold.div_ceil(2), config.peak_radius_cells)
        .into_iter()
        .partition(|f| f.votes >= threshold);
    let arcs = Arcs::new(readings, half_cone_rad);
    let located = locate_features(peaks, &arcs, readings.len(), map, config);
    let features = merge_features(located, config.merge_radius_m);
    let below_threshold = merge_features(
        locate_features(weak, &arcs, readings.len(), map, config),
        config.merge_radius_m,
    )
    .into_iter()
    .filter(|w| {
        features
            .iter()
            .all(|f| (f.x_m - w.x_m).hypot(f.y_m - w.y_m) >= config.merge_radius_m)
    })
    .collect();
    OfflineFeatures {
        features,
        below_threshold,
        accumulator: acc,
    }
}

/// Ring around a feature inspected for wall cells by [`is_mid_wall`]: 0.25 to 0.7 m.
const WALL_RING_M: (f64, f64) = (0.25, 0.7);
/// Axial concentration above which the occupied cells around a feature form one straight line.
const STRAIGHT_AXIAL: f64 = 0.6;
/// ... and mean resultant below which that line runs through the feature (both ways).
const STRAIGHT_THROUGH: f64 = 0.45;

/// Rule 4, from the grid: whether a feature sits in the middle of a straight wall. Around a
/// wall point the occupied cells lie in two opposite directions (their doubled angles agree, their
/// angles cancel); around a corner they lie in two directions at an angle, around a wall end in
/// one. A feature with fewer than three occupied cells around it counts as mid-wall too: a corner
/// is made of walls.
pub fn is_mid_wall(f: &Feature, map: &OccupancyMap) -> bool {
    let g = &map.geometry;
    let reach = (WALL_RING_M.1 / g.resolution_m).ceil() as i64;
    let Some((c0, r0)) = g.cell_of(f.x_m, f.y_m) else {
        return true;
    };
    let (mut n, mut s1, mut c1, mut s2, mut c2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for dr in -reach..=reach {
        for dc in -reach..=reach {
            let (c, r) = (c0 as i64 + dc, r0 as i64 + dr);
            if c < 0 || r < 0 || c >= g.width as i64 || r >= g.height as i64 {
                continue;
            }
            let idx = r as usize * g.width + c as usize;
            if !map.is_occupied(idx) {
                continue;
            }
            let [x, y] = g.centre(c as usize, r as usize);
            let d = (x - f.x_m).hypot(y - f.y_m);
            if !(WALL_RING_M.0..=WALL_RING_M.1).contains(&d) {
                continue;
            }
            let a = (y - f.y_m).atan2(x - f.x_m);
            n += 1.0;
            s1 += a.sin();
            c1 += a.cos();
            s2 += (2.0 * a).sin();
            c2 += (2.0 * a).cos();
        }
    }
    if n < 3.0 {
        return true;
    }
    let axial = s2.hypot(c2) / n;
    let through = s1.hypot(c1) / n;
    axial > STRAIGHT_AXIAL && through < STRAIGHT_THROUGH
}

/// Ring around a feature inspected by [`classify_features`]: 0.3 to 0.6 m.
const RING_M: (f64, f64) = (0.3, 0.6);

/// Labels each feature a room corner or an edge from the free space around it in the grid.
pub fn classify_features(features: &mut [Feature], map: &OccupancyMap) {
    let g = &map.geometry;
    let reach = (RING_M.1 / g.resolution_m).ceil() as i64;
    for f in features.iter_mut() {
        let Some((c0, r0)) = g.cell_of(f.x_m, f.y_m) else {
            continue;
        };
        let (mut free, mut known) = (0usize, 0usize);
        for dr in -reach..=reach {
            for dc in -reach..=reach {
                let (c, r) = (c0 as i64 + dc, r0 as i64 + dr);
                if c < 0 || r < 0 || c >= g.width as i64 || r >= g.height as i64 {
                    continue;
                }
                let [x, y] = g.centre(c as usize, r as usize);
                let d = (x - f.x_m).hypot(y - f.y_m);
                if !(RING_M.0..=RING_M.1).contains(&d) {
                    continue;
                }
                let idx = r as usize * g.width + c as usize;
                if map.occupancy[idx].is_some() {
                    known += 1;
                    if map.is_free(idx) {
                        free += 1;
                    }
                }
            }
        }
        f.kind = if known < 4 {
            FeatureKind::Unknown
        } else {
            let frac = free as f64 / known as f64;
            if frac < 0.4 {
                FeatureKind::Corner
            } else if frac > 0.6 {
                FeatureKind::Edge
            } else {
                FeatureKind::Unknown
            }
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;

    #[test]
    fn a_feature_on_a_walls_line_near_its_extent_is_on_a_wall() {
        // The face y = 2 seen from below (normal -y), echoes from x = 0 to 3.
        let wall = crate::sonar::walls::WallSegment {
            normal_rad: 1.5 * std::f64::consts::PI,
            offset_m: -2.0,
            from_m: [0.0, 2.0],
            to_m: [3.0, 2.0],
            readings: 40,
            rms_m: 0.01,
            sigma_m: None,
        };
        let at = |x_m: f64, y_m: f64| Feature {
            x_m,
            y_m,
            votes: 100,
            sightings: 1,
            spread_deg: 90.0,
            kind: FeatureKind::Corner,
        };
        // The room's corner beyond the face's last echo, and a jamb at its end.
        assert!(on_a_wall(&at(3.8, 2.1), &[wall]));
        assert!(on_a_wall(&at(-0.9, 1.85), &[wall]));
        assert!(on_a_wall(&at(3.0, 2.0), &[wall]));
        // Off its line, or along it past the reach.
        assert!(!on_a_wall(&at(1.5, 2.3), &[wall]));
        assert!(!on_a_wall(&at(1.5, 1.7), &[wall]));
        assert!(!on_a_wall(&at(4.5, 2.0), &[wall]));
        assert!(!on_a_wall(&at(1.5, 2.0), &[]));
        // Judged only with a face within 2 m.
        assert!(off_the_walls(&at(1.5, 1.0), &[wall]));
        assert!(!off_the_walls(&at(1.5, -0.5), &[wall]));
        assert!(!off_the_walls(&at(3.8, 2.1), &[wall]));
    }

    #[test]
    fn the_fast_arctangent_is_within_its_bound() {
        for k in 0..100_000 {
            let a = k as f64 * 0.000_731 - 36.0;
            let r = 0.01 + (k % 97) as f64;
            let (y, x) = (r * a.sin(), r * a.cos());
            let e = crate::geometry::wrap_angle(fast_atan2(y, x) - y.atan2(x));
            assert!(e.abs() < FAST_ATAN2_ERROR, "{x} {y}: {e}");
        }
        let acc = Accumulator::new(&HoughConfig::default());
        for k in 0..20_000 {
            let (x, y) = (
                (k as f64 * 0.37).sin() * 12.0,
                (k as f64 * 0.91).cos() * 12.0,
            );
            assert_eq!(acc.cell_fast(x, y), acc.cell(x, y), "{x} {y}");
        }
    }

    #[test]
    fn an_arcs_votes_are_those_of_its_samples_one_by_one() {
        // The reference: every sample's cell found exactly and added at once.
        fn vote_sample_by_sample(acc: &mut Accumulator, r: &PlacedReading, half: f64, step: f64) {
            let (range, p) = (r.range_m.unwrap(), r.world_from_sensor);
            let n = ((2.0 * half * range / step).ceil() as usize).max(1);
            let (a0, da) = (p.theta - half, 2.0 * half / n as f64);
            let (mut s, mut c) = a0.sin_cos();
            let (ds, dc) = da.sin_cos();
            for k in 0..=n {
                let a = a0 + da * k as f64;
                let (x, y) = (p.x + range * c, p.y + range * s);
                (s, c) = (s * dc + c * ds, c * dc - s * ds);
                let Some(i) = acc.cell(x, y) else { continue };
                if acc.votes[i] == 0 {
                    acc.touched.push(i);
                }
                acc.votes[i] += 1;
                acc.sum_x[i] += x as f32;
                acc.sum_y[i] += y as f32;
                acc.sectors[i] |= sector_bit(sector_position(a).floor());
            }
        }
        for config in [
            HoughConfig::default(),
            HoughConfig {
                rho_step_m: 0.07,
                phi_step_deg: 1.3,
                ..HoughConfig::default()
            },
            // Cells too wide for the run's test: every sample looked up.
            HoughConfig {
                phi_step_deg: 90.0,
                ..HoughConfig::default()
            },
        ] {
            let (mut fast, mut exact) = (Accumulator::new(&config), Accumulator::new(&config));
            for k in 0..3000 {
                let f = k as f64;
                let r = PlacedReading {
                    t_s: f,
                    // Sensors all round the origin (through it too), ranges up to 5 m.
                    world_from_sensor: Pose2::new(
                        (f * 0.37).sin() * 9.0,
                        (f * 0.91).cos() * 9.0,
                        f * 0.731,
                    ),
                    range_m: Some(0.05 + (k % 50) as f64 * 0.1),
                };
                fast.vote(&r, 15f64.to_radians(), config.arc_sample_m);
                vote_sample_by_sample(&mut exact, &r, 15f64.to_radians(), config.arc_sample_m);
            }
            assert_eq!(fast.touched, exact.touched);
            assert_eq!(fast.votes, exact.votes);
            assert_eq!(fast.sectors, exact.sectors);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fast.sum_x), bits(&exact.sum_x));
            assert_eq!(bits(&fast.sum_y), bits(&exact.sum_y));
        }
    }

    #[test]
    fn readings_around_a_point_make_a_peak_there() {
        let target = (5.0, 4.0);
        let mut readings = Vec::new();
        for k in 0..24 {
            let a = (k as f64 * 5.0 - 60.0).to_radians();
            let (sx, sy) = (target.0 - 1.2 * a.cos(), target.1 - 1.2 * a.sin());
            readings.push(PlacedReading {
                t_s: 0.0,
                world_from_sensor: Pose2::new(sx, sy, a + 0.05),
                range_m: Some(1.2),
            });
        }
        let mut acc = Accumulator::new(&HoughConfig::default());
        for r in &readings {
            acc.vote(r, 15f64.to_radians(), 0.01);
        }
        let f = acc.peaks(70, 2);
        assert!(!f.is_empty());
        assert!(
            (f[0].x_m - target.0).hypot(f[0].y_m - target.1) < 0.1,
            "{:?}",
            f[0]
        );
    }
}
