use std::path::PathBuf;
use stereotag::io::{self, OutputDir};
use stereotag::plan::{plan_tags, predict, PlanConfig};
use stereotag::sonar::grid::OccupancyMap;

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
}

impl PlanArgs {
    pub fn run(&self) -> anyhow::Result<()> {
        let map = io::load_ros_occupancy(&self.map.join("map.yaml"))?;
        let corners = io::load_features_csv(&self.map.join("corners.csv"))?;
        let mut config = if self.no_visual_odometry {
            PlanConfig::wheels_only()
        } else {
            PlanConfig::default()
        };
        if let Some(r) = self.range_m {
            config.capture_range_m = r;
        }
        if let Some(n) = self.max_tags {
            config.max_tags = n;
        }
        let walls = if self.no_walls {
            Vec::new()
        } else {
            match ["walls.csv", "walls_corrected.csv"]
                .iter()
                .map(|f| self.map.join(f))
                .find(|p| p.exists())
            {
                Some(path) => io::load_walls_csv(&path)?,
                None => {
                    tracing::warn!(
                        "{}: no walls.csv (written by `stereotag map`): predicting as with tags only",
                        self.map.display()
                    );
                    Vec::new()
                }
            }
        };
        if let Some(tags) = &self.tags {
            let file = io::load_landmarks(tags)?;
            let positions: Vec<[f64; 2]> = file
                .landmarks
                .iter()
                .map(|r| [r.landmark.position_m[0], r.landmark.position_m[1]])
                .collect();
            let prediction = predict(&map, &positions, &walls, &config);
            tracing::info!(
                "{} tags from {}: {:.0}% of {} free cells see one, {:.0}% are held by {} walls; predicted error mean {:.3} m, worst {:.3} m",
                positions.len(),
                tags.display(),
                100.0 * prediction.coverage,
                prediction.free_cells,
                100.0 * prediction.wall_held,
                walls.len(),
                prediction.predicted_error_mean_m,
                prediction.predicted_error_max_m
            );
            let json = serde_json::json!({ "prediction": prediction, "tags_m": positions, "config": config });
            return self.write(&json, &map, &prediction.cell_errors_m);
        }
        let plan = plan_tags(&map, &corners, &walls, &config);
        let json = serde_json::json!({ "plan": plan, "config": config });
        self.write(&json, &map, &plan.prediction.cell_errors_m)?;
        tracing::info!(
            "{} tags proposed over {} corners: {:.0}% of {} free cells see one, {:.0}% are held by {} walls; predicted error mean {:.3} m, worst {:.3} m",
            plan.tags.len(),
            corners.len(),
            100.0 * plan.prediction.coverage,
            plan.prediction.free_cells,
            100.0 * plan.prediction.wall_held,
            walls.len(),
            plan.prediction.predicted_error_mean_m,
            plan.prediction.predicted_error_max_m
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

    /// plan.json and predicted_error.csv into `--out`, or plan.json printed.
    fn write(
        &self,
        json: &serde_json::Value,
        map: &OccupancyMap,
        cell_errors_m: &[Option<f64>],
    ) -> anyhow::Result<()> {
        match &self.out {
            Some(out) => {
                let dir = OutputDir::create(out, self.force)?;
                io::save_json(&dir.path("plan.json"), json)?;
                let g = &map.geometry;
                let mut csv = String::from("x_m,y_m,error_m\n");
                for (i, e) in cell_errors_m.iter().enumerate() {
                    if let Some(e) = e {
                        let (x, y) = g.centre(i % g.width, i / g.width);
                        csv.push_str(&format!("{x:.3},{y:.3},{e:.4}\n"));
                    }
                }
                std::fs::write(dir.path("predicted_error.csv"), csv)?;
                dir.commit()?;
            }
            None => println!("{}", serde_json::to_string_pretty(json)?),
        }
        Ok(())
    }
}
