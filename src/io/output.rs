//! Output directories and files that appear whole or not at all.
//!
//! An output is built in a hidden sibling (`.NAME.partial-PID`, a directory or a file) and renamed
//! into place when complete. Every such directory of the process is listed, so that a program interrupted by
//! a signal can remove them ([`remove_partial_outputs`], which the command line calls on Ctrl-C
//! and SIGTERM), and one left by a process that died (killed, power cut) is removed by the next
//! output made beside it.

use super::IoError;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The staging directories and files of this process's outputs under construction.
static PARTIAL: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn partial() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    PARTIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes every output of this process still under construction; returns how many there were.
/// For a signal handler: the process should exit right after, as its work is gone.
pub fn remove_partial_outputs() -> usize {
    let dirs = std::mem::take(&mut *partial());
    for dir in &dirs {
        // Renamed away first, so that a thread still writing cannot refill it while it goes.
        let mut doomed = dir.clone().into_os_string();
        doomed.push(".removing");
        let doomed = PathBuf::from(doomed);
        let gone = if std::fs::rename(dir, &doomed).is_ok() {
            &doomed
        } else {
            dir
        };
        let _ = remove_path(gone);
        let _ = remove_path(dir);
    }
    dirs.len()
}

/// Removes a directory with what it holds, or a file.
fn remove_path(path: &Path) -> std::io::Result<()> {
    if std::fs::symlink_metadata(path)?.is_dir() {
        std::fs::remove_dir_all(path)
    } else {
        std::fs::remove_file(path)
    }
}

/// The process id in a staging directory's name `.NAME.partial-PID`, if `file_name` is one for
/// the output `name`.
fn staging_pid(file_name: &str, name: &str) -> Option<u32> {
    file_name
        .strip_prefix(&format!(".{name}.partial-"))
        .and_then(|rest| rest.strip_suffix(".removing").or(Some(rest)))
        .and_then(|pid| pid.parse().ok())
}

/// Whether process `pid` is running (on systems where that cannot be asked, assumed so).
fn running(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid.to_string()).exists()
    } else {
        true
    }
}

/// Removes the staging directories of `name` in `parent` left by processes no longer running,
/// saying so.
fn remove_stale(parent: &Path, name: &str) {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    for entry in entries.flatten() {
        let file_name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = staging_pid(&file_name, name) else {
            continue;
        };
        if pid != std::process::id() && !running(pid) {
            let path = entry.path();
            match remove_path(&path) {
                Ok(()) => tracing::warn!(
                    "removed {}, the partial output of an interrupted run (process {pid})",
                    path.display()
                ),
                Err(e) => tracing::warn!(
                    "{} is the partial output of an interrupted run (process {pid}) and cannot be removed: {e}",
                    path.display()
                ),
            }
        }
    }
}

/// The hidden sibling `.NAME.partial-PID` an output `target` is built in (its directory made
/// when missing, stale ones of dead processes removed).
fn staging_beside(target: &Path) -> Result<PathBuf, IoError> {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| IoError::file(&parent, e))?;
    remove_stale(&parent, &name);
    let staging = parent.join(format!(".{name}.partial-{}", std::process::id()));
    Ok(staging)
}

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
        let staging = staging_beside(target)?;
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| IoError::file(&staging, e))?;
        }
        std::fs::create_dir_all(&staging).map_err(|e| IoError::file(&staging, e))?;
        partial().push(staging.clone());
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
        partial().retain(|p| p != &self.staging);
        Ok(self.target.clone())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
            partial().retain(|p| p != &self.staging);
        }
    }
}

/// A file under construction: written as a hidden sibling (`.NAME.partial-PID`) and renamed
/// into place by [`PartialFile::commit`], replacing what was there; dropped without commit, or
/// at Ctrl-C, it is removed and the old file stays.
#[derive(Debug)]
pub struct PartialFile {
    target: PathBuf,
    staging: PathBuf,
    committed: bool,
}

impl PartialFile {
    /// Starts the file `target` (its directory is made when missing).
    pub fn create(target: &Path) -> Result<Self, IoError> {
        let staging = staging_beside(target)?;
        partial().push(staging.clone());
        Ok(Self {
            target: target.to_path_buf(),
            staging,
            committed: false,
        })
    }

    /// Where to write the file until it is committed.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Moves the finished file into place.
    pub fn commit(mut self) -> Result<PathBuf, IoError> {
        std::fs::rename(&self.staging, &self.target).map_err(|e| IoError::file(&self.target, e))?;
        self.committed = true;
        partial().retain(|p| p != &self.staging);
        Ok(self.target.clone())
    }
}

impl Drop for PartialFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.staging);
            partial().retain(|p| p != &self.staging);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_staging_directory_is_known_by_its_name_and_process() {
        assert_eq!(staging_pid(".out.partial-1234", "out"), Some(1234));
        assert_eq!(staging_pid(".out.partial-1234.removing", "out"), Some(1234));
        assert_eq!(staging_pid(".out.partial-x", "out"), None);
        assert_eq!(staging_pid(".other.partial-1234", "out"), None);
    }

    #[test]
    fn a_dead_process_partial_output_is_removed_and_a_running_one_kept() {
        let parent = std::env::temp_dir().join(format!("stereotag-stale-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&parent);
        // No process has id u32::MAX - 1 (Linux caps ids at 2^22).
        let dead = parent.join(format!(".out.partial-{}", u32::MAX - 1));
        let alive = parent.join(".out.partial-1"); // init
        std::fs::create_dir_all(dead.join("run")).unwrap();
        std::fs::create_dir_all(&alive).unwrap();
        let out = OutputDir::create(&parent.join("out"), false).unwrap();
        assert!(!dead.exists());
        assert!(alive.exists());
        let staging = out.staging.clone();
        assert!(partial().contains(&staging));
        drop(out);
        assert!(!staging.exists() && !partial().contains(&staging));
        std::fs::remove_dir_all(&parent).unwrap();
    }
}
