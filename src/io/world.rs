//! World files (YAML): walls or a ROS map, tags, targets, people, and the simulation and mapping
//! settings that suit the place. Unknown keys are rejected.

use super::{load_ros_map, parse_yaml, read_text, IoError};
use crate::geometry::{Pose2, Segment};
use crate::sim::SimConfig;
use crate::sonar::map::MappingConfig;
use crate::world::{
    walls_from_raster, Person, PlacedTarget, Tag, Wall, World, DEFAULT_WALL_HEIGHT_M,
};
use nalgebra::Point2;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The start pose as written in a world file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartPose {
    /// Metres.
    pub x_m: f64,
    /// Metres.
    pub y_m: f64,
    /// Radians.
    #[serde(default)]
    pub theta_rad: f64,
}

/// Walls along a polyline.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSpec {
    /// Corner points, metres; at least two.
    pub polyline_m: Vec<[f64; 2]>,
    /// Join the last point back to the first (a pillar, a room).
    #[serde(default)]
    pub closed: bool,
    /// Height, metres (default 2.5).
    #[serde(default)]
    pub height_m: Option<f64>,
}

/// A ROS map used as the wall raster.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapSpec {
    /// The map_server YAML, relative to the world file.
    pub yaml: String,
    /// Height of the walls, metres (default 2.5).
    #[serde(default)]
    pub wall_height_m: Option<f64>,
    /// Largest deviation of the traced walls from the raster, metres (default 0.05).
    #[serde(default)]
    pub simplify_m: Option<f64>,
    /// Obstacle blobs smaller than this many cells are laser speckle and dropped (default 4).
    #[serde(default)]
    pub min_blob_cells: Option<usize>,
}

/// The world file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldFile {
    /// A short name.
    #[serde(default)]
    pub name: Option<String>,
    /// What the place is.
    #[serde(default)]
    pub description: String,
    /// Where the robot starts.
    pub start: StartPose,
    /// Walls as polylines.
    #[serde(default)]
    pub walls: Vec<WallSpec>,
    /// A ROS map as the wall raster.
    #[serde(default)]
    pub map: Option<MapSpec>,
    /// Tags.
    #[serde(default)]
    pub tags: Vec<Tag>,
    /// Calibration targets.
    #[serde(default)]
    pub targets: Vec<PlacedTarget>,
    /// People.
    #[serde(default)]
    pub people: Vec<Person>,
    /// Simulation settings for this place.
    #[serde(default)]
    pub simulation: SimConfig,
    /// Mapping settings for this place (none: a run simulated in it gets its grid fitted to its
    /// path, as a real log does).
    #[serde(default)]
    pub mapping: Option<MappingConfig>,
}

/// A world with the settings its file gives.
#[derive(Debug, Clone)]
pub struct LoadedWorld {
    /// The file it came from.
    pub path: PathBuf,
    /// Its name (the file stem if none is given).
    pub name: String,
    /// The world.
    pub world: World,
    /// Simulation settings (the robot's online grid is `mapping.grid`).
    pub simulation: SimConfig,
    /// Mapping settings, if the file gives them.
    pub mapping: Option<MappingConfig>,
}

fn finite(path: &Path, key: &str, values: &[f64]) -> Result<(), IoError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(IoError::content(
            path,
            format!("`{key}` must hold finite numbers, found {values:?}"),
        ))
    }
}

/// The walls along one polyline of the world file (`key` names it in errors).
fn polyline_walls(path: &Path, key: &str, w: &WallSpec) -> Result<Vec<Wall>, IoError> {
    if w.polyline_m.len() < 2 {
        return Err(IoError::content(
            path,
            format!("`{key}.polyline_m` needs at least two points"),
        ));
    }
    let height = w.height_m.unwrap_or(DEFAULT_WALL_HEIGHT_M);
    if !(height.is_finite() && height > 0.0) {
        return Err(IoError::content(
            path,
            format!("`{key}.height_m` must be positive"),
        ));
    }
    let mut pts: Vec<Point2<f64>> = Vec::new();
    for p in &w.polyline_m {
        finite(path, &format!("{key}.polyline_m"), p)?;
        pts.push(Point2::new(p[0], p[1]));
    }
    if w.closed {
        pts.push(pts[0]);
    }
    Ok(pts
        .windows(2)
        .filter(|s| (s[1] - s[0]).norm() > 1e-9)
        .map(|s| Wall {
            segment: Segment::new(s[0], s[1]),
            height_m: height,
        })
        .collect())
}

/// The walls traced from the world's ROS map.
fn map_walls(path: &Path, yaml: &Path, m: &MapSpec) -> Result<Vec<Wall>, IoError> {
    let mut raster = load_ros_map(yaml)?;
    raster.remove_specks(m.min_blob_cells.unwrap_or(4));
    let simplify = m.simplify_m.unwrap_or(0.05);
    if !(simplify.is_finite() && simplify >= 0.0) {
        return Err(IoError::content(path, "`map.simplify_m` must be >= 0"));
    }
    Ok(walls_from_raster(
        &raster,
        simplify,
        m.wall_height_m.unwrap_or(DEFAULT_WALL_HEIGHT_M),
    ))
}

/// The start, the tags and the people: finite, sized, each tag once.
fn check_placements(path: &Path, file: &WorldFile) -> Result<(), IoError> {
    finite(
        path,
        "start",
        &[file.start.x_m, file.start.y_m, file.start.theta_rad],
    )?;
    let mut seen = std::collections::HashSet::new();
    for (i, t) in file.tags.iter().enumerate() {
        finite(path, &format!("tags[{i}].position_m"), &t.position_m)?;
        finite(path, &format!("tags[{i}].yaw_rad"), &[t.yaw_rad])?;
        finite(
            path,
            &format!("tags[{i}].pitch_rad, roll_rad"),
            &[t.pitch_rad, t.roll_rad],
        )?;
        if !(t.size_m.is_finite() && t.size_m > 0.0) {
            return Err(IoError::content(
                path,
                format!("`tags[{i}].size_m` must be positive, found {}", t.size_m),
            ));
        }
        if !seen.insert((t.family, t.id)) {
            return Err(IoError::content(
                path,
                format!("`tags[{i}]`: id {} of {} appears twice", t.id, t.family),
            ));
        }
    }
    for (i, p) in file.people.iter().enumerate() {
        if p.path_m.is_empty() || !(p.speed_mps >= 0.0 && p.radius_m > 0.0) {
            return Err(IoError::content(
                path,
                format!("`people[{i}]` needs a non-empty path_m, speed_mps >= 0 and radius_m > 0"),
            ));
        }
        for q in &p.path_m {
            finite(path, &format!("people[{i}].path_m"), q)?;
        }
    }
    Ok(())
}

/// Loads a world file, tracing its ROS map into walls if it has one.
pub fn load_world(path: &Path) -> Result<LoadedWorld, IoError> {
    let file: WorldFile = parse_yaml(path, &read_text(path)?)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut walls = Vec::new();
    for (i, w) in file.walls.iter().enumerate() {
        walls.extend(polyline_walls(path, &format!("walls[{i}]"), w)?);
    }
    if let Some(m) = &file.map {
        walls.extend(map_walls(path, &base.join(&m.yaml), m)?);
    }
    if walls.is_empty() {
        return Err(IoError::content(
            path,
            "the world has no walls: give `walls` or `map`",
        ));
    }
    check_placements(path, &file)?;
    if let Some(m) = &file.mapping {
        super::check_mapping(path, m, "`mapping`: ")?;
    }
    let start = Pose2::new(file.start.x_m, file.start.y_m, file.start.theta_rad);
    let world = World::new(walls, file.tags, file.targets, file.people, start);
    let mut simulation = file.simulation;
    simulation.grid = file
        .mapping
        .as_ref()
        .map(|m| m.grid.clone())
        .unwrap_or_default();
    let name = file.name.unwrap_or_else(|| {
        path.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    });
    Ok(LoadedWorld {
        path: path.to_path_buf(),
        name,
        world,
        simulation,
        mapping: file.mapping,
    })
}
