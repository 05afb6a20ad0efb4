//! CARMEN logs (Radish and the classic 2D SLAM data sets) as runs: their laser as the run's
//! lidar, or turned into sonar-like readings so the paper's method runs on real buildings.

use super::{
    check_odometry_against_truth, lidar_of, sonar_readings, time_ordered, LidarImport,
    OdometryAgainstTruth,
};
use crate::dataset::{RobotDescription, RunDataset, RunMeta, RUN_FORMAT};
use crate::geometry::StampedPose;
use crate::io::carmen::{read_carmen, LaserScan};
use crate::io::{self, OutputDir};
use crate::sonar::grid::GridConfig;
use crate::sonar::map::MappingConfig;
use crate::sonar::SonarLayout;
use crate::workflow::Result;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// What to import.
#[derive(Debug, Clone)]
pub struct CarmenRequest<'a> {
    /// The CARMEN log (`.gz` for gzip).
    pub carmen: &'a Path,
    /// The run directory to write.
    pub out: &'a Path,
    /// The sonar ring the laser is turned into; `None` keeps it a laser (the run's lidar).
    pub as_sonar: Option<SonarLayout>,
    /// Replace the output directory if it exists.
    pub force: bool,
}

/// What was read and written (also `import.json` in the run directory).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CarmenSummary {
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
    /// The laser as the run's lidar (without `--as-sonar`).
    pub lidar: Option<LidarImport>,
    /// Whether the scans' poses were written as the ground truth (a `*-corrected` log).
    pub ground_truth: bool,
    /// With a ground truth, how far the odometry strays from it: [`OdometryAgainstTruth`].
    pub odometry_against_ground_truth: Option<OdometryAgainstTruth>,
    /// The grid fitted to the run: lower-left corner (m) and size (cells).
    pub grid_origin_m: [f64; 2],
    /// Cells across and up.
    pub grid_cells: [usize; 2],
}

/// Imports a CARMEN log as a run: odometry from the `ODOM` lines (the scans' odometry fields
/// when there are none), the laser as the run's lidar (the log's largest range taken as the
/// laser's no-return value: 81.91 m on a SICK, 50 m in aces), or with `as_sonar` each scan as
/// one reading per sonar of that ring (the nearest return in the sonar's cone, none within its
/// range: no echo), the scans' poses as the ground truth of a `*-corrected` log, and a grid of
/// the paper's 20 cm cells fitted to the run. Times start at the log's first time stamp.
pub fn import_carmen(request: &CarmenRequest<'_>) -> Result<(RunDataset, CarmenSummary)> {
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
    let (layout, sonar, unseen, lidar) = match &request.as_sonar {
        Some(layout) => {
            let (sonar, unseen) = sonar_readings(&scans, layout, start_s);
            (layout.clone(), sonar, unseen, None)
        }
        None => {
            let largest = scans
                .iter()
                .flat_map(|s| s.ranges_m.iter().copied())
                .filter(|r| r.is_finite())
                .fold(0.0, f64::max);
            let lidar = lidar_of(&scans, 0.0, largest, start_s).ok_or_else(|| {
                io::IoError::content(
                    request.carmen,
                    "no FLASER, RLASER or ROBOTLASER1 lines: no laser to import",
                )
            })?;
            if lidar.2.scans_left_out > 0 {
                tracing::warn!(
                    "{}: {} scans of another laser (another mounting, field of view or beam count than the first scan's) left out",
                    request.carmen.display(),
                    lidar.2.scans_left_out
                );
            }
            let empty = SonarLayout {
                name: "none".into(),
                sensors: Vec::new(),
                ..SonarLayout::frontal5()
            };
            (empty, Vec::new(), Vec::new(), Some(lidar))
        }
    };
    let layout = &layout;
    let corrected = request
        .carmen
        .file_name()
        .is_some_and(|n| n.to_string_lossy().contains("corrected"));
    let ground_truth = corrected.then(|| shift(poses_of(&scans)));
    let odometry = shift(odometry);
    let against_truth = check_odometry_against_truth(
        (
            &odometry,
            &format!("{}: the odometry", request.carmen.display()),
        ),
        ground_truth
            .as_deref()
            .map(|truth| (truth, "the corrected poses")),
        "a corrected log's ODOM lines are reset to the corrected pose at each scan, so this \
         odometry does not drift as wheels do, and its steps carry the correction's jitter from \
         scan to scan (scripts/drift_odometry.py RUN OUT drifts it as wheels would)",
    );
    let ranging = match &lidar {
        Some((l, _, _)) => l.beam_layout(),
        None => layout.clone(),
    };
    let grid = GridConfig::fitted(ground_truth.as_deref().unwrap_or(&odometry), &ranging)
        .unwrap_or_else(|| {
            tracing::warn!(
                "{}: the run spans over 1 km: run.yaml keeps the paper's grid; set mapping.grid",
                request.carmen.display()
            );
            GridConfig::default()
        });
    let summary = CarmenSummary {
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
        lidar: lidar.as_ref().map(|l| l.2.clone()),
        ground_truth: ground_truth.is_some(),
        odometry_against_ground_truth: against_truth,
        grid_origin_m: grid.origin_m,
        grid_cells: [grid.width_cells, grid.height_cells],
    };
    let run = RunDataset {
        meta: RunMeta {
            format: RUN_FORMAT.into(),
            robot: RobotDescription {
                sonar: layout.clone(),
                lidar: lidar.as_ref().map(|l| l.0.clone()),
                ranging: None,
                rig: None,
                robot_from_left: None,
            },
            world: None,
            mapping: Some(MappingConfig {
                grid: grid.clone(),
                ..MappingConfig::default()
            }),
            notes: format!(
                "imported from {} by stereotag import: {}; times from the log's first time stamp, {start_s} s{}",
                request.carmen.display(),
                match &request.as_sonar {
                    Some(l) => format!("each laser scan as the {} sonar ring (the nearest return in each cone)", l.name),
                    None => "the laser as the run's lidar".into(),
                },
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
        lidar: lidar.map(|l| l.1).unwrap_or_default(),
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
        summary.lidar.as_ref().map_or(summary.readings, |l| l.scans * l.beams),
        summary.lidar.as_ref().map_or(summary.echoes, |l| l.returns),
        if summary.lidar.is_some() { "the lidar" } else { &layout.name },
        if summary.ground_truth { ", ground truth" } else { "" },
        grid.width_cells,
        grid.height_cells,
        grid.origin_m[0],
        grid.origin_m[1],
        request.out.display()
    );
    Ok((run, summary))
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
