//! The kornia-apriltag backend: its adaptive threshold, connected components and tag families,
//! with our port of the C library's quad fit and decoding on top (`quads.rs`, `decode.rs`), or
//! kornia-apriltag's own pipeline end to end.

use super::*;
use image::GrayImage;

/// kornia-apriltag: its adaptive threshold, connected components and tag families, with the
/// C library's quad stage in Rust on top ([`KorniaDetector::new`], see `tagquads`), or
/// kornia-apriltag's own pipeline end to end ([`KorniaDetector::library`]).
///
/// On the C library's own test photos (47 tags, decimate 1, no edge refinement) kornia's own
/// pipeline finds 34 within 0.5 px of the C library's corners, ours 47 (`tests/detect_real.rs`).
pub struct KorniaDetector {
    config: DetectorConfig,
    stages: KorniaStages,
}

/// Which stages a [`KorniaDetector`] runs after kornia's segmentation.
enum KorniaStages {
    /// Our port of the C library's quad fit and decoding, with kornia's family tables.
    OwnQuads(Vec<kornia_apriltag::family::TagFamily>),
    /// kornia-apriltag's decoder end to end; built on the first image (sized by it).
    Library(Option<(u32, u32, Box<kornia_apriltag::AprilTagDecoder>)>),
}

impl KorniaDetector {
    /// A detector: kornia-apriltag's segmentation and families, our quad fit and decoding.
    pub fn new(config: DetectorConfig) -> Result<Self, TagError> {
        Self::check(&config)?;
        let families = config
            .families
            .iter()
            .map(|f| {
                let mut family = kornia_apriltag::family::TagFamily::try_from(f.kornia())
                    .map_err(|e| TagError::Kornia(e.to_string()))?;
                let hamming = (config.hamming_for(*f).min(3) as u8).min(family.max_safe_hamming());
                family
                    .set_max_hamming(hamming)
                    .map_err(|e| TagError::Kornia(e.to_string()))?;
                Ok(family)
            })
            .collect::<Result<Vec<_>, TagError>>()?;
        Ok(Self {
            config,
            stages: KorniaStages::OwnQuads(families),
        })
    }

    /// A detector running kornia-apriltag's own pipeline end to end (its quad fit and decoder),
    /// as the parity table measures it; its buffers are sized on the first image.
    pub fn library(config: DetectorConfig) -> Result<Self, TagError> {
        Self::check(&config)?;
        Ok(Self {
            config,
            stages: KorniaStages::Library(None),
        })
    }

    fn check(config: &DetectorConfig) -> Result<(), TagError> {
        if config.families.is_empty() || !valid_decimation(config.decimate) {
            return Err(TagError::Invalid(
                "needs at least one family and a decimation >= 1".into(),
            ));
        }
        config.check_families()?;
        if config.decimate.fract() != 0.0 {
            return Err(TagError::Invalid(format!(
                "decimation {}: kornia-apriltag decimates by whole factors (fractions need the \
                 C library's backend, apriltag-c)",
                config.decimate
            )));
        }
        Ok(())
    }

    fn detect_own(
        &self,
        families: &[kornia_apriltag::family::TagFamily],
        image: &GrayImage,
    ) -> Result<Vec<TagDetection>, TagError> {
        let settings = crate::visual::tags::quads::QuadSettings {
            decimate: self.config.decimate as u32,
            refine_edges: self.config.refine_edges,
            sharpening: self.config.sharpening,
            min_contrast: self.config.min_contrast,
        };
        let found = crate::visual::tags::quads::detect(image, families, &settings)
            .map_err(TagError::Kornia)?;
        Ok(found
            .into_iter()
            .map(|d| TagDetection {
                id: d.id,
                family: self.config.families[d.family],
                hamming: d.hamming,
                corners_px: d.corners.map(to_centre_convention),
                centre_px: to_centre_convention(d.centre),
            })
            .collect())
    }

    fn detect_library(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError> {
        let (w, h) = image.dimensions();
        let KorniaStages::Library(decoder) = &mut self.stages else {
            return Ok(Vec::new());
        };
        if !matches!(decoder, Some((dw, dh, _)) if *dw == w && *dh == h) {
            let kinds = self.config.families.iter().map(|f| f.kornia()).collect();
            let mut cfg = kornia_apriltag::DecodeTagsConfig::new(kinds)
                .map_err(|e| TagError::Kornia(e.to_string()))?;
            cfg.downscale_factor = self.config.decimate as usize;
            cfg.refine_edges_enabled = self.config.refine_edges;
            cfg.decode_sharpening = self.config.sharpening as f32;
            cfg.threshold_split = KORNIA_THRESHOLD_SPLIT;
            cfg.min_white_black_difference = self.config.min_contrast;
            let size = kornia_image::ImageSize {
                width: w as usize,
                height: h as usize,
            };
            let dec = kornia_apriltag::AprilTagDecoder::new(cfg, size)
                .map_err(|e| TagError::Kornia(e.to_string()))?;
            *decoder = Some((w, h, Box::new(dec)));
        }
        let Some((_, _, dec)) = decoder.as_mut() else {
            return Ok(Vec::new());
        };
        let size = kornia_image::ImageSize {
            width: w as usize,
            height: h as usize,
        };
        let img = kornia_image::Image::<u8, 1>::from_size_slice(size, image.as_raw())
            .map_err(|e| TagError::Kornia(e.to_string()))?;
        let found = dec
            .decode(&img)
            .map_err(|e| TagError::Kornia(e.to_string()));
        dec.clear();
        let families = &self.config.families;
        Ok(found?
            .into_iter()
            .filter_map(|d| {
                let family = families.iter().find(|f| f.kornia() == d.tag_family_kind)?;
                let corners_px = C_TAG_CORNERS.map(|(x, y)| {
                    let c = d.quad.homography_project(x, y);
                    to_centre_convention([c.x as f64, c.y as f64])
                });
                Some(TagDetection {
                    id: d.id as u32,
                    family: *family,
                    hamming: d.hamming as u32,
                    corners_px,
                    centre_px: to_centre_convention([d.center.x as f64, d.center.y as f64]),
                })
            })
            .collect())
    }
}

/// Binarisation split between each tile's min and max for kornia's own pipeline: 0.5, the C
/// library's midpoint, so both backends see the same black and white (kornia's own default is
/// 0.33; on the C library's test photos it leaves 4 of 47 tags within 0.5 px).
const KORNIA_THRESHOLD_SPLIT: f32 = 0.5;

/// Tag-frame corners in the C library's order (`apriltag.c`: counter-clockwise from (-1, 1)).
/// kornia lists its quad corners in image order, without the decoded rotation; its homography
/// carries the rotation, so projecting these through it gives the C order.
const C_TAG_CORNERS: [(f32, f32); 4] = [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)];

impl TagDetector for KorniaDetector {
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError> {
        let mut out = match &self.stages {
            KorniaStages::OwnQuads(families) => self.detect_own(families, image)?,
            KorniaStages::Library(_) => self.detect_library(image)?,
        };
        if self.config.subpixel {
            refine_all(image, &mut out);
        }
        Ok(sort_detections(out))
    }

    fn name(&self) -> &'static str {
        match self.stages {
            KorniaStages::OwnQuads(_) => "kornia",
            KorniaStages::Library(_) => "kornia-library",
        }
    }
}
