use super::UsageError;
use std::path::PathBuf;
use stereotag::geometry::Pose2;
use stereotag::io::{self, OutputDir};
use stereotag::render::{render_pair, RenderConfig};

/// Arguments of `stereotag render`.
#[derive(Debug, clap::Args)]
pub struct Render {
    /// World file.
    #[arg(long)]
    world: PathBuf,
    /// Stereo rig file (Kalibr camchain).
    #[arg(long, default_value = "calibration/rigs/default.yaml")]
    rig: PathBuf,
    /// Robot pose `x,y,theta` (metres, radians).
    #[arg(long, allow_hyphen_values = true)]
    pose: String,
    /// Output directory: left.png, right.png, truth.json.
    #[arg(long)]
    out: PathBuf,
    /// Sensor noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

impl Render {
    pub fn run(&self) -> anyhow::Result<()> {
        let parts: Vec<f64> = self
            .pose
            .split(',')
            .map(|p| p.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| {
                UsageError(format!(
                    "--pose {}: expected x,y,theta in metres and radians, e.g. 2.5,2.5,0",
                    self.pose
                ))
            })?;
        let [x, y, theta] = parts[..] else {
            return Err(UsageError(format!(
                "--pose {}: expected three numbers x,y,theta",
                self.pose
            ))
            .into());
        };
        if !(x.is_finite() && y.is_finite() && theta.is_finite()) {
            return Err(UsageError(format!("--pose {}: numbers must be finite", self.pose)).into());
        }
        let loaded = io::load_world(&self.world)?;
        let rig = io::load_rig(&self.rig)?;
        let config = RenderConfig {
            seed: self.seed,
            ..RenderConfig::default()
        };
        let start = std::time::Instant::now();
        let pair = render_pair(&loaded.world, &rig, Pose2::new(x, y, theta), &config)?;
        let secs = start.elapsed().as_secs_f64();
        let dir = OutputDir::create(&self.out, self.force)?;
        let save = |img: &image::GrayImage, name: &str| {
            img.save(dir.path(name))
                .map_err(|e| anyhow::anyhow!("{}: {e}", dir.target().join(name).display()))
        };
        save(&pair.left, "left.png")?;
        save(&pair.right, "right.png")?;
        let truth = serde_json::json!({
            "world_from_robot": [x, y, theta],
            "tags": pair.tags,
        });
        io::save_json(&dir.path("truth.json"), &truth)?;
        dir.commit()?;
        tracing::info!(
            "rendered in {secs:.3} s; {} tags in view -> {}",
            pair.tags.len(),
            self.out.display()
        );
        Ok(())
    }
}
