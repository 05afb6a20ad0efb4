//! Camera models and the stereo rig.
//!
//! A pinhole camera maps a point `P = (X, Y, Z)` in its frame (x right, y down, z forward) to
//! normalised coordinates `n = (X/Z, Y/Z)`, distorts them, and scales them to pixels:
//! `u = fx * xd + cx`, `v = fy * yd + cy` (the centre of the top-left pixel is (0, 0)).
//!
//! The distortions are radtan (OpenCV, Kalibr `radtan`) and equidistant (Kannala-Brandt,
//! Kalibr `equidistant`, OpenCV fisheye).
//!
//! The models are written once, generic over the scalar, in [`lens`]; the camera's Jacobians
//! are analytic (chain rule through the three steps). Unprojection inverts the distortion by
//! Gauss-Newton with the same Jacobian. The rig's Bouguet rectification is in `rectify.rs`, the
//! pose of a plane seen by a camera (planar PnP) in `plane_pose.rs`.

pub mod lens;
mod plane_pose;
mod rectify;

pub use lens::LensModel;
pub use plane_pose::plane_pose;
pub use rectify::Rectification;

use nalgebra::{Isometry3, Matrix2, Matrix2x3, Point2, Vector2, Vector3};

/// Lens distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distortion {
    /// No distortion.
    None,
    /// Radial-tangential: k1, k2, p1, p2, k3.
    Radtan {
        /// Radial r².
        k1: f64,
        /// Radial r⁴.
        k2: f64,
        /// Tangential.
        p1: f64,
        /// Tangential.
        p2: f64,
        /// Radial r⁶ (0 when not given).
        k3: f64,
    },
    /// Equidistant (Kannala-Brandt): k1..k4.
    Equidistant {
        /// θ³ term.
        k1: f64,
        /// θ⁵ term.
        k2: f64,
        /// θ⁷ term.
        k3: f64,
        /// θ⁹ term.
        k4: f64,
    },
    /// Double sphere (Kalibr `ds`): ξ, α ([`lens`]).
    DoubleSphere {
        /// The second sphere's offset ξ.
        xi: f64,
        /// α, from 0 to 1.
        alpha: f64,
    },
    /// Extended unified (Kalibr `eucm`): α, β ([`lens`]).
    Eucm {
        /// α, from 0 to 1.
        alpha: f64,
        /// β, positive.
        beta: f64,
    },
}

/// A camera: pinhole projection with distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Distortion.
    pub distortion: Distortion,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

/// Errors of camera settings.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CameraError {
    /// A focal length is not positive.
    #[error("focal lengths must be positive, got fx = {fx}, fy = {fy}")]
    BadFocal {
        /// fx.
        fx: f64,
        /// fy.
        fy: f64,
    },
    /// A number is not finite or the resolution is zero.
    #[error("camera parameters must be finite and the resolution non-zero")]
    NotFinite,
    /// A rotation is not a rotation.
    #[error("{name} is not a rotation (determinant {det:.4}, orthogonality error {error:.2e})")]
    NotRotation {
        /// Which transform.
        name: &'static str,
        /// Its determinant.
        det: f64,
        /// Largest entry of R Rᵀ - I.
        error: f64,
    },
}

/// The Jacobian of `(x, y) / den(x² + y²)` given `den` and its derivative by `x² + y²`.
fn radial_quotient_jacobian(x: f64, y: f64, den: f64, dden: f64) -> Matrix2<f64> {
    let (s, k) = (1.0 / den, -2.0 * dden / (den * den));
    Matrix2::new(s + k * x * x, k * x * y, k * x * y, s + k * y * y)
}

/// Largest Gauss-Newton steps taken to undistort a point.
const UNDISTORT_ITERATIONS: usize = 20;
/// Undistortion stops when the residual is below this (normalised units, about 1e-7 px).
const UNDISTORT_TOLERANCE: f64 = 1e-10;

impl Distortion {
    /// Distorts normalised coordinates ([`lens`]).
    pub fn apply(&self, n: Vector2<f64>) -> Vector2<f64> {
        let [xd, yd] = match *self {
            Distortion::None => return n,
            Distortion::Radtan { k1, k2, p1, p2, k3 } => {
                lens::radtan([k1, k2, p1, p2, k3], n.x, n.y)
            }
            Distortion::Equidistant { k1, k2, k3, k4 } => {
                lens::equidistant([k1, k2, k3, k4], n.x, n.y)
            }
            Distortion::DoubleSphere { xi, alpha } => lens::double_sphere([xi, alpha], n.x, n.y),
            Distortion::Eucm { alpha, beta } => lens::eucm([alpha, beta], n.x, n.y),
        };
        Vector2::new(xd, yd)
    }

    /// Distorts normalised coordinates; returns the distorted point and its 2x2 Jacobian
    /// (analytic, the chain rule through the model; `lens`'s tests check it against the
    /// models' automatic derivatives).
    pub fn distort(&self, n: Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        (self.apply(n), self.jacobian(n))
    }

    /// The Jacobian of [`Distortion::apply`] at `n`.
    fn jacobian(&self, n: Vector2<f64>) -> Matrix2<f64> {
        let (x, y) = (n.x, n.y);
        match *self {
            Distortion::None => Matrix2::identity(),
            Distortion::Radtan { k1, k2, p1, p2, k3 } => {
                let r2 = x * x + y * y;
                let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                let dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
                let (dr_dx, dr_dy) = (dradial_dr2 * 2.0 * x, dradial_dr2 * 2.0 * y);
                Matrix2::new(
                    radial + x * dr_dx + 2.0 * p1 * y + 6.0 * p2 * x,
                    x * dr_dy + 2.0 * p1 * x + 2.0 * p2 * y,
                    y * dr_dx + 2.0 * p1 * x + 2.0 * p2 * y,
                    radial + y * dr_dy + 6.0 * p1 * y + 2.0 * p2 * x,
                )
            }
            Distortion::Equidistant { k1, k2, k3, k4 } => {
                let r = (x * x + y * y).sqrt();
                if r < lens::EQUIDISTANT_CENTRE {
                    return Matrix2::identity();
                }
                let th = r.atan();
                let t2 = th * th;
                let poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)));
                let thd = th * poly;
                let dthd_dth =
                    1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
                let dth_dr = 1.0 / (1.0 + r * r);
                let s = thd / r;
                let ds_dr = (dthd_dth * dth_dr * r - thd) / (r * r);
                let (ux, uy) = (x / r, y / r);
                Matrix2::new(
                    s + x * ds_dr * ux,
                    x * ds_dr * uy,
                    y * ds_dr * ux,
                    s + y * ds_dr * uy,
                )
            }
            // Both are (x, y) / den(q), q = r²: J = I / den − 2 den'(q) (x, y)ᵀ(x, y) / den².
            Distortion::DoubleSphere { xi, alpha } => {
                let q = x * x + y * y;
                let d1 = (q + 1.0).sqrt();
                let zp = xi * d1 + 1.0;
                let d2 = (q + zp * zp).sqrt();
                let den = alpha * d2 + (1.0 - alpha) * zp;
                let dzp = xi / (2.0 * d1);
                let dd2 = (1.0 + 2.0 * zp * dzp) / (2.0 * d2);
                radial_quotient_jacobian(x, y, den, alpha * dd2 + (1.0 - alpha) * dzp)
            }
            Distortion::Eucm { alpha, beta } => {
                let d = (beta * (x * x + y * y) + 1.0).sqrt();
                let den = alpha * d + 1.0 - alpha;
                radial_quotient_jacobian(x, y, den, alpha * beta / (2.0 * d))
            }
        }
    }

    /// Undistorts by Gauss-Newton; `None` if it does not converge.
    pub fn undistort(&self, d: Vector2<f64>) -> Option<Vector2<f64>> {
        let mut n = d;
        for _ in 0..UNDISTORT_ITERATIONS {
            let (f, j) = self.distort(n);
            let r = f - d;
            if r.norm_squared() < UNDISTORT_TOLERANCE * UNDISTORT_TOLERANCE {
                return Some(n);
            }
            n -= j.try_inverse()? * r;
            if !n.iter().all(|v| v.is_finite()) {
                return None;
            }
        }
        let (f, _) = self.distort(n);
        ((f - d).norm() < 1e-8).then_some(n)
    }
}

impl Camera {
    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), CameraError> {
        if !(self.fx > 0.0 && self.fy > 0.0) {
            return Err(CameraError::BadFocal {
                fx: self.fx,
                fy: self.fy,
            });
        }
        let dist_ok = match self.distortion {
            Distortion::None => true,
            Distortion::Radtan { k1, k2, p1, p2, k3 } => {
                [k1, k2, p1, p2, k3].iter().all(|v| v.is_finite())
            }
            Distortion::Equidistant { k1, k2, k3, k4 } => {
                [k1, k2, k3, k4].iter().all(|v| v.is_finite())
            }
            Distortion::DoubleSphere { xi, alpha } => {
                xi.is_finite() && (0.0..=1.0).contains(&alpha)
            }
            Distortion::Eucm { alpha, beta } => (0.0..=1.0).contains(&alpha) && beta > 0.0,
        };
        if !(self.fx.is_finite()
            && self.fy.is_finite()
            && self.cx.is_finite()
            && self.cy.is_finite()
            && dist_ok)
            || self.width == 0
            || self.height == 0
        {
            return Err(CameraError::NotFinite);
        }
        Ok(())
    }

    /// Projects a point in the camera frame to pixels; `None` behind the camera.
    pub fn project(&self, p: &Vector3<f64>) -> Option<Point2<f64>> {
        if p.z <= 1e-9 {
            return None;
        }
        let iz = 1.0 / p.z;
        let d = self.distortion.apply(Vector2::new(p.x * iz, p.y * iz));
        Some(Point2::new(
            self.fx * d.x + self.cx,
            self.fy * d.y + self.cy,
        ))
    }

    /// Projects a point and returns d(pixel)/d(point), 2x3.
    pub fn project_with_jacobian(&self, p: &Vector3<f64>) -> Option<(Point2<f64>, Matrix2x3<f64>)> {
        if p.z <= 1e-9 {
            return None;
        }
        let iz = 1.0 / p.z;
        let n = Vector2::new(p.x * iz, p.y * iz);
        let (d, jd) = self.distortion.distort(n);
        let dn_dp = Matrix2x3::new(iz, 0.0, -p.x * iz * iz, 0.0, iz, -p.y * iz * iz);
        let scale = Matrix2::new(self.fx, 0.0, 0.0, self.fy);
        let px = Point2::new(self.fx * d.x + self.cx, self.fy * d.y + self.cy);
        Some((px, scale * jd * dn_dp))
    }

    /// Normalised undistorted coordinates `(x, y)` of a pixel (the ray is `(x, y, 1)`).
    pub fn unproject(&self, px: &Point2<f64>) -> Option<Vector2<f64>> {
        let d = Vector2::new((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy);
        self.distortion.undistort(d)
    }

    /// Unprojects and returns d(normalised)/d(pixel), 2x2.
    pub fn unproject_with_jacobian(
        &self,
        px: &Point2<f64>,
    ) -> Option<(Vector2<f64>, Matrix2<f64>)> {
        let n = self.unproject(px)?;
        let (_, jd) = self.distortion.distort(n);
        let j = jd.try_inverse()? * Matrix2::new(1.0 / self.fx, 0.0, 0.0, 1.0 / self.fy);
        Some((n, j))
    }
}

/// A stereo rig: two cameras, the transform between them and the mount on the robot.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoRig {
    /// Left camera (Kalibr `cam0`).
    pub left: Camera,
    /// Right camera (Kalibr `cam1`).
    pub right: Camera,
    /// `right_from_left` (Kalibr `cam1.T_cn_cnm1`).
    pub right_from_left: Isometry3<f64>,
    /// `robot_from_left`: where the left camera sits on the robot.
    pub robot_from_left: Isometry3<f64>,
    /// The covariance of `right_from_left` from its calibration, as `[rotation vector (rad),
    /// translation (m)]` (`right_from_left.rx .. tz` of the calibration report), when known
    /// (`stereotag.right_from_left_covariance` of a camchain `calibrate` wrote). Triangulated tags
    /// carry it into their covariance.
    pub right_from_left_covariance: Option<nalgebra::Matrix6<f64>>,
}

impl StereoRig {
    /// The left camera's pose in the right camera's frame.
    pub fn left_from_right(&self) -> Isometry3<f64> {
        self.right_from_left.inverse()
    }

    /// Checks both cameras.
    pub fn validate(&self) -> Result<(), CameraError> {
        self.left.validate()?;
        self.right.validate()
    }

    /// Baseline: distance between the optical centres, metres.
    pub fn baseline_m(&self) -> f64 {
        self.right_from_left.translation.vector.norm()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cameras() -> Vec<Camera> {
        let base = Camera {
            fx: 460.0,
            fy: 455.0,
            cx: 319.5,
            cy: 239.5,
            distortion: Distortion::None,
            width: 640,
            height: 480,
        };
        vec![
            base,
            Camera {
                distortion: Distortion::Radtan {
                    k1: -0.28,
                    k2: 0.074,
                    p1: 2e-4,
                    p2: 1.8e-5,
                    k3: 0.0,
                },
                ..base
            },
            Camera {
                distortion: Distortion::Radtan {
                    k1: -0.08,
                    k2: 0.01,
                    p1: 1e-3,
                    p2: -5e-4,
                    k3: 0.002,
                },
                ..base
            },
            Camera {
                distortion: Distortion::Equidistant {
                    k1: 0.0034,
                    k2: 0.0007,
                    k3: 0.0007,
                    k4: -0.0002,
                },
                ..base
            },
        ]
    }

    #[test]
    fn project_unproject_round_trip() {
        for cam in cameras() {
            for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.5, 0.35), (0.6, 0.45)] {
                let p = Vector3::new(x * 2.0, y * 2.0, 2.0);
                let px = cam.project(&p).unwrap();
                let n = cam.unproject(&px).unwrap();
                assert!((n - Vector2::new(x, y)).norm() < 1e-9, "{cam:?} {x} {y}");
            }
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let h = 1e-6;
        for cam in cameras() {
            let p = Vector3::new(0.4, -0.3, 1.7);
            let (_, j) = cam.project_with_jacobian(&p).unwrap();
            for k in 0..3 {
                let mut dp = Vector3::zeros();
                dp[k] = h;
                let a = cam.project(&(p + dp)).unwrap();
                let b = cam.project(&(p - dp)).unwrap();
                let num = (a - b) / (2.0 * h);
                assert!(
                    (num.x - j[(0, k)]).abs() < 1e-4 && (num.y - j[(1, k)]).abs() < 1e-4,
                    "{cam:?} col {k}"
                );
            }
            let px = Point2::new(500.0, 100.0);
            let (_, ju) = cam.unproject_with_jacobian(&px).unwrap();
            for k in 0..2 {
                let mut d = Vector2::zeros();
                d[k] = 1e-3;
                let num =
                    (cam.unproject(&(px + d)).unwrap() - cam.unproject(&(px - d)).unwrap()) / 2e-3;
                assert!(
                    (num - ju.column(k)).norm() < 1e-7,
                    "{cam:?} unproject col {k}"
                );
            }
        }
    }

    #[test]
    fn points_behind_do_not_project() {
        assert!(cameras()[0]
            .project(&Vector3::new(0.0, 0.0, -1.0))
            .is_none());
    }
}
