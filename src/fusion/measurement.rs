//! The measurement models of the fusion stage: a sighting as a planar measurement of its tag in
//! the robot frame, and the noise of an odometry increment.

use crate::fusion::FuseConfig;
use crate::geometry::{wrap_angle, Pose2};
use crate::visual::sightings::TagSighting;
use nalgebra::{Matrix3, Vector3};

/// Odometry noise of one increment, in the frame of its start.
pub(crate) fn odometry_covariance(path_m: f64, turn_rad: f64, config: &FuseConfig) -> Matrix3<f64> {
    let vt = config.odometry_sigma_m_per_sqrt_m.powi(2) * path_m;
    let vh = config.heading_sigma_per_sqrt_rad.powi(2) * turn_rad
        + config.heading_sigma_per_sqrt_m.powi(2) * path_m;
    Matrix3::from_diagonal(&Vector3::new(vt + 1e-12, vt + 1e-12, vh + 1e-12))
}
/// A turn made with less travel than this per radian is a pivot, about a point between the
/// wheels (the inner wheel runs backwards for any wheel base over 0.2 m): 0.1 m.
pub(crate) const PIVOT_RADIUS_M: f64 = 0.1;

/// Odometry noise of one increment with no other measure of its turn, when the graph estimates
/// the odometry's calibration from tags or visual turns: its turns made along arcs with the
/// calibrated turn noise, since the calibration removes the wheel-base error the uncalibrated
/// noise covers; its pivots (`pivot_rad` of the turn, [`PIVOT_RADIUS_M`]) with the uncalibrated
/// noise, since a robot turning on the spot scrubs its wheels sideways and its effective wheel
/// base differs from the one its arcs calibrate (Borenstein and Feng's UMBmark).
pub(crate) fn calibrated_odometry_covariance(
    path_m: f64,
    turn_rad: f64,
    pivot_rad: f64,
    config: &FuseConfig,
) -> Matrix3<f64> {
    let pivot = pivot_rad.clamp(0.0, turn_rad);
    let mut cov = odometry_covariance(path_m, 0.0, config);
    cov[(2, 2)] += config.heading_sigma_per_sqrt_rad.powi(2) * pivot
        + config.calibrated_heading_sigma_per_sqrt_rad.powi(2) * (turn_rad - pivot);
    cov
}

/// A tag at planar pose `tag` seen from robot pose `robot`: its position and yaw in the robot
/// frame, and their Jacobian over the robot's `(x, y, theta)` (over the tag's it is the rotation
/// into the robot frame, and 1 for the yaw).
pub(crate) fn tag_in_robot(robot: Pose2, tag: Pose2) -> (Vector3<f64>, Matrix3<f64>) {
    let (s, c) = robot.theta.sin_cos();
    let (dx, dy) = (tag.x - robot.x, tag.y - robot.y);
    let h = Vector3::new(
        c * dx + s * dy,
        -s * dx + c * dy,
        wrap_angle(tag.theta - robot.theta),
    );
    let jac = Matrix3::new(
        -c,
        -s,
        -s * dx + c * dy,
        s,
        -c,
        -c * dx - s * dy,
        0.0,
        0.0,
        -1.0,
    );
    (h, jac)
}

/// The planar measurement `(x, y, ψ)` and its covariance, with the configured floors.
pub(crate) fn sighting_measurement(
    s: &TagSighting,
    config: &FuseConfig,
) -> (Vector3<f64>, Matrix3<f64>) {
    let z = Vector3::new(
        s.position_in_robot_m[0],
        s.position_in_robot_m[1],
        s.yaw_in_robot_rad,
    );
    let floor = config.sighting_sigma_floor_m.powi(2);
    let c = &s.covariance_m2;
    let yaw_sigma = s.yaw_sigma_rad.max(config.yaw_sigma_floor_rad);
    let r = Matrix3::new(
        c[0][0] + floor,
        c[0][1],
        0.0,
        c[1][0],
        c[1][1] + floor,
        0.0,
        0.0,
        0.0,
        yaw_sigma * yaw_sigma,
    );
    (z, r)
}
