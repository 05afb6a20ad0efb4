//! The C library's decoding stage, in Rust: each quad's bit cells sampled through its
//! homography against a grey model of its border (`quad_decode`), the code matched against the
//! family (any of four rotations, up to the allowed bit errors), and overlapping decodes
//! reconciled. Its arithmetic follows the library's (pixel-corner convention, the library's own
//! bilinear sample and homography), so that it decodes what the library decodes.

use super::quads::{Decoded, Quad};
use crate::geometry::homography::Homography;
use image::GrayImage;
use kornia_apriltag::family::TagFamily as Family;
use nalgebra::Matrix3;

/// Bilinear grey level at `(x, y)` in the pixel-corner convention (`value_for_pixel`).
pub(super) fn value_for_pixel(im: &GrayImage, px: f64, py: f64) -> Option<f64> {
    let (w, h) = (im.width() as i64, im.height() as i64);
    let x1 = (px - 0.5).floor() as i64;
    let x2 = (px - 0.5).ceil() as i64;
    let x = px - 0.5 - x1 as f64;
    let y1 = (py - 0.5).floor() as i64;
    let y2 = (py - 0.5).ceil() as i64;
    let y = py - 0.5 - y1 as f64;
    if x1 < 0 || x2 >= w || y1 < 0 || y2 >= h {
        return None;
    }
    let raw = im.as_raw();
    let v = |xx: i64, yy: i64| raw[(yy * w + xx) as usize] as f64;
    Some(
        v(x1, y1) * (1.0 - x) * (1.0 - y)
            + v(x2, y1) * x * (1.0 - y)
            + v(x1, y2) * (1.0 - x) * y
            + v(x2, y2) * x * y,
    )
}

/// A plane `c0 x + c1 y + c2` fitted to grey levels sampled in the tag frame (`graymodel`).
#[derive(Default)]
pub(super) struct GrayModel {
    pub(super) a: [f64; 9],
    pub(super) b: [f64; 3],
    pub(super) c: [f64; 3],
}

impl GrayModel {
    pub(super) fn add(&mut self, x: f64, y: f64, gray: f64) {
        self.a[0] += x * x;
        self.a[1] += x * y;
        self.a[2] += x;
        self.a[4] += y * y;
        self.a[5] += y;
        self.a[8] += 1.0;
        self.b[0] += x * gray;
        self.b[1] += y * gray;
        self.b[2] += gray;
    }

    /// Cholesky solve of the symmetric normal equations (`mat33_sym_solve`).
    pub(super) fn solve(&mut self) {
        let a = &self.a;
        let mut l = [0.0; 9];
        l[0] = a[0].sqrt();
        l[3] = a[1] / l[0];
        l[6] = a[2] / l[0];
        l[4] = (a[4] - l[3] * l[3]).sqrt();
        l[7] = (a[5] - l[3] * l[6]) / l[4];
        l[8] = (a[8] - l[6] * l[6] - l[7] * l[7]).sqrt();
        let mut m = [0.0; 9];
        m[0] = 1.0 / l[0];
        m[3] = -l[3] * m[0] / l[4];
        m[4] = 1.0 / l[4];
        m[6] = (-l[6] * m[0] - l[7] * m[3]) / l[8];
        m[7] = -l[7] * m[4] / l[8];
        m[8] = 1.0 / l[8];
        let b = &self.b;
        let t = [
            m[0] * b[0],
            m[3] * b[0] + m[4] * b[1],
            m[6] * b[0] + m[7] * b[1] + m[8] * b[2],
        ];
        self.c = [
            m[0] * t[0] + m[3] * t[1] + m[6] * t[2],
            m[4] * t[1] + m[7] * t[2],
            m[8] * t[2],
        ];
    }

    pub(super) fn at(&self, x: f64, y: f64) -> f64 {
        self.c[0] * x + self.c[1] * y + self.c[2]
    }
}

/// The C library's 90-degree rotation of a code (`rotate90`).
pub(super) fn rotate90(w: u64, nbits: usize) -> u64 {
    let (p, l) = if nbits % 4 == 1 {
        (nbits - 1, 1)
    } else {
        (nbits, 0)
    };
    let w = ((w >> l) << (p / 4 + l)) | (w >> (3 * p / 4 + l) << l) | (w & l as u64);
    w & ((1u64 << nbits) - 1)
}

/// Decodes every family that fits the quad's border (`quad_decode_task`).
pub(super) fn decode_quad(
    im: &GrayImage,
    quad: &Quad,
    families: &[Family],
    sharpening: f64,
) -> Vec<Decoded> {
    let Some(h) = Homography::from_square(&quad.p) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for (fi, family) in families.iter().enumerate() {
        if family.reversed_border != quad.reversed_border {
            continue;
        }
        let Some(Code {
            id,
            hamming,
            rotation,
            margin,
        }) = decode(im, family, &h, sharpening)
        else {
            continue;
        };
        let theta = rotation as f64 * std::f64::consts::FRAC_PI_2;
        let (c, s) = (theta.cos(), theta.sin());
        // H * R, R = [c -s 0; s c 0; 0 0 1].
        let hr = Homography(Matrix3::new(
            h.0[(0, 0)] * c + h.0[(0, 1)] * s,
            -h.0[(0, 0)] * s + h.0[(0, 1)] * c,
            h.0[(0, 2)],
            h.0[(1, 0)] * c + h.0[(1, 1)] * s,
            -h.0[(1, 0)] * s + h.0[(1, 1)] * c,
            h.0[(1, 2)],
            h.0[(2, 0)] * c + h.0[(2, 1)] * s,
            -h.0[(2, 0)] * s + h.0[(2, 1)] * c,
            h.0[(2, 2)],
        ));
        out.push(Decoded {
            family: fi,
            id,
            hamming,
            margin,
            corners: [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)]
                .map(|(x, y)| hr.project(x, y)),
            centre: hr.project(0.0, 0.0),
        });
    }
    out
}

/// A code read inside a quad.
pub(super) struct Code {
    /// The tag's id in its family.
    pub(super) id: u32,
    /// Bits corrected.
    pub(super) hamming: u32,
    /// Quarter turns from the quad's corner order to the tag's.
    pub(super) rotation: u32,
    /// The smaller of the mean white and mean black distances from the threshold.
    pub(super) margin: f64,
}

/// Reads the code inside the quad (`quad_decode`): the border's gray models, each bit's value
/// against their mean, sharpened, read as a code and looked up in every rotation.
pub(super) fn decode(
    im: &GrayImage,
    family: &Family,
    h: &Homography,
    sharpening: f64,
) -> Option<Code> {
    let (white, black) = border_models(im, family, h)?;
    let mut values = bit_values(im, family, h, &white, &black);
    sharpen(&mut values, family.total_width, sharpening);
    let (mut rcode, margin) = read_bits(&values, family)?;
    let codes = &family.code_data;
    for rotation in 0..4 {
        if let Some(e) = family.quick_decode.decode(rcode as usize, codes) {
            return Some(Code {
                id: e.id as u32,
                hamming: e.hamming as u32,
                rotation,
                margin,
            });
        }
        rcode = rotate90(rcode, family.nbits);
    }
    None
}

/// The white and black gray models fitted along the border's inside and outside; none when the
/// border's polarity is not the family's.
fn border_models(
    im: &GrayImage,
    family: &Family,
    h: &Homography,
) -> Option<(GrayModel, GrayModel)> {
    let wb = family.width_at_border as f64;
    // (x0, y0, dx, dy, white): the four sides, just outside and just inside the border.
    let patterns: [(f64, f64, f64, f64, bool); 8] = [
        (-0.5, 0.5, 0.0, 1.0, true),
        (0.5, 0.5, 0.0, 1.0, false),
        (wb + 0.5, 0.5, 0.0, 1.0, true),
        (wb - 0.5, 0.5, 0.0, 1.0, false),
        (0.5, -0.5, 1.0, 0.0, true),
        (0.5, 0.5, 1.0, 0.0, false),
        (0.5, wb + 0.5, 1.0, 0.0, true),
        (0.5, wb - 0.5, 1.0, 0.0, false),
    ];
    let (iw, ih) = (im.width() as i64, im.height() as i64);
    let raw = im.as_raw();
    let mut white = GrayModel::default();
    let mut black = GrayModel::default();
    for &(x0, y0, dx, dy, is_white) in &patterns {
        for i in 0..family.width_at_border {
            let tagx = 2.0 * ((x0 + i as f64 * dx) / wb - 0.5);
            let tagy = 2.0 * ((y0 + i as f64 * dy) / wb - 0.5);
            let [px, py] = h.project(tagx, tagy);
            // Truncated, as the C library's (int) cast.
            let (ix, iy) = (px as i64, py as i64);
            if ix < 0 || iy < 0 || ix >= iw || iy >= ih {
                continue;
            }
            let v = raw[(iy * iw + ix) as usize] as f64;
            if is_white {
                white.add(tagx, tagy, v);
            } else {
                black.add(tagx, tagy, v);
            }
        }
    }
    if family.width_at_border > 1 {
        white.solve();
        black.solve();
    } else {
        white.solve();
        black.c = [0.0, 0.0, black.b[2] / 4.0];
    }
    if (white.at(0.0, 0.0) - black.at(0.0, 0.0) < 0.0) != family.reversed_border {
        return None;
    }
    Some((white, black))
}

/// The index of bit cell (`bx`, `by`) in the tag's `total_width` squared cells.
fn cell(family: &Family, bx: i8, by: i8) -> usize {
    let tw = family.total_width as i64;
    let min_coord = (family.width_at_border as i64 - tw) / 2;
    ((by as i64 - min_coord) * tw + bx as i64 - min_coord) as usize
}

/// Each bit's gray value less the threshold the models give at its place, on the tag's cells.
fn bit_values(
    im: &GrayImage,
    family: &Family,
    h: &Homography,
    white: &GrayModel,
    black: &GrayModel,
) -> Vec<f64> {
    let wb = family.width_at_border as f64;
    let tw = family.total_width;
    let mut values = vec![0.0f64; tw * tw];
    for i in 0..family.nbits {
        let (bx, by) = (family.bit_x[i], family.bit_y[i]);
        let tagx = 2.0 * ((bx as f64 + 0.5) / wb - 0.5);
        let tagy = 2.0 * ((by as f64 + 0.5) / wb - 0.5);
        let [px, py] = h.project(tagx, tagy);
        let Some(v) = value_for_pixel(im, px, py) else {
            continue;
        };
        let thresh = (black.at(tagx, tagy) + white.at(tagx, tagy)) / 2.0;
        values[cell(family, bx, by)] = v - thresh;
    }
    values
}

/// Sharpens the `tw` x `tw` cell values with a Laplacian, `sharpening` of it added.
fn sharpen(values: &mut [f64], tw: usize, sharpening: f64) {
    let mut sharpened = vec![0.0f64; tw * tw];
    let kernel = [0.0, -1.0, 0.0, -1.0, 4.0, -1.0, 0.0, -1.0, 0.0];
    let tw = tw as i64;
    for y in 0..tw {
        for x in 0..tw {
            let mut acc = 0.0;
            for i in 0..3i64 {
                for j in 0..3i64 {
                    let (yy, xx) = (y + i - 1, x + j - 1);
                    if yy < 0 || yy >= tw || xx < 0 || xx >= tw {
                        continue;
                    }
                    acc += values[(yy * tw + xx) as usize] * kernel[(i * 3 + j) as usize];
                }
            }
            sharpened[(y * tw + x) as usize] = acc;
        }
    }
    for (v, s) in values.iter_mut().zip(&sharpened) {
        *v += sharpening * s;
    }
}

/// The bits as a code (first bit highest) and the margin; none when the margin is negative.
fn read_bits(values: &[f64], family: &Family) -> Option<(u64, f64)> {
    let (mut black_score, mut white_score) = (0.0f32, 0.0f32);
    let (mut black_count, mut white_count) = (1.0f32, 1.0f32);
    let mut rcode = 0u64;
    for i in 0..family.nbits {
        rcode <<= 1;
        let v = values[cell(family, family.bit_x[i], family.bit_y[i])];
        if v > 0.0 {
            white_score += v as f32;
            white_count += 1.0;
            rcode |= 1;
        } else {
            black_score -= v as f32;
            black_count += 1.0;
        }
    }
    let margin = (white_score / white_count).min(black_score / black_count) as f64;
    // Not `margin >= 0.0`: a NaN margin goes on to the look-up, as in the C library.
    if margin < 0.0 {
        None
    } else {
        Some((rcode, margin))
    }
}

/// Keeps one of any two detections of the same tag whose quads overlap: fewer bits corrected,
/// then the larger margin, then the smaller corner coordinates (the C library's reconcile step).
pub(super) fn reconcile(mut found: Vec<Decoded>) -> Vec<Decoded> {
    let prefer_first = |a: &Decoded, b: &Decoded| -> bool {
        if a.hamming != b.hamming {
            return a.hamming < b.hamming;
        }
        if a.margin != b.margin {
            return a.margin > b.margin;
        }
        for i in 0..4 {
            for k in 0..2 {
                if a.corners[i][k] != b.corners[i][k] {
                    return a.corners[i][k] < b.corners[i][k];
                }
            }
        }
        true
    };
    let mut i0 = 0;
    while i0 < found.len() {
        let mut i1 = i0 + 1;
        let mut removed_i0 = false;
        while i1 < found.len() {
            let (a, b) = (&found[i0], &found[i1]);
            if a.id == b.id && a.family == b.family && quads_overlap(&a.corners, &b.corners) {
                if prefer_first(a, b) {
                    found.remove(i1);
                    continue;
                }
                found.remove(i0);
                removed_i0 = true;
                break;
            }
            i1 += 1;
        }
        if !removed_i0 {
            i0 += 1;
        }
    }
    found
}

/// Whether two convex quads overlap (separating axes).
pub(super) fn quads_overlap(a: &[[f64; 2]; 4], b: &[[f64; 2]; 4]) -> bool {
    let separated_by = |poly: &[[f64; 2]; 4]| {
        (0..4).any(|i| {
            let (p, q) = (poly[i], poly[(i + 1) % 4]);
            let n = [q[1] - p[1], p[0] - q[0]];
            let proj = |s: &[[f64; 2]; 4]| {
                s.iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                        let d = n[0] * v[0] + n[1] * v[1];
                        (lo.min(d), hi.max(d))
                    })
            };
            let (alo, ahi) = proj(a);
            let (blo, bhi) = proj(b);
            ahi < blo || bhi < alo
        })
    };
    !separated_by(a) && !separated_by(b)
}
