//! The fusion stage's settings, each with where its default comes from.

use serde::Serialize;

/// How noisy a robot's calibrated odometry is against [`FuseConfig`]'s model, each as a factor on
/// the model's sigmas: what a survey measures ([`super::NoiseScales`]) and `localize` predicts
/// with ([`FuseConfig::with_odometry_noise_scale`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OdometryNoiseScale {
    /// On the translation's sigma ([`FuseConfig::odometry_sigma_m_per_sqrt_m`]).
    pub translation: f64,
    /// On the heading's sigmas per radian turned (calibrated or not).
    pub turning: f64,
    /// On the heading's sigma per metre travelled.
    pub drift: f64,
}

/// Settings of the fusion stage. Defaults say where they come from.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct FuseConfig {
    /// Translation noise of odometry, m per √m travelled (ours: 1 cm/√m, five times the simulated
    /// random wheel noise to cover the wheel-scale error).
    pub odometry_sigma_m_per_sqrt_m: f64,
    /// Heading noise of odometry per √rad turned (ours: 0.03, covers the simulated 1% wheel-base
    /// error over a full turn, 0.063 rad, at about one sigma).
    pub heading_sigma_per_sqrt_rad: f64,
    /// Heading noise per √rad turned of odometry corrected with a survey's calibration
    /// ([`FuseConfig::for_calibrated_odometry`], what `localize` predicts with; also what the
    /// offline graph weighs a turn along an arc with where no visual turn measures it and the
    /// graph estimates the calibration from tags or visual turns; ours: 0.015, a
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
    /// Try a re-sighting the filter gates out as a loop closure: solve the graph of the run so
    /// far with it and fuse it when that solution explains it within the odometry's noise (tag
    /// ids are unique, so however far the odometry drifted a re-seen tag closes a loop unless no
    /// such trajectory exists); only what fails is reported as moved (ours: on; needs
    /// `online_resolve`).
    pub loop_test: bool,
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
    /// ([`super::localize::hold_tail_to_walls`]; ours: on).
    pub hold_tail_to_walls: bool,
    /// Solve the offline graph a second time with range factors off the walls mapped from its
    /// first solution, so that the walls hold the trajectory between tag sightings
    /// ([`super::run_offline_walls`]; ours: off).
    pub walls_between_tags: bool,
    /// When localising, take the pose from the walls when the filter is too unsure of it to
    /// match ranges with walls one at a time (its position sigma above
    /// `sonar_max_range_sigma_m`): the last ranges matched with the surveyed walls over poses
    /// around the estimate, taken only when one pose clearly explains most of them (ours: on).
    pub wall_relocalise: bool,
    /// With no tag sighting and no visual turn to correct the odometry against, let the sonar
    /// correct it: each keyframe's latest ranges matched with the grid of the older readings
    /// ([`super::run_offline_sonar`]; ours: on).
    pub sonar_scan_match: bool,
    /// Fuse the turns the cameras measure between frames ([`crate::visual::vo`]) with the odometry,
    /// online and offline (ours: on; they are used when the run's pictures give them).
    pub visual_odometry: bool,
    /// χ² gate of a visual turn against the filter, 1 dof (10.83: 99.9%).
    pub visual_gate_chi2: f64,
    /// Estimate the camera's planar mounting error (x, y and yaw of `robot_from_left` in the
    /// robot frame) in the offline graph from the sightings and the odometry's turns, and correct
    /// the survey with it (ours: off; `survey --estimate-mounting`).
    pub estimate_mounting: bool,
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

    /// The settings for odometry already corrected with a survey's [`super::OdometryCalibration`]: the
    /// turn noise is then what the calibration leaves
    /// (`calibrated_heading_sigma_per_sqrt_rad`), not the wheel-base error it removed.
    pub fn for_calibrated_odometry(&self) -> Self {
        Self {
            heading_sigma_per_sqrt_rad: self.calibrated_heading_sigma_per_sqrt_rad,
            ..self.clone()
        }
    }

    /// The settings with the odometry's noise scaled as a survey measured it
    /// ([`super::NoiseScales`], `landmarks.json`'s `odometry_noise_scale`): the translation's
    /// sigma by `scale.translation`, the heading's per radian turned by `scale.turning`, and its
    /// per metre travelled by `scale.drift`.
    pub fn with_odometry_noise_scale(&self, scale: &OdometryNoiseScale) -> Self {
        Self {
            odometry_sigma_m_per_sqrt_m: self.odometry_sigma_m_per_sqrt_m * scale.translation,
            heading_sigma_per_sqrt_rad: self.heading_sigma_per_sqrt_rad * scale.turning,
            calibrated_heading_sigma_per_sqrt_rad: self.calibrated_heading_sigma_per_sqrt_rad
                * scale.turning,
            heading_sigma_per_sqrt_m: self.heading_sigma_per_sqrt_m * scale.drift,
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
            loop_test: true,
            sonar_sigma_m: 0.01,
            sonar_sigma_frac: 0.01,
            wall_sigma_m: 0.02,
            sonar_gate_chi2: 6.63,
            sonar_max_range_sigma_m: 0.2,
            hold_tail_to_walls: true,
            walls_between_tags: false,
            wall_relocalise: true,
            sonar_scan_match: true,
            visual_odometry: true,
            visual_gate_chi2: 10.83,
            estimate_mounting: false,
        }
    }
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
}
