//! Kalibr's AprilGrid tags (tag36h11 codes with a 2-bit black border) by the C library with a
//! widened family, at several scales.

use super::*;
use image::GrayImage;

/// Kalibr's AprilGrid tags: tag36h11 codes inside a black border two bits wide. The AprilTag C
/// library finds them with its own tag36h11 family widened to that border (the black square is
/// 10 cells across, the data bits one cell further in); neither the library's families nor
/// kornia-apriltag decode them as they are. Corners are in the C library's order and our pixel
/// convention.
pub struct AprilGridDetector {
    detector: *mut apriltag_sys::apriltag_detector_t,
    family: *mut apriltag_sys::apriltag_family_t,
}

// The raw pointers are owned by this value alone and used through `&mut self` only.
unsafe impl Send for AprilGridDetector {}

/// Cells across the black square of a Kalibr AprilGrid tag (6 data + 2 x 2 border).
pub const APRILGRID_BORDER_CELLS: i32 = 10;

impl AprilGridDetector {
    /// A detector at the given decimation (1 = full resolution) with edge refinement on or off.
    pub fn new(decimate: f32, refine_edges: bool) -> Result<Self, TagError> {
        if !valid_decimation(decimate) {
            return Err(TagError::Invalid(format!(
                "decimate {decimate}: must be >= 1"
            )));
        }
        // SAFETY: the family comes from the library's constructor; we only widen its border and
        // shift its bit positions (arrays of `nbits` entries it allocated), before handing it to
        // a detector that this value owns and destroys first in `drop`.
        unsafe {
            let family = apriltag_sys::tag36h11_create();
            if family.is_null() {
                return Err(TagError::C("tag36h11_create failed".into()));
            }
            (*family).width_at_border = APRILGRID_BORDER_CELLS;
            (*family).total_width = APRILGRID_BORDER_CELLS + 2;
            for i in 0..(*family).nbits as usize {
                *(*family).bit_x.add(i) += 1;
                *(*family).bit_y.add(i) += 1;
            }
            let detector = apriltag_sys::apriltag_detector_create();
            if detector.is_null() {
                apriltag_sys::tag36h11_destroy(family);
                return Err(TagError::C("apriltag_detector_create failed".into()));
            }
            apriltag_sys::apriltag_detector_add_family_bits(detector, family, 2);
            (*detector).quad_decimate = decimate;
            (*detector).refine_edges = i32::from(refine_edges);
            (*detector).nthreads = 1;
            Ok(Self { detector, family })
        }
    }
}

impl Drop for AprilGridDetector {
    fn drop(&mut self) {
        // SAFETY: both were created in `new` and are destroyed once, detector first.
        unsafe {
            apriltag_sys::apriltag_detector_destroy(self.detector);
            apriltag_sys::tag36h11_destroy(self.family);
        }
    }
}

/// Smallest image side, in pixels after decimation, handed to the C library: its thresholding
/// reads past its tile arrays when the decimated image is under one 4-pixel tile (a 256 x 8
/// image at decimation 3 overflowed the heap; found by fuzzing with AddressSanitizer). No tag
/// fits in fewer pixels anyway.
pub(super) const C_MIN_SIDE_PX: f32 = 8.0;

/// Whether the C library may be given this image at this decimation.
pub(super) fn c_can_take(image: &GrayImage, decimate: f32) -> bool {
    image.width() as f32 / decimate >= C_MIN_SIDE_PX
        && image.height() as f32 / decimate >= C_MIN_SIDE_PX
}

impl TagDetector for AprilGridDetector {
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError> {
        let mut out = Vec::new();
        // SAFETY: the detector was created in `new` and is alive.
        if !c_can_take(image, unsafe { (*self.detector).quad_decimate }) {
            return Ok(out);
        }
        // SAFETY: the image buffer is created with the image's size and filled row by row within
        // its stride; the detections array is read within its size and destroyed once.
        unsafe {
            let im = apriltag_sys::image_u8_create(image.width(), image.height());
            if im.is_null() {
                return Err(TagError::C("image_u8_create failed".into()));
            }
            let stride = (*im).stride as usize;
            for (y, row) in image.as_raw().chunks(image.width() as usize).enumerate() {
                std::ptr::copy_nonoverlapping(row.as_ptr(), (*im).buf.add(y * stride), row.len());
            }
            let detections = apriltag_sys::apriltag_detector_detect(self.detector, im);
            if !detections.is_null() {
                let n = (*detections).size.max(0) as usize;
                let data = (*detections).data as *mut *mut apriltag_sys::apriltag_detection_t;
                for i in 0..n {
                    let d = *data.add(i);
                    out.push(TagDetection {
                        id: (*d).id.max(0) as u32,
                        family: TagFamily::Aprilgrid36h11,
                        hamming: (*d).hamming.max(0) as u32,
                        corners_px: (*d).p.map(to_centre_convention),
                        centre_px: to_centre_convention((*d).c),
                    });
                }
                apriltag_sys::apriltag_detections_destroy(detections);
            }
            apriltag_sys::image_u8_destroy(im);
        }
        Ok(sort_detections(out))
    }

    fn name(&self) -> &'static str {
        "aprilgrid-c"
    }
}

/// Decimations [`AprilGridMultiScale`] runs, finest first (ours: 1, 2, 3: on the EuRoC frame
/// they find 32, 35 and 36 of the 36 tags; the small black squares joining Kalibr's tags at their
/// corners upset the full-resolution segmentation of some, the coarser ones of others).
pub const APRILGRID_DECIMATIONS: [f32; 3] = [1.0, 2.0, 3.0];

/// AprilGrid detection at several decimations, merged by id: each tag is taken from the finest
/// decimation that found it (the corners are refined on the full image at every level); then a
/// pass on the image with its dark areas thinned adds the tags still missing.
pub struct AprilGridMultiScale {
    levels: Vec<AprilGridDetector>,
    /// Runs on the image with its dark areas thinned by one pixel (see [`lighten_3x3`]).
    thinned: AprilGridDetector,
}

impl AprilGridMultiScale {
    /// Detectors at [`APRILGRID_DECIMATIONS`] with edge refinement.
    pub fn new() -> Result<Self, TagError> {
        Ok(Self {
            levels: APRILGRID_DECIMATIONS
                .iter()
                .map(|&d| AprilGridDetector::new(d, true))
                .collect::<Result<_, _>>()?,
            thinned: AprilGridDetector::new(THINNED_DECIMATION, true)?,
        })
    }
}

/// Decimation of the pass on the thinned image.
const THINNED_DECIMATION: f32 = 2.0;

/// The image with each pixel the brightest of its 3 x 3 neighbourhood: dark areas lose a pixel
/// at their edges. On a blurred or low-contrast AprilGrid the small squares between tags bleed
/// into the tags' black borders at their corners, and the C library then sees one dark blob
/// instead of a tag; thinning cuts those bridges (TUM-VI's fisheye frame: 22 of 36 tags found
/// without, 36 with).
fn lighten_3x3(image: &GrayImage) -> GrayImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let src = image.as_raw();
    let mut rows = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (x.saturating_sub(1), (x + 1).min(w - 1));
            rows[y * w + x] = src[y * w + a].max(src[y * w + x]).max(src[y * w + b]);
        }
    }
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        let (a, b) = (y.saturating_sub(1), (y + 1).min(h - 1));
        for x in 0..w {
            out[y * w + x] = rows[a * w + x].max(rows[y * w + x]).max(rows[b * w + x]);
        }
    }
    GrayImage::from_raw(w as u32, h as u32, out).unwrap_or_else(|| image.clone())
}

impl TagDetector for AprilGridMultiScale {
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError> {
        let mut out: Vec<TagDetection> = Vec::new();
        for level in &mut self.levels {
            for d in level.detect(image)? {
                if !out.iter().any(|o| o.id == d.id) {
                    out.push(d);
                }
            }
        }
        if image.width() > 0 && image.height() > 0 {
            for mut d in self.thinned.detect(&lighten_3x3(image))? {
                if !out.iter().any(|o| o.id == d.id) {
                    // Thinning moved each corner about one pixel in along the diagonal: undo it.
                    for c in &mut d.corners_px {
                        let (dx, dy) = (c[0] - d.centre_px[0], c[1] - d.centre_px[1]);
                        let n = dx.hypot(dy).max(1e-9);
                        c[0] += std::f64::consts::SQRT_2 * dx / n;
                        c[1] += std::f64::consts::SQRT_2 * dy / n;
                    }
                    out.push(d);
                }
            }
        }
        Ok(sort_detections(out))
    }

    fn name(&self) -> &'static str {
        "aprilgrid-c-multiscale"
    }
}
