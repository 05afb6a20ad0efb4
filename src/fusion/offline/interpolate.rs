//! The corrected trajectory at every odometry sample: the keyframes' corrections
//! (`world_from_odometry`) interpolated by the distance travelled between the keyframes around
//! it.

use super::keyframes::Keyframe;
use crate::geometry::{wrap_angle, Pose2, StampedPose};

/// Every odometry sample corrected, given each keyframe's solved pose.
pub(super) fn corrected(
    odometry: &[StampedPose],
    keyframes: &[Keyframe],
    solved: &[Pose2],
) -> Vec<StampedPose> {
    let corrections: Vec<Pose2> = keyframes
        .iter()
        .zip(solved)
        .map(|(kf, pose)| pose.compose(&kf.odom.inverse()))
        .collect();
    let mut trajectory = Vec::with_capacity(odometry.len());
    let mut kf = 0;
    for sample in odometry {
        while kf + 1 < keyframes.len() && keyframes[kf + 1].t_s < sample.t_s {
            kf += 1;
        }
        let correction = if kf + 1 < keyframes.len() && sample.t_s >= keyframes[kf].t_s {
            let (a, b) = (&keyframes[kf], &keyframes[kf + 1]);
            corrections[kf].lerp(&corrections[kf + 1], share_done(a, b, sample))
        } else {
            corrections[kf.min(corrections.len() - 1)]
        };
        let pose = correction.compose(&sample.pose);
        trajectory.push(StampedPose {
            t_s: sample.t_s,
            pose: Pose2::new(pose.x, pose.y, wrap_angle(pose.theta)),
        });
    }
    trajectory
}

/// How far from keyframe `a` to `b` the odometry sample is: by distance, or by time when the
/// robot turned on the spot between them.
fn share_done(a: &Keyframe, b: &Keyframe, sample: &StampedPose) -> f64 {
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
    if span > 1e-9 {
        (done / span).clamp(0.0, 1.0)
    } else {
        ((sample.t_s - a.t_s) / (b.t_s - a.t_s).max(1e-9)).clamp(0.0, 1.0)
    }
}
