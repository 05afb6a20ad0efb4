//! X-corner refinement (as OpenCV's `cornerSubPix`): the point where the image gradients around
//! a chessboard-like corner are all perpendicular to the lines joining them to it, found by
//! iterated least squares with Gaussian weights; shared by the chessboard and the AprilGrid.

use crate::imgproc::Plane;

/// Largest half-width of the sub-pixel window (OpenCV's usual `winSize` 11).
pub(crate) const MAX_REFINE_HALF_WIDTH: i32 = 11;

/// The X-corner near `(x, y)` within a window of `half_width` pixels; `None` when the window
/// holds no corner or the estimate runs off it.
pub(crate) fn refine_x_corner(plane: &Plane, x: f64, y: f64, half_width: i32) -> Option<[f64; 2]> {
    refine_x_corner_where(plane, x, y, half_width, |_, _| true)
}

/// [`refine_x_corner`] from the pixels `keep` accepts alone (by their centres): a corner with
/// other edges close by (a ChArUco corner between its markers) keeps only its own.
pub(crate) fn refine_x_corner_where<F: Fn(f64, f64) -> bool>(
    plane: &Plane,
    x: f64,
    y: f64,
    half_width: i32,
    keep: F,
) -> Option<[f64; 2]> {
    let hw = half_width.max(1);
    let inv = 1.0 / (hw as f64 * hw as f64);
    let (mut cx, mut cy) = (x, y);
    for _ in 0..30 {
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        // Gradients at whole pixels (no interpolation, which would bias the corner towards
        // pixel centres); weights from the distance to the current estimate.
        let (ix, iy) = (cx.round() as i64, cy.round() as i64);
        for qy in iy - hw as i64..=iy + hw as i64 {
            for qx in ix - hw as i64..=ix + hw as i64 {
                if qx < 1 || qy < 1 || qx + 1 >= plane.w as i64 || qy + 1 >= plane.h as i64 {
                    continue;
                }
                if !keep(qx as f64, qy as f64) {
                    continue;
                }
                let (ux, uy) = (qx as usize, qy as usize);
                let gx = 0.5 * (plane.at(ux + 1, uy) - plane.at(ux - 1, uy)) as f64;
                let gy = 0.5 * (plane.at(ux, uy + 1) - plane.at(ux, uy - 1)) as f64;
                let (qx, qy) = (qx as f64, qy as f64);
                let w = (-((qx - cx).powi(2) + (qy - cy).powi(2)) * inv).exp();
                let (gxx, gxy, gyy) = (w * gx * gx, w * gx * gy, w * gy * gy);
                a11 += gxx;
                a12 += gxy;
                a22 += gyy;
                b1 += gxx * qx + gxy * qy;
                b2 += gxy * qx + gyy * qy;
            }
        }
        let det = a11 * a22 - a12 * a12;
        if det.abs() <= 1e-9 * (a11 + a22).powi(2).max(1e-30) {
            return None;
        }
        let nx = (a22 * b1 - a12 * b2) / det;
        let ny = (a11 * b2 - a12 * b1) / det;
        let moved = (nx - cx).hypot(ny - cy);
        (cx, cy) = (nx, ny);
        if (cx - x).hypot(cy - y) > hw as f64 {
            return None;
        }
        if moved < 0.005 {
            break;
        }
    }
    Some([cx, cy])
}

/// The refined corner from `p` if it converges within `max_move_px`.
pub(crate) fn refine_near(
    plane: &Plane,
    p: [f64; 2],
    hw: i32,
    max_move_px: f64,
) -> Option<[f64; 2]> {
    refine_x_corner(plane, p[0], p[1], hw)
        .filter(|q| (q[0] - p[0]).hypot(q[1] - p[1]) <= max_move_px)
}
