//! Kalibr camchain files: the shipped default rig, a real EuRoC calibration, round trips, bad input.

mod common;

use nalgebra::{Point2, Vector3};
use stereotag::io::{load_rig, save_rig};

/// The official EuRoC calibration (sensor.yaml of the ASL VI-Sensor) in Kalibr camchain form.
const EUROC_CAMCHAIN: &str = "
cam0:
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
  - [0.9999972564779, 0.0023080393, 0.0003750431, -0.1100738]
  - [-0.0023105212, 0.9999250989, 0.0119774354, 0.0003991]
  - [-0.0003473845, -0.0119782732, 0.9999282108, -0.0008537]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]
  distortion_model: radtan
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
  rostopic: /cam1/image_raw
";

#[test]
fn default_rig_is_a_small_home_robot_rig() {
    let rig = load_rig(&common::root().join("calibration/rigs/default.yaml")).unwrap();
    assert_eq!((rig.left.width, rig.left.height), (640, 480));
    assert!((rig.baseline_m() - 0.12).abs() < 1e-9);
    // A point 2 m ahead of the robot at camera height projects near the left image centre.
    let p_robot = Vector3::new(2.1, 0.06, 0.35);
    let p_left = rig
        .robot_from_left
        .inverse_transform_vector(&(p_robot - rig.robot_from_left.translation.vector));
    let px = rig.left.project(&p_left).unwrap();
    assert!((px - Point2::new(319.5, 239.5)).norm() < 1.0, "{px}");
}

#[test]
fn euroc_camchain_reads_and_round_trips() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("camchain.yaml");
    std::fs::write(&path, EUROC_CAMCHAIN).unwrap();
    let rig = load_rig(&path).unwrap();
    assert!(
        (rig.baseline_m() - 0.110078).abs() < 1e-5,
        "{}",
        rig.baseline_m()
    );
    let again = tmp.path().join("again.yaml");
    save_rig(&again, &rig).unwrap();
    let back = load_rig(&again).unwrap();
    assert_eq!(back.left, rig.left);
    assert!(
        (back.right_from_left.to_homogeneous() - rig.right_from_left.to_homogeneous())
            .abs()
            .max()
            < 1e-9
    );
}

#[test]
fn bad_rigs_name_the_file_and_key() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        (
            EUROC_CAMCHAIN.replace("[458.654, 457.296", "[-458.654, 457.296"),
            "cam0.intrinsics",
        ),
        (
            EUROC_CAMCHAIN.replace(
                "[0.9999972564779, 0.0023080393",
                "[1.9999972564779, 0.0023080393",
            ),
            "not a rotation",
        ),
        (
            EUROC_CAMCHAIN.replace(
                "distortion_model: radtan\n  intrinsics: [458",
                "distortion_model: fov\n  intrinsics: [458",
            ),
            "cam0.distortion_model",
        ),
        (
            EUROC_CAMCHAIN.replace("rostopic: /cam0/image_raw", "colour: red"),
            "unknown field `colour`",
        ),
    ];
    for (text, expect) in cases {
        let path = tmp.path().join("rig.yaml");
        std::fs::write(&path, text).unwrap();
        let err = load_rig(&path).unwrap_err().to_string();
        assert!(
            err.contains("rig.yaml") && err.contains(expect),
            "expected `{expect}` in {err}"
        );
    }
}

#[test]
fn rig_export_writes_opencv_and_ros_files() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("export");
    let export = stereotag::workflow::rig::export_rig(
        &common::root().join("calibration/rigs/default.yaml"),
        &out,
        false,
    )
    .unwrap();
    assert!((export.rectification.focal_px - 459.5).abs() < 1.0);
    let info = std::fs::read_to_string(out.join("right.yaml")).unwrap();
    assert!(info.contains("distortion_model: plumb_bob") && info.contains("projection_matrix:"));
    // P2[0][3] = f * Tx with Tx = -baseline: -459.5 * 0.12.
    assert!(info.contains("-55.14,"), "{info}");
    let cv = std::fs::read_to_string(out.join("opencv_stereo.yaml")).unwrap();
    assert!(cv.starts_with("%YAML:1.0") && cv.contains("Q: !!opencv-matrix"));
    assert!(
        !cv.contains('e'.to_string().as_str()) || !cv.contains("e-"),
        "no exponents for YAML 1.1 readers"
    );
    let back = load_rig(&out.join("camchain.yaml")).unwrap();
    assert!((back.baseline_m() - 0.12).abs() < 1e-12);
}

/// Outside the repository (an installed binary, another working directory) the default rig
/// comes from the copy built into the binary, the same rig as the repository's file.
#[test]
fn the_default_rig_is_built_in_outside_the_repository() {
    let tmp = tempfile::tempdir().unwrap();
    let world = common::root().join("samples/office/world.yaml");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_stereotag"))
        .current_dir(tmp.path())
        .args(["render", "--world", world.to_str().unwrap()])
        .args(["--pose", "1.2,5.8,2.3", "--out", "pair"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("using the copy built into stereotag"),
        "{stderr}"
    );
    assert!(tmp.path().join("pair/left.png").exists());
    // A rig named explicitly is never replaced: a missing one is an error naming it.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_stereotag"))
        .current_dir(tmp.path())
        .args([
            "render",
            "--world",
            world.to_str().unwrap(),
            "--rig",
            "mine.yaml",
        ])
        .args(["--pose", "1.2,5.8,2.3", "--out", "pair2"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("mine.yaml"));
}
