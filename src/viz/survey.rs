//! The survey's recording: the 3D scene, the maps, the cameras with their detections, the
//! error plots and the report, with its default layout.

use super::draw::*;
use super::palette;
use super::{Recorder, SurveyScene, VizError, GRID_SNAPSHOT_S, POSE_SAMPLE_S};
use crate::fusion::{Nis, Survey, TagSighting};
use crate::geometry::{pose_at, Pose2, StampedPose};
use crate::sonar::grid::{CountingGrid, OccupancyGrid};
use crate::sonar::hough::{Accumulator, Feature};
use nalgebra::Matrix3;
use rerun::blueprint as bp;
use std::collections::BTreeMap;

/// The default layout of a survey: the 3D scene and the map on top, the stereo pair and the time
/// series below, the report beside.
pub(super) fn blueprint() -> bp::Blueprint {
    let scene = bp::Spatial3DView::new("Scene")
        .with_origin("/world")
        .with_contents(["+ /world/**", "+ /landmarks/**"]);
    let maps = bp::Tabs::new([
        bp::Spatial2DView::new("Online map")
            .with_origin("/map/online")
            .into(),
        bp::Spatial2DView::new("Corrected map")
            .with_origin("/map/corrected")
            .into(),
        bp::Spatial2DView::new("Hough accumulator")
            .with_origin("/map/hough")
            .into(),
    ]);
    let left = bp::Spatial2DView::new("Left camera").with_origin("/world/robot/left/image");
    let right = bp::Spatial2DView::new("Right camera").with_origin("/world/robot/right/image");
    let errors = bp::Tabs::new([
        bp::TimeSeriesView::new("Position error")
            .with_origin("/metrics")
            .with_contents([
                "+ /metrics/position_error_m/**",
                "+ /metrics/online_sigma_m",
            ])
            .into(),
        bp::TimeSeriesView::new("Tag NIS")
            .with_origin("/metrics/tag_nis")
            .into(),
        bp::TimeSeriesView::new("Turn error (cameras vs wheels)")
            .with_origin("/metrics/turn_deg")
            .into(),
        bp::TextLogView::new("Online re-solves")
            .with_origin("/events")
            .into(),
    ]);
    let report = bp::TextDocumentView::new("Report").with_origin("/report");
    bp::Blueprint::new(
        bp::Vertical::new([
            bp::Horizontal::new([scene.into(), maps.into(), report.into()])
                .with_column_shares([0.45, 0.35, 0.2])
                .into(),
            bp::Horizontal::new([left.into(), right.into(), errors.into()]).into(),
        ])
        .with_row_shares([0.6, 0.4]),
    )
    .with_time_panel(following_time_panel())
}

impl Recorder {
    /// Logs a whole survey.
    pub fn log_survey(&self, scene: &SurveyScene<'_>) -> Result<(), VizError> {
        let rec = self.stream();
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        log_world(rec, scene.world)?;
        log_trajectories(rec, scene)?;
        log_landmarks(rec, scene)?;
        log_sonar_and_grid(rec, scene)?;
        log_cameras(rec, scene)?;
        log_errors(rec, scene)?;
        log_report(rec, scene)?;
        Ok(())
    }
}

fn log_trajectories(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    let s = scene.survey;
    let mut lines: Vec<(&str, &[StampedPose], rerun::Color)> = vec![
        ("odometry", &scene.run.odometry, palette::ODOMETRY),
        ("online", &s.online.trajectory, palette::ONLINE),
        ("offline", &s.offline.trajectory, palette::OFFLINE),
    ];
    if let Some(gt) = &scene.run.ground_truth {
        lines.push(("ground_truth", gt, palette::GROUND_TRUTH));
    }
    log_trajectory_lines(rec, &lines)?;
    // The robot moved by the online estimate.
    log_robot(rec, &s.online.trajectory)
}

fn log_landmarks(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    for l in &scene.survey.landmarks {
        let path = log_landmark(rec, l)?;
        if let Some(c) = l.matched_corner {
            rec.log_static(
                format!("{path}/association"),
                &rerun::LineStrips3D::new([vec![
                    f32s(l.position_m),
                    [c.x_m as f32, c.y_m as f32, 0.0],
                ]])
                .with_colors([palette::ASSOCIATION])
                .with_labels([format!("corner {} votes", c.votes)]),
            )?;
        }
    }
    for c in &scene.survey.online.conflicts {
        rec.log_static(
            format!("landmarks/conflicts/tag_{}", c.id),
            &rerun::Points3D::new([[c.seen_at_m[0] as f32, c.seen_at_m[1] as f32, 0.5]])
                .with_labels([format!("tag {} {}", c.id, c.kind)])
                .with_colors([palette::GATED_OUT])
                .with_radii([0.06f32]),
        )?;
    }
    // Each fused sighting in the world, at its time, placed with the offline pose.
    for (k, s) in scene.sightings.iter().enumerate() {
        let Some(pose) = pose_at(&scene.survey.offline.trajectory, s.t_s) else {
            continue;
        };
        let p = pose.transform_point(nalgebra::Point2::new(
            s.position_in_robot_m[0],
            s.position_in_robot_m[1],
        ));
        rec.set_duration_secs("time", s.t_s);
        rec.set_time_sequence("frame", s.frame as i64);
        let fused = scene.survey.online.accepted.contains(&k);
        rec.log(
            "world/sightings",
            &rerun::Points3D::new([[p.x as f32, p.y as f32, s.position_in_robot_m[2] as f32]])
                .with_labels([format!("tag {}", s.id)])
                .with_colors([if fused {
                    palette::FUSED
                } else {
                    palette::GATED_OUT
                }])
                .with_radii([0.025f32]),
        )?;
    }
    rec.reset_time();
    Ok(())
}

fn log_sonar_and_grid(
    rec: &rerun::RecordingStream,
    scene: &SurveyScene<'_>,
) -> Result<(), VizError> {
    let s = scene.survey;
    log_hough(rec, &s.raw.accumulator)?;
    for (name, features) in [
        ("raw", &s.raw.features_offline),
        ("corrected", &s.corrected.features_offline),
    ] {
        log_features(rec, name, features)?;
    }
    log_corrected_map(rec, s)?;
    log_growing_grid(rec, scene)
}

/// The final Hough accumulator as an image, votes on a log scale.
fn log_hough(rec: &rerun::RecordingStream, acc: &Accumulator) -> Result<(), VizError> {
    let max = acc.votes.iter().copied().max().unwrap_or(1).max(1) as f64;
    let pixels: Vec<u8> = acc
        .votes
        .iter()
        .map(|&v| (255.0 * (1.0 + v as f64).ln() / (1.0 + max).ln()).round() as u8)
        .collect();
    rec.log_static(
        "map/hough",
        &rerun::Image::from_l8(pixels, [acc.n_phi as u32, acc.n_rho as u32]),
    )?;
    Ok(())
}

/// The Hough corners and edges in the 3D scene, coloured by kind.
fn log_features(
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

/// The 2D maps: the online and offline trajectories over the corrected grid, with its features
/// and walls.
fn log_corrected_map(rec: &rerun::RecordingStream, s: &Survey) -> Result<(), VizError> {
    let map = &s.corrected.counting;
    for (name, trajectory, color) in [
        ("online", &s.online.trajectory, palette::ONLINE),
        ("corrected", &s.offline.trajectory, palette::OFFLINE),
    ] {
        let traj: Vec<[f32; 2]> = trajectory
            .iter()
            .map(|p| map_pixel(map, p.pose.x, p.pose.y))
            .collect();
        rec.log_static(
            format!("map/{name}/trajectory"),
            &rerun::LineStrips2D::new([traj]).with_colors([color]),
        )?;
    }
    let features = &s.corrected.features_offline;
    rec.log_static(
        "map/corrected/features",
        &rerun::Points2D::new(features.iter().map(|f| map_pixel(map, f.x_m, f.y_m)))
            .with_colors(
                features
                    .iter()
                    .map(|f| feature_color(f.kind))
                    .collect::<Vec<_>>(),
            )
            .with_radii([1.0f32]),
    )?;
    rec.log_static("map/corrected/grid", &map_image(map))?;
    log_surveyed_walls(rec, &s.corrected.walls, Some(map))
}

/// The online grid (readings placed with the online poses) as it grows, with the sonar cones.
fn log_growing_grid(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    let layout = &scene.run.meta.robot.sonar;
    let readings = scene.run.placed_readings(&scene.survey.online.trajectory);
    let Ok(mut grid) = CountingGrid::new(
        scene.mapping.grid.clone(),
        layout.cone_rad,
        layout.max_range_m,
    ) else {
        return Ok(());
    };
    let log_grid = |grid: &CountingGrid, t_s: f64| -> Result<(), VizError> {
        let map = grid.map();
        rec.set_duration_secs("time", t_s);
        rec.log("world/grid", &grid_map(&map))?;
        rec.log("map/online/grid", &map_image(&map))?;
        Ok(())
    };
    let mut beams = StripBatches::new(rec, "world/sonar/beams");
    let mut next_snapshot = f64::NEG_INFINITY;
    for r in &readings {
        grid.insert(r);
        if let Some(range) = r.range_m {
            let cone = cone_outline(&r.world_from_sensor, range, layout.cone_rad);
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

fn log_cameras(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    let Some(rig) = scene.rig else {
        return Ok(());
    };
    let robot_from_right = rig.robot_from_left * rig.left_from_right();
    for (name, cam, pose) in [
        ("left", &rig.left, rig.robot_from_left),
        ("right", &rig.right, robot_from_right),
    ] {
        rec.log_static(format!("world/robot/{name}"), &transform(&pose))?;
        rec.log_static(
            format!("world/robot/{name}/image"),
            &rerun::Pinhole::from_focal_length_and_resolution(
                [cam.fx as f32, cam.fy as f32],
                [cam.width as f32, cam.height as f32],
            )
            .with_principal_point([cam.cx as f32, cam.cy as f32])
            .with_image_plane_distance(0.3),
        )?;
    }
    let mut by_frame: BTreeMap<usize, Vec<&TagSighting>> = BTreeMap::new();
    for s in scene.sightings {
        by_frame.entry(s.frame).or_default().push(s);
    }
    for (k, entry) in scene.run.stereo.iter().enumerate() {
        let pair = scene.images.get(k).cloned().flatten();
        rec.set_duration_secs("time", entry.t_s);
        rec.set_time_sequence("frame", k as i64);
        if let Some((left, right)) = pair {
            rec.log(
                "world/robot/left/image",
                &rerun::EncodedImage::from_file_contents(left),
            )?;
            rec.log(
                "world/robot/right/image",
                &rerun::EncodedImage::from_file_contents(right),
            )?;
        }
        let tags = by_frame.get(&k).map(Vec::as_slice).unwrap_or(&[]);
        for (side, corners_of) in [("left", 0usize), ("right", 1usize)] {
            let outlines: Vec<Vec<[f32; 2]>> = tags
                .iter()
                .filter_map(|s| s.corners_px.as_ref())
                .map(|c| {
                    let c = if corners_of == 0 { &c.0 } else { &c.1 };
                    let mut v: Vec<[f32; 2]> = c.iter().map(|p| f32s(*p)).collect();
                    v.push(f32s(c[0]));
                    v
                })
                .collect();
            rec.log(
                format!("world/robot/{side}/image/tags"),
                &rerun::LineStrips2D::new(outlines)
                    .with_labels(tags.iter().map(|s| format!("{}", s.id)))
                    .with_colors([palette::DETECTION]),
            )?;
        }
        // Triangulated centres in the left camera frame, with their covariance.
        let left_from_robot = rig.robot_from_left.inverse();
        let mut centres = Vec::new();
        let mut radii = Vec::new();
        let mut rotations = Vec::new();
        for s in tags {
            let p = left_from_robot * nalgebra::Point3::from(s.position_in_robot_m);
            let r = left_from_robot.rotation.to_rotation_matrix();
            let c = Matrix3::from_fn(|i, j| s.covariance_m2[i][j]);
            let c = r.matrix() * c * r.matrix().transpose();
            let (rad, q) = ellipsoid(&std::array::from_fn(|i| std::array::from_fn(|j| c[(i, j)])));
            centres.push(f32s([p.x, p.y, p.z]));
            radii.push(rad);
            rotations.push(q);
        }
        rec.log(
            "world/robot/left/triangulated",
            &rerun::Ellipsoids3D::from_centers_and_half_sizes(centres, radii)
                .with_quaternions(rotations)
                .with_colors([palette::TRIANGULATED]),
        )?;
    }
    rec.reset_time();
    Ok(())
}

fn log_errors(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    let s = scene.survey;
    let truth = scene.run.ground_truth.as_deref();
    let mut next = f64::NEG_INFINITY;
    for (i, p) in scene.run.odometry.iter().enumerate() {
        if p.t_s < next {
            continue;
        }
        next = p.t_s + POSE_SAMPLE_S;
        rec.set_duration_secs("time", p.t_s);
        if let Some(sigma) = s.online.sigma_m.get(i) {
            rec.log("metrics/online_sigma_m", &rerun::Scalars::single(*sigma))?;
        }
        let Some(gt) = truth.and_then(|t| pose_at(t, p.t_s)) else {
            continue;
        };
        let err = |q: Option<&StampedPose>| q.map(|q| (q.pose.x - gt.x).hypot(q.pose.y - gt.y));
        for (name, e) in [
            ("odometry", err(Some(p))),
            ("online", err(s.online.trajectory.get(i))),
            ("offline", err(s.offline.trajectory.get(i))),
        ] {
            if let Some(e) = e {
                rec.log(
                    format!("metrics/position_error_m/{name}"),
                    &rerun::Scalars::single(e),
                )?;
            }
        }
    }
    for &Nis { t_s: t, value: nis } in &s.online.nis {
        rec.set_duration_secs("time", t);
        rec.log("metrics/tag_nis", &rerun::Scalars::single(nis))?;
    }
    // Each turn the cameras measured, at the picture it ends: its error against the truth beside
    // the wheels' over the same stretch, and its sigma.
    let odometry = &scene.run.odometry;
    for v in &s.visual {
        rec.set_duration_secs("time", v.to_t_s);
        rec.log(
            "metrics/turn_deg/visual_sigma",
            &rerun::Scalars::single(v.sigma_rad.to_degrees()),
        )?;
        let turn = |poses: &[StampedPose]| {
            Some(crate::geometry::wrap_angle(
                pose_at(poses, v.to_t_s)?.theta - pose_at(poses, v.from_t_s)?.theta,
            ))
        };
        let Some(truth) = truth.and_then(turn) else {
            continue;
        };
        let error = |turn: f64| crate::geometry::wrap_angle(turn - truth).to_degrees();
        rec.log(
            "metrics/turn_deg/visual_error",
            &rerun::Scalars::single(error(v.turn_rad)),
        )?;
        if let Some(wheels) = turn(odometry) {
            rec.log(
                "metrics/turn_deg/wheels_error",
                &rerun::Scalars::single(error(wheels)),
            )?;
        }
    }
    for r in &s.online.resolves {
        let c = &r.odometry_calibration;
        rec.set_duration_secs("time", r.t_s);
        rec.log(
            "events/online_resolve",
            &rerun::TextLog::new(format!(
                "online re-solve of the run so far: pose moved {:.3} m and turned {:.2} deg; \
                 odometry from now on: turn scale {:+.2}%, heading drift {:+.4} rad/m, \
                 distance scale {:+.2}%",
                r.moved_m,
                r.turned_rad.to_degrees(),
                100.0 * c.turn_scale_error,
                c.heading_drift_rad_per_m,
                100.0 * c.distance_scale_error
            ))
            .with_level(rerun::TextLogLevel::INFO),
        )?;
    }
    rec.reset_time();
    Ok(())
}

fn log_report(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    let mut md = metrics_markdown("stereotag survey", scene.metrics);
    md.push_str("\n## Landmarks\n\n| tag | x m | y m | z m | sightings | corner |\n|---|---|---|---|---|---|\n");
    for l in &scene.survey.landmarks {
        md.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.3} | {} | {} |\n",
            l.id,
            l.position_m[0],
            l.position_m[1],
            l.position_m[2],
            l.observations,
            l.matched_corner.map_or("none".to_string(), |c| format!(
                "({:.2}, {:.2})",
                c.x_m, c.y_m
            ))
        ));
    }
    for c in &scene.survey.online.conflicts {
        md.push_str(&format!(
            "\n**tag {} {}**: landmark at ({:.2}, {:.2}) m, {} sightings at ({:.2}, {:.2}) m from t = {:.1} s\n",
            c.id, c.kind, c.landmark_m[0], c.landmark_m[1], c.sightings, c.seen_at_m[0], c.seen_at_m[1], c.first_t_s
        ));
    }
    rec.log_static("report", &rerun::TextDocument::from_markdown(md))?;
    Ok(())
}
