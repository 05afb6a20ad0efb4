//! Any image file through every detector: the AprilTag C library, the kornia backend (our quad
//! stage) and kornia-apriltag's own pipeline, the AprilGrid detector with its corner refinement,
//! and the chessboard detector. Images are read as the commands read them (`io::load_gray`); big
//! ones are skipped to keep runs fast.
#![no_main]
mod common;

use stereotag::visual::tags::{AprilGridMultiScale, CDetector, DetectorConfig, KorniaDetector, TagDetector};

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let path = common::write("image.bin", data);
    let Ok(image) = stereotag::io::load_gray(&path) else {
        return;
    };
    if image.width() as u64 * image.height() as u64 > 256 * 256 {
        return;
    }
    if let Ok(mut c) = CDetector::new(DetectorConfig::default()) {
        let _ = c.detect(&image);
    }
    if let Ok(mut k) = KorniaDetector::new(DetectorConfig::default()) {
        let _ = k.detect(&image);
    }
    let decimate_1 = DetectorConfig {
        decimate: 1.0,
        ..DetectorConfig::default()
    };
    if let Ok(mut k) = KorniaDetector::new(decimate_1.clone()) {
        let _ = k.detect(&image);
    }
    if let Ok(mut k) = KorniaDetector::library(decimate_1) {
        let _ = k.detect(&image);
    }
    if let Ok(mut grid) = AprilGridMultiScale::new() {
        if let Ok(found) = grid.detect(&image) {
            let _ = stereotag::calib::aprilgrid::refine_aprilgrid(&image, &found, 6, 0.3);
        }
    }
    let _ = stereotag::calib::chessboard::detect_chessboard(&image, 9, 6);
});
