//! Survey a run: its tags detected and triangulated, fused with the odometry and the sonar's
//! corners online and offline, the map rebuilt from the corrected trajectory; the survey
//! outputs written, scored when the world is known, and recorded.

use super::sightings::known_tag_size;
use super::sightings::{detect_run, DetectOptions, KeptPair, RunSightings};
use super::{load_run, load_world_of_run, Error, Result, Warnings};
use crate::camera::StereoRig;
use crate::dataset::RunDataset;
use crate::fusion::{self, OdometryCalibration, Survey};
use crate::geometry::Pose2;
use crate::io::{self, OutputDir};
use crate::metrics::{score_survey, survey_metrics, SurveyScores};
use crate::progress::{staged, timed, Progress};
use crate::sonar::grid::GridError;
use crate::sonar::map::{map_trajectory, SonarMap};
use crate::viz::{Recorder, Recording, RecordingRequest, SurveyScene};
use crate::world::World;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// What to survey and how.
#[derive(Debug, Clone)]
pub struct SurveyRequest<'a> {
    /// The run dataset directory.
    pub run_dir: &'a Path,
    /// The output directory.
    pub out: &'a Path,
    /// A world file to score against and to give planned tag positions (default: the one
    /// run.yaml names, if it exists).
    pub world: Option<&'a Path>,
    /// Fusion settings (YAML); default [`fusion::FuseConfig::default`].
    pub config: Option<&'a Path>,
    /// An earlier survey of the same robot (its directory): the online filter predicts with the
    /// odometry errors it found until the run's own are learnt.
    pub calibration_from: Option<&'a Path>,
    /// How the tags are detected.
    pub detect: DetectOptions,
    /// Replace the output directory if it exists.
    pub force: bool,
    /// Where the recording goes (default: `survey.rrd` in the output).
    pub recording: RecordingRequest,
    /// Known tag poses the survey is solved in the frame of (default: none, the frame is the
    /// robot's start).
    pub anchors: Anchoring<'a>,
    /// Estimate the camera's planar mounting error in the offline pass (x, y, yaw of
    /// `robot_from_left`), correct the survey with it and write the corrected rig as
    /// `camchain_mounting.yaml` (`FuseConfig::estimate_mounting` does the first two alone).
    pub estimate_mounting: bool,
}

impl<'a> SurveyRequest<'a> {
    /// A survey of `run_dir` into `out` at the defaults: the world run.yaml names, the default
    /// fusion settings, the C library at the survey's detector settings, no recording, in the
    /// frame of the run's start; change any field after.
    pub fn new(run_dir: &'a Path, out: &'a Path) -> Self {
        Self {
            run_dir,
            out,
            world: None,
            config: None,
            calibration_from: None,
            detect: DetectOptions::survey(crate::visual::tags::Backend::ApriltagC),
            force: false,
            recording: RecordingRequest::none(),
            anchors: Anchoring::default(),
            estimate_mounting: false,
        }
    }
}

/// The frame a survey is solved in: the robot's start (the default), known tag poses
/// (`--anchors`), or a tag's (`--origin-tag`).
#[derive(Debug, Clone, PartialEq)]
pub struct Anchoring<'a> {
    /// A file of known tag poses: a WPILib AprilTag field layout (JSON) or the YAML of
    /// [`io::load_anchors`].
    pub file: Option<&'a Path>,
    /// The sigmas of an anchor that gives none (a WPILib layout never does): metres, radians.
    pub default_sigma: (f64, f64),
    /// The tag the frame's origin is put at, facing along x.
    pub origin_tag: Option<crate::visual::tags::TagId>,
}

/// An anchor's position sigma when its file gives none: 1 cm (a tag placed by tape on a
/// floor plan).
pub const DEFAULT_ANCHOR_SIGMA_M: f64 = 0.01;
/// ... and its facing's: 1 degree.
pub const DEFAULT_ANCHOR_SIGMA_DEG: f64 = 1.0;

impl Default for Anchoring<'_> {
    fn default() -> Self {
        Self {
            file: None,
            default_sigma: (
                DEFAULT_ANCHOR_SIGMA_M,
                DEFAULT_ANCHOR_SIGMA_DEG.to_radians(),
            ),
            origin_tag: None,
        }
    }
}

impl Anchoring<'_> {
    /// The anchors, loaded.
    fn load(&self) -> Result<Vec<fusion::Anchor>> {
        let mut anchors = match self.file {
            Some(path) => io::load_anchors(path, self.default_sigma)?,
            None => Vec::new(),
        };
        anchors.extend(self.origin_tag.map(fusion::origin_anchor));
        Ok(anchors)
    }

    /// What the anchors are called in messages.
    fn name(&self) -> String {
        match (self.file, self.origin_tag) {
            (Some(f), _) => format!("--anchors {}", f.display()),
            (None, Some(t)) => format!("--origin-tag {}", t.id),
            (None, None) => "no anchors".into(),
        }
    }
}

/// What a survey produced, beyond its files.
#[derive(Debug, Clone)]
pub struct SurveyOutput {
    /// The survey.
    pub survey: Survey,
    /// The scores against the run's ground truth and the world, where known (none for a survey
    /// in a tag's frame).
    pub scores: SurveyScores,
    /// The warnings the survey printed on stderr: what reading the run warned of (rows
    /// re-ordered, an odometry jump, a world named but missing, a rig with no mounting), a run
    /// without stereo pairs, what the raw map hid or left out, tags the filter would not fuse,
    /// sizes the sightings disagree about, sightings mostly gated out, what the offline pass did
    /// not keep ([`fusion::OfflineResult::notes`]), ranges scattering far off the walls, anchors far
    /// from their surveyed tags, a mounting off or not estimated.
    pub warnings: Vec<String>,
    /// Tag sightings in the run's stereo pairs, fused or not.
    pub sightings: usize,
    /// Every figure of `report.json`: the scores' and what needs no truth.
    pub metrics: BTreeMap<String, f64>,
    /// The world it was scored against, if any.
    pub world: Option<World>,
}

/// Surveys a run and writes the survey outputs (DESIGN.md) into a new output directory.
pub fn survey(request: &SurveyRequest<'_>, progress: &dyn Progress) -> Result<SurveyOutput> {
    // Refuse an existing output before the long work, not after.
    let dir = OutputDir::create(request.out, request.force)?;
    let output = survey_into(request, &dir, progress)?;
    dir.commit()?;
    Ok(output)
}

/// A tag whose sightings' triangulated sizes spread more than this (standard deviation over
/// mean) is warned about when no printed size is known: 10% (a tag's size triangulates to a few
/// percent; several different tags under one id, or one moved between sizes, do not).
pub const SIZE_SPREAD_WARNING: f64 = 0.1;

/// Each landmark's size: the printed one when known ([`known_tag_size`]); else the triangulated
/// mean stays, with a warning when the sightings disagree about it (over
/// [`SIZE_SPREAD_WARNING`], from three sightings).
fn size_landmarks(
    landmarks: &mut [fusion::Landmark],
    world: Option<&World>,
    sizes: &crate::visual::sightings::TagSizes,
    warnings: &mut Warnings,
) {
    for l in landmarks {
        match known_tag_size(world, sizes, l.family, l.id) {
            Some(size) => l.size_m = size,
            None if l.observations >= 3 && l.size_spread > SIZE_SPREAD_WARNING => {
                warnings.warn(format!(
                    "{} {}: its {} sightings triangulate to sizes {:.0}% apart (mean {:.3} m) and no printed size is known: give it with --tag-sizes or --tag-size-m",
                    l.family,
                    l.id,
                    l.observations,
                    100.0 * l.size_spread,
                    l.size_triangulated_m
                ));
            }
            None => {}
        }
    }
}

/// What a survey or a localisation says of a run without stereo pairs.
pub(super) fn no_stereo_pairs(run: &RunDataset) -> String {
    format!(
        "the run has no stereo pairs (stereo.csv is empty): its {} ranges and odometry only",
        run.ranging().name()
    )
}

/// The odometry calibration an earlier survey found, from its `landmarks.json`.
fn calibration_of(survey_dir: &Path) -> Result<OdometryCalibration> {
    let path = survey_dir.join("landmarks.json");
    io::load_landmarks(&path)?
        .odometry_calibration
        .ok_or_else(|| {
            Error::Request(format!(
                "{}: no odometry_calibration (a survey whose offline pass did not estimate \
                 one); survey without --calibration-from",
                path.display()
            ))
        })
}

/// The stereo rig of a run with its mounting (run.yaml's, else the rig file's; see
/// [`io::load_mounted_rig`], `default_mounting` its flag), or `None` when the run has no
/// pictures.
pub fn load_run_rig(
    run_dir: &Path,
    run: &RunDataset,
    default_mounting: bool,
) -> Result<Option<StereoRig>> {
    if run.stereo.is_empty() {
        return Ok(None);
    }
    let rig_name = run.meta.robot.rig.as_ref().ok_or_else(|| {
        io::IoError::content(
            &run_dir.join("run.yaml"),
            "the run has stereo pairs but run.yaml names no rig (robot.rig)",
        )
    })?;
    let from_run = run.meta.robot.robot_from_left.map(|v| {
        nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::new(v[0], v[1], v[2]),
            nalgebra::UnitQuaternion::from_euler_angles(v[3], v[4], v[5]),
        )
    });
    Ok(Some(io::load_mounted_rig(
        &run_dir.join(rig_name),
        from_run,
        default_mounting,
    )?))
}

/// A run and what surveying it needs, loaded.
struct Inputs {
    run: RunDataset,
    /// The stereo rig ([`load_run_rig`]).
    rig: Option<StereoRig>,
    world: Option<World>,
    fuse: fusion::FuseConfig,
    calibration: Option<OdometryCalibration>,
    mapping: crate::sonar::map::MappingConfig,
    anchors: Vec<fusion::Anchor>,
}

impl Inputs {
    fn load(request: &SurveyRequest<'_>) -> Result<Self> {
        let run = load_run(request.run_dir)?;
        let rig = load_run_rig(request.run_dir, &run, request.detect.default_mounting)?;
        let world = load_world_of_run(request.world, request.run_dir, &run)?;
        let mut fuse = io::load_fuse_config(request.config)?;
        fuse.estimate_mounting |= request.estimate_mounting;
        let calibration = request.calibration_from.map(calibration_of).transpose()?;
        let mapping = super::mapping_of_run(&run, None);
        Ok(Self {
            run,
            rig,
            world,
            fuse,
            calibration,
            mapping,
            anchors: request.anchors.load()?,
        })
    }
}

/// [`survey`] writing into an output directory under construction (not committed here).
pub fn survey_into(
    request: &SurveyRequest<'_>,
    dir: &OutputDir,
    progress: &dyn Progress,
) -> Result<SurveyOutput> {
    let started = std::time::Instant::now();
    // What reading the run warned of goes into report.json with the rest.
    let (inputs, read) = super::capturing_warnings(|| Inputs::load(request));
    let mut inputs = inputs?;
    let recorder = Recorder::open(
        &request.recording,
        Recording::Survey,
        &dir.path("survey.rrd"),
    )?;
    let rig = inputs.rig.take();
    let mut warnings = Warnings(read);
    if rig.is_none() {
        warnings.warn(no_stereo_pairs(&inputs.run));
    }
    let options = DetectOptions {
        keep_images: recorder.is_some(),
        visual_odometry: inputs.fuse.visual_odometry,
        ..request.detect.clone()
    };
    let mut timings = BTreeMap::new();
    let anchored = !inputs.anchors.is_empty();
    // The camera's mounting error is found first and the rig corrected, before the filters gate
    // the sightings against each other and the visual odometry turns the robot's motion into the
    // camera's with it; the offline pass refines what is left.
    let first_mounting = match (&rig, inputs.fuse.estimate_mounting) {
        (Some(rig), true) => timed("detect_for_mounting", &mut timings, || {
            first_mounting(
                &inputs,
                &options,
                (request.run_dir, rig),
                &mut warnings,
                progress,
            )
        })?,
        _ => None,
    };
    let survey_rig = match (&rig, &first_mounting) {
        (Some(rig), Some(m)) => Some(crate::camera::StereoRig {
            robot_from_left: m.corrected(&rig.robot_from_left),
            ..rig.clone()
        }),
        _ => rig.clone(),
    };
    let (seen, raw, map_raw_s) = timed("detect", &mut timings, || {
        detect_and_map(
            &inputs,
            &options,
            request.run_dir,
            survey_rig.as_ref(),
            progress,
        )
    });
    let seen = seen?;
    // Both alongside each other: "detect" is their wall time, "map_raw" the map's alone.
    timings.insert("map_raw".into(), map_raw_s);
    let mut frame_from_odometry = None;
    let raw = match raw {
        Some(raw) => raw?,
        None => {
            // Anchored: the run is first moved into the anchors' frame, then mapped.
            let frame = anchor_frame(&inputs, &seen, &request.anchors.name())?;
            move_run(&mut inputs, frame);
            frame_from_odometry = Some(frame);
            timed("map_raw", &mut timings, || {
                map_trajectory(
                    &inputs.run.sonar_log(),
                    &inputs.run.odometry,
                    &inputs.mapping,
                )
            })?
        }
    };
    let (run, world, mapping) = (&inputs.run, inputs.world.as_ref(), &inputs.mapping);
    // The pairs are compressed for the recording while the survey runs: it is mostly one thread
    // (grids, Hough, pose graph), which leaves the other core to the JPEG encoder.
    let ((images, compress_s), result) = staged(progress, "fuse", || {
        rayon::join(
            || {
                let t = std::time::Instant::now();
                (compress_pairs(seen.images), t.elapsed().as_secs_f64())
            },
            || {
                let settings = fusion::SurveySettings {
                    mapping,
                    fuse: &inputs.fuse,
                    calibration: inputs.calibration,
                    anchors: &inputs.anchors,
                };
                fusion::survey(run, raw, &seen.sightings, &seen.visual, &settings)
            },
        )
    });
    let mut result = result?;
    result.frame_from_odometry = frame_from_odometry;
    // What the raw map hid or left out, the tags the filter would not fuse, and what follows.
    let raw = &result.raw;
    for w in raw.warnings() {
        warnings.warn(w);
    }
    for c in &result.online.conflicts {
        warnings.warn(format!(
            "tag {} ({}): {} — landmark at ({:.2}, {:.2}) m but {} sightings from t = {:.1} s put it at ({:.2}, {:.2}) m; not fused",
            c.id, c.family, c.kind, c.landmark_m[0], c.landmark_m[1], c.sightings, c.first_t_s,
            c.seen_at_m[0], c.seen_at_m[1]
        ));
    }
    size_landmarks(
        &mut result.landmarks,
        world,
        &request.detect.tag_sizes,
        &mut warnings,
    );
    // Printed by the offline pass as it ran.
    warnings.0.extend(result.offline.notes.iter().cloned());
    let mut metrics = survey_metrics(&result, seen.sightings.len());
    metrics.insert(
        "sightings.implausible_height".into(),
        seen.implausible_height as f64,
    );
    metrics.insert(
        "online.calibration_from_earlier_survey".into(),
        f64::from(u8::from(inputs.calibration.is_some())),
    );
    if let Some(w) = report_range_scatter(run, &result, &inputs.fuse, &mut metrics) {
        warnings.warn(w);
    }
    if anchored {
        report_anchors(
            &result.landmarks,
            &inputs.anchors,
            &mut metrics,
            &mut warnings,
        );
    }
    // The mounting error in all: the offline pass's refinement after the first estimate.
    let mounting = match (first_mounting, result.offline.mounting) {
        (Some(first), Some(rest)) => Some(fusion::MountingEstimate {
            correction: rest.correction.compose(&first.correction),
            covariance: rest.covariance.or(first.covariance),
        }),
        (first, rest) => rest.or(first),
    };
    if inputs.fuse.estimate_mounting {
        report_mounting(mounting.as_ref(), &mut metrics, &mut warnings);
    } else if result.online.rejected.len() > result.online.accepted.len() {
        // A camera mounted other than the rig says breaks the filters this way (museum: 5 cm
        // and 5 degrees off, 214 of 297 sightings gated out).
        warnings.warn(format!(
            "{} of {} sightings were gated out: the sightings disagree with each other and the odometry; is the rig's robot_from_left right? survey --estimate-mounting estimates it",
            result.online.rejected.len(),
            result.online.rejected.len() + result.online.accepted.len()
        ));
    }
    if let (true, Some(m), Some(rig)) = (request.estimate_mounting, mounting.as_ref(), rig.as_ref())
    {
        let mounted = crate::camera::StereoRig {
            robot_from_left: m.corrected(&rig.robot_from_left),
            ..rig.clone()
        };
        let note = format!(
            "robot_from_left corrected by the survey of {} (x {:+.4} m, y {:+.4} m, yaw {:+.3} degrees)",
            request.run_dir.display(),
            m.correction.x,
            m.correction.y,
            m.correction.theta.to_degrees()
        );
        io::save_rig_noted(&dir.path("camchain_mounting.yaml"), &mounted, &[note])?;
    }
    // With the ground truth alone, the trajectories and maps are scored; with the world, all.
    // A survey in a tag's frame is not in theirs: it is not scored.
    let scores = if let Some(tag) = request.anchors.origin_tag {
        tracing::info!(
            "the survey is in tag {}'s frame, not the world's or the ground truth's: it is not scored against them",
            tag.id
        );
        SurveyScores::default()
    } else {
        score_survey(&result, run, world, mapping)?
    };
    metrics.extend(scores.metrics());
    timings.extend(result.timings_s.clone());
    if let Some(rec) = &recorder {
        // Alongside the survey's stages above, which it slows down on a two-core machine.
        timings.insert("record_compress".into(), compress_s);
        let scene = SurveyScene {
            run,
            world,
            survey: &result,
            sightings: &seen.sightings,
            metrics: &metrics,
            scores: &scores,
            warnings: &warnings.0,
            mapping,
            rig: survey_rig.as_ref(),
            images: &images,
        };
        timed("record", &mut timings, || {
            staged(progress, "record", || rec.log_survey(&scene))
        })
        .map_err(|e| Error::from(e).during("recording the survey"))?;
    }
    timings.insert("total".into(), started.elapsed().as_secs_f64());
    io::save_survey(
        &dir.path(""),
        run,
        world,
        &result,
        &metrics,
        &timings,
        &warnings.0,
    )?;
    if let Some(rec) = recorder {
        rec.finish()
            .map_err(|e| Error::from(e).during("finishing the recording"))?;
    }
    Ok(SurveyOutput {
        survey: result,
        scores,
        warnings: warnings.0,
        sightings: seen.sightings.len(),
        metrics,
        world: inputs.world,
    })
}

/// The mounting error of `rig` from the run's sightings and odometry alone
/// ([`fusion::estimate_mounting`]), its tags detected for it without the visual odometry.
fn first_mounting(
    inputs: &Inputs,
    options: &DetectOptions,
    (run_dir, rig): (&Path, &StereoRig),
    warnings: &mut Warnings,
    progress: &dyn Progress,
) -> Result<Option<fusion::MountingEstimate>> {
    let options = DetectOptions {
        visual_odometry: false,
        keep_images: false,
        ..options.clone()
    };
    tracing::info!("estimating the camera's mounting: the tags first, then the survey");
    let seen = detect_run(
        &options,
        run_dir,
        &inputs.run,
        rig,
        inputs.world.as_ref(),
        progress,
    )?;
    let found = fusion::estimate_mounting(&inputs.run.odometry, &seen.sightings, &inputs.fuse);
    if found.is_none() {
        warnings.warn(format!(
            "the camera's mounting cannot be estimated before the survey: no tag is seen twice within {} m of travel",
            fusion::MOUNTING_STRETCH_M
        ));
    }
    Ok(found)
}

/// The run's sightings and visual turns (none without a rig) and, alongside them on the other
/// core, its raw map (the odometry's poses: it needs no pictures), with the map's seconds; no
/// map when the survey is anchored (the run is moved into the anchors' frame first).
fn detect_and_map(
    inputs: &Inputs,
    options: &DetectOptions,
    run_dir: &Path,
    rig: Option<&StereoRig>,
    progress: &dyn Progress,
) -> (Result<RunSightings>, Option<RawMap>, f64) {
    let run = &inputs.run;
    // Without pictures the raw map is all there is to wait for.
    if rig.is_none() {
        progress.start("map", 0);
    }
    let (seen, (raw, seconds)) = rayon::join(
        || match rig {
            Some(rig) => detect_run(options, run_dir, run, rig, inputs.world.as_ref(), progress),
            None => Ok(RunSightings::default()),
        },
        || {
            if !inputs.anchors.is_empty() {
                return (None, 0.0);
            }
            let t = std::time::Instant::now();
            let raw = map_trajectory(&run.sonar_log(), &run.odometry, &inputs.mapping);
            (Some(raw), t.elapsed().as_secs_f64())
        },
    );
    if rig.is_none() {
        progress.finish();
    }
    (seen, raw, seconds)
}

/// `anchors_from_start`: where the anchors put the run's odometry frame, from a first online pass
/// over the odometry and the sightings (`name`: the anchors as the user gave them).
fn anchor_frame(inputs: &Inputs, seen: &RunSightings, name: &str) -> Result<Pose2> {
    let obs = fusion::Observations {
        odometry: &inputs.run.odometry,
        sightings: &seen.sightings,
        visual: &seen.visual,
    };
    let online = fusion::run_online(&obs, &[], &inputs.fuse, inputs.calibration);
    let frame = fusion::anchor_frame(&online.landmarks, &inputs.anchors)
        .map_err(|e| Error::Request(format!("{name}: {e}")))?;
    let seen_anchors = fusion::anchor_residuals(&online.landmarks, &inputs.anchors).len();
    tracing::info!(
        "{name}: {seen_anchors} of {} anchored tags seen; the run's start is at ({:.3}, {:.3}) m, {:.1} degrees in their frame",
        inputs.anchors.len(),
        frame.x,
        frame.y,
        frame.theta.to_degrees()
    );
    Ok(frame)
}

/// Moves the run's odometry by `frame` (`anchors_from_start`); the grid run.yaml sets is kept
/// when that moves no pose by more than a cell, else a grid is fitted to the moved odometry.
fn move_run(inputs: &mut Inputs, frame: Pose2) {
    let run = &mut inputs.run;
    let cell = inputs.mapping.grid.resolution_m;
    let mut moved_most: f64 = 0.0;
    for p in &mut run.odometry {
        let moved = frame.compose(&p.pose);
        moved_most = moved_most.max((moved.x - p.pose.x).hypot(moved.y - p.pose.y));
        p.pose = moved;
    }
    if moved_most > cell {
        tracing::info!(
            "run.yaml's grid is in the odometry's frame, which the anchors move by up to {moved_most:.2} m: a grid is fitted in their frame instead"
        );
        run.meta.mapping = None;
        inputs.mapping = super::mapping_of_run(run, None);
    }
}

/// A mounting error larger than this many of its sigmas is warned about: 3.
const MOUNTING_WARN_SIGMAS: f64 = 3.0;

/// The mounting estimate on stderr and in the metrics (`mounting.*`), with a warning when the
/// rig's mounting is off by more than [`MOUNTING_WARN_SIGMAS`] in x, y or yaw.
fn report_mounting(
    mounting: Option<&fusion::MountingEstimate>,
    metrics: &mut BTreeMap<String, f64>,
    warnings: &mut Warnings,
) {
    let Some(m) = mounting else {
        warnings.warn(
            "the camera's mounting was not estimated: the offline pass kept no solution, or no tag was seen"
                .into(),
        );
        return;
    };
    let c = m.correction;
    let values = [c.x, c.y, c.theta.to_degrees()];
    for (name, v) in ["x_m", "y_m", "yaw_deg"].iter().zip(values) {
        metrics.insert(format!("mounting.{name}"), v);
    }
    let Some(sigmas) = m.sigmas() else {
        warnings.warn(format!(
            "the camera's mounting error estimated as x {:+.4} m, y {:+.4} m, yaw {:+.3} degrees, with no sigma (the run does not determine it: turn the robot while it sees a tag)",
            values[0],
            values[1],
            values[2]
        ));
        return;
    };
    let sigmas = [sigmas[0], sigmas[1], sigmas[2].to_degrees()];
    for (name, v) in ["x_m", "y_m", "yaw_deg"].iter().zip(sigmas) {
        metrics.insert(format!("mounting.sigma_{name}"), v);
    }
    let off = values
        .iter()
        .zip(&sigmas)
        .map(|(v, s)| v.abs() / s.max(1e-12))
        .fold(0.0, f64::max);
    let text = format!(
        "x {:+.4} ± {:.4} m, y {:+.4} ± {:.4} m, yaw {:+.3} ± {:.3} degrees",
        values[0], sigmas[0], values[1], sigmas[1], values[2], sigmas[2]
    );
    if off > MOUNTING_WARN_SIGMAS {
        warnings.warn(format!(
            "the rig's mounting (robot_from_left) is off by {text} ({off:.1} sigmas): survey --estimate-mounting writes the corrected rig"
        ));
    } else {
        tracing::info!("the camera's mounting error: {text} (within its sigmas)");
    }
}

/// How well the survey placed its corrected walls (`walls.placed`, the faces whose placement it
/// measured, and `walls.placement_sigma_m_median`), how its own ranges scatter about them along
/// its corrected trajectory (`walls.range_residual_sigma_m`, `walls.ranges_off_share`,
/// `walls.ranges_matched`, and `walls.range_sigma_assumed_m`, what `localize` takes); returns the
/// warning when they scatter far more than `localize` assumes ([`fusion::RangeScatter::warning`]),
/// unless `localize` will match a lidar's scans with the survey's returns instead.
fn report_range_scatter(
    run: &RunDataset,
    result: &fusion::Survey,
    fuse: &fusion::FuseConfig,
    metrics: &mut BTreeMap<String, f64>,
) -> Option<String> {
    let mut placed: Vec<f64> = result
        .corrected
        .walls
        .iter()
        .filter_map(|w| w.sigma_m)
        .collect();
    placed.sort_by(f64::total_cmp);
    metrics.insert("walls.placed".into(), placed.len() as f64);
    if let Some(&median) = placed.get(placed.len() / 2) {
        metrics.insert("walls.placement_sigma_m_median".into(), median);
        tracing::info!(
            "{} of the {} corrected walls placed within {:.1} cm (median sigma, from the offline trajectory's covariance; walls_corrected.csv's sigma_m)",
            placed.len(),
            result.corrected.walls.len(),
            100.0 * median
        );
    }
    let sonar = fusion::SonarInput {
        readings: &run.sonar,
        layout: &run.meta.robot.sonar,
        walls: &result.corrected.walls,
        walls_covariance: None,
    };
    let scatter = fusion::range_scatter(&sonar, &result.offline.trajectory)?;
    metrics.insert("walls.range_residual_sigma_m".into(), scatter.sigma_m);
    metrics.insert("walls.ranges_off_share".into(), scatter.off_share);
    metrics.insert("walls.ranges_matched".into(), scatter.matched as f64);
    metrics.insert(
        "walls.range_sigma_assumed_m".into(),
        scatter.assumed_sigma_m(fuse),
    );
    // A lidar's later runs are matched with the survey's returns, not with its walls.
    scatter.warning(fuse).filter(|_| result.returns.is_none())
}

/// Each anchor's residual in the survey, on stderr and in the metrics (`anchors.*`); a warning for
/// one over three of its sigmas.
fn report_anchors(
    landmarks: &[fusion::Landmark],
    anchors: &[fusion::Anchor],
    metrics: &mut BTreeMap<String, f64>,
    warnings: &mut Warnings,
) {
    let residuals = fusion::anchor_residuals(landmarks, anchors);
    metrics.insert("anchors.given".into(), anchors.len() as f64);
    metrics.insert("anchors.seen".into(), residuals.len() as f64);
    for r in &residuals {
        let key = format!("anchors.{}_{}", r.tag.family, r.tag.id);
        metrics.insert(format!("{key}.residual_m"), r.distance_m);
        metrics.insert(format!("{key}.residual_sigmas"), r.sigmas);
        if let Some(yaw) = r.yaw_rad {
            metrics.insert(format!("{key}.residual_deg"), yaw.to_degrees());
        }
        let yaw = r.yaw_rad.map_or(String::new(), |y| {
            format!(", facing {:+.2} degrees", y.to_degrees())
        });
        if r.sigmas > 3.0 {
            warnings.warn(format!(
                "anchor {} {}: surveyed {:.3} m from where the anchors put it ({:.1} sigmas{yaw}): is the anchor's pose right, or the tag moved?",
                r.tag.family,
                r.tag.id,
                r.distance_m,
                r.sigmas
            ));
        } else {
            tracing::info!(
                "anchor {} {}: residual {:.3} m ({:.1} sigmas{yaw})",
                r.tag.family,
                r.tag.id,
                r.distance_m,
                r.sigmas
            );
        }
    }
    if let Some(worst) = residuals.iter().map(|r| r.distance_m).reduce(f64::max) {
        metrics.insert("anchors.residual_m.max".into(), worst);
    }
}

/// The map along the odometry, before any correction.
type RawMap = std::result::Result<SonarMap, GridError>;

/// The kept pairs compressed for the recording, in parallel, each freed once compressed.
fn compress_pairs(images: Vec<Option<KeptPair>>) -> Vec<Option<(Vec<u8>, Vec<u8>)>> {
    images
        .into_par_iter()
        .map(|pair| match pair? {
            KeptPair::Decoded(l, r) => crate::viz::jpeg_pair(&l, &r),
            KeptPair::Jpeg(l, r) => Some((l, r)),
        })
        .collect()
}
