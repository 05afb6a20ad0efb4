//! A robot run: what the robot logged, in the form of DESIGN.md's run dataset.
//!
//! Poses are stamped `world_from_robot` transforms. Sonar readings are placed in the world by
//! interpolating a trajectory at the reading's time and composing with the sensor's mount.

use crate::geometry::StampedPose;
use crate::sonar::{PlacedReading, SonarLayout, SonarLog, SonarReading};
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

/// The robot as `run.yaml` describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RobotDescription {
    /// The sonar ring.
    pub sonar: SonarLayout,
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

    /// Every sonar reading placed in the world along the given trajectory.
    pub fn placed_readings(&self, trajectory: &[StampedPose]) -> Vec<PlacedReading> {
        self.sonar_log().placed(trajectory)
    }
}
