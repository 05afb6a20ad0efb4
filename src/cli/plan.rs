use std::path::PathBuf;
use stereotag::plan::PlanConfig;
use stereotag::workflow::plan::{plan, PlanOutput, PlanRequest};

/// Arguments of `stereotag plan`.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// A map directory from `stereotag map` or `survey` (map.yaml + map.pgm and corners.csv).
    #[arg(long)]
    map: PathBuf,
    /// Output directory: plan.json, predicted_error.csv, plan.png (a picture of the map with the
    /// tags) and plan.rrd (the Rerun recording: the predicted error over the map) (default:
    /// print plan.json).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Largest useful distance to a tag, metres.
    #[arg(long, default_value_t = PlanConfig::default().capture_range_m)]
    range_m: f64,
    /// Tags at most.
    #[arg(long, default_value_t = PlanConfig::default().max_tags)]
    max_tags: usize,
    /// Predict the error with these tags instead of proposing some: a survey's landmarks.json
    /// (the tags already up).
    #[arg(long, value_name = "LANDMARKS_JSON")]
    tags: Option<PathBuf>,
    /// Ignore the map's straight walls (walls.csv, or a survey's walls_corrected.csv): predict
    /// as for `localize --no-walls`.
    #[arg(long)]
    no_walls: bool,
    /// Predict for a robot that does not measure its turns with its cameras between sightings
    /// (`localize` with `visual_odometry: false`, or runs with pictures of tags only).
    #[arg(long)]
    no_visual_odometry: bool,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    rerun: super::RerunArgs,
}

impl PlanArgs {
    pub fn run(&self) -> anyhow::Result<()> {
        let mut config = if self.no_visual_odometry {
            PlanConfig::wheels_only()
        } else {
            PlanConfig::default()
        };
        config.capture_range_m = self.range_m;
        config.max_tags = self.max_tags;
        let output = plan(&PlanRequest {
            map: &self.map,
            out: self.out.as_deref(),
            config,
            tags: self.tags.as_deref(),
            no_walls: self.no_walls,
            force: self.force,
            recording: self.rerun.request()?,
        })?;
        let json = match &output {
            PlanOutput::Predicted {
                prediction,
                tags_m,
                walls,
                json,
                ..
            } => {
                tracing::info!(
                    "{} tags from {}: {:.0}% of {} free cells see one, {:.0}% are held by {} walls; {}{}",
                    tags_m.len(),
                    self.tags.as_deref().unwrap_or(std::path::Path::new("")).display(),
                    100.0 * prediction.coverage,
                    prediction.free_cells,
                    100.0 * prediction.wall_held,
                    walls,
                    prediction.error_summary(),
                    out_of_reach(prediction)
                );
                json
            }
            PlanOutput::Proposed {
                plan,
                corners,
                walls,
                json,
                ..
            } => {
                tracing::info!(
                    "{} tags proposed over {} corners: {:.0}% of {} free cells see one, {:.0}% are held by {} walls; {}{}",
                    plan.tags.len(),
                    corners,
                    100.0 * plan.prediction.coverage,
                    plan.prediction.free_cells,
                    100.0 * plan.prediction.wall_held,
                    walls,
                    plan.prediction.error_summary(),
                    out_of_reach(&plan.prediction)
                );
                for t in &plan.tags {
                    tracing::info!(
                        "  tag at ({:.2}, {:.2}) m: {} {} votes, {} new cells",
                        t.x_m,
                        t.y_m,
                        t.kind.as_str(),
                        t.votes,
                        t.new_cells
                    );
                }
                json
            }
        };
        if self.out.is_none() {
            super::print_out(&(serde_json::to_string_pretty(json)? + "\n"))?;
        }
        Ok(())
    }
}

/// ", over N free cells (M out of reach of any tag)" when some are: the mean and worst leave
/// those out.
fn out_of_reach(p: &stereotag::plan::Prediction) -> String {
    if p.unreachable_cells == 0 {
        return String::new();
    }
    format!(
        " over the {} free cells within reach ({} have no way to a cell that sees a tag)",
        p.free_cells - p.unreachable_cells,
        p.unreachable_cells
    )
}
