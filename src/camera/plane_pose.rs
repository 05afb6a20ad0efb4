//! The pose of a plane seen by a camera (planar PnP): a calibration board, a tag.

use super::Camera;
use crate::geometry::homography::Homography;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};

/// Pose in a camera of a plane whose points `(x, y)` (metres, z = 0 on the plane) are seen at
/// the given pixels: the homography of the undistorted normalised points, decomposed (planar
/// PnP). Points that do not unproject are left out; `None` when fewer than four remain or the
/// homography is degenerate.
pub fn plane_pose(
    cam: &Camera,
    points: impl Iterator<Item = ([f64; 2], [f64; 2])>,
) -> Option<Isometry3<f64>> {
    let pairs: Vec<_> = points
        .filter_map(|(plane, px)| {
            let n = cam.unproject(&nalgebra::Point2::new(px[0], px[1]))?;
            Some((plane, [n.x, n.y]))
        })
        .collect();
    let h = Homography::from_pairs(&pairs)?.0;
    let scale = 1.0 / h.column(0).norm();
    let mut h = h * scale;
    if h[(2, 2)] < 0.0 {
        h = -h; // the board in front of the camera
    }
    let r1 = h.column(0).into_owned();
    let r2 = h.column(1).into_owned();
    let t = h.column(2).into_owned();
    let r = Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]);
    // Nearest rotation.
    let svd = r.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut rot = u * vt;
    if rot.determinant() < 0.0 {
        rot = -rot;
    }
    Some(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot)),
    ))
}
