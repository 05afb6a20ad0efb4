use super::detect::Backend;
use super::simulate::simulate_world;
use super::survey::{survey_into, DetectOptions, SurveyJob};
use std::path::{Path, PathBuf};
use stereotag::io::OutputDir;

/// Arguments of `stereotag demo`.
#[derive(Debug, clap::Args)]
pub struct Demo {
    /// Output directory.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// World to run (default: the bundled office).
    #[arg(long, default_value = "samples/office/world.yaml")]
    world: PathBuf,
    /// Random seed of the simulation (default: the world file's).
    #[arg(long)]
    seed: Option<u64>,
    /// The tag detector's decimation (default 1.5, the survey's; 1 = full resolution, slower,
    /// finds the farthest tags as well).
    #[arg(long)]
    decimate: Option<f32>,
    /// The tag detector's contrast floor (default 40, the survey's; `survey --help` says more).
    #[arg(long)]
    min_contrast: Option<u8>,
    /// Replace the output directory if it exists (the demo replaces its own default `out`).
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    rerun: super::RerunArgs,
}

impl Demo {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        if let Some(d) = self.decimate {
            super::check_decimate(d)?; // before the simulation, not after it
        }
        let force = self.force || self.out == Path::new("out");
        let dir = OutputDir::create(&self.out, force)?;
        let run_dir = dir.path("run");
        let rig = Path::new(super::DEFAULT_RIG);
        let policy = stereotag::render::CapturePolicy::default();
        let sim = simulate_world(
            &self.world,
            &run_dir,
            Some((rig, &policy)),
            false,
            quiet,
            |c| {
                if let Some(s) = self.seed {
                    c.seed = s;
                }
                Ok(())
            },
        )?;
        tracing::info!("{}; surveying", sim.end_reason);
        let output = survey_into(
            &SurveyJob {
                run_dir: &run_dir,
                out: &self.out,
                world: Some(&self.world),
                config: None,
                calibration_from: None,
                detect: DetectOptions {
                    keep_images: false,
                    backend: Backend::ApriltagC,
                    families: &[],
                    decimate: self
                        .decimate
                        .unwrap_or(super::survey::default_decimate(Backend::ApriltagC)),
                    min_contrast: self
                        .min_contrast
                        .unwrap_or(super::survey::DEFAULT_MIN_CONTRAST),
                    tag_size_m: None,
                    quiet,
                    visual_odometry: true,
                },
                force,
                rerun: &self.rerun,
            },
            &dir,
        )?;
        dir.commit()?;
        let get = |k: &str| output.metrics.get(k).copied().unwrap_or(f64::NAN);
        println!(
            "stereotag demo: {} -> {}",
            self.world.display(),
            self.out.display()
        );
        println!(
            "  trajectory error (ATE): odometry {:.3} m -> online {:.3} m -> offline {:.3} m",
            get("ate_m.odometry"),
            get("ate_m.online"),
            get("ate_m.offline")
        );
        println!(
            "  map occupied precision/recall: raw {:.3}/{:.3} -> corrected {:.3}/{:.3} (ground-truth poses {:.3}/{:.3})",
            get("map.occupied_precision"),
            get("map.occupied_recall"),
            get("map_corrected.occupied_precision"),
            get("map_corrected.occupied_recall"),
            get("map_ground_truth.occupied_precision"),
            get("map_ground_truth.occupied_recall"),
        );
        if output.survey.landmarks.is_empty() {
            println!(
                "  no landmarks: the robot saw no tag ({} sightings); see {}/map_corrected.png, survey.rrd",
                get("sightings.total"),
                self.out.display()
            );
        } else {
            println!(
                "  {} landmarks, median position error {:.1} mm; see {}/landmarks.json, map_corrected.png, survey.rrd",
                output.survey.landmarks.len(),
                get("landmarks.median_error_m") * 1e3,
                self.out.display()
            );
        }
        Ok(())
    }
}
