//! The factors of the offline graph, generic over the scalar so that the solver differentiates
//! them: odometry between-factors (with the odometry calibration), visual turns, tag
//! observations and priors.

use nalgebra::Matrix3;
use tiny_solver::na as sna;

/// Whitened SE(2) between-factor: `r = S · (p0⁻¹ ∘ p1 ⊖ measured)`.
#[derive(Clone)]
pub(super) struct BetweenFactor {
    pub(super) measured: [f64; 3],
    pub(super) sqrt_info: [[f64; 3]; 3],
    /// Signed turn and path length of the interval, for the odometry calibration (when the
    /// factor has a third variable `[a, c, s]`: turn scale error, heading drift per metre, distance
    /// scale error; `dθ_true = dθ (1 + a) + c L`, `ds_true = ds (1 + s)`).
    pub(super) turn_rad: f64,
    pub(super) path_m: f64,
}

/// Whitened turn between two keyframes: `r = (θ1 − θ0 − measured) / σ`.
pub(super) struct TurnFactor {
    pub(super) measured: f64,
    pub(super) sqrt_info: f64,
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for TurnFactor {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let (a, b) = (&params[0], &params[1]);
        let r = angle(b[2].clone() - a[2].clone() - constant::<T>(self.measured));
        sna::DVector::from_vec(vec![r * constant::<T>(self.sqrt_info)])
    }
}

/// Whitened tag factor: `r = S · (h(pose, landmark) − z)`.
#[derive(Clone)]
pub(super) struct TagFactor {
    pub(super) measured: [f64; 3],
    pub(super) sqrt_info: [[f64; 3]; 3],
}

/// Whitened range off a wall face from a keyframe's pose: the reading was taken at `delta` (in the
/// keyframe's frame, from the odometry) from the keyframe, by a sensor at `sensor` (x, y, bearing in
/// the robot frame); the face is the line `n . p = offset` with `n` at `normal_rad`.
/// `r = (d / cos(phi) − measured) · sqrt_info` with `d = n . q − offset` (`q`: the sensor's
/// position) and `phi` the ray's angle off the face's normal for a laser (0 for a sonar's cone,
/// whose echo comes back along the normal).
pub(super) struct WallRangeFactor {
    pub(super) delta: [f64; 3],
    pub(super) sensor: [f64; 3],
    pub(super) normal_rad: f64,
    pub(super) offset_m: f64,
    pub(super) ray: bool,
    pub(super) measured: f64,
    pub(super) sqrt_info: f64,
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for WallRangeFactor {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let p = &params[0];
        let (s, c) = (p[2].clone().sin(), p[2].clone().cos());
        let [dx, dy, dt] = self.delta.map(constant::<T>);
        // The robot when the reading was taken, then the sensor.
        let rx = p[0].clone() + c.clone() * dx.clone() - s.clone() * dy.clone();
        let ry = p[1].clone() + s * dx + c * dy;
        let rt = p[2].clone() + dt;
        let (rs, rc) = (rt.clone().sin(), rt.clone().cos());
        let [ox, oy, bearing] = self.sensor.map(constant::<T>);
        let qx = rx + rc.clone() * ox.clone() - rs.clone() * oy.clone();
        let qy = ry + rs * ox + rc * oy;
        let (ns, nc) = self.normal_rad.sin_cos();
        let d = constant::<T>(nc) * qx + constant::<T>(ns) * qy - constant::<T>(self.offset_m);
        let range = if self.ray {
            let phi = rt + bearing - constant::<T>(self.normal_rad + std::f64::consts::PI);
            d / phi.cos()
        } else {
            d
        };
        sna::DVector::from_vec(vec![
            (range - constant::<T>(self.measured)) * constant::<T>(self.sqrt_info),
        ])
    }
}

/// Whitened prior on a pose: `r = S · (p ⊖ measured)` (the heading's difference wrapped).
pub(super) struct PoseFactor {
    pub(super) measured: [f64; 3],
    pub(super) sqrt_info: [[f64; 3]; 3],
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for PoseFactor {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let p = &params[0];
        let [x, y, theta] = self.measured.map(constant::<T>);
        whiten(
            &self.sqrt_info,
            [
                p[0].clone() - x,
                p[1].clone() - y,
                angle(p[2].clone() - theta),
            ],
        )
    }
}

/// Whitened wall direction seen from a keyframe, against the building's wall direction `axes`
/// (a one-dimensional variable): the wall's normal, `normal_rad` in the keyframe's frame, lies
/// along one of the four directions `axes + k · 90°`.
/// `r = ((θ + normal − axes) wrapped to a quarter turn) · sqrt_info`.
pub(super) struct WallDirectionFactor {
    pub(super) normal_rad: f64,
    pub(super) sqrt_info: f64,
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for WallDirectionFactor {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let (pose, axes) = (&params[0], &params[1]);
        let off = pose[2].clone() + constant::<T>(self.normal_rad) - axes[0].clone();
        let four = constant::<T>(4.0);
        let r = angle(off * four.clone()) / four;
        sna::DVector::from_vec(vec![r * constant::<T>(self.sqrt_info)])
    }
}

/// Whitened prior on a vector variable (first pose; corner priors on landmark x, y).
pub(super) struct PriorFactor {
    pub(super) measured: Vec<f64>,
    pub(super) sqrt_info: Vec<f64>,
}

fn angle<T: sna::RealField>(a: T) -> T {
    a.clone().sin().atan2(a.cos())
}

fn whiten<T: sna::RealField>(s: &[[f64; 3]; 3], r: [T; 3]) -> sna::DVector<T> {
    sna::DVector::from_fn(3, |i, _| {
        (0..3).fold(T::zero(), |acc, j| {
            acc + T::from_f64(s[i][j]).unwrap_or_else(T::zero) * r[j].clone()
        })
    })
}

fn constant<T: sna::RealField>(v: f64) -> T {
    T::from_f64(v).unwrap_or_else(T::zero)
}

/// The odometry calibration's model, for any scalar (the offline graph differentiates it): an
/// increment `measured` (x, y, turn; in the frame of its start) over `path_m` with signed turn
/// `turn_rad`, corrected by `[a, c, s]` (turn scale error, heading drift per metre, distance
/// scale error): the turn scaled and the drift added, the translation turned by half that extra
/// turn and scaled.
pub(super) fn corrected_increment<T: sna::RealField>(
    [a, c, s]: [T; 3],
    measured: [f64; 3],
    turn_rad: f64,
    path_m: f64,
) -> [T; 3] {
    let extra = a * constant::<T>(turn_rad) + c * constant::<T>(path_m);
    let half = extra.clone() * constant::<T>(0.5);
    let scale = T::one() + s;
    let (hs, hc) = (half.clone().sin(), half.cos());
    let (x, y) = (constant::<T>(measured[0]), constant::<T>(measured[1]));
    [
        (hc.clone() * x.clone() - hs.clone() * y.clone()) * scale.clone(),
        (hs * x + hc * y) * scale,
        constant::<T>(measured[2]) + extra,
    ]
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for BetweenFactor {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let (a, b) = (&params[0], &params[1]);
        // The measured increment, corrected by the odometry calibration when there is one.
        let [mx, my, mt] = match params.get(2) {
            Some(k) => corrected_increment(
                [k[0].clone(), k[1].clone(), k[2].clone()],
                self.measured,
                self.turn_rad,
                self.path_m,
            ),
            None => self.measured.map(constant::<T>),
        };
        let (s, c) = (a[2].clone().sin(), a[2].clone().cos());
        let dx = b[0].clone() - a[0].clone();
        let dy = b[1].clone() - a[1].clone();
        let rx = c.clone() * dx.clone() + s.clone() * dy.clone() - mx;
        let ry = -s * dx + c * dy - my;
        let rt = angle(b[2].clone() - a[2].clone() - mt);
        whiten(&self.sqrt_info, [rx, ry, rt])
    }
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for TagFactor {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let (p, l) = (&params[0], &params[1]);
        // The sighting in the robot frame; with a third variable, the camera's mounting error
        // `m = (x, y, yaw)` moves it: the tag is at `m ∘ z` from the robot.
        let [zx, zy, zt] = self.measured.map(constant::<T>);
        let [mx, my, mt] = match params.get(2) {
            Some(m) => {
                let (ms, mc) = (m[2].clone().sin(), m[2].clone().cos());
                [
                    m[0].clone() + mc.clone() * zx.clone() - ms.clone() * zy.clone(),
                    m[1].clone() + ms * zx + mc * zy,
                    zt + m[2].clone(),
                ]
            }
            None => [zx, zy, zt],
        };
        let (s, c) = (p[2].clone().sin(), p[2].clone().cos());
        let dx = l[0].clone() - p[0].clone();
        let dy = l[1].clone() - p[1].clone();
        let rx = c.clone() * dx.clone() + s.clone() * dy.clone() - mx;
        let ry = -s * dx + c * dy - my;
        let rt = angle(l[2].clone() - p[2].clone() - mt);
        whiten(&self.sqrt_info, [rx, ry, rt])
    }
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for PriorFactor {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let v = &params[0];
        sna::DVector::from_fn(self.measured.len(), |i, _| {
            (v[i].clone() - constant::<T>(self.measured[i])) * constant::<T>(self.sqrt_info[i])
        })
    }
}

/// Upper-triangular `S` with `Sᵀ S = Σ⁻¹`.
pub(super) fn sqrt_information(cov: &Matrix3<f64>) -> [[f64; 3]; 3] {
    let info = cov.try_inverse().unwrap_or_else(Matrix3::identity);
    let info = (info + info.transpose()) * 0.5;
    match info.cholesky() {
        // info = L Lᵀ, so S = Lᵀ.
        Some(ch) => {
            let s = ch.l().transpose();
            std::array::from_fn(|i| std::array::from_fn(|j| s[(i, j)]))
        }
        None => {
            let d = cov.diagonal().map(|v| 1.0 / v.max(1e-12).sqrt());
            [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
        }
    }
}
