//! Calibration targets (Kalibr's target YAML: AprilGrid, checkerboard; and our tag board: a grid
//! of ordinary tags of any family with its own id layout) and the one detector that finds any
//! target's corners in an image, each with its position on the board.

use crate::calib::aprilgrid::refine_aprilgrid;
use crate::calib::chessboard::detect_chessboard;
use crate::calib::{aprilgrid_corners, chessboard_board_corners, Corner};
use crate::visual::tags::{
    AprilGridMultiScale, Backend, DetectorConfig, TagDetection, TagDetector, TagError,
};
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
    /// A grid of ordinary tags (1-bit border) of any family, ids in any order.
    Tagboard(TagBoardTarget),
    /// OpenCV's ChArUco board: a chessboard with ArUco markers in its white squares.
    Charuco(crate::calib::CharucoTarget),
}

/// A board of ordinary tags (`target_type: tagboard`): `tagCols x tagRows` tags of `family`,
/// laid out as Kalibr lays an AprilGrid (position 0 at the origin, x along a row, y up the board
/// as printed, pitch `tagSize · (1 + tagSpacing)`), with the tag at each position given by
/// `ids` (row-major from position 0; default 0, 1, 2, ...). Corner `k` of a tag is the AprilTag
/// library's corner `k`, placed as an AprilGrid's ([`crate::calib::aprilgrid_board_point`]);
/// corner ids are tag id × 4 + k.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagBoardTarget {
    /// The tags' family (`tag36h11`, `tag25h9`, `tag16h5`, `tagStandard41h12`).
    pub family: crate::visual::tags::TagFamily,
    /// Tags across.
    #[serde(rename = "tagCols")]
    pub tag_cols: u32,
    /// Tags down.
    #[serde(rename = "tagRows")]
    pub tag_rows: u32,
    /// Tag edge (the black square), metres.
    #[serde(rename = "tagSize")]
    pub tag_size: f64,
    /// Gap between tags over the tag edge.
    #[serde(rename = "tagSpacing")]
    pub tag_spacing: f64,
    /// The tag id at each position, row-major from position 0 (`tagCols · tagRows` distinct
    /// ids); default 0, 1, 2, ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ids: Option<Vec<u32>>,
    #[serde(default, rename = "target_type", skip_serializing)]
    kind: Option<serde::de::IgnoredAny>,
}

impl TagBoardTarget {
    /// The tag id at each position.
    pub fn layout(&self) -> Vec<u32> {
        self.ids
            .clone()
            .unwrap_or_else(|| (0..self.tag_cols * self.tag_rows).collect())
    }

    /// The position of tag `tag` on the board, if it is on it.
    fn position_of(&self, tag: u32) -> Option<u32> {
        match &self.ids {
            Some(ids) => ids.iter().position(|&t| t == tag).map(|p| p as u32),
            None => (tag < self.tag_cols * self.tag_rows).then_some(tag),
        }
    }

    /// Where corner `id` (tag id × 4 + k) sits on the board, if its tag is on it.
    pub fn board_point(&self, id: u32) -> Option<[f64; 3]> {
        let position = self.position_of(id / 4)?;
        Some(crate::calib::aprilgrid_board_point(
            position * 4 + id % 4,
            self.tag_cols,
            self.tag_size,
            self.tag_spacing,
        ))
    }
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
    tags: Option<Box<dyn TagDetector + Send>>,
}

impl TargetDetector {
    /// A detector of `target`'s corners.
    pub fn new(target: &Target) -> Result<Self, TagError> {
        let grid = match target {
            Target::Aprilgrid(_) => Some(AprilGridMultiScale::new()?),
            _ => None,
        };
        // Full resolution: a calibration wants every tag and the best corners.
        let family = match target {
            Target::Tagboard(b) => Some(b.family),
            Target::Charuco(c) => Some(c.dictionary),
            _ => None,
        };
        let tags = match family {
            Some(family) => Some(Backend::ApriltagC.detector(DetectorConfig {
                families: vec![family],
                decimate: 1.0,
                ..DetectorConfig::default()
            })?),
            None => None,
        };
        Ok(Self {
            target: target.clone(),
            grid,
            tags,
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
            (Target::Tagboard(b), _) => {
                let Some(detector) = self.tags.as_mut() else {
                    return Err(TagError::Invalid(
                        "no tag detector was made for this target".into(),
                    ));
                };
                let tags: Vec<TagDetection> = detector
                    .detect(image)?
                    .into_iter()
                    .filter(|t| t.family == b.family && b.board_point(t.id * 4).is_some())
                    .collect();
                let corners = tags
                    .iter()
                    .flat_map(|t| {
                        (0..4).filter_map(move |k| {
                            let id = t.id * 4 + k;
                            Some(Corner {
                                id,
                                board_m: b.board_point(id)?,
                                px: t.corners_px[k as usize],
                            })
                        })
                    })
                    .collect();
                let miss = tags
                    .is_empty()
                    .then(|| format!("no {} tags of the board", b.family));
                TargetView {
                    corners,
                    tags,
                    miss,
                }
            }
            (Target::Charuco(c), _) => {
                let Some(detector) = self.tags.as_mut() else {
                    return Err(TagError::Invalid(
                        "no marker detector was made for this target".into(),
                    ));
                };
                let tags = detector.detect(image)?;
                let corners = c.corners(image, &tags);
                let miss = corners.is_empty().then(|| {
                    format!(
                        "{} {} markers, no corner between two of them",
                        tags.len(),
                        c.dictionary
                    )
                });
                TargetView {
                    corners,
                    tags,
                    miss,
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
