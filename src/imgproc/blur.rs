//! The separable 5-tap binomial blur, `[1 4 6 4 1] / 16` each way (about a Gaussian of sigma
//! 1 px), borders clamped: on any float image, and on an 8-bit image worked in integers (16
//! times the value after the rows, 256 times after the columns, at most 65280), which gives
//! exactly the floating-point sums and lets the compiler use wide vectors.

use super::Plane;
use image::GrayImage;

/// The blur of a float image.
pub fn binomial5(plane: &Plane) -> Plane {
    let (w, h) = (plane.w, plane.h);
    if w == 0 || h == 0 {
        return Plane {
            w,
            h,
            data: Vec::new(),
        };
    }
    let tap = |a: f32, b: f32, c: f32, d: f32, e: f32| (a + e + 4.0 * (b + d) + 6.0 * c) / 16.0;
    let clamp = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
    let mut tmp = vec![0.0f32; w * h];
    for y in 0..h {
        let src = &plane.data[y * w..(y + 1) * w];
        let dst = &mut tmp[y * w..(y + 1) * w];
        let at = |x: usize, d: isize| src[clamp(x as isize + d, w)];
        // The borders clamped, the inside from windows (which vectorises).
        let interior = if w >= 5 { 2..w - 2 } else { 0..0 };
        for x in (0..w).filter(|x| !interior.contains(x)) {
            dst[x] = tap(at(x, -2), at(x, -1), at(x, 0), at(x, 1), at(x, 2));
        }
        for (o, t) in dst[interior].iter_mut().zip(src.windows(5)) {
            *o = tap(t[0], t[1], t[2], t[3], t[4]);
        }
    }
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        let rows: [&[f32]; 5] =
            std::array::from_fn(|k| &tmp[clamp(y as isize + k as isize - 2, h) * w..][..w]);
        let dst = &mut out[y * w..(y + 1) * w];
        for x in 0..w {
            dst[x] = tap(rows[0][x], rows[1][x], rows[2][x], rows[3][x], rows[4][x]);
        }
    }
    Plane { w, h, data: out }
}

/// The blur of an 8-bit image: the same values as [`binomial5`] of [`Plane::from_gray`], in
/// integers.
pub fn binomial5_gray(image: &GrayImage) -> Plane {
    let (w, h) = (image.width() as usize, image.height() as usize);
    if w == 0 || h == 0 {
        // An image file may say it has no columns (a PGM header `P5 0 353 ...`).
        return Plane {
            w,
            h,
            data: Vec::new(),
        };
    }
    let src = image.as_raw();
    let taps = |a: u16, b: u16, c: u16, d: u16, e: u16| a + e + 4 * (b + d) + 6 * c;
    let mut rows = vec![0u16; w * h];
    for (out, row) in rows.chunks_exact_mut(w).zip(src.chunks_exact(w)) {
        let at = |x: usize| row[x.saturating_sub(2).min(w - 1)] as u16;
        // Pixel `x` reads `at(x)` to `at(x + 4)`: source pixels `x - 2` to `x + 2`, clamped.
        let clamped = |x: usize| taps(at(x), at(x + 1), at(x + 2), at(x + 3), at(x + 4));
        let interior = if w >= 5 { 2..w - 2 } else { 0..0 };
        for x in (0..w).filter(|x| !interior.contains(x)) {
            out[x] = clamped(x);
        }
        for (o, t) in out[interior].iter_mut().zip(row.windows(5)) {
            *o = taps(
                t[0] as u16,
                t[1] as u16,
                t[2] as u16,
                t[3] as u16,
                t[4] as u16,
            );
        }
    }
    let mut data: Vec<f32> = Vec::with_capacity(w * h);
    for y in 0..h {
        let row = |k: usize| {
            let yy = (y + k).saturating_sub(2).min(h - 1);
            &rows[yy * w..(yy + 1) * w]
        };
        let (r0, r1, r2, r3, r4) = (row(0), row(1), row(2), row(3), row(4));
        data.extend((0..w).map(|x| taps(r0[x], r1[x], r2[x], r3[x], r4[x]) as f32 * (1.0 / 256.0)));
    }
    Plane { w, h, data }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blur in floating point, tap by tap, as it reads.
    fn tap_by_tap(src: &[u8], w: usize, h: usize) -> Vec<f32> {
        const K: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
        let at = |x: i64, y: i64| {
            src[(y.clamp(0, h as i64 - 1) as usize) * w + x.clamp(0, w as i64 - 1) as usize] as f32
        };
        let rows: Vec<f32> = (0..h as i64)
            .flat_map(|y| (0..w as i64).map(move |x| (y, x)))
            .map(|(y, x)| (0..5).map(|k| K[k] * at(x + k as i64 - 2, y)).sum())
            .collect();
        let row = |x: i64, y: i64| rows[(y.clamp(0, h as i64 - 1) as usize) * w + x as usize];
        (0..h as i64)
            .flat_map(|y| (0..w as i64).map(move |x| (y, x)))
            .map(|(y, x)| (0..5).map(|k| K[k] * row(x, y + k as i64 - 2)).sum())
            .collect()
    }

    /// The integer blur gives the float blurs' values exactly, whatever the size (narrower than
    /// the filter too), and keeps a flat image flat.
    #[test]
    fn the_integer_blur_is_the_floating_point_one_exactly() {
        let mut state = 12345u32;
        for (w, h) in [(1, 1), (2, 3), (4, 4), (5, 7), (17, 9), (64, 48)] {
            let src: Vec<u8> = (0..w * h)
                .map(|i| {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    // Extremes too: all-white rows reach the integer sums' largest value.
                    if i % 7 == 0 {
                        255
                    } else {
                        (state >> 24) as u8
                    }
                })
                .collect();
            let image = GrayImage::from_raw(w as u32, h as u32, src.clone()).unwrap();
            let integer = binomial5_gray(&image);
            assert_eq!(integer, binomial5(&Plane::from_gray(&image)), "{w} x {h}");
            assert_eq!(integer.data, tap_by_tap(&src, w, h), "{w} x {h}");
        }
        let white = GrayImage::from_pixel(30, 20, image::Luma([255]));
        assert!(binomial5_gray(&white).data.iter().all(|&v| v == 255.0));
    }
}
