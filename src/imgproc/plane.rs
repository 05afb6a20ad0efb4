//! A grey image as floats, sampled bilinearly.

use image::GrayImage;

/// A grey image as floats, row-major, with bilinear sampling. Pixel centres sit at integer
/// coordinates (the top-left pixel's centre is (0, 0)).
#[derive(Debug, Clone, PartialEq)]
pub struct Plane {
    /// Width, pixels.
    pub w: usize,
    /// Height, pixels.
    pub h: usize,
    /// The values, row after row (`w * h` of them).
    pub data: Vec<f32>,
}

impl Plane {
    /// An 8-bit grey image as floats (0..255).
    pub fn from_gray(image: &GrayImage) -> Self {
        Self {
            w: image.width() as usize,
            h: image.height() as usize,
            data: image.as_raw().iter().map(|&v| v as f32).collect(),
        }
    }

    /// The value of pixel `(x, y)`.
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.w + x]
    }

    /// Bilinear sample at `(x, y)`, clamped at the border.
    pub fn sample(&self, x: f64, y: f64) -> f32 {
        let x = x.clamp(0.0, (self.w - 1) as f64);
        let y = y.clamp(0.0, (self.h - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.w - 1), (y0 + 1).min(self.h - 1));
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let top = self.at(x0, y0) * (1.0 - fx) + self.at(x1, y0) * fx;
        let bottom = self.at(x0, y1) * (1.0 - fx) + self.at(x1, y1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Half the size, each pixel the mean of a 2 x 2 block (an odd last row or column dropped).
    pub fn halved(&self) -> Self {
        let (w, h) = (self.w, self.h);
        let (hw, hh) = (w / 2, h / 2);
        let mut data = Vec::with_capacity(hw * hh);
        for y in 0..hh {
            let (a, b) = (
                &self.data[2 * y * w..2 * y * w + 2 * hw],
                &self.data[(2 * y + 1) * w..(2 * y + 1) * w + 2 * hw],
            );
            data.extend(
                a.chunks_exact(2)
                    .zip(b.chunks_exact(2))
                    .map(|(a, b)| 0.25 * (a[0] + a[1] + b[0] + b[1])),
            );
        }
        Self { w: hw, h: hh, data }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_interpolate_between_pixel_centres_and_clamp_at_the_border() {
        let plane = Plane {
            w: 2,
            h: 2,
            data: vec![0.0, 10.0, 20.0, 30.0],
        };
        assert_eq!(plane.sample(0.0, 0.0), 0.0);
        assert_eq!(plane.sample(0.5, 0.0), 5.0);
        assert_eq!(plane.sample(0.5, 0.5), 15.0);
        assert_eq!(plane.sample(-3.0, 9.0), 20.0);
    }

    #[test]
    fn halving_averages_two_by_two_blocks() {
        let plane = Plane {
            w: 3,
            h: 2,
            data: vec![0.0, 4.0, 9.0, 8.0, 12.0, 9.0],
        };
        let half = plane.halved();
        assert_eq!((half.w, half.h, half.data), (1, 1, vec![6.0]));
    }
}
