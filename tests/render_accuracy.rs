//! Issue 3's accuracy figures on rendered pairs: 200 pairs of the office with a tag 0.5 to 4 m
//! away and at least 20 px wide, detected by the C backend (decimate 1) with our sub-pixel edge
//! fit, and triangulated.

mod common;

use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use stereotag::geometry::Pose2;
use stereotag::io::{load_rig, load_world};
use stereotag::render::{visible_tags, RenderConfig, Renderer};
use stereotag::visual::stereo::{detect_pair, triangulate_tags, StereoConfig};
use stereotag::visual::tags::{CDetector, DetectorConfig, KorniaDetector, TagDetector};

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Decimate 1, and our sub-pixel edge fit on top (the default); NO_SUBPIXEL=1 measures the
/// backend's corners alone.
fn settings() -> DetectorConfig {
    DetectorConfig {
        decimate: 1.0,
        subpixel: std::env::var("NO_SUBPIXEL").is_err(),
        ..DetectorConfig::default()
    }
}

#[test]
fn two_hundred_rendered_pairs() {
    measure(&mut CDetector::new(settings()).unwrap());
}

#[test]
fn two_hundred_rendered_pairs_kornia_backend() {
    measure(&mut KorniaDetector::new(settings()).unwrap());
}

fn measure(det: &mut dyn TagDetector) {
    let w = load_world(&common::sample("office/world.yaml")).unwrap();
    let rig = load_rig(&common::root().join("calibration/rigs/default.yaml")).unwrap();
    let rect = rig.rectify();
    let renderer = Renderer::new(&rig);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2026);
    let (mut pairs, mut found, mut wrong_ids) = (0, 0, 0);
    let (mut corner_err, mut rel_err, mut nees, mut disp_err, mut depth_err) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut stereo_normal_err, mut pnp_normal_err) = (Vec::new(), Vec::new());
    let mut attempts = 0;
    while pairs < 200 && attempts < 5000 {
        attempts += 1;
        let tag = &w.world.tags[rng.random_range(0..w.world.tags.len())];
        let range = rng.random_range(0.5..4.0);
        let bearing = tag.yaw_rad + rng.random_range(-1.0..1.0);
        let (x, y) = (
            tag.position_m[0] + range * bearing.cos(),
            tag.position_m[1] + range * bearing.sin(),
        );
        if w.world
            .nearest_wall_point(nalgebra::Point2::new(x, y), 0.25)
            .is_some()
            || !(0.0..7.0).contains(&x)
            || !(0.0..7.5).contains(&y)
        {
            continue;
        }
        let theta =
            (tag.position_m[1] - y).atan2(tag.position_m[0] - x) + rng.random_range(-0.4..0.4);
        let pose = Pose2::new(x, y, theta);
        let config = RenderConfig {
            seed: attempts,
            ..RenderConfig::default()
        };
        let Ok(truths) = visible_tags(&w.world, &rig, pose, &config) else {
            continue;
        };
        let wide = |c: &[[f64; 2]; 4]| {
            (0..4)
                .map(|i| (c[i][0] - c[(i + 1) % 4][0]).hypot(c[i][1] - c[(i + 1) % 4][1]))
                .fold(f64::INFINITY, f64::min)
                >= 20.0
        };
        let Some(truth) = truths
            .iter()
            .find(|t| t.id == tag.id && wide(&t.left_corners_px) && wide(&t.right_corners_px))
        else {
            continue;
        };
        let d = Vector3::from(truth.centre_in_left_m).norm();
        if !(0.5..=4.0).contains(&d) {
            continue;
        }
        pairs += 1;
        let pair = renderer.render(&w.world, pose, &config).unwrap();
        // BLUR=SIGMA blurs both images by a Gaussian first: a robustness measurement (README);
        // issue 3's figures are asserted on the sharp images only.
        let blur: f32 = std::env::var("BLUR")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(0.0);
        let (bl, br) = if blur > 0.0 {
            (
                image::imageops::blur(&pair.left, blur),
                image::imageops::blur(&pair.right, blur),
            )
        } else {
            (pair.left.clone(), pair.right.clone())
        };
        let (l, r) = detect_pair(det, &bl, &br).unwrap();
        let visible: Vec<u32> = pair.tags.iter().map(|t| t.id).collect();
        wrong_ids += l
            .iter()
            .chain(&r)
            .filter(|d| !visible.contains(&d.id))
            .count();
        let (tags, _) = triangulate_tags(
            &rig,
            &rect,
            &l,
            &r,
            Some(tag.size_m),
            &StereoConfig::default(),
        );
        let Some(t) = tags.iter().find(|t| t.id == tag.id) else {
            continue;
        };
        found += 1;
        for k in 0..4 {
            corner_err.push(
                (t.corners_px[k][0] - truth.left_corners_px[k][0])
                    .hypot(t.corners_px[k][1] - truth.left_corners_px[k][1]),
            );
            corner_err.push(
                (t.right_corners_px[k][0] - truth.right_corners_px[k][0])
                    .hypot(t.right_corners_px[k][1] - truth.right_corners_px[k][1]),
            );
            let dt = truth.left_corners_px[k][0] - truth.right_corners_px[k][0];
            let dm = t.corners_px[k][0] - t.right_corners_px[k][0];
            disp_err.push(dm - dt);
        }
        // Facing: stereo against one camera's PnP, both against the truth.
        let left_from_world = pair.world_from_left.inverse();
        let true_corners = truth
            .corners_world_m
            .map(|c| left_from_world * nalgebra::Point3::from(c))
            .map(|p| p.coords);
        let true_normal = stereotag::visual::stereo::fit_square(&true_corners, tag.size_m).normal;
        let angle = |n: &Vector3<f64>| n.angle(&true_normal).to_degrees();
        stereo_normal_err.push(angle(&Vector3::from(t.normal_in_left)));
        if let Some(v) = stereotag::visual::stereo::pnp_square(&rig.left, &t.corners_px, tag.size_m)
        {
            pnp_normal_err.push(angle(&-(v.rotation * Vector3::z())));
        }
        let e = Vector3::from(t.position_in_left_m) - Vector3::from(truth.centre_in_left_m);
        rel_err.push(e.norm() / d);
        depth_err.push((e.z, truth.centre_in_left_m[2]));
        let cov = Matrix3::from_fn(|i, j| t.covariance_m2[i][j]);
        if let Some(info) = cov.try_inverse() {
            nees.push((e.transpose() * info * e)[0] / 3.0);
        }
    }
    let recall = found as f64 / pairs as f64;
    let n_disp = disp_err.len() as f64;
    let sigma_d = (disp_err.iter().map(|e| e * e).sum::<f64>() / n_disp).sqrt();
    let mean_nees = nees.iter().sum::<f64>() / nees.len() as f64;
    // The stereo depth bound sigma_z = z² sigma_d / (f b) of one point, with sigma_d measured
    // above: the tag centre's depth error against it (RMS of the ratio).
    let fb = rig.left.fx * rig.right_from_left.translation.vector.norm();
    let bound_ratio = (depth_err
        .iter()
        .map(|(ez, z)| (ez / (z * z * sigma_d / fb)).powi(2))
        .sum::<f64>()
        / depth_err.len() as f64)
        .sqrt();
    let (med_c, p95_c) = (
        percentile(&mut corner_err.clone(), 0.5),
        percentile(&mut corner_err, 0.95),
    );
    let med_rel = percentile(&mut rel_err, 0.5);
    eprintln!(
        "{}: {pairs} pairs: recall {recall:.3}, wrong ids {wrong_ids}, corner error median {med_c:.3} px p95 {p95_c:.3} px, \
         3D error median {:.3}% of range, sigma_d {sigma_d:.3} px, centre depth error / stereo bound \
         (RMS) {bound_ratio:.2}, mean NEES {mean_nees:.2}",
        det.name(),
        100.0 * med_rel
    );
    let (n_s, n_p) = (stereo_normal_err.len(), pnp_normal_err.len());
    let (s_med, s_p95, s_max) = (
        percentile(&mut stereo_normal_err, 0.5),
        percentile(&mut stereo_normal_err, 0.95),
        percentile(&mut stereo_normal_err, 1.0),
    );
    let (p_med, p_p95, p_max) = (
        percentile(&mut pnp_normal_err, 0.5),
        percentile(&mut pnp_normal_err, 0.95),
        percentile(&mut pnp_normal_err, 1.0),
    );
    eprintln!(
        "tag facing error, degrees (median / p95 / max): stereo {s_med:.2} / {s_p95:.2} / {s_max:.2} \
         ({n_s} tags), left camera PnP alone {p_med:.2} / {p_p95:.2} / {p_max:.2} ({n_p} tags)"
    );
    assert_eq!(pairs, 200);
    if std::env::var("BLUR").is_ok() {
        return;
    }
    assert_eq!(wrong_ids, 0);
    // Issue 3: recall >= 0.99, corner error median <= 0.1 px and 95th percentile <= 0.3 px,
    // centre 3D error median <= 0.5% of range and within 1.5x the stereo bound, NEES in
    // [0.5, 2]. Measured: see README.
    assert!(recall >= 0.99, "recall {recall}");
    assert!((0.5..=2.0).contains(&mean_nees), "mean NEES {mean_nees}");
    if std::env::var("NO_SUBPIXEL").is_err() {
        assert!(
            med_c <= 0.1 && p95_c <= 0.3,
            "corner errors {med_c} {p95_c}"
        );
    }
    assert!(
        bound_ratio <= 1.5,
        "depth error / stereo bound {bound_ratio}"
    );
    assert!(med_rel <= 0.005, "3D median {med_rel}");
}
