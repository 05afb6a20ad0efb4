//! The bundle adjustment: both cameras' intrinsics and distortion, every board pose and
//! `right_from_left`, adjusted by Levenberg-Marquardt (dense normal equations, derivatives by
//! dual numbers of fixed size, on every core) under a Huber kernel to minimise every corner's
//! reprojection error in both cameras, `π(K, D, right_from_left · left_from_board · P) − x`
//! (the lens models of [`crate::camera::lens`]); and the parameters' sigmas from `(JᵀJ)⁻¹`
//! scaled by the residual variance, `J` at the solution. (Until 2026-12 tiny-solver's sparse
//! solver did the adjustment, to the same results: its dual numbers of run-time size allocate
//! at every operation, 8 ms an iteration on 13 chessboard pairs against 2.5 ms here.)

use super::{CalibConfig, CalibError, View};
use crate::camera::{lens, Camera, Distortion, LensModel};
use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use std::collections::BTreeMap;
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

/// Local parameters of one corner's residual at most: a camera's intrinsics (8), the board's
/// pose (6) and, in the right image, `right_from_left` (6).
const LEFT_PARAMS: usize = 14;
const RIGHT_PARAMS: usize = 20;

/// One corner's residual (pixels) and its derivatives, `(column, [d r_x, d r_y])` for every free
/// parameter it reads.
type Linearised = ([f64; 2], Vec<(usize, [f64; 2])>);

/// A number carrying its derivatives with respect to one corner's `K` local parameters.
type Dual<const K: usize> = num_dual::DualSVec64<K>;

/// Where each parameter block sits in the adjustment's vector: the free intrinsics, then
/// `right_from_left` (a rig), then every board pose.
struct Columns {
    left: Option<usize>,
    right: Option<usize>,
    extrinsics: Option<usize>,
    poses: usize,
    len: usize,
}

impl Columns {
    fn of(state: &State, views: usize, fixed_intrinsics: bool) -> Self {
        let (nl, nr) = (
            intrinsics_vec(&state.left).len(),
            intrinsics_vec(&state.right).len(),
        );
        let mut len = 0;
        let mut take = |n: usize, on: bool| {
            on.then(|| {
                len += n;
                len - n
            })
        };
        let left = take(nl, !fixed_intrinsics);
        let right = take(nr, !fixed_intrinsics && state.stereo);
        let extrinsics = take(6, state.stereo);
        let poses = len;
        len += 6 * views;
        Self {
            left,
            right,
            extrinsics,
            poses,
            len,
        }
    }
}

/// One corner's residual (pixels) and its derivatives: `(column, [d r_x, d r_y])` for every
/// free parameter it reads. `blocks` are the parameter blocks the residual takes in order, each
/// with the column of its first entry when it is adjusted.
fn linearise<const K: usize>(
    blocks: &[(&[f64], Option<usize>)],
    residual: impl Fn(&[sna::DVector<Dual<K>>]) -> sna::DVector<Dual<K>>,
) -> Linearised {
    let mut slot = 0;
    let mut columns = Vec::with_capacity(K);
    let params: Vec<sna::DVector<Dual<K>>> = blocks
        .iter()
        .map(|(values, column)| {
            sna::DVector::from_iterator(
                values.len(),
                values.iter().enumerate().map(|(j, &v)| match column {
                    Some(c) if slot < K => {
                        columns.push((slot, c + j));
                        slot += 1;
                        Dual::<K>::new(
                            v,
                            num_dual::Derivative::derivative_generic(
                                sna::Const::<K>,
                                sna::U1,
                                slot - 1,
                            ),
                        )
                    }
                    _ => Dual::<K>::from_re(v),
                }),
            )
        })
        .collect();
    let r = residual(&params);
    let d = |i: usize| r[i].eps.unwrap_generic(sna::Const::<K>, sna::U1);
    let (dx, dy) = (d(0), d(1));
    (
        [r[0].re, r[1].re],
        columns
            .into_iter()
            .map(|(k, c)| (c, [dx[k], dy[k]]))
            .collect(),
    )
}

/// Every corner's residual and derivatives at `x` (the adjustment's vector; the fixed
/// intrinsics from `state`), in the order of the views, left corners before right; the views
/// on every core.
fn linearise_all(
    state: &State,
    views: &[View<'_>],
    columns: &Columns,
    x: &[f64],
) -> Vec<Linearised> {
    let (li, ri) = (intrinsics_vec(&state.left), intrinsics_vec(&state.right));
    let block = |col: Option<usize>, fixed: &[f64]| -> Vec<f64> {
        col.map_or_else(|| fixed.to_vec(), |c| x[c..c + fixed.len()].to_vec())
    };
    let (left, right) = (block(columns.left, &li), block(columns.right, &ri));
    let extrinsics = block(columns.extrinsics, &pose_vec(&state.right_from_left));
    let (ml, mr) = (lens_model(&state.left), lens_model(&state.right));
    use rayon::prelude::*;
    let view = |(i, v): (usize, &View<'_>)| {
        let mut out = Vec::with_capacity(v.left.len() + v.right.len());
        let pc = columns.poses + 6 * i;
        let pose = &x[pc..pc + 6];
        for corner in &v.left {
            let f = LeftCorner {
                board: corner.board_m,
                px: corner.px,
                model: ml,
            };
            out.push(linearise::<LEFT_PARAMS>(
                &[(&left, columns.left), (pose, Some(pc))],
                |p| tiny_solver::factors::Factor::residual_func(&f, p),
            ));
        }
        for corner in v.right.iter().filter(|_| state.stereo) {
            let f = RightCorner {
                board: corner.board_m,
                px: corner.px,
                model: mr,
            };
            out.push(linearise::<RIGHT_PARAMS>(
                &[
                    (&right, columns.right),
                    (pose, Some(pc)),
                    (&extrinsics, columns.extrinsics),
                ],
                |p| tiny_solver::factors::Factor::residual_func(&f, p),
            ));
        }
        out
    };
    views.par_iter().enumerate().flat_map_iter(view).collect()
}

/// Huber's cost of one residual, `ρ(s)` with `s = |r|²` (twice the usual: Ceres' convention),
/// and the weight `√ρ'(s)` its residual and derivatives are scaled by in the normal equations
/// (Ceres' corrector, which for Huber's kernel is this scaling alone).
fn huber(r: [f64; 2], delta: f64) -> (f64, f64) {
    let s = r[0] * r[0] + r[1] * r[1];
    if s > delta * delta {
        let n = s.sqrt();
        (2.0 * delta * n - delta * delta, (delta / n).sqrt())
    } else {
        (s, 1.0)
    }
}

/// The adjustment's vector of `state` in `columns`' layout.
fn pack(state: &State, columns: &Columns) -> Vec<f64> {
    let mut x = vec![0.0; columns.len];
    let mut put = |col: Option<usize>, v: Vec<f64>| {
        if let Some(c) = col {
            x[c..c + v.len()].copy_from_slice(&v);
        }
    };
    put(columns.left, intrinsics_vec(&state.left));
    put(columns.right, intrinsics_vec(&state.right));
    put(columns.extrinsics, pose_vec(&state.right_from_left));
    for (i, p) in state.poses.iter().enumerate() {
        put(Some(columns.poses + 6 * i), pose_vec(p));
    }
    x
}

/// `state` with the adjustment's vector `x` written back.
fn unpack(state: &mut State, columns: &Columns, x: &[f64]) {
    if let Some(c) = columns.left {
        let n = intrinsics_vec(&state.left).len();
        state.left = camera_from_vec(&x[c..c + n], &state.left);
    }
    if let Some(c) = columns.right {
        let n = intrinsics_vec(&state.right).len();
        state.right = camera_from_vec(&x[c..c + n], &state.right);
    }
    if let Some(c) = columns.extrinsics {
        state.right_from_left = pose_from_vec(&x[c..c + 6]);
    }
    for (i, p) in state.poses.iter_mut().enumerate() {
        let c = columns.poses + 6 * i;
        *p = pose_from_vec(&x[c..c + 6]);
    }
}

/// The total Huber cost at `x`.
fn cost(state: &State, views: &[View<'_>], columns: &Columns, x: &[f64], delta: f64) -> f64 {
    let mut trial = State {
        poses: state.poses.clone(),
        ..*state
    };
    unpack(&mut trial, columns, x);
    let mut total = 0.0;
    for (v, pose) in views.iter().zip(&trial.poses) {
        let right_pose = trial.right_from_left * pose;
        let sides = [
            (&trial.left, pose, &v.left),
            (&trial.right, &right_pose, &v.right),
        ];
        for (cam, pose, corners) in sides.into_iter().take(if trial.stereo { 2 } else { 1 }) {
            for corner in corners {
                let p = pose * Point3::from(corner.board_m);
                let q = cam.project(&p.coords).map_or([f64::INFINITY; 2], |q| {
                    [q.x - corner.px[0], q.y - corner.px[1]]
                });
                total += huber(q, delta).0;
            }
        }
    }
    total
}

/// `JᵀJ` and `Jᵀr` at `x`, each corner weighted by Huber's kernel of width `delta` (none:
/// unweighted).
fn normal_equations(
    state: &State,
    views: &[View<'_>],
    columns: &Columns,
    x: &[f64],
    delta: Option<f64>,
) -> (DMatrix<f64>, DVector<f64>) {
    let n = columns.len;
    let mut jtj = DMatrix::<f64>::zeros(n, n);
    let mut jtr = DVector::<f64>::zeros(n);
    for (r, d) in linearise_all(state, views, columns, x) {
        let w2 = delta.map_or(1.0, |delta| huber(r, delta).1.powi(2));
        for (a, (ca, ga)) in d.iter().enumerate() {
            jtr[*ca] += w2 * (ga[0] * r[0] + ga[1] * r[1]);
            for (cb, gb) in &d[..=a] {
                jtj[(*ca, *cb)] += w2 * (ga[0] * gb[0] + ga[1] * gb[1]);
            }
        }
    }
    // Each pair went to one triangle or the other (by the order of its corner's blocks), the
    // diagonal once: fold the two triangles together.
    for i in 0..n {
        for j in 0..i {
            let v = jtj[(i, j)] + jtj[(j, i)];
            jtj[(i, j)] = v;
            jtj[(j, i)] = v;
        }
    }
    (jtj, jtr)
}

/// One bundle adjustment from the current state: Levenberg-Marquardt on the normal equations,
/// which are small and dense (the intrinsics, `right_from_left` and 6 numbers a view), each
/// corner's derivatives by dual numbers of fixed size, Huber's kernel by iterative reweighting,
/// the damping Nielsen's with the columns scaled by their first norms (tiny-solver's and Ceres'
/// rules, whose stopping tests it keeps).
pub(super) fn solve(
    state: &mut State,
    views: &[View<'_>],
    config: &CalibConfig,
) -> Result<(), CalibError> {
    let columns = Columns::of(state, views.len(), config.fixed_intrinsics.is_some());
    let n = columns.len;
    let delta = config.huber_px.max(1e-3);
    let mut x = pack(state, &columns);
    let mut current = cost(state, views, &columns, &x, delta);
    let mut scaling: Option<DVector<f64>> = None;
    let (mut u, mut nu) = (1e-4, 2.0);
    for _ in 0..config.max_iterations {
        let (jtj, jtr) = normal_equations(state, views, &columns, &x, Some(delta));
        let scale = scaling
            .get_or_insert_with(|| DVector::from_fn(n, |i, _| 1.0 / (1.0 + jtj[(i, i)].sqrt())))
            .clone();
        // In scaled columns: A = S JᵀJ S, g = S Jᵀr.
        let a = DMatrix::from_fn(n, n, |i, j| scale[i] * jtj[(i, j)] * scale[j]);
        let g = DVector::from_fn(n, |i, _| scale[i] * jtr[i]);
        let mut damped = a.clone();
        for i in 0..n {
            damped[(i, i)] += u * a[(i, i)].clamp(1e-6, 1e32);
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&(-&g))) else {
            u *= nu;
            nu *= 2.0;
            continue;
        };
        let dx = step.component_mul(&scale);
        let x_norm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if dx.norm() <= 1e-8 * (x_norm + 1e-8) {
            break;
        }
        let trial: Vec<f64> = x.iter().zip(dx.iter()).map(|(a, b)| a + b).collect();
        let new = cost(state, views, &columns, &trial, delta);
        // The decrease the linear model predicts, in Ceres' units (costs here are 2x Ceres').
        let predicted = -(step.dot(&g) * 2.0 + step.dot(&(&a * &step)));
        let ratio = (current - new) / predicted.max(1e-300);
        if new.is_finite() && new < current && ratio > 0.0 {
            let decrease = current - new;
            x = trial;
            current = new;
            u *= (1.0f64 / 3.0).max(1.0 - (2.0 * ratio - 1.0).powi(3));
            nu = 2.0;
            if current < 1e-10 || decrease < 1e-5 || decrease < 1e-5 * (current + decrease) {
                break;
            }
        } else {
            u *= nu;
            nu *= 2.0;
            if u > 1e32 {
                break;
            }
        }
    }
    if !x.iter().all(|v| v.is_finite()) {
        return Err(CalibError::Solver);
    }
    unpack(state, &columns, &x);
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
/// poses, with `J` the reprojections' derivatives (by dual numbers); the sigmas (one per named
/// parameter, and the baseline's by propagation through its norm) and the covariance of all
/// but the board poses. Empty when `JᵀJ` is singular (a parameter the views do not touch).
pub(super) fn parameter_covariance(
    state: &State,
    views: &[View<'_>],
    config: &CalibConfig,
    rms_px: f64,
) -> (BTreeMap<String, f64>, Covariance) {
    let free_intrinsics = config.fixed_intrinsics.is_none();
    let columns = Columns::of(state, views.len(), !free_intrinsics);
    // The names of the parameters before the board poses, in `columns`' order.
    let mut param_names: Vec<String> = Vec::new();
    if free_intrinsics {
        let names = super::camera_names(state.stereo);
        for (side, cam) in names.iter().zip([&state.left, &state.right]) {
            param_names.extend(intrinsics_names(cam).iter().map(|n| format!("{side}.{n}")));
        }
    }
    let base = param_names.len();
    if state.stereo {
        param_names.extend(
            ["rx", "ry", "rz", "tx", "ty", "tz"]
                .iter()
                .map(|n| format!("right_from_left.{n}")),
        );
    }
    debug_assert_eq!(columns.poses, param_names.len());
    let (info, _) = normal_equations(state, views, &columns, &pack(state, &columns), None);

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
