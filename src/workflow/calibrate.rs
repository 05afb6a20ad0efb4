//! Calibrate a stereo rig from images of a target (or corners already detected): the corners of
//! every view found, both cameras and `right_from_left` adjusted; the rig written as Kalibr,
//! OpenCV and ROS files with a report, and recorded.

use super::{Error, Result};
use crate::calib::{
    calibrate_camera, calibrate_stereo, CalibConfig, CalibError, Calibration, Corner, Target,
    TargetDetector, TargetView, ViewCorners,
};
use crate::camera::{LensModel, StereoRig};
use crate::io::{self, OutputDir};
use crate::progress::Progress;
use crate::viz::{CalibrationScene, Recorder, Recording, RecordingRequest};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// Where the views come from.
#[derive(Debug, Clone, PartialEq)]
pub enum CalibrationInput<'a> {
    /// Left and right images, as globs with `*` in the last component (pairs matched in
    /// sorted order).
    Images {
        /// Left images, e.g. `cam0/*.png`.
        left: &'a str,
        /// Right images.
        right: &'a str,
    },
    /// Directories of corners already detected (EuRoC / yac CSV, one file per view).
    Corners {
        /// Left corners.
        left: &'a Path,
        /// Right corners.
        right: &'a Path,
    },
    /// One camera's images, a glob: the camera alone is calibrated.
    CameraImages(&'a str),
    /// One camera's corners already detected (EuRoC / yac CSV, one file per view).
    CameraCorners(&'a Path),
}

impl CalibrationInput<'_> {
    /// Whether these are a rig's views (else one camera's).
    pub fn stereo(&self) -> bool {
        matches!(self, Self::Images { .. } | Self::Corners { .. })
    }
}

/// What to calibrate from, and how.
#[derive(Debug, Clone)]
pub struct CalibrateRequest<'a> {
    /// The target (Kalibr target YAML).
    pub target: &'a Path,
    /// The views.
    pub input: CalibrationInput<'a>,
    /// The image size, needed with corner files unless the intrinsics are fixed (images give it).
    pub resolution: Option<(u32, u32)>,
    /// The lens model of a free calibration.
    pub model: LensModel,
    /// Keep this rig file's intrinsics and distortion; solve `right_from_left` only (a rig's
    /// views only).
    pub fix_intrinsics: Option<&'a Path>,
    /// The output directory.
    pub out: &'a Path,
    /// Replace the output directory if it exists.
    pub force: bool,
    /// Write the rig even when the calibration fails its checks ([`crate::calib::failures`]),
    /// marked as failed in `camchain.yaml` and `report.json`.
    pub force_write: bool,
    /// A raw pair (left, right) to rectify with the result into `rectified.png`.
    pub rectify_pair: Option<(&'a Path, &'a Path)>,
    /// Where the recording goes (default: `calibration.rrd` in the output).
    pub recording: RecordingRequest,
}

impl<'a> CalibrateRequest<'a> {
    /// A request to calibrate `input` against `target` into `out`, with the defaults: the
    /// images' size, the radtan model, free intrinsics, a new output directory, nothing written
    /// when the checks fail, no rectified pair, no recording.
    pub fn new(target: &'a Path, input: CalibrationInput<'a>, out: &'a Path) -> Self {
        Self {
            target,
            input,
            resolution: None,
            model: LensModel::Radtan,
            fix_intrinsics: None,
            out,
            force: false,
            force_write: false,
            rectify_pair: None,
            recording: RecordingRequest::none(),
        }
    }
}

/// A calibration and its report.
#[derive(Debug, Clone)]
pub struct CalibrateOutput {
    /// The calibration.
    pub calibration: Calibration,
    /// `report.json`'s contents.
    pub report: serde_json::Value,
}

/// Rows between the epipolar lines drawn on `rectified.png`.
const EPIPOLAR_LINE_ROWS: u32 = 32;

/// Each view's left and right images as JPEG, for the recording.
type ViewImages = BTreeMap<String, (Vec<u8>, Vec<u8>)>;

/// The corners of the views in both cameras, with the image size (when images gave them), why
/// views were lost and the images for the recording.
#[derive(Default)]
pub struct CalibrationViews {
    /// Left corners by view name.
    pub left: ViewCorners,
    /// Right corners by view name.
    pub right: ViewCorners,
    /// The image size, when read from images.
    pub resolution: Option<(u32, u32)>,
    /// Images that gave no usable board, with why.
    pub misses: Vec<String>,
    /// What each image (or corner file) gave, in input order.
    pub per_image: Vec<ImageRecord>,
    /// Each view's images as JPEG, when kept for the recording.
    pub images: ViewImages,
}

/// What one image or corner file gave, for the report.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ImageRecord {
    /// The image (or corner file).
    pub image: String,
    /// Its view's name.
    pub view: String,
    /// `left`, `right` or `camera`.
    pub camera: &'static str,
    /// Tags found (an AprilGrid's, a tag board's, a ChArUco board's markers; 0 for a
    /// chessboard).
    pub tags: usize,
    /// Board corners found.
    pub corners: usize,
    /// Why no board was found, when none was.
    pub miss: Option<String>,
}

impl ImageRecord {
    /// The record of a corner file read for `camera`'s `view` (of an AprilGrid, whose corners
    /// name their tags, when `aprilgrid`).
    fn of_corner_file(
        dir: &Path,
        view: &str,
        camera: &'static str,
        corners: &[Corner],
        aprilgrid: bool,
    ) -> Self {
        let tags: std::collections::BTreeSet<u32> = corners.iter().map(|c| c.id / 4).collect();
        Self {
            image: dir.join(format!("{view}.csv")).display().to_string(),
            view: view.to_string(),
            camera,
            tags: if aprilgrid { tags.len() } else { 0 },
            corners: corners.len(),
            miss: corners.is_empty().then(|| "no corners in the file".into()),
        }
    }
}

/// Calibrates a rig and writes `camchain.yaml`, `opencv_stereo.yaml`, `left.yaml`,
/// `right.yaml`, `report.json`, `rectified.png` (when asked) and the recording into a new
/// directory; or one camera ([`CalibrationInput::CameraImages`]), written as a one-camera
/// `camchain.yaml`, `opencv_camera.yaml` and `camera.yaml`. Progress: one step per image.
///
/// ```no_run
/// use std::path::Path;
/// use stereotag::progress::Silent;
/// use stereotag::workflow::calibrate::{calibrate, CalibrateRequest, CalibrationInput};
///
/// let input = CalibrationInput::Images {
///     left: "images/*_left.jpg",
///     right: "images/*_right.jpg",
/// };
/// let out = calibrate(
///     &CalibrateRequest::new(
///         Path::new("calibration/targets/checkerboard_9x6.yaml"),
///         input,
///         Path::new("calib/my-rig"),
///     ),
///     &Silent,
/// )?;
/// println!("baseline {:.4} m", out.calibration.rig.baseline_m());
/// # Ok::<(), stereotag::workflow::Error>(())
/// ```
pub fn calibrate(
    request: &CalibrateRequest<'_>,
    progress: &dyn Progress,
) -> Result<CalibrateOutput> {
    let started = std::time::Instant::now();
    let stereo = request.input.stereo();
    if !stereo && request.fix_intrinsics.is_some() {
        return Err(Error::Request(
            "--fix-intrinsics is for a rig's extrinsics: one camera with fixed intrinsics leaves nothing to calibrate".into(),
        ));
    }
    if !stereo && request.rectify_pair.is_some() {
        return Err(Error::Request(
            "--rectify-pair needs a rig: one camera has no pair to rectify".into(),
        ));
    }
    let target = io::load_target(request.target)?;
    let keep_images = !request.recording.off;
    let views = match request.input {
        CalibrationInput::Corners { left, right } => {
            corner_files(&[(left, "left"), (right, "right")], &target)?
        }
        CalibrationInput::CameraCorners(dir) => corner_files(&[(dir, "camera")], &target)?,
        CalibrationInput::Images { left, right } => {
            detect_views(&target, left, Some(right), keep_images, progress)?
        }
        CalibrationInput::CameraImages(images) => {
            detect_views(&target, images, None, keep_images, progress)?
        }
    };
    let detect_s = started.elapsed().as_secs_f64();
    let mut config = CalibConfig {
        model: request.model,
        ..CalibConfig::default()
    };
    let resolution = match (request.fix_intrinsics, request.resolution, views.resolution) {
        (Some(rig_path), _, size) => {
            let rig = io::load_rig(rig_path)?;
            let res = (rig.left.width, rig.left.height);
            if let Some((w, h)) = size.filter(|s| *s != res) {
                return Err(Error::Request(format!(
                    "{}: the rig is {}x{} but the images are {w}x{h}",
                    rig_path.display(),
                    res.0,
                    res.1
                )));
            }
            config.fixed_intrinsics = Some((rig.left, rig.right));
            res
        }
        (None, Some(r), _) => r,
        (None, None, Some(size)) => size,
        (None, None, None) => {
            return Err(Error::Request(
                "--resolution WIDTHxHEIGHT is needed with corner files when the intrinsics are not fixed".into(),
            ))
        }
    };
    let (left, right) = solved_views(&views, &target);
    let calib = if stereo {
        calibrate_stereo(&left, &right, resolution, &config)
    } else {
        calibrate_camera(&left, resolution, &config)
    }
    .inspect_err(|e| {
        if matches!(e, CalibError::TooFewViews { .. }) {
            for m in &views.misses {
                tracing::warn!("no usable board in {m}");
            }
        }
    })?;
    let solve_s = started.elapsed().as_secs_f64() - detect_s;
    let failures = crate::calib::failures(&calib, request.fix_intrinsics.is_some());
    if !failures.is_empty() && !request.force_write {
        return Err(Error::Request(format!(
            "the calibration failed its checks, nothing was written:\n  - {}\n(--force-write writes it anyway, marked as failed)",
            failures.join("\n  - ")
        )));
    }
    let dir = OutputDir::create(request.out, request.force)?;
    // A forced rig says so where its reader will see it.
    let notes: Vec<String> = if failures.is_empty() {
        Vec::new()
    } else {
        std::iter::once("FAILED CALIBRATION, written with --force-write. Its checks found:".into())
            .chain(failures.iter().map(|f| format!("  - {f}")))
            .collect()
    };
    if stereo {
        io::save_rig_exports_noted(&dir.path(""), &calib.rig, &notes)?;
    } else {
        io::save_camera_exports_noted(&dir.path(""), &calib.rig.left, &notes)?;
    }
    for f in &failures {
        tracing::warn!("written despite: {f}");
    }
    save_corners(&dir, &views, &target)?;
    let uncertainty = crate::calib::projection_uncertainty(&calib);
    let mut report = report(
        &calib,
        &target,
        request.fix_intrinsics.is_some(),
        [detect_s, solve_s, started.elapsed().as_secs_f64()],
    )?;
    report["failures"] = serde_json::json!(failures);
    report["images"] = images_json(&calib, &views.per_image, &target);
    report["projection_uncertainty"] = serde_json::json!(uncertainty);
    io::save_json(&dir.path("report.json"), &report)?;
    let rectified = match request.rectify_pair {
        Some((l, r)) => {
            let img = rectified_pair(&calib.rig, &io::load_gray(l)?, &io::load_gray(r)?);
            io::save_gray_png(&dir.path("rectified.png"), &img)?;
            Some(img)
        }
        None => None,
    };
    let recorder = Recorder::open(
        &request.recording,
        Recording::Calibration,
        &dir.path("calibration.rrd"),
    )?;
    if let Some(rec) = recorder {
        let md = report_markdown(&calib, request.fix_intrinsics.is_some());
        rec.log_calibration(&CalibrationScene {
            calibration: &calib,
            report_markdown: &md,
            rectified_pair: rectified.as_ref(),
            view_images: &solved_view_images(&views.images, &left, &right),
        })?;
        rec.finish()?;
    }
    dir.commit()?;
    Ok(CalibrateOutput {
        calibration: calib,
        report,
    })
}

/// Every view's corners as `corners/<camera>/<view>.csv` (EuRoC / yac CSV, which
/// `--corners-left`, `--corners-right` and `--corners` read back), and for a chessboard or a
/// ChArUco board mrcal's `corners.vnl` of every image.
fn save_corners(dir: &OutputDir, views: &CalibrationViews, target: &Target) -> Result<()> {
    let stereo = !views.right.is_empty();
    let sides = if stereo {
        [("left", &views.left), ("right", &views.right)].to_vec()
    } else {
        [("camera", &views.left)].to_vec()
    };
    for (camera, corners) in &sides {
        io::save_corner_csvs(&dir.path(&format!("corners/{camera}")), corners, target)?;
    }
    let grid = match target {
        Target::Checkerboard(board) => Some((board.target_cols, board.target_rows)),
        Target::Charuco(board) => Some(board.inner()),
        _ => None,
    };
    if let Some((cols, rows)) = grid {
        let images: Vec<(String, &[Corner])> = views
            .per_image
            .iter()
            .map(|r| {
                let side = if r.camera == "right" {
                    &views.right
                } else {
                    &views.left
                };
                let corners = side.get(&r.view).map_or(&[][..], Vec::as_slice);
                // A chessboard seen in part is numbered from its own first corner, not the
                // board's, which mrcal's file cannot say: written as no board.
                let part = matches!(target, Target::Checkerboard(_))
                    && corners.len() < (cols * rows) as usize;
                (r.image.clone(), if part { &[][..] } else { corners })
            })
            .collect();
        io::save_corners_vnl(&dir.path("corners.vnl"), &images, cols, rows)?;
    }
    Ok(())
}

/// Separator between a view's name and the part of it [`solved_views`] made a view of its own.
const PART_SEPARATOR: char = '#';

/// The views the calibration solves, left and right: several boards' one a board seen
/// (`VIEW#k` for board `k`, the corner ids saying the board,
/// [`crate::calib::BOARD_ID_STRIDE`]), each with a pose of its own; a rig's chessboard seen in
/// part in either image one a camera (`VIEW#left` in the left camera's views alone, `VIEW#right`
/// in the right's: a part cannot be numbered alike in both images, so its view ties no camera to
/// the other); other views as they are.
fn solved_views(views: &CalibrationViews, target: &Target) -> (ViewCorners, ViewCorners) {
    match target {
        Target::Boards(_) => {
            let by_board = |side: &ViewCorners| {
                let mut out = ViewCorners::new();
                for (name, corners) in side {
                    for c in corners {
                        let board = c.id / crate::calib::BOARD_ID_STRIDE;
                        out.entry(format!("{name}{PART_SEPARATOR}{board}"))
                            .or_default()
                            .push(*c);
                    }
                }
                out
            };
            (by_board(&views.left), by_board(&views.right))
        }
        Target::Checkerboard(board) if !views.right.is_empty() => {
            let whole = (board.target_cols * board.target_rows) as usize;
            let part = |c: &Vec<Corner>| !c.is_empty() && c.len() < whole;
            let (mut left, mut right) = (ViewCorners::new(), ViewCorners::new());
            for (name, l) in &views.left {
                let r = views.right.get(name);
                if part(l) || r.is_some_and(part) {
                    if !l.is_empty() {
                        left.insert(format!("{name}{PART_SEPARATOR}left"), l.clone());
                    }
                    if let Some(r) = r.filter(|r| !r.is_empty()) {
                        right.insert(format!("{name}{PART_SEPARATOR}right"), r.clone());
                    }
                } else {
                    left.insert(name.clone(), l.clone());
                    if let Some(r) = r {
                        right.insert(name.clone(), r.clone());
                    }
                }
            }
            (left, right)
        }
        _ => (views.left.clone(), views.right.clone()),
    }
}

/// The view a view of [`solved_views`] came from.
fn view_of(name: &str) -> &str {
    name.split(PART_SEPARATOR).next().unwrap_or(name)
}

/// The images of [`solved_views`]' views: each its view's.
fn solved_view_images(images: &ViewImages, left: &ViewCorners, right: &ViewCorners) -> ViewImages {
    left.keys()
        .chain(right.keys())
        .filter_map(|k| Some((k.clone(), images.get(view_of(k))?.clone())))
        .collect()
}

/// Each image's record with whether its view was used and how many of its corners were left
/// out as outliers; a view that found a board but was not used says why.
fn images_json(calib: &Calibration, records: &[ImageRecord], target: &Target) -> serde_json::Value {
    let several = if matches!(target, Target::Boards(_)) {
        " of any one board"
    } else {
        ""
    };
    let used: std::collections::BTreeSet<&str> =
        calib.used.iter().map(|v| view_of(&v.name)).collect();
    records
        .iter()
        .map(|r| {
            let mut v = serde_json::json!(r);
            let is_used = used.contains(r.view.as_str());
            v["used"] = is_used.into();
            v["outliers"] = calib
                .outliers
                .iter()
                .filter(|o| view_of(&o.view) == r.view && o.camera == r.camera)
                .count()
                .into();
            if !is_used && r.miss.is_none() {
                v["miss"] = format!(
                    "{} corners here: here, or in the other camera's image of this view, fewer than the {} corners{several} a view needs",
                    r.corners,
                    crate::calib::CalibConfig::default().min_corners
                )
                .into();
            }
            v
        })
        .collect()
}

/// The views of corner files, one directory a camera (`left` and `right`, or `camera` alone).
fn corner_files(dirs: &[(&Path, &'static str)], target: &Target) -> Result<CalibrationViews> {
    let aprilgrid = matches!(target, Target::Aprilgrid(_) | Target::Tagboard(_));
    let mut out = CalibrationViews::default();
    for (k, (dir, camera)) in dirs.iter().enumerate() {
        let views = io::load_corner_csvs(dir)?;
        out.per_image.extend(views.iter().map(|(view, corners)| {
            ImageRecord::of_corner_file(dir, view, camera, corners, aprilgrid)
        }));
        if k == 0 {
            out.left = views;
        } else {
            out.right = views;
        }
    }
    Ok(out)
}

/// `report.json`: the metrics, timings (`[detect, solve, total]` seconds), target, intrinsics
/// (distortion by name), `right_from_left`, sigmas, the covariance of the intrinsics and
/// `right_from_left`, per-view residuals, outliers, coverage and warnings. One camera's report
/// has `camera` in place of `left` and `right`, and no extrinsics.
fn report(
    calib: &Calibration,
    target: &Target,
    intrinsics_fixed: bool,
    [detect_s, solve_s, total_s]: [f64; 3],
) -> Result<serde_json::Value> {
    let t = calib.rig.right_from_left.translation.vector;
    let (roll, pitch, yaw) = calib.rig.right_from_left.rotation.euler_angles();
    let mut metrics = serde_json::json!({
        "rms_px": calib.rms_px,
        "views_used": calib.views.len(),
        "outliers": calib.outliers.len(),
    });
    if calib.stereo {
        metrics["rms_left_px"] = calib.rms_left_px.into();
        metrics["rms_right_px"] = calib.rms_right_px.into();
        metrics["baseline_m"] = t.norm().into();
        metrics["epipolar_error_px"] = calib.epipolar_error_px.into();
        metrics["coverage_left"] = calib.coverage.0.into();
        metrics["coverage_right"] = calib.coverage.1.into();
    } else {
        metrics["coverage"] = calib.coverage.0.into();
    }
    let cov = &calib.covariance;
    let mut report = serde_json::json!({
        "metrics": metrics,
        "timings_s": {"read_and_detect": detect_s, "solve": solve_s, "total": total_s},
        "target": serde_json::to_value(target).map_err(|e| Error::Request(e.to_string()))?,
        "intrinsics_fixed": intrinsics_fixed,
        "sigmas": calib.sigmas,
        "covariance": {
            "names": cov.names,
            "matrix": cov.matrix.row_iter().map(|r| r.iter().copied().collect::<Vec<f64>>()).collect::<Vec<_>>(),
        },
        "per_view": calib.views,
        "outliers": calib.outliers,
        "warnings": calib.warnings,
    });
    for (name, cam) in calib.cameras() {
        report[name] = intrinsics_json(cam);
    }
    if calib.stereo {
        report["right_from_left"] =
            serde_json::json!({"t_m": [t.x, t.y, t.z], "roll_pitch_yaw_rad": [roll, pitch, yaw]});
        report["coverage_counts"] = serde_json::json!({"cols": 8, "rows": 6, "left": calib.coverage_counts.0, "right": calib.coverage_counts.1});
    } else {
        report["coverage_counts"] =
            serde_json::json!({"cols": 8, "rows": 6, "camera": calib.coverage_counts.0});
    }
    Ok(report)
}

/// A camera's intrinsics for the report: `fx`, `fy`, `cx`, `cy`, and the distortion as its
/// model's Kalibr name with each coefficient by name.
fn intrinsics_json(c: &crate::camera::Camera) -> serde_json::Value {
    let mut distortion = serde_json::Map::new();
    let model = match c.distortion {
        crate::camera::Distortion::Equidistant { .. } => "equidistant",
        crate::camera::Distortion::Radtan { .. } => "radtan",
        crate::camera::Distortion::None => "none",
        crate::camera::Distortion::DoubleSphere { .. } => "ds",
        crate::camera::Distortion::Eucm { .. } => "eucm",
    };
    distortion.insert("model".into(), model.into());
    for (name, value) in crate::calib::named_intrinsics(c).into_iter().skip(4) {
        distortion.insert(name.into(), value.into());
    }
    if let crate::camera::Distortion::Radtan { k3, .. } = c.distortion {
        distortion.insert("k3".into(), k3.into());
    }
    serde_json::json!({"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "width": c.width, "height": c.height, "distortion": distortion})
}

/// The report as the recording shows it (Markdown): the warnings first, the fit, then each
/// camera's intrinsics and the rig's extrinsics with their sigmas.
pub fn report_markdown(calib: &Calibration, intrinsics_fixed: bool) -> String {
    let mut md = String::from("# stereotag calibration\n\n## Warnings\n\n");
    if calib.warnings.is_empty() {
        md.push_str("None.\n");
    }
    for w in &calib.warnings {
        md.push_str(&format!("- **{w}**\n"));
    }
    let sigma = |key: &str| calib.sigmas.get(key).copied();
    let pm = |v: f64, s: Option<f64>, digits: usize| match s {
        Some(s) => format!("{v:.digits$} ± {s:.digits$}"),
        None => format!("{v:.digits$}"),
    };
    let t = calib.rig.right_from_left.translation.vector;
    if calib.stereo {
        md.push_str(&format!(
            "\n## Fit\n\n| value | |\n|---:|---|\n\
             | {:.3} px | RMS reprojection (left {:.3}, right {:.3}) |\n\
             | {:.3} px | epipolar error |\n\
             | {} mm | baseline (± 1σ) |\n\
             | {} | views used |\n| {} | outliers left out |\n\
             | {:.0}% / {:.0}% | image cells covered, left / right |\n",
            calib.rms_px,
            calib.rms_left_px,
            calib.rms_right_px,
            calib.epipolar_error_px,
            pm(1e3 * t.norm(), sigma("baseline_m").map(|s| 1e3 * s), 2),
            calib.views.len(),
            calib.outliers.len(),
            100.0 * calib.coverage.0,
            100.0 * calib.coverage.1,
        ));
    } else {
        md.push_str(&format!(
            "\n## Fit\n\n| value | |\n|---:|---|\n\
             | {:.3} px | RMS reprojection |\n\
             | {} | views used |\n| {} | outliers left out |\n\
             | {:.0}% | image cells covered |\n",
            calib.rms_px,
            calib.views.len(),
            calib.outliers.len(),
            100.0 * calib.coverage.0,
        ));
    }
    let cameras = calib.cameras();
    md.push_str(&format!(
        "\n## Intrinsics (± 1σ{})\n\n|{}|\n|---|{}\n",
        if intrinsics_fixed {
            "; fixed, as given"
        } else {
            ""
        },
        cameras
            .iter()
            .fold(" ".to_string(), |acc, (n, _)| format!("{acc}| {n} ")),
        "---:|".repeat(cameras.len()),
    ));
    let named: Vec<_> = cameras
        .iter()
        .map(|(side, cam)| (*side, crate::calib::named_intrinsics(cam)))
        .collect();
    for k in 0..named[0].1.len() {
        let name = named[0].1[k].0;
        let digits = if name.starts_with('f') || name.starts_with('c') {
            2
        } else {
            5
        };
        md.push_str(&format!("| {name} |"));
        for (side, values) in &named {
            md.push_str(&format!(
                " {} |",
                pm(values[k].1, sigma(&format!("{side}.{name}")), digits)
            ));
        }
        md.push('\n');
    }
    let uncertainty = crate::calib::projection_uncertainty(calib);
    if !uncertainty.is_empty() {
        md.push_str(
            "\n## Projection uncertainty (1σ, worst direction, px)\n\n| | centre | median | largest |\n|---|---:|---:|---:|\n",
        );
        for u in &uncertainty {
            md.push_str(&format!(
                "| {} | {:.3} | {:.3} | {:.3} |\n",
                u.camera, u.centre_px, u.median_px, u.max_px
            ));
        }
    }
    if !calib.stereo {
        return md;
    }
    md.push_str("\n## Right camera from left (± 1σ)\n\n| | value |\n|---|---:|\n");
    let r = calib.rig.right_from_left.rotation.scaled_axis();
    for (name, v, scale, unit) in [
        ("tx", t.x, 1e3, "mm"),
        ("ty", t.y, 1e3, "mm"),
        ("tz", t.z, 1e3, "mm"),
        ("rx", r.x, 180.0 / std::f64::consts::PI, "deg"),
        ("ry", r.y, 180.0 / std::f64::consts::PI, "deg"),
        ("rz", r.z, 180.0 / std::f64::consts::PI, "deg"),
    ] {
        md.push_str(&format!(
            "| {name} | {} {unit} |\n",
            pm(
                v * scale,
                sigma(&format!("right_from_left.{name}")).map(|s| s * scale),
                3
            )
        ));
    }
    md
}

/// Both images rectified, side by side, with horizontal lines: corresponding points of a good
/// calibration lie on the same line.
pub fn rectified_pair(
    rig: &StereoRig,
    left: &image::GrayImage,
    right: &image::GrayImage,
) -> image::GrayImage {
    let rect = rig.rectify();
    let l = rect.rectify_image(&rig.left, &rect.left_rotation, left);
    let r = rect.rectify_image(&rig.right, &rect.right_rotation, right);
    let (w, h) = (l.width() + r.width(), l.height().max(r.height()));
    let mut out = image::GrayImage::new(w, h);
    image::imageops::replace(&mut out, &l, 0, 0);
    image::imageops::replace(&mut out, &r, l.width() as i64, 0);
    for y in (EPIPOLAR_LINE_ROWS / 2..h).step_by(EPIPOLAR_LINE_ROWS as usize) {
        for x in 0..w {
            out.put_pixel(x, y, image::Luma([255]));
        }
    }
    out
}

/// What one image gave: its view name (the file stem), size, the target's corners and the
/// JPEG for the recording.
struct ImageFound {
    name: String,
    size: (u32, u32),
    view: TargetView,
    jpeg: Option<Vec<u8>>,
}

/// Detects the target's corners in the left images (a glob) and, for a rig, the right ones,
/// images in parallel; `keep_images` keeps them for the recording. Left and right are paired
/// in sorted order and named by the left image.
pub fn detect_views(
    target: &Target,
    left: &str,
    right: Option<&str>,
    keep_images: bool,
    progress: &dyn Progress,
) -> Result<CalibrationViews> {
    let lf = io::glob(left)?;
    let rf = match right {
        Some(right) => io::glob(right)?,
        None => Vec::new(),
    };
    if right.is_some() && lf.len() != rf.len() {
        return Err(Error::Request(format!(
            "{} left images but {} right images: the pairs must match",
            lf.len(),
            rf.len()
        )));
    }
    let paths: Vec<&std::path::PathBuf> = lf.iter().chain(&rf).collect();
    let mut found = detect_images(target, &paths, keep_images, progress)?.into_iter();
    let lefts: Vec<ImageFound> = found.by_ref().take(lf.len()).collect();
    let rights: Vec<Option<ImageFound>> = if right.is_some() {
        found.map(Some).collect()
    } else {
        lefts.iter().map(|_| None).collect()
    };
    let mut out = CalibrationViews::default();
    for (i, (l, r)) in lefts.into_iter().zip(rights).enumerate() {
        if let Some(r) = r.as_ref().filter(|r| r.size != l.size) {
            return Err(Error::Request(format!(
                "{} is {}x{} but {} is {}x{}: left and right images must be the same size",
                lf[i].display(),
                l.size.0,
                l.size.1,
                rf[i].display(),
                r.size.0,
                r.size.1
            )));
        }
        if let Some(before) = out.resolution.filter(|s| *s != l.size) {
            return Err(Error::Request(format!(
                "{} is {}x{} but the images before it are {}x{}: one camera, one size",
                lf[i].display(),
                l.size.0,
                l.size.1,
                before.0,
                before.1
            )));
        }
        out.resolution = Some(l.size);
        let (first, second) = if right.is_some() {
            ("left", "right")
        } else {
            ("camera", "")
        };
        let found = std::iter::once((&lf[i], &l.view, first))
            .chain(r.as_ref().map(|r| (&rf[i], &r.view, second)));
        for (path, view, camera) in found {
            if let Some(m) = &view.miss {
                tracing::info!("{}: {m}", path.display());
                out.misses.push(format!("{}: {m}", path.display()));
            }
            out.per_image.push(ImageRecord {
                image: path.display().to_string(),
                view: l.name.clone(),
                camera,
                tags: view.tags.len(),
                corners: view.corners.len(),
                miss: view.miss.clone(),
            });
        }
        if let Some(lj) = l.jpeg {
            let rj = r.as_ref().and_then(|r| r.jpeg.clone()).unwrap_or_default();
            out.images.insert(l.name.clone(), (lj, rj));
        }
        if let Some(r) = r {
            out.right.insert(l.name.clone(), r.view.corners);
        }
        out.left.insert(l.name, l.view.corners);
    }
    Ok(out)
}

/// Finds the target in every image, in parallel, one detector per worker thread (the C
/// detector is not shared); the results in the order of `paths`.
fn detect_images(
    target: &Target,
    paths: &[&std::path::PathBuf],
    keep_images: bool,
    progress: &dyn Progress,
) -> Result<Vec<ImageFound>> {
    progress.start("detect", paths.len() as u64);
    let found: Vec<Result<ImageFound>> = paths
        .par_iter()
        .map_init(
            || TargetDetector::new(target),
            |detector, path| {
                let detector = detector
                    .as_mut()
                    .map_err(|e| Error::Request(e.to_string()))?;
                let img = io::load_gray(path)?;
                let found = ImageFound {
                    name: path
                        .file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_default(),
                    size: img.dimensions(),
                    view: detector.detect(&img)?,
                    jpeg: keep_images.then(|| crate::viz::jpeg_image(&img)).flatten(),
                };
                progress.advance(1);
                Ok(found)
            },
        )
        .collect();
    progress.finish();
    found.into_iter().collect()
}
