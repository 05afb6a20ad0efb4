//! The bundle adjustment: both cameras' intrinsics and distortion, every board pose and
//! `right_from_left`, adjusted by Levenberg-Marquardt (tiny-solver, automatic derivatives)
//! under a Huber kernel to minimise every corner's reprojection error in both cameras,
//! `π(K, D, right_from_left · left_from_board · P) − x` (the lens models of
//! [`crate::camera::lens`]); and the parameters' sigmas from `(JᵀJ)⁻¹` scaled by the residual
//! variance, `J` by central differences at the solution.

use super::{CalibConfig, CalibError, View};
use crate::camera::{lens, Camera, Distortion, LensModel};
use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use std::collections::{BTreeMap, HashMap};
use tiny_solver::na as sna;

/// What the adjustment changes. With one camera (`stereo` false) only `left` and the board
/// poses are adjusted; `right` and `right_from_left` stay as they are.
pub(super) struct State {
    pub(super) left: Camera,
    pub(super) right: Camera,
    pub(super) right_from_left: Isometry3<f64>,
    pub(super) poses: Vec<Isometry3<f64>>,
    pub(super) stereo: bool,
}

/// `[fx, fy, cx, cy, d...]`: radtan k1, k2, p1, p2, equidistant k1..k4, double sphere ξ, α,
/// extended unified α, β (the length [`intrinsics_names`] gives).
pub(super) fn intrinsics_vec(c: &Camera) -> Vec<f64> {
    let mut v = vec![c.fx, c.fy, c.cx, c.cy];
    match c.distortion {
        Distortion::Radtan { k1, k2, p1, p2, .. } => v.extend([k1, k2, p1, p2]),
        Distortion::Equidistant { k1, k2, k3, k4 } => v.extend([k1, k2, k3, k4]),
        Distortion::None => v.extend([0.0; 4]),
        Distortion::DoubleSphere { xi, alpha } => v.extend([xi, alpha]),
        Distortion::Eucm { alpha, beta } => v.extend([alpha, beta]),
    }
    v
}

/// The camera of an intrinsics vector, in the model of `like` (radtan for none).
pub(super) fn camera_from_vec(v: &[f64], like: &Camera) -> Camera {
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
        Distortion::DoubleSphere { .. } => Distortion::DoubleSphere {
            xi: v[4],
            alpha: v[5],
        },
        Distortion::Eucm { .. } => Distortion::Eucm {
            alpha: v[4],
            beta: v[5],
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
pub(super) fn intrinsics_names(c: &Camera) -> &'static [&'static str] {
    match c.distortion {
        Distortion::Equidistant { .. } => &["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
        Distortion::DoubleSphere { .. } => &["fx", "fy", "cx", "cy", "xi", "alpha"],
        Distortion::Eucm { .. } => &["fx", "fy", "cx", "cy", "alpha", "beta"],
        Distortion::Radtan { .. } | Distortion::None => {
            &["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"]
        }
    }
}

pub(super) fn pose_vec(p: &Isometry3<f64>) -> Vec<f64> {
    let r = p.rotation.scaled_axis();
    let t = p.translation.vector;
    vec![r.x, r.y, r.z, t.x, t.y, t.z]
}

pub(super) fn pose_from_vec(v: &[f64]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(v[3], v[4], v[5]),
        UnitQuaternion::from_scaled_axis(Vector3::new(v[0], v[1], v[2])),
    )
}

pub(super) fn c<T: sna::RealField>(v: f64) -> T {
    T::from_f64(v).unwrap_or_else(T::zero)
}

/// Rotates `p` by the rotation vector `r` (Rodrigues), generic for automatic derivatives.
pub(super) fn rotate<T: sna::RealField>(r: [T; 3], p: [T; 3]) -> [T; 3] {
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

pub(super) fn transform<T: sna::RealField>(pose: &sna::DVector<T>, p: [T; 3]) -> [T; 3] {
    let r = rotate([pose[0].clone(), pose[1].clone(), pose[2].clone()], p);
    [
        r[0].clone() + pose[3].clone(),
        r[1].clone() + pose[4].clone(),
        r[2].clone() + pose[5].clone(),
    ]
}

/// One corner in the left image: params [intrinsics_left, board pose].
pub(super) struct LeftCorner {
    board: [f64; 3],
    px: [f64; 2],
    model: LensModel,
}

/// One corner in the right image: params [intrinsics_right, board pose, right_from_left].
pub(super) struct RightCorner {
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

pub(super) fn lens_model(cam: &Camera) -> LensModel {
    match cam.distortion {
        Distortion::Equidistant { .. } => LensModel::Equidistant,
        Distortion::DoubleSphere { .. } => LensModel::DoubleSphere,
        Distortion::Eucm { .. } => LensModel::Eucm,
        Distortion::Radtan { .. } | Distortion::None => LensModel::Radtan,
    }
}

pub(super) const LEFT: &str = "intrinsics_left";
pub(super) const RIGHT: &str = "intrinsics_right";
pub(super) const EXTRINSICS: &str = "right_from_left";

pub(super) fn view_name(i: usize) -> String {
    format!("board_{i}")
}

/// One bundle adjustment from the current state.
pub(super) fn solve(
    state: &mut State,
    views: &[View<'_>],
    config: &CalibConfig,
) -> Result<(), CalibError> {
    let mut problem = tiny_solver::Problem::new();
    let mut init: HashMap<String, sna::DVector<f64>> = HashMap::new();
    init.insert(
        LEFT.into(),
        sna::DVector::from_vec(intrinsics_vec(&state.left)),
    );
    if state.stereo {
        init.insert(
            RIGHT.into(),
            sna::DVector::from_vec(intrinsics_vec(&state.right)),
        );
        init.insert(
            EXTRINSICS.into(),
            sna::DVector::from_vec(pose_vec(&state.right_from_left)),
        );
    }
    for (
        i,
        View {
            left: l, right: r, ..
        },
    ) in views.iter().enumerate()
    {
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
        for corner in r.iter().filter(|_| state.stereo) {
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
        for k in 0..intrinsics_vec(&state.left).len() {
            problem.fix_variable(LEFT, k);
        }
        for k in 0..intrinsics_vec(&state.right).len() {
            if state.stereo {
                problem.fix_variable(RIGHT, k);
            }
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
        if let Some(v) = get(RIGHT).filter(|_| state.stereo) {
            state.right = camera_from_vec(&v, &state.right);
        }
    }
    if let Some(v) = get(EXTRINSICS).filter(|_| state.stereo) {
        state.right_from_left = pose_from_vec(&v);
    }
    for i in 0..views.len() {
        if let Some(v) = get(&view_name(i)) {
            state.poses[i] = pose_from_vec(&v);
        }
    }
    Ok(())
}

/// The covariance of the calibrated parameters (the intrinsics of each free camera, then
/// `right_from_left` as a rotation vector and a translation), board poses marginalised out.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Covariance {
    /// Each row's and column's parameter, named as [`super::Calibration::sigmas`] names them.
    pub names: Vec<String>,
    /// The covariance, in the parameters' units (pixels, radians, metres) squared.
    pub matrix: DMatrix<f64>,
}

impl Covariance {
    /// The 6x6 block from the parameter `first` on (`right_from_left.rx`: the relative pose's),
    /// when the covariance holds it.
    pub fn block(&self, first: &str) -> Option<nalgebra::Matrix6<f64>> {
        let k = self.names.iter().position(|n| n == first)?;
        (k + 6 <= self.names.len())
            .then(|| nalgebra::Matrix6::from_fn(|i, j| self.matrix[(k + i, k + j)]))
    }
}

/// Parameter sigmas and covariance: `Σ = rms² (JᵀJ)⁻¹` over intrinsics, extrinsics and board
/// poses, with `J` by central differences of the reprojections; the sigmas (one per named
/// parameter, and the baseline's by propagation through its norm) and the covariance of all
/// but the board poses. Empty when `JᵀJ` is singular (a parameter the views do not touch).
pub(super) fn parameter_covariance(
    state: &State,
    views: &[View<'_>],
    config: &CalibConfig,
    rms_px: f64,
) -> (BTreeMap<String, f64>, Covariance) {
    let free_intrinsics = config.fixed_intrinsics.is_none();
    let names = super::camera_names(state.stereo);
    let mut x: Vec<f64> = Vec::new();
    let mut param_names: Vec<String> = Vec::new();
    if free_intrinsics {
        for (side, cam) in names.iter().zip([&state.left, &state.right]) {
            x.extend(intrinsics_vec(cam));
            param_names.extend(intrinsics_names(cam).iter().map(|n| format!("{side}.{n}")));
        }
    }
    let base = x.len();
    if state.stereo {
        x.extend(pose_vec(&state.right_from_left));
        param_names.extend(
            ["rx", "ry", "rz", "tx", "ty", "tz"]
                .iter()
                .map(|n| format!("right_from_left.{n}")),
        );
    }
    let poses_from = x.len();
    for p in &state.poses {
        x.extend(pose_vec(p));
    }
    let n_left = intrinsics_vec(&state.left).len();
    let residuals = |x: &[f64]| -> Vec<f64> {
        let (cl, cr) = if free_intrinsics {
            (
                camera_from_vec(&x[..n_left], &state.left),
                if state.stereo {
                    camera_from_vec(&x[n_left..base], &state.right)
                } else {
                    state.right
                },
            )
        } else {
            (state.left, state.right)
        };
        let rl = if state.stereo {
            pose_from_vec(&x[base..base + 6])
        } else {
            state.right_from_left
        };
        let mut out = Vec::new();
        for (
            i,
            View {
                left: l, right: r, ..
            },
        ) in views.iter().enumerate()
        {
            let o = poses_from + 6 * i;
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
        return (out, Covariance::default());
    };
    // Symmetric, as a covariance is (the inverse is only to rounding).
    let cov: DMatrix<f64> = (&cov + cov.transpose()) * (0.5 * rms_px * rms_px);
    for (k, n) in param_names.iter().enumerate() {
        out.insert(n.clone(), cov[(k, k)].max(0.0).sqrt());
    }
    if state.stereo {
        // The baseline's sigma by propagation through its norm.
        let t = state.right_from_left.translation.vector;
        let g = DVector::from_vec(vec![t.x, t.y, t.z]) / t.norm().max(1e-12);
        let ct = cov.view((base + 3, base + 3), (3, 3));
        out.insert(
            "baseline_m".into(),
            (g.transpose() * ct * &g)[(0, 0)].max(0.0).sqrt(),
        );
    }
    let n = param_names.len();
    let covariance = Covariance {
        names: param_names,
        matrix: cov.view((0, 0), (n, n)).into_owned(),
    };
    (out, covariance)
}
