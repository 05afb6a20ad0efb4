use std::path::PathBuf;
use stereotag::io::{self, OutputDir};

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
        let rig = io::load_rig(&self.rig)?;
        let dir = OutputDir::create(&self.out, self.force)?;
        let rect = write_rig_exports(&dir, &rig)?;
        dir.commit()?;
        tracing::info!(
            "baseline {:.4} m, rectified focal {:.2} px; wrote {}",
            rig.baseline_m(),
            rect.focal_px,
            self.out.display()
        );
        Ok(())
    }
}

/// Writes a rig as Kalibr camchain, OpenCV FileStorage and ROS camera_info (Bouguet-rectified).
pub(crate) fn write_rig_exports(
    dir: &OutputDir,
    rig: &stereotag::camera::StereoRig,
) -> anyhow::Result<stereotag::camera::Rectification> {
    let rect = rig.rectify();
    io::save_rig(&dir.path("camchain.yaml"), rig)?;
    io::save_opencv_stereo(&dir.path("opencv_stereo.yaml"), rig, &rect)?;
    io::save_camera_info(
        &dir.path("left.yaml"),
        "left",
        &rig.left,
        &rect.left_rotation,
        &rect.left_projection(),
    )?;
    io::save_camera_info(
        &dir.path("right.yaml"),
        "right",
        &rig.right,
        &rect.right_rotation,
        &rect.right_projection(),
    )?;
    Ok(rect)
}
