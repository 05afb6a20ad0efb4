//! AprilTag detection behind one trait, with two real backends: kornia-apriltag (pure Rust) and
//! the AprilRobotics C library (through the `apriltag` crate, built from the source it ships).
//!
//! **Pixel convention.** Both libraries report positions with the top-left pixel's *corner* at
//! (0, 0) (its centre at (0.5, 0.5)): on rendered tags seen head-on, kornia's corners sit
//! +0.500 / +0.502 px and the C library's +0.446 / +0.454 px from the truth in the centre
//! convention. We shift both by [`LIBRARY_TO_CENTRE_PX`] so every position we report has the
//! top-left pixel's centre at (0, 0), as OpenCV, Kalibr and DESIGN.md.
//!
//! Both return corners in the C library's order: counter-clockwise around the tag in the image
//! as the tag is drawn (tag frame corners (-1, 1), (1, 1), (1, -1), (-1, -1) with y up; in the
//! image the first corner is the tag's bottom-left), pixel centres at integer coordinates.
//! kornia-apriltag lists its quad corners in image order; [`KorniaDetector`] projects the tag
//! corners through kornia's (rotation-aware) homography to get the C order (checked against the C library's own test photos in `tests/detect_real.rs`).

use image::GrayImage;
use serde::Serialize;

/// Shift from the libraries' pixel-corner convention to the pixel-centre convention.
pub const LIBRARY_TO_CENTRE_PX: f64 = -0.5;

fn to_centre_convention(p: [f64; 2]) -> [f64; 2] {
    [p[0] + LIBRARY_TO_CENTRE_PX, p[1] + LIBRARY_TO_CENTRE_PX]
}

/// Tag families both backends support.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum TagFamily {
    /// tag36h11, the default: the family of the paper's landmarks and of Kalibr's AprilGrid.
    Tag36h11,
    /// tag25h9.
    Tag25h9,
    /// tag16h5.
    Tag16h5,
    /// tagStandard41h12.
    TagStandard41h12,
}

impl TagFamily {
    /// The name the AprilTag library uses.
    pub fn name(&self) -> &'static str {
        match self {
            TagFamily::Tag36h11 => "tag36h11",
            TagFamily::Tag25h9 => "tag25h9",
            TagFamily::Tag16h5 => "tag16h5",
            TagFamily::TagStandard41h12 => "tagStandard41h12",
        }
    }

    /// From the library's name.
    pub fn from_name(name: &str) -> Option<Self> {
        [
            TagFamily::Tag36h11,
            TagFamily::Tag25h9,
            TagFamily::Tag16h5,
            TagFamily::TagStandard41h12,
        ]
        .into_iter()
        .find(|f| f.name() == name)
    }

    fn kornia(&self) -> kornia_apriltag::family::TagFamilyKind {
        use kornia_apriltag::family::TagFamilyKind as K;
        match self {
            TagFamily::Tag36h11 => K::Tag36H11,
            TagFamily::Tag25h9 => K::Tag25H9,
            TagFamily::Tag16h5 => K::Tag16H5,
            TagFamily::TagStandard41h12 => K::TagStandard41H12,
        }
    }

    fn c(&self) -> apriltag::Family {
        match self {
            TagFamily::Tag36h11 => apriltag::Family::tag_36h11(),
            TagFamily::Tag25h9 => apriltag::Family::tag_25h9(),
            TagFamily::Tag16h5 => apriltag::Family::tag_16h5(),
            TagFamily::TagStandard41h12 => apriltag::Family::tag_standard_41h12(),
        }
    }
}

/// Detector settings shared by both backends.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorConfig {
    /// Families to look for (default: tag36h11).
    pub families: Vec<TagFamily>,
    /// Decimation of the image before quad detection (the C library's `quad_decimate`;
    /// default 2, both libraries' default).
    pub decimate: u32,
    /// Refine the quad edges on the full image after decimation (default: on, both libraries').
    pub refine_edges: bool,
    /// Sharpening of the decoded bits (default 0.25, both libraries').
    pub sharpening: f64,
    /// Largest number of bit errors corrected (C backend; default 2).
    pub max_hamming: usize,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            families: vec![TagFamily::Tag36h11],
            decimate: 2,
            refine_edges: true,
            sharpening: 0.25,
            max_hamming: 2,
        }
    }
}

/// One detected tag.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TagDetection {
    /// Tag id.
    pub id: u32,
    /// Family name.
    pub family: &'static str,
    /// Bits corrected.
    pub hamming: u32,
    /// Corners in the C library's order, pixels.
    pub corners_px: [[f64; 2]; 4],
    /// Centre, pixels.
    pub centre_px: [f64; 2],
}

/// Errors of the detectors.
#[derive(Debug, thiserror::Error)]
pub enum TagError {
    /// A setting is out of range.
    #[error("detector setting {0}")]
    Invalid(String),
    /// The kornia backend failed.
    #[error("kornia-apriltag: {0}")]
    Kornia(String),
    /// The C backend failed.
    #[error("AprilTag C library: {0}")]
    C(String),
}

/// A tag detector.
pub trait TagDetector {
    /// Detects tags in a grey image; the list is sorted by id, then by the centre's x.
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError>;
    /// The backend's name.
    fn name(&self) -> &'static str;
}

fn sort_detections(mut d: Vec<TagDetection>) -> Vec<TagDetection> {
    d.sort_by(|a, b| {
        a.id.cmp(&b.id)
            .then(a.centre_px[0].total_cmp(&b.centre_px[0]))
    });
    d
}

/// kornia-apriltag.
pub struct KorniaDetector {
    config: DetectorConfig,
    decoder: Option<(u32, u32, kornia_apriltag::AprilTagDecoder)>,
}

impl KorniaDetector {
    /// A detector; its buffers are sized on the first image.
    pub fn new(config: DetectorConfig) -> Result<Self, TagError> {
        if config.families.is_empty() || config.decimate == 0 {
            return Err(TagError::Invalid(
                "needs at least one family and a decimation >= 1".into(),
            ));
        }
        Ok(Self {
            config,
            decoder: None,
        })
    }
}

/// Binarisation split between each tile's min and max: 0.5, the C library's midpoint, so both
/// backends see the same black and white (kornia's own default is 0.33).
const KORNIA_THRESHOLD_SPLIT: f32 = 0.5;

/// Tag-frame corners in the C library's order (`apriltag.c`: counter-clockwise from (-1, 1)).
/// kornia lists its quad corners in image order, without the decoded rotation; its homography
/// carries the rotation, so projecting these through it gives the C order.
const C_TAG_CORNERS: [(f32, f32); 4] = [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)];

impl TagDetector for KorniaDetector {
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError> {
        let (w, h) = image.dimensions();
        if !matches!(&self.decoder, Some((dw, dh, _)) if *dw == w && *dh == h) {
            let kinds = self.config.families.iter().map(|f| f.kornia()).collect();
            let mut cfg = kornia_apriltag::DecodeTagsConfig::new(kinds)
                .map_err(|e| TagError::Kornia(e.to_string()))?;
            cfg.downscale_factor = self.config.decimate as usize;
            cfg.refine_edges_enabled = self.config.refine_edges;
            cfg.decode_sharpening = self.config.sharpening as f32;
            cfg.threshold_split = KORNIA_THRESHOLD_SPLIT;
            let size = kornia_image::ImageSize {
                width: w as usize,
                height: h as usize,
            };
            let dec = kornia_apriltag::AprilTagDecoder::new(cfg, size)
                .map_err(|e| TagError::Kornia(e.to_string()))?;
            self.decoder = Some((w, h, dec));
        }
        let Some((_, _, dec)) = self.decoder.as_mut() else {
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
        let out = found?
            .into_iter()
            .filter_map(|d| {
                let family = families.iter().find(|f| f.kornia() == d.tag_family_kind)?;
                let corners_px = C_TAG_CORNERS.map(|(x, y)| {
                    let c = d.quad.homography_project(x, y);
                    to_centre_convention([c.x as f64, c.y as f64])
                });
                Some(TagDetection {
                    id: d.id as u32,
                    family: family.name(),
                    hamming: d.hamming as u32,
                    corners_px,
                    centre_px: to_centre_convention([d.center.x as f64, d.center.y as f64]),
                })
            })
            .collect();
        Ok(sort_detections(out))
    }

    fn name(&self) -> &'static str {
        "kornia"
    }
}

/// The AprilRobotics C library.
pub struct CDetector {
    detector: apriltag::Detector,
    families: Vec<TagFamily>,
}

impl CDetector {
    /// A detector with the given settings.
    pub fn new(config: DetectorConfig) -> Result<Self, TagError> {
        if config.families.is_empty() || config.decimate == 0 {
            return Err(TagError::Invalid(
                "needs at least one family and a decimation >= 1".into(),
            ));
        }
        let mut builder = apriltag::DetectorBuilder::new();
        for f in &config.families {
            builder = builder.add_family_bits(f.c(), config.max_hamming);
        }
        let mut detector = builder.build().map_err(|e| TagError::C(format!("{e:?}")))?;
        detector.set_decimation(config.decimate as f32);
        detector.set_refine_edges(config.refine_edges);
        detector.set_shapening(config.sharpening);
        detector.set_thread_number(1);
        Ok(Self {
            detector,
            families: config.families,
        })
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
        let family = self.families[0].name();
        let out = self
            .detector
            .detect(&img)
            .into_iter()
            .map(|d| TagDetection {
                id: d.id() as u32,
                family,
                hamming: d.hamming() as u32,
                corners_px: d.corners().map(to_centre_convention),
                centre_px: to_centre_convention(d.center()),
            })
            .collect();
        Ok(sort_detections(out))
    }

    fn name(&self) -> &'static str {
        "apriltag-c"
    }
}
