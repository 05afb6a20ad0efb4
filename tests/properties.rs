//! Property tests of the geometry (proptest): SE(2) compositions, camera project / unproject round
//! trips for both lens models, and triangulation of exact points.

use nalgebra::{Isometry3, Point2, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use stereotag::camera::{Camera, Distortion, StereoRig};
use stereotag::geometry::{wrap_angle, Pose2};
use stereotag::visual::stereo::triangulate_point;

/// Round trips must agree to this, pixels.
const ROUND_TRIP_PX: f64 = 1e-6;
/// Poses composed two ways agree to this, metres and radians.
const POSE_EPS: f64 = 1e-9;
/// Exact corners triangulate to within this share of their range.
const TRIANGULATION_REL: f64 = 1e-6;

fn pose() -> impl Strategy<Value = Pose2> {
    (-10.0..10.0f64, -10.0..10.0f64, -3.2..3.2f64).prop_map(|(x, y, t)| Pose2::new(x, y, t))
}

fn close(a: &Pose2, b: &Pose2) -> bool {
    (a.x - b.x).abs() < POSE_EPS
        && (a.y - b.y).abs() < POSE_EPS
        && wrap_angle(a.theta - b.theta).abs() < POSE_EPS
}

fn radtan(k1: f64, k2: f64, p1: f64, p2: f64) -> Camera {
    Camera {
        fx: 460.0,
        fy: 458.0,
        cx: 320.0,
        cy: 240.0,
        distortion: Distortion::Radtan {
            k1,
            k2,
            p1,
            p2,
            k3: 0.0,
        },
        width: 640,
        height: 480,
    }
}

fn equidistant(k1: f64, k2: f64) -> Camera {
    Camera {
        fx: 280.0,
        fy: 280.0,
        cx: 320.0,
        cy: 240.0,
        distortion: Distortion::Equidistant {
            k1,
            k2,
            k3: 0.0,
            k4: 0.0,
        },
        width: 640,
        height: 480,
    }
}

proptest! {
    #[test]
    fn se2_composition_is_associative_and_inverts(a in pose(), b in pose(), c in pose()) {
        prop_assert!(close(&a.compose(&b).compose(&c), &a.compose(&b.compose(&c))));
        prop_assert!(close(&a.compose(&a.inverse()), &Pose2::new(0.0, 0.0, 0.0)));
        prop_assert!(close(&a.compose(&a.between(&b)), &b));
        let p = Point2::new(b.x, b.y);
        let q = a.inverse().transform_point(a.transform_point(p));
        prop_assert!((q - p).norm() < POSE_EPS);
    }

    #[test]
    fn radtan_project_unproject_round_trip(
        k1 in -0.3..0.1f64, k2 in -0.05..0.1f64, p1 in -0.002..0.002f64, p2 in -0.002..0.002f64,
        u in 20.0..620.0f64, v in 20.0..460.0f64,
    ) {
        let cam = radtan(k1, k2, p1, p2);
        let px = Point2::new(u, v);
        if let Some(n) = cam.unproject(&px) {
            let back = cam.project(&Vector3::new(n.x, n.y, 1.0)).unwrap();
            prop_assert!((back - px).norm() < ROUND_TRIP_PX, "{px} -> {n} -> {back}");
        }
    }

    #[test]
    fn equidistant_project_unproject_round_trip(
        k1 in -0.05..0.05f64, k2 in -0.01..0.01f64, u in 20.0..620.0f64, v in 20.0..460.0f64,
    ) {
        let cam = equidistant(k1, k2);
        let px = Point2::new(u, v);
        let n = cam.unproject(&px).unwrap();
        let back = cam.project(&Vector3::new(n.x, n.y, 1.0)).unwrap();
        prop_assert!((back - px).norm() < ROUND_TRIP_PX, "{px} -> {n} -> {back}");
    }

    #[test]
    fn exact_corners_triangulate_exactly(
        x in -1.0..1.0f64, y in -0.7..0.7f64, z in 0.5..6.0f64,
        baseline in 0.05..0.3f64, yaw in -0.02..0.02f64,
    ) {
        let rig = StereoRig {
            left: radtan(-0.08, 0.012, 0.0, 0.0),
            right: radtan(-0.07, 0.01, 0.0005, 0.0),
            right_from_left: Isometry3::from_parts(
                Translation3::new(-baseline, 0.001, 0.0),
                UnitQuaternion::from_euler_angles(0.0, yaw, 0.0),
            ),
            robot_from_left: Isometry3::identity(),
            right_from_left_covariance: None,
        };
        let p = Vector3::new(x, y, z);
        let l = rig.left.project(&p).unwrap();
        let r = rig.right.project(&(rig.right_from_left * nalgebra::Point3::from(p)).coords).unwrap();
        let t = triangulate_point(&rig, &l, &r).unwrap();
        prop_assert!((t - p).norm() < TRIANGULATION_REL * z.max(1.0) * 10.0, "{p} -> {t}");
    }
}
