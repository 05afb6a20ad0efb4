//! A sonar map's recording: the finished grid with the trajectory it was built on, the Hough
//! corners and the walls; the grid growing over the run with the beams; the log-odds grid, the
//! Hough accumulator and the report.

use super::draw::*;
use super::layout::{row, tabs, Layout, View};
use super::palette;
use super::sonar::{log_features, log_growing_grid, log_hough};
use super::{MapScene, Recorder, VizError};
use crate::geometry::StampedPose;
use rerun::blueprint::components::PlayState;

/// The default layout of a map: the finished map (with the grid growing, the 3D scene, the
/// log-odds map and the Hough accumulator in tabs) beside the report.
fn layout(frame: &MapFrame) -> Layout {
    let scene = frame.scene_view("Scene (3D)");
    let maps = tabs([
        frame
            .view("Map: trajectory, Hough corners, walls", "/map/final")
            .into(),
        frame
            .view("Map growing (at the time cursor)", "/map/growing")
            .into(),
        scene.into(),
        frame.view("Log-odds map", "/map/log_odds").into(),
        View::spatial_2d("Hough accumulator", "/map/hough").into(),
    ]);
    Layout {
        root: row(
            [maps, View::text_document("Report", "/report").into()],
            &[0.7, 0.3],
        ),
        timeline: "time",
        play: PlayState::Following,
    }
}

impl Recorder {
    /// Logs a sonar map: the finished counting grid with the trajectory that placed the readings
    /// (and the ground truth beside it when the run has one), the offline Hough corners and the
    /// walls, with a legend; the grid growing over the run with each reading's beam; the
    /// log-odds grid; the Hough accumulator; the report.
    pub fn log_map(&self, scene: &MapScene<'_>) -> Result<(), VizError> {
        let rec = self.stream();
        let sonar = scene.map;
        let frame = MapFrame::new(&sonar.counting);
        layout(&frame).send(rec)?;
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        log_world(rec, scene.world)?;

        let mapped_on = if scene.poses == "odometry" {
            palette::ODOMETRY
        } else {
            palette::GROUND_TRUTH
        };
        let mut lines: Vec<(&str, &[StampedPose], rerun::Color)> =
            vec![(scene.poses, scene.trajectory, mapped_on)];
        if let (Some(truth), "odometry") = (&scene.run.ground_truth, scene.poses) {
            lines.push(("ground truth", truth, palette::GROUND_TRUTH));
        }
        log_trajectory_lines(rec, &lines)?;
        log_robot(rec, scene.trajectory)?;

        let map = &frame.map;
        rec.log_static("map/final/grid", &map_image(map))?;
        log_map_trajectories(rec, "map/final/trajectories", map, &lines)?;
        rec.log_static(
            "map/final/corners",
            &map_features(map, &sonar.features_offline),
        )?;
        log_surveyed_walls(rec, &sonar.walls, Some(("map/final", map)))?;
        log_legend(rec, "map/final/legend", map, &map_legend(&lines, false))?;
        rec.log_static(
            "map/log_odds/grid",
            &map_image(&frame.crop(&sonar.log_odds)),
        )?;
        log_hough(rec, "map/hough", &sonar.accumulator)?;
        log_features(rec, "offline", &sonar.features_offline)?;
        log_features(rec, "online", &sonar.features_online)?;
        log_growing_grid(
            rec,
            scene.run,
            scene.trajectory,
            scene.grid,
            &frame,
            "map/growing",
        )?;
        rec.log_static("report", &rerun::TextDocument::from_markdown(report(scene)))?;
        Ok(())
    }
}

/// The report: what the map holds and hides, the warnings, then every figure.
fn report(scene: &MapScene<'_>) -> String {
    let sonar = scene.map;
    let mut md = metrics_markdown("stereotag map", scene.metrics);
    let mut glance = format!(
        "## At a glance\n\n{} readings ({} with an echo) placed with the {} poses: {} Hough \
         corners and edges offline ({} online), {} walls ({:.1} m of wall faces).\n\n",
        sonar.readings,
        sonar.echoes,
        scene.poses,
        sonar.features_offline.len(),
        sonar.features_online.len(),
        sonar.walls.len(),
        sonar.walls.iter().map(|w| w.length_m()).sum::<f64>(),
    );
    glance.push_str(&format!(
        "A cell needs {} of evidence before the map calls it free or occupied{}.\n\n",
        sonar.min_evidence,
        sonar.sampling_spacing_m.map_or(String::new(), |s| format!(
            " (the run reads each sensor every {:.2} m of travel)",
            s
        )),
    ));
    if let Some(scores) = scene.scores {
        let (grid, features) = (&scores.counting, &scores.features_offline);
        glance.push_str(&format!(
            "Against the world: occupied cells precision **{:.3}**, recall **{:.3}**; corners \
             and edges precision **{:.3}**, recall **{:.3}**.\n\n",
            grid.occupied_precision, grid.occupied_recall, features.precision, features.recall
        ));
    }
    if !scene.warnings.is_empty() {
        glance.push_str("## Warnings\n\n");
        for w in scene.warnings {
            glance.push_str(&format!("- {w}\n"));
        }
        glance.push('\n');
    }
    md.insert_str(md.find("| value").unwrap_or(0), &glance);
    md
}
