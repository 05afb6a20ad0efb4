//! Planar geometry: SE(2) poses, segments, ray casting.
//!
//! Poses are `world_from_robot` transforms: a point `p_robot` maps to
//! `p_world = R(theta) * p_robot + (x, y)`. Angles are radians, wrapped to (-pi, pi].

pub mod homography;
mod trajectory;

pub use trajectory::{
    distance_travelled, odometry_jumps, path_length_m, pose_at, pose_within, transformed,
    OdometryJump, StampedPose, JUMP_MIN_M, JUMP_SPEED_MPS,
};

use nalgebra::{Point2, Vector2};
use serde::{Deserialize, Serialize};

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let mut w = a % std::f64::consts::TAU;
    if w <= -std::f64::consts::PI {
        w += std::f64::consts::TAU;
    } else if w > std::f64::consts::PI {
        w -= std::f64::consts::TAU;
    }
    w
}

/// A planar rigid transform (SE(2)): translation in metres, rotation in radians.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    /// Translation along x, metres.
    pub x: f64,
    /// Translation along y, metres.
    pub y: f64,
    /// Rotation, radians.
    pub theta: f64,
}

impl Pose2 {
    /// A pose from its parts; the angle is wrapped.
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Self {
            x,
            y,
            theta: wrap_angle(theta),
        }
    }

    /// The translation as a point.
    pub fn position(&self) -> Point2<f64> {
        Point2::new(self.x, self.y)
    }

    /// `a_from_c = a_from_b * b_from_c`.
    pub fn compose(&self, b_from_c: &Pose2) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            self.x + c * b_from_c.x - s * b_from_c.y,
            self.y + s * b_from_c.x + c * b_from_c.y,
            self.theta + b_from_c.theta,
        )
    }

    /// The inverse transform (`b_from_a` from `a_from_b`).
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            -c * self.x - s * self.y,
            s * self.x - c * self.y,
            -self.theta,
        )
    }

    /// `self^-1 * other`: `other` expressed in this pose's frame.
    pub fn between(&self, other: &Pose2) -> Pose2 {
        self.inverse().compose(other)
    }

    /// Maps a point from this pose's frame into the parent frame.
    pub fn transform_point(&self, p: Point2<f64>) -> Point2<f64> {
        let (s, c) = self.theta.sin_cos();
        Point2::new(self.x + c * p.x - s * p.y, self.y + s * p.x + c * p.y)
    }

    /// Unit vector of the heading.
    pub fn heading(&self) -> Vector2<f64> {
        Vector2::new(self.theta.cos(), self.theta.sin())
    }

    /// Linear interpolation between two poses (shortest way round for the angle).
    pub fn lerp(&self, other: &Pose2, f: f64) -> Pose2 {
        Pose2::new(
            self.x + (other.x - self.x) * f,
            self.y + (other.y - self.y) * f,
            self.theta + wrap_angle(other.theta - self.theta) * f,
        )
    }
}

/// A line segment between two points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// First end point.
    pub a: Point2<f64>,
    /// Second end point.
    pub b: Point2<f64>,
}

/// Where a ray met something.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// Distance along the ray, metres.
    pub range_m: f64,
    /// Unit normal of the surface at the hit, facing the ray's origin.
    pub normal: Vector2<f64>,
}

impl Segment {
    /// A segment from its end points.
    pub fn new(a: Point2<f64>, b: Point2<f64>) -> Self {
        Self { a, b }
    }

    /// Length in metres.
    pub fn length(&self) -> f64 {
        (self.b - self.a).norm()
    }

    /// The closest point of the segment to `p`.
    pub fn closest_point(&self, p: Point2<f64>) -> Point2<f64> {
        let d = self.b - self.a;
        let len2 = d.norm_squared();
        if len2 <= f64::EPSILON {
            return self.a;
        }
        let t = ((p - self.a).dot(&d) / len2).clamp(0.0, 1.0);
        self.a + d * t
    }

    /// Distance from `p` to the segment.
    pub fn distance_to(&self, p: Point2<f64>) -> f64 {
        (p - self.closest_point(p)).norm()
    }

    /// Intersection of the ray `origin + s * dir` (`dir` unit, `s` in `(0, max_m]`) with the segment.
    pub fn ray_hit(&self, origin: Point2<f64>, dir: Vector2<f64>, max_m: f64) -> Option<RayHit> {
        let e = self.b - self.a;
        let denom = dir.x * e.y - dir.y * e.x;
        if denom.abs() < 1e-12 {
            return None;
        }
        let w = self.a - origin;
        let s = (w.x * e.y - w.y * e.x) / denom;
        let u = (w.x * dir.y - w.y * dir.x) / denom;
        if s <= 1e-9 || s > max_m || !(0.0..=1.0).contains(&u) {
            return None;
        }
        let len = e.norm();
        let mut normal = Vector2::new(-e.y / len, e.x / len);
        if normal.dot(&dir) > 0.0 {
            normal = -normal;
        }
        Some(RayHit { range_m: s, normal })
    }
}

/// Intersection of a ray with a circle (the people of the world).
pub fn ray_hit_circle(
    origin: Point2<f64>,
    dir: Vector2<f64>,
    centre: Point2<f64>,
    radius_m: f64,
    max_m: f64,
) -> Option<RayHit> {
    let oc = origin - centre;
    let b = oc.dot(&dir);
    let c = oc.norm_squared() - radius_m * radius_m;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let s = -b - disc.sqrt();
    if s <= 1e-9 || s > max_m {
        return None;
    }
    let hit = origin + dir * s;
    Some(RayHit {
        range_m: s,
        normal: (hit - centre) / radius_m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_inverse_is_identity() {
        let a = Pose2::new(1.0, -2.0, 0.7);
        let i = a.compose(&a.inverse());
        assert!(i.x.abs() < 1e-12 && i.y.abs() < 1e-12 && i.theta.abs() < 1e-12);
    }

    #[test]
    fn ray_meets_wall_at_right_range_and_normal() {
        let s = Segment::new(Point2::new(2.0, -1.0), Point2::new(2.0, 1.0));
        let h = s
            .ray_hit(Point2::origin(), Vector2::new(1.0, 0.0), 5.0)
            .unwrap();
        assert!((h.range_m - 2.0).abs() < 1e-12);
        assert!((h.normal - Vector2::new(-1.0, 0.0)).norm() < 1e-12);
        assert!(s
            .ray_hit(Point2::origin(), Vector2::new(-1.0, 0.0), 5.0)
            .is_none());
    }

    #[test]
    fn wrap_angle_stays_in_range() {
        for k in -20..20 {
            let a = wrap_angle(k as f64 * 0.9);
            assert!(a > -std::f64::consts::PI && a <= std::f64::consts::PI);
        }
    }
}
