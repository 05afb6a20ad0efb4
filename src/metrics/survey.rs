//! A survey's figures: with the world and ground truth, map and feature scores, ATE of each
//! trajectory, landmark errors and visual-turn errors; without them, what was fused and found.

use crate::dataset::RunDataset;
use crate::fusion::Survey;
use crate::geometry::{Pose2, StampedPose};
use crate::metrics::map::{score_features, score_map, score_map_against, FeatureScore, MapScore};
use crate::metrics::{align_se2, ate_m};
use crate::sonar::grid::GridError;
use crate::sonar::map::{counting_map_along, MappingConfig, SonarMap};
use crate::world::World;
use std::collections::BTreeMap;

/// Where the sonars were at each reading: on the ground truth when the run has it, else on the
/// odometry.
fn sonar_positions(run: &RunDataset) -> Vec<nalgebra::Point2<f64>> {
    let trajectory = run.ground_truth.as_deref().unwrap_or(&run.odometry);
    run.placed_readings(trajectory)
        .iter()
        .map(|r| r.world_from_sensor.position())
        .collect()
}

/// Scores of a [`SonarMap`] against a world.
#[derive(Debug, Clone)]
pub struct SonarScores {
    /// Counting grid.
    pub counting: MapScore,
    /// Log-odds grid.
    pub log_odds: MapScore,
    /// Online features.
    pub features_online: FeatureScore,
    /// Offline features.
    pub features_offline: FeatureScore,
}

/// Scores a survey against what is known of the truth: with the run's ground truth, ATE of each
/// trajectory, the visual turns' errors, and the raw and corrected maps against the map the
/// ground-truth poses give (their occupied cells within a cell of its occupied cells); with the
/// world, the sonar scores of the raw map, the online and corrected maps and the ground-truth-pose
/// map, the corrected map's features (`features_corrected.*`) and the landmark position errors
/// (also after aligning the whole survey). Empty with neither.
pub fn score_survey(
    survey: &Survey,
    run: &RunDataset,
    world: Option<&World>,
    mapping: &MappingConfig,
) -> Result<BTreeMap<String, f64>, GridError> {
    let mut m = BTreeMap::new();
    let gt_map = match &run.ground_truth {
        Some(truth) => {
            // Only its counting grid: not the Hough passes and walls a full map builds.
            let gt_map = counting_map_along(&run.sonar_log(), truth, mapping)?;
            for (key, estimate) in [
                ("ate_m.odometry", &run.odometry),
                ("ate_m.online", &survey.online.trajectory),
                ("ate_m.offline", &survey.offline.trajectory),
            ] {
                if let Some(ate) = ate_m(estimate, truth) {
                    m.insert(key.into(), ate);
                }
            }
            m.extend(visual_turn_metrics(&survey.visual, truth));
            let reference: Vec<bool> = (0..gt_map.occupancy.len())
                .map(|i| gt_map.is_occupied(i))
                .collect();
            for (name, map) in [
                ("map_raw", &survey.raw.counting),
                ("map_corrected", &survey.corrected.counting),
            ] {
                if map.geometry == gt_map.geometry {
                    let score = score_map_against(map, &reference);
                    m.insert(
                        format!("{name}.vs_ground_truth_map.occupied_precision"),
                        score.occupied_precision,
                    );
                    m.insert(
                        format!("{name}.vs_ground_truth_map.occupied_recall"),
                        score.occupied_recall,
                    );
                }
            }
            Some(gt_map)
        }
        None => None,
    };
    let Some(world) = world else {
        return Ok(m);
    };
    m.extend(score_sonar_map(&survey.raw, run, world).metrics());
    let mut occupied = |name: &str, map: &crate::sonar::grid::OccupancyMap| {
        let score = score_map(map, world);
        m.insert(
            format!("{name}.occupied_precision"),
            score.occupied_precision,
        );
        m.insert(format!("{name}.occupied_recall"), score.occupied_recall);
    };
    occupied("map_online", &survey.online_map);
    occupied("map_corrected", &survey.corrected.counting);
    if let Some(gt_map) = &gt_map {
        occupied("map_ground_truth", gt_map);
    }
    let corrected = score_features(
        &survey.corrected.features_offline,
        world,
        &sonar_positions(run),
    );
    m.insert("features_corrected.precision".into(), corrected.precision);
    m.insert("features_corrected.recall".into(), corrected.recall);
    m.insert("features_corrected.count".into(), corrected.features as f64);
    m.extend(landmark_metrics(survey, run, world));
    m.insert("landmarks.count".into(), survey.landmarks.len() as f64);
    m.insert("landmarks.planned".into(), world.tags.len() as f64);
    Ok(m)
}

/// `error` of each landmark against its tag in the world, sorted.
fn sorted_errors(
    survey: &Survey,
    world: &World,
    error: impl Fn(&crate::fusion::Landmark, &crate::world::Tag) -> f64,
) -> Vec<f64> {
    let mut errors: Vec<f64> = survey
        .landmarks
        .iter()
        .filter_map(|l| Some(error(l, world.tag(l.family, l.id)?)))
        .collect();
    errors.sort_by(f64::total_cmp);
    errors
}

/// The distance of each landmark from its tag in the world, after moving the survey by
/// `align`, sorted.
fn landmark_errors(survey: &Survey, world: &World, align: Pose2) -> Vec<f64> {
    sorted_errors(survey, world, |l, tag| {
        let p = align.transform_point(nalgebra::Point2::new(l.position_m[0], l.position_m[1]));
        (nalgebra::Vector3::new(p.x, p.y, l.position_m[2])
            - nalgebra::Vector3::from(tag.position_m))
        .norm()
    })
}

/// The angle between each landmark's orientation and its tag's in the world, degrees, sorted.
fn orientation_errors_deg(survey: &Survey, world: &World) -> Vec<f64> {
    sorted_errors(survey, world, |l, tag| {
        l.rotation().angle_to(&tag.rotation()).to_degrees()
    })
}

/// The landmarks' median and largest error; and, as diagnostics, the median and the offline
/// ATE after the best rigid alignment of the offline trajectory with the truth (the shift and
/// turn of the whole survey, its anchoring, taken out).
fn landmark_metrics(survey: &Survey, run: &RunDataset, world: &World) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    let errors = landmark_errors(survey, world, Pose2::new(0.0, 0.0, 0.0));
    if let Some(median) = median_sorted(&errors) {
        m.insert("landmarks.median_error_m".into(), median);
        m.insert("landmarks.max_error_m".into(), errors[errors.len() - 1]);
    }
    let turned = orientation_errors_deg(survey, world);
    if let Some(median) = median_sorted(&turned) {
        m.insert("landmarks.median_orientation_error_deg".into(), median);
        m.insert(
            "landmarks.max_orientation_error_deg".into(),
            turned[turned.len() - 1],
        );
    }
    let Some(truth) = run.ground_truth.as_deref() else {
        return m;
    };
    let Some(align) = align_se2(&survey.offline.trajectory, truth) else {
        return m;
    };
    if let Some(median) = median_sorted(&landmark_errors(survey, world, align)) {
        m.insert("landmarks.median_error_aligned_m".into(), median);
    }
    let aligned: Vec<StampedPose> = survey
        .offline
        .trajectory
        .iter()
        .map(|p| StampedPose {
            t_s: p.t_s,
            pose: align.compose(&p.pose),
        })
        .collect();
    if let Some(ate) = ate_m(&aligned, truth) {
        m.insert("ate_m.offline_aligned".into(), ate);
    }
    m
}

/// The visual turns' RMS error against the truth, degrees, and their NEES.
fn visual_turn_metrics(
    visual: &[crate::visual::vo::VisualTurn],
    truth: &[StampedPose],
) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    let errors: Vec<(f64, f64)> = visual
        .iter()
        .filter_map(|v| {
            let a = crate::geometry::pose_at(truth, v.from_t_s)?;
            let b = crate::geometry::pose_at(truth, v.to_t_s)?;
            let e = crate::geometry::wrap_angle(v.turn_rad - (b.theta - a.theta));
            Some((e, v.sigma_rad))
        })
        .collect();
    if !errors.is_empty() {
        let n = errors.len() as f64;
        let rms = (errors.iter().map(|(e, _)| e * e).sum::<f64>() / n).sqrt();
        let nees = errors.iter().map(|(e, s)| (e / s).powi(2)).sum::<f64>() / n;
        m.insert("visual.turn_error_rms_deg".into(), rms.to_degrees());
        m.insert("visual.turn_nees".into(), nees);
    }
    m
}

/// Median of a sorted list.
fn median_sorted(v: &[f64]) -> Option<f64> {
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
    }
}

/// Survey figures that need no ground truth.
pub fn survey_metrics(survey: &Survey, sightings: usize) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    m.insert("sightings.total".into(), sightings as f64);
    m.insert("echoes".into(), survey.raw.echoes as f64);
    m.extend(survey.raw.coverage_metrics());
    m.insert(
        "readings.unplaced".into(),
        survey.raw.readings_unplaced as f64,
    );
    m.insert(
        "sightings.fused".into(),
        survey.online.accepted.len() as f64,
    );
    m.insert(
        "sightings.gated_out".into(),
        survey.online.rejected.len() as f64,
    );
    m.insert("conflicts".into(), survey.online.conflicts.len() as f64);
    m.insert(
        "online.resolves".into(),
        survey.online.resolves.len() as f64,
    );
    m.insert("online.loop_tests".into(), survey.online.loop_tests as f64);
    m.insert(
        "sightings.loop_closing".into(),
        survey
            .online
            .resolves
            .iter()
            .map(|r| r.loop_sightings)
            .sum::<usize>() as f64,
    );
    m.insert("landmarks.count".into(), survey.landmarks.len() as f64);
    m.insert(
        "landmarks.matched_corners".into(),
        survey
            .landmarks
            .iter()
            .filter(|l| l.matched_corner.is_some())
            .count() as f64,
    );
    m.insert("visual.turns".into(), survey.visual.len() as f64);
    m.insert(
        "visual.fused_online".into(),
        survey.online.visual_fused as f64,
    );
    m.insert(
        "visual.gated_out_online".into(),
        survey.online.visual_rejected as f64,
    );
    m.insert("offline.keyframes".into(), survey.offline.keyframes as f64);
    m.insert("offline.factors".into(), survey.offline.factors as f64);
    m.insert(
        "offline.wall_ranges".into(),
        survey.offline.wall_ranges as f64,
    );
    m.insert(
        "offline.sonar_matches".into(),
        survey.offline.sonar_matches as f64,
    );
    if let Some([before, after]) = survey.offline.sonar_agreement {
        m.insert("offline.sonar_agreement_odometry".into(), before);
        m.insert("offline.sonar_agreement_corrected".into(), after);
    }
    if let Some(c) = survey.offline.odometry_calibration {
        m.insert(
            "offline.odometry_turn_scale_error".into(),
            c.turn_scale_error,
        );
        m.insert(
            "offline.odometry_heading_drift_rad_per_m".into(),
            c.heading_drift_rad_per_m,
        );
        m.insert(
            "offline.odometry_distance_scale_error".into(),
            c.distance_scale_error,
        );
    }
    if let Some(n) = &survey.offline.noise {
        let groups = [
            ("odometry_translation", n.odometry_translation),
            ("odometry_turning", n.odometry_turning),
            ("odometry_drift", n.odometry_drift),
            ("sightings", n.sightings),
            ("visual_turns", n.turns),
        ];
        for ((name, scale), redundancy) in groups.into_iter().zip(n.redundancy) {
            if let Some(scale) = scale {
                m.insert(format!("offline.noise_scale.{name}"), scale);
            }
            m.insert(format!("offline.noise_redundancy.{name}"), redundancy);
        }
    }
    let o = &survey.offline;
    if o.kept == crate::fusion::OfflineKept::Nothing {
        // Nothing was solved: nothing is claimed.
        m.insert("offline.nothing_to_correct".into(), 1.0);
        return m;
    }
    m.insert(
        "offline.converged".into(),
        f64::from(u8::from(survey.offline.converged)),
    );
    m.insert(
        "offline.kept_solution".into(),
        f64::from(u8::from(o.kept == crate::fusion::OfflineKept::Solution)),
    );
    m.insert("offline.cost_start".into(), o.cost[0]);
    m.insert("offline.cost".into(), o.cost[1]);
    m.insert("offline.sightings".into(), o.sightings as f64);
    m.insert(
        "offline.sightings_consistent_start".into(),
        o.sightings_consistent[0] as f64,
    );
    m.insert(
        "offline.sightings_consistent".into(),
        o.sightings_consistent[1] as f64,
    );
    m
}

/// Scores a sonar map against the world. Sonar positions come from the ground truth when the run
/// has it (else from odometry).
pub fn score_sonar_map(map: &SonarMap, run: &RunDataset, world: &World) -> SonarScores {
    let positions = sonar_positions(run);
    SonarScores {
        counting: score_map(&map.counting, world),
        log_odds: score_map(&map.log_odds, world),
        features_online: score_features(&map.features_online, world, &positions),
        features_offline: score_features(&map.features_offline, world, &positions),
    }
}

impl SonarScores {
    /// The scores as `report.json` metrics (DESIGN.md keys plus ours).
    pub fn metrics(&self) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let mut put = |k: &str, v: f64| {
            m.insert(k.to_string(), v);
        };
        put("map.occupied_precision", self.counting.occupied_precision);
        put("map.occupied_recall", self.counting.occupied_recall);
        put("map.free_accuracy", self.counting.free_accuracy);
        put(
            "map_log_odds.occupied_precision",
            self.log_odds.occupied_precision,
        );
        put(
            "map_log_odds.occupied_recall",
            self.log_odds.occupied_recall,
        );
        put("map_log_odds.free_accuracy", self.log_odds.free_accuracy);
        put("features.precision", self.features_offline.precision);
        put("features.recall", self.features_offline.recall);
        put("features.count", self.features_offline.features as f64);
        put(
            "features.reachable_corners",
            self.features_offline.reachable_corners as f64,
        );
        put("features_online.precision", self.features_online.precision);
        put("features_online.recall", self.features_online.recall);
        put(
            "features_online.count",
            self.features_online.features as f64,
        );
        m
    }
}
