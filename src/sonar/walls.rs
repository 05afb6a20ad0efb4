//! The straight walls of a whole map, as line segments fitted to the sonar ranges: what a later
//! run's sonar is matched against when it localises in a survey.
//!
//! The occupancy grid says where echoes came from to within its cell (20 cm on the samples), too
//! coarse to hold a robot to a few centimetres. A flat wall is known far better than that: a sonar
//! echo off it comes from the foot of the perpendicular, so every reading whose cone holds the
//! wall's normal has `range = n . sensor - offset` exactly, up to the range noise. The walls are
//! found with the same tangent-line Hough transform as [`crate::sonar::corners`] (every direction inside a
//! reading's cone votes for the line tangent to its arc there), over the whole map and with the
//! side a wall was seen from kept, then each is split where the robot did not see it and refitted
//! to its readings by least squares.

use crate::sonar::grid::OccupancyMap;
use crate::sonar::tangent::{cone_steps, LineVotes, Strongest, ANGLE_STEP_DEG, DIST_STEP_M};
use crate::sonar::PlacedReading;
use serde::Serialize;
use std::f64::consts::TAU;

/// A reading supports a wall when its tangent at the wall's angle (within one cell) is this close
/// to the wall's line: 4.5 cm.
const SUPPORT_M: f64 = 0.045;
/// A wall needs this many supporting readings: 12 ([`WallConfig::min_readings`]).
pub const MIN_READINGS: usize = 12;
/// A wall is split where no echo came from it over this length: 0.5 m
/// ([`WallConfig::max_gap_m`]).
pub const MAX_GAP_M: f64 = 0.5;
/// The fewest supporting readings a wall needs however sparse the run: 5 (aces as five frontal
/// sonars, a reading every 0.73 m: 23 faces, every one on the full laser's walls).
pub const FEWEST_READINGS: usize = 5;
/// A sparse run's gap is this many times its spacing: 2.5 (a face's reading may be missed: a
/// scan of aces often finds no echo off a given face).
pub const GAP_SPACINGS: f64 = 2.5;

/// Settings of the wall step: the `walls:` part of the mapping settings.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct WallConfig {
    /// Supporting readings a face needs (ours: 12).
    pub min_readings: usize,
    /// A face is split where no echo came from it over this length, metres (ours: 0.5 m).
    pub max_gap_m: f64,
    /// Whether a face may lie on cells the grid leaves unknown (not only on occupied ones) for
    /// the part of its length it must lie on: off by default, on for a sparse run (its cells
    /// under the evidence floor are most of the map).
    pub on_unknown_cells: bool,
    /// Whether these follow how densely the run samples (`MappingConfig::for_run`): as set for
    /// runs with a reading every 15 cm of travel or closer; for a sparser run, `min_readings`
    /// scaled down as the evidence floor is (5 at least), a gap of 2.5 times the spacing
    /// (`max_gap_m` at least) and `on_unknown_cells` on. On by default.
    pub follow_sampling: bool,
}

impl Default for WallConfig {
    fn default() -> Self {
        Self {
            min_readings: MIN_READINGS,
            max_gap_m: MAX_GAP_M,
            on_unknown_cells: false,
            follow_sampling: true,
        }
    }
}

impl WallConfig {
    /// The settings for a run with a reading every `spacing_m` of travel (one sensor's), with
    /// `follow_sampling`; the settings returned follow nothing more.
    pub fn for_spacing(&self, spacing_m: Option<f64>) -> WallConfig {
        let mut out = WallConfig {
            follow_sampling: false,
            ..self.clone()
        };
        let spacing_m = spacing_m.unwrap_or(0.0);
        if self.follow_sampling && spacing_m > crate::sonar::map::FLOOR_SPACING_M {
            let scaled = self.min_readings as f64 * crate::sonar::map::FLOOR_SPACING_M / spacing_m;
            out.min_readings = (scaled.round() as usize)
                .max(FEWEST_READINGS)
                .min(self.min_readings);
            out.max_gap_m = self.max_gap_m.max(GAP_SPACINGS * spacing_m);
            out.on_unknown_cells = true;
        }
        out
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), crate::sonar::grid::GridError> {
        let bad = |key, value: f64, reason| {
            Err(crate::sonar::grid::GridError::Invalid { key, value, reason })
        };
        if self.min_readings < 3 {
            return bad(
                "walls.min_readings",
                self.min_readings as f64,
                "a face needs 3 readings at least",
            );
        }
        if !(self.max_gap_m.is_finite() && self.max_gap_m > 0.0) {
            return bad(
                "walls.max_gap_m",
                self.max_gap_m,
                "must be a positive number of metres",
            );
        }
        Ok(())
    }
}
/// The sensors that saw a wall must have been spread this far along it, so that its direction
/// comes from the ranges and not from the 1 degree Hough cell (a robot turning on the spot sees a
/// wall from one place): 0.5 m.
const MIN_SPREAD_M: f64 = 0.5;
/// A weaker face within this angle of a stronger one ... : 50 degrees.
const SHADOW_ANGLE_DEG: f64 = 50.0;
/// ... whose middle is this close to the stronger one's line ... : 0.3 m.
const SHADOW_DIST_M: f64 = 0.3;
/// ... and this close to its extent is dropped: 0.6 m (the robot turns 0.5-0.9 m before a
/// corner, so the faces end short of it).
const SHADOW_ALONG_M: f64 = 0.6;
/// A face must lie on occupied grid cells (or unknown ones, [`WallConfig::on_unknown_cells`]) for
/// this part of its length: 0.8 (a concave corner's tip echoes like a 45 degree face across the
/// corner, on free cells).
const MIN_ON_GRID: f64 = 0.8;
/// Walls searched at most.
const MAX_WALLS: usize = 400;
/// Readings whose sensor lies farther than this from the readings' median position are left
/// out: 500 m, more than any building. The accumulator is sized by the readings' extent, so one
/// pose far off (an odometry jump in a log, a diverged estimate) would otherwise make it huge
/// (100 km: 12 s instead of 0.06 s; 10,000 km: more memory than there is).
const MAX_REACH_M: f64 = 500.0;

/// One face of a straight wall, seen from the side its normal points to: the points `q` with
/// `n . q = offset_m`, `n = (cos normal_rad, sin normal_rad)`, between two ends. A sensor at `s`
/// in front of it is `n . s - offset_m` away.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSegment {
    /// Direction the face looks, towards where it was seen from, radians in [0, 2 pi).
    pub normal_rad: f64,
    /// Signed distance of the line from the origin along the normal, metres.
    pub offset_m: f64,
    /// One end, metres (the first echo along the wall's direction `(-sin, cos)` of the normal).
    pub from_m: [f64; 2],
    /// The other end, metres.
    pub to_m: [f64; 2],
    /// Readings fitted.
    pub readings: usize,
    /// Root-mean-square range residual of the fit, metres.
    pub rms_m: f64,
    /// How well the face is placed: one sigma along its normal where its survey's ranges met it
    /// (their mean place), metres, when known (a survey's corrected faces, from its trajectory's
    /// covariance); `None` for a face whose placement was not measured, taken to
    /// [`crate::fusion::FuseConfig::wall_sigma_m`].
    pub sigma_m: Option<f64>,
}

impl WallSegment {
    /// The face's length, metres.
    pub fn length_m(&self) -> f64 {
        (self.to_m[0] - self.from_m[0]).hypot(self.to_m[1] - self.from_m[1])
    }

    /// The unit normal.
    pub fn normal(&self) -> [f64; 2] {
        let (s, c) = self.normal_rad.sin_cos();
        [c, s]
    }

    /// Position along the wall's direction `(-sin, cos)` of the normal.
    fn along(&self, p: [f64; 2]) -> f64 {
        let (s, c) = self.normal_rad.sin_cos();
        -s * p[0] + c * p[1]
    }

    /// Position of `p`'s foot on the face along its direction, from the face's middle, metres.
    pub fn from_middle(&self, p: [f64; 2]) -> f64 {
        self.along(p) - 0.5 * (self.along(self.from_m) + self.along(self.to_m))
    }

    /// Whether `p` lies within `across_m` of the face's line and within its ends extended by
    /// `past_ends_m`.
    pub fn holds_near(&self, p: [f64; 2], across_m: f64, past_ends_m: f64) -> bool {
        let n = self.normal();
        let across = n[0] * p[0] + n[1] * p[1] - self.offset_m;
        let (a, b) = (self.along(self.from_m), self.along(self.to_m));
        let u = self.along(p);
        across.abs() <= across_m && u >= a.min(b) - past_ends_m && u <= a.max(b) + past_ends_m
    }

    /// The range a sonar at `sensor` looking along `beam_rad` measures off this face when the face
    /// is in front of it, its normal within `half_cone_rad` of the beam's axis (reversed), and the
    /// foot of the perpendicular on the segment, `inset_m` inside its ends: `None` otherwise.
    pub fn expected_range(
        &self,
        sensor: [f64; 2],
        beam_rad: f64,
        half_cone_rad: f64,
        inset_m: f64,
    ) -> Option<f64> {
        let n = self.normal();
        let range = n[0] * sensor[0] + n[1] * sensor[1] - self.offset_m;
        // The beam must look against the normal.
        let off_axis =
            crate::geometry::wrap_angle(beam_rad - self.normal_rad - std::f64::consts::PI);
        if range <= 0.0 || off_axis.abs() > half_cone_rad {
            return None;
        }
        let foot = self.along(sensor);
        let (a, b) = (self.along(self.from_m), self.along(self.to_m));
        (foot >= a.min(b) + inset_m && foot <= a.max(b) - inset_m).then_some(range)
    }
}

impl WallSegment {
    /// The range a laser at `sensor` measures along `beam_rad` off this face: where the ray
    /// meets the face's line, when it looks against the face within `max_incidence_rad` of its
    /// normal and meets it `inset_m` inside its ends; `None` otherwise.
    pub fn expected_ray_range(
        &self,
        sensor: [f64; 2],
        beam_rad: f64,
        max_incidence_rad: f64,
        inset_m: f64,
    ) -> Option<f64> {
        let n = self.normal();
        let d = n[0] * sensor[0] + n[1] * sensor[1] - self.offset_m;
        let phi = crate::geometry::wrap_angle(beam_rad - self.normal_rad - std::f64::consts::PI);
        if d <= 0.0 || phi.abs() > max_incidence_rad {
            return None;
        }
        let range = d / phi.cos();
        let hit = [
            sensor[0] + range * beam_rad.cos(),
            sensor[1] + range * beam_rad.sin(),
        ];
        let u = self.along(hit);
        let (a, b) = (self.along(self.from_m), self.along(self.to_m));
        (u >= a.min(b) + inset_m && u <= a.max(b) - inset_m).then_some(range)
    }
}

/// A reading reduced to what the fit needs: sensor position, beam direction, range.
#[derive(Debug, Clone, Copy)]
struct Echo {
    s: [f64; 2],
    beam: f64,
    range: f64,
}

/// The cells of the whole-circle accumulator a reading votes for: for each direction `b` of
/// its cone, the line tangent to its arc there has normal `-u(b)` and passes `s + r u(b)`, so
/// the side it was seen from is kept.
fn cells(votes: &LineVotes, e: &Echo, half_cone_rad: f64) -> impl Iterator<Item = (usize, usize)> {
    let (s, range, n_angle, n_dist, reach) = (
        e.s,
        e.range,
        votes.n_angle as i64,
        votes.n_dist,
        votes.reach_m,
    );
    cone_steps(e.beam, half_cone_rad).filter_map(move |c| {
        let offset = -(c.cos * s[0] + c.sin * s[1]) - range;
        let ia = (c.k + n_angle / 2).rem_euclid(n_angle) as usize;
        let id = ((offset + reach) / DIST_STEP_M).floor();
        (id >= 0.0 && (id as usize) < n_dist).then_some((ia, id as usize))
    })
}

/// Adds (`sign` 1) or takes back (-1) a reading's votes.
fn vote(votes: &mut LineVotes, e: &Echo, half_cone_rad: f64, sign: i32) {
    let found: Vec<_> = cells(votes, e, half_cone_rad).collect();
    for (ia, id) in found {
        let c = &mut votes.counts[ia * votes.n_dist + id];
        *c = c.saturating_add_signed(sign);
    }
}

/// The walls of a map from its readings placed along a (corrected) trajectory, strongest first.
/// Readings without an echo or at the sensor's maximum range are left out. A face must lie on
/// occupied cells of `map` (the grid of the same readings) for 80% of its length.
pub fn map_walls(
    readings: &[PlacedReading],
    half_cone_rad: f64,
    max_range_m: f64,
    map: &OccupancyMap,
    config: &WallConfig,
) -> Vec<WallSegment> {
    let mut echoes: Vec<Echo> = readings
        .iter()
        .filter_map(|r| {
            let range = r
                .range_m
                .filter(|&x| x.is_finite() && x >= 0.0 && x < max_range_m - 1e-6)?;
            let p = r.world_from_sensor;
            (p.x.is_finite() && p.y.is_finite() && p.theta.is_finite()).then_some(Echo {
                s: [p.x, p.y],
                beam: p.theta,
                range,
            })
        })
        .collect();
    if let Some(middle) = median_position(&echoes) {
        echoes.retain(|e| (e.s[0] - middle[0]).hypot(e.s[1] - middle[1]) <= MAX_REACH_M);
    }
    // The accumulator's offsets are taken about the sensors' mean position, so that its size
    // follows the map's extent, wherever the map lies (a real robot's odometry may start far
    // from the origin).
    let n = echoes.len().max(1) as f64;
    let centre = echoes
        .iter()
        .fold([0.0, 0.0], |c, e| [c[0] + e.s[0] / n, c[1] + e.s[1] / n]);
    for e in &mut echoes {
        e.s = [e.s[0] - centre[0], e.s[1] - centre[1]];
    }
    let reach = echoes
        .iter()
        .map(|e| e.s[0].hypot(e.s[1]) + e.range)
        .fold(0.0, f64::max)
        + DIST_STEP_M;
    let mut votes = LineVotes::new(
        (360.0 / ANGLE_STEP_DEG).round() as usize,
        (2.0 * reach / DIST_STEP_M).ceil() as usize + 1,
        reach,
    );
    for e in &echoes {
        vote(&mut votes, e, half_cone_rad, 1);
    }
    let mut strongest = Strongest::new(&votes, config.min_readings as u32);
    let by_beam = BeamBins::new(&echoes);
    let mut used = vec![false; echoes.len()];
    let mut walls = Vec::new();
    for _ in 0..MAX_WALLS {
        let Some((best, count)) = strongest.next(&votes) else {
            break;
        };
        if (count as usize) < config.min_readings {
            break;
        }
        let step = ANGLE_STEP_DEG.to_radians();
        let normal = votes.angle_rad(best / votes.n_dist);
        let offset = votes.offset_m(best % votes.n_dist);
        // Readings whose cone holds the normal (within a cell) and whose range fits the line.
        let cone = half_cone_rad + step;
        let line = Support::new(normal, offset, cone);
        let support = by_beam.facing(normal, cone, |i| !used[i] && line.holds(&echoes[i]));
        votes.counts[best] = 0;
        for mut piece in split(&echoes, &support, normal, config.max_gap_m) {
            // A piece before it may have grown over this one's readings.
            piece.retain(|&i| !used[i]);
            let fitted = fit(&echoes, &piece, normal, offset, config.min_readings)
                .map(|first| grow(&echoes, &by_beam, &used, first, cone, config));
            if let Some((w, members)) = fitted {
                for i in members {
                    take(&mut votes, &mut used, &echoes[i], i, half_cone_rad);
                }
                walls.push(w);
            }
        }
        // Whatever the outcome, the readings on the cell's line have voted: take their votes
        // back, and the cell's own count, so the search moves on.
        for i in support {
            take(&mut votes, &mut used, &echoes[i], i, half_cone_rad);
        }
    }
    // Strongest first; a weaker face along a stronger one is its cone-edge echoes or a corner's
    // (a concave corner echoes from its tip, whose tangents line up at 45 degrees).
    walls.sort_by_key(|w| std::cmp::Reverse(w.readings));
    let mut kept: Vec<WallSegment> = Vec::new();
    for mut w in walls {
        let n = w.normal();
        w.offset_m += n[0] * centre[0] + n[1] * centre[1];
        for end in [&mut w.from_m, &mut w.to_m] {
            *end = [end[0] + centre[0], end[1] + centre[1]];
        }
        if on_grid(&w, map, config.on_unknown_cells) >= MIN_ON_GRID
            && !kept.iter().any(|k| shadows(k, &w))
        {
            kept.push(w);
        }
    }
    kept
}

/// Echoes binned by their beam's direction, one bin per accumulator angle: a wall's support is
/// looked for among the echoes that can face it.
struct BeamBins(Vec<Vec<usize>>);

impl BeamBins {
    fn new(echoes: &[Echo]) -> Self {
        let n = (360.0 / ANGLE_STEP_DEG).round() as usize;
        let mut bins = vec![Vec::new(); n];
        for (i, e) in echoes.iter().enumerate() {
            bins[Self::bin(e.beam, n)].push(i);
        }
        Self(bins)
    }

    fn bin(angle_rad: f64, n: usize) -> usize {
        ((angle_rad.rem_euclid(TAU) / TAU * n as f64) as usize).min(n - 1)
    }

    /// Indices, ascending, of the echoes that pass `keep` among those whose beam may lie within
    /// `half_rad` of looking against `normal` (all that do, and some that do not).
    fn facing(&self, normal: f64, half_rad: f64, keep: impl Fn(usize) -> bool) -> Vec<usize> {
        let n = self.0.len();
        let axis = normal + std::f64::consts::PI;
        let bins = (half_rad / TAU * n as f64).ceil() as usize + 1;
        let range = if 2 * bins + 1 >= n {
            0..n
        } else {
            let first = Self::bin(axis, n) + n - bins;
            first..first + 2 * bins + 1
        };
        let mut found: Vec<usize> = range
            .flat_map(|b| self.0[b % n].iter().copied())
            .filter(|&i| keep(i))
            .collect();
        found.sort_unstable();
        found
    }
}

/// The median sensor position (each coordinate's), `None` without echoes.
fn median_position(echoes: &[Echo]) -> Option<[f64; 2]> {
    let median = |k: usize| {
        let mut v: Vec<f64> = echoes.iter().map(|e| e.s[k]).collect();
        let mid = v.len() / 2;
        v.select_nth_unstable_by(mid, f64::total_cmp);
        v[mid]
    };
    (!echoes.is_empty()).then(|| [median(0), median(1)])
}

/// The part of a face's length that lies on occupied cells (within half a cell across it), or
/// unknown ones with `unknown`, or off the grid.
fn on_grid(w: &WallSegment, map: &OccupancyMap, unknown: bool) -> f64 {
    let g = &map.geometry;
    let length = (w.to_m[0] - w.from_m[0]).hypot(w.to_m[1] - w.from_m[1]);
    let steps = (length / (0.25 * g.resolution_m)).ceil().max(1.0) as usize;
    let n = w.normal();
    let half = 0.5 * g.resolution_m;
    let on = (0..=steps)
        .filter(|&k| {
            let f = k as f64 / steps as f64;
            let p = [
                w.from_m[0] + f * (w.to_m[0] - w.from_m[0]),
                w.from_m[1] + f * (w.to_m[1] - w.from_m[1]),
            ];
            // Off the grid (a wall on its edge), or on a cell it does not know when asked (a
            // sparse run's cells under the evidence floor), the grid cannot tell.
            [-half, 0.0, half].iter().any(|e| {
                g.cell_of(p[0] + e * n[0], p[1] + e * n[1])
                    .is_none_or(|(c, r)| {
                        let i = r * g.width + c;
                        map.is_occupied(i) || (unknown && map.occupancy[i].is_none())
                    })
            })
        })
        .count();
    on as f64 / (steps + 1) as f64
}

/// Whether `weak` lies along `strong`: normals within [`SHADOW_ANGLE_DEG`], the middle of `weak`
/// within [`SHADOW_DIST_M`] of `strong`'s line and [`SHADOW_ALONG_M`] of its extent.
fn shadows(strong: &WallSegment, weak: &WallSegment) -> bool {
    let angle = crate::geometry::wrap_angle(strong.normal_rad - weak.normal_rad).abs();
    let mid = [
        0.5 * (weak.from_m[0] + weak.to_m[0]),
        0.5 * (weak.from_m[1] + weak.to_m[1]),
    ];
    angle <= SHADOW_ANGLE_DEG.to_radians() && strong.holds_near(mid, SHADOW_DIST_M, SHADOW_ALONG_M)
}

/// A line `n . p = offset` (`n` at `normal`) that echoes support when their tangent at the
/// normal lies on it ([`Support::holds`]); the normal's sine and cosine are taken once for the
/// many echoes a face is tested against.
struct Support {
    normal: f64,
    sin: f64,
    cos: f64,
    offset: f64,
    half_cone_rad: f64,
}

impl Support {
    fn new(normal: f64, offset: f64, half_cone_rad: f64) -> Self {
        let (sin, cos) = normal.sin_cos();
        Self {
            normal,
            sin,
            cos,
            offset,
            half_cone_rad,
        }
    }

    /// Whether an echo's tangent at the line's normal lies on the line: its range fits the
    /// line (tested first: most echoes of a bin lie elsewhere) and its cone holds the normal.
    fn holds(&self, e: &Echo) -> bool {
        (self.cos * e.s[0] + self.sin * e.s[1] - e.range - self.offset).abs() <= SUPPORT_M
            && crate::geometry::wrap_angle(e.beam - self.normal - std::f64::consts::PI).abs()
                <= self.half_cone_rad
    }
}

/// Marks an echo used by a face (or looked at for one), its votes taken back.
fn take(votes: &mut LineVotes, used: &mut [bool], e: &Echo, i: usize, half_cone_rad: f64) {
    if !used[i] {
        vote(votes, e, half_cone_rad, -1);
        used[i] = true;
    }
}

/// Rounds of [`grow`] at most.
const GROW_ROUNDS: usize = 4;

/// A face fitted to the readings near its Hough cell's line, grown along its own fitted line:
/// the readings within [`SUPPORT_M`] of it, unused, in the piece (split at gaps) that holds most
/// of the face's readings, fitted again, until it gains none. An accumulator cell holds a wall's
/// direction to half an [`ANGLE_STEP_DEG`], so the cell's line leaves a long wall at no whole
/// degree within a few metres (a real building's corridor: 8 cm off at 10 m), where the fitted
/// line follows it; a wall that steps back or forth by more than [`SUPPORT_M`] stays two faces.
fn grow(
    echoes: &[Echo],
    by_beam: &BeamBins,
    used: &[bool],
    (mut wall, mut members): (WallSegment, Vec<usize>),
    cone: f64,
    config: &WallConfig,
) -> (WallSegment, Vec<usize>) {
    for _ in 0..GROW_ROUNDS {
        let (normal, offset) = (wall.normal_rad, wall.offset_m);
        let line = Support::new(normal, offset, cone);
        let band = by_beam.facing(normal, cone, |i| {
            line.holds(&echoes[i]) && (!used[i] || members.binary_search(&i).is_ok())
        });
        let shared = |p: &Vec<usize>| {
            p.iter()
                .filter(|i| members.binary_search(i).is_ok())
                .count()
        };
        let Some(piece) = split(echoes, &band, normal, config.max_gap_m)
            .into_iter()
            .max_by_key(shared)
        else {
            break;
        };
        if piece.len() <= members.len() {
            break;
        }
        match fit(echoes, &piece, normal, offset, config.min_readings) {
            Some((w, m)) if m.len() > members.len() => (wall, members) = (w, m),
            _ => break,
        }
    }
    (wall, members)
}

/// The foot of an echo's perpendicular on the line, as a position along it.
fn foot_along(e: &Echo, normal: f64) -> f64 {
    let (s, c) = normal.sin_cos();
    -s * e.s[0] + c * e.s[1]
}

/// The supporting readings in pieces along the line, split where no echo came over `max_gap_m`.
fn split(echoes: &[Echo], support: &[usize], normal: f64, max_gap_m: f64) -> Vec<Vec<usize>> {
    let mut sorted: Vec<(f64, usize)> = support
        .iter()
        .map(|&i| (foot_along(&echoes[i], normal), i))
        .collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut pieces: Vec<Vec<usize>> = Vec::new();
    let mut last = f64::NEG_INFINITY;
    for (u, i) in sorted {
        match pieces.last_mut() {
            Some(p) if u - last <= max_gap_m => p.push(i),
            _ => pieces.push(vec![i]),
        }
        last = u;
    }
    pieces
}

/// Least-squares line of one piece: minimises `sum (n(a) . s_i - r_i - c)^2` over the normal `a`
/// and offset `c` (Gauss-Newton from the Hough cell), then drops readings off by more than
/// [`SUPPORT_M`] and fits again. The face and the readings it kept; `None` for fewer than
/// `min_readings` or sensors too bunched along it.
fn fit(
    echoes: &[Echo],
    piece: &[usize],
    normal: f64,
    offset: f64,
    min_readings: usize,
) -> Option<(WallSegment, Vec<usize>)> {
    let mut members: Vec<usize> = piece.to_vec();
    let (mut a, mut c) = (normal, offset);
    for round in 0..2 {
        if members.len() < min_readings {
            return None;
        }
        let along: Vec<f64> = members.iter().map(|&i| foot_along(&echoes[i], a)).collect();
        let spread = along.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - along.iter().copied().fold(f64::INFINITY, f64::min);
        if spread < MIN_SPREAD_M {
            return None;
        }
        for _ in 0..5 {
            // Normal equations of the two parameters.
            let (mut h00, mut h01, mut h11, mut g0, mut g1) = (0.0, 0.0, 0.0, 0.0, 0.0);
            let (s, co) = a.sin_cos();
            for &i in &members {
                let e = &echoes[i];
                let res = co * e.s[0] + s * e.s[1] - e.range - c;
                let da = -s * e.s[0] + co * e.s[1];
                h00 += da * da;
                h01 -= da;
                h11 += 1.0;
                g0 += da * res;
                g1 -= res;
            }
            let det = h00 * h11 - h01 * h01;
            if det.abs() < 1e-12 {
                return None;
            }
            let step_a = -(h11 * g0 - h01 * g1) / det;
            let step_c = -(h00 * g1 - h01 * g0) / det;
            a += step_a;
            c += step_c;
            if step_a.abs() < 1e-9 && step_c.abs() < 1e-9 {
                break;
            }
        }
        if round == 0 {
            let (s, co) = a.sin_cos();
            members.retain(|&i| {
                let e = &echoes[i];
                (co * e.s[0] + s * e.s[1] - e.range - c).abs() <= SUPPORT_M
            });
        }
    }
    let (s, co) = a.sin_cos();
    let residual = |e: &Echo| co * e.s[0] + s * e.s[1] - e.range - c;
    let rms = (members
        .iter()
        .map(|&i| residual(&echoes[i]).powi(2))
        .sum::<f64>()
        / members.len() as f64)
        .sqrt();
    let along: Vec<f64> = members.iter().map(|&i| foot_along(&echoes[i], a)).collect();
    let lo = along.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = along.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // The point of the line at position u along it: c n + u (-sin, cos).
    let at = |u: f64| [c * co - u * s, c * s + u * co];
    members.sort_unstable();
    let wall = WallSegment {
        normal_rad: a.rem_euclid(TAU),
        offset_m: c,
        from_m: at(lo),
        to_m: at(hi),
        readings: members.len(),
        rms_m: rms,
        sigma_m: None,
    };
    Some((wall, members))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;
    use crate::sonar::grid::{CountingGrid, GridConfig, OccupancyGrid};

    /// Readings of the sensors of a robot driving along `y = 2` at 0.5 m, looking left and
    /// forward-left, plus a turn on the spot at the start.
    fn along_wall() -> Vec<PlacedReading> {
        let mut out = Vec::new();
        for k in 0..60 {
            let x = 0.5 + k as f64 * 0.05;
            for (bearing, range) in [(std::f64::consts::FRAC_PI_2 + 0.05, 0.5), (0.785, 0.72)] {
                out.push(PlacedReading {
                    t_s: k as f64,
                    world_from_sensor: Pose2::new(x, 1.5, bearing),
                    range_m: Some(range + 0.002 * ((k * 7 % 5) as f64 - 2.0)),
                });
            }
        }
        out
    }

    /// The walls of `readings` of 30 degree cones with 2.1 m range on `grid`, default settings.
    fn walls_on(readings: &[PlacedReading], grid: &OccupancyMap) -> Vec<WallSegment> {
        map_walls(
            readings,
            15f64.to_radians(),
            2.1,
            grid,
            &WallConfig::default(),
        )
    }

    fn grid_of(readings: &[PlacedReading]) -> OccupancyMap {
        let mut grid = CountingGrid::new(GridConfig::default(), 30f64.to_radians(), 2.1).unwrap();
        grid.insert_all(readings);
        grid.map()
    }

    #[test]
    fn the_wall_step_follows_a_sparse_runs_sampling() {
        let set = WallConfig::default();
        // Dense (the samples, freiburg-079): as set.
        let dense = set.for_spacing(Some(0.09));
        assert_eq!((dense.min_readings, dense.max_gap_m), (12, 0.5));
        assert!(!dense.on_unknown_cells && !dense.follow_sampling);
        // aces as sonar, a reading every 0.73 m: 12 x 0.15 / 0.73 = 2.5 readings, 5 at least.
        let sparse = set.for_spacing(Some(0.73));
        assert_eq!(sparse.min_readings, FEWEST_READINGS);
        assert!((sparse.max_gap_m - 1.825).abs() < 1e-12);
        assert!(sparse.on_unknown_cells);
        assert_eq!(sparse.for_spacing(Some(2.0)), sparse, "follows once");
        // 0.25 m: 12 x 0.6 = 7.2 -> 7 readings, the gap 0.625 m.
        let between = set.for_spacing(Some(0.25));
        assert_eq!(between.min_readings, 7);
        let fixed = WallConfig {
            follow_sampling: false,
            ..set.clone()
        };
        assert_eq!(fixed.for_spacing(Some(0.73)).min_readings, 12);
        assert!(set.validate().is_ok());
        let bad = WallConfig {
            min_readings: 2,
            ..set
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn a_laser_ray_meets_a_face_where_its_line_crosses_it() {
        // The face y = 2 seen from below: normal -y, offset -2, from x = -5 to 5.
        let w = WallSegment {
            normal_rad: 1.5 * std::f64::consts::PI,
            offset_m: -2.0,
            from_m: [-5.0, 2.0],
            to_m: [5.0, 2.0],
            readings: 20,
            rms_m: 0.01,
            sigma_m: None,
        };
        let up = std::f64::consts::FRAC_PI_2;
        let r = w.expected_ray_range([0.0, 0.0], up, 1.0, 0.05).unwrap();
        assert!((r - 2.0).abs() < 1e-12);
        // 30 degrees off the normal: 2 / cos 30, meeting the face at x = -2 tan 30.
        let slant = up + 30f64.to_radians();
        let r = w.expected_ray_range([0.0, 0.0], slant, 1.0, 0.05).unwrap();
        assert!((r - 2.0 / 30f64.to_radians().cos()).abs() < 1e-12);
        // Beyond the largest incidence, past the face's end, from behind, or looking away: none.
        assert_eq!(w.expected_ray_range([0.0, 0.0], slant, 0.5, 0.05), None);
        assert_eq!(w.expected_ray_range([4.5, 0.0], up - 0.5, 1.0, 0.05), None);
        assert_eq!(w.expected_ray_range([0.0, 3.0], -up, 1.0, 0.05), None);
        assert_eq!(w.expected_ray_range([0.0, 0.0], -up, 1.0, 0.05), None);
    }

    #[test]
    fn laser_returns_vote_for_the_walls_through_them() {
        // A laser 1.5 m from the wall y = 2, sweeping its beams across it as it drives along.
        let mut placed = Vec::new();
        for step in 0..40 {
            let x = -2.0 + 0.1 * step as f64;
            for k in -30..=30 {
                let beam = std::f64::consts::FRAC_PI_2 + (k as f64).to_radians();
                placed.push(PlacedReading {
                    t_s: step as f64,
                    world_from_sensor: Pose2::new(x, 0.5, beam),
                    range_m: Some(1.5 / (k as f64).to_radians().cos()),
                });
            }
        }
        let layout = crate::sonar::SonarLayout {
            beam: crate::sonar::BeamModel::Ray,
            cone_rad: 1f64.to_radians(),
            max_range_m: 10.0,
            min_range_m: 0.0,
            ..crate::sonar::SonarLayout::frontal5()
        };
        let mut grid =
            crate::sonar::grid::CountingGrid::for_layout(GridConfig::default(), &layout).unwrap();
        grid.insert_all(&placed);
        let walls =
            crate::sonar::map::layout_walls(&layout, &placed, &grid.map(), &WallConfig::default());
        assert!(!walls.is_empty());
        let w = &walls[0];
        assert!(
            (w.normal_rad - 1.5 * std::f64::consts::PI).abs() < 0.01,
            "{w:?}"
        );
        assert!((w.offset_m + 2.0).abs() < 0.01, "{w:?}");
    }

    #[test]
    fn a_wall_followed_is_one_segment_on_its_line() {
        let readings = along_wall();
        let walls = walls_on(&readings, &grid_of(&readings));
        let w = walls.first().expect("a wall");
        // The face looks down (-y), towards the robot: normal -90 degrees, n . q = -2.
        assert!(
            (w.normal_rad - 1.5 * std::f64::consts::PI).abs() < 0.005,
            "{w:?}"
        );
        assert!((w.offset_m + 2.0).abs() < 0.005, "{w:?}");
        assert!(
            w.from_m[0].min(w.to_m[0]) < 0.6 && w.from_m[0].max(w.to_m[0]) > 3.3,
            "{w:?}"
        );
        // Seen from the robot's path, the wall is 0.5 m away, and not from behind it.
        let r = w.expected_range([2.0, 1.5], std::f64::consts::FRAC_PI_2, 0.26, 0.05);
        assert!((r.unwrap() - 0.5).abs() < 0.005);
        assert!(w
            .expected_range([2.0, 2.5], -std::f64::consts::FRAC_PI_2, 0.26, 0.05)
            .is_none());
        assert!(w.expected_range([2.0, 1.5], 0.0, 0.26, 0.05).is_none());
    }

    #[test]
    fn a_long_wall_at_no_whole_degree_is_one_face_on_its_line() {
        // A 30 m corridor wall turned 5.4 degrees (a real building's), followed 1 m away: the
        // accumulator holds its direction to half a degree, 5 cm off at its ends. The step fits
        // one face along all of it.
        let a = 5.4f64.to_radians();
        let (u, left) = ([a.cos(), a.sin()], [-a.sin(), a.cos()]);
        let readings: Vec<PlacedReading> = (-300..=300i32)
            .map(|k| {
                let along = k as f64 * 0.05;
                let noise = 0.004 * ((k * 7).rem_euclid(5) as f64 - 2.0) / 2.0;
                PlacedReading {
                    t_s: k as f64,
                    world_from_sensor: Pose2::new(
                        along * u[0] - left[0],
                        along * u[1] - left[1],
                        a + std::f64::consts::FRAC_PI_2,
                    ),
                    range_m: Some(1.0 + noise),
                }
            })
            .collect();
        let walls = walls_on(&readings, &grid_of(&readings));
        assert_eq!(walls.len(), 1, "{walls:?}");
        let w = &walls[0];
        assert!(w.length_m() > 29.5, "{w:?}");
        assert!(w.readings > 590, "{w:?}");
        // On the line through the origin along `u`, seen from its right.
        for end in [w.from_m, w.to_m] {
            let off = end[0] * left[0] + end[1] * left[1];
            assert!(off.abs() < 0.01, "{w:?}");
        }
    }

    #[test]
    fn a_map_far_from_the_origin_gives_the_same_walls_moved() {
        let readings = along_wall();
        let shift = [1000.0, -500.0];
        let moved: Vec<PlacedReading> = readings
            .iter()
            .map(|r| PlacedReading {
                world_from_sensor: Pose2::new(
                    r.world_from_sensor.x + shift[0],
                    r.world_from_sensor.y + shift[1],
                    r.world_from_sensor.theta,
                ),
                ..*r
            })
            .collect();
        let grid = grid_of(&readings);
        let (a, b) = (walls_on(&readings, &grid), walls_on(&moved, &grid));
        assert_eq!(a.len(), b.len());
        for (a, b) in a.iter().zip(&b) {
            let n = a.normal();
            assert!((a.normal_rad - b.normal_rad).abs() < 1e-6, "{a:?} {b:?}");
            let offset = a.offset_m + n[0] * shift[0] + n[1] * shift[1];
            assert!((offset - b.offset_m).abs() < 1e-6, "{a:?} {b:?}");
            assert!((a.from_m[0] + shift[0] - b.from_m[0]).abs() < 1e-6);
            assert!((a.to_m[1] + shift[1] - b.to_m[1]).abs() < 1e-6);
        }
    }

    #[test]
    fn a_pose_far_off_is_left_out_instead_of_sizing_the_accumulator() {
        let readings = along_wall();
        let grid = grid_of(&readings);
        let mut glitched = readings.clone();
        // A jump of 10,000 km in a few poses: sized by it, the accumulator would need terabytes.
        for r in glitched.iter_mut().take(6) {
            r.world_from_sensor.x += 1e7;
        }
        glitched.push(PlacedReading {
            t_s: 99.0,
            world_from_sensor: Pose2::new(f64::NAN, 1.0, 0.0),
            range_m: Some(1.0),
        });
        let (a, b) = (walls_on(&readings, &grid), walls_on(&glitched, &grid));
        assert!(!b.is_empty());
        assert!(
            (a[0].normal_rad - b[0].normal_rad).abs() < 0.01,
            "{a:?} {b:?}"
        );
        assert!((a[0].offset_m - b[0].offset_m).abs() < 0.01, "{a:?} {b:?}");
    }

    #[test]
    fn a_robot_turning_on_the_spot_makes_no_wall() {
        // One place, every direction: the ranges cannot tell a wall's direction.
        let readings: Vec<PlacedReading> = (0..200)
            .map(|k| PlacedReading {
                t_s: k as f64,
                world_from_sensor: Pose2::new(1.0, 1.0, k as f64 * 0.0314),
                range_m: Some(1.0),
            })
            .collect();
        assert!(walls_on(&readings, &grid_of(&readings)).is_empty());
    }
}
