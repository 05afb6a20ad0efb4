//! The demo: simulate a sample world (pictures included) and survey the run, into one output
//! directory (`run/` and the survey outputs beside it).

use super::sightings::DetectOptions;
use super::simulate::{simulate_untold, tell, Pictures, SimSettings, SimulateRequest, Simulated};
use super::survey::{survey_into, SurveyOutput, SurveyRequest};
use super::Result;
use crate::io::{OutputDir, DEFAULT_RIG};
use crate::progress::Progress;
use crate::sim::capture::CapturePolicy;
use crate::viz::RecordingRequest;
use std::path::Path;

/// What the demo runs.
#[derive(Debug, Clone)]
pub struct DemoRequest<'a> {
    /// The world (the office sample by default).
    pub world: &'a Path,
    /// The output directory.
    pub out: &'a Path,
    /// The simulation's seed (default: the world file's).
    pub seed: Option<u64>,
    /// The stereo rig the pictures are taken with (default: [`DEFAULT_RIG`]).
    pub rig: Option<&'a Path>,
    /// How the survey detects tags.
    pub detect: DetectOptions,
    /// Replace the output directory if it exists.
    pub force: bool,
    /// Where the survey's recording goes.
    pub recording: RecordingRequest,
}

/// What the demo did.
#[derive(Debug, Clone)]
pub struct DemoOutput {
    /// The simulation.
    pub simulated: Simulated,
    /// The survey.
    pub survey: SurveyOutput,
}

/// Simulates `world` with the rig asked for (else the default one) and the default capture
/// policy into `out/run`, then surveys that run into `out`.
pub fn demo(request: &DemoRequest<'_>, progress: &dyn Progress) -> Result<DemoOutput> {
    super::sightings::check_decimate(request.detect.decimate)?; // before the simulation, not after
    let dir = OutputDir::create(request.out, request.force)?;
    let run_dir = dir.path("run");
    let simulated = simulate_untold(
        &SimulateRequest {
            world: request.world,
            out: &run_dir,
            settings: SimSettings {
                seed: request.seed,
                ..SimSettings::default()
            },
            pictures: Some(Pictures {
                rig: request.rig.unwrap_or(Path::new(DEFAULT_RIG)),
                policy: CapturePolicy::default(),
                default_mounting: false,
            }),
            force: false,
            along: None,
        },
        progress,
    )?;
    tell(&simulated, &request.out.join("run"));
    tracing::info!("{}; surveying", simulated.output.end_reason);
    let survey = survey_into(
        &SurveyRequest {
            run_dir: &run_dir,
            out: request.out,
            world: Some(request.world),
            config: None,
            calibration_from: None,
            detect: request.detect.clone(),
            force: request.force,
            recording: request.recording.clone(),
            anchors: Default::default(),
            estimate_mounting: false,
        },
        &dir,
        progress,
    )?;
    dir.commit()?;
    Ok(DemoOutput { simulated, survey })
}
