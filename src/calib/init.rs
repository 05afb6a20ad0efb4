//! Where the bundle adjustment starts: each camera by Zhang's closed form (or, for a fisheye, the
//! equidistant focal length that best reprojects the views), each board's pose by planar PnP,
//! and `right_from_left` as the median of the views' relative poses.
//!
//! Zhang's method: each view's board-to-image homography `H = K [r1 r2 t]` gives two linear
//! constraints on `B = K⁻ᵀ K⁻¹` (`h1ᵀ B h2 = 0`, `h1ᵀ B h1 = h2ᵀ B h2`); three views fix `B` and so
//! `K`.

use super::{CalibError, Corner};
use crate::camera::{plane_pose, Camera, Distortion, LensModel};
use crate::geometry::homography::Homography;
use nalgebra::{DMatrix, Isometry3, Matrix3, Point3};

/// Reprojection error of one corner, pixels (infinite behind the camera).
pub(super) fn reprojection_error(
    cam: &Camera,
    camera_from_board: &Isometry3<f64>,
    c: &Corner,
) -> f64 {
    let p = camera_from_board * Point3::from(c.board_m);
    cam.project(&p.coords)
        .map_or(f64::INFINITY, |q| (q.x - c.px[0]).hypot(q.y - c.px[1]))
}

/// Zhang's closed-form intrinsics (no distortion, no skew) from several views of a plane.
pub(super) fn zhang<'a>(
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
/// lenses, whose raw corners no homography fits, the focal length (principal point at the image
/// centre; equidistant without distortion, double sphere ξ 0 and α 0.5, extended unified α 0.5
/// and β 1) that best reprojects every view's board pose, searched from a sixth to twice the
/// image width.
pub(super) fn initial_camera<'a>(
    views: impl Iterator<Item = &'a Vec<Corner>> + Clone,
    resolution: (u32, u32),
    model: LensModel,
) -> Result<Camera, CalibError> {
    if model == LensModel::Radtan {
        return zhang(views, resolution);
    }
    let (w, h) = (resolution.0 as f64, resolution.1 as f64);
    let lens = match model {
        // A middle of each fisheye model's range: no sphere offset, half-way between the
        // pinhole (α = 0) and the sphere; for the extended unified, a sphere (β = 1).
        LensModel::DoubleSphere => Distortion::DoubleSphere {
            xi: 0.0,
            alpha: 0.5,
        },
        LensModel::Eucm => Distortion::Eucm {
            alpha: 0.5,
            beta: 1.0,
        },
        _ => Distortion::Equidistant {
            k1: 0.0,
            k2: 0.0,
            k3: 0.0,
            k4: 0.0,
        },
    };
    let guess = |f: f64| Camera {
        fx: f,
        fy: f,
        cx: 0.5 * (w - 1.0),
        cy: 0.5 * (h - 1.0),
        distortion: lens,
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
pub(super) fn board_pose(cam: &Camera, corners: &[Corner]) -> Option<Isometry3<f64>> {
    plane_pose(
        cam,
        corners.iter().map(|c| ([c.board_m[0], c.board_m[1]], c.px)),
    )
}

/// `right_from_left` as the per-view relative pose with the median translation norm.
pub(super) fn median_relative(left: &[Isometry3<f64>], right: &[Isometry3<f64>]) -> Isometry3<f64> {
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
