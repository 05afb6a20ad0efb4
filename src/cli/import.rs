use std::path::PathBuf;
use stereotag::sonar::SonarLayout;
use stereotag::workflow::import::{import_carmen, ImportRequest};

/// Arguments of `stereotag import`.
#[derive(Debug, clap::Args)]
pub struct Import {
    /// A CARMEN log (Radish and the classic 2D SLAM data sets; `.gz` for gzip): ODOM, FLASER,
    /// RLASER and ROBOTLASER1 lines; the scans' poses of a `*-corrected` log become the ground
    /// truth.
    #[arg(long, value_name = "LOG[.gz]")]
    carmen: PathBuf,
    /// The run directory to write (run.yaml, odometry.csv, sonar.csv, ground_truth.csv and
    /// import.json, what was read).
    #[arg(long)]
    out: PathBuf,
    /// Turn the laser into this sonar ring (frontal5 or pioneer16): per scan, each sonar's
    /// reading is the nearest laser return inside its cone (no echo beyond its range). Needed:
    /// maps from the laser itself are not supported yet.
    #[arg(long, value_name = "LAYOUT")]
    as_sonar: String,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

impl Import {
    pub fn run(&self) -> anyhow::Result<()> {
        let layout = SonarLayout::by_name(&self.as_sonar).ok_or_else(|| {
            super::UsageError(format!(
                "--as-sonar {}: the layouts are frontal5 and pioneer16",
                self.as_sonar
            ))
        })?;
        import_carmen(&ImportRequest {
            carmen: &self.carmen,
            out: &self.out,
            as_sonar: layout,
            force: self.force,
        })?;
        Ok(())
    }
}
