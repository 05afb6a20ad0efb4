//! The sonar's own correction, for a run with nothing else to correct the odometry against (no
//! tag sightings, no visual turns): keyframe by keyframe, the latest ranges (placed relative to
//! the keyframe by the odometry) are matched with the counting grid of every older reading,
//! placed along the trajectory corrected so far. A robot that comes back to a place it mapped
//! earlier, or turns on the spot before walls it has just seen, is pulled back onto them; the
//! matched keyframes then hold the offline graph, whose odometry calibration carries the
//! correction through the stretches no match reached.
//!
//! A range is explained at a pose by how near its echo's arc (the range across the beam's cone)
//! comes to an occupied cell of the grid so far, or, for a laser, how near its return comes to
//! an older return ([`ReturnField`]); a range whose arc lies wholly in cells the grid has not
//! seen says nothing and is left out of that match.
//!
//! Where a sonar slid along a wall and the building's walls run at right angles, the heading the
//! wall gives updates the keyframe's prediction first ([`super::wall_directions`]): the grid is
//! then placed along headings the walls hold, not along the odometry's drift across a stretch
//! where nothing was heard.

use super::keyframes::Keyframe;
use crate::fusion::ekf::compose_jacobians;
use crate::fusion::measurement::odometry_covariance;
use crate::fusion::wall_fix::DistanceField;
use crate::fusion::FuseConfig;
use crate::geometry::{pose_at, wrap_angle, Pose2, StampedPose};
use crate::sonar::grid::{CountingGrid, GridConfig, GridGeometry, OccupancyGrid, OccupancyMap};
use crate::sonar::{BeamModel, PlacedReading, SonarLayout, SonarReading};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Ranges (with an echo) matched at a keyframe: the latest, enough for walls in several
/// directions and a few metres of travel (the heading shows in how ranges taken apart agree).
const WINDOW: usize = 96;
/// The grid they are matched with holds the readings at least this long before them, seconds:
/// the readings just before are placed by the same odometry, and a match with them would only
/// repeat it (and make the filter surer than it is).
const GAP_S: f64 = 10.0;
/// A match needs at least this many of the window's ranges to fall where the grid has seen.
const MIN_SEEN: usize = 24;
/// The search around the pose the odometry predicts: metres and radians (10 degrees), and its
/// steps (metres, radians): coarse over it, then fine around the coarse mean.
const REACH_M: f64 = 0.4;
const REACH_RAD: f64 = 0.175;
const COARSE_STEP: (f64, f64) = (0.08, 0.035);
const FINE_STEP: (f64, f64) = (0.02, 0.0087);
/// A range's residual is truncated here (metres): further off, it is another wall or none.
const TRUNCATE_M: f64 = 0.15;
/// A range's residual sigma, metres: the sonar's noise, the grid's cells, and room for the
/// window's ranges not being independent (several off one wall).
const RANGE_SIGMA_M: f64 = 0.1;
/// A match is used only when it agrees with the prediction (its squared Mahalanobis distance
/// below the chi-square 99% point with 3 degrees of freedom): a wrong wall's match is left out.
const MATCH_GATE_CHI2: f64 = 11.34;
/// A range agrees with a pose when its arc comes this near an occupied cell, metres; a match
/// needs this share of the seen ranges to agree at its pose.
const INLIER_M: f64 = 0.06;
const MIN_INLIER_SHARE: f64 = 0.6;
/// A match that leaves its position sigma above this (metres) in every direction says nothing.
const MAX_MATCH_SIGMA_M: f64 = 0.12;
/// Points of an echo's arc are taken this far apart across the cone: 5 degrees.
const ARC_STEP_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// The distance table's cells per grid cell along each axis.
const FIELD_SUBCELLS: f64 = 4.0;
/// How far a laser scan's time stamp may be from when the scan was taken against the odometry's,
/// seconds: its match is as unsure as the robot's motion over it ([`timing_covariance`]). aces'
/// scans turn against its logged odometry by 1-3 degrees more, scan to scan, where the robot turns
/// than where it drives straight, and agree best with it shifted by 0.1 s; matched as if taken
/// exactly when stamped, a scan taken while turning put its keyframe's heading several degrees
/// off and held it there (docs/RESULTS.md, "The walls' directions for a laser").
const SCAN_TIME_SIGMA_S: f64 = 0.1;

/// What the sequential matching gave: every keyframe's pose (the odometry's prediction from the
/// one before, updated by its match when it has one) and the matches: keyframe, pose, covariance.
pub(super) struct ScanMatches {
    pub(super) poses: Vec<Pose2>,
    pub(super) matched: Vec<(usize, Pose2, Matrix3<f64>)>,
    /// Keyframes whose predicted heading a wall's direction corrected.
    pub(super) headings_held: usize,
}

/// Matches each keyframe's latest ranges with the grid of the older ones, in time order (see
/// the module's documentation); `None` when the grid cannot be made from `grid`. `headings`
/// gives keyframes a heading from the walls' directions (the correction to the keyframe's
/// odometry heading, and its sigma; empty for none): the prediction's heading is updated with
/// it, gated at three sigmas, before the match.
pub(super) fn sequential(
    frames: &[Keyframe],
    odometry: &[StampedPose],
    readings: &[SonarReading],
    layout: &SonarLayout,
    grid: &GridConfig,
    config: &FuseConfig,
    headings: &[Option<(f64, f64)>],
) -> Option<ScanMatches> {
    let mut counting = CountingGrid::for_layout(grid.clone(), layout).ok()?;
    let mut returns = (layout.beam == BeamModel::Ray)
        .then(|| ReturnField::over(&GridGeometry::from_config(grid)));
    // A reading at the transducer's shortest range is kept: the thing is at most that near, a
    // centimetre or two off the arc, well within a match's tolerance.
    let echo = |r: &SonarReading| layout.echo(r.range_m).is_some();
    // Times of the readings with an echo: the window of keyframe k is the WINDOW latest by then.
    let echo_times: Vec<f64> = readings.iter().filter(|r| echo(r)).map(|r| r.t_s).collect();
    let mut poses: Vec<Pose2> = Vec::with_capacity(frames.len());
    let mut matched = Vec::new();
    let mut inserted = 0; // readings already in the grid
    let mut covariance = Matrix3::zeros();
    let mut headings_held = 0;
    for (k, frame) in frames.iter().enumerate() {
        let mut predicted = match k {
            0 => frame.odom,
            _ => {
                let delta = frames[k - 1].odom.between(&frame.odom);
                covariance = propagated(&covariance, poses[k - 1], delta, config);
                poses[k - 1].compose(&delta)
            }
        };
        // The heading the walls' directions give (relative to their axes), a Kalman update.
        if let Some(&Some((innovation, sigma))) = headings.get(k).filter(|_| k > 0) {
            let innovation = innovation - wrap_angle(predicted.theta - frame.odom.theta);
            let s = covariance[(2, 2)] + sigma * sigma;
            if innovation * innovation / s < 9.0 {
                headings_held += 1;
                let gain = covariance.column(2) / s;
                predicted = Pose2::new(
                    predicted.x + gain[0] * innovation,
                    predicted.y + gain[1] * innovation,
                    wrap_angle(predicted.theta + gain[2] * innovation),
                );
                covariance -= gain * covariance.row(2);
                covariance = 0.5 * (covariance + covariance.transpose());
            }
        }
        let last = echo_times.partition_point(|&t| t <= frame.t_s);
        let window_start = echo_times[last.saturating_sub(WINDOW)..last]
            .first()
            .copied()
            .unwrap_or(frame.t_s);
        // The grid takes every reading older than the window, at the pose corrected so far.
        while inserted < readings.len() && readings[inserted].t_s < window_start - GAP_S {
            if let Some(p) = placed(&readings[inserted], odometry, frames, &poses, layout) {
                counting.insert(&p);
                if let Some(returns) = returns.as_mut().filter(|_| echo(&readings[inserted])) {
                    returns.add(&p);
                }
            }
            inserted += 1;
        }
        let mut window: Vec<&SonarReading> = readings[inserted..]
            .iter()
            .take_while(|r| r.t_s <= frame.t_s)
            .filter(|r| echo(r) && r.t_s >= window_start)
            .collect();
        // A laser's scan shares one time: the window is the whole latest scan (360 returns on
        // freiburg-079), of which every k-th is matched, [`WINDOW`] at most: as well placed
        // (freiburg-079 drifted three ways: the same ATE within 2 cm) in a third of the time.
        if window.len() > WINDOW && layout.beam == BeamModel::Ray {
            let k = window.len().div_ceil(WINDOW);
            window = window.into_iter().step_by(k).collect();
        }
        let pose = (k > 0)
            .then(|| {
                let map = counting.map();
                let arcs = arcs(&window, odometry, frame.odom, layout);
                match returns.as_ref() {
                    Some(returns) => match_arcs(&map, &returns.field, &arcs, predicted),
                    None => match_arcs(
                        &map,
                        &occupied_distances(
                            &map,
                            map.geometry.resolution_m / FIELD_SUBCELLS,
                            TRUNCATE_M,
                        ),
                        &arcs,
                        predicted,
                    ),
                }
            })
            .flatten();
        // A laser's match is as unsure as the motion over its scan's time stamp's own sigma.
        let pose = pose.map(|(z, r)| match (layout.beam, window.first()) {
            (BeamModel::Ray, Some(scan)) => (z, r + timing_covariance(odometry, scan.t_s)),
            _ => (z, r),
        });
        match pose {
            Some((z, r))
                if {
                    let innovation = Vector3::new(
                        z.x - predicted.x,
                        z.y - predicted.y,
                        wrap_angle(z.theta - predicted.theta),
                    );
                    (covariance + r)
                        .try_inverse()
                        .is_some_and(|s| innovation.dot(&(s * innovation)) < MATCH_GATE_CHI2)
                } =>
            {
                // The prediction and the match, each with its covariance (a Kalman update).
                let gain = covariance * (covariance + r).try_inverse()?;
                let innovation = Vector3::new(
                    z.x - predicted.x,
                    z.y - predicted.y,
                    wrap_angle(z.theta - predicted.theta),
                );
                let d = gain * innovation;
                poses.push(Pose2::new(
                    predicted.x + d[0],
                    predicted.y + d[1],
                    wrap_angle(predicted.theta + d[2]),
                ));
                covariance = (Matrix3::identity() - gain) * covariance;
                covariance = 0.5 * (covariance + covariance.transpose());
                matched.push((k, z, r));
            }
            _ => poses.push(predicted),
        }
    }
    Some(ScanMatches {
        poses,
        matched,
        headings_held,
    })
}

/// Time of the run's first echo, seconds; `None` if it has none.
pub(super) fn first_echo_s(readings: &[SonarReading], layout: &SonarLayout) -> Option<f64> {
    readings
        .iter()
        .find(|r| layout.echo(r.range_m).is_some())
        .map(|r| r.t_s)
}

/// How well a run's ranges agree with one another placed along `trajectory`: the share of the
/// readings with an echo whose arc comes within [`INLIER_M`] of an occupied cell of the counting
/// grid (on `grid`) of all of them (a laser's: of a return a minute older,
/// [`returns_agreement`]). A trajectory that places a wall's echoes where the wall was seen from
/// elsewhere scores higher; `None` when the grid cannot be made.
pub(super) fn agreement(
    trajectory: &[StampedPose],
    readings: &[SonarReading],
    layout: &SonarLayout,
    grid: &GridConfig,
) -> Option<f64> {
    let placed: Vec<PlacedReading> = crate::sonar::place_readings(readings, layout, trajectory);
    let echo = |p: &PlacedReading| layout.echo(p.range_m);
    if layout.beam == BeamModel::Ray {
        let extent = GridGeometry::from_config(grid);
        return Some(returns_agreement(&placed, &extent, echo));
    }
    let mut counting = CountingGrid::for_layout(grid.clone(), layout).ok()?;
    for p in &placed {
        counting.insert(p);
    }
    let map = counting.map();
    let field = occupied_distances(&map, map.geometry.resolution_m / FIELD_SUBCELLS, TRUNCATE_M);
    let (mut echoes, mut agree) = (0usize, 0usize);
    for p in &placed {
        let Some(range) = echo(p) else {
            continue;
        };
        let at = p.world_from_sensor;
        let residual = arc(at, range, layout)
            .map(|(x, y)| field.at(x, y))
            .fold(f64::INFINITY, f64::min);
        echoes += 1;
        agree += usize::from(residual < INLIER_M);
    }
    (echoes > 0).then(|| agree as f64 / echoes as f64)
}

/// A laser's returns are scored against those taken at least this long before them, seconds:
/// along a drifting odometry a return agrees with the returns of a few seconds before wherever
/// it is placed, and only a place seen again tells a trajectory that closes its loops from one
/// that does not. Scored against every return of other 10 s stretches, freiburg-079's odometry
/// drifted three ways agreed 96-97% and its corrections 98%, less than the 3 points a correction
/// must gain to be kept; against those of 60 s before, 42-46% and 69% (docs/RESULTS.md).
const FAR_S: f64 = 60.0;

/// [`agreement`] for a laser: the share of the returns (`placed`, in time order, those `echo`
/// keeps) within [`INLIER_M`] of a return taken at least [`FAR_S`] before them.
fn returns_agreement(
    placed: &[PlacedReading],
    extent: &GridGeometry,
    echo: impl Fn(&PlacedReading) -> Option<f64>,
) -> f64 {
    let mut older = ReturnField::over(extent);
    let (mut inserted, mut echoes, mut agree) = (0, 0usize, 0usize);
    for p in placed {
        let Some(range) = echo(p) else {
            continue;
        };
        while inserted < placed.len() && placed[inserted].t_s < p.t_s - FAR_S {
            if echo(&placed[inserted]).is_some() {
                older.add(&placed[inserted]);
            }
            inserted += 1;
        }
        let at = p.world_from_sensor;
        let residual = older
            .field
            .at(at.x + range * at.theta.cos(), at.y + range * at.theta.sin());
        echoes += 1;
        agree += usize::from(residual < INLIER_M);
    }
    if echoes == 0 {
        0.0
    } else {
        agree as f64 / echoes as f64
    }
}

/// The points of an echo's arc at `range` from a sensor at `at`: across the beam's cone every
/// [`ARC_STEP_RAD`] or so, or the one point down a laser's ray.
fn arc(at: Pose2, range: f64, layout: &SonarLayout) -> impl Iterator<Item = (f64, f64)> {
    let half = match layout.beam {
        BeamModel::Cone => 0.5 * layout.cone_rad,
        BeamModel::Ray => 0.0,
    };
    let steps = (half / ARC_STEP_RAD).ceil() as i32;
    (-steps..=steps).map(move |k| {
        let a = at.theta + half * k as f64 / steps.max(1) as f64;
        (at.x + range * a.cos(), at.y + range * a.sin())
    })
}

/// What a scan stamped at `t_s` adds to its match's covariance: the robot's turn and travel (by
/// the odometry, over the second about `t_s`) in [`SCAN_TIME_SIGMA_S`].
fn timing_covariance(odometry: &[StampedPose], t_s: f64) -> Matrix3<f64> {
    let Some((a, b)) = pose_at(odometry, t_s - 0.5).zip(pose_at(odometry, t_s + 0.5)) else {
        return Matrix3::zeros();
    };
    let turn = wrap_angle(b.theta - a.theta) * SCAN_TIME_SIGMA_S;
    let travel = (b.x - a.x).hypot(b.y - a.y) * SCAN_TIME_SIGMA_S;
    Matrix3::from_diagonal(&Vector3::new(travel.powi(2), travel.powi(2), turn.powi(2)))
}

/// The covariance of `pose ∘ delta` from `pose`'s and the odometry's over `delta`.
fn propagated(
    covariance: &Matrix3<f64>,
    pose: Pose2,
    delta: Pose2,
    config: &FuseConfig,
) -> Matrix3<f64> {
    let (f, g) = compose_jacobians(pose.theta, delta.x, delta.y);
    let q = odometry_covariance(
        delta.x.hypot(delta.y),
        wrap_angle(delta.theta).abs(),
        config,
    );
    f * covariance * f.transpose() + g * q * g.transpose()
}

/// A reading placed in the world along the trajectory corrected so far: the correction of the
/// last keyframe at or before it, applied to its odometry pose.
fn placed(
    reading: &SonarReading,
    odometry: &[StampedPose],
    frames: &[Keyframe],
    poses: &[Pose2],
    layout: &SonarLayout,
) -> Option<PlacedReading> {
    let sensor = layout.sensors.get(reading.sensor)?;
    let j = frames[..poses.len()]
        .partition_point(|kf| kf.t_s <= reading.t_s)
        .checked_sub(1)?;
    let correction = poses[j].compose(&frames[j].odom.inverse());
    let odom = pose_at(odometry, reading.t_s)?;
    Some(PlacedReading {
        t_s: reading.t_s,
        world_from_sensor: correction
            .compose(&odom)
            .compose(&sensor.robot_from_sensor()),
        range_m: reading.range_m,
    })
}

/// Each reading's echo arc as points in the frame of the robot at odometry pose `now`.
fn arcs(
    window: &[&SonarReading],
    odometry: &[StampedPose],
    now: Pose2,
    layout: &SonarLayout,
) -> Vec<Vec<(f64, f64)>> {
    window
        .iter()
        .filter_map(|r| {
            let sensor = layout.sensors.get(r.sensor)?;
            let at = now
                .between(&pose_at(odometry, r.t_s)?)
                .compose(&sensor.robot_from_sensor());
            let range = r.range_m?;
            Some(arc(at, range, layout).collect())
        })
        .collect()
}

/// The pose near `predicted` at which the arcs come nearest what `field` tables (the map's
/// occupied cells, or a laser's older returns), and its covariance: each pose of a grid around
/// `predicted` weighed by the likelihood of the ranges' truncated residuals there, the weighted
/// mean and spread (a corridor gives a long covariance along it); `None` when the map has seen
/// too few of the arcs, when too few agree with the mean, or when the match leaves the position
/// unsure in every direction.
fn match_arcs(
    map: &OccupancyMap,
    field: &DistanceField,
    arcs: &[Vec<(f64, f64)>],
    predicted: Pose2,
) -> Option<(Pose2, Matrix3<f64>)> {
    let g = &map.geometry;
    // The arcs that fall where the grid has seen (at the predicted pose).
    let sc = predicted.theta.sin_cos();
    let seen: Vec<&[(f64, f64)]> = arcs
        .iter()
        .filter(|arc| {
            arc.iter().any(|&q| {
                let (x, y) = world(predicted, sc, q);
                g.cell_of(x, y)
                    .is_some_and(|(col, row)| map.occupancy[row * g.width + col].is_some())
            })
        })
        .map(|arc| arc.as_slice())
        .collect();
    match_seen(field, &seen, arcs.len(), predicted)
}

/// A point `(x, y)` in the frame of `pose` (its heading's sine and cosine `sc`), in the world.
fn world(pose: Pose2, (s, c): (f64, f64), (x, y): (f64, f64)) -> (f64, f64) {
    (pose.x + c * x - s * y, pose.y + s * x + c * y)
}

/// A scan is matched with a survey's returns only when this share of its returns lands near
/// them: a scan taken mostly where the survey did not go is pulled onto what little it shares
/// with the map. freiburg-079's second half localised against a survey of its first half,
/// as logged and drifted two ways: 0.32 / 0.15 / 0.80 m with no such share, 0.15 / 0.16 / 0.17 m
/// at a half, 0.10 / 0.13 / 0.12 m at 70% (the whole log against its own survey: the same).
const MIN_SEEN_SHARE: f64 = 0.7;

/// A laser's scan matched with a map of returns: the pose near `predicted` at which `points`
/// (the scan's returns in the robot's frame, every k-th of them, [`WINDOW`] at most) come
/// nearest the returns `field` tables, and its covariance, as the survey matches a scan
/// ([`match_arcs`]); a return that lands nowhere near a tabled one at `predicted` (something
/// the survey did not see) is left out. `None` when fewer than [`MIN_SEEN_SHARE`] are left,
/// too few agree, or the match leaves the position unsure.
///
/// A pose unsure by more than the survey's search ([`REACH_M`], [`REACH_RAD`]) is first searched
/// for over `reach` (metres, radians), in as many steps, with every return; the match is then
/// made around the pose found, and the covariance holds that search's spread too.
pub(crate) fn match_returns(
    field: &SurveyedReturns,
    points: &[(f64, f64)],
    predicted: Pose2,
    reach: (f64, f64),
) -> Option<(Pose2, Matrix3<f64>)> {
    let k = points.len().div_ceil(WINDOW).max(1);
    let scan: Vec<&[(f64, f64)]> = points.iter().step_by(k).map(std::slice::from_ref).collect();
    let (centre, wide_spread) = widened(&field.fine, &scan, predicted, reach);
    let sc = centre.theta.sin_cos();
    let seen: Vec<&[(f64, f64)]> = scan
        .iter()
        .copied()
        .filter(|arc| {
            let (x, y) = world(centre, sc, arc[0]);
            field.fine.at(x, y) < TRUNCATE_M
        })
        .collect();
    if (seen.len() as f64) < MIN_SEEN_SHARE * scan.len() as f64 {
        return None;
    }
    let (pose, covariance) = match_seen(&field.fine, &seen, scan.len(), centre)?;
    Some((pose, covariance + wide_spread))
}

/// Where to centre the search for a pose unsure by `reach` (metres, radians): `predicted` when
/// the survey's search ([`REACH_M`], [`REACH_RAD`]) covers it, else the weighted mean of a search
/// over `reach` in as many steps, with its spread.
fn widened(
    field: &DistanceField,
    arcs: &[&[(f64, f64)]],
    predicted: Pose2,
    reach: (f64, f64),
) -> (Pose2, Matrix3<f64>) {
    if reach.0 <= REACH_M && reach.1 <= REACH_RAD {
        return (predicted, Matrix3::zeros());
    }
    let reach = (reach.0.max(REACH_M), reach.1.max(REACH_RAD));
    let steps = (
        reach.0 / REACH_M * COARSE_STEP.0,
        reach.1 / REACH_RAD * COARSE_STEP.1,
    );
    let (mean, spread) = weighed(predicted, reach, steps, &|p| cost_at(field, arcs, p));
    (offset(predicted, &mean), spread)
}

/// The summed truncated squares of the arcs' residuals at `pose` (each arc's nearest point to
/// what `field` tables), and how many arcs agree there ([`INLIER_M`]).
fn cost_at(field: &DistanceField, arcs: &[&[(f64, f64)]], pose: Pose2) -> (f64, usize) {
    let sc = pose.theta.sin_cos();
    let mut sum = 0.0;
    let mut inliers = 0;
    for arc in arcs {
        let residual = arc
            .iter()
            .map(|&q| {
                let (x, y) = world(pose, sc, q);
                field.at(x, y)
            })
            .fold(f64::INFINITY, f64::min);
        sum += residual.min(TRUNCATE_M).powi(2);
        inliers += usize::from(residual < INLIER_M);
    }
    (sum, inliers)
}

/// [`match_arcs`] over the arcs `seen` of `total`.
fn match_seen(
    field: &DistanceField,
    seen: &[&[(f64, f64)]],
    total: usize,
    predicted: Pose2,
) -> Option<(Pose2, Matrix3<f64>)> {
    if seen.len() < MIN_SEEN {
        tracing::trace!(
            "scan match: {} of {} ranges where the grid has seen",
            seen.len(),
            total
        );
        return None;
    }
    let cost = |pose: Pose2| cost_at(field, seen, pose);
    // Coarse over the whole search, then fine over one coarse step around its mean.
    let (coarse_mean, coarse_spread) = weighed(predicted, (REACH_M, REACH_RAD), COARSE_STEP, &cost);
    let centre = offset(predicted, &coarse_mean);
    let (fine_mean, fine_spread) = weighed(centre, COARSE_STEP, FINE_STEP, &cost);
    let pose = offset(centre, &fine_mean);
    // The coarse spread says how far the ranges let the pose wander; the fine one, and the
    // fine grid's steps, how well they place it.
    let covariance = coarse_spread
        + fine_spread
        + Matrix3::from_diagonal(&Vector3::new(
            FINE_STEP.0.powi(2) / 12.0,
            FINE_STEP.0.powi(2) / 12.0,
            FINE_STEP.1.powi(2) / 12.0,
        ));
    let mean = Vector3::new(
        pose.x - predicted.x,
        pose.y - predicted.y,
        wrap_angle(pose.theta - predicted.theta),
    );
    let (_, inliers) = cost(pose);
    let position = covariance.fixed_view::<2, 2>(0, 0).symmetric_eigenvalues();
    tracing::trace!(
        "scan match: {inliers} of {} inliers, moved {:.3} m {:.2} deg, sigmas {:.3} {:.3} m {:.2} deg",
        seen.len(),
        mean[0].hypot(mean[1]),
        mean[2].to_degrees(),
        position.min().sqrt(),
        position.max().sqrt(),
        covariance[(2, 2)].sqrt().to_degrees()
    );
    (inliers as f64 >= MIN_INLIER_SHARE * seen.len() as f64
        && position.min() < MAX_MATCH_SIGMA_M.powi(2))
    .then_some((pose, covariance))
}

/// `pose` moved by `d` (x, y, heading; in the world frame).
fn offset(pose: Pose2, d: &Vector3<f64>) -> Pose2 {
    Pose2::new(pose.x + d[0], pose.y + d[1], wrap_angle(pose.theta + d[2]))
}

/// The poses of a grid around `centre` (within `reach`, at `step`) weighed by the likelihood of
/// the ranges' residuals there (`cost`: summed truncated squares): the weighted mean offset from
/// `centre` and the weighted spread about it.
fn weighed(
    centre: Pose2,
    reach: (f64, f64),
    step: (f64, f64),
    cost: &(impl Fn(Pose2) -> (f64, usize) + Sync),
) -> (Vector3<f64>, Matrix3<f64>) {
    let scored: Vec<(Vector3<f64>, f64)> = grid(centre, reach, step)
        .into_par_iter()
        .map(|p| {
            let d = Vector3::new(
                p.x - centre.x,
                p.y - centre.y,
                wrap_angle(p.theta - centre.theta),
            );
            (d, cost(p).0)
        })
        .collect();
    let least = scored.iter().map(|s| s.1).fold(f64::INFINITY, f64::min);
    let weights: Vec<f64> = scored
        .iter()
        .map(|(_, c)| (-(c - least) / (2.0 * RANGE_SIGMA_M.powi(2))).exp())
        .collect();
    let total: f64 = weights.iter().sum();
    let mean = scored
        .iter()
        .zip(&weights)
        .map(|((d, _), w)| d * *w)
        .sum::<Vector3<f64>>()
        / total;
    let spread = scored
        .iter()
        .zip(&weights)
        .map(|((d, _), w)| (d - mean) * (d - mean).transpose() * *w)
        .sum::<Matrix3<f64>>()
        / total;
    (mean, spread)
}

/// Poses on a grid around `centre`: positions within `reach.0` and headings within `reach.1`, at
/// `step` (metres, radians); the steps each way rounded to the nearest.
fn grid(centre: Pose2, reach: (f64, f64), step: (f64, f64)) -> Vec<Pose2> {
    let n = |reach: f64, step: f64| (reach / step).round() as i32;
    crate::fusion::wall_fix::pose_grid(centre, (n(reach.0, step.0), n(reach.1, step.1)), step)
}

/// A laser's returns are matched with the older returns on cells this size, metres: 2.5 cm.
const RETURN_CELL_M: f64 = 0.025;

/// Where the older returns of a laser lie: the distance to the nearest cell of
/// [`RETURN_CELL_M`] that holds one (from cell centre to cell centre), capped at
/// [`TRUNCATE_M`], kept up as returns are added. A laser's return is a point, not an arc
/// touching a wall somewhere across a cone: against the counting grid's 20 cm cells, whose
/// centres lie up to 14 cm from the wall points in them, a well-placed scan agreed at a third of
/// its returns, and no scan was ever matched (freiburg-079 as lidar: 0 of 797 keyframes).
struct ReturnField {
    field: DistanceField,
    /// Cells that hold a return, row-major as the field's.
    held: Vec<bool>,
    /// Offsets (columns, rows) within the cap, with their distance.
    kernel: Vec<(i64, i64, f32)>,
}

impl ReturnField {
    /// An empty field over the extent of grid `g`.
    fn over(g: &GridGeometry) -> Self {
        let cols = (g.width as f64 * g.resolution_m / RETURN_CELL_M).ceil() as usize;
        let rows = (g.height as f64 * g.resolution_m / RETURN_CELL_M).ceil() as usize;
        let reach = (TRUNCATE_M / RETURN_CELL_M).ceil() as i64;
        let kernel = (-reach..=reach)
            .flat_map(|r| (-reach..=reach).map(move |c| (c, r)))
            .map(|(c, r)| (c, r, ((c as f64).hypot(r as f64) * RETURN_CELL_M) as f32))
            .filter(|&(_, _, d)| f64::from(d) < TRUNCATE_M)
            .collect();
        let origin = (g.origin_m[0], g.origin_m[1]);
        Self {
            field: DistanceField::capped(origin, RETURN_CELL_M, (cols, rows), TRUNCATE_M),
            held: vec![false; cols * rows],
            kernel,
        }
    }

    /// Adds a reading's return (the point at its range down the ray); one off the table is left
    /// out.
    fn add(&mut self, reading: &PlacedReading) {
        let Some(range) = reading.range_m else {
            return;
        };
        let at = reading.world_from_sensor;
        self.hold(at.x + range * at.theta.cos(), at.y + range * at.theta.sin());
    }

    /// Marks the cell of `(x, y)` as holding a return, and lowers the distances around it.
    fn hold(&mut self, x: f64, y: f64) {
        let f = &mut self.field;
        let c = ((x - f.origin.0) / f.cell_m).floor();
        let r = ((y - f.origin.1) / f.cell_m).floor();
        if !(c >= 0.0 && r >= 0.0 && c < f.cols as f64 && r < f.rows as f64) {
            return;
        }
        let (c, r) = (c as i64, r as i64);
        let cell = r as usize * f.cols + c as usize;
        if std::mem::replace(&mut self.held[cell], true) {
            return;
        }
        for &(dc, dr, d) in &self.kernel {
            let (cc, rr) = (c + dc, r + dr);
            if cc >= 0 && rr >= 0 && (cc as usize) < f.cols && (rr as usize) < f.rows {
                let at = &mut f.d[rr as usize * f.cols + cc as usize];
                *at = at.min(d);
            }
        }
    }
}

/// A survey's laser returns (`returns_corrected.pgm`, [`crate::sonar::grid::returns_map`]) as
/// [`match_returns`] matches a later run's scans with them: the distance to the nearest
/// occupied cell's centre, tabled on thirds of the map's cells (an odd split: a cell's centre
/// lies inside a table cell, not on the edge between two, which would move every return half a
/// table cell one way).
///
/// For finding a scan anywhere in the map ([`locate_scan`]) the distances are also tabled on
/// cells of [`LOCATE_CELL_M`] up to [`LOCATE_CAP_M`], and the occupied cells' extent is kept.
#[derive(Debug, Clone)]
pub(crate) struct SurveyedReturns {
    fine: DistanceField,
    coarse: DistanceField,
    /// The occupied cells' centres' extent, lower and upper corners (metres).
    extent: ([f64; 2], [f64; 2]),
}

impl SurveyedReturns {
    /// The returns `map` holds.
    pub(crate) fn of_map(map: &OccupancyMap) -> Self {
        let g = &map.geometry;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for idx in (0..map.occupancy.len()).filter(|&i| map.is_occupied(i)) {
            let [x, y] = g.centre(idx % g.width, idx / g.width);
            (lo, hi) = ([lo[0].min(x), lo[1].min(y)], [hi[0].max(x), hi[1].max(y)]);
        }
        Self {
            fine: occupied_distances(map, g.resolution_m / RETURNS_SUBCELLS, TRUNCATE_M),
            coarse: occupied_distances(map, LOCATE_CELL_M, LOCATE_CAP_M),
            extent: (lo, hi),
        }
    }
}

/// See [`SurveyedReturns`].
const RETURNS_SUBCELLS: f64 = 3.0;

/// [`locate_scan`]'s coarse table: cells of 10 cm, distances up to 0.5 m (a pose on its search's
/// grid, up to 0.18 m and 1.5 degrees from the true one, still scores near it).
const LOCATE_CELL_M: f64 = 0.1;
const LOCATE_CAP_M: f64 = 0.5;
/// [`locate_scan`]'s search grid: positions 0.25 m apart, headings 3 degrees apart.
const LOCATE_STEP: (f64, f64) = (0.25, 3.0 * std::f64::consts::PI / 180.0);
/// A position is not tried this near a surveyed return (the robot stands clear of walls), metres.
const LOCATE_CLEARANCE_M: f64 = 0.2;
/// The poses of the search grid refined by matching, the best-scoring.
const LOCATE_CANDIDATES: usize = 40;
/// A scan is located when this share of its returns agree at the pose found ([`INLIER_M`]) and
/// no pose further than [`LOCATE_DISTINCT`] (metres, radians) away explains it within
/// [`LOCATE_MARGIN`] of that share.
const LOCATE_MIN_SHARE: f64 = 0.7;
const LOCATE_DISTINCT: (f64, f64) = (1.0, 0.35);
const LOCATE_MARGIN: f64 = 0.15;

/// Where in the survey's map a scan (`points`, its returns in the robot's frame) was taken, with
/// no prior: every pose of a grid over the map's extent ([`LOCATE_STEP`]) clear of its returns is
/// scored on the coarse table, the [`LOCATE_CANDIDATES`] best are matched as [`match_returns`]
/// matches, and the best match is taken when enough of the scan agrees there and no distinct
/// pose explains it nearly as well (a corridor's repeating doors, a building's twin rooms);
/// `None` otherwise.
pub(crate) fn locate_scan(
    returns: &SurveyedReturns,
    points: &[(f64, f64)],
) -> Option<(Pose2, Matrix3<f64>)> {
    let k = points.len().div_ceil(LOCATE_POINTS).max(1);
    let sample: Vec<(f64, f64)> = points.iter().step_by(k).copied().collect();
    if sample.len() < MIN_SEEN {
        return None;
    }
    let (lo, hi) = returns.extent;
    let (nx, ny) = (
        ((hi[0] - lo[0]) / LOCATE_STEP.0).ceil() as usize + 1,
        ((hi[1] - lo[1]) / LOCATE_STEP.0).ceil() as usize + 1,
    );
    let headings: Vec<(f64, (f64, f64))> = (0..(std::f64::consts::TAU / LOCATE_STEP.1).round()
        as usize)
        .map(|h| {
            let theta = wrap_angle(h as f64 * LOCATE_STEP.1);
            (theta, theta.sin_cos())
        })
        .collect();
    // Each position's best heading and its cost on the coarse table.
    let mut scored: Vec<(f64, Pose2)> = (0..nx * ny)
        .into_par_iter()
        .filter_map(|i| {
            let x = lo[0] + (i % nx) as f64 * LOCATE_STEP.0;
            let y = lo[1] + (i / nx) as f64 * LOCATE_STEP.0;
            if returns.coarse.at(x, y) < LOCATE_CLEARANCE_M {
                return None;
            }
            headings
                .iter()
                .map(|&(theta, sc)| {
                    let pose = Pose2::new(x, y, theta);
                    let cost: f64 = sample
                        .iter()
                        .map(|&q| {
                            let (wx, wy) = world(pose, sc, q);
                            returns.coarse.at(wx, wy).powi(2)
                        })
                        .sum();
                    (cost, pose)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
        })
        .collect();
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let reach = (LOCATE_STEP.0, 2.0 * LOCATE_STEP.1);
    let arcs: Vec<&[(f64, f64)]> = sample.iter().map(std::slice::from_ref).collect();
    let mut matched: Vec<(usize, Pose2, Matrix3<f64>)> = scored
        .iter()
        .take(LOCATE_CANDIDATES)
        .collect::<Vec<_>>()
        .into_par_iter()
        .filter_map(|&(_, start)| {
            let (pose, covariance) = match_returns(returns, &sample, start, reach)?;
            let (_, inliers) = cost_at(&returns.fine, &arcs, pose);
            Some((inliers, pose, covariance))
        })
        .collect();
    matched.sort_by_key(|m| std::cmp::Reverse(m.0));
    let &(best, pose, covariance) = matched.first()?;
    let n = sample.len() as f64;
    let rival = matched.iter().find(|(_, p, _)| {
        (p.x - pose.x).hypot(p.y - pose.y) > LOCATE_DISTINCT.0
            || wrap_angle(p.theta - pose.theta).abs() > LOCATE_DISTINCT.1
    });
    tracing::debug!(
        "scans looked up in the whole map: at best ({:.2}, {:.2}, {:.1} deg), {best} of {} returns agree; the best distinct pose {}",
        pose.x,
        pose.y,
        pose.theta.to_degrees(),
        sample.len(),
        rival.map_or("none".to_string(), |r| format!(
            "({:.2}, {:.2}, {:.1} deg) {}",
            r.1.x,
            r.1.y,
            r.1.theta.to_degrees(),
            r.0
        ))
    );
    let clear = rival.is_none_or(|r| (r.0 as f64) < best as f64 - LOCATE_MARGIN * n);
    (best as f64 >= LOCATE_MIN_SHARE * n && clear).then_some((pose, covariance))
}

/// [`locate_scan`] scores this many of a scan's returns at most.
const LOCATE_POINTS: usize = 96;

/// Distance to the nearest occupied cell's centre of `map`, tabled on cells of `cell_m` over the
/// map's extent and capped at `cap`.
fn occupied_distances(map: &OccupancyMap, cell_m: f64, cap: f64) -> DistanceField {
    let g = &map.geometry;
    let cells = |n: usize| (n as f64 * g.resolution_m / cell_m - 1e-6).ceil() as usize;
    let (cols, rows) = (cells(g.width), cells(g.height));
    let origin = (g.origin_m[0], g.origin_m[1]);
    let mut field = DistanceField::capped(origin, cell_m, (cols, rows), cap);
    let reach = (cap / cell_m).ceil() as i64;
    for idx in (0..map.occupancy.len()).filter(|&i| map.is_occupied(i)) {
        let centre = g.centre(idx % g.width, idx / g.width);
        let c0 = ((centre[0] - origin.0) / cell_m).floor() as i64;
        let r0 = ((centre[1] - origin.1) / cell_m).floor() as i64;
        for r in (r0 - reach).max(0)..(r0 + reach + 1).min(rows as i64) {
            for c in (c0 - reach).max(0)..(c0 + reach + 1).min(cols as i64) {
                let x = origin.0 + (c as f64 + 0.5) * cell_m;
                let y = origin.1 + (r as f64 + 0.5) * cell_m;
                let cell = &mut field.d[r as usize * cols + c as usize];
                *cell = cell.min((x - centre[0]).hypot(y - centre[1]) as f32);
            }
        }
    }
    field
}
