//! Track a later run against a survey: its tags against the surveyed landmarks, its sonar against
//! the surveyed walls, its odometry corrected with the survey's calibration; how the error grows
//! between sightings, written as `localization.csv` and a report, and recorded.

use super::sightings::{detect_run, DetectOptions, RunSightings};
use super::survey::load_run_rig;
use super::{load_run, load_world_of_run, Error, Result};
use crate::fusion::{self, FuseConfig, Landmark, LocalizeResult, OdometryCalibration, SonarInput};
use crate::io::{self, OutputDir};
use crate::metrics::{error_growth, localization_metrics, GrowthBin, LocalizationCounts};
use crate::progress::Progress;
use crate::sonar::walls::WallSegment;
use crate::viz::{LocalizeScene, Recorder, Recording, RecordingRequest};
use std::path::Path;

/// What to localise against what.
#[derive(Debug, Clone)]
pub struct LocalizeRequest<'a> {
    /// A survey output directory (its `landmarks.json` is the map of tags, its
    /// `walls_corrected.csv` the walls).
    pub survey: &'a Path,
    /// The run to track.
    pub run_dir: &'a Path,
    /// The output directory.
    pub out: &'a Path,
    /// A world file for the tag sizes (default: the one run.yaml names, if it exists).
    pub world: Option<&'a Path>,
    /// Fusion settings (YAML).
    pub config: Option<&'a Path>,
    /// How the tags are detected (families: the survey's when none are given).
    pub detect: DetectOptions,
    /// Track with the run's odometry as logged, not corrected with the survey's calibration.
    pub raw_odometry: bool,
    /// Track with the tags alone, not the sonar against the survey's walls.
    pub no_walls: bool,
    /// Replace the output directory if it exists.
    pub force: bool,
    /// Where the recording goes (default: `localize.rrd` in the output).
    pub recording: RecordingRequest,
}

/// What a localisation produced, beyond its files.
#[derive(Debug, Clone)]
pub struct LocalizeOutput {
    /// The filter's result.
    pub result: LocalizeResult,
    /// The surveyed landmarks tracked against.
    pub landmarks: Vec<Landmark>,
    /// The surveyed walls the sonar was matched against.
    pub walls: Vec<WallSegment>,
    /// Error statistics by distance since the last sighting.
    pub growth: Vec<GrowthBin>,
    /// The figures of `report.json`.
    pub metrics: serde_json::Map<String, serde_json::Value>,
}

/// The survey's walls, unless told not to use them or the survey has none.
fn surveyed_walls(survey: &Path, no_walls: bool) -> Result<Vec<WallSegment>> {
    let path = survey.join("walls_corrected.csv");
    if no_walls {
        Ok(Vec::new())
    } else if path.exists() {
        Ok(io::load_walls_csv(&path)?)
    } else {
        tracing::warn!(
            "{} not found (a survey of an older version): tracking with the tags alone",
            path.display()
        );
        Ok(Vec::new())
    }
}

/// The settings the filter predicts with: those given, with the turn noise that calibrated
/// odometry leaves when the odometry is calibrated.
fn filter_config(config: FuseConfig, calibration: Option<&OdometryCalibration>) -> FuseConfig {
    match calibration {
        Some(_) => {
            let c = config.for_calibrated_odometry();
            tracing::info!(
                "predicting with {} heading noise per √rad turned (calibrated odometry)",
                c.heading_sigma_per_sqrt_rad
            );
            c
        }
        None => config,
    }
}

/// Localises a run against a survey and writes `localization.csv`, `report.json` and the
/// recording into a new directory.
pub fn localize(request: &LocalizeRequest<'_>, progress: &dyn Progress) -> Result<LocalizeOutput> {
    let file = io::load_landmarks(&request.survey.join("landmarks.json"))?;
    let calibration = file.odometry_calibration.filter(|_| !request.raw_odometry);
    let landmarks: Vec<_> = file.landmarks.into_iter().map(|r| r.landmark).collect();
    let walls = surveyed_walls(request.survey, request.no_walls)?;
    let run = load_run(request.run_dir)?;
    let odometry: std::borrow::Cow<'_, [_]> = match &calibration {
        Some(c) => {
            tracing::info!(
                "odometry corrected with the survey's calibration: turns {:+.2}%, drift {:+.4} rad/m, distances {:+.2}%",
                100.0 * c.turn_scale_error,
                c.heading_drift_rad_per_m,
                100.0 * c.distance_scale_error
            );
            c.apply(&run.odometry).into()
        }
        None => run.odometry.as_slice().into(),
    };
    let config = filter_config(io::load_fuse_config(request.config)?, calibration.as_ref());
    let world = load_world_of_run(request.world, request.run_dir, &run)?;
    let dir = OutputDir::create(request.out, request.force)?;
    let recorder = Recorder::open(
        &request.recording,
        Recording::Localization,
        &dir.path("localize.rrd"),
    )?;
    let mut families: Vec<_> = landmarks.iter().map(|l| l.family).collect();
    families.sort();
    families.dedup();
    let options = DetectOptions {
        families: if request.detect.families.is_empty() {
            families
        } else {
            request.detect.families.clone()
        },
        visual_odometry: config.visual_odometry,
        keep_images: false,
        ..request.detect.clone()
    };
    let seen = match load_run_rig(request.run_dir, &run)? {
        Some(rig) => detect_run(
            &options,
            request.run_dir,
            &run,
            &rig,
            world.as_ref(),
            progress,
        )?,
        None => RunSightings {
            sightings: Vec::new(),
            visual: Vec::new(),
            images: Vec::new(),
        },
    };
    let sonar = SonarInput {
        readings: &run.sonar,
        layout: &run.meta.robot.sonar,
        walls: &walls,
    };
    let obs = fusion::Observations {
        odometry: &odometry,
        sightings: &seen.sightings,
        visual: &seen.visual,
    };
    let result = fusion::localize(
        &obs,
        &landmarks,
        (!walls.is_empty()).then_some(sonar),
        &config,
    );
    let truth = run.ground_truth.as_deref();
    let growth = error_growth(&result, truth);
    io::save_localization_csv(&dir.path("localization.csv"), &run.odometry, &result, truth)?;
    let metrics = localization_metrics(
        &result,
        &run.odometry,
        &odometry,
        calibration.is_some(),
        truth,
        LocalizationCounts {
            walls: walls.len(),
            visual_turns: seen.visual.len(),
        },
    );
    io::save_json(
        &dir.path("report.json"),
        &serde_json::json!({ "metrics": metrics, "error_growth": growth }),
    )?;
    if let Some(rec) = recorder {
        let numbers: std::collections::BTreeMap<String, f64> = metrics
            .iter()
            .filter_map(|(k, v)| Some((k.clone(), v.as_f64()?)))
            .collect();
        let scene = LocalizeScene {
            run: &run,
            world: world.as_ref(),
            calibrated_odometry: calibration.is_some().then_some(&*odometry),
            landmarks: &landmarks,
            walls: &walls,
            sightings: &seen.sightings,
            result: &result,
            growth: &growth,
            metrics: &numbers,
        };
        rec.log_localization(&scene)
            .map_err(|e| Error::from(e).during("recording the localisation"))?;
        rec.finish()
            .map_err(|e| Error::from(e).during("finishing the recording"))?;
    }
    dir.commit()?;
    Ok(LocalizeOutput {
        result,
        landmarks,
        walls,
        growth,
        metrics,
    })
}
