//! The camera's planar mounting error from the sightings and the odometry alone, before any
//! filter runs: a hand-eye calibration over short stretches of the run. Within a stretch of a
//! few metres the odometry is good to a centimetre or two, so each tag seen several times in it
//! must come out at one place; a mounting error moves it as the robot turns and drives (its
//! offset turns with the robot, its yaw swings the tag about the camera as the range changes).
//! The filters gate sightings against each other: a mounting 5 degrees off puts a tag 4 m away
//! 35 cm off and breaks them, so the error is found and taken out first; the offline graph then
//! refines what is left ([`crate::fusion::FuseConfig::estimate_mounting`]).

use super::factors::{sqrt_information, BetweenFactor, PriorFactor, TagFactor};
use super::graph::{CALIBRATION_PRIOR_SIGMA, MOUNTING_PRIOR_SIGMA};
use super::MountingEstimate;
use crate::fusion::measurement::{odometry_covariance, sighting_measurement};
use crate::fusion::FuseConfig;
use crate::geometry::{pose_at, wrap_angle, Pose2, StampedPose};
use crate::visual::sightings::TagSighting;
use std::collections::{BTreeMap, HashMap};
use tiny_solver::na as sna;

/// A stretch of one tag's sightings ends where the odometry has run this far since its first:
/// 3 m (the simulated wheels drift about 1.5 cm over it, below a sighting's own noise at range).
pub const MOUNTING_STRETCH_M: f64 = 3.0;

/// The mounting error `m` (the tag at `m ∘ z` from the robot for a sighting `z`) that makes each
/// tag's sightings agree within every stretch of [`MOUNTING_STRETCH_M`] of odometry, with its
/// marginal covariance; `None` when no tag is seen twice in a stretch or the solve fails.
pub fn estimate_mounting(
    odometry: &[StampedPose],
    sightings: &[TagSighting],
    config: &FuseConfig,
) -> Option<MountingEstimate> {
    let stretches = stretches(odometry, sightings);
    if stretches.is_empty() {
        return None;
    }
    let mut problem = tiny_solver::Problem::new();
    let mut init: HashMap<String, sna::DVector<f64>> = HashMap::new();
    init.insert("m".into(), sna::DVector::zeros(3));
    let prior = PriorFactor {
        measured: vec![0.0; 3],
        sqrt_info: MOUNTING_PRIOR_SIGMA.iter().map(|s| 1.0 / s).collect(),
    };
    problem.add_residual_block(3, &["m"], Box::new(prior), None);
    // The odometry's systematic errors (a turn scale error of 1% is 3.6 degrees over a turn on
    // the spot between two sightings of a tag, which the mounting's yaw would otherwise take).
    init.insert("c".into(), sna::DVector::zeros(3));
    let prior = PriorFactor {
        measured: vec![0.0; 3],
        sqrt_info: CALIBRATION_PRIOR_SIGMA.iter().map(|s| 1.0 / s).collect(),
    };
    problem.add_residual_block(3, &["c"], Box::new(prior), None);
    for (w, members) in stretches.iter().enumerate() {
        let tag = format!("t{w}");
        for (i, &(k, pose)) in members.iter().enumerate() {
            let (z, r) = sighting_measurement(&sightings[k], config);
            let name = format!("p{k}");
            init.insert(
                name.clone(),
                sna::DVector::from_vec(vec![pose.x, pose.y, pose.theta]),
            );
            if i == 0 {
                // The stretch's frame: its first pose.
                for j in 0..3 {
                    problem.fix_variable(&name, j);
                }
            } else {
                let before = members[i - 1].0;
                let odometry_factor =
                    between(odometry, sightings[before].t_s, sightings[k].t_s, config);
                let previous = format!("p{before}");
                problem.add_residual_block(
                    3,
                    &[&previous, &name, "c"],
                    Box::new(odometry_factor),
                    None,
                );
            }
            let factor = TagFactor {
                measured: [z.x, z.y, z.z],
                sqrt_info: sqrt_information(&r),
            };
            let loss = tiny_solver::loss_functions::HuberLoss::new(config.huber_sigma.max(1e-3));
            problem.add_residual_block(
                3,
                &[&name, &tag, "m"],
                Box::new(factor),
                Some(Box::new(loss)),
            );
        }
        // The tag where its first sighting puts it.
        let (k, pose) = members[0];
        let s = &sightings[k];
        let at = pose.compose(&Pose2::new(
            s.position_in_robot_m[0],
            s.position_in_robot_m[1],
            s.yaw_in_robot_rad,
        ));
        init.insert(tag, sna::DVector::from_vec(vec![at.x, at.y, at.theta]));
    }
    use tiny_solver::Optimizer;
    let values = tiny_solver::LevenbergMarquardtOptimizer::default().optimize(
        &problem,
        &init,
        Some(tiny_solver::OptimizerOptions {
            max_iteration: config.max_iterations,
            ..Default::default()
        }),
    )?;
    let m = values.get("m")?;
    let estimate = MountingEstimate {
        correction: Pose2::new(m[0], m[1], wrap_angle(m[2])),
        covariance: super::graph::marginal_covariance(&problem, &values, "m", 3)
            .map(|c| nalgebra::Matrix3::from_fn(|r, k| c[(r, k)])),
    };
    tracing::info!(
        "mounting from {} stretches of sightings: x {:+.4} m, y {:+.4} m, yaw {:+.3} degrees",
        stretches.len(),
        estimate.correction.x,
        estimate.correction.y,
        estimate.correction.theta.to_degrees()
    );
    Some(estimate)
}

/// The odometry between times `a` and `b` as a between-factor, its path and turn summed over the
/// samples between them.
fn between(odometry: &[StampedPose], a: f64, b: f64, config: &FuseConfig) -> BetweenFactor {
    let (pa, pb) = (
        pose_at(odometry, a).unwrap_or(Pose2::new(0.0, 0.0, 0.0)),
        pose_at(odometry, b).unwrap_or(Pose2::new(0.0, 0.0, 0.0)),
    );
    let (mut path, mut turn, mut signed) = (0.0, 0.0, 0.0);
    let mut previous = pa;
    let inside = odometry
        .iter()
        .filter(|p| p.t_s > a && p.t_s < b)
        .map(|p| p.pose);
    for pose in inside.chain(std::iter::once(pb)) {
        let d = previous.between(&pose);
        path += d.x.hypot(d.y);
        turn += wrap_angle(d.theta).abs();
        signed += wrap_angle(d.theta);
        previous = pose;
    }
    let delta = pa.between(&pb);
    BetweenFactor {
        measured: [delta.x, delta.y, wrap_angle(delta.theta)],
        sqrt_info: sqrt_information(&odometry_covariance(path, turn, config)),
        turn_rad: signed,
        path_m: path,
    }
}

/// Each tag's sightings cut into stretches of [`MOUNTING_STRETCH_M`] of odometry, with the
/// odometry pose of each; only stretches of two sightings or more.
fn stretches(odometry: &[StampedPose], sightings: &[TagSighting]) -> Vec<Vec<(usize, Pose2)>> {
    let travelled = crate::geometry::distance_travelled(odometry);
    let distance_at = |t: f64| {
        let i = odometry
            .partition_point(|p| p.t_s < t)
            .min(odometry.len().saturating_sub(1));
        travelled.get(i).copied().unwrap_or(0.0)
    };
    let mut by_tag: BTreeMap<_, Vec<(usize, Pose2, f64)>> = BTreeMap::new();
    for (k, s) in sightings.iter().enumerate() {
        if let Some(pose) = pose_at(odometry, s.t_s) {
            by_tag
                .entry(s.key())
                .or_default()
                .push((k, pose, distance_at(s.t_s)));
        }
    }
    let mut out = Vec::new();
    for seen in by_tag.values() {
        let mut current: Vec<(usize, Pose2)> = Vec::new();
        let mut from = f64::NEG_INFINITY;
        for &(k, pose, d) in seen {
            if d - from > MOUNTING_STRETCH_M {
                if current.len() >= 2 {
                    out.push(std::mem::take(&mut current));
                }
                current.clear();
                from = d;
            }
            current.push((k, pose));
        }
        if current.len() >= 2 {
            out.push(current);
        }
    }
    out
}
