//! Sonar sensors: where they sit on the robot, what a reading is, and the cone they see.
//!
//! A sonar sends a cone of sound (30 degrees wide on the paper's robot) and reports the range of
//! the first echo, or nothing. Mapping treats a reading as an arc: somewhere on the arc of radius
//! `range_m` across the cone there is an obstacle, and the cone before the arc is free.

pub mod corners;
pub mod grid;
pub mod hough;
pub mod map;
pub mod tangent;
pub mod walls;

use crate::geometry::{pose_at, Pose2, StampedPose};
use serde::{Deserialize, Serialize};

/// Beam width of the paper's sonars: 30 degrees.
pub const PAPER_CONE_RAD: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// Maximum range of the paper's sonars: about 2.1 m.
pub const PAPER_MAX_RANGE_M: f64 = 2.1;

/// One transducer, in the robot frame (x forward, y left).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SonarSensor {
    /// Position forward of the robot centre, metres.
    pub x_m: f64,
    /// Position left of the robot centre, metres.
    pub y_m: f64,
    /// Direction of the beam axis, radians (0 = forward, positive = left).
    pub bearing_rad: f64,
}

impl SonarSensor {
    /// `robot_from_sensor`.
    pub fn robot_from_sensor(&self) -> Pose2 {
        Pose2::new(self.x_m, self.y_m, self.bearing_rad)
    }
}

/// How a range sensor's beam meets the world.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum BeamModel {
    /// A sonar's cone: the echo comes from somewhere on the arc at the range, from a surface
    /// facing the sensor (the foot of the perpendicular); the cone before the arc is free.
    #[default]
    Cone,
    /// A laser's (or a time-of-flight ranger's) thin ray: the return is the point at the range
    /// along the axis, off a surface at any incidence; the cells the ray crosses before it are
    /// free.
    Ray,
}

impl BeamModel {
    /// Whether this is the sonar cone (the default, left out of `run.yaml`).
    pub fn is_cone(&self) -> bool {
        *self == BeamModel::Cone
    }
}

/// A laser return seen as a surface point: a surface through it faces the ray within this angle
/// (grazing returns beyond it are too rare and too noisy to vote for a wall): 80 degrees.
pub const RAY_INCIDENCE_RAD: f64 = 80.0 * std::f64::consts::PI / 180.0;

/// How near a range may come to the sensor's limits and still be a measured distance
/// ([`SonarLayout::measures`]), metres: a micrometre, the rounding of a log's decimals.
const RANGE_LIMIT_MARGIN_M: f64 = 1e-6;

/// A robot's sonar ring (or, with [`BeamModel::Ray`], the beams of a laser).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SonarLayout {
    /// A name for the layout.
    pub name: String,
    /// The beam model: `cone` (sonar, the default) or `ray` (a laser's beams).
    #[serde(default, skip_serializing_if = "BeamModel::is_cone")]
    pub beam: BeamModel,
    /// Full beam width, radians.
    #[serde(default = "default_cone")]
    pub cone_rad: f64,
    /// Largest range the sensor reports, metres.
    #[serde(default = "default_max_range")]
    pub max_range_m: f64,
    /// Shortest range the sensor reports, metres (0, the default: not known). A transducer
    /// reports anything nearer at this range, so a reading there says only that something is
    /// that near: it is not matched with walls as a distance ([`SonarLayout::measures`]).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub min_range_m: f64,
    /// The transducers; a reading's `sensor` is an index into this list.
    pub sensors: Vec<SonarSensor>,
}

fn default_cone() -> f64 {
    PAPER_CONE_RAD
}
fn default_max_range() -> f64 {
    PAPER_MAX_RANGE_M
}
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Default for SonarLayout {
    fn default() -> Self {
        Self::frontal5()
    }
}

impl SonarLayout {
    /// The paper's robot has five frontal sonars whose bearings it does not give. We choose
    /// -90, -45, 0, 45 and 90 degrees on a 0.2 m radius: the front half-plane is covered in
    /// 45 degree steps, and the two side sonars see the wall being followed.
    pub fn frontal5() -> Self {
        let radius_m = 0.2;
        let sensors = [-90.0f64, -45.0, 0.0, 45.0, 90.0]
            .iter()
            .map(|deg| {
                let b = deg.to_radians();
                SonarSensor {
                    x_m: radius_m * b.cos(),
                    y_m: radius_m * b.sin(),
                    bearing_rad: b,
                }
            })
            .collect();
        Self {
            name: "frontal5".into(),
            beam: BeamModel::Cone,
            cone_rad: PAPER_CONE_RAD,
            max_range_m: PAPER_MAX_RANGE_M,
            min_range_m: 0.0,
            sensors,
        }
    }

    /// The Pioneer 3-DX 16-sonar ring, from the manufacturer's parameter file `p3dx-sh.p`
    /// (ARIA 2.9, `SonarUnit i x_mm y_mm heading_deg`). Polaroid 600-series transducers: we keep the
    /// paper's 30 degree cone and give them a 5 m range.
    pub fn pioneer16() -> Self {
        let units: [(f64, f64, f64); 16] = [
            (69.0, 136.0, 90.0),
            (114.0, 119.0, 50.0),
            (148.0, 78.0, 30.0),
            (166.0, 27.0, 10.0),
            (166.0, -27.0, -10.0),
            (148.0, -78.0, -30.0),
            (114.0, -119.0, -50.0),
            (69.0, -136.0, -90.0),
            (-157.0, -136.0, -90.0),
            (-203.0, -119.0, -130.0),
            (-237.0, -78.0, -150.0),
            (-255.0, -27.0, -170.0),
            (-255.0, 27.0, 170.0),
            (-237.0, 78.0, 150.0),
            (-203.0, 119.0, 130.0),
            (-157.0, 136.0, 90.0),
        ];
        let sensors = units
            .iter()
            .map(|&(x, y, h)| SonarSensor {
                x_m: x / 1000.0,
                y_m: y / 1000.0,
                bearing_rad: h.to_radians(),
            })
            .collect();
        Self {
            name: "pioneer16".into(),
            beam: BeamModel::Cone,
            cone_rad: PAPER_CONE_RAD,
            max_range_m: 5.0,
            min_range_m: 0.0,
            sensors,
        }
    }

    /// The readings the Hough transforms and the wall fit vote with, and the half-width of the
    /// directions each votes for: a sonar's placed readings (but those at its shortest range,
    /// which place no wall) and half its cone; for a laser ([`BeamModel::Ray`]) each return as
    /// a surface point (see [`point_echoes`]) and [`RAY_INCIDENCE_RAD`].
    pub fn echoes_for_lines(&self, placed: &[PlacedReading]) -> (Vec<PlacedReading>, f64) {
        match self.beam {
            BeamModel::Cone => (
                placed
                    .iter()
                    .filter(|r| r.range_m.is_none_or(|x| !self.at_shortest_range(x)))
                    .copied()
                    .collect(),
                0.5 * self.cone_rad,
            ),
            BeamModel::Ray => (
                point_echoes(&keyframe_beams(placed, self.cone_rad), self.max_range_m),
                RAY_INCIDENCE_RAD,
            ),
        }
    }

    /// Whether a range measures a distance: shorter than the largest the sensor reports (at it,
    /// no echo came back within reach) and not at the shortest ([`Self::at_shortest_range`]).
    pub fn measures(&self, range_m: f64) -> bool {
        range_m < self.max_range_m - RANGE_LIMIT_MARGIN_M && !self.at_shortest_range(range_m)
    }

    /// The range of a reading when an echo came back within reach (shorter than the largest the
    /// sensor reports); a range at the shortest is kept, unlike [`Self::measures`].
    pub fn echo(&self, range_m: Option<f64>) -> Option<f64> {
        range_m.filter(|&m| m < self.max_range_m - RANGE_LIMIT_MARGIN_M)
    }

    /// Whether a range is at the sensor's shortest (`min_range_m`, when known): something is at
    /// most that near.
    pub fn at_shortest_range(&self, range_m: f64) -> bool {
        self.min_range_m > 0.0 && range_m <= self.min_range_m + RANGE_LIMIT_MARGIN_M
    }

    /// How many of `ranges` (no echo: `None`) are at the sensor's shortest
    /// ([`Self::at_shortest_range`]).
    pub fn count_at_shortest_range(&self, ranges: impl IntoIterator<Item = Option<f64>>) -> usize {
        ranges
            .into_iter()
            .flatten()
            .filter(|&x| self.at_shortest_range(x))
            .count()
    }

    /// A layout by name: `frontal5` or `pioneer16`.
    pub fn by_name(name: &str) -> Option<Self> {
        match name {
            "frontal5" => Some(Self::frontal5()),
            "pioneer16" => Some(Self::pioneer16()),
            _ => None,
        }
    }
}

/// One sonar reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SonarReading {
    /// Time, seconds.
    pub t_s: f64,
    /// Index into the layout's sensors.
    pub sensor: usize,
    /// Range of the first echo, metres; `None` when no echo came back.
    pub range_m: Option<f64>,
}

/// A reading placed in the world: the sensor pose (`world_from_sensor`) and the range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedReading {
    /// Time, seconds.
    pub t_s: f64,
    /// Pose of the transducer in the world; the beam axis is its x axis.
    pub world_from_sensor: Pose2,
    /// Range, metres; `None` for no echo.
    pub range_m: Option<f64>,
}

/// Readings further than this (seconds) before the trajectory's first pose or after its last
/// have no pose to be placed at and are left out (a log's sonar may start before its odometry).
pub const PLACE_TOLERANCE_S: f64 = 0.5;

/// Whether a reading at `t_s` lies within [`PLACE_TOLERANCE_S`] of the trajectory's span.
pub fn within_trajectory(trajectory: &[StampedPose], t_s: f64) -> bool {
    match (trajectory.first(), trajectory.last()) {
        (Some(a), Some(b)) => t_s >= a.t_s - PLACE_TOLERANCE_S && t_s <= b.t_s + PLACE_TOLERANCE_S,
        _ => false,
    }
}

/// Places readings in the world along a trajectory: each at the robot's pose interpolated at its
/// time (held at the end poses within [`PLACE_TOLERANCE_S`]), composed with its sensor's mount.
/// Readings of unknown sensors, or outside the trajectory's span, are left out.
pub fn place_readings(
    readings: &[SonarReading],
    layout: &SonarLayout,
    trajectory: &[StampedPose],
) -> Vec<PlacedReading> {
    readings
        .iter()
        .filter_map(|r| {
            let sensor = layout.sensors.get(r.sensor)?;
            if !within_trajectory(trajectory, r.t_s) {
                return None;
            }
            let robot = pose_at(trajectory, r.t_s)?;
            Some(PlacedReading {
                t_s: r.t_s,
                world_from_sensor: robot.compose(&sensor.robot_from_sensor()),
                range_m: r.range_m,
            })
        })
        .collect()
}

/// The line transforms take a laser's scans this far apart (or [`RAY_KEYFRAME_RAD`] turned):
/// 0.3 m. A laser sends hundreds of returns a scan, tens of scans a second; what the walls and
/// corners need is every wall seen from a few places.
pub const RAY_KEYFRAME_M: f64 = 0.3;
/// ... or this much turned: 10 degrees.
pub const RAY_KEYFRAME_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// ... and of each scan the beams this far apart: 1 degree (the line accumulators' angle cell).
pub const RAY_BEAM_SPACING_RAD: f64 = std::f64::consts::PI / 180.0;

/// The placed beams of a laser's keyframe scans ([`RAY_KEYFRAME_M`], [`RAY_KEYFRAME_RAD`]), one
/// beam in every [`RAY_BEAM_SPACING_RAD`]. A scan is the run of readings with one time, in beam
/// order (as [`place_readings`] leaves them); its first beam's pose stands for the scan's.
pub fn keyframe_beams(placed: &[PlacedReading], beam_step_rad: f64) -> Vec<PlacedReading> {
    let stride = (RAY_BEAM_SPACING_RAD / beam_step_rad.abs().max(1e-9))
        .round()
        .max(1.0) as usize;
    let mut out = Vec::new();
    let mut last: Option<Pose2> = None;
    for scan in placed.chunk_by(|a, b| a.t_s == b.t_s) {
        let p = scan[0].world_from_sensor;
        let moved = last.is_none_or(|q| {
            (p.x - q.x).hypot(p.y - q.y) >= RAY_KEYFRAME_M
                || crate::geometry::wrap_angle(p.theta - q.theta).abs() >= RAY_KEYFRAME_RAD
        });
        if moved {
            last = Some(p);
            out.extend(scan.iter().step_by(stride).copied());
        }
    }
    out
}

/// A laser's returns as the line transforms see them: each return below `max_range_m` becomes a
/// reading at the return itself, looking along its ray, with range zero. A sonar echo votes for
/// the lines tangent to its arc for each direction in its cone; at range zero those are the lines
/// through the point, one per direction, which is exactly what a laser return says (a surface
/// through this point, facing the ray within [`RAY_INCIDENCE_RAD`]). The tangent-line Hough
/// transforms, the point Hough transform and the wall fit then need no other change.
pub fn point_echoes(placed: &[PlacedReading], max_range_m: f64) -> Vec<PlacedReading> {
    placed
        .iter()
        .filter_map(|r| {
            let range = r
                .range_m
                .filter(|x| x.is_finite() && *x >= 0.0 && *x < max_range_m)?;
            let p = r.world_from_sensor;
            Some(PlacedReading {
                t_s: r.t_s,
                world_from_sensor: Pose2::new(
                    p.x + range * p.theta.cos(),
                    p.y + range * p.theta.sin(),
                    p.theta,
                ),
                range_m: Some(0.0),
            })
        })
        .collect()
}

/// A run's sonar: where the sensors sit and what they read, time-ordered.
#[derive(Debug, Clone, Copy)]
pub struct SonarLog<'a> {
    /// The sensors.
    pub layout: &'a SonarLayout,
    /// The readings.
    pub readings: &'a [SonarReading],
}

impl SonarLog<'_> {
    /// Every reading placed in the world along `trajectory` ([`place_readings`]).
    pub fn placed(&self, trajectory: &[StampedPose]) -> Vec<PlacedReading> {
        place_readings(self.readings, self.layout, trajectory)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;

    #[test]
    fn readings_outside_the_trajectory_are_left_out() {
        let trajectory: Vec<StampedPose> = (0..=10)
            .map(|i| StampedPose {
                t_s: 10.0 + i as f64,
                pose: Pose2::new(i as f64, 0.0, 0.0),
            })
            .collect();
        let readings: Vec<SonarReading> = [8.0, 9.6, 10.0, 15.0, 20.4, 21.0]
            .iter()
            .map(|&t_s| SonarReading {
                t_s,
                sensor: 2,
                range_m: Some(1.0),
            })
            .collect();
        let placed = place_readings(&readings, &SonarLayout::frontal5(), &trajectory);
        // 8.0 and 21.0 are over 0.5 s outside 10..20 s; 9.6 and 20.4 are held at the ends.
        let times: Vec<f64> = placed.iter().map(|r| r.t_s).collect();
        assert_eq!(times, vec![9.6, 10.0, 15.0, 20.4]);
        assert!((placed[0].world_from_sensor.x - 0.2).abs() < 1e-12);
        assert!((placed[2].world_from_sensor.x - 5.2).abs() < 1e-12);
    }
}
