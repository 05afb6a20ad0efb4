//! The calibration's recording: the cameras and every board pose, each view's corners and
//! residuals, all residuals together with their scale, the coverage and the per-view RMS, the
//! rectified pair and the report.

use super::draw::*;
use super::layout::{column, row, tabs, Layout, View};
use super::palette;
use super::recorder::jpeg;
use super::{CalibrationScene, Recorder, VizError};
use crate::calib::{Calibration, Corner, UsedView};
use crate::camera::{Camera, StereoRig};
use nalgebra::Isometry3;
use rerun::blueprint::components::PlayState;

/// The cells of the coverage grid across and down each image.
const COVERAGE_CELLS: [u32; 2] = [8, 6];

/// Scene units per pixel of residual in the residual plot.
const RESIDUAL_PLOT_SCALE: f32 = 100.0;

/// The default layout of a calibration: the cameras and board poses in 3D, each camera's view with
/// its corners and residuals (and the rectified pair in a tab), the report; below, all residuals
/// with their scale, the coverage and the per-view RMS.
fn layout(calib: &Calibration, arrow_scale: f32) -> Layout {
    let images = if calib.stereo {
        vec![
            View::spatial_2d("Left", "/views/left").into(),
            View::spatial_2d("Right", "/views/right").into(),
        ]
    } else {
        vec![View::spatial_2d("Camera", "/views/left").into()]
    };
    let views = row(images, &[]).named(&format!(
        "Corners (dots) and residuals (arrows x{arrow_scale})"
    ));
    let boards = View::spatial_3d("Cameras and boards", "/rig");
    let boards = match board_frame(calib) {
        Some((eye, target)) => boards.eye_up(eye, target, [0.0, -1.0, 0.0]),
        None => boards,
    };
    let views = if calib.stereo {
        tabs([
            views,
            View::spatial_2d("Rectified pair", "/rectified").into(),
        ])
    } else {
        views
    };
    let mut below = vec![View::spatial_2d(
        if calib.stereo {
            "All residuals: left blue, right orange (rings in px)"
        } else {
            "All residuals (rings in px)"
        },
        "/residuals",
    )
    .into()];
    // Each camera's coverage, and in a tab beside it its projection uncertainty.
    let names: &[(&str, &str)] = if calib.stereo {
        &[("left", "Left"), ("right", "Right")]
    } else {
        &[("left", "Camera")]
    };
    for (side, title) in names {
        below.push(tabs([
            View::spatial_2d(&format!("{title}: coverage"), &format!("/coverage/{side}")).into(),
            View::spatial_2d(
                &format!("{title}: uncertainty, px"),
                &format!("/uncertainty/{side}"),
            )
            .into(),
        ]));
    }
    below.push(
        View::time_series("RMS per view, px", "/rms")
            .whole_run("view")
            .into(),
    );
    Layout {
        root: column(
            [
                row(
                    [
                        boards.into(),
                        views,
                        View::text_document("Report", "/report").into(),
                    ],
                    &[0.27, 0.48, 0.25],
                ),
                row(below, &[]),
            ],
            &[0.6, 0.4],
        ),
        timeline: "view",
        play: PlayState::Paused,
    }
}

/// Where the 3D view looks from and at (left camera frame: x right, y down, z ahead): behind,
/// above and beside the cameras, at the middle between them and the boards.
fn board_frame(calib: &Calibration) -> Option<([f32; 3], [f32; 3])> {
    let n = calib.used.len();
    if n == 0 {
        return None;
    }
    let centre = calib
        .used
        .iter()
        .map(|v| v.left_from_board * board_centre(v))
        .fold(nalgebra::Vector3::zeros(), |acc, p| acc + p.coords)
        / n as f64;
    let d = centre.norm().max(0.1);
    let target = centre * 0.5;
    let eye = target + nalgebra::Vector3::new(0.9 * d, -0.8 * d, -d);
    Some((
        f32s([eye.x, eye.y, eye.z]),
        f32s([target.x, target.y, target.z]),
    ))
}

/// The middle of the board's corners seen in a view, in the board's frame.
fn board_centre(v: &UsedView) -> nalgebra::Point3<f64> {
    let n = v.left.len().max(1) as f64;
    let sum = v.left.iter().fold(nalgebra::Vector3::zeros(), |acc, c| {
        acc + nalgebra::Vector3::from(c.board_m)
    });
    nalgebra::Point3::from(sum / n)
}

/// How many times the residual arrows are drawn longer than they are: the RMS residual drawn at
/// about 1.5% of the image width, rounded to 1, 2 or 5 times a power of ten.
fn arrow_scale(rms_px: f64, width: u32) -> f32 {
    let wanted = (0.015 * width as f64 / rms_px.max(1e-3)).max(1.0);
    let decade = 10f64.powf(wanted.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .rfind(|m| m * decade <= wanted)
        .unwrap_or(1.0);
    (step * decade) as f32
}

impl Recorder {
    /// Logs a calibration: per view (the `view` sequence) the images (when given, keyed by view
    /// name, JPEG), the corners and residual arrows (magnified, the factor in the view's name)
    /// in each image, the board's pose in 3D, the per-view RMS; once, the cameras, every board's
    /// outline, all residuals in one plot with rings at round pixel values, the coverage with
    /// each cell's count, the rectified pair and the report.
    pub fn log_calibration(&self, scene: &CalibrationScene<'_>) -> Result<(), VizError> {
        let rec = self.stream();
        let calib = scene.calibration;
        let scale = arrow_scale(calib.rms_px, calib.rig.left.width);
        layout(calib, scale).send(rec)?;
        if let Some(img) = scene.rectified_pair {
            rec.log_static(
                "rectified",
                &rerun::EncodedImage::from_file_contents(jpeg(img)?),
            )?;
        }
        log_rig(rec, calib)?;
        let names = calib.cameras();
        let styles = [
            ("rms/left", names[0].0, palette::LEFT),
            ("rms/right", "right", palette::RIGHT),
        ];
        log_series_styles(rec, &styles[..names.len()])?;
        log_board_outlines(rec, calib)?;
        log_all_residuals(rec, calib)?;
        let sides = [
            ("left", &calib.coverage_counts.0),
            ("right", &calib.coverage_counts.1),
        ];
        for (side, counts) in &sides[..calib.cameras().len()] {
            log_coverage(rec, side, counts)?;
        }
        log_uncertainty(rec, calib)?;
        for (k, v) in calib.used.iter().enumerate() {
            rec.set_time_sequence("view", k as i64);
            log_view(rec, &calib.rig, v, scene.view_images.get(&v.name), scale)?;
        }
        rec.reset_time();
        rec.log_static(
            "report",
            &rerun::TextDocument::from_markdown(scene.report_markdown),
        )?;
        Ok(())
    }
}

/// Every view's board as the outline of its corners, in the left camera's frame.
fn log_board_outlines(rec: &rerun::RecordingStream, calib: &Calibration) -> Result<(), VizError> {
    let outlines: Vec<Vec<[f32; 3]>> = calib
        .used
        .iter()
        .map(|v| {
            let (lo, hi) = v.left.iter().fold(
                ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
                |(lo, hi), c| {
                    (
                        [lo[0].min(c.board_m[0]), lo[1].min(c.board_m[1])],
                        [hi[0].max(c.board_m[0]), hi[1].max(c.board_m[1])],
                    )
                },
            );
            [
                [lo[0], lo[1]],
                [hi[0], lo[1]],
                [hi[0], hi[1]],
                [lo[0], hi[1]],
                [lo[0], lo[1]],
            ]
            .iter()
            .map(|&[x, y]| {
                let p = v.left_from_board * nalgebra::Point3::new(x, y, 0.0);
                f32s([p.x, p.y, p.z])
            })
            .collect()
        })
        .collect();
    rec.log_static(
        "rig/boards",
        &rerun::LineStrips3D::new(outlines)
            .with_colors([palette::BOARD_OUTLINE])
            .with_labels(calib.used.iter().map(|v| v.name.clone()))
            .with_show_labels(false),
    )?;
    Ok(())
}

/// Every corner's residual (projected minus detected) of both cameras in one plot, magnified
/// [`RESIDUAL_PLOT_SCALE`] times, with rings at round pixel values and at the RMS.
fn log_all_residuals(rec: &rerun::RecordingStream, calib: &Calibration) -> Result<(), VizError> {
    let right_from_left = calib.rig.right_from_left;
    let mut largest = 0.0f64;
    let sides = [("left", palette::LEFT), ("right", palette::RIGHT)];
    for &(side, color) in &sides[..calib.cameras().len()] {
        let mut points = Vec::new();
        for v in &calib.used {
            let (cam, pose, corners) = if side == "left" {
                (&calib.rig.left, v.left_from_board, &v.left)
            } else {
                (
                    &calib.rig.right,
                    right_from_left * v.left_from_board,
                    &v.right,
                )
            };
            for d in residuals(cam, &pose, corners).into_iter().map(|(_, d)| d) {
                largest = largest.max(d[0].hypot(d[1]));
                points.push([
                    d[0] as f32 * RESIDUAL_PLOT_SCALE,
                    d[1] as f32 * RESIDUAL_PLOT_SCALE,
                ]);
            }
        }
        rec.log_static(
            format!("residuals/{side}"),
            &rerun::Points2D::new(points)
                .with_colors([color])
                .with_radii([rerun::Radius::new_ui_points(2.0)]),
        )?;
    }
    let rings: Vec<(f64, String)> = [0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0]
        .into_iter()
        .filter(|&r| r <= 1.5 * largest.max(0.05))
        .map(|r| (r, format!("{r} px")))
        .collect();
    let ring = |r: f64| -> Vec<[f32; 2]> {
        let r = r as f32 * RESIDUAL_PLOT_SCALE;
        (0..=64)
            .map(|k| {
                let a = k as f32 / 64.0 * std::f32::consts::TAU;
                [r * a.cos(), r * a.sin()]
            })
            .collect()
    };
    let rms = calib.rms_px;
    rec.log_static(
        "residuals/rings",
        &rerun::LineStrips2D::new(rings.iter().map(|(r, _)| ring(*r))).with_colors([palette::RING]),
    )?;
    rec.log_static(
        "residuals/rms",
        &rerun::LineStrips2D::new([ring(rms)]).with_colors([palette::RESIDUAL]),
    )?;
    // Each ring's value written at its top (the RMS at its bottom, apart from the round values).
    rec.log_static(
        "residuals/values",
        &rerun::Points2D::new(
            rings
                .iter()
                .map(|(r, _)| [0.0, -(*r as f32) * RESIDUAL_PLOT_SCALE])
                .chain([[0.0, rms as f32 * RESIDUAL_PLOT_SCALE]]),
        )
        .with_labels(
            rings
                .iter()
                .map(|(_, l)| l.clone())
                .chain([format!("RMS {rms:.3} px")]),
        )
        .with_colors(
            rings
                .iter()
                .map(|_| palette::RING)
                .chain([palette::RESIDUAL])
                .collect::<Vec<_>>(),
        )
        .with_radii([0.0f32])
        .with_show_labels(true),
    )?;
    Ok(())
}

/// The cameras, the right one placed from the left.
fn log_rig(rec: &rerun::RecordingStream, calib: &Calibration) -> Result<(), VizError> {
    let rig = &calib.rig;
    rec.log_static("rig", &rerun::ViewCoordinates::RDF())?;
    if calib.stereo {
        rec.log_static("rig/right", &transform(&rig.left_from_right()))?;
    }
    let cameras = [("rig/left", &rig.left), ("rig/right", &rig.right)];
    for (path, cam) in &cameras[..calib.cameras().len()] {
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
    Ok(())
}

/// How many corners fell in each cell of the image: a heat map with each cell's count written on
/// it.
fn log_coverage(rec: &rerun::RecordingStream, side: &str, counts: &[u32]) -> Result<(), VizError> {
    let max = counts.iter().copied().max().unwrap_or(1).max(1) as f32;
    log_cells(
        rec,
        &format!("coverage/{side}"),
        COVERAGE_CELLS,
        &counts
            .iter()
            .map(|&n| (n > 0).then_some(n as f32 / max))
            .collect::<Vec<_>>(),
        counts.iter().map(u32::to_string),
    )
}

/// The projection uncertainty of each camera over its image: a heat map of the worst-direction
/// sigma with each grid point's value in pixels.
fn log_uncertainty(rec: &rerun::RecordingStream, calib: &Calibration) -> Result<(), VizError> {
    let paths = ["uncertainty/left", "uncertainty/right"];
    for (u, path) in crate::calib::projection_uncertainty(calib)
        .iter()
        .zip(paths)
    {
        let max = u.max_px.max(1e-12) as f32;
        log_cells(
            rec,
            path,
            [u.cols as u32, u.rows as u32],
            &u.sigma_px
                .iter()
                .map(|&s| s.is_finite().then_some(s as f32 / max))
                .collect::<Vec<_>>(),
            u.sigma_px.iter().map(|s| format!("{s:.2}")),
        )?;
    }
    Ok(())
}

/// A grid of `cells` (across, down) as a grey heat map (each cell's `shade` 0 to 1; `None` black
/// and its label in the gated-out colour) with a label on every cell.
fn log_cells(
    rec: &rerun::RecordingStream,
    path: &str,
    cells: [u32; 2],
    shade: &[Option<f32>],
    labels: impl Iterator<Item = String>,
) -> Result<(), VizError> {
    let pixels: Vec<u8> = shade
        .iter()
        .map(|s| s.map_or(0, |s| (40.0 + 215.0 * s.clamp(0.0, 1.0)) as u8))
        .collect();
    rec.log_static(path, &rerun::Image::from_l8(pixels, cells))?;
    let cols = cells[0] as usize;
    rec.log_static(
        format!("{path}/values"),
        &rerun::Points2D::new(
            (0..shade.len()).map(|i| [(i % cols) as f32 + 0.5, (i / cols) as f32 + 0.5]),
        )
        .with_labels(labels)
        .with_colors(
            shade
                .iter()
                .map(|s| {
                    if s.is_none() {
                        palette::GATED_OUT
                    } else {
                        palette::DETECTION
                    }
                })
                .collect::<Vec<_>>(),
        )
        .with_radii([0.0f32])
        .with_show_labels(true),
    )?;
    Ok(())
}

/// One view: the board's pose and corners in 3D, the images, each camera's corners and residuals
/// (arrows `scale` times longer).
fn log_view(
    rec: &rerun::RecordingStream,
    rig: &StereoRig,
    v: &UsedView,
    images: Option<&(Vec<u8>, Vec<u8>)>,
    scale: f32,
) -> Result<(), VizError> {
    rec.log("rig/board", &transform(&v.left_from_board))?;
    rec.log(
        "rig/board/corners",
        &rerun::Points3D::new(v.left.iter().map(|c| f32s(c.board_m)))
            .with_colors([palette::BOARD_CORNER])
            .with_radii([rerun::Radius::new_ui_points(3.0)]),
    )?;
    if let Some((l, r)) = images {
        for (side, jpeg) in [("left", l), ("right", r)] {
            if jpeg.is_empty() {
                continue;
            }
            rec.log(
                format!("views/{side}/image"),
                &rerun::EncodedImage::from_file_contents(jpeg.clone()),
            )?;
        }
    }
    log_residuals(rec, "left", &rig.left, &v.left_from_board, &v.left, scale)?;
    if v.right.is_empty() {
        return Ok(());
    }
    let right_from_board = rig.right_from_left * v.left_from_board;
    log_residuals(rec, "right", &rig.right, &right_from_board, &v.right, scale)
}

/// Each corner the camera projects: its detected position and the residual (projected minus
/// detected), pixels.
fn residuals(
    cam: &Camera,
    cam_from_board: &Isometry3<f64>,
    corners: &[Corner],
) -> Vec<([f64; 2], [f64; 2])> {
    corners
        .iter()
        .filter_map(|c| {
            let p = cam_from_board * nalgebra::Point3::from(c.board_m);
            let q = cam.project(&p.coords)?;
            Some((c.px, [q.x - c.px[0], q.y - c.px[1]]))
        })
        .collect()
}

/// One camera's corners in a view, with arrows `scale` times longer than the residuals and
/// their RMS.
fn log_residuals(
    rec: &rerun::RecordingStream,
    side: &str,
    cam: &Camera,
    cam_from_board: &Isometry3<f64>,
    corners: &[Corner],
    scale: f32,
) -> Result<(), VizError> {
    let found = residuals(cam, cam_from_board, corners);
    let origins: Vec<[f32; 2]> = found.iter().map(|(p, _)| f32s(*p)).collect();
    let sum: f64 = found.iter().map(|(_, d)| d[0] * d[0] + d[1] * d[1]).sum();
    rec.log(
        format!("views/{side}/corners"),
        &rerun::Points2D::new(origins.clone())
            .with_colors([palette::DETECTION])
            .with_radii([rerun::Radius::new_ui_points(2.5)]),
    )?;
    rec.log(
        format!("views/{side}/residuals"),
        &rerun::Arrows2D::from_vectors(
            found
                .iter()
                .map(|(_, d)| [d[0] as f32 * scale, d[1] as f32 * scale]),
        )
        .with_origins(origins)
        .with_colors([palette::RESIDUAL])
        .with_radii([rerun::Radius::new_ui_points(1.5)]),
    )?;
    rec.log(
        format!("rms/{side}"),
        &rerun::Scalars::single((sum / found.len().max(1) as f64).sqrt()),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrows_are_magnified_to_a_round_factor_that_shows_them() {
        // 0.18 px on a 1024 px image: 15 px wanted, x50 (9 px).
        assert_eq!(arrow_scale(0.18, 1024), 50.0);
        assert_eq!(arrow_scale(0.02, 752), 500.0);
        // Large residuals are drawn as they are.
        assert_eq!(arrow_scale(30.0, 640), 1.0);
    }
}
