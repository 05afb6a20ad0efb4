//! Kalibr AprilGrid (tag36h11 with 2-bit borders) on real frames (../shared/data/aprilgrid_frames,
//! expected tag counts from aprilgrid-rs's tests) and a real EuRoC stereo pair calibrated from its
//! images with the official intrinsics.

use std::path::Path;
use stereotag::io::load_gray;
use stereotag::progress::Silent;
use stereotag::visual::tags::{AprilGridMultiScale, TagDetector};
use stereotag::workflow::calibrate::{calibrate, CalibrateRequest, CalibrationInput};

fn detect(name: &str) -> Vec<u32> {
    let img =
        load_gray(&std::path::Path::new("../shared/data/aprilgrid_frames").join(name)).unwrap();
    let mut d = AprilGridMultiScale::new().unwrap();
    d.detect(&img).unwrap().iter().map(|t| t.id).collect()
}

#[test]
fn aprilgrid_frames() {
    // EuRoC: all 36 (OpenCV's aruco with 2-bit borders finds 31, SOURCE.txt).
    let euroc = detect("EuRoC.png");
    assert_eq!(euroc.len(), 36, "{euroc:?}");
    assert!(euroc.iter().all(|&id| id < 36), "{euroc:?}");
    // Two boards: all 72, each id once.
    let mut two = detect("two_boards.png");
    assert_eq!(two.len(), 72, "{two:?}");
    two.dedup();
    assert_eq!(two.len(), 72);
    // TUM-VI's 16-bit fisheye frame: all 36 (22 before the pass on the thinned image).
    let tum = detect("TUM_VI.png");
    assert_eq!(tum.len(), 36, "{tum:?}");
    assert!(tum.iter().all(|&id| id < 36), "{tum:?}");
}

#[test]
fn euroc_pair_calibrates_from_its_images() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal");
    let data = "../shared/data/euroc_aprilgrid/calib/stereo";
    let (left, right) = (format!("{data}/cam0_*.png"), format!("{data}/cam1_*.png"));
    calibrate(
        &CalibrateRequest {
            fix_intrinsics: Some(Path::new("calibration/rigs/euroc_official.yaml")),
            ..CalibrateRequest::new(
                Path::new("calibration/targets/aprilgrid_6x6.yaml"),
                CalibrationInput::Images {
                    left: &left,
                    right: &right,
                },
                &out,
            )
        },
        &Silent,
    )
    .unwrap();
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let m = &r["metrics"];
    // One view: the corner order and board layout are right when the RMS is sub-pixel, and the
    // baseline lands within its sigma (2.4 mm) of the official 110.08 mm.
    assert!(m["rms_px"].as_f64().unwrap() < 0.5, "{m}");
    let b = m["baseline_m"].as_f64().unwrap();
    assert!((b - 0.110078).abs() < 0.004, "baseline {b}");
}

/// `stereotag detect --family aprilgrid36h11` (or `tag36h11b2`) sees the AprilGrid tags the
/// calibration sees: all 36 in the EuRoC frame, all 72 of the two boards; `tag36h11` alone finds
/// at most two there (the 2-bit border is not its 1-bit one).
#[test]
fn detect_sees_kalibr_aprilgrids() {
    let count = |family: &str, frame: &str| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_stereotag"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["detect", "--family", family])
            .arg(Path::new("../shared/data/aprilgrid_frames").join(frame))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let found = json["detections"].as_array().unwrap().clone();
        for d in &found {
            let expected = if family == "tag36h11" {
                "tag36h11"
            } else {
                "aprilgrid36h11"
            };
            assert_eq!(d["family"], expected, "{d}");
        }
        found.len()
    };
    assert_eq!(count("aprilgrid36h11", "EuRoC.png"), 36);
    assert_eq!(count("tag36h11b2", "two_boards.png"), 72);
    assert!(count("tag36h11", "EuRoC.png") <= 2);
}
