//! The calibration's recording: board poses, each view's corners and residuals, coverage and the
//! per-view RMS.

use super::draw::*;
use super::palette;
use super::recorder::jpeg;
use super::{CalibrationScene, Recorder, VizError, RESIDUAL_ARROW_SCALE};
use crate::calib::{Corner, UsedView};
use crate::camera::{Camera, StereoRig};
use nalgebra::Isometry3;
use rerun::blueprint as bp;

/// The default layout of a calibration: board poses in 3D, each camera's view with corners and
/// residual arrows, the coverage heat maps and the per-view RMS.
pub(super) fn blueprint() -> bp::Blueprint {
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
    .with_time_panel(
        bp::TimePanel::new()
            .with_timeline("view")
            .with_state(bp::components::PanelState::Collapsed),
    )
}

impl Recorder {
    /// Logs a calibration: per view (the `view` sequence) the images (when given, keyed by view
    /// name, JPEG), the corners and residual arrows (x20) in each image, the board's pose in 3D, the
    /// per-view RMS; once, the cameras and coverage heat maps.
    pub fn log_calibration(&self, scene: &CalibrationScene<'_>) -> Result<(), VizError> {
        let rec = self.stream();
        let calib = scene.calibration;
        if let Some(img) = scene.rectified_pair {
            rec.log_static(
                "rectified",
                &rerun::EncodedImage::from_file_contents(jpeg(img)?),
            )?;
        }
        log_rig(rec, &calib.rig)?;
        for (side, counts) in [
            ("left", &calib.coverage_counts.0),
            ("right", &calib.coverage_counts.1),
        ] {
            log_coverage(rec, side, counts)?;
        }
        for (k, v) in calib.used.iter().enumerate() {
            rec.set_time_sequence("view", k as i64);
            log_view(rec, &calib.rig, v, scene.view_images.get(&v.name))?;
        }
        rec.reset_time();
        rec.log_static(
            "report",
            &rerun::TextDocument::from_markdown(scene.report_markdown),
        )?;
        Ok(())
    }
}

/// The two cameras, the right one placed from the left.
fn log_rig(rec: &rerun::RecordingStream, rig: &StereoRig) -> Result<(), VizError> {
    rec.log_static("rig", &rerun::ViewCoordinates::RDF())?;
    rec.log_static("rig/right", &transform(&rig.left_from_right()))?;
    for (path, cam) in [("rig/left", &rig.left), ("rig/right", &rig.right)] {
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

/// How many corners fell in each cell of the image, as a heat map.
fn log_coverage(rec: &rerun::RecordingStream, side: &str, counts: &[u32]) -> Result<(), VizError> {
    let max = counts.iter().copied().max().unwrap_or(1).max(1) as f32;
    let pixels: Vec<u8> = counts
        .iter()
        .map(|&n| (255.0 * n as f32 / max) as u8)
        .collect();
    rec.log_static(
        format!("coverage/{side}"),
        &rerun::Image::from_l8(pixels, [8, 6]),
    )?;
    Ok(())
}

/// One view: the board's pose and corners in 3D, the images, each camera's corners and residuals.
fn log_view(
    rec: &rerun::RecordingStream,
    rig: &StereoRig,
    v: &UsedView,
    images: Option<&(Vec<u8>, Vec<u8>)>,
) -> Result<(), VizError> {
    rec.log("rig/board", &transform(&v.left_from_board))?;
    rec.log(
        "rig/board/corners",
        &rerun::Points3D::new(v.left.iter().map(|c| f32s(c.board_m))).with_radii([0.003f32]),
    )?;
    if let Some((l, r)) = images {
        for (side, jpeg) in [("left", l), ("right", r)] {
            rec.log(
                format!("views/{side}/image"),
                &rerun::EncodedImage::from_file_contents(jpeg.clone()),
            )?;
        }
    }
    let right_from_board = rig.right_from_left * v.left_from_board;
    log_residuals(rec, "left", &rig.left, &v.left_from_board, &v.left)?;
    log_residuals(rec, "right", &rig.right, &right_from_board, &v.right)
}

/// One camera's corners in a view, with arrows to where the calibration projects them (x20) and
/// their RMS.
fn log_residuals(
    rec: &rerun::RecordingStream,
    side: &str,
    cam: &Camera,
    cam_from_board: &Isometry3<f64>,
    corners: &[Corner],
) -> Result<(), VizError> {
    let mut origins = Vec::new();
    let mut vectors = Vec::new();
    let mut sum = 0.0;
    for c in corners {
        let p = cam_from_board * nalgebra::Point3::from(c.board_m);
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
            .with_colors([palette::RESIDUAL]),
    )?;
    rec.log(
        format!("rms/{side}"),
        &rerun::Scalars::single((sum / origins.len().max(1) as f64).sqrt()),
    )?;
    Ok(())
}
