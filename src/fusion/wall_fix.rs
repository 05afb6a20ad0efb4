//! The pose from the walls, for a localiser too unsure of its pose to match ranges with walls one
//! at a time (a far tag's fix, an uncertain start): the recent ranges, placed relative to now by
//! the odometry, are matched with the surveyed walls over a grid of poses around the estimate,
//! coarse then fine; a fix is taken only when most ranges agree with it and no other pose of the
//! grid explains them nearly as well (a corridor, whose walls say nothing about where along it
//! the robot is, gives none). What else is known of the pose (a far tag's sightings, which hold
//! the robot on an arc around the tag) rules poses out of the grid and weighs the rest.
//!
//! A range is explained at a pose by how near its echo's arc (the range across the beam's cone,
//! or the point down a laser's ray) comes to a surveyed wall: a sonar hears a wall square to its
//! axis, one at the cone's edge and a corner alike, all of which touch the arc. The distance to
//! the walls is looked up in a table over the walls' surroundings, built once.

use crate::geometry::{Pose2, Segment};
use crate::sonar::walls::WallSegment;
use crate::sonar::{SonarLayout, SonarReading};
use nalgebra::{Matrix3, Point2, Vector3};
use rayon::prelude::*;
use std::collections::VecDeque;

/// Ranges kept, the latest: enough for walls in several directions.
const WINDOW: usize = 48;
/// A match is tried with at least this many ranges (12: a robot placed metres off by a far tag
/// while turning on the spot has few echoes; 24 left museum seed 3's third unknown start 1.09 m
/// off for 6 s, docs/RESULTS.md) ...
const MIN_RANGES: usize = 12;
/// ... every this many new ranges (a filter placed metres off by a far tag needs its pose at
/// once), or this much travel, metres, or turn, radians (45 degrees: a robot looking around sees
/// new walls without moving). A clear fix from few ranges may leave the heading loose, and says
/// so in its covariance ([`RangeWindow::fix`]).
const TRY_EVERY_M: f64 = 0.5;
const TRY_EVERY_RAD: f64 = std::f64::consts::FRAC_PI_4;
const TRY_EVERY_RANGES: usize = 4;
/// The search reaches this far around the estimate at most (or 3 sigma when less): metres, and
/// radians (30 degrees).
const MAX_REACH_M: f64 = 1.5;
const MAX_REACH_RAD: f64 = 0.52;
/// Coarse grid steps and the residual beyond which a range counts as unexplained there, metres.
const COARSE_STEP_M: f64 = 0.1;
const COARSE_STEP_RAD: f64 = 0.035;
const COARSE_TRUNCATE_M: f64 = 0.2;
/// Fine grid: steps over one coarse step around the best, and its residual cut.
const FINE_STEP_M: f64 = 0.02;
const FINE_STEP_RAD: f64 = 0.007;
const FINE_TRUNCATE_M: f64 = 0.06;
/// A range agrees with a pose when its residual is below this, metres; a fix needs this share of
/// the ranges to agree.
const INLIER_M: f64 = 0.05;
const MIN_INLIER_SHARE: f64 = 0.8;
/// A range's sigma against the walls, metres: half the inlier cut.
const RANGE_SIGMA_M: f64 = 0.5 * INLIER_M;
/// A rival pose (further than this from the best, metres) must explain the ranges this many
/// times worse, in summed truncated squares, for the best to be taken.
const RIVAL_M: f64 = 0.4;
const RIVAL_RATIO: f64 = 3.0;
/// The fix's sigmas: metres and radians (the fine grid's steps and the ranges' noise, with room).
pub(super) const FIX_SIGMA_M: f64 = 0.05;
pub(super) const FIX_SIGMA_RAD: f64 = 0.026;

/// Points of an echo's arc are taken this far apart across the cone: 5 degrees.
const ARC_STEP_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// The latest ranges with an echo, each with the odometry pose when it was taken.
#[derive(Debug, Clone, Default)]
pub(super) struct RangeWindow {
    ranges: VecDeque<(Pose2, SonarReading)>,
    /// The odometry pose at the last try.
    last_try: Option<Pose2>,
    /// Ranges kept since the last try.
    since_try: usize,
    /// The distance to the walls, once needed.
    field: Option<DistanceField>,
}

/// A distance tabled on a grid of square cells from `origin` (the lower-left corner, metres),
/// row-major from the bottom row, capped at `cap` (and `cap` off the table): here to the nearest
/// surveyed wall face, over the walls and a sensor's reach around them ([`FIELD_CAP_M`]); in
/// [`crate::fusion::offline`] to the nearest occupied cell of a grid.
#[derive(Debug, Clone)]
pub(super) struct DistanceField {
    pub(super) origin: (f64, f64),
    pub(super) cell_m: f64,
    pub(super) cols: usize,
    pub(super) rows: usize,
    pub(super) d: Vec<f32>,
    pub(super) cap: f64,
}

/// Distances are tabled up to this, metres (more than any truncation used).
const FIELD_CAP_M: f64 = 0.3;
/// The table's cells: this size, or larger to hold at most [`FIELD_MAX_CELLS`].
const FIELD_CELL_M: f64 = 0.02;
const FIELD_MAX_CELLS: f64 = 4.0e6;

impl DistanceField {
    /// A table of `cols` by `rows` cells of `cell_m` from `origin`, every distance `cap`.
    pub(super) fn capped(
        origin: (f64, f64),
        cell_m: f64,
        (cols, rows): (usize, usize),
        cap: f64,
    ) -> Self {
        Self {
            origin,
            cell_m,
            cols,
            rows,
            d: vec![cap as f32; cols * rows],
            cap,
        }
    }

    fn new(walls: &[WallSegment], reach_m: f64) -> Self {
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for w in walls {
            for p in [w.from_m, w.to_m] {
                lo = (lo.0.min(p[0]), lo.1.min(p[1]));
                hi = (hi.0.max(p[0]), hi.1.max(p[1]));
            }
        }
        if !(lo.0.is_finite() && hi.0.is_finite()) {
            return Self {
                origin: (0.0, 0.0),
                cell_m: 1.0,
                cols: 0,
                rows: 0,
                d: Vec::new(),
                cap: FIELD_CAP_M,
            };
        }
        let margin = reach_m + FIELD_CAP_M;
        let (w, h) = (hi.0 - lo.0 + 2.0 * margin, hi.1 - lo.1 + 2.0 * margin);
        let cell_m = FIELD_CELL_M.max((w * h / FIELD_MAX_CELLS).sqrt());
        let (cols, rows) = ((w / cell_m).ceil() as usize, (h / cell_m).ceil() as usize);
        let origin = (lo.0 - margin, lo.1 - margin);
        let mut d = vec![FIELD_CAP_M as f32; cols * rows];
        // Each wall writes the cells of its bounding box grown by the cap, once each.
        let cell_of =
            |v: f64, lo: f64, n: usize| ((v - lo) / cell_m).clamp(0.0, n as f64 - 1.0) as usize;
        for wall in walls {
            let segment = Segment::new(Point2::from(wall.from_m), Point2::from(wall.to_m));
            let (a, b) = (wall.from_m, wall.to_m);
            let (c0, c1) = (
                cell_of(a[0].min(b[0]) - FIELD_CAP_M, origin.0, cols),
                cell_of(a[0].max(b[0]) + FIELD_CAP_M, origin.0, cols),
            );
            let (r0, r1) = (
                cell_of(a[1].min(b[1]) - FIELD_CAP_M, origin.1, rows),
                cell_of(a[1].max(b[1]) + FIELD_CAP_M, origin.1, rows),
            );
            for r in r0..=r1 {
                for c in c0..=c1 {
                    let centre = Point2::new(
                        origin.0 + (c as f64 + 0.5) * cell_m,
                        origin.1 + (r as f64 + 0.5) * cell_m,
                    );
                    let cell = &mut d[r * cols + c];
                    *cell = cell.min(segment.distance_to(centre) as f32);
                }
            }
        }
        Self {
            origin,
            cell_m,
            cols,
            rows,
            d,
            cap: FIELD_CAP_M,
        }
    }

    /// The distance tabled at `(x, y)`: the cap off the table.
    pub(super) fn at(&self, x: f64, y: f64) -> f64 {
        let (c, r) = (
            (x - self.origin.0) / self.cell_m,
            (y - self.origin.1) / self.cell_m,
        );
        if c < 0.0 || r < 0.0 || c >= self.cols as f64 || r >= self.rows as f64 {
            return self.cap;
        }
        f64::from(self.d[r as usize * self.cols + c as usize])
    }
}

/// A pose the walls give.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct WallFix {
    pub(super) pose: Pose2,
    /// Its covariance: [`FIX_SIGMA_M`], and [`FIX_SIGMA_RAD`] or the spread of the headings
    /// that explain the ranges nearly as well, for a clear fix; for an ambiguous
    /// one, the spread of the poses that explain the ranges nearly as well as the best (at
    /// least [`RIVAL_M`] a side).
    pub(super) cov: Matrix3<f64>,
    /// Whether no other pose explains the ranges nearly as well.
    pub(super) clear: bool,
    /// Ranges that agree with it, of those matched.
    pub(super) inliers: usize,
    pub(super) ranges: usize,
}

impl RangeWindow {
    /// Keeps a reading taken at odometry pose `odom` (one whose range measures a distance:
    /// [`SonarLayout::measures`]).
    pub(super) fn push(&mut self, odom: Pose2, reading: &SonarReading, layout: &SonarLayout) {
        if reading.range_m.is_some_and(|r| layout.measures(r)) {
            if self.ranges.len() == WINDOW {
                self.ranges.pop_front();
            }
            self.ranges.push_back((odom, *reading));
            self.since_try += 1;
        }
    }

    /// Whether a match is due at odometry pose `odom`: enough ranges, and new ranges or travel
    /// since the last.
    pub(super) fn due(&self, odom: Pose2) -> bool {
        self.ranges.len() >= MIN_RANGES
            && (self.since_try >= TRY_EVERY_RANGES
                || self.last_try.is_none_or(|p| {
                    (p.x - odom.x).hypot(p.y - odom.y) >= TRY_EVERY_M
                        || crate::geometry::wrap_angle(p.theta - odom.theta).abs() >= TRY_EVERY_RAD
                }))
    }

    /// Matches the ranges with `walls` around `estimate` (the pose now, at odometry pose `odom`)
    /// within `reach` (metres, radians: 3 sigma, capped); `None` when no pose of the grid the
    /// prior allows explains most ranges. When others explain them nearly as well the fix is
    /// not clear, and its covariance spans them: a robot placed metres off by a far tag is
    /// brought within decimetres at once, and the next ranges pick the pose (`None` again when
    /// they run past the grid, and past a second one around the best). A clear fix's heading
    /// sigma spans the headings that explain the ranges nearly as well near it (a sonar's arc
    /// touches a wall across the cone's width, so a few ranges may fix the place and leave the
    /// heading loose), at least [`FIX_SIGMA_RAD`]. `prior` says
    /// what else is known of the pose: `None` for a pose it rules out, else its chi-square there,
    /// added to the ranges' (`Some(0.0)` everywhere: the walls alone).
    pub(super) fn fix(
        &mut self,
        odom: Pose2,
        estimate: Pose2,
        reach: (f64, f64),
        walls: &[WallSegment],
        layout: &SonarLayout,
        prior: &(dyn Fn(Pose2) -> Option<f64> + Sync),
    ) -> Option<WallFix> {
        self.last_try = Some(odom);
        self.since_try = 0;
        let field = self
            .field
            .get_or_insert_with(|| DistanceField::new(walls, layout.max_range_m));
        // Each echo's arc, as points in the frame of the robot now (odometry-relative).
        let half = match layout.beam {
            crate::sonar::BeamModel::Cone => 0.5 * layout.cone_rad,
            crate::sonar::BeamModel::Ray => 0.0,
        };
        let steps = (half / ARC_STEP_RAD).ceil() as i32;
        let arcs: Vec<Vec<(f64, f64)>> = self
            .ranges
            .iter()
            .filter_map(|(o, r)| {
                let sensor = layout.sensors.get(r.sensor)?;
                let at = odom.between(o).compose(&sensor.robot_from_sensor());
                let range = r.range_m?;
                Some(
                    (-steps..=steps)
                        .map(|k| {
                            let a = at.theta + half * k as f64 / steps.max(1) as f64;
                            (at.x + range * a.cos(), at.y + range * a.sin())
                        })
                        .collect(),
                )
            })
            .collect();
        let field = &*field;
        let cost = |pose: Pose2, truncate: f64| -> (f64, usize) {
            let (s, c) = pose.theta.sin_cos();
            let mut sum = 0.0;
            let mut inliers = 0;
            for arc in &arcs {
                let residual = arc
                    .iter()
                    .map(|&(x, y)| field.at(pose.x + c * x - s * y, pose.y + s * x + c * y))
                    .fold(f64::INFINITY, f64::min);
                sum += residual.min(truncate).powi(2);
                inliers += usize::from(residual < INLIER_M);
            }
            (sum, inliers)
        };
        let (reach_m, reach_rad) = (reach.0.min(MAX_REACH_M), reach.1.min(MAX_REACH_RAD));
        // A pose the prior allows: its ranges' summed truncated squares, those with the prior's
        // chi-square added (in the same units: times a range's variance), and its inliers.
        let weigh = |p: Pose2, truncate: f64| {
            let prior = prior(p)?;
            let (walls, inliers) = cost(p, truncate);
            Some((p, walls, walls + RANGE_SIGMA_M.powi(2) * prior, inliers))
        };
        // The ranges' own noise, so that a near-perfect best does not make every rival look far.
        let floor = arcs.len() as f64 * RANGE_SIGMA_M.powi(2);
        // Whether `p` lies inside the grid around `centre`, off its edge.
        let inside = |centre: &Pose2, p: &Pose2| {
            let edge_m = reach_m - 0.5 * COARSE_STEP_M;
            (p.x - centre.x).abs() < edge_m
                && (p.y - centre.y).abs() < edge_m
                && crate::geometry::wrap_angle(p.theta - centre.theta).abs()
                    < reach_rad - 0.5 * COARSE_STEP_RAD
        };
        // The coarse grid around the estimate; when the poses that explain the ranges nearly as
        // well as the best reach its edge, once more around the best (the two grids' poses
        // weighed together).
        let mut centres = vec![estimate];
        let mut scored: Vec<(Pose2, f64, f64)> = Vec::new();
        let best = loop {
            let centre = centres[centres.len() - 1];
            scored.extend(
                grid(
                    centre,
                    (reach_m, reach_rad),
                    (COARSE_STEP_M, COARSE_STEP_RAD),
                )
                .into_par_iter()
                .filter_map(|p| weigh(p, COARSE_TRUNCATE_M).map(|(p, w, j, _)| (p, w, j)))
                .collect::<Vec<_>>(),
            );
            let &(best, best_cost, _) = scored.iter().min_by(|a, b| a.2.total_cmp(&b.2))?;
            let rival = scored
                .iter()
                .filter(|(p, _, _)| (p.x - best.x).hypot(p.y - best.y) > RIVAL_M)
                .map(|&(_, c, _)| c)
                .fold(f64::INFINITY, f64::min);
            let near = RIVAL_RATIO * best_cost.max(floor);
            let plausible: Vec<Pose2> = scored.iter().filter(|s| s.1 < near).map(|s| s.0).collect();
            if rival >= near {
                // Near the best, the headings that explain the ranges nearly as well: a sonar's
                // arcs touch a wall over the cone's width, so few ranges may leave the heading
                // loose where the place is sure.
                break (best, spread(&plausible, best).1[(2, 2)]);
            }
            tracing::debug!(
                "no clear pose from the walls: {} ranges explained nearly as well {RIVAL_M} m apart (cost {best_cost:.4} and {rival:.4})",
                arcs.len()
            );
            let (_, _, _, inliers) = weigh(best, COARSE_TRUNCATE_M)?;
            if (inliers as f64) < MIN_INLIER_SHARE * arcs.len() as f64 {
                return None;
            }
            // They must lie inside a searched grid: one on the edge says the grid cut off others
            // beyond it (a corridor's walls place the robot anywhere along it).
            if plausible
                .iter()
                .all(|p| centres.iter().any(|c| inside(c, p)))
            {
                let (pose, mut cov) = spread(&plausible, best);
                for (k, floor) in [RIVAL_M, RIVAL_M, COARSE_STEP_RAD].into_iter().enumerate() {
                    cov[(k, k)] = cov[(k, k)].max(floor * floor);
                }
                return Some(WallFix {
                    pose,
                    cov,
                    clear: false,
                    inliers,
                    ranges: arcs.len(),
                });
            }
            if centres.len() == 2 {
                return None;
            }
            centres.push(best);
        };
        let (best, heading_var) = best;
        let (fine, _, _, inliers) = grid(
            best,
            (COARSE_STEP_M, COARSE_STEP_RAD),
            (FINE_STEP_M, FINE_STEP_RAD),
        )
        .into_iter()
        .filter_map(|p| weigh(p, FINE_TRUNCATE_M))
        .min_by(|a, b| a.2.total_cmp(&b.2))?;
        (inliers as f64 >= MIN_INLIER_SHARE * arcs.len() as f64).then_some(WallFix {
            pose: fine,
            cov: Matrix3::from_diagonal(&Vector3::new(
                FIX_SIGMA_M.powi(2),
                FIX_SIGMA_M.powi(2),
                FIX_SIGMA_RAD.powi(2).max(heading_var),
            )),
            clear: true,
            inliers,
            ranges: arcs.len(),
        })
    }
}

/// The mean of `poses` (headings about `about`'s) and their spread: their covariance with a
/// coarse step's rounding.
fn spread(poses: &[Pose2], about: Pose2) -> (Pose2, Matrix3<f64>) {
    let n = poses.len().max(1) as f64;
    let offsets: Vec<Vector3<f64>> = poses
        .iter()
        .map(|p| {
            Vector3::new(
                p.x - about.x,
                p.y - about.y,
                crate::geometry::wrap_angle(p.theta - about.theta),
            )
        })
        .collect();
    let mean = offsets.iter().sum::<Vector3<f64>>() / n;
    let mut cov = offsets
        .iter()
        .map(|d| (d - mean) * (d - mean).transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let rounding =
        Vector3::new(COARSE_STEP_M, COARSE_STEP_M, COARSE_STEP_RAD).map(|s| s * s / 12.0);
    for k in 0..3 {
        cov[(k, k)] += rounding[k];
    }
    let pose = Pose2::new(
        about.x + mean[0],
        about.y + mean[1],
        crate::geometry::wrap_angle(about.theta + mean[2]),
    );
    (pose, cov)
}

/// Poses on a grid around `centre`: positions within `reach.0` and headings within `reach.1`, at
/// `step` (metres, radians); the steps each way rounded up.
fn grid(centre: Pose2, reach: (f64, f64), step: (f64, f64)) -> Vec<Pose2> {
    let n = |reach: f64, step: f64| (reach / step).ceil() as i32;
    pose_grid(centre, (n(reach.0, step.0), n(reach.1, step.1)), step)
}

/// Poses on a grid around `centre`: `nm` steps of `step.0` each way in x and y, `nr` of `step.1`
/// in heading.
pub(super) fn pose_grid(centre: Pose2, (nm, nr): (i32, i32), step: (f64, f64)) -> Vec<Pose2> {
    let mut out = Vec::new();
    for i in -nm..=nm {
        for j in -nm..=nm {
            for k in -nr..=nr {
                out.push(Pose2::new(
                    centre.x + i as f64 * step.0,
                    centre.y + j as f64 * step.0,
                    centre.theta + k as f64 * step.1,
                ));
            }
        }
    }
    out
}
