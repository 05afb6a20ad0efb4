use super::survey::{detect_run, load_fuse_config, load_run_rig, DetectOptions};
use std::fmt::Write as _;
use std::path::PathBuf;
use stereotag::fusion::{localize, SonarInput};
use stereotag::io::{self, OutputDir};
use stereotag::metrics::{ate_m, error_growth};

/// Arguments of `stereotag localize`.
#[derive(Debug, clap::Args)]
pub struct Localize {
    /// A survey output directory (its landmarks.json is the map of tags).
    #[arg(long)]
    survey: PathBuf,
    /// The new run to track.
    #[arg(long)]
    run: PathBuf,
    /// Output directory.
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
        let file = io::load_landmarks(&self.survey.join("landmarks.json"))?;
        let calibration = file.odometry_calibration.filter(|_| !self.raw_odometry);
        let landmarks: Vec<_> = file.landmarks.into_iter().map(|r| r.landmark).collect();
        let walls_path = self.survey.join("walls_corrected.csv");
        let walls = if self.no_walls {
            Vec::new()
        } else if walls_path.exists() {
            io::load_walls_csv(&walls_path)?
        } else {
            tracing::warn!(
                "{} not found (a survey of an older version): tracking with the tags alone",
                walls_path.display()
            );
            Vec::new()
        };
        let run = super::load_run(&self.run)?;
        let odometry: std::borrow::Cow<'_, [_]> = match &calibration {
            Some(c) => {
                tracing::info!(
                    "odometry corrected with the survey's calibration: turns {:+.2}%, drift {:+.4} rad/m, distances {:+.2}%",
                    100.0 * c.turn_scale_error,
                    c.heading_drift_rad_per_m,
                    100.0 * c.distance_scale_error
                );
                c.apply(&run.odometry).into()
            }
            None => run.odometry.as_slice().into(),
        };
        let config = load_fuse_config(self.config.as_deref())?;
        let config = match calibration {
            Some(_) => {
                let c = config.for_calibrated_odometry();
                tracing::info!(
                    "predicting with {} heading noise per √rad turned (calibrated odometry)",
                    c.heading_sigma_per_sqrt_rad
                );
                c
            }
            None => config,
        };
        let world_path = super::world_of_run(self.world.as_deref(), &self.run, &run);
        let world = world_path
            .as_deref()
            .map(io::load_world)
            .transpose()?
            .map(|w| w.world);
        let dir = OutputDir::create(&self.out, self.force)?;
        let recorder = super::recorder(
            &self.rerun,
            super::Recording::Localization,
            &dir.path("localize.rrd"),
        )?;
        let families: Vec<String> = {
            let mut f: Vec<String> = landmarks.iter().map(|l| l.family.clone()).collect();
            f.sort();
            f.dedup();
            f
        };
        let (sightings, _, visual) = match load_run_rig(&self.run, &run)? {
            Some(rig) => detect_run(
                &DetectOptions {
                    visual_odometry: config.visual_odometry,
                    ..self.detect.options(&families, quiet)
                },
                &self.run,
                &run,
                &rig,
                world.as_ref(),
            )?,
            None => (Vec::new(), Vec::new(), Vec::new()),
        };
        let sonar = SonarInput {
            readings: &run.sonar,
            layout: &run.meta.robot.sonar,
            walls: &walls,
        };
        let result = localize(
            &odometry,
            &visual,
            &sightings,
            &landmarks,
            (!walls.is_empty()).then_some(sonar),
            &config,
        );
        let truth = run.ground_truth.as_deref();
        let growth = error_growth(&result, truth);

        let mut csv = String::from(
            "t_s,odom_x_m,odom_y_m,odom_theta_rad,x_m,y_m,theta_rad,sigma_m,since_sighting_m,gt_x_m,gt_y_m,gt_theta_rad\n",
        );
        for (i, (o, p)) in run.odometry.iter().zip(&result.trajectory).enumerate() {
            let gt = truth
                .and_then(|t| stereotag::geometry::pose_at(t, o.t_s))
                .map_or(",,".to_string(), |g| {
                    format!("{:.5},{:.5},{:.6}", g.x, g.y, g.theta)
                });
            let _ = writeln!(
                csv,
                "{:.4},{:.5},{:.5},{:.6},{:.5},{:.5},{:.6},{:.5},{:.4},{gt}",
                o.t_s,
                o.pose.x,
                o.pose.y,
                o.pose.theta,
                p.pose.x,
                p.pose.y,
                p.pose.theta,
                result.sigma_m[i],
                result.since_sighting_m[i],
            );
        }
        std::fs::write(dir.path("localization.csv"), csv)?;
        let mut metrics = serde_json::Map::new();
        metrics.insert("sightings.fused".into(), result.accepted.len().into());
        metrics.insert("sightings.gated_out".into(), result.rejected.len().into());
        metrics.insert("sightings.unknown_tag".into(), result.unknown.len().into());
        metrics.insert("walls.surveyed".into(), walls.len().into());
        metrics.insert("ranges.fused".into(), result.ranges_fused().into());
        metrics.insert("ranges.gated_out".into(), result.ranges_gated_out().into());
        metrics.insert("relocalised".into(), result.relocalised_t_s.len().into());
        metrics.insert("visual.turns".into(), visual.len().into());
        metrics.insert("visual.fused".into(), result.visual_fused.into());
        metrics.insert("visual.gated_out".into(), result.visual_rejected.into());
        metrics.insert(
            "odometry.calibrated".into(),
            f64::from(u8::from(calibration.is_some())).into(),
        );
        if let Some(t) = truth {
            metrics.insert("ate_m.odometry".into(), ate_m(&run.odometry, t).into());
            if calibration.is_some() {
                metrics.insert(
                    "ate_m.odometry_calibrated".into(),
                    ate_m(&odometry, t).into(),
                );
            }
            metrics.insert(
                "ate_m.localized".into(),
                ate_m(&result.trajectory, t).into(),
            );
        }
        io::save_json(
            &dir.path("report.json"),
            &serde_json::json!({ "metrics": metrics, "error_growth": growth }),
        )?;
        #[cfg(feature = "rerun")]
        if let Some(rec) = recorder {
            let numbers: std::collections::BTreeMap<String, f64> = metrics
                .iter()
                .filter_map(|(k, v)| Some((k.clone(), v.as_f64()?)))
                .collect();
            stereotag::viz::log_localization(
                &rec,
                &stereotag::viz::LocalizeScene {
                    run: &run,
                    world: world.as_ref(),
                    calibrated_odometry: calibration.is_some().then_some(&*odometry),
                    landmarks: &landmarks,
                    walls: &walls,
                    sightings: &sightings,
                    result: &result,
                    growth: &growth,
                    metrics: &numbers,
                },
            )
            .map_err(|e| anyhow::anyhow!("recording the localisation: {e}"))?;
            rec.finish()
                .map_err(|e| anyhow::anyhow!("finishing the recording: {e}"))?;
        }
        #[cfg(not(feature = "rerun"))]
        let _ = recorder;
        dir.commit()?;
        tracing::info!(
            "{} sightings of {} surveyed tags fused ({} gated out, {} of unknown tags)",
            result.accepted.len(),
            landmarks.len(),
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
        for b in &growth {
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
        let get = |k: &str| metrics.get(k).and_then(|v| v.as_f64());
        if let (Some(a), Some(b)) = (get("ate_m.odometry"), get("ate_m.localized")) {
            tracing::info!("ATE: odometry {a:.3} m, localised {b:.3} m");
        }
        Ok(())
    }
}
