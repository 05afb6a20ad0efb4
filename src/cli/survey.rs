use super::Bars;
use std::path::PathBuf;
use stereotag::fusion::Survey;
use stereotag::metrics::map::MapScore;
use stereotag::metrics::{SurveyScores, TrajectoryErrors};
use stereotag::workflow::sightings::{survey_decimate, DetectOptions, SURVEY_MIN_CONTRAST};
use stereotag::workflow::survey::{survey, SurveyRequest};
use stereotag::world::World;

/// Arguments of `stereotag survey`.
#[derive(Debug, clap::Args)]
pub struct SurveyArgs {
    /// Run dataset directory.
    #[arg(long)]
    run: PathBuf,
    /// Output directory: landmarks.json, layout.json (WPILib), map*.yaml/pgm/png (raw, online
    /// and corrected), corners*.csv, walls_corrected.csv, hough*.png, trajectory.csv,
    /// visual_turns.csv, report.json and survey.rrd; with a lidar, returns_corrected.yaml/pgm.
    #[arg(long)]
    out: PathBuf,
    /// World file to score against and to give planned tag positions (default: the one run.yaml
    /// names, if it exists).
    #[arg(long)]
    world: Option<PathBuf>,
    /// Fusion settings (YAML, `stereotag config --default fuse`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// An earlier survey of the same robot (its directory): the online filter predicts with the
    /// odometry errors that survey found (its landmarks.json's odometry_calibration) until the
    /// run's own are learnt, instead of dead reckoning until the first loop closes.
    #[arg(long, value_name = "SURVEY_DIR")]
    calibration_from: Option<PathBuf>,
    #[command(flatten)]
    detect: DetectArgs,
    /// Known tag poses to solve the survey in the frame of, any subset of the tags: a WPILib
    /// AprilTag field layout (.json) or YAML (`anchors:` a list of `{id, x_m, y_m, z_m, yaw_deg,
    /// sigma_m, sigma_deg}`, all but id, x_m and y_m optional). Each is a prior on its landmark;
    /// report.json gives each one's residual. Then `localize` starts a later run where the
    /// survey's did, in this frame.
    #[arg(long, value_name = "FILE", conflicts_with = "origin_tag")]
    anchors: Option<PathBuf>,
    /// Position sigma of an anchor whose file gives none (a WPILib layout), metres.
    #[arg(long, default_value_t = stereotag::workflow::survey::DEFAULT_ANCHOR_SIGMA_M)]
    anchor_sigma_m: f64,
    /// Facing sigma of an anchor whose file gives none, degrees.
    #[arg(long, default_value_t = stereotag::workflow::survey::DEFAULT_ANCHOR_SIGMA_DEG)]
    anchor_sigma_deg: f64,
    /// Put the survey's origin at this tag (of the first --family, else tag36h11), x out of its
    /// face, instead of at the robot's start.
    #[arg(long, value_name = "ID")]
    origin_tag: Option<u32>,
    /// Estimate the camera's mounting error on the robot (x, y and yaw of robot_from_left, from
    /// the sightings and the robot's turns), correct the survey with it, report it with sigmas in
    /// report.json (`mounting.*`) and write the corrected rig as camchain_mounting.yaml.
    #[arg(long)]
    estimate_mounting: bool,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    pub rerun: super::RerunArgs,
}

/// Which detector.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Backend {
    /// kornia-apriltag's segmentation and tag families with our port of the C library's quad
    /// fit and decoding (pure Rust).
    Kornia,
    /// kornia-apriltag's own pipeline end to end (for comparison: it finds fewer tags).
    KorniaLibrary,
    /// The AprilRobotics C library.
    ApriltagC,
}

impl From<Backend> for stereotag::visual::tags::Backend {
    fn from(b: Backend) -> Self {
        match b {
            Backend::Kornia => Self::Kornia,
            Backend::KorniaLibrary => Self::KorniaLibrary,
            Backend::ApriltagC => Self::ApriltagC,
        }
    }
}

/// How a run's stereo pairs are searched for tags (survey and localize).
#[derive(Debug, clap::Args)]
pub struct DetectArgs {
    /// Detector backend.
    #[arg(long, value_enum, default_value = "apriltag-c")]
    backend: Backend,
    /// Tag families to look for (default: the world's or the survey's and those the
    /// --tag-sizes table names, else tag36h11).
    #[arg(long)]
    family: Vec<String>,
    /// Decimation before quad detection [default: 1.5 with the C library, 1 with kornia]. 1 is
    /// full resolution: about 25% slower, and finds the farthest tags 1.5 misses; the C library
    /// still decodes and refines the corners at full resolution either way.
    #[arg(long)]
    decimate: Option<f32>,
    /// Edge length of the tags in metres when no world gives it (enables the size check; the
    /// size landmarks.json gives).
    #[arg(long)]
    tag_size_m: Option<f64>,
    /// Tag sizes per tag (YAML: `default: 0.16` and `tags:` a list of `{id, size_m}` with an
    /// optional `family`, whose families are looked for when --family is not given); a world
    /// file's sizes come first, --tag-size-m is the default.
    #[arg(long, value_name = "FILE")]
    tag_sizes: Option<std::path::PathBuf>,
    /// Smallest white-to-black grey difference around a 4x4 tile for it to be searched (both
    /// backends). The default skips wall texture and sensor noise, which is what most detection
    /// time goes to (museum run: 10x faster than the C library's 5, the same tags found); lower
    /// it for dim or low-contrast tags.
    #[arg(long, default_value_t = SURVEY_MIN_CONTRAST)]
    min_contrast: u8,
    /// When the run's rig does not say where it sits on the robot (no robot_from_left, or the
    /// identity that `calibrate` writes), take the left camera at the robot centre, looking
    /// ahead, 0.3 m up, instead of stopping.
    #[arg(long)]
    default_mounting: bool,
}

impl DetectArgs {
    /// The detector options these flags give (the survey's defaults where none is given).
    pub(crate) fn options(&self) -> anyhow::Result<DetectOptions> {
        let backend = self.backend.into();
        let families = super::families(&self.family)?;
        let mut tag_sizes = match &self.tag_sizes {
            Some(path) => stereotag::io::load_tag_sizes(path)?,
            None => Default::default(),
        };
        if self.tag_size_m.is_some() {
            tag_sizes.default_m = self.tag_size_m;
        }
        Ok(DetectOptions {
            families,
            decimate: self.decimate.unwrap_or(survey_decimate(backend)),
            min_contrast: self.min_contrast,
            tag_sizes,
            default_mounting: self.default_mounting,
            ..DetectOptions::survey(backend)
        })
    }
}

impl SurveyArgs {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let detect = self.detect.options()?;
        for (name, v) in [
            ("--anchor-sigma-m", self.anchor_sigma_m),
            ("--anchor-sigma-deg", self.anchor_sigma_deg),
        ] {
            if !(v.is_finite() && v > 0.0) {
                anyhow::bail!("{name} {v}: must be a positive number");
            }
        }
        let anchors = stereotag::workflow::survey::Anchoring {
            file: self.anchors.as_deref(),
            default_sigma: (self.anchor_sigma_m, self.anchor_sigma_deg.to_radians()),
            origin_tag: self.origin_tag.map(|id| stereotag::visual::tags::TagId {
                family: detect
                    .families
                    .first()
                    .copied()
                    .unwrap_or(stereotag::visual::tags::TagFamily::Tag36h11),
                id,
            }),
        };
        let output = survey(
            &SurveyRequest {
                run_dir: &self.run,
                out: &self.out,
                world: self.world.as_deref(),
                config: self.config.as_deref(),
                calibration_from: self.calibration_from.as_deref(),
                detect,
                force: self.force,
                recording: self.rerun.request()?,
                anchors,
                estimate_mounting: self.estimate_mounting,
            },
            &Bars::new(quiet),
        )?;
        print_summary(&output.survey, &output.scores, output.world.as_ref());
        Ok(())
    }
}

/// Prints the landmarks, the planned-versus-surveyed table and the before/after figures.
pub(crate) fn print_summary(s: &Survey, scores: &SurveyScores, world: Option<&World>) {
    tracing::info!(
        "{} landmarks ({} matched with a Hough corner); {} sightings fused, {} gated out; offline graph: {} keyframes, {} factors",
        s.landmarks.len(),
        s.landmarks.iter().filter(|l| l.matched_corner.is_some()).count(),
        s.online.accepted.len(),
        s.online.rejected.len(),
        s.offline.keyframes,
        s.offline.factors,
    );
    let closing: usize = s.online.resolves.iter().map(|r| r.loop_sightings).sum();
    if closing > 0 {
        tracing::info!(
            "{closing} re-sightings the filter's gate turned away closed a loop: the graph of the run so far explained them within the odometry's noise ({} loop hypotheses tested)",
            s.online.loop_tests
        );
    }
    if let Some(w) = world {
        for l in &s.landmarks {
            if let Some(t) = w.tag(l.family, l.id) {
                let d =
                    nalgebra::Vector3::from(l.position_m) - nalgebra::Vector3::from(t.position_m);
                tracing::info!(
                    "  tag {:>3}: planned ({:.3}, {:.3}, {:.3}) surveyed ({:.3}, {:.3}, {:.3}) m, displacement {:.1} mm, turned {:.1} deg",
                    l.id, t.position_m[0], t.position_m[1], t.position_m[2],
                    l.position_m[0], l.position_m[1], l.position_m[2], d.norm() * 1e3,
                    l.rotation().angle_to(&t.rotation()).to_degrees()
                );
            }
        }
    }
    let truth = scores.truth.as_ref();
    if let Some(TrajectoryErrors {
        odometry: Some(o),
        online: Some(on),
        offline: Some(off),
    }) = truth.map(|t| t.ate_m)
    {
        tracing::info!("trajectory ATE: odometry {o:.3} m, online {on:.3} m, offline {off:.3} m");
    }
    let pr = |m: MapScore| format!("{:.3}/{:.3}", m.occupied_precision, m.occupied_recall);
    if s.raw.readings == 0 {
        tracing::info!(
            "no sonar readings: the survey stands on the tags and the odometry, its map is empty"
        );
    } else if let Some(w) = &scores.world {
        tracing::info!(
            "map occupied precision/recall: raw {}, online {}, corrected {}{}",
            pr(w.raw.counting),
            pr(w.online_map),
            pr(w.corrected_map),
            w.ground_truth_map.map_or(String::new(), |g| format!(
                ", with ground-truth poses {}",
                pr(g)
            ))
        );
    } else if let Some((raw, corrected)) = truth.and_then(|t| {
        t.raw_vs_ground_truth_map
            .zip(t.corrected_vs_ground_truth_map)
    }) {
        // No world: the map the ground-truth poses give is the reference.
        tracing::info!(
            "map occupied precision/recall against the ground-truth poses' map: raw {}, corrected {}",
            pr(raw),
            pr(corrected)
        );
    }
    if let Some(m) = scores.world.as_ref().and_then(|w| w.landmarks.median_m) {
        tracing::info!("landmark position error: median {:.1} mm", m * 1e3);
    }
}
