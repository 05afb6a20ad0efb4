//! Plane-to-plane homographies: estimated from point pairs (normalised DLT), or solved exactly
//! from a square's four corners as the AprilTag C library does; and points mapped through them.

use nalgebra::{DMatrix, Matrix3, Vector3};

/// A homography `x' ~ H x` between two planes (3 x 3, defined up to scale).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homography(pub Matrix3<f64>);

impl Homography {
    /// The homography that best maps the first point of each pair onto the second (least
    /// squares; the normalised DLT of Hartley and Zisserman, each side's points moved to their
    /// centroid and scaled to a mean distance of √2); `None` with fewer than four pairs or a
    /// degenerate set. Normalised so that `h[(2, 2)] = 1`.
    pub fn from_pairs(pairs: &[([f64; 2], [f64; 2])]) -> Option<Self> {
        if pairs.len() < 4 {
            return None;
        }
        let norm = |pts: Vec<[f64; 2]>| -> Matrix3<f64> {
            let n = pts.len() as f64;
            let (mx, my) = pts
                .iter()
                .fold((0.0, 0.0), |a, p| (a.0 + p[0] / n, a.1 + p[1] / n));
            let d = pts
                .iter()
                .map(|p| (p[0] - mx).hypot(p[1] - my))
                .sum::<f64>()
                / n;
            let s = std::f64::consts::SQRT_2 / d.max(1e-12);
            Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
        };
        let ta = norm(pairs.iter().map(|p| p.0).collect());
        let tb = norm(pairs.iter().map(|p| p.1).collect());
        let mut a = DMatrix::zeros(2 * pairs.len(), 9);
        for (i, (src, dst)) in pairs.iter().enumerate() {
            let s = ta * Vector3::new(src[0], src[1], 1.0);
            let d = tb * Vector3::new(dst[0], dst[1], 1.0);
            let (x, y, u, v) = (s.x / s.z, s.y / s.z, d.x / d.z, d.y / d.z);
            let r0 = [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u];
            let r1 = [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v];
            for j in 0..9 {
                a[(2 * i, j)] = r0[j];
                a[(2 * i + 1, j)] = r1[j];
            }
        }
        let svd = (a.transpose() * &a).symmetric_eigen();
        let k = svd.eigenvalues.imin();
        let h = svd.eigenvectors.column(k);
        let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
        let h = tb.try_inverse()? * hn * ta;
        Some(Self(h / h[(2, 2)]))
    }

    /// The homography from the square with corners (-1, -1), (1, -1), (1, 1), (-1, 1) onto the
    /// four points `p` (in that order), solved exactly as the AprilTag C library solves it
    /// (`homography_compute2`: Gaussian elimination with partial pivoting of the 8 x 9 system),
    /// so that the tag decoder's port samples the bits where the library does; `None` for a
    /// degenerate quad.
    pub fn from_square(p: &[[f64; 2]; 4]) -> Option<Self> {
        let tag = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
        let mut a = [0.0f64; 72];
        for i in 0..4 {
            let (x, y, u, v) = (tag[i][0], tag[i][1], p[i][0], p[i][1]);
            a[18 * i..18 * i + 9].copy_from_slice(&[x, y, 1.0, 0.0, 0.0, 0.0, -x * u, -y * u, u]);
            a[18 * i + 9..18 * i + 18].copy_from_slice(&[
                0.0,
                0.0,
                0.0,
                x,
                y,
                1.0,
                -x * v,
                -y * v,
                v,
            ]);
        }
        for col in 0..8 {
            let (mut max_val, mut max_idx) = (0.0, None);
            for row in col..8 {
                let val = a[row * 9 + col].abs();
                if val > max_val {
                    max_val = val;
                    max_idx = Some(row);
                }
            }
            let max_idx = max_idx?;
            if max_val < 1e-10 {
                return None;
            }
            if max_idx != col {
                for i in col..9 {
                    a.swap(col * 9 + i, max_idx * 9 + i);
                }
            }
            for i in col + 1..8 {
                let f = a[i * 9 + col] / a[col * 9 + col];
                a[i * 9 + col] = 0.0;
                for j in col + 1..9 {
                    a[i * 9 + j] -= f * a[col * 9 + j];
                }
            }
        }
        for col in (0..8).rev() {
            let sum: f64 = (col + 1..8).map(|i| a[col * 9 + i] * a[i * 9 + 8]).sum();
            a[col * 9 + 8] = (a[col * 9 + 8] - sum) / a[col * 9 + col];
        }
        let h = [a[8], a[17], a[26], a[35], a[44], a[53], a[62], a[71], 1.0];
        let det = h[0] * (h[4] * h[8] - h[5] * h[7]) - h[1] * (h[3] * h[8] - h[5] * h[6])
            + h[2] * (h[3] * h[7] - h[4] * h[6]);
        (det != 0.0 && det.is_finite()).then(|| Self(Matrix3::from_row_slice(&h)))
    }

    /// The image of `(x, y)`: `(h00 x + h01 y + h02, h10 x + h11 y + h12) / (h20 x + h21 y +
    /// h22)`.
    pub fn project(&self, x: f64, y: f64) -> [f64; 2] {
        let h = &self.0;
        let xx = h[(0, 0)] * x + h[(0, 1)] * y + h[(0, 2)];
        let yy = h[(1, 0)] * x + h[(1, 1)] * y + h[(1, 2)];
        let zz = h[(2, 0)] * x + h[(2, 1)] * y + h[(2, 2)];
        [xx / zz, yy / zz]
    }
}
