//! Chessboards seen in part (issue 32, item 6): the corners that are found are used. A part
//! cannot be numbered as the board is (its rows and columns look alike), but its corners lie on
//! the board's grid, so it is numbered from its own first corner and solved with a board pose
//! of its own; in a rig, such a view is a view of its camera alone (`VIEW#left`, `VIEW#right`).
//! Rendered pairs of the 9x6 board, every other left image cut half a square past corner column
//! 4 (24 of the 54 corners left) and every fourth right image past row 2 (27 left), calibrate
//! the rig as well as whole boards do: intrinsics within 0.1% of the truth.

mod common;

use serde_json::Value;
use std::path::Path;
use stereotag::workflow::calibrate::CalibrationInput;

const CHESSBOARD: &str = "calibration/targets/checkerboard_9x6.yaml";

/// Paints grey over the side of the line through `a` and `b` away from `keep`, as the image's
/// edge would cut the board there.
fn cut(image: &mut image::GrayImage, a: [f64; 2], b: [f64; 2], keep: [f64; 2]) {
    let side = |p: [f64; 2]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
    let kept = side(keep).signum();
    for (x, y, px) in image.enumerate_pixels_mut() {
        if side([x as f64, y as f64]).signum() != kept {
            px.0 = [128];
        }
    }
}

/// The midpoint between corners `i` and `j` of a frame in camera `cam` (`left_px`, `right_px`).
fn mid(frame: &Value, cam: &str, i: usize, j: usize) -> [f64; 2] {
    let p = |k: usize| {
        let c = &frame["corners"][k][cam];
        [c[0].as_f64().unwrap(), c[1].as_f64().unwrap()]
    };
    let (a, b) = (p(i), p(j));
    [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]
}

#[test]
fn chessboards_seen_in_part_calibrate_the_rig_and_one_camera() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    let target = Path::new(CHESSBOARD);
    let truth = common::render_calibration(&seq, "calibration/rigs/default.yaml", target, 20, 5);
    let frames: Value =
        serde_json::from_str(&std::fs::read_to_string(seq.join("truth.json")).unwrap()).unwrap();
    // Corner (c, r) is frame corner r * 9 + c.
    for (k, frame) in frames["frames"].as_array().unwrap().iter().enumerate() {
        let name = format!("{k:06}.png");
        if k % 2 == 0 {
            // Left: keep columns 5-8, cut between columns 4 and 5.
            let path = seq.join("left").join(&name);
            let mut image = image::open(&path).unwrap().to_luma8();
            let (a, b) = (mid(frame, "left_px", 4, 5), mid(frame, "left_px", 49, 50));
            cut(&mut image, a, b, mid(frame, "left_px", 8, 53));
            image.save(&path).unwrap();
        }
        if k % 4 == 1 {
            // Right: keep rows 0-2, cut between rows 2 and 3.
            let path = seq.join("right").join(&name);
            let mut image = image::open(&path).unwrap().to_luma8();
            let (a, b) = (
                mid(frame, "right_px", 18, 27),
                mid(frame, "right_px", 26, 35),
            );
            cut(&mut image, a, b, mid(frame, "right_px", 0, 8));
            image.save(&path).unwrap();
        }
    }
    let (left, right) = (
        format!("{}/left/*.png", seq.display()),
        format!("{}/right/*.png", seq.display()),
    );
    let report = common::calibrate_report(
        target,
        CalibrationInput::Images {
            left: &left,
            right: &right,
        },
        &dir.path().join("cal"),
    );
    let m = &report["metrics"];
    eprintln!("rig, parts: {m}; left {}", report["left"]);
    // 20 views, of which 10 cut in the left image and 5 in the right: those 13 are 26 views of
    // one camera each.
    assert_eq!(m["views_used"].as_u64().unwrap(), 7 + 26, "{m}");
    assert!(m["rms_px"].as_f64().unwrap() <= 0.1, "{m}");
    common::assert_rig_within_a_thousandth(&report, &truth);
    // The cut image's 24 corners, used; no miss.
    let first = &report["images"][0];
    assert_eq!(first["corners"], 24, "{first}");
    assert_eq!(first["used"], Value::Bool(true), "{first}");
    assert!(first["miss"].is_null(), "{first}");

    // One camera: the left images, half of them cut.
    let report = common::calibrate_report(
        target,
        CalibrationInput::CameraImages(&left),
        &dir.path().join("cal-left"),
    );
    eprintln!(
        "left alone, parts: {}; {}",
        report["metrics"], report["camera"]
    );
    assert_eq!(report["metrics"]["views_used"].as_u64().unwrap(), 20);
    assert!(
        common::worst_share(&report, "camera", &truth.left) <= 1e-3,
        "{}",
        report["camera"]
    );
}
