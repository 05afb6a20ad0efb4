//! The survey's recording: the 3D scene, the maps, the cameras with their detections, the
//! error plots and the report, with its default layout.

use super::draw::*;
use super::layout::{column, row, tabs, Layout, View};
use super::palette;
use super::sonar::{log_features, log_growing_grid, log_hough};
use super::{Recorder, SurveyScene, VizError, POSE_SAMPLE_S};
use crate::fusion::{Nis, TagSighting};
use crate::geometry::{pose_at, pose_within, StampedPose};
use crate::sonar::grid::OccupancyMap;
use nalgebra::Matrix3;
use rerun::blueprint::components::PlayState;
use std::collections::BTreeMap;

/// The default layout of a survey: the top-down map (with the 3D scene, the online map and the
/// Hough accumulator in tabs), the error plots over the whole run and the report on top; the
/// stereo pair below, when the run has pictures (a run without keeps the whole height for the
/// rest).
fn layout(frame: &MapFrame, tag_frame: Option<&TagFrame>, pictures: bool) -> Layout {
    let map_view = |name: &str, origin: &str| frame.view(name, origin);
    let scene = frame
        .scene_view("Scene (3D)")
        .with_contents(["+ /world/**", "+ /landmarks/**"]);
    let maps = tabs([
        map_view("Map", "/map/corrected").into(),
        scene.into(),
        map_view("Online map", "/map/online").into(),
        View::spatial_2d("Hough accumulator", "/map/hough").into(),
    ]);
    let errors = tabs([
        View::time_series("Position error", "/metrics")
            .with_contents([
                "+ /metrics/position_error_m/online",
                "+ /metrics/position_error_m/offline",
                "+ /metrics/online_sigma_m",
            ])
            .whole_run("time")
            .into(),
        View::time_series("Odometry error", "/metrics/position_error_m")
            .whole_run("time")
            .into(),
        View::time_series("Tag NIS", "/metrics/tag_nis")
            .whole_run("time")
            .into(),
        View::time_series("Turn error (cameras vs wheels)", "/metrics/turn_deg")
            .whole_run("time")
            .into(),
        View::text_log("Online re-solves", "/events").into(),
    ]);
    let report = View::text_document("Report", "/report");
    // Each camera opens on the picture with the most tags (a copy of it, whatever the time
    // cursor), the picture at the time cursor in the next tab.
    let camera = |side: &str| {
        let origin = format!("/world/robot/{side}/image");
        let live = View::spatial_2d(&format!("{side} camera at the cursor"), &origin);
        match tag_frame {
            Some(f) => tabs([
                View::spatial_2d(
                    &format!(
                        "{side} camera, frame {} at {:.1} s (tags {})",
                        f.frame, f.t_s, f.tags
                    ),
                    &format!("/tag_frame/{side}"),
                )
                .into(),
                live.into(),
            ]),
            None => live.into(),
        }
    };
    let top = row([maps, errors, report.into()], &[0.46, 0.32, 0.22]);
    Layout {
        root: if pictures {
            column(
                [top, row([camera("left"), camera("right")], &[])],
                &[0.6, 0.4],
            )
        } else {
            top
        },
        timeline: "time",
        play: PlayState::Following,
    }
}

/// The picture with the most tags in it, the largest in the picture among equals.
struct TagFrame {
    /// Its index in the run's stereo pairs.
    frame: usize,
    /// Its time, seconds.
    t_s: f64,
    /// The tags' ids, as a list.
    tags: String,
}

impl TagFrame {
    fn find(scene: &SurveyScene<'_>) -> Option<Self> {
        // Per picture: its tags and their area in the left image, pixels².
        let mut by_frame: BTreeMap<usize, (Vec<u32>, f64)> = BTreeMap::new();
        for s in scene.sightings {
            let entry = by_frame.entry(s.frame).or_default();
            entry.0.push(s.id);
            entry.1 += s.corners_px.map_or(0.0, |(left, _)| quad_area(&left));
        }
        let (&frame, (ids, _)) = by_frame.iter().max_by(|a, b| {
            (a.1 .0.len(), a.1 .1)
                .partial_cmp(&(b.1 .0.len(), b.1 .1))
                .unwrap_or(std::cmp::Ordering::Equal)
                // The first of equals.
                .then(b.0.cmp(a.0))
        })?;
        let t_s = scene.run.stereo.get(frame)?.t_s;
        let tags = ids
            .iter()
            .map(u32::to_string)
            .collect::<Vec<_>>()
            .join(", ");
        Some(Self { frame, t_s, tags })
    }
}

/// A stereo pair (JPEG bytes) under `{prefix}/left/image` and `{prefix}/right/image` with the
/// tags' outlines and ids on each; `still`: static, else at the current time.
fn log_picture(
    rec: &rerun::RecordingStream,
    prefix: &str,
    pair: Option<&(Vec<u8>, Vec<u8>)>,
    tags: &[&TagSighting],
    still: bool,
) -> Result<(), VizError> {
    let log = |path: String, what: &dyn rerun::AsComponents| {
        if still {
            rec.log_static(path, what)
        } else {
            rec.log(path, what)
        }
    };
    for (side, index) in [("left", 0usize), ("right", 1usize)] {
        if let Some(pair) = pair {
            let jpeg = if index == 0 { &pair.0 } else { &pair.1 };
            log(
                format!("{prefix}/{side}/image"),
                &rerun::EncodedImage::from_file_contents(jpeg.clone()),
            )?;
        }
        let outlines: Vec<Vec<[f32; 2]>> = tags
            .iter()
            .filter_map(|s| s.corners_px.as_ref())
            .map(|c| {
                let c = if index == 0 { &c.0 } else { &c.1 };
                let mut v: Vec<[f32; 2]> = c.iter().map(|p| f32s(*p)).collect();
                v.push(f32s(c[0]));
                v
            })
            .collect();
        log(
            format!("{prefix}/{side}/image/tags"),
            &rerun::LineStrips2D::new(outlines)
                .with_labels(tags.iter().map(|s| format!("tag {}", s.id)))
                .with_colors([palette::DETECTION])
                .with_radii([rerun::Radius::new_ui_points(1.5)]),
        )?;
    }
    Ok(())
}

/// The area of a quadrilateral (shoelace), pixels².
fn quad_area(c: &[[f64; 2]; 4]) -> f64 {
    let twice: f64 = (0..4)
        .map(|i| {
            let (a, b) = (c[i], c[(i + 1) % 4]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum();
    0.5 * twice.abs()
}

impl Recorder {
    /// Logs a whole survey.
    pub fn log_survey(&self, scene: &SurveyScene<'_>) -> Result<(), VizError> {
        let rec = self.stream();
        let frame = MapFrame::new(&scene.survey.corrected.counting);
        let tag_frame = TagFrame::find(scene);
        layout(&frame, tag_frame.as_ref(), !scene.run.stereo.is_empty()).send(rec)?;
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        log_world(rec, scene.world)?;
        log_trajectories(rec, scene)?;
        log_landmarks(rec, scene)?;
        log_sonar_and_grid(rec, scene, &frame)?;
        log_cameras(rec, scene, tag_frame.as_ref())?;
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
                .with_labels([format!("corner {} votes", c.votes)])
                .with_show_labels(false),
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
    frame: &MapFrame,
) -> Result<(), VizError> {
    let s = scene.survey;
    log_hough(rec, "map/hough", &s.raw.accumulator)?;
    for (name, features) in [
        ("raw", &s.raw.features_offline),
        ("corrected", &s.corrected.features_offline),
    ] {
        log_features(rec, name, features)?;
    }
    log_corrected_map(rec, scene, frame)?;
    // The online grid: the readings placed with the online poses.
    log_growing_grid(
        rec,
        scene.run,
        &s.online.trajectory,
        &scene.mapping.grid,
        frame,
        "map/online",
    )
}

/// The top-down map: the corrected grid with every trajectory, the Hough features, the surveyed
/// walls and the landmarks, and a legend beside it; the online trajectory on the online map.
fn log_corrected_map(
    rec: &rerun::RecordingStream,
    scene: &SurveyScene<'_>,
    frame: &MapFrame,
) -> Result<(), VizError> {
    let s = scene.survey;
    let map = &frame.map;
    let mut lines: Vec<(&str, &[StampedPose], rerun::Color)> = vec![
        ("odometry", &scene.run.odometry, palette::ODOMETRY),
        ("online", &s.online.trajectory, palette::ONLINE),
        ("offline", &s.offline.trajectory, palette::OFFLINE),
    ];
    if let Some(gt) = &scene.run.ground_truth {
        lines.insert(0, ("ground truth", gt, palette::GROUND_TRUTH));
    }
    log_map_trajectories(rec, "map/corrected/trajectories", map, &lines)?;
    log_map_trajectories(
        rec,
        "map/online",
        map,
        &[("trajectory", &s.online.trajectory, palette::ONLINE)],
    )?;
    rec.log_static(
        "map/corrected/features",
        &map_features(map, &s.corrected.features_offline),
    )?;
    log_map_landmarks(rec, scene, map)?;
    log_legend(rec, "map/corrected/legend", map, &map_legend(&lines, true))?;
    rec.log_static("map/corrected/grid", &map_image(map))?;
    log_surveyed_walls(rec, &s.corrected.walls, Some(("map/corrected", map)))
}

/// The landmarks on the map: a dot, the 3-sigma ellipse of the position and the tag's number.
fn log_map_landmarks(
    rec: &rerun::RecordingStream,
    scene: &SurveyScene<'_>,
    map: &OccupancyMap,
) -> Result<(), VizError> {
    let landmarks = &scene.survey.landmarks;
    let ellipses: Vec<Vec<[f32; 2]>> = landmarks
        .iter()
        .map(|l| {
            let c = &l.covariance_m2;
            ellipse_2d([[c[0][0], c[0][1]], [c[1][0], c[1][1]]])
                .into_iter()
                .map(|[dx, dy]| map_pixel(map, l.position_m[0] + dx, l.position_m[1] + dy))
                .collect()
        })
        .collect();
    rec.log_static(
        "map/corrected/landmarks/covariance",
        &rerun::LineStrips2D::new(ellipses).with_colors([palette::LANDMARK_COVARIANCE]),
    )?;
    rec.log_static(
        "map/corrected/landmarks",
        &rerun::Points2D::new(
            landmarks
                .iter()
                .map(|l| map_pixel(map, l.position_m[0], l.position_m[1])),
        )
        .with_labels(landmarks.iter().map(|l| {
            let c = &l.covariance_m2;
            let sigma_mm = 1e3 * (c[0][0].max(c[1][1])).max(0.0).sqrt();
            format!("tag {} ±{:.0} mm", l.id, 3.0 * sigma_mm)
        }))
        .with_colors([palette::FUSED])
        .with_radii([1.0f32]),
    )?;
    Ok(())
}

fn log_cameras(
    rec: &rerun::RecordingStream,
    scene: &SurveyScene<'_>,
    tag_frame: Option<&TagFrame>,
) -> Result<(), VizError> {
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
        let tags = by_frame.get(&k).map(Vec::as_slice).unwrap_or(&[]);
        log_picture(rec, "world/robot", pair.as_ref(), tags, false)?;
        if tag_frame.is_some_and(|f| f.frame == k) {
            log_picture(rec, "tag_frame", pair.as_ref(), tags, true)?;
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

/// Each plotted series' name and colour, the trajectories' colours as on the map.
fn log_survey_series(rec: &rerun::RecordingStream) -> Result<(), VizError> {
    log_series_styles(
        rec,
        &[
            (
                "metrics/position_error_m/odometry",
                "odometry",
                palette::ODOMETRY,
            ),
            ("metrics/position_error_m/online", "online", palette::ONLINE),
            (
                "metrics/position_error_m/offline",
                "offline",
                palette::OFFLINE,
            ),
            (
                "metrics/online_sigma_m",
                "online σ (filter's own)",
                palette::SIGMA,
            ),
            ("metrics/tag_nis", "tag NIS", palette::FUSED),
            (
                "metrics/turn_deg/visual_error",
                "cameras' turn error",
                palette::OFFLINE,
            ),
            (
                "metrics/turn_deg/wheels_error",
                "wheels' turn error",
                palette::ODOMETRY,
            ),
            (
                "metrics/turn_deg/visual_sigma",
                "cameras' turn σ",
                palette::SIGMA,
            ),
        ],
    )?;
    Ok(())
}

fn log_errors(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    log_survey_series(rec)?;
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
        let Some(gt) = truth.and_then(|t| pose_within(t, p.t_s)) else {
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

/// The online filter's position error over its own sigma, median over the run; `None` without
/// the truth.
fn error_over_sigma(scene: &SurveyScene<'_>) -> Option<f64> {
    let truth = scene.run.ground_truth.as_deref()?;
    let online = &scene.survey.online;
    let mut ratios: Vec<f64> = online
        .trajectory
        .iter()
        .zip(&online.sigma_m)
        .filter(|(_, s)| **s > 0.0)
        .filter_map(|(p, s)| {
            let gt = pose_within(truth, p.t_s)?;
            Some((p.pose.x - gt.x).hypot(p.pose.y - gt.y) / s)
        })
        .collect();
    if ratios.is_empty() {
        return None;
    }
    ratios.sort_by(f64::total_cmp);
    Some(ratios[ratios.len() / 2])
}

/// The report's opening lines: the figures a reader looks for first, and how to read the plots.
fn at_a_glance(scene: &SurveyScene<'_>) -> String {
    let mut md = String::from("## At a glance\n\n");
    let ate = scene.scores.truth.as_ref().map(|t| t.ate_m);
    if let Some(crate::metrics::TrajectoryErrors {
        odometry: Some(o),
        online: Some(on),
        offline: Some(off),
    }) = ate
    {
        md.push_str(&format!(
            "Position error (ATE): odometry **{:.3} m**, online **{:.3} m**, offline **{:.3} m**.\n\n",
            o, on, off
        ));
    }
    md.push_str(&format!(
        "{} landmarks surveyed.\n\n",
        scene.survey.landmarks.len()
    ));
    let offline = &scene.survey.offline;
    if let Some([before, after]) = offline.sonar_agreement {
        md.push_str(&if offline.kept == crate::fusion::OfflineKept::Nothing {
            format!(
                "No tags and no visual turns: the {}'s own correction made its ranges agree \
                 with one another only {:.0}% → {:.0}%, so it is not kept: the offline \
                 trajectory is the odometry.\n\n",
                scene.run.ranging().name(),
                100.0 * before,
                100.0 * after
            )
        } else {
            format!(
                "No tags and no visual turns: the {} corrected the odometry ({}; its ranges \
                 agree with one another {:.0}% along the odometry, {:.0}% along the \
                 correction{}).\n\n",
                scene.run.ranging().name(),
                match offline.sonar_matches {
                    0 => format!(
                        "the walls' directions alone: a sonar slid along a wall at {} of {} \
                         keyframes, and the walls run at right angles",
                        offline.sonar_wall_directions, offline.keyframes
                    ),
                    m => format!(
                        "the latest matched the older readings at {m} of {} keyframes{}{}",
                        offline.keyframes,
                        match offline.sonar_wall_directions {
                            0 => String::new(),
                            d => format!(
                                ", predicted along headings {d} walls' directions corrected"
                            ),
                        },
                        if offline.sonar_turns_from_walls {
                            ", along the turn scale and heading drift the walls' directions gave"
                        } else {
                            ""
                        }
                    ),
                },
                100.0 * before,
                100.0 * after,
                if offline.sonar_wheel_distance && offline.sonar_matches > 0 {
                    ", which takes the wheels' distance as right: the distance scale estimated \
                     did not make the ranges agree clearly better"
                } else {
                    ""
                }
            )
        });
    }
    if let Some(r) = error_over_sigma(scene) {
        md.push_str(&format!(
            "The plot's *online σ* is the filter's own 1-σ position uncertainty (its longest \
             axis), not an error: on this run the online error is {:.2} σ at the median, so the \
             filter is {} (its noise settings are in `stereotag config --default`).\n\n",
            r,
            if r < 0.5 {
                "cautious: it believes itself less than it could"
            } else if r > 2.0 {
                "over-confident"
            } else {
                "consistent"
            }
        ));
    }
    // The same words as on stderr.
    if !scene.warnings.is_empty() {
        md.push_str("## Warnings\n\n");
        for w in scene.warnings {
            md.push_str(&format!("- {w}\n"));
        }
        md.push('\n');
    }
    md
}

fn log_report(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    let mut md = metrics_markdown("stereotag survey", scene.metrics);
    md.insert_str(md.find("| value").unwrap_or(0), &at_a_glance(scene));
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
