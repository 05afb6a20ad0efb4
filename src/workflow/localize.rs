//! Track a later run against a survey: its tags against the surveyed landmarks, its sonar against
//! the surveyed walls, its odometry corrected with the survey's calibration; how the error grows
//! between sightings, written as `localization.csv` and a report, and recorded.

use super::sightings::{detect_run, DetectOptions, RunSightings};
use super::survey::load_run_rig;
use super::{load_run, load_world_of_run, Error, Result, Warnings};
use crate::dataset::RunDataset;
use crate::fusion::{
    self, FuseConfig, Landmark, LocalizeResult, OdometryCalibration, OdometryNoiseScale,
};
use crate::geometry::{Pose2, StampedPose};
use crate::io::{self, OutputDir};
use crate::metrics::{
    error_growth, localization_metrics, score_localization, GrowthBin, LocalizationCounts,
    LocalizationScores, Located,
};
use crate::progress::{staged, Progress};
use crate::sonar::grid::OccupancyMap;
use crate::sonar::walls::WallSegment;
use crate::sonar::BeamModel;
use crate::visual::tags::TagFamily;
use crate::viz::{LocalizeScene, Recorder, Recording, RecordingRequest};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;

/// What to localise against what.
#[derive(Debug, Clone)]
pub struct LocalizeRequest<'a> {
    /// A survey output directory (its `landmarks.json` is the map of tags, its
    /// `walls_corrected.csv` the walls).
    pub survey: &'a Path,
    /// The run to track.
    pub run_dir: &'a Path,
    /// The output directory.
    pub out: &'a Path,
    /// A world file for the tag sizes (default: the one run.yaml names, if it exists; without
    /// one, the sizes `detect` gives, else those the survey used).
    pub world: Option<&'a Path>,
    /// Fusion settings (YAML).
    pub config: Option<&'a Path>,
    /// How the tags are detected (families: the survey's when none are given).
    pub detect: DetectOptions,
    /// Track with the run's odometry as logged, not corrected with the survey's calibration.
    pub raw_odometry: bool,
    /// Track with the tags alone, not the sonar against the survey's walls.
    pub no_walls: bool,
    /// Where the run starts (default: where the survey's run did).
    pub start: fusion::Start,
    /// Replace the output directory if it exists.
    pub force: bool,
    /// Where the recording goes (default: `localize.rrd` in the output).
    pub recording: RecordingRequest,
}

/// What a localisation produced, beyond its files.
#[derive(Debug, Clone)]
pub struct LocalizeOutput {
    /// The filter's result.
    pub result: LocalizeResult,
    /// The surveyed landmarks tracked against.
    pub landmarks: Vec<Landmark>,
    /// The surveyed walls the sonar was matched against.
    pub walls: Vec<WallSegment>,
    /// Error statistics by distance since the last sighting.
    pub growth: Vec<GrowthBin>,
    /// The scores against the run's ground truth, when it has one.
    pub scores: Option<LocalizationScores>,
    /// The figures of `report.json`.
    pub metrics: serde_json::Map<String, serde_json::Value>,
    /// What it had to work with (also in `metrics`).
    pub counts: LocalizationCounts,
    /// What it did and how well, a sentence each ([`summary`]): printed by `localize` and the
    /// opening of its recording's report.
    pub summary: Vec<String>,
    /// The warnings it printed: what reading the run warned of (rows re-ordered, an odometry
    /// jump, a world named but missing), a survey without walls, a run without stereo pairs,
    /// each time the filter found itself lost.
    pub warnings: Vec<String>,
}

/// The survey's walls, unless told not to use them or the survey has none, and the covariance
/// of their placement when the survey measured it (`walls_corrected_covariance.csv`).
fn surveyed_walls(
    survey: &Path,
    no_walls: bool,
    warnings: &mut Warnings,
) -> Result<(Vec<WallSegment>, Option<nalgebra::DMatrix<f64>>)> {
    let path = survey.join("walls_corrected.csv");
    if no_walls {
        return Ok((Vec::new(), None));
    }
    if !path.exists() {
        warnings.warn(format!(
            "{} not found (a survey of an older version): tracking with the tags alone",
            path.display()
        ));
        return Ok((Vec::new(), None));
    }
    let walls = io::load_walls_csv(&path)?;
    let covariance = survey.join("walls_corrected_covariance.csv");
    let covariance = if covariance.exists() {
        Some(io::load_walls_covariance_csv(&covariance, walls.len())?)
    } else {
        None
    };
    let mut placed: Vec<f64> = walls.iter().filter_map(|w| w.sigma_m).collect();
    placed.sort_by(f64::total_cmp);
    if !placed.is_empty() {
        tracing::info!(
            "the survey placed {} of the {} walls within {:.1} cm (median sigma){}",
            placed.len(),
            walls.len(),
            100.0 * placed[placed.len() / 2],
            if covariance.is_some() {
                ", with how they err together"
            } else {
                ""
            }
        );
    }
    Ok((walls, covariance))
}

/// What of a survey a localisation uses.
#[derive(Debug, Clone, Copy, Default)]
pub struct SurveyUse {
    /// Track with the run's odometry as logged, not corrected with the survey's calibration.
    pub raw_odometry: bool,
    /// Track with the tags alone, not the sonar against the survey's walls nor a lidar against
    /// its returns (their files are not read).
    pub no_walls: bool,
}

/// What a survey gives a localisation, read from its output directory: the map a robot
/// localises in ([`SurveyedMap::localizer`]).
///
/// ```no_run
/// use std::path::Path;
/// use stereotag::fusion::{FuseConfig, Start};
/// use stereotag::geometry::Pose2;
/// use stereotag::workflow::localize::{SurveyUse, SurveyedMap};
///
/// let map = SurveyedMap::load(Path::new("surveys/office"), SurveyUse::default())?;
/// let layout = stereotag::io::load_run(Path::new("runs/office-monday"))?.meta.robot.sonar;
/// let mut filter = map.localizer(FuseConfig::default(), Start::Unknown, Some(&layout));
/// filter.odometry(0.0, Pose2::new(0.0, 0.0, 0.0));
/// println!("{:?}", filter.estimate());
/// # Ok::<(), stereotag::workflow::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct SurveyedMap {
    /// The surveyed tags (`landmarks.json`).
    pub landmarks: Vec<Landmark>,
    /// The corrected walls (`walls_corrected.csv`).
    pub walls: Vec<WallSegment>,
    /// The covariance of the walls' placement, when the survey measured it
    /// (`walls_corrected_covariance.csv`).
    pub walls_covariance: Option<nalgebra::DMatrix<f64>>,
    /// Where a laser's returns fell in the survey (`returns_corrected.pgm`): a lidar's scans are
    /// matched with them instead of its ranges with the walls.
    pub returns: Option<OccupancyMap>,
    /// The odometry's errors the survey found, unless told to track with the raw odometry.
    pub calibration: Option<OdometryCalibration>,
    /// How noisy the survey found the calibrated odometry against the model (with
    /// `calibration` only).
    pub noise_scale: Option<OdometryNoiseScale>,
    /// Where the survey's run's odometry frame lies in the survey's frame (an anchored survey).
    pub frame_from_odometry: Option<Pose2>,
    /// What reading it warned of, as printed: a survey without walls.
    pub warnings: Vec<String>,
}

impl SurveyedMap {
    /// Reads the survey in directory `survey` (`landmarks.json`, and unless `using.no_walls`
    /// its walls and a lidar's returns), naming the file and line of anything bad.
    pub fn load(survey: &Path, using: SurveyUse) -> Result<Self> {
        let file = io::load_landmarks(&survey.join("landmarks.json"))?;
        let mut warnings = Warnings::default();
        let (walls, walls_covariance) = surveyed_walls(survey, using.no_walls, &mut warnings)?;
        let returns = survey.join("returns_corrected.yaml");
        let returns = if !using.no_walls && returns.exists() {
            Some(io::load_ros_occupancy(&returns)?)
        } else {
            None
        };
        Ok(Self {
            warnings: warnings.0,
            walls,
            walls_covariance,
            returns,
            calibration: file.odometry_calibration.filter(|_| !using.raw_odometry),
            noise_scale: file
                .odometry_noise_scale
                .filter(|_| file.odometry_calibration.is_some() && !using.raw_odometry),
            frame_from_odometry: file
                .frame_from_odometry
                .map(|[x, y, theta]| Pose2::new(x, y, theta)),
            landmarks: file.landmarks.into_iter().map(|r| r.landmark).collect(),
        })
    }

    /// The settings a filter predicts with, from `config`: with the turn noise calibrated
    /// odometry leaves and the odometry's noise as the survey measured it, when it calibrated
    /// the odometry.
    pub fn filter_config(&self, config: FuseConfig) -> FuseConfig {
        if self.calibration.is_none() {
            return config;
        }
        let mut c = config.for_calibrated_odometry();
        if let Some(scale) = &self.noise_scale {
            tracing::info!(
                "the survey measured the calibrated odometry's noise against the model: translation {:.2}, turning {:.2}, drift {:.2} times the model's sigmas; predicting with them",
                scale.translation,
                scale.turning,
                scale.drift
            );
            c = c.with_odometry_noise_scale(scale);
        }
        tracing::info!(
            "predicting with {:.4} m per √m travelled, {:.4} heading noise per √rad turned (calibrated odometry)",
            c.odometry_sigma_m_per_sqrt_m,
            c.heading_sigma_per_sqrt_rad
        );
        c
    }

    /// A streaming localiser in this map from `start`, fed the run's odometry as logged (each
    /// increment corrected with the survey's calibration, the start moved into an anchored
    /// survey's frame) and, with the sonar `layout`, its ranges against the walls (a laser's
    /// scans against the survey's returns, when it has them).
    pub fn localizer(
        &self,
        config: FuseConfig,
        start: fusion::Start,
        layout: Option<&crate::sonar::SonarLayout>,
    ) -> fusion::Localizer {
        let mut filter =
            fusion::Localizer::new(self.landmarks.clone(), self.filter_config(config), start);
        let returns = self.returns.as_ref();
        if let (Some(layout), Some(returns)) =
            (layout.filter(|l| l.beam == BeamModel::Ray), returns)
        {
            filter = filter.with_returns(returns, layout.clone());
        } else if let (Some(layout), false) = (layout, self.walls.is_empty()) {
            filter = filter.with_walls(self.walls.clone(), layout.clone());
            if let Some(c) = &self.walls_covariance {
                filter = filter.with_walls_covariance(c.clone());
            }
        }
        if let Some(c) = self.calibration {
            filter = filter.with_calibration(c);
        }
        if let Some(frame) = self.frame_from_odometry {
            filter = filter.with_odometry_frame(frame);
        }
        filter
    }

    /// The tag families the survey holds, each once.
    fn families(&self) -> Vec<TagFamily> {
        let mut families: Vec<_> = self.landmarks.iter().map(|l| l.family).collect();
        families.sort();
        families.dedup();
        families
    }
}

/// The run's odometry, corrected with the survey's calibration when there is one.
fn corrected_odometry<'r>(
    run: &'r RunDataset,
    calibration: Option<&OdometryCalibration>,
) -> Cow<'r, [StampedPose]> {
    match calibration {
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
    }
}

/// Localises a run against a survey and writes `localization.csv`, `report.json` and the
/// recording into a new directory.
///
/// ```no_run
/// use std::path::Path;
/// use stereotag::progress::Silent;
/// use stereotag::visual::tags::Backend;
/// use stereotag::viz::RecordingRequest;
/// use stereotag::workflow::localize::{localize, LocalizeRequest};
/// use stereotag::workflow::sightings::DetectOptions;
///
/// let out = localize(
///     &LocalizeRequest {
///         survey: Path::new("surveys/office"),
///         run_dir: Path::new("runs/office-tuesday"),
///         out: Path::new("localized/office-tuesday"),
///         world: None,
///         config: None,
///         detect: DetectOptions::survey(Backend::ApriltagC),
///         raw_odometry: false,
///         no_walls: false,
///         start: stereotag::fusion::Start::Unknown,
///         force: false,
///         recording: RecordingRequest::none(),
///     },
///     &Silent,
/// )?;
/// let last = out.result.trajectory.last().unwrap();
/// println!("ended at {:?}", last.pose);
/// # Ok::<(), stereotag::workflow::Error>(())
/// ```
pub fn localize(request: &LocalizeRequest<'_>, progress: &dyn Progress) -> Result<LocalizeOutput> {
    let surveyed = SurveyedMap::load(
        request.survey,
        SurveyUse {
            raw_odometry: request.raw_odometry,
            no_walls: request.no_walls,
        },
    )?;
    // What reading the run warned of goes into report.json with the rest.
    let (loaded, read) = super::capturing_warnings(|| -> Result<_> {
        let run = load_run(request.run_dir)?;
        let world = load_world_of_run(request.world, request.run_dir, &run)?;
        Ok((run, world))
    });
    let (run, world) = loaded?;
    let calibration = surveyed.calibration.as_ref();
    let mut odometry = corrected_odometry(&run, calibration);
    if let (Some(frame), fusion::Start::Survey) = (surveyed.frame_from_odometry, request.start) {
        // The survey is in its anchors' frame: the run leaves from where the survey's did, there.
        tracing::info!(
            "the survey is anchored: the run's odometry is moved into its frame by ({:.3}, {:.3}) m, {:.1} degrees, as the survey's run was",
            frame.x,
            frame.y,
            frame.theta.to_degrees()
        );
        odometry = crate::geometry::transformed(frame, &odometry).into();
    }
    let layout =
        (!surveyed.walls.is_empty() || surveyed.returns.is_some()).then_some(&run.meta.robot.sonar);
    let filter = surveyed.localizer(io::load_fuse_config(request.config)?, request.start, layout);
    let matches_scans = filter.matches_scans();
    let mut warnings = Warnings(surveyed.warnings.iter().cloned().chain(read).collect());
    let lidar = run.meta.robot.sonar.beam == BeamModel::Ray && !run.sonar.is_empty();
    if lidar && !matches_scans && !surveyed.walls.is_empty() {
        warnings.warn(format!(
            "{} has no returns_corrected.pgm (a survey by an older version, or of a sonar): the lidar's ranges are matched with its walls one at a time, which pulls a real lidar's run off (docs/RESULTS.md); survey again, or localize with --no-walls",
            request.survey.display()
        ));
    }
    let dir = OutputDir::create(request.out, request.force)?;
    let recorder = Recorder::open(
        &request.recording,
        Recording::Localization,
        &dir.path("localize.rrd"),
    )?;
    let no_sizes_given = request.detect.tag_sizes == Default::default();
    let options = DetectOptions {
        families: if request.detect.families.is_empty() {
            surveyed.families()
        } else {
            request.detect.families.clone()
        },
        // The printed sizes: a world's first, else those given, else those the survey used.
        tag_sizes: if no_sizes_given {
            fusion::surveyed_tag_sizes(&surveyed.landmarks)
        } else {
            request.detect.tag_sizes.clone()
        },
        visual_odometry: filter.config().visual_odometry,
        keep_images: false,
        ..request.detect.clone()
    };
    let seen = match load_run_rig(request.run_dir, &run, request.detect.default_mounting)? {
        Some(rig) => detect_run(
            &options,
            request.run_dir,
            &run,
            &rig,
            world.as_ref(),
            progress,
        )?,
        None => {
            warnings.warn(super::survey::no_stereo_pairs(&run));
            RunSightings::default()
        }
    };
    // The filter corrects the odometry as logged with the survey's calibration, and moves it
    // into an anchored survey's frame, itself; `odometry` is that for the report.
    let obs = fusion::Observations {
        odometry: &run.odometry,
        sightings: &seen.sightings,
        visual: &seen.visual,
    };
    let result = staged(progress, "localize", || {
        fusion::track(filter, &obs, &run.sonar)
    });
    for t in &result.relocalised_t_s {
        warnings.warn(format!(
            "lost at t = {t:.1} s: {} sightings in a row were gated out and agreed among \
             themselves; started again from them",
            fusion::RELOCALISE_AFTER
        ));
    }
    for t in &result.relocalised_by_scans_t_s {
        warnings.warn(format!(
            "lost at t = {t:.1} s: {} times in a row the latest scans, found in the whole map, \
             put the robot away from the pose held and agreed among themselves; started again \
             from them",
            fusion::RELOCALISE_AFTER
        ));
    }
    let SurveyedMap {
        landmarks,
        walls,
        returns,
        ..
    } = surveyed;
    // A lidar's scans matched with the survey's returns leave the walls unused.
    let (walls, returns) = match matches_scans {
        true => (Vec::new(), returns),
        false => (walls, None),
    };
    let truth = run.ground_truth.as_deref();
    let growth = error_growth(&result, truth);
    io::save_localization_csv(&dir.path("localization.csv"), &run.odometry, &result, truth)?;
    io::save_tum(&dir.path("localized.tum"), &result.trajectory)?;
    io::save_tum(&dir.path("odometry.tum"), &run.odometry)?;
    if calibration.is_some() {
        io::save_tum(&dir.path("odometry_calibrated.tum"), &odometry)?;
    }
    if let Some(truth) = truth {
        io::save_tum(
            &dir.path("ground_truth.tum"),
            &io::truth_at(truth, &result.trajectory),
        )?;
    }
    let counts = LocalizationCounts {
        walls: walls.len(),
        visual_turns: seen.visual.len(),
        ranges_at_shortest: run
            .meta
            .robot
            .sonar
            .count_at_shortest_range(run.sonar.iter().map(|r| r.range_m)),
    };
    let calibrated = calibration.is_some();
    let scores =
        truth.map(|t| score_localization(&result, &run.odometry, &odometry, calibrated, t));
    let summary = summary(
        &result,
        (landmarks.len(), walls.len()),
        &counts,
        scores.as_ref(),
    );
    let mut metrics = localization_metrics(&result, calibrated, scores.as_ref(), counts);
    if let Some(scale) = surveyed.noise_scale {
        metrics.insert(
            "odometry.noise_scale_translation".into(),
            scale.translation.into(),
        );
        metrics.insert("odometry.noise_scale_turning".into(), scale.turning.into());
        metrics.insert("odometry.noise_scale_drift".into(), scale.drift.into());
    }
    io::save_json(
        &dir.path("report.json"),
        &serde_json::json!({ "metrics": metrics, "error_growth": growth, "warnings": warnings.0 }),
    )?;
    if let Some(rec) = recorder {
        let numbers: BTreeMap<String, f64> = metrics
            .iter()
            .filter_map(|(k, v)| Some((k.clone(), v.as_f64()?)))
            .collect();
        let scene = LocalizeScene {
            run: &run,
            world: world.as_ref(),
            calibrated_odometry: calibrated.then_some(&*odometry),
            landmarks: &landmarks,
            walls: &walls,
            returns: returns.as_ref(),
            sightings: &seen.sightings,
            result: &result,
            growth: &growth,
            metrics: &numbers,
            summary: &summary,
            warnings: &warnings.0,
        };
        staged(progress, "record", || rec.log_localization(&scene))
            .map_err(|e| Error::from(e).during("recording the localisation"))?;
        rec.finish()
            .map_err(|e| Error::from(e).during("finishing the recording"))?;
    }
    dir.commit()?;
    Ok(LocalizeOutput {
        result,
        landmarks,
        walls,
        growth,
        scores,
        metrics,
        counts,
        summary,
        warnings: warnings.0,
    })
}

/// What a localisation did and how well, a sentence each: the sightings fused, when an unknown
/// start was found, the poses taken from the walls, the ranges fused (against `walls` surveyed
/// walls; `landmarks` the surveyed tags), and with the truth the ATE and whether the sigma
/// reported was honest (NEES).
pub fn summary(
    result: &LocalizeResult,
    (landmarks, walls): (usize, usize),
    counts: &LocalizationCounts,
    scores: Option<&LocalizationScores>,
) -> Vec<String> {
    let mut lines = vec![format!(
        "{} sightings of {landmarks} surveyed tags fused ({} gated out, {} of unknown tags)",
        result.accepted.len(),
        result.rejected.len(),
        result.unknown.len()
    )];
    if let Some(t) = result.located_t_s {
        // The first sample from then on: the pose the sighting gave, with its sigma.
        let sigma = result
            .trajectory
            .iter()
            .zip(&result.sigma_m)
            .find(|(p, _)| p.t_s >= t)
            .map_or(f64::NAN, |(_, s)| *s);
        let by = if result.located_by_scan {
            "a lidar scan found in the survey's returns"
        } else {
            "the first sighting of a surveyed tag"
        };
        lines.push(format!(
            "located at t = {t:.1} s by {by} (position sigma then {sigma:.2} m{})",
            if sigma > 1.0 {
                ": a far tag places the robot on an arc around it; the next tags or the walls say where"
            } else {
                ""
            }
        ));
    }
    if let Some(first) = result.wall_fixed_t_s.first() {
        let times = match result.wall_fixed_t_s.len() {
            1 => "once".to_string(),
            n => format!("{n} times"),
        };
        lines.push(format!(
            "the pose was taken from the walls {times} (first at t = {first:.1} s): the filter was too unsure of it to match ranges one at a time",
        ));
    }
    if !result.scan_outcomes.is_empty() || result.scans_unmatched > 0 {
        let fused = result.scan_outcomes.iter().filter(|o| o.1).count();
        lines.push(format!(
            "{fused} lidar scans fused against the survey's returns ({} gated out, {} not matched: too few returns near the survey's, or the pose left unsure)",
            result.scan_outcomes.len() - fused,
            result.scans_unmatched
        ));
    }
    if walls > 0 {
        let at_shortest = counts.ranges_at_shortest;
        lines.push(format!(
            "{} sonar ranges fused against {walls} surveyed walls ({} gated out{})",
            result.ranges_fused(),
            result.ranges_gated_out(),
            if at_shortest > 0 {
                format!(
                    "; {at_shortest} echoes at the sonar's shortest range not taken as distances"
                )
            } else {
                String::new()
            }
        ));
    }
    let Some(scores) = scores else {
        return lines;
    };
    if let (Some(a), Some(b)) = (scores.ate_odometry_m, scores.ate_localized_m) {
        lines.push(format!("ATE: odometry {a:.3} m, localised {b:.3} m"));
    }
    // After an unknown start: how well it did once a sighting placed it, and whether the sigma
    // it reported covered its error before that too.
    let nees = match (result.located_t_s, scores.located) {
        (Some(_), Some(Located { from_t_s, ate_m })) => {
            if let Some(ate) = ate_m {
                lines.push(format!(
                    "from t = {from_t_s:.1} s, once located: ATE {ate:.3} m"
                ));
            }
            format!(
                "{:.2} once located, {:.2} from the start",
                scores.nees_located, scores.nees_from_start
            )
        }
        _ => format!("{:.2}", scores.nees_located),
    };
    lines.push(format!(
        "position NEES {nees} (near 1: the sigma reported is honest; well above it: overconfident); largest error {:.1} sigmas",
        scores.worst_error_over_sigma
    ));
    if scores.nees_located > NEES_OVERCONFIDENT {
        lines.push(
            "overconfident: either the odometry is noisier than the filter predicts with (a \
             corrected log's odometry, reset at each scan, is: its import warns), which \
             `localize --config` with the odometry sigmas of `stereotag config --default fuse` \
             scaled up tests, or the survey's own map is off the truth, which no sigma here \
             knows (docs/RESULTS.md, \"What the real logs' localisation NEES measures\")"
                .into(),
        );
    }
    lines
}

/// A run's position NEES (its mean, per degree of freedom) over this says the sigma reported is
/// too small for the error, and the summary says why it may be (an honest filter's stays near 1:
/// 0.8-1.4 on the simulated homes; the real Radish logs' as logged 4-6).
const NEES_OVERCONFIDENT: f64 = 3.0;
