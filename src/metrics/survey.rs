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
#[derive(Debug, Clone, PartialEq)]
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

/// A survey's scores against what is known of the truth ([`score_survey`]): the run's ground
/// truth, the world, both or neither.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SurveyScores {
    /// Against the run's ground truth, when it has one.
    pub truth: Option<TruthScores>,
    /// Against the world, when it is known.
    pub world: Option<WorldScores>,
}

/// A survey against its run's ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthScores {
    /// ATE of the odometry, the online and the offline trajectories, metres.
    pub ate_m: TrajectoryErrors,
    /// The visual turns' errors, when any turn was measured.
    pub visual_turns: Option<TurnErrors>,
    /// The raw map's occupied cells against the map the ground-truth poses give (within a cell
    /// of its occupied cells), when the two grids are alike.
    pub raw_vs_ground_truth_map: Option<MapScore>,
    /// The corrected map's, the same way.
    pub corrected_vs_ground_truth_map: Option<MapScore>,
}

/// ATE of a survey's trajectories, metres: `None` where a trajectory does not overlap the truth.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrajectoryErrors {
    /// The odometry.
    pub odometry: Option<f64>,
    /// The online filter.
    pub online: Option<f64>,
    /// The offline pass.
    pub offline: Option<f64>,
}

/// The visual turns against the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnErrors {
    /// RMS error, degrees.
    pub rms_deg: f64,
    /// Mean normalised squared error under each turn's stated sigma.
    pub nees: f64,
}

/// A survey against the world.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldScores {
    /// The raw map (made on the odometry): its grids and features.
    pub raw: SonarScores,
    /// The map made on the online filter's poses.
    pub online_map: MapScore,
    /// The map made on the offline pass's poses.
    pub corrected_map: MapScore,
    /// The map made on the ground-truth poses, when the run has them.
    pub ground_truth_map: Option<MapScore>,
    /// The corrected map's offline features.
    pub features_corrected: FeatureScore,
    /// The landmarks against their tags.
    pub landmarks: LandmarkErrors,
    /// Tags the world holds.
    pub planned: usize,
    /// Landmarks the survey holds.
    pub surveyed: usize,
}

/// The landmarks against their tags in the world.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LandmarkErrors {
    /// Median and largest position error, metres (`None` without a landmark of the world's).
    pub median_m: Option<f64>,
    /// See `median_m`.
    pub max_m: Option<f64>,
    /// Median and largest angle between a landmark's orientation and its tag's, degrees.
    pub median_orientation_deg: Option<f64>,
    /// See `median_orientation_deg`.
    pub max_orientation_deg: Option<f64>,
    /// Diagnostics, with the ground truth: the median position error after the best rigid
    /// alignment of the offline trajectory with the truth (the survey's anchoring taken out)...
    pub median_aligned_m: Option<f64>,
    /// ... and the offline ATE after it.
    pub ate_offline_aligned_m: Option<f64>,
}

impl SurveyScores {
    /// The scores as `report.json` metrics (DESIGN.md keys plus ours); empty with neither truth
    /// nor world.
    pub fn metrics(&self) -> BTreeMap<String, f64> {
        fn put(m: &mut BTreeMap<String, f64>, key: &str, value: Option<f64>) {
            if let Some(v) = value {
                m.insert(key.to_string(), v);
            }
        }
        let mut m = BTreeMap::new();
        if let Some(t) = &self.truth {
            put(&mut m, "ate_m.odometry", t.ate_m.odometry);
            put(&mut m, "ate_m.online", t.ate_m.online);
            put(&mut m, "ate_m.offline", t.ate_m.offline);
            put(
                &mut m,
                "visual.turn_error_rms_deg",
                t.visual_turns.map(|v| v.rms_deg),
            );
            put(&mut m, "visual.turn_nees", t.visual_turns.map(|v| v.nees));
            for (name, score) in [
                ("map_raw", t.raw_vs_ground_truth_map),
                ("map_corrected", t.corrected_vs_ground_truth_map),
            ] {
                let key = |what: &str| format!("{name}.vs_ground_truth_map.occupied_{what}");
                put(
                    &mut m,
                    &key("precision"),
                    score.map(|s| s.occupied_precision),
                );
                put(&mut m, &key("recall"), score.map(|s| s.occupied_recall));
            }
        }
        let Some(w) = &self.world else {
            return m;
        };
        m.extend(w.raw.metrics());
        for (name, score) in [
            ("map_online", Some(w.online_map)),
            ("map_corrected", Some(w.corrected_map)),
            ("map_ground_truth", w.ground_truth_map),
        ] {
            put(
                &mut m,
                &format!("{name}.occupied_precision"),
                score.map(|s| s.occupied_precision),
            );
            put(
                &mut m,
                &format!("{name}.occupied_recall"),
                score.map(|s| s.occupied_recall),
            );
        }
        let f = &w.features_corrected;
        put(&mut m, "features_corrected.precision", Some(f.precision));
        put(&mut m, "features_corrected.recall", Some(f.recall));
        put(&mut m, "features_corrected.count", Some(f.features as f64));
        let l = &w.landmarks;
        put(&mut m, "landmarks.median_error_m", l.median_m);
        put(&mut m, "landmarks.max_error_m", l.max_m);
        put(
            &mut m,
            "landmarks.median_orientation_error_deg",
            l.median_orientation_deg,
        );
        put(
            &mut m,
            "landmarks.max_orientation_error_deg",
            l.max_orientation_deg,
        );
        put(
            &mut m,
            "landmarks.median_error_aligned_m",
            l.median_aligned_m,
        );
        put(&mut m, "ate_m.offline_aligned", l.ate_offline_aligned_m);
        put(&mut m, "landmarks.count", Some(w.surveyed as f64));
        put(&mut m, "landmarks.planned", Some(w.planned as f64));
        m
    }
}

/// Scores a survey against what is known of the truth: with the run's ground truth, ATE of each
/// trajectory, the visual turns' errors, and the raw and corrected maps against the map the
/// ground-truth poses give (their occupied cells within a cell of its occupied cells); with the
/// world, the sonar scores of the raw map, the online and corrected maps and the ground-truth-pose
/// map, the corrected map's features and the landmark errors (also after aligning the whole
/// survey). Neither without them.
pub fn score_survey(
    survey: &Survey,
    run: &RunDataset,
    world: Option<&World>,
    mapping: &MappingConfig,
) -> Result<SurveyScores, GridError> {
    let mut scores = SurveyScores::default();
    let gt_map = match &run.ground_truth {
        Some(truth) => {
            // Only its counting grid: not the Hough passes and walls a full map builds.
            let gt_map = counting_map_along(&run.sonar_log(), truth, mapping)?;
            let reference: Vec<bool> = (0..gt_map.occupancy.len())
                .map(|i| gt_map.is_occupied(i))
                .collect();
            let against = |map: &crate::sonar::grid::OccupancyMap| {
                (map.geometry == gt_map.geometry).then(|| score_map_against(map, &reference))
            };
            scores.truth = Some(TruthScores {
                ate_m: TrajectoryErrors {
                    odometry: ate_m(&run.odometry, truth),
                    online: ate_m(&survey.online.trajectory, truth),
                    offline: ate_m(&survey.offline.trajectory, truth),
                },
                visual_turns: visual_turn_errors(&survey.visual, truth),
                raw_vs_ground_truth_map: against(&survey.raw.counting),
                corrected_vs_ground_truth_map: against(&survey.corrected.counting),
            });
            Some(gt_map)
        }
        None => None,
    };
    let Some(world) = world else {
        return Ok(scores);
    };
    scores.world = Some(WorldScores {
        raw: score_sonar_map(&survey.raw, run, world),
        online_map: score_map(&survey.online_map, world),
        corrected_map: score_map(&survey.corrected.counting, world),
        ground_truth_map: gt_map.as_ref().map(|map| score_map(map, world)),
        features_corrected: score_features(
            &survey.corrected.features_offline,
            world,
            &sonar_positions(run),
        ),
        landmarks: landmark_errors_of(survey, run, world),
        planned: world.tags.len(),
        surveyed: survey.landmarks.len(),
    });
    Ok(scores)
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

/// The landmarks' median and largest errors; and, as diagnostics, the median and the offline
/// ATE after the best rigid alignment of the offline trajectory with the truth.
fn landmark_errors_of(survey: &Survey, run: &RunDataset, world: &World) -> LandmarkErrors {
    let errors = landmark_errors(survey, world, Pose2::new(0.0, 0.0, 0.0));
    let turned = orientation_errors_deg(survey, world);
    let mut out = LandmarkErrors {
        median_m: median_sorted(&errors),
        max_m: errors.last().copied(),
        median_orientation_deg: median_sorted(&turned),
        max_orientation_deg: turned.last().copied(),
        ..LandmarkErrors::default()
    };
    let Some(truth) = run.ground_truth.as_deref() else {
        return out;
    };
    let Some(align) = align_se2(&survey.offline.trajectory, truth) else {
        return out;
    };
    out.median_aligned_m = median_sorted(&landmark_errors(survey, world, align));
    let aligned = crate::geometry::transformed(align, &survey.offline.trajectory);
    out.ate_offline_aligned_m = ate_m(&aligned, truth);
    out
}

/// The visual turns' RMS error against the truth and their NEES; `None` without a turn.
fn visual_turn_errors(
    visual: &[crate::visual::vo::VisualTurn],
    truth: &[StampedPose],
) -> Option<TurnErrors> {
    let errors: Vec<(f64, f64)> = visual
        .iter()
        .filter_map(|v| {
            let a = crate::geometry::pose_within(truth, v.from_t_s)?;
            let b = crate::geometry::pose_within(truth, v.to_t_s)?;
            let e = crate::geometry::wrap_angle(v.turn_rad - (b.theta - a.theta));
            Some((e, v.sigma_rad))
        })
        .collect();
    if errors.is_empty() {
        return None;
    }
    let n = errors.len() as f64;
    let rms = (errors.iter().map(|(e, _)| e * e).sum::<f64>() / n).sqrt();
    let nees = errors.iter().map(|(e, s)| (e / s).powi(2)).sum::<f64>() / n;
    Some(TurnErrors {
        rms_deg: rms.to_degrees(),
        nees,
    })
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
    m.insert(
        "offline.sonar_wall_directions".into(),
        survey.offline.sonar_wall_directions as f64,
    );
    if let Some([before, after]) = survey.offline.sonar_agreement {
        m.insert("offline.sonar_agreement_odometry".into(), before);
        m.insert("offline.sonar_agreement_corrected".into(), after);
        m.insert(
            "offline.sonar_wheel_distance".into(),
            f64::from(u8::from(survey.offline.sonar_wheel_distance)),
        );
        m.insert(
            "offline.sonar_turns_from_walls".into(),
            f64::from(u8::from(survey.offline.sonar_turns_from_walls)),
        );
    }
    if let Some(s) = survey.offline.sonar_silent_start {
        m.insert("offline.sonar_silent_start_s".into(), s.duration_s);
        m.insert("offline.sonar_silent_start_m".into(), s.path_m);
        m.insert(
            "offline.sonar_silent_start_heading_sigma_deg".into(),
            s.heading_sigma_rad.to_degrees(),
        );
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
