//! AprilTag detection behind one trait, with two real backends: kornia-apriltag (pure Rust: its
//! threshold, connected components and tag families, with our Rust port of the C library's quad
//! fit and decoding on top, `tagquads`; [`KorniaDetector::library`] runs kornia-apriltag's own
//! pipeline) and the AprilRobotics C library (through the `apriltag` crate, built from the
//! source in `vendor/`).
//!
//! **Pixel convention.** Both libraries report positions with the top-left pixel's *corner* at
//! (0, 0) (its centre at (0.5, 0.5)): on rendered tags seen head-on, kornia-apriltag's own
//! pipeline's corners sit +0.500 / +0.502 px and the C library's (and so our kornia backend's)
//! +0.446 / +0.454 px from the truth in the centre convention. We shift both by [`LIBRARY_TO_CENTRE_PX`] so every position we report has the
//! top-left pixel's centre at (0, 0), as OpenCV, Kalibr and DESIGN.md.
//!
//! Both return corners in the C library's order: counter-clockwise around the tag in the image
//! as the tag is drawn (tag frame corners (-1, 1), (1, 1), (1, -1), (-1, -1) with y up; in the
//! image the first corner is the tag's bottom-left), pixel centres at integer coordinates.
//! kornia-apriltag's own pipeline lists its quad corners in image order; there we project the
//! tag corners through its (rotation-aware) homography to get the C order (checked against the
//! C library's own test photos in `tests/detect_real.rs`).

pub(crate) mod edges;
pub(crate) mod quads;

use image::GrayImage;
use serde::{Deserialize, Serialize};

/// Shift from the libraries' pixel-corner convention to the pixel-centre convention.
pub const LIBRARY_TO_CENTRE_PX: f64 = -0.5;

fn to_centre_convention(p: [f64; 2]) -> [f64; 2] {
    [p[0] + LIBRARY_TO_CENTRE_PX, p[1] + LIBRARY_TO_CENTRE_PX]
}

/// The tag families: the four both backends detect, and Kalibr's AprilGrid tags. Written in
/// files by the AprilTag library's names (`tag36h11`, ...), and ordered by them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum TagFamily {
    /// tag36h11, the default: the family of the paper's landmarks and of Kalibr's AprilGrid.
    #[serde(rename = "tag36h11")]
    Tag36h11,
    /// tag25h9.
    #[serde(rename = "tag25h9")]
    Tag25h9,
    /// tag16h5.
    #[serde(rename = "tag16h5")]
    Tag16h5,
    /// tagStandard41h12.
    #[serde(rename = "tagStandard41h12")]
    TagStandard41h12,
    /// Kalibr's AprilGrid tags: tag36h11's codes with a 2-bit black border, found by the
    /// AprilGrid detector ([`AprilGridDetector`]) alone.
    #[serde(rename = "aprilgrid36h11")]
    Aprilgrid36h11,
}

impl PartialOrd for TagFamily {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for TagFamily {
    /// By name, as the files list them.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.name().cmp(other.name())
    }
}

impl std::fmt::Display for TagFamily {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A tag: its family and id (ids are unique within a family).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TagId {
    /// The family.
    pub family: TagFamily,
    /// The id.
    pub id: u32,
}

/// The families the tag detectors look for (not the AprilGrid's, which its own detector finds).
pub const DETECTABLE_FAMILIES: [TagFamily; 4] = [
    TagFamily::Tag36h11,
    TagFamily::Tag25h9,
    TagFamily::Tag16h5,
    TagFamily::TagStandard41h12,
];

impl TagFamily {
    /// The name the AprilTag library uses.
    pub fn name(&self) -> &'static str {
        match self {
            TagFamily::Tag36h11 => "tag36h11",
            TagFamily::Tag25h9 => "tag25h9",
            TagFamily::Tag16h5 => "tag16h5",
            TagFamily::TagStandard41h12 => "tagStandard41h12",
            TagFamily::Aprilgrid36h11 => "aprilgrid36h11",
        }
    }

    /// A family the detectors look for, from the library's name.
    pub fn from_name(name: &str) -> Option<Self> {
        DETECTABLE_FAMILIES.into_iter().find(|f| f.name() == name)
    }

    fn kornia(&self) -> kornia_apriltag::family::TagFamilyKind {
        use kornia_apriltag::family::TagFamilyKind as K;
        match self {
            TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 => K::Tag36H11,
            TagFamily::Tag25h9 => K::Tag25H9,
            TagFamily::Tag16h5 => K::Tag16H5,
            TagFamily::TagStandard41h12 => K::TagStandard41H12,
        }
    }

    /// The C library's family (null if its constructor fails); free it with [`Self::c_destroy`].
    fn c_create(&self) -> *mut apriltag_sys::apriltag_family_t {
        // SAFETY: the library's constructors take nothing and return an owned family.
        unsafe {
            match self {
                TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 => apriltag_sys::tag36h11_create(),
                TagFamily::Tag25h9 => apriltag_sys::tag25h9_create(),
                TagFamily::Tag16h5 => apriltag_sys::tag16h5_create(),
                TagFamily::TagStandard41h12 => apriltag_sys::tagStandard41h12_create(),
            }
        }
    }

    /// Frees a family from [`Self::c_create`] of the same kind.
    ///
    /// # Safety
    /// `family` came from `self.c_create()`, is not null, and is used by no live detector.
    unsafe fn c_destroy(&self, family: *mut apriltag_sys::apriltag_family_t) {
        // SAFETY: as the caller promises.
        unsafe {
            match self {
                TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 => {
                    apriltag_sys::tag36h11_destroy(family)
                }
                TagFamily::Tag25h9 => apriltag_sys::tag25h9_destroy(family),
                TagFamily::Tag16h5 => apriltag_sys::tag16h5_destroy(family),
                TagFamily::TagStandard41h12 => apriltag_sys::tagStandard41h12_destroy(family),
            }
        }
    }
}

/// A tag's printed pattern as the AprilTag library draws it (`apriltag_to_image`): a square of
/// cells, row-major from the top-left, `true` where white.
#[derive(Debug, Clone, PartialEq)]
pub struct TagImage {
    /// Cells across the whole pattern, the library's 1-cell white border included.
    pub total_cells: usize,
    /// Cells across the black square whose corners are the tag's corners.
    pub black_square_cells: usize,
    /// Row-major, `total_cells²` entries.
    pub white: Vec<bool>,
}

impl TagFamily {
    /// The family's code tables (built once per process: kornia builds a decoding table with them).
    fn tables(&self) -> Option<&'static kornia_apriltag::family::TagFamily> {
        use kornia_apriltag::family::TagFamily as K;
        use std::sync::OnceLock;
        static T36: OnceLock<Option<K>> = OnceLock::new();
        static T25: OnceLock<Option<K>> = OnceLock::new();
        static T16: OnceLock<Option<K>> = OnceLock::new();
        static T41: OnceLock<Option<K>> = OnceLock::new();
        type Cached = OnceLock<Option<K>>;
        let (cell, make): (&Cached, fn() -> Option<K>) = match self {
            TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 => (&T36, || K::tag36_h11().ok()),
            TagFamily::Tag25h9 => (&T25, || K::tag25_h9().ok()),
            TagFamily::Tag16h5 => (&T16, || K::tag16_h5().ok()),
            TagFamily::TagStandard41h12 => (&T41, || K::tagstandard41_h12().ok()),
        };
        cell.get_or_init(make).as_ref()
    }

    /// Number of ids in the family.
    pub fn code_count(&self) -> usize {
        self.tables().map_or(0, |f| f.code_data.len())
    }

    /// The printed pattern of tag `id`, from the family's true code bits; `None` past the last id.
    pub fn code_image(&self, id: u32) -> Option<TagImage> {
        let family = self.tables()?;
        let code = *family.code_data.get(id as usize)?;
        let tw = family.total_width as i64;
        let border = (tw - family.width_at_border as i64) / 2;
        let inside = |v: i64| v >= border && v < tw - border;
        let mut white: Vec<bool> = (0..tw * tw)
            .map(|i| {
                let (x, y) = (i % tw, i / tw);
                if family.reversed_border {
                    // Reversed-border families: black but for a one-cell white ring around the
                    // corner square (`apriltag_to_image`); the code bits lie inside and outside
                    // it.
                    let ring = |v: i64| v == border || v == tw - 1 - border;
                    (ring(x) && inside(y)) || (ring(y) && inside(x))
                } else {
                    !(inside(x) && inside(y))
                }
            })
            .collect();
        for i in 0..family.nbits {
            if code & (1usize << (family.nbits - i - 1)) != 0 {
                let (x, y) = (
                    family.bit_x[i] as i64 + border,
                    family.bit_y[i] as i64 + border,
                );
                if (0..tw).contains(&x) && (0..tw).contains(&y) {
                    white[(y * tw + x) as usize] = true;
                }
            }
        }
        Some(TagImage {
            total_cells: tw as usize,
            black_square_cells: family.width_at_border,
            white,
        })
    }
}

impl DetectorConfig {
    /// An error for a family only the AprilGrid detector finds.
    fn check_families(&self) -> Result<(), TagError> {
        match self
            .families
            .iter()
            .find(|f| !DETECTABLE_FAMILIES.contains(f))
        {
            Some(f) => Err(TagError::Invalid(format!(
                "family {f}: found by the AprilGrid detector, not the tag detectors"
            ))),
            None => Ok(()),
        }
    }
}

/// Detector settings shared by both backends.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorConfig {
    /// Families to look for (default: tag36h11).
    pub families: Vec<TagFamily>,
    /// Decimation of the image before quad detection (the C library's `quad_decimate`;
    /// default 2, both libraries' default). The C library also takes fractions (1.5 resamples
    /// 3 x 3 pixels to 2 x 2); kornia-apriltag only whole factors.
    pub decimate: f32,
    /// Refine the quad edges on the full image after decimation (default: on, both libraries').
    pub refine_edges: bool,
    /// Sharpening of the decoded bits (default 0.25, both libraries').
    pub sharpening: f64,
    /// Largest number of bit errors corrected (C backend; default 2).
    pub max_hamming: usize,
    /// Apply our shared sub-pixel corner refinement ([`refine_corners`]) after either backend
    /// (default: on). On 200 rendered office pairs (C backend, decimate 1) it takes the corner
    /// error from 0.086 / 0.217 px (median / 95th percentile) to 0.066 / 0.150 px.
    pub subpixel: bool,
    /// Smallest grey-level difference between the white and the black of a 4x4-pixel tile's
    /// neighbourhood for the tile to be segmented (the C library's `min_white_black_diff`,
    /// kornia's `min_white_black_difference`; default 5, both libraries'). Raising it skips
    /// low-contrast texture, which is most of what the detectors spend their time on in indoor
    /// images; a tag's border is far above it.
    pub min_contrast: u8,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            families: vec![TagFamily::Tag36h11],
            decimate: 2.0,
            refine_edges: true,
            sharpening: 0.25,
            max_hamming: 2,
            subpixel: true,
            min_contrast: 5,
        }
    }
}

/// One detected tag.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TagDetection {
    /// Tag id.
    pub id: u32,
    /// Family.
    pub family: TagFamily,
    /// Bits corrected.
    pub hamming: u32,
    /// Corners in the C library's order, pixels.
    pub corners_px: [[f64; 2]; 4],
    /// Centre, pixels.
    pub centre_px: [f64; 2],
}

impl TagDetection {
    /// The largest distance between this detection's corners and another's, corner for corner,
    /// pixels (how far apart two detectors put the same tag).
    pub fn corner_offset_px(&self, other: &TagDetection) -> f64 {
        self.corners_px
            .iter()
            .zip(&other.corners_px)
            .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
            .fold(0.0, f64::max)
    }
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

/// The detector backends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// kornia-apriltag's segmentation and tag families with our port of the C library's quad
    /// fit and decoding (pure Rust).
    Kornia,
    /// kornia-apriltag's own pipeline end to end (for comparison: it finds fewer tags).
    KorniaLibrary,
    /// The AprilRobotics C library.
    ApriltagC,
}

impl Backend {
    /// A detector of this backend with `config`, or the error naming the setting it refuses.
    pub fn detector(self, config: DetectorConfig) -> Result<Box<dyn TagDetector + Send>, TagError> {
        Ok(match self {
            Backend::Kornia => Box::new(KorniaDetector::new(config)?),
            Backend::KorniaLibrary => Box::new(KorniaDetector::library(config)?),
            Backend::ApriltagC => Box::new(CDetector::new(config)?),
        })
    }
}

/// A tag detector.
pub trait TagDetector {
    /// Detects tags in a grey image; the list is sorted by id, then by the centre's x.
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError>;
    /// The backend's name.
    fn name(&self) -> &'static str;
}

/// Cells across the black square of a family (its `width_at_border`); `None` where the
/// refinement does not apply (reversed-border families).
fn border_cells(family: TagFamily) -> Option<f64> {
    match family {
        TagFamily::Tag36h11 => Some(8.0),
        TagFamily::Tag25h9 => Some(7.0),
        TagFamily::Tag16h5 => Some(6.0),
        TagFamily::TagStandard41h12 | TagFamily::Aprilgrid36h11 => None,
    }
}

/// Applies [`refine_corners`] to every detection it can improve; the centre becomes the
/// intersection of the refined diagonals.
fn refine_all(image: &GrayImage, detections: &mut [TagDetection]) {
    if detections.is_empty() {
        return;
    }
    let plane = crate::imgproc::Plane::from_gray(image);
    for d in detections.iter_mut() {
        let Some(cells) = border_cells(d.family) else {
            continue;
        };
        let Some(c) = refine_on(&plane, &d.corners_px, cells) else {
            continue;
        };
        let (p, q) = (c[0], c[2]);
        let (r, t) = (c[1], c[3]);
        let (d1, d2) = ([q[0] - p[0], q[1] - p[1]], [t[0] - r[0], t[1] - r[1]]);
        let den = d1[0] * d2[1] - d1[1] * d2[0];
        if den.abs() > 1e-9 {
            let s = ((r[0] - p[0]) * d2[1] - (r[1] - p[1]) * d2[0]) / den;
            d.centre_px = [p[0] + d1[0] * s, p[1] + d1[1] * s];
        }
        d.corners_px = c;
    }
}

fn sort_detections(mut d: Vec<TagDetection>) -> Vec<TagDetection> {
    d.sort_by(|a, b| {
        a.id.cmp(&b.id)
            .then(a.centre_px[0].total_cmp(&b.centre_px[0]))
    });
    d
}

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
                let hamming = (config.max_hamming.min(3) as u8).min(family.max_safe_hamming());
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
                    config.max_hamming as i32,
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

/// Whether a decimation factor is one the detectors take: finite and at least 1.
pub fn valid_decimation(decimate: f32) -> bool {
    decimate >= 1.0 && decimate.is_finite()
}

/// Smallest image side, in pixels after decimation, handed to the C library: its thresholding
/// reads past its tile arrays when the decimated image is under one 4-pixel tile (a 256 x 8
/// image at decimation 3 overflowed the heap; found by fuzzing with AddressSanitizer). No tag
/// fits in fewer pixels anyway.
const C_MIN_SIDE_PX: f32 = 8.0;

/// Whether the C library may be given this image at this decimation.
fn c_can_take(image: &GrayImage, decimate: f32) -> bool {
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

/// Shared sub-pixel refinement of a detected tag's corners (either backend): the four edges of
/// the black square are fitted from the image gradient along them, every pixel of a band inside
/// the black border and the white quiet zone weighted by its gradient across the edge, each
/// edge a quadratic across its chord (lens distortion bends it), and the corners are where
/// adjacent edges cross (the crate's sub-pixel edge fit). `border_cells` is the black square's width in
/// cells (its border is one cell wide). Returns `None` when the tag is too small, an edge shows
/// no gradient, or a corner would move more than a tenth of the tag's edge (at least 1 px): the
/// caller keeps the detector's corners.
pub fn refine_corners(
    image: &GrayImage,
    corners: &[[f64; 2]; 4],
    border_cells: f64,
) -> Option<[[f64; 2]; 4]> {
    refine_on(
        &crate::imgproc::Plane::from_gray(image),
        corners,
        border_cells,
    )
}

/// [`refine_corners`] on an image already converted to floats.
fn refine_on(
    plane: &crate::imgproc::Plane,
    corners: &[[f64; 2]; 4],
    border_cells: f64,
) -> Option<[[f64; 2]; 4]> {
    let dist = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let side = (0..4)
        .map(|k| dist(corners[k], corners[(k + 1) % 4]))
        .sum::<f64>()
        / 4.0;
    if side / border_cells < MIN_CELL_PX {
        return None;
    }
    let fitted = crate::visual::tags::edges::fit_quad(plane, corners, 1.0 / border_cells, None)?;
    let limit = (0.1 * side).max(1.0);
    (0..4)
        .all(|k| dist(fitted[k], corners[k]) <= limit)
        .then_some(fitted)
}

/// Smallest cell, pixels, for [`refine_corners`] (the border must hold the fitting band).
const MIN_CELL_PX: f64 = 1.5;

#[cfg(test)]
mod tests {
    use super::*;

    /// Tags of `family` drawn 9 px per cell on a grey page, slightly sheared so no edge is
    /// axis-aligned, with their ids.
    fn page(family: TagFamily, ids: &[u32]) -> GrayImage {
        let cell = 9.0;
        let mut img = GrayImage::from_pixel(640, 200, image::Luma([170]));
        for (k, &id) in ids.iter().enumerate() {
            let t = family.code_image(id).unwrap();
            let n = t.total_cells as f64;
            let (ox, oy) = (30.0 + 200.0 * k as f64, 40.0);
            for y in 0..200u32 {
                for x in 0..640u32 {
                    // Inverse of a small shear and rotation about the tag's origin.
                    let (dx, dy) = (x as f64 + 0.5 - ox, y as f64 + 0.5 - oy);
                    let (u, v) = (dx + 0.08 * dy, dy - 0.05 * dx);
                    let (cx, cy) = ((u / cell).floor(), (v / cell).floor());
                    if cx >= 0.0 && cy >= 0.0 && cx < n && cy < n {
                        let white = t.white[cy as usize * t.total_cells + cx as usize];
                        img.put_pixel(x, y, image::Luma([if white { 235 } else { 25 }]));
                    }
                }
            }
        }
        img
    }

    #[test]
    fn both_backends_read_every_family_alike() {
        let config = |family| DetectorConfig {
            families: vec![family],
            decimate: 1.0,
            subpixel: false,
            ..DetectorConfig::default()
        };
        for family in [
            TagFamily::Tag36h11,
            TagFamily::Tag25h9,
            TagFamily::Tag16h5,
            TagFamily::TagStandard41h12,
        ] {
            let last = family.code_count() as u32 - 1;
            let ids = [0, 7, last];
            let img = page(family, &ids);
            let c = CDetector::new(config(family))
                .unwrap()
                .detect(&img)
                .unwrap();
            let k = KorniaDetector::new(config(family))
                .unwrap()
                .detect(&img)
                .unwrap();
            let found: Vec<u32> = k.iter().map(|d| d.id).collect();
            assert_eq!(found, ids, "{}: kornia found {found:?}", family.name());
            assert_eq!(c.len(), k.len(), "{}", family.name());
            for (a, b) in c.iter().zip(&k) {
                assert_eq!((a.id, a.hamming), (b.id, b.hamming));
                let e = a.corner_offset_px(b);
                assert!(
                    e < 1e-3,
                    "{} tag {}: corners {e} px apart",
                    family.name(),
                    a.id
                );
            }
        }
    }
}
