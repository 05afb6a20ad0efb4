//! The recording in a build without the `rerun` feature: the same API, recording nothing.

use super::{
    CalibrationScene, LocalizeScene, MapScene, PlanScene, Recording, RecordingRequest, SurveyScene,
    VizError,
};
use std::path::Path;

/// No recording can be open in this build: the type has no values.
pub enum Recorder {}

impl Recorder {
    /// `None`, or [`VizError::NotBuilt`] when a sink is named explicitly.
    pub fn open(
        request: &RecordingRequest,
        _kind: Recording,
        _default_file: &Path,
    ) -> Result<Option<Recorder>, VizError> {
        if request.names_a_sink() {
            return Err(VizError::NotBuilt);
        }
        Ok(None)
    }

    /// Never called: there is no recorder.
    pub fn finish(self) -> Result<(), VizError> {
        match self {}
    }

    /// Never called: there is no recorder.
    pub fn log_survey(&self, _scene: &SurveyScene<'_>) -> Result<(), VizError> {
        match *self {}
    }

    /// Never called: there is no recorder.
    pub fn log_localization(&self, _scene: &LocalizeScene<'_>) -> Result<(), VizError> {
        match *self {}
    }

    /// Never called: there is no recorder.
    pub fn log_plan(&self, _scene: &PlanScene<'_>) -> Result<(), VizError> {
        match *self {}
    }

    /// Never called: there is no recorder.
    pub fn log_map(&self, _scene: &MapScene<'_>) -> Result<(), VizError> {
        match *self {}
    }

    /// Never called: there is no recorder.
    pub fn log_calibration(&self, _scene: &CalibrationScene<'_>) -> Result<(), VizError> {
        match *self {}
    }
}

/// No images are kept for a recording in this build.
pub fn jpeg_pair(
    _left: &image::GrayImage,
    _right: &image::GrayImage,
) -> Option<(Vec<u8>, Vec<u8>)> {
    None
}

/// No images are kept for a recording in this build.
pub fn jpeg_image(_img: &image::GrayImage) -> Option<Vec<u8>> {
    None
}
