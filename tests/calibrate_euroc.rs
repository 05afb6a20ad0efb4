//! Calibration on real EuRoC AprilGrid detections (../shared/data/euroc_aprilgrid, 30 stereo
//! views): with the official intrinsics fixed the baseline must come within 1.5 mm of the official
//! 110.07 mm (issue 4), outliers listed; the free calibration runs and warns that these views
//! (1.5 s of nearly the same pose) do not observe the intrinsics.

use serde_json::Value;
use std::path::Path;
use stereotag::progress::Silent;
use stereotag::workflow::calibrate::{calibrate, CalibrateRequest, CalibrationInput};

/// Official EuRoC baseline, metres (|T_c1_c0 translation| of sensor.yaml).
const OFFICIAL_BASELINE_M: f64 = 0.110078;
/// Issue 4's tolerance on the baseline with intrinsics fixed, metres.
const BASELINE_TOLERANCE_M: f64 = 0.0015;

/// Calibrates from the EuRoC corner files with `fix_intrinsics` or `resolution`, and
/// `rectify_pair`; returns report.json as written.
fn calibrate_corners(
    fix_intrinsics: Option<&str>,
    resolution: Option<(u32, u32)>,
    rectify_pair: Option<(&Path, &Path)>,
    out: &Path,
) -> Value {
    let data = Path::new("../shared/data/euroc_aprilgrid/calib/cam_april");
    let (left, right) = (data.join("cam0"), data.join("cam1"));
    calibrate(
        &CalibrateRequest {
            resolution,
            fix_intrinsics: fix_intrinsics.map(Path::new),
            rectify_pair,
            ..CalibrateRequest::new(
                Path::new("calibration/targets/aprilgrid_6x6.yaml"),
                CalibrationInput::Corners {
                    left: &left,
                    right: &right,
                },
                out,
            )
        },
        &Silent,
    )
    .unwrap();
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

#[test]
fn euroc_baseline_with_official_intrinsics() {
    let dir = tempfile::tempdir().unwrap();
    let stereo = "../shared/data/euroc_aprilgrid/calib/stereo";
    let (l, r) = (
        format!("{stereo}/cam0_1403709395937837056.png"),
        format!("{stereo}/cam1_1403709395937837056.png"),
    );
    let r = calibrate_corners(
        Some("calibration/rigs/euroc_official.yaml"),
        None,
        Some((Path::new(&l), Path::new(&r))),
        &dir.path().join("fixed"),
    );
    let m = &r["metrics"];
    let baseline = m["baseline_m"].as_f64().unwrap();
    assert!(
        (baseline - OFFICIAL_BASELINE_M).abs() <= BASELINE_TOLERANCE_M,
        "baseline {baseline}"
    );
    assert_eq!(m["views_used"].as_u64(), Some(30));
    assert!(m["rms_px"].as_f64().unwrap() < 0.5, "{m}");
    // Corresponding corners share a row after rectification.
    assert!(m["epipolar_error_px"].as_f64().unwrap() < 0.5, "{m}");
    assert!(!r["outliers"].as_array().unwrap().is_empty());
    for f in [
        "camchain.yaml",
        "opencv_stereo.yaml",
        "left.yaml",
        "right.yaml",
    ] {
        assert!(dir.path().join("fixed").join(f).exists(), "{f}");
    }
}

/// Free intrinsics from these corners are not determined (fx came out 2.5 times the official
/// 458 px, the principal point 1400 px right on a 752 px image): the calibration fails loudly,
/// nothing written; `--force-write` writes it marked as failed.
#[test]
fn euroc_free_calibration_fails_loudly_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let data = Path::new("../shared/data/euroc_aprilgrid/calib/cam_april");
    let (left, right) = (data.join("cam0"), data.join("cam1"));
    let request = |out, force_write| CalibrateRequest {
        resolution: Some((752, 480)),
        force_write,
        ..CalibrateRequest::new(
            Path::new("calibration/targets/aprilgrid_6x6.yaml"),
            CalibrationInput::Corners {
                left: &left,
                right: &right,
            },
            out,
        )
    };
    let out = dir.path().join("free");
    let err = calibrate(&request(&out, false), &Silent).unwrap_err();
    assert!(err.is_bad_input());
    let message = err.to_string();
    assert!(
        message.contains("principal point") && message.contains("outside the 752x480 image"),
        "{message}"
    );
    assert!(message.contains("--force-write"), "{message}");
    assert!(!out.exists());
    // Forced: written, and marked in the camchain and the report.
    let forced = dir.path().join("forced");
    calibrate(&request(&forced, true), &Silent).unwrap();
    let camchain = std::fs::read_to_string(forced.join("camchain.yaml")).unwrap();
    assert!(camchain.starts_with("# FAILED CALIBRATION"), "{camchain}");
    stereotag::io::load_rig(&forced.join("camchain.yaml")).unwrap();
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(forced.join("report.json")).unwrap())
            .unwrap();
    assert!(
        !report["failures"].as_array().unwrap().is_empty(),
        "{report}"
    );
}

/// The real EuRoC pair through the rig calibrated from its AprilGrid corners: all 35 tags that
/// both cameras see triangulate, none past the square's gate (their corners 0.05 corner sigmas
/// off a square at the median, 0.85 at most: the gate is 2.0), and each within 10% of the
/// AprilGrid's 88 mm.
#[test]
fn the_real_pairs_tags_pass_the_squares_gate() {
    use stereotag::visual::stereo::StereoConfig;
    use stereotag::visual::tags::{Backend, DetectorConfig, TagFamily};
    use stereotag::workflow::detect::{detect, DetectOutput, DetectRequest};
    let dir = tempfile::tempdir().unwrap();
    calibrate_corners(
        Some("calibration/rigs/euroc_official.yaml"),
        None,
        None,
        &dir.path().join("rig"),
    );
    let stereo = Path::new("../shared/data/euroc_aprilgrid/calib/stereo");
    let images = [
        stereo.join("cam0_1403709395937837056.png"),
        stereo.join("cam1_1403709395937837056.png"),
    ];
    let camchain = dir.path().join("rig/camchain.yaml");
    let output = detect(&DetectRequest {
        images: &images,
        rig: Some(&camchain),
        tag_size_m: Some(0.088),
        sigma_px: StereoConfig::default().sigma_px,
        backend: Backend::ApriltagC,
        config: DetectorConfig {
            families: vec![TagFamily::Aprilgrid36h11],
            ..DetectorConfig::default()
        },
    })
    .unwrap();
    let DetectOutput::Stereo { tags, rejected } = output else {
        panic!("a rig gives stereo tags");
    };
    assert_eq!(tags.len(), 35, "{rejected:?}");
    assert!(
        rejected.iter().all(|r| !r.reason.contains("off a square")),
        "{rejected:?}"
    );
    for t in &tags {
        assert!(
            (t.size_m / 0.088 - 1.0).abs() < 0.1,
            "tag {}: {}",
            t.id,
            t.size_m
        );
    }
}
