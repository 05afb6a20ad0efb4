use super::Bars;
use std::path::PathBuf;
use stereotag::dataset::PoseSource;
use stereotag::workflow::map::{map, MapOutput, MapRequest};

/// Which trajectory places the readings.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Poses {
    /// The robot's dead reckoning.
    Odometry,
    /// ground_truth.csv.
    GroundTruth,
}

/// Arguments of `stereotag map`.
#[derive(Debug, clap::Args)]
pub struct Map {
    /// Run dataset directory.
    #[arg(long)]
    run: PathBuf,
    /// Output directory: map.pgm/.yaml and map.png (the counting grid), map_log_odds.*,
    /// hough.png, corners.csv, corners_online.csv, walls.csv, report.json and map.rrd (the Rerun
    /// recording: the map growing over the run, its corners and walls).
    #[arg(long)]
    out: PathBuf,
    /// Trajectory that places the readings.
    #[arg(long, value_enum, default_value = "odometry")]
    poses: Poses,
    /// World file to score against (default: the one run.yaml names, if it exists).
    #[arg(long)]
    world: Option<PathBuf>,
    /// Mapping settings (YAML, `stereotag config --default mapping`); default: run.yaml's, else the paper's.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    rerun: super::RerunArgs,
}

impl Map {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let output = map(
            &MapRequest {
                run_dir: &self.run,
                out: &self.out,
                poses: match self.poses {
                    Poses::Odometry => PoseSource::Odometry,
                    Poses::GroundTruth => PoseSource::GroundTruth,
                },
                world: self.world.as_deref(),
                config: self.config.as_deref(),
                force: self.force,
                recording: self.rerun.request()?,
            },
            &Bars::new(quiet),
        )?;
        print_summary(&output);
        Ok(())
    }
}

/// Prints the counts and, with a world, the scores (the warnings were printed as they came).
fn print_summary(output: &MapOutput) {
    let map = &output.map;
    tracing::info!(
        "{} readings; {} features offline, {} online; mapped in {:.3} s",
        map.readings,
        map.features_offline.len(),
        map.features_online.len(),
        map.timings_s.get("total").copied().unwrap_or(0.0)
    );
    if let Some(scores) = &output.scores {
        let (counting, log_odds, features) =
            (&scores.counting, &scores.log_odds, &scores.features_offline);
        tracing::info!(
            "counting grid: occupied precision {:.3}, recall {:.3}; log-odds: {:.3}, {:.3}; features precision {:.3}, recall {:.3}",
            counting.occupied_precision,
            counting.occupied_recall,
            log_odds.occupied_precision,
            log_odds.occupied_recall,
            features.precision,
            features.recall,
        );
    }
}
