//! Each frame as a pyramid (full resolution smoothed, half and quarter), its patches for
//! normalised cross-correlation, and its corners (Shi-Tomasi's response, the strongest of each
//! cell of a grid, at half resolution).

use super::*;
use crate::imgproc::blur::binomial5_gray;
use crate::imgproc::ncc::{dot, zero_mean_unit, LANES};
use crate::imgproc::Plane;
use nalgebra::Point2;

/// One level of an image pyramid, with its integral images (sums of values and of squares, for
/// the mean and spread of any patch in constant time) where many patches are compared.
pub(super) struct Level {
    pub(super) image: Plane,
    pub(super) sums: Option<(Vec<f64>, Vec<f64>)>,
}

impl Level {
    pub(super) fn new(image: Plane, with_sums: bool) -> Self {
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

    pub(super) fn width(&self) -> i64 {
        self.image.w as i64
    }

    pub(super) fn height(&self) -> i64 {
        self.image.h as i64
    }

    pub(super) fn inside(&self, x: i64, y: i64, half: i64) -> bool {
        x - half >= 0 && y - half >= 0 && x + half < self.width() && y + half < self.height()
    }

    /// Sum of values and of squares over the square of half-width `half` at `(x, y)` (inside).
    pub(super) fn box_sums(&self, x: i64, y: i64, half: i64) -> (f64, f64) {
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
    pub(super) fn correlate_at(
        &self,
        reference: &[f32],
        positions: &[(i64, i64)],
        half: i64,
    ) -> Vec<f32> {
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
    pub(super) fn correlate_row(
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
    pub(super) fn box_sums_row(
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
    pub(super) fn correlate(&self, reference: &[f32], x: i64, y: i64, half: i64) -> Option<f32> {
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
pub(super) struct Columns {
    pub(super) run: Option<(i64, i64, usize, i64)>,
    pub(super) sums: Vec<(f64, f64)>,
}

/// The pixels of the square of half-width `r` around `(cx, cy)`, row by row.
pub(super) fn square((cx, cy): (i64, i64), r: i64) -> Vec<(i64, i64)> {
    (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (cx + dx, cy + dy)))
        .collect()
}

/// The vertex offset of a parabola through three samples one step apart, within half a step.
pub(super) fn vertex(l: f32, c: f32, r: f32) -> f32 {
    let den = l - 2.0 * c + r;
    if l.is_finite() && r.is_finite() && den < 0.0 {
        (0.5 * (l - r) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// Pixel coordinates at pyramid level `level` of a full-resolution pixel.
pub(super) fn to_level(p: Point2<f64>, level: u32) -> Point2<f64> {
    let s = (1u32 << level) as f64;
    Point2::new((p.x + 0.5) / s - 0.5, (p.y + 0.5) / s - 0.5)
}

/// Full-resolution pixel of a pixel at pyramid level `level`.
pub(super) fn from_level(p: Point2<f64>, level: u32) -> Point2<f64> {
    let s = (1u32 << level) as f64;
    Point2::new((p.x + 0.5) * s - 0.5, (p.y + 0.5) * s - 0.5)
}

/// One camera image ready for the visual odometry: full resolution smoothed (the sensor noise
/// against a soft texture would blur the matches), half and quarter resolution.
pub struct VoImage {
    pub(super) full: Level,
    pub(super) half: Level,
    pub(super) quarter: Level,
}

impl VoImage {
    /// From an 8-bit grey image. Only the quarter resolution gets integral images: the searches
    /// there cover many positions (a whole epipolar line, the tracking radius); the few at half
    /// and full resolution sum the columns of their own patches (`Level::box_sums_row`).
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

    pub(super) fn size(&self) -> (usize, usize) {
        (self.full.image.w, self.full.image.h)
    }
}

/// The `(2 half + 1)²` pixels around integer `(x, y)`, zero-mean and unit-norm; `None` near a
/// border or on a flat patch.
pub(super) fn patch_at(level: &Level, x: i64, y: i64, half: i64) -> Option<Vec<f32>> {
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
pub(super) fn patch_scaled(
    level: &Level,
    x: i64,
    y: i64,
    half: i64,
    step: f64,
) -> Option<Vec<f32>> {
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
pub(super) fn corner_response(level: &Level) -> Vec<f32> {
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
pub(super) fn sum5(rows: [&[f32]; 5], out: &mut [f32]) {
    let n = out.len();
    let [r0, r1, r2, r3, r4] = rows.map(|r| &r[..n]);
    for x in 0..n {
        out[x] = r0[x] + r1[x] + r2[x] + r3[x] + r4[x];
    }
}

/// The strongest corner of each grid cell, found at half resolution, in full-resolution pixels.
pub(super) fn corners(image: &VoImage, config: &VoConfig) -> Vec<Point2<f64>> {
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
