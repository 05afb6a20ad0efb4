use std::path::PathBuf;
use stereotag::io::{self, OutputDir};
use stereotag::plan::{plan_tags, PlanConfig};

/// Arguments of `stereotag plan`.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// A map directory from `stereotag map` or `survey` (map.yaml + map.pgm and corners.csv).
    #[arg(long)]
    map: PathBuf,
    /// Write plan.json here (default: print it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Largest useful distance to a tag, metres.
    #[arg(long)]
    range_m: Option<f64>,
    /// Tags at most.
    #[arg(long)]
    max_tags: Option<usize>,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

impl PlanArgs {
    pub fn run(&self) -> anyhow::Result<()> {
        let map = io::load_ros_occupancy(&self.map.join("map.yaml"))?;
        let corners = io::load_features_csv(&self.map.join("corners.csv"))?;
        let mut config = PlanConfig::default();
        if let Some(r) = self.range_m {
            config.capture_range_m = r;
        }
        if let Some(n) = self.max_tags {
            config.max_tags = n;
        }
        let plan = plan_tags(&map, &corners, &config);
        let json = serde_json::json!({ "plan": plan, "config": config });
        match &self.out {
            Some(out) => {
                let dir = OutputDir::create(out, self.force)?;
                io::save_json(&dir.path("plan.json"), &json)?;
                dir.commit()?;
            }
            None => println!("{}", serde_json::to_string_pretty(&json)?),
        }
        tracing::info!(
            "{} tags proposed over {} corners: {:.0}% of {} free cells see one; predicted error mean {:.3} m, worst {:.3} m",
            plan.tags.len(),
            corners.len(),
            100.0 * plan.coverage,
            plan.free_cells,
            plan.predicted_error_mean_m,
            plan.predicted_error_max_m
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
        Ok(())
    }
}
