use super::UsageError;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use stereotag::dataset::{PoseSource, RunDataset};
use stereotag::io::{self, OutputDir};
use stereotag::metrics::score_sonar_map;
use stereotag::sonar::map::map_run;
use stereotag::sonar::map::MappingConfig;
use stereotag::sonar::map::SonarMap;

/// Which trajectory places the readings.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Poses {
    /// The robot's dead reckoning.
    Odometry,
    /// ground_truth.csv.
    GroundTruth,
}

/// Arguments of `stereotag map`.
#[derive(Debug, clap::Args)]
pub struct Map {
    /// Run dataset directory.
    #[arg(long)]
    run: PathBuf,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Trajectory that places the readings.
    #[arg(long, value_enum, default_value = "odometry")]
    poses: Poses,
    /// World file to score against (default: the one run.yaml names, if it exists).
    #[arg(long)]
    world: Option<PathBuf>,
    /// Mapping settings (YAML, `stereotag config --default mapping`); default: run.yaml's, else the paper's.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

impl Map {
    pub fn run(&self) -> anyhow::Result<()> {
        let run = super::load_run(&self.run)?;
        let config = match &self.config {
            Some(p) => io::parse_yaml::<MappingConfig>(
                p,
                &std::fs::read_to_string(p)
                    .map_err(|e| UsageError(format!("{}: {e}", p.display())))?,
            )?,
            None => run.meta.mapping.clone().unwrap_or_default(),
        };
        let poses = match self.poses {
            Poses::Odometry => PoseSource::Odometry,
            Poses::GroundTruth => PoseSource::GroundTruth,
        };
        let world = super::world_of_run(self.world.as_deref(), &self.run, &run);
        let (map, metrics) = map_and_score(&run, poses, &config, world.as_deref())?;
        write_map_outputs(&self.out, self.force, &map, &metrics)?;
        print_summary(&map, &metrics);
        Ok(())
    }
}

/// Maps a run and scores it when a world file is given.
pub(crate) fn map_and_score(
    run: &RunDataset,
    poses: PoseSource,
    config: &MappingConfig,
    world: Option<&Path>,
) -> anyhow::Result<(SonarMap, BTreeMap<String, f64>)> {
    let map = map_run(run, poses, config)?;
    let mut metrics = BTreeMap::new();
    if let Some(w) = world {
        let loaded = io::load_world(w)?;
        metrics = score_sonar_map(&map, run, &loaded.world).metrics();
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
    metrics.insert("readings".into(), map.readings as f64);
    metrics.insert("echoes".into(), map.echoes as f64);
    metrics.insert("echoes.off_grid".into(), map.echoes_off_grid as f64);
    let duration =
        run.odometry.last().map_or(0.0, |p| p.t_s) - run.odometry.first().map_or(0.0, |p| p.t_s);
    metrics.insert("run.duration_s".into(), duration);
    Ok((map, metrics))
}

/// Writes maps, features and report into a fresh output directory.
pub(crate) fn write_map_outputs(
    out: &Path,
    force: bool,
    map: &SonarMap,
    metrics: &BTreeMap<String, f64>,
) -> anyhow::Result<()> {
    let dir = OutputDir::create(out, force)?;
    io::save_ros_map(&dir.path(""), "map", &map.counting)?;
    io::save_map_png(&dir.path("map.png"), &map.counting)?;
    io::save_ros_map(&dir.path(""), "map_log_odds", &map.log_odds)?;
    io::save_accumulator_png(&dir.path("hough.png"), &map.accumulator)?;
    io::save_features_csv(&dir.path("corners.csv"), &map.features_offline)?;
    io::save_features_csv(&dir.path("corners_online.csv"), &map.features_online)?;
    io::save_walls_csv(&dir.path("walls.csv"), &map.walls)?;
    let finite: BTreeMap<_, _> = metrics
        .iter()
        .map(|(k, v)| (k.clone(), v.is_finite().then_some(*v)))
        .collect();
    let report = serde_json::json!({ "metrics": finite, "timings_s": map.timings_s });
    io::save_json(&dir.path("report.json"), &report)?;
    dir.commit()?;
    Ok(())
}

/// Share of echoes off the grid above which the grid is taken not to cover the run: 25% (odometry
/// drift puts up to 15% of the samples' echoes off their grids, ground-truth poses 0.4-3%: echoes
/// from behind the outer walls).
const OFF_GRID_WARN: f64 = 0.25;

/// Warns when the grid does not cover the run: a share of its echoes fell outside it and is lost.
pub(crate) fn warn_if_off_grid(map: &SonarMap) {
    let share = map.echoes_off_grid as f64 / map.echoes.max(1) as f64;
    if share > OFF_GRID_WARN {
        let g = &map.counting.geometry;
        tracing::warn!(
            "{} of {} sonar echoes ({:.0}%) fall outside the grid (x {:.1}..{:.1} m, y {:.1}..{:.1} m) and are lost: set `mapping.grid` (origin_m, width_cells, height_cells) in run.yaml or the mapping settings to cover the run",
            map.echoes_off_grid,
            map.echoes,
            100.0 * share,
            g.origin_m[0],
            g.origin_m[0] + g.width as f64 * g.resolution_m,
            g.origin_m[1],
            g.origin_m[1] + g.height as f64 * g.resolution_m,
        );
    }
}

pub(crate) fn print_summary(map: &SonarMap, metrics: &BTreeMap<String, f64>) {
    warn_if_off_grid(map);
    let get = |k: &str| metrics.get(k).copied().unwrap_or(f64::NAN);
    tracing::info!(
        "{} readings; {} features offline, {} online; mapped in {:.3} s",
        map.readings,
        map.features_offline.len(),
        map.features_online.len(),
        map.timings_s.get("total").copied().unwrap_or(0.0)
    );
    if metrics.contains_key("map.occupied_precision") {
        tracing::info!(
            "counting grid: occupied precision {:.3}, recall {:.3}; log-odds: {:.3}, {:.3}; features precision {:.3}, recall {:.3}",
            get("map.occupied_precision"),
            get("map.occupied_recall"),
            get("map_log_odds.occupied_precision"),
            get("map_log_odds.occupied_recall"),
            get("features.precision"),
            get("features.recall"),
        );
    }
}
