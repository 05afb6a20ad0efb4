use super::Bars;
use std::path::{Path, PathBuf};
use stereotag::metrics::map::MapScore;
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
        super::survey::print_summary(&survey.survey, &survey.scores, survey.world.as_ref());
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
        // The demo simulates its run from a world: the truth and the world are both known.
        let (truth, world) = (survey.scores.truth.as_ref(), survey.scores.world.as_ref());
        let figure = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.3}"));
        let ate = truth.map(|t| t.ate_m).unwrap_or_default();
        text += &format!(
            "  trajectory error (ATE): odometry {} m -> online {} m -> offline {} m\n",
            figure(ate.odometry),
            figure(ate.online),
            figure(ate.offline)
        );
        let pr = |m: Option<MapScore>| {
            m.map_or("n/a".to_string(), |m| {
                format!("{:.3}/{:.3}", m.occupied_precision, m.occupied_recall)
            })
        };
        text += &format!(
            "  map occupied precision/recall: raw {} -> corrected {} (ground-truth poses {})\n",
            pr(world.map(|w| w.raw.counting)),
            pr(world.map(|w| w.corrected_map)),
            pr(world.and_then(|w| w.ground_truth_map)),
        );
        text += &if survey.survey.landmarks.is_empty() {
            format!(
                "  no landmarks: the robot saw no tag ({} sightings); see {see}\n",
                survey.sightings,
            )
        } else {
            format!(
                "  {} landmarks, median position error {} mm; see {see}\n",
                survey.survey.landmarks.len(),
                world
                    .and_then(|w| w.landmarks.median_m)
                    .map_or("n/a".to_string(), |m| format!("{:.1}", m * 1e3)),
            )
        };
        super::print_out(&text)
    }
}
