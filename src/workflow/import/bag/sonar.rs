//! A bag's sonar: the `Range` topics placed by tf (REP 117's conventions), or a `LaserScan`
//! turned into a sonar ring's readings.

use super::{decimal, mount, topic_error, BagRequest, Gathered, RangeSensor, Roles};
use crate::dataset::{LidarDescription, LidarScan};
use crate::geometry::Pose2;
use crate::io::carmen::LaserScan;
use crate::io::rosbag::Bag;
use crate::sonar::{SonarLayout, SonarReading, SonarSensor};
use crate::workflow::import::{flat, lidar_of, sonar_readings, LidarImport};
use crate::workflow::Result;
use std::collections::BTreeMap;

impl Gathered {
    /// The laser's scans in the robot frame (the laser placed by tf; a laser mounted upside down
    /// sweeps its angles the other way). Invalid ranges (outside the message's limits, inf, NaN)
    /// become 0, no return.
    pub(super) fn laser_scans(
        &self,
        request: &BagRequest<'_>,
        seconds: &dyn Fn(i64) -> f64,
    ) -> Result<Vec<LaserScan>> {
        let (path, base) = (request.bag, request.base_frame.as_str());
        let mut scans = Vec::with_capacity(self.scans.len());
        let mut laser_in_robot: BTreeMap<String, (Pose2, bool)> = BTreeMap::new();
        for (t, frame, s) in &self.scans {
            if !laser_in_robot.contains_key(frame) {
                let m = mount(&self.tf, path, base, frame, "the laser")?;
                let flipped = m.rotation.to_rotation_matrix()[(2, 2)] < 0.0;
                laser_in_robot.insert(frame.clone(), (flat(&m), flipped));
            }
            let (mounting, flipped) = laser_in_robot[frame];
            let sign = if flipped { -1.0 } else { 1.0 };
            let valid = |r: f32| r.is_finite() && r >= s.range_min && r <= s.range_max && r > 0.0;
            scans.push(LaserScan {
                t_s: seconds(*t),
                start_rad: sign * s.angle_min as f64,
                step_rad: sign * s.angle_increment as f64,
                ranges_m: s
                    .ranges
                    .iter()
                    .map(|&r| if valid(r) { decimal(r) } else { 0.0 })
                    .collect(),
                pose: Pose2::new(0.0, 0.0, 0.0),
                laser_in_robot: mounting,
                line: 0,
            });
        }
        Ok(scans)
    }

    /// The laser as the run's lidar, when the bag has one and it is not turned into sonar: the
    /// limits from its first message.
    pub(super) fn lidar(
        &self,
        request: &BagRequest<'_>,
        seconds: &dyn Fn(i64) -> f64,
    ) -> Result<Option<(LidarDescription, Vec<LidarScan>, LidarImport)>> {
        if request.as_sonar.is_some() {
            return Ok(None);
        }
        let Some((_, _, first)) = self.scans.first() else {
            return Ok(None);
        };
        let scans = self.laser_scans(request, seconds)?;
        // A range at range_max is no return (as for a Range message before REP 117).
        let (min, max) = (decimal(first.range_min).max(0.0), decimal(first.range_max));
        Ok(lidar_of(&scans, min, max, 0.0))
    }

    /// The sonar layout and readings (from the `Range` topics, or the laser turned into the
    /// ring asked for), and the readings nearer than their minimum and left out.
    pub(super) fn sonar(
        &self,
        bag: &Bag,
        roles: &Roles,
        request: &BagRequest<'_>,
        seconds: &dyn Fn(i64) -> f64,
    ) -> Result<(SonarLayout, Vec<SonarReading>, usize, usize)> {
        let path = request.bag;
        let base = request.base_frame.as_str();
        if let Some(layout) = &request.as_sonar {
            let scans = self.laser_scans(request, seconds)?;
            let (readings, unseen) = sonar_readings(&scans, layout, 0.0);
            if !unseen.is_empty() {
                tracing::warn!(
                    "{}: the laser does not see the cones of sensors {unseen:?} of {}: they have no readings",
                    path.display(),
                    layout.name
                );
            }
            Ok((layout.clone(), readings, 0, 0))
        } else {
            let mut sensors = Vec::with_capacity(roles.sonar.len());
            let mut first_sensor: Option<RangeSensor> = None;
            for (k, topic) in roles.sonar.iter().enumerate() {
                let Some(s) = self.sensors[k].clone() else {
                    return Err(topic_error(
                        bag,
                        format!(
                            "sonar topic {topic} has no messages: choose the sonars with --sonar"
                        ),
                    ));
                };
                let m = mount(&self.tf, path, base, &s.frame, &format!("sonar {topic}"))?;
                let f = flat(&m);
                sensors.push(SonarSensor {
                    x_m: f.x,
                    y_m: f.y,
                    bearing_rad: f.theta,
                });
                match &first_sensor {
                    None => first_sensor = Some(s),
                    Some(f)
                        if (f.field_of_view - s.field_of_view).abs() > 0.01 * f.field_of_view
                            || (f.max_range - s.max_range).abs() > 0.01 * f.max_range =>
                    {
                        tracing::warn!(
                            "{}: {topic}'s cone ({} rad, {} m) differs from {}'s ({} rad, {} m): a run has one cone for all its sonars; the first is used",
                            path.display(),
                            s.field_of_view,
                            s.max_range,
                            roles.sonar[0],
                            f.field_of_view,
                            f.max_range
                        );
                    }
                    Some(_) => {}
                }
            }
            let Some(first_sensor) = first_sensor else {
                // No sonar: the laser is the run's range sensor.
                let layout = SonarLayout {
                    name: "none".into(),
                    sensors: Vec::new(),
                    ..SonarLayout::frontal5()
                };
                return Ok((layout, Vec::new(), 0, 0));
            };
            let layout = SonarLayout {
                name: "ros2-bag".into(),
                beam: crate::sonar::BeamModel::Cone,
                cone_rad: decimal(first_sensor.field_of_view),
                max_range_m: decimal(first_sensor.max_range),
                min_range_m: decimal(first_sensor.min_range.max(0.0)),
                sensors,
            };
            let (mut too_close, mut left_out) = (0, 0);
            let mut readings = Vec::with_capacity(self.ranges.len());
            for r in &self.ranges {
                let s = self.sensors[r.sensor].as_ref().expect("seen");
                // REP 117: +inf no echo within reach, -inf nearer than the minimum; a finite
                // range at or beyond the maximum is also no echo (drivers before REP 117).
                let range_m = if r.range == f32::INFINITY
                    || (r.range.is_finite() && r.range >= s.max_range)
                {
                    None
                } else if r.range == f32::NEG_INFINITY {
                    too_close += 1;
                    Some(decimal(s.min_range.max(0.0)))
                } else if r.range.is_finite() && r.range >= s.min_range {
                    Some(decimal(r.range))
                } else {
                    left_out += 1;
                    continue;
                };
                readings.push(SonarReading {
                    t_s: seconds(r.stamp_ns),
                    sensor: r.sensor,
                    range_m,
                });
            }
            readings.sort_by(|a, b| a.t_s.total_cmp(&b.t_s).then(a.sensor.cmp(&b.sensor)));
            if left_out > 0 {
                tracing::warn!(
                    "{}: {left_out} Range messages left out: NaN, or finite and below min_range",
                    path.display()
                );
            }
            Ok((layout, readings, too_close, left_out))
        }
    }
}
