//! Calibration boards drawn by the renderer: Kalibr AprilGrids (tag36h11 with 2-bit black
//! borders and the small black squares between tags) and chessboards, on white paper with a
//! margin, lit unevenly; and synthetic calibration sequences with board poses spread over the
//! image and tilted, with the true corner positions in both images.
//!
//! Board frames follow the detectors: an AprilGrid as Kalibr lays it out (tag 0 at the origin,
//! x along a row, y up the grid as printed, the camera on the +z side); a chessboard as OpenCV
//! and Kalibr's checkerboard (x along `cols`, y along `rows`, the camera on the −z side). Corner
//! ids are those of [`crate::calib::aprilgrid_corners`] and
//! [`crate::calib::chessboard_board_corners`].

use crate::camera::StereoRig;
use crate::render::{texture, RenderConfig, RenderError, Renderer};
use crate::render::{TAG_BLACK, TAG_WHITE};
use crate::visual::tags::TagFamily;
use image::GrayImage;
use nalgebra::{Isometry3, Matrix3, Point2, Point3, Rotation3, Translation3, UnitQuaternion};
use nalgebra::{Vector2, Vector3};
use rand::{Rng, SeedableRng};
use serde::Serialize;

/// Cells across an AprilGrid tag's black square (2-bit border + 6 data bits + 2-bit border).
const APRILGRID_CELLS: usize = 10;

/// A calibration board pattern.
#[derive(Debug, Clone, PartialEq)]
pub enum Board {
    /// A grid of tags: Kalibr's AprilGrid (2-bit borders, black squares in the gaps) or a tag
    /// board of ordinary tags in any id order.
    TagGrid {
        /// Tags across.
        cols: u32,
        /// Tags down.
        rows: u32,
        /// Tag edge (black square), metres.
        size_m: f64,
        /// Gap between tags over the tag edge.
        spacing: f64,
        /// Cells across a tag's black square.
        cells_across: usize,
        /// Per position (row-major from position 0), `true` where a cell of its tag's black
        /// square is white (row-major from the top of the tag as printed, `cells_across²`).
        cells: Vec<Vec<bool>>,
        /// The tag id at each position.
        ids: Vec<u32>,
        /// Whether the small black squares of an AprilGrid fill the gaps' crossings.
        gap_squares: bool,
    },
    /// Chessboard by inner corners.
    Chessboard {
        /// Inner corners across.
        cols: u32,
        /// Inner corners down.
        rows: u32,
        /// Square width, metres.
        col_m: f64,
        /// Square height, metres.
        row_m: f64,
    },
    /// Several boards side by side on one sheet, each at its offset (metres, along the sheet);
    /// board `k`'s corner ids offset by `k` times [`crate::calib::BOARD_ID_STRIDE`].
    Several(Vec<([f64; 2], Board)>),
    /// OpenCV's ChArUco board.
    Charuco {
        /// The board.
        target: crate::calib::CharucoTarget,
        /// Cells across a marker's black square.
        cells_across: usize,
        /// Per marker square (the target's order), `true` where a cell of its marker's black
        /// square is white (row-major from the top of the marker as printed).
        cells: Vec<Vec<bool>>,
        /// Per square (row-major from the top-left), its marker's index in `cells`.
        marker_of_square: Vec<Option<usize>>,
    },
}

impl Board {
    /// A Kalibr AprilGrid of `cols x rows` tag36h11 tags.
    pub fn aprilgrid(cols: u32, rows: u32, size_m: f64, spacing: f64) -> Result<Self, RenderError> {
        let family = TagFamily::Tag36h11;
        let cells = (0..cols * rows)
            .map(|id| {
                let code = family
                    .code_image(id)
                    .ok_or_else(|| RenderError::IdOutOfRange {
                        id,
                        family: TagFamily::Tag36h11,
                        count: family.code_count(),
                    })?;
                // The library's image: 1 white, 1 black, 6 data, 1 black, 1 white cells. Kalibr
                // widens the black border to 2 cells over the same data cells.
                let tw = code.total_cells;
                Ok((0..APRILGRID_CELLS * APRILGRID_CELLS)
                    .map(|i| {
                        let (x, y) = (i % APRILGRID_CELLS, i / APRILGRID_CELLS);
                        let data = (2..APRILGRID_CELLS - 2).contains(&x)
                            && (2..APRILGRID_CELLS - 2).contains(&y);
                        data && code.white[y * tw + x]
                    })
                    .collect())
            })
            .collect::<Result<_, RenderError>>()?;
        Ok(Self::TagGrid {
            cols,
            rows,
            size_m,
            spacing,
            cells_across: APRILGRID_CELLS,
            cells,
            ids: (0..cols * rows).collect(),
            gap_squares: true,
        })
    }

    /// A board of ordinary tags ([`crate::calib::TagBoardTarget`]): each tag's black square with
    /// its data cells, as the AprilTag library prints it, in the board's id layout.
    pub fn tag_board(target: &crate::calib::TagBoardTarget) -> Result<Self, RenderError> {
        let ids = target.layout();
        let (cells_across, cells) = black_squares(target.family, &ids, false)?;
        Ok(Self::TagGrid {
            cols: target.tag_cols,
            rows: target.tag_rows,
            size_m: target.tag_size,
            spacing: target.tag_spacing,
            cells_across,
            cells,
            ids,
            gap_squares: false,
        })
    }

    /// The board a calibration target describes.
    pub fn of_target(target: &crate::calib::Target) -> Result<Self, RenderError> {
        use crate::calib::Target;
        Ok(match target {
            Target::Aprilgrid(g) => {
                Board::aprilgrid(g.tag_cols, g.tag_rows, g.tag_size, g.tag_spacing)?
            }
            Target::Checkerboard(c) => Board::Chessboard {
                cols: c.target_cols,
                rows: c.target_rows,
                col_m: c.col_spacing_m,
                row_m: c.row_spacing_m,
            },
            Target::Tagboard(b) => Board::tag_board(b)?,
            Target::Charuco(c) => Board::charuco(c)?,
            Target::Boards(several) => {
                let boards = several
                    .boards
                    .iter()
                    .map(Board::of_target)
                    .collect::<Result<Vec<_>, _>>()?;
                Board::side_by_side(boards)?
            }
        })
    }

    /// Boards printed side by side along x on one sheet, a tenth of the first board's width
    /// apart; they must face the camera from the same side.
    pub fn side_by_side(boards: Vec<Board>) -> Result<Self, RenderError> {
        let side = boards.first().map_or(1.0, Board::camera_side);
        if boards.iter().any(|b| b.camera_side() != side) {
            return Err(RenderError::Boards(
                "boards on one sheet must all be ChArUco (or chessboards) or all tag grids: their frames face opposite ways".into(),
            ));
        }
        let gap = boards.first().map_or(0.0, |b| {
            let [x0, _, x1, _] = b.paper();
            0.1 * (x1 - x0)
        });
        let mut right = 0.0;
        let mut placed = Vec::with_capacity(boards.len());
        for (k, board) in boards.into_iter().enumerate() {
            let [x0, ..] = board.paper();
            let offset = if k == 0 { 0.0 } else { right + gap - x0 };
            right = offset + board.paper()[2];
            placed.push(([offset, 0.0], board));
        }
        Ok(Self::Several(placed))
    }

    /// A ChArUco board ([`crate::calib::CharucoTarget`]): the chessboard's black squares and a
    /// marker as OpenCV prints it in each white square.
    pub fn charuco(target: &crate::calib::CharucoTarget) -> Result<Self, RenderError> {
        // OpenCV prints its AprilTag dictionaries' tags upside down.
        let turned = target.marker_turns() == 2;
        let (cells_across, cells) = black_squares(target.dictionary, &target.layout(), turned)?;
        let squares = target.marker_squares();
        let marker_of_square = (0..target.squares_y)
            .flat_map(|r| (0..target.squares_x).map(move |c| (c, r)))
            .map(|s| squares.iter().position(|&q| q == s))
            .collect();
        Ok(Self::Charuco {
            target: target.clone(),
            cells_across,
            cells,
            marker_of_square,
        })
    }

    /// Board corners `(id, position on the board)`, as the calibration numbers and places them.
    pub fn corners(&self) -> Vec<(u32, [f64; 3])> {
        use crate::calib::{aprilgrid_board_point, chessboard_board_point};
        match self {
            Self::TagGrid {
                cols,
                size_m,
                spacing,
                ids,
                ..
            } => ids
                .iter()
                .enumerate()
                .flat_map(|(position, tag)| {
                    (0..4).map(move |k| {
                        let at = position as u32 * 4 + k;
                        (
                            tag * 4 + k,
                            aprilgrid_board_point(at, *cols, *size_m, *spacing),
                        )
                    })
                })
                .collect(),
            Self::Chessboard {
                cols,
                rows,
                col_m,
                row_m,
            } => (0..cols * rows)
                .map(|k| (k, chessboard_board_point(k, *cols, *col_m, *row_m)))
                .collect(),
            Self::Charuco { target, .. } => {
                let (cols, rows) = target.inner();
                (0..cols * rows)
                    .filter_map(|k| Some((k, target.corner_point(k)?)))
                    .collect()
            }
            Self::Several(boards) => boards
                .iter()
                .enumerate()
                .flat_map(|(k, (o, b))| {
                    b.corners().into_iter().map(move |(id, p)| {
                        (
                            id + k as u32 * crate::calib::BOARD_ID_STRIDE,
                            [p[0] + o[0], p[1] + o[1], p[2]],
                        )
                    })
                })
                .collect(),
        }
    }

    /// The side of the board the camera must be on (sign of board z).
    fn camera_side(&self) -> f64 {
        match self {
            Self::TagGrid { .. } => 1.0,
            Self::Chessboard { .. } | Self::Charuco { .. } => -1.0,
            Self::Several(boards) => boards.first().map_or(1.0, |(_, b)| b.camera_side()),
        }
    }

    /// The printed area `(x0, y0, x1, y1)`, metres: the pattern and a white margin.
    fn paper(&self) -> [f64; 4] {
        match self {
            Self::TagGrid {
                cols,
                rows,
                size_m,
                spacing,
                ..
            } => {
                let (pitch, gap) = (size_m * (1.0 + spacing), size_m * spacing);
                let margin = gap + 0.3 * size_m;
                [
                    -margin,
                    -margin,
                    *cols as f64 * pitch + margin,
                    *rows as f64 * pitch + margin,
                ]
            }
            Self::Chessboard {
                cols,
                rows,
                col_m,
                row_m,
            } => [
                -2.0 * col_m,
                -2.0 * row_m,
                (*cols as f64 + 1.0) * col_m,
                (*rows as f64 + 1.0) * row_m,
            ],
            Self::Several(boards) => {
                boards
                    .iter()
                    .fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |a, (o, b)| {
                        let p = b.paper();
                        [
                            a[0].min(p[0] + o[0]),
                            a[1].min(p[1] + o[1]),
                            a[2].max(p[2] + o[0]),
                            a[3].max(p[3] + o[1]),
                        ]
                    })
            }
            Self::Charuco { target, .. } => {
                let margin = 0.5 * target.square_length;
                [
                    -margin,
                    -margin,
                    target.squares_x as f64 * target.square_length + margin,
                    target.squares_y as f64 * target.square_length + margin,
                ]
            }
        }
    }

    /// Albedo at a point of the board plane; `None` off the paper.
    fn albedo(&self, x: f64, y: f64) -> Option<f64> {
        let [x0, y0, x1, y1] = self.paper();
        if x < x0 || y < y0 || x >= x1 || y >= y1 {
            return None;
        }
        if let Self::Several(boards) = self {
            // White sheet between the boards.
            return Some(
                boards
                    .iter()
                    .find_map(|(o, b)| b.albedo(x - o[0], y - o[1]))
                    .unwrap_or(TAG_WHITE),
            );
        }
        let black = match self {
            Self::Several(_) => false,
            Self::TagGrid {
                cols,
                rows,
                size_m,
                spacing,
                cells_across,
                cells,
                gap_squares,
                ..
            } => {
                let (pitch, gap) = (size_m * (1.0 + spacing), size_m * spacing);
                // The black squares between tags sit at every tag corner crossing.
                let in_gap = |v: f64, n: u32| {
                    let k = ((v + gap) / pitch).floor();
                    k >= 0.0 && k <= n as f64 && v >= k * pitch - gap && v < k * pitch
                };
                let (tc, tr) = ((x / pitch).floor(), (y / pitch).floor());
                let (lx, ly) = (x - tc * pitch, y - tr * pitch);
                if *gap_squares && in_gap(x, *cols) && in_gap(y, *rows) {
                    true
                } else if tc >= 0.0
                    && tr >= 0.0
                    && tc < *cols as f64
                    && tr < *rows as f64
                    && lx < *size_m
                    && ly < *size_m
                {
                    let n = *cells_across;
                    let cell = size_m / n as f64;
                    let mx = ((lx / cell) as usize).min(n - 1);
                    // Printed upright, the tag's top row is at the largest board y.
                    let my = n - 1 - ((ly / cell) as usize).min(n - 1);
                    let position = tr as usize * *cols as usize + tc as usize;
                    !cells[position][my * n + mx]
                } else {
                    false
                }
            }
            Self::Chessboard {
                cols,
                rows,
                col_m,
                row_m,
            } => {
                let (i, j) = ((x / col_m).floor() as i64, (y / row_m).floor() as i64);
                let on = i >= -1 && j >= -1 && i < *cols as i64 && j < *rows as i64;
                // The square between corners (0, 0) and (1, 1) is dark.
                on && (i + j).rem_euclid(2) == 0
            }
            Self::Charuco {
                target,
                cells_across,
                cells,
                marker_of_square,
            } => {
                let l = target.square_length;
                let (c, r) = ((x / l).floor(), (y / l).floor());
                if c < 0.0
                    || r < 0.0
                    || c >= target.squares_x as f64
                    || r >= target.squares_y as f64
                {
                    false
                } else {
                    let (c, r) = (c as u32, r as u32);
                    match marker_of_square[(r * target.squares_x + c) as usize] {
                        None => !target.holds_marker(c, r),
                        Some(marker) => {
                            let m = target.marker_length;
                            let margin = 0.5 * (l - m);
                            let lx = x - c as f64 * l - margin;
                            let ly = y - r as f64 * l - margin;
                            if (0.0..m).contains(&lx) && (0.0..m).contains(&ly) {
                                let n = *cells_across;
                                let cell = m / n as f64;
                                // y grows down the board as printed.
                                let (mx, my) = (
                                    ((lx / cell) as usize).min(n - 1),
                                    ((ly / cell) as usize).min(n - 1),
                                );
                                !cells[marker][my * n + mx]
                            } else {
                                false
                            }
                        }
                    }
                }
            }
        };
        Some(if black { TAG_BLACK } else { TAG_WHITE })
    }
}

/// Each tag's black square as printed (`true` where white, row-major from the top; turned
/// upside down if `turned`), inside the library's white ring, and its cells across.
fn black_squares(
    family: TagFamily,
    ids: &[u32],
    turned: bool,
) -> Result<(usize, Vec<Vec<bool>>), RenderError> {
    let mut cells_across = 0;
    let cells = ids
        .iter()
        .map(|&id| {
            let code = family.code_image(id).ok_or(RenderError::IdOutOfRange {
                id,
                family,
                count: family.code_count(),
            })?;
            let (tw, n) = (code.total_cells, code.black_square_cells);
            let border = (tw - n) / 2;
            cells_across = n;
            let mut cells: Vec<bool> = (0..n * n)
                .map(|i| code.white[(border + i / n) * tw + border + i % n])
                .collect();
            if turned {
                cells.reverse();
            }
            Ok(cells)
        })
        .collect::<Result<_, RenderError>>()?;
    Ok((cells_across, cells))
}

/// True position of one board corner in a rendered view.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CornerTruth {
    /// Corner id.
    pub id: u32,
    /// Position on the board, metres.
    pub board_m: [f64; 3],
    /// Pixel in the left image (`None` outside it).
    pub left_px: Option<[f64; 2]>,
    /// Pixel in the right image.
    pub right_px: Option<[f64; 2]>,
}

/// A rendered view of a calibration board.
#[derive(Debug, Clone)]
pub struct BoardView {
    /// Left image.
    pub left: GrayImage,
    /// Right image.
    pub right: GrayImage,
    /// Pose of the board in the left camera.
    pub left_from_board: Isometry3<f64>,
    /// Every board corner.
    pub corners: Vec<CornerTruth>,
}

/// Pixels a corner must keep from the image border to count as seen.
const BORDER_PX: f64 = 4.0;
/// The backdrop behind the board, metres beyond it.
const BACKDROP_BEHIND_M: f64 = 1.5;
/// Light lost from one side of the board to the other (uneven lighting).
const LIGHT_GRADIENT: f64 = 0.25;

/// Pixel of a point in the left camera frame, in both cameras, if inside the images.
fn project_both(rig: &StereoRig, p_left: &Point3<f64>) -> (Option<[f64; 2]>, Option<[f64; 2]>) {
    let inside = |cam: &crate::camera::Camera, p: &Point3<f64>| {
        if p.z <= 0.05 {
            return None;
        }
        let q = cam.project(&p.coords)?;
        let ok = q.x >= BORDER_PX
            && q.y >= BORDER_PX
            && q.x <= cam.width as f64 - 1.0 - BORDER_PX
            && q.y <= cam.height as f64 - 1.0 - BORDER_PX;
        ok.then_some([q.x, q.y])
    };
    (
        inside(&rig.left, p_left),
        inside(&rig.right, &(rig.right_from_left * p_left)),
    )
}

impl Renderer {
    /// Renders a calibration board at `left_from_board` in front of a plain textured backdrop.
    pub fn render_board(
        &self,
        board: &Board,
        left_from_board: &Isometry3<f64>,
        config: &RenderConfig,
    ) -> BoardView {
        let board_from_left = left_from_board.inverse();
        let side = board.camera_side();
        let [x0, _, x1, _] = board.paper();
        let backdrop_m = left_from_board.translation.vector.norm() + BACKDROP_BEHIND_M;
        let trace = |o: &Vector3<f64>, d: &Vector3<f64>| -> (f64, f64) {
            let ob = board_from_left * Point3::from(*o);
            let db = board_from_left.rotation * d;
            if db.z * side < -1e-9 {
                let t = -ob.z / db.z;
                let p = ob + db * t;
                if t > 0.0 {
                    if let Some(a) = board.albedo(p.x, p.y) {
                        let light = 1.0 - LIGHT_GRADIENT * ((p.x - x0) / (x1 - x0)).clamp(0.0, 1.0);
                        return (t, a * light);
                    }
                }
            }
            let (u, v) = (d.x / d.z.abs().max(0.1), d.y / d.z.abs().max(0.1));
            (
                backdrop_m,
                0.5 + 0.1 * texture(u * 6.0, v * 6.0) + 0.05 * texture(u * 40.0, v * 40.0),
            )
        };
        let rig = &self.rig;
        let (left, right) = self.render_both(&trace, &Isometry3::identity(), config);
        let corners = board
            .corners()
            .into_iter()
            .map(|(id, b)| {
                let (left_px, right_px) = project_both(rig, &(left_from_board * Point3::from(b)));
                CornerTruth {
                    id,
                    board_m: b,
                    left_px,
                    right_px,
                }
            })
            .collect();
        BoardView {
            left,
            right,
            left_from_board: *left_from_board,
            corners,
        }
    }
}

/// Board poses for a synthetic calibration sequence of `n` views: the board centre stepped over a
/// 3 x 3 grid of the left image, filling 50–85% of its width, tilted up to 40° about both board
/// axes and rolled up to 20°, every corner inside both images. Seeded, so repeatable.
pub fn calibration_poses(
    rig: &StereoRig,
    board: &Board,
    n: usize,
    seed: u64,
) -> Vec<Isometry3<f64>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let corners = board.corners();
    let (lo, hi) = corners.iter().fold(
        (Vector2::repeat(f64::MAX), Vector2::repeat(f64::MIN)),
        |(lo, hi), (_, p)| {
            let p = Vector2::new(p[0], p[1]);
            (lo.inf(&p), hi.sup(&p))
        },
    );
    let centre = Vector3::new(0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), 0.0);
    let extent = (hi - lo).max();
    // Chessboard: board axes along the camera's; AprilGrid: y up and z towards the camera.
    let base = if board.camera_side() > 0.0 {
        Rotation3::from_matrix_unchecked(Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0)))
    } else {
        Rotation3::identity()
    };
    let cam = &rig.left;
    let (w, h) = (cam.width as f64, cam.height as f64);
    let deg = std::f64::consts::PI / 180.0;
    let mut poses = Vec::with_capacity(n);
    for k in 0..n {
        let (gx, gy) = ((k % 3) as f64, ((k / 3) % 3) as f64);
        let mut best = None;
        for attempt in 0..400 {
            // Smaller boards when big ones keep falling off the image.
            let shrink = 1.0 - 0.4 * (attempt as f64 / 400.0);
            let fill = rng.random_range(0.5..0.85) * shrink;
            let depth = cam.fx * extent / (fill * w);
            let u = w * (0.3 + 0.2 * gx + rng.random_range(-0.08..0.08));
            let v = h * (0.3 + 0.2 * gy + rng.random_range(-0.08..0.08));
            let Some(ray) = cam.unproject(&Point2::new(u, v)) else {
                continue;
            };
            let tilt = UnitQuaternion::from_euler_angles(
                rng.random_range(-40.0..40.0) * deg,
                rng.random_range(-40.0..40.0) * deg,
                rng.random_range(-20.0..20.0) * deg,
            );
            let rotation = tilt * UnitQuaternion::from_rotation_matrix(&base);
            let t = Vector3::new(ray.x, ray.y, 1.0) * depth - rotation * centre;
            let pose = Isometry3::from_parts(Translation3::from(t), rotation);
            let all_in = corners.iter().all(|(_, b)| {
                let (l, r) = project_both(rig, &(pose * Point3::from(*b)));
                l.is_some() && r.is_some()
            });
            if all_in {
                best = Some(pose);
                break;
            }
        }
        if let Some(pose) = best {
            poses.push(pose);
        }
    }
    poses
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aprilgrid_tag_zero_reads_its_code_upright() {
        let board = Board::aprilgrid(2, 2, 0.1, 0.3).expect("grid");
        let Board::TagGrid { cells, .. } = &board else {
            unreachable!()
        };
        let code = TagFamily::from_name("tag36h11")
            .and_then(|f| f.code_image(0))
            .expect("code");
        let cell = 0.01;
        for my in 2..8 {
            for mx in 2..8 {
                // Cell (mx, my) from the top of the printed tag, sampled at its centre.
                let (x, y) = ((mx as f64 + 0.5) * cell, (9.5 - my as f64) * cell);
                let white = board.albedo(x, y) == Some(TAG_WHITE);
                assert_eq!(
                    white,
                    code.white[my * code.total_cells + mx],
                    "cell {mx},{my}"
                );
                assert_eq!(white, cells[0][my * 10 + mx]);
            }
        }
        // The border is black, the gap square black, the paper between tags white.
        assert_eq!(board.albedo(0.005, 0.005), Some(TAG_BLACK));
        assert_eq!(board.albedo(0.115, 0.115), Some(TAG_BLACK));
        assert_eq!(board.albedo(0.115, 0.05), Some(TAG_WHITE));
    }

    #[test]
    fn chessboard_square_between_the_first_corners_is_dark() {
        let board = Board::Chessboard {
            cols: 9,
            rows: 6,
            col_m: 0.03,
            row_m: 0.03,
        };
        assert_eq!(board.albedo(0.015, 0.015), Some(TAG_BLACK));
        assert_eq!(board.albedo(0.045, 0.015), Some(TAG_WHITE));
        assert_eq!(board.albedo(-0.015, -0.015), Some(TAG_BLACK));
        assert_eq!(board.albedo(-0.045, 0.0), Some(TAG_WHITE));
        assert_eq!(board.corners().len(), 54);
    }
}
