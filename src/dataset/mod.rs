//! A robot run: what the robot logged, in the form of DESIGN.md's run dataset.
//!
//! Poses are stamped `world_from_robot` transforms. Sonar readings are placed in the world by
//! interpolating a trajectory at the reading's time and composing with the sensor's mount.

use crate::geometry::{Pose2, StampedPose};
use crate::sonar::{BeamModel, PlacedReading, SonarLayout, SonarLog, SonarReading, SonarSensor};
use serde::{Deserialize, Serialize};

/// Version tag written into `run.yaml`.
pub const RUN_FORMAT: &str = "stereotag-run/1";

/// One stereo pair of the run.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoEntry {
    /// Time, seconds.
    pub t_s: f64,
    /// Left image, relative to the run directory.
    pub left: String,
    /// Right image, relative to the run directory.
    pub right: String,
}

/// A 2D laser scanner (lidar) as `run.yaml` describes it (`robot.lidar`); its scans are in
/// `lidar.csv`. Angles follow ROS `LaserScan`: in the laser's frame, 0 along its x axis, positive
/// to the left, beam `k` at `angle_min_rad + k * angle_increment_rad`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LidarDescription {
    /// Laser position forward of the robot centre, metres.
    pub x_m: f64,
    /// Laser position left of the robot centre, metres.
    pub y_m: f64,
    /// Direction of the laser's x axis in the robot frame, radians (0 forward, positive left).
    pub yaw_rad: f64,
    /// Bearing of the first beam in the laser's frame, radians.
    pub angle_min_rad: f64,
    /// Angle from one beam to the next, radians (negative for a laser sweeping right, as one
    /// mounted upside down does).
    pub angle_increment_rad: f64,
    /// Beams per scan: the columns of `lidar.csv` after the time.
    pub beams: usize,
    /// Returns nearer than this are not returns (the laser's own housing), metres.
    #[serde(default)]
    pub range_min_m: f64,
    /// Returns at or beyond this are no returns (the laser's largest value), metres.
    pub range_max_m: f64,
    /// Returns beyond this are not mapped, metres: 10 m by default (a 0.5 degree beam is then
    /// 9 cm wide and its angle error a cell of the paper's grid; gmapping's `maxUrange` is the
    /// same idea). They are counted and said when a run is read.
    #[serde(default = "default_mapped_range")]
    pub mapped_range_m: f64,
}

fn default_mapped_range() -> f64 {
    LIDAR_MAPPED_RANGE_M
}

/// Returns beyond this are not mapped by default: 10 m.
pub const LIDAR_MAPPED_RANGE_M: f64 = 10.0;

impl LidarDescription {
    /// `robot_from_laser`.
    pub fn robot_from_laser(&self) -> Pose2 {
        Pose2::new(self.x_m, self.y_m, self.yaw_rad)
    }

    /// The largest range used: the mapped range, or less when the laser reaches less.
    pub fn reach_m(&self) -> f64 {
        self.mapped_range_m.min(self.range_max_m)
    }

    /// The laser's beams as a range-sensor layout: one sensor per beam, each a thin ray
    /// ([`BeamModel::Ray`]) as wide as the angle between beams, reaching [`Self::reach_m`]. The
    /// grids, Hough transforms, walls and localisation then take the laser as they take sonar.
    pub fn beam_layout(&self) -> SonarLayout {
        let mount = self.robot_from_laser();
        SonarLayout {
            name: "lidar".into(),
            beam: BeamModel::Ray,
            cone_rad: self.angle_increment_rad.abs(),
            max_range_m: self.reach_m(),
            min_range_m: 0.0,
            sensors: (0..self.beams)
                .map(|k| {
                    let b = mount.compose(&Pose2::new(
                        0.0,
                        0.0,
                        self.angle_min_rad + k as f64 * self.angle_increment_rad,
                    ));
                    SonarSensor {
                        x_m: b.x,
                        y_m: b.y,
                        bearing_rad: b.theta,
                    }
                })
                .collect(),
        }
    }

    /// What `run.yaml`'s values must satisfy; the reason when they do not.
    pub fn check(&self) -> Result<(), String> {
        let finite = [
            self.x_m,
            self.y_m,
            self.yaw_rad,
            self.angle_min_rad,
            self.angle_increment_rad,
            self.range_min_m,
            self.range_max_m,
            self.mapped_range_m,
        ]
        .iter()
        .all(|v| v.is_finite());
        if !finite {
            return Err("every value must be a finite number".into());
        }
        if self.beams == 0 || self.angle_increment_rad == 0.0 {
            return Err("beams must be at least 1 and angle_increment_rad not zero".into());
        }
        if !(self.range_min_m >= 0.0
            && self.range_max_m > self.range_min_m
            && self.mapped_range_m > 0.0)
        {
            return Err(
                "ranges must satisfy 0 <= range_min_m < range_max_m and mapped_range_m > 0".into(),
            );
        }
        Ok(())
    }
}

/// One laser scan: its time and a range per beam (`None`: no return).
#[derive(Debug, Clone, PartialEq)]
pub struct LidarScan {
    /// Time, seconds.
    pub t_s: f64,
    /// Range of each beam, metres; `None` where no return came back.
    pub ranges_m: Vec<Option<f64>>,
}

/// Which range sensor the sonar half (grids, Hough features, walls, localisation) reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum RangeSensor {
    /// The sonar ring (`sonar.csv`).
    Sonar,
    /// The laser (`lidar.csv`).
    Lidar,
}

impl RangeSensor {
    /// The sensor's name in messages: "sonar" or "lidar".
    pub fn name(self) -> &'static str {
        match self {
            Self::Sonar => "sonar",
            Self::Lidar => "lidar",
        }
    }
}

impl From<BeamModel> for RangeSensor {
    /// The sensor whose beams a layout models: a cone is a sonar's, a ray a laser's.
    fn from(beam: BeamModel) -> Self {
        match beam {
            BeamModel::Cone => Self::Sonar,
            BeamModel::Ray => Self::Lidar,
        }
    }
}

/// The robot as `run.yaml` describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RobotDescription {
    /// The sonar ring.
    pub sonar: SonarLayout,
    /// The 2D laser, if the robot has one (its scans in `lidar.csv`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lidar: Option<LidarDescription>,
    /// Which range sensor maps and localises: by default the lidar when there is one, else the
    /// sonar.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ranging: Option<RangeSensor>,
    /// Stereo rig file (Kalibr camchain YAML), relative to the run directory.
    #[serde(default)]
    pub rig: Option<String>,
    /// `robot_from_left` as `[x, y, z, roll, pitch, yaw]` (metres, radians), if not in the rig file.
    #[serde(default)]
    pub robot_from_left: Option<[f64; 6]>,
}

/// The contents of `run.yaml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunMeta {
    /// Format tag, [`RUN_FORMAT`].
    pub format: String,
    /// The robot.
    pub robot: RobotDescription,
    /// World file, relative to the run directory, when the place is known.
    #[serde(default)]
    pub world: Option<String>,
    /// Mapping settings suggested for this run (grid and Hough), if any.
    #[serde(default)]
    pub mapping: Option<crate::sonar::map::MappingConfig>,
    /// Free text.
    #[serde(default)]
    pub notes: String,
}

/// Which trajectory places the readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PoseSource {
    /// The robot's dead reckoning.
    Odometry,
    /// Ground truth (simulation, motion capture).
    GroundTruth,
}

impl PoseSource {
    /// `odometry` or `ground-truth`, as `map --poses` takes it.
    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Odometry => "odometry",
            Self::GroundTruth => "ground-truth",
        }
    }
}

/// A whole run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunDataset {
    /// `run.yaml`.
    pub meta: RunMeta,
    /// `odometry.csv`, time-ordered.
    pub odometry: Vec<StampedPose>,
    /// `sonar.csv`, time-ordered.
    pub sonar: Vec<SonarReading>,
    /// `stereo.csv`.
    pub stereo: Vec<StereoEntry>,
    /// `ground_truth.csv`, when known.
    pub ground_truth: Option<Vec<StampedPose>>,
    /// `lidar.csv`, time-ordered, when the robot has a lidar.
    pub lidar: Vec<LidarScan>,
}

impl RunDataset {
    /// The trajectory of a pose source, if the run has it.
    pub fn trajectory(&self, source: PoseSource) -> Option<&[StampedPose]> {
        match source {
            PoseSource::Odometry => Some(&self.odometry),
            PoseSource::GroundTruth => self.ground_truth.as_deref(),
        }
    }

    /// The run's sonar: its layout and readings.
    pub fn sonar_log(&self) -> SonarLog<'_> {
        SonarLog {
            layout: &self.meta.robot.sonar,
            readings: &self.sonar,
        }
    }

    /// The range sensor the sonar half reads: `run.yaml`'s `robot.ranging`, else the lidar when
    /// the robot has one, else the sonar.
    pub fn ranging(&self) -> RangeSensor {
        let robot = &self.meta.robot;
        robot.ranging.unwrap_or(match robot.lidar {
            Some(_) => RangeSensor::Lidar,
            None => RangeSensor::Sonar,
        })
    }

    /// The run with its lidar in place of its sonar ([`LidarDescription::beam_layout`], one
    /// reading per beam and scan) when the lidar is the range sensor ([`Self::ranging`]); the
    /// sonar half then reads the laser. Returns the run and the returns beyond the mapped range
    /// (left out of the readings, as no return). Unchanged without a lidar.
    pub fn with_lidar_as_ranges(mut self) -> (Self, usize) {
        let Some(lidar) = self.meta.robot.lidar.clone() else {
            return (self, 0);
        };
        if self.ranging() != RangeSensor::Lidar {
            return (self, 0);
        }
        let reach = lidar.reach_m();
        let mut beyond = 0;
        let mut readings = Vec::with_capacity(self.lidar.len() * lidar.beams);
        for scan in &self.lidar {
            for (sensor, &r) in scan.ranges_m.iter().enumerate() {
                let range_m = r.filter(|&r| {
                    let far = r > reach;
                    beyond += far as usize;
                    !far
                });
                readings.push(SonarReading {
                    t_s: scan.t_s,
                    sensor,
                    range_m,
                });
            }
        }
        self.meta.robot.sonar = lidar.beam_layout();
        self.sonar = readings;
        (self, beyond)
    }

    /// Every sonar reading placed in the world along the given trajectory.
    pub fn placed_readings(&self, trajectory: &[StampedPose]) -> Vec<PlacedReading> {
        self.sonar_log().placed(trajectory)
    }
}
