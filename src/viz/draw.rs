//! Drawing shared by the recordings: conversions to rerun's types, the world's walls and planned
//! tags, trajectories, the robot, landmarks with their ellipsoids, surveyed walls, maps.

use super::layout::View;
use super::palette;
use super::{VizError, ELLIPSOID_SIGMAS, POSE_SAMPLE_S};
use crate::fusion::Landmark;
use crate::geometry::StampedPose;
use crate::sonar::grid::OccupancyMap;
use crate::sonar::hough::Feature;
use crate::sonar::walls::WallSegment;
use crate::world::World;
use nalgebra::{Isometry3, Matrix3, Rotation3, UnitQuaternion};

/// The time panel on the `time` timeline, following the end of the run (the finished map and
/// trajectories); scrub back to replay it.
pub(super) fn f32s<const N: usize>(v: [f64; N]) -> [f32; N] {
    v.map(|x| x as f32)
}

pub(super) fn quaternion(r: &UnitQuaternion<f64>) -> rerun::Quaternion {
    rerun::Quaternion::from_xyzw([r.i as f32, r.j as f32, r.k as f32, r.w as f32])
}

pub(super) fn transform(iso: &Isometry3<f64>) -> rerun::Transform3D {
    let t = iso.translation.vector;
    rerun::Transform3D::from_translation_rotation(f32s([t.x, t.y, t.z]), quaternion(&iso.rotation))
}

pub(super) fn planar_transform(p: &crate::geometry::Pose2) -> rerun::Transform3D {
    let r = UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), p.theta);
    rerun::Transform3D::from_translation_rotation([p.x as f32, p.y as f32, 0.0], quaternion(&r))
}

pub(super) fn strip(trajectory: &[StampedPose], z: f64) -> Vec<[f32; 3]> {
    trajectory
        .iter()
        .map(|p| [p.pose.x as f32, p.pose.y as f32, z as f32])
        .collect()
}

/// Pixel position in the map image (row 0 at the top) of a world point.
pub(super) fn map_pixel(map: &OccupancyMap, x: f64, y: f64) -> [f32; 2] {
    let g = &map.geometry;
    [
        ((x - g.origin_m[0]) / g.resolution_m) as f32,
        (g.height as f64 - (y - g.origin_m[1]) / g.resolution_m) as f32,
    ]
}

/// The map as the paper shows it: inverse grey, unknown mid-grey; row 0 at the top.
pub(super) fn map_image(map: &OccupancyMap) -> rerun::Image {
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

/// The colour of a Hough feature of this kind.
pub(super) fn feature_color(kind: crate::sonar::hough::FeatureKind) -> rerun::Color {
    match kind {
        crate::sonar::hough::FeatureKind::Corner => palette::CORNER,
        crate::sonar::hough::FeatureKind::Edge => palette::EDGE,
        crate::sonar::hough::FeatureKind::Unknown => palette::UNKNOWN_FEATURE,
    }
}

/// Hough features as dots on `map`'s image, coloured by kind, with their votes as (hidden)
/// labels.
pub(super) fn map_features(map: &OccupancyMap, features: &[Feature]) -> rerun::Points2D {
    rerun::Points2D::new(features.iter().map(|f| map_pixel(map, f.x_m, f.y_m)))
        .with_colors(
            features
                .iter()
                .map(|f| feature_color(f.kind))
                .collect::<Vec<_>>(),
        )
        .with_labels(
            features
                .iter()
                .map(|f| format!("{} {} votes", f.kind.as_str(), f.votes)),
        )
        .with_show_labels(false)
        .with_radii([0.8f32])
}

/// Each trajectory as a line on `map`'s image under `{path}/NAME` (spaces in the name become
/// underscores), in its colour.
pub(super) fn log_map_trajectories(
    rec: &rerun::RecordingStream,
    path: &str,
    map: &OccupancyMap,
    lines: &[(&str, &[StampedPose], rerun::Color)],
) -> Result<(), VizError> {
    for (name, trajectory, color) in lines {
        let pixels: Vec<[f32; 2]> = trajectory
            .iter()
            .map(|p| map_pixel(map, p.pose.x, p.pose.y))
            .collect();
        rec.log_static(
            format!("{path}/{}", name.replace(' ', "_")),
            &rerun::LineStrips2D::new([pixels])
                .with_colors([*color])
                .with_labels([*name])
                .with_show_labels(false),
        )?;
    }
    Ok(())
}

/// The map as a ROS OccupancyGrid (0 free .. 100 occupied, 255 unknown) for the GridMap archetype.
pub(super) fn grid_map(map: &OccupancyMap) -> rerun::GridMap {
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

/// Radii (at [`ELLIPSOID_SIGMAS`]) and orientation of a covariance ellipsoid.
pub(super) fn ellipsoid(cov: &[[f64; 3]; 3]) -> ([f32; 3], rerun::Quaternion) {
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

/// The smallest rectangle holding the points, `(lower-left, upper-right)`; `None` for none.
pub(super) fn bounding_box(
    points: impl IntoIterator<Item = [f64; 2]>,
) -> Option<([f64; 2], [f64; 2])> {
    points.into_iter().fold(None, |acc, p| {
        let (lo, hi) = acc.unwrap_or((p, p));
        Some((
            [lo[0].min(p[0]), lo[1].min(p[1])],
            [hi[0].max(p[0]), hi[1].max(p[1])],
        ))
    })
}

/// The outline (32 points, closed) of the [`ELLIPSOID_SIGMAS`] ellipse of a 2x2 covariance, as
/// offsets from its centre.
pub(super) fn ellipse_2d(cov: [[f64; 2]; 2]) -> Vec<[f64; 2]> {
    let m = nalgebra::Matrix2::new(cov[0][0], cov[0][1], cov[1][0], cov[1][1]);
    let eig = ((m + m.transpose()) * 0.5).symmetric_eigen();
    let axes = eig.eigenvectors;
    let r = eig
        .eigenvalues
        .map(|v| ELLIPSOID_SIGMAS * v.max(0.0).sqrt());
    (0..=32)
        .map(|k| {
            let a = k as f64 / 32.0 * std::f64::consts::TAU;
            let p = axes * nalgebra::Vector2::new(r[0] * a.cos(), r[1] * a.sin());
            [p.x, p.y]
        })
        .collect()
}

pub(super) fn log_world(
    rec: &rerun::RecordingStream,
    world: Option<&World>,
) -> Result<(), VizError> {
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
            .with_colors([palette::WALLS])
            .with_radii([rerun::Radius::new_ui_points(1.0)]),
    )?;
    let planned: Vec<[f32; 3]> = world.tags.iter().map(|t| f32s(t.position_m)).collect();
    rec.log_static(
        "world/tags_planned",
        &rerun::Points3D::new(planned)
            .with_labels(world.tags.iter().map(|t| format!("planned {}", t.id)))
            .with_show_labels(false)
            .with_colors([palette::PLANNED_TAG])
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
            .with_colors([palette::TRUE_CORNER])
            .with_radii([0.02f32]),
    )?;
    Ok(())
}

/// Each trajectory as a line under `world/trajectories/NAME` (spaces in the name become
/// underscores), in its colour.
pub(super) fn log_trajectory_lines(
    rec: &rerun::RecordingStream,
    lines: &[(&str, &[StampedPose], rerun::Color)],
) -> Result<(), VizError> {
    for (name, t, c) in lines {
        rec.log_static(
            format!("world/trajectories/{}", name.replace(' ', "_")),
            &rerun::LineStrips3D::new([strip(t, 0.02)])
                .with_colors([*c])
                .with_radii([rerun::Radius::new_ui_points(1.5)])
                .with_labels([*name])
                .with_show_labels(false),
        )?;
    }
    Ok(())
}

/// The robot, a disc outline with a heading tick, moved along `trajectory` on the `time`
/// timeline.
pub(super) fn log_robot(
    rec: &rerun::RecordingStream,
    trajectory: &[StampedPose],
) -> Result<(), VizError> {
    let mut outline: Vec<[f32; 3]> = (0..=24)
        .map(|k| {
            let a = k as f32 / 24.0 * std::f32::consts::TAU;
            [0.2 * a.cos(), 0.2 * a.sin(), 0.05]
        })
        .collect();
    outline.push([0.0, 0.0, 0.05]);
    rec.log_static(
        "world/robot/shape",
        &rerun::LineStrips3D::new([outline]).with_colors([palette::ROBOT]),
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
pub(super) fn log_landmark(rec: &rerun::RecordingStream, l: &Landmark) -> Result<String, VizError> {
    let path = format!("landmarks/tag_{}", l.id);
    let (radii, q) = ellipsoid(&l.covariance_m2);
    rec.log_static(
        path.as_str(),
        &rerun::Points3D::new([f32s(l.position_m)])
            .with_labels([format!("tag {}", l.id)])
            .with_colors([palette::FUSED])
            .with_radii([0.04f32]),
    )?;
    // The tag's square as surveyed, and its face's normal: its orientation in 3D.
    let r = l.rotation();
    let centre = nalgebra::Vector3::from(l.position_m);
    let h = 0.5 * l.size_m;
    let corner = |y: f64, z: f64| f32s((centre + r * nalgebra::Vector3::new(0.0, y, z)).into());
    rec.log_static(
        format!("{path}/square"),
        &rerun::LineStrips3D::new([[
            corner(-h, -h),
            corner(h, -h),
            corner(h, h),
            corner(-h, h),
            corner(-h, -h),
        ]])
        .with_colors([palette::FUSED]),
    )?;
    rec.log_static(
        format!("{path}/normal"),
        &rerun::Arrows3D::from_vectors([f32s((r * nalgebra::Vector3::x() * 0.15).into())])
            .with_origins([f32s(l.position_m)])
            .with_colors([palette::FUSED]),
    )?;
    rec.log_static(
        format!("{path}/covariance"),
        &rerun::Ellipsoids3D::from_centers_and_half_sizes([f32s(l.position_m)], [radii])
            .with_quaternions([q])
            .with_colors([palette::LANDMARK_COVARIANCE]),
    )?;
    Ok(path)
}

/// The surveyed walls (what `localize` holds a later run's sonar to): in the scene a low line
/// along each face, and under `{path}/walls` on a map when given (`(path, map)`).
pub(super) fn log_surveyed_walls(
    rec: &rerun::RecordingStream,
    walls: &[WallSegment],
    on_map: Option<(&str, &OccupancyMap)>,
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
        .with_colors([palette::SURVEYED_WALL])
        .with_radii([rerun::Radius::new_ui_points(2.5)])
        .with_labels(labels.clone())
        .with_show_labels(false),
    )?;
    if let Some((path, map)) = on_map {
        rec.log_static(
            format!("{path}/walls"),
            &rerun::LineStrips2D::new(walls.iter().map(|w| {
                [
                    map_pixel(map, w.from_m[0], w.from_m[1]),
                    map_pixel(map, w.to_m[0], w.to_m[1]),
                ]
            }))
            .with_colors([palette::SURVEYED_WALL])
            .with_labels(labels)
            .with_show_labels(false),
        )?;
    }
    Ok(())
}

/// The height the sonar's beams and ranges are drawn at, m (about the transducers').
pub(super) const SONAR_Z_M: f32 = 0.3;

/// How much of the run one batch of sonar lines covers: one log call a second rather than one a
/// reading keeps the recording small and the viewer's time line light.
pub(super) const BATCH_S: f64 = 1.0;

/// Line strips logged to one entity in batches of [`BATCH_S`] of the run, each at the time of its
/// last strip.
pub(super) struct StripBatches<'a> {
    rec: &'a rerun::RecordingStream,
    path: &'static str,
    strips: Vec<Vec<[f32; 3]>>,
    colors: Vec<rerun::Color>,
    started_s: f64,
    last_s: f64,
}

impl<'a> StripBatches<'a> {
    /// No strips yet, for the entity at `path`.
    pub(super) fn new(rec: &'a rerun::RecordingStream, path: &'static str) -> Self {
        Self {
            rec,
            path,
            strips: Vec::new(),
            colors: Vec::new(),
            started_s: f64::NEG_INFINITY,
            last_s: 0.0,
        }
    }

    /// Adds a strip seen at `t_s`, logging the batch before it when that one is full.
    pub(super) fn push(
        &mut self,
        t_s: f64,
        strip: Vec<[f32; 3]>,
        color: rerun::Color,
    ) -> Result<(), VizError> {
        if t_s >= self.started_s + BATCH_S {
            self.flush()?;
            self.started_s = t_s;
        }
        self.last_s = t_s;
        self.strips.push(strip);
        self.colors.push(color);
        Ok(())
    }

    /// Logs the strips not logged yet.
    pub(super) fn flush(&mut self) -> Result<(), VizError> {
        if self.strips.is_empty() {
            return Ok(());
        }
        self.rec.set_duration_secs("time", self.last_s);
        self.rec.log(
            self.path,
            &rerun::LineStrips3D::new(std::mem::take(&mut self.strips))
                .with_colors(std::mem::take(&mut self.colors)),
        )?;
        Ok(())
    }
}

/// Width kept right of the map for its legend, pixels of the map.
const LEGEND_WIDTH_PX: f32 = 30.0;
/// Legend rows a map's height is shared among (more when there are more entries).
const LEGEND_ROWS: usize = 8;

/// Height of one legend row on a map `w` by `h` pixels with `rows` entries: an eighth of the
/// map's height, but at least a 25th of its width, so that the labels of a long, thin map (a
/// corridor) do not overlap.
fn legend_step(w: f32, h: f32, rows: usize) -> f32 {
    (h / rows.max(LEGEND_ROWS) as f32).max(w / 25.0)
}

/// The part of the home the maps show: a map's observed cells and a margin, on the grid's own
/// cells (every map image of a recording is cropped to it).
pub(super) struct MapFrame {
    /// The map, cropped.
    pub(super) map: OccupancyMap,
    /// The rectangle shown, metres.
    pub(super) extent: ([f64; 2], [f64; 2]),
}

impl MapFrame {
    pub(super) fn new(corrected: &OccupancyMap) -> Self {
        const MARGIN_M: f64 = 0.6;
        let g = &corrected.geometry;
        let (lo, hi) = corrected.known_extent().unwrap_or((
            g.origin_m,
            [
                g.origin_m[0] + g.width as f64 * g.resolution_m,
                g.origin_m[1] + g.height as f64 * g.resolution_m,
            ],
        ));
        let lo = [lo[0] - MARGIN_M, lo[1] - MARGIN_M];
        let hi = [hi[0] + MARGIN_M, hi[1] + MARGIN_M];
        let map = corrected.cropped(lo, hi);
        let mg = &map.geometry;
        let extent = (
            mg.origin_m,
            [
                mg.origin_m[0] + mg.width as f64 * mg.resolution_m,
                mg.origin_m[1] + mg.height as f64 * mg.resolution_m,
            ],
        );
        Self { map, extent }
    }

    /// A 2D view of the map at `origin` framed on it, its legend and a margin for the labels.
    pub(super) fn view(&self, name: &str, origin: &str) -> View {
        let [w, h] = [
            self.map.geometry.width as f32,
            self.map.geometry.height as f32,
        ];
        let margin = 0.06 * w.max(h);
        View::spatial_2d(name, origin).framed(
            [-margin, -margin],
            [
                w + LEGEND_WIDTH_PX + margin,
                h.max(LEGEND_ROWS as f32 * legend_step(w, h, LEGEND_ROWS)) + margin,
            ],
        )
    }

    /// A 3D view of the scene at `/world` looking at the map's middle from the south, above it.
    pub(super) fn scene_view(&self, name: &str) -> View {
        let (lo, hi) = self.extent;
        let centre = [
            0.5 * (lo[0] + hi[0]) as f32,
            0.5 * (lo[1] + hi[1]) as f32,
            0.0,
        ];
        let size = (hi[0] - lo[0]).max(hi[1] - lo[1]) as f32;
        View::spatial_3d(name, "/world").eye([centre[0], centre[1] - 0.9 * size, size], centre)
    }

    /// Another map of the same grid, cropped the same.
    pub(super) fn crop(&self, map: &OccupancyMap) -> OccupancyMap {
        map.cropped(self.extent.0, self.extent.1)
    }
}

/// A map's legend: each trajectory drawn, the tags when `tags`, the Hough features by kind and
/// the walls.
pub(super) fn map_legend(
    lines: &[(&str, &[StampedPose], rerun::Color)],
    tags: bool,
) -> Vec<(String, rerun::Color)> {
    let mut legend: Vec<(String, rerun::Color)> = lines
        .iter()
        .map(|(name, _, color)| (name.to_string(), *color))
        .collect();
    if tags {
        legend.push(("tags".to_string(), palette::FUSED));
    }
    legend.extend([
        ("Hough corners".to_string(), palette::CORNER),
        ("Hough edges".to_string(), palette::EDGE),
        ("Hough, kind unknown".to_string(), palette::UNKNOWN_FEATURE),
        ("walls".to_string(), palette::SURVEYED_WALL),
    ]);
    legend
}

/// A legend right of the map: each name in its colour, one row each.
pub(super) fn log_legend(
    rec: &rerun::RecordingStream,
    path: &str,
    map: &OccupancyMap,
    entries: &[(String, rerun::Color)],
) -> Result<(), VizError> {
    let x = map.geometry.width as f32 + 0.5 * LEGEND_WIDTH_PX;
    let step = legend_step(
        map.geometry.width as f32,
        map.geometry.height as f32,
        entries.len(),
    );
    rec.log_static(
        path,
        &rerun::Points2D::new((0..entries.len()).map(|i| [x, step * (i as f32 + 0.5)]))
            .with_colors(entries.iter().map(|(_, c)| *c).collect::<Vec<_>>())
            .with_labels(entries.iter().map(|(n, _)| n.clone()))
            .with_radii([rerun::Radius::new_ui_points(0.5)]),
    )?;
    Ok(())
}

/// Each plotted series' name and colour: `(entity path, name, colour)`.
pub(super) fn log_series_styles(
    rec: &rerun::RecordingStream,
    series: &[(&str, &str, rerun::Color)],
) -> Result<(), VizError> {
    for &(path, name, color) in series {
        rec.log_static(
            path,
            &rerun::SeriesLines::new()
                .with_names([name])
                .with_colors([color])
                .with_widths([2.0f32]),
        )?;
    }
    Ok(())
}

/// A markdown table of `metric | value` rows under a title.
pub(super) fn metrics_markdown<'m>(
    title: &str,
    metrics: impl IntoIterator<Item = (&'m String, &'m f64)>,
) -> String {
    // The value first: a narrow panel clips the last column, and the names are long.
    let mut md = format!("# {title}\n\n| value | metric |\n|---:|---|\n");
    for (k, v) in metrics {
        // Counts as counts; figures to four places.
        if v.fract() == 0.0 && v.abs() < 1e9 {
            md.push_str(&format!("| {v:.0} | {k} |\n"));
        } else {
            md.push_str(&format!("| {v:.4} | {k} |\n"));
        }
    }
    md
}
