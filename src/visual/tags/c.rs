//! The AprilRobotics C library backend (through the `apriltag` crate, built from the source in
//! `vendor/`).

use super::aprilgrid::c_can_take;
use super::*;
use image::GrayImage;

/// The AprilRobotics C library.
pub struct CDetector {
    /// `None` only while dropping.
    detector: Option<apriltag::Detector>,
    /// The families the detector uses, freed after it: the `apriltag` crate hands families to
    /// the C detector and never frees them (the C library leaves that to its caller), which
    /// leaked them once per detector (found by fuzzing with LeakSanitizer).
    owned: Vec<(TagFamily, *mut apriltag_sys::apriltag_family_t)>,
    subpixel: bool,
    decimate: f32,
}

// The family pointers are owned by this value alone and only freed in `drop`.
unsafe impl Send for CDetector {}

impl CDetector {
    /// A detector with the given settings.
    pub fn new(config: DetectorConfig) -> Result<Self, TagError> {
        if config.families.is_empty() || !valid_decimation(config.decimate) {
            return Err(TagError::Invalid(
                "needs at least one family and a decimation >= 1".into(),
            ));
        }
        config.check_families()?;
        // SAFETY: the detector comes from the library's constructor and is owned by the
        // `apriltag::Detector` made from it; each family comes from its constructor, is added to
        // that detector and freed after it in `drop` (or here, if construction fails).
        let (raw, owned) = unsafe {
            let raw = apriltag_sys::apriltag_detector_create();
            if raw.is_null() {
                return Err(TagError::C("apriltag_detector_create failed".into()));
            }
            let mut owned = Vec::new();
            for f in &config.families {
                let family = f.c_create();
                if family.is_null() {
                    apriltag_sys::apriltag_detector_destroy(raw);
                    for (g, p) in owned {
                        TagFamily::c_destroy(&g, p);
                    }
                    return Err(TagError::C(format!("{} constructor failed", f.name())));
                }
                apriltag_sys::apriltag_detector_add_family_bits(
                    raw,
                    family,
                    config.hamming_for(*f) as i32,
                );
                owned.push((*f, family));
            }
            (*raw).qtp.min_white_black_diff = config.min_contrast as i32;
            (raw, owned)
        };
        // SAFETY: `raw` was created by `apriltag_detector_create` above.
        let mut detector = unsafe { apriltag::Detector::from_raw(raw) };
        detector.set_decimation(config.decimate);
        detector.set_refine_edges(config.refine_edges);
        detector.set_shapening(config.sharpening);
        detector.set_thread_number(1);
        Ok(Self {
            detector: Some(detector),
            owned,
            subpixel: config.subpixel,
            decimate: config.decimate,
        })
    }
}

impl Drop for CDetector {
    fn drop(&mut self) {
        // The detector first (it refers to the families), then the families.
        drop(self.detector.take());
        for (family, ptr) in self.owned.drain(..) {
            // SAFETY: created by `c_create` in `new`, no longer used by any detector.
            unsafe { family.c_destroy(ptr) };
        }
    }
}

impl TagDetector for CDetector {
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError> {
        let (w, h) = (image.width() as usize, image.height() as usize);
        let mut img = apriltag::Image::zeros_with_stride(w, h, w)
            .map_err(|e| TagError::C(format!("{e:?}")))?;
        img.as_slice_mut().copy_from_slice(image.as_raw());
        // One family per detector is the common case; with several, the C library does not say
        // which family a detection came from in this binding, so report the first.
        let Some(family) = self.owned.first().map(|(f, _)| *f) else {
            return Ok(Vec::new());
        };
        let Some(detector) = self
            .detector
            .as_mut()
            .filter(|_| c_can_take(image, self.decimate))
        else {
            return Ok(Vec::new());
        };
        let mut out = detector
            .detect(&img)
            .into_iter()
            .map(|d| TagDetection {
                id: d.id() as u32,
                family,
                hamming: d.hamming() as u32,
                corners_px: d.corners().map(to_centre_convention),
                centre_px: to_centre_convention(d.center()),
            })
            .collect::<Vec<_>>();
        if self.subpixel {
            refine_all(image, &mut out);
        }
        Ok(sort_detections(out))
    }

    fn name(&self) -> &'static str {
        "apriltag-c"
    }
}
