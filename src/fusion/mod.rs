//! Fusion: odometry, triangulated tags and Hough corners → landmarks and corrected trajectories.
//!
//! The planar robot pose `(x, y, θ)` and each tag landmark `(x, y, ψ)` (ψ: the direction the tag
//! faces) form the state. A sighting measures the tag in the robot frame,
//! `z = (R(θ)ᵀ (l − p), ψ − θ)`, with the covariance of the stereo triangulation rotated into the
//! robot frame and a yaw sigma from the corner noise over the tag size.
//!
//! **Online** ([`run_online`]): an EKF over the pose and the landmarks (EKF-SLAM; a home has tens of
//! tags, so the dense state stays small). Odometry increments predict, with noise growing with the
//! distance travelled and the angle turned; sightings update after a χ² gate on the innovation; a
//! tag seen the first time is added to the state and matched to the nearest Hough corner by
//! Mahalanobis distance on both covariances. Sightings that fail the gate are kept aside and checked
//! for consistency (the same id in two places, a tag moved after its first sighting) rather than
//! fused.
//!
//! **Offline** ([`run_offline`], the method's a-posteriori pass): a pose graph over keyframes (every
//! half metre or half radian of odometry, and every sighting), with odometry between-factors, tag
//! observation factors under a Huber kernel and optionally Hough-corner priors on landmarks, solved by
//! Levenberg-Marquardt in the `tiny-solver` crate (sparse Cholesky, automatic derivatives) from the
//! online estimate. Poses between keyframes follow the odometry with the keyframe corrections
//! interpolated by distance travelled.

use crate::geometry::{wrap_angle, Pose2};
use crate::sonar::hough::Feature;
use crate::dataset::{pose_at, StampedPose};
use crate::sonar::{SonarLayout, SonarReading};
use crate::visual::stereo::StereoTag;
use crate::visual::vo::VisualTurn;
use crate::sonar::walls::WallSegment;
use nalgebra::{DMatrix, DVector, Isometry3, Matrix2, Matrix3, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use tiny_solver::na as sna;

/// Settings of the fusion stage. Defaults say where they come from.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FuseConfig {
    /// Translation noise of odometry, m per √m travelled (ours: 1 cm/√m, five times the simulated
    /// random wheel noise to cover the wheel-scale error).
    pub odometry_sigma_m_per_sqrt_m: f64,
    /// Heading noise of odometry per √rad turned (ours: 0.03, covers the simulated 1% wheel-base
    /// error over a full turn, 0.063 rad, at about one sigma).
    pub heading_sigma_per_sqrt_rad: f64,
    /// Heading noise per √rad turned of odometry corrected with a survey's calibration
    /// ([`FuseConfig::for_calibrated_odometry`], what `localize` predicts with; ours: 0.015, a
    /// measured choice: the calibration removes the 1% wheel-base error that the 0.03 covers,
    /// and with 0.03 each sonar range turns the heading too far. The localisation ATE summed
    /// over the pairs of README, with the walls: willow's 14 pairs 110 cm at 0.03, 81 at 0.02,
    /// 75 at 0.015 and 0.01 (73 at 0.015 once faces beyond the sonar's reach are not matched);
    /// office's 12 and museum's 12 within 2 cm of 0.03's; tags alone
    /// office's 12 pairs 80 cm at 0.03, 85 at 0.015, 88 at 0.01).
    pub calibrated_heading_sigma_per_sqrt_rad: f64,
    /// Heading noise per √m travelled (ours: 0.01 rad/√m: random wheel noise of 2 mm/√m on each
    /// wheel of a 0.3 m base, the simulation's default, gives 0.0094).
    pub heading_sigma_per_sqrt_m: f64,
    /// Floor added to each sighting's position sigma, m (ours: 1 cm for the camera mounting and
    /// the time stamp of the picture).
    pub sighting_sigma_floor_m: f64,
    /// Floor of a sighting's yaw sigma, rad (ours: 0.02).
    pub yaw_sigma_floor_rad: f64,
    /// Position sigma of a Hough corner, m (ours: 0.12: the 100 mm Hough cell and the offset of
    /// the tag centre from the corner it marks).
    pub corner_sigma_m: f64,
    /// χ² gate of a sighting's innovation, 3 dof (16.27: 99.9%).
    pub gate_chi2: f64,
    /// χ² gate of tag-to-corner association, 2 dof (9.21: 99%).
    pub association_chi2: f64,
    /// Gated-out sightings within this distance of each other form one conflicting place, m.
    pub conflict_radius_m: f64,
    /// Sightings needed at a second place before it is reported (ours: 2; one can be a blunder).
    pub conflict_min_sightings: usize,
    /// A second place closer than this to the landmark is drift, not a conflict (ours: 0.3 m,
    /// beyond the pose error the filter reaches between sightings in a home).
    pub conflict_min_distance_m: f64,
    /// Keyframe spacing of the offline graph, m of travel (ours: 0.5 m, short enough that heading
    /// error does not make the linearised odometry factors overconfident).
    pub keyframe_spacing_m: f64,
    /// Keyframe spacing of the offline graph, rad of turn.
    pub keyframe_turn_rad: f64,
    /// Huber kernel width on whitened tag residuals (ours: 2 sigma).
    pub huber_sigma: f64,
    /// Add Hough-corner priors on matched landmarks in the offline graph (off by default: the
    /// corners are placed with odometry poses and carry their drift).
    pub corner_factors: bool,
    /// Levenberg-Marquardt iterations at most.
    pub max_iterations: usize,
    /// Estimate the odometry's systematic errors (turn scale from the wheel base, heading drift
    /// from unequal wheels, distance scale) in the offline graph and correct the whole run with
    /// them, also before the first sighting (ours: on).
    pub calibrate_odometry: bool,
    /// While the run streams in, re-solve the graph of the run so far now and then (after a
    /// tag seen before is seen again, once the robot has travelled 5 m and a quarter of its
    /// distance so far since the last solve) and go on from its pose, landmarks and odometry calibration,
    /// as an incremental smoother does; the filter then predicts with calibrated odometry
    /// (ours: on; needs `calibrate_odometry`).
    pub online_resolve: bool,
    /// Constant part of a sonar range's sigma when localising against surveyed walls, m (ours:
    /// 1 cm, the simulated sonar's).
    pub sonar_sigma_m: f64,
    /// Part of a sonar range's sigma proportional to the range (ours: 1%, the simulated sonar's).
    pub sonar_sigma_frac: f64,
    /// How well a surveyed wall is placed, m (ours: 2 cm: the survey's own pose error). Added to
    /// each range's noise; a range is not fused when the filter already knows its distance to the
    /// wall better than this (the same wall's error is shared by every range off it).
    pub wall_sigma_m: f64,
    /// χ² gate of a sonar range against a surveyed wall, 1 dof (6.63: 99%).
    pub sonar_gate_chi2: f64,
    /// A range is not fused when the filter knows its distance to the wall worse than this, m
    /// (ours: 0.2 m): the nearest face in the beam may then be the wrong one, and a range off the
    /// wrong face pulls the pose further off (willow, seed-1 survey, seed-2 run: 20 m without a
    /// sighting, position sigma 0.6 m, then 2 m and 19 degrees off).
    pub sonar_max_range_sigma_m: f64,
    /// Hold the survey's trajectory after its last sighting to the walls mapped before it
    /// ([`hold_tail_to_walls`]; ours: on).
    pub hold_tail_to_walls: bool,
    /// Fuse the turns the cameras measure between frames ([`crate::visual::vo`]) with the odometry,
    /// online and offline (ours: on; they are used when the run's pictures give them).
    pub visual_odometry: bool,
    /// χ² gate of a visual turn against the filter, 1 dof (10.83: 99.9%).
    pub visual_gate_chi2: f64,
}

/// A fusion setting out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("fusion setting `{key}` = {value} is invalid: {reason}")]
pub struct FuseConfigError {
    /// The key.
    pub key: &'static str,
    /// Its value.
    pub value: f64,
    /// What is expected.
    pub reason: &'static str,
}

impl FuseConfig {
    /// Checks the settings: sigmas, gates and spacings positive (the sighting floor, the
    /// conflict distance and the sonar's proportional and wall sigmas may be zero), counts at
    /// least one.
    pub fn validate(&self) -> Result<(), FuseConfigError> {
        let positive = [
            (
                "odometry_sigma_m_per_sqrt_m",
                self.odometry_sigma_m_per_sqrt_m,
            ),
            (
                "heading_sigma_per_sqrt_rad",
                self.heading_sigma_per_sqrt_rad,
            ),
            (
                "calibrated_heading_sigma_per_sqrt_rad",
                self.calibrated_heading_sigma_per_sqrt_rad,
            ),
            ("heading_sigma_per_sqrt_m", self.heading_sigma_per_sqrt_m),
            ("yaw_sigma_floor_rad", self.yaw_sigma_floor_rad),
            ("corner_sigma_m", self.corner_sigma_m),
            ("gate_chi2", self.gate_chi2),
            ("association_chi2", self.association_chi2),
            ("conflict_radius_m", self.conflict_radius_m),
            ("keyframe_spacing_m", self.keyframe_spacing_m),
            ("keyframe_turn_rad", self.keyframe_turn_rad),
            ("huber_sigma", self.huber_sigma),
            ("sonar_sigma_m", self.sonar_sigma_m),
            ("sonar_gate_chi2", self.sonar_gate_chi2),
            ("sonar_max_range_sigma_m", self.sonar_max_range_sigma_m),
            ("visual_gate_chi2", self.visual_gate_chi2),
        ];
        let non_negative = [
            ("sighting_sigma_floor_m", self.sighting_sigma_floor_m),
            ("conflict_min_distance_m", self.conflict_min_distance_m),
            ("sonar_sigma_frac", self.sonar_sigma_frac),
            ("wall_sigma_m", self.wall_sigma_m),
        ];
        let counts = [
            ("conflict_min_sightings", self.conflict_min_sightings),
            ("max_iterations", self.max_iterations),
        ];
        let bad = |key, value, reason| Err(FuseConfigError { key, value, reason });
        if let Some(&(key, value)) = positive.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
            return bad(key, value, "must be a positive number");
        }
        if let Some(&(key, value)) = non_negative
            .iter()
            .find(|(_, v)| !(v.is_finite() && *v >= 0.0))
        {
            return bad(key, value, "must be zero or a positive number");
        }
        if let Some(&(key, value)) = counts.iter().find(|(_, v)| *v == 0) {
            return bad(key, value as f64, "must be at least 1");
        }
        Ok(())
    }

    /// The settings for odometry already corrected with a survey's [`OdometryCalibration`]: the
    /// turn noise is then what the calibration leaves
    /// (`calibrated_heading_sigma_per_sqrt_rad`), not the wheel-base error it removed.
    pub fn for_calibrated_odometry(&self) -> Self {
        Self {
            heading_sigma_per_sqrt_rad: self.calibrated_heading_sigma_per_sqrt_rad,
            ..self.clone()
        }
    }
}

impl Default for FuseConfig {
    fn default() -> Self {
        Self {
            odometry_sigma_m_per_sqrt_m: 0.01,
            heading_sigma_per_sqrt_rad: 0.03,
            calibrated_heading_sigma_per_sqrt_rad: 0.015,
            heading_sigma_per_sqrt_m: 0.01,
            sighting_sigma_floor_m: 0.01,
            yaw_sigma_floor_rad: 0.02,
            corner_sigma_m: 0.12,
            gate_chi2: 16.27,
            association_chi2: 9.21,
            conflict_radius_m: 0.3,
            conflict_min_sightings: 2,
            conflict_min_distance_m: 0.3,
            keyframe_spacing_m: 0.5,
            keyframe_turn_rad: 0.5,
            huber_sigma: 2.0,
            corner_factors: false,
            max_iterations: 50,
            calibrate_odometry: true,
            online_resolve: true,
            sonar_sigma_m: 0.01,
            sonar_sigma_frac: 0.01,
            wall_sigma_m: 0.02,
            sonar_gate_chi2: 6.63,
            sonar_max_range_sigma_m: 0.2,
            hold_tail_to_walls: true,
            visual_odometry: true,
            visual_gate_chi2: 10.83,
        }
    }
}

/// Yaw sigma of a sighting per unit of (centre depth sigma / tag size): 2√2, as if the corners
/// erred independently. On the rendered office runs (`cargo run --release --example
/// sighting_errors -- RUN`) the yaw errors are mostly 5-10 times smaller, but those seen from 2.5
/// to 3 m at a slant share a bias of 0.05-0.13 rad; with 0.6 instead of 2√2 the offline ATE of a
/// perfect-odometry office run went from 3 cm to 10 cm, so the yaw stays weakly weighted.
pub const YAW_SIGMA_PER_DEPTH_SIGMA: f64 = 2.0 * std::f64::consts::SQRT_2;

/// A tag's four corners in the left and the right image, pixels (AprilTag C order).
pub type PairCorners = ([[f64; 2]; 4], [[f64; 2]; 4]);

/// A tag seen in a stereo pair, in the robot frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TagSighting {
    /// Time of the picture, seconds.
    pub t_s: f64,
    /// Index of the stereo pair in the run.
    pub frame: usize,
    /// Tag id.
    pub id: u32,
    /// Tag family.
    pub family: String,
    /// Triangulated edge length, metres.
    pub size_m: f64,
    /// Tag centre in the robot frame, metres.
    pub position_in_robot_m: [f64; 3],
    /// Covariance of the centre in the robot frame, m².
    pub covariance_m2: [[f64; 3]; 3],
    /// Direction the tag faces in the robot frame, radians.
    pub yaw_in_robot_rad: f64,
    /// One sigma of that direction, radians.
    pub yaw_sigma_rad: f64,
    /// The detected corners (left, right), pixels, when the sighting came from images.
    pub corners_px: Option<PairCorners>,
}

impl TagSighting {
    /// A stereo tag moved into the robot frame through `robot_from_left`.
    pub fn from_stereo(
        t_s: f64,
        frame: usize,
        tag: &StereoTag,
        robot_from_left: &Isometry3<f64>,
    ) -> Self {
        let p = robot_from_left * Point3::from(tag.position_in_left_m);
        let r = robot_from_left.rotation.to_rotation_matrix();
        let cov_left = Matrix3::from_fn(|i, j| tag.covariance_m2[i][j]);
        let cov = r.matrix() * cov_left * r.matrix().transpose();
        let n = r * Vector3::from(tag.normal_in_left);
        // The yaw error is the depth difference of opposite corners over the tag size, scaled by
        // the centre's depth sigma; see [`YAW_SIGMA_PER_DEPTH_SIGMA`].
        let largest = cov_left.symmetric_eigenvalues().max().max(0.0).sqrt();
        let yaw_sigma = YAW_SIGMA_PER_DEPTH_SIGMA * largest / tag.size_m.max(1e-3);
        Self {
            t_s,
            frame,
            id: tag.id,
            family: tag.family.to_string(),
            size_m: tag.size_m,
            position_in_robot_m: [p.x, p.y, p.z],
            covariance_m2: std::array::from_fn(|i| std::array::from_fn(|j| cov[(i, j)])),
            yaw_in_robot_rad: n.y.atan2(n.x),
            yaw_sigma_rad: yaw_sigma,
            corners_px: Some((tag.corners_px, tag.right_corners_px)),
        }
    }

    /// The planar measurement `(x, y, ψ)` and its covariance, with the configured floors.
    fn measurement(&self, config: &FuseConfig) -> (Vector3<f64>, Matrix3<f64>) {
        let z = Vector3::new(
            self.position_in_robot_m[0],
            self.position_in_robot_m[1],
            self.yaw_in_robot_rad,
        );
        let floor = config.sighting_sigma_floor_m.powi(2);
        let c = &self.covariance_m2;
        let yaw_sigma = self.yaw_sigma_rad.max(config.yaw_sigma_floor_rad);
        let r = Matrix3::new(
            c[0][0] + floor,
            c[0][1],
            0.0,
            c[1][0],
            c[1][1] + floor,
            0.0,
            0.0,
            0.0,
            yaw_sigma * yaw_sigma,
        );
        (z, r)
    }

    fn key(&self) -> (String, u32) {
        (self.family.clone(), self.id)
    }
}

/// A Hough corner a landmark was matched with.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct CornerMatch {
    /// Corner position, metres.
    pub x_m: f64,
    /// Corner position, metres.
    pub y_m: f64,
    /// Votes of the Hough peak.
    pub votes: u32,
    /// Squared Mahalanobis distance of the match (0 when read from a file that lacks it).
    #[serde(default)]
    pub distance_chi2: f64,
}

/// A surveyed tag (as `landmarks.json` holds it, see `io::LandmarkRecord`).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct Landmark {
    /// Tag id.
    pub id: u32,
    /// Tag family.
    pub family: String,
    /// Mean triangulated edge length, metres.
    pub size_m: f64,
    /// Tag centre in the world, metres (z is the mean of the sightings).
    pub position_m: [f64; 3],
    /// Direction the tag faces, radians from the world x axis.
    pub yaw_rad: f64,
    /// Covariance of the centre, m² (x, y from the filter; z from the spread of the sightings).
    pub covariance_m2: [[f64; 3]; 3],
    /// Sightings fused.
    pub observations: usize,
    /// The Hough corner matched, if any.
    pub matched_corner: Option<CornerMatch>,
}

/// Sightings of one id that disagree with its landmark.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Conflict {
    /// Tag id.
    pub id: u32,
    /// Tag family.
    pub family: String,
    /// `"moved"` (never seen at the first place again) or `"duplicate id"` (seen at both).
    pub kind: String,
    /// Where the landmark is, metres.
    pub landmark_m: [f64; 2],
    /// Where the conflicting sightings put it, metres.
    pub seen_at_m: [f64; 2],
    /// Number of conflicting sightings.
    pub sightings: usize,
    /// Time of the first conflicting sighting, seconds.
    pub first_t_s: f64,
}

/// The result of the online filter.
#[derive(Debug, Clone)]
pub struct OnlineResult {
    /// Filtered pose at each odometry time.
    pub trajectory: Vec<StampedPose>,
    /// Landmarks at the end of the run.
    pub landmarks: Vec<Landmark>,
    /// Sightings fused (indices into the input).
    pub accepted: Vec<usize>,
    /// Sightings gated out (indices into the input).
    pub rejected: Vec<usize>,
    /// Consistency problems found.
    pub conflicts: Vec<Conflict>,
    /// Filtered pose at each sighting (same order as the input), used to start the offline pass.
    pub pose_at_sighting: Vec<Pose2>,
    /// Normalised innovation squared of each accepted update (for consistency plots).
    pub nis: Vec<(f64, f64)>,
    /// Position sigma of the pose (√ of the largest eigenvalue) at each odometry time, metres.
    pub sigma_m: Vec<f64>,
    /// Each re-solve of the graph of the run so far ([`FuseConfig::online_resolve`]).
    pub resolves: Vec<OnlineResolve>,
    /// Visual turns fused.
    pub visual_fused: usize,
    /// Visual turns gated out.
    pub visual_rejected: usize,
}

/// One re-solve of the online graph: what the filter took from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnlineResolve {
    /// When, seconds (an odometry time).
    pub t_s: f64,
    /// The odometry calibration found (the filter predicts with it from then on).
    pub odometry_calibration: OdometryCalibration,
    /// How far the solve moved the filter's pose, metres.
    pub moved_m: f64,
    /// How far it turned the filter's heading, radians.
    pub turned_rad: f64,
}

/// Odometry noise of one increment, in the frame of its start.
fn odometry_covariance(path_m: f64, turn_rad: f64, config: &FuseConfig) -> Matrix3<f64> {
    let vt = config.odometry_sigma_m_per_sqrt_m.powi(2) * path_m;
    let vh = config.heading_sigma_per_sqrt_rad.powi(2) * turn_rad
        + config.heading_sigma_per_sqrt_m.powi(2) * path_m;
    Matrix3::from_diagonal(&Vector3::new(vt + 1e-12, vt + 1e-12, vh + 1e-12))
}

/// The EKF state: pose first, then three numbers per landmark.
struct Ekf {
    x: DVector<f64>,
    p: DMatrix<f64>,
    slots: Vec<(String, u32)>,
}

impl Ekf {
    /// A filter sure of its start pose (the run's first odometry pose, the survey's anchor).
    fn at_start(odometry: &[StampedPose]) -> (Self, Pose2) {
        let start = odometry
            .first()
            .map_or(Pose2::new(0.0, 0.0, 0.0), |p| p.pose);
        let ekf = Self {
            x: DVector::from_vec(vec![start.x, start.y, start.theta]),
            p: DMatrix::identity(3, 3) * 1e-9,
            slots: Vec::new(),
        };
        (ekf, start)
    }

    /// Predicts with the odometry increment from `last` to `to` and moves `last` on; returns the
    /// distance travelled.
    fn advance(&mut self, last: &mut Pose2, to: Pose2, config: &FuseConfig) -> f64 {
        self.advance_calibrated(last, to, None, config)
    }

    /// [`Ekf::advance`] with the increment corrected by an odometry calibration.
    fn advance_calibrated(
        &mut self,
        last: &mut Pose2,
        to: Pose2,
        calibration: Option<&OdometryCalibration>,
        config: &FuseConfig,
    ) -> f64 {
        let mut delta = last.between(&to);
        let path = delta.x.hypot(delta.y);
        if let Some(c) = calibration {
            delta.theta = wrap_angle(delta.theta);
            delta = c.correct(delta, delta.theta, path);
        }
        let q = odometry_covariance(path, wrap_angle(delta.theta).abs(), config);
        self.predict(&delta, &q);
        *last = to;
        path
    }

    /// The landmarks the filter holds, in slot order.
    fn landmarks(&self, extras: &[Extras]) -> Vec<Landmark> {
        self.slots
            .iter()
            .enumerate()
            .map(|(slot, key)| {
                let (xy, cov) = self.landmark_xy_cov(slot);
                landmark_from(key, xy, self.x[3 + 3 * slot + 2], &cov, &extras[slot])
            })
            .collect()
    }

    /// Position sigma of the pose (√ of the largest eigenvalue), metres.
    fn position_sigma_m(&self) -> f64 {
        let pos = self.p.fixed_view::<2, 2>(0, 0).into_owned();
        pos.symmetric_eigenvalues().max().max(0.0).sqrt()
    }

    fn pose(&self) -> Pose2 {
        Pose2::new(self.x[0], self.x[1], self.x[2])
    }

    fn slot(&self, key: &(String, u32)) -> Option<usize> {
        self.slots.iter().position(|k| k == key)
    }

    fn predict(&mut self, delta: &Pose2, q: &Matrix3<f64>) {
        let (s, c) = self.x[2].sin_cos();
        let f = Matrix3::new(
            1.0,
            0.0,
            -s * delta.x - c * delta.y,
            0.0,
            1.0,
            c * delta.x - s * delta.y,
            0.0,
            0.0,
            1.0,
        );
        let g = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
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
    fn observe(&self, slot: usize) -> (Vector3<f64>, DMatrix<f64>) {
        let i = 3 + 3 * slot;
        let (s, c) = self.x[2].sin_cos();
        let d = Vector2::new(self.x[i] - self.x[0], self.x[i + 1] - self.x[1]);
        let h = Vector3::new(
            c * d.x + s * d.y,
            -s * d.x + c * d.y,
            wrap_angle(self.x[i + 2] - self.x[2]),
        );
        let mut jac = DMatrix::zeros(3, self.x.len());
        jac[(0, 0)] = -c;
        jac[(0, 1)] = -s;
        jac[(1, 0)] = s;
        jac[(1, 1)] = -c;
        jac[(0, 2)] = -s * d.x + c * d.y;
        jac[(1, 2)] = -c * d.x - s * d.y;
        jac[(2, 2)] = -1.0;
        jac[(0, i)] = c;
        jac[(0, i + 1)] = s;
        jac[(1, i)] = -s;
        jac[(1, i + 1)] = c;
        jac[(2, i + 2)] = 1.0;
        (h, jac)
    }

    /// Innovation, its covariance and the Jacobian of a sighting of landmark `slot`.
    fn innovation(
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

    fn update(&mut self, y: &Vector3<f64>, s: &Matrix3<f64>, jac: &DMatrix<f64>, r: &Matrix3<f64>) {
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

    /// Updates the pose with one scalar measurement: innovation `y`, Jacobian `h` over the pose,
    /// noise variance `r`, after a χ² gate; returns whether it was fused.
    fn update_scalar(&mut self, y: f64, h: &Vector3<f64>, r: f64, gate_chi2: f64) -> bool {
        let ph = self.p.columns(0, 3) * h;
        let s = h.dot(&ph.rows(0, 3)) + r;
        if s.is_nan() || s <= 0.0 || y * y / s > gate_chi2 {
            return false;
        }
        let k = &ph / s;
        self.x += &k * y;
        self.x[2] = wrap_angle(self.x[2]);
        // Joseph form, written for one row: P - K h'P - P h K' + K (h'Ph + r) K'.
        self.p = &self.p - &k * ph.transpose() - &ph * k.transpose() + &k * k.transpose() * s;
        true
    }

    /// Whether the state ends with a copy of the heading ([`Ekf::clone_heading`]).
    fn has_clone(&self) -> bool {
        self.x.len() == 3 + 3 * self.slots.len() + 1
    }

    /// Appends a copy of the current heading to the state (replacing an older one), so that a
    /// turn measured from now on can be fused when it ends (stochastic cloning).
    fn clone_heading(&mut self) {
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
    fn drop_clone(&mut self) {
        if self.has_clone() {
            let n = self.x.len() - 1;
            self.x = self.x.rows(0, n).into_owned();
            self.p = self.p.view((0, 0), (n, n)).into_owned();
        }
    }

    /// Updates with a turn measured since the heading was cloned: `turn` with variance `var`,
    /// after a χ² gate; returns whether it was fused (false also without a clone).
    fn update_turn(&mut self, turn: f64, var: f64, gate_chi2: f64) -> bool {
        if !self.has_clone() {
            return false;
        }
        let c = self.x.len() - 1;
        let y = wrap_angle(turn - (self.x[2] - self.x[c]));
        let ph = self.p.column(2) - self.p.column(c);
        let s = ph[2] - ph[c] + var;
        if s.is_nan() || s <= 0.0 || y * y / s > gate_chi2 {
            return false;
        }
        let k = &ph / s;
        self.x += &k * y;
        self.x[2] = wrap_angle(self.x[2]);
        self.x[c] = wrap_angle(self.x[c]);
        // Joseph form for one row, as in `update_scalar`.
        self.p = &self.p - &k * ph.transpose() - &ph * k.transpose() + &k * k.transpose() * s;
        true
    }

    /// Adds a landmark at the sighting seen from the current pose; returns its slot.
    fn add(&mut self, key: (String, u32), z: &Vector3<f64>, r: &Matrix3<f64>) -> usize {
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
        let gp = Matrix3::new(
            1.0,
            0.0,
            -s * z.x - c * z.y,
            0.0,
            1.0,
            c * z.x - s * z.y,
            0.0,
            0.0,
            1.0,
        );
        let gz = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
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

    fn landmark_xy_cov(&self, slot: usize) -> (Vector2<f64>, Matrix2<f64>) {
        let i = 3 + 3 * slot;
        (
            Vector2::new(self.x[i], self.x[i + 1]),
            self.p.fixed_view::<2, 2>(i, i).into_owned(),
        )
    }
}

/// Matches a landmark at `xy` with covariance `cov` to the nearest Hough corner within the gate.
pub fn associate(
    xy: &Vector2<f64>,
    cov: &Matrix2<f64>,
    corners: &[Feature],
    config: &FuseConfig,
) -> Option<CornerMatch> {
    let s = cov + Matrix2::identity() * config.corner_sigma_m.powi(2);
    let s_inv = s.try_inverse()?;
    corners
        .iter()
        .map(|f| {
            let d = Vector2::new(f.x_m - xy.x, f.y_m - xy.y);
            (f, (d.transpose() * s_inv * d)[0])
        })
        .filter(|(_, d2)| *d2 <= config.association_chi2)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(f, d2)| CornerMatch {
            x_m: f.x_m,
            y_m: f.y_m,
            votes: f.votes,
            distance_chi2: d2,
        })
}

/// Per-landmark running sums of what the planar state does not hold.
#[derive(Default, Clone)]
struct Extras {
    z_sum: f64,
    z_sq: f64,
    size_sum: f64,
    n: usize,
    corner: Option<CornerMatch>,
}

/// Travel between two re-solves of the online graph, at least (metres; see
/// [`FuseConfig::online_resolve`]).
const RESOLVE_MIN_TRAVEL_M: f64 = 5.0;
/// Travel between two re-solves of the online graph as a share of the travel so far, at least:
/// the solves grow with the run, so they come less often as it goes on (about eight on the
/// museum's 165 m, 0.17 s in all; with 0.1 instead of 0.25 there are fourteen, 0.31 s, for an
/// online ATE within 1 cm of this one's on the office and museum sample runs).
const RESOLVE_SHARE: f64 = 0.25;

/// Runs the online filter over odometry and time-ordered sightings; `corners` are the Hough
/// features a new landmark is matched with.
pub fn run_online(
    odometry: &[StampedPose],
    sightings: &[TagSighting],
    corners: &[Feature],
    config: &FuseConfig,
) -> OnlineResult {
    run_online_calibrated(odometry, &[], sightings, corners, config, None)
}

/// What the online filter does at a moment of the run, in the order it does them at one time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Event {
    /// A visual turn ends: fuse it.
    TurnEnds(usize),
    /// A tag sighting.
    Sighting(usize),
    /// A visual turn starts: copy the heading.
    TurnStarts(usize),
}

/// The sightings and, when `config` uses them, the visual turns that start at or after `from_t_s`
/// (the odometry's first time) as events in time order.
fn events(
    sightings: &[TagSighting],
    visual: &[VisualTurn],
    from_t_s: f64,
    config: &FuseConfig,
) -> Vec<(f64, Event)> {
    let mut events: Vec<(f64, Event)> = sightings
        .iter()
        .enumerate()
        .map(|(k, s)| (s.t_s, Event::Sighting(k)))
        .collect();
    if config.visual_odometry {
        for (j, v) in visual
            .iter()
            .enumerate()
            .filter(|(_, v)| v.from_t_s >= from_t_s)
        {
            events.push((v.from_t_s, Event::TurnStarts(j)));
            events.push((v.to_t_s, Event::TurnEnds(j)));
        }
    }
    events.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    events
}

/// [`run_online`] with the turns the cameras measured (`visual`, fused as they end) and
/// predicting from the start with `calibration` (the same robot's odometry errors found by an
/// earlier survey) until a re-solve finds the run's own.
pub fn run_online_calibrated(
    odometry: &[StampedPose],
    visual: &[VisualTurn],
    sightings: &[TagSighting],
    corners: &[Feature],
    config: &FuseConfig,
    calibration: Option<OdometryCalibration>,
) -> OnlineResult {
    let (mut ekf, start) = Ekf::at_start(odometry);
    let mut extras: Vec<Extras> = Vec::new();
    let mut result = OnlineResult {
        trajectory: Vec::with_capacity(odometry.len()),
        landmarks: Vec::new(),
        accepted: Vec::new(),
        rejected: Vec::new(),
        conflicts: Vec::new(),
        pose_at_sighting: vec![start; sightings.len()],
        nis: Vec::new(),
        sigma_m: Vec::with_capacity(odometry.len()),
        resolves: Vec::new(),
        visual_fused: 0,
        visual_rejected: 0,
    };
    let mut last_odom = start;
    let first_t = odometry.first().map_or(f64::NEG_INFINITY, |p| p.t_s);
    let mut pending = events(sightings, visual, first_t, config)
        .into_iter()
        .peekable();
    // The visual turn whose start the heading copy holds.
    let mut cloned_for: Option<usize> = None;
    let prior = calibration;
    let mut calibration = calibration;
    let (mut travel, mut travel_at_solve) = (0.0, 0.0);
    let resolve = config.online_resolve && config.calibrate_odometry;
    for (i, sample) in odometry.iter().enumerate() {
        let mut seen_again = false;
        while let Some(&(t, event)) = pending.peek() {
            if t > sample.t_s {
                break;
            }
            pending.next();
            let odom = pose_at(odometry, t).unwrap_or(sample.pose);
            travel += ekf.advance_calibrated(&mut last_odom, odom, calibration.as_ref(), config);
            match event {
                Event::TurnStarts(j) => {
                    ekf.clone_heading();
                    cloned_for = Some(j);
                }
                Event::TurnEnds(j) => {
                    if cloned_for == Some(j) {
                        let v = &visual[j];
                        let var = v.sigma_rad * v.sigma_rad;
                        if ekf.update_turn(v.turn_rad, var, config.visual_gate_chi2) {
                            result.visual_fused += 1;
                        } else {
                            result.visual_rejected += 1;
                        }
                    }
                    ekf.drop_clone();
                    cloned_for = None;
                }
                Event::Sighting(k) => {
                    result.pose_at_sighting[k] = ekf.pose();
                    let known = ekf.slot(&sightings[k].key()).is_some();
                    let fused = fuse_sighting(
                        &mut ekf,
                        &mut extras,
                        &sightings[k],
                        k,
                        corners,
                        config,
                        &mut result,
                    );
                    seen_again |= known && fused;
                }
            }
        }
        travel += ekf.advance_calibrated(&mut last_odom, sample.pose, calibration.as_ref(), config);
        result.trajectory.push(StampedPose {
            t_s: sample.t_s,
            pose: ekf.pose(),
        });
        result.sigma_m.push(ekf.position_sigma_m());
        let since = travel - travel_at_solve;
        if resolve && seen_again && since >= RESOLVE_MIN_TRAVEL_M.max(RESOLVE_SHARE * travel) {
            travel_at_solve = travel;
            let so_far = OnlineResult {
                landmarks: ekf.landmarks(&extras),
                ..result.clone()
            };
            let solved = run_offline_with_prior(
                &odometry[..=i],
                visual,
                sightings,
                &so_far,
                config,
                prior.as_ref(),
            );
            if let (Some(c), Some(now)) = (solved.odometry_calibration, solved.trajectory.last()) {
                let was = ekf.pose();
                result.resolves.push(OnlineResolve {
                    t_s: sample.t_s,
                    odometry_calibration: c,
                    moved_m: (now.pose.x - was.x).hypot(now.pose.y - was.y),
                    turned_rad: wrap_angle(now.pose.theta - was.theta),
                });
                if let Some(last) = result.trajectory.last_mut() {
                    last.pose = now.pose;
                }
                calibration = Some(c);
                ekf.x[0] = now.pose.x;
                ekf.x[1] = now.pose.y;
                ekf.x[2] = now.pose.theta;
                for (slot, l) in solved.landmarks.iter().enumerate() {
                    ekf.x[3 + 3 * slot] = l.position_m[0];
                    ekf.x[3 + 3 * slot + 1] = l.position_m[1];
                    ekf.x[3 + 3 * slot + 2] = l.yaw_rad;
                }
                // The heading copy belongs to the state before the solve: the turn under way
                // is left to the next solve.
                ekf.drop_clone();
                cloned_for = None;
            }
        }
    }
    // Sightings after the last odometry sample: fused at the last pose.
    for (_, event) in pending {
        if let Event::Sighting(k) = event {
            result.pose_at_sighting[k] = ekf.pose();
            fuse_sighting(
                &mut ekf,
                &mut extras,
                &sightings[k],
                k,
                corners,
                config,
                &mut result,
            );
        }
    }
    result.landmarks = ekf.landmarks(&extras);
    result.conflicts = find_conflicts(sightings, &result, config);
    result
}

fn landmark_from(
    key: &(String, u32),
    xy: Vector2<f64>,
    yaw: f64,
    cov: &Matrix2<f64>,
    extra: &Extras,
) -> Landmark {
    let n = extra.n.max(1) as f64;
    let z = extra.z_sum / n;
    let var_z = (extra.z_sq / n - z * z).max(0.0) / n + 1e-6;
    Landmark {
        id: key.1,
        family: key.0.clone(),
        size_m: extra.size_sum / n,
        position_m: [xy.x, xy.y, z],
        yaw_rad: wrap_angle(yaw),
        covariance_m2: [
            [cov[(0, 0)], cov[(0, 1)], 0.0],
            [cov[(1, 0)], cov[(1, 1)], 0.0],
            [0.0, 0.0, var_z],
        ],
        observations: extra.n,
        matched_corner: extra.corner,
    }
}

/// Fuses one sighting (a new landmark, or an update when it passes the gate); true when fused.
fn fuse_sighting(
    ekf: &mut Ekf,
    extras: &mut Vec<Extras>,
    sighting: &TagSighting,
    index: usize,
    corners: &[Feature],
    config: &FuseConfig,
    result: &mut OnlineResult,
) -> bool {
    let (z, r) = sighting.measurement(config);
    let key = sighting.key();
    let slot = match ekf.slot(&key) {
        Some(slot) => {
            let (y, s, jac) = ekf.innovation(slot, &z, &r);
            let Some(s_inv) = s.try_inverse() else {
                result.rejected.push(index);
                return false;
            };
            let d2 = (y.transpose() * s_inv * y)[0];
            if d2 > config.gate_chi2 {
                result.rejected.push(index);
                return false;
            }
            ekf.update(&y, &s, &jac, &r);
            result.nis.push((sighting.t_s, d2));
            slot
        }
        None => {
            let slot = ekf.add(key, &z, &r);
            let (xy, cov) = ekf.landmark_xy_cov(slot);
            extras.push(Extras {
                corner: associate(&xy, &cov, corners, config),
                ..Extras::default()
            });
            slot
        }
    };
    let e = &mut extras[slot];
    let zr = sighting.position_in_robot_m[2];
    e.z_sum += zr;
    e.z_sq += zr * zr;
    e.size_sum += sighting.size_m;
    e.n += 1;
    result.accepted.push(index);
    true
}

/// Groups gated-out sightings by place and reports the places seen often enough.
fn find_conflicts(
    sightings: &[TagSighting],
    online: &OnlineResult,
    config: &FuseConfig,
) -> Vec<Conflict> {
    let mut places: Vec<(usize, Vec<usize>, Vector2<f64>)> = Vec::new(); // (landmark, members, sum)
    for &k in &online.rejected {
        let s = &sightings[k];
        let Some(l) = online
            .landmarks
            .iter()
            .position(|l| l.id == s.id && l.family == s.family)
        else {
            continue;
        };
        let world = online.pose_at_sighting[k].transform_point(nalgebra::Point2::new(
            s.position_in_robot_m[0],
            s.position_in_robot_m[1],
        ));
        let w = Vector2::new(world.x, world.y);
        match places.iter_mut().find(|(pl, members, sum)| {
            *pl == l && (sum / members.len() as f64 - w).norm() <= config.conflict_radius_m
        }) {
            Some((_, members, sum)) => {
                members.push(k);
                *sum += w;
            }
            None => places.push((l, vec![k], w)),
        }
    }
    places
        .into_iter()
        .filter(|(l, members, sum)| {
            let at = sum / members.len() as f64;
            let lm = &online.landmarks[*l].position_m;
            members.len() >= config.conflict_min_sightings
                && (at - Vector2::new(lm[0], lm[1])).norm() >= config.conflict_min_distance_m
        })
        .map(|(l, members, sum)| {
            let lm = &online.landmarks[l];
            let first_t_s = members
                .iter()
                .map(|&k| sightings[k].t_s)
                .fold(f64::INFINITY, f64::min);
            let seen_again = online.accepted.iter().any(|&k| {
                sightings[k].id == lm.id
                    && sightings[k].family == lm.family
                    && sightings[k].t_s > first_t_s
            });
            let at = sum / members.len() as f64;
            Conflict {
                id: lm.id,
                family: lm.family.clone(),
                kind: if seen_again { "duplicate id" } else { "moved" }.into(),
                landmark_m: [lm.position_m[0], lm.position_m[1]],
                seen_at_m: [at.x, at.y],
                sightings: members.len(),
                first_t_s,
            }
        })
        .collect()
}

/// The result of the offline pass.
#[derive(Debug, Clone)]
pub struct OfflineResult {
    /// Corrected pose at each odometry time.
    pub trajectory: Vec<StampedPose>,
    /// Landmarks from the graph (covariances from the online filter).
    pub landmarks: Vec<Landmark>,
    /// Keyframes of the graph.
    pub keyframes: usize,
    /// Factors of the graph.
    pub factors: usize,
    /// Whether the solver returned a solution (else the online estimate is kept).
    pub converged: bool,
    /// The odometry calibration found, when estimated and the solver converged.
    pub odometry_calibration: Option<OdometryCalibration>,
}

/// Systematic odometry errors as the offline pass estimates them: an odometry increment of
/// signed turn `dθ` over a path `ds` truly turned `dθ (1 + turn_scale_error) +
/// heading_drift_rad_per_m ds` and travelled `ds (1 + distance_scale_error)`. The same robot's
/// later runs can be corrected with it ([`OdometryCalibration::apply`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OdometryCalibration {
    /// Relative error of the turns (a wheel base off by 1% gives about 0.01).
    pub turn_scale_error: f64,
    /// Heading drift per metre travelled, radians (unequal wheel scales).
    pub heading_drift_rad_per_m: f64,
    /// Relative error of the distances.
    pub distance_scale_error: f64,
}

impl OdometryCalibration {
    /// An odometry increment `delta` (in the frame of its start) over `path_m` with signed turn
    /// `turn_rad`, corrected: the turn scaled and drift added, the translation turned by half the
    /// extra turn and scaled (the offline pass's own model of an interval).
    pub fn correct(&self, delta: Pose2, turn_rad: f64, path_m: f64) -> Pose2 {
        let [x, y, theta] = corrected_increment(
            [
                self.turn_scale_error,
                self.heading_drift_rad_per_m,
                self.distance_scale_error,
            ],
            [delta.x, delta.y, delta.theta],
            turn_rad,
            path_m,
        );
        Pose2::new(x, y, theta)
    }

    /// A whole odometry log corrected increment by increment, from the same first pose.
    pub fn apply(&self, odometry: &[StampedPose]) -> Vec<StampedPose> {
        let Some(first) = odometry.first() else {
            return Vec::new();
        };
        let mut pose = first.pose;
        let mut out = vec![*first];
        for w in odometry.windows(2) {
            let d = w[0].pose.between(&w[1].pose);
            let step = Pose2::new(d.x, d.y, wrap_angle(d.theta));
            pose = pose.compose(&self.correct(step, step.theta, d.x.hypot(d.y)));
            out.push(StampedPose {
                t_s: w[1].t_s,
                pose,
            });
        }
        out
    }
}

/// Whitened SE(2) between-factor: `r = S · (p0⁻¹ ∘ p1 ⊖ measured)`.
struct BetweenFactor {
    measured: [f64; 3],
    sqrt_info: [[f64; 3]; 3],
    /// Signed turn and path length of the interval, for the odometry calibration (when the
    /// factor has a third variable `[a, c, s]`: turn scale error, heading drift per metre, distance
    /// scale error; `dθ_true = dθ (1 + a) + c L`, `ds_true = ds (1 + s)`).
    turn_rad: f64,
    path_m: f64,
}

/// Whitened turn between two keyframes: `r = (θ1 − θ0 − measured) / σ`.
struct TurnFactor {
    measured: f64,
    sqrt_info: f64,
}

impl<T: sna::RealField> tiny_solver::factors::Factor<T> for TurnFactor {
    fn residual_func(&self, params: &[sna::DVector<T>]) -> sna::DVector<T> {
        let (a, b) = (&params[0], &params[1]);
        let r = angle(b[2].clone() - a[2].clone() - constant::<T>(self.measured));
        sna::DVector::from_vec(vec![r * constant::<T>(self.sqrt_info)])
    }
}

/// Whitened tag factor: `r = S · (h(pose, landmark) − z)`.
struct TagFactor {
    measured: [f64; 3],
    sqrt_info: [[f64; 3]; 3],
}

/// Whitened prior on a vector variable (first pose; corner priors on landmark x, y).
struct PriorFactor {
    measured: Vec<f64>,
    sqrt_info: Vec<f64>,
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
fn corrected_increment<T: sna::RealField>(
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
        let (s, c) = (p[2].clone().sin(), p[2].clone().cos());
        let dx = l[0].clone() - p[0].clone();
        let dy = l[1].clone() - p[1].clone();
        let rx = c.clone() * dx.clone() + s.clone() * dy.clone() - constant::<T>(self.measured[0]);
        let ry = -s * dx + c * dy - constant::<T>(self.measured[1]);
        let rt = angle(l[2].clone() - p[2].clone() - constant::<T>(self.measured[2]));
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
fn sqrt_information(cov: &Matrix3<f64>) -> [[f64; 3]; 3] {
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

/// Name of the odometry calibration variable of the offline graph.
const CALIBRATION: &str = "odometry_calibration";
/// Prior sigmas of the odometry calibration `[a, c, s]`: 5% turn scale, 0.02 rad/m heading drift,
/// 2% distance scale (weak: wheel errors of a few percent at most).
const CALIBRATION_PRIOR_SIGMA: [f64; 3] = [0.05, 0.02, 0.02];

/// One keyframe: the time, the odometry pose and the starting estimate.
struct Keyframe {
    t_s: f64,
    odom: Pose2,
    init: Pose2,
}

/// The method's a-posteriori pass: a pose graph over the whole run, started from `online`, with
/// the turns the cameras measured (`visual`) beside the odometry.
pub fn run_offline(
    odometry: &[StampedPose],
    visual: &[VisualTurn],
    sightings: &[TagSighting],
    online: &OnlineResult,
    config: &FuseConfig,
) -> OfflineResult {
    run_offline_with_prior(odometry, visual, sightings, online, config, None)
}

/// Prior sigmas of the odometry calibration when an earlier survey of the same robot gives it:
/// about what one survey's estimate scatters by (turn scale 0.0066-0.0106 for 0.0100 over the
/// office's and museum's sample runs, heading drift -0.0059 to -0.0082 for -0.0067 rad/m).
const CALIBRATION_FROM_SURVEY_SIGMA: [f64; 3] = [0.004, 0.002, 0.004];

/// [`run_offline`] with the odometry calibration's prior centred on `prior` (an earlier survey's)
/// instead of on no error.
fn run_offline_with_prior(
    odometry: &[StampedPose],
    visual: &[VisualTurn],
    sightings: &[TagSighting],
    online: &OnlineResult,
    config: &FuseConfig,
    prior: Option<&OdometryCalibration>,
) -> OfflineResult {
    let Some(first) = odometry.first() else {
        return OfflineResult {
            trajectory: Vec::new(),
            landmarks: online.landmarks.clone(),
            keyframes: 0,
            factors: 0,
            converged: false,
            odometry_calibration: None,
        };
    };
    // Keyframes: the odometry thinned by travel and turn, plus one at every fused sighting and at
    // both ends of every visual turn within the odometry.
    let end_t = odometry.last().map_or(first.t_s, |p| p.t_s);
    let visual: Vec<&VisualTurn> = visual
        .iter()
        .filter(|v| config.visual_odometry && v.from_t_s >= first.t_s && v.to_t_s <= end_t)
        .collect();
    let mut anchors: Vec<(f64, Option<usize>)> = online
        .accepted
        .iter()
        .map(|&k| (sightings[k].t_s, Some(k)))
        .chain(
            visual
                .iter()
                .flat_map(|v| [(v.from_t_s, None), (v.to_t_s, None)]),
        )
        .collect();
    anchors.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut keyframes: Vec<Keyframe> = Vec::new();
    let mut sighting_kf: HashMap<usize, usize> = HashMap::new();
    let mut time_kf: HashMap<u64, usize> = HashMap::new();
    let mut anchors = anchors.into_iter().peekable();
    let mut last_kf = first.pose;
    for (i, sample) in odometry.iter().enumerate() {
        while let Some(&(t, sighting)) = anchors.peek() {
            if t > sample.t_s && i + 1 < odometry.len() {
                break;
            }
            anchors.next();
            let odom = pose_at(odometry, t).unwrap_or(sample.pose);
            let same = keyframes.last().is_some_and(|kf| (kf.t_s - t).abs() < 1e-9);
            if !same {
                let init = match sighting {
                    Some(k) => online.pose_at_sighting[k],
                    None => pose_at(&online.trajectory, t).unwrap_or(odom),
                };
                keyframes.push(Keyframe { t_s: t, odom, init });
                last_kf = odom;
            }
            let kf = keyframes.len() - 1;
            time_kf.insert(t.to_bits(), kf);
            if let Some(k) = sighting {
                sighting_kf.insert(k, kf);
            }
        }
        let d = last_kf.between(&sample.pose);
        let is_end = i == 0 || i + 1 == odometry.len();
        if is_end
            || d.x.hypot(d.y) >= config.keyframe_spacing_m
            || wrap_angle(d.theta).abs() >= config.keyframe_turn_rad
        {
            if keyframes.last().is_some_and(|kf| kf.t_s >= sample.t_s) {
                continue;
            }
            keyframes.push(Keyframe {
                t_s: sample.t_s,
                odom: sample.pose,
                init: online.trajectory.get(i).map_or(sample.pose, |p| p.pose),
            });
            last_kf = sample.pose;
        }
    }

    let pose_name = |i: usize| format!("p{i}");
    let landmark_name = |i: usize| format!("l{i}");
    let mut problem = tiny_solver::Problem::new();
    let mut init: HashMap<String, sna::DVector<f64>> = HashMap::new();
    for (i, kf) in keyframes.iter().enumerate() {
        init.insert(
            pose_name(i),
            sna::DVector::from_vec(vec![kf.init.x, kf.init.y, kf.init.theta]),
        );
    }
    for (i, l) in online.landmarks.iter().enumerate() {
        init.insert(
            landmark_name(i),
            sna::DVector::from_vec(vec![l.position_m[0], l.position_m[1], l.yaw_rad]),
        );
    }
    let mut factors = 0;
    if config.calibrate_odometry {
        let (mean, sigma) = match prior {
            Some(c) => (
                vec![
                    c.turn_scale_error,
                    c.heading_drift_rad_per_m,
                    c.distance_scale_error,
                ],
                CALIBRATION_FROM_SURVEY_SIGMA,
            ),
            None => (vec![0.0; 3], CALIBRATION_PRIOR_SIGMA),
        };
        init.insert(CALIBRATION.into(), sna::DVector::from_vec(mean.clone()));
        problem.add_residual_block(
            3,
            &[CALIBRATION],
            Box::new(PriorFactor {
                measured: mean,
                sqrt_info: sigma.iter().map(|s| 1.0 / s).collect(),
            }),
            None,
        );
        factors += 1;
    }
    problem.add_residual_block(
        3,
        &[&pose_name(0)],
        Box::new(PriorFactor {
            measured: vec![first.pose.x, first.pose.y, first.pose.theta],
            sqrt_info: vec![1e3; 3],
        }),
        None,
    );
    factors += 1;
    // Odometry factors; path and turn summed over the samples between the keyframes.
    let mut sample = 0;
    for i in 1..keyframes.len() {
        let (a, b) = (&keyframes[i - 1], &keyframes[i]);
        let mut path = 0.0;
        let mut turn = 0.0;
        let mut signed_turn = 0.0;
        let mut prev = a.odom;
        while sample < odometry.len() && odometry[sample].t_s <= a.t_s {
            sample += 1;
        }
        let mut j = sample;
        while j < odometry.len() && odometry[j].t_s < b.t_s {
            let d = prev.between(&odometry[j].pose);
            path += d.x.hypot(d.y);
            turn += wrap_angle(d.theta).abs();
            signed_turn += wrap_angle(d.theta);
            prev = odometry[j].pose;
            j += 1;
        }
        let d = prev.between(&b.odom);
        path += d.x.hypot(d.y);
        turn += wrap_angle(d.theta).abs();
        signed_turn += wrap_angle(d.theta);
        let delta = a.odom.between(&b.odom);
        let cov = odometry_covariance(path, turn, config);
        let (p0, p1) = (pose_name(i - 1), pose_name(i));
        let mut vars: Vec<&str> = vec![&p0, &p1];
        if config.calibrate_odometry {
            vars.push(CALIBRATION);
        }
        problem.add_residual_block(
            3,
            &vars,
            Box::new(BetweenFactor {
                measured: [delta.x, delta.y, wrap_angle(delta.theta)],
                sqrt_info: sqrt_information(&cov),
                turn_rad: signed_turn,
                path_m: path,
            }),
            None,
        );
        factors += 1;
    }
    let slot_of: BTreeMap<(String, u32), usize> = online
        .landmarks
        .iter()
        .enumerate()
        .map(|(i, l)| ((l.family.clone(), l.id), i))
        .collect();
    for (&k, &kf) in &sighting_kf {
        let s = &sightings[k];
        let Some(&l) = slot_of.get(&s.key()) else {
            continue;
        };
        let (z, r) = s.measurement(config);
        problem.add_residual_block(
            3,
            &[&pose_name(kf), &landmark_name(l)],
            Box::new(TagFactor {
                measured: [z.x, z.y, z.z],
                sqrt_info: sqrt_information(&r),
            }),
            Some(Box::new(tiny_solver::loss_functions::HuberLoss::new(
                config.huber_sigma.max(1e-3),
            ))),
        );
        factors += 1;
    }
    for v in &visual {
        let (Some(&a), Some(&b)) = (
            time_kf.get(&v.from_t_s.to_bits()),
            time_kf.get(&v.to_t_s.to_bits()),
        ) else {
            continue;
        };
        if a == b {
            continue;
        }
        problem.add_residual_block(
            1,
            &[&pose_name(a), &pose_name(b)],
            Box::new(TurnFactor {
                measured: v.turn_rad,
                sqrt_info: 1.0 / v.sigma_rad.max(1e-6),
            }),
            Some(Box::new(tiny_solver::loss_functions::HuberLoss::new(
                config.huber_sigma.max(1e-3),
            ))),
        );
        factors += 1;
    }
    if config.corner_factors {
        for (i, l) in online.landmarks.iter().enumerate() {
            if let Some(c) = l.matched_corner {
                problem.add_residual_block(
                    2,
                    &[&landmark_name(i)],
                    Box::new(PriorFactor {
                        measured: vec![c.x_m, c.y_m],
                        sqrt_info: vec![1.0 / config.corner_sigma_m; 2],
                    }),
                    None,
                );
                factors += 1;
            }
        }
    }
    let options = tiny_solver::OptimizerOptions {
        max_iteration: config.max_iterations,
        ..Default::default()
    };
    use tiny_solver::Optimizer;
    let solution = tiny_solver::LevenbergMarquardtOptimizer::default().optimize(
        &problem,
        &init,
        Some(options),
    );
    let converged = solution.is_some();
    let values = solution.unwrap_or(init);
    let kf_pose = |i: usize| {
        values.get(&pose_name(i)).map_or(keyframes[i].init, |v| {
            Pose2::new(v[0], v[1], wrap_angle(v[2]))
        })
    };
    // Every odometry sample: the keyframe corrections (world_from_odometry) interpolated by
    // distance travelled between the keyframes around it.
    let corrections: Vec<Pose2> = (0..keyframes.len())
        .map(|i| kf_pose(i).compose(&keyframes[i].odom.inverse()))
        .collect();
    let mut trajectory = Vec::with_capacity(odometry.len());
    let mut kf = 0;
    for sample in odometry {
        while kf + 1 < keyframes.len() && keyframes[kf + 1].t_s < sample.t_s {
            kf += 1;
        }
        let correction = if kf + 1 < keyframes.len() && sample.t_s >= keyframes[kf].t_s {
            let (a, b) = (&keyframes[kf], &keyframes[kf + 1]);
            let span = a
                .odom
                .position()
                .coords
                .metric_distance(&b.odom.position().coords);
            let done = a
                .odom
                .position()
                .coords
                .metric_distance(&sample.pose.position().coords);
            let f = if span > 1e-9 {
                (done / span).clamp(0.0, 1.0)
            } else {
                ((sample.t_s - a.t_s) / (b.t_s - a.t_s).max(1e-9)).clamp(0.0, 1.0)
            };
            corrections[kf].lerp(&corrections[kf + 1], f)
        } else {
            corrections[kf.min(corrections.len() - 1)]
        };
        let pose = correction.compose(&sample.pose);
        trajectory.push(StampedPose {
            t_s: sample.t_s,
            pose: Pose2::new(pose.x, pose.y, wrap_angle(pose.theta)),
        });
    }
    let landmarks = online
        .landmarks
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let mut l = l.clone();
            if let Some(v) = values.get(&landmark_name(i)) {
                l.position_m[0] = v[0];
                l.position_m[1] = v[1];
                l.yaw_rad = wrap_angle(v[2]);
            }
            l
        })
        .collect();
    OfflineResult {
        trajectory,
        landmarks,
        keyframes: keyframes.len(),
        factors,
        converged,
        odometry_calibration: values
            .get(CALIBRATION)
            .filter(|_| converged && config.calibrate_odometry)
            .map(|v| OdometryCalibration {
                turn_scale_error: v[0],
                heading_drift_rad_per_m: v[1],
                distance_scale_error: v[2],
            }),
    }
}

/// The result of localising a new run against a saved survey.
#[derive(Debug, Clone)]
pub struct LocalizeResult {
    /// Filtered pose at each odometry time.
    pub trajectory: Vec<StampedPose>,
    /// Position sigma at each odometry time, metres.
    pub sigma_m: Vec<f64>,
    /// Distance travelled since the last fused sighting at each odometry time, metres.
    pub since_sighting_m: Vec<f64>,
    /// Sightings fused.
    pub accepted: Vec<usize>,
    /// Sightings gated out.
    pub rejected: Vec<usize>,
    /// Sightings of tags the survey does not hold.
    pub unknown: Vec<usize>,
    /// Each sonar range matched with a surveyed wall: its index in the run's readings, and whether
    /// it was fused (else gated out: a person, a moved object, an echo off the cone's edge).
    pub range_outcomes: Vec<(usize, bool)>,
    /// Times the filter was found lost and started again from the sightings (seconds): see
    /// [`RELOCALISE_AFTER`].
    pub relocalised_t_s: Vec<f64>,
    /// Visual turns fused.
    pub visual_fused: usize,
    /// Visual turns gated out.
    pub visual_rejected: usize,
}

/// Gated-out sightings in a row, each putting the robot where the others do (within
/// [`RELOCALISE_AGREE_M`] and [`RELOCALISE_AGREE_RAD`] once the odometry between them is
/// accounted for), after which the filter takes itself for lost and starts again from the last
/// of them (ours: 3; one or two can be blunders).
pub const RELOCALISE_AFTER: usize = 3;
/// How close the poses the gated-out sightings give must agree, metres.
pub const RELOCALISE_AGREE_M: f64 = 0.3;
/// How close their headings must agree, radians (about 6 degrees).
pub const RELOCALISE_AGREE_RAD: f64 = 0.1;

/// The robot pose a sighting of a surveyed landmark gives, with its covariance (the sighting's
/// and the landmark's position noise, and the heading's carried over the distance to the tag).
fn pose_from_sighting(s: &TagSighting, l: &Landmark, config: &FuseConfig) -> (Pose2, Matrix3<f64>) {
    let (z, r) = s.measurement(config);
    let theta = wrap_angle(l.yaw_rad - z.z);
    let (st, ct) = theta.sin_cos();
    let x = l.position_m[0] - (ct * z.x - st * z.y);
    let y = l.position_m[1] - (st * z.x + ct * z.y);
    let yaw_var = r[(2, 2)] + config.yaw_sigma_floor_rad.powi(2);
    let c = &l.covariance_m2;
    let pos_var =
        0.5 * (r[(0, 0)] + r[(1, 1)] + c[0][0] + c[1][1]) + (z.x * z.x + z.y * z.y) * yaw_var;
    (
        Pose2::new(x, y, theta),
        Matrix3::from_diagonal(&Vector3::new(pos_var, pos_var, yaw_var)),
    )
}

impl LocalizeResult {
    /// Sonar ranges fused against a surveyed wall.
    pub fn ranges_fused(&self) -> usize {
        self.range_outcomes.iter().filter(|r| r.1).count()
    }

    /// Sonar ranges matched with a surveyed wall that failed the gate.
    pub fn ranges_gated_out(&self) -> usize {
        self.range_outcomes.len() - self.ranges_fused()
    }
}

/// A run's sonar and the surveyed walls its ranges are matched against when localising.
#[derive(Debug, Clone, Copy)]
pub struct SonarInput<'a> {
    /// The run's readings.
    pub readings: &'a [SonarReading],
    /// Where the run's sonars sit.
    pub layout: &'a SonarLayout,
    /// The survey's walls (`walls_corrected.csv`).
    pub walls: &'a [WallSegment],
}

/// A wall face is used only when its normal is this far inside the beam's half-cone: 2 degrees
/// (outside the cone the echo comes off the cone's edge, longer than the perpendicular).
pub const WALL_CONE_MARGIN_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// ... and the foot of the perpendicular this far inside the face's ends: 5 cm.
pub const WALL_INSET_M: f64 = 0.05;

/// A sonar range matched with a surveyed wall face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallMatch {
    /// The face's index in [`SonarInput::walls`].
    pub wall: usize,
    /// The range measured, metres.
    pub range_m: f64,
    /// The range expected off the face from the pose given, metres.
    pub expected_m: f64,
}

/// The surveyed wall face a sonar range taken at `world_from_robot` is matched with, as
/// [`localize`] matches it: the nearest face whose normal lies [`WALL_CONE_MARGIN_RAD`] inside
/// the beam and whose foot of the perpendicular lies [`WALL_INSET_M`] inside its ends. `None`
/// for no echo, an echo at the sensor's largest range, an unknown sensor, no face in the beam,
/// or a nearest face beyond the sensor's largest range (it cannot have sent the echo).
pub fn wall_in_beam(
    sonar: &SonarInput<'_>,
    reading: &SonarReading,
    world_from_robot: Pose2,
) -> Option<WallMatch> {
    let range = reading.range_m?;
    let sensor = sonar.layout.sensors.get(reading.sensor)?;
    if range >= sonar.layout.max_range_m - 1e-6 {
        return None;
    }
    let at = world_from_robot.compose(&sensor.robot_from_sensor());
    let half = 0.5 * sonar.layout.cone_rad - WALL_CONE_MARGIN_RAD;
    sonar
        .walls
        .iter()
        .enumerate()
        .filter_map(|(i, w)| {
            w.expected_range([at.x, at.y], at.theta, half, WALL_INSET_M)
                .map(|expected_m| WallMatch {
                    wall: i,
                    range_m: range,
                    expected_m,
                })
        })
        .min_by(|a, b| a.expected_m.total_cmp(&b.expected_m))
        .filter(|m| m.expected_m < sonar.layout.max_range_m)
}

/// Fuses one sonar range against the nearest surveyed wall face in the beam; `Some(fused)` when
/// a face is in the beam, `None` when there is none (or the filter already knows its distance to
/// it better than the wall is known).
fn fuse_range(
    ekf: &mut Ekf,
    reading: &SonarReading,
    sonar: &SonarInput<'_>,
    config: &FuseConfig,
) -> Option<bool> {
    let pose = ekf.pose();
    let m = wall_in_beam(sonar, reading, pose)?;
    let (range, expected) = (m.range_m, m.expected_m);
    let wall = sonar.walls.get(m.wall)?;
    let sensor = sonar.layout.sensors.get(reading.sensor)?;
    // range = n . (p + R(theta) o) - offset.
    let n = wall.normal();
    let (st, ct) = pose.theta.sin_cos();
    let (ox, oy) = (sensor.x_m, sensor.y_m);
    let h = Vector3::new(
        n[0],
        n[1],
        n[0] * (-st * ox - ct * oy) + n[1] * (ct * ox - st * oy),
    );
    let known = (h.transpose() * ekf.p.fixed_view::<3, 3>(0, 0) * h)[0];
    if known < config.wall_sigma_m.powi(2) || known > config.sonar_max_range_sigma_m.powi(2) {
        return None;
    }
    let r = (config.sonar_sigma_m + config.sonar_sigma_frac * range).powi(2)
        + config.wall_sigma_m.powi(2);
    Some(ekf.update_scalar(range - expected, &h, r, config.sonar_gate_chi2))
}

/// Tracks a run's pose against surveyed landmarks held fixed (their covariance is added to each
/// sighting's) and, with `sonar`, its ranges against the surveyed walls (each range whose beam
/// holds a wall face's normal measures the distance to it): the method's long-term use. The run
/// starts at its odometry's first pose in the survey's frame (the robot leaves from the same
/// place).
pub fn localize(
    odometry: &[StampedPose],
    visual: &[VisualTurn],
    sightings: &[TagSighting],
    landmarks: &[Landmark],
    sonar: Option<SonarInput<'_>>,
    config: &FuseConfig,
) -> LocalizeResult {
    let (mut ekf, start) = Ekf::at_start(odometry);
    let first_t = odometry.first().map_or(f64::NEG_INFINITY, |p| p.t_s);
    let mut pending = events(sightings, visual, first_t, config)
        .into_iter()
        .peekable();
    let mut cloned_for: Option<usize> = None;
    let mut ranges: Vec<(usize, &SonarReading)> =
        sonar.map_or(Vec::new(), |s| s.readings.iter().enumerate().collect());
    ranges.sort_by(|a, b| a.1.t_s.total_cmp(&b.1.t_s));
    let mut ranges = ranges.into_iter().peekable();
    let mut out = LocalizeResult {
        trajectory: Vec::with_capacity(odometry.len()),
        sigma_m: Vec::with_capacity(odometry.len()),
        since_sighting_m: Vec::with_capacity(odometry.len()),
        accepted: Vec::new(),
        rejected: Vec::new(),
        unknown: Vec::new(),
        range_outcomes: Vec::new(),
        relocalised_t_s: Vec::new(),
        visual_fused: 0,
        visual_rejected: 0,
    };
    let mut last = start;
    let mut travelled = 0.0;
    // Gated-out sightings since the last fused one: the pose each gives and the odometry then.
    let mut lost: Vec<(Pose2, Pose2)> = Vec::new();
    for sample in odometry {
        while let Some(&(t, event)) = pending.peek() {
            if t > sample.t_s {
                break;
            }
            pending.next();
            let odom = pose_at(odometry, t).unwrap_or(sample.pose);
            travelled += ekf.advance(&mut last, odom, config);
            let k = match event {
                Event::TurnStarts(j) => {
                    ekf.clone_heading();
                    cloned_for = Some(j);
                    continue;
                }
                Event::TurnEnds(j) => {
                    if cloned_for == Some(j) {
                        let v = &visual[j];
                        if ekf.update_turn(v.turn_rad, v.sigma_rad.powi(2), config.visual_gate_chi2)
                        {
                            out.visual_fused += 1;
                        } else {
                            out.visual_rejected += 1;
                        }
                    }
                    ekf.drop_clone();
                    cloned_for = None;
                    continue;
                }
                Event::Sighting(k) => k,
            };
            // A sighting updates the pose alone: a heading copy is let go (the turn under way is
            // not fused).
            ekf.drop_clone();
            cloned_for = None;
            let s = &sightings[k];
            let Some(l) = landmarks
                .iter()
                .find(|l| l.id == s.id && l.family == s.family)
            else {
                out.unknown.push(k);
                continue;
            };
            // The landmark as a fixed state slot: a pose-only filter with the landmark's
            // uncertainty moved into the measurement noise.
            let mut full = Ekf {
                x: DVector::from_vec(vec![
                    ekf.x[0],
                    ekf.x[1],
                    ekf.x[2],
                    l.position_m[0],
                    l.position_m[1],
                    l.yaw_rad,
                ]),
                p: DMatrix::zeros(6, 6),
                slots: vec![(l.family.clone(), l.id)],
            };
            full.p
                .fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&ekf.p.fixed_view::<3, 3>(0, 0));
            let c = &l.covariance_m2;
            full.p[(3, 3)] = c[0][0];
            full.p[(3, 4)] = c[0][1];
            full.p[(4, 3)] = c[1][0];
            full.p[(4, 4)] = c[1][1];
            full.p[(5, 5)] = config.yaw_sigma_floor_rad.powi(2);
            let (z, r) = s.measurement(config);
            let (y, sm, jac) = full.innovation(0, &z, &r);
            let d2 = sm
                .try_inverse()
                .map_or(f64::INFINITY, |si| (y.transpose() * si * y)[0]);
            if d2 > config.gate_chi2 {
                out.rejected.push(k);
                let (pose, cov) = pose_from_sighting(s, l, config);
                lost.push((pose, odom));
                let agree = lost.len() >= RELOCALISE_AFTER
                    && lost[lost.len() - RELOCALISE_AFTER..].iter().all(|(p, o)| {
                        let moved = p.compose(&o.between(&odom));
                        (moved.x - pose.x).hypot(moved.y - pose.y) <= RELOCALISE_AGREE_M
                            && wrap_angle(moved.theta - pose.theta).abs() <= RELOCALISE_AGREE_RAD
                    });
                if agree {
                    ekf.x[0] = pose.x;
                    ekf.x[1] = pose.y;
                    ekf.x[2] = pose.theta;
                    ekf.p.copy_from(&cov);
                    out.relocalised_t_s.push(s.t_s);
                    lost.clear();
                    travelled = 0.0;
                }
                continue;
            }
            full.update(&y, &sm, &jac, &r);
            ekf.x.copy_from(&full.x.rows(0, 3));
            ekf.p.copy_from(&full.p.view((0, 0), (3, 3)));
            out.accepted.push(k);
            lost.clear();
            travelled = 0.0;
        }
        travelled += ekf.advance(&mut last, sample.pose, config);
        // The sonar sampled with this odometry pose (or before it).
        while let Some((i, reading)) = ranges.next_if(|r| r.1.t_s <= sample.t_s) {
            if let Some(fused) = sonar.and_then(|s| fuse_range(&mut ekf, reading, &s, config)) {
                out.range_outcomes.push((i, fused));
            }
        }
        out.trajectory.push(StampedPose {
            t_s: sample.t_s,
            pose: ekf.pose(),
        });
        out.sigma_m.push(ekf.position_sigma_m());
        out.since_sighting_m.push(travelled);
    }
    out
}

/// Holds the end of a survey's offline trajectory, after its last fused sighting at `last_t_s`, to
/// walls mapped from the readings before it: from the offline pose there, the filter of
/// [`localize`] runs on the rest of the odometry (corrected with `calibration`, and then
/// predicted with [`FuseConfig::for_calibrated_odometry`] as `localize` does) with the ranges
/// taken after it. Until then the offline graph has nothing but odometry there. `sonar` holds the
/// run's readings and the walls; the trajectory is returned whole.
pub fn hold_tail_to_walls(
    odometry: &[StampedPose],
    visual: &[VisualTurn],
    offline: &[StampedPose],
    last_t_s: f64,
    calibration: Option<&OdometryCalibration>,
    sonar: SonarInput<'_>,
    config: &FuseConfig,
) -> Vec<StampedPose> {
    let start = odometry.partition_point(|p| p.t_s < last_t_s);
    if start + 1 >= odometry.len() || start >= offline.len() || sonar.walls.is_empty() {
        return offline.to_vec();
    }
    let tail = &odometry[start..];
    let tail = calibration.map_or_else(|| tail.to_vec(), |c| c.apply(tail));
    let anchor = offline[start].pose.compose(&tail[0].pose.inverse());
    let tail: Vec<StampedPose> = tail
        .iter()
        .map(|p| StampedPose {
            t_s: p.t_s,
            pose: anchor.compose(&p.pose),
        })
        .collect();
    let readings: Vec<SonarReading> = sonar
        .readings
        .iter()
        .filter(|r| r.t_s > tail[0].t_s)
        .copied()
        .collect();
    let held = localize(
        &tail,
        visual,
        &[],
        &[],
        Some(SonarInput {
            readings: &readings,
            ..sonar
        }),
        &match calibration {
            Some(_) => config.for_calibrated_odometry(),
            None => config.clone(),
        },
    );
    let mut out = offline[..start].to_vec();
    out.extend(held.trajectory);
    out
}

/// Error statistics of a localised run over one band of distance since the last sighting.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GrowthBin {
    /// Band start, metres travelled since the last fused sighting.
    pub from_m: f64,
    /// Band end, metres.
    pub to_m: f64,
    /// Odometry samples in the band.
    pub samples: usize,
    /// Mean filter sigma, metres.
    pub mean_sigma_m: f64,
    /// RMS position error against ground truth, metres (`None` without ground truth).
    pub rms_error_m: Option<f64>,
}

/// Bands of distance since the last sighting used by [`error_growth`], metres.
pub const GROWTH_BANDS_M: [f64; 7] = [0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0];

/// How the error grows with the distance travelled since the last sighting.
pub fn error_growth(result: &LocalizeResult, truth: Option<&[StampedPose]>) -> Vec<GrowthBin> {
    let mut bins: Vec<GrowthBin> = GROWTH_BANDS_M
        .iter()
        .enumerate()
        .map(|(i, &from_m)| GrowthBin {
            from_m,
            to_m: GROWTH_BANDS_M.get(i + 1).copied().unwrap_or(f64::INFINITY),
            samples: 0,
            mean_sigma_m: 0.0,
            rms_error_m: truth.map(|_| 0.0),
        })
        .collect();
    for (i, p) in result.trajectory.iter().enumerate() {
        let d = result.since_sighting_m.get(i).copied().unwrap_or(0.0);
        let Some(bin) = bins.iter_mut().find(|b| d >= b.from_m && d < b.to_m) else {
            continue;
        };
        bin.samples += 1;
        bin.mean_sigma_m += result.sigma_m.get(i).copied().unwrap_or(0.0);
        if let (Some(sum), Some(gt)) = (
            bin.rms_error_m.as_mut(),
            truth.and_then(|t| pose_at(t, p.t_s)),
        ) {
            *sum += (p.pose.x - gt.x).powi(2) + (p.pose.y - gt.y).powi(2);
        }
    }
    for b in &mut bins {
        let n = b.samples.max(1) as f64;
        b.mean_sigma_m /= n;
        b.rms_error_m = b.rms_error_m.map(|s| (s / n).sqrt());
    }
    bins.retain(|b| b.samples > 0);
    bins
}

/// The rigid motion `truth_from_estimate` that best aligns an estimate's positions with the truth
/// at the estimate's times (least squares, closed form), for diagnostics: what of an error is a
/// shift and turn of the whole survey, and what is shape.
pub fn align_se2(estimate: &[StampedPose], truth: &[StampedPose]) -> Option<Pose2> {
    let pairs: Vec<(Vector2<f64>, Vector2<f64>)> = estimate
        .iter()
        .filter_map(|p| {
            let t = pose_at(truth, p.t_s)?;
            Some((Vector2::new(p.pose.x, p.pose.y), Vector2::new(t.x, t.y)))
        })
        .collect();
    if pairs.len() < 2 {
        return None;
    }
    let n = pairs.len() as f64;
    let ca = pairs.iter().map(|p| p.0).sum::<Vector2<f64>>() / n;
    let cb = pairs.iter().map(|p| p.1).sum::<Vector2<f64>>() / n;
    let (mut sin, mut cos) = (0.0, 0.0);
    for (a, b) in &pairs {
        let (a, b) = (a - ca, b - cb);
        sin += a.x * b.y - a.y * b.x;
        cos += a.x * b.x + a.y * b.y;
    }
    let theta = sin.atan2(cos);
    let (s, c) = theta.sin_cos();
    let t = cb - Vector2::new(c * ca.x - s * ca.y, s * ca.x + c * ca.y);
    Some(Pose2::new(t.x, t.y, theta))
}

/// Root-mean-square position error of `estimate` against `truth` at the estimate's times (no
/// alignment: both start from the known start pose in the world frame).
pub fn ate_m(estimate: &[StampedPose], truth: &[StampedPose]) -> Option<f64> {
    let mut sum = 0.0;
    let mut n = 0usize;
    for p in estimate {
        let t = pose_at(truth, p.t_s)?;
        sum += (p.pose.x - t.x).powi(2) + (p.pose.y - t.y).powi(2);
        n += 1;
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_settings_are_valid_and_bad_ones_are_named() {
        assert_eq!(FuseConfig::default().validate(), Ok(()));
        let bad = FuseConfig {
            wall_sigma_m: f64::NAN,
            ..FuseConfig::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "wall_sigma_m");
        let bad = FuseConfig {
            max_iterations: 0,
            ..FuseConfig::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "max_iterations");
        let bad = FuseConfig {
            calibrated_heading_sigma_per_sqrt_rad: 0.0,
            ..FuseConfig::default()
        };
        assert_eq!(
            bad.validate().unwrap_err().key,
            "calibrated_heading_sigma_per_sqrt_rad"
        );
    }

    /// Calibrated odometry is predicted with the turn noise the calibration leaves, and only
    /// that setting changes.
    #[test]
    fn calibrated_odometry_has_its_own_turn_noise() {
        let config = FuseConfig {
            heading_sigma_per_sqrt_rad: 0.05,
            calibrated_heading_sigma_per_sqrt_rad: 0.02,
            ..FuseConfig::default()
        };
        let calibrated = config.for_calibrated_odometry();
        assert_eq!(calibrated.heading_sigma_per_sqrt_rad, 0.02);
        assert_eq!(
            FuseConfig {
                heading_sigma_per_sqrt_rad: 0.05,
                ..calibrated
            },
            config
        );
    }

    /// The calibration model matches the wheels: the office simulated with the default wheel
    /// errors and no random noise (wheel base 1% long: turns scaled by 1.01; wheels -0.1% and
    /// +0.1%: 2 x 0.001 / 0.3 m = 0.00667 rad of false turn per metre), corrected with those
    /// values, follows the truth.
    #[test]
    fn the_calibration_undoes_the_wheels_errors() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let world = crate::io::load_world(&root.join("samples/office/world.yaml"))
            .unwrap()
            .world;
        let mut config = crate::sim::SimConfig::default();
        config.odometry.random_m_per_sqrt_m = 0.0;
        config.exploration.duration_s = 300.0;
        let run = crate::sim::simulate(&world, &config, |_| {}).unwrap().run;
        let truth = run.ground_truth.as_deref().unwrap();
        let calibration = OdometryCalibration {
            turn_scale_error: config.odometry.wheel_base_error,
            heading_drift_rad_per_m: (config.odometry.left_scale_error
                - config.odometry.right_scale_error)
                / config.exploration.wheel_base_m,
            distance_scale_error: 0.0,
        };
        let raw = ate_m(&run.odometry, truth).unwrap();
        let corrected = ate_m(&calibration.apply(&run.odometry), truth).unwrap();
        assert!(raw > 0.1, "raw odometry ATE {raw}");
        assert!(corrected < 0.02, "corrected {corrected} (raw {raw})");
        // A calibration of nothing changes nothing.
        let none = OdometryCalibration {
            turn_scale_error: 0.0,
            heading_drift_rad_per_m: 0.0,
            distance_scale_error: 0.0,
        };
        assert!((ate_m(&none.apply(&run.odometry), truth).unwrap() - raw).abs() < 1e-9);
    }

    /// A robot driving 10 m along a wall 0.5 m to its left (odometry, truth, the left sonar's
    /// ranges), its odometry drifting 0.01 rad per metre to the right, and the wall's face.
    fn corridor() -> (
        crate::sonar::SonarLayout,
        WallSegment,
        Vec<StampedPose>,
        Vec<StampedPose>,
        Vec<SonarReading>,
    ) {
        let layout = crate::sonar::SonarLayout {
            name: "left".into(),
            cone_rad: 30f64.to_radians(),
            max_range_m: 2.1,
            sensors: vec![crate::sonar::SonarSensor {
                x_m: 0.0,
                y_m: 0.2,
                bearing_rad: std::f64::consts::FRAC_PI_2,
            }],
        };
        let wall = WallSegment {
            normal_rad: 1.5 * std::f64::consts::PI,
            offset_m: -0.5,
            from_m: [-1.0, 0.5],
            to_m: [11.0, 0.5],
            readings: 100,
            rms_m: 0.01,
        };
        let (mut odometry, mut truth, mut readings) = (Vec::new(), Vec::new(), Vec::new());
        let mut odom = Pose2::new(0.0, 0.0, 0.0);
        for k in 0..=200 {
            let t_s = k as f64;
            truth.push(StampedPose {
                t_s,
                pose: Pose2::new(0.05 * k as f64, 0.0, 0.0),
            });
            odometry.push(StampedPose { t_s, pose: odom });
            odom = odom.compose(&Pose2::new(0.05, 0.0, -0.0005));
            readings.push(SonarReading {
                t_s,
                sensor: 0,
                range_m: Some(0.3 + 0.004 * ((k * 7 % 5) as f64 - 2.0)),
            });
        }
        (layout, wall, odometry, truth, readings)
    }

    /// Along the corridor, with the wall's ranges (left sonar 0.2 m off centre) the filter stays
    /// on its line; without them it ends half a metre off.
    #[test]
    fn ranges_off_a_surveyed_wall_hold_the_robot_to_it() {
        let (layout, wall, odometry, truth, readings) = corridor();
        let sonar = SonarInput {
            readings: &readings,
            layout: &layout,
            walls: std::slice::from_ref(&wall),
        };
        let config = FuseConfig::default();
        let with = localize(&odometry, &[], &[], &[], Some(sonar), &config);
        let without = localize(&odometry, &[], &[], &[], None, &config);
        let end = |r: &LocalizeResult| r.trajectory.last().unwrap().pose.y;
        assert!(end(&without).abs() > 0.4, "{}", end(&without));
        assert!(end(&with).abs() < 0.03, "{}", end(&with));
        assert!(with.ranges_fused() > 10 && with.ranges_gated_out() == 0);
        assert!(ate_m(&with.trajectory, &truth).unwrap() < 0.03);
    }

    /// Given the robot's odometry errors by an earlier survey, the online filter tracks the first
    /// lap too, which it otherwise dead-reckons until the loop closes.
    #[test]
    fn an_earlier_surveys_calibration_helps_the_first_lap() {
        let (odom, truth, sightings, _) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let first_lap = |r: &OnlineResult| {
            let half = r.trajectory.len() / 2;
            ate_m(&r.trajectory[..half], &truth[..half]).unwrap()
        };
        // The square's wheels: turns 3% long, 0.01 rad of false turn and 1% more distance per metre.
        let known = OdometryCalibration {
            turn_scale_error: 1.0 / 1.03 - 1.0,
            heading_drift_rad_per_m: -0.01,
            distance_scale_error: 1.0 / 1.01 - 1.0,
        };
        let plain = first_lap(&run_online(&odom, &sightings, &[], &config));
        let given = first_lap(&run_online_calibrated(
            &odom,
            &[],
            &sightings,
            &[],
            &config,
            Some(known),
        ));
        assert!(
            given < 0.3 * plain,
            "first lap: {given} m given, {plain} m plain"
        );
    }

    /// A robot whose odometry jumps (a wheel slip, a kidnap) has its sightings gated out; three in
    /// a row that agree put it back where they say.
    #[test]
    fn a_lost_filter_starts_again_from_sightings_that_agree() {
        let (odom, truth, sightings, _) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let online = run_online(&odom, &sightings, &[], &config);
        let survey = run_offline(&odom, &[], &sightings, &online, &config);
        // Halfway round, the odometry jumps 1 m to the robot's left.
        let half = odom.len() / 2;
        let jump = odom[half].pose.compose(&Pose2::new(0.0, 1.0, 0.0));
        let jumped: Vec<StampedPose> = odom
            .iter()
            .enumerate()
            .map(|(i, p)| StampedPose {
                t_s: p.t_s,
                pose: if i < half {
                    p.pose
                } else {
                    jump.compose(&odom[half].pose.between(&p.pose))
                },
            })
            .collect();
        let result = localize(&jumped, &[], &sightings, &survey.landmarks, None, &config);
        assert_eq!(
            result.relocalised_t_s.len(),
            1,
            "{:?}",
            result.relocalised_t_s
        );
        assert!(result.relocalised_t_s[0] > odom[half].t_s);
        let (end, gt) = (
            result.trajectory.last().unwrap().pose,
            truth.last().unwrap().pose,
        );
        let error = (end.x - gt.x).hypot(end.y - gt.y);
        assert!(error < 0.05, "{error} m off at the end");
    }

    /// The face a range is matched with: the nearest one in the beam, none without an echo.
    #[test]
    fn a_range_is_matched_with_the_nearest_face_in_its_beam() {
        let (layout, wall, _, _, readings) = corridor();
        // A nearer face across the same beam, and a still nearer one behind the sensor (facing
        // it, but not in the beam's direction).
        let nearer = WallSegment {
            offset_m: -0.35,
            from_m: [2.0, 0.35],
            to_m: [4.0, 0.35],
            ..wall
        };
        let behind = WallSegment {
            normal_rad: 0.5 * std::f64::consts::PI,
            offset_m: 0.0,
            from_m: [-1.0, 0.0],
            to_m: [11.0, 0.0],
            ..wall
        };
        let walls = [wall, nearer, behind];
        let sonar = SonarInput {
            readings: &readings,
            layout: &layout,
            walls: &walls,
        };
        let reading = readings[0];
        let m = wall_in_beam(&sonar, &reading, Pose2::new(0.0, 0.0, 0.0)).unwrap();
        assert_eq!(m.wall, 0);
        assert!((m.expected_m - 0.3).abs() < 1e-12, "{m:?}");
        assert_eq!(m.range_m, reading.range_m.unwrap());
        let m = wall_in_beam(&sonar, &reading, Pose2::new(3.0, 0.0, 0.0)).unwrap();
        assert_eq!(m.wall, 1);
        assert!((m.expected_m - 0.15).abs() < 1e-12, "{m:?}");
        // Past the nearer face's end (less its inset) the far wall is matched again.
        let m = wall_in_beam(&sonar, &reading, Pose2::new(3.97, 0.0, 0.0)).unwrap();
        assert_eq!(m.wall, 0);
        // Turned 20 degrees, the wall's normal is outside the beam less its margin.
        assert_eq!(
            wall_in_beam(&sonar, &reading, Pose2::new(0.0, 0.0, 20f64.to_radians())),
            None
        );
        let none = SonarReading {
            range_m: None,
            ..reading
        };
        assert_eq!(wall_in_beam(&sonar, &none, Pose2::new(0.0, 0.0, 0.0)), None);
        let at_max = SonarReading {
            range_m: Some(layout.max_range_m),
            ..reading
        };
        assert_eq!(
            wall_in_beam(&sonar, &at_max, Pose2::new(0.0, 0.0, 0.0)),
            None
        );
        // A face beyond the sensor's reach cannot have sent the echo.
        let far = WallSegment {
            offset_m: wall.offset_m - layout.max_range_m,
            from_m: [-1.0, 0.5 + layout.max_range_m],
            to_m: [11.0, 0.5 + layout.max_range_m],
            ..wall
        };
        let m = far.expected_range([0.0, 0.2], 0.5 * std::f64::consts::PI, 0.1, 0.0);
        assert!(m.is_some_and(|e| e > layout.max_range_m), "{m:?}");
        let beyond = SonarInput {
            walls: std::slice::from_ref(&far),
            ..sonar
        };
        assert_eq!(
            wall_in_beam(&beyond, &reading, Pose2::new(0.0, 0.0, 0.0)),
            None
        );
        let unknown = SonarReading {
            sensor: 3,
            ..reading
        };
        assert_eq!(
            wall_in_beam(&sonar, &unknown, Pose2::new(0.0, 0.0, 0.0)),
            None
        );
    }

    /// A range is not fused while the filter knows its distance to the wall worse than
    /// `sonar_max_range_sigma_m`: the face it would be matched with may be the wrong one.
    #[test]
    fn a_lost_filter_does_not_fuse_ranges() {
        let (layout, wall, odometry, _, readings) = corridor();
        let sonar = SonarInput {
            readings: &readings,
            layout: &layout,
            walls: std::slice::from_ref(&wall),
        };
        let config = FuseConfig::default();
        for (sigma, fused) in [(0.05, true), (0.5, false)] {
            let (mut ekf, _) = Ekf::at_start(&odometry);
            ekf.p = DMatrix::identity(3, 3) * (sigma * sigma);
            ekf.p[(2, 2)] = 1e-6;
            let before = ekf.x.clone();
            let outcome = fuse_range(&mut ekf, &readings[0], &sonar, &config);
            assert_eq!(outcome.is_some(), fused, "sigma {sigma}: {outcome:?}");
            assert_eq!(ekf.x == before, !fused, "sigma {sigma}");
        }
    }

    /// A survey whose last sighting came 2 m into the corridor: its offline trajectory is right
    /// until then and drifts after; held to the wall, the end stays on the line and the part
    /// before the sighting is kept as it was.
    #[test]
    fn the_tail_after_the_last_sighting_is_held_to_the_walls() {
        let (layout, wall, odometry, truth, readings) = corridor();
        let last_t_s = 40.0;
        let k = 40;
        let anchor = truth[k].pose.compose(&odometry[k].pose.inverse());
        let offline: Vec<StampedPose> = (0..odometry.len())
            .map(|i| {
                if i <= k {
                    truth[i]
                } else {
                    StampedPose {
                        t_s: odometry[i].t_s,
                        pose: anchor.compose(&odometry[i].pose),
                    }
                }
            })
            .collect();
        let sonar = SonarInput {
            readings: &readings,
            layout: &layout,
            walls: std::slice::from_ref(&wall),
        };
        let held = hold_tail_to_walls(
            &odometry,
            &[],
            &offline,
            last_t_s,
            None,
            sonar,
            &FuseConfig::default(),
        );
        assert_eq!(held.len(), offline.len());
        assert_eq!(&held[..k], &offline[..k]);
        let end = |t: &[StampedPose]| t.last().unwrap().pose.y;
        assert!(end(&offline).abs() > 0.3, "{}", end(&offline));
        assert!(end(&held).abs() < 0.03, "{}", end(&held));
    }

    /// A square loop driven with a biased odometry, a tag at each corner seen from near it.
    fn square_run(
        bias: f64,
        laps: usize,
    ) -> (
        Vec<StampedPose>,
        Vec<StampedPose>,
        Vec<TagSighting>,
        Vec<[f64; 3]>,
    ) {
        let tags = vec![
            [5.0, 0.0, std::f64::consts::PI],
            [5.0, 5.0, -std::f64::consts::FRAC_PI_2],
            [0.0, 5.0, 0.0],
            [0.0, 0.0, std::f64::consts::FRAC_PI_2],
        ];
        let mut truth = Vec::new();
        let mut odom = Vec::new();
        let mut t = 0.0;
        let mut gt = Pose2::new(0.5, 0.5, 0.0);
        let mut od = gt;
        for _ in 0..4 * laps {
            {
                for _ in 0..40 {
                    let step = Pose2::new(0.1, 0.0, 0.0);
                    gt = gt.compose(&step);
                    od = od.compose(&Pose2::new(0.1 * (1.0 + bias), 0.0, bias * 0.1));
                    t += 1.0;
                    truth.push(StampedPose { t_s: t, pose: gt });
                    odom.push(StampedPose { t_s: t, pose: od });
                }
                for _ in 0..10 {
                    let step = Pose2::new(0.0, 0.0, std::f64::consts::FRAC_PI_2 / 10.0);
                    gt = gt.compose(&step);
                    od = od.compose(&Pose2::new(0.0, 0.0, step.theta * (1.0 + 3.0 * bias)));
                    t += 1.0;
                    truth.push(StampedPose { t_s: t, pose: gt });
                    odom.push(StampedPose { t_s: t, pose: od });
                }
            }
        }
        let mut sightings = Vec::new();
        for (i, p) in truth.iter().enumerate().step_by(5) {
            for (id, tag) in tags.iter().enumerate() {
                let local = p
                    .pose
                    .inverse()
                    .transform_point(nalgebra::Point2::new(tag[0], tag[1]));
                let range = local.coords.norm();
                if range > 3.5 || local.x < 0.3 || local.y.abs() > local.x {
                    continue;
                }
                sightings.push(TagSighting {
                    t_s: p.t_s,
                    frame: i,
                    id: id as u32,
                    family: "tag36h11".into(),
                    size_m: 0.16,
                    position_in_robot_m: [local.x, local.y, 0.5],
                    covariance_m2: [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-6]],
                    yaw_in_robot_rad: wrap_angle(tag[2] - p.pose.theta),
                    yaw_sigma_rad: 0.01,
                    corners_px: None,
                });
            }
        }
        (odom, truth, sightings, tags)
    }

    /// Turns measured along a run every `every` samples, from the truth, with sigma `sigma`.
    fn turns_of(truth: &[StampedPose], every: usize, sigma: f64) -> Vec<VisualTurn> {
        truth
            .iter()
            .step_by(every)
            .zip(truth.iter().step_by(every).skip(1))
            .map(|(a, b)| VisualTurn {
                from_t_s: a.t_s,
                to_t_s: b.t_s,
                turn_rad: wrap_angle(b.pose.theta - a.pose.theta),
                sigma_rad: sigma,
            })
            .collect()
    }

    /// The cameras' turns keep the heading where no tag is seen: two laps of a square with 1%
    /// wheel errors and no sighting at all, online and offline.
    #[test]
    fn visual_turns_hold_the_heading_without_a_tag() {
        let (odom, truth, _, _) = square_run(0.01, 2);
        let turns = turns_of(&truth, 5, 0.001);
        let config = FuseConfig::default();
        let online = run_online_calibrated(&odom, &turns, &[], &[], &config, None);
        let offline = run_offline(&odom, &turns, &[], &online, &config);
        let raw = ate_m(&odom, &truth).unwrap();
        let on = ate_m(&online.trajectory, &truth).unwrap();
        let off = ate_m(&offline.trajectory, &truth).unwrap();
        assert_eq!(online.visual_fused, turns.len());
        assert!(
            on < 0.2 * raw && off < 0.2 * raw,
            "odometry {raw}, online {on}, offline {off}"
        );
        // Without them (or with the setting off) the heading walks with the wheels.
        let off_config = FuseConfig {
            visual_odometry: false,
            ..config
        };
        let blind = run_online_calibrated(&odom, &turns, &[], &[], &off_config, None);
        assert_eq!(blind.visual_fused, 0);
        assert!(ate_m(&blind.trajectory, &truth).unwrap() > 0.5 * raw);
    }

    /// A landmark added while the heading is copied leaves the filter as if it had been added
    /// first: the copy stays last, with its covariance to the landmark carried through the pose.
    #[test]
    fn the_heading_copy_stays_last_when_a_landmark_joins() {
        let odometry = [StampedPose {
            t_s: 0.0,
            pose: Pose2::new(1.0, 2.0, 0.3),
        }];
        let config = FuseConfig::default();
        let z = Vector3::new(2.0, 0.5, 0.1);
        let r = Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.03));
        let moved = |ekf: &mut Ekf| {
            let mut last = odometry[0].pose;
            ekf.advance(&mut last, Pose2::new(2.0, 2.5, 0.6), &config);
        };
        let (mut copy_first, _) = Ekf::at_start(&odometry);
        moved(&mut copy_first);
        copy_first.clone_heading();
        copy_first.add(("tag36h11".into(), 1), &z, &r);
        let (mut add_first, _) = Ekf::at_start(&odometry);
        moved(&mut add_first);
        add_first.add(("tag36h11".into(), 1), &z, &r);
        add_first.clone_heading();
        assert!(copy_first.has_clone());
        assert!((&copy_first.x - &add_first.x).norm() < 1e-12);
        assert!((&copy_first.p - &add_first.p).norm() < 1e-12);
        // A turn of what the filter already believes moves nothing.
        let before = copy_first.x.clone();
        assert!(copy_first.update_turn(0.0, 1e-4, 10.83));
        assert!((&copy_first.x - &before).norm() < 1e-9);
    }

    #[test]
    fn online_and_offline_beat_odometry_on_a_biased_loop() {
        let (odom, truth, sightings, tags) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let online = run_online(&odom, &sightings, &[], &config);
        let offline = run_offline(&odom, &[], &sightings, &online, &config);
        let ate_odom = ate_m(&odom, &truth).unwrap();
        let ate_online = ate_m(&online.trajectory, &truth).unwrap();
        let ate_offline = ate_m(&offline.trajectory, &truth).unwrap();
        assert!(offline.converged);
        assert!(ate_odom > 0.2, "odometry ATE {ate_odom}");
        assert!(
            ate_online < 0.5 * ate_odom,
            "online {ate_online} odometry {ate_odom}"
        );
        assert!(
            ate_offline < 0.2 * ate_odom,
            "offline {ate_offline} odometry {ate_odom}"
        );
        assert_eq!(online.landmarks.len(), tags.len());
        for l in &offline.landmarks {
            let t = tags[l.id as usize];
            let e = (l.position_m[0] - t[0]).hypot(l.position_m[1] - t[1]);
            assert!(e < 0.05, "tag {} error {e}", l.id);
        }
        assert!(
            online.conflicts.is_empty(),
            "{:?} rejected {}",
            online.conflicts,
            online.rejected.len()
        );
    }

    /// Over four laps of the biased square, the filter that re-solves the run so far learns the
    /// odometry's errors and tracks the later laps far better than the plain EKF.
    #[test]
    fn re_solving_online_learns_the_odometry_errors() {
        let (odom, truth, sightings, _) = square_run(0.01, 4);
        let later = |r: &OnlineResult| {
            let half = r.trajectory.len() / 2;
            ate_m(&r.trajectory[half..], &truth[half..]).unwrap()
        };
        let plain = run_online(
            &odom,
            &sightings,
            &[],
            &FuseConfig {
                online_resolve: false,
                ..FuseConfig::default()
            },
        );
        let resolved = run_online(&odom, &sightings, &[], &FuseConfig::default());
        assert!(plain.resolves.is_empty());
        assert!(resolved.resolves.len() >= 2, "{:?}", resolved.resolves);
        // The last re-solve found the wheels' errors: turns 3% long, 0.01 rad of false turn per
        // metre (the simulated odometry's own, see `square_run`).
        let c = resolved.resolves.last().unwrap().odometry_calibration;
        assert!(
            (c.turn_scale_error + 0.03 / 1.03).abs() < 0.005
                && (c.heading_drift_rad_per_m + 0.01).abs() < 0.002,
            "{c:?}"
        );
        let (a, b) = (later(&plain), later(&resolved));
        assert!(b < 0.25 * a, "later laps: plain {a} m, re-solved {b} m");
    }

    #[test]
    fn localisation_against_a_survey_bounds_the_drift() {
        let (odom, truth, sightings, _) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let online = run_online(&odom, &sightings, &[], &config);
        let survey = run_offline(&odom, &[], &sightings, &online, &config);
        // A second run with the same drift, localised against the first run's landmarks.
        let result = localize(&odom, &[], &sightings, &survey.landmarks, None, &config);
        let ate = ate_m(&result.trajectory, &truth).unwrap();
        assert!(
            ate < 0.2 * ate_m(&odom, &truth).unwrap(),
            "localised ATE {ate}"
        );
        assert!(result.rejected.is_empty() && result.unknown.is_empty());
        assert!(result.since_sighting_m.contains(&0.0));
    }

    #[test]
    fn a_moved_tag_is_reported_not_fused() {
        let (odom, _, mut sightings, _) = square_run(0.0, 2);
        // Tag 1 is moved by 1 m along x after the first lap.
        let lap_end = odom[odom.len() / 2].t_s;
        for s in sightings
            .iter_mut()
            .filter(|s| s.id == 1 && s.t_s > lap_end)
        {
            let truth = odom.iter().find(|p| p.t_s == s.t_s).unwrap().pose;
            let moved = truth
                .inverse()
                .transform_point(nalgebra::Point2::new(4.0, 5.0));
            s.position_in_robot_m = [moved.x, moved.y, 0.5];
        }
        let online = run_online(&odom, &sightings, &[], &FuseConfig::default());
        assert_eq!(online.conflicts.len(), 1, "{:?}", online.conflicts);
        let c = &online.conflicts[0];
        assert_eq!((c.id, c.kind.as_str()), (1, "moved"));
        assert!((c.seen_at_m[0] - 4.0).abs() < 0.1 && (c.seen_at_m[1] - 5.0).abs() < 0.1);
        let l = online.landmarks.iter().find(|l| l.id == 1).unwrap();
        assert!((l.position_m[0] - 5.0).abs() < 0.05, "{l:?}");
    }

    #[test]
    fn a_tag_is_matched_with_the_corner_it_marks() {
        let (odom, _, sightings, _) = square_run(0.0, 2);
        let corner = |x: f64, y: f64| Feature {
            x_m: x,
            y_m: y,
            votes: 80,
            sightings: 1,
            spread_deg: 90.0,
            kind: crate::sonar::hough::FeatureKind::Corner,
        };
        let corners = vec![corner(4.95, 0.1), corner(2.5, 2.5)];
        let online = run_online(&odom, &sightings, &corners, &FuseConfig::default());
        let tag0 = online.landmarks.iter().find(|l| l.id == 0).unwrap();
        let m = tag0.matched_corner.expect("tag 0 matched");
        assert_eq!((m.x_m, m.y_m), (4.95, 0.1));
        let tag2 = online.landmarks.iter().find(|l| l.id == 2).unwrap();
        assert!(tag2.matched_corner.is_none());
    }
}
