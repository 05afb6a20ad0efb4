//! The sonar half end to end: readings placed along a trajectory, the counting and log-odds
//! grids, the online and offline Hough features, and the straight walls.

use crate::geometry::StampedPose;
use crate::progress::timed;
use crate::sonar::grid::{
    CountingGrid, GridConfig, GridError, LogOddsGrid, OccupancyGrid, OccupancyMap,
};
use crate::sonar::hough::{
    classify_features, features_offline, features_online, off_the_walls, Accumulator, Feature,
    HoughConfig, OfflineFeatures, STRONG_PEAK,
};
use crate::sonar::walls::{map_walls, WallConfig, WallSegment};
use crate::sonar::{PlacedReading, SonarLayout, SonarLog};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::time::Instant;

/// Grid and Hough settings together: the `mapping:` section of a world or run file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct MappingConfig {
    /// Occupancy grid.
    pub grid: GridConfig,
    /// Hough corner features.
    pub hough: HoughConfig,
    /// Straight walls.
    pub walls: WallConfig,
}

/// Travel between one sensor's readings up to which the evidence floor is used as set: 0.15 m.
/// The sample homes are simulated with a reading every 4-10 cm, freiburg-079 (real) every 9 cm;
/// aces (real, a scan every 3 s) every 73 cm.
pub const FLOOR_SPACING_M: f64 = 0.15;
/// The lowest the floor follows sparse sampling down to: 2. On aces against its full laser,
/// floor 6 / 4 / 3 / 2 / 1: cells known 641 / 1,321 / 2,265 / 4,665 / 9,784, occupied precision
/// 0.977 / 0.974 / 0.946 / 0.949 / 0.887, recall 0.98 / 0.97 / 0.98 / 0.95 / 0.98: one reading
/// alone makes too many false walls.
pub const LOWEST_FLOOR: u32 = 2;

/// Metres of travel between one sensor's readings, on average: the trajectory's length times the
/// sensors over the readings. `None` without readings or travel.
pub fn sampling_spacing_m(sonar: &SonarLog<'_>, trajectory: &[StampedPose]) -> Option<f64> {
    let travel = crate::geometry::path_length_m(trajectory);
    let per_sensor = sonar.readings.len() as f64 / sonar.layout.sensors.len().max(1) as f64;
    (travel > 0.0 && per_sensor > 0.0).then(|| travel / per_sensor)
}

impl MappingConfig {
    /// The settings for `sonar`'s readings along `trajectory`. With `grid.floor_follows_sampling`
    /// (and a sonar's cones: a laser counts beams), a run sampled sparser than every
    /// [`FLOOR_SPACING_M`] gets the floor `min_evidence * FLOOR_SPACING_M / spacing`, rounded,
    /// [`LOWEST_FLOOR`] at least: a cell is seen by fewer readings, in proportion; with
    /// `walls.follow_sampling`, the wall step's readings and gap follow it too
    /// ([`WallConfig::for_spacing`]). The settings returned follow nothing more (applying this
    /// twice changes nothing).
    pub fn for_run(&self, sonar: &SonarLog<'_>, trajectory: &[StampedPose]) -> MappingConfig {
        self.for_spacing(sonar.layout, sampling_spacing_m(sonar, trajectory))
    }

    /// [`Self::for_run`] with the run's spacing already measured.
    fn for_spacing(&self, layout: &SonarLayout, spacing: Option<f64>) -> MappingConfig {
        let mut config = self.clone();
        // A laser counts beams, not a sonar's cones: its settings stay as set.
        let cones = layout.beam == crate::sonar::BeamModel::Cone;
        config.walls = config.walls.for_spacing(spacing.filter(|_| cones));
        if !config.grid.floor_follows_sampling {
            return config;
        }
        config.grid.floor_follows_sampling = false;
        if let Some(spacing) = spacing.filter(|&s| cones && s > FLOOR_SPACING_M) {
            let scaled = (config.grid.min_evidence as f64 * FLOOR_SPACING_M / spacing).round();
            config.grid.min_evidence = (scaled as u32)
                .max(LOWEST_FLOOR)
                .min(config.grid.min_evidence);
        }
        config
    }
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
    /// Readings left out: their time lies outside the trajectory's span (beyond
    /// [`crate::sonar::PLACE_TOLERANCE_S`]), so no pose places them.
    pub readings_unplaced: usize,
    /// What the settings that leave data out left out.
    pub hidden: Hidden,
    /// Metres of travel between one sensor's readings ([`sampling_spacing_m`]).
    pub sampling_spacing_m: Option<f64>,
    /// The evidence floor used ([`MappingConfig::for_run`]).
    pub min_evidence: u32,
    /// The wall step's settings used ([`MappingConfig::for_run`]).
    pub wall_config: WallConfig,
    /// Seconds per stage.
    pub timings_s: BTreeMap<String, f64>,
}

/// What the settings that leave data out (the evidence floor, the Hough threshold, the sonar's
/// range) left out of a map: on a sparsely sampled run (a real robot's log, a reading every
/// 0.1-0.7 m) they can hide most of it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Hidden {
    /// Cells of the counting grid with a value.
    pub cells_known: usize,
    /// Cells with some evidence but less than the floor (`mapping.grid.min_evidence`), left
    /// unknown.
    pub cells_below_floor: usize,
    /// Offline features kept.
    pub features_kept: usize,
    /// Offline features the threshold (`mapping.hough.offline_threshold`, else `threshold`) hid:
    /// from peaks with at least half its votes, that pass every other rule
    /// ([`crate::sonar::hough::OfflineFeatures::below_threshold`]).
    pub features_below_threshold: usize,
    /// Readings at or beyond the sonar's range (`max_range_m`), taken as no echo.
    pub readings_beyond_range: usize,
    /// Echoes at the sonar's shortest range (`min_range_m`): they mark the grid, but place no
    /// line or wall ([`crate::sonar::SonarLayout::at_shortest_range`]).
    pub readings_at_shortest_range: usize,
    /// Offline features dropped for lying on no wall's line (rule 6 of [`crate::sonar::hough`],
    /// `mapping.hough.features_on_walls`).
    pub features_off_walls: usize,
}

impl Hidden {
    /// The metrics for `report.json` (`hidden.*`).
    pub fn metrics(&self) -> [(&'static str, f64); 7] {
        [
            ("hidden.cells_known", self.cells_known as f64),
            ("hidden.cells_below_floor", self.cells_below_floor as f64),
            ("hidden.features_kept", self.features_kept as f64),
            (
                "hidden.features_below_threshold",
                self.features_below_threshold as f64,
            ),
            (
                "hidden.readings_beyond_range",
                self.readings_beyond_range as f64,
            ),
            (
                "hidden.readings_at_shortest_range",
                self.readings_at_shortest_range as f64,
            ),
            ("hidden.features_off_walls", self.features_off_walls as f64),
        ]
    }
}

/// Share of echoes off the grid above which the grid is taken not to cover the run: 25% (odometry
/// drift puts up to 15% of the samples' echoes off their grids, ground-truth poses 0.4-3%: echoes
/// from behind the outer walls).
pub const OFF_GRID_WARN: f64 = 0.25;

impl SonarMap {
    /// What to tell the user when readings were left out for want of a pose.
    pub fn unplaced_warning(&self) -> Option<String> {
        (self.readings_unplaced > 0).then(|| {
            format!(
                "{} of {} sonar readings are left out: their time lies more than {} s before the first or after the last pose placing them",
                self.readings_unplaced,
                self.readings + self.readings_unplaced,
                crate::sonar::PLACE_TOLERANCE_S
            )
        })
    }

    /// What `report.json` says of the data the map kept and left out: the echoes off the grid,
    /// [`Hidden::metrics`], the floor used, the run's sampling and the walls' summed and longest
    /// length.
    pub fn coverage_metrics(&self) -> Vec<(String, f64)> {
        let lengths = self.walls.iter().map(WallSegment::length_m);
        let mut m = vec![
            ("echoes.off_grid".to_string(), self.echoes_off_grid as f64),
            ("grid.min_evidence".to_string(), self.min_evidence as f64),
            (
                "walls.length_m".to_string(),
                lengths.clone().fold(0.0, |a, l| a + l),
            ),
            ("walls.longest_m".to_string(), lengths.fold(0.0, f64::max)),
        ];
        m.extend(self.hidden.metrics().map(|(k, v)| (k.to_string(), v)));
        m.extend(
            self.sampling_spacing_m
                .map(|s| ("sampling.spacing_m".to_string(), s)),
        );
        m
    }

    /// What to tell the user when a setting hid most of what it could have shown: the evidence
    /// floor more cells than it left known, the Hough threshold over three times the peaks it
    /// kept (the simulated museum, sampled every 5-10 cm, has 1.6 times as many low peaks as
    /// kept ones: its walls; a real log sampled every 3 s, aces, 3.9 times); and a map with
    /// echoes but no wall fitted.
    pub fn hidden_warnings(&self) -> Vec<String> {
        let h = &self.hidden;
        let mut out = Vec::new();
        if h.cells_below_floor > h.cells_known {
            let spacing = self.sampling_spacing_m.map_or(String::new(), |s| {
                format!(", a reading every {s:.2} m of travel")
            });
            out.push(format!(
                "the evidence floor ({} readings a cell: mapping.grid.min_evidence, following the run's sampling{spacing}) leaves {} cells unknown that some reading saw, more than the {} it shows; a lower floor shows more of the map, with less evidence a cell",
                self.min_evidence, h.cells_below_floor, h.cells_known
            ));
        }
        if self.walls.is_empty() && self.echoes >= self.wall_config.min_readings {
            let spacing = self.sampling_spacing_m.map_or(String::new(), |s| {
                format!(" (this run: a reading every {s:.2} m of travel)")
            });
            out.push(format!(
                "no straight wall was fitted: a wall needs {} echoes off its face with no gap over {:.2} m between them (mapping.walls){spacing}; `localize` will have no walls to hold the robot to between tags, and `plan` none to predict with",
                self.wall_config.min_readings,
                self.wall_config.max_gap_m
            ));
        }
        if h.features_below_threshold > h.features_kept.max(2) {
            out.push(format!(
                "the Hough threshold (mapping.hough.threshold, or offline_threshold) hides {} corner features with at least half its votes that pass every other rule, more than the {} it keeps: a sparsely sampled run gives fewer votes a corner; a lower threshold shows them, with less evidence each",
                h.features_below_threshold, h.features_kept
            ));
        }
        out
    }

    /// What the map leaves out or hides that a user should know of: readings off the grid
    /// ([`Self::off_grid_warning`]) or outside the trajectory's span
    /// ([`Self::unplaced_warning`]), and knobs that hid most of it ([`Self::hidden_warnings`]).
    pub fn warnings(&self) -> Vec<String> {
        [self.off_grid_warning(), self.unplaced_warning()]
            .into_iter()
            .flatten()
            .chain(self.hidden_warnings())
            .collect()
    }

    /// What to tell the user when the grid does not cover the run (more than [`OFF_GRID_WARN`]
    /// of the echoes fell outside it and are lost): how many, where the grid lies, what to set.
    pub fn off_grid_warning(&self) -> Option<String> {
        let share = self.echoes_off_grid as f64 / self.echoes.max(1) as f64;
        if share <= OFF_GRID_WARN {
            return None;
        }
        let g = &self.counting.geometry;
        Some(format!(
            "{} of {} sonar echoes ({:.0}%) fall outside the grid (x {:.1}..{:.1} m, y {:.1}..{:.1} m) and are lost: set `mapping.grid` (origin_m, width_cells, height_cells) in run.yaml or the mapping settings to cover the run",
            self.echoes_off_grid,
            self.echoes,
            100.0 * share,
            g.origin_m[0],
            g.origin_m[0] + g.width as f64 * g.resolution_m,
            g.origin_m[1],
            g.origin_m[1] + g.height as f64 * g.resolution_m,
        ))
    }
}

/// Builds the grids, features and walls of a run's sonar with the readings placed along
/// `trajectory` (odometry, ground truth or a corrected estimate).
///
/// The sonar half alone, on two minutes of a simulated office:
///
/// ```
/// use stereotag::sim::{simulate, SimConfig};
/// use stereotag::sonar::map::{map_trajectory, MappingConfig};
///
/// let path = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/office/world.yaml");
/// let office = stereotag::io::load_world(std::path::Path::new(path))?;
/// let mut config: SimConfig = office.simulation.clone();
/// config.exploration.duration_s = 120.0;
/// let run = simulate(&office.world, &config, |_| {}).expect("a valid world").run;
/// let map = map_trajectory(&run.sonar_log(), &run.odometry, &MappingConfig::default())
///     .expect("valid grid settings");
/// println!("{} corners and edges, {} walls", map.features_offline.len(), map.walls.len());
/// assert!(!map.features_offline.is_empty());
/// # Ok::<(), stereotag::io::IoError>(())
/// ```
pub fn map_trajectory(
    sonar: &SonarLog<'_>,
    trajectory: &[StampedPose],
    config: &MappingConfig,
) -> Result<SonarMap, GridError> {
    let layout = sonar.layout;
    // The settings as given, before the sampling moves them.
    config.walls.validate()?;
    let spacing = sampling_spacing_m(sonar, trajectory);
    let config = &config.for_spacing(layout, spacing);
    let mut timings_s = BTreeMap::new();
    let start = Instant::now();
    let readings = timed("place_readings", &mut timings_s, || {
        sonar.placed(trajectory)
    });
    let readings_unplaced = sonar.readings.len() - readings.len();
    let (counting, cells_below_floor) = timed("grid_counting", &mut timings_s, || {
        let mut grid = CountingGrid::for_layout(config.grid.clone(), layout)?;
        grid.insert_all(&readings);
        Ok::<_, GridError>((grid.map(), grid.cells_below_floor()))
    })?;
    let readings_beyond_range = readings
        .iter()
        .filter(|r| r.range_m.is_some_and(|x| x >= layout.max_range_m))
        .count();
    let readings_at_shortest_range =
        layout.count_at_shortest_range(readings.iter().map(|r| r.range_m));
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
    // counting grid and nothing of each other: the online Hough pass, the offline pass (after the
    // log-odds grid) and the walls run alongside each other (a sonar run's online pass is the
    // longest; a lidar run's offline pass and walls are, each a few seconds). Each stage's time
    // is its own, taken while the others run.
    let (line_echoes, half) = layout.echoes_for_lines(&readings);
    let ((online, online_times), rest) = rayon::join(
        || {
            let mut times = BTreeMap::new();
            let online = timed("hough_online", &mut times, || {
                let mut online =
                    features_online(&line_echoes, trajectory, half, &counting, &config.hough);
                classify_features(&mut online, &counting);
                online
            });
            (online, times)
        },
        || -> Result<_, GridError> {
            let (grid_and_offline, (walls, walls_times)) = rayon::join(
                || {
                    let mut times = BTreeMap::new();
                    let log_odds = timed("grid_log_odds", &mut times, || {
                        let mut grid = LogOddsGrid::for_layout(config.grid.clone(), layout)?;
                        grid.insert_all(&readings);
                        Ok::<_, GridError>(grid.map())
                    })?;
                    let offline = timed("hough_offline", &mut times, || {
                        let mut offline =
                            features_offline(&line_echoes, half, &counting, &config.hough);
                        classify_features(&mut offline.features, &counting);
                        offline
                    });
                    Ok::<_, GridError>((log_odds, offline, times))
                },
                || {
                    let mut times = BTreeMap::new();
                    let walls = timed("walls", &mut times, || {
                        map_walls(
                            &line_echoes,
                            half,
                            layout.max_range_m,
                            &counting,
                            &config.walls,
                        )
                    });
                    (walls, times)
                },
            );
            let (log_odds, offline, mut times) = grid_and_offline?;
            times.extend(walls_times);
            Ok((log_odds, offline, walls, times))
        },
    );
    let (log_odds, pass, walls, rest_times) = rest?;
    let OfflineFeatures {
        features: mut offline,
        below_threshold: mut hidden_features,
        accumulator,
    } = pass;
    let features_found = offline.len();
    let threshold = config
        .hough
        .offline_threshold
        .unwrap_or(config.hough.threshold);
    if config.hough.features_on_walls && !walls.is_empty() {
        let keep = |f: &Feature| f.votes >= STRONG_PEAK * threshold || !off_the_walls(f, &walls);
        offline.retain(keep);
        hidden_features.retain(keep);
    }
    let hidden = Hidden {
        cells_known: counting.occupancy.iter().filter(|c| c.is_some()).count(),
        cells_below_floor,
        features_kept: offline.len(),
        features_below_threshold: hidden_features.len(),
        readings_beyond_range,
        readings_at_shortest_range,
        features_off_walls: features_found - offline.len(),
    };
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
        readings_unplaced,
        hidden,
        sampling_spacing_m: spacing,
        min_evidence: config.grid.min_evidence,
        wall_config: config.walls.clone(),
        timings_s,
    })
}

/// The counting grid of the run's sonar readings placed along `trajectory` (the grid alone, not
/// the Hough passes and walls of [`map_trajectory`]).
pub fn counting_map_along(
    sonar: &SonarLog<'_>,
    trajectory: &[StampedPose],
    mapping: &MappingConfig,
) -> Result<OccupancyMap, GridError> {
    let mapping = mapping.for_run(sonar, trajectory);
    counting_map(sonar.layout, &sonar.placed(trajectory), &mapping)
}

/// The counting grid of placed readings of sensors of `layout`.
pub fn counting_map(
    layout: &SonarLayout,
    readings: &[PlacedReading],
    mapping: &MappingConfig,
) -> Result<OccupancyMap, GridError> {
    let mut grid = CountingGrid::for_layout(mapping.grid.clone(), layout)?;
    grid.insert_all(readings);
    Ok(grid.map())
}

/// The straight walls of placed readings of sensors of `layout` on `map` (their counting grid):
/// [`map_walls`] with the layout's beam model ([`SonarLayout::echoes_for_lines`]).
pub fn layout_walls(
    layout: &SonarLayout,
    readings: &[PlacedReading],
    map: &OccupancyMap,
    config: &WallConfig,
) -> Vec<WallSegment> {
    let (echoes, half) = layout.echoes_for_lines(readings);
    map_walls(&echoes, half, layout.max_range_m, map, config)
}
