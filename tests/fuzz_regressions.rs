//! Inputs the fuzzers (`scripts/fuzz.sh`, cargo-fuzz with AddressSanitizer) found, kept as
//! regression tests. Each must give a clean result, not a crash.

use image::GrayImage;
use stereotag::tags::{
    AprilGridMultiScale, CDetector, DetectorConfig, KorniaDetector, TagDetector,
};

/// Every detector on one image; none may fail or find anything in a blank strip.
fn detect_everything(image: &GrayImage) {
    let mut c = CDetector::new(DetectorConfig::default()).unwrap();
    assert!(c.detect(image).unwrap().is_empty());
    let mut k = KorniaDetector::new(DetectorConfig::default()).unwrap();
    assert!(k.detect(image).unwrap_or_default().is_empty());
    let mut grid = AprilGridMultiScale::new().unwrap();
    let found = grid.detect(image).unwrap();
    assert!(found.is_empty());
    assert!(stereotag::chessboard::refine_aprilgrid(image, &found, 6, 0.3).is_empty());
    assert!(stereotag::chessboard::detect_chessboard(image, 9, 6).is_err());
}

/// image_detect: a 256 x 8 image at decimation 3 is under one of the C library's 4-pixel
/// thresholding tiles, and its `threshold()` read past the heap (AddressSanitizer). Images too
/// small for a tag are no longer handed to the library.
#[test]
fn thin_images_do_not_reach_the_c_library() {
    for (w, h) in [(256, 8), (8, 256), (256, 11), (1, 1), (3, 40)] {
        detect_everything(&GrayImage::from_pixel(w, h, image::Luma([77])));
    }
}
