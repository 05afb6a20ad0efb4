use super::detect::{check_image_size, Backend};
use super::{progress, Pool, UsageError};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use stereotag::camera::StereoRig;
use stereotag::dataset::RunDataset;
use stereotag::fusion::survey;
use stereotag::fusion::Survey;
use stereotag::fusion::{FuseConfig, TagSighting};
use stereotag::geometry::pose_at;
use stereotag::io::{self, LandmarkRecord, LandmarksFile, OutputDir, Trajectories};
use stereotag::metrics::score_survey;
use stereotag::metrics::survey_metrics;
use stereotag::sonar::map::raw_map;
use stereotag::visual::sightings::sightings_from_pair;
use stereotag::visual::stereo::StereoConfig;
use stereotag::visual::tags::{CDetector, DetectorConfig, KorniaDetector, TagDetector, TagFamily};
use stereotag::visual::vo::{frame_pairs, relative_motion, VisualTurn, VoConfig, VoImage};
use stereotag::world::World;

/// Arguments of `stereotag survey`.
#[derive(Debug, clap::Args)]
pub struct SurveyArgs {
    /// Run dataset directory.
    #[arg(long)]
    run: PathBuf,
    /// Output directory.
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
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    pub rerun: super::RerunArgs,
}

/// How a run's stereo pairs are searched for tags (survey and localize).
#[derive(Debug, clap::Args)]
pub struct DetectArgs {
    /// Detector backend.
    #[arg(long, value_enum, default_value = "apriltag-c")]
    backend: Backend,
    /// Tag families to look for (default: the world's or the survey's, else tag36h11).
    #[arg(long)]
    family: Vec<String>,
    /// Decimation before quad detection [default: 1.5 with the C library, 1 with kornia]. 1 is
    /// full resolution: about 25% slower, and finds the farthest tags 1.5 misses; the C library
    /// still decodes and refines the corners at full resolution either way.
    #[arg(long)]
    decimate: Option<f32>,
    /// Edge length of the tags in metres when no world gives it (enables the size check).
    #[arg(long)]
    tag_size_m: Option<f64>,
    /// Smallest white-to-black grey difference around a 4x4 tile for it to be searched (both
    /// backends). The default skips wall texture and sensor noise, which is what most detection
    /// time goes to (museum run: 10x faster than the C library's 5, the same tags found); lower
    /// it for dim or low-contrast tags.
    #[arg(long, default_value_t = DEFAULT_MIN_CONTRAST)]
    min_contrast: u8,
}

/// The survey's default `--decimate` for a backend: 1.5 for the C library (the museum survey in
/// 2 s on two cores, README *Speed*), 1 for kornia-apriltag, which decimates by whole factors.
pub(crate) fn default_decimate(backend: Backend) -> f32 {
    match backend {
        Backend::ApriltagC => 1.5,
        Backend::Kornia | Backend::KorniaLibrary => 1.0,
    }
}

/// The survey's default `--min-contrast`: a printed tag's black border on white is far above
/// it even when dim, sensor noise and wall texture mostly below (30 and 40 find the same tags
/// on the ten office and museum runs, 60 on office and museum seed 1; 40 finds the same 47 in
/// the C library's test photos as 5).
pub(crate) const DEFAULT_MIN_CONTRAST: u8 = 40;

impl DetectArgs {
    /// The options these flags give; `default_families` when no `--family` is given.
    pub(crate) fn options<'a>(
        &'a self,
        default_families: &'a [String],
        quiet: bool,
    ) -> DetectOptions<'a> {
        DetectOptions {
            keep_images: false,
            backend: self.backend,
            families: if self.family.is_empty() {
                default_families
            } else {
                &self.family
            },
            decimate: self.decimate.unwrap_or(default_decimate(self.backend)),
            min_contrast: self.min_contrast,
            tag_size_m: self.tag_size_m,
            quiet,
            visual_odometry: false,
        }
    }
}

/// What the survey command produced, for the demo's summary.
pub(crate) struct SurveyOutput {
    pub survey: Survey,
    pub metrics: BTreeMap<String, f64>,
}

impl SurveyArgs {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        survey_run(&SurveyJob {
            run_dir: &self.run,
            out: &self.out,
            world: self.world.as_deref(),
            config: self.config.as_deref(),
            calibration_from: self.calibration_from.as_deref(),
            detect: self.detect.options(&[], quiet),
            force: self.force,
            rerun: &self.rerun,
        })
        .map(|_| ())
    }
}

/// How tags are detected in a run's stereo pairs.
#[derive(Clone)]
pub(crate) struct DetectOptions<'a> {
    /// Keep each decoded pair for the recording (which compresses them while the survey runs).
    pub keep_images: bool,
    pub backend: Backend,
    pub families: &'a [String],
    pub decimate: f32,
    pub min_contrast: u8,
    pub tag_size_m: Option<f64>,
    pub quiet: bool,
    /// Measure the turns between pictures ([`stereotag::visual::vo`]) as well.
    pub visual_odometry: bool,
}

/// A decoded stereo pair (left, right).
pub(crate) type GrayPair = (image::GrayImage, image::GrayImage);

/// A stereo pair kept for the recording.
pub(crate) enum KeptPair {
    /// Decoded, to be compressed while the survey's single-threaded stages run.
    Decoded(GrayPair),
    /// Already compressed (JPEG left, right): a run too long to hold decoded.
    Jpeg(Vec<u8>, Vec<u8>),
}

/// Most memory the decoded pairs kept for the recording may take, bytes; a longer run's pairs
/// are compressed as they are detected instead (slower: the encoder then competes with the
/// detectors), so memory stays bounded whatever the run's length.
const KEPT_DECODED_BYTES: usize = 1 << 30;

/// Whether stereo pair `frame` goes into the recording: every pair a tag was found in, and one in
/// [`RECORD_EVERY`] of the others (the pictures taken for the visual odometry alone, more than
/// half of the office demo's). Compressing the pairs is most of what a recording costs; between
/// two recorded pairs the viewer shows the earlier one.
fn recorded(frame: usize, tag_found: bool) -> bool {
    tag_found || frame % RECORD_EVERY == 0
}

/// One in how many pairs without a tag the recording keeps (ours: 3, about every metre of
/// travel or 60 degrees of turn: the office demo's recording then costs under 20% of its survey).
const RECORD_EVERY: usize = 3;

/// Whether a run's pairs, `pairs` of `pixels` each image, are too many to keep decoded.
fn compress_while_detecting(pairs: usize, pixels: usize) -> bool {
    pairs.saturating_mul(2 * pixels) > KEPT_DECODED_BYTES
}

/// A run's sightings and, when keeping them, its pairs.
pub(crate) type Detected = (Vec<TagSighting>, Vec<Option<KeptPair>>, Vec<VisualTurn>);

/// Everything `survey_run` needs.
pub(crate) struct SurveyJob<'a> {
    pub run_dir: &'a Path,
    pub out: &'a Path,
    /// World file (default: the one run.yaml names, if it exists).
    pub world: Option<&'a Path>,
    pub config: Option<&'a Path>,
    /// An earlier survey whose odometry calibration the online filter starts with.
    pub calibration_from: Option<&'a Path>,
    pub detect: DetectOptions<'a>,
    pub force: bool,
    pub rerun: &'a super::RerunArgs,
}

/// Loads a run, detects and triangulates its tags, fuses, and writes the survey outputs.
pub(crate) fn survey_run(job: &SurveyJob<'_>) -> anyhow::Result<SurveyOutput> {
    // Refuse an existing output before the long work, not after.
    let dir = OutputDir::create(job.out, job.force)?;
    let output = survey_into(job, &dir)?;
    dir.commit()?;
    Ok(output)
}

/// [`survey_run`] writing into an output directory under construction (not committed here).
pub(crate) fn survey_into(job: &SurveyJob<'_>, dir: &OutputDir) -> anyhow::Result<SurveyOutput> {
    let started = std::time::Instant::now();
    let run = super::load_run(job.run_dir)?;
    let world = super::world_of_run(job.world, job.run_dir, &run)
        .as_deref()
        .map(io::load_world)
        .transpose()?
        .map(|w| w.world);
    let fuse = load_fuse_config(job.config)?;
    let calibration = job
        .calibration_from
        .map(|d| {
            let path = d.join("landmarks.json");
            io::load_landmarks(&path)?
                .odometry_calibration
                .ok_or_else(|| {
                    anyhow::Error::from(UsageError(format!(
                    "{}: no odometry_calibration (a survey whose offline pass did not estimate \
                     one); survey without --calibration-from",
                    path.display()
                )))
                })
        })
        .transpose()?;
    let mapping = run.meta.mapping.clone().unwrap_or_default();
    let recorder = super::recorder(job.rerun, super::Recording::Survey, &dir.path("survey.rrd"))?;

    let rig = load_run_rig(job.run_dir, &run)?;
    let detect_start = std::time::Instant::now();
    let options = DetectOptions {
        keep_images: recorder.is_some(),
        visual_odometry: fuse.visual_odometry,
        ..job.detect.clone()
    };
    // The raw map needs no pictures: it is built on whichever core the detectors leave it.
    let (detected, (raw, map_raw_s)) = rayon::join(
        || match &rig {
            Some(rig) => detect_run(&options, job.run_dir, &run, rig, world.as_ref()),
            None => Ok((Vec::new(), Vec::new(), Vec::new())),
        },
        || {
            let t = std::time::Instant::now();
            (raw_map(&run, &mapping), t.elapsed().as_secs_f64())
        },
    );
    let (sightings, images, visual) = detected?;
    let raw = raw?;
    let detect_s = detect_start.elapsed().as_secs_f64();

    // The pairs are compressed for the recording while the survey runs: it is mostly one thread
    // (grids, Hough, pose graph), which leaves the other core to the JPEG encoder.
    let ((images, compress_s), result) = rayon::join(
        || {
            let t = std::time::Instant::now();
            (compress_pairs(images), t.elapsed().as_secs_f64())
        },
        || {
            let sighted = (&sightings[..], &visual[..]);
            survey(&run, raw, sighted, &mapping, &fuse, calibration)
        },
    );
    let result = result?;
    let mut metrics = survey_metrics(&result, sightings.len());
    metrics.insert(
        "online.calibration_from_earlier_survey".into(),
        f64::from(u8::from(calibration.is_some())),
    );
    if let Some(w) = &world {
        metrics.extend(score_survey(&result, &run, w, &mapping)?);
    }
    let mut timings = result.timings_s.clone();
    // Both alongside each other: "detect" is their wall time, "map_raw" the map's alone.
    timings.insert("detect".into(), detect_s);
    timings.insert("map_raw".into(), map_raw_s);
    if recorder.is_some() {
        // Alongside the survey's stages above, which it slows down on a two-core machine.
        timings.insert("record_compress".into(), compress_s);
    }

    #[cfg(feature = "rerun")]
    if let Some(rec) = &recorder {
        let t = std::time::Instant::now();
        stereotag::viz::log_survey(
            rec,
            &stereotag::viz::SurveyScene {
                run: &run,
                world: world.as_ref(),
                survey: &result,
                sightings: &sightings,
                metrics: &metrics,
                mapping: &mapping,
                rig: rig.as_ref(),
                images: &images,
            },
        )
        .map_err(|e| anyhow::anyhow!("recording the survey: {e}"))?;
        timings.insert("record".into(), t.elapsed().as_secs_f64());
    }
    timings.insert("total".into(), started.elapsed().as_secs_f64());
    write_outputs(dir, &run, world.as_ref(), &result, &metrics, &timings)?;
    #[cfg(feature = "rerun")]
    if let Some(rec) = recorder {
        rec.finish()
            .map_err(|e| anyhow::anyhow!("finishing the recording: {e}"))?;
    }
    #[cfg(not(feature = "rerun"))]
    let _ = (recorder, images);
    print_summary(&result, &metrics, world.as_ref());
    Ok(SurveyOutput {
        survey: result,
        metrics,
    })
}

/// The kept pairs compressed for the recording, in parallel, each freed once compressed.
fn compress_pairs(images: Vec<Option<KeptPair>>) -> Vec<Option<(Vec<u8>, Vec<u8>)>> {
    images
        .into_par_iter()
        .map(|pair| match pair? {
            KeptPair::Decoded((l, r)) => jpeg_pair(&l, &r),
            KeptPair::Jpeg(l, r) => Some((l, r)),
        })
        .collect()
}

/// A pair compressed for the recording (`None` in a build without it).
fn jpeg_pair(left: &image::GrayImage, right: &image::GrayImage) -> Option<(Vec<u8>, Vec<u8>)> {
    #[cfg(feature = "rerun")]
    return stereotag::viz::jpeg_pair(left, right);
    #[cfg(not(feature = "rerun"))]
    return {
        let _ = (left, right);
        None
    };
}

/// Fusion settings from a YAML file, or the defaults.
pub(crate) fn load_fuse_config(path: Option<&Path>) -> anyhow::Result<FuseConfig> {
    let Some(p) = path else {
        return Ok(FuseConfig::default());
    };
    let config: FuseConfig = io::parse_yaml(
        p,
        &std::fs::read_to_string(p).map_err(|e| UsageError(format!("{}: {e}", p.display())))?,
    )?;
    config
        .validate()
        .map_err(|e| UsageError(format!("{}: {e}", p.display())))?;
    Ok(config)
}

/// The run's stereo rig with run.yaml's mounting, or `None` when the run has no pictures.
pub(crate) fn load_run_rig(run_dir: &Path, run: &RunDataset) -> anyhow::Result<Option<StereoRig>> {
    if run.stereo.is_empty() {
        tracing::warn!(
            "the run has no stereo pairs (stereo.csv is empty): sonar and odometry only"
        );
        return Ok(None);
    }
    let rig_name = run.meta.robot.rig.as_ref().ok_or_else(|| {
        UsageError(format!(
            "{}: the run has stereo pairs but run.yaml names no rig (robot.rig)",
            run_dir.join("run.yaml").display()
        ))
    })?;
    let mut rig = io::load_rig(&run_dir.join(rig_name))?;
    if let Some(v) = run.meta.robot.robot_from_left {
        rig.robot_from_left = nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::new(v[0], v[1], v[2]),
            nalgebra::UnitQuaternion::from_euler_angles(v[3], v[4], v[5]),
        );
    }
    Ok(Some(rig))
}

/// Detects and triangulates the tags of every stereo pair, in parallel.
pub(crate) fn detect_run(
    job: &DetectOptions<'_>,
    run_dir: &Path,
    run: &RunDataset,
    rig: &StereoRig,
    world: Option<&World>,
) -> anyhow::Result<Detected> {
    super::check_decimate(job.decimate)?;
    let rect = rig.rectify();
    let mut names: Vec<String> = job.families.to_vec();
    if names.is_empty() {
        names = world
            .map(|w| w.tags.iter().map(|t| t.family.clone()).collect())
            .unwrap_or_default();
        names.sort();
        names.dedup();
    }
    if names.is_empty() {
        names.push("tag36h11".into());
    }
    let families = names
        .iter()
        .map(|f| {
            TagFamily::from_name(f).ok_or_else(|| {
                UsageError(format!(
                    "family {f}: expected tag36h11, tag25h9, tag16h5 or tagStandard41h12"
                ))
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let config = DetectorConfig {
        families,
        decimate: job.decimate,
        min_contrast: job.min_contrast,
        ..DetectorConfig::default()
    };
    let make = || -> Result<Box<dyn TagDetector + Send>, stereotag::visual::tags::TagError> {
        Ok(match job.backend {
            Backend::Kornia => Box::new(KorniaDetector::new(config.clone())?),
            Backend::KorniaLibrary => Box::new(KorniaDetector::library(config.clone())?),
            Backend::ApriltagC => Box::new(CDetector::new(config.clone())?),
        })
    };
    let detectors = Pool::new(make()?); // a bad configuration fails here, once
    let known = |family: &str, id: u32| -> Option<f64> {
        world
            .and_then(|w| w.tags.iter().find(|t| t.id == id && t.family == family))
            .map(|t| t.size_m)
            .or(job.tag_size_m)
    };
    let stereo_config = StereoConfig::default();
    let compress_now = compress_while_detecting(
        run.stereo.len(),
        (rig.left.width as usize) * (rig.left.height as usize),
    );
    if job.keep_images && compress_now {
        tracing::info!(
            "{} stereo pairs: compressing them for the recording as they are detected",
            run.stereo.len()
        );
    }
    // The pairs of pictures whose motion the visual odometry measures: pair `k` to `next[k]`.
    let vo_config = VoConfig::default();
    let mut next: Vec<Option<usize>> = vec![None; run.stereo.len()];
    if job.visual_odometry {
        let times: Vec<f64> = run.stereo.iter().map(|e| e.t_s).collect();
        for (a, b) in frame_pairs(&times, &run.odometry, &vo_config) {
            next[a] = Some(b);
        }
    }
    let bar = progress(run.stereo.len() as u64, "detect", job.quiet);
    // Runs of consecutive pairs, each worked through in order by one thread, so that a picture's
    // images are decoded and prepared for the visual odometry once, for both turns it ends and
    // starts (only a turn that crosses into the next run decodes its last picture again).
    const RUN_OF_PAIRS: usize = 16;
    let starts: Vec<usize> = (0..run.stereo.len()).step_by(RUN_OF_PAIRS).collect();
    type PerPair = (Vec<TagSighting>, Option<KeptPair>, Option<VisualTurn>);
    let per_run: Vec<anyhow::Result<Vec<PerPair>>> = starts
        .par_iter()
        .map_init(
            || detectors.take(make),
            |detector, &first| {
                let detector = detector.as_mut().map_err(|e| anyhow::anyhow!("{e}"))?;
                let last = (first + RUN_OF_PAIRS).min(run.stereo.len());
                let mut out: Vec<PerPair> = Vec::with_capacity(last - first);
                // The picture a turn starts from (its index and prepared images), and where to.
                let mut from: Option<(usize, VoImage, VoImage, usize)> = None;
                for (frame, entry) in run.stereo.iter().enumerate().take(last).skip(first) {
                    let left_path = run_dir.join(&entry.left);
                    let right_path = run_dir.join(&entry.right);
                    let left = io::load_gray(&left_path)?;
                    let right = io::load_gray(&right_path)?;
                    check_image_size(&left, &rig.left, &left_path, "the rig")?;
                    check_image_size(&right, &rig.right, &right_path, "the rig")?;
                    let (sightings, rejected) = sightings_from_pair(
                        detector.as_mut(),
                        rig,
                        &rect,
                        &left,
                        &right,
                        (entry.t_s, frame),
                        &known,
                        &stereo_config,
                    )?;
                    let tag_found = !sightings.is_empty() || !rejected.is_empty();
                    for r in rejected {
                        tracing::debug!(
                            "pair {frame} (t = {:.1} s): tag {} rejected: {}",
                            entry.t_s,
                            r.id,
                            r.reason
                        );
                    }
                    let ends = from.as_ref().is_some_and(|f| f.3 == frame);
                    let starts = next[frame].is_some();
                    if ends || starts {
                        let here = VoImage::new(&left);
                        if let Some((a, a_left, a_right, _)) = from.take().filter(|_| ends) {
                            let t = visual_turn(
                                run,
                                rig,
                                (a, &a_left, &a_right),
                                (frame, &here),
                                &vo_config,
                            );
                            out[a - first].2 = t;
                        }
                        if let Some(to) = next[frame] {
                            from = Some((frame, here, VoImage::new(&right), to));
                        }
                    }
                    let kept = match (job.keep_images && recorded(frame, tag_found), compress_now) {
                        (false, _) => None,
                        (true, false) => Some(KeptPair::Decoded((left, right))),
                        (true, true) => jpeg_pair(&left, &right).map(|(l, r)| KeptPair::Jpeg(l, r)),
                    };
                    out.push((sightings, kept, None));
                    bar.inc(1);
                }
                // A turn into the next run of pairs: its last picture decoded here as well.
                if let Some((a, a_left, a_right, to)) = from {
                    let path = run_dir.join(&run.stereo[to].left);
                    let image = io::load_gray(&path)?;
                    check_image_size(&image, &rig.left, &path, "the rig")?;
                    let here = VoImage::new(&image);
                    out[a - first].2 =
                        visual_turn(run, rig, (a, &a_left, &a_right), (to, &here), &vo_config);
                }
                Ok(out)
            },
        )
        .collect();
    bar.finish_and_clear();
    let mut sightings = Vec::new();
    let mut images = Vec::new();
    let mut visual = Vec::new();
    for r in per_run {
        for (s, e, v) in r? {
            sightings.extend(s);
            images.push(e);
            visual.extend(v);
        }
    }
    tracing::info!(
        "{} tag sightings in {} stereo pairs",
        sightings.len(),
        run.stereo.len()
    );
    if job.visual_odometry {
        let tried = next.iter().flatten().count();
        tracing::info!(
            "visual odometry: the turn between {} of {tried} pairs of pictures measured",
            visual.len()
        );
    }
    Ok((sightings, images, visual))
}

/// The turn from picture `from` to picture `to` of the run (their images prepared), measured by
/// the visual odometry from the odometry's; `None` when the pictures do not show it (too little
/// texture in common).
fn visual_turn(
    run: &RunDataset,
    rig: &StereoRig,
    (from, left, right): (usize, &VoImage, &VoImage),
    (to, next): (usize, &VoImage),
    config: &VoConfig,
) -> Option<VisualTurn> {
    let (a, b) = (&run.stereo[from], &run.stereo[to]);
    let prior = pose_at(&run.odometry, a.t_s)?.between(&pose_at(&run.odometry, b.t_s)?);
    match relative_motion(rig, (left, right), next, &prior, config) {
        Ok(m) => Some(m.turn(a.t_s, b.t_s)),
        Err(e) => {
            tracing::debug!(
                "visual odometry, pictures at {:.2} s and {:.2} s: {e}",
                a.t_s,
                b.t_s
            );
            None
        }
    }
}

/// Writes every survey output into the staging directory.
fn write_outputs(
    dir: &OutputDir,
    run: &RunDataset,
    world: Option<&World>,
    s: &Survey,
    metrics: &BTreeMap<String, f64>,
    timings: &BTreeMap<String, f64>,
) -> anyhow::Result<()> {
    io::save_ros_map(&dir.path(""), "map", &s.raw.counting)?;
    io::save_map_png(&dir.path("map.png"), &s.raw.counting)?;
    io::save_accumulator_png(&dir.path("hough.png"), &s.raw.accumulator)?;
    io::save_features_csv(&dir.path("corners.csv"), &s.raw.features_offline)?;
    io::save_ros_map(&dir.path(""), "map_online", &s.online_map)?;
    io::save_map_png(&dir.path("map_online.png"), &s.online_map)?;
    io::save_ros_map(&dir.path(""), "map_corrected", &s.corrected.counting)?;
    io::save_map_png(&dir.path("map_corrected.png"), &s.corrected.counting)?;
    io::save_accumulator_png(&dir.path("hough_corrected.png"), &s.corrected.accumulator)?;
    io::save_features_csv(
        &dir.path("corners_corrected.csv"),
        &s.corrected.features_offline,
    )?;
    io::save_walls_csv(&dir.path("walls_corrected.csv"), &s.corrected.walls)?;
    io::save_visual_turns_csv(
        &dir.path("visual_turns.csv"),
        &s.visual,
        &run.odometry,
        run.ground_truth.as_deref(),
    )?;
    let planned = |l: &stereotag::fusion::Landmark| {
        world
            .and_then(|w| w.tags.iter().find(|t| t.id == l.id && t.family == l.family))
            .map(|t| t.position_m)
    };
    let mut landmarks = s.landmarks.clone();
    landmarks.sort_by(|a, b| (&a.family, a.id).cmp(&(&b.family, b.id)));
    let records = landmarks
        .iter()
        .map(|l| LandmarkRecord {
            landmark: l.clone(),
            planned_position_m: planned(l),
        })
        .collect();
    io::save_landmarks(
        &dir.path("landmarks.json"),
        &LandmarksFile {
            landmarks: records,
            odometry_calibration: s.offline.odometry_calibration,
        },
    )?;
    io::save_wpilib_layout(&dir.path("layout.json"), &landmarks, 0.5)?;
    io::save_trajectory_csv(
        &dir.path("trajectory.csv"),
        &Trajectories {
            odometry: &run.odometry,
            online: &s.online.trajectory,
            offline: &s.offline.trajectory,
            ground_truth: run.ground_truth.as_deref(),
        },
    )?;
    let displacement: Vec<_> = landmarks
        .iter()
        .filter_map(|l| {
            let p = planned(l)?;
            let d = [
                l.position_m[0] - p[0],
                l.position_m[1] - p[1],
                l.position_m[2] - p[2],
            ];
            Some(serde_json::json!({
                "id": l.id, "family": l.family, "planned_m": p, "surveyed_m": l.position_m,
                "displacement_m": d, "distance_m": (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(),
            }))
        })
        .collect();
    let finite: BTreeMap<_, _> = metrics
        .iter()
        .map(|(k, v)| (k.clone(), v.is_finite().then_some(*v)))
        .collect();
    let report = serde_json::json!({
        "metrics": finite,
        "timings_s": timings,
        "conflicts": s.online.conflicts,
        "planned_vs_surveyed": displacement,
    });
    io::save_json(&dir.path("report.json"), &report)?;
    Ok(())
}

/// Prints the landmarks, the planned-versus-surveyed table and the before/after figures.
pub(crate) fn print_summary(s: &Survey, metrics: &BTreeMap<String, f64>, world: Option<&World>) {
    super::map::warn_if_off_grid(&s.raw);
    let get = |k: &str| metrics.get(k).copied();
    tracing::info!(
        "{} landmarks ({} matched with a Hough corner); {} sightings fused, {} gated out; offline graph: {} keyframes, {} factors",
        s.landmarks.len(),
        s.landmarks.iter().filter(|l| l.matched_corner.is_some()).count(),
        s.online.accepted.len(),
        s.online.rejected.len(),
        s.offline.keyframes,
        s.offline.factors,
    );
    for c in &s.online.conflicts {
        tracing::warn!(
            "tag {} ({}): {} — landmark at ({:.2}, {:.2}) m but {} sightings from t = {:.1} s put it at ({:.2}, {:.2}) m; not fused",
            c.id, c.family, c.kind, c.landmark_m[0], c.landmark_m[1], c.sightings, c.first_t_s, c.seen_at_m[0], c.seen_at_m[1]
        );
    }
    if let Some(w) = world {
        for l in &s.landmarks {
            if let Some(t) = w.tags.iter().find(|t| t.id == l.id && t.family == l.family) {
                let d =
                    nalgebra::Vector3::from(l.position_m) - nalgebra::Vector3::from(t.position_m);
                tracing::info!(
                    "  tag {:>3}: planned ({:.3}, {:.3}, {:.3}) surveyed ({:.3}, {:.3}, {:.3}) m, displacement {:.1} mm",
                    l.id, t.position_m[0], t.position_m[1], t.position_m[2],
                    l.position_m[0], l.position_m[1], l.position_m[2], d.norm() * 1e3
                );
            }
        }
    }
    if let (Some(o), Some(on), Some(off)) = (
        get("ate_m.odometry"),
        get("ate_m.online"),
        get("ate_m.offline"),
    ) {
        tracing::info!(
            "trajectory ATE: odometry {:.3} m, online {:.3} m, offline {:.3} m",
            o,
            on,
            off
        );
    }
    if let (Some(p0), Some(r0), Some(p1), Some(r1)) = (
        get("map.occupied_precision"),
        get("map.occupied_recall"),
        get("map_corrected.occupied_precision"),
        get("map_corrected.occupied_recall"),
    ) {
        let online = match (
            get("map_online.occupied_precision"),
            get("map_online.occupied_recall"),
        ) {
            (Some(p), Some(r)) => format!(", online {p:.3}/{r:.3}"),
            _ => String::new(),
        };
        tracing::info!(
            "map occupied precision/recall: raw {p0:.3}/{r0:.3}{online}, corrected {p1:.3}/{r1:.3}{}",
            match (
                get("map_ground_truth.occupied_precision"),
                get("map_ground_truth.occupied_recall")
            ) {
                (Some(p), Some(r)) => format!(", with ground-truth poses {p:.3}/{r:.3}"),
                _ => String::new(),
            }
        );
    }
    if let Some(m) = get("landmarks.median_error_m") {
        tracing::info!("landmark position error: median {:.1} mm", m * 1e3);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pair with a tag is recorded, one in three of the others.
    #[test]
    fn the_recording_keeps_every_tag_pair_and_a_third_of_the_others() {
        assert!((0..30).all(|k| recorded(k, true)));
        assert_eq!((0..30).filter(|&k| recorded(k, false)).count(), 10);
    }

    /// The museum's 468 pairs of 640x480 (288 MB decoded) are kept decoded; a run of hours is
    /// compressed as it is detected, so the recording never holds more than 1 GiB of pixels.
    #[test]
    fn a_long_run_is_compressed_as_it_is_detected() {
        let vga = 640 * 480;
        assert!(!compress_while_detecting(468, vga));
        assert!(!compress_while_detecting(1700, vga));
        assert!(compress_while_detecting(1800, vga));
        assert!(compress_while_detecting(usize::MAX, vga));
    }
}
