//! The lens models, once, generic over the scalar: [`Camera`](super::Camera) evaluates them
//! in `f64` (with their analytic Jacobians beside them, checked here against these functions'
//! automatic derivatives), and the calibration's bundle adjustment in the solver's dual numbers,
//! so that a fix to a model reaches both.
//!
//! * **radtan** (OpenCV, Kalibr `radtan`): `r2 = x² + y²`,
//!   `xd = x (1 + k1 r2 + k2 r2² + k3 r2³) + 2 p1 x y + p2 (r2 + 2 x²)`, and symmetrically for
//!   `yd`;
//! * **equidistant** (Kannala-Brandt, Kalibr `equidistant`, OpenCV fisheye): `θ = atan(r)`,
//!   `θd = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`, `(xd, yd) = (θd / r) (x, y)`;
//! * **double sphere** (Usenko et al. 2018, Kalibr `ds`): of the normalised point `(x, y, 1)`,
//!   `d1 = √(r² + 1)`, `z' = ξ d1 + 1`, `d2 = √(r² + z'²)`, `(xd, yd) = (x, y) / (α d2 + (1 −
//!   α) z')`;
//! * **extended unified** (Khomutenko et al. 2016, Kalibr `eucm`): `d = √(β r² + 1)`,
//!   `(xd, yd) = (x, y) / (α d + 1 − α)`.
//!
//! The last two are written here on the normalised point, so on points in front of the camera:
//! a lens seeing beyond 180 degrees is cut at 180.

use tiny_solver::na::RealField;

/// The lens models a calibration fits (Kalibr's `pinhole-radtan` and `pinhole-equi`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LensModel {
    /// Radial-tangential k1, k2, p1, p2 (k3 held at zero).
    #[default]
    Radtan,
    /// Equidistant (Kannala-Brandt) k1..k4, for fisheye lenses.
    Equidistant,
    /// Double sphere ξ, α (Kalibr `ds-none`), for fisheye lenses.
    DoubleSphere,
    /// Extended unified α, β (Kalibr `eucm-none`), for fisheye lenses.
    Eucm,
}

impl LensModel {
    /// How many lens parameters follow `fx, fy, cx, cy`.
    pub fn lens_parameters(&self) -> usize {
        match self {
            LensModel::Radtan | LensModel::Equidistant => 4,
            LensModel::DoubleSphere | LensModel::Eucm => 2,
        }
    }
}

/// Below this radius (normalised) the equidistant model is the identity (its `θd / r` is 1 in
/// the limit).
pub const EQUIDISTANT_CENTRE: f64 = 1e-12;

fn constant<T: RealField>(v: f64) -> T {
    T::from_f64(v).unwrap_or_else(T::zero)
}

/// Radtan distortion of normalised `(x, y)` with `[k1, k2, p1, p2, k3]`.
pub fn radtan<T: RealField>([k1, k2, p1, p2, k3]: [T; 5], x: T, y: T) -> [T; 2] {
    let r2 = x.clone() * x.clone() + y.clone() * y.clone();
    let radial = T::one() + r2.clone() * (k1 + r2.clone() * (k2 + r2.clone() * k3));
    let two = constant::<T>(2.0);
    let xd = x.clone() * radial.clone()
        + two.clone() * p1.clone() * x.clone() * y.clone()
        + p2.clone() * (r2.clone() + two.clone() * x.clone() * x.clone());
    let yd =
        y.clone() * radial + p1 * (r2 + two.clone() * y.clone() * y.clone()) + two * p2 * x * y;
    [xd, yd]
}

/// Equidistant distortion of normalised `(x, y)` with `[k1, k2, k3, k4]`.
pub fn equidistant<T: RealField>([k1, k2, k3, k4]: [T; 4], x: T, y: T) -> [T; 2] {
    let r = (x.clone() * x.clone() + y.clone() * y.clone()).sqrt();
    if r < constant::<T>(EQUIDISTANT_CENTRE) {
        return [x, y];
    }
    let th = r.clone().atan();
    let t2 = th.clone() * th.clone();
    let poly = T::one() + t2.clone() * (k1 + t2.clone() * (k2 + t2.clone() * (k3 + t2 * k4)));
    let s = th * poly / r;
    [s.clone() * x, s * y]
}

/// Double-sphere distortion of normalised `(x, y)` with `[ξ, α]`.
pub fn double_sphere<T: RealField>([xi, alpha]: [T; 2], x: T, y: T) -> [T; 2] {
    let r2 = x.clone() * x.clone() + y.clone() * y.clone();
    let d1 = (r2.clone() + T::one()).sqrt();
    let zp = xi * d1 + T::one();
    let d2 = (r2 + zp.clone() * zp.clone()).sqrt();
    let den = alpha.clone() * d2 + (T::one() - alpha) * zp;
    [x / den.clone(), y / den]
}

/// Extended-unified distortion of normalised `(x, y)` with `[α, β]`.
pub fn eucm<T: RealField>([alpha, beta]: [T; 2], x: T, y: T) -> [T; 2] {
    let r2 = x.clone() * x.clone() + y.clone() * y.clone();
    let d = (beta * r2 + T::one()).sqrt();
    let den = alpha.clone() * d + (T::one() - alpha);
    [x / den.clone(), y / den]
}

/// Pixel of a point `p` in the camera frame through intrinsics `k` = `[fx, fy, cx, cy, d...]`
/// (`d`: radtan `k1, k2, p1, p2` with k3 zero, equidistant `k1..k4`, double sphere `ξ, α`,
/// extended unified `α, β`): `u = fx xd + cx`,
/// `v = fy yd + cy`.
pub fn project<T: RealField>(k: &[T], model: LensModel, p: [T; 3]) -> [T; 2] {
    let [px, py, pz] = p;
    let (x, y) = (px / pz.clone(), py / pz);
    let d = |i: usize| k[4 + i].clone();
    let [xd, yd] = match model {
        LensModel::Radtan => radtan([d(0), d(1), d(2), d(3), T::zero()], x, y),
        LensModel::Equidistant => equidistant([d(0), d(1), d(2), d(3)], x, y),
        LensModel::DoubleSphere => double_sphere([d(0), d(1)], x, y),
        LensModel::Eucm => eucm([d(0), d(1)], x, y),
    };
    [
        k[0].clone() * xd + k[2].clone(),
        k[1].clone() * yd + k[3].clone(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Distortion;
    use nalgebra::Vector2;
    use num_dual::Dual64;

    /// The camera's analytic Jacobian of each model is the automatic derivative of the model
    /// here, all over the image (so a change to a model without its Jacobian fails).
    #[test]
    fn the_cameras_jacobians_are_the_models_derivatives() {
        let models = [
            Distortion::Radtan {
                k1: -0.28,
                k2: 0.074,
                p1: 2e-4,
                p2: 1.8e-5,
                k3: 0.01,
            },
            Distortion::Equidistant {
                k1: -0.01,
                k2: 0.05,
                k3: -0.08,
                k4: 0.04,
            },
            Distortion::DoubleSphere {
                xi: -0.18,
                alpha: 0.59,
            },
            Distortion::Eucm {
                alpha: 0.6,
                beta: 1.1,
            },
        ];
        for d in models {
            for (x, y) in [(0.3, -0.2), (-0.7, 0.5), (1.1, 0.9), (1e-7, 0.0)] {
                let (value, jacobian) = d.distort(Vector2::new(x, y));
                // One direction at a time: d/dx with x seeded, then d/dy.
                for (col, (dx, dy)) in [
                    (Dual64::from_re(x).derivative(), Dual64::from_re(y)),
                    (Dual64::from_re(x), Dual64::from_re(y).derivative()),
                ]
                .into_iter()
                .enumerate()
                {
                    let c = Dual64::from_re;
                    let [u, v] = match d {
                        Distortion::Radtan { k1, k2, p1, p2, k3 } => {
                            radtan([c(k1), c(k2), c(p1), c(p2), c(k3)], dx, dy)
                        }
                        Distortion::Equidistant { k1, k2, k3, k4 } => {
                            equidistant([c(k1), c(k2), c(k3), c(k4)], dx, dy)
                        }
                        Distortion::DoubleSphere { xi, alpha } => {
                            double_sphere([c(xi), c(alpha)], dx, dy)
                        }
                        Distortion::Eucm { alpha, beta } => eucm([c(alpha), c(beta)], dx, dy),
                        Distortion::None => unreachable!("not in the list"),
                    };
                    // The same function in dual numbers: equal but for rounding (num-dual
                    // divides by multiplying with the reciprocal).
                    for (a, b) in [(value.x, u.re), (value.y, v.re)] {
                        assert!(
                            (a - b).abs() <= 1e-15 * (1.0 + a.abs()),
                            "{d:?} at ({x}, {y})"
                        );
                    }
                    for (row, auto) in [u.eps, v.eps].into_iter().enumerate() {
                        let analytic = jacobian[(row, col)];
                        assert!(
                            (auto - analytic).abs() <= 1e-9 * (1.0 + analytic.abs()),
                            "{d:?} at ({x}, {y}): d{row}/d{col} analytic {analytic}, automatic {auto}"
                        );
                    }
                }
            }
        }
    }
}
