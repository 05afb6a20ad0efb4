//! Stereo calibration: targets and their corners ([`Target`], [`TargetDetector`]: the chessboard
//! in `chessboard.rs`, Kalibr's AprilGrid in `aprilgrid.rs`, X-corner refinement in
//! `xcorner.rs`), then per-camera closed-form initialisation (Zhang, `init.rs`) and one
//! Levenberg-Marquardt bundle adjustment of both cameras' intrinsics and distortion, the board
//! poses and `right_from_left`, under a Huber kernel (`bundle.rs`), with outliers removed and
//! listed, and the fit, coverage, sigmas and warnings a user needs.

pub mod aprilgrid;
mod bundle;
pub mod charuco;
pub mod chessboard;
mod init;
mod target;
mod uncertainty;
mod xcorner;

pub use aprilgrid::{aprilgrid_board_point, aprilgrid_corners};
pub use charuco::CharucoTarget;
pub use chessboard::{chessboard_board_corners, chessboard_board_point};
pub(crate) use target::check_id_layout;
pub use target::{
    AprilGridTarget, BoardsTarget, CheckerboardTarget, TagBoardTarget, Target, TargetDetector,
    TargetView, BOARD_ID_STRIDE,
};
pub use uncertainty::{
    projection_uncertainty, ProjectionUncertainty, UNCERTAINTY_COLS, UNCERTAINTY_ROWS,
};

use crate::camera::{Camera, LensModel, StereoRig};
pub use bundle::Covariance;
use bundle::{parameter_covariance, solve, State};
use init::{board_pose, initial_camera, median_relative, reprojection_error};
use nalgebra::Isometry3;
use serde::Serialize;
use std::collections::BTreeMap;

/// A board corner seen in one image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Corner id on the board (tag id × 4 + corner index for an AprilGrid).
    pub id: u32,
    /// Position on the board, metres (z = 0).
    pub board_m: [f64; 3],
    /// Detected position, pixels.
    pub px: [f64; 2],
}

/// The corners of one image, keyed by a view name (the time stamp) shared by left and right.
pub type ViewCorners = BTreeMap<String, Vec<Corner>>;

/// Settings of the calibration. Defaults say where they come from.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibConfig {
    /// Huber kernel width, pixels (ours: 1 px).
    pub huber_px: f64,
    /// A corner whose reprojection error exceeds this after the first solve is an outlier, pixels
    /// (ours: 2 px: real detections hold outliers of several pixels, good ones stay below 1).
    pub outlier_px: f64,
    /// After the second solve of free intrinsics, a corner whose error exceeds this many times
    /// the fit's own scatter (its robust per-axis sigma, from the median error) is an outlier too, but never
    /// one under [`CalibConfig::outlier_floor_px`] (ours: 5: a Gaussian corner error passes 5
    /// sigma once in 270,000; a mis-refined corner on a fisheye's rim, 0.3-2 px off where good
    /// ones are 0.03 px off, does not).
    pub outlier_sigmas: f64,
    /// The second pass never calls a corner within this of its projection an outlier, pixels
    /// (ours: 0.5 px).
    pub outlier_floor_px: f64,
    /// Corners a view needs to be used (ours: 12).
    pub min_corners: usize,
    /// Keep these intrinsics (and distortion) fixed and solve the extrinsics only.
    pub fixed_intrinsics: Option<(Camera, Camera)>,
    /// Levenberg-Marquardt iterations at most.
    pub max_iterations: usize,
    /// Lens model of free intrinsics (ours: radtan; equidistant for fisheye lenses).
    pub model: LensModel,
}

impl Default for CalibConfig {
    fn default() -> Self {
        Self {
            huber_px: 1.0,
            outlier_px: 2.0,
            outlier_sigmas: 5.0,
            outlier_floor_px: 0.5,
            min_corners: 12,
            fixed_intrinsics: None,
            max_iterations: 100,
            model: LensModel::Radtan,
        }
    }
}

/// Errors of the calibration.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// Too few usable views.
    #[error("too few views with {} at least {min_corners} corners: got {got}, need {need}", if *stereo { "both cameras seeing" } else { "the camera seeing" })]
    TooFewViews {
        /// Views found.
        got: usize,
        /// Views needed.
        need: usize,
        /// Corners per view needed.
        min_corners: usize,
        /// Whether both cameras of a rig had to see them.
        stereo: bool,
    },
    /// Zhang's initialisation has no positive-definite solution.
    #[error("the closed-form initialisation failed: the board views are too alike (all square-on to the camera?), so the focal length cannot be told from the distance; tilt the board up to 45 degrees in turn towards each edge")]
    Initialisation,
    /// The solver returned nothing.
    #[error("the bundle adjustment did not converge")]
    Solver,
}

/// A corner left out as an outlier.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Outlier {
    /// View name.
    pub view: String,
    /// `left` or `right` (`camera` for one camera).
    pub camera: &'static str,
    /// Corner id.
    pub id: u32,
    /// Its reprojection error after the first solve, pixels.
    pub error_px: f64,
}

/// Reprojection error of one view.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ViewResidual {
    /// View name.
    pub view: String,
    /// RMS over the view's corners in the left image, pixels.
    pub rms_left_px: f64,
    /// RMS in the right image, pixels.
    pub rms_right_px: f64,
}

/// The calibration of a stereo rig or of one camera.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// Whether a rig was calibrated; else one camera, `rig.left`, whose views are the `left`
    /// ones: `rig.right` then repeats it, `right_from_left` is the identity, and the right
    /// fields (RMS, coverage, corners) are empty. [`Calibration::cameras`] names the cameras.
    pub stereo: bool,
    /// The rig (robot_from_left identity).
    pub rig: StereoRig,
    /// RMS reprojection error over all corners used, pixels.
    pub rms_px: f64,
    /// RMS in the left images.
    pub rms_left_px: f64,
    /// RMS in the right images.
    pub rms_right_px: f64,
    /// Per view.
    pub views: Vec<ViewResidual>,
    /// Corners left out.
    pub outliers: Vec<Outlier>,
    /// Parameter sigmas by name (`left.fx`, ..., `right_from_left.tx`, `baseline_m`; `camera.fx`,
    /// ... for one camera), one sigma.
    pub sigmas: BTreeMap<String, f64>,
    /// The covariance of the intrinsics and `right_from_left` (empty when it is singular).
    pub covariance: Covariance,
    /// RMS row difference of the same corner in the two rectified images (Bouguet rectification
    /// of the result), pixels; 0 for one camera.
    pub epipolar_error_px: f64,
    /// Share of each image's 8 x 6 cells holding at least one corner (left, right).
    pub coverage: (f64, f64),
    /// Cell counts of corners per image (row-major 6 rows x 8 columns), left and right.
    pub coverage_counts: (Vec<u32>, Vec<u32>),
    /// Things the user should know, with what to do.
    pub warnings: Vec<String>,
    /// The views used, with the corners kept and the solved board pose.
    pub used: Vec<UsedView>,
}

/// A view as the adjustment used it.
#[derive(Debug, Clone)]
pub struct UsedView {
    /// View name.
    pub name: String,
    /// Left corners kept.
    pub left: Vec<Corner>,
    /// Right corners kept.
    pub right: Vec<Corner>,
    /// `left_from_board`.
    pub left_from_board: Isometry3<f64>,
}

/// Columns and rows of the grid over each image by which coverage is counted.
const COVERAGE_COLS: usize = 8;
/// Rows of the coverage grid.
const COVERAGE_ROWS: usize = 6;
/// Views the free calibration needs (Zhang needs three; fewer than 10 gets a warning).
const MIN_VIEWS_FREE: usize = 3;
/// Views the extrinsics-only calibration needs.
const MIN_VIEWS_FIXED: usize = 1;
/// Fewer views than this get a warning (ours: 10; Kalibr and OpenCV ask for 20 or more).
const FEW_VIEWS: usize = 10;
/// Coverage of either image's cells below this gets a warning (ours: 60%).
const LOW_COVERAGE: f64 = 0.6;
/// An RMS or an epipolar error above this gets a warning, pixels (ours: 0.5 px).
const HIGH_ERROR_PX: f64 = 0.5;
/// A focal length or principal point whose sigma exceeds this share of it gets a warning (1%).
const POORLY_OBSERVED_SHARE: f64 = 0.01;

/// The cameras' names, as sigmas, reports and messages use them: `left` and `right` for a rig,
/// `camera` for one camera.
pub(crate) fn camera_names(stereo: bool) -> &'static [&'static str] {
    if stereo {
        &["left", "right"]
    } else {
        &["camera"]
    }
}

impl Calibration {
    /// The calibrated cameras with their names: `left` and `right`, or `camera` alone.
    pub fn cameras(&self) -> Vec<(&'static str, &Camera)> {
        camera_names(self.stereo)
            .iter()
            .copied()
            .zip([&self.rig.left, &self.rig.right])
            .collect()
    }
}

/// One view's corners in both images (corners keyed by id).
#[derive(Debug, Clone)]
pub(crate) struct View<'a> {
    /// The view's name.
    pub(crate) name: &'a str,
    /// Left corners.
    pub(crate) left: Vec<Corner>,
    /// Right corners.
    pub(crate) right: Vec<Corner>,
}

/// A camera's calibrated intrinsics by name (`fx`, `fy`, `cx`, `cy` and its lens model's terms:
/// four for radtan and equidistant, two for double sphere and extended unified), named as
/// [`Calibration::sigmas`] names them (after `left.`, `right.` or `camera.`).
pub fn named_intrinsics(c: &Camera) -> Vec<(&'static str, f64)> {
    bundle::intrinsics_names(c)
        .iter()
        .copied()
        .zip(bundle::intrinsics_vec(c))
        .collect()
}

/// Calibrates a stereo rig from corners of the same views in both cameras: the cameras and
/// board poses initialised, adjusted, the outliers dropped and listed, adjusted again; with the
/// residuals, coverage, sigmas and warnings.
pub fn calibrate_stereo(
    left: &ViewCorners,
    right: &ViewCorners,
    resolution: (u32, u32),
    config: &CalibConfig,
) -> Result<Calibration, CalibError> {
    adjust(usable_views(left, Some(right), config)?, resolution, config)
}

/// Calibrates one camera from its views' corners, as [`calibrate_stereo`] does a rig (the
/// result's `stereo` is false). `config.fixed_intrinsics` must be `None`: one camera with fixed
/// intrinsics leaves nothing to calibrate.
pub fn calibrate_camera(
    views: &ViewCorners,
    resolution: (u32, u32),
    config: &CalibConfig,
) -> Result<Calibration, CalibError> {
    let config = CalibConfig {
        fixed_intrinsics: None,
        ..config.clone()
    };
    adjust(usable_views(views, None, &config)?, resolution, &config)
}

/// The adjustment of one camera's views (their `right` corners empty) or a rig's.
fn adjust(
    views: Vec<View<'_>>,
    resolution: (u32, u32),
    config: &CalibConfig,
) -> Result<Calibration, CalibError> {
    let stereo = views.iter().any(|v| !v.right.is_empty());
    let mut state = initial_state(&views, resolution, config, stereo)?;
    solve(&mut state, &views, config)?;
    // Outliers: corners far off after the first solve are dropped, listed, and the solve
    // repeated; then, when the intrinsics are free, those far off for the fit's own scatter, and
    // the solve repeated again. (Fixed intrinsics leave their own mismatch with the views in the
    // errors, which is no detection's fault: there only the first rule applies.)
    let (mut views, mut outliers) = drop_outliers(&state, views, config.outlier_px);
    solve(&mut state, &views, config)?;
    if config.fixed_intrinsics.is_none() {
        let threshold = scatter_threshold(&state, &views, config);
        let (kept, more) = drop_outliers(&state, views, threshold);
        views = kept;
        if !more.is_empty() {
            outliers.extend(more);
            solve(&mut state, &views, config)?;
        }
    }
    let fit = Fit::of(&state, &views, resolution);
    let (sigmas, covariance) = parameter_covariance(&state, &views, config, fit.rms_px);
    let rig = StereoRig {
        left: state.left,
        right: state.right,
        right_from_left: state.right_from_left,
        robot_from_left: Isometry3::identity(),
        right_from_left_covariance: covariance.block("right_from_left.rx"),
    };
    let epipolar_error_px = if stereo {
        epipolar_rms(&rig, &views)
    } else {
        0.0
    };
    let mut calib = Calibration {
        stereo,
        rig,
        epipolar_error_px,
        rms_px: fit.rms_px,
        rms_left_px: fit.rms_left_px,
        rms_right_px: fit.rms_right_px,
        views: fit.per_view,
        outliers,
        sigmas,
        covariance,
        coverage: fit.coverage,
        coverage_counts: fit.coverage_counts,
        warnings: Vec::new(),
        used: views
            .iter()
            .zip(&state.poses)
            .map(|(v, pose)| UsedView {
                name: v.name.to_string(),
                left: v.left.clone(),
                right: v.right.clone(),
                left_from_board: *pose,
            })
            .collect(),
    };
    calib.warnings = warnings(&calib, config);
    Ok(calib)
}

/// The views whose corners are enough (in both cameras when `right` is given; with one camera
/// the right corners are empty), sorted by name; an error when too few. A rig's view that only
/// one camera's corners name (the other camera's map has no such view: a board seen in part,
/// which cannot be numbered alike in both images) is a view of that camera alone, its other
/// side empty; at least one view must be seen by both.
fn usable_views<'a>(
    left: &'a ViewCorners,
    right: Option<&'a ViewCorners>,
    config: &CalibConfig,
) -> Result<Vec<View<'a>>, CalibError> {
    let enough = |c: Option<&Vec<Corner>>| c.is_some_and(|c| c.len() >= config.min_corners);
    let names: std::collections::BTreeSet<&String> = left
        .keys()
        .chain(right.iter().flat_map(|r| r.keys()))
        .collect();
    let names: Vec<&String> = names
        .into_iter()
        .filter(|k| match right {
            None => enough(left.get(*k)),
            Some(right) => match (left.get(*k), right.get(*k)) {
                (Some(_), Some(_)) => enough(left.get(*k)) && enough(right.get(*k)),
                (l, r) => enough(l) || enough(r),
            },
        })
        .collect();
    let need = if config.fixed_intrinsics.is_some() {
        MIN_VIEWS_FIXED
    } else {
        MIN_VIEWS_FREE
    };
    let both = names
        .iter()
        .filter(|k| right.is_none_or(|r| left.contains_key(**k) && r.contains_key(**k)))
        .count();
    if names.len() < need || both == 0 {
        return Err(CalibError::TooFewViews {
            got: both.min(names.len()),
            need,
            min_corners: config.min_corners,
            stereo: right.is_some(),
        });
    }
    Ok(names
        .iter()
        .map(|n| View {
            name: n.as_str(),
            left: left.get(*n).cloned().unwrap_or_default(),
            right: right.and_then(|r| r.get(*n).cloned()).unwrap_or_default(),
        })
        .collect())
}

/// Where the adjustment starts: the cameras given or initialised, each board's pose in the left
/// camera, and `right_from_left` as the median of the views' relative poses.
fn initial_state(
    views: &[View<'_>],
    resolution: (u32, u32),
    config: &CalibConfig,
    stereo: bool,
) -> Result<State, CalibError> {
    let (left, right) = match &config.fixed_intrinsics {
        Some((l, r)) => (*l, *r),
        None => {
            let seen = |side: fn(&View<'_>) -> bool| views.iter().filter(move |v| side(v));
            let left = initial_camera(
                seen(|v| !v.left.is_empty()).map(|v| &v.left),
                resolution,
                config.model,
            )?;
            let right = if stereo {
                initial_camera(
                    seen(|v| !v.right.is_empty()).map(|v| &v.right),
                    resolution,
                    config.model,
                )?
            } else {
                left
            };
            (left, right)
        }
    };
    if !stereo {
        let poses = views
            .iter()
            .map(|v| board_pose(&left, &v.left).ok_or(CalibError::Initialisation))
            .collect::<Result<Vec<_>, _>>()?;
        return Ok(State {
            left,
            right,
            right_from_left: Isometry3::identity(),
            poses,
            stereo,
        });
    }
    let pose = |cam: &Camera, corners: &[Corner]| {
        board_pose(cam, corners).ok_or(CalibError::Initialisation)
    };
    // `right_from_left` from the views both cameras saw; a view of the right camera alone
    // placed through it.
    let (mut both_l, mut both_r) = (Vec::new(), Vec::new());
    for v in views
        .iter()
        .filter(|v| !v.left.is_empty() && !v.right.is_empty())
    {
        both_l.push(pose(&left, &v.left)?);
        both_r.push(pose(&right, &v.right)?);
    }
    let right_from_left = median_relative(&both_l, &both_r);
    let poses = views
        .iter()
        .map(|v| match v.left.is_empty() {
            false => pose(&left, &v.left),
            true => Ok(right_from_left.inverse() * pose(&right, &v.right)?),
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(State {
        left,
        right,
        right_from_left,
        poses,
        stereo,
    })
}

/// The outlier threshold of the fit's own scatter: [`CalibConfig::outlier_sigmas`] times the
/// robust per-axis sigma of the corners' errors (their median over `sqrt(2 ln 2)`, the median of
/// a 2D Gaussian error's length in sigmas), at least [`CalibConfig::outlier_floor_px`].
fn scatter_threshold(state: &State, views: &[View<'_>], config: &CalibConfig) -> f64 {
    let mut errors: Vec<f64> = views
        .iter()
        .enumerate()
        .flat_map(|(i, v)| {
            let pl = state.poses[i];
            let pr = state.right_from_left * pl;
            let left = v
                .left
                .iter()
                .map(move |c| reprojection_error(&state.left, &pl, c));
            let right = v
                .right
                .iter()
                .map(move |c| reprojection_error(&state.right, &pr, c));
            left.chain(right)
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    let median = errors.get(errors.len() / 2).copied().unwrap_or(0.0);
    let sigma = median / (2.0 * std::f64::consts::LN_2).sqrt();
    (config.outlier_sigmas * sigma).max(config.outlier_floor_px)
}

/// The views without the corners whose reprojection error exceeds `threshold_px`, and those
/// corners.
fn drop_outliers<'a>(
    state: &State,
    views: Vec<View<'a>>,
    threshold_px: f64,
) -> (Vec<View<'a>>, Vec<Outlier>) {
    let mut outliers = Vec::new();
    let views = views
        .into_iter()
        .enumerate()
        .map(|(i, v)| {
            let mut keep =
                |side: &'static str, corners: Vec<Corner>, cam: &Camera, pose: Isometry3<f64>| {
                    corners
                        .into_iter()
                        .filter(|c| {
                            let e = reprojection_error(cam, &pose, c);
                            if e > threshold_px {
                                outliers.push(Outlier {
                                    view: v.name.to_string(),
                                    camera: side,
                                    id: c.id,
                                    error_px: e,
                                });
                                false
                            } else {
                                true
                            }
                        })
                        .collect::<Vec<_>>()
                };
            let pl = state.poses[i];
            let pr = state.right_from_left * state.poses[i];
            let names = camera_names(state.stereo);
            let left = keep(names[0], v.left, &state.left, pl);
            let right = keep("right", v.right, &state.right, pr);
            View {
                name: v.name,
                left,
                right,
            }
        })
        .collect();
    (views, outliers)
}

/// How well the adjusted cameras fit the corners, and how much of each image the corners cover.
struct Fit {
    rms_px: f64,
    rms_left_px: f64,
    rms_right_px: f64,
    per_view: Vec<ViewResidual>,
    coverage: (f64, f64),
    coverage_counts: (Vec<u32>, Vec<u32>),
}

impl Fit {
    fn of(state: &State, views: &[View<'_>], resolution: (u32, u32)) -> Self {
        let (cam_l, cam_r) = (&state.left, &state.right);
        let (mut sum_l, mut n_l, mut sum_r, mut n_r) = (0.0, 0usize, 0.0, 0usize);
        let mut per_view = Vec::new();
        let mut cells_l = vec![0u32; COVERAGE_COLS * COVERAGE_ROWS];
        let mut cells_r = vec![0u32; COVERAGE_COLS * COVERAGE_ROWS];
        for (i, v) in views.iter().enumerate() {
            let pl = state.poses[i];
            let pr = state.right_from_left * pl;
            let squares = |cam: &Camera, pose: &Isometry3<f64>, corners: &[Corner]| -> Vec<f64> {
                corners
                    .iter()
                    .map(|c| reprojection_error(cam, pose, c).powi(2))
                    .collect()
            };
            let el = squares(cam_l, &pl, &v.left);
            let er = squares(cam_r, &pr, &v.right);
            sum_l += el.iter().sum::<f64>();
            n_l += el.len();
            sum_r += er.iter().sum::<f64>();
            n_r += er.len();
            per_view.push(ViewResidual {
                view: v.name.to_string(),
                rms_left_px: (el.iter().sum::<f64>() / el.len().max(1) as f64).sqrt(),
                rms_right_px: (er.iter().sum::<f64>() / er.len().max(1) as f64).sqrt(),
            });
            count_cells(&mut cells_l, &v.left, resolution);
            count_cells(&mut cells_r, &v.right, resolution);
        }
        let share = |c: &[u32]| c.iter().filter(|&&n| n > 0).count() as f64 / c.len() as f64;
        Self {
            rms_px: ((sum_l + sum_r) / (n_l + n_r).max(1) as f64).sqrt(),
            rms_left_px: (sum_l / n_l.max(1) as f64).sqrt(),
            rms_right_px: (sum_r / n_r.max(1) as f64).sqrt(),
            per_view,
            coverage: (share(&cells_l), share(&cells_r)),
            coverage_counts: (cells_l, cells_r),
        }
    }
}

/// Counts the corners in each cell of the coverage grid over the image.
fn count_cells(cells: &mut [u32], corners: &[Corner], resolution: (u32, u32)) {
    for c in corners {
        let col = ((c.px[0] / resolution.0 as f64) * COVERAGE_COLS as f64) as usize;
        let row = ((c.px[1] / resolution.1 as f64) * COVERAGE_ROWS as f64) as usize;
        if col < COVERAGE_COLS && row < COVERAGE_ROWS {
            cells[row * COVERAGE_COLS + col] += 1;
        }
    }
}

/// A focal length whose sigma exceeds this share of it is not determined by the views: 10%
/// (a failure; from 1% it is a warning).
pub const UNOBSERVED_SHARE: f64 = 0.10;
/// The two cameras' focal lengths may differ by this factor at most before the calibration is
/// taken to have failed: 1.5 (the cameras of a stereo rig are nearly always alike; two truly
/// different ones need `--force-write`).
pub const FOCAL_RATIO_LIMIT: f64 = 1.5;
/// More than this share of the corners left out as outliers is a failure: 20% (a good
/// calibration leaves out a few percent; a wrong one rejects what it cannot explain).
pub const OUTLIER_SHARE_LIMIT: f64 = 0.2;

/// Why a calibration cannot be trusted, each with what was found: a principal point outside its
/// image, a focal length its views do not determine (sigma over [`UNOBSERVED_SHARE`]) or that
/// disagrees between the cameras (over [`FOCAL_RATIO_LIMIT`]), too many outliers
/// ([`OUTLIER_SHARE_LIMIT`]), a camera with every corner rejected, or a `right_from_left` the
/// views do not determine (sigmas over [`UNDETERMINED_BASELINE_SHARE`] or
/// [`UNDETERMINED_ROTATION_RAD`]). Empty when none. With fixed intrinsics the intrinsics are not
/// judged.
pub fn failures(calib: &Calibration, fixed_intrinsics: bool) -> Vec<String> {
    let mut out = Vec::new();
    let rig = &calib.rig;
    if !fixed_intrinsics {
        for (name, cam) in calib.cameras() {
            let (w, h) = (cam.width as f64, cam.height as f64);
            if !(cam.cx >= 0.0 && cam.cx <= w && cam.cy >= 0.0 && cam.cy <= h) {
                out.push(format!(
                    "the {name} principal point ({:.1}, {:.1}) px lies outside the {}x{} image: these views do not determine the intrinsics",
                    cam.cx, cam.cy, cam.width, cam.height
                ));
            }
            for (key, value) in [("fx", cam.fx), ("fy", cam.fy)] {
                let k = format!("{name}.{key}");
                match calib.sigmas.get(&k) {
                    Some(s) if s.is_nan() || *s > UNOBSERVED_SHARE * value.abs() => {
                        out.push(format!(
                            "{k} = {value:.1} px is not determined by the views (sigma {s:.1} px, over {:.0}%)",
                            100.0 * UNOBSERVED_SHARE
                        ));
                    }
                    None => out.push(format!(
                        "{k} = {value:.1} px is not determined by the views (no sigma: the views leave some parameter free)"
                    )),
                    Some(_) => {}
                }
            }
        }
        let ratio = rig.left.fx.abs().max(rig.right.fx.abs())
            / rig.left.fx.abs().min(rig.right.fx.abs()).max(1e-9);
        if calib.stereo && (ratio.is_nan() || ratio > FOCAL_RATIO_LIMIT) {
            out.push(format!(
                "the focal lengths disagree: left fx {:.1} px, right fx {:.1} px (a factor {ratio:.2}, over {FOCAL_RATIO_LIMIT})",
                rig.left.fx, rig.right.fx
            ));
        }
    }
    if calib.stereo {
        out.extend(undetermined_pose(calib));
    }
    let kept = |side: fn(&UsedView) -> usize| calib.used.iter().map(side).sum::<usize>();
    let (kept_left, kept_right) = (kept(|v| v.left.len()), kept(|v| v.right.len()));
    for ((name, _), n) in calib.cameras().into_iter().zip([kept_left, kept_right]) {
        let rejected = calib.outliers.iter().filter(|o| o.camera == name).count();
        if n == 0 && rejected > 0 {
            out.push(format!(
                "every {name} corner ({rejected}) was rejected as an outlier: the {name} camera's pose is not determined"
            ));
        }
    }
    let total = kept_left + kept_right + calib.outliers.len();
    let share = calib.outliers.len() as f64 / total.max(1) as f64;
    if share > OUTLIER_SHARE_LIMIT {
        out.push(format!(
            "{} of {total} corners ({:.0}%) were rejected as outliers (over {:.0}%): the model does not explain the views",
            calib.outliers.len(),
            100.0 * share,
            100.0 * OUTLIER_SHARE_LIMIT
        ));
    }
    out
}

/// A baseline whose sigma exceeds this share of it is not determined by the views: 5%.
pub const UNDETERMINED_BASELINE_SHARE: f64 = 0.05;
/// A relative rotation whose sigma (any axis) exceeds this is not determined: 1 degree.
pub const UNDETERMINED_ROTATION_RAD: f64 = 1.0 * std::f64::consts::PI / 180.0;

/// Why `right_from_left` is not determined by the views, if it is not: no sigma (a singular
/// adjustment), a baseline sigma over [`UNDETERMINED_BASELINE_SHARE`] of it, or a rotation sigma
/// over [`UNDETERMINED_ROTATION_RAD`].
fn undetermined_pose(calib: &Calibration) -> Option<String> {
    let baseline = calib.rig.right_from_left.translation.vector.norm();
    let Some(sb) = calib.sigmas.get("baseline_m").copied() else {
        return Some(
            "right_from_left is not determined by the views (no sigma: the adjustment is singular)"
                .into(),
        );
    };
    let sr = ["rx", "ry", "rz"]
        .iter()
        .filter_map(|k| calib.sigmas.get(&format!("right_from_left.{k}")))
        .fold(0.0f64, |m, s| m.max(*s));
    if sb.is_nan() || sb > UNDETERMINED_BASELINE_SHARE * baseline {
        return Some(format!(
            "the baseline {:.2} mm is not determined by the views (sigma {:.2} mm, over {:.0}%)",
            1e3 * baseline,
            1e3 * sb,
            100.0 * UNDETERMINED_BASELINE_SHARE
        ));
    }
    if sr.is_nan() || sr > UNDETERMINED_ROTATION_RAD {
        return Some(format!(
            "the rotation between the cameras is not determined by the views (sigma {:.2} deg, over {:.0} deg)",
            sr.to_degrees(),
            UNDETERMINED_ROTATION_RAD.to_degrees()
        ));
    }
    None
}

/// What the user should know about the calibration, with what to do.
fn warnings(calib: &Calibration, config: &CalibConfig) -> Vec<String> {
    let mut warnings = Vec::new();
    let views = calib.used.len();
    if views < FEW_VIEWS {
        warnings.push(format!(
            "only {views} views: take 20 or more, the board tilted in turn towards each edge"
        ));
    }
    let coverage = calib.coverage;
    if !calib.stereo && coverage.0 < LOW_COVERAGE {
        warnings.push(format!(
            "corners cover {:.0}% of the image cells: move the board into the corners and edges of the image",
            100.0 * coverage.0,
        ));
    }
    if calib.stereo && (coverage.0 < LOW_COVERAGE || coverage.1 < LOW_COVERAGE) {
        warnings.push(format!(
            "corners cover {:.0}% / {:.0}% of the left / right image cells: move the board into the corners and edges of each image",
            100.0 * coverage.0,
            100.0 * coverage.1
        ));
    }
    let rms_px = calib.rms_px;
    if rms_px > HIGH_ERROR_PX {
        warnings.push(format!(
            "RMS reprojection error {rms_px:.2} px: check the target file's sizes, blur and the corner detections"
        ));
    }
    if config.fixed_intrinsics.is_none() {
        for (side, cam) in calib.cameras() {
            for (key, value) in [("fx", cam.fx), ("cx", cam.cx)] {
                let name = format!("{side}.{key}");
                if let Some(s) = calib.sigmas.get(&name) {
                    if *s > POORLY_OBSERVED_SHARE * value.abs() {
                        warnings.push(format!(
                            "{name} is poorly observed (sigma {s:.1} px, {:.1}%): add views with more tilt and at different distances{}",
                            100.0 * s / value.abs(),
                            if calib.stereo { ", or fix the intrinsics (--fix-intrinsics)" } else { "" }
                        ));
                    }
                }
            }
        }
    }
    if calib.epipolar_error_px > HIGH_ERROR_PX {
        warnings.push(format!(
            "corresponding corners are {:.2} px apart vertically after rectification: stereo matching will suffer; recalibrate with more views",
            calib.epipolar_error_px
        ));
    }
    warnings
}

/// RMS row difference of corners seen in both images, after rectification.
fn epipolar_rms(rig: &StereoRig, views: &[View<'_>]) -> f64 {
    let rect = rig.rectify();
    let (mut sum, mut n) = (0.0, 0usize);
    for View {
        left: l, right: r, ..
    } in views
    {
        for a in l {
            let Some(b) = r.iter().find(|b| b.id == a.id) else {
                continue;
            };
            let pa = rect.rectify_pixel(
                &rig.left,
                &rect.left_rotation,
                &nalgebra::Point2::from(a.px),
            );
            let pb = rect.rectify_pixel(
                &rig.right,
                &rect.right_rotation,
                &nalgebra::Point2::from(b.px),
            );
            if let (Some(pa), Some(pb)) = (pa, pb) {
                sum += (pa.y - pb.y).powi(2);
                n += 1;
            }
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

/// Cameras, board poses and corners for the calibration's tests.
#[cfg(test)]
pub(crate) mod testing {
    use super::*;
    use crate::camera::Distortion;
    use nalgebra::{Point3, Translation3, UnitQuaternion};

    /// The corners of a 9x6 grid of 3 cm squares that `cam` sees from `camera_from_board`.
    pub(crate) fn grid_corners(cam: &Camera, camera_from_board: &Isometry3<f64>) -> Vec<Corner> {
        let mut out = Vec::new();
        for i in 0..9 {
            for j in 0..6 {
                let b = [0.03 * i as f64, 0.03 * j as f64, 0.0];
                let p = camera_from_board * Point3::from(b);
                if let Some(q) = cam.project(&p.coords) {
                    out.push(Corner {
                        id: (i * 6 + j) as u32,
                        board_m: b,
                        px: [q.x, q.y],
                    });
                }
            }
        }
        out
    }

    /// A 640x480 radtan camera with these focal length, cx and k1.
    pub(crate) fn distorted(fx: f64, cx: f64, k1: f64) -> Camera {
        Camera {
            fx,
            fy: fx * 1.002,
            cx,
            cy: 242.0,
            distortion: Distortion::Radtan {
                k1,
                k2: 0.01,
                p1: 0.0005,
                p2: -0.0003,
                k3: 0.0,
            },
            width: 640,
            height: 480,
        }
    }

    /// The `k`-th of a set of board poses at 0.45-0.8 m, tilted up to 20 degrees each way.
    pub(crate) fn tilted_board(k: usize) -> Isometry3<f64> {
        let a = k as f64;
        Isometry3::from_parts(
            Translation3::new(
                -0.12 + 0.02 * (a % 3.0),
                -0.08 + 0.02 * (a % 4.0),
                0.45 + 0.03 * a,
            ),
            UnitQuaternion::from_euler_angles(
                0.35 * (a * 1.3).sin(),
                0.35 * (a * 0.7).cos(),
                0.2 * a.sin(),
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::testing::*;
    use super::*;
    use crate::camera::Distortion;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn recovers_a_known_rig_from_exact_corners_and_drops_a_blunder() {
        let (l, r) = (
            distorted(460.0, 322.0, -0.08),
            distorted(455.0, 318.0, -0.07),
        );
        let right_from_left = Isometry3::from_parts(
            Translation3::new(-0.12, 0.001, 0.002),
            UnitQuaternion::from_euler_angles(0.002, -0.004, 0.001),
        );
        let mut left_views = ViewCorners::new();
        let mut right_views = ViewCorners::new();
        for k in 0..12 {
            let pose = tilted_board(k);
            left_views.insert(format!("{k:03}"), grid_corners(&l, &pose));
            right_views.insert(
                format!("{k:03}"),
                grid_corners(&r, &(right_from_left * pose)),
            );
        }
        // One blunder of 6 px.
        if let Some(v) = left_views.get_mut("003") {
            v[5].px[0] += 6.0;
        }
        let calib = calibrate_stereo(
            &left_views,
            &right_views,
            (640, 480),
            &CalibConfig::default(),
        )
        .unwrap();
        assert_eq!(calib.outliers.len(), 1, "{:?}", calib.outliers);
        assert!(calib.rms_px < 0.01, "rms {}", calib.rms_px);
        assert!(
            (calib.rig.left.fx - 460.0).abs() < 0.05,
            "{:?}",
            calib.rig.left
        );
        assert!(
            (calib.rig.right.cx - 318.0).abs() < 0.05,
            "{:?}",
            calib.rig.right
        );
        let t = calib.rig.right_from_left.translation.vector;
        assert!(
            (t.norm() - right_from_left.translation.vector.norm()).abs() < 1e-4,
            "{t}"
        );
    }

    #[test]
    fn one_view_whose_right_corners_are_all_rejected_fails_saying_so() {
        let cam = Camera {
            fx: 460.0,
            fy: 460.0,
            cx: 320.0,
            cy: 240.0,
            distortion: Distortion::None,
            width: 640,
            height: 480,
        };
        let right_from_left = Isometry3::translation(-0.12, 0.0, 0.0);
        let pose = Isometry3::from_parts(
            Translation3::new(-0.1, -0.08, 0.6),
            UnitQuaternion::from_euler_angles(0.3, -0.2, 0.1),
        );
        let left = ViewCorners::from([("0".to_string(), grid_corners(&cam, &pose))]);
        let mut wrong = grid_corners(&cam, &(right_from_left * pose));
        // The right camera's corners matched to scrambled board points (not a symmetry of the
        // board): no pose explains them.
        let n = wrong.len();
        let points: Vec<[f64; 3]> = wrong.iter().map(|c| c.board_m).collect();
        for (k, c) in wrong.iter_mut().enumerate() {
            c.board_m = points[(k * 7 + 3) % n];
        }
        let right = ViewCorners::from([("0".to_string(), wrong)]);
        let config = CalibConfig {
            fixed_intrinsics: Some((cam, cam)),
            ..CalibConfig::default()
        };
        let calib = calibrate_stereo(&left, &right, (640, 480), &config).unwrap();
        let failed = failures(&calib, true).join("\n");
        assert!(
            failed.contains("right_from_left is not determined")
                || failed.contains("not determined by the views"),
            "{failed}"
        );
        assert!(failed.contains("outliers"), "{failed}");
    }

    #[test]
    fn one_camera_is_calibrated_alone_and_named_so() {
        let cam = distorted(460.0, 322.0, -0.08);
        let mut views = ViewCorners::new();
        for k in 0..10 {
            let pose = tilted_board(k);
            views.insert(format!("{k:03}"), grid_corners(&cam, &pose));
        }
        let calib = calibrate_camera(&views, (640, 480), &CalibConfig::default()).unwrap();
        assert!(!calib.stereo);
        assert!(
            (calib.rig.left.fx - 460.0).abs() < 0.01,
            "{:?}",
            calib.rig.left
        );
        assert_eq!(calib.cameras().len(), 1);
        assert!(calib.sigmas.contains_key("camera.fx"), "{:?}", calib.sigmas);
        assert!(!calib.sigmas.keys().any(|k| k.starts_with("right")));
        assert_eq!(calib.covariance.names.len(), 8);
        assert!(
            failures(&calib, false).is_empty(),
            "{:?}",
            failures(&calib, false)
        );
    }

    #[test]
    fn fronto_parallel_views_are_an_error_saying_what_cannot_be_observed() {
        let cam = Camera {
            fx: 460.0,
            fy: 460.0,
            cx: 320.0,
            cy: 240.0,
            distortion: Distortion::Radtan {
                k1: -0.05,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0,
            },
            width: 640,
            height: 480,
        };
        let right_from_left = Isometry3::translation(-0.12, 0.0, 0.0);
        let (mut left_views, mut right_views) = (ViewCorners::new(), ViewCorners::new());
        for k in 0..8 {
            let a = k as f64;
            let pose = Isometry3::translation(-0.1 + 0.02 * a, -0.05 + 0.01 * a, 0.5 + 0.05 * a);
            left_views.insert(format!("{k}"), grid_corners(&cam, &pose));
            right_views.insert(
                format!("{k}"),
                grid_corners(&cam, &(right_from_left * pose)),
            );
        }
        let result = calibrate_stereo(
            &left_views,
            &right_views,
            (640, 480),
            &CalibConfig::default(),
        );
        // Square-on views cannot separate the focal length from the distance: a clear error.
        let msg = result.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(msg.contains("focal length cannot be told"), "{msg}");
    }
}
