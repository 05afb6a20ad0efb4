use super::UsageError;
use std::path::PathBuf;
use stereotag::geometry::Pose2;
use stereotag::io::{self, OutputDir};
use stereotag::render::{render_pair, RenderConfig, Renderer};

/// Arguments of `stereotag render`.
#[derive(Debug, clap::Args)]
pub struct Render {
    /// World file.
    #[arg(long)]
    world: PathBuf,
    /// Stereo rig file (Kalibr camchain).
    #[arg(long, default_value = "calibration/rigs/default.yaml")]
    rig: PathBuf,
    /// Robot pose `x,y,theta` (metres, radians): one pair.
    #[arg(
        long,
        allow_hyphen_values = true,
        required_unless_present = "poses",
        conflicts_with = "poses"
    )]
    pose: Option<String>,
    /// Sequence mode: a pose CSV (`t_s,x_m,y_m,theta_rad`, e.g. a run's ground_truth.csv); writes
    /// left/NNNNNN.png, right/NNNNNN.png and one truth.json listing every frame.
    #[arg(long)]
    poses: Option<PathBuf>,
    /// Output directory: left.png, right.png, truth.json (one pair) or the sequence.
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
        if let Some(poses) = &self.poses {
            return self.run_sequence(poses);
        }
        let pose = self.pose.as_deref().unwrap_or_default();
        let parts: Vec<f64> = pose
            .split(',')
            .map(|p| p.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| {
                UsageError(format!(
                    "--pose {}: expected x,y,theta in metres and radians, e.g. 2.5,2.5,0",
                    pose
                ))
            })?;
        let [x, y, theta] = parts[..] else {
            return Err(
                UsageError(format!("--pose {}: expected three numbers x,y,theta", pose)).into(),
            );
        };
        if !(x.is_finite() && y.is_finite() && theta.is_finite()) {
            return Err(UsageError(format!("--pose {pose}: numbers must be finite")).into());
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

    fn run_sequence(&self, poses_path: &std::path::Path) -> anyhow::Result<()> {
        let poses = io::read_poses(poses_path)?;
        let loaded = io::load_world(&self.world)?;
        let rig = io::load_rig(&self.rig)?;
        let renderer = Renderer::new(&rig);
        let dir = OutputDir::create(&self.out, self.force)?;
        std::fs::create_dir_all(dir.path("left"))?;
        std::fs::create_dir_all(dir.path("right"))?;
        let bar = super::progress(poses.len() as u64, "render", false);
        let mut frames = Vec::with_capacity(poses.len());
        for (k, p) in poses.iter().enumerate() {
            let config = RenderConfig {
                seed: self.seed.wrapping_add(k as u64),
                ..RenderConfig::default()
            };
            let pair = renderer.render(&loaded.world, p.pose, &config)?;
            let (left, right) = (format!("left/{k:06}.png"), format!("right/{k:06}.png"));
            pair.left
                .save(dir.path(&left))
                .map_err(|e| anyhow::anyhow!("{}: {e}", dir.target().join(&left).display()))?;
            pair.right
                .save(dir.path(&right))
                .map_err(|e| anyhow::anyhow!("{}: {e}", dir.target().join(&right).display()))?;
            frames.push(serde_json::json!({
                "t_s": p.t_s,
                "world_from_robot": [p.pose.x, p.pose.y, p.pose.theta],
                "left": left,
                "right": right,
                "tags": pair.tags,
            }));
            bar.inc(1);
        }
        bar.finish_and_clear();
        io::save_json(
            &dir.path("truth.json"),
            &serde_json::json!({ "frames": frames }),
        )?;
        dir.commit()?;
        tracing::info!("rendered {} pairs -> {}", poses.len(), self.out.display());
        Ok(())
    }
}
