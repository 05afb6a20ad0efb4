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
        /// What makes the figures speak for little ([`PlanOutput::warnings`]).
        warnings: Vec<String>,
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
        /// What makes the figures speak for little ([`PlanOutput::warnings`]).
        warnings: Vec<String>,
    },
}

/// One map's files, all in one frame: a survey's corrected map, corners and walls when the
/// directory holds a survey (the raw map beside them is drifted), else `map`'s own.
#[derive(Debug, Clone, PartialEq)]
pub struct MapFiles {
    /// `map.yaml` or `map_corrected.yaml`.
    pub map_yaml: std::path::PathBuf,
    /// `corners.csv` or `corners_corrected.csv`.
    pub corners: std::path::PathBuf,
    /// `walls.csv` or `walls_corrected.csv`.
    pub walls: std::path::PathBuf,
    /// The key of `report.json`'s metrics that scores these corners against the world, when it
    /// was known: `features.precision` or `features_corrected.precision`.
    pub precision_key: &'static str,
    /// Whether these are a survey's corrected files.
    pub corrected: bool,
}

impl MapFiles {
    /// The files of the map in `dir`.
    pub fn of(dir: &Path) -> Self {
        let corrected = dir.join("map_corrected.yaml").exists();
        let (suffix, precision_key) = if corrected {
            ("_corrected", "features_corrected.precision")
        } else {
            ("", "features.precision")
        };
        Self {
            map_yaml: dir.join(format!("map{suffix}.yaml")),
            corners: dir.join(format!("corners{suffix}.csv")),
            walls: dir.join(format!("walls{suffix}.csv")),
            precision_key,
            corrected,
        }
    }
}

/// The map's straight walls, `None` when there is no walls file.
fn map_walls(files: &MapFiles, no_walls: bool) -> Result<Option<Vec<WallSegment>>> {
    if no_walls {
        return Ok(Some(Vec::new()));
    }
    if !files.walls.exists() {
        return Ok(None);
    }
    Ok(Some(io::load_walls_csv(&files.walls)?))
}

/// Share of the free cells with no estimate (no way to a covered cell) above which `plan` warns
/// that its figures speak for little of the map: a half.
pub const UNREACHABLE_WARN: f64 = 0.5;

/// Precision of the map's corners against the world (when `report.json` has it) below which
/// `plan` warns that its tag places may not be corners: 0.5.
pub const POOR_CORNERS: f64 = 0.5;

/// Error of the odometry against the run's ground truth (`report.json`'s `ate_m.trajectory`)
/// below which a map on the odometry alone is not warned about: 5 cm.
pub const GOOD_ODOMETRY_M: f64 = 0.05;

/// What is wrong with planning on this map: the corners scored poorly against the world (from
/// the map's `report.json`, when the map was scored) or, with no world to score them, a map
/// placed by the odometry alone (a `map --poses odometry`, or a survey that corrected nothing);
/// most free cells out of reach of any tag; no walls. Each is a sentence for the user.
fn map_warnings(
    dir: &Path,
    files: &MapFiles,
    prediction: &Prediction,
    walls: Option<usize>,
) -> Vec<String> {
    let mut warnings = Vec::new();
    let report_path = dir.join("report.json");
    let report = std::fs::read_to_string(&report_path)
        .ok()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
        .unwrap_or_default();
    let metric = |key: &str| report["metrics"][key].as_f64();
    match metric(files.precision_key) {
        Some(p) if p < POOR_CORNERS => warnings.push(format!(
            "{}: the map's corners score precision {p:.2} against the world ({} in {}): most are not corners, so the places proposed may not be either; map on better poses first (a survey's corrected map, or `map --poses ground-truth`)",
            files.corners.display(),
            files.precision_key,
            report_path.display()
        )),
        Some(_) => {}
        None => warnings.extend(odometry_only(files, &report)),
    }
    let reachable = prediction.free_cells - prediction.unreachable_cells;
    let out_of_reach = prediction.unreachable_cells as f64 / prediction.free_cells.max(1) as f64;
    if out_of_reach > UNREACHABLE_WARN {
        warnings.push(format!(
            "{} of {} free cells ({:.0}%) have no way over free cells to a cell that sees a tag: the predicted error speaks for the other {reachable} only (free cells cut off by unknown ones: a sparse map, or rooms no tag sees)",
            prediction.unreachable_cells,
            prediction.free_cells,
            100.0 * out_of_reach
        ));
    }
    if walls.is_none() {
        warnings.push(format!(
            "{}: no walls file (written by `stereotag map` and `survey`): predicting as with tags only",
            files.walls.display()
        ));
    }
    warnings
}

/// With no world to score its corners: the warning for a map the odometry alone placed, whose
/// drift smears walls and moves corners where the odometry is poor (`map --poses odometry`
/// without a ground truth showing it within [`GOOD_ODOMETRY_M`], or a survey that corrected
/// nothing). `None` for other maps, and for reports that do not say (written before `poses`).
fn odometry_only(files: &MapFiles, report: &serde_json::Value) -> Option<String> {
    let metric = |key: &str| report["metrics"][key].as_f64();
    let error = metric("ate_m.trajectory");
    // `map --poses ground-truth` only for a run that has it (scored against it).
    let truth = if error.or(metric("ate_m.odometry")).is_some() {
        ", or on `map --poses ground-truth`"
    } else {
        ""
    };
    let advice = format!("plan on a survey's corrected map instead (`stereotag survey` corrects the run with its tags, or with the sonar alone before any tag is up){truth}");
    if files.corrected {
        let nothing = metric("offline.nothing_to_correct") == Some(1.0)
            || (metric("offline.kept_solution") == Some(0.0)
                && metric("offline.sightings") == Some(0.0));
        return nothing.then(|| {
            format!(
                "{}: the survey corrected nothing (no tag sighting, and no sonar match it kept): its corrected map is its odometry's, whose drift smears walls and moves corners; the places proposed may not be corners. Survey a run that sees tags, or that drives along its walls again (the sonar then corrects it){truth}",
                files.map_yaml.display()
            )
        });
    }
    if report["poses"].as_str() != Some("odometry") {
        return None;
    }
    if error.is_some_and(|e| e < GOOD_ODOMETRY_M) {
        return None;
    }
    let travel = metric("run.path_m").map_or(String::new(), |m| format!(", {m:.0} m of travel"));
    let against_truth = error.map_or(String::new(), |e| {
        format!("; that odometry is {e:.2} m from the run's ground truth (ate_m.trajectory)")
    });
    Some(format!(
        "{}: placed by the run's odometry alone (`map --poses odometry`{travel}) and not scored against a world{against_truth}: odometry drifts, which smears walls and moves corners, so the places proposed may not be corners; {advice}",
        files.map_yaml.display()
    ))
}

/// Plans tags on a map (or predicts the error with given tags) and, with `out`, writes
/// `plan.json` and `predicted_error.csv` (the predicted error at each free cell).
///
/// A survey's directory is read as its corrected map, corners and walls ([`MapFiles`]). What
/// makes the figures speak for little (corners that scored poorly, most free cells out of
/// reach) is warned about, and listed in `plan.json`'s `warnings`.
pub fn plan(request: &PlanRequest<'_>) -> Result<PlanOutput> {
    let files = MapFiles::of(request.map);
    if files.corrected {
        tracing::info!(
            "{}: a survey: planning on its corrected map, corners and walls",
            request.map.display()
        );
    }
    let map = io::load_ros_occupancy(&files.map_yaml)?;
    let corners = io::load_features_csv(&files.corners)?;
    let loaded_walls = map_walls(&files, request.no_walls)?;
    let walls_found = loaded_walls.as_ref().map(Vec::len);
    let walls = loaded_walls.unwrap_or_default();
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
            let warnings = map_warnings(request.map, &files, &prediction, walls_found);
            let json = serde_json::json!({
                "prediction": prediction,
                "tags_m": tags_m,
                "config": config,
                "map_files": files_json(&files),
                "warnings": warnings,
            });
            PlanOutput::Predicted {
                prediction,
                tags_m,
                walls: walls.len(),
                json,
                warnings,
            }
        }
        None => {
            let plan = plan_tags(&map, &corners, &walls, config);
            let warnings = map_warnings(request.map, &files, &plan.prediction, walls_found);
            let json = serde_json::json!({
                "plan": plan,
                "config": config,
                "map_files": files_json(&files),
                "warnings": warnings,
            });
            PlanOutput::Proposed {
                plan,
                corners: corners.len(),
                walls: walls.len(),
                json,
                warnings,
            }
        }
    };
    for w in output.warnings() {
        tracing::warn!("{w}");
    }
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

/// The files planned on, for `plan.json`.
fn files_json(files: &MapFiles) -> serde_json::Value {
    serde_json::json!({
        "map": files.map_yaml,
        "corners": files.corners,
        "walls": files.walls,
        "corrected": files.corrected,
    })
}

impl PlanOutput {
    /// What makes the figures speak for little (also `plan.json`'s `warnings`).
    pub fn warnings(&self) -> &[String] {
        match self {
            PlanOutput::Proposed { warnings, .. } | PlanOutput::Predicted { warnings, .. } => {
                warnings
            }
        }
    }
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
        warnings: output.warnings(),
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
    // The free cells coloured by the error predicted there.
    let g = &map.geometry;
    let cells = (0..g.width * g.height)
        .map(
            |i| match prediction.cell_errors_m.get(i).copied().flatten() {
                Some(e) if e <= 0.02 => Some(ERROR_COLOURS[0]),
                Some(e) if e <= 0.05 => Some(ERROR_COLOURS[1]),
                Some(_) => Some(ERROR_COLOURS[2]),
                None if map.is_free(i) => Some(ERROR_COLOURS[3]),
                None => None,
            },
        )
        .collect();
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
        cells,
        cell_legend: vec![
            ("error <= 2 cm", ERROR_COLOURS[0]),
            ("<= 5 cm", ERROR_COLOURS[1]),
            ("> 5 cm", ERROR_COLOURS[2]),
            ("out of reach", ERROR_COLOURS[3]),
        ],
    };
    let warned = match output.warnings().len() {
        0 => String::new(),
        1 => " (a warning: see plan.json)".to_string(),
        n => format!(" ({n} warnings: see plan.json)"),
    };
    let title = format!(
        "plan.png: {} tags {what}; {:.0}% of free cells see one; {}{warned}",
        tags_m.len(),
        100.0 * prediction.coverage,
        prediction.error_summary()
    );
    Ok(io::save_map_png(path, map, &title, &overlay)?)
}

/// Colours of `plan.png`'s free cells: predicted error up to 2 cm, up to 5 cm, more, and no
/// estimate (no way to a cell that sees a tag).
const ERROR_COLOURS: [[u8; 3]; 4] = [
    [161, 217, 155],
    [254, 224, 139],
    [244, 137, 110],
    [222, 170, 222],
];

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
