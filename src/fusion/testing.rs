//! Runs for the fusion tests: a square loop with biased odometry and a tag at each corner, a
//! corridor along a wall, wall faces and the ranges a sonar ring hears off them.

use crate::fusion::TagSighting;
use crate::geometry::{wrap_angle, Pose2, StampedPose};
use crate::sonar::walls::WallSegment;
use crate::sonar::SonarReading;
use crate::visual::tags::TagFamily;
use crate::visual::vo::VisualTurn;

/// A robot driving 10 m along a wall 0.5 m to its left (odometry, truth, the left sonar's
/// ranges), its odometry drifting 0.01 rad per metre to the right, and the wall's face.
pub(crate) fn corridor() -> (
    crate::sonar::SonarLayout,
    WallSegment,
    Vec<StampedPose>,
    Vec<StampedPose>,
    Vec<SonarReading>,
) {
    let layout = crate::sonar::SonarLayout {
        name: "left".into(),
        beam: crate::sonar::BeamModel::Cone,
        cone_rad: 30f64.to_radians(),
        max_range_m: 2.1,
        min_range_m: 0.0,
        sensors: vec![crate::sonar::SonarSensor {
            x_m: 0.0,
            y_m: 0.2,
            bearing_rad: std::f64::consts::FRAC_PI_2,
        }],
    };
    let wall = WallSegment {
        normal_rad: 1.5 * std::f64::consts::PI,
        offset_m: -0.5,
        from_m: [-1.0, 0.5],
        to_m: [11.0, 0.5],
        readings: 100,
        rms_m: 0.01,
        sigma_m: None,
    };
    let (mut odometry, mut truth, mut readings) = (Vec::new(), Vec::new(), Vec::new());
    let mut odom = Pose2::new(0.0, 0.0, 0.0);
    for k in 0..=200 {
        let t_s = k as f64;
        truth.push(StampedPose {
            t_s,
            pose: Pose2::new(0.05 * k as f64, 0.0, 0.0),
        });
        odometry.push(StampedPose { t_s, pose: odom });
        odom = odom.compose(&Pose2::new(0.05, 0.0, -0.0005));
        readings.push(SonarReading {
            t_s,
            sensor: 0,
            range_m: Some(0.3 + 0.004 * ((k * 7 % 5) as f64 - 2.0)),
        });
    }
    (layout, wall, odometry, truth, readings)
}

/// A square loop driven with a biased odometry, a tag at each corner seen from near it.
pub(crate) fn square_run(
    bias: f64,
    laps: usize,
) -> (
    Vec<StampedPose>,
    Vec<StampedPose>,
    Vec<TagSighting>,
    Vec<[f64; 3]>,
) {
    let tags = vec![
        [5.0, 0.0, std::f64::consts::PI],
        [5.0, 5.0, -std::f64::consts::FRAC_PI_2],
        [0.0, 5.0, 0.0],
        [0.0, 0.0, std::f64::consts::FRAC_PI_2],
    ];
    let mut truth = Vec::new();
    let mut odom = Vec::new();
    let mut t = 0.0;
    let mut gt = Pose2::new(0.5, 0.5, 0.0);
    let mut od = gt;
    for _ in 0..4 * laps {
        {
            for _ in 0..40 {
                let step = Pose2::new(0.1, 0.0, 0.0);
                gt = gt.compose(&step);
                od = od.compose(&Pose2::new(0.1 * (1.0 + bias), 0.0, bias * 0.1));
                t += 1.0;
                truth.push(StampedPose { t_s: t, pose: gt });
                odom.push(StampedPose { t_s: t, pose: od });
            }
            for _ in 0..10 {
                let step = Pose2::new(0.0, 0.0, std::f64::consts::FRAC_PI_2 / 10.0);
                gt = gt.compose(&step);
                od = od.compose(&Pose2::new(0.0, 0.0, step.theta * (1.0 + 3.0 * bias)));
                t += 1.0;
                truth.push(StampedPose { t_s: t, pose: gt });
                odom.push(StampedPose { t_s: t, pose: od });
            }
        }
    }
    let mut sightings = Vec::new();
    for (i, p) in truth.iter().enumerate().step_by(5) {
        for (id, tag) in tags.iter().enumerate() {
            let local = p
                .pose
                .inverse()
                .transform_point(nalgebra::Point2::new(tag[0], tag[1]));
            let range = local.coords.norm();
            if range > 3.5 || local.x < 0.3 || local.y.abs() > local.x {
                continue;
            }
            sightings.push(TagSighting {
                t_s: p.t_s,
                frame: i,
                id: id as u32,
                family: TagFamily::Tag36h11,
                size_m: 0.16,
                position_in_robot_m: [local.x, local.y, 0.5],
                covariance_m2: [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-6]],
                yaw_in_robot_rad: wrap_angle(tag[2] - p.pose.theta),
                yaw_sigma_rad: 0.01,
                pitch_rad: 0.0,
                roll_rad: 0.0,
                corners_px: None,
            });
        }
    }
    (odom, truth, sightings, tags)
}

/// Turns measured along a run every `every` samples, from the truth, with sigma `sigma`.
pub(crate) fn turns_of(truth: &[StampedPose], every: usize, sigma: f64) -> Vec<VisualTurn> {
    truth
        .iter()
        .step_by(every)
        .zip(truth.iter().step_by(every).skip(1))
        .map(|(a, b)| VisualTurn {
            from_t_s: a.t_s,
            to_t_s: b.t_s,
            turn_rad: wrap_angle(b.pose.theta - a.pose.theta),
            sigma_rad: sigma,
        })
        .collect()
}

/// The observations of a run: its odometry, sightings and visual turns.
pub(crate) fn obs<'a>(
    odometry: &'a [StampedPose],
    sightings: &'a [TagSighting],
    visual: &'a [VisualTurn],
) -> crate::fusion::Observations<'a> {
    crate::fusion::Observations {
        odometry,
        sightings,
        visual,
    }
}

/// A surveyed wall face: its normal (degrees), offset and ends.
pub(crate) fn face(
    normal_deg: f64,
    offset_m: f64,
    from_m: [f64; 2],
    to_m: [f64; 2],
) -> WallSegment {
    WallSegment {
        normal_rad: normal_deg.to_radians(),
        offset_m,
        from_m,
        to_m,
        readings: 100,
        rms_m: 0.01,
        sigma_m: None,
    }
}

/// The ranges each sonar of `layout` hears at each pose of `path`: the nearest of `faces` square
/// to its cone (within 15 degrees, 5 cm inside the ends), with a deterministic noise of up to 8 mm.
pub(crate) fn ranges_off_faces(
    path: &[StampedPose],
    layout: &crate::sonar::SonarLayout,
    faces: &[WallSegment],
) -> Vec<SonarReading> {
    let mut readings = Vec::new();
    for (k, p) in path.iter().enumerate() {
        for (i, sensor) in layout.sensors.iter().enumerate() {
            let at = p.pose.compose(&sensor.robot_from_sensor());
            let range = faces
                .iter()
                .filter_map(|w| w.expected_range([at.x, at.y], at.theta, 0.26, 0.05))
                .min_by(f64::total_cmp);
            readings.push(SonarReading {
                t_s: p.t_s,
                sensor: i,
                range_m: range.map(|r| r + 0.004 * (((k * 7 + i) % 5) as f64 - 2.0)),
            });
        }
    }
    readings
}
