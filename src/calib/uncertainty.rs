//! How far the calibration's own uncertainty moves a projection, over the image: at each point of
//! a grid of pixels, the ray the calibrated camera sees there is projected again with the
//! intrinsics' covariance propagated to the pixel, `Σq = J Σ Jᵀ` (`J` the projection's derivative
//! by the eight intrinsics, by central differences), and the standard deviation in the worst
//! direction, `sqrt(λmax(Σq))`, is reported, as mrcal's `mrcal-show-projection-uncertainty` does.
//! mrcal also propagates the uncertainty of the reference frame the board poses define; this does
//! not (so it is what the intrinsics alone allow), and it needs free intrinsics.

use super::bundle::{camera_from_vec, intrinsics_vec};
use super::Calibration;
use nalgebra::{DMatrix, Matrix2, Point2, Vector3};
use serde::Serialize;

/// Grid points across the image.
pub const UNCERTAINTY_COLS: usize = 16;
/// Grid points down the image.
pub const UNCERTAINTY_ROWS: usize = 12;

/// The projection uncertainty of one camera over a grid of its image.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProjectionUncertainty {
    /// The camera's name (`left`, `right` or `camera`).
    pub camera: String,
    /// Grid points across.
    pub cols: usize,
    /// Grid points down.
    pub rows: usize,
    /// Each grid point's pixel (row-major; the grid's outer points lie on the image's edges).
    pub px: Vec<[f64; 2]>,
    /// The worst-direction standard deviation of the projection at each point, pixels (NaN
    /// where the camera has no ray, beyond a fisheye's rim).
    pub sigma_px: Vec<f64>,
    /// At the image centre, pixels.
    pub centre_px: f64,
    /// The median over the grid, pixels.
    pub median_px: f64,
    /// The largest over the grid, pixels.
    pub max_px: f64,
}

/// The projection uncertainty of each calibrated camera whose intrinsics have a covariance
/// (none with fixed intrinsics).
pub fn projection_uncertainty(calib: &Calibration) -> Vec<ProjectionUncertainty> {
    calib
        .cameras()
        .into_iter()
        .filter_map(|(name, cam)| camera_uncertainty(calib, name, cam))
        .collect()
}

fn camera_uncertainty(
    calib: &Calibration,
    name: &str,
    cam: &crate::camera::Camera,
) -> Option<ProjectionUncertainty> {
    let names = &calib.covariance.names;
    let first = names.iter().position(|n| n == &format!("{name}.fx"))?;
    let intrinsics = intrinsics_vec(cam);
    let count = intrinsics.len();
    if first + count > names.len() {
        return None;
    }
    let sigma = DMatrix::from_fn(count, count, |i, j| {
        calib.covariance.matrix[(first + i, first + j)]
    });
    // The pixel of `ray` through the intrinsics `k` (radtan's fixed k3 kept).
    let project = |k: &[f64], ray: &Vector3<f64>| -> Option<Point2<f64>> {
        camera_from_vec(k, cam).project(ray)
    };
    let (w, h) = (cam.width as f64 - 1.0, cam.height as f64 - 1.0);
    let mut px = Vec::new();
    let mut out = Vec::new();
    let at = |q: Point2<f64>| -> f64 {
        let Some(n) = cam.unproject(&q) else {
            return f64::NAN;
        };
        let ray = Vector3::new(n.x, n.y, 1.0);
        let mut jac = DMatrix::zeros(2, count);
        for j in 0..count {
            let step = 1e-6 * intrinsics[j].abs().max(1e-3);
            let mut k = intrinsics.clone();
            k[j] += step;
            let plus = project(&k, &ray);
            k[j] -= 2.0 * step;
            let (Some(plus), Some(minus)) = (plus, project(&k, &ray)) else {
                return f64::NAN;
            };
            jac[(0, j)] = (plus.x - minus.x) / (2.0 * step);
            jac[(1, j)] = (plus.y - minus.y) / (2.0 * step);
        }
        let sq = &jac * &sigma * jac.transpose();
        Matrix2::from_fn(|i, j| sq[(i, j)])
            .symmetric_eigenvalues()
            .max()
            .max(0.0)
            .sqrt()
    };
    for r in 0..UNCERTAINTY_ROWS {
        for c in 0..UNCERTAINTY_COLS {
            let q = Point2::new(
                w * c as f64 / (UNCERTAINTY_COLS - 1) as f64,
                h * r as f64 / (UNCERTAINTY_ROWS - 1) as f64,
            );
            px.push([q.x, q.y]);
            out.push(at(q));
        }
    }
    let centre_px = at(Point2::new(0.5 * w, 0.5 * h));
    let mut finite: Vec<f64> = out.iter().copied().filter(|v| v.is_finite()).collect();
    finite.sort_by(f64::total_cmp);
    Some(ProjectionUncertainty {
        camera: name.to_string(),
        cols: UNCERTAINTY_COLS,
        rows: UNCERTAINTY_ROWS,
        px,
        centre_px,
        median_px: finite.get(finite.len() / 2).copied().unwrap_or(f64::NAN),
        max_px: finite.last().copied().unwrap_or(f64::NAN),
        sigma_px: out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::testing::{distorted, grid_corners, tilted_board};
    use crate::calib::{calibrate_camera, CalibConfig, ViewCorners};
    use nalgebra::Isometry3;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// The reported uncertainty is what repeated calibrations show: 40 calibrations of one
    /// camera from 12 views of a 9x6 board with 0.2 px corner noise; at the image's centre and
    /// a quarter of the way to its corner the spread of where the true ray lands (worst direction) is within a factor 1.6 of
    /// the predicted sigma (a sample of 40 gives its sigma to about 11%).
    #[test]
    fn predicted_projection_spread_matches_repeated_calibrations() {
        let truth = distorted(460.0, 322.0, -0.08);
        let poses: Vec<Isometry3<f64>> = (0..12).map(tilted_board).collect();
        let noise = Normal::new(0.0, 0.2).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // The centre, and a grid point a quarter of the way in from the top-left corner (the
        // views' corners reach it; the image's own corners, which no board corner reaches, are
        // extrapolation, with sigmas of tens of pixels and more).
        let (col, row) = (4, 3);
        let off_centre = row * UNCERTAINTY_COLS + col;
        let pixels = [
            Point2::new(319.5, 239.5),
            Point2::new(
                639.0 * col as f64 / (UNCERTAINTY_COLS - 1) as f64,
                479.0 * row as f64 / (UNCERTAINTY_ROWS - 1) as f64,
            ),
        ];
        let mut landed: Vec<Vec<[f64; 2]>> = vec![Vec::new(); pixels.len()];
        let mut predicted = vec![0.0; pixels.len()];
        let trials = 40;
        for _ in 0..trials {
            let mut views = ViewCorners::new();
            for (k, pose) in poses.iter().enumerate() {
                let mut corners = grid_corners(&truth, pose);
                for c in &mut corners {
                    c.px[0] += noise.sample(&mut rng);
                    c.px[1] += noise.sample(&mut rng);
                }
                views.insert(format!("{k:02}"), corners);
            }
            let calib = calibrate_camera(&views, (640, 480), &CalibConfig::default()).unwrap();
            let u = &projection_uncertainty(&calib)[0];
            let est = calib.rig.left;
            for (k, q) in pixels.iter().enumerate() {
                let n = truth.unproject(q).unwrap();
                let p = est.project(&Vector3::new(n.x, n.y, 1.0)).unwrap();
                landed[k].push([p.x, p.y]);
                let at = if k == 0 {
                    u.centre_px
                } else {
                    u.sigma_px[off_centre]
                };
                predicted[k] += at / trials as f64;
            }
        }
        for (k, points) in landed.iter().enumerate() {
            let n = points.len() as f64;
            let mean = points
                .iter()
                .fold([0.0, 0.0], |m, p| [m[0] + p[0] / n, m[1] + p[1] / n]);
            let mut cov = Matrix2::zeros();
            for p in points {
                let d = nalgebra::Vector2::new(p[0] - mean[0], p[1] - mean[1]);
                cov += d * d.transpose() / (n - 1.0);
            }
            let spread = cov.symmetric_eigenvalues().max().sqrt();
            let ratio = spread / predicted[k];
            eprintln!(
                "pixel {:?}: spread {spread:.4} px, predicted {:.4} px, ratio {ratio:.2}",
                pixels[k], predicted[k]
            );
            assert!((1.0 / 1.6..1.6).contains(&ratio), "ratio {ratio}");
        }
    }
}
