//! Stereo calibration from board corners: per-camera closed-form initialisation (Zhang), then one
//! Levenberg-Marquardt bundle adjustment of both cameras' intrinsics and radtan distortion, the
//! board poses and `right_from_left`, under a Huber kernel, with outliers removed and listed.
//!
//! Zhang's method: each view's board-to-image homography `H = K [r1 r2 t]` gives two linear
//! constraints on `B = K⁻ᵀ K⁻¹` (`h1ᵀ B h2 = 0`, `h1ᵀ B h1 = h2ᵀ B h2`); three views fix `B` and so
//! `K`. Board poses start from `K⁻¹ H` (left camera), `right_from_left` from the median of the
//! per-view relative poses. The adjustment then minimises the reprojection error of every corner
//! in both cameras: `π(K, D, right_from_left · left_from_board · P) − x`. Parameter sigmas come from
//! `(JᵀJ)⁻¹` scaled by the residual variance, with `J` taken by central differences at the solution.

pub mod chessboard;
mod target;

pub use target::{AprilGridTarget, CheckerboardTarget, Target, TargetDetector, TargetView};

use crate::camera::{lens, plane_pose, Camera, Distortion, LensModel, StereoRig};
use crate::geometry::homography::Homography;
use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3,
};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use tiny_solver::na as sna;

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
    #[error("too few views with both cameras seeing at least {min_corners} corners: got {got}, need {need}")]
    TooFewViews {
        /// Views found.
        got: usize,
        /// Views needed.
        need: usize,
        /// Corners per view needed.
        min_corners: usize,
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
    /// `left` or `right`.
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

/// The calibration.
#[derive(Debug, Clone)]
pub struct Calibration {
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
    /// Parameter sigmas by name (`left.fx`, ..., `right_from_left.tx`), one sigma.
    pub sigmas: BTreeMap<String, f64>,
    /// RMS row difference of the same corner in the two rectified images (Bouguet rectification
    /// of the result), pixels.
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

const COVERAGE_COLS: usize = 8;
const COVERAGE_ROWS: usize = 6;
/// Views the free calibration needs (Zhang needs three; fewer than 10 gets a warning).
const MIN_VIEWS_FREE: usize = 3;
/// Views the extrinsics-only calibration needs.
const MIN_VIEWS_FIXED: usize = 1;

/// Calibrates a stereo rig from corners of the same views in both cameras.
pub fn calibrate_stereo(
    left: &ViewCorners,
    right: &ViewCorners,
    resolution: (u32, u32),
    config: &CalibConfig,
) -> Result<Calibration, CalibError> {
    // Views where both cameras see enough corners; corners keyed by id.
    let mut names: Vec<&String> = left
        .keys()
        .filter(|k| {
            left[*k].len() >= config.min_corners
                && right.get(*k).is_some_and(|r| r.len() >= config.min_corners)
        })
        .collect();
    names.sort();
    let need = if config.fixed_intrinsics.is_some() {
        MIN_VIEWS_FIXED
    } else {
        MIN_VIEWS_FREE
    };
    if names.len() < need {
        return Err(CalibError::TooFewViews {
            got: names.len(),
            need,
            min_corners: config.min_corners,
        });
    }
    let (mut cam_l, mut cam_r) = match &config.fixed_intrinsics {
        Some((l, r)) => (*l, *r),
        None => (
            initial_camera(names.iter().map(|n| &left[*n]), resolution, config.model)?,
            initial_camera(names.iter().map(|n| &right[*n]), resolution, config.model)?,
        ),
    };
    let poses_l: Vec<Isometry3<f64>> = names
        .iter()
        .map(|n| board_pose(&cam_l, &left[*n]).ok_or(CalibError::Initialisation))
        .collect::<Result<_, _>>()?;
    let poses_r: Vec<Isometry3<f64>> = names
        .iter()
        .map(|n| board_pose(&cam_r, &right[*n]).ok_or(CalibError::Initialisation))
        .collect::<Result<_, _>>()?;
    let right_from_left = median_relative(&poses_l, &poses_r);

    let views: Vec<(&str, Vec<Corner>, Vec<Corner>)> = names
        .iter()
        .map(|n| (n.as_str(), left[*n].clone(), right[*n].clone()))
        .collect();
    let mut state = State {
        left: cam_l,
        right: cam_r,
        right_from_left,
        poses: poses_l,
    };
    solve(&mut state, &views, config)?;
    // Outliers: corners far off after the first solve are dropped, listed, and the solve repeated.
    let mut outliers = Vec::new();
    let views: Vec<(&str, Vec<Corner>, Vec<Corner>)> = views
        .into_iter()
        .enumerate()
        .map(|(i, (name, l, r))| {
            let mut keep =
                |side: &'static str, corners: Vec<Corner>, cam: &Camera, pose: Isometry3<f64>| {
                    corners
                        .into_iter()
                        .filter(|c| {
                            let e = reprojection_error(cam, &pose, c);
                            if e > config.outlier_px {
                                outliers.push(Outlier {
                                    view: name.to_string(),
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
            let l = keep("left", l, &state.left, pl);
            let r = keep("right", r, &state.right, pr);
            (name, l, r)
        })
        .collect();
    solve(&mut state, &views, config)?;
    cam_l = state.left;
    cam_r = state.right;

    let (mut sum_l, mut n_l, mut sum_r, mut n_r) = (0.0, 0usize, 0.0, 0usize);
    let mut per_view = Vec::new();
    let mut cells_l = vec![0u32; COVERAGE_COLS * COVERAGE_ROWS];
    let mut cells_r = vec![0u32; COVERAGE_COLS * COVERAGE_ROWS];
    for (i, (name, l, r)) in views.iter().enumerate() {
        let pl = state.poses[i];
        let pr = state.right_from_left * pl;
        let el: Vec<f64> = l
            .iter()
            .map(|c| reprojection_error(&cam_l, &pl, c).powi(2))
            .collect();
        let er: Vec<f64> = r
            .iter()
            .map(|c| reprojection_error(&cam_r, &pr, c).powi(2))
            .collect();
        sum_l += el.iter().sum::<f64>();
        n_l += el.len();
        sum_r += er.iter().sum::<f64>();
        n_r += er.len();
        per_view.push(ViewResidual {
            view: name.to_string(),
            rms_left_px: (el.iter().sum::<f64>() / el.len().max(1) as f64).sqrt(),
            rms_right_px: (er.iter().sum::<f64>() / er.len().max(1) as f64).sqrt(),
        });
        for (cells, corners) in [(&mut cells_l, l), (&mut cells_r, r)] {
            for c in corners {
                let col = ((c.px[0] / resolution.0 as f64) * COVERAGE_COLS as f64) as usize;
                let row = ((c.px[1] / resolution.1 as f64) * COVERAGE_ROWS as f64) as usize;
                if col < COVERAGE_COLS && row < COVERAGE_ROWS {
                    cells[row * COVERAGE_COLS + col] += 1;
                }
            }
        }
    }
    let rms_left_px = (sum_l / n_l.max(1) as f64).sqrt();
    let rms_right_px = (sum_r / n_r.max(1) as f64).sqrt();
    let rms_px = ((sum_l + sum_r) / (n_l + n_r).max(1) as f64).sqrt();
    let share = |c: &[u32]| c.iter().filter(|&&n| n > 0).count() as f64 / c.len() as f64;
    let coverage = (share(&cells_l), share(&cells_r));
    let sigmas = parameter_sigmas(&state, &views, config, rms_px);
    let mut warnings = Vec::new();
    if views.len() < 10 {
        warnings.push(format!(
            "only {} views: take 20 or more, the board tilted in turn towards each edge",
            views.len()
        ));
    }
    if coverage.0 < 0.6 || coverage.1 < 0.6 {
        warnings.push(format!(
            "corners cover {:.0}% / {:.0}% of the left / right image cells: move the board into the corners and edges of each image",
            100.0 * coverage.0,
            100.0 * coverage.1
        ));
    }
    if rms_px > 0.5 {
        warnings.push(format!(
            "RMS reprojection error {rms_px:.2} px: check the target file's sizes, blur and the corner detections"
        ));
    }
    if config.fixed_intrinsics.is_none() {
        for (name, value) in [
            ("left.fx", cam_l.fx),
            ("left.cx", cam_l.cx),
            ("right.fx", cam_r.fx),
            ("right.cx", cam_r.cx),
        ] {
            if let Some(s) = sigmas.get(name) {
                if *s > 0.01 * value.abs() {
                    warnings.push(format!(
                        "{name} is poorly observed (sigma {s:.1} px, {:.1}%): add views with more tilt and at different distances, or fix the intrinsics (--fix-intrinsics)",
                        100.0 * s / value.abs()
                    ));
                }
            }
        }
    }
    let rig = StereoRig {
        left: cam_l,
        right: cam_r,
        right_from_left: state.right_from_left,
        robot_from_left: Isometry3::identity(),
    };
    let epipolar_error_px = epipolar_rms(&rig, &views);
    if epipolar_error_px > 0.5 {
        warnings.push(format!(
            "corresponding corners are {epipolar_error_px:.2} px apart vertically after rectification: stereo matching will suffer; recalibrate with more views"
        ));
    }
    Ok(Calibration {
        rig,
        epipolar_error_px,
        rms_px,
        rms_left_px,
        rms_right_px,
        views: per_view,
        outliers,
        sigmas,
        coverage,
        coverage_counts: (cells_l, cells_r),
        warnings,
        used: views
            .iter()
            .zip(&state.poses)
            .map(|((name, l, r), pose)| UsedView {
                name: name.to_string(),
                left: l.clone(),
                right: r.clone(),
                left_from_board: *pose,
            })
            .collect(),
    })
}

/// RMS row difference of corners seen in both images, after rectification.
fn epipolar_rms(rig: &StereoRig, views: &[(&str, Vec<Corner>, Vec<Corner>)]) -> f64 {
    let rect = rig.rectify();
    let (mut sum, mut n) = (0.0, 0usize);
    for (_, l, r) in views {
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

/// Position on the board of AprilGrid corner `id` (tag id × 4 + k), in Kalibr's layout: tag
/// `id / 4` at column `tag % cols`, row `tag / cols`, pitch `size · (1 + spacing)`; corner `k` of a
/// tag is the C library's corner `k`: (x, y), (x + s, y), (x + s, y + s), (x, y + s).
pub fn aprilgrid_board_point(id: u32, cols: u32, size_m: f64, spacing: f64) -> [f64; 3] {
    let pitch = size_m * (1.0 + spacing);
    let (tag, k) = (id / 4, id % 4);
    let (x, y) = ((tag % cols) as f64 * pitch, (tag / cols) as f64 * pitch);
    let (dx, dy) = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)][k as usize];
    [x + dx * size_m, y + dy * size_m, 0.0]
}

/// Position on the board of chessboard corner `k` (index `r · cols + c`): `(c · col_spacing,
/// r · row_spacing, 0)`, as Kalibr's checkerboard target places it.
pub fn chessboard_board_point(
    k: u32,
    cols: u32,
    col_spacing_m: f64,
    row_spacing_m: f64,
) -> [f64; 3] {
    let (c, r) = (k % cols, k / cols);
    [c as f64 * col_spacing_m, r as f64 * row_spacing_m, 0.0]
}

/// Board corners of AprilGrid corner points `(tag id × 4 + k, pixel)` (layout:
/// [`aprilgrid_board_point`]). Tags outside the grid are dropped.
pub fn aprilgrid_corners(
    points: &[(u32, [f64; 2])],
    cols: u32,
    rows: u32,
    size_m: f64,
    spacing: f64,
) -> Vec<Corner> {
    points
        .iter()
        .filter(|(id, _)| id / 4 < cols * rows)
        .map(|&(id, px)| Corner {
            id,
            board_m: aprilgrid_board_point(id, cols, size_m, spacing),
            px,
        })
        .collect()
}

/// Board corners of a chessboard found by [`crate::calib::chessboard::detect_chessboard`] (index
/// `r · cols + c`; layout: [`chessboard_board_point`]).
pub fn chessboard_board_corners(
    px: &[[f64; 2]],
    cols: u32,
    col_spacing_m: f64,
    row_spacing_m: f64,
) -> Vec<Corner> {
    px.iter()
        .enumerate()
        .map(|(k, p)| Corner {
            id: k as u32,
            board_m: chessboard_board_point(k as u32, cols, col_spacing_m, row_spacing_m),
            px: *p,
        })
        .collect()
}

/// Reprojection error of one corner, pixels (infinite behind the camera).
fn reprojection_error(cam: &Camera, camera_from_board: &Isometry3<f64>, c: &Corner) -> f64 {
    let p = camera_from_board * Point3::from(c.board_m);
    cam.project(&p.coords)
        .map_or(f64::INFINITY, |q| (q.x - c.px[0]).hypot(q.y - c.px[1]))
}

/// Zhang's closed-form intrinsics (no distortion, no skew) from several views of a plane.
fn zhang<'a>(
    views: impl Iterator<Item = &'a Vec<Corner>>,
    resolution: (u32, u32),
) -> Result<Camera, CalibError> {
    let v = |h: &Matrix3<f64>, i: usize, j: usize| {
        let (hi, hj) = (h.column(i), h.column(j));
        [
            hi[0] * hj[0],
            hi[0] * hj[1] + hi[1] * hj[0],
            hi[1] * hj[1],
            hi[2] * hj[0] + hi[0] * hj[2],
            hi[2] * hj[1] + hi[1] * hj[2],
            hi[2] * hj[2],
        ]
    };
    let mut rows: Vec<[f64; 6]> = Vec::new();
    for corners in views {
        let pairs: Vec<_> = corners
            .iter()
            .map(|c| ([c.board_m[0], c.board_m[1]], c.px))
            .collect();
        let Some(Homography(h)) = Homography::from_pairs(&pairs) else {
            continue;
        };
        let (v12, v11, v22) = (v(&h, 0, 1), v(&h, 0, 0), v(&h, 1, 1));
        rows.push(v12);
        rows.push(std::array::from_fn(|k| v11[k] - v22[k]));
    }
    // Zero skew as a constraint (B12 = 0) keeps the system determined with few views.
    rows.push([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
    let a = DMatrix::from_fn(rows.len(), 6, |i, j| rows[i][j]);
    let e = (a.transpose() * &a).symmetric_eigen();
    let b = e.eigenvectors.column(e.eigenvalues.imin()).into_owned();
    let b = if b[0] < 0.0 { -b } else { b };
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let den = b11 * b22 - b12 * b12;
    if den.abs() < 1e-300 || b11 <= 0.0 {
        return Err(CalibError::Initialisation);
    }
    let v0 = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let fx2 = lambda / b11;
    let fy2 = lambda * b11 / den;
    if !(fx2 > 0.0 && fy2 > 0.0) {
        return Err(CalibError::Initialisation);
    }
    let (fx, fy) = (fx2.sqrt(), fy2.sqrt());
    let u0 = -b13 * fx * fx / lambda;
    Ok(Camera {
        fx,
        fy,
        cx: u0,
        cy: v0,
        distortion: Distortion::Radtan {
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        },
        width: resolution.0,
        height: resolution.1,
    })
}

/// A camera to start the adjustment from: Zhang's closed form for radtan lenses; for fisheye
/// lenses, whose raw corners no homography fits, the equidistant focal length (principal point
/// at the image centre, no distortion) that best reprojects every view's board pose, searched
/// from a sixth to twice the image width.
fn initial_camera<'a>(
    views: impl Iterator<Item = &'a Vec<Corner>> + Clone,
    resolution: (u32, u32),
    model: LensModel,
) -> Result<Camera, CalibError> {
    if model == LensModel::Radtan {
        return zhang(views, resolution);
    }
    let (w, h) = (resolution.0 as f64, resolution.1 as f64);
    let guess = |f: f64| Camera {
        fx: f,
        fy: f,
        cx: 0.5 * (w - 1.0),
        cy: 0.5 * (h - 1.0),
        distortion: Distortion::Equidistant {
            k1: 0.0,
            k2: 0.0,
            k3: 0.0,
            k4: 0.0,
        },
        width: resolution.0,
        height: resolution.1,
    };
    let cost = |cam: &Camera| -> f64 {
        let mut errors: Vec<f64> = views
            .clone()
            .flat_map(|corners| match board_pose(cam, corners) {
                Some(pose) => corners
                    .iter()
                    .map(|c| reprojection_error(cam, &pose, c))
                    .collect::<Vec<_>>(),
                None => vec![f64::INFINITY; corners.len()],
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        errors
            .get(errors.len() / 2)
            .copied()
            .unwrap_or(f64::INFINITY)
    };
    let steps = 60;
    let (lo, hi) = (w / 6.0, 2.0 * w);
    let best = (0..=steps)
        .map(|i| lo * (hi / lo).powf(i as f64 / steps as f64))
        .map(|f| (f, cost(&guess(f))))
        .filter(|(_, e)| e.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .ok_or(CalibError::Initialisation)?;
    Ok(guess(best.0))
}

/// Board pose in a camera from the homography of undistorted normalised points.
fn board_pose(cam: &Camera, corners: &[Corner]) -> Option<Isometry3<f64>> {
    plane_pose(
        cam,
        corners.iter().map(|c| ([c.board_m[0], c.board_m[1]], c.px)),
    )
}

/// `right_from_left` as the per-view relative pose with the median translation norm.
fn median_relative(left: &[Isometry3<f64>], right: &[Isometry3<f64>]) -> Isometry3<f64> {
    let mut rel: Vec<Isometry3<f64>> = left
        .iter()
        .zip(right)
        .map(|(l, r)| r * l.inverse())
        .collect();
    rel.sort_by(|a, b| {
        a.translation
            .vector
            .norm()
            .total_cmp(&b.translation.vector.norm())
    });
    rel.get(rel.len() / 2)
        .copied()
        .unwrap_or_else(Isometry3::identity)
}

/// What the adjustment changes.
struct State {
    left: Camera,
    right: Camera,
    right_from_left: Isometry3<f64>,
    poses: Vec<Isometry3<f64>>,
}

/// `[fx, fy, cx, cy, d0, d1, d2, d3]`: radtan k1, k2, p1, p2 or equidistant k1..k4.
fn intrinsics_vec(c: &Camera) -> Vec<f64> {
    let d = match c.distortion {
        Distortion::Radtan { k1, k2, p1, p2, .. } => [k1, k2, p1, p2],
        Distortion::Equidistant { k1, k2, k3, k4 } => [k1, k2, k3, k4],
        Distortion::None => [0.0; 4],
    };
    vec![c.fx, c.fy, c.cx, c.cy, d[0], d[1], d[2], d[3]]
}

/// The camera of an intrinsics vector, in the model of `like`.
fn camera_from_vec(v: &[f64], like: &Camera) -> Camera {
    let distortion = match like.distortion {
        Distortion::Equidistant { .. } => Distortion::Equidistant {
            k1: v[4],
            k2: v[5],
            k3: v[6],
            k4: v[7],
        },
        Distortion::Radtan { k3, .. } => Distortion::Radtan {
            k1: v[4],
            k2: v[5],
            p1: v[6],
            p2: v[7],
            k3,
        },
        Distortion::None => Distortion::Radtan {
            k1: v[4],
            k2: v[5],
            p1: v[6],
            p2: v[7],
            k3: 0.0,
        },
    };
    Camera {
        fx: v[0],
        fy: v[1],
        cx: v[2],
        cy: v[3],
        distortion,
        width: like.width,
        height: like.height,
    }
}

/// Names of the intrinsics vector's entries.
fn intrinsics_names(c: &Camera) -> [&'static str; 8] {
    match c.distortion {
        Distortion::Equidistant { .. } => ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
        _ => ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"],
    }
}

fn pose_vec(p: &Isometry3<f64>) -> Vec<f64> {
    let r = p.rotation.scaled_axis();
    let t = p.translation.vector;
    vec![r.x, r.y, r.z, t.x, t.y, t.z]
}

fn pose_from_vec(v: &[f64]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(v[3], v[4], v[5]),
        UnitQuaternion::from_scaled_axis(Vector3::new(v[0], v[1], v[2])),
    )
}

fn c<T: sna::RealField>(v: f64) -> T {
    T::from_f64(v).unwrap_or_else(T::zero)
}

/// Rotates `p` by the rotation vector `r` (Rodrigues), generic for automatic derivatives.
fn rotate<T: sna::RealField>(r: [T; 3], p: [T; 3]) -> [T; 3] {
    let theta2 =
        r[0].clone() * r[0].clone() + r[1].clone() * r[1].clone() + r[2].clone() * r[2].clone();
    let theta = (theta2.clone() + c::<T>(1e-24)).sqrt();
    let (s, co) = (theta.clone().sin(), theta.clone().cos());
    let k = [
        r[0].clone() / theta.clone(),
        r[1].clone() / theta.clone(),
        r[2].clone() / theta,
    ];
    let dot =
        k[0].clone() * p[0].clone() + k[1].clone() * p[1].clone() + k[2].clone() * p[2].clone();
    let cross = [
        k[1].clone() * p[2].clone() - k[2].clone() * p[1].clone(),
        k[2].clone() * p[0].clone() - k[0].clone() * p[2].clone(),
        k[0].clone() * p[1].clone() - k[1].clone() * p[0].clone(),
    ];
    std::array::from_fn(|i| {
        p[i].clone() * co.clone()
            + cross[i].clone() * s.clone()
            + k[i].clone() * dot.clone() * (T::one() - co.clone())
    })
}

fn transform<T: sna::RealField>(pose: &sna::DVector<T>, p: [T; 3]) -> [T; 3] {
    let r = rotate([pose[0].clone(), pose[1].clone(), pose[2].clone()], p);
    [
        r[0].clone() + pose[3].clone(),
        r[1].clone() + pose[4].clone(),
        r[2].clone() + pose[5].clone(),
    ]
}

/// One corner in the left image: params [intrinsics_left, board pose].
struct LeftCorner {
    board: [f64; 3],
    px: [f64; 2],
    model: LensModel,
}

/// One corner in the right image: params [intrinsics_right, board pose, right_from_left].
struct RightCorner {
    board: [f64; 3],
    px: [f64; 2],
    model: LensModel,
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for LeftCorner {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let p = transform(&params[1], self.board.map(c::<T>));
        let q = lens::project(params[0].as_slice(), self.model, p);
        sna::DVector::from_vec(vec![
            q[0].clone() - c::<T>(self.px[0]),
            q[1].clone() - c::<T>(self.px[1]),
        ])
    }
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for RightCorner {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let p = transform(&params[2], transform(&params[1], self.board.map(c::<T>)));
        let q = lens::project(params[0].as_slice(), self.model, p);
        sna::DVector::from_vec(vec![
            q[0].clone() - c::<T>(self.px[0]),
            q[1].clone() - c::<T>(self.px[1]),
        ])
    }
}

fn lens_model(cam: &Camera) -> LensModel {
    match cam.distortion {
        Distortion::Equidistant { .. } => LensModel::Equidistant,
        Distortion::Radtan { .. } | Distortion::None => LensModel::Radtan,
    }
}

const LEFT: &str = "intrinsics_left";
const RIGHT: &str = "intrinsics_right";
const EXTRINSICS: &str = "right_from_left";

fn view_name(i: usize) -> String {
    format!("board_{i}")
}

/// One bundle adjustment from the current state.
fn solve(
    state: &mut State,
    views: &[(&str, Vec<Corner>, Vec<Corner>)],
    config: &CalibConfig,
) -> Result<(), CalibError> {
    let mut problem = tiny_solver::Problem::new();
    let mut init: HashMap<String, sna::DVector<f64>> = HashMap::new();
    init.insert(
        LEFT.into(),
        sna::DVector::from_vec(intrinsics_vec(&state.left)),
    );
    init.insert(
        RIGHT.into(),
        sna::DVector::from_vec(intrinsics_vec(&state.right)),
    );
    init.insert(
        EXTRINSICS.into(),
        sna::DVector::from_vec(pose_vec(&state.right_from_left)),
    );
    for (i, (_, l, r)) in views.iter().enumerate() {
        let name = view_name(i);
        init.insert(
            name.clone(),
            sna::DVector::from_vec(pose_vec(&state.poses[i])),
        );
        for corner in l {
            problem.add_residual_block(
                2,
                &[LEFT, &name],
                Box::new(LeftCorner {
                    board: corner.board_m,
                    px: corner.px,
                    model: lens_model(&state.left),
                }),
                Some(Box::new(tiny_solver::loss_functions::HuberLoss::new(
                    config.huber_px.max(1e-3),
                ))),
            );
        }
        for corner in r {
            problem.add_residual_block(
                2,
                &[RIGHT, &name, EXTRINSICS],
                Box::new(RightCorner {
                    board: corner.board_m,
                    px: corner.px,
                    model: lens_model(&state.right),
                }),
                Some(Box::new(tiny_solver::loss_functions::HuberLoss::new(
                    config.huber_px.max(1e-3),
                ))),
            );
        }
    }
    if config.fixed_intrinsics.is_some() {
        for k in 0..8 {
            problem.fix_variable(LEFT, k);
            problem.fix_variable(RIGHT, k);
        }
    }
    let options = tiny_solver::OptimizerOptions {
        max_iteration: config.max_iterations,
        ..Default::default()
    };
    use tiny_solver::Optimizer;
    let values = tiny_solver::LevenbergMarquardtOptimizer::default()
        .optimize(&problem, &init, Some(options))
        .ok_or(CalibError::Solver)?;
    let get = |k: &str| values.get(k).map(|v| v.as_slice().to_vec());
    if config.fixed_intrinsics.is_none() {
        if let Some(v) = get(LEFT) {
            state.left = camera_from_vec(&v, &state.left);
        }
        if let Some(v) = get(RIGHT) {
            state.right = camera_from_vec(&v, &state.right);
        }
    }
    if let Some(v) = get(EXTRINSICS) {
        state.right_from_left = pose_from_vec(&v);
    }
    for i in 0..views.len() {
        if let Some(v) = get(&view_name(i)) {
            state.poses[i] = pose_from_vec(&v);
        }
    }
    Ok(())
}

/// Parameter sigmas: `σ² = rms² · diag((JᵀJ)⁻¹)` over intrinsics, extrinsics and board poses,
/// with `J` by central differences of the reprojections.
fn parameter_sigmas(
    state: &State,
    views: &[(&str, Vec<Corner>, Vec<Corner>)],
    config: &CalibConfig,
    rms_px: f64,
) -> BTreeMap<String, f64> {
    let free_intrinsics = config.fixed_intrinsics.is_none();
    let mut x: Vec<f64> = Vec::new();
    if free_intrinsics {
        x.extend(intrinsics_vec(&state.left));
        x.extend(intrinsics_vec(&state.right));
    }
    let base = x.len();
    x.extend(pose_vec(&state.right_from_left));
    for p in &state.poses {
        x.extend(pose_vec(p));
    }
    let residuals = |x: &[f64]| -> Vec<f64> {
        let (cl, cr) = if free_intrinsics {
            (
                camera_from_vec(&x[0..8], &state.left),
                camera_from_vec(&x[8..16], &state.right),
            )
        } else {
            (state.left, state.right)
        };
        let rl = pose_from_vec(&x[base..base + 6]);
        let mut out = Vec::new();
        for (i, (_, l, r)) in views.iter().enumerate() {
            let o = base + 6 + 6 * i;
            let pl = pose_from_vec(&x[o..o + 6]);
            let pr = rl * pl;
            for (cam, pose, corners) in [(&cl, pl, l), (&cr, pr, r)] {
                for corner in corners {
                    let p = pose * Point3::from(corner.board_m);
                    let q = cam
                        .project(&p.coords)
                        .unwrap_or(nalgebra::Point2::new(0.0, 0.0));
                    out.push(q.x - corner.px[0]);
                    out.push(q.y - corner.px[1]);
                }
            }
        }
        out
    };
    let r0 = residuals(&x);
    let mut jac = DMatrix::zeros(r0.len(), x.len());
    for j in 0..x.len() {
        let h = 1e-6 * x[j].abs().max(1e-3);
        let mut xp = x.clone();
        xp[j] += h;
        let rp = residuals(&xp);
        xp[j] -= 2.0 * h;
        let rm = residuals(&xp);
        for i in 0..r0.len() {
            jac[(i, j)] = (rp[i] - rm[i]) / (2.0 * h);
        }
    }
    let info = jac.transpose() * &jac;
    let mut out = BTreeMap::new();
    let Some(cov) = info.try_inverse() else {
        return out;
    };
    let cov: DMatrix<f64> = cov * rms_px * rms_px;
    if free_intrinsics {
        for (k, n) in intrinsics_names(&state.left).iter().enumerate() {
            out.insert(format!("left.{n}"), cov[(k, k)].max(0.0).sqrt());
        }
        for (k, n) in intrinsics_names(&state.right).iter().enumerate() {
            out.insert(format!("right.{n}"), cov[(8 + k, 8 + k)].max(0.0).sqrt());
        }
    }
    for (k, n) in ["rx", "ry", "rz", "tx", "ty", "tz"].iter().enumerate() {
        out.insert(
            format!("right_from_left.{n}"),
            cov[(base + k, base + k)].max(0.0).sqrt(),
        );
    }
    // The baseline's sigma by propagation through its norm.
    let t = state.right_from_left.translation.vector;
    let g = DVector::from_vec(vec![t.x, t.y, t.z]) / t.norm().max(1e-12);
    let ct = cov.view((base + 3, base + 3), (3, 3));
    out.insert(
        "baseline_m".into(),
        (g.transpose() * ct * &g)[(0, 0)].max(0.0).sqrt(),
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_corners(cam: &Camera, camera_from_board: &Isometry3<f64>) -> Vec<Corner> {
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

    #[test]
    fn recovers_a_known_rig_from_exact_corners_and_drops_a_blunder() {
        let cam = |fx: f64, cx: f64, k1: f64| Camera {
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
        };
        let (l, r) = (cam(460.0, 322.0, -0.08), cam(455.0, 318.0, -0.07));
        let right_from_left = Isometry3::from_parts(
            Translation3::new(-0.12, 0.001, 0.002),
            UnitQuaternion::from_euler_angles(0.002, -0.004, 0.001),
        );
        let mut left_views = ViewCorners::new();
        let mut right_views = ViewCorners::new();
        for k in 0..12 {
            let a = k as f64;
            let pose = Isometry3::from_parts(
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
            );
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
