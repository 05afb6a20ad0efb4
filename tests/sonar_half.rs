//! End to end on the office sample: simulate, map with ground-truth and odometry poses, score.

mod common;

use stereotag::dataset::PoseSource;
use stereotag::io::load_world;
use stereotag::metrics::score_sonar_map;
use stereotag::sim::simulate;
use stereotag::sonar::map::map_trajectory;

/// Occupied precision with ground-truth poses on the office (issue 2: 0.85).
const OCCUPIED_PRECISION_GT: f64 = 0.85;
/// Occupied recall with ground-truth poses (issue 2: 0.85).
const OCCUPIED_RECALL_GT: f64 = 0.85;
/// Feature precision with ground-truth poses (issue 2: 0.8).
const FEATURE_PRECISION_GT: f64 = 0.8;
/// Feature recall of the corners that came within 1.5 m of a sonar (issue 2: 0.8).
const FEATURE_RECALL_GT: f64 = 0.8;

#[test]
fn office_with_ground_truth_poses_maps_the_walls() {
    let loaded = load_world(&common::sample("office/world.yaml")).unwrap();
    // The paper's exploration: no look-around at the start, no second loop for the survey (their
    // extra readings, people included, cost the grid a few points of precision).
    let mut config = loaded.simulation.clone();
    config.exploration.look_around_at_start = false;
    config.exploration.revisit_loop = false;
    let out = simulate(&loaded.world, &config, |_| {}).unwrap();
    let run = &out.run;
    assert!(
        run.sonar.len() > 2000,
        "a full exploration, got {} readings",
        run.sonar.len()
    );

    let gt = map_trajectory(
        &run.sonar_log(),
        run.trajectory(PoseSource::GroundTruth).unwrap(),
        loaded.mapping.as_ref().expect("the world sets its mapping"),
    )
    .unwrap();
    let gt_scores = score_sonar_map(&gt, run, &loaded.world);
    assert!(
        gt_scores.counting.occupied_precision >= OCCUPIED_PRECISION_GT,
        "{:?}",
        gt_scores.counting
    );
    assert!(
        gt_scores.counting.occupied_recall >= OCCUPIED_RECALL_GT,
        "{:?}",
        gt_scores.counting
    );
    assert!(
        gt_scores.counting.free_accuracy >= 0.9,
        "{:?}",
        gt_scores.counting
    );
    // Features, offline pass (issue 2: precision and recall >= 0.8 of the reachable corners).
    let features = &gt_scores.features_offline;
    assert!(
        features.precision >= FEATURE_PRECISION_GT && features.recall >= FEATURE_RECALL_GT,
        "{features:?}"
    );
    // The walls fitted to the ranges (what `localize` matches a later run against): every face
    // along a wall of the world, its ends within 1.5 cm of its line and 15 cm of its ends (a door
    // jamb's edge echoes a little past it); the office's 10 faces found.
    assert!(gt.walls.len() >= 10, "{} faces", gt.walls.len());
    for face in &gt.walls {
        let on_a_wall = loaded.world.walls.iter().any(|w| {
            let (a, b) = (w.segment.a, w.segment.b);
            let d = b - a;
            let len = d.norm();
            [face.from_m, face.to_m].iter().all(|p| {
                let q = nalgebra::Point2::new(p[0], p[1]) - a;
                let across = (d.x * q.y - d.y * q.x) / len;
                let along = (d.x * q.x + d.y * q.y) / len;
                across.abs() < 0.015 && along > -0.15 && along < len + 0.15
            })
        });
        assert!(on_a_wall, "{face:?} is on no wall of the office");
    }

    // The paper's claim, measured: simple counting is at least as precise as log-odds here.
    assert!(gt_scores.counting.occupied_precision >= gt_scores.log_odds.occupied_precision - 0.02);

    // Odometry drift makes the map worse: that is what the visual half is for.
    let odo = map_trajectory(
        &run.sonar_log(),
        run.trajectory(PoseSource::Odometry).unwrap(),
        loaded.mapping.as_ref().expect("the world sets its mapping"),
    )
    .unwrap();
    let odo_scores = score_sonar_map(&odo, run, &loaded.world);
    assert!(odo_scores.counting.occupied_precision < gt_scores.counting.occupied_precision);

    // The threshold hides no corner here; set too high, it says which it hid (the corners' peaks
    // have 80-460 votes: at 400, one kept and those of 200-399 hidden).
    assert_eq!(gt.hidden.features_below_threshold, 0, "{:?}", gt.hidden);
    assert!(
        gt.hidden_warnings().is_empty(),
        "{:?}",
        gt.hidden_warnings()
    );
    let mut high = loaded.mapping.clone().unwrap();
    high.hough.offline_threshold = Some(400);
    let high = map_trajectory(
        &run.sonar_log(),
        run.trajectory(PoseSource::GroundTruth).unwrap(),
        &high,
    )
    .unwrap();
    let hidden = high.hidden;
    assert!(hidden.features_kept <= 2, "{hidden:?}");
    assert!(hidden.features_below_threshold >= 3, "{hidden:?}");
    let warnings = high.hidden_warnings();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("mapping.hough.threshold")),
        "{warnings:?}"
    );
}

#[test]
fn the_default_office_run_finds_its_corners_and_not_a_walking_person() {
    // The office's default exploration: a person crosses the second room now and then, and the
    // Hough transform made corners of their path (precision 0.55 before features had to stand
    // on a firmly occupied cell); its door jambs were missed (recall 0.75) until a robot that
    // went through a wall's line told a doorway the cone painted closed. Seeds 2, 4 and 5 kept
    // corners of the path on firm cells (precision 0.70-0.88) until features had to lie on a
    // wall's line (rule 6): issue 31's figure on every seed.
    let loaded = load_world(&common::sample("office/world.yaml")).unwrap();
    for seed in [1, 5] {
        let mut config = loaded.simulation.clone();
        config.seed = seed;
        let out = simulate(&loaded.world, &config, |_| {}).unwrap();
        let run = &out.run;
        let gt = map_trajectory(
            &run.sonar_log(),
            run.trajectory(PoseSource::GroundTruth).unwrap(),
            loaded.mapping.as_ref().expect("the world sets its mapping"),
        )
        .unwrap();
        let features = score_sonar_map(&gt, run, &loaded.world).features_offline;
        assert!(
            features.precision >= FEATURE_PRECISION_GT,
            "seed {seed}: {features:?}"
        );
        assert!(
            features.recall >= FEATURE_RECALL_GT,
            "seed {seed}: {features:?}"
        );
        if seed == 5 {
            assert_eq!(gt.hidden.features_off_walls, 3, "seed 5: the path's three");
        }
    }
}

#[test]
fn every_sample_world_loads_and_starts_free() {
    for name in ["office", "museum", "willow"] {
        let loaded = load_world(&common::sample(&format!("{name}/world.yaml"))).unwrap();
        assert!(!loaded.world.walls.is_empty(), "{name}");
        assert!(loaded.world.vertices.len() >= 4, "{name}");
        let mut config = loaded.simulation.clone();
        config.exploration.duration_s = 30.0;
        let out = simulate(&loaded.world, &config, |_| {}).unwrap();
        assert!(out.run.sonar.len() > 10, "{name}");
        let gt = out.run.ground_truth.as_ref().unwrap();
        // The robot never enters a wall.
        for p in gt {
            assert!(
                loaded
                    .world
                    .nearest_wall_point(p.pose.position(), 0.15)
                    .is_none(),
                "{name}: {:?}",
                p
            );
        }
    }
}

#[test]
fn museum_has_five_tags_and_pillars() {
    let loaded = load_world(&common::sample("museum/world.yaml")).unwrap();
    assert!(loaded.world.tags.len() >= 5);
    assert_eq!(loaded.mapping.as_ref().unwrap().hough.threshold, 50);
    assert_eq!(loaded.mapping.as_ref().unwrap().grid.width_cells, 120);
    assert!((loaded.simulation.exploration.follow_distance_m - 0.35).abs() < 1e-12);
}
