use super::Bars;
use std::path::{Path, PathBuf};
use stereotag::visual::tags::Backend;
use stereotag::workflow::demo::{demo, DemoRequest};
use stereotag::workflow::sightings::DetectOptions;

/// Arguments of `stereotag demo`.
#[derive(Debug, clap::Args)]
pub struct Demo {
    /// Output directory: the run in run/, the survey's files (`survey --help`) and survey.rrd.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// World to run (default: the bundled office).
    #[arg(long, default_value = "samples/office/world.yaml")]
    world: PathBuf,
    /// Random seed of the simulation (default: the world file's).
    #[arg(long)]
    seed: Option<u64>,
    /// The stereo rig of the pictures (a Kalibr camchain with the mounting; default:
    /// calibration/rigs/default.yaml; calibration/rigs/upward.yaml looks 30 degrees up, for
    /// samples/loft's tags on the ceiling).
    #[arg(long)]
    rig: Option<PathBuf>,
    /// The tag detector's decimation (default 1.5, the survey's; 1 = full resolution, slower,
    /// finds the farthest tags as well).
    #[arg(long)]
    decimate: Option<f32>,
    /// The tag detector's contrast floor (default 40, the survey's; `survey --help` says more).
    #[arg(long)]
    min_contrast: Option<u8>,
    /// Replace the output directory if it exists (the demo replaces its own default `out`).
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    rerun: super::RerunArgs,
}

impl Demo {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        if let Some(d) = self.decimate {
            super::check_decimate(d)?; // before the simulation, not after it
        }
        let survey_defaults = DetectOptions::survey(Backend::ApriltagC);
        let output = demo(
            &DemoRequest {
                world: &self.world,
                out: &self.out,
                seed: self.seed,
                rig: self.rig.as_deref(),
                detect: DetectOptions {
                    decimate: self.decimate.unwrap_or(survey_defaults.decimate),
                    min_contrast: self.min_contrast.unwrap_or(survey_defaults.min_contrast),
                    ..survey_defaults
                },
                force: self.force || self.out == Path::new("out"),
                recording: self.rerun.request()?,
            },
            &Bars::new(quiet),
        )?;
        if quiet {
            return Ok(());
        }
        let survey = &output.survey;
        super::survey::print_summary(&survey.survey, &survey.metrics, survey.world.as_ref());
        let get = |k: &str| survey.metrics.get(k).copied().unwrap_or(f64::NAN);
        let mut see = format!("{}/landmarks.json, map_corrected.png", self.out.display());
        let default_rrd = self.out.join("survey.rrd");
        match self.rerun.request()?.file(&default_rrd) {
            Some(rrd) if rrd == default_rrd => see += ", survey.rrd",
            Some(rrd) => see += &format!(", {}", rrd.display()),
            None => {}
        }
        let mut text = format!(
            "stereotag demo: {} -> {}\n",
            self.world.display(),
            self.out.display()
        );
        text += &format!(
            "  trajectory error (ATE): odometry {:.3} m -> online {:.3} m -> offline {:.3} m\n",
            get("ate_m.odometry"),
            get("ate_m.online"),
            get("ate_m.offline")
        );
        text += &format!(
            "  map occupied precision/recall: raw {:.3}/{:.3} -> corrected {:.3}/{:.3} (ground-truth poses {:.3}/{:.3})\n",
            get("map.occupied_precision"),
            get("map.occupied_recall"),
            get("map_corrected.occupied_precision"),
            get("map_corrected.occupied_recall"),
            get("map_ground_truth.occupied_precision"),
            get("map_ground_truth.occupied_recall"),
        );
        text += &if survey.survey.landmarks.is_empty() {
            format!(
                "  no landmarks: the robot saw no tag ({} sightings); see {see}\n",
                get("sightings.total"),
            )
        } else {
            format!(
                "  {} landmarks, median position error {:.1} mm; see {see}\n",
                survey.survey.landmarks.len(),
                get("landmarks.median_error_m") * 1e3,
            )
        };
        super::print_out(&text)
    }
}
