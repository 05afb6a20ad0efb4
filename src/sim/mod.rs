//! Robot simulation: a differential-drive robot that explores a world the way the paper's robot
//! did, with odometry that drifts and sonars that behave like sonars.
//!
//! * **Odometry** (`odometry.rs`): the true motion integrated from the commanded wheel speeds,
//!   the robot's own estimate from encoders with scale errors, random noise and a wrong wheel
//!   base (Borenstein's UMBmark error model).
//! * **Sonar** (`sonar.rs`): each transducer's cone ([`crate::sonar::PAPER_CONE_RAD`] wide)
//!   sampled by rays; a smooth wall echoes along a ray only within
//!   [`SonarPhysics::roughness_deg`] of its normal, so a wall seen beyond the critical angle (half
//!   the cone plus the roughness: 25 degrees by default) gives no echo, or with
//!   [`SonarPhysics::multipath_prob`] a long reading from a multipath bounce. A concave corner
//!   inside the cone is a corner reflector and always echoes; a convex edge or wall end echoes
//!   weakly ([`SonarPhysics::edge_echo_prob`]). People echo from their bodies. The nearest echo
//!   wins, then range noise and random drop-outs apply.
//! * **Exploration** (`explore.rs`, the paper's): drive straight until an obstacle, follow its
//!   boundary, then head for the least-known region of the robot's own counting grid (built from
//!   its odometry) until the explored area stops growing or the time budget ends.
//! * **Pictures** ([`capture`]): when the stereo pictures are taken along the run.
//!
//! [`simulate`] steps the robot: a target when one is needed, a command, the wheels, and a sonar
//! sample every [`ExplorationConfig::sample_travel_m`] or [`ExplorationConfig::sample_turn_deg`].

pub mod capture;
mod explore;
mod odometry;
mod sonar;

pub use explore::{
    ExplorationConfig, REVISIT_REACHED_M, REVISIT_SPACING_M, REVISIT_TIMEOUT_TRAVEL_TIMES,
};
pub use odometry::OdometryNoise;
pub use sonar::{dropout_rate_from_ring, simulate_reading, SonarPhysics};

use crate::dataset::{RobotDescription, RunDataset, RunMeta, RUN_FORMAT};
use crate::geometry::{Pose2, StampedPose};
use crate::sonar::grid::{CountingGrid, GridConfig, GridError, OccupancyGrid, OccupancyMap};
use crate::sonar::{PlacedReading, SonarLayout, SonarReading};
use crate::world::World;
use explore::Explorer;
use nalgebra::Point2;
use odometry::Wheels;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Everything the simulation needs besides the world.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Random seed: the same seed and inputs give the same run.
    pub seed: u64,
    /// Sonar layout.
    pub sonar_layout: SonarLayout,
    /// Odometry error.
    pub odometry: OdometryNoise,
    /// Sonar physics.
    pub sonar: SonarPhysics,
    /// Exploration.
    pub exploration: ExplorationConfig,
    /// The robot's own online grid (for choosing where to go); a world file sets it from its
    /// `mapping.grid`.
    #[serde(skip)]
    pub grid: GridConfig,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            sonar_layout: SonarLayout::frontal5(),
            odometry: OdometryNoise::default(),
            sonar: SonarPhysics::default(),
            exploration: ExplorationConfig::default(),
            grid: GridConfig::default(),
        }
    }
}

/// Errors of the simulation.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// Bad grid settings.
    #[error(transparent)]
    Grid(#[from] GridError),
    /// A setting is out of range.
    #[error("simulation setting `{key}` is invalid: {reason}")]
    Invalid {
        /// The key.
        key: &'static str,
        /// What is expected.
        reason: &'static str,
    },
    /// The start pose is inside or touching a wall.
    #[error("the start pose ({x:.2}, {y:.2}) is closer than the robot radius to a wall")]
    StartInWall {
        /// x, metres.
        x: f64,
        /// y, metres.
        y: f64,
    },
}

impl SimConfig {
    fn validate(&self) -> Result<(), SimError> {
        let e = &self.exploration;
        let bad = |key, reason| Err(SimError::Invalid { key, reason });
        if !(e.speed_mps > 0.0 && e.speed_mps.is_finite()) {
            return bad("exploration.speed_mps", "must be positive");
        }
        if !(e.step_s > 0.0 && e.step_s <= 1.0) {
            return bad("exploration.step_s", "must be in (0, 1] seconds");
        }
        if !(e.sample_travel_m > 0.0 && e.sample_turn_deg > 0.0) {
            return bad(
                "exploration.sample_travel_m",
                "sampling intervals must be positive",
            );
        }
        if e.follow_distance_m.is_nan() || e.follow_distance_m <= e.robot_radius_m {
            return bad(
                "exploration.follow_distance_m",
                "must exceed the robot radius",
            );
        }
        if !(e.duration_s > 0.0 && e.duration_s <= 86_400.0) {
            return bad("exploration.duration_s", "must be in (0, 86400] seconds");
        }
        if self.sonar_layout.sensors.is_empty() {
            return bad("sonar_layout.sensors", "at least one sonar is needed");
        }
        if self.sonar.rays_per_cone < 2 {
            return bad("sonar.rays_per_cone", "at least 2");
        }
        for (k, p) in [
            ("sonar.dropout_prob", self.sonar.dropout_prob),
            ("sonar.multipath_prob", self.sonar.multipath_prob),
            ("sonar.edge_echo_prob", self.sonar.edge_echo_prob),
            ("sonar.person_echo_prob", self.sonar.person_echo_prob),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return bad(k, "a probability must lie in [0, 1]");
            }
        }
        Ok(())
    }
}

/// What the simulation produced.
#[derive(Debug, Clone)]
pub struct SimOutput {
    /// The run, with ground truth.
    pub run: RunDataset,
    /// The robot's own online grid at the end.
    pub online_map: OccupancyMap,
    /// Why exploration ended.
    pub end_reason: String,
    /// Exploration targets chosen, in order.
    pub targets: Vec<Point2<f64>>,
}

/// What the robot logs as it goes: odometry and true poses, sonar readings, and its own
/// counting grid (built from its odometry, what exploration steers by).
struct Log<'a> {
    world: &'a World,
    config: &'a SimConfig,
    odometry: Vec<StampedPose>,
    ground_truth: Vec<StampedPose>,
    sonar: Vec<SonarReading>,
    grid: CountingGrid,
    /// Travel and turn since the last sample.
    since: (f64, f64),
}

impl<'a> Log<'a> {
    /// An empty log, its grid by the configuration's.
    fn new(world: &'a World, config: &'a SimConfig) -> Result<Self, SimError> {
        Ok(Self {
            world,
            config,
            odometry: Vec::new(),
            ground_truth: Vec::new(),
            sonar: Vec::new(),
            grid: CountingGrid::for_layout(config.grid.clone(), &config.sonar_layout)?,
            since: (0.0, 0.0),
        })
    }

    /// Notes one step of the wheels at `t`; a sample (as [`Log::sample`]) once the robot has
    /// travelled [`ExplorationConfig::sample_travel_m`] or turned
    /// [`ExplorationConfig::sample_turn_deg`] since the last.
    fn moved(&mut self, t: f64, step: &odometry::Step, wheels: &Wheels, rng: &mut ChaCha8Rng) {
        let e = &self.config.exploration;
        self.since = (self.since.0 + step.ds.abs(), self.since.1 + step.dth.abs());
        if self.since.0 >= e.sample_travel_m || self.since.1 >= e.sample_turn_deg.to_radians() {
            self.since = (0.0, 0.0);
            self.sample(t, wheels.truth, wheels.odom, rng);
        }
    }

    /// Logs the poses at `t` and one reading of every sonar (random draws from `rng`).
    fn sample(&mut self, t: f64, truth: Pose2, odom: Pose2, rng: &mut ChaCha8Rng) {
        self.odometry.push(StampedPose { t_s: t, pose: odom });
        self.ground_truth.push(StampedPose {
            t_s: t,
            pose: truth,
        });
        let layout = &self.config.sonar_layout;
        for (i, s) in layout.sensors.iter().enumerate() {
            let range = simulate_reading(
                self.world,
                t,
                truth.compose(&s.robot_from_sensor()),
                layout,
                &self.config.sonar,
                rng,
            );
            self.sonar.push(SonarReading {
                t_s: t,
                sensor: i,
                range_m: range,
            });
            self.grid.insert(&PlacedReading {
                t_s: t,
                world_from_sensor: odom.compose(&s.robot_from_sensor()),
                range_m: range,
            });
        }
    }
}

/// Simulates a run in `world`. `on_progress(t_s)` is called about once per simulated second.
pub fn simulate(
    world: &World,
    config: &SimConfig,
    mut on_progress: impl FnMut(f64),
) -> Result<SimOutput, SimError> {
    config.validate()?;
    let e = &config.exploration;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    if world
        .nearest_wall_point(world.start.position(), e.robot_radius_m)
        .is_some()
    {
        return Err(SimError::StartInWall {
            x: world.start.x,
            y: world.start.y,
        });
    }
    let mut wheels = Wheels::new(world.start, e, &config.odometry)?;
    let mut log = Log::new(world, config)?;
    let mut explorer = Explorer::new(e);
    let mut t = 0.0;
    let mut end_reason = String::from("time budget ended");
    let mut next_progress = 1.0;
    log.sample(t, wheels.truth, wheels.odom, &mut rng);
    while t < e.duration_s {
        if let Some(reason) = explorer.next_target(t, wheels.odom, &log.grid, e) {
            end_reason = reason;
            break;
        }
        explorer.unstick(t, world, (wheels.truth, wheels.odom), e);
        let command = explorer.command(world, (wheels.truth, wheels.odom), e);
        let step = wheels.drive(command, e.step_s, world, e.robot_radius_m, &mut rng);
        t += e.step_s;
        explorer.moved(step.ds, step.dth, wheels.odom);
        log.moved(t, &step, &wheels, &mut rng);
        if t >= next_progress {
            on_progress(t);
            next_progress += 1.0;
        }
    }
    on_progress(t);
    let end_reason = explorer.end_reason(end_reason);
    let run = simulated_run(
        config,
        &end_reason,
        log.odometry,
        log.sonar,
        log.ground_truth,
    );
    Ok(SimOutput {
        run,
        online_map: log.grid.map(),
        end_reason,
        targets: explorer.targets,
    })
}

/// Simulates a run along a given path instead of exploring: the robot is at each of its poses
/// in turn (interpolated every [`ExplorationConfig::step_s`]; times from the path's first), its
/// wheels read with the configured errors, its sonar sampled as in [`simulate`]. The path may be
/// a real log's ground truth or one drawn on a floor plan; it is not checked against the walls.
/// `on_progress(t_s)` is called about once per simulated second.
pub fn simulate_along(
    world: &World,
    config: &SimConfig,
    path: &[StampedPose],
    mut on_progress: impl FnMut(f64),
) -> Result<SimOutput, SimError> {
    config.validate()?;
    let (Some(first), Some(last)) = (path.first(), path.last()) else {
        return Err(SimError::Invalid {
            key: "along",
            reason: "the path has no poses",
        });
    };
    if last.t_s.is_nan() || last.t_s <= first.t_s {
        return Err(SimError::Invalid {
            key: "along",
            reason: "the path must span some time (at least two poses, times increasing)",
        });
    }
    let e = &config.exploration;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut wheels = Wheels::new(first.pose, e, &config.odometry)?;
    let mut log = Log::new(world, config)?;
    let duration = last.t_s - first.t_s;
    let mut t = 0.0;
    let mut next_progress = 1.0;
    log.sample(t, wheels.truth, wheels.odom, &mut rng);
    while t < duration {
        t = (t + e.step_s).min(duration);
        let Some(next) = crate::geometry::pose_at(path, first.t_s + t) else {
            break;
        };
        let step = wheels.follow(next, &mut rng);
        log.moved(t, &step, &wheels, &mut rng);
        if t >= next_progress {
            on_progress(t);
            next_progress += 1.0;
        }
    }
    // The run lasts as long as the path: its last pose is logged too.
    if log.ground_truth.last().is_some_and(|p| p.t_s < t) {
        log.sample(t, wheels.truth, wheels.odom, &mut rng);
    }
    on_progress(t);
    let end_reason = format!("followed the given path of {} poses", path.len());
    Ok(SimOutput {
        run: simulated_run(
            config,
            &end_reason,
            log.odometry,
            log.sonar,
            log.ground_truth,
        ),
        online_map: log.grid.map(),
        end_reason,
        targets: Vec::new(),
    })
}

/// A simulated run's dataset. Its sonar layout carries the simulated transducers' shortest
/// range.
fn simulated_run(
    config: &SimConfig,
    end_reason: &str,
    odometry: Vec<StampedPose>,
    sonar: Vec<SonarReading>,
    ground_truth: Vec<StampedPose>,
) -> RunDataset {
    RunDataset {
        meta: RunMeta {
            format: RUN_FORMAT.into(),
            robot: RobotDescription {
                sonar: SonarLayout {
                    min_range_m: config.sonar.min_range_m,
                    ..config.sonar_layout.clone()
                },
                lidar: None,
                ranging: None,
                rig: None,
                robot_from_left: None,
            },
            world: None,
            mapping: None,
            notes: format!("simulated by stereotag, seed {}; {end_reason}", config.seed),
        },
        odometry,
        sonar,
        stereo: Vec::new(),
        ground_truth: Some(ground_truth),
        lidar: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_along_a_path_follows_it_and_its_odometry_drifts() {
        let w = crate::world::rectangle_world(12.0, 6.0, Pose2::new(2.0, 3.0, 0.0));
        // Along the long side and back: 8 m out at 0.4 m/s, a half turn, 8 m back.
        let mut path = Vec::new();
        for k in 0..=200 {
            let t = k as f64 * 0.1;
            path.push(StampedPose {
                t_s: t,
                pose: Pose2::new(2.0 + 0.4 * t, 3.0, 0.0),
            });
        }
        for k in 1..=40 {
            path.push(StampedPose {
                t_s: 20.0 + k as f64 * 0.1,
                pose: Pose2::new(10.0, 3.0, std::f64::consts::PI * k as f64 / 40.0),
            });
        }
        for k in 1..=200 {
            let t = k as f64 * 0.1;
            path.push(StampedPose {
                t_s: 24.0 + t,
                pose: Pose2::new(10.0 - 0.4 * t, 3.0, std::f64::consts::PI),
            });
        }
        let c = SimConfig::default();
        let out = simulate_along(&w, &c, &path, |_| {}).unwrap();
        let run = &out.run;
        let truth = run.ground_truth.as_ref().unwrap();
        // The truth is the path (a path wheels can drive), sampled every few centimetres.
        for p in truth {
            let q = crate::geometry::pose_at(&path, p.t_s).unwrap();
            assert!((p.pose.x - q.x).hypot(p.pose.y - q.y) < 1e-6, "{p:?} {q:?}");
        }
        assert!((truth.last().unwrap().t_s - 44.0).abs() < 1e-9);
        assert!(truth.len() > 100 && run.sonar.len() == 5 * truth.len());
        // The odometry drifts from it (1% wheel base: the half turn comes out 1% short).
        let end = run.odometry.last().unwrap().pose;
        assert!((end.theta - std::f64::consts::PI).abs() > 0.01, "{end:?}");
        assert!((end.x - 2.0).hypot(end.y - 3.0) > 0.05, "{end:?}");
        assert!((end.x - 2.0).hypot(end.y - 3.0) < 1.0, "{end:?}");
        // A path that spans no time is refused.
        assert!(simulate_along(&w, &c, &path[..1], |_| {}).is_err());
    }

    /// A real log's poses wander sideways from one to the next; the robot drives them as wheels
    /// can, never sideways, and stays within centimetres of them.
    #[test]
    fn a_path_that_wanders_sideways_is_driven_as_wheels_can() {
        let w = crate::world::rectangle_world(12.0, 6.0, Pose2::new(2.0, 3.0, 0.0));
        let path: Vec<StampedPose> = (0..=200)
            .map(|k| {
                let t = k as f64 * 0.1;
                // 2 cm of sideways jitter, alternating, along an 8 m straight drive.
                let side = if k % 2 == 0 { 0.01 } else { -0.01 };
                StampedPose {
                    t_s: t,
                    pose: Pose2::new(2.0 + 0.4 * t, 3.0 + side, 0.0),
                }
            })
            .collect();
        let c = SimConfig::default();
        let out = simulate_along(&w, &c, &path, |_| {}).unwrap();
        let truth = out.run.ground_truth.unwrap();
        for (a, b) in truth.iter().zip(truth.iter().skip(1)) {
            let d = a.pose.between(&b.pose);
            // Along arcs: sideways only as much as its small turns give (the path itself goes 2
            // cm sideways for every 4 cm forward).
            assert!(d.y.abs() < 0.05 * d.x.abs() + 1e-9, "{a:?} -> {b:?}");
            let q = crate::geometry::pose_at(&path, b.t_s).unwrap();
            assert!((b.pose.y - q.y).abs() < 0.03, "{b:?} vs {q:?}");
        }
    }

    #[test]
    fn same_seed_same_run() {
        let w = crate::world::rectangle_world(6.0, 3.0, Pose2::new(2.0, 1.5, 0.0));
        let mut c = SimConfig::default();
        c.exploration.duration_s = 60.0;
        let a = simulate(&w, &c, |_| {}).unwrap();
        let b = simulate(&w, &c, |_| {}).unwrap();
        assert_eq!(a.run, b.run);
        assert!(a.run.sonar.len() > 50);
    }
}
