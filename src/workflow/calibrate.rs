//! Calibrate a stereo rig from images of a target (or corners already detected): the corners of
//! every view found, both cameras and `right_from_left` adjusted; the rig written as Kalibr,
//! OpenCV and ROS files with a report, and recorded.

use super::{Error, Result};
use crate::calib::{
    calibrate_stereo, CalibConfig, CalibError, Calibration, Target, TargetDetector, TargetView,
    ViewCorners,
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
    /// Keep this rig file's intrinsics and distortion; solve `right_from_left` only.
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
    /// Each view's images as JPEG, when kept for the recording.
    pub images: ViewImages,
}

/// Calibrates a rig and writes `camchain.yaml`, `opencv_stereo.yaml`, `left.yaml`,
/// `right.yaml`, `report.json`, `rectified.png` (when asked) and the recording into a new
/// directory. Progress: one step per image pair.
///
/// ```no_run
/// use std::path::Path;
/// use stereotag::camera::LensModel;
/// use stereotag::progress::Silent;
/// use stereotag::viz::RecordingRequest;
/// use stereotag::workflow::calibrate::{calibrate, CalibrateRequest, CalibrationInput};
///
/// let out = calibrate(
///     &CalibrateRequest {
///         target: Path::new("calibration/targets/checkerboard_9x6.yaml"),
///         input: CalibrationInput::Images {
///             left: "images/*_left.jpg",
///             right: "images/*_right.jpg",
///         },
///         resolution: None,
///         model: LensModel::Radtan,
///         fix_intrinsics: None,
///         out: Path::new("calib/my-rig"),
///         force: false,
///         force_write: false,
///         rectify_pair: None,
///         recording: RecordingRequest::none(),
///     },
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
    let target = io::load_target(request.target)?;
    let views = match request.input {
        CalibrationInput::Corners { left, right } => CalibrationViews {
            left: io::load_corner_csvs(left)?,
            right: io::load_corner_csvs(right)?,
            ..CalibrationViews::default()
        },
        CalibrationInput::Images { left, right } => {
            detect_views(&target, left, right, !request.recording.off, progress)?
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
    let calib =
        calibrate_stereo(&views.left, &views.right, resolution, &config).inspect_err(|e| {
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
    io::save_rig_exports_noted(&dir.path(""), &calib.rig, &notes)?;
    for f in &failures {
        tracing::warn!("written despite: {f}");
    }
    let mut report = report(
        &calib,
        &target,
        request.fix_intrinsics.is_some(),
        [detect_s, solve_s, started.elapsed().as_secs_f64()],
    )?;
    report["failures"] = serde_json::json!(failures);
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
            view_images: &views.images,
        })?;
        rec.finish()?;
    }
    dir.commit()?;
    Ok(CalibrateOutput {
        calibration: calib,
        report,
    })
}

/// `report.json`: the metrics, timings (`[detect, solve, total]` seconds), target, intrinsics,
/// `right_from_left`, sigmas, per-view residuals, outliers, coverage and warnings.
fn report(
    calib: &Calibration,
    target: &Target,
    intrinsics_fixed: bool,
    [detect_s, solve_s, total_s]: [f64; 3],
) -> Result<serde_json::Value> {
    let t = calib.rig.right_from_left.translation.vector;
    let (roll, pitch, yaw) = calib.rig.right_from_left.rotation.euler_angles();
    let intr = |c: &crate::camera::Camera| serde_json::json!({"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "distortion": format!("{:?}", c.distortion)});
    Ok(serde_json::json!({
        "metrics": {
            "rms_px": calib.rms_px,
            "rms_left_px": calib.rms_left_px,
            "rms_right_px": calib.rms_right_px,
            "views_used": calib.views.len(),
            "outliers": calib.outliers.len(),
            "baseline_m": t.norm(),
            "epipolar_error_px": calib.epipolar_error_px,
            "coverage_left": calib.coverage.0,
            "coverage_right": calib.coverage.1,
        },
        "timings_s": {"read_and_detect": detect_s, "solve": solve_s, "total": total_s},
        "target": serde_json::to_value(target).map_err(|e| Error::Request(e.to_string()))?,
        "intrinsics_fixed": intrinsics_fixed,
        "left": intr(&calib.rig.left),
        "right": intr(&calib.rig.right),
        "right_from_left": {"t_m": [t.x, t.y, t.z], "roll_pitch_yaw_rad": [roll, pitch, yaw]},
        "sigmas": calib.sigmas,
        "per_view": calib.views,
        "outliers": calib.outliers,
        "coverage_counts": {"cols": 8, "rows": 6, "left": calib.coverage_counts.0, "right": calib.coverage_counts.1},
        "warnings": calib.warnings,
    }))
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
    md.push_str(&format!(
        "\n## Intrinsics (± 1σ{})\n\n| | left | right |\n|---|---:|---:|\n",
        if intrinsics_fixed {
            "; fixed, as given"
        } else {
            ""
        }
    ));
    let left = crate::calib::named_intrinsics(&calib.rig.left);
    let right = crate::calib::named_intrinsics(&calib.rig.right);
    for ((name, l), (_, r)) in left.iter().zip(&right) {
        let digits = if name.starts_with('f') || name.starts_with('c') {
            2
        } else {
            5
        };
        md.push_str(&format!(
            "| {name} | {} | {} |\n",
            pm(*l, sigma(&format!("left.{name}")), digits),
            pm(*r, sigma(&format!("right.{name}")), digits)
        ));
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

/// What one image pair gave: its view name, image size, what each camera saw, and the JPEGs
/// for the recording.
struct PairFound {
    name: String,
    size: (u32, u32),
    left: TargetView,
    right: TargetView,
    jpegs: Option<(Vec<u8>, Vec<u8>)>,
}

/// Detects the target's corners in every left and right image (globs), pairs in parallel;
/// `keep_images` keeps them for the recording.
pub fn detect_views(
    target: &Target,
    left: &str,
    right: &str,
    keep_images: bool,
    progress: &dyn Progress,
) -> Result<CalibrationViews> {
    let (lf, rf) = (io::glob(left)?, io::glob(right)?);
    if lf.len() != rf.len() {
        return Err(Error::Request(format!(
            "{} left images but {} right images: the pairs must match",
            lf.len(),
            rf.len()
        )));
    }
    progress.start("detect", lf.len() as u64);
    // One detector per worker thread (the C detector is not shared).
    let pairs: Vec<Result<PairFound>> = lf
        .par_iter()
        .zip(&rf)
        .map_init(
            || TargetDetector::new(target),
            |detector, (l, r)| {
                let detector = detector
                    .as_mut()
                    .map_err(|e| Error::Request(e.to_string()))?;
                let found = detect_pair(detector, l, r, keep_images)?;
                progress.advance(1);
                Ok(found)
            },
        )
        .collect();
    progress.finish();
    let mut out = CalibrationViews::default();
    for ((pair, l), r) in pairs.into_iter().zip(&lf).zip(&rf) {
        let pair = pair?;
        if let Some(j) = pair.jpegs {
            out.images.insert(pair.name.clone(), j);
        }
        if let Some(before) = out.resolution.filter(|s| *s != pair.size) {
            return Err(Error::Request(format!(
                "{} is {}x{} but the images before it are {}x{}: one camera, one size",
                l.display(),
                pair.size.0,
                pair.size.1,
                before.0,
                before.1
            )));
        }
        out.resolution = Some(pair.size);
        for (path, miss) in [(l, pair.left.miss), (r, pair.right.miss)] {
            if let Some(m) = miss {
                tracing::info!("{}: {m}", path.display());
                out.misses.push(format!("{}: {m}", path.display()));
            }
        }
        tracing::debug!(
            "{}: {} left, {} right corners",
            pair.name,
            pair.left.corners.len(),
            pair.right.corners.len()
        );
        out.left.insert(pair.name.clone(), pair.left.corners);
        out.right.insert(pair.name, pair.right.corners);
    }
    Ok(out)
}

/// Reads one pair of images and finds the target in both.
fn detect_pair(
    detector: &mut TargetDetector,
    l: &Path,
    r: &Path,
    keep_images: bool,
) -> Result<PairFound> {
    let (li, ri) = (io::load_gray(l)?, io::load_gray(r)?);
    if li.dimensions() != ri.dimensions() {
        return Err(Error::Request(format!(
            "{} is {}x{} but {} is {}x{}: left and right images must be the same size",
            l.display(),
            li.width(),
            li.height(),
            r.display(),
            ri.width(),
            ri.height()
        )));
    }
    let name = l
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let jpegs = keep_images
        .then(|| crate::viz::jpeg_pair(&li, &ri))
        .flatten();
    Ok(PairFound {
        name,
        size: li.dimensions(),
        left: detector.detect(&li)?,
        right: detector.detect(&ri)?,
        jpegs,
    })
}
