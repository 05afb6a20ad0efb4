use super::{progress, relative_path, UsageError};
use anyhow::Context;
use std::path::{Path, PathBuf};
use stereotag::io::{self, OutputDir};
use stereotag::render::CapturePolicy;
use stereotag::sim::{self, OdometryNoise, SimOutput};
use stereotag::sonar::SonarLayout;

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
    #[arg(long, default_value = super::DEFAULT_RIG)]
    rig: PathBuf,
    /// Take no stereo pictures (sonar and odometry only).
    #[arg(long)]
    no_stereo: bool,
    /// Take pictures only when a tag is in view (none in between for the visual odometry).
    #[arg(long, conflicts_with = "no_stereo")]
    tag_pictures_only: bool,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

impl Simulate {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let policy = CapturePolicy {
            every: (!self.tag_pictures_only)
                .then_some(CapturePolicy::default().every)
                .flatten(),
            ..CapturePolicy::default()
        };
        let pictures = (!self.no_stereo).then_some((self.rig.as_path(), &policy));
        simulate_world(&self.world, &self.out, pictures, self.force, quiet, |c| {
            if let Some(s) = self.seed {
                c.seed = s;
            }
            if let Some(d) = self.duration_s {
                c.exploration.duration_s = d;
            }
            if let Some(name) = &self.layout {
                c.sonar_layout = SonarLayout::by_name(name).ok_or_else(|| {
                    UsageError(format!("--layout {name}: expected frontal5 or pioneer16"))
                })?;
            }
            if self.no_odometry_noise {
                c.odometry = OdometryNoise::none();
            }
            if self.paper_exploration {
                c.exploration.look_around_at_start = false;
                c.exploration.revisit_loop = false;
            }
            Ok(())
        })
        .map(|_| ())
    }
}

/// Loads a world, simulates it and writes the run to `out`.
pub(crate) fn simulate_world(
    world_path: &Path,
    out: &Path,
    pictures: Option<(&Path, &CapturePolicy)>,
    force: bool,
    quiet: bool,
    adjust: impl FnOnce(&mut sim::SimConfig) -> anyhow::Result<()>,
) -> anyhow::Result<SimOutput> {
    let loaded = io::load_world(world_path)?;
    let mut config = loaded.simulation.clone();
    adjust(&mut config)?;
    let dir = OutputDir::create(out, force)?;
    let bar = progress(
        config.exploration.duration_s.ceil() as u64,
        "simulate s",
        quiet,
    );
    let mut output = sim::simulate(&loaded.world, &config, |t| bar.set_position(t as u64))
        .with_context(|| format!("simulating {}", world_path.display()))?;
    bar.finish_and_clear();
    output.run.meta.world = Some(
        relative_path(world_path, out)
            .to_string_lossy()
            .into_owned(),
    );
    output.run.meta.mapping = Some(loaded.mapping.clone());
    if let Some((rig_path, policy)) = pictures.filter(|_| !loaded.world.tags.is_empty()) {
        take_pictures(
            &loaded.world,
            rig_path,
            policy,
            &dir,
            &mut output,
            config.seed,
            quiet,
        )?;
    }
    io::save_run(&dir.path(""), &output.run)?;
    dir.commit()?;
    let last = output.run.odometry.last().map_or(0.0, |p| p.t_s);
    tracing::info!(
        "simulated {} for {:.0} s ({}): {} sonar readings, {} poses -> {}",
        loaded.name,
        last,
        output.end_reason,
        output.run.sonar.len(),
        output.run.odometry.len(),
        out.display()
    );
    Ok(output)
}

/// The sensor-noise seed of picture `k` of a run simulated with `seed`: `(seed - 1) x 10^6 + k + 1`,
/// so that runs of different seeds get independent noise even where their poses agree (a run with
/// perfect odometry), and seed 1 keeps the images it always had.
fn render_seed(seed: u64, k: usize) -> u64 {
    seed.wrapping_sub(1)
        .wrapping_mul(1_000_000)
        .wrapping_add(k as u64 + 1)
}

/// Renders the stereo pairs `policy` asks for and lists them in `stereo.csv`.
fn take_pictures(
    world: &stereotag::world::World,
    rig_path: &Path,
    policy: &CapturePolicy,
    dir: &OutputDir,
    output: &mut SimOutput,
    seed: u64,
    quiet: bool,
) -> anyhow::Result<()> {
    use stereotag::render::{plan_captures, RenderConfig, Renderer};
    let rig = super::load_rig_arg(rig_path)?;
    let truth = output.run.ground_truth.clone().unwrap_or_default();
    let config = RenderConfig::default();
    let plan = plan_captures(world, &rig, &truth, policy, &config)?;
    std::fs::create_dir_all(dir.path("stereo/left"))?;
    std::fs::create_dir_all(dir.path("stereo/right"))?;
    let bar = progress(plan.len() as u64, "render", quiet);
    let renderer = Renderer::new(&rig);
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
        output.run.stereo.push(stereotag::dataset::StereoEntry {
            t_s: p.t_s,
            left,
            right,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    io::save_rig(&dir.path("rig.yaml"), &rig)?;
    output.run.meta.robot.rig = Some("rig.yaml".into());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::render_seed;

    #[test]
    fn each_run_seed_gets_its_own_picture_noise() {
        assert_eq!(render_seed(1, 0), 1);
        assert_eq!(render_seed(1, 41), 42);
        let mut seeds: Vec<u64> = (1..=5)
            .flat_map(|s| (0..1000).map(move |k| render_seed(s, k)))
            .collect();
        seeds.sort_unstable();
        seeds.dedup();
        assert_eq!(seeds.len(), 5000);
    }
}
