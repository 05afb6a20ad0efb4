//! Inputs the fuzzers (`scripts/fuzz.sh`, cargo-fuzz with AddressSanitizer) found, kept as
//! regression tests. Each must give a clean result, not a crash.

use image::GrayImage;
use stereotag::visual::tags::{
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
    assert!(stereotag::calib::aprilgrid::refine_aprilgrid(image, &found, 6, 0.3).is_empty());
    assert!(stereotag::calib::chessboard::detect_chessboard(image, 9, 6).is_err());
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

/// corners_csv: a tag_id of 2676116726 overflowed `tag_id × 4 + corner_idx` (a panic with debug
/// assertions, a wrong id without). Now a located error.
#[test]
fn a_huge_tag_id_in_a_corner_csv_is_a_located_error() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("1.csv"),
        "#ts,tag_rows,tag_cols,tag_size,tag_spacing,kp_x,kp_y,p_x,p_y,p_z,tag_id,corner_idx\n\
         1,6,6,0.088,0.3,152.7,244.0,0.2288,0.5456,0.0,2676116726,0\n",
    )
    .unwrap();
    let err = stereotag::io::load_corner_csvs(dir.path())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("1.csv:2") && err.contains("tag_id: 2676116726 is too large"),
        "{err}"
    );
}

/// image_detect: a PBM header saying 0 x 4 decoded to an empty image, and the kornia backend's
/// decimation (`1 + (w - 1) / f`) underflowed. Images under 4 px either way now find nothing.
/// image_detect (the CI smoke run, 10 s): `P50 353 353`, a PGM of no columns and 353 rows, made
/// the AprilGrid corner refinement's blur split rows of zero pixels (a panic).
#[test]
fn an_image_of_no_columns_refines_no_corner() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("image.bin");
    std::fs::write(&path, b"P50 353 353").unwrap();
    let image = stereotag::io::load_gray(&path).unwrap();
    assert_eq!(image.width(), 0);
    let mut grid = AprilGridMultiScale::new().unwrap();
    let found = grid.detect(&image).unwrap_or_default();
    assert!(stereotag::calib::aprilgrid::refine_aprilgrid(&image, &found, 6, 0.3).is_empty());
    for (w, h) in [(0, 353), (353, 0)] {
        let empty = GrayImage::new(w, h);
        assert!(stereotag::calib::aprilgrid::refine_aprilgrid(&empty, &[], 6, 0.3).is_empty());
    }
}

#[test]
fn an_empty_image_finds_no_tag() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("image.bin");
    std::fs::write(&path, b"\x50\x34\x30\x0c\x34\x0c\x42\x73\x73\x73\x73\x0e\x80\x00\x00\x00\x00\x00\x00\x73\x00\x00\x00\x00\x73\xff\xff\xd8\xff\xd0\x31").unwrap();
    let image = stereotag::io::load_gray(&path).unwrap();
    assert_eq!(image.width() * image.height(), 0);
    for decimate in [1.0, 2.0] {
        let config = DetectorConfig {
            decimate,
            ..DetectorConfig::default()
        };
        let mut k = KorniaDetector::new(config.clone()).unwrap();
        assert!(k.detect(&image).unwrap().is_empty());
        let mut c = CDetector::new(config).unwrap();
        assert!(c.detect(&image).unwrap().is_empty());
    }
}

/// ros2_bag: an MCAP record claiming 0x6f00..0711 bytes made the reader allocate that much to
/// read it in (AddressSanitizer: allocation too big). The file is now read a MiB at a time and a
/// record longer than the file is an error.
#[test]
fn an_mcap_record_longer_than_its_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.mcap");
    std::fs::write(
        &path,
        b"\x89MCAP0\r\n\x00\x00\x07\x00\x00\x00\x00\x00odo~\x00",
    )
    .unwrap();
    let err = stereotag::io::rosbag::Bag::open(&path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("bad.mcap"), "{err}");
}

/// ros2_bag: an attachment record shorter than its own header made mcap's `parse_record` slice
/// out of bounds (a panic). Records the bag is not read for are no longer parsed.
#[test]
fn a_short_mcap_attachment_is_passed_over() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("attached.mcap");
    let mut bytes = b"\x89MCAP0\r\n".to_vec();
    // An attachment record (opcode 0x09) of 33 bytes: too short for its fields and CRC.
    bytes.push(0x09);
    bytes.extend(33u64.to_le_bytes());
    bytes.extend([0u8; 33]);
    std::fs::write(&path, &bytes).unwrap();
    // Cut short (no footer or end magic): an error naming the file, not a panic.
    let err = stereotag::io::rosbag::Bag::open(&path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("attached.mcap"), "{err}");
}
