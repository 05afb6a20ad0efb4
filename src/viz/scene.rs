//! What each recording shows, as plain data handed over by the workflows (compiled with or
//! without the `rerun` feature).

use crate::dataset::RunDataset;
use crate::fusion::{Landmark, LocalizeResult, Survey, TagSighting};
use crate::geometry::StampedPose;
use crate::metrics::GrowthBin;
use crate::sonar::grid::OccupancyMap;
use crate::sonar::walls::WallSegment;
use crate::world::World;
use std::collections::BTreeMap;

/// What a survey recording shows.
pub struct SurveyScene<'a> {
    /// The run.
    pub run: &'a RunDataset,
    /// The world, when known (walls and planned tags are drawn from it).
    pub world: Option<&'a World>,
    /// The survey.
    pub survey: &'a Survey,
    /// The sightings the survey used.
    pub sightings: &'a [TagSighting],
    /// The report's figures.
    pub metrics: &'a BTreeMap<String, f64>,
    /// The scores among them.
    pub scores: &'a crate::metrics::SurveyScores,
    /// What the survey warned about ([`crate::workflow::survey::SurveyOutput::warnings`]).
    pub warnings: &'a [String],
    /// The mapping settings (the online grid is rebuilt with them).
    pub mapping: &'a crate::sonar::map::MappingConfig,
    /// The stereo rig's cameras and mounting, when the run has pictures.
    pub rig: Option<&'a crate::camera::StereoRig>,
    /// Each stereo pair of the run as JPEG bytes (left, right) from [`crate::viz::jpeg_pair`], or `None`.
    pub images: &'a [Option<(Vec<u8>, Vec<u8>)>],
}

/// What a localisation recording shows.
pub struct LocalizeScene<'a> {
    /// The run tracked.
    pub run: &'a RunDataset,
    /// The world, when known.
    pub world: Option<&'a World>,
    /// The run's odometry corrected with the survey's calibration, when the filter ran on that
    /// (else on the run's odometry as logged).
    pub calibrated_odometry: Option<&'a [StampedPose]>,
    /// The surveyed landmarks.
    pub landmarks: &'a [Landmark],
    /// The surveyed walls.
    pub walls: &'a [WallSegment],
    /// Where the survey's laser returns fell, when a lidar's scans were matched with them.
    pub returns: Option<&'a OccupancyMap>,
    /// The run's tag sightings.
    pub sightings: &'a [TagSighting],
    /// The filter's result.
    pub result: &'a LocalizeResult,
    /// Error growth with distance since the last sighting.
    pub growth: &'a [GrowthBin],
    /// The report's figures.
    pub metrics: &'a BTreeMap<String, f64>,
    /// What it did and how well, a sentence each (`workflow::localize::summary`).
    pub summary: &'a [String],
    /// The warnings printed as it ran.
    pub warnings: &'a [String],
}

/// What a calibration recording shows.
pub struct CalibrationScene<'a> {
    /// The calibration.
    pub calibration: &'a crate::calib::Calibration,
    /// The report, as Markdown.
    pub report_markdown: &'a str,
    /// Both images of a pair rectified side by side, when one was given.
    pub rectified_pair: Option<&'a image::GrayImage>,
    /// Each view's left and right images as JPEG, keyed by view name (the right one empty for
    /// one camera).
    pub view_images: &'a BTreeMap<String, (Vec<u8>, Vec<u8>)>,
}

/// What a tag plan's recording shows.
pub struct PlanScene<'a> {
    /// The map planned on.
    pub map: &'a crate::sonar::grid::OccupancyMap,
    /// Its Hough corners.
    pub corners: &'a [crate::sonar::hough::Feature],
    /// The tags (proposed or given), x and y in metres.
    pub tags_m: &'a [[f64; 2]],
    /// Whether the tags were proposed (else given).
    pub proposed: bool,
    /// The predicted error.
    pub prediction: &'a crate::plan::Prediction,
    /// What makes the figures speak for little ([`crate::workflow::plan::PlanOutput::warnings`]).
    pub warnings: &'a [String],
}

/// What a sonar map's recording shows.
pub struct MapScene<'a> {
    /// The run mapped.
    pub run: &'a RunDataset,
    /// The poses that placed the readings.
    pub trajectory: &'a [StampedPose],
    /// Their name (`odometry` or `ground truth`).
    pub poses: &'a str,
    /// The world, when known.
    pub world: Option<&'a World>,
    /// The map.
    pub map: &'a crate::sonar::map::SonarMap,
    /// The grid's settings as used (the evidence floor set for the run's sampling), which the
    /// growing grid is rebuilt with.
    pub grid: &'a crate::sonar::grid::GridConfig,
    /// The report's figures.
    pub metrics: &'a BTreeMap<String, f64>,
    /// The scores against the world, when known.
    pub scores: Option<&'a crate::metrics::SonarScores>,
    /// What the map hides or leaves out (the warnings printed).
    pub warnings: &'a [String],
}
