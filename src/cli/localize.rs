use super::Bars;
use std::path::PathBuf;
use stereotag::workflow::localize::{localize, LocalizeOutput, LocalizeRequest};

/// Arguments of `stereotag localize`.
#[derive(Debug, clap::Args)]
pub struct Localize {
    /// A survey output directory (its landmarks.json is the map of tags).
    #[arg(long)]
    survey: PathBuf,
    /// The new run to track.
    #[arg(long)]
    run: PathBuf,
    /// Output directory: localization.csv, report.json and localize.rrd.
    #[arg(long)]
    out: PathBuf,
    /// World file for the tag sizes (default: the one run.yaml names, if it exists).
    #[arg(long)]
    world: Option<PathBuf>,
    /// Fusion settings (YAML, `stereotag config --default fuse`).
    #[arg(long)]
    config: Option<PathBuf>,
    #[command(flatten)]
    detect: super::survey::DetectArgs,
    /// Track with the run's odometry as logged. By default, when the survey's landmarks.json
    /// holds the odometry calibration its offline pass estimated (the same robot's wheel
    /// errors), the run's odometry is corrected with it first.
    #[arg(long)]
    raw_odometry: bool,
    /// Track with the tags alone. By default the run's sonar ranges are matched against the
    /// survey's walls (walls_corrected.csv) between sightings.
    #[arg(long)]
    no_walls: bool,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    rerun: super::RerunArgs,
}

impl Localize {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let output = localize(
            &LocalizeRequest {
                survey: &self.survey,
                run_dir: &self.run,
                out: &self.out,
                world: self.world.as_deref(),
                config: self.config.as_deref(),
                detect: self.detect.options()?,
                raw_odometry: self.raw_odometry,
                no_walls: self.no_walls,
                force: self.force,
                recording: self.rerun.request()?,
            },
            &Bars::new(quiet),
        )?;
        print_summary(&output);
        Ok(())
    }
}

/// Prints what was fused, each relocalisation, and the error against the distance since the
/// last sighting.
fn print_summary(output: &LocalizeOutput) {
    let (result, walls) = (&output.result, &output.walls);
    tracing::info!(
        "{} sightings of {} surveyed tags fused ({} gated out, {} of unknown tags)",
        result.accepted.len(),
        output.landmarks.len(),
        result.rejected.len(),
        result.unknown.len()
    );
    for t in &result.relocalised_t_s {
        tracing::warn!(
            "lost at t = {t:.1} s: {} sightings in a row were gated out and agreed among \
             themselves; started again from them",
            stereotag::fusion::RELOCALISE_AFTER
        );
    }
    if !walls.is_empty() {
        tracing::info!(
            "{} sonar ranges fused against {} surveyed walls ({} gated out)",
            result.ranges_fused(),
            walls.len(),
            result.ranges_gated_out()
        );
    }
    tracing::info!("error against distance since the last sighting:");
    for b in &output.growth {
        tracing::info!(
            "  {:>4.1}-{:<4.1} m: {:>6} samples, sigma {:.3} m{}",
            b.from_m,
            b.to_m,
            b.samples,
            b.mean_sigma_m,
            b.rms_error_m
                .map_or(String::new(), |e| format!(", RMS error {e:.3} m"))
        );
    }
    let get = |k: &str| output.metrics.get(k).and_then(|v| v.as_f64());
    if let (Some(a), Some(b)) = (get("ate_m.odometry"), get("ate_m.localized")) {
        tracing::info!("ATE: odometry {a:.3} m, localised {b:.3} m");
    }
}
