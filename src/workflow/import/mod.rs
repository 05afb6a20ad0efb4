//! A robot's log brought in as a run dataset: ROS 2 bags ([`bag`]), ASL folders ([`asl`]) and
//! CARMEN logs (Radish and the classic 2D SLAM data sets, [`carmen`]), a laser optionally turned
//! into sonar-like readings so the paper's method runs on real buildings.

pub mod asl;
pub mod bag;
pub mod carmen;

pub use asl::{import_asl, AslRequest, AslSummary};
pub use bag::{import_bag, BagRequest, BagSummary, BagTopics};
pub use carmen::{import_carmen, CarmenRequest, CarmenSummary};

use crate::geometry::StampedPose;
use crate::io;
use crate::io::carmen::LaserScan;
use crate::sonar::{SonarLayout, SonarReading};

/// Poses in time order: those earlier than one before them by up to
/// [`io::REORDER_TOLERANCE_S`] re-ordered, those further back left out, both counted.
pub(crate) struct TimeOrdered {
    /// The poses, in time order.
    pub poses: Vec<StampedPose>,
    /// Poses re-ordered.
    pub reordered: usize,
    /// Poses left out.
    pub dropped: usize,
    /// The time of the first left out.
    pub first_dropped_s: f64,
}

/// x, y and heading of a 3D pose (a log's pose of the robot or a sensor, seen from above).
pub(crate) fn flat(p: &nalgebra::Isometry3<f64>) -> crate::geometry::Pose2 {
    let r = p.rotation.to_rotation_matrix();
    crate::geometry::Pose2::new(p.translation.x, p.translation.y, r[(1, 0)].atan2(r[(0, 0)]))
}

/// The odometry in the run's frame, and that frame said in words: with a ground truth, the
/// truth's frame, the odometry moved to start at the truth's pose at its first time (`truth_name`
/// names the truth); without, the robot's pose at the first odometry pose (the odometry moved to
/// start at the origin).
pub(crate) fn anchored(
    odometry: &[StampedPose],
    truth: &[StampedPose],
    truth_name: &str,
) -> (Vec<StampedPose>, String) {
    let Some(first) = odometry.first() else {
        return (Vec::new(), String::new());
    };
    let (world_from_odom, frame) = match crate::geometry::pose_at(truth, first.t_s) {
        Some(start) => (
            start.compose(&first.pose.inverse()),
            format!("the ground truth's frame ({truth_name}): the odometry starts at its pose"),
        ),
        None => (
            first.pose.inverse(),
            "the robot's pose at the first odometry pose (the odometry moved to start at the origin)"
                .to_owned(),
        ),
    };
    let poses = crate::geometry::transformed(world_from_odom, odometry);
    (poses, frame)
}

pub(crate) fn time_ordered(logged: Vec<StampedPose>) -> TimeOrdered {
    let mut latest = f64::NEG_INFINITY;
    let mut out = TimeOrdered {
        poses: Vec::with_capacity(logged.len()),
        reordered: 0,
        dropped: 0,
        first_dropped_s: f64::NAN,
    };
    for p in logged {
        if p.t_s < latest - io::REORDER_TOLERANCE_S {
            if out.dropped == 0 {
                out.first_dropped_s = p.t_s;
            }
            out.dropped += 1;
            continue;
        }
        if p.t_s < latest {
            out.reordered += 1;
        }
        latest = latest.max(p.t_s);
        out.poses.push(p);
    }
    out.poses.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    out
}

/// Each scan as one reading per sonar whose beam axis the laser sees: the nearest laser return
/// inside the sonar's cone, measured from the sonar, or no echo when none is within its range.
/// Also the sensors no scan sees.
pub(crate) fn sonar_readings(
    scans: &[LaserScan],
    layout: &SonarLayout,
    start_s: f64,
) -> (Vec<SonarReading>, Vec<usize>) {
    let mut readings = Vec::new();
    let mut seen = vec![false; layout.sensors.len()];
    for scan in scans {
        // The returns in the robot frame.
        let points: Vec<[f64; 2]> = scan
            .ranges_m
            .iter()
            .enumerate()
            .filter(|(_, &r)| r > 0.0)
            .map(|(i, &r)| {
                let a = scan.start_rad + i as f64 * scan.step_rad;
                let p = scan
                    .laser_in_robot
                    .transform_point(nalgebra::Point2::new(r * a.cos(), r * a.sin()));
                [p.x, p.y]
            })
            .collect();
        let fov = field_of_view(scan);
        for (k, sensor) in layout.sensors.iter().enumerate() {
            if !fov.sees(sensor.bearing_rad) {
                continue;
            }
            seen[k] = true;
            let nearest = points
                .iter()
                .filter_map(|p| {
                    let (dx, dy) = (p[0] - sensor.x_m, p[1] - sensor.y_m);
                    let off = crate::geometry::wrap_angle(dy.atan2(dx) - sensor.bearing_rad);
                    (off.abs() <= 0.5 * layout.cone_rad).then(|| dx.hypot(dy))
                })
                .fold(f64::INFINITY, f64::min);
            readings.push(SonarReading {
                t_s: scan.t_s - start_s,
                sensor: k,
                range_m: (nearest <= layout.max_range_m).then_some(nearest),
            });
        }
    }
    let unseen = (0..seen.len()).filter(|&k| !seen[k]).collect();
    (readings, unseen)
}

/// The bearings a scan covers, in the robot frame.
struct FieldOfView {
    /// The middle bearing.
    middle_rad: f64,
    /// Half the width.
    half_rad: f64,
    /// The step between two ranges.
    step_rad: f64,
}

impl FieldOfView {
    /// Whether a beam axis at `bearing_rad` is in view, to a step of the laser's.
    fn sees(&self, bearing_rad: f64) -> bool {
        crate::geometry::wrap_angle(bearing_rad - self.middle_rad).abs()
            <= self.half_rad + self.step_rad + 1e-9
    }
}

fn field_of_view(scan: &LaserScan) -> FieldOfView {
    let width = scan.step_rad * scan.ranges_m.len().saturating_sub(1) as f64;
    FieldOfView {
        middle_rad: scan.laser_in_robot.theta + scan.start_rad + 0.5 * width,
        half_rad: 0.5 * width.abs(),
        step_rad: scan.step_rad.abs(),
    }
}

/// How far a run's odometry strays from its ground truth, over the ground truth's path. No wheel
/// odometry follows a ground truth within centimetres over hundreds of metres. A corrected CARMEN
/// log's `ODOM` lines are reset to the corrected pose at every scan, so its odometry does
/// (freiburg-079: 4.5 cm RMS over 422 m; aces: 7.3 cm over 323 m), and its steps carry the
/// correction's jitter from one scan to the next instead of the wheels' noise.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct OdometryAgainstTruth {
    /// The RMS of the odometry's position error at the ground truth's stamps, metres.
    pub rms_m: f64,
    /// The ground truth's path length, metres.
    pub path_m: f64,
    /// Whether the odometry follows the ground truth as no wheel odometry does: an RMS error
    /// within 0.1% of the path, over at least 50 m.
    pub follows: bool,
}

/// An odometry whose RMS error is within this share of the path it covers follows its ground
/// truth (0.1%; wheels on a good floor err by 1-5% of the distance, the simulated ones by about
/// 0.5%; the corrected Radish logs' odometry by 0.01-0.02%).
const FOLLOWS_SHARE: f64 = 0.001;
/// ... over at least this path, metres.
const FOLLOWS_PATH_M: f64 = 50.0;

/// How far `odometry` strays from `truth` (the same frame): its RMS error at the truth's stamps
/// ([`crate::metrics::ate_m`]) against the truth's path; `None` when they share no time.
pub(crate) fn odometry_against_truth(
    odometry: &[StampedPose],
    truth: &[StampedPose],
) -> Option<OdometryAgainstTruth> {
    let rms_m = crate::metrics::ate_m(odometry, truth)?;
    let path_m = crate::geometry::path_length_m(truth);
    Some(OdometryAgainstTruth {
        rms_m,
        path_m,
        follows: path_m >= FOLLOWS_PATH_M && rms_m <= FOLLOWS_SHARE * path_m,
    })
}

/// [`odometry_against_truth`], warned about when the odometry (`odometry`, named for the
/// message) follows the ground truth (`truth`) as no wheel odometry does; `why` says what may
/// have made it so.
pub(crate) fn check_odometry_against_truth(
    (odometry, named): (&[StampedPose], &str),
    truth: Option<(&[StampedPose], &str)>,
    why: &str,
) -> Option<OdometryAgainstTruth> {
    let (truth, truth_named) = truth?;
    let against = odometry_against_truth(odometry, truth)?;
    if against.follows {
        tracing::warn!(
            "{named} follows {truth_named} within {:.3} m RMS over {:.0} m, as no wheel odometry \
             does, so a survey or localisation scored on it tests little of what it corrects: \
             {why}",
            against.rms_m,
            against.path_m
        );
    }
    Some(against)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;

    fn scan(ranges: Vec<f64>) -> LaserScan {
        let n = ranges.len();
        LaserScan {
            t_s: 10.0,
            start_rad: -std::f64::consts::FRAC_PI_2,
            step_rad: std::f64::consts::PI / (n - 1) as f64,
            ranges_m: ranges,
            pose: Pose2::new(0.0, 0.0, 0.0),
            laser_in_robot: Pose2::new(0.0, 0.0, 0.0),
            line: 1,
        }
    }

    #[test]
    fn each_sonar_takes_the_nearest_return_in_its_cone() {
        // 181 beams, 1 degree apart: a wall 1.5 m ahead, one beam at 10 degrees left at 0.9 m.
        let mut ranges = vec![30.0; 181];
        for r in &mut ranges[75..=105] {
            *r = 1.5;
        }
        ranges[100] = 0.9;
        let layout = SonarLayout::frontal5();
        let (readings, unseen) = sonar_readings(&[scan(ranges)], &layout, 4.0);
        assert!(unseen.is_empty());
        assert_eq!(readings.len(), 5);
        let ahead = readings.iter().find(|r| r.sensor == 2).unwrap();
        assert_eq!(ahead.t_s, 6.0);
        // The sonar sits 0.2 m ahead of the centre: the 0.9 m return at 10 degrees is its nearest.
        let expect = {
            let (x, y) = (
                0.9 * 10f64.to_radians().cos(),
                0.9 * 10f64.to_radians().sin(),
            );
            (x - 0.2).hypot(y)
        };
        assert!((ahead.range_m.unwrap() - expect).abs() < 1e-9);
        // The side sonars see only the far returns: no echo within 2.1 m.
        assert!(readings
            .iter()
            .find(|r| r.sensor == 0)
            .unwrap()
            .range_m
            .is_none());
    }

    #[test]
    fn sonars_behind_a_front_laser_are_left_out() {
        let layout = SonarLayout::pioneer16();
        let (readings, unseen) = sonar_readings(&[scan(vec![3.0; 181])], &layout, 0.0);
        // The eight front sonars (bearings -90..90 degrees) are seen, the rear ones not (the two
        // rear side sonars at +-90 degrees face the laser's edges and count as seen).
        assert_eq!(readings.len() + unseen.len(), 16);
        assert!(unseen
            .iter()
            .all(|&k| layout.sensors[k].bearing_rad.cos() < 0.0));
    }

    /// A straight 100 m drive along x, a pose every 10 cm, its odometry `odometry(x)`.
    fn drive(odometry: impl Fn(f64) -> Pose2) -> (Vec<StampedPose>, Vec<StampedPose>) {
        let at = |k: usize, pose: Pose2| StampedPose {
            t_s: 0.1 * k as f64,
            pose,
        };
        let xs = (0..=1000).map(|k| (k, 0.1 * k as f64));
        (
            xs.clone()
                .map(|(k, x)| at(k, Pose2::new(x, 0.0, 0.0)))
                .collect(),
            xs.map(|(k, x)| at(k, odometry(x))).collect(),
        )
    }

    #[test]
    fn an_odometry_reset_to_the_truth_follows_it_and_wheels_do_not() {
        // A corrected log's odometry: the truth with centimetres of jitter, no drift.
        let (truth, jittered) =
            drive(|x| Pose2::new(x + 0.03 * (7.0 * x).sin(), 0.03 * (5.0 * x).cos(), 0.0));
        let a = odometry_against_truth(&jittered, &truth).unwrap();
        assert!((a.path_m - 100.0).abs() < 1e-9, "{a:?}");
        assert!(a.rms_m > 0.02 && a.rms_m < 0.05 && a.follows, "{a:?}");
        // Wheels 1% short, their heading drifting 2 mrad a metre: metres off at the end.
        let (truth, wheels) = drive(|x| Pose2::new(0.99 * x, 0.002 * x * x / 2.0, 0.0));
        let a = odometry_against_truth(&wheels, &truth).unwrap();
        assert!(!a.follows && a.rms_m > 0.5, "{a:?}");
        // A short run says nothing either way.
        let (truth, same) = drive(|x| Pose2::new(x, 0.0, 0.0));
        let short = odometry_against_truth(&same[..100], &truth[..100]).unwrap();
        assert!(!short.follows && short.rms_m < 1e-12, "{short:?}");
        assert!(odometry_against_truth(&[], &truth).is_none());
    }
}

/// What became of a log's laser scans as a run's lidar (`import.json`'s `lidar`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LidarImport {
    /// Scans written to `lidar.csv`.
    pub scans: usize,
    /// Beams per scan.
    pub beams: usize,
    /// Ranges with a return.
    pub returns: usize,
    /// Ranges with none (at or beyond the laser's largest value, below its least, or invalid).
    pub no_returns: usize,
    /// Scans left out: another laser's (another mounting, field of view or beam count than the
    /// first scan's).
    pub scans_left_out: usize,
    /// The laser's largest value, metres: a range at or beyond it is no return.
    pub range_max_m: f64,
}

/// Laser scans as a run's lidar: the laser described by the first scan (its mounting, angles and
/// beam count; `range_min_m` and `range_max_m` as the log gives them), its scans with times from
/// `start_s`. Ranges outside `[range_min_m, range_max_m)` are no returns. Scans of another
/// geometry (a rear laser, a second scanner) are left out and counted. `None` without scans.
pub(crate) fn lidar_of(
    scans: &[LaserScan],
    range_min_m: f64,
    range_max_m: f64,
    start_s: f64,
) -> Option<(
    crate::dataset::LidarDescription,
    Vec<crate::dataset::LidarScan>,
    LidarImport,
)> {
    let first = scans.first()?;
    let lidar = crate::dataset::LidarDescription {
        x_m: first.laser_in_robot.x,
        y_m: first.laser_in_robot.y,
        yaw_rad: first.laser_in_robot.theta,
        angle_min_rad: first.start_rad,
        angle_increment_rad: first.step_rad,
        beams: first.ranges_m.len(),
        range_min_m,
        range_max_m,
        mapped_range_m: crate::dataset::LIDAR_MAPPED_RANGE_M,
    };
    let same = |s: &LaserScan| {
        let (a, b) = (s.laser_in_robot, first.laser_in_robot);
        s.ranges_m.len() == first.ranges_m.len()
            && (s.start_rad - first.start_rad).abs() < 1e-4
            && (s.step_rad - first.step_rad).abs() < 1e-6
            && (a.x - b.x).hypot(a.y - b.y) < 0.01
            && crate::geometry::wrap_angle(a.theta - b.theta).abs() < 0.01
    };
    let mut out = Vec::with_capacity(scans.len());
    let (mut returns, mut none) = (0, 0);
    for s in scans.iter().filter(|s| same(s)) {
        let ranges_m: Vec<Option<f64>> = s
            .ranges_m
            .iter()
            .map(|&r| {
                (r.is_finite() && r > 0.0 && r >= range_min_m && r < range_max_m).then_some(r)
            })
            .collect();
        let n = ranges_m.iter().filter(|r| r.is_some()).count();
        returns += n;
        none += ranges_m.len() - n;
        out.push(crate::dataset::LidarScan {
            t_s: s.t_s - start_s,
            ranges_m,
        });
    }
    let summary = LidarImport {
        scans: out.len(),
        beams: lidar.beams,
        returns,
        no_returns: none,
        scans_left_out: scans.len() - out.len(),
        range_max_m,
    };
    Some((lidar, out, summary))
}
