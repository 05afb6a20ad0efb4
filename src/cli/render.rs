use super::{Bars, UsageError};
use std::path::PathBuf;
use stereotag::geometry::Pose2;
use stereotag::io::DEFAULT_RIG;
use stereotag::workflow::render::{
    render_calibration_sequence, render_pose, render_sequence, RenderRequest,
};

/// Arguments of `stereotag render`.
#[derive(Debug, clap::Args)]
pub struct Render {
    /// World file (not needed with --calibration-sequence).
    #[arg(long, required_unless_present = "calibration_sequence")]
    world: Option<PathBuf>,
    /// Stereo rig file (Kalibr camchain).
    #[arg(long, default_value = DEFAULT_RIG)]
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
    /// The request shared by the three modes.
    fn request(&self) -> RenderRequest<'_> {
        RenderRequest {
            rig: &self.rig,
            out: &self.out,
            samples: self.samples,
            every_sample: self.every_sample,
            motion: self.motion,
            seed: self.seed,
            force: self.force,
        }
    }

    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        if let (Some(n), Some(target)) = (self.calibration_sequence, &self.target) {
            let views = render_calibration_sequence(&self.request(), n, target, &Bars::new(quiet))?;
            tracing::info!(
                "rendered {views} calibration pairs -> {}",
                self.out.display()
            );
            return Ok(());
        }
        let world = self
            .world
            .as_deref()
            .ok_or_else(|| UsageError("--world is needed to render a scene".into()))?;
        if let Some(poses) = &self.poses {
            let pairs = render_sequence(&self.request(), world, poses, &Bars::new(quiet))?;
            tracing::info!("rendered {pairs} pairs -> {}", self.out.display());
            return Ok(());
        }
        let [x, y, theta] =
            parse_pose("--pose", self.pose.as_deref().unwrap_or_default()).map_err(UsageError)?;
        let rendered = render_pose(&self.request(), world, Pose2::new(x, y, theta))?;
        tracing::info!(
            "rendered in {:.3} s; {} tags in view -> {}",
            rendered.secs,
            rendered.tags,
            self.out.display()
        );
        Ok(())
    }
}
