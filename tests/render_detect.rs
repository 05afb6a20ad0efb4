//! Render → detect → triangulate, compared with the renderer's ground truth.

mod common;

use nalgebra::Vector3;
use stereotag::geometry::Pose2;
use stereotag::io::{load_rig, load_world};
use stereotag::render::{render_pair, RenderConfig};
use stereotag::visual::stereo::{triangulate_tags, StereoConfig};
use stereotag::visual::tags::{CDetector, DetectorConfig, KorniaDetector, TagDetector};

#[test]
fn rendered_pairs_are_deterministic() {
    let w = load_world(&common::sample("office/world.yaml")).unwrap();
    let rig = load_rig(&common::root().join("calibration/rigs/default.yaml")).unwrap();
    let pose = Pose2::new(1.0, 6.3, 2.35);
    let a = render_pair(&w.world, &rig, pose, &RenderConfig::default()).unwrap();
    let b = render_pair(&w.world, &rig, pose, &RenderConfig::default()).unwrap();
    assert_eq!(a.left.as_raw(), b.left.as_raw());
    assert_eq!(a.right.as_raw(), b.right.as_raw());
    assert_eq!(a.tags.len(), 1);
}

/// Every sample world's tags face the room they are in: seen from 1.2 m in front of each (willow's
/// three once faced into their walls, and no survey of it ever saw a tag).
#[test]
fn every_sample_tag_is_seen_from_in_front_of_it() {
    let rig = load_rig(&common::root().join("calibration/rigs/default.yaml")).unwrap();
    for name in ["office", "museum", "willow"] {
        let w = load_world(&common::sample(&format!("{name}/world.yaml"))).unwrap();
        for t in &w.world.tags {
            let (s, c) = t.yaw_rad.sin_cos();
            let pose = Pose2::new(
                t.position_m[0] + 1.2 * c,
                t.position_m[1] + 1.2 * s,
                t.yaw_rad + std::f64::consts::PI,
            );
            let pair = render_pair(&w.world, &rig, pose, &RenderConfig::default()).unwrap();
            assert!(
                pair.tags.iter().any(|seen| seen.id == t.id),
                "{name}: tag {} not seen from {pose:?}",
                t.id
            );
        }
    }
}

#[test]
fn both_backends_find_rendered_tags_where_the_truth_says() {
    let w = load_world(&common::sample("office/world.yaml")).unwrap();
    let rig = load_rig(&common::root().join("calibration/rigs/default.yaml")).unwrap();
    let rect = rig.rectify();
    let config = DetectorConfig {
        decimate: 1.0,
        ..DetectorConfig::default()
    };
    let mut backends: Vec<Box<dyn TagDetector>> = vec![
        Box::new(CDetector::new(config.clone()).unwrap()),
        Box::new(KorniaDetector::new(config).unwrap()),
    ];
    // Poses 0.8 to 2.6 m from tag 0, at angles.
    let mut seen = 0;
    for i in 0..8 {
        let d = 0.8 + 0.25 * i as f64;
        let a = 0.05 + 0.1 * i as f64;
        let (x, y) = (0.25 + d * a.sin(), 7.5 - d * a.cos());
        let theta = (7.5 - y).atan2(0.25 - x);
        let pair = render_pair(
            &w.world,
            &rig,
            Pose2::new(x, y, theta),
            &RenderConfig {
                seed: i,
                ..Default::default()
            },
        )
        .unwrap();
        let Some(truth) = pair.tags.iter().find(|t| t.id == 0) else {
            continue;
        };
        seen += 1;
        for det in backends.iter_mut() {
            let left = det.detect(&pair.left).unwrap();
            let right = det.detect(&pair.right).unwrap();
            let l = left
                .iter()
                .find(|d| d.id == 0)
                .unwrap_or_else(|| panic!("{} missed tag 0 at pose {i}", det.name()));
            for k in 0..4 {
                let e = (l.corners_px[k][0] - truth.left_corners_px[k][0])
                    .hypot(l.corners_px[k][1] - truth.left_corners_px[k][1]);
                assert!(
                    e < 0.6,
                    "{} corner {k} off by {e:.2} px at pose {i}",
                    det.name()
                );
            }
            let (tags, rejected) = triangulate_tags(
                &rig,
                &rect,
                &left,
                &right,
                Some(0.16),
                &StereoConfig::default(),
            );
            assert!(rejected.is_empty(), "{rejected:?}");
            let err = (Vector3::from(tags[0].position_in_left_m)
                - Vector3::from(truth.centre_in_left_m))
            .norm();
            let range = Vector3::from(truth.centre_in_left_m).norm();
            assert!(
                err < 0.01 * range,
                "{}: 3D error {err:.4} m at {range:.2} m",
                det.name()
            );
            // The fitted square faces where the tag faces.
            let yaw = w.world.tags[0].yaw_rad;
            let normal_world = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
            let normal_left = pair.world_from_left.rotation.inverse() * normal_world;
            let angle = Vector3::from(tags[0].normal_in_left)
                .angle(&normal_left)
                .to_degrees();
            // Depth noise of the corners (about 2 cm at 2 m) limits this to several degrees.
            assert!(
                angle < 15.0,
                "{}: normal off by {angle:.1} deg at pose {i}",
                det.name()
            );
            // A wrong corner order would leave residuals of the tag size (0.16 m).
            assert!(tags[0].fit_rms_m < 0.02, "{}", tags[0].fit_rms_m);
        }
    }
    assert!(seen >= 6, "tag 0 in view in {seen} poses");
}

#[test]
fn motion_blur_smears_the_tag_around_its_mid_exposure_pose() {
    let w = load_world(&common::sample("office/world.yaml")).unwrap();
    let rig = load_rig(&common::root().join("calibration/rigs/default.yaml")).unwrap();
    let pose = Pose2::new(1.0, 6.3, 2.35);
    let blurred = |turn: f64| RenderConfig {
        motion: Some(Pose2::new(0.0, 0.0, turn)),
        ..RenderConfig::default()
    };
    let still = render_pair(&w.world, &rig, pose, &RenderConfig::default()).unwrap();
    let mild = render_pair(&w.world, &rig, pose, &blurred(0.005)).unwrap();
    let again = render_pair(&w.world, &rig, pose, &blurred(0.005)).unwrap();
    assert_eq!(mild.left.as_raw(), again.left.as_raw(), "deterministic");
    assert_ne!(mild.left.as_raw(), still.left.as_raw(), "blurred");
    // The truth is the mid-exposure pose's.
    assert_eq!(mild.tags[0].left_corners_px, still.tags[0].left_corners_px);
    // A 2 px smear: still found, corners near the mid-exposure truth.
    let mut det = CDetector::new(DetectorConfig {
        decimate: 1.0,
        ..DetectorConfig::default()
    })
    .unwrap();
    let found = det.detect(&mild.left).unwrap();
    let tag = found.iter().find(|d| d.id == 0).expect("tag 0 found");
    for k in 0..4 {
        let (p, q) = (tag.corners_px[k], mild.tags[0].left_corners_px[k]);
        assert!(
            (p[0] - q[0]).hypot(p[1] - q[1]) < 0.5,
            "corner {k}: {p:?} vs {q:?}"
        );
    }
    // A 37 px smear hides it.
    let strong = render_pair(&w.world, &rig, pose, &blurred(0.08)).unwrap();
    assert!(det.detect(&strong.left).unwrap().is_empty());
}

#[test]
fn the_contrast_floor_skips_texture_and_keeps_tags() {
    let w = load_world(&common::sample("office/world.yaml")).unwrap();
    let rig = load_rig(&common::root().join("calibration/rigs/default.yaml")).unwrap();
    let pair = render_pair(
        &w.world,
        &rig,
        Pose2::new(1.0, 6.3, 2.35),
        &RenderConfig::default(),
    )
    .unwrap();
    for kornia in [false, true] {
        let detect = |min_contrast: u8| {
            let config = DetectorConfig {
                decimate: 1.0,
                min_contrast,
                ..DetectorConfig::default()
            };
            let mut det: Box<dyn TagDetector> = if kornia {
                Box::new(KorniaDetector::new(config).unwrap())
            } else {
                Box::new(CDetector::new(config).unwrap())
            };
            det.detect(&pair.left).unwrap()
        };
        let library_default = detect(5);
        assert_eq!(library_default.len(), 1, "kornia: {kornia}");
        // The survey's floor finds the same tag at the same corners.
        assert_eq!(detect(30), library_default, "kornia: {kornia}");
        // A floor above the tag's own contrast finds nothing: the setting reaches the library.
        assert!(detect(255).is_empty(), "kornia: {kornia}");
    }
}
