//! Where to put tags: from a sonar-only map's corners, the tags that cover the most free space,
//! with the localisation error to expect; or the error to expect with tags already up.

use super::Result;
use crate::io::{self, OutputDir};
use crate::plan::{plan_tags, predict, Plan, PlanConfig, Prediction};
use crate::sonar::grid::OccupancyMap;
use crate::sonar::walls::WallSegment;
use crate::viz::{PlanScene, Recorder, Recording, RecordingRequest};
use std::fmt::Write as _;
use std::path::Path;

/// What to plan on.
#[derive(Debug, Clone)]
pub struct PlanRequest<'a> {
    /// A map directory from `map` or `survey` (map.yaml + map.pgm, corners.csv, walls.csv).
    pub map: &'a Path,
    /// Write plan.json, predicted_error.csv, plan.png and plan.rrd here (default: nothing
    /// written).
    pub out: Option<&'a Path>,
    /// The settings.
    pub config: PlanConfig,
    /// Predict the error with the tags of this `landmarks.json` instead of proposing some.
    pub tags: Option<&'a Path>,
    /// Ignore the map's straight walls.
    pub no_walls: bool,
    /// Replace the output directory if it exists.
    pub force: bool,
    /// Where the recording goes (default: `plan.rrd` in `out`; without `out`, only a sink it
    /// names).
    pub recording: RecordingRequest,
}

/// What the planner found.
#[derive(Debug, Clone)]
pub enum PlanOutput {
    /// Tags proposed over the map's corners.
    Proposed {
        /// The plan.
        plan: Plan,
        /// Corners the tags were chosen from.
        corners: usize,
        /// Walls the prediction counted on.
        walls: usize,
        /// plan.json's contents.
        json: serde_json::Value,
    },
    /// The error to expect with tags already up.
    Predicted {
        /// The prediction.
        prediction: Prediction,
        /// The tags' positions.
        tags_m: Vec<[f64; 2]>,
        /// Walls the prediction counted on.
        walls: usize,
        /// plan.json's contents.
        json: serde_json::Value,
    },
}

/// The map's straight walls (`walls.csv` of `map`, or a survey's `walls_corrected.csv`).
fn map_walls(map: &Path, no_walls: bool) -> Result<Vec<WallSegment>> {
    if no_walls {
        return Ok(Vec::new());
    }
    match ["walls.csv", "walls_corrected.csv"]
        .iter()
        .map(|f| map.join(f))
        .find(|p| p.exists())
    {
        Some(path) => Ok(io::load_walls_csv(&path)?),
        None => {
            tracing::warn!(
                "{}: no walls.csv (written by `stereotag map`): predicting as with tags only",
                map.display()
            );
            Ok(Vec::new())
        }
    }
}

/// Plans tags on a map (or predicts the error with given tags) and, with `out`, writes
/// `plan.json` and `predicted_error.csv` (the predicted error at each free cell).
pub fn plan(request: &PlanRequest<'_>) -> Result<PlanOutput> {
    let map = io::load_ros_occupancy(&request.map.join("map.yaml"))?;
    let corners = io::load_features_csv(&request.map.join("corners.csv"))?;
    let walls = map_walls(request.map, request.no_walls)?;
    let config = &request.config;
    let output = match request.tags {
        Some(tags) => {
            let file = io::load_landmarks(tags)?;
            let tags_m: Vec<[f64; 2]> = file
                .landmarks
                .iter()
                .map(|r| [r.landmark.position_m[0], r.landmark.position_m[1]])
                .collect();
            let prediction = predict(&map, &tags_m, &walls, config);
            let json =
                serde_json::json!({ "prediction": prediction, "tags_m": tags_m, "config": config });
            PlanOutput::Predicted {
                prediction,
                tags_m,
                walls: walls.len(),
                json,
            }
        }
        None => {
            let plan = plan_tags(&map, &corners, &walls, config);
            let json = serde_json::json!({ "plan": plan, "config": config });
            PlanOutput::Proposed {
                plan,
                corners: corners.len(),
                walls: walls.len(),
                json,
            }
        }
    };
    if let Some(out) = request.out {
        let (json, errors) = match &output {
            PlanOutput::Proposed { plan, json, .. } => (json, &plan.prediction.cell_errors_m),
            PlanOutput::Predicted {
                prediction, json, ..
            } => (json, &prediction.cell_errors_m),
        };
        let dir = OutputDir::create(out, request.force)?;
        io::save_json(&dir.path("plan.json"), json)?;
        save_predicted_error(&dir.path("predicted_error.csv"), &map, errors)?;
        save_plan_picture(&dir.path("plan.png"), &map, &corners, &output)?;
        record(request, &map, &corners, &output, &dir.path("plan.rrd"))?;
        dir.commit()?;
    } else if request.recording.names_a_sink() {
        // Only the sinks named: there is no output directory for a default file.
        record(request, &map, &corners, &output, Path::new("plan.rrd"))?;
    }
    Ok(output)
}

/// Records the plan to the sinks asked for (`default_file` when none is named).
fn record(
    request: &PlanRequest<'_>,
    map: &OccupancyMap,
    corners: &[crate::sonar::hough::Feature],
    output: &PlanOutput,
    default_file: &Path,
) -> Result<()> {
    let Some(rec) = Recorder::open(&request.recording, Recording::Plan, default_file)? else {
        return Ok(());
    };
    let (tags_m, prediction, proposed) = tags_of(output);
    rec.log_plan(&PlanScene {
        map,
        corners,
        tags_m: &tags_m,
        proposed,
        prediction,
    })?;
    rec.finish()?;
    Ok(())
}

/// The tags (proposed or given), the prediction with them and whether they were proposed.
fn tags_of(output: &PlanOutput) -> (Vec<[f64; 2]>, &Prediction, bool) {
    match output {
        PlanOutput::Proposed { plan, .. } => (
            plan.tags.iter().map(|t| [t.x_m, t.y_m]).collect(),
            &plan.prediction,
            true,
        ),
        PlanOutput::Predicted {
            prediction, tags_m, ..
        } => (tags_m.clone(), prediction, false),
    }
}

/// `plan.png`: the map with its Hough corners and the tags (proposed or given), numbered, and
/// the predicted error in the title.
fn save_plan_picture(
    path: &Path,
    map: &OccupancyMap,
    corners: &[crate::sonar::hough::Feature],
    output: &PlanOutput,
) -> Result<()> {
    use crate::picture::{colours, Mark, Overlay};
    let (tags_m, prediction, proposed) = tags_of(output);
    let what = if proposed { "proposed" } else { "given" };
    let mut marks = Mark::corners(corners);
    marks.extend(tags_m.iter().enumerate().map(|(i, &at_m)| Mark {
        at_m,
        colour: colours::LANDMARK,
        label: format!("tag {}", i + 1),
    }));
    let overlay = Overlay {
        paths: Vec::new(),
        marks,
        mark_legend: vec![
            ("Hough corner", colours::CORNER),
            ("tag", colours::LANDMARK),
        ],
    };
    let title = format!(
        "plan.png: {} tags {what}; {:.0}% of free cells see one; predicted error mean {:.3} m, worst {:.3} m",
        tags_m.len(),
        100.0 * prediction.coverage,
        prediction.predicted_error_mean_m,
        prediction.predicted_error_max_m
    );
    Ok(io::save_map_png(path, map, &title, &overlay)?)
}

/// `predicted_error.csv`: the predicted error at each free cell's centre.
fn save_predicted_error(
    path: &Path,
    map: &OccupancyMap,
    cell_errors_m: &[Option<f64>],
) -> Result<()> {
    let g = &map.geometry;
    let mut csv = String::from("x_m,y_m,error_m\n");
    for (i, e) in cell_errors_m.iter().enumerate() {
        if let Some(e) = e {
            let [x, y] = g.centre(i % g.width, i / g.width);
            let _ = writeln!(csv, "{x:.3},{y:.3},{e:.4}");
        }
    }
    Ok(io::write_file(path, csv.as_bytes())?)
}
