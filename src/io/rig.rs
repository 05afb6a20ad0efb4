//! Stereo rigs as Kalibr camchain YAML (`cam0`, `cam1`, `cam1.T_cn_cnm1`), with our extras under
//! `stereotag:` so that Kalibr users and their tools read the files as they are.

use super::{parse_yaml, read_text, to_yaml, write_file, IoError};
use crate::camera::{Camera, Distortion, Rectification, StereoRig};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One camera of a Kalibr camchain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KalibrCamera {
    /// `pinhole` (the only projection we read).
    pub camera_model: String,
    /// `[fu, fv, pu, pv]`.
    pub intrinsics: Vec<f64>,
    /// `radtan`, `equidistant` or `none`.
    pub distortion_model: String,
    /// radtan: `[k1, k2, p1, p2]` (or with `k3`); equidistant: `[k1, k2, k3, k4]`.
    pub distortion_coeffs: Vec<f64>,
    /// `[width, height]`.
    pub resolution: Vec<u32>,
    /// This camera from the previous one (cam1: `right_from_left`), 4x4 row-major.
    #[serde(default, rename = "T_cn_cnm1", skip_serializing_if = "Option::is_none")]
    pub t_cn_cnm1: Option<Vec<Vec<f64>>>,
    /// Kalibr's camera-IMU transform (kept, not used).
    #[serde(default, rename = "T_cam_imu", skip_serializing_if = "Option::is_none")]
    pub t_cam_imu: Option<Vec<Vec<f64>>>,
    /// Kalibr's overlap list (kept, not used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cam_overlaps: Option<Vec<u32>>,
    /// Kalibr's image topic (kept, not used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rostopic: Option<String>,
    /// Kalibr's camera-IMU time shift (kept, not used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeshift_cam_imu: Option<f64>,
}

/// Our extra keys.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct StereotagExtras {
    /// `robot_from_left`, 4x4 row-major.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_from_left: Option<Vec<Vec<f64>>>,
    /// The covariance of `cam1.T_cn_cnm1` from its calibration, 6x6 row-major over its rotation
    /// vector (rad) and translation (m): [`StereoRig::right_from_left_covariance`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub right_from_left_covariance: Option<Vec<Vec<f64>>>,
}

/// A Kalibr camchain file with two cameras.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camchain {
    /// Left camera.
    pub cam0: KalibrCamera,
    /// Right camera.
    pub cam1: KalibrCamera,
    /// Our extras.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stereotag: Option<StereotagExtras>,
}

pub(crate) fn camera_from(path: &Path, key: &str, c: &KalibrCamera) -> Result<Camera, IoError> {
    let bad = |m: String| IoError::content(path, format!("`{key}.{m}"));
    let [width, height] = c.resolution[..] else {
        return Err(bad("resolution` needs [width, height]".into()));
    };
    let (fx, fy, cx, cy, lens) = match (c.camera_model.as_str(), &c.intrinsics[..]) {
        ("pinhole", &[fx, fy, cx, cy]) => (fx, fy, cx, cy, None),
        ("ds", &[xi, alpha, fx, fy, cx, cy]) => {
            (fx, fy, cx, cy, Some(Distortion::DoubleSphere { xi, alpha }))
        }
        ("eucm", &[alpha, beta, fx, fy, cx, cy]) => {
            (fx, fy, cx, cy, Some(Distortion::Eucm { alpha, beta }))
        }
        ("pinhole", i) => {
            return Err(bad(format!(
                "intrinsics` needs 4 numbers [fu, fv, pu, pv], found {}",
                i.len()
            )))
        }
        ("ds" | "eucm", i) => {
            return Err(bad(format!(
                "intrinsics` of a `{}` camera needs 6 numbers ({}, fu, fv, pu, pv), found {}",
                c.camera_model,
                if c.camera_model == "ds" { "xi, alpha" } else { "alpha, beta" },
                i.len()
            )))
        }
        (m, _) => {
            return Err(bad(format!(
                "camera_model` is `{m}`; expected pinhole, ds (double sphere) or eucm (extended unified)"
            )))
        }
    };
    let d = &c.distortion_coeffs;
    let distortion = match (lens, c.distortion_model.as_str(), d.len()) {
        (Some(lens), "none", 0) => lens,
        (Some(_), m, n) => {
            return Err(bad(format!(
                "distortion_model` `{m}` with {n} coefficients: a `{}` camera takes `none` with none",
                c.camera_model
            )))
        }
        (None, m, n) => pinhole_distortion(m, d).ok_or_else(|| bad(format!(
            "distortion_model` `{m}` with {n} coefficients: expected radtan (4 or 5), equidistant (4) or none (0)"
        )))?,
    };
    let cam = Camera {
        fx,
        fy,
        cx,
        cy,
        distortion,
        width,
        height,
    };
    cam.validate()
        .map_err(|e| bad(format!("intrinsics`: {e}")))?;
    Ok(cam)
}

/// A pinhole camera's distortion from Kalibr's model name and coefficients.
fn pinhole_distortion(model: &str, d: &[f64]) -> Option<Distortion> {
    Some(match (model, d.len()) {
        ("none", 0) => Distortion::None,
        ("radtan", 4) => Distortion::Radtan {
            k1: d[0],
            k2: d[1],
            p1: d[2],
            p2: d[3],
            k3: 0.0,
        },
        ("radtan", 5) => Distortion::Radtan {
            k1: d[0],
            k2: d[1],
            p1: d[2],
            p2: d[3],
            k3: d[4],
        },
        ("equidistant", 4) => Distortion::Equidistant {
            k1: d[0],
            k2: d[1],
            k3: d[2],
            k4: d[3],
        },
        _ => return None,
    })
}

pub(crate) fn isometry_from(
    path: &Path,
    key: &str,
    rows: &[Vec<f64>],
) -> Result<Isometry3<f64>, IoError> {
    let shape_ok = rows.len() == 4 && rows.iter().all(|r| r.len() == 4);
    if !shape_ok || rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(IoError::content(
            path,
            format!("`{key}` must be a 4x4 matrix of finite numbers"),
        ));
    }
    let r = Matrix3::from_fn(|i, j| rows[i][j]);
    let err = (r * r.transpose() - Matrix3::identity()).abs().max();
    let det = r.determinant();
    if err > 1e-3 || (det - 1.0).abs() > 1e-3 {
        return Err(IoError::content(
            path,
            format!("`{key}` rotation is not a rotation (determinant {det:.4}, orthogonality error {err:.1e})"),
        ));
    }
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_eps(
        &r,
        1e-9,
        50,
        Rotation3::identity(),
    ));
    Ok(Isometry3::from_parts(
        Translation3::new(rows[0][3], rows[1][3], rows[2][3]),
        rot,
    ))
}

fn rows_from(iso: &Isometry3<f64>) -> Vec<Vec<f64>> {
    let m = iso.to_homogeneous();
    (0..4)
        .map(|i| (0..4).map(|j| m[(i, j)]).collect())
        .collect()
}

fn kalibr_from(cam: &Camera, t_cn_cnm1: Option<Vec<Vec<f64>>>) -> KalibrCamera {
    let focal = [cam.fx, cam.fy, cam.cx, cam.cy];
    let (camera_model, intrinsics) = match cam.distortion {
        Distortion::DoubleSphere { xi, alpha } => ("ds", [&[xi, alpha][..], &focal].concat()),
        Distortion::Eucm { alpha, beta } => ("eucm", [&[alpha, beta][..], &focal].concat()),
        _ => ("pinhole", focal.to_vec()),
    };
    let (model, coeffs) = match cam.distortion {
        Distortion::DoubleSphere { .. } | Distortion::Eucm { .. } => ("none", vec![]),
        Distortion::None => ("none", vec![]),
        Distortion::Radtan {
            k1,
            k2,
            p1,
            p2,
            k3: 0.0,
        } => ("radtan", vec![k1, k2, p1, p2]),
        Distortion::Radtan { k1, k2, p1, p2, k3 } => ("radtan", vec![k1, k2, p1, p2, k3]),
        Distortion::Equidistant { k1, k2, k3, k4 } => ("equidistant", vec![k1, k2, k3, k4]),
    };
    KalibrCamera {
        camera_model: camera_model.into(),
        intrinsics,
        distortion_model: model.into(),
        distortion_coeffs: coeffs,
        resolution: vec![cam.width, cam.height],
        t_cn_cnm1,
        t_cam_imu: None,
        cam_overlaps: None,
        rostopic: None,
        timeshift_cam_imu: None,
    }
}

/// The camera looking straight ahead: camera z forward = robot x, camera x right = robot -y,
/// camera y down = robot -z.
pub fn robot_from_forward_camera(x_m: f64, y_m: f64, z_m: f64) -> Isometry3<f64> {
    let r = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    Isometry3::from_parts(
        Translation3::new(x_m, y_m, z_m),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    )
}

/// The stereo rig `simulate`, `render` and `demo` use unless told otherwise (repository-relative).
pub const DEFAULT_RIG: &str = "calibration/rigs/default.yaml";

/// Reads a Kalibr camchain YAML file as a stereo rig (the bundled rigs, such as [`DEFAULT_RIG`],
/// from their built-in copies when they are not on disk). Without `stereotag.robot_from_left` the
/// left camera is taken to look straight ahead from the robot centre, 0.3 m up.
pub fn load_rig(path: &Path) -> Result<StereoRig, IoError> {
    parse_rig(path, &read_text(path)?)
}

/// [`load_rig`] of a camchain's text already read (`path` names it in errors).
pub fn parse_rig(path: &Path, text: &str) -> Result<StereoRig, IoError> {
    let (rig, mounting) = parse_rig_mounting(path, text)?;
    Ok(StereoRig {
        robot_from_left: mounting.unwrap_or(rig.robot_from_left),
        ..rig
    })
}

/// Where the left camera sits on the robot when nothing says: at the robot centre looking
/// straight ahead, 0.3 m up.
pub fn default_mounting() -> Isometry3<f64> {
    robot_from_forward_camera(0.0, 0.0, 0.3)
}

/// Reads the rig a run's pictures were taken with, for `simulate`, `survey` and `localize`,
/// whose tags are placed through its mounting: `run_mounting` (run.yaml's
/// `robot.robot_from_left`) when given, else the camchain's `stereotag.robot_from_left`. With
/// neither, or with the identity (which `stereotag calibrate` writes: a calibration cannot know
/// the mounting; as a mounting it points the camera at the ceiling), it is an error that says
/// how to give it, unless `accept_default` takes [`default_mounting`] with a warning.
pub fn load_mounted_rig(
    path: &Path,
    run_mounting: Option<Isometry3<f64>>,
    accept_default: bool,
) -> Result<StereoRig, IoError> {
    let (rig, file_mounting) = parse_rig_mounting(path, &read_text(path)?)?;
    let problem = match run_mounting.or(file_mounting) {
        Some(m) if is_identity(&m) => {
            "its `stereotag.robot_from_left` is the identity, as `stereotag calibrate` writes it \
             (a calibration cannot know where the rig sits; the identity points the camera at the \
             ceiling)"
        }
        Some(m) => {
            return Ok(StereoRig {
                robot_from_left: m,
                ..rig
            })
        }
        None => {
            "it says nowhere where the left camera sits on the robot (`stereotag.robot_from_left`)"
        }
    };
    if accept_default {
        tracing::warn!(
            "{}: {problem}: taking the left camera at the robot centre, looking ahead, 0.3 m up (--default-mounting)",
            path.display()
        );
        return Ok(StereoRig {
            robot_from_left: default_mounting(),
            ..rig
        });
    }
    Err(IoError::content(
        path,
        format!(
            "{problem}. Give the mounting as `stereotag: robot_from_left:` (a 4x4 matrix, camera \
             to robot: camera z forward is robot x for a camera looking ahead) in this file or as \
             `robot: robot_from_left: [x, y, z, roll, pitch, yaw]` in run.yaml, or pass \
             --default-mounting to take the left camera at the robot centre, looking ahead, 0.3 m up"
        ),
    ))
}

/// Whether a pose is the identity (to a micrometre and a microradian).
fn is_identity(m: &Isometry3<f64>) -> bool {
    m.translation.vector.norm() < 1e-6 && m.rotation.angle() < 1e-6
}

/// A camchain's rig (with [`default_mounting`]) and its `stereotag.robot_from_left`, if given.
fn parse_rig_mounting(
    path: &Path,
    text: &str,
) -> Result<(StereoRig, Option<Isometry3<f64>>), IoError> {
    let chain: Camchain = parse_yaml(path, text)?;
    let left = camera_from(path, "cam0", &chain.cam0)?;
    let right = camera_from(path, "cam1", &chain.cam1)?;
    let t =
        chain.cam1.t_cn_cnm1.as_ref().ok_or_else(|| {
            IoError::content(path, "`cam1.T_cn_cnm1` (right_from_left) is missing")
        })?;
    let right_from_left = isometry_from(path, "cam1.T_cn_cnm1", t)?;
    let mounting = match chain
        .stereotag
        .as_ref()
        .and_then(|s| s.robot_from_left.as_ref())
    {
        Some(rows) => Some(isometry_from(path, "stereotag.robot_from_left", rows)?),
        None => None,
    };
    let right_from_left_covariance = match chain
        .stereotag
        .as_ref()
        .and_then(|s| s.right_from_left_covariance.as_ref())
    {
        Some(rows) => Some(covariance_from(
            path,
            "stereotag.right_from_left_covariance",
            rows,
        )?),
        None => None,
    };
    let rig = StereoRig {
        left,
        right,
        right_from_left,
        robot_from_left: default_mounting(),
        right_from_left_covariance,
    };
    Ok((rig, mounting))
}

/// A 6x6 covariance from its rows: finite, symmetric (to 1e-9 of its largest entry), with a
/// non-negative diagonal.
fn covariance_from(
    path: &Path,
    key: &str,
    rows: &[Vec<f64>],
) -> Result<nalgebra::Matrix6<f64>, IoError> {
    let shape_ok = rows.len() == 6 && rows.iter().all(|r| r.len() == 6);
    if !shape_ok || rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(IoError::content(
            path,
            format!("`{key}` must be a 6x6 matrix of finite numbers"),
        ));
    }
    let m = nalgebra::Matrix6::from_fn(|i, j| rows[i][j]);
    let scale = m.abs().max().max(1e-300);
    if (m - m.transpose()).abs().max() > 1e-9 * scale || (0..6).any(|i| m[(i, i)] < 0.0) {
        return Err(IoError::content(
            path,
            format!(
                "`{key}` is not a covariance: it must be symmetric with a non-negative diagonal"
            ),
        ));
    }
    Ok(m)
}

/// Writes a stereo rig as a Kalibr camchain YAML file.
pub fn save_rig(path: &Path, rig: &StereoRig) -> Result<(), IoError> {
    save_rig_noted(path, rig, &[])
}

/// [`save_rig`] with `notes` as YAML comment lines at the top of the file (Kalibr and
/// [`load_rig`] read past them): what a reader of the rig must know, such as a calibration
/// written despite failing its checks.
pub fn save_rig_noted(path: &Path, rig: &StereoRig, notes: &[String]) -> Result<(), IoError> {
    let chain = Camchain {
        cam0: kalibr_from(&rig.left, None),
        cam1: kalibr_from(&rig.right, Some(rows_from(&rig.right_from_left))),
        stereotag: Some(StereotagExtras {
            robot_from_left: Some(rows_from(&rig.robot_from_left)),
            right_from_left_covariance: rig
                .right_from_left_covariance
                .map(|c| c.row_iter().map(|r| r.iter().copied().collect()).collect()),
        }),
    };
    let mut text: String = notes.iter().map(|n| format!("# {n}\n")).collect();
    text.push_str(&to_yaml(path, &chain)?);
    write_file(path, text.as_bytes())
}

/// Fixed-point numbers (12 decimals, trailing zeros dropped): YAML 1.1 readers such as PyYAML,
/// which ROS uses, read `1e-5` as a string.
fn fmt_list(values: &[f64]) -> String {
    values
        .iter()
        .map(|v| {
            let s = format!("{v:.12}");
            let s = s.trim_end_matches('0');
            if s.ends_with('.') {
                format!("{s}0")
            } else {
                s.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

fn camera_matrix(c: &Camera) -> [f64; 9] {
    [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0]
}

/// Distortion as OpenCV and ROS list it, with ROS's model name.
fn distortion_list(c: &Camera) -> (&'static str, Vec<f64>) {
    match c.distortion {
        Distortion::None => ("plumb_bob", vec![0.0; 5]),
        Distortion::Radtan { k1, k2, p1, p2, k3 } => ("plumb_bob", vec![k1, k2, p1, p2, k3]),
        Distortion::Equidistant { k1, k2, k3, k4 } => ("equidistant", vec![k1, k2, k3, k4]),
        // Neither OpenCV nor ROS has these models: the parameters under the models' own names.
        Distortion::DoubleSphere { xi, alpha } => ("double_sphere", vec![xi, alpha]),
        Distortion::Eucm { alpha, beta } => ("eucm", vec![alpha, beta]),
    }
}

fn rotation_list(r: &nalgebra::Rotation3<f64>) -> Vec<f64> {
    let m = r.matrix();
    (0..3)
        .flat_map(|i| (0..3).map(move |j| m[(i, j)]))
        .collect()
}

/// Writes the rig and its rectification as OpenCV FileStorage YAML (the keys of
/// `stereoCalibrate` + `stereoRectify`: M1 D1 M2 D2 R T R1 R2 P1 P2 Q).
pub fn save_opencv_stereo(
    path: &Path,
    rig: &StereoRig,
    rect: &crate::camera::Rectification,
) -> Result<(), IoError> {
    let mat = |name: &str, rows: usize, cols: usize, data: &[f64]| {
        format!("{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n", fmt_list(data))
    };
    let (_, d1) = distortion_list(&rig.left);
    let (_, d2) = distortion_list(&rig.right);
    let r = rotation_list(&rig.right_from_left.rotation.to_rotation_matrix());
    let t = rig.right_from_left.translation.vector;
    let p1: Vec<f64> = rect.left_projection().iter().flatten().copied().collect();
    let p2: Vec<f64> = rect.right_projection().iter().flatten().copied().collect();
    let (f, [cx, cy]) = (rect.focal_px, rect.principal_px);
    let q = [
        1.0,
        0.0,
        0.0,
        -cx,
        0.0,
        1.0,
        0.0,
        -cy,
        0.0,
        0.0,
        0.0,
        f,
        0.0,
        0.0,
        -1.0 / rect.baseline_x_m,
        0.0,
    ];
    let mut s = format!(
        "%YAML:1.0\n---\nimage_width: {}\nimage_height: {}\n",
        rig.left.width, rig.left.height
    );
    s += &mat("M1", 3, 3, &camera_matrix(&rig.left));
    s += &mat("D1", 1, d1.len(), &d1);
    s += &mat("M2", 3, 3, &camera_matrix(&rig.right));
    s += &mat("D2", 1, d2.len(), &d2);
    s += &mat("R", 3, 3, &r);
    s += &mat("T", 3, 1, &[t.x, t.y, t.z]);
    s += &mat("R1", 3, 3, &rotation_list(&rect.left_rotation));
    s += &mat("R2", 3, 3, &rotation_list(&rect.right_rotation));
    s += &mat("P1", 3, 4, &p1);
    s += &mat("P2", 3, 4, &p2);
    s += &mat("Q", 4, 4, &q);
    write_file(path, s.as_bytes())
}

/// Writes one camera of a rectified rig as a ROS `camera_info` YAML (camera_calibration_parsers).
pub fn save_camera_info(
    path: &Path,
    name: &str,
    camera: &Camera,
    rotation: &nalgebra::Rotation3<f64>,
    projection: &[[f64; 4]; 3],
) -> Result<(), IoError> {
    let (model, d) = distortion_list(camera);
    let p: Vec<f64> = projection.iter().flatten().copied().collect();
    let s = format!(
        "image_width: {}\nimage_height: {}\ncamera_name: {name}\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [{}]\n\
         distortion_model: {model}\ndistortion_coefficients:\n  rows: 1\n  cols: {}\n  data: [{}]\n\
         rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [{}]\nprojection_matrix:\n  rows: 3\n  cols: 4\n  data: [{}]\n",
        camera.width,
        camera.height,
        fmt_list(&camera_matrix(camera)),
        d.len(),
        fmt_list(&d),
        fmt_list(&rotation_list(rotation)),
        fmt_list(&p),
    );
    write_file(path, s.as_bytes())
}

/// Writes a rig as Kalibr camchain (`camchain.yaml`), OpenCV FileStorage (`opencv_stereo.yaml`)
/// and ROS camera_info (`left.yaml`, `right.yaml`, Bouguet-rectified) into `dir`; returns the
/// rectification.
pub fn save_rig_exports(dir: &Path, rig: &StereoRig) -> Result<Rectification, IoError> {
    save_rig_exports_noted(dir, rig, &[])
}

/// [`save_rig_exports`] with `notes` at the top of `camchain.yaml` ([`save_rig_noted`]).
pub fn save_rig_exports_noted(
    dir: &Path,
    rig: &StereoRig,
    notes: &[String],
) -> Result<Rectification, IoError> {
    let rect = rig.rectify();
    save_rig_noted(&dir.join("camchain.yaml"), rig, notes)?;
    save_opencv_stereo(&dir.join("opencv_stereo.yaml"), rig, &rect)?;
    save_camera_info(
        &dir.join("left.yaml"),
        "left",
        &rig.left,
        &rect.left_rotation,
        &rect.left_projection(),
    )?;
    save_camera_info(
        &dir.join("right.yaml"),
        "right",
        &rig.right,
        &rect.right_rotation,
        &rect.right_projection(),
    )?;
    Ok(rect)
}

/// A Kalibr camchain with one camera, as Kalibr writes a single camera's calibration.
#[derive(Debug, Clone, PartialEq, Serialize)]
struct CameraChain<'a> {
    cam0: &'a KalibrCamera,
}

/// Writes one camera as a one-camera Kalibr camchain (`camchain.yaml`, `notes` at its top),
/// OpenCV FileStorage (`opencv_camera.yaml`: `camera_matrix` and `distortion_coefficients`, as
/// OpenCV's calibration sample writes them) and ROS camera_info (`camera.yaml`, the identity
/// rectification and `P = [K | 0]`) into `dir`.
pub fn save_camera_exports_noted(
    dir: &Path,
    camera: &Camera,
    notes: &[String],
) -> Result<(), IoError> {
    let path = dir.join("camchain.yaml");
    let mut text: String = notes.iter().map(|n| format!("# {n}\n")).collect();
    text.push_str(&to_yaml(
        &path,
        &CameraChain {
            cam0: &kalibr_from(camera, None),
        },
    )?);
    write_file(&path, text.as_bytes())?;
    let (model, d) = distortion_list(camera);
    let mat = |name: &str, rows: usize, cols: usize, data: &[f64]| {
        format!("{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n", fmt_list(data))
    };
    let mut s = format!(
        "%YAML:1.0\n---\nimage_width: {}\nimage_height: {}\n# distortion model: {}\n",
        camera.width,
        camera.height,
        if model == "equidistant" {
            "fisheye (cv::fisheye, k1..k4)"
        } else {
            "k1, k2, p1, p2, k3"
        }
    );
    s += &mat("camera_matrix", 3, 3, &camera_matrix(camera));
    s += &mat("distortion_coefficients", 1, d.len(), &d);
    write_file(&dir.join("opencv_camera.yaml"), s.as_bytes())?;
    let k = camera_matrix(camera);
    save_camera_info(
        &dir.join("camera.yaml"),
        "camera",
        camera,
        &nalgebra::Rotation3::identity(),
        &[
            [k[0], k[1], k[2], 0.0],
            [k[3], k[4], k[5], 0.0],
            [k[6], k[7], k[8], 0.0],
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_calibrations_covariance_round_trips_and_a_bad_one_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut rig = load_rig(Path::new(DEFAULT_RIG)).unwrap();
        let mut cov = nalgebra::Matrix6::from_diagonal_element(1e-8);
        cov[(0, 3)] = 2e-9;
        cov[(3, 0)] = 2e-9;
        rig.right_from_left_covariance = Some(cov);
        let path = dir.path().join("rig.yaml");
        save_rig(&path, &rig).unwrap();
        let back = load_rig(&path).unwrap().right_from_left_covariance.unwrap();
        assert!((back - cov).abs().max() < 1e-15);
        // The first entry made negative: no covariance.
        let mut text = read_text(&path).unwrap();
        let key = text.find("right_from_left_covariance:").unwrap();
        let first = key + text[key..].find("- - ").unwrap() + 4;
        text.insert(first, '-');
        let err = parse_rig(&path, &text).unwrap_err().to_string();
        assert!(err.contains("right_from_left_covariance"), "{err}");
    }

    #[test]
    fn a_mounting_comes_from_the_run_the_file_or_the_flag() {
        let dir = tempfile::tempdir().unwrap();
        let text = read_text(Path::new(DEFAULT_RIG)).unwrap();
        let bare = &text[..text.find("\nstereotag:").unwrap()];
        let path = dir.path().join("rig.yaml");
        std::fs::write(&path, bare).unwrap();
        assert!(load_mounted_rig(&path, None, false).is_err());
        let taken = load_mounted_rig(&path, None, true).unwrap();
        assert_eq!(taken.robot_from_left, default_mounting());
        let from_run = robot_from_forward_camera(0.1, 0.2, 0.5);
        let given = load_mounted_rig(&path, Some(from_run), false).unwrap();
        assert_eq!(given.robot_from_left, from_run);
        // The identity (calibrate's) is refused even when the run gives it.
        assert!(load_mounted_rig(&path, Some(Isometry3::identity()), false).is_err());
        // The bundled rig says where it sits.
        let bundled = load_mounted_rig(Path::new(DEFAULT_RIG), None, false).unwrap();
        let plain = load_rig(Path::new(DEFAULT_RIG)).unwrap();
        assert_eq!(bundled.robot_from_left, plain.robot_from_left);
    }
}
