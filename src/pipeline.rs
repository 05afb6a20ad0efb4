//! The sonar half end to end: a run's readings → counting and log-odds grids → Hough features →
//! scores against the world when it is known. Takes and returns values; [`crate::io`] does files.

use crate::grid::{
    CountingGrid, GridError, LogOddsGrid, MappingConfig, OccupancyGrid, OccupancyMap,
};
use crate::hough::{
    classify_features, features_offline, features_online, reject_mid_wall, Accumulator, Feature,
};
use crate::run::{PoseSource, RunDataset};
use crate::score::{score_features, score_map, FeatureScore, MapScore};
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
    /// Readings used (with an echo or not).
    pub readings: usize,
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
    let layout = &run.meta.robot.sonar;
    let mut timings_s = BTreeMap::new();
    let start = Instant::now();
    let readings = run.placed_readings(trajectory);
    timings_s.insert("place_readings".into(), start.elapsed().as_secs_f64());

    let t = Instant::now();
    let mut counting = CountingGrid::new(config.grid.clone(), layout.cone_rad, layout.max_range_m)?;
    counting.insert_all(&readings);
    let counting = counting.map();
    timings_s.insert("grid_counting".into(), t.elapsed().as_secs_f64());

    let t = Instant::now();
    let mut log_odds = LogOddsGrid::new(config.grid.clone(), layout.cone_rad, layout.max_range_m)?;
    log_odds.insert_all(&readings);
    let log_odds = log_odds.map();
    timings_s.insert("grid_log_odds".into(), t.elapsed().as_secs_f64());

    let half = 0.5 * layout.cone_rad;
    let t = Instant::now();
    let mut online = reject_mid_wall(
        features_online(&readings, trajectory, half, &config.hough),
        &counting,
    );
    classify_features(&mut online, &counting);
    timings_s.insert("hough_online".into(), t.elapsed().as_secs_f64());

    let t = Instant::now();
    let (offline, accumulator) = features_offline(&readings, half, &config.hough);
    let mut offline = reject_mid_wall(offline, &counting);
    classify_features(&mut offline, &counting);
    timings_s.insert("hough_offline".into(), t.elapsed().as_secs_f64());
    timings_s.insert("total".into(), start.elapsed().as_secs_f64());

    Ok(SonarMap {
        counting,
        log_odds,
        features_online: online,
        features_offline: offline,
        accumulator,
        readings: readings.len(),
        timings_s,
    })
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
