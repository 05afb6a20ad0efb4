//! Simulate a robot exploring a world: odometry, sonar and ground truth, and the stereo pictures
//! a capture policy asks for, written as a run dataset.

use super::{relative_path, Error, Result};
use crate::camera::StereoRig;
use crate::io::{self, OutputDir};
use crate::progress::Progress;
use crate::render::{RenderConfig, Renderer};
use crate::sim::capture::{plan_captures, render_seed, CapturePolicy};
use crate::sim::{self, OdometryNoise, SimConfig, SimOutput};
use crate::sonar::SonarLayout;
use std::path::Path;

/// Changes to a world's simulation settings.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimSettings {
    /// Random seed (default: the world file's, else 1).
    pub seed: Option<u64>,
    /// Time budget, seconds (default: the world file's, else 1800).
    pub duration_s: Option<f64>,
    /// The sonar layout (default: the world file's, else the paper's five frontal sonars).
    pub layout: Option<SonarLayout>,
    /// Perfect odometry (no wheel errors).
    pub no_odometry_noise: bool,
    /// The paper's exploration only: no look-around at the start, no second drive of the first
    /// boundary loop (both added for surveys).
    pub paper_exploration: bool,
}

impl SimSettings {
    /// `config` with these changes.
    pub fn apply(&self, config: &mut SimConfig) {
        if let Some(s) = self.seed {
            config.seed = s;
        }
        if let Some(d) = self.duration_s {
            config.exploration.duration_s = d;
        }
        if let Some(layout) = &self.layout {
            config.sonar_layout = layout.clone();
        }
        if self.no_odometry_noise {
            config.odometry = OdometryNoise::none();
        }
        if self.paper_exploration {
            config.exploration.look_around_at_start = false;
            config.exploration.revisit_loop = false;
        }
    }
}

/// Stereo pictures along a simulated run.
#[derive(Debug, Clone, PartialEq)]
pub struct Pictures<'a> {
    /// The stereo rig file (the default rig is built in, when its file is not there).
    pub rig: &'a Path,
    /// When to take them.
    pub policy: CapturePolicy,
    /// Take the default mounting for a rig that does not say where it sits on the robot, rather
    /// than stop (see [`io::load_mounted_rig`]).
    pub default_mounting: bool,
}

/// What to simulate.
#[derive(Debug, Clone)]
pub struct SimulateRequest<'a> {
    /// The world file.
    pub world: &'a Path,
    /// The run directory to write.
    pub out: &'a Path,
    /// Changes to the world's simulation settings.
    pub settings: SimSettings,
    /// Stereo pictures to take, if any (none in a world without tags).
    pub pictures: Option<Pictures<'a>>,
    /// Follow this path (a pose CSV, `t_s,x_m,y_m,theta_rad`: a log's `ground_truth.csv`, a
    /// path drawn on a floor plan) instead of exploring.
    pub along: Option<&'a Path>,
    /// Replace the output directory if it exists.
    pub force: bool,
}

/// A simulated run, and the name of its world.
#[derive(Debug, Clone)]
pub struct Simulated {
    /// The simulation: the run written, the robot's own grid, why exploring ended.
    pub output: SimOutput,
    /// The world's name.
    pub world_name: String,
}

/// Simulates a world and writes the run dataset (with `stereo/` and `rig.yaml` when pictures are
/// taken) into a new directory. Progress: simulated seconds, then pictures rendered.
pub fn simulate(request: &SimulateRequest<'_>, progress: &dyn Progress) -> Result<Simulated> {
    let simulated = simulate_untold(request, progress)?;
    tell(&simulated, request.out);
    Ok(simulated)
}

/// [`simulate`] without its summary line: for a caller that writes the run inside an output
/// directory under construction, and names the run where it will be ([`tell`]).
pub(crate) fn simulate_untold(
    request: &SimulateRequest<'_>,
    progress: &dyn Progress,
) -> Result<Simulated> {
    let loaded = io::load_world(request.world)?;
    // The rig and its mounting checked before the long work, not after.
    let rig = match &request.pictures {
        Some(p) => Some(io::load_mounted_rig(p.rig, None, p.default_mounting)?),
        None => None,
    };
    let dir = OutputDir::create(request.out, request.force)?;
    let simulated = simulate_into(request, &loaded, rig.as_ref(), &dir, progress)?;
    dir.commit()?;
    Ok(simulated)
}

/// The summary line of a simulation written to `out`.
pub(crate) fn tell(simulated: &Simulated, out: &Path) {
    let run = &simulated.output.run;
    tracing::info!(
        "simulated {} for {:.0} s ({}): {} sonar readings, {} poses -> {}",
        simulated.world_name,
        run.odometry.last().map_or(0.0, |p| p.t_s),
        simulated.output.end_reason,
        run.sonar.len(),
        run.odometry.len(),
        out.display()
    );
}

/// [`simulate`] into a directory under construction (not committed here), of a loaded world.
fn simulate_into(
    request: &SimulateRequest<'_>,
    loaded: &io::LoadedWorld,
    rig: Option<&StereoRig>,
    dir: &OutputDir,
    progress: &dyn Progress,
) -> Result<Simulated> {
    let mut config = loaded.simulation.clone();
    request.settings.apply(&mut config);
    let path = request.along.map(io::read_poses).transpose()?;
    let span = match &path {
        Some(p) => p.last().map_or(0.0, |l| l.t_s) - p.first().map_or(0.0, |f| f.t_s),
        None => config.exploration.duration_s,
    };
    progress.start("simulate s", span.max(0.0).ceil() as u64);
    let simulated = match &path {
        Some(path) => sim::simulate_along(&loaded.world, &config, path, |t| progress.set(t as u64)),
        None => sim::simulate(&loaded.world, &config, |t| progress.set(t as u64)),
    };
    let mut output = simulated.map_err(|cause| Error::Sim {
        world: request.world.to_path_buf(),
        cause,
    })?;
    progress.finish();
    output.run.meta.world = Some(
        relative_path(request.world, request.out)
            .to_string_lossy()
            .into_owned(),
    );
    output.run.meta.mapping = loaded.mapping.clone();
    if let (Some(pictures), Some(rig)) = (
        request
            .pictures
            .as_ref()
            .filter(|_| !loaded.world.tags.is_empty()),
        rig,
    ) {
        take_pictures(
            &loaded.world,
            pictures,
            rig,
            dir,
            &mut output,
            config.seed,
            progress,
        )?;
    }
    io::save_run(&dir.path(""), &output.run)?;
    Ok(Simulated {
        output,
        world_name: loaded.name.clone(),
    })
}

/// Renders the stereo pairs the policy asks for along the run's true trajectory, writes them
/// under `stereo/` with the rig, and lists them in the run.
fn take_pictures(
    world: &crate::world::World,
    pictures: &Pictures<'_>,
    rig: &StereoRig,
    dir: &OutputDir,
    output: &mut SimOutput,
    seed: u64,
    progress: &dyn Progress,
) -> Result<()> {
    let truth = output.run.ground_truth.clone().unwrap_or_default();
    let config = RenderConfig::default();
    let plan = plan_captures(world, rig, &truth, &pictures.policy, &config)?;
    for sub in ["stereo/left", "stereo/right"] {
        io::create_dir(&dir.path(sub))?;
    }
    progress.start("render", plan.len() as u64);
    let renderer = Renderer::new(rig);
    for (k, p) in plan.iter().enumerate() {
        let pair = renderer.render(
            world,
            p.pose,
            &RenderConfig {
                seed: render_seed(seed, k),
                ..config.clone()
            },
        )?;
        let (left, right) = (
            format!("stereo/left/{k:06}.png"),
            format!("stereo/right/{k:06}.png"),
        );
        io::save_camera_png(&dir.path(&left), &pair.left)?;
        io::save_camera_png(&dir.path(&right), &pair.right)?;
        output.run.stereo.push(crate::dataset::StereoEntry {
            t_s: p.t_s,
            left,
            right,
        });
        progress.advance(1);
    }
    progress.finish();
    io::save_rig(&dir.path("rig.yaml"), rig)?;
    output.run.meta.robot.rig = Some("rig.yaml".into());
    Ok(())
}
