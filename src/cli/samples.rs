use std::path::PathBuf;

/// Arguments of `stereotag samples`.
#[derive(Debug, clap::Args)]
pub struct Samples {
    /// Directory to write `samples/` and `calibration/` into.
    #[arg(long, default_value = ".")]
    out: PathBuf,
    /// Overwrite files that exist (default: keep them).
    #[arg(long)]
    force: bool,
}

impl Samples {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let written = stereotag::io::extract_bundled(&self.out, self.force)?;
        let kept = stereotag::io::BUNDLED_FILES.len() - written.len();
        if !quiet {
            for path in &written {
                eprintln!("wrote {}", path.display());
            }
            if kept > 0 {
                eprintln!("kept {kept} files that exist (--force overwrites them)");
            }
        }
        Ok(())
    }
}
