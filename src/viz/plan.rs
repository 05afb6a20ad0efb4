//! A tag plan's recording: the map with the predicted error over its free cells, the Hough
//! corners and the tags; the report beside it.

use super::draw::*;
use super::layout::{row, Layout, View};
use super::palette;
use super::{PlanScene, Recorder, VizError};
use crate::sonar::grid::OccupancyMap;
use rerun::blueprint::components::PlayState;

/// Opacity of the predicted error over the map.
const ERROR_ALPHA: u8 = 170;

/// The default layout of a plan: the map with the error, the tags and the corners, the report.
fn layout(frame: &MapFrame) -> Layout {
    Layout {
        root: row(
            [
                frame
                    .view("Predicted error (m) over the map, tags and corners", "/map")
                    .into(),
                View::text_document("Report", "/report").into(),
            ],
            &[0.72, 0.28],
        ),
        timeline: "time",
        play: PlayState::Paused,
    }
}

/// The colour of a predicted error of `e` on a scale up to `max`: green, yellow, red.
fn error_colour(e: f64, max: f64) -> [u8; 3] {
    let t = (e / max.max(1e-9)).clamp(0.0, 1.0);
    if t < 0.5 {
        [(510.0 * t) as u8, 200, 60]
    } else {
        [255, (200.0 * (2.0 - 2.0 * t)) as u8, 60]
    }
}

impl Recorder {
    /// Logs a plan: the map cropped to what was observed, the predicted error over its free
    /// cells with a colour scale, the Hough corners and the tags numbered, and the report.
    pub fn log_plan(&self, scene: &PlanScene<'_>) -> Result<(), VizError> {
        let rec = self.stream();
        let frame = MapFrame::new(scene.map);
        layout(&frame).send(rec)?;
        let map = &frame.map;
        rec.log_static("map/grid", &map_image(map))?;
        let max = scene.prediction.predicted_error_max_m;
        log_error_image(rec, scene, &frame, max)?;
        rec.log_static("map/corners", &map_features(map, scene.corners))?;
        rec.log_static(
            "map/tags",
            &rerun::Points2D::new(scene.tags_m.iter().map(|t| map_pixel(map, t[0], t[1])))
                .with_labels((1..=scene.tags_m.len()).map(|i| format!("tag {i}")))
                .with_colors([palette::FUSED])
                .with_radii([1.2f32])
                .with_show_labels(true),
        )?;
        let mut legend: Vec<(String, rerun::Color)> = (0..=4)
            .map(|k| {
                let e = max * k as f64 / 4.0;
                let [r, g, b] = error_colour(e, max);
                let digits = if max < 0.1 { 3 } else { 2 };
                (format!("{e:.digits$} m"), rerun::Color::from_rgb(r, g, b))
            })
            .collect();
        legend.extend([
            ("tags".to_string(), palette::FUSED),
            ("Hough corners".to_string(), palette::CORNER),
        ]);
        log_legend(rec, "map/legend", map, &legend)?;
        rec.log_static("report", &rerun::TextDocument::from_markdown(report(scene)))?;
        Ok(())
    }
}

/// The predicted error at each free cell as colour over the map (see-through elsewhere), row 0
/// at the top as the map image.
fn log_error_image(
    rec: &rerun::RecordingStream,
    scene: &PlanScene<'_>,
    frame: &MapFrame,
    max: f64,
) -> Result<(), VizError> {
    // The errors as a map of the same grid, cropped as the map is.
    let errors = OccupancyMap {
        occupancy: scene.prediction.cell_errors_m.clone(),
        ..scene.map.clone()
    };
    let errors = frame.crop(&errors);
    let g = &errors.geometry;
    let mut rgba = vec![0u8; 4 * g.width * g.height];
    for row in 0..g.height {
        for col in 0..g.width {
            if let Some(e) = errors.occupancy[row * g.width + col] {
                let [r, gr, b] = error_colour(e, max);
                let at = 4 * ((g.height - 1 - row) * g.width + col);
                rgba[at..at + 4].copy_from_slice(&[r, gr, b, ERROR_ALPHA]);
            }
        }
    }
    rec.log_static(
        "map/predicted_error",
        &rerun::Image::from_rgba32(rgba, [g.width as u32, g.height as u32]).with_draw_order(1.0),
    )?;
    Ok(())
}

/// The report: what the tags give, and where they go.
fn report(scene: &PlanScene<'_>) -> String {
    let p = scene.prediction;
    let mut md = String::from("# stereotag plan\n\n");
    if !scene.warnings.is_empty() {
        md.push_str("## Warnings\n\n");
        for w in scene.warnings {
            md.push_str(&format!("- {w}\n"));
        }
        md.push('\n');
    }
    // No reachable free cell, no error predicted: "none", not NaN.
    let metres = |v: f64| {
        if v.is_finite() {
            format!("{v:.3} m")
        } else {
            "none".to_owned()
        }
    };
    md += &format!(
        "{} tags {}.\n\n| value | |\n|---:|---|\n\
         | {:.0}% | free cells that see a tag |\n\
         | {} | predicted error, mean over reachable cells |\n\
         | {} | predicted error, worst cell |\n\
         | {:.0}% | free cells a mapped wall holds |\n\
         | {} | free cells no covered cell can be reached from |\n\
         \n## Tags\n\n| tag | x m | y m |\n|---|---:|---:|\n",
        scene.tags_m.len(),
        if scene.proposed { "proposed" } else { "given" },
        100.0 * p.coverage,
        metres(p.predicted_error_mean_m),
        metres(p.predicted_error_max_m),
        100.0 * p.wall_held,
        p.unreachable_cells,
    );
    for (i, t) in scene.tags_m.iter().enumerate() {
        md.push_str(&format!("| {} | {:.2} | {:.2} |\n", i + 1, t[0], t[1]));
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_error_scale_runs_from_green_through_yellow_to_red() {
        assert_eq!(error_colour(0.0, 1.0), [0, 200, 60]);
        assert_eq!(error_colour(0.5, 1.0), [255, 200, 60]);
        assert_eq!(error_colour(1.0, 1.0), [255, 0, 60]);
        assert_eq!(error_colour(7.0, 1.0), [255, 0, 60]);
    }
}
