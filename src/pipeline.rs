//! The stages end to end. The sonar half: a run's readings → counting and log-odds grids → Hough
//! features → scores against the world when it is known. The survey: stereo pairs → tag sightings
//! → fusion with odometry and corners → corrected trajectory and map → scores. Takes and returns values; [`crate::io`] does files.

use crate::camera::{Rectification, StereoRig};
use crate::fusion::{
    align_se2, associate, ate_m, hold_tail_to_walls, run_offline, run_online_calibrated,
    FuseConfig, Landmark, OdometryCalibration, OfflineResult, OnlineResult, SonarInput,
    TagSighting,
};
use crate::geometry::Pose2;
use crate::sonar::grid::{
    CountingGrid, GridError, LogOddsGrid, MappingConfig, OccupancyGrid, OccupancyMap,
};
use crate::sonar::hough::{classify_features, features_offline, features_online, Accumulator, Feature};
use crate::dataset::{PoseSource, RunDataset, StampedPose};
use crate::metrics::map::{score_features, score_map, FeatureScore, MapScore};
use crate::sonar::PlacedReading;
use crate::visual::stereo::{detect_pair, triangulate_tags, Rejection, StereoConfig};
use crate::visual::tags::{TagDetector, TagError};
use crate::visual::vo::VisualTurn;
use crate::sonar::walls::{map_walls, WallSegment};
use crate::world::World;
use std::collections::BTreeMap;
use std::time::Instant;

/// Errors of the mapping pipeline.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// Bad grid settings.
    #[error(transparent)]
    Grid(#[from] GridError),
    /// The run lacks the trajectory asked for.
    #[error("the run has no ground_truth.csv; use --poses odometry")]
    NoGroundTruth,
}

/// Everything the sonar half produces.
#[derive(Debug, Clone)]
pub struct SonarMap {
    /// The paper's counting grid.
    pub counting: OccupancyMap,
    /// The log-odds grid over the same readings.
    pub log_odds: OccupancyMap,
    /// Features from the online windows.
    pub features_online: Vec<Feature>,
    /// Features from the offline pass over the whole run.
    pub features_offline: Vec<Feature>,
    /// The offline accumulator.
    pub accumulator: Accumulator,
    /// The straight walls, fitted to the ranges (what a later run localises against).
    pub walls: Vec<WallSegment>,
    /// Readings used (with an echo or not).
    pub readings: usize,
    /// Readings with an echo.
    pub echoes: usize,
    /// Echoes whose point (the sensor's position plus the range along its axis) lies outside the
    /// grid: what the grid loses when it does not cover the run.
    pub echoes_off_grid: usize,
    /// Seconds per stage.
    pub timings_s: BTreeMap<String, f64>,
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

/// Builds the grids and features of a run along the chosen trajectory.
pub fn map_run(
    run: &RunDataset,
    poses: PoseSource,
    config: &MappingConfig,
) -> Result<SonarMap, PipelineError> {
    let trajectory = run.trajectory(poses).ok_or(PipelineError::NoGroundTruth)?;
    map_trajectory(run, trajectory, config)
}

/// Builds the grids and features of a run with the readings placed along `trajectory` (odometry,
/// ground truth or a corrected estimate).
pub fn map_trajectory(
    run: &RunDataset,
    trajectory: &[StampedPose],
    config: &MappingConfig,
) -> Result<SonarMap, PipelineError> {
    let layout = &run.meta.robot.sonar;
    let mut timings_s = BTreeMap::new();
    let start = Instant::now();
    let readings = timed("place_readings", &mut timings_s, || {
        run.placed_readings(trajectory)
    });
    let counting = timed("grid_counting", &mut timings_s, || {
        counting_map(run, &readings, config)
    })?;
    let (echoes, echoes_off_grid) = readings
        .iter()
        .filter_map(|r| {
            let range = r
                .range_m
                .filter(|x| x.is_finite() && *x < layout.max_range_m)?;
            let p = r.world_from_sensor;
            let (x, y) = (p.x + range * p.theta.cos(), p.y + range * p.theta.sin());
            Some(counting.geometry.cell_of(x, y).is_none())
        })
        .fold((0, 0), |(n, off), is_off| (n + 1, off + is_off as usize));

    // The log-odds grid, the two Hough passes and the walls read the same placed readings and
    // counting grid and nothing of each other: the online Hough pass (the longest) runs on one
    // core, the rest on the other. Each stage's time is its own, taken while the others run.
    let half = 0.5 * layout.cone_rad;
    let ((online, online_times), rest) = rayon::join(
        || {
            let mut times = BTreeMap::new();
            let online = timed("hough_online", &mut times, || {
                let mut online =
                    features_online(&readings, trajectory, half, &counting, &config.hough);
                classify_features(&mut online, &counting);
                online
            });
            (online, times)
        },
        || -> Result<_, PipelineError> {
            let mut times = BTreeMap::new();
            let log_odds = timed("grid_log_odds", &mut times, || {
                let mut grid =
                    LogOddsGrid::new(config.grid.clone(), layout.cone_rad, layout.max_range_m)?;
                grid.insert_all(&readings);
                Ok::<_, PipelineError>(grid.map())
            })?;
            let (offline, accumulator) = timed("hough_offline", &mut times, || {
                let (mut offline, accumulator) =
                    features_offline(&readings, half, &counting, &config.hough);
                classify_features(&mut offline, &counting);
                (offline, accumulator)
            });
            let walls = timed("walls", &mut times, || {
                map_walls(&readings, half, layout.max_range_m, &counting)
            });
            Ok((log_odds, offline, accumulator, walls, times))
        },
    );
    let (log_odds, offline, accumulator, walls, rest_times) = rest?;
    timings_s.extend(online_times);
    timings_s.extend(rest_times);
    timings_s.insert("total".into(), start.elapsed().as_secs_f64());

    Ok(SonarMap {
        counting,
        log_odds,
        features_online: online,
        features_offline: offline,
        accumulator,
        walls,
        readings: readings.len(),
        echoes,
        echoes_off_grid,
        timings_s,
    })
}

/// Runs `f`, noting its wall-clock time under `name`.
fn timed<T>(name: &str, timings: &mut BTreeMap<String, f64>, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    timings.insert(name.to_owned(), t.elapsed().as_secs_f64());
    out
}

/// Detects and triangulates the tags of one stereo pair and moves them into the robot frame.
/// `known_size_m` gives a tag's planned edge length (for the size check) when it is known.
#[allow(clippy::too_many_arguments)]
pub fn sightings_from_pair(
    detector: &mut dyn TagDetector,
    rig: &StereoRig,
    rect: &Rectification,
    left: &image::GrayImage,
    right: &image::GrayImage,
    (t_s, frame): (f64, usize),
    known_size_m: &dyn Fn(&str, u32) -> Option<f64>,
    config: &StereoConfig,
) -> Result<(Vec<TagSighting>, Vec<Rejection>), TagError> {
    let (in_left, in_right) = detect_pair(detector, left, right)?;
    let (tags, mut rejected) = triangulate_tags(rig, rect, &in_left, &in_right, None, config);
    let mut sightings = Vec::new();
    for tag in tags {
        if let Some(known) = known_size_m(tag.family, tag.id) {
            if ((tag.size_m - known) / known).abs() > config.max_size_error {
                rejected.push(Rejection {
                    id: tag.id,
                    reason: format!(
                        "triangulated size {:.3} m, expected {known:.3} m",
                        tag.size_m
                    ),
                });
                continue;
            }
        }
        sightings.push(TagSighting::from_stereo(
            t_s,
            frame,
            &tag,
            &rig.robot_from_left,
        ));
    }
    Ok((sightings, rejected))
}

/// Everything a survey produces.
#[derive(Debug, Clone)]
pub struct Survey {
    /// The grid and features with odometry poses (what the robot had while it ran).
    pub raw: SonarMap,
    /// The online filter.
    pub online: OnlineResult,
    /// The counting grid with the online filter's poses: the map the robot had while it ran.
    pub online_map: OccupancyMap,
    /// The offline pose graph.
    pub offline: OfflineResult,
    /// The grid and features rebuilt from the offline trajectory.
    pub corrected: SonarMap,
    /// The surveyed landmarks (offline positions, matched with the corrected map's corners).
    pub landmarks: Vec<Landmark>,
    /// The turns the cameras measured between pictures, as fused.
    pub visual: Vec<VisualTurn>,
    /// Seconds per stage.
    pub timings_s: BTreeMap<String, f64>,
}

/// The raw map: the grid and features with the odometry's poses. It needs no pictures, so a
/// survey builds it while the tags are being detected.
pub fn raw_map(run: &RunDataset, mapping: &MappingConfig) -> Result<SonarMap, PipelineError> {
    map_trajectory(run, &run.odometry, mapping)
}

/// Runs the survey over a run, its [`raw_map`], its tag sightings and the turns its cameras
/// measured: online filter (predicting with `calibration` until it finds the run's own, when an
/// earlier survey of the robot gives one), offline pass, and the map rebuilt from the corrected
/// poses.
pub fn survey(
    run: &RunDataset,
    raw: SonarMap,
    (sightings, visual): (&[TagSighting], &[VisualTurn]),
    mapping: &MappingConfig,
    fuse: &FuseConfig,
    calibration: Option<OdometryCalibration>,
) -> Result<Survey, PipelineError> {
    let mut timings_s = BTreeMap::new();
    let times = &mut timings_s;
    let online = timed("fuse_online", times, || {
        run_online_calibrated(
            &run.odometry,
            visual,
            sightings,
            &raw.features_online,
            fuse,
            calibration,
        )
    });
    let online_map = timed("map_online", times, || {
        counting_map_along(run, &online.trajectory, mapping)
    })?;
    let mut offline = timed("fuse_offline", times, || {
        run_offline(&run.odometry, visual, sightings, &online, fuse)
    });
    if fuse.hold_tail_to_walls {
        timed("fuse_tail", times, || {
            hold_tail(run, sightings, visual, &online, &mut offline, mapping, fuse)
        })?;
    }
    let corrected = timed("map_corrected", times, || {
        map_trajectory(run, &offline.trajectory, mapping)
    })?;
    let landmarks = offline
        .landmarks
        .iter()
        .map(|l| {
            let mut l = l.clone();
            let xy = nalgebra::Vector2::new(l.position_m[0], l.position_m[1]);
            let c = &l.covariance_m2;
            let cov = nalgebra::Matrix2::new(c[0][0], c[0][1], c[1][0], c[1][1]);
            l.matched_corner = associate(&xy, &cov, &corrected.features_offline, fuse);
            l
        })
        .collect();
    Ok(Survey {
        raw,
        online,
        online_map,
        offline,
        corrected,
        landmarks,
        visual: visual.to_vec(),
        timings_s,
    })
}

/// The counting grid of the run's sonar readings placed along `trajectory` (the grid alone, not
/// the Hough passes and walls of [`map_trajectory`]).
fn counting_map_along(
    run: &RunDataset,
    trajectory: &[StampedPose],
    mapping: &MappingConfig,
) -> Result<OccupancyMap, PipelineError> {
    counting_map(run, &run.placed_readings(trajectory), mapping)
}

/// The counting grid of sonar readings of the run, placed.
fn counting_map(
    run: &RunDataset,
    readings: &[PlacedReading],
    mapping: &MappingConfig,
) -> Result<OccupancyMap, PipelineError> {
    let layout = &run.meta.robot.sonar;
    let mut grid = CountingGrid::new(mapping.grid.clone(), layout.cone_rad, layout.max_range_m)?;
    grid.insert_all(readings);
    Ok(grid.map())
}

/// [`hold_tail_to_walls`] on a survey's offline trajectory, with the walls of the readings placed
/// along it up to the last fused sighting.
fn hold_tail(
    run: &RunDataset,
    sightings: &[TagSighting],
    visual: &[VisualTurn],
    online: &OnlineResult,
    offline: &mut OfflineResult,
    mapping: &MappingConfig,
    fuse: &FuseConfig,
) -> Result<(), PipelineError> {
    let Some(last_t) = online
        .accepted
        .iter()
        .map(|&k| sightings[k].t_s)
        .max_by(f64::total_cmp)
    else {
        return Ok(());
    };
    if run.odometry.last().is_none_or(|p| p.t_s <= last_t) {
        return Ok(()); // the run ends at its last sighting: no tail to hold
    }
    let layout = &run.meta.robot.sonar;
    let readings: Vec<_> = run
        .placed_readings(&offline.trajectory)
        .into_iter()
        .filter(|r| r.t_s <= last_t)
        .collect();
    let grid = counting_map(run, &readings, mapping)?;
    let walls = map_walls(&readings, 0.5 * layout.cone_rad, layout.max_range_m, &grid);
    offline.trajectory = hold_tail_to_walls(
        &run.odometry,
        visual,
        &offline.trajectory,
        last_t,
        offline.odometry_calibration.as_ref(),
        SonarInput {
            readings: &run.sonar,
            layout,
            walls: &walls,
        },
        fuse,
    );
    Ok(())
}

/// Scores a survey against the world and the run's ground truth: the sonar scores of the raw map,
/// the corrected map and the map built with ground-truth poses; ATE of each trajectory; the
/// landmark position errors.
pub fn score_survey(
    survey: &Survey,
    run: &RunDataset,
    world: &World,
    mapping: &MappingConfig,
) -> Result<BTreeMap<String, f64>, PipelineError> {
    let mut m = score_sonar_map(&survey.raw, run, world).metrics();
    let online = score_map(&survey.online_map, world);
    m.insert(
        "map_online.occupied_precision".into(),
        online.occupied_precision,
    );
    m.insert("map_online.occupied_recall".into(), online.occupied_recall);
    let corrected = score_map(&survey.corrected.counting, world);
    m.insert(
        "map_corrected.occupied_precision".into(),
        corrected.occupied_precision,
    );
    m.insert(
        "map_corrected.occupied_recall".into(),
        corrected.occupied_recall,
    );
    if let Some(truth) = &run.ground_truth {
        // Only its counting grid is scored: not the Hough passes and walls a full map builds.
        let gt_map = counting_map_along(run, truth, mapping)?;
        let gt = score_map(&gt_map, world);
        m.insert(
            "map_ground_truth.occupied_precision".into(),
            gt.occupied_precision,
        );
        m.insert(
            "map_ground_truth.occupied_recall".into(),
            gt.occupied_recall,
        );
        for (key, estimate) in [
            ("ate_m.odometry", &run.odometry),
            ("ate_m.online", &survey.online.trajectory),
            ("ate_m.offline", &survey.offline.trajectory),
        ] {
            if let Some(ate) = ate_m(estimate, truth) {
                m.insert(key.into(), ate);
            }
        }
    }
    let landmark_errors = |align: Pose2| -> Vec<f64> {
        let mut errors: Vec<f64> = survey
            .landmarks
            .iter()
            .filter_map(|l| {
                let tag = world
                    .tags
                    .iter()
                    .find(|t| t.id == l.id && t.family == l.family)?;
                let p =
                    align.transform_point(nalgebra::Point2::new(l.position_m[0], l.position_m[1]));
                let d = nalgebra::Vector3::new(p.x, p.y, l.position_m[2])
                    - nalgebra::Vector3::from(tag.position_m);
                Some(d.norm())
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        errors
    };
    let errors = landmark_errors(Pose2::new(0.0, 0.0, 0.0));
    if let Some(median) = median_sorted(&errors) {
        m.insert("landmarks.median_error_m".into(), median);
        m.insert("landmarks.max_error_m".into(), errors[errors.len() - 1]);
    }
    // Diagnostics: the same after the best rigid alignment of the offline trajectory with the
    // truth, i.e. with the shift and turn of the whole survey (its anchoring) taken out.
    if let Some(align) = run
        .ground_truth
        .as_deref()
        .and_then(|t| align_se2(&survey.offline.trajectory, t))
    {
        if let Some(median) = median_sorted(&landmark_errors(align)) {
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
        if let Some(ate) = run.ground_truth.as_deref().and_then(|t| ate_m(&aligned, t)) {
            m.insert("ate_m.offline_aligned".into(), ate);
        }
    }
    if let Some(truth) = run.ground_truth.as_deref() {
        let errors: Vec<(f64, f64)> = survey
            .visual
            .iter()
            .filter_map(|v| {
                let a = crate::dataset::pose_at(truth, v.from_t_s)?;
                let b = crate::dataset::pose_at(truth, v.to_t_s)?;
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
    }
    m.insert("landmarks.count".into(), survey.landmarks.len() as f64);
    m.insert("landmarks.planned".into(), world.tags.len() as f64);
    Ok(m)
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
    m.insert("echoes.off_grid".into(), survey.raw.echoes_off_grid as f64);
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
    m.insert(
        "offline.converged".into(),
        f64::from(u8::from(survey.offline.converged)),
    );
    m
}

/// Scores a sonar map against the world. Sonar positions come from the ground truth when the run
/// has it (else from odometry).
pub fn score_sonar_map(map: &SonarMap, run: &RunDataset, world: &World) -> SonarScores {
    let trajectory = run.ground_truth.as_deref().unwrap_or(&run.odometry);
    let positions: Vec<_> = run
        .placed_readings(trajectory)
        .iter()
        .map(|r| r.world_from_sensor.position())
        .collect();
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
