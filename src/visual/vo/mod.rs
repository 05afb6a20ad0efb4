//! Visual odometry: the robot's planar motion between two stereo frames, from the texture of the
//! home the cameras see.
//!
//! Wheel odometry measures distance well and heading badly: a few millimetres of random wheel
//! error per metre turn the heading by about half a degree per √m, and only a landmark can undo
//! that. The cameras see walls, floor and furniture all the time, so the image motion between two
//! frames measures the turn directly. For frames `a` (a stereo pair) and `b` (its left image):
//!
//! 1. corners (Shi-Tomasi's response, the strongest of each cell of a grid) in the left image of
//!    `a`, found at pyramid level 1 where the sensor noise is smoothed away (our own: kornia's
//!    `gftt_response` at full resolution took longer than the whole motion);
//! 2. each matched along its epipolar line in the right image of `a` by normalised
//!    cross-correlation (a quarter-resolution search, then quarter-pixel steps at full resolution)
//!    and triangulated;
//! 3. each looked for in the left image of `b` around where the wheel odometry puts it (a
//!    half-resolution search, then a full-resolution one with a parabola through the peak);
//! 4. the planar motion `robot_a_from_robot_b` that best reprojects the points into `b`
//!    (Gauss-Newton from the wheel odometry, Huber weights, points off by more than three sigma
//!    left out), with its covariance from the reprojection residuals.
//!
//! Walls and floors here carry a soft, cloudy texture (painted plaster, carpet): kornia-imgproc's
//! pyramidal Lucas-Kanade tracker, tried first, wandered off on it (median 150 px from the right place on the
//! rendered office), so points are matched by correlation, which needs a peak that stands out.

use crate::camera::StereoRig;
use crate::geometry::Pose2;
use crate::imgproc::blur::binomial5_gray;
use crate::imgproc::ncc::{dot, zero_mean_unit, LANES};
use crate::imgproc::Plane;
use crate::visual::stereo::triangulate_point;
use nalgebra::{Isometry3, Matrix3, Point2, Point3, Translation3, UnitQuaternion, Vector3};

/// Settings of the visual odometry.
#[derive(Debug, Clone, PartialEq)]
pub struct VoConfig {
    /// Grid of cells the corners are spread over (columns, rows).
    pub grid: (usize, usize),
    /// Weakest corner kept, as a share of the strongest in the image (texture corners are a
    /// thousand times weaker than a tag's).
    pub min_response_share: f32,
    /// Nearest and farthest point matched between the cameras, metres.
    pub depth_range_m: (f64, f64),
    /// How far from where the wheel odometry puts it a point is looked for in the next frame,
    /// pixels (a degree of heading error is 8 px with the default rig).
    pub search_radius_px: f64,
    /// Least normalised cross-correlation of a match.
    pub min_correlation: f32,
    /// Least margin of a match over the best correlation elsewhere.
    pub min_margin: f32,
    /// Largest change of a point's apparent size between the frames (the ratio of its depths,
    /// less one) for it to be matched (ours: 0.4); its patch is resampled to the size it will
    /// have before it is looked for.
    pub max_scale_change: f64,
    /// Points in agreement needed for a motion, at least.
    pub min_inliers: usize,
    /// Huber width of the reprojection residuals, pixels.
    pub huber_px: f64,
    /// Floor of the residual sigma behind the covariance, pixels.
    pub sigma_floor_px: f64,
    /// Factor on the variance from the reprojection residuals: the matches of one frame share
    /// errors the residuals do not show (ours: 2.5, so that the mean squared turn error over its
    /// variance, `visual.turn_nees` in a survey's report, is about 1 on the office and museum
    /// sample runs).
    pub variance_scale: f64,
    /// Least travel and turn between two frames whose motion is measured (ours: 0.25 m, 15
    /// degrees): closer frames add their errors without adding much motion.
    pub min_spacing: (f64, f64),
    /// Most travel and turn between two frames whose motion is measured (ours: 1 m, 45 degrees:
    /// beyond that too little of one frame is seen in the other).
    pub max_spacing: (f64, f64),
    /// Sigma of the wheel odometry's forward travel between two frames, metres: a floor plus a
    /// share of the distance (ours: 2 mm + 1%).
    pub forward_sigma: (f64, f64),
    /// Sigma of the sideways slip between two frames, metres: a floor plus a share of the
    /// distance (ours: 0.5 mm + 0.2%, the simulated wheels' random error over a step). A
    /// differential-drive robot does not move sideways: between two frames its path's chord
    /// points off its first heading by a share of the turn that the wheels' path gives (half on
    /// an arc, all of it when it turned on the spot and then drove), whatever the turn's size.
    /// The images alone tell a turn from a sideways step poorly when most of what they see lies
    /// at one depth (0.24 degrees RMS turn error on a rendered office run without this, 0.03
    /// with it); the path's shape tells them apart without the wheels' turn, which the images'
    /// is to correct.
    pub slip_sigma: (f64, f64),
}

impl Default for VoConfig {
    fn default() -> Self {
        Self {
            grid: (12, 9),
            min_response_share: 1e-4,
            depth_range_m: (0.3, 20.0),
            search_radius_px: 24.0,
            min_correlation: 0.8,
            min_margin: 0.05,
            max_scale_change: 0.4,
            min_inliers: 12,
            huber_px: 1.0,
            sigma_floor_px: 0.05,
            variance_scale: 2.5,
            min_spacing: (0.25, 15f64.to_radians()),
            max_spacing: (1.0, 45f64.to_radians()),
            forward_sigma: (0.002, 0.01),
            slip_sigma: (0.0005, 0.002),
        }
    }
}

/// Why two frames gave no motion.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VoError {
    /// Too few points survived.
    #[error("only {found} points agree (at least {needed} needed)")]
    TooFewPoints {
        /// How many.
        found: usize,
        /// How many needed.
        needed: usize,
    },
    /// An image is not of the rig's size.
    #[error("image is {found:?} pixels, the rig's camera {expected:?}")]
    WrongSize {
        /// Found (width, height).
        found: (usize, usize),
        /// Expected (width, height).
        expected: (usize, usize),
    },
}

/// One level of an image pyramid, with its integral images (sums of values and of squares, for
/// the mean and spread of any patch in constant time) where many patches are compared.
struct Level {
    image: Plane,
    sums: Option<(Vec<f64>, Vec<f64>)>,
}

impl Level {
    fn new(image: Plane, with_sums: bool) -> Self {
        let sums = with_sums.then(|| {
            let (w, h) = (image.w, image.h);
            let s = image.data.as_slice();
            let mut sum = vec![0.0f64; (w + 1) * (h + 1)];
            let mut sum2 = vec![0.0f64; (w + 1) * (h + 1)];
            for (y, pixels) in s.chunks_exact(w).enumerate() {
                let (above, below) = sum.split_at_mut((y + 1) * (w + 1));
                let (above2, below2) = sum2.split_at_mut((y + 1) * (w + 1));
                let above = &above[y * (w + 1) + 1..];
                let above2 = &above2[y * (w + 1) + 1..];
                let (mut row, mut row2) = (0.0, 0.0);
                for x in 0..w {
                    let v = pixels[x] as f64;
                    row += v;
                    row2 += v * v;
                    below[x + 1] = above[x] + row;
                    below2[x + 1] = above2[x] + row2;
                }
            }
            (sum, sum2)
        });
        Self { image, sums }
    }

    fn width(&self) -> i64 {
        self.image.w as i64
    }

    fn height(&self) -> i64 {
        self.image.h as i64
    }

    fn inside(&self, x: i64, y: i64, half: i64) -> bool {
        x - half >= 0 && y - half >= 0 && x + half < self.width() && y + half < self.height()
    }

    /// Sum of values and of squares over the square of half-width `half` at `(x, y)` (inside).
    fn box_sums(&self, x: i64, y: i64, half: i64) -> (f64, f64) {
        let (x0, y0) = ((x - half) as usize, (y - half) as usize);
        let side = (2 * half + 1) as usize;
        match &self.sums {
            Some((sum, sum2)) => {
                let w1 = self.image.w + 1;
                let (x1, y1) = (x0 + side, y0 + side);
                let at = |v: &[f64], xx: usize, yy: usize| v[yy * w1 + xx];
                let box_of =
                    |v: &[f64]| at(v, x1, y1) - at(v, x0, y1) - at(v, x1, y0) + at(v, x0, y0);
                (box_of(sum), box_of(sum2))
            }
            None => {
                let w = self.image.w;
                let data = self.image.data.as_slice();
                (0..side).fold((0.0, 0.0), |(s, s2), row| {
                    let line = &data[(y0 + row) * w + x0..(y0 + row) * w + x0 + side];
                    let (a, b) = line
                        .iter()
                        .fold((0.0f32, 0.0f32), |(a, b), &v| (a + v, b + v * v));
                    (s + a as f64, s2 + b as f64)
                })
            }
        }
    }

    /// Correlations of a zero-mean, unit-norm reference with the patches centred on integer
    /// `positions` (`NEG_INFINITY` where a patch leaves the image or is flat). Positions that
    /// follow each other along a row are worked together ([`Level::correlate_row`]).
    fn correlate_at(&self, reference: &[f32], positions: &[(i64, i64)], half: i64) -> Vec<f32> {
        let mut out = Vec::with_capacity(positions.len());
        let mut columns = Columns::default();
        let mut rest = positions;
        while let Some(&(x, y)) = rest.first() {
            // Along the row either way (a right image's epipolar line runs right to left).
            let run = |step: i64| {
                1 + rest
                    .windows(2)
                    .take_while(|p| p[1] == (p[0].0 + step, p[0].1))
                    .count()
            };
            let (forward, backward) = (run(1), run(-1));
            let n = forward.max(backward);
            if forward >= backward {
                self.correlate_row(reference, (x, y), n, half, &mut columns, &mut out);
            } else {
                let start = out.len();
                let first = x - (n as i64 - 1);
                self.correlate_row(reference, (first, y), n, half, &mut columns, &mut out);
                out[start..].reverse();
            }
            rest = &rest[n..];
        }
        out
    }

    /// [`Level::correlate_at`] the `n` pixels from `(x, y)` to `(x + n - 1, y)`, appended to
    /// `out`: the products are summed for eight positions at once, a reference pixel times eight
    /// image pixels at a time, which the compiler keeps in vector registers. `columns` holds the
    /// column sums of a level without integral images, from one run to the next.
    fn correlate_row(
        &self,
        reference: &[f32],
        (x, y): (i64, i64),
        n: usize,
        half: i64,
        columns: &mut Columns,
        out: &mut Vec<f32>,
    ) {
        let last = x + n as i64 - 1;
        if !(self.inside(x, y, half) && self.inside(last, y, half)) {
            out.extend((x..=last).map(|x| {
                self.correlate(reference, x, y, half)
                    .unwrap_or(f32::NEG_INFINITY)
            }));
            return;
        }
        let side = (2 * half + 1) as usize;
        let w = self.image.w;
        let (left, top) = ((x - half) as usize, (y - half) as usize);
        // Each lane of eight positions reads eight pixels past the first of its patches' rows:
        // past the last position, those of the image that follow, or zeros at its very end.
        let lanes = n.div_ceil(LANES);
        let reach = top * w + (side - 1) * w + left + lanes * LANES + side - 1;
        let data = self.image.data.as_slice();
        let padded;
        let (data, stride, origin) = if reach <= data.len() {
            (data, w, top * w + left)
        } else {
            let width = lanes * LANES + side - 1;
            let mut rows = vec![0.0f32; side * width];
            for (copy, row) in rows.chunks_exact_mut(width).zip(data[top * w..].chunks(w)) {
                copy[..n + side - 1].copy_from_slice(&row[left..left + n + side - 1]);
            }
            padded = rows;
            (&padded[..], width, 0)
        };
        let sums = self.box_sums_row((x, y), n, half, columns);
        let count = (side * side) as f64;
        for l in 0..lanes {
            let mut acc = [0.0f32; LANES];
            for (k, patch_row) in reference.chunks_exact(side).enumerate() {
                let row = &data[origin + k * stride + l * LANES..];
                for (c, &r) in patch_row.iter().enumerate() {
                    let v: &[f32; LANES] = row[c..c + LANES].try_into().expect("eight pixels");
                    for (a, &v) in acc.iter_mut().zip(v) {
                        *a += r * v;
                    }
                }
            }
            let first = l * LANES;
            for (&dot, &(s, s2)) in acc.iter().zip(&sums[first..(first + LANES).min(n)]) {
                let spread = (s2 - s * s / count).max(0.0).sqrt();
                out.push(if spread < 1e-3 * count {
                    f32::NEG_INFINITY
                } else {
                    (dot as f64 / spread) as f32
                });
            }
        }
    }

    /// [`Level::box_sums`] of the `n` squares centred from `(x, y)` to `(x + n - 1, y)` (all
    /// inside): from the integral images, or without them from the column sums of the rows the
    /// squares cover (in `columns`: moved down a row when the last run was the same one a row
    /// higher), slid along.
    fn box_sums_row(
        &self,
        (x, y): (i64, i64),
        n: usize,
        half: i64,
        columns: &mut Columns,
    ) -> Vec<(f64, f64)> {
        if self.sums.is_some() {
            return (x..x + n as i64)
                .map(|x| self.box_sums(x, y, half))
                .collect();
        }
        let side = (2 * half + 1) as usize;
        let w = self.image.w;
        let (left, top) = ((x - half) as usize, (y - half) as usize);
        let span = n + side - 1;
        let data = self.image.data.as_slice();
        let row = |r: usize| &data[r * w + left..r * w + left + span];
        if columns.run == Some((x, y - 1, n, half)) {
            for ((c, &out), &new) in columns
                .sums
                .iter_mut()
                .zip(row(top - 1))
                .zip(row(top + side - 1))
            {
                let (out, new) = (out as f64, new as f64);
                c.0 += new - out;
                c.1 += new * new - out * out;
            }
        } else {
            columns.sums.clear();
            columns.sums.resize(span, (0.0, 0.0));
            for r in top..top + side {
                for (c, &v) in columns.sums.iter_mut().zip(row(r)) {
                    let v = v as f64;
                    c.0 += v;
                    c.1 += v * v;
                }
            }
        }
        columns.run = Some((x, y, n, half));
        let c = &columns.sums;
        let mut window = c[..side]
            .iter()
            .fold((0.0, 0.0), |(s, s2), c| (s + c.0, s2 + c.1));
        let mut out = Vec::with_capacity(n);
        out.push(window);
        for i in 1..n {
            let (old, new) = (c[i - 1], c[i + side - 1]);
            window = (window.0 + new.0 - old.0, window.1 + new.1 - old.1);
            out.push(window);
        }
        out
    }

    /// Correlation of a zero-mean, unit-norm reference with the patch at integer `(x, y)`.
    fn correlate(&self, reference: &[f32], x: i64, y: i64, half: i64) -> Option<f32> {
        if !self.inside(x, y, half) {
            return None;
        }
        let (s, s2) = self.box_sums(x, y, half);
        let n = ((2 * half + 1) * (2 * half + 1)) as f64;
        let spread = (s2 - s * s / n).max(0.0).sqrt();
        if spread < 1e-3 * n {
            return None;
        }
        let w = self.image.w;
        let data = self.image.data.as_slice();
        let side = (2 * half + 1) as usize;
        let mut sum = 0.0f32;
        for row in 0..side {
            let start = (y - half) as usize * w + row * w + (x - half) as usize;
            sum += dot(
                &data[start..start + side],
                &reference[row * side..(row + 1) * side],
            );
        }
        Some((sum as f64 / spread) as f32)
    }
}

/// The column sums (of values and of squares) of the rows a run of patches covers, and which run
/// (first position, length, half-width) they are for.
#[derive(Default)]
struct Columns {
    run: Option<(i64, i64, usize, i64)>,
    sums: Vec<(f64, f64)>,
}

/// The pixels of the square of half-width `r` around `(cx, cy)`, row by row.
fn square((cx, cy): (i64, i64), r: i64) -> Vec<(i64, i64)> {
    (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (cx + dx, cy + dy)))
        .collect()
}

/// The vertex offset of a parabola through three samples one step apart, within half a step.
fn vertex(l: f32, c: f32, r: f32) -> f32 {
    let den = l - 2.0 * c + r;
    if l.is_finite() && r.is_finite() && den < 0.0 {
        (0.5 * (l - r) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// Pixel coordinates at pyramid level `level` of a full-resolution pixel.
fn to_level(p: Point2<f64>, level: u32) -> Point2<f64> {
    let s = (1u32 << level) as f64;
    Point2::new((p.x + 0.5) / s - 0.5, (p.y + 0.5) / s - 0.5)
}

/// Full-resolution pixel of a pixel at pyramid level `level`.
fn from_level(p: Point2<f64>, level: u32) -> Point2<f64> {
    let s = (1u32 << level) as f64;
    Point2::new((p.x + 0.5) * s - 0.5, (p.y + 0.5) * s - 0.5)
}

/// One camera image ready for the visual odometry: full resolution smoothed (the sensor noise
/// against a soft texture would blur the matches), half and quarter resolution.
pub struct VoImage {
    full: Level,
    half: Level,
    quarter: Level,
}

impl VoImage {
    /// From an 8-bit grey image. Only the quarter resolution gets integral images: the searches
    /// there cover many positions (a whole epipolar line, the tracking radius); the few at half
    /// and full resolution sum the columns of their own patches ([`Level::box_sums_row`]).
    pub fn new(gray: &image::GrayImage) -> Self {
        let full = binomial5_gray(gray);
        let half = full.halved();
        let quarter = half.halved();
        Self {
            full: Level::new(full, false),
            half: Level::new(half, false),
            quarter: Level::new(quarter, true),
        }
    }

    fn size(&self) -> (usize, usize) {
        (self.full.image.w, self.full.image.h)
    }
}

/// The `(2 half + 1)²` pixels around integer `(x, y)`, zero-mean and unit-norm; `None` near a
/// border or on a flat patch.
fn patch_at(level: &Level, x: i64, y: i64, half: i64) -> Option<Vec<f32>> {
    if !level.inside(x, y, half) {
        return None;
    }
    let w = level.image.w;
    let data = level.image.data.as_slice();
    let side = (2 * half + 1) as usize;
    let mut v = Vec::with_capacity(side * side);
    for row in 0..side {
        let start = ((y - half) as usize + row) * w + (x - half) as usize;
        v.extend_from_slice(&data[start..start + side]);
    }
    zero_mean_unit(v)
}

/// [`patch_at`] sampled every `step` pixels (bilinear) instead of every pixel: the patch as it
/// looks magnified `1 / step` times.
fn patch_scaled(level: &Level, x: i64, y: i64, half: i64, step: f64) -> Option<Vec<f32>> {
    if (step - 1.0).abs() < 0.02 {
        return patch_at(level, x, y, half);
    }
    let reach = (half as f64 * step).ceil() as i64 + 1;
    if !level.inside(x, y, reach) {
        return None;
    }
    let side = (2 * half + 1) as usize;
    let mut v = Vec::with_capacity(side * side);
    for j in -half..=half {
        for i in -half..=half {
            v.push(
                level
                    .image
                    .sample(x as f64 + i as f64 * step, y as f64 + j as f64 * step),
            );
        }
    }
    zero_mean_unit(v)
}

/// Shi-Tomasi corner response (the smaller eigenvalue of the structure tensor: Sobel gradients
/// summed over a 5 x 5 window) of every pixel of `level`; zero within 3 px of the border.
fn corner_response(level: &Level) -> Vec<f32> {
    let (w, h) = (level.image.w, level.image.h);
    let s = level.image.data.as_slice();
    let mut out = vec![0.0f32; w * h];
    if w < 5 || h < 5 {
        return out;
    }
    // Row by row, the 5-wide sums of the gradient products (xx, yy, xy) of the last five rows
    // kept in a ring, then summed down the columns: each sum in the same order as a plain loop
    // over the window, left to right and top to bottom; a row or column without a whole window
    // is zero. One array per product, so that the loops run in vector registers.
    let mut ring = [
        vec![0.0f32; 5 * w],
        vec![0.0f32; 5 * w],
        vec![0.0f32; 5 * w],
    ];
    let mut products = [vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]];
    let mut window = [vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]];
    for y in 0..h {
        let [xx, yy, xy] = &mut products;
        if y > 0 && y + 1 < h {
            let (up, mid, down) = (
                &s[(y - 1) * w..y * w],
                &s[y * w..(y + 1) * w],
                &s[(y + 1) * w..(y + 2) * w],
            );
            for x in 1..w - 1 {
                let gx = (up[x + 1] + 2.0 * mid[x + 1] + down[x + 1])
                    - (up[x - 1] + 2.0 * mid[x - 1] + down[x - 1]);
                let gy = (down[x - 1] + 2.0 * down[x] + down[x + 1])
                    - (up[x - 1] + 2.0 * up[x] + up[x + 1]);
                (xx[x], yy[x], xy[x]) = (gx * gx, gy * gy, gx * gy);
            }
        } else {
            for p in [xx, yy, xy] {
                p.fill(0.0);
            }
        }
        for (ring, p) in ring.iter_mut().zip(&products) {
            let sums = &mut ring[(y % 5) * w..(y % 5 + 1) * w];
            sum5(
                [&p[..], &p[1..], &p[2..], &p[3..], &p[4..]],
                &mut sums[2..w - 2],
            );
        }
        if y < 4 {
            continue;
        }
        // Row `y - 2`, whose window is rows `y - 4` to `y`.
        for (ring, total) in ring.iter().zip(&mut window) {
            let r = |k: usize| &ring[((y - 4 + k) % 5) * w..((y - 4 + k) % 5 + 1) * w];
            sum5([r(0), r(1), r(2), r(3), r(4)], total);
        }
        let [a, b, c] = &window;
        let row = out[(y - 2) * w..(y - 1) * w]
            .iter_mut()
            .zip(a)
            .zip(b)
            .zip(c);
        for (((o, &a), &b), &c) in row {
            *o = 0.5 * (a + b) - (0.25 * (a - b) * (a - b) + c * c).sqrt();
        }
    }
    out
}

/// `out[x] = rows[0][x] + rows[1][x] + ... + rows[4][x]`, summed in that order.
fn sum5(rows: [&[f32]; 5], out: &mut [f32]) {
    let n = out.len();
    let [r0, r1, r2, r3, r4] = rows.map(|r| &r[..n]);
    for x in 0..n {
        out[x] = r0[x] + r1[x] + r2[x] + r3[x] + r4[x];
    }
}

/// The strongest corner of each grid cell, found at half resolution, in full-resolution pixels.
fn corners(image: &VoImage, config: &VoConfig) -> Vec<Point2<f64>> {
    let level = &image.half;
    let (w, h) = (level.image.w, level.image.h);
    let r = corner_response(level);
    let floor = r.iter().cloned().fold(0.0f32, f32::max) * config.min_response_share;
    let (cols, rows) = config.grid;
    let border = 8;
    if w <= 2 * border || h <= 2 * border {
        return Vec::new();
    }
    let (span_x, span_y) = (w - 2 * border, h - 2 * border);
    let mut out = Vec::with_capacity(cols * rows);
    for gy in 0..rows {
        for gx in 0..cols {
            let (x0, x1) = (
                border + gx * span_x / cols,
                border + (gx + 1) * span_x / cols,
            );
            let (y0, y1) = (
                border + gy * span_y / rows,
                border + (gy + 1) * span_y / rows,
            );
            // The first strongest pixel in reading order: each row's maximum (a vectorised
            // fold), and its first position only when it beats the rows before.
            let mut top = (floor, None);
            for y in y0..y1 {
                let row = &r[y * w + x0..y * w + x1];
                let most = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                if most > top.0 {
                    let x = row.iter().position(|&v| v == most).unwrap_or(0);
                    top = (most, Some((x0 + x, y)));
                }
            }
            if let Some((x, y)) = top.1 {
                out.push(Point2::new(2.0 * x as f64, 2.0 * y as f64));
            }
        }
    }
    out
}

/// The right-image pixel matching left pixel `p`, searched along its epipolar line from the far
/// to the near end of the depth range, first at a quarter of the resolution, then in quarter
/// pixels at full resolution; `None` when no match stands out.
fn epipolar_match(
    rig: &StereoRig,
    left: &VoImage,
    right: &VoImage,
    p: Point2<f64>,
    config: &VoConfig,
) -> Option<Point2<f64>> {
    let n = rig.left.unproject(&p)?;
    let ray = Vector3::new(n.x, n.y, 1.0);
    let right_px = |inverse_depth: f64| -> Option<Point2<f64>> {
        let x = Point3::from(ray / inverse_depth.max(1e-9));
        rig.right.project(&(rig.right_from_left * x).coords)
    };
    let (near, far) = (1.0 / config.depth_range_m.0, 1.0 / config.depth_range_m.1);
    let span_px = (right_px(near)?.coords - right_px(far)?.coords).norm();
    // Coarse: a step of one quarter-resolution pixel along the line.
    const HALF: i64 = 3;
    let a = to_level(p, 2);
    let (ax, ay) = (a.x.round() as i64, a.y.round() as i64);
    if !left.quarter.inside(ax, ay, HALF) {
        return None;
    }
    let reference = patch_at(&left.quarter, ax, ay, HALF)?;
    let steps = (span_px / 4.0).ceil().max(2.0) as usize;
    let along: Vec<(f64, Point2<f64>)> = (0..=steps)
        .filter_map(|k| {
            let inverse_depth = far + (near - far) * k as f64 / steps as f64;
            Some((inverse_depth, right_px(inverse_depth)?))
        })
        .collect();
    let at: Vec<(i64, i64)> = along
        .iter()
        .map(|(_, q)| {
            let c = to_level(*q, 2);
            (c.x.round() as i64, c.y.round() as i64)
        })
        .collect();
    let scores: Vec<(f64, Point2<f64>, f32)> = along
        .iter()
        .zip(right.quarter.correlate_at(&reference, &at, HALF))
        .filter(|(_, s)| s.is_finite())
        .map(|(&(inverse_depth, q), s)| (inverse_depth, q, s))
        .collect();
    let &(best_rho, best_px, best) = scores.iter().max_by(|a, b| a.2.total_cmp(&b.2))?;
    if best < config.min_correlation {
        return None;
    }
    let rival = scores
        .iter()
        .filter(|s| (s.1 - best_px).norm() > 12.0)
        .map(|s| s.2)
        .fold(f32::NEG_INFINITY, f32::max);
    if rival > best - config.min_margin {
        return None;
    }
    // Fine: whole pixels along the line at full resolution, ±6 px around the coarse match (each
    // on the pixel row nearest the line), then a parabola through the peak.
    let (px, py) = (p.x.round() as i64, p.y.round() as i64);
    let reference = patch_at(&left.full, px, py, 5)?;
    let per_px = (near - far) / span_px.max(1e-9);
    let along: Vec<(f64, (i64, i64))> = (-6..=6)
        .filter_map(|k| {
            let rho = best_rho + per_px * k as f64;
            let q = right_px(rho).filter(|_| rho > 0.0)?;
            Some((rho, (q.x.round() as i64, q.y.round() as i64)))
        })
        .collect();
    let at: Vec<(i64, i64)> = along.iter().map(|a| a.1).collect();
    let fine: Vec<(f64, f32)> = along
        .iter()
        .zip(right.full.correlate_at(&reference, &at, 5))
        .filter(|(_, s)| s.is_finite())
        .map(|(&(rho, _), s)| (rho, s))
        .collect();
    let (i, &(rho, peak)) = fine
        .iter()
        .enumerate()
        .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1))?;
    if i == 0 || i + 1 == fine.len() || peak < config.min_correlation - 0.1 {
        return None;
    }
    let offset = vertex(fine[i - 1].1, peak, fine[i + 1].1) as f64;
    right_px(rho + (fine[i + 1].0 - rho) * offset)
}

/// Where left pixel `p` of frame `a` is in frame `b`'s left image, looked for around `guess`:
/// at half resolution over the search radius, then at full resolution around the best; `None`
/// when no match stands out.
fn track(
    a: &VoImage,
    b: &VoImage,
    p: Point2<f64>,
    guess: Point2<f64>,
    scale: f64,
    config: &VoConfig,
) -> Option<Point2<f64>> {
    // The reference patches are taken from `a` as they will look in `b`: magnified `scale` times.
    let step = 1.0 / scale;
    // Quarter resolution over the whole search radius.
    let pa = to_level(p, 2);
    let (qx, qy) = (pa.x.round() as i64, pa.y.round() as i64);
    let reference = patch_scaled(&a.quarter, qx, qy, 3, step)?;
    let g = to_level(guess, 2);
    let (gx, gy) = (g.x.round() as i64, g.y.round() as i64);
    let r = (config.search_radius_px / 4.0).ceil() as i64;
    let at = square((gx, gy), r);
    let scores: Vec<(i64, i64, f32)> = at
        .iter()
        .zip(b.quarter.correlate_at(&reference, &at, 3))
        .filter(|(_, s)| s.is_finite())
        .map(|(&(x, y), s)| (x - gx, y - gy, s))
        .collect();
    let &(bx, by, best) = scores.iter().max_by(|a, b| a.2.total_cmp(&b.2))?;
    if best < config.min_correlation {
        return None;
    }
    let rival = scores
        .iter()
        .filter(|(dx, dy, _)| (dx - bx).abs() > 3 || (dy - by).abs() > 3)
        .map(|s| s.2)
        .fold(f32::NEG_INFINITY, f32::max);
    if rival > best - config.min_margin {
        return None;
    }
    // Half resolution: ±2 px around the quarter-resolution match.
    const HALF: i64 = 4;
    let pa = to_level(p, 1);
    let (ax, ay) = (pa.x.round() as i64, pa.y.round() as i64);
    let reference = patch_scaled(&a.half, ax, ay, HALF, step)?;
    let centre = to_level(
        from_level(Point2::new((gx + bx) as f64, (gy + by) as f64), 2)
            + (p - from_level(Point2::new(qx as f64, qy as f64), 2)),
        1,
    );
    let (hx, hy) = (centre.x.round() as i64, centre.y.round() as i64);
    let at = square((hx, hy), 2);
    let (mut best, mut bx, mut by) = (f32::NEG_INFINITY, hx, hy);
    for (&(x, y), s) in at.iter().zip(b.half.correlate_at(&reference, &at, HALF)) {
        if s > best {
            (best, bx, by) = (s, x, y);
        }
    }
    if best < config.min_correlation {
        return None;
    }
    // Full resolution: the pixel the half-resolution match lands on (`p`'s offset from its
    // half-resolution pixel kept), ±3 px around it, then a parabola each way through the peak.
    let coarse = from_level(Point2::new(bx as f64, by as f64), 1)
        + (p - from_level(Point2::new(ax as f64, ay as f64), 1));
    let (cx, cy) = (coarse.x.round() as i64, coarse.y.round() as i64);
    let reference = patch_scaled(&a.full, p.x.round() as i64, p.y.round() as i64, 7, step)?;
    let scores = b.full.correlate_at(&reference, &square((cx, cy), 3), 7);
    let grid: Vec<&[f32]> = scores.chunks_exact(7).collect();
    let (peak, i, j) = (0..7).flat_map(|j| (0..7).map(move |i| (i, j))).fold(
        (f32::NEG_INFINITY, 3, 3),
        |top, (i, j)| {
            if grid[j][i] > top.0 {
                (grid[j][i], i, j)
            } else {
                top
            }
        },
    );
    if i == 0 || j == 0 || i == 6 || j == 6 || peak < config.min_correlation - 0.1 {
        return None;
    }
    let ox = vertex(grid[j][i - 1], peak, grid[j][i + 1]) as f64;
    let oy = vertex(grid[j - 1][i], peak, grid[j + 1][i]) as f64;
    Some(Point2::new(
        (cx + i as i64 - 3) as f64 + ox,
        (cy + j as i64 - 3) as f64 + oy,
    ))
}

/// A corner of frame `a`'s left image with its 3D position in that camera's frame.
#[derive(Debug, Clone, Copy)]
struct StereoPoint {
    px: Point2<f64>,
    in_left: Vector3<f64>,
}

/// Corners of the left image found again in the right image, triangulated.
fn stereo_points(
    rig: &StereoRig,
    left: &VoImage,
    right: &VoImage,
    config: &VoConfig,
) -> Vec<StereoPoint> {
    corners(left, config)
        .into_iter()
        .filter_map(|px| {
            let q = epipolar_match(rig, left, right, px, config)?;
            let in_left = triangulate_point(rig, &px, &q)?;
            let (near, far) = config.depth_range_m;
            (in_left.z >= near && in_left.z <= far).then_some(StereoPoint { px, in_left })
        })
        .collect()
}

/// `left_b_from_left_a` for the robot motion `robot_a_from_robot_b`.
fn camera_motion(rig: &StereoRig, robot_a_from_robot_b: &Pose2) -> Isometry3<f64> {
    let m = robot_a_from_robot_b;
    let a_from_b = Isometry3::from_parts(
        Translation3::new(m.x, m.y, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), m.theta),
    );
    rig.robot_from_left.inverse() * a_from_b.inverse() * rig.robot_from_left
}

/// The motion between two frames as the cameras saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct VisualMotion {
    /// `robot_a_from_robot_b`.
    pub motion: Pose2,
    /// Covariance of `(x, y, theta)`.
    pub covariance: Matrix3<f64>,
    /// Points that agreed.
    pub inliers: usize,
    /// Points found in both frames.
    pub tracked: usize,
    /// RMS reprojection residual of the inliers, pixels.
    pub rms_px: f64,
}

/// A turn of the robot the cameras measured between two frames: what the fusion stage takes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct VisualTurn {
    /// Time of the first frame, seconds.
    pub from_t_s: f64,
    /// Time of the second frame, seconds.
    pub to_t_s: f64,
    /// The turn between them, radians (counter-clockwise positive).
    pub turn_rad: f64,
    /// Its sigma, radians.
    pub sigma_rad: f64,
}

impl VisualMotion {
    /// The turn of this motion between frames taken at `from_t_s` and `to_t_s`.
    pub fn turn(&self, from_t_s: f64, to_t_s: f64) -> VisualTurn {
        VisualTurn {
            from_t_s,
            to_t_s,
            turn_rad: self.motion.theta,
            sigma_rad: self.covariance[(2, 2)].max(0.0).sqrt(),
        }
    }
}

/// The pairs of frames (indices into `times`, time order) whose motion is measured: from each
/// chosen frame to the first one at least [`VoConfig::min_spacing`] away by the odometry (or the
/// last frame before it, when that is farther than [`VoConfig::max_spacing`]); a pair still
/// farther apart than that is left out, and the chain starts again from its second frame.
pub fn frame_pairs(
    times: &[f64],
    odometry: &[crate::geometry::StampedPose],
    config: &VoConfig,
) -> Vec<(usize, usize)> {
    let pose = |t: f64| crate::geometry::pose_at(odometry, t);
    let apart = |a: usize, b: usize, (m, rad): (f64, f64)| match (pose(times[a]), pose(times[b])) {
        (Some(pa), Some(pb)) => {
            let d = pa.between(&pb);
            d.x.hypot(d.y) >= m || d.theta.abs() >= rad
        }
        _ => true,
    };
    let mut order: Vec<usize> = (0..times.len()).collect();
    order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
    let mut pairs = Vec::new();
    let Some(&first) = order.first() else {
        return pairs;
    };
    let mut from = first;
    let mut previous = first;
    for &k in &order[1..] {
        if apart(from, k, config.min_spacing) {
            // Step back to the frame before when this one is already too far.
            let to = if previous != from && apart(from, k, config.max_spacing) {
                previous
            } else {
                k
            };
            if !apart(from, to, config.max_spacing) {
                pairs.push((from, to));
            }
            from = to;
            if to == previous && previous != k && apart(from, k, config.min_spacing) {
                if !apart(from, k, config.max_spacing) {
                    pairs.push((from, k));
                }
                from = k;
            }
        }
        previous = k;
    }
    pairs
}

/// The planar motion `robot_a_from_robot_b` between frame `a` (its stereo pair) and frame `b`
/// (its left image), starting from the wheel odometry's `prior`.
pub fn relative_motion(
    rig: &StereoRig,
    (a_left, a_right): (&VoImage, &VoImage),
    b_left: &VoImage,
    prior: &Pose2,
    config: &VoConfig,
) -> Result<VisualMotion, VoError> {
    for (image, camera) in [
        (a_left, &rig.left),
        (a_right, &rig.right),
        (b_left, &rig.left),
    ] {
        let expected = (camera.width as usize, camera.height as usize);
        if image.size() != expected {
            return Err(VoError::WrongSize {
                found: image.size(),
                expected,
            });
        }
    }
    let points = stereo_points(rig, a_left, a_right, config);
    let b_from_a = camera_motion(rig, prior);
    let observations: Vec<(Vector3<f64>, Point2<f64>)> = points
        .iter()
        .filter_map(|p| {
            let moved = b_from_a * Point3::from(p.in_left);
            // A patch the motion magnifies or shrinks much no longer matches its image.
            let scale = p.in_left.z / moved.z.max(1e-6);
            if (scale - 1.0).abs() > config.max_scale_change {
                return None;
            }
            let guess = rig.left.project(&moved.coords)?;
            let found = track(a_left, b_left, p.px, guess, scale, config)?;
            Some((p.in_left, found))
        })
        .collect();
    let mut motion = solve_planar(rig, &observations, prior, config)?;
    motion.tracked = observations.len();
    Ok(motion)
}

/// Reprojection residuals, pixels, per observation (`None` where a point is left out or does not
/// project).
type Residuals = Vec<Option<[f64; 2]>>;

/// Residuals (pixels) of the observations under a motion; `None` where a point does not project.
fn residuals(
    rig: &StereoRig,
    observations: &[(Vector3<f64>, Point2<f64>)],
    motion: &Pose2,
    active: &[bool],
) -> Residuals {
    let b_from_a = camera_motion(rig, motion);
    observations
        .iter()
        .zip(active)
        .map(|((x, q), &on)| {
            let p = rig
                .left
                .project(&(b_from_a * Point3::from(*x)).coords)
                .filter(|_| on)?;
            Some([p.x - q.x, p.y - q.y])
        })
        .collect()
}

/// Steps of the numerical derivatives over `(x, y, theta)`.
const STEPS: [f64; 3] = [1e-6, 1e-6, 1e-7];

/// The residuals at `motion` and at `motion` moved by each of [`STEPS`].
fn residuals_and_columns(
    rig: &StereoRig,
    observations: &[(Vector3<f64>, Point2<f64>)],
    motion: &Pose2,
    active: &[bool],
) -> (Residuals, [Residuals; 3]) {
    let moved = |k: usize| {
        let mut m = *motion;
        match k {
            0 => m.x += STEPS[0],
            1 => m.y += STEPS[1],
            _ => m.theta += STEPS[2],
        }
        residuals(rig, observations, &m, active)
    };
    (
        residuals(rig, observations, motion, active),
        [moved(0), moved(1), moved(2)],
    )
}

/// `JᵀWJ` and `JᵀWr` of the active residuals; `huber` = `None` for unit weights.
fn normal_equations(
    r0: &[Option<[f64; 2]>],
    columns: &[Residuals; 3],
    huber: Option<f64>,
) -> (Matrix3<f64>, Vector3<f64>) {
    let mut jtj = Matrix3::zeros();
    let mut jtr = Vector3::zeros();
    for (i, r) in r0.iter().enumerate() {
        let Some(r) = r else { continue };
        let mut j = [Vector3::zeros(); 2];
        let mut complete = true;
        for k in 0..3 {
            match columns[k][i] {
                Some(rk) => {
                    j[0][k] = (rk[0] - r[0]) / STEPS[k];
                    j[1][k] = (rk[1] - r[1]) / STEPS[k];
                }
                None => complete = false,
            }
        }
        if !complete {
            continue;
        }
        let norm = r[0].hypot(r[1]);
        let w = match huber {
            Some(h) if norm > h => h / norm,
            _ => 1.0,
        };
        for row in 0..2 {
            jtj += w * j[row] * j[row].transpose();
            jtr += w * j[row] * r[row];
        }
    }
    (jtj, jtr)
}

/// Gauss-Newton on `(x, y, theta)` with Huber weights from `prior`; three rounds, each followed by
/// dropping the points over three sigma (by the median residual).
fn solve_planar(
    rig: &StereoRig,
    observations: &[(Vector3<f64>, Point2<f64>)],
    prior: &Pose2,
    config: &VoConfig,
) -> Result<VisualMotion, VoError> {
    let too_few = |found| VoError::TooFewPoints {
        found,
        needed: config.min_inliers,
    };
    if observations.len() < config.min_inliers {
        return Err(too_few(observations.len()));
    }
    let mut active = vec![true; observations.len()];
    let mut m = *prior;
    // The wheels' forward travel and the arc's sideways offset as priors, weighted against the
    // image residuals' sigma (found below).
    let travel = prior.x.hypot(prior.y);
    let forward_sigma = config.forward_sigma.0 + config.forward_sigma.1 * travel;
    let slip_sigma = config.slip_sigma.0 + config.slip_sigma.1 * travel;
    // The share of the turn the wheels' chord points off their first heading (a half on an arc;
    // straight steps take the wheels' chord direction as it is).
    let chord = prior.y.atan2(prior.x.abs().max(1e-9));
    let share = if prior.theta.abs() > 1e-3 {
        chord / prior.theta
    } else {
        0.0
    };
    let straight_offset = if prior.theta.abs() > 1e-3 { 0.0 } else { chord };
    let mut sigma_px = 0.5f64;
    let with_prior = |jtj: &mut Matrix3<f64>, jtr: &mut Vector3<f64>, m: &Pose2, sigma_px: f64| {
        let w = (sigma_px / forward_sigma).powi(2);
        jtj[(0, 0)] += w;
        jtr[0] += w * (m.x - prior.x);
        // Sideways: y = x tan(share theta), the chord `share` of the turn off the first heading.
        let (angle, w) = (
            share * m.theta + straight_offset,
            (sigma_px / slip_sigma).powi(2),
        );
        let r = m.y - m.x * angle.tan();
        let j = Vector3::new(
            -angle.tan(),
            1.0,
            -share * m.x / (angle.cos() * angle.cos()),
        );
        *jtj += w * j * j.transpose();
        *jtr += w * j * r;
    };
    for _round in 0..3 {
        for _ in 0..15 {
            let (r0, columns) = residuals_and_columns(rig, observations, &m, &active);
            let (mut jtj, mut jtr) = normal_equations(&r0, &columns, Some(config.huber_px));
            with_prior(&mut jtj, &mut jtr, &m, sigma_px);
            let step = jtj.try_inverse().ok_or_else(|| too_few(0))? * -jtr;
            m = Pose2::new(m.x + step[0], m.y + step[1], m.theta + step[2]);
            if step.norm() < 1e-9 {
                break;
            }
        }
        let r = residuals(rig, observations, &m, &active);
        let mut norms: Vec<f64> = r.iter().flatten().map(|r| r[0].hypot(r[1])).collect();
        if norms.len() < config.min_inliers {
            return Err(too_few(norms.len()));
        }
        norms.sort_by(f64::total_cmp);
        // The median of a 2D Gaussian residual's length is 1.1774 sigma.
        let sigma = (norms[norms.len() / 2] / 1.1774).max(config.sigma_floor_px);
        sigma_px = sigma;
        let limit = (3.0 * sigma).max(0.5);
        for (on, r) in active.iter_mut().zip(&r) {
            *on = r.is_some_and(|r| r[0].hypot(r[1]) <= limit);
        }
    }
    let (r0, columns) = residuals_and_columns(rig, observations, &m, &active);
    let inliers: Vec<[f64; 2]> = r0.iter().flatten().cloned().collect();
    if inliers.len() < config.min_inliers {
        return Err(too_few(inliers.len()));
    }
    let rms_px = (inliers
        .iter()
        .map(|r| r[0] * r[0] + r[1] * r[1])
        .sum::<f64>()
        / (2 * inliers.len()) as f64)
        .sqrt();
    let sigma = rms_px.max(config.sigma_floor_px);
    let (mut jtj, mut jtr) = normal_equations(&r0, &columns, None);
    with_prior(&mut jtj, &mut jtr, &m, sigma);
    let covariance =
        jtj.try_inverse().ok_or_else(|| too_few(0))? * (sigma * sigma * config.variance_scale);
    Ok(VisualMotion {
        motion: m,
        covariance,
        inliers: inliers.len(),
        tracked: observations.len(),
        rms_px,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::StampedPose;
    use crate::render::{RenderConfig, Renderer};
    use std::path::Path;

    /// The corner response as first written, pixel by pixel.
    fn plain_corner_response(level: &Level) -> Vec<f32> {
        let (w, h) = (level.image.w, level.image.h);
        let s = level.image.data.as_slice();
        let mut gxx = vec![0.0f32; w * h];
        let mut gyy = vec![0.0f32; w * h];
        let mut gxy = vec![0.0f32; w * h];
        for y in 1..h.saturating_sub(1) {
            for x in 1..w - 1 {
                let at = |dx: usize, dy: usize| s[(y + dy - 1) * w + x + dx - 1];
                let gx =
                    (at(2, 0) + 2.0 * at(2, 1) + at(2, 2)) - (at(0, 0) + 2.0 * at(0, 1) + at(0, 2));
                let gy =
                    (at(0, 2) + 2.0 * at(1, 2) + at(2, 2)) - (at(0, 0) + 2.0 * at(1, 0) + at(2, 0));
                let i = y * w + x;
                gxx[i] = gx * gx;
                gyy[i] = gy * gy;
                gxy[i] = gx * gy;
            }
        }
        // 5 x 5 box sums: along rows, then along columns.
        let box5 = |v: &[f32]| -> Vec<f32> {
            let mut rows = vec![0.0f32; w * h];
            for y in 0..h {
                let r = &v[y * w..(y + 1) * w];
                for x in 2..w.saturating_sub(2) {
                    rows[y * w + x] = r[x - 2] + r[x - 1] + r[x] + r[x + 1] + r[x + 2];
                }
            }
            let mut out = vec![0.0f32; w * h];
            for y in 2..h.saturating_sub(2) {
                for x in 0..w {
                    out[y * w + x] = (y - 2..=y + 2).map(|yy| rows[yy * w + x]).sum();
                }
            }
            out
        };
        let (a, b, c) = (box5(&gxx), box5(&gyy), box5(&gxy));
        a.iter()
            .zip(&b)
            .zip(&c)
            .map(|((a, b), c)| 0.5 * (a + b) - (0.25 * (a - b) * (a - b) + c * c).sqrt())
            .collect()
    }

    /// The left picture of the office from (2, 2) m facing 40 degrees, prepared.
    fn office_view() -> VoImage {
        let (world, rig) = office_and_rig();
        let pair = Renderer::new(&rig)
            .render(&world, Pose2::new(2.0, 2.0, 0.7), &RenderConfig::default())
            .unwrap();
        VoImage::new(&pair.left)
    }

    /// Correlations worked a row at a time are the position-by-position ones, whichever way the
    /// positions run, on every level, with and without integral images, and at the borders.
    #[test]
    fn correlations_a_row_at_a_time_are_the_single_ones() {
        let image = office_view();
        for (level, half) in [
            (&image.full, 7),
            (&image.full, 5),
            (&image.half, 4),
            (&image.quarter, 3),
        ] {
            let (w, h) = (level.width(), level.height());
            let reference = patch_at(level, w / 2, h / 2, half).unwrap();
            let forward: Vec<(i64, i64)> = (0..w).map(|x| (x, h / 3)).collect();
            let backward: Vec<(i64, i64)> =
                forward.iter().rev().map(|&(x, _)| (x, h / 2)).collect();
            let grid = square((w / 3, h / 2), 6);
            let corner = square((half, half), 3);
            let scattered = vec![(5, 5), (40, 9), (39, 9), (38, 10), (w - 1, h - 1), (12, 12)];
            for positions in [forward, backward, grid, corner, scattered] {
                let many = level.correlate_at(&reference, &positions, half);
                assert_eq!(many.len(), positions.len());
                for (&(x, y), s) in positions.iter().zip(many) {
                    match level.correlate(&reference, x, y, half) {
                        // The same products, summed in another order in f32.
                        Some(one) => assert!((one - s).abs() < 1e-4, "({x}, {y}): {one} vs {s}"),
                        None => assert_eq!(s, f32::NEG_INFINITY, "({x}, {y})"),
                    }
                }
            }
        }
    }

    #[test]
    fn the_corner_response_is_the_plain_one_exactly() {
        let image = office_view();
        for level in [&image.half, &image.quarter] {
            assert_eq!(corner_response(level), plain_corner_response(level));
        }
    }

    fn office_and_rig() -> (crate::world::World, StereoRig) {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let world = crate::io::load_world(&root.join("samples/office/world.yaml"))
            .unwrap()
            .world;
        let rig = crate::io::load_rig(&root.join("calibration/rigs/default.yaml")).unwrap();
        (world, rig)
    }

    /// Rendered office views, turns on the spot (the start's look-around), steps forward and
    /// curves, each measured from a wheel prior 0.5 degrees and 1 cm off: RMS turn error under
    /// 0.1 degrees (the wheels' over such steps: 0.2-0.7 degrees), none over 0.25, each within
    /// four of its sigmas.
    #[test]
    fn the_turn_between_two_rendered_views_is_measured() {
        let (world, rig) = office_and_rig();
        let renderer = Renderer::new(&rig);
        let render = |pose: Pose2, seed: u64| {
            let pair = renderer
                .render(
                    &world,
                    pose,
                    &RenderConfig {
                        seed,
                        ..RenderConfig::default()
                    },
                )
                .unwrap();
            (VoImage::new(&pair.left), VoImage::new(&pair.right))
        };
        let config = VoConfig::default();
        let mut squares = 0.0;
        let cases = [
            (Pose2::new(2.5, 2.5, 1.2), Pose2::new(2.5, 2.5, 1.55)),
            (Pose2::new(2.5, 2.5, -2.0), Pose2::new(2.5, 2.5, -2.3)),
            (Pose2::new(1.5, 2.0, 0.8), Pose2::new(1.7, 2.2, 0.9)),
            (Pose2::new(1.0, 1.0, 0.0), Pose2::new(1.3, 1.0, 0.0)),
            (Pose2::new(5.0, 6.0, -1.6), Pose2::new(5.0, 5.7, -1.5)),
            (Pose2::new(0.6, 4.0, 1.57), Pose2::new(0.6, 4.3, 1.8)),
        ];
        for (k, (a, b)) in cases.iter().enumerate() {
            let truth = a.between(b);
            let prior = Pose2::new(
                truth.x + 0.01,
                truth.y - 0.005,
                truth.theta + 0.5f64.to_radians(),
            );
            let (al, ar) = render(*a, 2 * k as u64 + 1);
            let (bl, _) = render(*b, 2 * k as u64 + 2);
            let m = relative_motion(&rig, (&al, &ar), &bl, &prior, &config).unwrap();
            let error = (m.motion.theta - truth.theta).to_degrees();
            let sigma = m.covariance[(2, 2)].sqrt().to_degrees();
            assert!(
                error.abs() < 0.25 && error.abs() < 4.0 * sigma,
                "{a:?} -> {b:?}: turn off by {error} degrees (sigma {sigma}, {} inliers)",
                m.inliers
            );
            squares += error * error;
        }
        let rms = (squares / cases.len() as f64).sqrt();
        assert!(rms < 0.1, "RMS turn error {rms} degrees");
    }

    /// Images of another size than the rig's are refused by name, not matched.
    #[test]
    fn images_of_the_wrong_size_are_refused() {
        let (_, rig) = office_and_rig();
        let small = VoImage::new(&image::GrayImage::new(320, 240));
        let err = relative_motion(
            &rig,
            (&small, &small),
            &small,
            &Pose2::default(),
            &VoConfig::default(),
        );
        assert_eq!(
            err.unwrap_err(),
            VoError::WrongSize {
                found: (320, 240),
                expected: (640, 480)
            }
        );
        // A blank view has nothing to match.
        let blank = VoImage::new(&image::GrayImage::from_pixel(640, 480, image::Luma([128])));
        let err = relative_motion(
            &rig,
            (&blank, &blank),
            &blank,
            &Pose2::default(),
            &VoConfig::default(),
        );
        assert!(matches!(err, Err(VoError::TooFewPoints { .. })), "{err:?}");
    }

    /// Frames every 10 cm along a straight drive are paired 30 cm apart; before a 2 m gap (a
    /// stretch with no pictures) the last frame is paired with the one before, however close,
    /// and the chain starts again after the gap.
    #[test]
    fn frames_are_paired_a_little_apart_and_not_across_a_gap() {
        let odometry: Vec<StampedPose> = (0..=100)
            .map(|i| StampedPose {
                t_s: i as f64,
                pose: Pose2::new(0.1 * i as f64, 0.0, 0.0),
            })
            .collect();
        let times: Vec<f64> = (0..=20).chain(40..=50).map(|i| i as f64).collect();
        let pairs = frame_pairs(&times, &odometry, &VoConfig::default());
        let as_times: Vec<(f64, f64)> = pairs.iter().map(|&(a, b)| (times[a], times[b])).collect();
        assert_eq!(
            as_times,
            vec![
                (0.0, 3.0),
                (3.0, 6.0),
                (6.0, 9.0),
                (9.0, 12.0),
                (12.0, 15.0),
                (15.0, 18.0),
                (18.0, 20.0),
                (40.0, 43.0),
                (43.0, 46.0),
                (46.0, 49.0)
            ]
        );
    }
}
