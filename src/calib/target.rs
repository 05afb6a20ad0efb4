//! Calibration targets (Kalibr's target YAML: AprilGrid, checkerboard) and the one detector that
//! finds any target's corners in an image, each with its position on the board.

use crate::calib::aprilgrid::refine_aprilgrid;
use crate::calib::chessboard::detect_chessboard;
use crate::calib::{aprilgrid_corners, chessboard_board_corners, Corner};
use crate::visual::tags::{AprilGridMultiScale, TagDetection, TagDetector, TagError};
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// A calibration target as Kalibr describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "target_type", rename_all = "lowercase")]
pub enum Target {
    /// Kalibr AprilGrid: tag36h11 tags with 2-bit borders in a grid.
    Aprilgrid(AprilGridTarget),
    /// Chessboard by inner corners.
    Checkerboard(CheckerboardTarget),
}

/// A Kalibr AprilGrid (`target_type: aprilgrid`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AprilGridTarget {
    /// Tags across.
    #[serde(rename = "tagCols")]
    pub tag_cols: u32,
    /// Tags down.
    #[serde(rename = "tagRows")]
    pub tag_rows: u32,
    /// Tag edge, metres.
    #[serde(rename = "tagSize")]
    pub tag_size: f64,
    /// Gap between tags over the tag edge.
    #[serde(rename = "tagSpacing")]
    pub tag_spacing: f64,
    #[serde(default, rename = "target_type", skip_serializing)]
    kind: Option<serde::de::IgnoredAny>,
}

/// A chessboard by its inner corners (`target_type: checkerboard`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckerboardTarget {
    /// Inner corners across.
    #[serde(rename = "targetCols")]
    pub target_cols: u32,
    /// Inner corners down.
    #[serde(rename = "targetRows")]
    pub target_rows: u32,
    /// Square height, metres.
    #[serde(rename = "rowSpacingMeters")]
    pub row_spacing_m: f64,
    /// Square width, metres.
    #[serde(rename = "colSpacingMeters")]
    pub col_spacing_m: f64,
    #[serde(default, rename = "target_type", skip_serializing)]
    kind: Option<serde::de::IgnoredAny>,
}

/// What a target's detector found in one image.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetView {
    /// The board's corners found, with their positions on the board.
    pub corners: Vec<Corner>,
    /// An AprilGrid's tags as detected, before the corners were refined (none for a
    /// chessboard).
    pub tags: Vec<TagDetection>,
    /// Why the image gave nothing, when it did not (no tag, no whole chessboard).
    pub miss: Option<String>,
}

/// Finds a target's corners in images: an AprilGrid's tags by the C library with Kalibr's 2-bit
/// border at several scales, their corners refined as X-corners and from the fitted tag edges;
/// a chessboard by our own detector. One per thread (the C detector is not shared).
pub struct TargetDetector {
    target: Target,
    grid: Option<AprilGridMultiScale>,
}

impl TargetDetector {
    /// A detector of `target`'s corners.
    pub fn new(target: &Target) -> Result<Self, TagError> {
        let grid = match target {
            Target::Aprilgrid(_) => Some(AprilGridMultiScale::new()?),
            Target::Checkerboard(_) => None,
        };
        Ok(Self {
            target: target.clone(),
            grid,
        })
    }

    /// The target's corners in `image`.
    pub fn detect(&mut self, image: &GrayImage) -> Result<TargetView, TagError> {
        Ok(match (&self.target, &mut self.grid) {
            (Target::Aprilgrid(g), Some(detector)) => {
                let tags = detector.detect(image)?;
                let points = refine_aprilgrid(image, &tags, g.tag_cols, g.tag_spacing);
                let corners =
                    aprilgrid_corners(&points, g.tag_cols, g.tag_rows, g.tag_size, g.tag_spacing);
                let miss = tags
                    .is_empty()
                    .then(|| format!("{} AprilGrid tags", tags.len()));
                TargetView {
                    corners,
                    tags,
                    miss,
                }
            }
            (Target::Checkerboard(c), _) => {
                match detect_chessboard(image, c.target_cols, c.target_rows) {
                    Ok(px) => TargetView {
                        corners: chessboard_board_corners(
                            &px,
                            c.target_cols,
                            c.col_spacing_m,
                            c.row_spacing_m,
                        ),
                        tags: Vec::new(),
                        miss: None,
                    },
                    Err(miss) => TargetView {
                        corners: Vec::new(),
                        tags: Vec::new(),
                        miss: Some(miss.to_string()),
                    },
                }
            }
            (Target::Aprilgrid(_), None) => {
                return Err(TagError::Invalid(
                    "no AprilGrid detector was made for this target".into(),
                ))
            }
        })
    }
}
