//! Recording to the Rerun viewer: the only module that imports rerun. Each workflow hands it
//! plain data (a [`SurveyScene`], [`LocalizeScene`], [`CalibrationScene`], [`PlanScene`] or [`MapScene`]); it logs static
//! things once (walls, cameras, landmarks) and everything else on the `time` timeline (seconds of
//! the run) and the `frame` sequence (stereo pairs), under entity paths that mirror the stages
//! (`world/walls`, `world/robot/left/image`, `world/sonar/beams`, `map/grid`, `map/hough`,
//! `landmarks/tag_7`, `metrics/...`), and sends a default layout with the recording.
//!
//! Built without the `rerun` feature, the same API records nothing: [`Recorder::open`] gives no
//! recorder unless asked for a sink, and then says the feature is missing. Callers need no
//! `cfg` of their own.

mod scene;

#[cfg(feature = "rerun")]
mod calibration;
#[cfg(feature = "rerun")]
mod draw;
#[cfg(feature = "rerun")]
mod layout;
#[cfg(feature = "rerun")]
mod localize;
#[cfg(feature = "rerun")]
mod map;
#[cfg(feature = "rerun")]
mod palette;
#[cfg(feature = "rerun")]
mod plan;
#[cfg(feature = "rerun")]
mod recorder;
#[cfg(feature = "rerun")]
mod sonar;
#[cfg(feature = "rerun")]
mod survey;

#[cfg(not(feature = "rerun"))]
mod off;

#[cfg(not(feature = "rerun"))]
pub use off::{jpeg_image, jpeg_pair, Recorder};
#[cfg(feature = "rerun")]
pub use recorder::{jpeg_image, jpeg_pair, Recorder};
pub use scene::{CalibrationScene, LocalizeScene, MapScene, PlanScene, SurveyScene};

use std::path::{Path, PathBuf};

/// JPEG quality of the camera images in the recording (ours: 60; the tags' cells and edges stay
/// clear in the viewer, and the sensor noise, which is most of what a higher quality spends its
/// bits and time on, is smoothed: the office demo's recording is 8.0 MB instead of 16.2 at 85).
pub const IMAGE_JPEG_QUALITY: u8 = 60;
/// Seconds of run time between grid snapshots (the issue asks for at most a few seconds).
pub const GRID_SNAPSHOT_S: f64 = 5.0;
/// Seconds between logged robot poses and error samples.
pub const POSE_SAMPLE_S: f64 = 0.5;
/// Ellipsoids are drawn at this many sigmas.
pub const ELLIPSOID_SIGMAS: f64 = 3.0;

/// Errors of the recording.
#[derive(Debug, thiserror::Error)]
pub enum VizError {
    /// Rerun refused a sink or a log call.
    #[cfg(feature = "rerun")]
    #[error("rerun: {0}")]
    Rerun(#[from] rerun::RecordingStreamError),
    /// The viewer could not be started.
    #[cfg(feature = "rerun")]
    #[error("--spawn: {0}")]
    Spawn(String),
    /// A bad `--connect` URL, or a file that cannot be written.
    #[error("--connect {url}: {message}")]
    Url {
        /// The URL given.
        url: String,
        /// Why it is wrong.
        message: String,
    },
    /// The recording could not be flushed to its sinks.
    #[error("writing the recording: {message}")]
    Flush {
        /// Why.
        message: String,
    },
    /// An image could not be encoded.
    #[error("encoding an image: {0}")]
    Jpeg(String),
    /// A sink was asked for in a build without the `rerun` feature.
    #[error("this stereotag was built without the `rerun` feature; rebuild with default features to record")]
    NotBuilt,
}

impl VizError {
    /// Whether the caller asked for something that cannot be (a bad URL or file, a recording
    /// from a build without it) rather than the recording failing.
    pub fn is_bad_input(&self) -> bool {
        matches!(self, VizError::Url { .. } | VizError::NotBuilt)
    }
}

/// Where a recording goes. Several may be combined.
#[derive(Debug, Clone, PartialEq)]
pub enum Sink {
    /// An `.rrd` file.
    Save(PathBuf),
    /// A new viewer process (the `rerun` executable on PATH).
    Spawn,
    /// A running viewer, e.g. `rerun+http://127.0.0.1:9876/proxy`.
    Connect(String),
}

/// What a recording holds, which picks its application name and default layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Recording {
    /// A survey (also the demo's).
    Survey,
    /// A stereo calibration.
    Calibration,
    /// A later run localised against a survey.
    Localization,
    /// Where to put tags, with the error to expect.
    Plan,
    /// A sonar (or laser) map of a run.
    Map,
}

impl Recording {
    /// The application name the viewer shows.
    pub fn application(self) -> &'static str {
        match self {
            Recording::Survey => "stereotag survey",
            Recording::Calibration => "stereotag calibration",
            Recording::Localization => "stereotag localize",
            Recording::Plan => "stereotag plan",
            Recording::Map => "stereotag map",
        }
    }
}

/// Where the caller wants a recording: nowhere, or to a file, a new viewer and/or a running
/// viewer. With no sink named, a workflow records to its output directory's default file
/// (`survey.rrd`, `localize.rrd`, `calibration.rrd`, `plan.rrd`, `map.rrd`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordingRequest {
    /// Record nothing.
    pub off: bool,
    /// Write the recording to this `.rrd` file instead of the default one.
    pub save: Option<PathBuf>,
    /// Stream to a new viewer.
    pub spawn: bool,
    /// Stream to a running viewer at this URL.
    pub connect: Option<String>,
}

impl RecordingRequest {
    /// No recording.
    pub fn none() -> Self {
        Self {
            off: true,
            ..Self::default()
        }
    }

    /// The sinks asked for, the default file when none is named; empty when off.
    pub fn sinks(&self, default_file: &Path) -> Vec<Sink> {
        if self.off {
            return Vec::new();
        }
        let mut sinks = Vec::new();
        match &self.save {
            Some(p) => sinks.push(Sink::Save(p.clone())),
            None if !self.spawn && self.connect.is_none() => {
                sinks.push(Sink::Save(default_file.to_path_buf()))
            }
            None => {}
        }
        if self.spawn {
            sinks.push(Sink::Spawn);
        }
        if let Some(url) = &self.connect {
            sinks.push(Sink::Connect(url.clone()));
        }
        sinks
    }

    /// The `.rrd` file the recording is written to, if any (`default_file` when no sink is named).
    pub fn file(&self, default_file: &Path) -> Option<PathBuf> {
        self.sinks(default_file).into_iter().find_map(|s| match s {
            Sink::Save(path) => Some(path),
            _ => None,
        })
    }

    /// Whether a sink is named explicitly (not only the default file).
    pub fn names_a_sink(&self) -> bool {
        !self.off && (self.save.is_some() || self.spawn || self.connect.is_some())
    }
}

/// The Rerun viewer version the recordings are written for (the `rerun` executable that
/// `--spawn` starts must match it).
pub const VIEWER_VERSION: &str = "0.36.3";

/// Whether a `rerun` executable is on `PATH` (what `--spawn` starts).
pub fn viewer_on_path() -> bool {
    let exe = if cfg!(windows) { "rerun.exe" } else { "rerun" };
    std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join(exe).is_file()))
}

/// Whether `path` looks like an `.rrd` file name.
pub fn is_rrd(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "rrd")
}
