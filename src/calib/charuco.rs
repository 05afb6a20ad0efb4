//! OpenCV's ChArUco board: a chessboard whose white squares hold ArUco markers, so each inner
//! corner is known by the markers beside it and a board seen in part still gives its corners.
//!
//! Layout and numbering are OpenCV's (4.6 and later, `cv::aruco::CharucoBoard`): squares
//! `squaresX x squaresY`, the top-left square black; a marker, `markerLength` across, centred in
//! every white square, ids 0, 1, 2, ... along each row from the top-left (or the board's `ids`);
//! the board frame's origin at the board's top-left outer corner, x to the right and y down as
//! printed (the camera on the −z side); inner corner `k` at row `k / (squaresX − 1)`, column
//! `k % (squaresX − 1)`, at `((column + 1) · squareLength, (row + 1) · squareLength, 0)`.
//! `legacyPattern: true` is OpenCV's `setLegacyPattern(true)` for boards made before 4.6: with an
//! even `squaresY`, the top-left square is white and holds a marker.
//!
//! Corners are found as OpenCV finds them: each inner corner's two neighbouring markers predict
//! it (one homography fitted to both markers' eight corners), and the X-corner there is refined
//! to a sub-pixel; a corner with a neighbouring marker unseen is left out.

use crate::calib::xcorner::{refine_x_corner_where, MAX_REFINE_HALF_WIDTH};
use crate::calib::Corner;
use crate::geometry::homography::Homography;
use crate::imgproc::blur::binomial5_gray;
use crate::visual::tags::{TagDetection, TagFamily};
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// Pixels around a marker left out of its corners' refinement: a blurred edge's reach (the
/// 5-tap binomial smoothing the refinement runs on spreads an edge over about 2 px), at most half
/// the marker's white margin (a narrow margin's edges are the corner's squares' edges too). On
/// OpenCV's drawn views (`tests/charuco.rs`, margins of about 5 px) 1.5 px gave a median error
/// of 0.022 px and a worst of 0.146 px, 2.5 px 0.016 and 0.141; on the rendered 11x8 board
/// (margins of 2-3 px) 2.5 px without the cap left 37 corners out as outliers, with it none.
const MARKER_CLEARANCE_PX: f64 = 2.5;

/// Pixels from the image's edge within which a marker counts as cut off by it.
const IMAGE_EDGE_PX: f64 = 2.0;

/// A ChArUco board (`target_type: charuco`), named as OpenCV names its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CharucoTarget {
    /// The markers' dictionary, by OpenCV's name (`DICT_5X5_100`; `DICT_APRILTAG_36h11` and
    /// the other AprilTag families too).
    pub dictionary: TagFamily,
    /// Squares across.
    #[serde(rename = "squaresX")]
    pub squares_x: u32,
    /// Squares down.
    #[serde(rename = "squaresY")]
    pub squares_y: u32,
    /// A square's edge, metres.
    #[serde(rename = "squareLength")]
    pub square_length: f64,
    /// A marker's edge (its black square), metres.
    #[serde(rename = "markerLength")]
    pub marker_length: f64,
    /// OpenCV's legacy layout (boards made before OpenCV 4.6).
    #[serde(
        default,
        rename = "legacyPattern",
        skip_serializing_if = "std::ops::Not::not"
    )]
    pub legacy_pattern: bool,
    /// The marker id in each marker square, in order (default 0, 1, 2, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ids: Option<Vec<u32>>,
    #[serde(default, rename = "target_type", skip_serializing)]
    pub(crate) kind: Option<serde::de::IgnoredAny>,
}

impl CharucoTarget {
    /// Whether square (`column`, `row`) (from the top-left) holds a marker.
    pub fn holds_marker(&self, column: u32, row: u32) -> bool {
        let white_first = self.legacy_pattern && self.squares_y.is_multiple_of(2);
        ((column + row) % 2 == 1) != white_first
    }

    /// The marker squares `(column, row)` in the order their ids are given.
    pub fn marker_squares(&self) -> Vec<(u32, u32)> {
        (0..self.squares_y)
            .flat_map(|r| (0..self.squares_x).map(move |c| (c, r)))
            .filter(|&(c, r)| self.holds_marker(c, r))
            .collect()
    }

    /// The marker id in each marker square ([`Self::marker_squares`]' order).
    pub fn layout(&self) -> Vec<u32> {
        self.ids
            .clone()
            .unwrap_or_else(|| (0..self.marker_squares().len() as u32).collect())
    }

    /// Inner corners across and down.
    pub fn inner(&self) -> (u32, u32) {
        (
            self.squares_x.saturating_sub(1),
            self.squares_y.saturating_sub(1),
        )
    }

    /// Where inner corner `id` sits on the board (`None` past the last).
    pub fn corner_point(&self, id: u32) -> Option<[f64; 3]> {
        let (cols, rows) = self.inner();
        (id < cols * rows).then(|| {
            let (c, r) = (id % cols, id / cols);
            [
                (c + 1) as f64 * self.square_length,
                (r + 1) as f64 * self.square_length,
                0.0,
            ]
        })
    }

    /// Quarter turns between a marker as OpenCV prints it and the tag the detectors read: 2 for
    /// OpenCV's AprilTag dictionaries (`DICT_APRILTAG_36h11` draws the AprilTag library's tag
    /// upside down), 0 for the ArUco ones.
    pub fn marker_turns(&self) -> usize {
        match self.dictionary {
            TagFamily::Aruco(_) => 0,
            _ => 2,
        }
    }

    /// Corner `k` of the marker in square (`column`, `row`) on the board: the detected tag's
    /// corner `k` (the detectors' order: the tag's bottom-left, bottom-right, top-right,
    /// top-left), on the marker as OpenCV prints it ([`Self::marker_turns`]).
    pub fn marker_corner(&self, column: u32, row: u32, k: usize) -> [f64; 2] {
        let [x0, y0, x1, y1] = self.marker_rect(column, row);
        // y grows down the board as printed: the marker's top is at y0.
        [[x0, y1], [x1, y1], [x1, y0], [x0, y0]][(k + self.marker_turns()) % 4]
    }

    /// The marker in square (`column`, `row`) on the board: `[x0, y0, x1, y1]`, metres.
    pub fn marker_rect(&self, column: u32, row: u32) -> [f64; 4] {
        let margin = 0.5 * (self.square_length - self.marker_length);
        let x0 = column as f64 * self.square_length + margin;
        let y0 = row as f64 * self.square_length + margin;
        [x0, y0, x0 + self.marker_length, y0 + self.marker_length]
    }

    /// Whether the numbers make a board: at least 2 x 2 squares, a marker smaller than its
    /// square, one distinct id of the dictionary per marker square; else why not.
    pub fn check(&self) -> Result<(), String> {
        if self.squares_x < 2 || self.squares_y < 2 {
            return Err(format!(
                "squaresX {} x squaresY {}: a ChArUco board has at least 2 x 2 squares",
                self.squares_x, self.squares_y
            ));
        }
        if !(self.square_length > 0.0
            && self.marker_length > 0.0
            && self.marker_length < self.square_length)
        {
            return Err(format!(
                "squareLength {} and markerLength {}: sizes in metres, the marker smaller than its square",
                self.square_length, self.marker_length
            ));
        }
        if !self.dictionary.is_detectable() {
            return Err(format!(
                "dictionary {}: a ChArUco board takes an ArUco dictionary (DICT_4X4_50 ...) or an AprilTag family",
                self.dictionary
            ));
        }
        crate::calib::check_id_layout(
            &self.layout(),
            self.marker_squares().len(),
            "marker squares",
            self.dictionary,
        )
    }

    /// The board's inner corners found in `image` from its detected markers (`markers`: the
    /// dictionary's tags in the image, others are ignored).
    pub fn corners(&self, image: &GrayImage, markers: &[TagDetection]) -> Vec<Corner> {
        let squares = self.marker_squares();
        let layout = self.layout();
        // The detected marker in each square, by (column, row).
        let found: std::collections::HashMap<(u32, u32), &TagDetection> = markers
            .iter()
            .filter(|d| d.family == self.dictionary)
            .filter_map(|d| {
                let p = layout.iter().position(|&id| id == d.id)?;
                Some((squares[p], d))
            })
            .collect();
        if found.len() < 2 {
            return Vec::new();
        }
        let plane = binomial5_gray(image);
        let (width, height) = (image.width() as f64, image.height() as f64);
        let (cols, rows) = self.inner();
        let margin_m = 0.5 * (self.square_length - self.marker_length);
        // Pixels a metre at board point `b`, the less of across and down.
        let px_per_m = |h: &Homography, b: [f64; 2]| {
            let a = h.project(b[0], b[1]);
            let d = self.square_length;
            let p = h.project(b[0] + d, b[1]);
            let q = h.project(b[0], b[1] + d);
            (p[0] - a[0])
                .hypot(p[1] - a[1])
                .min((q[0] - a[0]).hypot(q[1] - a[1]))
                / d
        };
        let mut out = Vec::new();
        for id in 0..cols * rows {
            let (c, r) = (id % cols, id / cols);
            // The four squares around the corner; two of them hold markers.
            let around = [(c, r), (c + 1, r), (c, r + 1), (c + 1, r + 1)];
            let beside: Vec<(u32, u32)> = around
                .into_iter()
                .filter(|&(sc, sr)| self.holds_marker(sc, sr))
                .collect();
            let pairs: Vec<([f64; 2], [f64; 2])> = beside
                .iter()
                .filter_map(|s| Some((*s, *found.get(s)?)))
                .flat_map(|((sc, sr), d)| {
                    (0..4).map(move |k| (self.marker_corner(sc, sr, k), d.corners_px[k]))
                })
                .collect();
            let (Some(h), Some(board_m)) = (Homography::from_pairs(&pairs), self.corner_point(id))
            else {
                continue;
            };
            // A neighbour unseen must be one the image's edge cuts (OpenCV asks for both).
            let in_image = |b: [f64; 2], edge: f64| {
                let p = h.project(b[0], b[1]);
                p[0] >= edge
                    && p[1] >= edge
                    && p[0] <= width - 1.0 - edge
                    && p[1] <= height - 1.0 - edge
            };
            let cut_off = |&(sc, sr): &(u32, u32)| {
                (0..4).any(|k| !in_image(self.marker_corner(sc, sr, k), IMAGE_EDGE_PX))
            };
            if beside.iter().any(|s| !found.contains_key(s) && !cut_off(s)) {
                continue;
            }
            let scale = px_per_m(&h, [board_m[0], board_m[1]]);
            let margin_px = scale * margin_m;
            // Two markers that one plane does not map: one of them is misread.
            let misfit = pairs.iter().map(|(b, p)| {
                let q = h.project(b[0], b[1]);
                (q[0] - p[0]).hypot(q[1] - p[1])
            });
            if misfit.fold(0.0, f64::max) > (0.25 * margin_px).max(1.5) {
                continue;
            }
            let predicted = h.project(board_m[0], board_m[1]);
            // The X-corner from the four squares' edges alone: a window within the squares,
            // the markers beside (and a blur's width around them) left out.
            let Some(inverse) = h.0.try_inverse().map(Homography) else {
                continue;
            };
            // At most half the white margin: a narrow margin's own edges are the corner's too.
            let blur_m = MARKER_CLEARANCE_PX.min(0.5 * margin_px) / scale;
            let markers: Vec<[f64; 4]> = beside
                .iter()
                .map(|&(sc, sr)| {
                    let [x0, y0, x1, y1] = self.marker_rect(sc, sr);
                    [x0 - blur_m, y0 - blur_m, x1 + blur_m, y1 + blur_m]
                })
                .collect();
            let off_markers = |qx: f64, qy: f64| {
                let [bx, by] = inverse.project(qx, qy);
                !markers
                    .iter()
                    .any(|r| bx >= r[0] && bx <= r[2] && by >= r[1] && by <= r[3])
            };
            let hw =
                ((0.4 * scale * self.square_length).round() as i32).clamp(2, MAX_REFINE_HALF_WIDTH);
            if !in_image([board_m[0], board_m[1]], hw as f64 + 1.0) {
                continue;
            }
            let refined =
                refine_x_corner_where(&plane, predicted[0], predicted[1], hw, off_markers).filter(
                    |q| {
                        (q[0] - predicted[0]).hypot(q[1] - predicted[1])
                            <= (0.5 * margin_px).max(1.5)
                    },
                );
            if let Some(px) = refined {
                out.push(Corner { id, board_m, px });
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn board(legacy: bool, squares_y: u32) -> CharucoTarget {
        CharucoTarget {
            dictionary: TagFamily::from_name("DICT_4X4_50").unwrap(),
            squares_x: 5,
            squares_y,
            square_length: 0.04,
            marker_length: 0.02,
            legacy_pattern: legacy,
            ids: None,
            kind: None,
        }
    }

    #[test]
    fn the_layout_is_opencvs() {
        // OpenCV 5.1's CharucoBoard((5, 4), 0.04, 0.02, DICT_4X4_50).getObjPoints(): marker 0's
        // top-left corner at (0.05, 0.01), marker 2's at (0.01, 0.05); getChessboardCorners():
        // corner 1 at (0.08, 0.04).
        let b = board(false, 4);
        let squares = b.marker_squares();
        assert_eq!(&squares[..3], &[(1, 0), (3, 0), (0, 1)]);
        let tl = |p: (u32, u32)| b.marker_corner(p.0, p.1, 3);
        assert!(
            (tl(squares[0])[0] - 0.05).abs() < 1e-12 && (tl(squares[0])[1] - 0.01).abs() < 1e-12
        );
        assert!(
            (tl(squares[2])[0] - 0.01).abs() < 1e-12 && (tl(squares[2])[1] - 0.05).abs() < 1e-12
        );
        assert_eq!(b.corner_point(1), Some([0.08, 0.04, 0.0]));
        assert_eq!(b.marker_squares().len(), 10);
        // setLegacyPattern(true): an even squaresY starts with a white square, an odd one not.
        assert_eq!(
            &board(true, 6).marker_squares()[..3],
            &[(0, 0), (2, 0), (4, 0)]
        );
        assert_eq!(&board(true, 5).marker_squares()[..2], &[(1, 0), (3, 0)]);
        assert!(board(false, 4).check().is_ok());
        let mut small = board(false, 40);
        small.squares_x = 10;
        assert!(small.check().unwrap_err().contains("not in DICT_4X4_50"));
    }
}
