//! The planar motion that best reprojects the triangulated points into the next frame:
//! Gauss-Newton from the wheel odometry with Huber weights, points off by more than three sigma
//! left out, and its covariance from the reprojection residuals.

use super::*;
use crate::camera::StereoRig;
use crate::geometry::Pose2;
use nalgebra::{Isometry3, Matrix3, Point2, Point3, Translation3, UnitQuaternion, Vector3};

/// `left_b_from_left_a` for the robot motion `robot_a_from_robot_b`.
pub(super) fn camera_motion(rig: &StereoRig, robot_a_from_robot_b: &Pose2) -> Isometry3<f64> {
    let m = robot_a_from_robot_b;
    let a_from_b = Isometry3::from_parts(
        Translation3::new(m.x, m.y, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), m.theta),
    );
    rig.robot_from_left.inverse() * a_from_b.inverse() * rig.robot_from_left
}

/// Reprojection residuals, pixels, per observation (`None` where a point is left out or does not
/// project).
pub(super) type Residuals = Vec<Option<[f64; 2]>>;

/// Residuals (pixels) of the observations under a motion; `None` where a point does not project.
pub(super) fn residuals(
    rig: &StereoRig,
    observations: &[(Vector3<f64>, Point2<f64>)],
    motion: &Pose2,
    active: &[bool],
) -> Residuals {
    let b_from_a = camera_motion(rig, motion);
    observations
        .iter()
        .zip(active)
        .map(|((x, q), &on)| {
            let p = rig
                .left
                .project(&(b_from_a * Point3::from(*x)).coords)
                .filter(|_| on)?;
            Some([p.x - q.x, p.y - q.y])
        })
        .collect()
}

/// Steps of the numerical derivatives over `(x, y, theta)`.
pub(super) const STEPS: [f64; 3] = [1e-6, 1e-6, 1e-7];

/// The residuals at `motion` and at `motion` moved by each of [`STEPS`].
pub(super) fn residuals_and_columns(
    rig: &StereoRig,
    observations: &[(Vector3<f64>, Point2<f64>)],
    motion: &Pose2,
    active: &[bool],
) -> (Residuals, [Residuals; 3]) {
    let moved = |k: usize| {
        let mut m = *motion;
        match k {
            0 => m.x += STEPS[0],
            1 => m.y += STEPS[1],
            _ => m.theta += STEPS[2],
        }
        residuals(rig, observations, &m, active)
    };
    (
        residuals(rig, observations, motion, active),
        [moved(0), moved(1), moved(2)],
    )
}

/// `JᵀWJ` and `JᵀWr` of the active residuals; `huber` = `None` for unit weights.
pub(super) fn normal_equations(
    r0: &[Option<[f64; 2]>],
    columns: &[Residuals; 3],
    huber: Option<f64>,
) -> (Matrix3<f64>, Vector3<f64>) {
    let mut jtj = Matrix3::zeros();
    let mut jtr = Vector3::zeros();
    for (i, r) in r0.iter().enumerate() {
        let Some(r) = r else { continue };
        let mut j = [Vector3::zeros(); 2];
        let mut complete = true;
        for k in 0..3 {
            match columns[k][i] {
                Some(rk) => {
                    j[0][k] = (rk[0] - r[0]) / STEPS[k];
                    j[1][k] = (rk[1] - r[1]) / STEPS[k];
                }
                None => complete = false,
            }
        }
        if !complete {
            continue;
        }
        let norm = r[0].hypot(r[1]);
        let w = match huber {
            Some(h) if norm > h => h / norm,
            _ => 1.0,
        };
        for row in 0..2 {
            jtj += w * j[row] * j[row].transpose();
            jtr += w * j[row] * r[row];
        }
    }
    (jtj, jtr)
}

/// Gauss-Newton on `(x, y, theta)` with Huber weights from `prior`; three rounds, each followed by
/// dropping the points over three sigma (by the median residual).
pub(super) fn solve_planar(
    rig: &StereoRig,
    observations: &[(Vector3<f64>, Point2<f64>)],
    prior: &Pose2,
    config: &VoConfig,
) -> Result<VisualMotion, VoError> {
    let too_few = |found| VoError::TooFewPoints {
        found,
        needed: config.min_inliers,
    };
    if observations.len() < config.min_inliers {
        return Err(too_few(observations.len()));
    }
    let mut active = vec![true; observations.len()];
    let mut m = *prior;
    // The wheels' forward travel and the arc's sideways offset as priors, weighted against the
    // image residuals' sigma (found below).
    let travel = prior.x.hypot(prior.y);
    let forward_sigma = config.forward_sigma.0 + config.forward_sigma.1 * travel;
    let slip_sigma = config.slip_sigma.0 + config.slip_sigma.1 * travel;
    // The chord's angle off the direction of travel (ahead of the robot when it drove forward,
    // behind it when it backed up; the sideways offset is then `-x tan(angle)`), as the wheels
    // give it, and how much of a correction to their turn moves it: on an arc half of it, after
    // a turn on the spot all of it, and exactly `chord / turn` when the wheels misjudge every
    // turn by one scale. An S-bend's chord owes little to its small net turn, so the share is
    // held to what a correction spread along the path can do (0 to 1); a straight step takes the
    // wheels' chord as it is.
    let backward = if prior.x < 0.0 { -1.0 } else { 1.0 };
    let chord = prior.y.atan2(prior.x.abs().max(1e-9));
    let share = if prior.theta.abs() > 1e-3 {
        (backward * chord / prior.theta).clamp(0.0, 1.0) * backward
    } else {
        0.0
    };
    let mut sigma_px = 0.5f64;
    let with_prior = |jtj: &mut Matrix3<f64>, jtr: &mut Vector3<f64>, m: &Pose2, sigma_px: f64| {
        let w = (sigma_px / forward_sigma).powi(2);
        jtj[(0, 0)] += w;
        jtr[0] += w * (m.x - prior.x);
        // Sideways: y = |x| tan(angle), the wheels' chord moved by its share of the correction.
        let (angle, w) = (
            chord + share * (m.theta - prior.theta),
            (sigma_px / slip_sigma).powi(2),
        );
        let r = m.y - backward * m.x * angle.tan();
        let j = Vector3::new(
            -backward * angle.tan(),
            1.0,
            -backward * share * m.x / (angle.cos() * angle.cos()),
        );
        *jtj += w * j * j.transpose();
        *jtr += w * j * r;
    };
    for _round in 0..3 {
        for _ in 0..15 {
            let (r0, columns) = residuals_and_columns(rig, observations, &m, &active);
            let (mut jtj, mut jtr) = normal_equations(&r0, &columns, Some(config.huber_px));
            with_prior(&mut jtj, &mut jtr, &m, sigma_px);
            let step = jtj.try_inverse().ok_or_else(|| too_few(0))? * -jtr;
            m = Pose2::new(m.x + step[0], m.y + step[1], m.theta + step[2]);
            if step.norm() < 1e-9 {
                break;
            }
        }
        let r = residuals(rig, observations, &m, &active);
        let mut norms: Vec<f64> = r.iter().flatten().map(|r| r[0].hypot(r[1])).collect();
        if norms.len() < config.min_inliers {
            return Err(too_few(norms.len()));
        }
        norms.sort_by(f64::total_cmp);
        // The median of a 2D Gaussian residual's length is 1.1774 sigma.
        let sigma = (norms[norms.len() / 2] / 1.1774).max(config.sigma_floor_px);
        sigma_px = sigma;
        let limit = (3.0 * sigma).max(0.5);
        for (on, r) in active.iter_mut().zip(&r) {
            *on = r.is_some_and(|r| r[0].hypot(r[1]) <= limit);
        }
    }
    let (r0, columns) = residuals_and_columns(rig, observations, &m, &active);
    let inliers: Vec<[f64; 2]> = r0.iter().flatten().cloned().collect();
    if inliers.len() < config.min_inliers {
        return Err(too_few(inliers.len()));
    }
    let rms_px = (inliers
        .iter()
        .map(|r| r[0] * r[0] + r[1] * r[1])
        .sum::<f64>()
        / (2 * inliers.len()) as f64)
        .sqrt();
    let sigma = rms_px.max(config.sigma_floor_px);
    let (mut jtj, mut jtr) = normal_equations(&r0, &columns, None);
    with_prior(&mut jtj, &mut jtr, &m, sigma);
    let covariance =
        jtj.try_inverse().ok_or_else(|| too_few(0))? * (sigma * sigma * config.variance_scale);
    Ok(VisualMotion {
        motion: m,
        covariance,
        inliers: inliers.len(),
        tracked: observations.len(),
        rms_px,
    })
}
