use super::map::{map_and_score, print_summary, write_map_outputs};
use super::simulate::simulate_world;
use std::path::{Path, PathBuf};
use stereotag::run::PoseSource;

/// Arguments of `stereotag demo`.
#[derive(Debug, clap::Args)]
pub struct Demo {
    /// Output directory.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// World to run (default: the bundled office).
    #[arg(long, default_value = "samples/office/world.yaml")]
    world: PathBuf,
    /// Replace the output directory if it exists (the demo replaces its own default `out`).
    #[arg(long)]
    force: bool,
}

impl Demo {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let force = self.force || self.out == Path::new("out");
        if self.out.exists() && !force {
            return Err(stereotag::io::IoError::OutputExists {
                path: self.out.clone(),
            }
            .into());
        }
        std::fs::create_dir_all(&self.out)?;
        let run_dir = self.out.join("run");
        let rig = Path::new("calibration/rigs/default.yaml");
        let output = simulate_world(&self.world, &run_dir, Some(rig), true, quiet, |_| Ok(()))?;
        let run = stereotag::io::load_run(&run_dir)?;
        let mapping = run.meta.mapping.clone().unwrap_or_default();
        for (poses, name) in [
            (PoseSource::Odometry, "map"),
            (PoseSource::GroundTruth, "map_ground_truth"),
        ] {
            let (map, metrics) = map_and_score(&run, poses, &mapping, Some(&self.world))?;
            write_map_outputs(&self.out.join(name), true, &map, &metrics)?;
            tracing::info!("{name} (poses from {poses:?}):");
            print_summary(&map, &metrics);
        }
        tracing::info!("{}; outputs in {}", output.end_reason, self.out.display());
        Ok(())
    }
}
