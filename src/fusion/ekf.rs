//! The extended Kalman filter over the robot pose and the landmarks (EKF-SLAM), shared by the
//! online survey and by localisation against a survey.

use crate::fusion::landmark::{landmark_from, Extras};
use crate::fusion::measurement::{odometry_covariance, tag_in_robot};
use crate::fusion::{FuseConfig, Landmark, OdometryCalibration};
use crate::geometry::{wrap_angle, Pose2, StampedPose};
use crate::visual::tags::TagId;
use nalgebra::{DMatrix, DVector, Matrix2, Matrix3, Vector2, Vector3};

/// The Jacobians of `pose ∘ (dx, dy, dθ)` with respect to the pose and to the step, for a pose
/// at heading `theta`.
pub(crate) fn compose_jacobians(theta: f64, dx: f64, dy: f64) -> (Matrix3<f64>, Matrix3<f64>) {
    let (s, c) = theta.sin_cos();
    #[rustfmt::skip]
    let wrt_pose = Matrix3::new(
        1.0, 0.0, -s * dx - c * dy,
        0.0, 1.0, c * dx - s * dy,
        0.0, 0.0, 1.0,
    );
    #[rustfmt::skip]
    let wrt_step = Matrix3::new(
        c, -s, 0.0,
        s, c, 0.0,
        0.0, 0.0, 1.0,
    );
    (wrt_pose, wrt_step)
}

/// The EKF state: pose first, then three numbers per landmark, then `biases` numbers a user
/// of the filter keeps (the localiser's surveyed walls' offsets and turns), then a heading copy
/// while a turn is measured ([`Ekf::clone_heading`]).
#[derive(Debug, Clone)]
pub(crate) struct Ekf {
    pub(crate) x: DVector<f64>,
    pub(crate) p: DMatrix<f64>,
    pub(crate) slots: Vec<TagId>,
    pub(crate) biases: usize,
}

/// The odometry increment from `last` to `to`, corrected by an odometry calibration when given,
/// and the distance travelled.
fn calibrated_increment(
    last: Pose2,
    to: Pose2,
    calibration: Option<&OdometryCalibration>,
) -> (Pose2, f64) {
    let mut delta = last.between(&to);
    let path = delta.x.hypot(delta.y);
    if let Some(c) = calibration {
        delta.theta = wrap_angle(delta.theta);
        delta = c.correct(delta, delta.theta, path);
    }
    (delta, path)
}

impl Ekf {
    /// A filter sure of its start pose (the run's first odometry pose, the survey's anchor).
    pub(crate) fn at_start(odometry: &[StampedPose]) -> (Self, Pose2) {
        let start = odometry
            .first()
            .map_or(Pose2::new(0.0, 0.0, 0.0), |p| p.pose);
        let ekf = Self {
            x: DVector::from_vec(vec![start.x, start.y, start.theta]),
            p: DMatrix::identity(3, 3) * 1e-9,
            slots: Vec::new(),
            biases: 0,
        };
        (ekf, start)
    }

    /// A filter at `pose` with covariance `cov`, holding `landmarks` (each its key, x, y, yaw
    /// and their covariance) and after them bias states at zero with covariance `biases`
    /// (square); the three uncorrelated.
    pub(crate) fn at_pose(
        pose: Pose2,
        cov: &Matrix3<f64>,
        landmarks: &[(TagId, Vector3<f64>, Matrix3<f64>)],
        biases: &DMatrix<f64>,
    ) -> Self {
        let b = biases.nrows();
        let l = 3 + 3 * landmarks.len();
        let n = l + b;
        let mut x = DVector::zeros(n);
        x.fixed_rows_mut::<3>(0)
            .copy_from(&Vector3::new(pose.x, pose.y, pose.theta));
        let mut p = DMatrix::zeros(n, n);
        p.fixed_view_mut::<3, 3>(0, 0).copy_from(cov);
        for (k, (_, at, c)) in landmarks.iter().enumerate() {
            x.fixed_rows_mut::<3>(3 + 3 * k).copy_from(at);
            p.fixed_view_mut::<3, 3>(3 + 3 * k, 3 + 3 * k).copy_from(c);
        }
        p.view_mut((l, l), (b, b)).copy_from(biases);
        Self {
            x,
            p,
            slots: landmarks.iter().map(|(key, _, _)| *key).collect(),
            biases: b,
        }
    }

    /// Updates with a sighting of landmark `slot` whose innovation `y`, its covariance `s` and
    /// Jacobian `jac` are [`Ekf::innovation`]'s, as [`Ekf::update`] does, in `O(n²)`: `P - K S
    /// K'` with `K = P H' S⁻¹` (a filter holding many states: the localiser's landmarks and
    /// walls).
    pub(crate) fn update_sighting(
        &mut self,
        y: &Vector3<f64>,
        s: &Matrix3<f64>,
        jac: &DMatrix<f64>,
    ) {
        let Some(s_inv) = s.try_inverse() else { return };
        let s_inv = DMatrix::from_column_slice(3, 3, s_inv.as_slice());
        let pht = &self.p * jac.transpose();
        let k = &pht * &s_inv;
        self.x += &k * DVector::from_column_slice(y.as_slice());
        self.x[2] = wrap_angle(self.x[2]);
        for l in 0..self.slots.len() {
            let i = 3 + 3 * l + 2;
            self.x[i] = wrap_angle(self.x[i]);
        }
        self.p -= &k * pht.transpose();
        self.p = (&self.p + self.p.transpose()) * 0.5;
    }

    /// Puts the pose at `pose`, taken as a linear function of landmarks plus noise: `Σ A ·
    /// landmark[slot]` over `from`'s `(slot, A)`, and noise of covariance `noise` apart from the
    /// state (no landmarks: a pose taken afresh, known apart from the rest of the state). The
    /// pose's covariance with every state follows (`T P Tᵀ` for the map `T` that
    /// replaces the pose's rows), so a pose taken from a tag errs with the tag as the filter
    /// holds it, and a later sighting of the tag is not counted as news.
    pub(crate) fn reset_pose_from(
        &mut self,
        pose: Pose2,
        noise: &Matrix3<f64>,
        from: &[(usize, Matrix3<f64>)],
    ) {
        let n = self.x.len();
        let mut cross = DMatrix::zeros(3, n);
        for (slot, a) in from {
            cross += a * self.p.rows(3 + 3 * slot, 3);
        }
        let mut own = *noise;
        for (slot, a) in from {
            own += cross.fixed_view::<3, 3>(0, 3 + 3 * slot) * a.transpose();
        }
        self.p.rows_mut(0, 3).copy_from(&cross);
        self.p.columns_mut(0, 3).copy_from(&cross.transpose());
        self.p
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&((own + own.transpose()) * 0.5));
        self.x.fixed_rows_mut::<3>(0).copy_from(&Vector3::new(
            pose.x,
            pose.y,
            wrap_angle(pose.theta),
        ));
    }

    /// Predicts with the odometry increment from `last` to `to`, corrected by an odometry
    /// calibration when given, and moves `last` on; returns the increment predicted with and
    /// the distance travelled.
    pub(crate) fn advance_calibrated(
        &mut self,
        last: &mut Pose2,
        to: Pose2,
        calibration: Option<&OdometryCalibration>,
        config: &FuseConfig,
    ) -> (Pose2, f64) {
        let (delta, path) = calibrated_increment(*last, to, calibration);
        let q = odometry_covariance(path, wrap_angle(delta.theta).abs(), config);
        self.predict(&delta, &q);
        *last = to;
        (delta, path)
    }

    /// The landmarks the filter holds, in slot order.
    pub(crate) fn landmarks(&self, extras: &[Extras]) -> Vec<Landmark> {
        self.slots
            .iter()
            .enumerate()
            .map(|(slot, key)| {
                let (xy, cov) = self.landmark_xy_cov(slot);
                let yaw = 3 + 3 * slot + 2;
                landmark_from(
                    key,
                    xy,
                    (self.x[yaw], self.p[(yaw, yaw)]),
                    &cov,
                    &extras[slot],
                )
            })
            .collect()
    }

    /// Position sigma of the pose (√ of the largest eigenvalue), metres.
    pub(crate) fn position_sigma_m(&self) -> f64 {
        let pos = self.p.fixed_view::<2, 2>(0, 0).into_owned();
        pos.symmetric_eigenvalues().max().max(0.0).sqrt()
    }

    pub(crate) fn pose(&self) -> Pose2 {
        Pose2::new(self.x[0], self.x[1], self.x[2])
    }

    pub(crate) fn slot(&self, key: &TagId) -> Option<usize> {
        self.slots.iter().position(|k| k == key)
    }

    pub(crate) fn predict(&mut self, delta: &Pose2, q: &Matrix3<f64>) {
        let (f, g) = compose_jacobians(self.x[2], delta.x, delta.y);
        let moved = self.pose().compose(delta);
        self.x[0] = moved.x;
        self.x[1] = moved.y;
        self.x[2] = wrap_angle(moved.theta);
        let n = self.x.len();
        let ppp = self.p.fixed_view::<3, 3>(0, 0).into_owned();
        let new_pp = f * ppp * f.transpose() + g * q * g.transpose();
        if n > 3 {
            let ppl = self.p.view((0, 3), (3, n - 3)).into_owned();
            let new_pl = f * ppl;
            self.p.view_mut((0, 3), (3, n - 3)).copy_from(&new_pl);
            self.p
                .view_mut((3, 0), (n - 3, 3))
                .copy_from(&new_pl.transpose());
        }
        self.p.fixed_view_mut::<3, 3>(0, 0).copy_from(&new_pp);
    }

    /// Predicted measurement of landmark `slot` and its Jacobian over the whole state.
    pub(crate) fn observe(&self, slot: usize) -> (Vector3<f64>, DMatrix<f64>) {
        let i = 3 + 3 * slot;
        let (s, c) = self.x[2].sin_cos();
        // The state's own angles, not wrapped again (the filter's figures stay to the bit).
        let robot = Pose2 {
            x: self.x[0],
            y: self.x[1],
            theta: self.x[2],
        };
        let tag = Pose2 {
            x: self.x[i],
            y: self.x[i + 1],
            theta: self.x[i + 2],
        };
        let (h, over_robot) = tag_in_robot(robot, tag);
        let mut jac = DMatrix::zeros(3, self.x.len());
        jac.fixed_view_mut::<3, 3>(0, 0).copy_from(&over_robot);
        jac[(0, i)] = c;
        jac[(0, i + 1)] = s;
        jac[(1, i)] = -s;
        jac[(1, i + 1)] = c;
        jac[(2, i + 2)] = 1.0;
        (h, jac)
    }

    /// Innovation, its covariance and the Jacobian of a sighting of landmark `slot`.
    pub(crate) fn innovation(
        &self,
        slot: usize,
        z: &Vector3<f64>,
        r: &Matrix3<f64>,
    ) -> (Vector3<f64>, Matrix3<f64>, DMatrix<f64>) {
        let (h, jac) = self.observe(slot);
        let mut y = z - h;
        y[2] = wrap_angle(y[2]);
        let s = &jac * &self.p * jac.transpose() + DMatrix::from_column_slice(3, 3, r.as_slice());
        (y, Matrix3::from_fn(|i, j| s[(i, j)]), jac)
    }

    pub(crate) fn update(
        &mut self,
        y: &Vector3<f64>,
        s: &Matrix3<f64>,
        jac: &DMatrix<f64>,
        r: &Matrix3<f64>,
    ) {
        let Some(s_inv) = s.try_inverse() else { return };
        let s_inv = DMatrix::from_column_slice(3, 3, s_inv.as_slice());
        let k = &self.p * jac.transpose() * s_inv;
        self.x += &k * DVector::from_column_slice(y.as_slice());
        self.x[2] = wrap_angle(self.x[2]);
        for l in 0..self.slots.len() {
            let i = 3 + 3 * l + 2;
            self.x[i] = wrap_angle(self.x[i]);
        }
        // Joseph form keeps the covariance symmetric and positive.
        let n = self.x.len();
        let ikh = DMatrix::identity(n, n) - &k * jac;
        let rr = DMatrix::from_column_slice(3, 3, r.as_slice());
        self.p = &ikh * &self.p * ikh.transpose() + &k * rr * k.transpose();
    }

    /// Updates the pose with a measurement of it, `z` with covariance `r` (a scan matched with a
    /// map), after a χ² gate; returns whether it was fused.
    pub(crate) fn update_pose(&mut self, z: &Pose2, r: &Matrix3<f64>, gate_chi2: f64) -> bool {
        let n = self.x.len();
        let mut jac = DMatrix::zeros(3, n);
        for i in 0..3 {
            jac[(i, i)] = 1.0;
        }
        let mut y = Vector3::new(z.x - self.x[0], z.y - self.x[1], z.theta - self.x[2]);
        y[2] = wrap_angle(y[2]);
        let s = self.p.fixed_view::<3, 3>(0, 0) + r;
        let fits = s
            .try_inverse()
            .is_some_and(|s_inv| y.dot(&(s_inv * y)) < gate_chi2);
        if fits {
            self.update(&y, &s, &jac, r);
        }
        fits
    }

    /// Updates the pose with one scalar measurement: innovation `y`, Jacobian `h` over the pose,
    /// noise variance `r`, after a χ² gate; returns whether it was fused.
    pub(crate) fn update_scalar(
        &mut self,
        y: f64,
        h: &Vector3<f64>,
        r: f64,
        gate_chi2: f64,
    ) -> bool {
        let ph = self.p.columns(0, 3) * h;
        let s = h.dot(&ph.rows(0, 3)) + r;
        self.update_with(y, &ph, s, gate_chi2)
    }

    /// Updates with one measurement over the whole state: innovation `y`, Jacobian `h` (one
    /// number per state), noise variance `r`, after a χ² gate; returns whether it was fused.
    pub(crate) fn update_row(&mut self, y: f64, h: &DVector<f64>, r: f64, gate_chi2: f64) -> bool {
        let ph = &self.p * h;
        let s = h.dot(&ph) + r;
        self.update_with(y, &ph, s, gate_chi2)
    }

    /// The update of one measurement with `ph` = P h' and innovation variance `s`.
    fn update_with(&mut self, y: f64, ph: &DVector<f64>, s: f64, gate_chi2: f64) -> bool {
        if s.is_nan() || s <= 0.0 || y * y / s > gate_chi2 {
            return false;
        }
        let k = ph / s;
        self.x += &k * y;
        self.x[2] = wrap_angle(self.x[2]);
        // Joseph form, written for one row: P - K h'P - P h K' + K (h'Ph + r) K'.
        self.p = &self.p - &k * ph.transpose() - ph * k.transpose() + &k * k.transpose() * s;
        true
    }

    /// Whether the state ends with a copy of the heading ([`Ekf::clone_heading`]).
    pub(crate) fn has_clone(&self) -> bool {
        self.x.len() == 3 + 3 * self.slots.len() + self.biases + 1
    }

    /// Appends a copy of the current heading to the state (replacing an older one), so that a
    /// turn measured from now on can be fused when it ends (stochastic cloning).
    pub(crate) fn clone_heading(&mut self) {
        self.drop_clone();
        let n = self.x.len();
        let mut x = DVector::zeros(n + 1);
        x.rows_mut(0, n).copy_from(&self.x);
        x[n] = self.x[2];
        let mut p = DMatrix::zeros(n + 1, n + 1);
        p.view_mut((0, 0), (n, n)).copy_from(&self.p);
        for i in 0..n {
            p[(n, i)] = self.p[(2, i)];
            p[(i, n)] = self.p[(i, 2)];
        }
        p[(n, n)] = self.p[(2, 2)];
        self.x = x;
        self.p = p;
    }

    /// Removes the heading copy, if any.
    pub(crate) fn drop_clone(&mut self) {
        if self.has_clone() {
            let n = self.x.len() - 1;
            self.x = self.x.rows(0, n).into_owned();
            self.p = self.p.view((0, 0), (n, n)).into_owned();
        }
    }

    /// Updates with a turn measured since the heading was cloned: `turn` with variance `var`,
    /// after a χ² gate; returns whether it was fused (false also without a clone).
    pub(crate) fn update_turn(&mut self, turn: f64, var: f64, gate_chi2: f64) -> bool {
        if !self.has_clone() {
            return false;
        }
        let c = self.x.len() - 1;
        let y = wrap_angle(turn - (self.x[2] - self.x[c]));
        let ph = self.p.column(2) - self.p.column(c);
        let s = ph[2] - ph[c] + var;
        let fused = self.update_with(y, &ph, s, gate_chi2);
        if fused {
            self.x[c] = wrap_angle(self.x[c]);
        }
        fused
    }

    /// Adds a landmark at the sighting seen from the current pose; returns its slot.
    pub(crate) fn add(&mut self, key: TagId, z: &Vector3<f64>, r: &Matrix3<f64>) -> usize {
        // The heading copy stays last: taken out, put back after the new landmark.
        let cloned = self.has_clone().then(|| {
            let c = self.x.len() - 1;
            (self.x[c], self.p.column(c).into_owned())
        });
        self.drop_clone();
        let (s, c) = self.x[2].sin_cos();
        let l = Vector3::new(
            self.x[0] + c * z.x - s * z.y,
            self.x[1] + s * z.x + c * z.y,
            wrap_angle(self.x[2] + z.z),
        );
        let (gp, gz) = compose_jacobians(self.x[2], z.x, z.y);
        let n = self.x.len();
        let mut x = DVector::zeros(n + 3);
        x.rows_mut(0, n).copy_from(&self.x);
        x.rows_mut(n, 3).copy_from(&l);
        let mut p = DMatrix::zeros(n + 3, n + 3);
        p.view_mut((0, 0), (n, n)).copy_from(&self.p);
        let gp_d = DMatrix::from_column_slice(3, 3, gp.as_slice());
        let cross = &gp_d * self.p.view((0, 0), (3, n)); // 3 x n
        p.view_mut((n, 0), (3, n)).copy_from(&cross);
        p.view_mut((0, n), (n, 3)).copy_from(&cross.transpose());
        let ppp = self.p.fixed_view::<3, 3>(0, 0).into_owned();
        let pll = gp * ppp * gp.transpose() + gz * r * gz.transpose();
        p.fixed_view_mut::<3, 3>(n, n).copy_from(&pll);
        self.x = x;
        self.p = p;
        self.slots.push(key);
        if let Some((value, column)) = cloned {
            // Covariance of the copy with the new landmark: through the pose, as for the others.
            let with_pose = Vector3::new(column[0], column[1], column[2]);
            let with_landmark = gp * with_pose;
            let n = self.x.len();
            let mut x = DVector::zeros(n + 1);
            x.rows_mut(0, n).copy_from(&self.x);
            x[n] = value;
            let mut p = DMatrix::zeros(n + 1, n + 1);
            p.view_mut((0, 0), (n, n)).copy_from(&self.p);
            for i in 0..n {
                let v = if i < n - 3 {
                    column[i]
                } else {
                    with_landmark[i - (n - 3)]
                };
                p[(n, i)] = v;
                p[(i, n)] = v;
            }
            p[(n, n)] = column[column.len() - 1];
            self.x = x;
            self.p = p;
        }
        self.slots.len() - 1
    }

    pub(crate) fn landmark_xy_cov(&self, slot: usize) -> (Vector2<f64>, Matrix2<f64>) {
        let i = 3 + 3 * slot;
        (
            Vector2::new(self.x[i], self.x[i + 1]),
            self.p.fixed_view::<2, 2>(i, i).into_owned(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visual::tags::TagFamily;

    /// A landmark added while the heading is copied leaves the filter as if it had been added
    /// first: the copy stays last, with its covariance to the landmark carried through the pose.
    #[test]
    pub(crate) fn the_heading_copy_stays_last_when_a_landmark_joins() {
        let odometry = [StampedPose {
            t_s: 0.0,
            pose: Pose2::new(1.0, 2.0, 0.3),
        }];
        let config = FuseConfig::default();
        let z = Vector3::new(2.0, 0.5, 0.1);
        let r = Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.03));
        let moved = |ekf: &mut Ekf| {
            let mut last = odometry[0].pose;
            ekf.advance_calibrated(&mut last, Pose2::new(2.0, 2.5, 0.6), None, &config);
        };
        let (mut copy_first, _) = Ekf::at_start(&odometry);
        moved(&mut copy_first);
        copy_first.clone_heading();
        copy_first.add(
            TagId {
                family: TagFamily::Tag36h11,
                id: 1,
            },
            &z,
            &r,
        );
        let (mut add_first, _) = Ekf::at_start(&odometry);
        moved(&mut add_first);
        add_first.add(
            TagId {
                family: TagFamily::Tag36h11,
                id: 1,
            },
            &z,
            &r,
        );
        add_first.clone_heading();
        assert!(copy_first.has_clone());
        assert!((&copy_first.x - &add_first.x).norm() < 1e-12);
        assert!((&copy_first.p - &add_first.p).norm() < 1e-12);
        // A turn of what the filter already believes moves nothing.
        let before = copy_first.x.clone();
        assert!(copy_first.update_turn(0.0, 1e-4, 10.83));
        assert!((&copy_first.x - &before).norm() < 1e-9);
    }
}
