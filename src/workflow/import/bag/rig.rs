//! The stereo rig of a bag: the cameras from their `CameraInfo` (or a camchain), the baseline
//! from tf or the right camera's projection, the mounting from tf.

use super::{mount, topic_error, BagRequest, Gathered, Roles, CAMERA_INFO};
use crate::camera::{Camera, Distortion, StereoRig};
use crate::io::rosbag::cdr::CameraInfo;
use crate::io::rosbag::Bag;
use crate::io::{self, IoError};
use crate::workflow::Result;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// A camera from its `CameraInfo`.
fn camera_of(info: &CameraInfo) -> std::result::Result<Camera, String> {
    if info.k.iter().all(|&v| v == 0.0) {
        return Err("the camera is not calibrated (K is all zero): calibrate it (`stereotag calibrate`) and pass --rig camchain.yaml".into());
    }
    if info.binning.iter().any(|&b| b > 1) || info.roi.iter().any(|&v| v != 0) {
        return Err(format!(
            "binning {:?} or region of interest {:?} is not read: pass --rig for the images as they are",
            info.binning, info.roi
        ));
    }
    let d = |i: usize| info.d.get(i).copied().unwrap_or(0.0);
    let distortion = match info.distortion_model.as_str() {
        _ if info.d.iter().all(|&v| v == 0.0) => Distortion::None,
        "plumb_bob" | "rational_polynomial" => {
            if info.d.iter().skip(5).any(|&v| v != 0.0) {
                return Err(format!(
                    "{} with k4..k6 = {:?} is not read (radtan with k1, k2, p1, p2, k3 is)",
                    info.distortion_model,
                    &info.d[5..]
                ));
            }
            Distortion::Radtan {
                k1: d(0),
                k2: d(1),
                p1: d(2),
                p2: d(3),
                k3: d(4),
            }
        }
        "equidistant" | "fisheye" => Distortion::Equidistant {
            k1: d(0),
            k2: d(1),
            k3: d(2),
            k4: d(3),
        },
        other => {
            return Err(format!(
                "distortion model `{other}` is not read (plumb_bob, equidistant)"
            ))
        }
    };
    let camera = Camera {
        fx: info.k[0],
        fy: info.k[4],
        cx: info.k[2],
        cy: info.k[5],
        distortion,
        width: info.width,
        height: info.height,
    };
    camera.validate().map_err(|e| e.to_string())?;
    Ok(camera)
}

/// `right_from_left` from the two `CameraInfo`'s rectification rotations and the right one's
/// projection (`P[0][3] = -fx' B`, B the baseline in the rectified frame).
fn right_from_left_of(left: &CameraInfo, right: &CameraInfo) -> Option<Isometry3<f64>> {
    let fx = right.p[0];
    let baseline = -right.p[3] / fx;
    if !(baseline.is_finite() && baseline.abs() > 1e-6) {
        return None;
    }
    let rot = |r: &[f64; 9]| {
        let m = Matrix3::from_row_slice(r);
        if m.iter().all(|&v| v == 0.0) {
            Some(Rotation3::identity())
        } else {
            let det = m.determinant();
            ((det - 1.0).abs() < 1e-3).then(|| Rotation3::from_matrix(&m))
        }
    };
    let (rl, rr) = (rot(&left.r)?, rot(&right.r)?);
    let rotation = rr.inverse() * rl;
    let translation = rr.inverse() * Vector3::new(-baseline, 0.0, 0.0);
    Some(Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

impl Gathered {
    /// The rig (and the images' size), and where it came from.
    pub(super) fn rig(
        &self,
        bag: &Bag,
        roles: &Roles,
        request: &BagRequest<'_>,
    ) -> Result<((StereoRig, [u32; 2]), String)> {
        let path = request.bag;
        let base = request.base_frame.as_str();
        let topics = [
            roles.left.as_deref().unwrap_or(""),
            roles.right.as_deref().unwrap_or(""),
        ];
        let sizes = [
            self.sizes[0].expect("pairs written"),
            self.sizes[1].expect("pairs written"),
        ];
        if sizes[0].0 != sizes[1].0 {
            return Err(IoError::content(
                path,
                format!(
                    "the left images ({}, message {}) are {} x {} but the right images ({}, message {}) {} x {}: a stereo pair must be one size",
                    topics[0], sizes[0].1, sizes[0].0[0], sizes[0].0[1], topics[1], sizes[1].1, sizes[1].0[0], sizes[1].0[1]
                ),
            )
            .into());
        }
        let frames: [String; 2] = std::array::from_fn(|s| {
            self.infos[s]
                .as_ref()
                .map(|i| i.header.frame_id.clone())
                .filter(|f| !f.is_empty())
                .or_else(|| self.image_frames[s].clone())
                .unwrap_or_default()
        });
        if let Some(rig_path) = request.rig {
            let file_rig = io::load_rig(rig_path)?;
            for (s, camera) in [file_rig.left, file_rig.right].iter().enumerate() {
                if [camera.width, camera.height] != sizes[s].0 {
                    return Err(IoError::content(
                        rig_path,
                        format!(
                            "cam{s} is {} x {} but the images on {} are {} x {}",
                            camera.width, camera.height, topics[s], sizes[s].0[0], sizes[s].0[1]
                        ),
                    )
                    .into());
                }
            }
            let robot_from_left = if self.tf.knows(&frames[0]) {
                mount(&self.tf, path, base, &frames[0], "the left camera")?
            } else {
                io::load_mounted_rig(rig_path, None, false)?.robot_from_left
            };
            return Ok((
                (
                    StereoRig {
                        robot_from_left,
                        right_from_left_covariance: None,
                        ..file_rig
                    },
                    sizes[0].0,
                ),
                format!(
                    "{} (the mounting from tf when it has the left camera's frame)",
                    rig_path.display()
                ),
            ));
        }
        let mut cameras = Vec::new();
        for s in 0..2 {
            let Some(info) = self.infos[s].as_ref() else {
                return Err(topic_error(
                    bag,
                    format!(
                        "no {CAMERA_INFO} beside {} (looked for camera_info in its namespaces): pass --rig camchain.yaml",
                        topics[s]
                    ),
                ));
            };
            let info_topic = if s == 0 {
                &roles.left_info
            } else {
                &roles.right_info
            };
            let info_topic = info_topic.as_deref().unwrap_or("");
            let camera = camera_of(info)
                .map_err(|e| IoError::content(path, format!("topic {info_topic}: {e}")))?;
            if [camera.width, camera.height] != sizes[s].0 {
                return Err(IoError::content(
                    path,
                    format!(
                        "topic {info_topic} says {} x {} but the images on {} are {} x {} (message {})",
                        camera.width, camera.height, topics[s], sizes[s].0[0], sizes[s].0[1], sizes[s].1
                    ),
                )
                .into());
            }
            cameras.push(camera);
        }
        let (left_info, right_info) = (
            self.infos[0].as_ref().expect("checked"),
            self.infos[1].as_ref().expect("checked"),
        );
        let by_tf = frames[0] != frames[1]
            && self.tf.knows(&frames[0])
            && self.tf.knows(&frames[1])
            && self.tf.lookup(&frames[1], &frames[0]).is_ok();
        let (right_from_left, from) = if by_tf {
            (
                self.tf.lookup(&frames[1], &frames[0]).expect("checked"),
                "camera_info (intrinsics) and tf (between the cameras and on the robot)",
            )
        } else {
            let Some(p) = right_from_left_of(left_info, right_info) else {
                return Err(IoError::content(
                    path,
                    format!(
                        "the baseline is unknown: tf does not connect the camera frames `{}` and `{}`, and the right camera_info's projection has no baseline (P[0][3] = {}): pass --rig camchain.yaml",
                        frames[0], frames[1], right_info.p[3]
                    ),
                )
                .into());
            };
            (p, "camera_info (intrinsics, and the baseline from the right projection) and tf (on the robot)")
        };
        let robot_from_left = mount(&self.tf, path, base, &frames[0], "the left camera")?;
        let rig = StereoRig {
            left: cameras[0],
            right: cameras[1],
            right_from_left,
            robot_from_left,
            right_from_left_covariance: None,
        };
        Ok(((rig, sizes[0].0), from.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::rosbag::cdr::Header;

    fn info(model: &str, d: Vec<f64>, r: Rotation3<f64>, tx: f64) -> CameraInfo {
        CameraInfo {
            header: Header::default(),
            height: 480,
            width: 640,
            distortion_model: model.into(),
            d,
            k: [460.0, 0.0, 320.0, 0.0, 461.0, 240.0, 0.0, 0.0, 1.0],
            r: r.matrix().transpose().as_slice().try_into().unwrap(),
            p: [
                450.0, 0.0, 320.0, tx, 0.0, 450.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0,
            ],
            binning: [0, 0],
            roi: [0; 4],
        }
    }

    #[test]
    fn the_baseline_comes_from_the_right_projection_through_both_rotations() {
        // A right camera 0.12 m to the right, turned 2 degrees about y: rectification turns
        // each camera onto the common frame whose x axis runs along the baseline.
        let right_from_left = Isometry3::from_parts(
            Translation3::new(-0.12, 0.0, 0.004),
            UnitQuaternion::from_euler_angles(0.0, 0.035, 0.0),
        );
        let baseline = right_from_left.translation.vector.norm();
        let centre_in_left = right_from_left.inverse().translation.vector;
        // The rectified frame seen from the left camera: x along the baseline.
        let x = centre_in_left.normalize();
        let z = (Vector3::z() - x * x.z).normalize();
        let rect_from_left = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
            x.transpose(),
            z.cross(&x).transpose(),
            z.transpose(),
        ]));
        let rect_from_right =
            rect_from_left * right_from_left.rotation.inverse().to_rotation_matrix();
        let left = info(
            "plumb_bob",
            vec![-0.1, 0.01, 0.0, 0.0, 0.0],
            rect_from_left,
            0.0,
        );
        let right = info("plumb_bob", vec![], rect_from_right, -450.0 * baseline);
        let got = right_from_left_of(&left, &right).unwrap();
        assert!((got.translation.vector - right_from_left.translation.vector).norm() < 1e-9);
        assert!(got.rotation.angle_to(&right_from_left.rotation) < 1e-9);
        // No baseline in P: unknown.
        assert!(
            right_from_left_of(&left, &info("plumb_bob", vec![], rect_from_right, 0.0)).is_none()
        );
    }

    #[test]
    fn camera_info_models_are_read_or_refused() {
        let id = Rotation3::identity();
        let c = camera_of(&info(
            "plumb_bob",
            vec![-0.1, 0.01, 0.001, 0.002, 0.0],
            id,
            0.0,
        ))
        .unwrap();
        assert_eq!((c.fx, c.fy, c.cx, c.cy), (460.0, 461.0, 320.0, 240.0));
        assert!(
            matches!(c.distortion, Distortion::Radtan { k1, p2, .. } if k1 == -0.1 && p2 == 0.002)
        );
        let c = camera_of(&info("equidistant", vec![0.1, 0.2, 0.3, 0.4], id, 0.0)).unwrap();
        assert!(matches!(c.distortion, Distortion::Equidistant { k4, .. } if k4 == 0.4));
        assert!(camera_of(&info(
            "rational_polynomial",
            vec![0.1, 0.0, 0.0, 0.0, 0.0, 0.3, 0.0, 0.0],
            id,
            0.0
        ))
        .unwrap_err()
        .contains("k4..k6"));
        assert!(camera_of(&info("double_sphere", vec![0.1], id, 0.0))
            .unwrap_err()
            .contains("not read"));
        let mut blank = info("plumb_bob", vec![], id, 0.0);
        blank.k = [0.0; 9];
        assert!(camera_of(&blank).unwrap_err().contains("not calibrated"));
    }
}
