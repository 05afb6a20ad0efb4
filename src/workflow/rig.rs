//! Check a stereo rig file and export it for OpenCV and ROS.

use super::Result;
use crate::camera::{Rectification, StereoRig};
use crate::io::{self, OutputDir};
use std::path::Path;

/// A rig read and exported.
#[derive(Debug, Clone)]
pub struct RigExport {
    /// The rig as read.
    pub rig: StereoRig,
    /// Its Bouguet rectification.
    pub rectification: Rectification,
}

/// Reads a Kalibr camchain and writes it back with its OpenCV FileStorage and ROS camera_info
/// exports (Bouguet-rectified) into a new directory.
pub fn export_rig(rig_path: &Path, out: &Path, force: bool) -> Result<RigExport> {
    let rig = io::load_rig(rig_path)?;
    let dir = OutputDir::create(out, force)?;
    let rectification = io::save_rig_exports(&dir.path(""), &rig)?;
    dir.commit()?;
    Ok(RigExport { rig, rectification })
}
