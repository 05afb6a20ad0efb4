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

mod aprilgrid;
mod aruco;
#[rustfmt::skip]
mod aruco_codes;
mod c;
mod decode;
pub(crate) mod edges;
mod family;
mod kornia;
pub(crate) mod quads;

pub use aprilgrid::{
    AprilGridDetector, AprilGridMultiScale, APRILGRID_BORDER_CELLS, APRILGRID_DECIMATIONS,
};
pub use aruco::ArucoDictionary;
pub use c::CDetector;
pub use family::{TagFamily, TagId, TagImage, DETECTABLE_FAMILIES};
pub use kornia::KorniaDetector;

use image::GrayImage;
use serde::Serialize;

/// Shift from the libraries' pixel-corner convention to the pixel-centre convention.
pub const LIBRARY_TO_CENTRE_PX: f64 = -0.5;

fn to_centre_convention(p: [f64; 2]) -> [f64; 2] {
    [p[0] + LIBRARY_TO_CENTRE_PX, p[1] + LIBRARY_TO_CENTRE_PX]
}

impl DetectorConfig {
    /// An error for a family only the AprilGrid detector finds.
    fn check_families(&self) -> Result<(), TagError> {
        match self.families.iter().find(|f| !f.is_detectable()) {
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
    /// Largest number of bit errors corrected; `None` (the default): each family's safe number
    /// ([`TagFamily::default_max_hamming`]: 2 for tag36h11 and tagStandard41h12, 1 for tag25h9,
    /// 0 for tag16h5, whose codes lie so close that corrected bits turn texture into tags).
    pub max_hamming: Option<usize>,
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

impl DetectorConfig {
    /// The bit errors corrected for `family`: the setting, else the family's safe default.
    pub fn hamming_for(&self, family: TagFamily) -> usize {
        self.max_hamming
            .unwrap_or_else(|| family.default_max_hamming())
    }
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            families: vec![TagFamily::Tag36h11],
            decimate: 2.0,
            refine_edges: true,
            sharpening: 0.25,
            max_hamming: None,
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
    ///
    /// ```
    /// use stereotag::visual::tags::{Backend, DetectorConfig, TagFamily};
    ///
    /// // Tag 7 of tag36h11, 20 pixels a cell, on a white page.
    /// let tag = TagFamily::Tag36h11.code_image(7).unwrap();
    /// let (n, cell, margin) = (tag.total_cells as i64, 20, 40);
    /// let side = (n * cell + 2 * margin) as u32;
    /// let image = image::GrayImage::from_fn(side, side, |x, y| {
    ///     let (x, y) = (x as i64 - margin, y as i64 - margin);
    ///     let inside = (0..n * cell).contains(&x) && (0..n * cell).contains(&y);
    ///     let white = !inside || tag.white[((y / cell) * n + x / cell) as usize];
    ///     image::Luma([if white { 255 } else { 0 }])
    /// });
    /// let mut detector = Backend::ApriltagC.detector(DetectorConfig::default())?;
    /// let found = detector.detect(&image)?;
    /// assert_eq!(found.len(), 1);
    /// assert_eq!((found[0].family, found[0].id), (TagFamily::Tag36h11, 7));
    /// println!("centre {:?} px, corners {:?}", found[0].centre_px, found[0].corners_px);
    /// # Ok::<(), stereotag::visual::tags::TagError>(())
    /// ```
    ///
    /// With [`TagFamily::Aprilgrid36h11`] among the families, Kalibr AprilGrid tags (2-bit
    /// border) are found too, by [`AprilGridMultiScale`] (the C library whatever the backend; it
    /// searches its own decimations), beside the backend's search for the other families.
    pub fn detector(self, config: DetectorConfig) -> Result<Box<dyn TagDetector + Send>, TagError> {
        let grids = config.families.contains(&TagFamily::Aprilgrid36h11);
        let mut config = config;
        config.families.retain(|f| *f != TagFamily::Aprilgrid36h11);
        if !grids {
            return self.plain_detector(config);
        }
        let plain = if config.families.is_empty() {
            None
        } else {
            Some(self.plain_detector(config)?)
        };
        Ok(Box::new(WithAprilGrids {
            grids: AprilGridMultiScale::new()?,
            plain,
        }))
    }

    /// The backend's detector of the tag families (not AprilGrids).
    fn plain_detector(
        self,
        config: DetectorConfig,
    ) -> Result<Box<dyn TagDetector + Send>, TagError> {
        Ok(match self {
            Backend::Kornia => Box::new(KorniaDetector::new(config)?),
            Backend::KorniaLibrary => Box::new(KorniaDetector::library(config)?),
            Backend::ApriltagC => Box::new(CDetector::new(config)?),
        })
    }
}

/// AprilGrid tags and, when other families are asked for too, the backend's tags.
struct WithAprilGrids {
    grids: AprilGridMultiScale,
    plain: Option<Box<dyn TagDetector + Send>>,
}

impl TagDetector for WithAprilGrids {
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, TagError> {
        let mut out = self.grids.detect(image)?;
        if let Some(plain) = &mut self.plain {
            out.extend(plain.detect(image)?);
        }
        out.sort_by(|a, b| {
            (a.id, a.family.name())
                .cmp(&(b.id, b.family.name()))
                .then(a.centre_px[0].total_cmp(&b.centre_px[0]))
        });
        Ok(out)
    }

    fn name(&self) -> &'static str {
        self.plain.as_ref().map_or("apriltag-c", |p| p.name())
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
        TagFamily::Aruco(d) => Some(d.cells() as f64 + 2.0),
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

/// Whether a decimation factor is one the detectors take: finite and at least 1.
pub fn valid_decimation(decimate: f32) -> bool {
    decimate >= 1.0 && decimate.is_finite()
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
