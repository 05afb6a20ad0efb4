//! The sample worlds, calibration targets and rigs built into stereotag, so that `demo` and the
//! README's commands work outside the repository (an installed binary, an empty directory).
//!
//! A repository-relative path such as `samples/office/world.yaml` that does not exist where
//! stereotag runs is read from the copy built in, and the log says so; a file that exists is
//! always read from disk. [`extract`] writes the copies out for editing.

use super::IoError;
use std::path::{Component, Path, PathBuf};

/// `(path, include_bytes!(path))`, the path relative to the crate root.
macro_rules! bundle {
    ($path:literal) => {
        (
            $path,
            include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/", $path)),
        )
    };
}

/// Every bundled file: its repository-relative path and its content.
pub const FILES: &[(&str, &[u8])] = &[
    bundle!("samples/office/world.yaml"),
    bundle!("samples/museum/world.yaml"),
    bundle!("samples/apartment/world.yaml"),
    bundle!("samples/loft/world.yaml"),
    bundle!("samples/willow/world.yaml"),
    bundle!("samples/willow/willow_crop.yaml"),
    bundle!("samples/willow/willow_crop.pgm"),
    bundle!("samples/willow/README.md"),
    bundle!("calibration/rigs/default.yaml"),
    bundle!("calibration/rigs/euroc_official.yaml"),
    bundle!("calibration/rigs/fisheye_example.yaml"),
    bundle!("calibration/rigs/double_sphere_example.yaml"),
    bundle!("calibration/rigs/eucm_example.yaml"),
    bundle!("calibration/rigs/upward.yaml"),
    bundle!("calibration/targets/aprilgrid_6x6.yaml"),
    bundle!("calibration/targets/checkerboard_9x6.yaml"),
    bundle!("calibration/targets/tagboard_6x6_reversed.yaml"),
    bundle!("calibration/targets/charuco_11x8.yaml"),
];

/// The built-in copy of `path`, if it names one (`./samples/...` as well as `samples/...`).
pub fn bundled(path: &Path) -> Option<&'static [u8]> {
    let normal: PathBuf = path
        .components()
        .filter(|c| !matches!(c, Component::CurDir))
        .collect();
    FILES
        .iter()
        .find(|(p, _)| Path::new(p) == normal)
        .map(|(_, content)| *content)
}

/// The content of `path`: the file if it exists, else its built-in copy if it has one (each
/// such read is logged), else the error of reading the missing file.
pub(crate) fn read(path: &Path) -> Result<Vec<u8>, IoError> {
    match std::fs::read(path) {
        Ok(bytes) => Ok(bytes),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => match bundled(path) {
            Some(content) => {
                tracing::info!(
                    "{} is not here: using the copy built into stereotag",
                    path.display()
                );
                Ok(content.to_vec())
            }
            None => Err(IoError::file(path, e)),
        },
        Err(e) => Err(IoError::file(path, e)),
    }
}

/// Writes every bundled file under `dir` (keeping its relative path); existing files are kept
/// unless `force`. Returns the files written.
pub fn extract(dir: &Path, force: bool) -> Result<Vec<PathBuf>, IoError> {
    let mut written = Vec::new();
    for (rel, content) in FILES {
        let path = dir.join(rel);
        if path.exists() && !force {
            continue;
        }
        if let Some(parent) = path.parent() {
            super::create_dir(parent)?;
        }
        std::fs::write(&path, content).map_err(|e| IoError::file(&path, e))?;
        written.push(path);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_sample_and_target_is_found_by_its_relative_path() {
        assert!(bundled(Path::new("samples/office/world.yaml")).is_some());
        assert!(bundled(Path::new("./calibration/targets/aprilgrid_6x6.yaml")).is_some());
        assert!(bundled(Path::new("/samples/office/world.yaml")).is_none());
        assert!(bundled(Path::new("samples/office/other.yaml")).is_none());
        for (rel, content) in FILES {
            assert_eq!(std::fs::read(rel).unwrap(), *content, "{rel}");
        }
    }
}
