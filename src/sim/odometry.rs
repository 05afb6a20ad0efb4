//! The simulated robot's wheels: the true motion integrated from the commanded wheel speeds,
//! and the robot's own estimate from its wheel encoders, which read each wheel with a
//! systematic scale error and a random error growing with the square root of the distance, and
//! turn them into motion with a nominal wheel base that differs from the true one (Borenstein's
//! UMBmark error model).

use crate::geometry::Pose2;
use crate::sim::{ExplorationConfig, SimError};
use crate::world::World;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// Odometry error model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryNoise {
    /// Relative scale error of the left wheel encoder (ours: -0.1%).
    pub left_scale_error: f64,
    /// Relative scale error of the right wheel encoder (ours: +0.1%, so the robot thinks it turns).
    pub right_scale_error: f64,
    /// Relative error of the nominal wheel base against the true one (ours: +1%).
    pub wheel_base_error: f64,
    /// Random wheel error, metres per square root metre travelled (ours: 2 mm).
    pub random_m_per_sqrt_m: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        Self {
            left_scale_error: -0.001,
            right_scale_error: 0.001,
            wheel_base_error: 0.01,
            random_m_per_sqrt_m: 0.002,
        }
    }
}

impl OdometryNoise {
    /// No error at all.
    pub fn none() -> Self {
        Self {
            left_scale_error: 0.0,
            right_scale_error: 0.0,
            wheel_base_error: 0.0,
            random_m_per_sqrt_m: 0.0,
        }
    }
}

/// The robot's pose, true and as its wheels say, and its wheels.
pub(super) struct Wheels {
    /// The true pose.
    pub(super) truth: Pose2,
    /// The pose the encoders give (dead reckoning).
    pub(super) odom: Pose2,
    base_true: f64,
    base_nominal: f64,
    noise: OdometryNoise,
    unit: Normal<f64>,
}

/// What one step of the wheels did, as the encoders saw it.
pub(super) struct Step {
    /// Distance travelled, metres (signed).
    pub(super) ds: f64,
    /// Turn, radians (signed).
    pub(super) dth: f64,
}

impl Wheels {
    /// Wheels at `start`, both poses there.
    pub(super) fn new(
        start: Pose2,
        e: &ExplorationConfig,
        noise: &OdometryNoise,
    ) -> Result<Self, SimError> {
        Ok(Self {
            truth: start,
            odom: start,
            base_true: e.wheel_base_m,
            base_nominal: e.wheel_base_m * (1.0 + noise.wheel_base_error),
            noise: noise.clone(),
            unit: Normal::new(0.0, 1.0).map_err(|_| SimError::Invalid {
                key: "odometry",
                reason: "bad noise",
            })?,
        })
    }

    /// Drives at speed `v` and turn rate `w` for `dt` (no translation into a wall: the bumper),
    /// then reads the encoders (two random draws from `rng`).
    pub(super) fn drive(
        &mut self,
        (v, w): (f64, f64),
        dt: f64,
        world: &World,
        robot_radius_m: f64,
        rng: &mut ChaCha8Rng,
    ) -> Step {
        let base_true = self.base_true;
        let mut v = v;
        let next = integrate(self.truth, v * dt, w * dt);
        if world
            .nearest_wall_point(next.position(), robot_radius_m)
            .is_some()
        {
            v = 0.0; // bumper: no translation into a wall
        }
        let dl = (v - 0.5 * w * base_true) * dt;
        let dr = (v + 0.5 * w * base_true) * dt;
        self.truth = integrate(self.truth, 0.5 * (dl + dr), (dr - dl) / base_true);
        self.read_encoders(dl, dr, rng)
    }

    /// Drives the robot towards `next` (the next pose of a given path) as wheels can: forward
    /// by the path's forward motion, turned by its turn plus a pull back towards it when the
    /// robot is off to its side (pure pursuit, [`PATH_PULL_PER_M2`]), then reads the encoders
    /// (two random draws from `rng`). A real log's poses wander sideways by centimetres from one
    /// to the next (freiburg-079's corrected poses: 14% as much sideways as forward); taken as
    /// they are, they would move the robot sideways, which neither its wheels nor its camera's
    /// motion could do.
    pub(super) fn follow(&mut self, next: Pose2, rng: &mut ChaCha8Rng) -> Step {
        let d = self.truth.between(&next);
        let ds = d.x;
        let dth = crate::geometry::wrap_angle(d.theta) + PATH_PULL_PER_M2 * d.y * ds;
        let dl = ds - 0.5 * dth * self.base_true;
        let dr = ds + 0.5 * dth * self.base_true;
        self.truth = integrate(self.truth, ds, dth);
        self.read_encoders(dl, dr, rng)
    }

    /// The odometry's step from the wheels' true travels `dl` and `dr`: each read with its scale
    /// error and random error, turned into motion with the nominal wheel base.
    fn read_encoders(&mut self, dl: f64, dr: f64, rng: &mut ChaCha8Rng) -> Step {
        let noise = self.noise.random_m_per_sqrt_m;
        let ml = dl * (1.0 + self.noise.left_scale_error)
            + noise * dl.abs().sqrt() * self.unit.sample(rng);
        let mr = dr * (1.0 + self.noise.right_scale_error)
            + noise * dr.abs().sqrt() * self.unit.sample(rng);
        let ds = 0.5 * (ml + mr);
        let dth = (mr - ml) / self.base_nominal;
        self.odom = integrate(self.odom, ds, dth);
        Step { ds, dth }
    }
}

/// How hard a robot following a path steers back to it: the curvature asked per metre off
/// it, 1/m² (pure pursuit with a 0.5 m look-ahead: 2 / 0.5²). Off by a sideways error `e`, the
/// error decays over about `1 / (8 ds)` steps of `ds` metres (2 m of travel at 6 cm steps).
pub const PATH_PULL_PER_M2: f64 = 8.0;

/// Moves a pose by `ds` along an arc turning `dth` (midpoint rule).
pub(super) fn integrate(p: Pose2, ds: f64, dth: f64) -> Pose2 {
    let mid = p.theta + 0.5 * dth;
    Pose2::new(p.x + ds * mid.cos(), p.y + ds * mid.sin(), p.theta + dth)
}
