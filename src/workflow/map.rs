//! The sonar map of a run: the counting and log-odds grids, the Hough corner features and the
//! straight walls, scored when the world is known, written as ROS map_server files, CSVs and a
//! report.

use super::{load_run, world_of_run, Error, Result};
use crate::dataset::{PoseSource, RunDataset};
use crate::io::{self, OutputDir};
use crate::metrics::score_sonar_map;
use crate::progress::{staged, Progress};
use crate::sonar::grid::GridConfig;
use crate::sonar::map::{map_trajectory, MappingConfig, SonarMap};
use crate::viz::{MapScene, Recorder, Recording, RecordingRequest};
use crate::world::World;
use std::collections::BTreeMap;
use std::path::Path;

/// What to map and how.
#[derive(Debug, Clone)]
pub struct MapRequest<'a> {
    /// The run dataset directory.
    pub run_dir: &'a Path,
    /// The output directory.
    pub out: &'a Path,
    /// Which trajectory places the readings.
    pub poses: PoseSource,
    /// A world file to score against (default: the one run.yaml names, if it exists).
    pub world: Option<&'a Path>,
    /// Mapping settings (YAML); default: run.yaml's, else the paper's.
    pub config: Option<&'a Path>,
    /// Replace the output directory if it exists.
    pub force: bool,
    /// Where the recording goes (default: `map.rrd` in `out`).
    pub recording: RecordingRequest,
}

/// The map made, and the figures of its `report.json`.
#[derive(Debug, Clone)]
pub struct MapOutput {
    /// The grids, features and walls.
    pub map: SonarMap,
    /// Scores (with a world) and counts.
    pub metrics: BTreeMap<String, f64>,
    /// The scores against the world, when one was given (also in `metrics`).
    pub scores: Option<crate::metrics::SonarScores>,
    /// Which trajectory placed the readings (`report.json`'s `poses`).
    pub poses: PoseSource,
    /// The range sensor mapped with (`ranging.lidar` in `metrics`).
    pub ranging: crate::dataset::RangeSensor,
    /// What a user should know of, as printed on stderr and kept in `report.json` and the
    /// recording: what reading the run warned of, then what the map leaves out or hides
    /// (readings off the grid or outside the trajectory's span, knobs that hid most of the map).
    /// [`map_and_score`] gives the map's own alone, without printing them.
    pub warnings: Vec<String>,
}

/// Maps a run and writes `map.pgm`/`map.yaml`, `map.png`, `map_log_odds.*`, `hough.png`,
/// `corners.csv`, `corners_online.csv`, `walls.csv`, `report.json` and the recording
/// (`map.rrd`, unless asked for elsewhere or none) into a new directory.
///
/// ```no_run
/// use std::path::Path;
/// use stereotag::dataset::PoseSource;
/// use stereotag::viz::RecordingRequest;
/// use stereotag::progress::Silent;
/// use stereotag::workflow::map::{map, MapRequest};
///
/// let out = map(&MapRequest {
///     run_dir: Path::new("runs/office"),
///     out: Path::new("maps/office"),
///     poses: PoseSource::Odometry,
///     world: None,
///     config: None,
///     force: false,
///     recording: RecordingRequest::default(),
/// }, &Silent)?;
/// println!("{} corners", out.map.features_offline.len());
/// # Ok::<(), stereotag::workflow::Error>(())
/// ```
pub fn map(request: &MapRequest<'_>, progress: &dyn Progress) -> Result<MapOutput> {
    // What reading the run warned of goes into report.json with the rest.
    let (loaded, read) = super::capturing_warnings(|| -> Result<_> {
        let run = load_run(request.run_dir)?;
        let given = match request.config {
            Some(p) => Some(io::load_mapping_config(p)?),
            None => None,
        };
        let config = super::mapping_of_run(&run, given);
        let world = match world_of_run(request.world, request.run_dir, &run) {
            Some(w) => Some(io::load_world(&w)?.world),
            None => None,
        };
        Ok((run, config, world))
    });
    let (run, config, world) = loaded?;
    let dir = OutputDir::create(request.out, request.force)?;
    // Opened before the work, so that a sink that cannot be used fails at once.
    let recorder = Recorder::open(&request.recording, Recording::Map, &dir.path("map.rrd"))?;
    let mut output = staged(progress, "map", || {
        map_and_score(&run, request.poses, &config, world.as_ref())
    })?;
    let mut warnings = super::Warnings(read);
    for w in std::mem::take(&mut output.warnings) {
        warnings.warn(w);
    }
    output.warnings = warnings.0;
    if let Some(rec) = recorder {
        let started = std::time::Instant::now();
        staged(progress, "record", || -> Result<()> {
            record(&rec, &run, &output, &config, world.as_ref())?;
            Ok(rec.finish()?)
        })?;
        output
            .map
            .timings_s
            .insert("record".into(), started.elapsed().as_secs_f64());
    }
    save_map(&dir.path(""), &output)?;
    dir.commit()?;
    Ok(output)
}

/// Logs the map to the recording.
fn record(
    rec: &Recorder,
    run: &RunDataset,
    output: &MapOutput,
    config: &MappingConfig,
    world: Option<&World>,
) -> Result<()> {
    let trajectory = run.trajectory(output.poses).unwrap_or_default();
    // The grid as the map built it: the floor set for the run's sampling.
    let grid = GridConfig {
        min_evidence: output.map.min_evidence,
        floor_follows_sampling: false,
        ..config.grid.clone()
    };
    rec.log_map(&MapScene {
        run,
        trajectory,
        poses: match output.poses {
            PoseSource::Odometry => "odometry",
            PoseSource::GroundTruth => "ground truth",
        },
        world,
        map: &output.map,
        grid: &grid,
        metrics: &output.metrics,
        scores: output.scores.as_ref(),
        warnings: &output.warnings,
    })?;
    Ok(())
}

/// Maps a run and scores it against the world when one is given; with the run's ground truth, the
/// trajectory mapped on is scored against it (`ate_m.trajectory`: the odometry's error, or 0
/// with `--poses ground-truth`). Its `warnings` are the map's own, not printed.
pub fn map_and_score(
    run: &RunDataset,
    poses: PoseSource,
    config: &MappingConfig,
    world: Option<&World>,
) -> Result<MapOutput> {
    let trajectory = run.trajectory(poses).ok_or_else(|| {
        Error::Request("the run has no ground_truth.csv; use --poses odometry".into())
    })?;
    let map = map_trajectory(&run.sonar_log(), trajectory, config)?;
    let scores = world.map(|world| score_sonar_map(&map, run, world));
    let mut metrics = scores.as_ref().map(|s| s.metrics()).unwrap_or_default();
    // With the ground truth, how far the mapped trajectory is from it, world or not.
    if let Some(ate) = run
        .ground_truth
        .as_deref()
        .and_then(|truth| crate::metrics::ate_m(trajectory, truth))
    {
        metrics.insert("ate_m.trajectory".into(), ate);
    }
    let per_reading_us =
        |k: &str| map.timings_s.get(k).copied().unwrap_or(0.0) * 1e6 / map.readings.max(1) as f64;
    metrics.insert(
        "grid_counting.us_per_reading".into(),
        per_reading_us("grid_counting"),
    );
    metrics.insert(
        "grid_log_odds.us_per_reading".into(),
        per_reading_us("grid_log_odds"),
    );
    metrics.insert("total.us_per_reading".into(), per_reading_us("total"));
    metrics.insert("readings".into(), map.readings as f64);
    metrics.insert("echoes".into(), map.echoes as f64);
    metrics.extend(map.coverage_metrics());
    metrics.insert("readings.unplaced".into(), map.readings_unplaced as f64);
    metrics.insert("walls".into(), map.walls.len() as f64);
    metrics.insert("features".into(), map.features_offline.len() as f64);
    let ranging = run.ranging();
    metrics.insert(
        "ranging.lidar".into(),
        (ranging == crate::dataset::RangeSensor::Lidar) as u8 as f64,
    );
    let duration =
        run.odometry.last().map_or(0.0, |p| p.t_s) - run.odometry.first().map_or(0.0, |p| p.t_s);
    metrics.insert("run.duration_s".into(), duration);
    // How far the robot drove by its odometry, which its drift grows with.
    metrics.insert(
        "run.path_m".into(),
        crate::geometry::path_length_m(&run.odometry),
    );
    Ok(MapOutput {
        warnings: map.warnings(),
        map,
        metrics,
        scores,
        ranging,
        poses,
    })
}

/// Writes a map's files into `dir`.
fn save_map(dir: &Path, output: &MapOutput) -> Result<()> {
    let map = &output.map;
    io::save_ros_map(dir, "map", &map.counting)?;
    let corners = crate::picture::Overlay {
        marks: crate::picture::Mark::corners(&map.features_offline),
        mark_legend: vec![("Hough corner", crate::picture::colours::CORNER)],
        ..Default::default()
    };
    let sensor = output.ranging.name();
    io::save_map_png(
        &dir.join("map.png"),
        &map.counting,
        &format!("map.png: {sensor} map (simple counting) with its Hough corners"),
        &corners,
    )?;
    io::save_ros_map(dir, "map_log_odds", &map.log_odds)?;
    io::save_accumulator_png(
        &dir.join("hough.png"),
        &map.accumulator,
        "hough.png: Hough accumulator",
    )?;
    io::save_features_csv(&dir.join("corners.csv"), &map.features_offline)?;
    io::save_features_csv(&dir.join("corners_online.csv"), &map.features_online)?;
    io::save_walls_csv(&dir.join("walls.csv"), &map.walls)?;
    let finite: BTreeMap<_, _> = output
        .metrics
        .iter()
        .map(|(k, v)| (k.clone(), v.is_finite().then_some(*v)))
        .collect();
    let report = serde_json::json!({
        "poses": output.poses.as_str(),
        "metrics": finite,
        "timings_s": map.timings_s,
        "warnings": output.warnings,
    });
    io::save_json(&dir.join("report.json"), &report)?;
    Ok(())
}
