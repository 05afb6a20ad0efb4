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
