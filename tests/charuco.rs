//! ChArUco boards (issue 32, item 6): OpenCV's board, its markers read with OpenCV's ArUco
//! dictionaries.
//! - Views drawn by OpenCV itself (`scripts/opencv_charuco.py`: its `CharucoBoard` drawing seen
//!   by a pinhole camera, one view cut off by the image's edge, one upside down, one of a board
//!   of OpenCV's `DICT_APRILTAG_36h11`, whose tags OpenCV draws upside down), in
//!   `tests/fixtures/charuco`: every corner found has OpenCV's id and lies within 0.15 px of the
//!   truth (median within 0.03 px), and at least as many corners are found as OpenCV's own
//!   `CharucoDetector` finds in the same images (more: a corner whose second marker the image's
//!   edge cuts is kept).
//! - A rendered sequence of a ChArUco board calibrates the rig (intrinsics within 0.1% of the
//!   truth).

mod common;

use serde_json::Value;
use std::path::Path;
use stereotag::calib::{Target, TargetDetector};
use stereotag::workflow::calibrate::CalibrationInput;

const FIXTURES: &str = "tests/fixtures/charuco";

#[test]
fn opencvs_charuco_views_give_the_true_corners_with_opencvs_ids() {
    let meta: Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(FIXTURES).join("views.json")).unwrap(),
    )
    .unwrap();
    let mut all_errors = Vec::new();
    eprintln!("view | in view | OpenCV finds | we find | median px | worst px");
    for (name, view) in meta["views"].as_object().unwrap() {
        let board = format!("{}.yaml", view["board"].as_str().unwrap());
        let target = stereotag::io::load_target(&Path::new(FIXTURES).join(board)).unwrap();
        assert!(matches!(target, Target::Charuco(_)));
        let mut detector = TargetDetector::new(&target).unwrap();
        let image = image::open(Path::new(FIXTURES).join(format!("{name}.png")))
            .unwrap()
            .to_luma8();
        let found = detector.detect(&image).unwrap();
        let truth: std::collections::BTreeMap<u32, [f64; 2]> = view["truth"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                let p = &c["px"];
                (
                    c["id"].as_u64().unwrap() as u32,
                    [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()],
                )
            })
            .collect();
        let mut errors: Vec<f64> = found
            .corners
            .iter()
            .map(|c| {
                let t = truth
                    .get(&c.id)
                    .unwrap_or_else(|| panic!("{name}: corner {} is not in view", c.id));
                (c.px[0] - t[0]).hypot(c.px[1] - t[1])
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        let opencv = view["opencv"].as_array().unwrap().len();
        eprintln!(
            "{name} | {} | {opencv} | {} | {:.3} | {:.3}",
            truth.len(),
            errors.len(),
            errors[errors.len() / 2],
            errors[errors.len() - 1]
        );
        assert!(
            errors.len() >= opencv,
            "{name}: {} < {opencv}",
            errors.len()
        );
        assert!(errors[errors.len() - 1] <= 0.15, "{name}: {errors:?}");
        all_errors.extend(errors);
    }
    all_errors.sort_by(f64::total_cmp);
    let median = all_errors[all_errors.len() / 2];
    eprintln!(
        "all views: {} corners, median {median:.3} px",
        all_errors.len()
    );
    assert!(median <= 0.03, "{median}");
}

#[test]
fn a_rendered_charuco_board_calibrates_the_rig() {
    let target = Path::new("calibration/targets/charuco_11x8.yaml");
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    let truth = common::render_calibration(&seq, "calibration/rigs/default.yaml", target, 24, 1);
    let (left, right) = (
        format!("{}/left/*.png", seq.display()),
        format!("{}/right/*.png", seq.display()),
    );
    let out = dir.path().join("cal");
    let report = common::calibrate_report(
        target,
        CalibrationInput::Images {
            left: &left,
            right: &right,
        },
        &out,
    );
    let m = &report["metrics"];
    eprintln!("ChArUco 11x8: {m}; left {}", report["left"]);
    assert!(m["rms_px"].as_f64().unwrap() <= 0.06, "{m}");
    assert!(m["outliers"].as_u64().unwrap() <= 2, "{m}");
    assert!(m["views_used"].as_u64().unwrap() >= 22, "{m}");
    common::assert_rig_within_a_thousandth(&report, &truth);
    // Markers counted per image; the corners out as EuRoC CSV and mrcal's corners.vnl (7 x 10
    // inner corners an image).
    assert!(
        report["images"][0]["tags"].as_u64().unwrap() >= 40,
        "{}",
        report["images"][0]
    );
    let vnl = std::fs::read_to_string(out.join("corners.vnl")).unwrap();
    assert_eq!(vnl.lines().count(), 1 + 48 * 70);
    assert!(out.join("corners/left").read_dir().unwrap().count() >= 22);
}

#[test]
fn both_backends_read_opencvs_aruco_markers_alike() {
    use stereotag::visual::tags::{Backend, DetectorConfig, TagFamily};
    let family = TagFamily::from_name("DICT_5X5_100").unwrap();
    let image = image::open(Path::new(FIXTURES).join("upside_down.png"))
        .unwrap()
        .to_luma8();
    let detect = |backend: Backend| {
        backend
            .detector(DetectorConfig {
                families: vec![family],
                decimate: 1.0,
                ..DetectorConfig::default()
            })
            .unwrap()
            .detect(&image)
            .unwrap()
    };
    let (c, k) = (detect(Backend::ApriltagC), detect(Backend::Kornia));
    // The board's 24 markers (ids 0-23), upside down, and nothing else.
    let ids: Vec<u32> = c.iter().map(|d| d.id).collect();
    assert_eq!(ids, (0..24).collect::<Vec<_>>());
    assert_eq!(c.len(), k.len());
    for (a, b) in c.iter().zip(&k) {
        assert_eq!(a.id, b.id);
        for (p, q) in a.corners_px.iter().zip(&b.corners_px) {
            assert!((p[0] - q[0]).hypot(p[1] - q[1]) < 0.01, "{a:?} {b:?}");
        }
    }
}

/// Two ChArUco boards side by side, told apart by their markers' ids.
const TWO_BOARDS: &str = "target_type: boards
boards:
  - {target_type: charuco, dictionary: DICT_4X4_50, squaresX: 5, squaresY: 4, squareLength: 0.04, markerLength: 0.03}
  - {target_type: charuco, dictionary: DICT_4X4_50, squaresX: 5, squaresY: 4, squareLength: 0.04, markerLength: 0.03,
     ids: [10, 11, 12, 13, 14, 15, 16, 17, 18, 19]}
";

#[test]
fn several_boards_in_one_view_each_get_their_pose() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("two.yaml");
    std::fs::write(&target, TWO_BOARDS).unwrap();
    let seq = dir.path().join("seq");
    let truth = common::render_calibration(&seq, "calibration/rigs/default.yaml", &target, 24, 3);
    // Both boards in every image, 12 corners each.
    let image = image::open(seq.join("left/000000.png")).unwrap().to_luma8();
    let t = stereotag::io::load_target(&target).unwrap();
    let view = TargetDetector::new(&t).unwrap().detect(&image).unwrap();
    let on_second = view
        .corners
        .iter()
        .filter(|c| c.id >= stereotag::calib::BOARD_ID_STRIDE)
        .count();
    assert_eq!((view.corners.len(), on_second), (24, 12));
    let (left, right) = (
        format!("{}/left/*.png", seq.display()),
        format!("{}/right/*.png", seq.display()),
    );
    let report = common::calibrate_report(
        &target,
        CalibrationInput::Images {
            left: &left,
            right: &right,
        },
        &dir.path().join("cal"),
    );
    let m = &report["metrics"];
    eprintln!("two boards: {m}; left {}", report["left"]);
    // Each board of each view is a view of its own (of 48, those with all 12 corners seen in
    // both cameras).
    assert!(m["views_used"].as_u64().unwrap() >= 36, "{m}");
    assert!(m["rms_px"].as_f64().unwrap() <= 0.1, "{m}");
    common::assert_rig_within_a_thousandth(&report, &truth);
    assert_eq!(report["images"][0]["used"], Value::Bool(true));
    // A tag on two boards is refused, naming the file.
    let bad = dir.path().join("bad.yaml");
    std::fs::write(&bad, TWO_BOARDS.replace("ids: [10,", "ids: [9,")).unwrap();
    let err = stereotag::io::load_target(&bad).unwrap_err().to_string();
    assert!(
        err.contains("bad.yaml") && err.contains("both hold DICT_4X4_50 tag 9"),
        "{err}"
    );
}
