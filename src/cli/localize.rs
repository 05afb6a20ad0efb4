use super::{Bars, UsageError};
use std::path::PathBuf;
use stereotag::fusion::Start;
use stereotag::workflow::localize::{localize, LocalizeOutput, LocalizeRequest};

/// Arguments of `stereotag localize`.
#[derive(Debug, clap::Args)]
pub struct Localize {
    /// A survey output directory (its landmarks.json is the map of tags).
    #[arg(long)]
    survey: PathBuf,
    /// The new run to track.
    #[arg(long)]
    run: PathBuf,
    /// Output directory: localization.csv, report.json and localize.rrd.
    #[arg(long)]
    out: PathBuf,
    /// World file for the tag sizes (default: the one run.yaml names, if it exists).
    #[arg(long)]
    world: Option<PathBuf>,
    /// Fusion settings (YAML, `stereotag config --default fuse`).
    #[arg(long)]
    config: Option<PathBuf>,
    #[command(flatten)]
    detect: super::survey::DetectArgs,
    /// Track with the run's odometry as logged. By default, when the survey's landmarks.json
    /// holds the odometry calibration its offline pass estimated (the same robot's wheel
    /// errors), the run's odometry is corrected with it first.
    #[arg(long)]
    raw_odometry: bool,
    /// Track with the tags alone. By default the run's sonar ranges are matched against the
    /// survey's walls (walls_corrected.csv) between sightings, and a lidar's scans with the
    /// survey's returns (returns_corrected.pgm).
    #[arg(long)]
    no_walls: bool,
    /// Where the run starts: `survey` (where the survey's run started, sure of it), `unknown`
    /// (anywhere: found from the first sighting of a surveyed tag or, with a lidar, its latest
    /// scans found in the survey's returns; the sigma 100 m until then), or
    /// `x,y,theta` in the survey's frame (metres, radians) with --start-sigma-m and
    /// --start-sigma-deg.
    #[arg(long, default_value = "survey")]
    start: String,
    /// Position sigma of a given --start, metres.
    #[arg(long, default_value_t = 0.5)]
    start_sigma_m: f64,
    /// Heading sigma of a given --start, degrees.
    #[arg(long, default_value_t = 10.0)]
    start_sigma_deg: f64,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    rerun: super::RerunArgs,
}

impl Localize {
    /// The start `--start` and its sigmas give.
    fn start(&self) -> Result<Start, UsageError> {
        let bad = || {
            UsageError(format!(
                "--start {}: expected survey, unknown or x,y,theta (metres, radians)",
                self.start
            ))
        };
        Ok(match self.start.as_str() {
            "survey" => Start::Survey,
            "unknown" => Start::Unknown,
            text => {
                let v: Vec<f64> = text
                    .split(',')
                    .map(|p| p.trim().parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad())?;
                let [x, y, theta] = v[..] else {
                    return Err(bad());
                };
                let sigmas_ok = self.start_sigma_m > 0.0 && self.start_sigma_deg > 0.0;
                if !(v.iter().all(|a| a.is_finite()) && sigmas_ok) {
                    return Err(bad());
                }
                Start::Given {
                    pose: stereotag::geometry::Pose2::new(x, y, theta),
                    sigma_m: self.start_sigma_m,
                    sigma_rad: self.start_sigma_deg.to_radians(),
                }
            }
        })
    }

    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let output = localize(
            &LocalizeRequest {
                survey: &self.survey,
                run_dir: &self.run,
                out: &self.out,
                world: self.world.as_deref(),
                config: self.config.as_deref(),
                detect: self.detect.options()?,
                raw_odometry: self.raw_odometry,
                no_walls: self.no_walls,
                start: self.start()?,
                force: self.force,
                recording: self.rerun.request()?,
            },
            &Bars::new(quiet),
        )?;
        print_summary(&output);
        Ok(())
    }
}

/// Prints what was fused, when the robot was located, how well (the workflow printed its
/// warnings as it ran), and the error against the distance since the last sighting.
fn print_summary(output: &LocalizeOutput) {
    for line in &output.summary {
        tracing::info!("{line}");
    }
    tracing::info!("error against distance since the last sighting:");
    for b in &output.growth {
        tracing::info!(
            "  {:>4.1}-{:<4.1} m: {:>6} samples, sigma {:.3} m{}",
            b.from_m,
            b.to_m,
            b.samples,
            b.mean_sigma_m,
            b.rms_error_m
                .map_or(String::new(), |e| format!(", RMS error {e:.3} m"))
        );
    }
}
