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
//! interpolated by distance travelled. A run with no tag sighting and no visual turn is corrected
//! by its sonar ([`run_offline_sonar`]): each keyframe's latest ranges matched with the counting
//! grid of the older readings, the matches holding the graph.
//!
//! The stage is split along its phases: [`FuseConfig`] (`config.rs`), the measurement models
//! (`measurement.rs`), the filter (`ekf.rs`), the online pass (`online.rs`), the offline graph
//! (`offline/`), localisation against a survey (`localize.rs`) and the survey over a whole run
//! (`survey.rs`).

mod anchors;
mod config;
mod ekf;
mod events;
mod landmark;
mod localize;
mod measurement;
mod observations;
mod offline;
mod online;
mod streaming;
mod survey;
#[cfg(test)]
pub(crate) mod testing;
mod wall_fix;

pub use crate::visual::sightings::{PairCorners, TagSighting, YAW_SIGMA_PER_DEPTH_SIGMA};
pub use anchors::{
    anchor_frame, anchor_residuals, origin_anchor, Anchor, AnchorError, AnchorResidual,
};
pub use config::{FuseConfig, FuseConfigError, OdometryNoiseScale};
pub use landmark::{associate, surveyed_tag_sizes, Conflict, CornerMatch, Landmark};
pub use localize::{
    hold_tail_to_walls, localize, localize_from, range_scatter, scatter_too_wide, track,
    wall_in_beam, wall_misfits, LocalizeResult, Localizer, PoseEstimate, RangeScatter, ScanOutcome,
    SightingOutcome, SonarInput, Start, WallMatch, RANGE_OFF_M, RANGE_OFF_WARN, RANGE_SCATTER_MIN,
    RAY_BEAM_SPACING_RAD, RAY_MATCH_RAD, RELOCALISE_AFTER, RELOCALISE_AGREE_M,
    RELOCALISE_AGREE_RAD, UNKNOWN_START_SIGMA_M, WALL_CONE_MARGIN_RAD, WALL_INSET_M, WALL_PARTS,
};
pub use observations::Observations;
pub use offline::{
    estimate_mounting, run_offline, run_offline_anchored, run_offline_sonar, run_offline_walls,
    MountingEstimate, NoiseScales, OdometryCalibration, OfflineKept, OfflineResult, PoseFunction,
    SilentStart, SolutionCovariance, MOUNTING_STRETCH_M,
};
pub use online::{run_online, Nis, OnlineResolve, OnlineResult};
pub use streaming::{PairError, PairUpdate, StereoLocalizer};
pub use survey::{survey, Survey, SurveySettings};
