//! The survey end to end over a run: the online filter, the offline pass, the tail held to the
//! walls, and the map rebuilt from the corrected trajectory, its corners matched with the
//! landmarks.

use crate::dataset::RunDataset;
use crate::fusion::{
    associate, hold_tail_to_walls, run_offline_anchored, run_offline_sonar, run_offline_walls,
    run_online, FuseConfig, Landmark, Observations, OdometryCalibration, OfflineResult,
    OnlineResult, SonarInput,
};
use crate::progress::timed;
use crate::sonar::grid::{GridError, OccupancyMap};
use crate::sonar::map::{
    counting_map, counting_map_along, layout_walls, map_trajectory, MappingConfig, SonarMap,
};
use crate::visual::sightings::TagSighting;
use crate::visual::vo::VisualTurn;
use std::collections::BTreeMap;

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
    /// Where the run's odometry frame lies in the survey's, when the survey is solved in another
    /// frame than its start's (anchors): the run's odometry was moved by it before the survey.
    pub frame_from_odometry: Option<crate::geometry::Pose2>,
}

/// How a survey is made.
#[derive(Debug, Clone, Copy)]
pub struct SurveySettings<'a> {
    /// The grid and Hough settings of the maps.
    pub mapping: &'a MappingConfig,
    /// The fusion settings.
    pub fuse: &'a FuseConfig,
    /// The same robot's odometry errors found by an earlier survey: the online filter predicts
    /// with them until it finds the run's own.
    pub calibration: Option<OdometryCalibration>,
    /// Known tag poses, held as priors in the offline pass (the run's odometry already in their
    /// frame: see [`crate::fusion::anchor_frame`]); empty for a survey in its start's frame.
    pub anchors: &'a [crate::fusion::Anchor],
}

/// Runs the survey over a run, its raw map (the grid and features with the odometry's poses),
/// its tag sightings and the turns its cameras measured: online filter, offline pass, the tail
/// after the last sighting held to the walls, and the map rebuilt from the corrected poses.
pub fn survey(
    run: &RunDataset,
    raw: SonarMap,
    sightings: &[TagSighting],
    visual: &[VisualTurn],
    settings: &SurveySettings<'_>,
) -> Result<Survey, GridError> {
    // The floor the raw map used (following the run's sampling), for every map after it.
    let mapping = &settings.mapping.for_run(&run.sonar_log(), &run.odometry);
    let fuse = settings.fuse;
    let obs = Observations {
        odometry: &run.odometry,
        sightings,
        visual,
    };
    let mut timings_s = BTreeMap::new();
    let times = &mut timings_s;
    let online = timed("fuse_online", times, || {
        run_online(&obs, &raw.features_online, fuse, settings.calibration)
    });
    let online_map = timed("map_online", times, || {
        counting_map_along(&run.sonar_log(), &online.trajectory, mapping)
    })?;
    // With no sighting and no visual turn, only the sonar can correct the odometry.
    let sonar_only = online.accepted.is_empty() && visual.is_empty() && settings.anchors.is_empty();
    let mut offline = if sonar_only && fuse.sonar_scan_match && !run.sonar.is_empty() {
        let sonar = SonarInput {
            readings: &run.sonar,
            layout: &run.meta.robot.sonar,
            walls: &[],
        };
        timed("fuse_sonar", times, || {
            run_offline_sonar(&obs, &online, fuse, &sonar, &mapping.grid)
        })
    } else {
        timed("fuse_offline", times, || {
            run_offline_anchored(&obs, &online, fuse, None, settings.anchors)
        })
    };
    if fuse.walls_between_tags {
        offline = timed("fuse_walls", times, || {
            walls_pass(run, &obs, &online, offline, settings, mapping)
        })?;
    }
    if fuse.hold_tail_to_walls {
        timed("fuse_tail", times, || {
            hold_tail(run, sightings, visual, &online, &mut offline, mapping, fuse)
        })?;
    }
    let corrected = timed("map_corrected", times, || {
        map_trajectory(&run.sonar_log(), &offline.trajectory, mapping)
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
        frame_from_odometry: None,
    })
}

/// [`run_offline_walls`] after a first offline pass, with the walls of all the run's readings
/// placed along its trajectory.
fn walls_pass(
    run: &RunDataset,
    obs: &Observations<'_>,
    online: &OnlineResult,
    offline: OfflineResult,
    settings: &SurveySettings<'_>,
    // The settings following the run's sampling ([`MappingConfig::for_run`]).
    mapping: &MappingConfig,
) -> Result<OfflineResult, GridError> {
    let layout = &run.meta.robot.sonar;
    let readings = run.placed_readings(&offline.trajectory);
    let walls = walls_of(layout, &readings, mapping)?;
    let sonar = SonarInput {
        readings: &run.sonar,
        layout,
        walls: &walls,
    };
    let held = run_offline_walls(
        obs,
        online,
        &offline,
        settings.fuse,
        settings.anchors,
        &sonar,
    );
    tracing::info!(
        "walls between tags: {} ranges off {} walls; the solution {} ({} of {} sightings consistent, {} before)",
        held.wall_ranges,
        walls.len(),
        match held.kept {
            crate::fusion::OfflineKept::Solution => "is kept",
            _ => "explains fewer sightings and is not kept",
        },
        held.sightings_consistent[1],
        held.sightings,
        offline.sightings_consistent[1]
    );
    Ok(match held.kept {
        crate::fusion::OfflineKept::Solution => held,
        _ => offline,
    })
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
) -> Result<(), GridError> {
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
    let walls = walls_of(
        layout,
        &readings,
        &mapping.for_run(&run.sonar_log(), &run.odometry),
    )?;
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

/// The wall faces of placed readings: their counting grid, then the layout's wall fit.
fn walls_of(
    layout: &crate::sonar::SonarLayout,
    readings: &[crate::sonar::PlacedReading],
    mapping: &MappingConfig,
) -> Result<Vec<crate::sonar::walls::WallSegment>, GridError> {
    let grid = counting_map(layout, readings, mapping)?;
    Ok(layout_walls(layout, readings, &grid, &mapping.walls))
}
