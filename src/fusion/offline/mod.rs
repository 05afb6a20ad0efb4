//! The offline pass (the method's a-posteriori correction): a pose graph over keyframes of the
//! whole run, solved by Levenberg-Marquardt, its keyframe corrections interpolated along the
//! odometry.

mod factors;
mod graph;
mod interpolate;
mod keyframes;

use crate::fusion::{FuseConfig, Landmark, Observations, OnlineResult};
use crate::geometry::{wrap_angle, Pose2, StampedPose};
use factors::corrected_increment;
use serde::{Deserialize, Serialize};

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

/// The method's a-posteriori pass: a pose graph over the whole run (keyframes, odometry, tag
/// sightings, visual turns), started from the `online` estimate and solved by
/// Levenberg-Marquardt; with `prior` (an earlier survey's odometry calibration) the calibration
/// is estimated near it instead of near no error.
pub fn run_offline(
    obs: &Observations<'_>,
    online: &OnlineResult,
    config: &FuseConfig,
    prior: Option<&OdometryCalibration>,
) -> OfflineResult {
    let Some(first) = obs.odometry.first() else {
        return OfflineResult {
            trajectory: Vec::new(),
            landmarks: online.landmarks.clone(),
            keyframes: 0,
            factors: 0,
            converged: false,
            odometry_calibration: None,
        };
    };
    let visual = keyframes::turns_used(obs, config);
    let keyframes = keyframes::choose(obs, &visual, online, config, first.pose);
    let graph = graph::build(
        obs,
        &keyframes,
        &visual,
        online,
        config,
        (first.pose, prior),
    );
    let options = tiny_solver::OptimizerOptions {
        max_iteration: config.max_iterations,
        ..Default::default()
    };
    use tiny_solver::Optimizer;
    let solution = tiny_solver::LevenbergMarquardtOptimizer::default().optimize(
        &graph.problem,
        &graph.init,
        Some(options),
    );
    let converged = solution.is_some();
    let values = solution.unwrap_or(graph.init);
    let solved: Vec<Pose2> = (0..keyframes.frames.len())
        .map(|i| {
            values
                .get(&graph::pose_name(i))
                .map_or(keyframes.frames[i].init, |v| {
                    Pose2::new(v[0], v[1], wrap_angle(v[2]))
                })
        })
        .collect();
    let landmarks = online
        .landmarks
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let mut l = l.clone();
            if let Some(v) = values.get(&graph::landmark_name(i)) {
                l.position_m[0] = v[0];
                l.position_m[1] = v[1];
                l.yaw_rad = wrap_angle(v[2]);
            }
            l
        })
        .collect();
    OfflineResult {
        trajectory: interpolate::corrected(obs.odometry, &keyframes.frames, &solved),
        landmarks,
        keyframes: keyframes.frames.len(),
        factors: graph.factors,
        converged,
        odometry_calibration: values
            .get(graph::CALIBRATION)
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
    use crate::fusion::run_online;
    use crate::fusion::testing::obs;
    use crate::fusion::testing::{square_run, turns_of};
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
        let online = run_online(&obs(&odom, &[], &turns), &[], &config, None);
        let offline = run_offline(&obs(&odom, &[], &turns), &online, &config, None);
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
        let blind = run_online(&obs(&odom, &[], &turns), &[], &off_config, None);
        assert_eq!(blind.visual_fused, 0);
        assert!(ate_m(&blind.trajectory, &truth).unwrap() > 0.5 * raw);
    }

    #[test]
    fn online_and_offline_beat_odometry_on_a_biased_loop() {
        let (odom, truth, sightings, tags) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let online = run_online(&obs(&odom, &sightings, &[]), &[], &config, None);
        let offline = run_offline(&obs(&odom, &sightings, &[]), &online, &config, None);
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
