//! Tag sightings: the tags of a stereo pair, triangulated and moved into the robot frame, which
//! is what the fusion stage takes from the visual half.

use crate::camera::{Rectification, StereoRig};
use crate::visual::stereo::{
    detect_pair, largest_sigma, triangulate_tags, Rejection, StereoConfig, StereoTag,
};
use crate::visual::tags::{TagDetector, TagError, TagFamily, TagId};
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use serde::Serialize;

/// Yaw sigma of a sighting per unit of (centre depth sigma / tag size): 2√2, as if the corners
/// erred independently. On the rendered office runs (`cargo run --release --example
/// sighting_errors -- RUN`) the yaw errors are mostly 5-10 times smaller, but those seen from 2.5
/// to 3 m at a slant share a bias of 0.05-0.13 rad; with 0.6 instead of 2√2 the offline ATE of a
/// perfect-odometry office run went from 3 cm to 10 cm, so the yaw stays weakly weighted.
pub const YAW_SIGMA_PER_DEPTH_SIGMA: f64 = 2.0 * std::f64::consts::SQRT_2;

/// The level part of the axis a sighting's yaw is taken from below which the yaw is taken as
/// unknown (about 87 degrees of tilt): the yaw's sigma is divided by the level part, floored here.
const MIN_LEVEL_NORMAL: f64 = 0.05;

/// A tag whose normal is tilted more than 60 degrees from level (its vertical part above
/// sin 60 degrees) lies flat: on a ceiling or the floor. Its normal's heading says little or
/// nothing, so its yaw is the heading of its printed up axis (for a tag facing down; of its down
/// axis for one facing up), and its roll is 0: for a level tag, yaw and roll turn it about the
/// same vertical axis, and [`crate::world::Tag::rotation`] with roll 0 and that yaw is its
/// orientation.
pub const FLAT_NORMAL_Z: f64 = 0.866;

/// `robot_from_tag`'s rotation in stereotag's tag frame (x the outward normal, y right, z up)
/// from a stereo tag's `left_from_tag` in the AprilTag library's frame (x right, y down, z into
/// the wall).
fn robot_from_tag(
    robot_from_left: nalgebra::UnitQuaternion<f64>,
    tag: &StereoTag,
) -> nalgebra::Rotation3<f64> {
    let m = &tag.rotation_left_from_tag;
    let column = |k: usize| Vector3::new(m[0][k], m[1][k], m[2][k]);
    let ours = Matrix3::from_columns(&[-column(2), column(0), -column(1)]);
    robot_from_left.to_rotation_matrix() * nalgebra::Rotation3::from_matrix_unchecked(ours)
}

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
    pub family: TagFamily,
    /// Triangulated edge length, metres.
    pub size_m: f64,
    /// Tag centre in the robot frame, metres.
    pub position_in_robot_m: [f64; 3],
    /// Covariance of the centre in the robot frame, m².
    pub covariance_m2: [[f64; 3]; 3],
    /// Direction the tag faces in the robot frame, radians: its normal's heading; for a tag
    /// lying flat (on a ceiling or the floor, [`FLAT_NORMAL_Z`]) the heading of its printed top
    /// (of its bottom for one facing up).
    pub yaw_in_robot_rad: f64,
    /// One sigma of that direction, radians.
    pub yaw_sigma_rad: f64,
    /// How far the tag's face is turned up from the vertical, radians (the robot stands level,
    /// so this is the tag's pitch in the world; see [`crate::world::Tag::rotation`]). A flat
    /// tag's may pass plus or minus 90 degrees by its tilt towards its yaw's heading.
    pub pitch_rad: f64,
    /// How far the tag is turned about its normal, radians (0 for a flat tag: its yaw says it).
    pub roll_rad: f64,
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
        let robot_from_tag = robot_from_tag(robot_from_left.rotation, tag);
        let n = r * Vector3::from(tag.normal_in_left);
        // A wall's tag: its yaw is the direction of the normal's level part, which shrinks as
        // the tag tilts. A flat tag's ([`FLAT_NORMAL_Z`]): the direction of its up axis (down
        // axis facing up), which lies level.
        let flat = n.z.abs() > FLAT_NORMAL_Z;
        let axis = if flat {
            robot_from_tag * Vector3::z() * -n.z.signum()
        } else {
            n
        };
        // The yaw error is the depth difference of opposite corners over the tag size, scaled by
        // the centre's depth sigma (a flat tag seen at a slant has its corners' depth errors in
        // its plane); see [`YAW_SIGMA_PER_DEPTH_SIGMA`].
        let largest = largest_sigma(&cov_left);
        let level = axis.x.hypot(axis.y).max(MIN_LEVEL_NORMAL);
        let yaw_sigma = YAW_SIGMA_PER_DEPTH_SIGMA * largest / tag.size_m.max(1e-3) / level;
        let [roll, pitch] = if flat {
            // The normal's tilt towards the yaw's heading, signed (from its vertical part alone
            // the tilt would always come out short of flat: 5 degrees of normal noise put a
            // ceiling tag's pitch 5 degrees off); the tilt across it is left out (roll 0).
            let towards = (n.x * axis.x + n.y * axis.y) / level;
            let tilt = towards.clamp(-1.0, 1.0).asin();
            [0.0, n.z.signum() * (std::f64::consts::FRAC_PI_2 - tilt)]
        } else {
            let [roll, pitch, _] = crate::world::tag_roll_pitch_yaw(&robot_from_tag);
            [roll, pitch]
        };
        Self {
            t_s,
            frame,
            id: tag.id,
            family: tag.family,
            size_m: tag.size_m,
            position_in_robot_m: [p.x, p.y, p.z],
            covariance_m2: std::array::from_fn(|i| std::array::from_fn(|j| cov[(i, j)])),
            yaw_in_robot_rad: axis.y.atan2(axis.x),
            yaw_sigma_rad: yaw_sigma,
            pitch_rad: pitch,
            roll_rad: roll,
            corners_px: Some((tag.corners_px, tag.right_corners_px)),
        }
    }

    /// The tag seen: its family and id.
    pub fn key(&self) -> TagId {
        TagId {
            family: self.family,
            id: self.id,
        }
    }
}

/// The printed edge length of the tags: per tag, with a default for the rest (`--tag-sizes`
/// FILE, `--tag-size-m`; a world file's tags come first).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TagSizes {
    /// The size of every tag not listed, metres.
    pub default_m: Option<f64>,
    /// Per tag, metres.
    pub by_tag: std::collections::BTreeMap<TagId, f64>,
}

impl TagSizes {
    /// The size of a tag, if known: its own, else the default.
    pub fn of(&self, family: TagFamily, id: u32) -> Option<f64> {
        self.by_tag
            .get(&TagId { family, id })
            .copied()
            .or(self.default_m)
    }
}

/// Heights (robot frame z, metres) a tag may be triangulated at when nothing says how high the
/// walls are: from 0.3 m below the floor to 3.5 m (a home's ceiling is under 3 m). Outside, a
/// sighting is a wrong rig mounting or a false match between the cameras.
pub const TAG_HEIGHT_RANGE_M: (f64, f64) = (-0.3, 3.5);

/// Detects and triangulates the tags of one stereo pair and moves them into the robot frame.
/// `known_size_m` gives a tag's planned edge length (for the size check) when it is known.
#[allow(clippy::too_many_arguments)]
pub fn sightings_from_pair(
    detector: &mut dyn TagDetector,
    rig: &StereoRig,
    rect: &Rectification,
    left: &image::GrayImage,
    right: &image::GrayImage,
    (t_s, frame): (f64, usize),
    known_size_m: &dyn Fn(TagFamily, u32) -> Option<f64>,
    config: &StereoConfig,
) -> Result<(Vec<TagSighting>, Vec<Rejection>), TagError> {
    let (in_left, in_right) = detect_pair(detector, left, right)?;
    let (tags, mut rejected) = triangulate_tags(rig, rect, &in_left, &in_right, None, config);
    let mut sightings = Vec::new();
    for tag in tags {
        if let Some(known) = known_size_m(tag.family, tag.id) {
            if ((tag.size_m - known) / known).abs() > config.max_size_error {
                rejected.push(Rejection {
                    id: tag.id,
                    reason: format!(
                        "triangulated size {:.3} m, expected {known:.3} m",
                        tag.size_m
                    ),
                });
                continue;
            }
        }
        sightings.push(TagSighting::from_stereo(
            t_s,
            frame,
            &tag,
            &rig.robot_from_left,
        ));
    }
    Ok((sightings, rejected))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::tag_rotation;
    use nalgebra::{Rotation3, UnitQuaternion};

    /// A stereo tag 2 m ahead of the left camera whose rotation there is `left_from_tag`
    /// (stereotag's tag frame), as the triangulation gives it.
    fn stereo_tag(left_from_tag: &Rotation3<f64>) -> StereoTag {
        let col = |k: usize| left_from_tag.matrix().column(k).into_owned();
        // The AprilTag library's frame: x right (ours y), y down (ours -z), z into the wall.
        let m = Matrix3::from_columns(&[col(1), -col(2), -col(0)]);
        StereoTag {
            id: 0,
            family: TagFamily::Tag36h11,
            hamming: 0,
            corners_px: [[0.0; 2]; 4],
            centre_px: [0.0; 2],
            right_corners_px: [[0.0; 2]; 4],
            corners_in_left_m: [[0.0; 3]; 4],
            position_in_left_m: [0.0, 0.0, 2.0],
            covariance_m2: [[1e-5, 0.0, 0.0], [0.0, 1e-5, 0.0], [0.0, 0.0, 1e-5]],
            epipolar_error_px: 0.0,
            size_m: 0.2,
            rotation_left_from_tag: std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)])),
            normal_in_left: col(0).into(),
            fit_rms_m: 0.0,
            pnp_angle_deg: [None, None],
            pnp_distance_m: [None, None],
        }
    }

    #[test]
    fn a_sighting_gives_back_the_tags_orientation_on_walls_ceilings_and_floors() {
        // The camera looks 30 degrees up (calibration/rigs/upward.yaml); the robot heads 0.4 rad.
        let (s, c) = 30f64.to_radians().sin_cos();
        let robot_from_left = Isometry3::from_parts(
            nalgebra::Translation3::new(0.1, 0.06, 0.35),
            UnitQuaternion::from_matrix(&Matrix3::new(0.0, s, c, -1.0, 0.0, 0.0, 0.0, -c, s)),
        );
        let heading = 0.4;
        let world_from_robot = Rotation3::from_axis_angle(&Vector3::z_axis(), heading);
        let deg = |d: f64| d.to_radians();
        for (roll, pitch, yaw, flat) in [
            (0.0, deg(-90.0), 0.7, true),  // on the ceiling, its top towards 0.7 rad
            (0.0, deg(-80.0), -2.5, true), // a ceiling's tag tilted 10 degrees
            (0.0, deg(90.0), -2.0, true),  // on the floor
            (deg(30.0), 0.0, 1.0, false),  // on a wall, turned about its normal
            (0.0, deg(-20.0), 3.0, false), // high on a wall, tipped down
        ] {
            let world_from_tag = tag_rotation(roll, pitch, yaw);
            let left_from_tag = robot_from_left.rotation.to_rotation_matrix().inverse()
                * world_from_robot.inverse()
                * world_from_tag;
            let sighting =
                TagSighting::from_stereo(0.0, 0, &stereo_tag(&left_from_tag), &robot_from_left);
            let surveyed = world_from_robot.angle() + sighting.yaw_in_robot_rad;
            let back = tag_rotation(sighting.roll_rad, sighting.pitch_rad, surveyed);
            assert!(
                back.angle_to(&world_from_tag) < 1e-9,
                "({roll}, {pitch}, {yaw}): {sighting:?}"
            );
            if flat {
                assert_eq!(sighting.roll_rad, 0.0, "a flat tag's yaw holds its roll");
            }
            assert!(sighting.yaw_sigma_rad < 0.1, "{sighting:?}");
        }
    }
}
