//! The localisation's recording: the surveyed map, the trajectories, the sightings and ranges
//! fused, the error and sigma over time.

use super::draw::*;
use super::layout::{column, row, tabs, Layout, View};
use super::palette;
use super::{LocalizeScene, Recorder, VizError, POSE_SAMPLE_S};
use crate::geometry::{pose_at, pose_within, StampedPose};
use crate::sonar::grid::OccupancyMap;
use rerun::blueprint::components::PlayState;

/// The default layout of a localisation: the 3D scene (surveyed tags and walls, the trajectories,
/// the robot with the sightings and the sonar ranges it fused) seen from above the home, the error
/// and sigma over the whole run and the report.
fn layout(scene: &LocalizeScene<'_>) -> Layout {
    let points = scene
        .result
        .trajectory
        .iter()
        .map(|p| [p.pose.x, p.pose.y])
        .chain(
            scene
                .landmarks
                .iter()
                .map(|l| [l.position_m[0], l.position_m[1]]),
        );
    let view =
        View::spatial_3d("Scene", "/world").with_contents(["+ /world/**", "+ /landmarks/**"]);
    let view = match bounding_box(points) {
        Some((lo, hi)) => {
            let centre = [
                0.5 * (lo[0] + hi[0]) as f32,
                0.5 * (lo[1] + hi[1]) as f32,
                0.0,
            ];
            let size = ((hi[0] - lo[0]).max(hi[1] - lo[1]) as f32).max(2.0);
            view.eye([centre[0], centre[1] - 0.9 * size, 1.1 * size], centre)
        }
        None => view,
    };
    let plot = View::time_series("Position error and sigma", "/metrics")
        .with_contents(["+ /metrics/position_error_m/**", "+ /metrics/sigma_m"])
        .whole_run("time");
    let plot = match error_plot_top(scene) {
        Some(top) => plot.value_range(0.0, top),
        None => plot,
    };
    let errors = tabs([
        plot.into(),
        View::time_series("Distance since a sighting", "/metrics/since_sighting_m")
            .whole_run("time")
            .into(),
    ]);
    let report = View::text_document("Report", "/report");
    Layout {
        root: row(
            [view.into(), column([errors, report.into()], &[0.5, 0.5])],
            &[0.62, 0.38],
        ),
        timeline: "time",
        play: PlayState::Following,
    }
}

impl Recorder {
    /// Logs a localisation of a later run against a survey.
    pub fn log_localization(&self, scene: &LocalizeScene<'_>) -> Result<(), VizError> {
        let rec = self.stream();
        layout(scene).send(rec)?;
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        log_world(rec, scene.world)?;
        log_surveyed_walls(rec, scene.walls, None)?;
        if let Some(returns) = scene.returns {
            log_surveyed_returns(rec, returns)?;
        }
        for l in scene.landmarks {
            log_landmark(rec, l)?;
        }
        log_trajectories(rec, scene)?;
        log_sightings(rec, scene)?;
        log_ranges(rec, scene)?;
        log_scans(rec, scene)?;
        log_wall_fixes(rec, scene)?;
        log_errors(rec, scene)?;
        rec.reset_time();
        log_report(rec, scene)
    }
}

/// The odometry (and its calibrated version), the localised trajectory, the truth and the robot.
fn log_trajectories(
    rec: &rerun::RecordingStream,
    scene: &LocalizeScene<'_>,
) -> Result<(), VizError> {
    let r = scene.result;
    let mut lines: Vec<(&str, &[StampedPose], rerun::Color)> = vec![
        ("odometry", &scene.run.odometry, palette::ODOMETRY),
        ("localized", &r.trajectory, palette::OFFLINE),
    ];
    if let Some(calibrated) = scene.calibrated_odometry {
        lines.push(("odometry_calibrated", calibrated, palette::ONLINE));
    }
    if let Some(gt) = &scene.run.ground_truth {
        lines.push(("ground_truth", gt, palette::GROUND_TRUTH));
    }
    log_trajectory_lines(rec, &lines)?;
    log_robot(rec, &r.trajectory)
}

/// Sightings at their time, placed with the localised pose: fused green, gated out red, tags the
/// survey does not hold grey.
fn log_sightings(rec: &rerun::RecordingStream, scene: &LocalizeScene<'_>) -> Result<(), VizError> {
    let r = scene.result;
    for (k, s) in scene.sightings.iter().enumerate() {
        let Some(pose) = pose_at(&r.trajectory, s.t_s) else {
            continue;
        };
        let p = pose.transform_point(nalgebra::Point2::new(
            s.position_in_robot_m[0],
            s.position_in_robot_m[1],
        ));
        let (what, color) = if r.accepted.contains(&k) {
            ("fused", palette::FUSED)
        } else if r.rejected.contains(&k) {
            ("gated out", palette::GATED_OUT)
        } else {
            ("not surveyed", palette::NOT_SURVEYED)
        };
        rec.set_duration_secs("time", s.t_s);
        rec.log(
            "world/sightings",
            &rerun::Points3D::new([[p.x as f32, p.y as f32, s.position_in_robot_m[2] as f32]])
                .with_labels([format!("tag {} {what}", s.id)])
                .with_show_labels(false)
                .with_colors([color])
                .with_radii([0.025f32]),
        )?;
    }
    Ok(())
}

/// Where the pose was taken from the walls (the filter too unsure of it to match ranges one at
/// a time): the pose after the fix, at its time, in the surveyed walls' colour.
fn log_wall_fixes(rec: &rerun::RecordingStream, scene: &LocalizeScene<'_>) -> Result<(), VizError> {
    let r = scene.result;
    for &t in &r.wall_fixed_t_s {
        let Some(pose) = pose_at(&r.trajectory, t) else {
            continue;
        };
        rec.set_duration_secs("time", t);
        rec.log(
            "world/wall_fixes",
            &rerun::Points3D::new([[pose.x as f32, pose.y as f32, SONAR_Z_M]])
                .with_labels(["pose from the walls"])
                .with_colors([palette::SURVEYED_WALL])
                .with_radii([0.06f32]),
        )?;
    }
    Ok(())
}

/// The ranges matched with a surveyed wall, from the sensor along the beam axis: fused cyan,
/// gated out red.
fn log_ranges(rec: &rerun::RecordingStream, scene: &LocalizeScene<'_>) -> Result<(), VizError> {
    let r = scene.result;
    let layout = &scene.run.meta.robot.sonar;
    let mut batches = StripBatches::new(rec, "world/sonar/ranges");
    for &(i, fused) in &r.range_outcomes {
        let Some(reading) = scene.run.sonar.get(i) else {
            continue;
        };
        let (Some(range), Some(sensor), Some(pose)) = (
            reading.range_m,
            layout.sensors.get(reading.sensor),
            pose_at(&r.trajectory, reading.t_s),
        ) else {
            continue;
        };
        let o = pose.compose(&sensor.robot_from_sensor());
        let end = [o.x + range * o.theta.cos(), o.y + range * o.theta.sin()];
        let color = if fused {
            palette::RANGE_FUSED
        } else {
            palette::GATED_OUT
        };
        let line = vec![
            [o.x as f32, o.y as f32, SONAR_Z_M],
            [end[0] as f32, end[1] as f32, SONAR_Z_M],
        ];
        batches.push(reading.t_s, line, color)?;
    }
    batches.flush()
}

/// The survey's laser returns a lidar's scans were matched with: a point at each cell that holds
/// them, in the surveyed walls' colour.
fn log_surveyed_returns(rec: &rerun::RecordingStream, map: &OccupancyMap) -> Result<(), VizError> {
    let g = &map.geometry;
    let points: Vec<[f32; 3]> = (0..map.occupancy.len())
        .filter(|&i| map.is_occupied(i))
        .map(|i| {
            let [x, y] = g.centre(i % g.width, i / g.width);
            [x as f32, y as f32, SONAR_Z_M]
        })
        .collect();
    rec.log_static(
        "world/returns_surveyed",
        &rerun::Points3D::new(points)
            .with_colors([palette::SURVEYED_WALL])
            .with_radii([0.5 * g.resolution_m as f32]),
    )?;
    Ok(())
}

/// Each lidar scan matched with the survey's returns, at its time, placed with the localised
/// pose: fused cyan, gated out red (the latest one shows, lying on the survey's returns when
/// the pose is right).
fn log_scans(rec: &rerun::RecordingStream, scene: &LocalizeScene<'_>) -> Result<(), VizError> {
    let (r, readings) = (scene.result, &scene.run.sonar);
    let layout = &scene.run.meta.robot.sonar;
    for &(t, fused) in &r.scan_outcomes {
        let Some(pose) = pose_at(&r.trajectory, t) else {
            continue;
        };
        let first = readings.partition_point(|x| x.t_s < t);
        let points: Vec<[f32; 3]> = readings[first..]
            .iter()
            .take_while(|x| x.t_s == t)
            .filter_map(|x| {
                let range = layout.echo(x.range_m)?;
                let o = pose.compose(&layout.sensors.get(x.sensor)?.robot_from_sensor());
                let end = [o.x + range * o.theta.cos(), o.y + range * o.theta.sin()];
                Some([end[0] as f32, end[1] as f32, SONAR_Z_M])
            })
            .collect();
        let color = if fused {
            palette::RANGE_FUSED
        } else {
            palette::GATED_OUT
        };
        rec.set_duration_secs("time", t);
        rec.log(
            "world/lidar/scan",
            &rerun::Points3D::new(points)
                .with_colors([color])
                .with_radii([0.03f32]),
        )?;
    }
    Ok(())
}

/// The error against the truth (when known), the filter's sigma and the distance since the last
/// sighting, over time.
fn log_errors(rec: &rerun::RecordingStream, scene: &LocalizeScene<'_>) -> Result<(), VizError> {
    let odometry = if scene.calibrated_odometry.is_some() {
        "odometry (calibrated)"
    } else {
        "odometry"
    };
    log_series_styles(
        rec,
        &[
            (
                "metrics/position_error_m/localized",
                "localized",
                palette::OFFLINE,
            ),
            (
                "metrics/position_error_m/odometry",
                odometry,
                palette::ODOMETRY,
            ),
            ("metrics/sigma_m", "σ (filter's own)", palette::SIGMA),
            (
                "metrics/since_sighting_m",
                "distance since a sighting, m",
                palette::FUSED,
            ),
        ],
    )?;
    for p in plotted(scene) {
        rec.set_duration_secs("time", p.t_s);
        if let Some(sigma) = p.sigma_m {
            rec.log("metrics/sigma_m", &rerun::Scalars::single(sigma))?;
        }
        rec.log(
            "metrics/since_sighting_m",
            &rerun::Scalars::single(p.since_sighting_m),
        )?;
        if let Some(e) = p.localized_error_m {
            rec.log(
                "metrics/position_error_m/localized",
                &rerun::Scalars::single(e),
            )?;
        }
        if let Some(e) = p.odometry_error_m {
            rec.log(
                "metrics/position_error_m/odometry",
                &rerun::Scalars::single(e),
            )?;
        }
    }
    Ok(())
}

/// One plotted sample of the localisation ([`plotted`]).
struct Plotted {
    t_s: f64,
    /// The filter's sigma, once located.
    sigma_m: Option<f64>,
    since_sighting_m: f64,
    /// The errors against the truth: the localised pose's once located, the odometry's.
    localized_error_m: Option<f64>,
    odometry_error_m: Option<f64>,
}

/// The samples plotted, one every [`POSE_SAMPLE_S`]. Before an unknown start is located the pose
/// is a guess with a building-sized sigma: neither is plotted, so that the scale shows the rest.
fn plotted(scene: &LocalizeScene<'_>) -> Vec<Plotted> {
    let r = scene.result;
    let truth = scene.run.ground_truth.as_deref();
    let tracked = scene.calibrated_odometry.unwrap_or(&scene.run.odometry);
    let mut next = f64::NEG_INFINITY;
    let mut out = Vec::new();
    for (i, p) in r.trajectory.iter().enumerate() {
        if p.t_s < next {
            continue;
        }
        next = p.t_s + POSE_SAMPLE_S;
        let located = r.located.get(i).copied().unwrap_or(true);
        let gt = truth.and_then(|t| pose_within(t, p.t_s));
        out.push(Plotted {
            t_s: p.t_s,
            sigma_m: located.then(|| r.sigma_m[i]),
            since_sighting_m: r.since_sighting_m[i],
            localized_error_m: gt
                .filter(|_| located)
                .map(|gt| (p.pose.x - gt.x).hypot(p.pose.y - gt.y)),
            odometry_error_m: gt
                .zip(pose_at(tracked, p.t_s))
                .map(|(gt, o)| (o.x - gt.x).hypot(o.y - gt.y)),
        });
    }
    out
}

/// The top of the error plot: the largest error plotted, or without the truth twice the 95th
/// percentile of the sigma, so that a moment of a wide sigma (a far tag's first sighting places
/// the robot on an arc metres long) does not flatten the rest of the run.
fn error_plot_top(scene: &LocalizeScene<'_>) -> Option<f64> {
    let samples = plotted(scene);
    let errors = samples
        .iter()
        .flat_map(|p| [p.localized_error_m, p.odometry_error_m])
        .flatten()
        .fold(None, |m: Option<f64>, e| Some(m.map_or(e, |m| m.max(e))));
    let top = errors.or_else(|| {
        let mut sigmas: Vec<f64> = samples.iter().filter_map(|p| p.sigma_m).collect();
        sigmas.sort_by(f64::total_cmp);
        sigmas
            .get((0.95 * sigmas.len() as f64) as usize)
            .or(sigmas.last())
            .map(|s| 2.0 * s)
    })?;
    (top.is_finite() && top > 0.0).then_some(1.05 * top)
}

/// The figures and the error's growth with the distance since a sighting.
fn log_report(rec: &rerun::RecordingStream, scene: &LocalizeScene<'_>) -> Result<(), VizError> {
    let mut md = metrics_markdown("stereotag localize", scene.metrics);
    let matched = if scene.returns.is_some() {
        "the survey's lidar returns orange, the latest scan matched with them cyan (gated out red)"
    } else {
        "surveyed walls orange, the sonar ranges fused cyan (gated out red)"
    };
    let colours = format!(
        "In the scene: odometry red{}, localized green{}; {}{matched}{}.\n\n",
        if scene.calibrated_odometry.is_some() {
            ", calibrated with the survey yellow"
        } else {
            ""
        },
        if scene.run.ground_truth.is_some() {
            ", ground truth grey"
        } else {
            ""
        },
        if scene.landmarks.is_empty() {
            ""
        } else {
            "surveyed tags green dots, "
        },
        if scene.result.wall_fixed_t_s.is_empty() {
            ""
        } else {
            "; an orange dot where the pose was taken from the walls"
        }
    );
    let mut glance = String::from("## At a glance\n\n");
    for line in scene.summary {
        // A sentence each, as on stderr.
        let mut line = line.clone();
        if let Some(first) = line.get(..1) {
            line.replace_range(..1, &first.to_uppercase());
        }
        glance.push_str(&format!("{line}.\n\n"));
    }
    if !scene.warnings.is_empty() {
        glance.push_str("## Warnings\n\n");
        for w in scene.warnings {
            glance.push_str(&format!("- {w}\n"));
        }
        glance.push('\n');
    }
    md.insert_str(
        md.find("| value").unwrap_or(0),
        &format!("{glance}{colours}"),
    );
    md.push_str("\n## Error by distance since the last sighting\n\n| from m | to m | samples | sigma m | RMS error m |\n|---|---|---|---|---|\n");
    for b in scene.growth {
        md.push_str(&format!(
            "| {:.1} | {:.1} | {} | {:.3} | {} |\n",
            b.from_m,
            b.to_m,
            b.samples,
            b.mean_sigma_m,
            b.rms_error_m.map_or("-".into(), |e| format!("{e:.3}"))
        ));
    }
    rec.log_static("report", &rerun::TextDocument::from_markdown(md))?;
    Ok(())
}
