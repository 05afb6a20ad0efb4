//! The offline pass (the method's a-posteriori correction): a pose graph over keyframes of the
//! whole run, solved by Levenberg-Marquardt, its keyframe corrections interpolated along the
//! odometry.

mod factors;

use crate::fusion::measurement::odometry_covariance;
use crate::fusion::measurement::sighting_measurement;
use crate::fusion::{FuseConfig, Landmark, OnlineResult};
use crate::geometry::{pose_at, wrap_angle, Pose2, StampedPose};
use crate::visual::sightings::TagSighting;
use crate::visual::tags::TagId;
use crate::visual::vo::VisualTurn;
use factors::{
    corrected_increment, sqrt_information, BetweenFactor, PriorFactor, TagFactor, TurnFactor,
};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use tiny_solver::na as sna;

/// The result of the offline pass.
#[derive(Debug, Clone)]
pub struct OfflineResult {
    /// Corrected pose at each odometry time.
    pub trajectory: Vec<StampedPose>,
    /// Landmarks from the graph (covariances from the online filter).
    pub landmarks: Vec<Landmark>,
    /// Keyframes of the graph.
    pub keyframes: usize,
    /// Factors of the graph.
    pub factors: usize,
    /// Whether the solver returned a solution (else the online estimate is kept).
    pub converged: bool,
    /// The odometry calibration found, when estimated and the solver converged.
    pub odometry_calibration: Option<OdometryCalibration>,
}

/// Systematic odometry errors as the offline pass estimates them: an odometry increment of
/// signed turn `dθ` over a path `ds` truly turned `dθ (1 + turn_scale_error) +
/// heading_drift_rad_per_m ds` and travelled `ds (1 + distance_scale_error)`. The same robot's
/// later runs can be corrected with it ([`OdometryCalibration::apply`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OdometryCalibration {
    /// Relative error of the turns (a wheel base off by 1% gives about 0.01).
    pub turn_scale_error: f64,
    /// Heading drift per metre travelled, radians (unequal wheel scales).
    pub heading_drift_rad_per_m: f64,
    /// Relative error of the distances.
    pub distance_scale_error: f64,
}

impl OdometryCalibration {
    /// An odometry increment `delta` (in the frame of its start) over `path_m` with signed turn
    /// `turn_rad`, corrected: the turn scaled and drift added, the translation turned by half the
    /// extra turn and scaled (the offline pass's own model of an interval).
    pub fn correct(&self, delta: Pose2, turn_rad: f64, path_m: f64) -> Pose2 {
        let [x, y, theta] = corrected_increment(
            [
                self.turn_scale_error,
                self.heading_drift_rad_per_m,
                self.distance_scale_error,
            ],
            [delta.x, delta.y, delta.theta],
            turn_rad,
            path_m,
        );
        Pose2::new(x, y, theta)
    }

    /// A whole odometry log corrected increment by increment, from the same first pose.
    pub fn apply(&self, odometry: &[StampedPose]) -> Vec<StampedPose> {
        let Some(first) = odometry.first() else {
            return Vec::new();
        };
        let mut pose = first.pose;
        let mut out = vec![*first];
        for w in odometry.windows(2) {
            let d = w[0].pose.between(&w[1].pose);
            let step = Pose2::new(d.x, d.y, wrap_angle(d.theta));
            pose = pose.compose(&self.correct(step, step.theta, d.x.hypot(d.y)));
            out.push(StampedPose {
                t_s: w[1].t_s,
                pose,
            });
        }
        out
    }
}

/// Name of the odometry calibration variable of the offline graph.
const CALIBRATION: &str = "odometry_calibration";
/// Prior sigmas of the odometry calibration `[a, c, s]`: 5% turn scale, 0.02 rad/m heading drift,
/// 2% distance scale (weak: wheel errors of a few percent at most).
const CALIBRATION_PRIOR_SIGMA: [f64; 3] = [0.05, 0.02, 0.02];

/// One keyframe: the time, the odometry pose and the starting estimate.
struct Keyframe {
    t_s: f64,
    odom: Pose2,
    init: Pose2,
}

/// The method's a-posteriori pass: a pose graph over the whole run, started from `online`, with
/// the turns the cameras measured (`visual`) beside the odometry.
pub fn run_offline(
    odometry: &[StampedPose],
    visual: &[VisualTurn],
    sightings: &[TagSighting],
    online: &OnlineResult,
    config: &FuseConfig,
) -> OfflineResult {
    run_offline_with_prior(odometry, visual, sightings, online, config, None)
}

/// Prior sigmas of the odometry calibration when an earlier survey of the same robot gives it:
/// about what one survey's estimate scatters by (turn scale 0.0066-0.0106 for 0.0100 over the
/// office's and museum's sample runs, heading drift -0.0059 to -0.0082 for -0.0067 rad/m).
const CALIBRATION_FROM_SURVEY_SIGMA: [f64; 3] = [0.004, 0.002, 0.004];

/// [`run_offline`] with the odometry calibration's prior centred on `prior` (an earlier survey's)
/// instead of on no error.
pub(crate) fn run_offline_with_prior(
    odometry: &[StampedPose],
    visual: &[VisualTurn],
    sightings: &[TagSighting],
    online: &OnlineResult,
    config: &FuseConfig,
    prior: Option<&OdometryCalibration>,
) -> OfflineResult {
    let Some(first) = odometry.first() else {
        return OfflineResult {
            trajectory: Vec::new(),
            landmarks: online.landmarks.clone(),
            keyframes: 0,
            factors: 0,
            converged: false,
            odometry_calibration: None,
        };
    };
    // Keyframes: the odometry thinned by travel and turn, plus one at every fused sighting and at
    // both ends of every visual turn within the odometry.
    let end_t = odometry.last().map_or(first.t_s, |p| p.t_s);
    let visual: Vec<&VisualTurn> = visual
        .iter()
        .filter(|v| config.visual_odometry && v.from_t_s >= first.t_s && v.to_t_s <= end_t)
        .collect();
    let mut anchors: Vec<(f64, Option<usize>)> = online
        .accepted
        .iter()
        .map(|&k| (sightings[k].t_s, Some(k)))
        .chain(
            visual
                .iter()
                .flat_map(|v| [(v.from_t_s, None), (v.to_t_s, None)]),
        )
        .collect();
    anchors.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut keyframes: Vec<Keyframe> = Vec::new();
    // Ordered: the tag factors go into the graph in the order of the sightings, so that the
    // solution does not depend on a hash order (it did in its last digits).
    let mut sighting_kf: BTreeMap<usize, usize> = BTreeMap::new();
    let mut time_kf: HashMap<u64, usize> = HashMap::new();
    let mut anchors = anchors.into_iter().peekable();
    let mut last_kf = first.pose;
    for (i, sample) in odometry.iter().enumerate() {
        while let Some(&(t, sighting)) = anchors.peek() {
            if t > sample.t_s && i + 1 < odometry.len() {
                break;
            }
            anchors.next();
            let odom = pose_at(odometry, t).unwrap_or(sample.pose);
            let same = keyframes.last().is_some_and(|kf| (kf.t_s - t).abs() < 1e-9);
            if !same {
                let init = match sighting {
                    Some(k) => online.pose_at_sighting[k],
                    None => pose_at(&online.trajectory, t).unwrap_or(odom),
                };
                keyframes.push(Keyframe { t_s: t, odom, init });
                last_kf = odom;
            }
            let kf = keyframes.len() - 1;
            time_kf.insert(t.to_bits(), kf);
            if let Some(k) = sighting {
                sighting_kf.insert(k, kf);
            }
        }
        let d = last_kf.between(&sample.pose);
        let is_end = i == 0 || i + 1 == odometry.len();
        if is_end
            || d.x.hypot(d.y) >= config.keyframe_spacing_m
            || wrap_angle(d.theta).abs() >= config.keyframe_turn_rad
        {
            if keyframes.last().is_some_and(|kf| kf.t_s >= sample.t_s) {
                continue;
            }
            keyframes.push(Keyframe {
                t_s: sample.t_s,
                odom: sample.pose,
                init: online.trajectory.get(i).map_or(sample.pose, |p| p.pose),
            });
            last_kf = sample.pose;
        }
    }

    let pose_name = |i: usize| format!("p{i}");
    let landmark_name = |i: usize| format!("l{i}");
    let mut problem = tiny_solver::Problem::new();
    let mut init: HashMap<String, sna::DVector<f64>> = HashMap::new();
    for (i, kf) in keyframes.iter().enumerate() {
        init.insert(
            pose_name(i),
            sna::DVector::from_vec(vec![kf.init.x, kf.init.y, kf.init.theta]),
        );
    }
    for (i, l) in online.landmarks.iter().enumerate() {
        init.insert(
            landmark_name(i),
            sna::DVector::from_vec(vec![l.position_m[0], l.position_m[1], l.yaw_rad]),
        );
    }
    let mut factors = 0;
    if config.calibrate_odometry {
        let (mean, sigma) = match prior {
            Some(c) => (
                vec![
                    c.turn_scale_error,
                    c.heading_drift_rad_per_m,
                    c.distance_scale_error,
                ],
                CALIBRATION_FROM_SURVEY_SIGMA,
            ),
            None => (vec![0.0; 3], CALIBRATION_PRIOR_SIGMA),
        };
        init.insert(CALIBRATION.into(), sna::DVector::from_vec(mean.clone()));
        problem.add_residual_block(
            3,
            &[CALIBRATION],
            Box::new(PriorFactor {
                measured: mean,
                sqrt_info: sigma.iter().map(|s| 1.0 / s).collect(),
            }),
            None,
        );
        factors += 1;
    }
    problem.add_residual_block(
        3,
        &[&pose_name(0)],
        Box::new(PriorFactor {
            measured: vec![first.pose.x, first.pose.y, first.pose.theta],
            sqrt_info: vec![1e3; 3],
        }),
        None,
    );
    factors += 1;
    // Odometry factors; path and turn summed over the samples between the keyframes.
    let mut sample = 0;
    for i in 1..keyframes.len() {
        let (a, b) = (&keyframes[i - 1], &keyframes[i]);
        let mut path = 0.0;
        let mut turn = 0.0;
        let mut signed_turn = 0.0;
        let mut prev = a.odom;
        while sample < odometry.len() && odometry[sample].t_s <= a.t_s {
            sample += 1;
        }
        let mut j = sample;
        while j < odometry.len() && odometry[j].t_s < b.t_s {
            let d = prev.between(&odometry[j].pose);
            path += d.x.hypot(d.y);
            turn += wrap_angle(d.theta).abs();
            signed_turn += wrap_angle(d.theta);
            prev = odometry[j].pose;
            j += 1;
        }
        let d = prev.between(&b.odom);
        path += d.x.hypot(d.y);
        turn += wrap_angle(d.theta).abs();
        signed_turn += wrap_angle(d.theta);
        let delta = a.odom.between(&b.odom);
        let cov = odometry_covariance(path, turn, config);
        let (p0, p1) = (pose_name(i - 1), pose_name(i));
        let mut vars: Vec<&str> = vec![&p0, &p1];
        if config.calibrate_odometry {
            vars.push(CALIBRATION);
        }
        problem.add_residual_block(
            3,
            &vars,
            Box::new(BetweenFactor {
                measured: [delta.x, delta.y, wrap_angle(delta.theta)],
                sqrt_info: sqrt_information(&cov),
                turn_rad: signed_turn,
                path_m: path,
            }),
            None,
        );
        factors += 1;
    }
    let slot_of: BTreeMap<TagId, usize> = online
        .landmarks
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let tag = TagId {
                family: l.family,
                id: l.id,
            };
            (tag, i)
        })
        .collect();
    for (&k, &kf) in &sighting_kf {
        let s = &sightings[k];
        let Some(&l) = slot_of.get(&s.key()) else {
            continue;
        };
        let (z, r) = sighting_measurement(s, config);
        problem.add_residual_block(
            3,
            &[&pose_name(kf), &landmark_name(l)],
            Box::new(TagFactor {
                measured: [z.x, z.y, z.z],
                sqrt_info: sqrt_information(&r),
            }),
            Some(Box::new(tiny_solver::loss_functions::HuberLoss::new(
                config.huber_sigma.max(1e-3),
            ))),
        );
        factors += 1;
    }
    for v in &visual {
        let (Some(&a), Some(&b)) = (
            time_kf.get(&v.from_t_s.to_bits()),
            time_kf.get(&v.to_t_s.to_bits()),
        ) else {
            continue;
        };
        if a == b {
            continue;
        }
        problem.add_residual_block(
            1,
            &[&pose_name(a), &pose_name(b)],
            Box::new(TurnFactor {
                measured: v.turn_rad,
                sqrt_info: 1.0 / v.sigma_rad.max(1e-6),
            }),
            Some(Box::new(tiny_solver::loss_functions::HuberLoss::new(
                config.huber_sigma.max(1e-3),
            ))),
        );
        factors += 1;
    }
    if config.corner_factors {
        for (i, l) in online.landmarks.iter().enumerate() {
            if let Some(c) = l.matched_corner {
                problem.add_residual_block(
                    2,
                    &[&landmark_name(i)],
                    Box::new(PriorFactor {
                        measured: vec![c.x_m, c.y_m],
                        sqrt_info: vec![1.0 / config.corner_sigma_m; 2],
                    }),
                    None,
                );
                factors += 1;
            }
        }
    }
    let options = tiny_solver::OptimizerOptions {
        max_iteration: config.max_iterations,
        ..Default::default()
    };
    use tiny_solver::Optimizer;
    let solution = tiny_solver::LevenbergMarquardtOptimizer::default().optimize(
        &problem,
        &init,
        Some(options),
    );
    let converged = solution.is_some();
    let values = solution.unwrap_or(init);
    let kf_pose = |i: usize| {
        values.get(&pose_name(i)).map_or(keyframes[i].init, |v| {
            Pose2::new(v[0], v[1], wrap_angle(v[2]))
        })
    };
    // Every odometry sample: the keyframe corrections (world_from_odometry) interpolated by
    // distance travelled between the keyframes around it.
    let corrections: Vec<Pose2> = (0..keyframes.len())
        .map(|i| kf_pose(i).compose(&keyframes[i].odom.inverse()))
        .collect();
    let mut trajectory = Vec::with_capacity(odometry.len());
    let mut kf = 0;
    for sample in odometry {
        while kf + 1 < keyframes.len() && keyframes[kf + 1].t_s < sample.t_s {
            kf += 1;
        }
        let correction = if kf + 1 < keyframes.len() && sample.t_s >= keyframes[kf].t_s {
            let (a, b) = (&keyframes[kf], &keyframes[kf + 1]);
            let span = a
                .odom
                .position()
                .coords
                .metric_distance(&b.odom.position().coords);
            let done = a
                .odom
                .position()
                .coords
                .metric_distance(&sample.pose.position().coords);
            let f = if span > 1e-9 {
                (done / span).clamp(0.0, 1.0)
            } else {
                ((sample.t_s - a.t_s) / (b.t_s - a.t_s).max(1e-9)).clamp(0.0, 1.0)
            };
            corrections[kf].lerp(&corrections[kf + 1], f)
        } else {
            corrections[kf.min(corrections.len() - 1)]
        };
        let pose = correction.compose(&sample.pose);
        trajectory.push(StampedPose {
            t_s: sample.t_s,
            pose: Pose2::new(pose.x, pose.y, wrap_angle(pose.theta)),
        });
    }
    let landmarks = online
        .landmarks
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let mut l = l.clone();
            if let Some(v) = values.get(&landmark_name(i)) {
                l.position_m[0] = v[0];
                l.position_m[1] = v[1];
                l.yaw_rad = wrap_angle(v[2]);
            }
            l
        })
        .collect();
    OfflineResult {
        trajectory,
        landmarks,
        keyframes: keyframes.len(),
        factors,
        converged,
        odometry_calibration: values
            .get(CALIBRATION)
            .filter(|_| converged && config.calibrate_odometry)
            .map(|v| OdometryCalibration {
                turn_scale_error: v[0],
                heading_drift_rad_per_m: v[1],
                distance_scale_error: v[2],
            }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::testing::{square_run, turns_of};
    use crate::fusion::{run_online, run_online_calibrated};
    use crate::metrics::ate_m;

    /// The calibration model matches the wheels: the office simulated with the default wheel
    /// errors and no random noise (wheel base 1% long: turns scaled by 1.01; wheels -0.1% and
    /// +0.1%: 2 x 0.001 / 0.3 m = 0.00667 rad of false turn per metre), corrected with those
    /// values, follows the truth.
    #[test]
    fn the_calibration_undoes_the_wheels_errors() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let world = crate::io::load_world(&root.join("samples/office/world.yaml"))
            .unwrap()
            .world;
        let mut config = crate::sim::SimConfig::default();
        config.odometry.random_m_per_sqrt_m = 0.0;
        config.exploration.duration_s = 300.0;
        let run = crate::sim::simulate(&world, &config, |_| {}).unwrap().run;
        let truth = run.ground_truth.as_deref().unwrap();
        let calibration = OdometryCalibration {
            turn_scale_error: config.odometry.wheel_base_error,
            heading_drift_rad_per_m: (config.odometry.left_scale_error
                - config.odometry.right_scale_error)
                / config.exploration.wheel_base_m,
            distance_scale_error: 0.0,
        };
        let raw = ate_m(&run.odometry, truth).unwrap();
        let corrected = ate_m(&calibration.apply(&run.odometry), truth).unwrap();
        assert!(raw > 0.1, "raw odometry ATE {raw}");
        assert!(corrected < 0.02, "corrected {corrected} (raw {raw})");
        // A calibration of nothing changes nothing.
        let none = OdometryCalibration {
            turn_scale_error: 0.0,
            heading_drift_rad_per_m: 0.0,
            distance_scale_error: 0.0,
        };
        assert!((ate_m(&none.apply(&run.odometry), truth).unwrap() - raw).abs() < 1e-9);
    }

    /// The cameras' turns keep the heading where no tag is seen: two laps of a square with 1%
    /// wheel errors and no sighting at all, online and offline.
    #[test]
    fn visual_turns_hold_the_heading_without_a_tag() {
        let (odom, truth, _, _) = square_run(0.01, 2);
        let turns = turns_of(&truth, 5, 0.001);
        let config = FuseConfig::default();
        let online = run_online_calibrated(&odom, &turns, &[], &[], &config, None);
        let offline = run_offline(&odom, &turns, &[], &online, &config);
        let raw = ate_m(&odom, &truth).unwrap();
        let on = ate_m(&online.trajectory, &truth).unwrap();
        let off = ate_m(&offline.trajectory, &truth).unwrap();
        assert_eq!(online.visual_fused, turns.len());
        assert!(
            on < 0.2 * raw && off < 0.2 * raw,
            "odometry {raw}, online {on}, offline {off}"
        );
        // Without them (or with the setting off) the heading walks with the wheels.
        let off_config = FuseConfig {
            visual_odometry: false,
            ..config
        };
        let blind = run_online_calibrated(&odom, &turns, &[], &[], &off_config, None);
        assert_eq!(blind.visual_fused, 0);
        assert!(ate_m(&blind.trajectory, &truth).unwrap() > 0.5 * raw);
    }

    #[test]
    fn online_and_offline_beat_odometry_on_a_biased_loop() {
        let (odom, truth, sightings, tags) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let online = run_online(&odom, &sightings, &[], &config);
        let offline = run_offline(&odom, &[], &sightings, &online, &config);
        let ate_odom = ate_m(&odom, &truth).unwrap();
        let ate_online = ate_m(&online.trajectory, &truth).unwrap();
        let ate_offline = ate_m(&offline.trajectory, &truth).unwrap();
        assert!(offline.converged);
        assert!(ate_odom > 0.2, "odometry ATE {ate_odom}");
        assert!(
            ate_online < 0.5 * ate_odom,
            "online {ate_online} odometry {ate_odom}"
        );
        assert!(
            ate_offline < 0.2 * ate_odom,
            "offline {ate_offline} odometry {ate_odom}"
        );
        assert_eq!(online.landmarks.len(), tags.len());
        for l in &offline.landmarks {
            let t = tags[l.id as usize];
            let e = (l.position_m[0] - t[0]).hypot(l.position_m[1] - t[1]);
            assert!(e < 0.05, "tag {} error {e}", l.id);
        }
        assert!(
            online.conflicts.is_empty(),
            "{:?} rejected {}",
            online.conflicts,
            online.rejected.len()
        );
    }
}
