//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// The repository root (tests run with the package root as working directory).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A path under `../shared/data`, or `None` when the shared data is not beside the repo.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let p = root().join("../shared/data").join(rel);
    p.exists().then_some(p)
}

pub fn sample(rel: &str) -> PathBuf {
    root().join("samples").join(rel)
}

/// Largest pixel difference between two cameras' projections over the image (rays through a
/// 33 x 25 grid of the true camera's pixels, those in front of it).
pub fn max_projection_difference_px(
    truth: &stereotag::camera::Camera,
    est: &stereotag::camera::Camera,
) -> f64 {
    let mut worst: f64 = 0.0;
    for i in 0..=32 {
        for j in 0..=24 {
            let px = nalgebra::Point2::new(
                i as f64 * (truth.width - 1) as f64 / 32.0,
                j as f64 * (truth.height - 1) as f64 / 24.0,
            );
            // Pixels beyond a fisheye's 180 degrees have no ray in front of the camera.
            let Some(n) = truth.unproject(&px) else {
                continue;
            };
            let q = est.project(&nalgebra::Vector3::new(n.x, n.y, 1.0)).unwrap();
            worst = worst.max((q - px).norm());
        }
    }
    worst
}

/// Renders `views` calibration pairs of `rig` seeing `target` into `out` (`seed` places the
/// boards); returns the true rig.
pub fn render_calibration(
    out: &std::path::Path,
    rig: &str,
    target: &std::path::Path,
    views: usize,
    seed: u64,
) -> stereotag::camera::StereoRig {
    use stereotag::workflow::render::{render_calibration_sequence, RenderRequest};
    render_calibration_sequence(
        &RenderRequest {
            rig: std::path::Path::new(rig),
            out,
            samples: None,
            every_sample: false,
            motion: None,
            seed,
            force: false,
        },
        views,
        target,
        &stereotag::progress::Silent,
    )
    .unwrap();
    stereotag::io::load_rig(&out.join("rig.yaml")).unwrap()
}

/// Calibrates `input` with `target` into `out` with the defaults; returns report.json.
pub fn calibrate_report(
    target: &std::path::Path,
    input: stereotag::workflow::calibrate::CalibrationInput<'_>,
    out: &std::path::Path,
) -> serde_json::Value {
    use stereotag::workflow::calibrate::{calibrate, CalibrateRequest};
    calibrate(
        &CalibrateRequest::new(target, input, out),
        &stereotag::progress::Silent,
    )
    .unwrap();
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

/// The largest relative difference of fx, fy, cx, cy between the report's camera `cam`
/// (`left`, `right` or `camera`) and `truth`.
pub fn worst_share(
    report: &serde_json::Value,
    cam: &str,
    truth: &stereotag::camera::Camera,
) -> f64 {
    [
        ("fx", truth.fx),
        ("fy", truth.fy),
        ("cx", truth.cx),
        ("cy", truth.cy),
    ]
    .iter()
    .map(|(k, t)| (report[cam][*k].as_f64().unwrap() - t).abs() / t)
    .fold(0.0, f64::max)
}

/// Both cameras' fx, fy, cx, cy and the baseline of a calibration report within a thousandth of
/// the truth.
pub fn assert_rig_within_a_thousandth(
    report: &serde_json::Value,
    truth: &stereotag::camera::StereoRig,
) {
    for (cam, t) in [("left", &truth.left), ("right", &truth.right)] {
        assert!(
            worst_share(report, cam, t) <= 1e-3,
            "{cam}: {}",
            report[cam]
        );
    }
    let baseline = report["metrics"]["baseline_m"].as_f64().unwrap();
    let true_baseline = truth.right_from_left.translation.vector.norm();
    assert!((baseline - true_baseline).abs() <= 1e-3 * true_baseline);
}
