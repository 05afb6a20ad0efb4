//! Trajectory errors against the truth: the absolute trajectory error (ATE) and the rigid
//! alignment that separates a survey's anchoring from its shape.

use crate::geometry::{pose_within, Pose2, StampedPose};
use nalgebra::Vector2;

/// One place an estimate is scored against the truth ([`at_truth`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scored {
    /// The truth's time stamp, seconds.
    pub t_s: f64,
    /// The estimate's pose nearest in time (for what it reports with each pose: a sigma, a
    /// covariance).
    pub index: usize,
    /// The estimate at `t_s`, interpolated between its poses.
    pub estimate: Pose2,
    /// The truth at `t_s`.
    pub truth: Pose2,
}

/// Where an estimate is scored against a truth: at each of the truth's own time stamps within
/// the estimate's span, the estimate interpolated there. The truth is a measurement at its
/// stamps and nowhere between: a real log's corrected poses come with its laser scans, seconds
/// apart (aces: a median 2.2 s, 17 gaps over 10 s), and interpolated across such a gap the truth
/// cuts the corners the robot drove (aces' own odometry scored 0.20 m at its 7,050 odometry
/// stamps, 0.07 m at the 440 stamps of its truth). An estimate is sampled at its odometry's
/// rate, so its own interpolation spans a fraction of a second. Where both share their stamps (a
/// simulated run), this scores the estimate at its own poses.
pub fn at_truth<'a>(
    estimate: &'a [StampedPose],
    truth: &'a [StampedPose],
) -> impl Iterator<Item = Scored> + 'a {
    truth.iter().filter_map(move |g| {
        let at = pose_within(estimate, g.t_s)?;
        let after = estimate.partition_point(|p| p.t_s < g.t_s);
        let index = match after {
            0 => 0,
            i if i == estimate.len() => i - 1,
            i if estimate[i].t_s - g.t_s < g.t_s - estimate[i - 1].t_s => i,
            i => i - 1,
        };
        Some(Scored {
            t_s: g.t_s,
            index,
            estimate: at,
            truth: g.pose,
        })
    })
}

/// The rigid motion `truth_from_estimate` that best aligns an estimate's positions with the truth
/// at the truth's times ([`at_truth`]; least squares, closed form), for diagnostics: what of an
/// error is a shift and turn of the whole survey, and what is shape.
pub fn align_se2(estimate: &[StampedPose], truth: &[StampedPose]) -> Option<Pose2> {
    let pairs: Vec<(Vector2<f64>, Vector2<f64>)> = at_truth(estimate, truth)
        .map(|s| {
            (
                Vector2::new(s.estimate.x, s.estimate.y),
                Vector2::new(s.truth.x, s.truth.y),
            )
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

/// Root-mean-square position error of `estimate` against `truth` at the truth's times within
/// the estimate's span ([`at_truth`]; no alignment: both start from the known start pose in the
/// world frame).
pub fn ate_m(estimate: &[StampedPose], truth: &[StampedPose]) -> Option<f64> {
    let mut sum = 0.0;
    let mut n = 0usize;
    for s in at_truth(estimate, truth) {
        sum += (s.estimate.x - s.truth.x).powi(2) + (s.estimate.y - s.truth.y).powi(2);
        n += 1;
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A truth that starts after the run and ends before it (a real log's corrected poses)
    /// scores only the estimate's poses it covers: none is compared with a held end pose.
    #[test]
    fn the_ate_counts_only_where_the_truth_is() {
        let truth = [
            StampedPose::along_x(10.0, 1.0),
            StampedPose::along_x(20.0, 2.0),
        ];
        // 3 m off before the truth starts, 0.5 m within it, 3 m off after it ends.
        let estimate = [
            StampedPose::along_x(0.0, 4.0),
            StampedPose::along_x(10.0, 1.5),
            StampedPose::along_x(15.0, 2.0),
            StampedPose::along_x(20.0, 2.5),
            StampedPose::along_x(30.0, 5.0),
        ];
        assert!((ate_m(&estimate, &truth).unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(ate_m(&estimate[..1], &truth), None);
        assert_eq!(ate_m(&estimate, &[]), None);
        let aligned = align_se2(&estimate, &truth).unwrap();
        assert!((aligned.x + 0.5).abs() < 1e-12 && aligned.theta.abs() < 1e-12);
    }

    /// A truth measured only at the ends of a stretch round a corner (a real log's corrected
    /// poses, seconds apart) scores an estimate that drove the corner exactly as exact: the
    /// chord between the truth's stamps is nobody's path.
    #[test]
    fn a_truth_is_scored_at_its_stamps_not_across_its_gaps() {
        // 1 m/s east for 2 s, then north for 2 s; the estimate every 0.5 s, the truth at 0 and 4 s.
        let path = |t: f64| Pose2::new(t.min(2.0), (t - 2.0).max(0.0), 0.0);
        let estimate: Vec<StampedPose> = (0..=8)
            .map(|k| StampedPose {
                t_s: 0.5 * k as f64,
                pose: path(0.5 * k as f64),
            })
            .collect();
        let truth = [0.0, 4.0].map(|t_s| StampedPose {
            t_s,
            pose: path(t_s),
        });
        assert_eq!(ate_m(&estimate, &truth), Some(0.0));
        let scored: Vec<Scored> = at_truth(&estimate, &truth).collect();
        assert_eq!(scored.iter().map(|s| s.index).collect::<Vec<_>>(), [0, 8]);
        // An estimate between the truth's stamps is scored where it is interpolated.
        let shifted: Vec<StampedPose> = estimate
            .iter()
            .map(|p| StampedPose {
                t_s: p.t_s + 0.25,
                pose: p.pose,
            })
            .collect();
        let s: Vec<Scored> = at_truth(&shifted, &truth).collect();
        assert_eq!(s.len(), 1);
        assert_eq!((s[0].index, s[0].t_s), (7, 4.0));
        assert!((s[0].estimate.y - 1.75).abs() < 1e-12);
    }
}
