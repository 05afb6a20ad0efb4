//! Drawing the sonar half, shared by the survey's and the map's recordings: the Hough
//! accumulator, and the grid growing reading by reading with the beams that build it.

use super::draw::{feature_color, grid_map, map_image, MapFrame, StripBatches, SONAR_Z_M};
use super::palette;
use super::{VizError, GRID_SNAPSHOT_S};
use crate::dataset::RunDataset;
use crate::geometry::{Pose2, StampedPose};
use crate::sonar::grid::{CountingGrid, GridConfig, OccupancyGrid};
use crate::sonar::hough::{Accumulator, Feature};
use crate::sonar::BeamModel;

/// The final Hough accumulator as an image at `path`, votes on a log scale.
pub(super) fn log_hough(
    rec: &rerun::RecordingStream,
    path: &str,
    acc: &Accumulator,
) -> Result<(), VizError> {
    let max = acc.votes.iter().copied().max().unwrap_or(1).max(1) as f64;
    let pixels: Vec<u8> = acc
        .votes
        .iter()
        .map(|&v| (255.0 * (1.0 + v as f64).ln() / (1.0 + max).ln()).round() as u8)
        .collect();
    rec.log_static(
        path,
        &rerun::Image::from_l8(pixels, [acc.n_phi as u32, acc.n_rho as u32]),
    )?;
    Ok(())
}

/// Hough corners and edges in the 3D scene under `world/features_{name}`, coloured by kind.
pub(super) fn log_features(
    rec: &rerun::RecordingStream,
    name: &str,
    features: &[Feature],
) -> Result<(), VizError> {
    let colors: Vec<rerun::Color> = features.iter().map(|f| feature_color(f.kind)).collect();
    let labels: Vec<String> = features
        .iter()
        .map(|f| format!("{} {} votes", f.kind.as_str(), f.votes))
        .collect();
    rec.log_static(
        format!("world/features_{name}"),
        &rerun::Points3D::new(features.iter().map(|f| [f.x_m as f32, f.y_m as f32, 0.0]))
            .with_colors(colors)
            .with_labels(labels)
            .with_show_labels(false)
            .with_radii([0.05f32]),
    )?;
    Ok(())
}

/// A laser's beams are drawn one every 10 degrees of its fan (all of them would hide the map).
const LASER_BEAM_DRAWN_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// The counting grid of the run's readings placed along `trajectory`, as it grows: a snapshot
/// every [`GRID_SNAPSHOT_S`] of the run under `world/grid` (in the 3D scene) and `{map_path}/grid`
/// (cropped to `frame`), and each reading's beam under `world/sonar/beams`.
pub(super) fn log_growing_grid(
    rec: &rerun::RecordingStream,
    run: &RunDataset,
    trajectory: &[StampedPose],
    config: &GridConfig,
    frame: &MapFrame,
    map_path: &str,
) -> Result<(), VizError> {
    let layout = &run.meta.robot.sonar;
    let readings = run.placed_readings(trajectory);
    let Ok(mut grid) = CountingGrid::for_layout(config.clone(), layout) else {
        return Ok(());
    };
    let grid_path = format!("{map_path}/grid");
    let log_grid = |grid: &CountingGrid, t_s: f64| -> Result<(), VizError> {
        let map = frame.crop(&grid.map());
        rec.set_duration_secs("time", t_s);
        rec.log("world/grid", &grid_map(&map))?;
        rec.log(grid_path.as_str(), &map_image(&map))?;
        Ok(())
    };
    let mut beams = StripBatches::new(rec, "world/sonar/beams");
    let mut next_snapshot = f64::NEG_INFINITY;
    // A laser's beams are drawn as lines, one in every [`LASER_BEAM_DRAWN_RAD`] of its fan.
    let stride = match layout.beam {
        BeamModel::Cone => 1,
        BeamModel::Ray => (LASER_BEAM_DRAWN_RAD / layout.cone_rad).round().max(1.0) as usize,
    };
    for (k, r) in readings.iter().enumerate() {
        grid.insert(r);
        if let (Some(range), true) = (r.range_m, k.is_multiple_of(stride)) {
            let cone = match layout.beam {
                BeamModel::Cone => cone_outline(&r.world_from_sensor, range, layout.cone_rad),
                BeamModel::Ray => cone_outline(&r.world_from_sensor, range, 0.0)[..2].to_vec(),
            };
            beams.push(r.t_s, cone, palette::SONAR_BEAM)?;
        }
        if r.t_s >= next_snapshot {
            next_snapshot = r.t_s + GRID_SNAPSHOT_S;
            log_grid(&grid, r.t_s)?;
        }
    }
    beams.flush()?;
    if let Some(last) = readings.last() {
        log_grid(&grid, last.t_s)?;
    }
    rec.reset_time();
    Ok(())
}

/// A sonar cone drawn as a fan: from the sensor out to the range along seven rays and back.
fn cone_outline(o: &Pose2, range: f64, cone_rad: f64) -> Vec<[f32; 3]> {
    const RAYS: usize = 7;
    let at = |x: f64, y: f64| [x as f32, y as f32, SONAR_Z_M];
    let mut cone = vec![at(o.x, o.y)];
    for k in 0..RAYS {
        let a = o.theta - 0.5 * cone_rad + cone_rad * k as f64 / (RAYS - 1) as f64;
        cone.push(at(o.x + range * a.cos(), o.y + range * a.sin()));
    }
    cone.push(at(o.x, o.y));
    cone
}
