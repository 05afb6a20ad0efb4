use super::{Bars, UsageError};
use std::path::PathBuf;
use stereotag::io::DEFAULT_RIG;
use stereotag::sim::capture::CapturePolicy;
use stereotag::sonar::SonarLayout;
use stereotag::workflow::simulate::{simulate, Pictures, SimSettings, SimulateRequest};

/// Arguments of `stereotag simulate`.
#[derive(Debug, clap::Args)]
pub struct Simulate {
    /// World file (YAML).
    #[arg(long)]
    world: PathBuf,
    /// Output run directory.
    #[arg(long)]
    out: PathBuf,
    /// Random seed (default: the world file's, else 1).
    #[arg(long)]
    seed: Option<u64>,
    /// Time budget in seconds (default: the world file's, else 1800).
    #[arg(long)]
    duration_s: Option<f64>,
    /// Sonar layout: frontal5 (the paper's five frontal sonars) or pioneer16 (Pioneer 3-DX ring).
    #[arg(long)]
    layout: Option<String>,
    /// Perfect odometry (no wheel errors).
    #[arg(long)]
    no_odometry_noise: bool,
    /// The paper's exploration only: no look-around at the start, no second drive of the first
    /// boundary loop (both added for surveys).
    #[arg(long)]
    paper_exploration: bool,
    /// Stereo rig of the pictures (taken whenever a tag is in view, and every 0.3 m or 20
    /// degrees in between for the visual odometry).
    #[arg(long, default_value = DEFAULT_RIG)]
    rig: PathBuf,
    /// Take no stereo pictures (sonar and odometry only).
    #[arg(long)]
    no_stereo: bool,
    /// Take pictures only when a tag is in view (none in between for the visual odometry).
    #[arg(long, conflicts_with = "no_stereo")]
    tag_pictures_only: bool,
    /// When --rig does not say where it sits on the robot (no robot_from_left, or the identity
    /// that `calibrate` writes), take the left camera at the robot centre, looking ahead, 0.3 m
    /// up, instead of stopping.
    #[arg(long, conflicts_with = "no_stereo")]
    default_mounting: bool,
    /// Follow this path instead of exploring: a pose CSV (`t_s,x_m,y_m,theta_rad`), e.g. a real
    /// log's ground_truth.csv (`stereotag import`) or a path drawn on a floor plan. The sonar,
    /// the odometry (with its wheel errors) and the pictures are simulated along it; the run
    /// lasts as long as the path. The robot drives it as wheels can: never sideways, steering
    /// back to it when a pose lies off to its side (ground_truth.csv is where it went).
    #[arg(long, value_name = "POSES.csv", conflicts_with_all = ["duration_s", "paper_exploration"])]
    along: Option<PathBuf>,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

impl Simulate {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let layout = self
            .layout
            .as_deref()
            .map(|name| {
                SonarLayout::by_name(name).ok_or_else(|| {
                    UsageError(format!("--layout {name}: expected frontal5 or pioneer16"))
                })
            })
            .transpose()?;
        let policy = CapturePolicy {
            every: (!self.tag_pictures_only)
                .then_some(CapturePolicy::default().every)
                .flatten(),
            ..CapturePolicy::default()
        };
        simulate(
            &SimulateRequest {
                world: &self.world,
                out: &self.out,
                settings: SimSettings {
                    seed: self.seed,
                    duration_s: self.duration_s,
                    layout,
                    no_odometry_noise: self.no_odometry_noise,
                    paper_exploration: self.paper_exploration,
                },
                pictures: (!self.no_stereo).then_some(Pictures {
                    rig: &self.rig,
                    policy,
                    default_mounting: self.default_mounting,
                }),
                force: self.force,
                along: self.along.as_deref(),
            },
            &Bars::new(quiet),
        )?;
        Ok(())
    }
}
