//! Bouguet rectification of a stereo rig (as OpenCV's `stereoRectify` with `alpha = -1`), and
//! rectified images and pixels.

use super::{Camera, StereoRig};
use crate::imgproc::Plane;
use nalgebra::{Point2, Vector3};

/// A rectified stereo pair (Bouguet's method, as OpenCV's `stereoRectify` with `alpha = -1`
/// and zero disparity at infinity): each camera is turned half of the way towards the other so the
/// image planes become coplanar, then both are turned so the baseline runs along the new x axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Rectification {
    /// `rectified_from_left` rotation (OpenCV `R1`).
    pub left_rotation: nalgebra::Rotation3<f64>,
    /// `rectified_from_right` rotation (OpenCV `R2`).
    pub right_rotation: nalgebra::Rotation3<f64>,
    /// Focal length of both rectified cameras, pixels.
    pub focal_px: f64,
    /// Principal point of both rectified cameras, pixels.
    pub principal_px: [f64; 2],
    /// Signed x offset of the right camera in the rectified frame, metres (negative for a
    /// right camera to the right, as OpenCV's `P2[0][3] / f`).
    pub baseline_x_m: f64,
}

impl Rectification {
    /// OpenCV `P1` (3x4, row-major).
    pub fn left_projection(&self) -> [[f64; 4]; 3] {
        let (f, [cx, cy]) = (self.focal_px, self.principal_px);
        [[f, 0.0, cx, 0.0], [0.0, f, cy, 0.0], [0.0, 0.0, 1.0, 0.0]]
    }

    /// OpenCV `P2` (3x4, row-major).
    pub fn right_projection(&self) -> [[f64; 4]; 3] {
        let (f, [cx, cy]) = (self.focal_px, self.principal_px);
        [
            [f, 0.0, cx, f * self.baseline_x_m],
            [0.0, f, cy, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ]
    }

    /// The rectified image of one camera (same size as the raw one): each rectified pixel's ray
    /// turned back into the camera, projected through its distortion and sampled bilinearly;
    /// black where it falls outside the raw image.
    pub fn rectify_image(
        &self,
        camera: &Camera,
        rotation: &nalgebra::Rotation3<f64>,
        raw: &image::GrayImage,
    ) -> image::GrayImage {
        let (w, h) = raw.dimensions();
        let back = rotation.inverse();
        let plane = Plane::from_gray(raw);
        let inside =
            |x: f64, y: f64| x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64;
        let sample = |x: f64, y: f64| -> Option<u8> {
            inside(x, y).then(|| plane.sample(x, y).round() as u8)
        };
        image::GrayImage::from_fn(w, h, |u, v| {
            let ray = back
                * Vector3::new(
                    (u as f64 - self.principal_px[0]) / self.focal_px,
                    (v as f64 - self.principal_px[1]) / self.focal_px,
                    1.0,
                );
            let value = camera
                .project(&ray)
                .and_then(|q| sample(q.x, q.y))
                .unwrap_or(0);
            image::Luma([value])
        })
    }

    /// Pixel in the rectified image of a raw pixel of one camera; `None` if it cannot be undistorted.
    pub fn rectify_pixel(
        &self,
        camera: &Camera,
        rotation: &nalgebra::Rotation3<f64>,
        px: &Point2<f64>,
    ) -> Option<Point2<f64>> {
        let n = camera.unproject(px)?;
        let r = rotation * Vector3::new(n.x, n.y, 1.0);
        (r.z > 1e-9).then(|| {
            Point2::new(
                self.focal_px * r.x / r.z + self.principal_px[0],
                self.focal_px * r.y / r.z + self.principal_px[1],
            )
        })
    }
}

impl StereoRig {
    /// Bouguet rectification of the rig. The rectified focal length is the smaller of the two
    /// cameras' fy and the principal point their mean, so no image is magnified.
    pub fn rectify(&self) -> Rectification {
        use nalgebra::Rotation3;
        let r = self.right_from_left.rotation.to_rotation_matrix();
        let t = self.right_from_left.translation.vector;
        // Half rotations: the right camera turns back by half, the left forward by half.
        let half = Rotation3::from_scaled_axis(r.scaled_axis() * -0.5);
        let r_left = half.inverse();
        let t_half = half * t;
        // New x axis along the baseline (pointing from right to left camera centre as OpenCV).
        let e1 = t_half.normalize() * if t_half.x > 0.0 { 1.0 } else { -1.0 };
        let e2 = Vector3::new(-e1.y, e1.x, 0.0).normalize();
        let e3 = e1.cross(&e2);
        let align = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_rows(&[
            e1.transpose(),
            e2.transpose(),
            e3.transpose(),
        ]));
        let left_rotation = align * r_left;
        let right_rotation = align * half;
        // In the rectified frames the right camera is the left one moved by `right_rotation * t`,
        // which lies along x by construction.
        let baseline_x_m = (right_rotation * t).x;
        Rectification {
            left_rotation,
            right_rotation,
            focal_px: self.left.fy.min(self.right.fy),
            principal_px: [
                0.5 * (self.left.cx + self.right.cx),
                0.5 * (self.left.cy + self.right.cy),
            ],
            baseline_x_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Distortion;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn rectified_rows_agree_and_disparity_gives_depth() {
        let cam = Camera {
            fx: 460.0,
            fy: 458.0,
            cx: 320.0,
            cy: 240.0,
            distortion: Distortion::Radtan {
                k1: -0.08,
                k2: 0.01,
                p1: 1e-4,
                p2: -2e-4,
                k3: 0.0,
            },
            width: 640,
            height: 480,
        };
        let right = Camera {
            fx: 462.0,
            fy: 461.0,
            cx: 318.0,
            cy: 243.0,
            ..cam
        };
        let rig = StereoRig {
            left: cam,
            right,
            right_from_left: nalgebra::Isometry3::from_parts(
                Translation3::new(-0.12, 0.004, -0.002),
                UnitQuaternion::from_euler_angles(0.01, -0.02, 0.015),
            ),
            robot_from_left: nalgebra::Isometry3::identity(),
            right_from_left_covariance: None,
        };
        let rect = rig.rectify();
        for &(x, y, z) in &[
            (0.3, -0.2, 2.0),
            (-0.5, 0.3, 3.5),
            (0.0, 0.0, 1.0),
            (0.8, 0.5, 4.0),
        ] {
            let p_left = Vector3::new(x, y, z);
            let p_right = rig.right_from_left * nalgebra::Point3::from(p_left);
            let l = rig.left.project(&p_left).unwrap();
            let r = rig.right.project(&p_right.coords).unwrap();
            let lr = rect
                .rectify_pixel(&rig.left, &rect.left_rotation, &l)
                .unwrap();
            let rr = rect
                .rectify_pixel(&rig.right, &rect.right_rotation, &r)
                .unwrap();
            assert!((lr.y - rr.y).abs() < 1e-6, "rows differ: {lr} {rr}");
            // Depth along the rectified axis from disparity: z' = -f * Tx / d.
            let depth = -rect.focal_px * rect.baseline_x_m / (lr.x - rr.x);
            let expected = (rect.left_rotation * p_left).z;
            assert!(
                (depth - expected).abs() < 1e-6 * expected,
                "{depth} vs {expected}"
            );
        }
        assert!((rect.baseline_x_m.abs() - rig.baseline_m()).abs() < 1e-9);
    }
}
