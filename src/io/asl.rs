//! ASL dataset folders (the EuRoC layout: `mav0/cam0/data.csv`, `mav0/cam0/data/*.png`,
//! `mav0/cam0/sensor.yaml`, the same for `cam1`, and `state_groundtruth_estimate0/data.csv`), and
//! TUM trajectory files (`timestamp tx ty tz qx qy qz qw`).

use super::rig::{camera_from, isometry_from, KalibrCamera};
use super::{parse_yaml, read_text, IoError};
use crate::camera::Camera;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// One camera of an ASL folder.
#[derive(Debug, Clone, PartialEq)]
pub struct AslCamera {
    /// The camera, from its `sensor.yaml`.
    pub camera: Camera,
    /// `T_BS`: the camera's pose in the body frame.
    pub body_from_camera: Isometry3<f64>,
    /// Its pictures: time stamp (ns) and file, in the order of `data.csv`.
    pub frames: Vec<(i64, PathBuf)>,
    /// `data.csv`, for messages.
    pub list: PathBuf,
}

/// A 4 x 4 matrix as `sensor.yaml` writes it.
#[derive(Debug, Deserialize)]
struct Matrix {
    rows: usize,
    cols: usize,
    data: Vec<f64>,
}

/// The keys of a camera's `sensor.yaml` read here (others, such as `rate_hz`, are passed over).
#[derive(Debug, Deserialize)]
struct SensorYaml {
    #[serde(rename = "T_BS")]
    t_bs: Matrix,
    resolution: Vec<u32>,
    #[serde(default = "pinhole")]
    camera_model: String,
    intrinsics: Vec<f64>,
    distortion_model: String,
    distortion_coefficients: Vec<f64>,
}

fn pinhole() -> String {
    "pinhole".into()
}

/// The folder holding `cam0` and `cam1`: `dir` itself or its `mav0`.
pub fn asl_root(dir: &Path) -> Result<PathBuf, IoError> {
    for root in [dir.to_owned(), dir.join("mav0")] {
        if root.join("cam0").is_dir() && root.join("cam1").is_dir() {
            return Ok(root);
        }
    }
    Err(IoError::content(
        dir,
        "not an ASL folder: expected cam0/ and cam1/ (each with data.csv, data/ and sensor.yaml) here or in mav0/",
    ))
}

/// Reads camera `name` (`cam0`, `cam1`) of an ASL folder's root.
pub fn read_asl_camera(root: &Path, name: &str) -> Result<AslCamera, IoError> {
    let dir = root.join(name);
    let sensor = dir.join("sensor.yaml");
    let yaml: SensorYaml = parse_yaml(&sensor, &read_text(&sensor)?)?;
    let distortion_model = match yaml.distortion_model.as_str() {
        "radial-tangential" | "radtan" | "plumb_bob" => "radtan",
        "equidistant" | "equi" | "fisheye" => "equidistant",
        "none" => "none",
        other => {
            return Err(IoError::content(
                &sensor,
                format!(
                    "`distortion_model` `{other}`: expected radial-tangential, equidistant or none"
                ),
            ))
        }
    };
    let camera = camera_from(
        &sensor,
        name,
        &KalibrCamera {
            camera_model: yaml.camera_model,
            intrinsics: yaml.intrinsics,
            distortion_model: distortion_model.into(),
            distortion_coeffs: yaml.distortion_coefficients,
            resolution: yaml.resolution,
            t_cn_cnm1: None,
            t_cam_imu: None,
            cam_overlaps: None,
            rostopic: None,
            timeshift_cam_imu: None,
        },
    )?;
    let m = &yaml.t_bs;
    if m.rows != 4 || m.cols != 4 || m.data.len() != 16 {
        return Err(IoError::content(
            &sensor,
            format!(
                "`T_BS` must be 4 x 4 with 16 numbers, found {} x {} with {}",
                m.rows,
                m.cols,
                m.data.len()
            ),
        ));
    }
    let rows: Vec<Vec<f64>> = m.data.chunks(4).map(<[f64]>::to_vec).collect();
    let body_from_camera = isometry_from(&sensor, "T_BS", &rows)?;
    let list = dir.join("data.csv");
    let text = read_text(&list)?;
    let mut frames = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (stamp, file) = line.split_once(',').ok_or_else(|| {
            IoError::line(&list, i as u64 + 1, "expected `timestamp [ns],filename`")
        })?;
        let stamp: i64 = stamp.trim().parse().map_err(|_| {
            IoError::line(
                &list,
                i as u64 + 1,
                format!("`{}` is not a time stamp in nanoseconds", stamp.trim()),
            )
        })?;
        let file = dir.join("data").join(file.trim());
        frames.push((stamp, file));
    }
    Ok(AslCamera {
        camera,
        body_from_camera,
        frames,
        list,
    })
}

/// A pose from a translation and a quaternion (x, y, z, w).
fn pose_of(t: [f64; 3], q: [f64; 4]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2])),
    )
}

/// The numbers of a line, located errors when one is not.
fn numbers(path: &Path, line: u64, fields: &[&str]) -> Result<Vec<f64>, IoError> {
    fields
        .iter()
        .map(|f| {
            f.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| IoError::line(path, line, format!("`{}` is not a number", f.trim())))
        })
        .collect()
}

/// Reads a TUM trajectory file: `timestamp tx ty tz qx qy qz qw` a line (seconds, metres),
/// `#` comments.
pub fn read_tum(path: &Path) -> Result<Vec<(f64, Isometry3<f64>)>, IoError> {
    let text = read_text(path)?;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() != 8 {
            return Err(IoError::line(
                path,
                i as u64 + 1,
                format!(
                    "{} fields: a TUM line is `timestamp tx ty tz qx qy qz qw`",
                    fields.len()
                ),
            ));
        }
        let v = numbers(path, i as u64 + 1, &fields)?;
        out.push((v[0], pose_of([v[1], v[2], v[3]], [v[4], v[5], v[6], v[7]])));
    }
    Ok(out)
}

/// A time stamp (ns) and a pose.
pub type StampedIsometry = (i64, Isometry3<f64>);

/// Reads an ASL folder's ground truth (`state_groundtruth_estimate0/data.csv`: time stamp in ns,
/// position, quaternion w x y z, then velocities and biases), if it has one: stamp (ns) and
/// `world_from_body`.
pub fn read_asl_ground_truth(root: &Path) -> Result<Option<Vec<StampedIsometry>>, IoError> {
    let path = root.join("state_groundtruth_estimate0").join("data.csv");
    if !path.is_file() {
        return Ok(None);
    }
    let text = read_text(&path)?;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() < 8 {
            return Err(IoError::line(
                &path,
                i as u64 + 1,
                "expected `timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z, ...`",
            ));
        }
        let stamp: i64 = fields[0].trim().parse().map_err(|_| {
            IoError::line(
                &path,
                i as u64 + 1,
                format!("`{}` is not a time stamp in nanoseconds", fields[0].trim()),
            )
        })?;
        let v = numbers(&path, i as u64 + 1, &fields[1..8])?;
        out.push((stamp, pose_of([v[0], v[1], v[2]], [v[4], v[5], v[6], v[3]])));
    }
    Ok(Some(out))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tum_file_reads_and_a_bad_line_is_located() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("odom.tum");
        std::fs::write(
            &p,
            "# t x y z qx qy qz qw\n1.5 1 2 0 0 0 0.7071068 0.7071068\n",
        )
        .unwrap();
        let poses = read_tum(&p).unwrap();
        assert_eq!(poses.len(), 1);
        assert!((poses[0].1.rotation.euler_angles().2 - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
        std::fs::write(&p, "1.5 1 2 0 0 0 0.7071068\n").unwrap();
        let e = read_tum(&p).unwrap_err().to_string();
        assert!(e.contains(":1") && e.contains("7 fields"), "{e}");
    }
}
