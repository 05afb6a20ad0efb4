//! Calibration targets (Kalibr's target YAML: AprilGrid, checkerboard; and our tag board: a grid
//! of ordinary tags of any family with its own id layout) and the one detector that finds any
//! target's corners in an image, each with its position on the board.

use crate::calib::aprilgrid::refine_aprilgrid;
use crate::calib::chessboard::{find_chessboard, ChessboardFound};
use crate::calib::{aprilgrid_corners, chessboard_board_corners, Corner};
use crate::visual::tags::{
    AprilGridMultiScale, Backend, DetectorConfig, TagDetection, TagDetector, TagError, TagFamily,
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
    /// Several boards seen together (tag boards and ChArUco boards, each tag on one board
    /// alone), each its own rigid board: every board seen in a view gets its own pose.
    Boards(BoardsTarget),
}

/// Corner ids of several boards: board `k`'s corner `id` is `k · BOARD_ID_STRIDE + id`.
pub const BOARD_ID_STRIDE: u32 = 1 << 20;

/// Several boards (`target_type: boards`, `boards:` a list of tag board and ChArUco targets).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardsTarget {
    /// The boards, in the order their corner ids are offset.
    pub boards: Vec<Target>,
    #[serde(default, rename = "target_type", skip_serializing)]
    kind: Option<serde::de::IgnoredAny>,
}

impl Target {
    /// The boards: several boards' list, else the target itself.
    pub fn boards(&self) -> Vec<&Target> {
        match self {
            Target::Boards(b) => b.boards.iter().collect(),
            other => vec![other],
        }
    }

    /// The tag family whose tags the board's corners come from (tag and ChArUco boards).
    pub fn family(&self) -> Option<TagFamily> {
        match self {
            Target::Tagboard(b) => Some(b.family),
            Target::Charuco(c) => Some(c.dictionary),
            _ => None,
        }
    }

    /// Whether `tag` is one of this board's tags.
    pub fn holds_tag(&self, tag: &TagDetection) -> bool {
        match self {
            Target::Tagboard(b) => b.holds(tag),
            Target::Charuco(c) => tag.family == c.dictionary && c.layout().contains(&tag.id),
            Target::Aprilgrid(_) => tag.family == TagFamily::Aprilgrid36h11,
            Target::Checkerboard(_) => false,
            Target::Boards(b) => b.boards.iter().any(|t| t.holds_tag(tag)),
        }
    }
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

    /// Whether `tag` is one of the board's tags.
    pub fn holds(&self, tag: &TagDetection) -> bool {
        tag.family == self.family && self.position_of(tag.id).is_some()
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
    /// The tags the corners came from, as detected (an AprilGrid's before its corners were
    /// refined; a tag board's or ChArUco board's); none for a chessboard.
    pub tags: Vec<TagDetection>,
    /// Why the image gave nothing, when it did not (no tag, no whole chessboard).
    pub miss: Option<String>,
}

/// Finds a target's corners in images: an AprilGrid's tags by the C library with Kalibr's 2-bit
/// border at several scales, their corners refined as X-corners and from the fitted tag edges;
/// a chessboard by our own detector; a tag board's and a ChArUco board's tags by the C library
/// at full resolution (one detector a family). One per thread (the C detector is not shared).
pub struct TargetDetector {
    target: Target,
    grid: Option<AprilGridMultiScale>,
    tags: Vec<(TagFamily, Box<dyn TagDetector + Send>)>,
}

impl TargetDetector {
    /// A detector of `target`'s corners.
    pub fn new(target: &Target) -> Result<Self, TagError> {
        let grid = match target {
            Target::Aprilgrid(_) => Some(AprilGridMultiScale::new()?),
            _ => None,
        };
        let mut families: Vec<TagFamily> =
            target.boards().iter().filter_map(|b| b.family()).collect();
        families.sort();
        families.dedup();
        // Full resolution: a calibration wants every tag and the best corners.
        let tags = families
            .into_iter()
            .map(|family| {
                let detector = Backend::ApriltagC.detector(DetectorConfig {
                    families: vec![family],
                    decimate: 1.0,
                    ..DetectorConfig::default()
                })?;
                Ok((family, detector))
            })
            .collect::<Result<_, TagError>>()?;
        Ok(Self {
            target: target.clone(),
            grid,
            tags,
        })
    }

    /// The target's corners in `image` (of several boards: each board's corner ids offset by
    /// its index times [`BOARD_ID_STRIDE`]).
    pub fn detect(&mut self, image: &GrayImage) -> Result<TargetView, TagError> {
        if let (Target::Aprilgrid(g), Some(detector)) = (&self.target, &mut self.grid) {
            let tags = detector.detect(image)?;
            let points = refine_aprilgrid(image, &tags, g.tag_cols, g.tag_spacing);
            let corners =
                aprilgrid_corners(&points, g.tag_cols, g.tag_rows, g.tag_size, g.tag_spacing);
            let miss = tags
                .is_empty()
                .then(|| format!("{} AprilGrid tags", tags.len()));
            return Ok(TargetView {
                corners,
                tags,
                miss,
            });
        }
        if let Target::Checkerboard(c) = &self.target {
            return Ok(chessboard_view(image, c));
        }
        let mut tags = Vec::new();
        for (_, detector) in &mut self.tags {
            tags.extend(detector.detect(image)?);
        }
        let boards = self.target.boards();
        let mut corners = Vec::new();
        for (k, board) in boards.iter().enumerate() {
            let offset = k as u32 * BOARD_ID_STRIDE;
            let found = match board {
                Target::Tagboard(b) => tag_board_corners(b, &tags),
                Target::Charuco(c) => c.corners(image, &tags),
                _ => {
                    return Err(TagError::Invalid(
                        "several boards are tag boards and ChArUco boards only".into(),
                    ))
                }
            };
            corners.extend(found.into_iter().map(|c| Corner {
                id: c.id + offset,
                ..c
            }));
        }
        // The boards' tags alone.
        tags.retain(|t| boards.iter().any(|b| b.holds_tag(t)));
        let miss = corners.is_empty().then(|| {
            let names: Vec<String> = boards
                .iter()
                .filter_map(|b| b.family())
                .map(|f| f.to_string())
                .collect();
            format!(
                "{} tags of the board ({}), no corner found",
                tags.len(),
                names.join(", ")
            )
        });
        Ok(TargetView {
            corners,
            tags,
            miss,
        })
    }
}

/// A chessboard's corners in `image`: the whole board's, or those of a part of it
/// ([`find_chessboard`]) numbered from the part's own first corner (id `r · max(cols, rows) + c`)
/// and placed on the board from there, with no miss (a calibration solves such a view with a
/// pose of its own). A part needs square squares (its way round is unknown) and as many corners
/// as a view needs ([`crate::calib::CalibConfig`]'s default).
fn chessboard_view(image: &GrayImage, c: &CheckerboardTarget) -> TargetView {
    let square = (c.col_spacing_m - c.row_spacing_m).abs() <= 1e-9 * c.col_spacing_m;
    let min_part = square.then(|| crate::calib::CalibConfig::default().min_corners);
    let corners = match find_chessboard(image, c.target_cols, c.target_rows, min_part) {
        Ok(ChessboardFound::Whole(px)) => {
            chessboard_board_corners(&px, c.target_cols, c.col_spacing_m, c.row_spacing_m)
        }
        Ok(ChessboardFound::Part(part)) => {
            let stride = c.target_cols.max(c.target_rows);
            part.into_iter()
                .map(|((col, row), px)| Corner {
                    id: row * stride + col,
                    board_m: [
                        col as f64 * c.col_spacing_m,
                        row as f64 * c.row_spacing_m,
                        0.0,
                    ],
                    px,
                })
                .collect()
        }
        Err(miss) => {
            return TargetView {
                corners: Vec::new(),
                tags: Vec::new(),
                miss: Some(miss.to_string()),
            }
        }
    };
    TargetView {
        corners,
        tags: Vec::new(),
        miss: None,
    }
}

/// Whether `layout` puts one distinct tag of `family` at each of `places` places (`what`, for
/// the message: "positions", "marker squares"); else why not.
pub(crate) fn check_id_layout(
    layout: &[u32],
    places: usize,
    what: &str,
    family: TagFamily,
) -> Result<(), String> {
    if layout.len() != places {
        return Err(format!(
            "ids: {} ids for the board's {places} {what}",
            layout.len()
        ));
    }
    let mut seen = std::collections::BTreeSet::new();
    for id in layout {
        if !seen.insert(id) {
            return Err(format!("ids: {id} appears twice"));
        }
        if *id as usize >= family.code_count() {
            return Err(format!(
                "tag {id} is not in {family} (it has {} tags): a larger family or fewer {what}",
                family.code_count()
            ));
        }
    }
    Ok(())
}

/// A tag board's corners: the corners of its tags found (`tags`: any tags in the image).
fn tag_board_corners(b: &TagBoardTarget, tags: &[TagDetection]) -> Vec<Corner> {
    tags.iter()
        .filter(|t| b.holds(t))
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
        .collect()
}
