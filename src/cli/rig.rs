use std::path::PathBuf;
use stereotag::workflow::rig::export_rig;

/// Arguments of `stereotag rig`.
#[derive(Debug, clap::Args)]
pub struct Rig {
    /// Stereo rig file (Kalibr camchain YAML).
    rig: PathBuf,
    /// Output directory: camchain.yaml, opencv_stereo.yaml, left.yaml and right.yaml (ROS camera_info).
    #[arg(long)]
    out: PathBuf,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

impl Rig {
    pub fn run(&self) -> anyhow::Result<()> {
        let export = export_rig(&self.rig, &self.out, self.force)?;
        tracing::info!(
            "baseline {:.4} m, rectified focal {:.2} px; wrote {}",
            export.rig.baseline_m(),
            export.rectification.focal_px,
            self.out.display()
        );
        Ok(())
    }
}
