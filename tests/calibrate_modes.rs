//! The everyday calibration modes of issue 32:
//! - one camera (`calibrate --images`): rendered pinhole (AprilGrid, 30 views) and fisheye
//!   (`--model equidistant`, 24 views) sequences give intrinsics within 0.05% of the truth; the
//!   real MRPT photos, one camera at a time, agree with their stereo calibration within three
//!   combined sigmas; the files written are a one-camera Kalibr camchain, OpenCV's and ROS's;
//! - extrinsics only (`--fix-intrinsics`) from one shared view of the rendered AprilGrid with the
//!   true intrinsics: baseline within 1%, rotation within 0.3 degree, each within three of its
//!   reported sigmas, the covariance in the report;
//! - double sphere and extended unified lenses (`--model ds`, `--model eucm`): rendered fisheye
//!   sequences calibrated to 0.1 px RMS, read and written as Kalibr `ds-none` / `eucm-none`;
//! - a board of ordinary tags in its own id order (`target_type: tagboard`, a 6x6 tag36h11
//!   board with reversed ids) rendered and calibrated;
//! - corners and report out: every view's corners as EuRoC CSV (which calibrate again to the same
//!   result) and mrcal's `corners.vnl`, per-image counts, the full covariance and the projection
//!   uncertainty over the image.

mod common;

use serde_json::Value;
use std::path::Path;
use std::process::Command;
use stereotag::camera::{LensModel, StereoRig};
use stereotag::progress::Silent;
use stereotag::workflow::calibrate::{calibrate, CalibrateRequest, CalibrationInput};

const APRILGRID: &str = "calibration/targets/aprilgrid_6x6.yaml";

/// Renders `views` calibration pairs of `rig` into `dir/seq`; returns the true rig.
fn render(dir: &Path, rig: &str, views: usize) -> StereoRig {
    render_target(dir, rig, views, APRILGRID)
}

/// Renders `views` calibration pairs of `rig` seeing `target` into `dir/seq`; returns the true
/// rig.
fn render_target(dir: &Path, rig: &str, views: usize, target: &str) -> StereoRig {
    common::render_calibration(&dir.join("seq"), rig, Path::new(target), views, 1)
}

/// Calibrates `input` into `out` (fixing the intrinsics of `fix` when given); returns
/// report.json as written.
fn run(
    input: CalibrationInput<'_>,
    target: &str,
    model: LensModel,
    fix: Option<&Path>,
    out: &Path,
) -> Value {
    calibrate(
        &CalibrateRequest {
            model,
            fix_intrinsics: fix,
            ..CalibrateRequest::new(Path::new(target), input, out)
        },
        &Silent,
    )
    .unwrap();
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

#[test]
fn one_camera_rendered_pinhole_and_fisheye_within_half_a_thousandth() {
    let dir = tempfile::tempdir().unwrap();
    let truth = render(dir.path(), "calibration/rigs/default.yaml", 30);
    let out = dir.path().join("cal");
    let glob = format!("{}/seq/left/*.png", dir.path().display());
    let report = run(
        CalibrationInput::CameraImages(&glob),
        APRILGRID,
        LensModel::Radtan,
        None,
        &out,
    );
    let pinhole = common::worst_share(&report, "camera", &truth.left);
    eprintln!(
        "one pinhole camera: {} ; intrinsics within {:.4}%",
        report["metrics"],
        100.0 * pinhole
    );
    assert!(pinhole <= 5e-4, "{}", report["camera"]);
    assert!(report.get("left").is_none() && report.get("right_from_left").is_none());
    assert_eq!(report["camera"]["distortion"]["model"], "radtan");
    // The files: a one-camera Kalibr camchain, OpenCV's and ROS's.
    let chain = std::fs::read_to_string(out.join("camchain.yaml")).unwrap();
    assert!(
        chain.contains("cam0:") && !chain.contains("cam1"),
        "{chain}"
    );
    let opencv = std::fs::read_to_string(out.join("opencv_camera.yaml")).unwrap();
    assert!(opencv.starts_with("%YAML:1.0") && opencv.contains("camera_matrix: !!opencv-matrix"));
    let ros = std::fs::read_to_string(out.join("camera.yaml")).unwrap();
    assert!(ros.contains("distortion_model: plumb_bob"), "{ros}");

    let dir = tempfile::tempdir().unwrap();
    let truth = render(dir.path(), "calibration/rigs/fisheye_example.yaml", 24);
    let glob = format!("{}/seq/right/*.png", dir.path().display());
    let report = run(
        CalibrationInput::CameraImages(&glob),
        APRILGRID,
        LensModel::Equidistant,
        None,
        &dir.path().join("cal"),
    );
    let fisheye = common::worst_share(&report, "camera", &truth.right);
    eprintln!(
        "one fisheye camera: {} ; intrinsics within {:.4}%",
        report["metrics"],
        100.0 * fisheye
    );
    assert!(fisheye <= 5e-4, "{}", report["camera"]);
    assert_eq!(report["camera"]["distortion"]["model"], "equidistant");
}

/// The MRPT photos calibrated as a rig into `out`; report.json.
fn mrpt_stereo(out: &Path) -> Value {
    let data = "../shared/data/mrpt_stereo_calib";
    run(
        CalibrationInput::Images {
            left: &format!("{data}/*_left.jpg"),
            right: &format!("{data}/*_right.jpg"),
        },
        "calibration/targets/checkerboard_9x6.yaml",
        LensModel::Radtan,
        None,
        out,
    )
}

#[test]
fn mrpt_one_camera_at_a_time_agrees_with_the_stereo_calibration() {
    let data = "../shared/data/mrpt_stereo_calib";
    let target = "calibration/targets/checkerboard_9x6.yaml";
    let dir = tempfile::tempdir().unwrap();
    let stereo = mrpt_stereo(&dir.path().join("stereo"));
    for side in ["left", "right"] {
        let mono = run(
            CalibrationInput::CameraImages(&format!("{data}/*_{side}.jpg")),
            target,
            LensModel::Radtan,
            None,
            &dir.path().join(side),
        );
        for k in ["fx", "fy", "cx", "cy", "k1", "k2"] {
            let value = |r: &Value, cam: &str| {
                r[cam][k]
                    .as_f64()
                    .or_else(|| r[cam]["distortion"][k].as_f64())
                    .unwrap()
            };
            let (a, b) = (value(&stereo, side), value(&mono, "camera"));
            let sa = stereo["sigmas"][format!("{side}.{k}")].as_f64().unwrap();
            let sb = mono["sigmas"][format!("camera.{k}")].as_f64().unwrap();
            let sigmas = (a - b).abs() / sa.hypot(sb);
            eprintln!("mrpt {side}.{k}: stereo {a:.4} ± {sa:.4}, alone {b:.4} ± {sb:.4}: {sigmas:.2} sigma");
            assert!(sigmas < 3.0, "{side}.{k}: {sigmas} combined sigmas apart");
        }
    }
}

#[test]
fn extrinsics_from_one_shared_view_with_the_true_intrinsics() {
    let dir = tempfile::tempdir().unwrap();
    let truth = render(dir.path(), "calibration/rigs/default.yaml", 21);
    let rig = dir.path().join("seq/rig.yaml");
    let true_baseline = truth.right_from_left.translation.vector.norm();
    for view in ["000000", "000010", "000020"] {
        let (l, r) = (
            format!("{}/seq/left/{view}.png", dir.path().display()),
            format!("{}/seq/right/{view}.png", dir.path().display()),
        );
        let report = run(
            CalibrationInput::Images {
                left: &l,
                right: &r,
            },
            APRILGRID,
            LensModel::Radtan,
            Some(&rig),
            &dir.path().join(view),
        );
        assert_eq!(report["metrics"]["views_used"], 1);
        let t: Vec<f64> = report["right_from_left"]["t_m"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let baseline = t.iter().map(|v| v * v).sum::<f64>().sqrt();
        let sb = report["sigmas"]["baseline_m"].as_f64().unwrap();
        let est = stereotag::io::load_rig(&dir.path().join(view).join("camchain.yaml")).unwrap();
        // The camchain carries the relative pose's covariance to the tags.
        let carried = est
            .right_from_left_covariance
            .expect("the covariance in the camchain");
        let stx = report["sigmas"]["right_from_left.tx"].as_f64().unwrap();
        assert!((carried[(3, 3)].sqrt() - stx).abs() < 1e-6 * stx);
        let angle =
            (truth.right_from_left.rotation.inverse() * est.right_from_left.rotation).angle();
        let error = truth.right_from_left.inverse() * est.right_from_left;
        let sr = ["rx", "ry", "rz"].map(|k| {
            report["sigmas"][format!("right_from_left.{k}")]
                .as_f64()
                .unwrap()
        });
        eprintln!(
            "view {view}: baseline {:.3} mm ± {:.3} (error {:.3} mm), rotation error {:.4} deg, sigmas {:.4} {:.4} {:.4} deg",
            1e3 * baseline,
            1e3 * sb,
            1e3 * (baseline - true_baseline),
            angle.to_degrees(),
            sr[0].to_degrees(),
            sr[1].to_degrees(),
            sr[2].to_degrees()
        );
        assert!((baseline - true_baseline).abs() < 0.01 * true_baseline);
        assert!(angle.to_degrees() < 0.3);
        assert!(
            (baseline - true_baseline).abs() < 3.0 * sb,
            "the sigma covers the error"
        );
        let axis = error.rotation.scaled_axis();
        for i in 0..3 {
            assert!(
                axis[i].abs() < 3.0 * sr[i],
                "rotation axis {i}: {} vs sigma {}",
                axis[i],
                sr[i]
            );
        }
        // The relative pose's covariance: 6x6, symmetric, its diagonal the sigmas squared.
        let names = report["covariance"]["names"].as_array().unwrap();
        assert_eq!(names.len(), 6, "{names:?}");
        let m = report["covariance"]["matrix"].as_array().unwrap();
        let tx = m[3][3].as_f64().unwrap().sqrt();
        let stx = report["sigmas"]["right_from_left.tx"].as_f64().unwrap();
        assert!((tx - stx).abs() <= 1e-9 * stx.max(1e-12), "{tx} vs {stx}");
    }
}

#[test]
fn one_camera_refuses_what_needs_a_rig() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_stereotag"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "calibrate",
            "--target",
            "calibration/targets/checkerboard_9x6.yaml",
            "--images",
            "../shared/data/mrpt_stereo_calib/*_left.jpg",
            "--fix-intrinsics",
            "calibration/rigs/default.yaml",
            "--out",
        ])
        .arg(dir.path().join("cal"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("cannot be used with"));
    assert!(!dir.path().join("cal").exists());
}

#[test]
fn mrpt_corners_come_out_and_calibrate_again() {
    let target = "calibration/targets/checkerboard_9x6.yaml";
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("images");
    let first = mrpt_stereo(&out);
    // Per image: 8 images, each with its 54 corners, used, and its outliers counted.
    let images = first["images"].as_array().unwrap();
    assert_eq!(images.len(), 8);
    for i in images {
        assert_eq!(i["corners"], 54, "{i}");
        assert_eq!(i["used"], true, "{i}");
        assert!(i["outliers"].is_u64() && i["miss"].is_null(), "{i}");
    }
    // mrcal's corners.vnl: a header and 54 corners of each of the 8 images.
    let vnl = std::fs::read_to_string(out.join("corners.vnl")).unwrap();
    assert!(vnl.starts_with("# filename x y level\n"));
    assert_eq!(vnl.lines().count(), 1 + 8 * 54);
    assert!(vnl.lines().nth(1).unwrap().ends_with(" 0"));
    // The full covariance: both cameras' eight intrinsics and the six of right_from_left.
    let names = first["covariance"]["names"].as_array().unwrap();
    assert_eq!(names.len(), 22);
    let m = first["covariance"]["matrix"].as_array().unwrap();
    for (i, row) in m.iter().enumerate() {
        for (j, value) in row.as_array().unwrap().iter().enumerate() {
            let (a, b) = (value.as_f64().unwrap(), m[j][i].as_f64().unwrap());
            assert!((a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-30));
        }
    }
    // The projection uncertainty over each image, larger towards the edges than at the centre.
    let u = first["projection_uncertainty"].as_array().unwrap();
    assert_eq!(u.len(), 2);
    for cam in u {
        let (centre, largest) = (
            cam["centre_px"].as_f64().unwrap(),
            cam["max_px"].as_f64().unwrap(),
        );
        eprintln!(
            "{}: projection uncertainty {centre:.3} px at the centre, {largest:.3} px at most",
            cam["camera"]
        );
        assert!(centre > 0.0 && largest > centre);
        assert_eq!(cam["sigma_px"].as_array().unwrap().len(), 16 * 12);
    }
    // The corners written calibrate again to the same rig.
    let (left, right) = (out.join("corners/left"), out.join("corners/right"));
    let again = calibrate(
        &CalibrateRequest {
            resolution: Some((1024, 768)),
            ..CalibrateRequest::new(
                Path::new(target),
                CalibrationInput::Corners {
                    left: &left,
                    right: &right,
                },
                &dir.path().join("corners"),
            )
        },
        &Silent,
    )
    .unwrap();
    let fx = first["left"]["fx"].as_f64().unwrap();
    let rig = again.calibration.rig;
    assert!(
        (rig.left.fx - fx).abs() < 1e-5 * fx,
        "{} vs {fx}",
        rig.left.fx
    );
    let baseline = first["metrics"]["baseline_m"].as_f64().unwrap();
    assert!((rig.baseline_m() - baseline).abs() < 1e-6);
}

#[test]
fn double_sphere_and_extended_unified_fisheyes_calibrate_to_a_tenth_of_a_pixel() {
    for (rig, model, kalibr) in [
        (
            "calibration/rigs/double_sphere_example.yaml",
            LensModel::DoubleSphere,
            "camera_model: ds",
        ),
        (
            "calibration/rigs/eucm_example.yaml",
            LensModel::Eucm,
            "camera_model: eucm",
        ),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let truth = render(dir.path(), rig, 24);
        let (left, right) = (
            format!("{}/seq/left/*.png", dir.path().display()),
            format!("{}/seq/right/*.png", dir.path().display()),
        );
        let out = dir.path().join("cal");
        let report = run(
            CalibrationInput::Images {
                left: &left,
                right: &right,
            },
            APRILGRID,
            model,
            None,
            &out,
        );
        let chain = std::fs::read_to_string(out.join("camchain.yaml")).unwrap();
        assert!(chain.contains(kalibr), "{chain}");
        let est = stereotag::io::load_rig(&out.join("camchain.yaml")).unwrap();
        let worst = common::max_projection_difference_px(&truth.left, &est.left).max(
            common::max_projection_difference_px(&truth.right, &est.right),
        );
        let rms = report["metrics"]["rms_px"].as_f64().unwrap();
        eprintln!(
            "{model:?}: {} ; left {} ; largest projection difference over the image {worst:.3} px",
            report["metrics"], report["left"]
        );
        assert!(rms <= 0.1, "RMS {rms}");
        assert!(report["metrics"]["views_used"].as_u64().unwrap() >= 15);
        let baseline = report["metrics"]["baseline_m"].as_f64().unwrap();
        let true_baseline = truth.right_from_left.translation.vector.norm();
        assert!((baseline - true_baseline).abs() < 1e-3 * true_baseline);
        assert!(worst < 0.3, "{worst} px");
    }
}

#[test]
fn a_board_of_ordinary_tags_in_reversed_order_calibrates_the_rig() {
    let target = "calibration/targets/tagboard_6x6_reversed.yaml";
    let dir = tempfile::tempdir().unwrap();
    let truth = render_target(dir.path(), "calibration/rigs/default.yaml", 30, target);
    let (left, right) = (
        format!("{}/seq/left/*.png", dir.path().display()),
        format!("{}/seq/right/*.png", dir.path().display()),
    );
    let report = run(
        CalibrationInput::Images {
            left: &left,
            right: &right,
        },
        target,
        LensModel::Radtan,
        None,
        &dir.path().join("cal"),
    );
    let m = &report["metrics"];
    eprintln!("tag board: {m}; left {}", report["left"]);
    assert!(m["rms_px"].as_f64().unwrap() <= 0.1, "{m}");
    assert!(m["views_used"].as_u64().unwrap() >= 28, "{m}");
    common::assert_rig_within_a_thousandth(&report, &truth);
    // Tags found per image, reported.
    assert!(
        report["images"][0]["tags"].as_u64().unwrap() >= 30,
        "{}",
        report["images"][0]
    );
    // A layout that names a tag twice is refused, naming the file.
    let bad = dir.path().join("bad.yaml");
    let text = std::fs::read_to_string(target)
        .unwrap()
        .replace("34, 33", "34, 34");
    std::fs::write(&bad, text).unwrap();
    let err = stereotag::io::load_target(&bad).unwrap_err().to_string();
    assert!(
        err.contains("bad.yaml") && err.contains("34 appears twice"),
        "{err}"
    );
}
