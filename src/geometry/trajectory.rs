//! Trajectories: poses stamped with times, interpolated between their samples, and the jumps a
//! real log's odometry may hold.

use crate::geometry::Pose2;

/// A pose at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampedPose {
    /// Time, seconds.
    pub t_s: f64,
    /// `world_from_robot`.
    pub pose: Pose2,
}

impl StampedPose {
    /// The pose `x` metres along the x axis, heading along it, at `t_s` (for tests of
    /// trajectories against each other).
    #[cfg(test)]
    pub(crate) fn along_x(t_s: f64, x: f64) -> Self {
        Self {
            t_s,
            pose: Pose2::new(x, 0.0, 0.0),
        }
    }
}

/// Pose at time `t_s` by linear interpolation (clamped at the ends); `None` for an empty trajectory.
pub fn pose_at(trajectory: &[StampedPose], t_s: f64) -> Option<Pose2> {
    let first = trajectory.first()?;
    let i = trajectory.partition_point(|p| p.t_s <= t_s);
    if i == 0 {
        return Some(first.pose);
    }
    let a = trajectory[i - 1];
    let Some(b) = trajectory.get(i) else {
        return Some(a.pose);
    };
    let span = b.t_s - a.t_s;
    let f = if span > 0.0 {
        (t_s - a.t_s) / span
    } else {
        0.0
    };
    Some(a.pose.lerp(&b.pose, f))
}

/// The pose at `t_s` as [`pose_at`] gives it, but only within the trajectory's span: `None`
/// before its first pose or after its last. What a ground truth says, which may start after a
/// log's odometry (aces' corrected poses begin 20.9 s in) or end before it: held at its end
/// poses, it would score the estimate against poses nobody measured.
pub fn pose_within(trajectory: &[StampedPose], t_s: f64) -> Option<Pose2> {
    let (first, last) = (trajectory.first()?, trajectory.last()?);
    if t_s < first.t_s || t_s > last.t_s {
        return None;
    }
    pose_at(trajectory, t_s)
}

/// An odometry step longer than a robot could drive in its time: a reset or a glitch in a log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryJump {
    /// Index of the sample the step ends on (0 is the first pose).
    pub index: usize,
    /// Time of that line, seconds.
    pub t_s: f64,
    /// Length of the step, metres.
    pub distance_m: f64,
}

/// Length of a trajectory's path, metres (steps that are not finite left out).
pub fn path_length_m(trajectory: &[StampedPose]) -> f64 {
    trajectory
        .windows(2)
        .map(|w| (w[1].pose.x - w[0].pose.x).hypot(w[1].pose.y - w[0].pose.y))
        .filter(|d| d.is_finite())
        .sum()
}

/// A trajectory taken into another frame: each pose `frame ∘ pose`, at its time.
pub fn transformed(frame: Pose2, trajectory: &[StampedPose]) -> Vec<StampedPose> {
    trajectory
        .iter()
        .map(|p| StampedPose {
            t_s: p.t_s,
            pose: frame.compose(&p.pose),
        })
        .collect()
}

/// The distance travelled along a trajectory up to each of its poses, metres (0 at the first).
pub fn distance_travelled(trajectory: &[StampedPose]) -> Vec<f64> {
    let mut total = 0.0;
    let mut out = Vec::with_capacity(trajectory.len());
    for (i, p) in trajectory.iter().enumerate() {
        if i > 0 {
            let q = trajectory[i - 1].pose;
            total += (p.pose.x - q.x).hypot(p.pose.y - q.y);
        }
        out.push(total);
    }
    out
}

/// An odometry step is a jump when it is longer than this, metres ...
pub const JUMP_MIN_M: f64 = 1.0;
/// ... and faster than this, metres per second (a home robot drives at most 1-2 m/s).
pub const JUMP_SPEED_MPS: f64 = 5.0;

/// Steps of an odometry trajectory (as read from `odometry.csv`) longer than [`JUMP_MIN_M`] and
/// faster than [`JUMP_SPEED_MPS`]: a survey places everything after one with it, so a user should
/// hear of it.
pub fn odometry_jumps(odometry: &[StampedPose]) -> Vec<OdometryJump> {
    odometry
        .windows(2)
        .enumerate()
        .filter_map(|(i, w)| {
            let d = (w[1].pose.x - w[0].pose.x).hypot(w[1].pose.y - w[0].pose.y);
            let dt = w[1].t_s - w[0].t_s;
            (d > JUMP_MIN_M && d > JUMP_SPEED_MPS * dt).then_some(OdometryJump {
                index: i + 1,
                t_s: w[1].t_s,
                distance_m: d,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_between_stamps() {
        let tr = vec![
            StampedPose {
                t_s: 0.0,
                pose: Pose2::new(0.0, 0.0, 0.0),
            },
            StampedPose {
                t_s: 2.0,
                pose: Pose2::new(2.0, 0.0, 1.0),
            },
        ];
        let p = pose_at(&tr, 1.0).unwrap();
        assert!((p.x - 1.0).abs() < 1e-12 && (p.theta - 0.5).abs() < 1e-12);
        assert_eq!(pose_at(&tr, 5.0).unwrap(), tr[1].pose);
    }

    #[test]
    fn an_odometry_jump_is_found_with_its_line() {
        let pose = |t: f64, x: f64| StampedPose {
            t_s: t,
            pose: Pose2::new(x, 0.0, 0.0),
        };
        // 0.1 m/s, then 100 km in a tenth of a second, then 0.1 m/s again; a slow log with 1.5 m
        // steps at 1 s is no jump.
        let odometry = vec![
            pose(0.0, 0.0),
            pose(0.1, 0.01),
            pose(0.2, 1e5),
            pose(0.3, 1e5 + 0.01),
            pose(1.3, 1e5 + 1.5),
        ];
        let jumps = odometry_jumps(&odometry);
        assert_eq!(jumps.len(), 1, "{jumps:?}");
        assert_eq!(jumps[0].index, 2);
        assert!((jumps[0].distance_m - 1e5).abs() < 1.0);
    }
}
