//! Recording to the Rerun viewer: the only module that imports rerun. Each stage hands it plain
//! data; it logs static things once (walls, cameras, landmarks) and everything else on the `time`
//! timeline (seconds of the run) and the `frame` sequence (stereo pairs), under entity paths that
//! mirror the stages (`world/walls`, `world/robot/left/image`, `world/sonar/beams`, `map/grid`,
//! `map/hough`, `landmarks/tag_7`, `metrics/...`), and sends a default layout with the recording.

use crate::dataset::RunDataset;
use crate::fusion::Survey;
use crate::fusion::{Landmark, LocalizeResult, TagSighting};
use crate::geometry::{pose_at, StampedPose};
use crate::metrics::GrowthBin;
use crate::sonar::grid::{CountingGrid, OccupancyGrid, OccupancyMap};
use crate::sonar::walls::WallSegment;
use crate::world::World;
use nalgebra::{Isometry3, Matrix3, Rotation3, UnitQuaternion};
use rerun::blueprint as bp;
use std::collections::BTreeMap;
use std::path::Path;

/// Errors of the recording.
#[derive(Debug, thiserror::Error)]
pub enum VizError {
    /// Rerun refused a sink or a log call.
    #[error("rerun: {0}")]
    Rerun(#[from] rerun::RecordingStreamError),
    /// The viewer could not be started.
    #[error("starting the rerun viewer: {0}")]
    Spawn(#[from] rerun::SpawnError),
    /// A bad `--connect` URL.
    #[error("--connect {url}: {message}")]
    Url {
        /// The URL given.
        url: String,
        /// Why it is wrong.
        message: String,
    },
    /// An image could not be encoded.
    #[error("encoding an image: {0}")]
    Jpeg(String),
}

/// Where a recording goes. Several may be combined.
#[derive(Debug, Clone, PartialEq)]
pub enum Sink {
    /// An `.rrd` file.
    Save(std::path::PathBuf),
    /// A new viewer process (the `rerun` executable on PATH).
    Spawn,
    /// A running viewer, e.g. `rerun+http://127.0.0.1:9876/proxy`.
    Connect(String),
}

/// An open recording.
pub struct Recorder {
    rec: rerun::RecordingStream,
}

/// JPEG quality of the camera images in the recording (ours: 60; the tags' cells and edges stay
/// clear in the viewer, and the sensor noise, which is most of what a higher quality spends its
/// bits and time on, is smoothed: the office demo's recording is 8.0 MB instead of 16.2 at 85).
pub const IMAGE_JPEG_QUALITY: u8 = 60;
/// Seconds of run time between grid snapshots (the issue asks for at most a few seconds).
pub const GRID_SNAPSHOT_S: f64 = 5.0;
/// Seconds between logged robot poses and error samples.
pub const POSE_SAMPLE_S: f64 = 0.5;
/// Ellipsoids are drawn at this many sigmas.
pub const ELLIPSOID_SIGMAS: f64 = 3.0;

impl Recorder {
    /// Opens a recording to the sinks, with the layout `blueprint` sent first.
    pub fn new(
        application: &'static str,
        sinks: &[Sink],
        blueprint: bp::Blueprint,
    ) -> Result<Self, VizError> {
        let mut boxed: Vec<Box<dyn rerun::sink::LogSink>> = Vec::new();
        for sink in sinks {
            match sink {
                Sink::Save(path) => {
                    boxed.push(Box::new(rerun::sink::FileSink::new(path).map_err(|e| {
                        VizError::Url {
                            url: path.display().to_string(),
                            message: e.to_string(),
                        }
                    })?))
                }
                Sink::Spawn => {
                    rerun::spawn(&rerun::SpawnOptions::default())?;
                    boxed.push(Box::new(rerun::sink::GrpcSink::new(
                        rerun::DEFAULT_CONNECT_URL.parse().map_err(
                            |e: rerun::external::re_uri::Error| VizError::Url {
                                url: rerun::DEFAULT_CONNECT_URL.into(),
                                message: e.to_string(),
                            },
                        )?,
                    )));
                }
                Sink::Connect(url) => boxed.push(Box::new(rerun::sink::GrpcSink::new(
                    url.parse()
                        .map_err(|e: rerun::external::re_uri::Error| VizError::Url {
                            url: url.clone(),
                            message: e.to_string(),
                        })?,
                ))),
            }
        }
        let rec = rerun::RecordingStreamBuilder::new(application)
            .with_blueprint(blueprint)
            .set_sinks(boxed)?;
        Ok(Self { rec })
    }

    /// Flushes everything to the sinks.
    pub fn finish(self) -> Result<(), VizError> {
        self.rec.flush_blocking().map_err(|e| VizError::Url {
            url: "sink".into(),
            message: e.to_string(),
        })?;
        Ok(())
    }

    /// The stream, for the other `log_*` functions of this module.
    fn stream(&self) -> &rerun::RecordingStream {
        &self.rec
    }
}

/// The default layout of a survey: the 3D scene and the map on top, the stereo pair and the time
/// series below, the report beside.
pub fn survey_blueprint() -> bp::Blueprint {
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

/// The time panel on the `time` timeline, following the end of the run (the finished map and
/// trajectories); scrub back to replay it.
fn following_time_panel() -> bp::TimePanel {
    bp::TimePanel::new()
        .with_timeline("time")
        .with_play_state(bp::components::PlayState::Following)
}

/// What a survey recording shows.
pub struct SurveyScene<'a> {
    /// The run.
    pub run: &'a RunDataset,
    /// The world, when known (walls and planned tags are drawn from it).
    pub world: Option<&'a World>,
    /// The survey.
    pub survey: &'a Survey,
    /// The sightings the survey used.
    pub sightings: &'a [TagSighting],
    /// The report's figures.
    pub metrics: &'a BTreeMap<String, f64>,
    /// The mapping settings (the online grid is rebuilt with them).
    pub mapping: &'a crate::sonar::map::MappingConfig,
    /// The stereo rig's cameras and mounting, when the run has pictures.
    pub rig: Option<&'a crate::camera::StereoRig>,
    /// Each stereo pair of the run as JPEG bytes (left, right) from [`jpeg_pair`], or `None`.
    pub images: &'a [Option<(Vec<u8>, Vec<u8>)>],
}

fn f32s<const N: usize>(v: [f64; N]) -> [f32; N] {
    v.map(|x| x as f32)
}

fn quaternion(r: &UnitQuaternion<f64>) -> rerun::Quaternion {
    rerun::Quaternion::from_xyzw([r.i as f32, r.j as f32, r.k as f32, r.w as f32])
}

fn transform(iso: &Isometry3<f64>) -> rerun::Transform3D {
    let t = iso.translation.vector;
    rerun::Transform3D::from_translation_rotation(f32s([t.x, t.y, t.z]), quaternion(&iso.rotation))
}

fn planar_transform(p: &crate::geometry::Pose2) -> rerun::Transform3D {
    let r = UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), p.theta);
    rerun::Transform3D::from_translation_rotation([p.x as f32, p.y as f32, 0.0], quaternion(&r))
}

fn strip(trajectory: &[StampedPose], z: f64) -> Vec<[f32; 3]> {
    trajectory
        .iter()
        .map(|p| [p.pose.x as f32, p.pose.y as f32, z as f32])
        .collect()
}

/// Pixel position in the map image (row 0 at the top) of a world point.
fn map_pixel(map: &OccupancyMap, x: f64, y: f64) -> [f32; 2] {
    let g = &map.geometry;
    [
        ((x - g.origin_m[0]) / g.resolution_m) as f32,
        (g.height as f64 - (y - g.origin_m[1]) / g.resolution_m) as f32,
    ]
}

/// The map as the paper shows it: inverse grey, unknown mid-grey; row 0 at the top.
fn map_image(map: &OccupancyMap) -> rerun::Image {
    let g = &map.geometry;
    let mut pixels = vec![0u8; g.width * g.height];
    for row in 0..g.height {
        for col in 0..g.width {
            let v = map.occupancy[row * g.width + col];
            pixels[(g.height - 1 - row) * g.width + col] = match v {
                Some(p) => (255.0 * (1.0 - p)).round().clamp(0.0, 255.0) as u8,
                None => 128,
            };
        }
    }
    rerun::Image::from_l8(pixels, [g.width as u32, g.height as u32])
}

/// The map as a ROS OccupancyGrid (0 free .. 100 occupied, 255 unknown) for the GridMap archetype.
fn feature_color(kind: crate::sonar::hough::FeatureKind) -> rerun::Color {
    match kind {
        crate::sonar::hough::FeatureKind::Corner => rerun::Color::from_rgb(255, 60, 200),
        crate::sonar::hough::FeatureKind::Edge => rerun::Color::from_rgb(60, 160, 255),
        crate::sonar::hough::FeatureKind::Unknown => rerun::Color::from_rgb(200, 200, 0),
    }
}

fn grid_map(map: &OccupancyMap) -> rerun::GridMap {
    let g = &map.geometry;
    let data: Vec<u8> = map
        .occupancy
        .iter()
        .map(|v| v.map_or(255, |p| (100.0 * p).round().clamp(0.0, 100.0) as u8))
        .collect();
    // GridMap rows run from the lower-left corner, as the map's.
    rerun::GridMap::new(
        data,
        rerun::components::ImageFormat::from_color_model(
            [g.width as u32, g.height as u32],
            rerun::ColorModel::L,
            rerun::ChannelDatatype::U8,
        ),
        g.resolution_m as f32,
    )
    .with_translation([g.origin_m[0] as f32, g.origin_m[1] as f32, -0.01])
    .with_colormap(rerun::components::Colormap::RvizMap)
}

/// A stereo pair compressed for the recording (compressing is most of a recording's cost, so the
/// survey does it alongside its single-threaded stages).
pub fn jpeg_pair(left: &image::GrayImage, right: &image::GrayImage) -> Option<(Vec<u8>, Vec<u8>)> {
    Some((jpeg(left).ok()?, jpeg(right).ok()?))
}

fn jpeg(img: &image::GrayImage) -> Result<Vec<u8>, VizError> {
    let mut bytes = Vec::new();
    let (Ok(w), Ok(h)) = (u16::try_from(img.width()), u16::try_from(img.height())) else {
        return Err(VizError::Jpeg(format!(
            "a {}x{} image is too large for JPEG",
            img.width(),
            img.height()
        )));
    };
    jpeg_encoder::Encoder::new(&mut bytes, IMAGE_JPEG_QUALITY)
        .encode(img.as_raw(), w, h, jpeg_encoder::ColorType::Luma)
        .map_err(|e| VizError::Jpeg(e.to_string()))?;
    Ok(bytes)
}

/// Radii (at [`ELLIPSOID_SIGMAS`]) and orientation of a covariance ellipsoid.
fn ellipsoid(cov: &[[f64; 3]; 3]) -> ([f32; 3], rerun::Quaternion) {
    let m = Matrix3::from_fn(|i, j| cov[i][j]);
    let eig = ((m + m.transpose()) * 0.5).symmetric_eigen();
    let mut axes = eig.eigenvectors;
    if axes.determinant() < 0.0 {
        axes.column_mut(2).neg_mut();
    }
    let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
    let radii = eig
        .eigenvalues
        .map(|v| (ELLIPSOID_SIGMAS * v.max(0.0).sqrt()).max(1e-3));
    (f32s([radii[0], radii[1], radii[2]]), quaternion(&r))
}

/// Logs a whole survey.
pub fn log_survey(recorder: &Recorder, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    let rec = recorder.stream();
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

fn log_world(rec: &rerun::RecordingStream, world: Option<&World>) -> Result<(), VizError> {
    let Some(world) = world else {
        return Ok(());
    };
    let walls: Vec<Vec<[f32; 3]>> = world
        .walls
        .iter()
        .map(|w| {
            let (a, b) = (w.segment.a, w.segment.b);
            let h = w.height_m as f32;
            vec![
                [a.x as f32, a.y as f32, 0.0],
                [b.x as f32, b.y as f32, 0.0],
                [b.x as f32, b.y as f32, h],
                [a.x as f32, a.y as f32, h],
                [a.x as f32, a.y as f32, 0.0],
            ]
        })
        .collect();
    rec.log_static(
        "world/walls",
        &rerun::LineStrips3D::new(walls)
            .with_colors([rerun::Color::from_rgb(150, 150, 150)])
            .with_radii([rerun::Radius::new_ui_points(1.0)]),
    )?;
    let planned: Vec<[f32; 3]> = world.tags.iter().map(|t| f32s(t.position_m)).collect();
    rec.log_static(
        "world/tags_planned",
        &rerun::Points3D::new(planned)
            .with_labels(world.tags.iter().map(|t| format!("planned {}", t.id)))
            .with_colors([rerun::Color::from_rgb(120, 120, 255)])
            .with_radii([0.03f32]),
    )?;
    let corners: Vec<[f32; 3]> = world
        .vertices
        .iter()
        .map(|v| [v.position.x as f32, v.position.y as f32, 0.0])
        .collect();
    rec.log_static(
        "world/corners_true",
        &rerun::Points3D::new(corners)
            .with_colors([rerun::Color::from_rgb(90, 90, 90)])
            .with_radii([0.02f32]),
    )?;
    Ok(())
}

fn log_trajectories(rec: &rerun::RecordingStream, scene: &SurveyScene<'_>) -> Result<(), VizError> {
    let s = scene.survey;
    let mut lines: Vec<(&str, &[StampedPose], [u8; 3])> = vec![
        ("odometry", &scene.run.odometry, [230, 80, 60]),
        ("online", &s.online.trajectory, [240, 180, 40]),
        ("offline", &s.offline.trajectory, [60, 200, 90]),
    ];
    if let Some(gt) = &scene.run.ground_truth {
        lines.push(("ground_truth", gt, [200, 200, 200]));
    }
    log_trajectory_lines(rec, &lines)?;
    // The robot moved by the online estimate.
    log_robot(rec, &s.online.trajectory)
}

/// Each trajectory as a line under `world/trajectories/NAME`, in its colour.
fn log_trajectory_lines(
    rec: &rerun::RecordingStream,
    lines: &[(&str, &[StampedPose], [u8; 3])],
) -> Result<(), VizError> {
    for (name, t, c) in lines {
        rec.log_static(
            format!("world/trajectories/{name}"),
            &rerun::LineStrips3D::new([strip(t, 0.02)])
                .with_colors([rerun::Color::from_rgb(c[0], c[1], c[2])])
                .with_radii([rerun::Radius::new_ui_points(1.5)])
                .with_labels([*name]),
        )?;
    }
    Ok(())
}

/// The robot, a disc outline with a heading tick, moved along `trajectory` on the `time`
/// timeline.
fn log_robot(rec: &rerun::RecordingStream, trajectory: &[StampedPose]) -> Result<(), VizError> {
    let mut outline: Vec<[f32; 3]> = (0..=24)
        .map(|k| {
            let a = k as f32 / 24.0 * std::f32::consts::TAU;
            [0.2 * a.cos(), 0.2 * a.sin(), 0.05]
        })
        .collect();
    outline.push([0.0, 0.0, 0.05]);
    rec.log_static(
        "world/robot/shape",
        &rerun::LineStrips3D::new([outline]).with_colors([rerun::Color::from_rgb(255, 255, 255)]),
    )?;
    let mut next = f64::NEG_INFINITY;
    for p in trajectory {
        if p.t_s < next {
            continue;
        }
        next = p.t_s + POSE_SAMPLE_S;
        rec.set_duration_secs("time", p.t_s);
        rec.log("world/robot", &planar_transform(&p.pose))?;
    }
    rec.reset_time();
    Ok(())
}

/// A landmark as a point and its covariance ellipsoid under `landmarks/tag_ID`; returns the path.
fn log_landmark(rec: &rerun::RecordingStream, l: &Landmark) -> Result<String, VizError> {
    let path = format!("landmarks/tag_{}", l.id);
    let (radii, q) = ellipsoid(&l.covariance_m2);
    rec.log_static(
        path.as_str(),
        &rerun::Points3D::new([f32s(l.position_m)])
            .with_labels([format!("tag {} ({} sightings)", l.id, l.observations)])
            .with_colors([rerun::Color::from_rgb(40, 220, 120)])
            .with_radii([0.04f32]),
    )?;
    rec.log_static(
        format!("{path}/covariance"),
        &rerun::Ellipsoids3D::from_centers_and_half_sizes([f32s(l.position_m)], [radii])
            .with_quaternions([q])
            .with_colors([rerun::Color::from_unmultiplied_rgba(40, 220, 120, 120)]),
    )?;
    Ok(path)
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
                .with_colors([rerun::Color::from_rgb(255, 0, 255)])
                .with_labels([format!("corner {} votes", c.votes)]),
            )?;
        }
    }
    for c in &scene.survey.online.conflicts {
        rec.log_static(
            format!("landmarks/conflicts/tag_{}", c.id),
            &rerun::Points3D::new([[c.seen_at_m[0] as f32, c.seen_at_m[1] as f32, 0.5]])
                .with_labels([format!("tag {} {}", c.id, c.kind)])
                .with_colors([rerun::Color::from_rgb(255, 40, 40)])
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
                    rerun::Color::from_rgb(40, 220, 120)
                } else {
                    rerun::Color::from_rgb(255, 40, 40)
                }])
                .with_radii([0.025f32]),
        )?;
    }
    rec.reset_time();
    Ok(())
}

/// The surveyed walls (what `localize` holds a later run's sonar to): in the scene a low line
/// along each face, and on `map` when given.
fn log_surveyed_walls(
    rec: &rerun::RecordingStream,
    walls: &[WallSegment],
    map: Option<&OccupancyMap>,
) -> Result<(), VizError> {
    let labels: Vec<String> = walls
        .iter()
        .map(|w| {
            format!(
                "wall {} readings, rms {:.1} cm",
                w.readings,
                100.0 * w.rms_m
            )
        })
        .collect();
    rec.log_static(
        "world/walls_surveyed",
        &rerun::LineStrips3D::new(walls.iter().map(|w| {
            let (a, b) = (w.from_m, w.to_m);
            [
                [a[0] as f32, a[1] as f32, 0.1],
                [b[0] as f32, b[1] as f32, 0.1],
            ]
        }))
        .with_colors([rerun::Color::from_rgb(255, 140, 0)])
        .with_radii([rerun::Radius::new_ui_points(2.5)])
        .with_labels(labels.clone())
        .with_show_labels(false),
    )?;
    if let Some(map) = map {
        rec.log_static(
            "map/corrected/walls",
            &rerun::LineStrips2D::new(walls.iter().map(|w| {
                [
                    map_pixel(map, w.from_m[0], w.from_m[1]),
                    map_pixel(map, w.to_m[0], w.to_m[1]),
                ]
            }))
            .with_colors([rerun::Color::from_rgb(255, 140, 0)])
            .with_labels(labels)
            .with_show_labels(false),
        )?;
    }
    Ok(())
}

fn log_sonar_and_grid(
    rec: &rerun::RecordingStream,
    scene: &SurveyScene<'_>,
) -> Result<(), VizError> {
    let s = scene.survey;
    let layout = &scene.run.meta.robot.sonar;
    let readings = scene.run.placed_readings(&s.online.trajectory);
    let Ok(mut grid) = CountingGrid::new(
        scene.mapping.grid.clone(),
        layout.cone_rad,
        layout.max_range_m,
    ) else {
        return Ok(());
    };
    // Hough accumulator and features: the final ones, static.
    let acc = &s.raw.accumulator;
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
    for (name, features) in [
        ("raw", &s.raw.features_offline),
        ("corrected", &s.corrected.features_offline),
    ] {
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
    }
    // The 2D maps: the online grid as it grows with the online trajectory, and the corrected grid
    // with its features and the offline trajectory.
    for (name, map, trajectory, color) in [
        (
            "online",
            &s.corrected.counting,
            &s.online.trajectory,
            [240, 180, 40],
        ),
        (
            "corrected",
            &s.corrected.counting,
            &s.offline.trajectory,
            [60, 200, 90],
        ),
    ] {
        let traj: Vec<[f32; 2]> = trajectory
            .iter()
            .map(|p| map_pixel(map, p.pose.x, p.pose.y))
            .collect();
        rec.log_static(
            format!("map/{name}/trajectory"),
            &rerun::LineStrips2D::new([traj])
                .with_colors([rerun::Color::from_rgb(color[0], color[1], color[2])]),
        )?;
    }
    let features = &s.corrected.features_offline;
    rec.log_static(
        "map/corrected/features",
        &rerun::Points2D::new(
            features
                .iter()
                .map(|f| map_pixel(&s.corrected.counting, f.x_m, f.y_m)),
        )
        .with_colors(
            features
                .iter()
                .map(|f| feature_color(f.kind))
                .collect::<Vec<_>>(),
        )
        .with_radii([1.0f32]),
    )?;
    rec.log_static("map/corrected/grid", &map_image(&s.corrected.counting))?;
    log_surveyed_walls(rec, &s.corrected.walls, Some(&s.corrected.counting))?;

    // The online grid (readings placed with the online poses) as it grows, and the sonar cones.
    let half = 0.5 * layout.cone_rad;
    let mut next_snapshot = f64::NEG_INFINITY;
    let mut batch: Vec<Vec<[f32; 3]>> = Vec::new();
    let mut batch_t = f64::NEG_INFINITY;
    let flush = |batch: &mut Vec<Vec<[f32; 3]>>, t: f64| -> Result<(), VizError> {
        if batch.is_empty() {
            return Ok(());
        }
        rec.set_duration_secs("time", t);
        rec.log(
            "world/sonar/beams",
            &rerun::LineStrips3D::new(std::mem::take(batch))
                .with_colors([rerun::Color::from_unmultiplied_rgba(0, 200, 255, 160)]),
        )?;
        Ok(())
    };
    for r in &readings {
        grid.insert(r);
        if let Some(range) = r.range_m {
            let o = r.world_from_sensor;
            let mut cone = vec![[o.x as f32, o.y as f32, 0.3]];
            for k in 0..=6 {
                let a = o.theta - half + layout.cone_rad * k as f64 / 6.0;
                cone.push([
                    (o.x + range * a.cos()) as f32,
                    (o.y + range * a.sin()) as f32,
                    0.3,
                ]);
            }
            cone.push([o.x as f32, o.y as f32, 0.3]);
            batch.push(cone);
        }
        if r.t_s >= batch_t + 1.0 {
            flush(&mut batch, r.t_s)?;
            batch_t = r.t_s;
        }
        if r.t_s >= next_snapshot {
            next_snapshot = r.t_s + GRID_SNAPSHOT_S;
            let map = grid.map();
            rec.set_duration_secs("time", r.t_s);
            rec.log("world/grid", &grid_map(&map))?;
            rec.log("map/online/grid", &map_image(&map))?;
        }
    }
    if let Some(last) = readings.last() {
        flush(&mut batch, last.t_s)?;
        let map = grid.map();
        rec.set_duration_secs("time", last.t_s);
        rec.log("world/grid", &grid_map(&map))?;
        rec.log("map/online/grid", &map_image(&map))?;
    }
    rec.reset_time();
    Ok(())
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
                    .with_colors([rerun::Color::from_rgb(40, 255, 120)]),
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
                .with_colors([rerun::Color::from_rgb(255, 200, 0)]),
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
    for (t, nis) in &s.online.nis {
        rec.set_duration_secs("time", *t);
        rec.log("metrics/tag_nis", &rerun::Scalars::single(*nis))?;
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
    let mut md = String::from("# stereotag survey\n\n| metric | value |\n|---|---|\n");
    for (k, v) in scene.metrics {
        md.push_str(&format!("| {k} | {v:.4} |\n"));
    }
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

/// The default layout of a localisation: the 3D scene (surveyed tags and walls, the trajectories,
/// the robot with the sightings and the sonar ranges it fused), the error and sigma over time and
/// the report.
pub fn localization_blueprint() -> bp::Blueprint {
    let scene = bp::Spatial3DView::new("Scene")
        .with_origin("/world")
        .with_contents(["+ /world/**", "+ /landmarks/**"]);
    let errors = bp::Tabs::new([
        bp::TimeSeriesView::new("Position error and sigma")
            .with_origin("/metrics")
            .with_contents(["+ /metrics/position_error_m/**", "+ /metrics/sigma_m"])
            .into(),
        bp::TimeSeriesView::new("Distance since a sighting")
            .with_origin("/metrics/since_sighting_m")
            .into(),
    ]);
    let report = bp::TextDocumentView::new("Report").with_origin("/report");
    bp::Blueprint::new(
        bp::Horizontal::new([
            scene.into(),
            bp::Vertical::new([errors.into(), report.into()]).into(),
        ])
        .with_column_shares([0.65, 0.35]),
    )
    .with_time_panel(following_time_panel())
}

/// What a localisation recording shows.
pub struct LocalizeScene<'a> {
    /// The run tracked.
    pub run: &'a RunDataset,
    /// The world, when known.
    pub world: Option<&'a World>,
    /// The run's odometry corrected with the survey's calibration, when the filter ran on that
    /// (else on the run's odometry as logged).
    pub calibrated_odometry: Option<&'a [StampedPose]>,
    /// The surveyed landmarks.
    pub landmarks: &'a [Landmark],
    /// The surveyed walls.
    pub walls: &'a [WallSegment],
    /// The run's tag sightings.
    pub sightings: &'a [TagSighting],
    /// The filter's result.
    pub result: &'a LocalizeResult,
    /// Error growth with distance since the last sighting.
    pub growth: &'a [GrowthBin],
    /// The report's figures.
    pub metrics: &'a BTreeMap<String, f64>,
}

/// Logs a localisation of a later run against a survey.
pub fn log_localization(recorder: &Recorder, scene: &LocalizeScene<'_>) -> Result<(), VizError> {
    let rec = recorder.stream();
    let r = scene.result;
    rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
    log_world(rec, scene.world)?;
    log_surveyed_walls(rec, scene.walls, None)?;
    for l in scene.landmarks {
        log_landmark(rec, l)?;
    }
    let mut lines: Vec<(&str, &[StampedPose], [u8; 3])> = vec![
        ("odometry", &scene.run.odometry, [230, 80, 60]),
        ("localized", &r.trajectory, [60, 200, 90]),
    ];
    if let Some(calibrated) = scene.calibrated_odometry {
        lines.push(("odometry_calibrated", calibrated, [240, 180, 40]));
    }
    if let Some(gt) = &scene.run.ground_truth {
        lines.push(("ground_truth", gt, [200, 200, 200]));
    }
    log_trajectory_lines(rec, &lines)?;
    log_robot(rec, &r.trajectory)?;

    // Sightings at their time, placed with the localised pose: fused green, gated out red, tags
    // the survey does not hold grey.
    for (k, s) in scene.sightings.iter().enumerate() {
        let Some(pose) = pose_at(&r.trajectory, s.t_s) else {
            continue;
        };
        let p = pose.transform_point(nalgebra::Point2::new(
            s.position_in_robot_m[0],
            s.position_in_robot_m[1],
        ));
        let (what, color) = if r.accepted.contains(&k) {
            ("fused", rerun::Color::from_rgb(40, 220, 120))
        } else if r.rejected.contains(&k) {
            ("gated out", rerun::Color::from_rgb(255, 40, 40))
        } else {
            ("not surveyed", rerun::Color::from_rgb(150, 150, 150))
        };
        rec.set_duration_secs("time", s.t_s);
        rec.log(
            "world/sightings",
            &rerun::Points3D::new([[p.x as f32, p.y as f32, s.position_in_robot_m[2] as f32]])
                .with_labels([format!("tag {} {what}", s.id)])
                .with_colors([color])
                .with_radii([0.025f32]),
        )?;
    }

    // The ranges matched with a surveyed wall, from the sensor along the beam axis, in batches
    // of a second: fused cyan, gated out red.
    let layout = &scene.run.meta.robot.sonar;
    let mut batch: (Vec<[[f32; 3]; 2]>, Vec<rerun::Color>) = (Vec::new(), Vec::new());
    let (mut batch_t, mut last_t) = (f64::NEG_INFINITY, 0.0);
    let flush = |batch: &mut (Vec<[[f32; 3]; 2]>, Vec<rerun::Color>), t: f64| {
        if batch.0.is_empty() {
            return Ok::<(), VizError>(());
        }
        rec.set_duration_secs("time", t);
        rec.log(
            "world/sonar/ranges",
            &rerun::LineStrips3D::new(std::mem::take(&mut batch.0))
                .with_colors(std::mem::take(&mut batch.1)),
        )?;
        Ok(())
    };
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
        if reading.t_s >= batch_t + 1.0 {
            flush(&mut batch, last_t)?;
            batch_t = reading.t_s;
        }
        last_t = reading.t_s;
        let o = pose.compose(&sensor.robot_from_sensor());
        let end = [o.x + range * o.theta.cos(), o.y + range * o.theta.sin()];
        batch.0.push([
            [o.x as f32, o.y as f32, 0.3],
            [end[0] as f32, end[1] as f32, 0.3],
        ]);
        batch.1.push(if fused {
            rerun::Color::from_rgb(0, 200, 255)
        } else {
            rerun::Color::from_rgb(255, 40, 40)
        });
    }
    flush(&mut batch, last_t)?;

    // Error against the truth (when known), the filter's sigma and the distance since the last
    // sighting.
    let truth = scene.run.ground_truth.as_deref();
    let mut next = f64::NEG_INFINITY;
    for (i, p) in r.trajectory.iter().enumerate() {
        if p.t_s < next {
            continue;
        }
        next = p.t_s + POSE_SAMPLE_S;
        rec.set_duration_secs("time", p.t_s);
        rec.log("metrics/sigma_m", &rerun::Scalars::single(r.sigma_m[i]))?;
        rec.log(
            "metrics/since_sighting_m",
            &rerun::Scalars::single(r.since_sighting_m[i]),
        )?;
        let Some(gt) = truth.and_then(|t| pose_at(t, p.t_s)) else {
            continue;
        };
        rec.log(
            "metrics/position_error_m/localized",
            &rerun::Scalars::single((p.pose.x - gt.x).hypot(p.pose.y - gt.y)),
        )?;
        let tracked = scene.calibrated_odometry.unwrap_or(&scene.run.odometry);
        if let Some(o) = pose_at(tracked, p.t_s) {
            rec.log(
                "metrics/position_error_m/odometry",
                &rerun::Scalars::single((o.x - gt.x).hypot(o.y - gt.y)),
            )?;
        }
    }
    rec.reset_time();

    let mut md = String::from("# stereotag localize\n\n| metric | value |\n|---|---|\n");
    for (k, v) in scene.metrics {
        md.push_str(&format!("| {k} | {v:.4} |\n"));
    }
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

/// Whether `path` looks like an `.rrd` file name (for the CLI's checks).
pub fn is_rrd(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "rrd")
}

/// The default layout of a calibration: board poses in 3D, each camera's view with corners and
/// residual arrows, the coverage heat maps and the per-view RMS.
pub fn calibration_blueprint() -> bp::Blueprint {
    bp::Blueprint::new(bp::Vertical::new([
        bp::Horizontal::new([
            bp::Spatial3DView::new("Board poses")
                .with_origin("/rig")
                .into(),
            bp::Spatial2DView::new("Left")
                .with_origin("/views/left")
                .into(),
            bp::Spatial2DView::new("Right")
                .with_origin("/views/right")
                .into(),
        ])
        .into(),
        bp::Horizontal::new([
            bp::Spatial2DView::new("Coverage left")
                .with_origin("/coverage/left")
                .into(),
            bp::Spatial2DView::new("Coverage right")
                .with_origin("/coverage/right")
                .into(),
            bp::TimeSeriesView::new("RMS per view")
                .with_origin("/rms")
                .into(),
            bp::TextDocumentView::new("Report")
                .with_origin("/report")
                .into(),
        ])
        .into(),
    ]))
    .with_time_panel(bp::TimePanel::new().with_timeline("view"))
}

/// Residuals magnified this many times in the recording's arrows.
pub const RESIDUAL_ARROW_SCALE: f32 = 20.0;

/// Logs a calibration: per view (the `view` sequence) the images (when given, keyed by view
/// name, JPEG), the corners and residual arrows (x20) in each image, the board's pose in 3D, the
/// per-view RMS; once, the cameras and coverage heat maps.
pub fn log_calibration(
    recorder: &Recorder,
    calib: &crate::calib::Calibration,
    report_markdown: &str,
    rectified_pair: Option<&image::GrayImage>,
    view_images: &std::collections::BTreeMap<String, (Vec<u8>, Vec<u8>)>,
) -> Result<(), VizError> {
    let rec = recorder.stream();
    if let Some(img) = rectified_pair {
        rec.log_static(
            "rectified",
            &rerun::EncodedImage::from_file_contents(jpeg(img)?),
        )?;
    }
    let rig = &calib.rig;
    rec.log_static("rig", &rerun::ViewCoordinates::RDF())?;
    rec.log_static("rig/right", &transform(&rig.left_from_right()))?;
    for (name, cam) in [("left", &rig.left), ("rig/right", &rig.right)] {
        let path = if name == "left" {
            "rig/left".to_string()
        } else {
            name.to_string()
        };
        rec.log_static(
            format!("{path}/image"),
            &rerun::Pinhole::from_focal_length_and_resolution(
                [cam.fx as f32, cam.fy as f32],
                [cam.width as f32, cam.height as f32],
            )
            .with_principal_point([cam.cx as f32, cam.cy as f32])
            .with_image_plane_distance(0.05),
        )?;
    }
    for (side, counts) in [
        ("left", &calib.coverage_counts.0),
        ("right", &calib.coverage_counts.1),
    ] {
        let max = counts.iter().copied().max().unwrap_or(1).max(1) as f32;
        let pixels: Vec<u8> = counts
            .iter()
            .map(|&n| (255.0 * n as f32 / max) as u8)
            .collect();
        rec.log_static(
            format!("coverage/{side}"),
            &rerun::Image::from_l8(pixels, [8, 6]),
        )?;
    }
    for (k, v) in calib.used.iter().enumerate() {
        rec.set_time_sequence("view", k as i64);
        rec.log("rig/board", &transform(&v.left_from_board))?;
        rec.log(
            "rig/board/corners",
            &rerun::Points3D::new(v.left.iter().map(|c| f32s(c.board_m))).with_radii([0.003f32]),
        )?;
        if let Some((l, r)) = view_images.get(&v.name) {
            for (side, jpeg) in [("left", l), ("right", r)] {
                rec.log(
                    format!("views/{side}/image"),
                    &rerun::EncodedImage::from_file_contents(jpeg.clone()),
                )?;
            }
        }
        let right_from_board = rig.right_from_left * v.left_from_board;
        for (side, cam, pose, corners) in [
            ("left", &rig.left, v.left_from_board, &v.left),
            ("right", &rig.right, right_from_board, &v.right),
        ] {
            let mut origins = Vec::new();
            let mut vectors = Vec::new();
            let mut sum = 0.0;
            for c in corners.iter() {
                let p = pose * nalgebra::Point3::from(c.board_m);
                if let Some(q) = cam.project(&p.coords) {
                    origins.push([c.px[0] as f32, c.px[1] as f32]);
                    let d = [(q.x - c.px[0]) as f32, (q.y - c.px[1]) as f32];
                    sum += (d[0] * d[0] + d[1] * d[1]) as f64;
                    vectors.push([d[0] * RESIDUAL_ARROW_SCALE, d[1] * RESIDUAL_ARROW_SCALE]);
                }
            }
            rec.log(
                format!("views/{side}/corners"),
                &rerun::Points2D::new(origins.clone()).with_radii([2.0f32]),
            )?;
            rec.log(
                format!("views/{side}/residuals_x20"),
                &rerun::Arrows2D::from_vectors(vectors)
                    .with_origins(origins.clone())
                    .with_colors([rerun::Color::from_rgb(255, 80, 80)]),
            )?;
            rec.log(
                format!("rms/{side}"),
                &rerun::Scalars::single((sum / origins.len().max(1) as f64).sqrt()),
            )?;
        }
    }
    rec.reset_time();
    rec.log_static(
        "report",
        &rerun::TextDocument::from_markdown(report_markdown),
    )?;
    Ok(())
}
