//! Trajectory errors against the truth: the absolute trajectory error (ATE) and the rigid
//! alignment that separates a survey's anchoring from its shape.

use crate::geometry::{pose_within, Pose2, StampedPose};
use nalgebra::Vector2;

/// The rigid motion `truth_from_estimate` that best aligns an estimate's positions with the truth
/// at the estimate's times (least squares, closed form), for diagnostics: what of an error is a
/// shift and turn of the whole survey, and what is shape.
pub fn align_se2(estimate: &[StampedPose], truth: &[StampedPose]) -> Option<Pose2> {
    let pairs: Vec<(Vector2<f64>, Vector2<f64>)> = estimate
        .iter()
        .filter_map(|p| {
            let t = pose_within(truth, p.t_s)?;
            Some((Vector2::new(p.pose.x, p.pose.y), Vector2::new(t.x, t.y)))
        })
        .collect();
    if pairs.len() < 2 {
        return None;
    }
    let n = pairs.len() as f64;
    let ca = pairs.iter().map(|p| p.0).sum::<Vector2<f64>>() / n;
    let cb = pairs.iter().map(|p| p.1).sum::<Vector2<f64>>() / n;
    let (mut sin, mut cos) = (0.0, 0.0);
    for (a, b) in &pairs {
        let (a, b) = (a - ca, b - cb);
        sin += a.x * b.y - a.y * b.x;
        cos += a.x * b.x + a.y * b.y;
    }
    let theta = sin.atan2(cos);
    let (s, c) = theta.sin_cos();
    let t = cb - Vector2::new(c * ca.x - s * ca.y, s * ca.x + c * ca.y);
    Some(Pose2::new(t.x, t.y, theta))
}

/// Root-mean-square position error of `estimate` against `truth` at the estimate's times (no
/// alignment: both start from the known start pose in the world frame).
pub fn ate_m(estimate: &[StampedPose], truth: &[StampedPose]) -> Option<f64> {
    let mut sum = 0.0;
    let mut n = 0usize;
    for p in estimate {
        let Some(t) = pose_within(truth, p.t_s) else {
            continue;
        };
        sum += (p.pose.x - t.x).powi(2) + (p.pose.y - t.y).powi(2);
        n += 1;
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(t_s: f64, x: f64) -> StampedPose {
        StampedPose {
            t_s,
            pose: Pose2::new(x, 0.0, 0.0),
        }
    }

    /// A truth that starts after the run and ends before it (a real log's corrected poses)
    /// scores only the estimate's poses it covers: none is compared with a held end pose.
    #[test]
    fn the_ate_counts_only_where_the_truth_is() {
        let truth = [at(10.0, 1.0), at(20.0, 2.0)];
        // 3 m off before the truth starts, 0.5 m within it, 3 m off after it ends.
        let estimate = [
            at(0.0, 4.0),
            at(10.0, 1.5),
            at(15.0, 2.0),
            at(20.0, 2.5),
            at(30.0, 5.0),
        ];
        assert!((ate_m(&estimate, &truth).unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(ate_m(&estimate[..1], &truth), None);
        assert_eq!(ate_m(&estimate, &[]), None);
        let aligned = align_se2(&estimate, &truth).unwrap();
        assert!((aligned.x + 0.5).abs() < 1e-12 && aligned.theta.abs() < 1e-12);
    }
}
