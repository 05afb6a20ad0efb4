use super::UsageError;
use std::path::PathBuf;
use stereotag::geometry::Pose2;
use stereotag::io::{self, OutputDir};
use stereotag::render::{RenderConfig, Renderer};

/// Arguments of `stereotag render`.
#[derive(Debug, clap::Args)]
pub struct Render {
    /// World file (not needed with --calibration-sequence).
    #[arg(long, required_unless_present = "calibration_sequence")]
    world: Option<PathBuf>,
    /// Stereo rig file (Kalibr camchain).
    #[arg(long, default_value = super::DEFAULT_RIG)]
    rig: PathBuf,
    /// Robot pose `x,y,theta` (metres, radians): one pair.
    #[arg(
        long,
        allow_hyphen_values = true,
        required_unless_present_any = ["poses", "calibration_sequence"],
        conflicts_with_all = ["poses", "calibration_sequence"]
    )]
    pose: Option<String>,
    /// Sequence mode: a pose CSV (`t_s,x_m,y_m,theta_rad`, e.g. a run's ground_truth.csv); writes
    /// left/NNNNNN.png, right/NNNNNN.png and one truth.json listing every frame.
    #[arg(long, conflicts_with = "calibration_sequence")]
    poses: Option<PathBuf>,
    /// Calibration mode: N views of the --target board in front of the rig, poses spread over
    /// the image and tilted; writes left/NNNNNN.png, right/NNNNNN.png, rig.yaml (the true rig)
    /// and truth.json (board pose and every corner's true pixel in both images, per view).
    #[arg(long, value_name = "N", requires = "target")]
    calibration_sequence: Option<usize>,
    /// Calibration target (Kalibr target YAML) for --calibration-sequence.
    #[arg(long)]
    target: Option<PathBuf>,
    /// Output directory: left.png, right.png, truth.json (one pair) or the sequence.
    #[arg(long)]
    out: PathBuf,
    /// Samples per pixel, a square number (4 = 2 x 2 jittered strata; 16 comes closer to a
    /// sensor that integrates light over each pixel's whole area, at four times the cost).
    /// Default: 4, and 16 for --calibration-sequence (a calibration is judged at hundredths of
    /// a pixel, where four jittered samples leave edge noise no real sensor has).
    #[arg(long, value_parser = samples_per_pixel)]
    samples: Option<usize>,
    /// Trace every sample of every pixel. By default a pixel that no edge of the scene crosses
    /// (no wall's end, foot or top, no tag) is traced with one ray, since all its samples meet
    /// the same surface; the images differ by a grey level here and there, at twice the cost.
    #[arg(long)]
    every_sample: bool,
    /// Motion blur: how far the robot moves during the exposure, `x,y,theta` in its own frame
    /// (metres forward and left, radians), centred on the pose rendered, e.g. 0.02,0,0.05.
    #[arg(
        long,
        allow_hyphen_values = true,
        conflicts_with = "calibration_sequence",
        value_parser = motion_arg
    )]
    motion: Option<Pose2>,
    /// Sensor noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

/// Samples per pixel of scenes (issue 3: at least 4).
const SCENE_SAMPLES: usize = 4;
/// Samples per pixel of calibration views.
const CALIBRATION_SAMPLES: usize = 16;

/// Parses `x,y,theta` (metres, radians) given to `flag`.
fn parse_pose(flag: &str, text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            format!("{flag} {text}: expected x,y,theta in metres and radians, e.g. 2.5,2.5,0")
        })?;
    let [x, y, theta] = parts[..] else {
        return Err(format!("{flag} {text}: expected three numbers x,y,theta"));
    };
    if !(x.is_finite() && y.is_finite() && theta.is_finite()) {
        return Err(format!("{flag} {text}: numbers must be finite"));
    }
    Ok([x, y, theta])
}

/// Parses `--motion`.
fn motion_arg(text: &str) -> Result<Pose2, String> {
    let [x, y, theta] = parse_pose("--motion", text)?;
    Ok(Pose2::new(x, y, theta))
}

/// Parses `--samples`: a square number from 1 to 64.
fn samples_per_pixel(text: &str) -> Result<usize, String> {
    let n: usize = text
        .parse()
        .map_err(|_| format!("`{text}` is not a whole number"))?;
    let side = (n as f64).sqrt().round() as usize;
    if side * side != n || !(1..=64).contains(&n) {
        return Err(format!(
            "{n} is not a square number from 1 to 64 (4, 9, 16, ...)"
        ));
    }
    Ok(n)
}

impl Render {
    /// Render settings with the noise seed and `--motion`.
    fn config(&self, seed: u64) -> RenderConfig {
        RenderConfig {
            seed,
            motion: self.motion,
            ..RenderConfig::default()
        }
    }

    /// The renderer for `rig` with `--samples` per pixel.
    fn renderer(&self, rig: &stereotag::camera::StereoRig) -> Renderer {
        let default = if self.calibration_sequence.is_some() {
            CALIBRATION_SAMPLES
        } else {
            SCENE_SAMPLES
        };
        let n = self.samples.unwrap_or(default);
        let renderer = Renderer::with_samples(rig, (n as f64).sqrt().round() as usize);
        if self.every_sample {
            renderer.with_every_sample()
        } else {
            renderer
        }
    }

    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        if let (Some(n), Some(target)) = (self.calibration_sequence, &self.target) {
            return self.run_calibration_sequence(n, target, quiet);
        }
        let world = self
            .world
            .as_deref()
            .ok_or_else(|| UsageError("--world is needed to render a scene".into()))?;
        if let Some(poses) = &self.poses {
            return self.run_sequence(world, poses, quiet);
        }
        let [x, y, theta] =
            parse_pose("--pose", self.pose.as_deref().unwrap_or_default()).map_err(UsageError)?;
        let loaded = io::load_world(world)?;
        let rig = super::load_rig_arg(&self.rig)?;
        let config = self.config(self.seed);
        let start = std::time::Instant::now();
        let pair = self
            .renderer(&rig)
            .render(&loaded.world, Pose2::new(x, y, theta), &config)?;
        let secs = start.elapsed().as_secs_f64();
        let dir = OutputDir::create(&self.out, self.force)?;
        let save = |img: &image::GrayImage, name: &str| io::save_camera_png(&dir.path(name), img);
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

    fn run_sequence(
        &self,
        world: &std::path::Path,
        poses_path: &std::path::Path,
        quiet: bool,
    ) -> anyhow::Result<()> {
        let poses = io::read_poses(poses_path)?;
        let loaded = io::load_world(world)?;
        let rig = super::load_rig_arg(&self.rig)?;
        let renderer = self.renderer(&rig);
        let dir = OutputDir::create(&self.out, self.force)?;
        std::fs::create_dir_all(dir.path("left"))?;
        std::fs::create_dir_all(dir.path("right"))?;
        let bar = super::progress(poses.len() as u64, "render", quiet);
        let mut frames = Vec::with_capacity(poses.len());
        for (k, p) in poses.iter().enumerate() {
            let config = self.config(self.seed.wrapping_add(k as u64));
            let pair = renderer.render(&loaded.world, p.pose, &config)?;
            let (left, right) = save_pair(&dir, k, &pair.left, &pair.right)?;
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

/// Writes the `k`th pair of a sequence as left/NNNNNN.png and right/NNNNNN.png; returns the
/// names.
fn save_pair(
    dir: &OutputDir,
    k: usize,
    left: &image::GrayImage,
    right: &image::GrayImage,
) -> anyhow::Result<(String, String)> {
    let names = (format!("left/{k:06}.png"), format!("right/{k:06}.png"));
    for (img, name) in [(left, &names.0), (right, &names.1)] {
        io::save_camera_png(&dir.path(name), img)?;
    }
    Ok(names)
}

impl Render {
    fn run_calibration_sequence(
        &self,
        n: usize,
        target_path: &std::path::Path,
        quiet: bool,
    ) -> anyhow::Result<()> {
        use stereotag::render::board::{calibration_poses, Board};
        let target = io::load_target(target_path)?;
        let rig = super::load_rig_arg(&self.rig)?;
        let board = match &target {
            io::Target::Aprilgrid(g) => {
                Board::aprilgrid(g.tag_cols, g.tag_rows, g.tag_size, g.tag_spacing)?
            }
            io::Target::Checkerboard(c) => Board::Chessboard {
                cols: c.target_cols,
                rows: c.target_rows,
                col_m: c.col_spacing_m,
                row_m: c.row_spacing_m,
            },
        };
        let poses = calibration_poses(&rig, &board, n, self.seed);
        if poses.len() < n {
            tracing::warn!(
                "the whole board fits both images in only {} of {n} views tried: a smaller board or a wider lens helps",
                poses.len()
            );
        }
        let renderer = self.renderer(&rig);
        let dir = OutputDir::create(&self.out, self.force)?;
        std::fs::create_dir_all(dir.path("left"))?;
        std::fs::create_dir_all(dir.path("right"))?;
        io::save_rig(&dir.path("rig.yaml"), &rig)?;
        let bar = super::progress(poses.len() as u64, "render", quiet);
        let mut frames = Vec::with_capacity(poses.len());
        for (k, pose) in poses.iter().enumerate() {
            let config = RenderConfig {
                seed: self.seed.wrapping_add(k as u64),
                ..RenderConfig::default()
            };
            let view = renderer.render_board(&board, pose, &config);
            let (left, right) = save_pair(&dir, k, &view.left, &view.right)?;
            let q = pose.rotation.coords;
            let t = pose.translation.vector;
            frames.push(serde_json::json!({
                "left": left,
                "right": right,
                "left_from_board": {"t_m": [t.x, t.y, t.z], "q_xyzw": [q.x, q.y, q.z, q.w]},
                "corners": view.corners,
            }));
            bar.inc(1);
        }
        bar.finish_and_clear();
        io::save_json(
            &dir.path("truth.json"),
            &serde_json::json!({ "target": target, "frames": frames }),
        )?;
        dir.commit()?;
        tracing::info!(
            "rendered {} calibration pairs -> {}",
            poses.len(),
            self.out.display()
        );
        Ok(())
    }
}
