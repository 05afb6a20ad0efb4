//! The pixels an edge of the scene crosses (a wall's ends, foot and top, a tag's cells, the
//! horizon): only those are traced with every sample, the others with one ray.

use super::*;
use crate::camera::Camera;
use nalgebra::{Isometry3, Point2, Point3, Vector3};

/// Pixels of one image marked for all their samples.
pub(super) struct Mask {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) on: Vec<bool>,
}

impl Mask {
    pub(super) fn new(camera: &Camera) -> Self {
        let (w, h) = (camera.width as usize, camera.height as usize);
        Self {
            w,
            h,
            on: vec![false; w * h],
        }
    }

    /// Marks the pixel nearest to a point of an edge and its 8 neighbours: with the edge's
    /// points at most [`EDGE_STEP_PX`] apart, every pixel the edge crosses is marked.
    pub(super) fn mark_around(&mut self, x: f64, y: f64) {
        self.mark_box([x - 1.0, y - 1.0, x + 1.0, y + 1.0]);
    }

    /// Marks the pixels whose square meets `[x0, y0, x1, y1]`.
    pub(super) fn mark_box(&mut self, [x0, y0, x1, y1]: [f64; 4]) {
        let (w, h) = (self.w as f64, self.h as f64);
        if !(x0 <= x1 && y0 <= y1) || x1 < -0.5 || y1 < -0.5 || x0 > w - 0.5 || y0 > h - 0.5 {
            return;
        }
        // Pixel c's square is [c - 0.5, c + 0.5].
        let first = |v: f64| (-fast_floor(0.5 - v)).max(0.0) as usize;
        let last = |v: f64, n: f64| fast_floor(v + 0.5).min(n - 1.0) as usize;
        let (c0, c1) = (first(x0), last(x1, w));
        let (r0, r1) = (first(y0), last(y1, h));
        for row in r0..=r1 {
            self.on[row * self.w + c0..=row * self.w + c1].fill(true);
        }
    }
}

/// A camera for tracing the scene's edges into its image.
pub(super) struct View<'a> {
    pub(super) camera: &'a Camera,
    pub(super) camera_from_world: Isometry3<f64>,
    /// Tangent of the largest angle off the optical axis that any pixel sees, with a margin.
    pub(super) tan_reach: f64,
}

/// Largest distance between the image points of a traced edge, pixels. Any pixel the edge
/// crosses then has its centre within 1 + 0.75 px of the nearest point rounded to a pixel, so
/// within one pixel (both are whole pixels): marking 3 x 3 pixels around each point is enough.
pub(super) const EDGE_STEP_PX: f64 = 1.5;

/// Nearest distance in front of a camera an edge is traced at, metres.
pub(super) const EDGE_NEAR_M: f64 = 0.01;

impl View<'_> {
    /// The sides of the pyramid that holds everything the camera sees, each >= 0 inside.
    pub(super) fn sides(&self, c: &Vector3<f64>) -> [f64; 5] {
        let r = self.tan_reach * c.z;
        [c.z - EDGE_NEAR_M, r - c.x, r + c.x, r - c.y, r + c.y]
    }

    /// Whether a world point is inside that pyramid.
    pub(super) fn holds(&self, p: &Vector3<f64>) -> bool {
        let c = self
            .camera_from_world
            .transform_point(&Point3::from(*p))
            .coords;
        self.sides(&c).iter().all(|&v| v >= 0.0)
    }

    /// Calls `f` with image points of the world segment `p`-`q`, at most [`EDGE_STEP_PX`]
    /// apart, along the part of it the camera can see.
    pub(super) fn trace(&self, p: &Vector3<f64>, q: &Vector3<f64>, f: &mut dyn FnMut(f64, f64)) {
        self.trace_points(p, q, &mut |x, y, _| f(x, y));
    }

    /// [`View::trace`], with each image point's point of the segment in the camera's frame.
    pub(super) fn trace_points(
        &self,
        p: &Vector3<f64>,
        q: &Vector3<f64>,
        f: &mut dyn FnMut(f64, f64, &Vector3<f64>),
    ) {
        let c0 = self
            .camera_from_world
            .transform_point(&Point3::from(*p))
            .coords;
        let c1 = self
            .camera_from_world
            .transform_point(&Point3::from(*q))
            .coords;
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for (v0, v1) in self.sides(&c0).into_iter().zip(self.sides(&c1)) {
            if v0 < 0.0 && v1 < 0.0 {
                return;
            } else if v0 < 0.0 {
                lo = lo.max(v0 / (v0 - v1));
            } else if v1 < 0.0 {
                hi = hi.min(v0 / (v0 - v1));
            }
        }
        if lo > hi {
            return;
        }
        let (a, b) = (c0 + (c1 - c0) * lo, c0 + (c1 - c0) * hi);
        let (Some(pa), Some(pb)) = (self.camera.project(&a), self.camera.project(&b)) else {
            return;
        };
        self.subdivide(&a, &b, pa, pb, 0, f);
        f(pb.x, pb.y, &b);
    }

    /// Emits `pa` and the points between `a` and `b` (not `pb`), halving until they are at
    /// most [`EDGE_STEP_PX`] apart (at least 8 pieces, for the bend of the lens); a piece with
    /// both ends well beyond the same side of the image is not followed further.
    pub(super) fn subdivide(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        pa: Point2<f64>,
        pb: Point2<f64>,
        depth: u32,
        f: &mut dyn FnMut(f64, f64, &Vector3<f64>),
    ) {
        const MIN_DEPTH: u32 = 3;
        const MAX_DEPTH: u32 = 18;
        // Pixels beyond the image's border a piece of 1/8 of an edge or less cannot bend back
        // over.
        const OUTSIDE_PX: f64 = 8.0;
        let (w, h) = (self.camera.width as f64, self.camera.height as f64);
        let outside = (pa.x < -OUTSIDE_PX && pb.x < -OUTSIDE_PX)
            || (pa.y < -OUTSIDE_PX && pb.y < -OUTSIDE_PX)
            || (pa.x > w + OUTSIDE_PX && pb.x > w + OUTSIDE_PX)
            || (pa.y > h + OUTSIDE_PX && pb.y > h + OUTSIDE_PX);
        if depth >= MIN_DEPTH && outside {
            return;
        }
        if depth < MAX_DEPTH && (depth < MIN_DEPTH || (pa - pb).norm() > EDGE_STEP_PX) {
            let m = (a + b) * 0.5;
            if let Some(pm) = self.camera.project(&m) {
                self.subdivide(a, &m, pa, pm, depth + 1, f);
                self.subdivide(&m, b, pm, pb, depth + 1, f);
                return;
            }
        }
        f(pa.x, pa.y, a);
    }
}
