//! A robot's log brought in as a run dataset: CARMEN logs (Radish and the classic 2D SLAM data
//! sets), their laser turned into sonar-like readings so the paper's method runs on real
//! buildings.

use super::Result;
use crate::dataset::{RobotDescription, RunDataset, RunMeta, RUN_FORMAT};
use crate::geometry::StampedPose;
use crate::io::carmen::{read_carmen, LaserScan};
use crate::io::{self, OutputDir};
use crate::sonar::grid::GridConfig;
use crate::sonar::map::MappingConfig;
use crate::sonar::{SonarLayout, SonarReading};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// What to import.
#[derive(Debug, Clone)]
pub struct ImportRequest<'a> {
    /// The CARMEN log (`.gz` for gzip).
    pub carmen: &'a Path,
    /// The run directory to write.
    pub out: &'a Path,
    /// The sonar ring the laser is turned into.
    pub as_sonar: SonarLayout,
    /// Replace the output directory if it exists.
    pub force: bool,
}

/// What was read and written (also `import.json` in the run directory).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImportSummary {
    /// The log read.
    pub log: String,
    /// `ODOM` lines.
    pub odometry_poses: usize,
    /// Laser scans (front and rear).
    pub scans: usize,
    /// Lines of other kinds, by kind.
    pub other_lines: BTreeMap<String, usize>,
    /// The log's first time stamp, seconds: the run's times start there.
    pub start_s: f64,
    /// Seconds from the first to the last time stamp.
    pub duration_s: f64,
    /// Odometry rows a little out of time order, re-ordered.
    pub odometry_reordered: usize,
    /// Odometry rows left out: their time goes back more than the tolerance.
    pub odometry_dropped: usize,
    /// Sonar-like readings written, and those with an echo.
    pub readings: usize,
    /// Of those, with an echo.
    pub echoes: usize,
    /// Sensors of the layout the laser does not see (their cones outside its field of view).
    pub sensors_unseen: Vec<usize>,
    /// Whether the scans' poses were written as the ground truth (a `*-corrected` log).
    pub ground_truth: bool,
    /// The grid fitted to the run: lower-left corner (m) and size (cells).
    pub grid_origin_m: [f64; 2],
    /// Cells across and up.
    pub grid_cells: [usize; 2],
}

/// Imports a CARMEN log as a run: odometry from the `ODOM` lines (the scans' odometry fields
/// when there are none), each laser scan as one reading per sonar of `as_sonar` (the nearest
/// return in the sonar's cone, none within its range: no echo), the scans' poses as the ground
/// truth of a `*-corrected` log, and a grid of the paper's 20 cm cells fitted to the run.
/// Times start at the log's first time stamp.
pub fn import_carmen(request: &ImportRequest<'_>) -> Result<(RunDataset, ImportSummary)> {
    let log = read_carmen(request.carmen)?;
    let mut scans = log.scans;
    scans.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let (logged, from_scans) = if log.odometry.is_empty() {
        (poses_of(&scans), true)
    } else {
        (log.odometry, false)
    };
    let in_order = time_ordered(logged);
    if in_order.dropped > 0 {
        tracing::warn!(
            "{}: {} ODOM lines left out: their time goes back more than {} s (the first at t = {} s; \
             corrected logs reset the odometry with such lines)",
            request.carmen.display(),
            in_order.dropped,
            io::REORDER_TOLERANCE_S,
            in_order.first_dropped_s
        );
    }
    let (reordered, dropped) = (in_order.reordered, in_order.dropped);
    let odometry = in_order.poses;
    if odometry.is_empty() {
        return Err(io::IoError::content(
            request.carmen,
            "no ODOM, FLASER, RLASER or ROBOTLASER1 lines: nothing to import",
        )
        .into());
    }
    if from_scans {
        tracing::warn!(
            "{}: no ODOM lines: the odometry is the poses logged with the scans",
            request.carmen.display()
        );
    }
    let start_s = odometry[0]
        .t_s
        .min(scans.first().map_or(f64::INFINITY, |s| s.t_s));
    let end_s = odometry[odometry.len() - 1]
        .t_s
        .max(scans.last().map_or(f64::NEG_INFINITY, |s| s.t_s));
    let shift = |poses: Vec<StampedPose>| -> Vec<StampedPose> {
        poses
            .into_iter()
            .map(|p| StampedPose {
                t_s: p.t_s - start_s,
                pose: p.pose,
            })
            .collect()
    };
    let layout = &request.as_sonar;
    let (sonar, unseen) = sonar_readings(&scans, layout, start_s);
    let corrected = request
        .carmen
        .file_name()
        .is_some_and(|n| n.to_string_lossy().contains("corrected"));
    let ground_truth = corrected.then(|| shift(poses_of(&scans)));
    let odometry = shift(odometry);
    let grid = GridConfig::fitted(ground_truth.as_deref().unwrap_or(&odometry), layout)
        .unwrap_or_else(|| {
            tracing::warn!(
                "{}: the run spans over 1 km: run.yaml keeps the paper's grid; set mapping.grid",
                request.carmen.display()
            );
            GridConfig::default()
        });
    let summary = ImportSummary {
        log: request.carmen.display().to_string(),
        odometry_poses: odometry.len(),
        scans: scans.len(),
        other_lines: log.other_lines,
        start_s,
        duration_s: end_s - start_s,
        odometry_reordered: reordered,
        odometry_dropped: dropped,
        readings: sonar.len(),
        echoes: sonar.iter().filter(|r| r.range_m.is_some()).count(),
        sensors_unseen: unseen,
        ground_truth: ground_truth.is_some(),
        grid_origin_m: grid.origin_m,
        grid_cells: [grid.width_cells, grid.height_cells],
    };
    let run = RunDataset {
        meta: RunMeta {
            format: RUN_FORMAT.into(),
            robot: RobotDescription {
                sonar: layout.clone(),
                rig: None,
                robot_from_left: None,
            },
            world: None,
            mapping: Some(MappingConfig {
                grid: grid.clone(),
                ..MappingConfig::default()
            }),
            notes: format!(
                "imported from {} by stereotag import: each laser scan as the {} sonar ring (the \
                 nearest return in each cone); times from the log's first time stamp, {start_s} s{}",
                request.carmen.display(),
                layout.name,
                if corrected {
                    "; the ground truth is the corrected log's scan poses"
                } else {
                    ""
                }
            ),
        },
        odometry,
        sonar,
        stereo: Vec::new(),
        ground_truth,
    };
    let dir = OutputDir::create(request.out, request.force)?;
    io::save_run(&dir.path(""), &run)?;
    io::save_json(&dir.path("import.json"), &summary)?;
    dir.commit()?;
    tracing::info!(
        "imported {}: {} odometry poses, {} scans over {:.0} s -> {} readings ({} echoes) of {}{}; grid {} x {} cells from ({:.1}, {:.1}) m -> {}",
        request.carmen.display(),
        summary.odometry_poses,
        summary.scans,
        summary.duration_s,
        summary.readings,
        summary.echoes,
        layout.name,
        if summary.ground_truth { ", ground truth" } else { "" },
        grid.width_cells,
        grid.height_cells,
        grid.origin_m[0],
        grid.origin_m[1],
        request.out.display()
    );
    Ok((run, summary))
}

/// Poses in time order: those earlier than one before them by up to
/// [`io::REORDER_TOLERANCE_S`] re-ordered, those further back left out, both counted.
struct TimeOrdered {
    poses: Vec<StampedPose>,
    reordered: usize,
    dropped: usize,
    first_dropped_s: f64,
}

fn time_ordered(logged: Vec<StampedPose>) -> TimeOrdered {
    let mut latest = f64::NEG_INFINITY;
    let mut out = TimeOrdered {
        poses: Vec::with_capacity(logged.len()),
        reordered: 0,
        dropped: 0,
        first_dropped_s: f64::NAN,
    };
    for p in logged {
        if p.t_s < latest - io::REORDER_TOLERANCE_S {
            if out.dropped == 0 {
                out.first_dropped_s = p.t_s;
            }
            out.dropped += 1;
            continue;
        }
        if p.t_s < latest {
            out.reordered += 1;
        }
        latest = latest.max(p.t_s);
        out.poses.push(p);
    }
    out.poses.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    out
}

/// The poses logged with the scans.
fn poses_of(scans: &[LaserScan]) -> Vec<StampedPose> {
    scans
        .iter()
        .map(|s| StampedPose {
            t_s: s.t_s,
            pose: s.pose,
        })
        .collect()
}

/// Each scan as one reading per sonar whose beam axis the laser sees: the nearest laser return
/// inside the sonar's cone, measured from the sonar, or no echo when none is within its range.
/// Also the sensors no scan sees.
fn sonar_readings(
    scans: &[LaserScan],
    layout: &SonarLayout,
    start_s: f64,
) -> (Vec<SonarReading>, Vec<usize>) {
    let mut readings = Vec::new();
    let mut seen = vec![false; layout.sensors.len()];
    for scan in scans {
        // The returns in the robot frame.
        let points: Vec<[f64; 2]> = scan
            .ranges_m
            .iter()
            .enumerate()
            .filter(|(_, &r)| r > 0.0)
            .map(|(i, &r)| {
                let a = scan.start_rad + i as f64 * scan.step_rad;
                let p = scan
                    .laser_in_robot
                    .transform_point(nalgebra::Point2::new(r * a.cos(), r * a.sin()));
                [p.x, p.y]
            })
            .collect();
        let fov = field_of_view(scan);
        for (k, sensor) in layout.sensors.iter().enumerate() {
            if !fov.sees(sensor.bearing_rad) {
                continue;
            }
            seen[k] = true;
            let nearest = points
                .iter()
                .filter_map(|p| {
                    let (dx, dy) = (p[0] - sensor.x_m, p[1] - sensor.y_m);
                    let off = crate::geometry::wrap_angle(dy.atan2(dx) - sensor.bearing_rad);
                    (off.abs() <= 0.5 * layout.cone_rad).then(|| dx.hypot(dy))
                })
                .fold(f64::INFINITY, f64::min);
            readings.push(SonarReading {
                t_s: scan.t_s - start_s,
                sensor: k,
                range_m: (nearest <= layout.max_range_m).then_some(nearest),
            });
        }
    }
    let unseen = (0..seen.len()).filter(|&k| !seen[k]).collect();
    (readings, unseen)
}

/// The bearings a scan covers, in the robot frame.
struct FieldOfView {
    /// The middle bearing.
    middle_rad: f64,
    /// Half the width.
    half_rad: f64,
    /// The step between two ranges.
    step_rad: f64,
}

impl FieldOfView {
    /// Whether a beam axis at `bearing_rad` is in view, to a step of the laser's.
    fn sees(&self, bearing_rad: f64) -> bool {
        crate::geometry::wrap_angle(bearing_rad - self.middle_rad).abs()
            <= self.half_rad + self.step_rad + 1e-9
    }
}

fn field_of_view(scan: &LaserScan) -> FieldOfView {
    let width = scan.step_rad * scan.ranges_m.len().saturating_sub(1) as f64;
    FieldOfView {
        middle_rad: scan.laser_in_robot.theta + scan.start_rad + 0.5 * width,
        half_rad: 0.5 * width.abs(),
        step_rad: scan.step_rad.abs(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;

    fn scan(ranges: Vec<f64>) -> LaserScan {
        let n = ranges.len();
        LaserScan {
            t_s: 10.0,
            start_rad: -std::f64::consts::FRAC_PI_2,
            step_rad: std::f64::consts::PI / (n - 1) as f64,
            ranges_m: ranges,
            pose: Pose2::new(0.0, 0.0, 0.0),
            laser_in_robot: Pose2::new(0.0, 0.0, 0.0),
            line: 1,
        }
    }

    #[test]
    fn each_sonar_takes_the_nearest_return_in_its_cone() {
        // 181 beams, 1 degree apart: a wall 1.5 m ahead, one beam at 10 degrees left at 0.9 m.
        let mut ranges = vec![30.0; 181];
        for r in &mut ranges[75..=105] {
            *r = 1.5;
        }
        ranges[100] = 0.9;
        let layout = SonarLayout::frontal5();
        let (readings, unseen) = sonar_readings(&[scan(ranges)], &layout, 4.0);
        assert!(unseen.is_empty());
        assert_eq!(readings.len(), 5);
        let ahead = readings.iter().find(|r| r.sensor == 2).unwrap();
        assert_eq!(ahead.t_s, 6.0);
        // The sonar sits 0.2 m ahead of the centre: the 0.9 m return at 10 degrees is its nearest.
        let expect = {
            let (x, y) = (
                0.9 * 10f64.to_radians().cos(),
                0.9 * 10f64.to_radians().sin(),
            );
            (x - 0.2).hypot(y)
        };
        assert!((ahead.range_m.unwrap() - expect).abs() < 1e-9);
        // The side sonars see only the far returns: no echo within 2.1 m.
        assert!(readings
            .iter()
            .find(|r| r.sensor == 0)
            .unwrap()
            .range_m
            .is_none());
    }

    #[test]
    fn sonars_behind_a_front_laser_are_left_out() {
        let layout = SonarLayout::pioneer16();
        let (readings, unseen) = sonar_readings(&[scan(vec![3.0; 181])], &layout, 0.0);
        // The eight front sonars (bearings -90..90 degrees) are seen, the rear ones not (the two
        // rear side sonars at +-90 degrees face the laser's edges and count as seen).
        assert_eq!(readings.len() + unseen.len(), 16);
        assert!(unseen
            .iter()
            .all(|&k| layout.sensors[k].bearing_rad.cos() < 0.0));
    }
}
