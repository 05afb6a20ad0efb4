//! Chessboard inner-corner detection with sub-pixel refinement, for calibration.
//!
//! 1. **Candidates**: the ChESS response (Bennett and Lasenby, 2014) on a lightly blurred image.
//!    Sixteen samples on a circle of radius 5 px around a chessboard X-corner alternate dark,
//!    bright, dark, bright in quarters: opposite samples agree (the *sum* response is high) while
//!    samples half a turn apart differ little (*diff* response low), and the ring mean equals the
//!    centre (*mean* response low). An edge or a blob fails one of the three. Local maxima above a
//!    fraction of the strongest are kept.
//! 2. **Grid**: from the strongest candidates in turn, the board is grown corner by corner. Two
//!    corners are neighbours on the board when the line between them is a square's edge: the
//!    grey levels either side of its middle differ by a good part of the local contrast (a
//!    diagonal runs through one square and sees the same grey on both sides). Each next corner is
//!    predicted from the last step in that direction (which follows perspective and lens
//!    distortion) and taken if a candidate lies within 30% of a step. The board is accepted only
//!    when the grown grid is exactly `cols x rows`, all corners present.
//! 3. **Order**: corner `(c, r)` (index `r · cols + c`) runs along the board's `cols` axis first.
//!    The image-handedness of the board is fixed (OpenCV's: +c then +r turn clockwise on the image,
//!    so the board's z axis points away from the camera), and the half-turn ambiguity is settled by
//!    colour: the square between corners `(0, 0)` and `(1, 1)` is dark. A board whose `cols + rows`
//!    is even looks the same after a half turn, so its order is ambiguous (use an odd sum, as 9 x 6).
//! 4. **Sub-pixel**: each corner is refined as OpenCV's `cornerSubPix` does: inside a window, the
//!    image gradient at every point `q` is perpendicular to `q − p` when `p` is the corner, so `p`
//!    solves `Σ w g gᵀ p = Σ w g gᵀ q`, iterated to 0.005 px. The window is sized from the local
//!    square size (at most 23 x 23 px, OpenCV's usual 11 half-width).

use crate::calib::xcorner::{refine_x_corner, MAX_REFINE_HALF_WIDTH};
use crate::imgproc::blur::{binomial5, binomial5_gray};
use crate::imgproc::Plane;
use image::GrayImage;
use std::collections::{HashMap, VecDeque};

/// Why a chessboard was not found in an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ChessboardMiss {
    /// No chessboard corners stand out.
    #[error("no chessboard corners in the image")]
    NoCorners,
    /// The largest grid grown does not hold the whole board (board cut by the image edge,
    /// hidden, or too small to see).
    #[error("only {found} of the board's {expected} inner corners found as one grid (part of the board cut off or hidden?)")]
    Partial {
        /// Corners in the largest grid.
        found: usize,
        /// Inner corners of the board.
        expected: usize,
    },
}

/// Radius of the ChESS sampling ring, pixels.
const RING_RADIUS: f64 = 5.0;
/// Candidates weaker than this fraction of the strongest are dropped.
const RESPONSE_FRACTION: f32 = 0.04;
/// Most candidates kept (strongest first).
const MAX_CANDIDATES: usize = 1500;
/// A neighbour must be within this fraction of a step of its prediction.
const SEARCH_FRACTION: f64 = 0.3;
/// An edge between neighbours must show this fraction of the smaller local contrast.
const EDGE_CONTRAST_FRACTION: f32 = 0.3;
/// A corner of a part may lie this share of a square off the plane through the part (lens
/// distortion; a grid grown astray is a whole square off).
const PART_PLANE_SHARE: f64 = 0.25;
/// Seeds tried before giving up.
const MAX_SEEDS: usize = 40;

/// A candidate corner: integer position, ChESS response and local contrast.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    x: f64,
    y: f64,
    response: f32,
    contrast: f32,
}

/// The sixteen ring offsets, a full turn.
fn ring_offsets() -> [(isize, isize); 16] {
    std::array::from_fn(|k| {
        let a = k as f64 * std::f64::consts::TAU / 16.0;
        (
            (RING_RADIUS * a.cos()).round() as isize,
            (RING_RADIUS * a.sin()).round() as isize,
        )
    })
}

/// ChESS candidates: local maxima of the response, strongest first.
fn candidates(blur: &Plane) -> Vec<Candidate> {
    let (w, h) = (blur.w, blur.h);
    let ring = ring_offsets();
    let r = RING_RADIUS as usize + 1;
    let mut response = vec![0.0f32; w * h];
    // Ring samples as offsets into the row-major buffer.
    let offsets: [isize; 16] = std::array::from_fn(|k| ring[k].1 * w as isize + ring[k].0);
    let data = &blur.data;
    // Row by row, each ring sample a slice shifted along the row (so the loop vectorises).
    let span = w.saturating_sub(2 * r);
    for y in r..h.saturating_sub(r) {
        let start = y * w + r;
        let at = |offset: isize| &data[(start as isize + offset) as usize..][..span];
        let ring: [&[f32]; 16] = std::array::from_fn(|k| at(offsets[k]));
        let centre = [at(0), at(-1), at(1), at(-(w as isize)), at(w as isize)];
        let out = &mut response[start..start + span];
        for (j, out) in out.iter_mut().enumerate() {
            let s: [f32; 16] = std::array::from_fn(|k| ring[k][j]);
            let mut sum = 0.0;
            for n in 0..4 {
                sum += ((s[n] + s[n + 8]) - (s[n + 4] + s[n + 12])).abs();
            }
            let mut diff = 0.0;
            for n in 0..8 {
                diff += (s[n] - s[n + 8]).abs();
            }
            let ring_mean = s.iter().sum::<f32>() / 16.0;
            let local =
                (centre[0][j] + centre[1][j] + centre[2][j] + centre[3][j] + centre[4][j]) / 5.0;
            *out = sum - diff - 16.0 * (ring_mean - local).abs();
        }
    }
    let best = response.iter().cloned().fold(0.0f32, f32::max);
    if best <= 0.0 {
        return Vec::new();
    }
    let floor = best * RESPONSE_FRACTION;
    let nms = 3isize;
    let mut out = Vec::new();
    for y in r..h.saturating_sub(r) {
        for x in r..w.saturating_sub(r) {
            let v = response[y * w + x];
            if v <= floor {
                continue;
            }
            let mut is_max = true;
            'window: for dy in -nms..=nms {
                for dx in -nms..=nms {
                    let (xx, yy) = (x as isize + dx, y as isize + dy);
                    if (dx, dy) == (0, 0)
                        || xx < 0
                        || yy < 0
                        || xx >= w as isize
                        || yy >= h as isize
                    {
                        continue;
                    }
                    let o = response[yy as usize * w + xx as usize];
                    // Ties go to the first in raster order.
                    if o > v || (o == v && (dy < 0 || (dy == 0 && dx < 0))) {
                        is_max = false;
                        break 'window;
                    }
                }
            }
            if let Some(contrast) = is_max
                .then(|| x_corner_contrast(blur, &ring, x, y))
                .flatten()
            {
                out.push(Candidate {
                    x: x as f64,
                    y: y as f64,
                    response: v,
                    contrast,
                });
            }
        }
    }
    out.sort_by(|a, b| b.response.total_cmp(&a.response));
    out.truncate(MAX_CANDIDATES);
    out
}

/// The contrast of the ring around a point if it crosses its mean grey four times (dark, bright,
/// dark, bright: an X-corner), not twice (the L-corner where the board's outer squares meet its
/// margin).
fn x_corner_contrast(blur: &Plane, ring: &[(isize, isize); 16], x: usize, y: usize) -> Option<f32> {
    let s: [f32; 16] = std::array::from_fn(|k| {
        blur.at(
            (x as isize + ring[k].0) as usize,
            (y as isize + ring[k].1) as usize,
        )
    });
    let mean = s.iter().sum::<f32>() / 16.0;
    let (lo, hi) = s
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let margin = 0.15 * (hi - lo);
    let signs: Vec<bool> = s
        .iter()
        .filter(|&&v| (v - mean).abs() > margin)
        .map(|&v| v > mean)
        .collect();
    let changes = (0..signs.len())
        .filter(|&k| signs[k] != signs[(k + 1) % signs.len()])
        .count();
    (changes == 4).then_some(hi - lo)
}

/// Whether the segment between two corners is a square's edge: the grey levels either side of
/// its middle differ by a good part of the local contrast.
fn is_edge(blur: &Plane, a: &Candidate, b: &Candidate) -> bool {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let (nx, ny) = (-dy * 0.25, dx * 0.25);
    let side = |sign: f64| -> f32 {
        [0.35, 0.5, 0.65]
            .iter()
            .map(|t| blur.sample(a.x + t * dx + sign * nx, a.y + t * dy + sign * ny))
            .sum::<f32>()
            / 3.0
    };
    (side(1.0) - side(-1.0)).abs() > EDGE_CONTRAST_FRACTION * a.contrast.min(b.contrast)
}

/// Grid cell -> candidate index.
type Grid = HashMap<(i32, i32), usize>;

/// Grows a grid from one seed candidate; `None` when the seed has no two edge neighbours.
fn grow(blur: &Plane, cands: &[Candidate], seed: usize) -> Option<Grid> {
    let s = cands[seed];
    let dist = |a: &Candidate, b: &Candidate| (a.x - b.x).hypot(a.y - b.y);
    let mut near: Vec<usize> = (0..cands.len()).filter(|&i| i != seed).collect();
    near.sort_by(|&a, &b| dist(&cands[a], &s).total_cmp(&dist(&cands[b], &s)));
    near.truncate(8);
    near.retain(|&i| is_edge(blur, &s, &cands[i]));
    let u_i = *near.first()?;
    let u = (cands[u_i].x - s.x, cands[u_i].y - s.y);
    let v_i = *near.iter().skip(1).find(|&&i| {
        let v = (cands[i].x - s.x, cands[i].y - s.y);
        let cos = (u.0 * v.0 + u.1 * v.1) / (u.0.hypot(u.1) * v.0.hypot(v.1));
        cos.abs() < 0.7
    })?;
    let v = (cands[v_i].x - s.x, cands[v_i].y - s.y);
    let mut grid = Grid::new();
    let mut used = vec![false; cands.len()];
    grid.insert((0, 0), seed);
    used[seed] = true;
    let mut queue = VecDeque::from([(0i32, 0i32)]);
    while let Some((i, j)) = queue.pop_front() {
        let p = cands[grid[&(i, j)]];
        for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let target = (i + di, j + dj);
            if grid.contains_key(&target) {
                continue;
            }
            let pos = |cell: (i32, i32)| grid.get(&cell).map(|&k| (cands[k].x, cands[k].y));
            let step = if let Some(back) = pos((i - di, j - dj)) {
                (p.x - back.0, p.y - back.1)
            } else if let Some(step) = [(dj, di), (-dj, -di)].iter().find_map(|(ei, ej)| {
                let a = pos((i + ei, j + ej))?;
                let b = pos((i + ei + di, j + ej + dj))?;
                Some((b.0 - a.0, b.1 - a.1))
            }) {
                step
            } else {
                let sign = (di + dj) as f64;
                if di != 0 {
                    (u.0 * sign, u.1 * sign)
                } else {
                    (v.0 * sign, v.1 * sign)
                }
            };
            let (px, py) = (p.x + step.0, p.y + step.1);
            let radius = SEARCH_FRACTION * step.0.hypot(step.1);
            let found = (0..cands.len())
                .filter(|&k| !used[k])
                .map(|k| (k, (cands[k].x - px).hypot(cands[k].y - py)))
                .filter(|&(_, d)| d < radius)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(k, _)| k)
                .filter(|&k| is_edge(blur, &p, &cands[k]));
            if let Some(k) = found {
                used[k] = true;
                grid.insert(target, k);
                queue.push_back(target);
            }
        }
    }
    Some(grid)
}

/// Finds a `cols x rows` inner-corner chessboard; corners in board order (index `r · cols + c`,
/// see the module notes), refined to sub-pixel.
pub fn detect_chessboard(
    image: &GrayImage,
    cols: u32,
    rows: u32,
) -> Result<Vec<[f64; 2]>, ChessboardMiss> {
    match find_chessboard(image, cols, rows, None)? {
        ChessboardFound::Whole(px) => Ok(px),
        ChessboardFound::Part(part) => Err(ChessboardMiss::Partial {
            found: part.len(),
            expected: (cols * rows) as usize,
        }),
    }
}

/// What was found of a chessboard: the whole board (corners in board order, refined), or a part
/// of it ([`PartCorner`]s).
#[derive(Debug, Clone, PartialEq)]
pub enum ChessboardFound {
    /// The whole board, as [`detect_chessboard`] gives it.
    Whole(Vec<[f64; 2]>),
    /// The board seen in part.
    Part(Vec<PartCorner>),
}

/// Finds a `cols x rows` chessboard, whole, or when `min_part_corners` is given and the whole
/// board is not in view, a part of it: the largest grid grown, when it holds at least that many
/// corners in two rows and two columns or more, fits inside the board either way round and lies
/// on one plane (every corner within a quarter of a square of the homography through
/// the part). A part's corners are refined to sub-pixel, each with its cell `(c, r)` counted
/// from the part's own first corner (+c then +r turning clockwise on the image, as a whole
/// board's). Which of the board's corners they are is not known (rows and columns look alike),
/// but they lie on the board's grid: a calibration gives such a view a board pose of its own,
/// which takes up the offset.
pub fn find_chessboard(
    image: &GrayImage,
    cols: u32,
    rows: u32,
    min_part_corners: Option<usize>,
) -> Result<ChessboardFound, ChessboardMiss> {
    if image.width() < 16 || image.height() < 16 || cols < 2 || rows < 2 {
        return Err(ChessboardMiss::NoCorners);
    }
    let blur = binomial5_gray(image);
    let cands = candidates(&blur);
    if cands.len() < 4 {
        return Err(ChessboardMiss::NoCorners);
    }
    match search(&blur, &cands, cols, rows) {
        Search::Whole(at) => Ok(ChessboardFound::Whole(refine_all(
            &binomial5(&blur),
            &at,
            cols as usize,
            rows as usize,
        ))),
        Search::Part(grid) if grid.is_empty() => Err(ChessboardMiss::NoCorners),
        Search::Part(grid) => {
            let found = grid.len();
            min_part_corners
                .and_then(|min| part_corners(&blur, grid, cols, rows, min))
                .map(ChessboardFound::Part)
                .ok_or(ChessboardMiss::Partial {
                    found,
                    expected: (cols * rows) as usize,
                })
        }
    }
}

/// What the search for a board found: the whole board (corners in board order, not yet
/// refined), or the largest grid grown.
enum Search {
    Whole(Vec<[f64; 2]>),
    Part(Vec<((i32, i32), [f64; 2])>),
}

/// Grows grids from the strongest candidates until one holds the whole board; else the largest.
fn search(blur: &Plane, cands: &[Candidate], cols: u32, rows: u32) -> Search {
    let (cols_i, rows_i) = (cols as i32, rows as i32);
    let mut largest: Vec<((i32, i32), [f64; 2])> = Vec::new();
    let mut seeded = vec![false; cands.len()];
    for seed in 0..cands.len().min(MAX_SEEDS * 4) {
        if seeded[seed] || seeded.iter().filter(|&&s| s).count() >= MAX_SEEDS {
            continue;
        }
        seeded[seed] = true;
        let Some(grid) = grow(blur, cands, seed) else {
            continue;
        };
        // Candidates in a failed grid are not tried again as seeds.
        for &k in grid.values() {
            seeded[k] = true;
        }
        if grid.len() > largest.len() {
            largest = grid
                .iter()
                .map(|(&cell, &k)| (cell, [cands[k].x, cands[k].y]))
                .collect();
        }
        let Some(cell) = best_window(&grid, cands, cols_i, rows_i) else {
            continue;
        };
        let mut at: Vec<[f64; 2]> = (0..rows_i)
            .flat_map(|r| (0..cols_i).map(move |c| (c, r)))
            .map(|(c, r)| {
                let k = grid[&cell(c, r)];
                [cands[k].x, cands[k].y]
            })
            .collect();
        order_board(blur, &mut at, cols as usize, rows as usize);
        return Search::Whole(at);
    }
    largest.sort_by_key(|(cell, _)| (cell.1, cell.0));
    Search::Part(largest)
}

/// A corner of a chessboard seen in part: its cell `(c, r)` counted from the part's first
/// corner, and its pixel.
pub type PartCorner = ((u32, u32), [f64; 2]);

/// The part of a board a grown grid is ([`find_chessboard`]), numbered and refined; `None` when
/// it is not one.
fn part_corners(
    blur: &Plane,
    part: Vec<((i32, i32), [f64; 2])>,
    cols: u32,
    rows: u32,
    min_corners: usize,
) -> Option<Vec<PartCorner>> {
    let (i0, i1) = range(part.iter().map(|(c, _)| c.0));
    let (j0, j1) = range(part.iter().map(|(c, _)| c.1));
    let (ni, nj) = ((i1 - i0 + 1) as u32, (j1 - j0 + 1) as u32);
    let fits = (ni <= cols && nj <= rows) || (ni <= rows && nj <= cols);
    if part.len() < min_corners.max(4) || ni < 2 || nj < 2 || !fits {
        return None;
    }
    let at: HashMap<(i32, i32), [f64; 2]> = part.iter().copied().collect();
    // Handedness, from the first corner with both neighbours: mirror the columns if +c then +r
    // turn anticlockwise.
    let anticlockwise = part.iter().find_map(|(c, p)| {
        let (u, v) = (at.get(&(c.0 + 1, c.1))?, at.get(&(c.0, c.1 + 1))?);
        let (u, v) = ([u[0] - p[0], u[1] - p[1]], [v[0] - p[0], v[1] - p[1]]);
        Some(u[0] * v[1] - u[1] * v[0] < 0.0)
    })?;
    // One plane maps the cells onto the corners (within lens distortion): a grid grown astray,
    // a step skipped or doubled, is a square off somewhere.
    let pairs: Vec<([f64; 2], [f64; 2])> = part
        .iter()
        .map(|&((i, j), p)| ([i as f64, j as f64], p))
        .collect();
    let h = crate::geometry::homography::Homography::from_pairs(&pairs)?;
    let step = {
        let mut steps: Vec<f64> = part
            .iter()
            .filter_map(|(c, p)| {
                let q = at.get(&(c.0 + 1, c.1))?;
                Some((q[0] - p[0]).hypot(q[1] - p[1]))
            })
            .collect();
        steps.sort_by(f64::total_cmp);
        steps.get(steps.len() / 2).copied()?
    };
    let off = |(c, p): &((i32, i32), [f64; 2])| {
        let q = h.project(c.0 as f64, c.1 as f64);
        (q[0] - p[0]).hypot(q[1] - p[1])
    };
    if part.iter().map(off).fold(0.0, f64::max) > (PART_PLANE_SHARE * step).max(2.0) {
        return None;
    }
    let plane = binomial5(blur);
    Some(
        part.iter()
            .map(|&((i, j), p)| {
                let nearest = [(1, 0), (-1, 0), (0, 1), (0, -1)]
                    .iter()
                    .filter_map(|(di, dj)| at.get(&(i + di, j + dj)))
                    .map(|q| (q[0] - p[0]).hypot(q[1] - p[1]))
                    .fold(f64::INFINITY, f64::min);
                let hw = ((0.4 * nearest) as i32).clamp(2, MAX_REFINE_HALF_WIDTH);
                let c = if anticlockwise { i1 - i } else { i - i0 };
                (
                    (c as u32, (j - j0) as u32),
                    refine_x_corner(&plane, p[0], p[1], hw).unwrap_or(p),
                )
            })
            .collect(),
    )
}

/// Board cell `(c, r)` -> grid cell.
type CellMap = Box<dyn Fn(i32, i32) -> (i32, i32)>;

/// The fully populated `cols x rows` window of a grown grid (either way round) with the strongest
/// corners: a grid may run one row past the board onto its margin, where weaker L-corners sit.
fn best_window(grid: &Grid, cands: &[Candidate], cols: i32, rows: i32) -> Option<CellMap> {
    if grid.len() < (cols * rows) as usize {
        return None;
    }
    let (i0, i1) = range(grid.keys().map(|k| k.0));
    let (j0, j1) = range(grid.keys().map(|k| k.1));
    let mut best: Option<(f32, i32, i32, bool)> = None;
    for transposed in [false, true] {
        let (ni, nj) = if transposed {
            (rows, cols)
        } else {
            (cols, rows)
        };
        for a in i0..=i1 - ni + 1 {
            for b in j0..=j1 - nj + 1 {
                let mut strength = 0.0;
                let full = (a..a + ni).all(|i| {
                    (b..b + nj).all(|j| {
                        grid.get(&(i, j))
                            .map(|&k| strength += cands[k].response)
                            .is_some()
                    })
                });
                if full && best.is_none_or(|(s, ..)| strength > s) {
                    best = Some((strength, a, b, transposed));
                }
            }
        }
    }
    let (_, a, b, transposed) = best?;
    Some(if transposed {
        Box::new(move |c, r| (a + r, b + c))
    } else {
        Box::new(move |c, r| (a + c, b + r))
    })
}

fn range(values: impl Iterator<Item = i32>) -> (i32, i32) {
    values.fold((i32::MAX, i32::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)))
}

/// Puts a full grid (row-major, `cols` across) in board order: clockwise handedness, dark square
/// between corners (0, 0) and (1, 1).
fn order_board(blur: &Plane, at: &mut [[f64; 2]], cols: usize, rows: usize) {
    let idx = |c: usize, r: usize| r * cols + c;
    let (c, r) = ((cols - 2) / 2, (rows - 2) / 2);
    let o = at[idx(c, r)];
    let u = [at[idx(c + 1, r)][0] - o[0], at[idx(c + 1, r)][1] - o[1]];
    let v = [at[idx(c, r + 1)][0] - o[0], at[idx(c, r + 1)][1] - o[1]];
    if u[0] * v[1] - u[1] * v[0] < 0.0 {
        // Mirror the columns.
        for r in 0..rows {
            at[idx(0, r)..idx(0, r) + cols].reverse();
        }
    }
    // Square colours alternate; sum them with alternating signs so a lighting gradient cancels.
    let mut score = 0.0f64;
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let q = [idx(c, r), idx(c + 1, r), idx(c, r + 1), idx(c + 1, r + 1)];
            let x = q.iter().map(|&k| at[k][0]).sum::<f64>() / 4.0;
            let y = q.iter().map(|&k| at[k][1]).sum::<f64>() / 4.0;
            let sign = if (c + r) % 2 == 0 { 1.0 } else { -1.0 };
            score += sign * blur.sample(x, y) as f64;
        }
    }
    if score > 0.0 {
        // Square (0, 0) is bright: a half turn makes it dark when cols + rows is odd.
        at.reverse();
    }
}

/// Refines every corner with a window sized from its nearest grid neighbour.
fn refine_all(plane: &Plane, at: &[[f64; 2]], cols: usize, rows: usize) -> Vec<[f64; 2]> {
    let mut out = Vec::with_capacity(at.len());
    for r in 0..rows {
        for c in 0..cols {
            let p = at[r * cols + c];
            let mut nearest = f64::INFINITY;
            for (dc, dr) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                let (cc, rr) = (c as i64 + dc, r as i64 + dr);
                if cc >= 0 && rr >= 0 && (cc as usize) < cols && (rr as usize) < rows {
                    let q = at[rr as usize * cols + cc as usize];
                    nearest = nearest.min((q[0] - p[0]).hypot(q[1] - p[1]));
                }
            }
            let hw = ((0.4 * nearest) as i32).clamp(2, MAX_REFINE_HALF_WIDTH);
            out.push(refine_x_corner(plane, p[0], p[1], hw).unwrap_or(p));
        }
    }
    out
}

/// Position on the board of chessboard corner `k` (index `r · cols + c`): `(c · col_spacing,
/// r · row_spacing, 0)`, as Kalibr's checkerboard target places it.
pub fn chessboard_board_point(
    k: u32,
    cols: u32,
    col_spacing_m: f64,
    row_spacing_m: f64,
) -> [f64; 3] {
    let (c, r) = (k % cols, k / cols);
    [c as f64 * col_spacing_m, r as f64 * row_spacing_m, 0.0]
}

/// Board corners of a chessboard found by [`detect_chessboard`] (index
/// `r · cols + c`; layout: [`chessboard_board_point`]).
pub fn chessboard_board_corners(
    px: &[[f64; 2]],
    cols: u32,
    col_spacing_m: f64,
    row_spacing_m: f64,
) -> Vec<crate::calib::Corner> {
    px.iter()
        .enumerate()
        .map(|(k, p)| crate::calib::Corner {
            id: k as u32,
            board_m: chessboard_board_point(k as u32, cols, col_spacing_m, row_spacing_m),
            px: *p,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic board: squares of `s` px, the (0, 0) inner corner at `origin`.
    fn board(cols: u32, rows: u32, s: f64, origin: (f64, f64)) -> GrayImage {
        GrayImage::from_fn(320, 240, |x, y| {
            // Area-average 16x16 sub-samples: edges placed to 1/16 px.
            let mut sum = 0.0f64;
            for k in 0..256 {
                let (fx, fy) = (
                    x as f64 + ((k % 16) as f64 + 0.5) / 16.0 - 0.5,
                    y as f64 + ((k / 16) as f64 + 0.5) / 16.0 - 0.5,
                );
                let (u, v) = ((fx - origin.0) / s, (fy - origin.1) / s);
                let inside = u > -1.0 && v > -1.0 && u < cols as f64 && v < rows as f64;
                let dark = inside && (u.floor() as i64 + v.floor() as i64) % 2 == 0;
                sum += if dark { 30.0 } else { 220.0 };
            }
            image::Luma([(sum / 256.0).round() as u8])
        })
    }

    #[test]
    fn finds_a_sharp_synthetic_board_in_order_within_005_px() {
        let (s, origin) = (24.3, (52.4, 47.7));
        let corners = detect_chessboard(&board(9, 6, s, origin), 9, 6).expect("found");
        assert_eq!(corners.len(), 54);
        for (k, p) in corners.iter().enumerate() {
            let (c, r) = ((k % 9) as f64, (k / 9) as f64);
            let want = (origin.0 + c * s, origin.1 + r * s);
            let err = (p[0] - want.0).hypot(p[1] - want.1);
            assert!(err < 0.05, "corner {k}: {p:?} vs {want:?}");
        }
    }

    #[test]
    fn a_board_cut_by_the_edge_is_reported_partial() {
        let miss = detect_chessboard(&board(9, 6, 30.0, (-40.0, 30.0)), 9, 6).unwrap_err();
        assert!(matches!(miss, ChessboardMiss::Partial { .. }), "{miss:?}");
    }

    #[test]
    fn a_plain_image_has_no_corners() {
        let img = GrayImage::from_pixel(100, 80, image::Luma([128]));
        assert_eq!(
            detect_chessboard(&img, 9, 6),
            Err(ChessboardMiss::NoCorners)
        );
    }
}
