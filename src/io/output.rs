//! Output directories that appear whole or not at all.

use super::IoError;
use std::path::{Path, PathBuf};

/// An output directory under construction. Files are written into a hidden sibling directory;
/// [`OutputDir::commit`] renames it into place. Dropped without commit, it is removed.
#[derive(Debug)]
pub struct OutputDir {
    target: PathBuf,
    staging: PathBuf,
    force: bool,
    committed: bool,
}

impl OutputDir {
    /// Starts an output at `target`. Fails if it exists and `force` is false.
    pub fn create(target: &Path, force: bool) -> Result<Self, IoError> {
        if target.exists() && !force {
            return Err(IoError::OutputExists {
                path: target.to_path_buf(),
            });
        }
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| IoError::file(&parent, e))?;
        let staging = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| IoError::file(&staging, e))?;
        }
        std::fs::create_dir_all(&staging).map_err(|e| IoError::file(&staging, e))?;
        Ok(Self {
            target: target.to_path_buf(),
            staging,
            force,
            committed: false,
        })
    }

    /// Path of a file inside the output (in the staging directory until commit).
    pub fn path(&self, name: &str) -> PathBuf {
        self.staging.join(name)
    }

    /// The final location.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Moves the finished output into place, replacing an old one when forced.
    pub fn commit(mut self) -> Result<PathBuf, IoError> {
        if self.target.exists() {
            if !self.force {
                return Err(IoError::OutputExists {
                    path: self.target.clone(),
                });
            }
            let meta = std::fs::symlink_metadata(&self.target)
                .map_err(|e| IoError::file(&self.target, e))?;
            let removed = if meta.is_dir() {
                std::fs::remove_dir_all(&self.target)
            } else {
                std::fs::remove_file(&self.target)
            };
            removed.map_err(|e| IoError::file(&self.target, e))?;
        }
        std::fs::rename(&self.staging, &self.target).map_err(|e| IoError::file(&self.target, e))?;
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}
