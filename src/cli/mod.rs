//! Command-line interface: argument parsing, error reporting, progress. The only module that uses
//! clap, anyhow and indicatif.

mod calibrate;
mod config;
mod demo;
mod detect;
mod localize;
mod map;
mod plan;
mod render;
mod rig;
mod simulate;
mod survey;

use clap::{CommandFactory, Parser, Subcommand};
use std::path::{Path, PathBuf};

/// Map a home with sonar and keep the robot's pose honest with stereo AprilTag landmarks.
#[derive(Debug, Parser)]
#[command(name = "stereotag", version, about, long_about = None)]
#[command(
    after_help = "Example:\n  stereotag demo\n  stereotag simulate --world samples/office/world.yaml --out runs/office\n  stereotag map --run runs/office --out maps/office"
)]
pub struct Cli {
    /// Only print errors.
    #[arg(short, long, global = true)]
    quiet: bool,
    /// Print more (repeat for debug output).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Simulate the office sample and map it: writes out/run and out/map.
    ///
    /// Example: stereotag demo --out out
    Demo(demo::Demo),
    /// Simulate a robot exploring a world; writes a run dataset.
    ///
    /// Example: stereotag simulate --world samples/office/world.yaml --out runs/office
    Simulate(simulate::Simulate),
    /// Build the occupancy grid and Hough corner features of a run; scores them if the world is known.
    ///
    /// Example: stereotag map --run runs/office --out maps/office --poses ground-truth
    Map(map::Map),
    /// Detect AprilTags in images; prints JSON (corners in the AprilTag C library's order).
    ///
    /// Example: stereotag detect --backend kornia --decimate 1 photo.jpg
    Detect(detect::Detect),
    /// Render the stereo pair a robot sees at a pose, with ground truth of every tag in view; or
    /// a sequence along poses; or a calibration sequence of a target.
    ///
    /// Example: stereotag render --world samples/office/world.yaml --pose 1.2,5.8,2.3 --out pair
    ///
    /// Example: stereotag render --calibration-sequence 30 --target calibration/targets/aprilgrid_6x6.yaml --out calseq
    Render(render::Render),
    /// Check a stereo rig file and export it for OpenCV and ROS (with its Bouguet rectification).
    ///
    /// Example: stereotag rig calibration/rigs/default.yaml --out rig_export
    Rig(rig::Rig),
    /// Survey a run: detect and triangulate the tags, fuse them with odometry and the sonar
    /// corners online and offline, rebuild the map; writes landmarks, maps, trajectories, report
    /// and a Rerun recording.
    ///
    /// Example: stereotag survey --run runs/office --out surveys/office
    Survey(survey::SurveyArgs),
    /// Track a new run against a saved survey's landmarks and report how the error grows
    /// between sightings.
    ///
    /// Example: stereotag localize --survey out --run runs/office2 --out loc
    Localize(localize::Localize),
    /// Propose where tags should go from a sonar-only map's corners, with the predicted error.
    ///
    /// Example: stereotag plan --map maps/museum --out plan
    Plan(plan::PlanArgs),
    /// Calibrate a stereo rig from chessboard or AprilGrid images (or corners already detected):
    /// Zhang initialisation, bundle adjustment of both cameras and right_from_left with outliers
    /// listed; writes Kalibr, OpenCV and ROS files, a report and a Rerun recording.
    ///
    /// Example: stereotag calibrate --target calibration/targets/checkerboard_9x6.yaml --left 'cam0/*.png' --right 'cam1/*.png' --out calib
    ///
    /// Example: stereotag calibrate --target calibration/targets/aprilgrid_6x6.yaml --corners-left cam0 --corners-right cam1 --resolution 752x480 --out calib
    Calibrate(calibrate::Calibrate),
    /// Print a settings file with its defaults.
    ///
    /// Example: stereotag config --default mapping > mapping.yaml
    Config(config::Config),
    /// Print shell completions.
    ///
    /// Example: stereotag completions bash > /etc/bash_completion.d/stereotag
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
}

/// Errors caused by the user's input: exit status 2.
fn is_input_error(err: &anyhow::Error) -> bool {
    err.chain().any(|e| {
        e.is::<stereotag::io::IoError>()
            || e.is::<stereotag::sonar::grid::GridError>()
            || e.is::<stereotag::sonar::map::MapError>()
            || e.is::<stereotag::sim::SimError>()
            || e.is::<UsageError>()
            || e.is::<stereotag::visual::tags::TagError>()
            || e.is::<stereotag::render::RenderError>()
            || e.is::<stereotag::calib::CalibError>()
            || is_viz_input_error(e)
    })
}

/// A mistake in how the command was called.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// Runs the command line; returns the exit status.
pub fn main() -> i32 {
    let cli = Cli::parse();
    let level = match (cli.quiet, cli.verbose) {
        (true, _) => "error",
        (false, 0) => "info",
        (false, 1) => "debug",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_target(false)
        .without_time()
        .with_writer(std::io::stderr)
        .init();
    let result = match &cli.command {
        Command::Demo(c) => c.run(cli.quiet),
        Command::Simulate(c) => c.run(cli.quiet),
        Command::Map(c) => c.run(),
        Command::Survey(c) => c.run(cli.quiet),
        Command::Localize(c) => c.run(cli.quiet),
        Command::Calibrate(c) => c.run(cli.quiet),
        Command::Plan(c) => c.run(),
        Command::Detect(c) => c.run(),
        Command::Rig(c) => c.run(),
        Command::Render(c) => c.run(cli.quiet),
        Command::Config(c) => c.run(),
        Command::Completions { shell } => {
            clap_complete::generate(
                *shell,
                &mut Cli::command(),
                "stereotag",
                &mut std::io::stdout(),
            );
            Ok(())
        }
    };
    match result {
        Ok(()) => 0,
        Err(err) => {
            eprintln!("error: {err:#}");
            if is_input_error(&err) {
                2
            } else {
                1
            }
        }
    }
}

/// A progress bar on stderr (hidden with `--quiet`).
pub(crate) fn progress(len: u64, what: &str, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    let style =
        indicatif::ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} ({eta} left)")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

/// A `--decimate` the detectors take (finite, at least 1), or the usage error naming it.
pub(crate) fn check_decimate(decimate: f32) -> Result<(), UsageError> {
    if stereotag::visual::tags::valid_decimation(decimate) {
        Ok(())
    } else {
        Err(UsageError(format!(
            "--decimate {decimate}: must be at least 1"
        )))
    }
}

/// The stereo rig `simulate`, `render` and `demo` use unless told otherwise (repo-relative).
pub(crate) const DEFAULT_RIG: &str = "calibration/rigs/default.yaml";

/// Loads a `--rig` file; the default one, when it is not there (stereotag run outside its
/// repository, or installed), from the copy built into the binary, and says so.
pub(crate) fn load_rig_arg(path: &Path) -> anyhow::Result<stereotag::camera::StereoRig> {
    if path == Path::new(DEFAULT_RIG) && !path.exists() {
        tracing::info!("{DEFAULT_RIG} is not here: using the copy built into stereotag");
        let text = include_str!("../../calibration/rigs/default.yaml");
        return Ok(stereotag::io::parse_rig(path, text)?);
    }
    Ok(stereotag::io::load_rig(path)?)
}

/// Loads a run directory and warns about each odometry jump in it (a reset or glitch in a log:
/// everything after it is placed with it).
pub(crate) fn load_run(run_dir: &Path) -> anyhow::Result<stereotag::dataset::RunDataset> {
    let run = stereotag::io::load_run(run_dir)?;
    let jumps = stereotag::geometry::odometry_jumps(&run.odometry);
    if jumps.is_empty() {
        return Ok(run);
    }
    let file = run_dir.join("odometry.csv");
    // The file's line of each pose (the reader skips the header and blank lines), read again
    // only when there is a jump to name.
    let lines: Vec<usize> = std::fs::read_to_string(&file)
        .unwrap_or_default()
        .lines()
        .enumerate()
        .skip(1)
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, _)| i + 1)
        .collect();
    for j in jumps.iter().take(3) {
        tracing::warn!(
            "{}:{}: the odometry jumps {:.2} m at t = {:.2} s (faster than {} m/s): a reset or a glitch? Everything after it is placed with it",
            file.display(),
            lines.get(j.index).copied().unwrap_or(j.index + 2),
            j.distance_m,
            j.t_s,
            stereotag::geometry::JUMP_SPEED_MPS
        );
    }
    if jumps.len() > 3 {
        tracing::warn!(
            "{}: {} more odometry jumps",
            file.display(),
            jumps.len() - 3
        );
    }
    Ok(run)
}

/// The world file to score a run against: the one given, else the one run.yaml names if it exists.
pub(crate) fn world_of_run(
    given: Option<&Path>,
    run_dir: &Path,
    run: &stereotag::dataset::RunDataset,
) -> Option<PathBuf> {
    given.map(Path::to_path_buf).or_else(|| {
        run.meta
            .world
            .as_ref()
            .map(|w| run_dir.join(w))
            .filter(|p| p.exists())
    })
}

/// `to` relative to the directory `from` (both as given, made absolute first).
pub(crate) fn relative_path(to: &Path, from_dir: &Path) -> PathBuf {
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let (to, from) = (abs(to), abs(from_dir));
    let tc: Vec<_> = to.components().collect();
    let fc: Vec<_> = from.components().collect();
    let common = tc.iter().zip(&fc).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..fc.len() {
        out.push("..");
    }
    for c in &tc[common..] {
        out.push(c);
    }
    out
}

/// Where a command's Rerun recording goes.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RerunArgs {
    /// Write the recording to this .rrd file (default: the output directory's survey.rrd, or
    /// localize.rrd for `localize`).
    #[arg(long, value_name = "FILE.rrd")]
    save: Option<PathBuf>,
    /// Stream the recording to a new Rerun viewer (the `rerun` executable on PATH).
    #[arg(long)]
    spawn: bool,
    /// Stream the recording to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy.
    #[arg(long, value_name = "URL")]
    connect: Option<String>,
    /// Record nothing.
    #[arg(long, conflicts_with_all = ["save", "spawn", "connect"])]
    pub(crate) no_rerun: bool,
}

#[cfg(feature = "rerun")]
fn is_viz_input_error(e: &(dyn std::error::Error + 'static)) -> bool {
    matches!(
        e.downcast_ref::<stereotag::viz::VizError>(),
        Some(stereotag::viz::VizError::Url { .. })
    )
}

#[cfg(not(feature = "rerun"))]
fn is_viz_input_error(_: &(dyn std::error::Error + 'static)) -> bool {
    false
}

/// The open recording of a command (nothing when built without the `rerun` feature).
#[cfg(feature = "rerun")]
pub(crate) type Recorder = stereotag::viz::Recorder;
#[cfg(not(feature = "rerun"))]
pub(crate) type Recorder = ();

/// What a recording holds, which picks its application name and default layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Recording {
    /// A survey (also the demo's).
    Survey,
    /// A stereo calibration.
    Calibration,
    /// A later run localised against a survey.
    Localization,
}

/// Opens the recording the flags ask for; `default_file` is used unless `--save`, `--spawn` or
/// `--connect` say otherwise. The file is written into the staging directory with the other
/// outputs.
#[cfg(feature = "rerun")]
pub(crate) fn recorder(
    args: &RerunArgs,
    kind: Recording,
    default_file: &Path,
) -> anyhow::Result<Option<Recorder>> {
    use stereotag::viz::Sink;
    if args.no_rerun {
        return Ok(None);
    }
    let mut sinks = Vec::new();
    match &args.save {
        Some(p) if !stereotag::viz::is_rrd(p) => {
            return Err(
                UsageError(format!("--save {}: expected a .rrd file name", p.display())).into(),
            )
        }
        Some(p) => sinks.push(Sink::Save(p.clone())),
        None if !args.spawn && args.connect.is_none() => {
            sinks.push(Sink::Save(default_file.to_path_buf()))
        }
        None => {}
    }
    if args.spawn {
        sinks.push(Sink::Spawn);
    }
    if let Some(url) = &args.connect {
        sinks.push(Sink::Connect(url.clone()));
    }
    let (application, blueprint) = match kind {
        Recording::Survey => ("stereotag survey", stereotag::viz::survey_blueprint()),
        Recording::Calibration => (
            "stereotag calibration",
            stereotag::viz::calibration_blueprint(),
        ),
        Recording::Localization => (
            "stereotag localize",
            stereotag::viz::localization_blueprint(),
        ),
    };
    Ok(Some(stereotag::viz::Recorder::new(
        application,
        &sinks,
        blueprint,
    )?))
}

#[cfg(not(feature = "rerun"))]
pub(crate) fn recorder(
    args: &RerunArgs,
    _kind: Recording,
    _default_file: &Path,
) -> anyhow::Result<Option<Recorder>> {
    if args.save.is_some() || args.spawn || args.connect.is_some() {
        return Err(UsageError(
            "this stereotag was built without the `rerun` feature; rebuild with default features to record".into(),
        )
        .into());
    }
    Ok(None)
}

/// Values lent to parallel jobs and given back when a job ends, so that each is built about once
/// per thread: rayon's `map_init` calls its init for every split of the work, and a tag detector
/// builds its families' decoding tables when it is made.
pub(crate) struct Pool<T> {
    free: std::sync::Mutex<Vec<T>>,
}

impl<T> Pool<T> {
    /// A pool holding `first`.
    pub(crate) fn new(first: T) -> Self {
        Self {
            free: std::sync::Mutex::new(vec![first]),
        }
    }

    /// A value from the pool, or a new one from `make` when every value is lent.
    pub(crate) fn take<E>(&self, make: impl FnOnce() -> Result<T, E>) -> Result<Pooled<'_, T>, E> {
        let free = self.free.lock().unwrap_or_else(|e| e.into_inner()).pop();
        let item = match free {
            Some(item) => item,
            None => make()?,
        };
        Ok(Pooled {
            item: Some(item),
            pool: self,
        })
    }
}

/// A value lent by a [`Pool`]; it goes back when dropped.
pub(crate) struct Pooled<'p, T> {
    item: Option<T>,
    pool: &'p Pool<T>,
}

impl<T> std::ops::Deref for Pooled<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.item.as_ref().expect("lent until dropped")
    }
}

impl<T> std::ops::DerefMut for Pooled<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        self.item.as_mut().expect("lent until dropped")
    }
}

impl<T> Drop for Pooled<'_, T> {
    fn drop(&mut self) {
        if let Some(item) = self.item.take() {
            self.pool
                .free
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(item);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Pool;
    use std::cell::Cell;

    #[test]
    fn a_pool_makes_a_value_only_when_every_value_is_lent() {
        let made = Cell::new(0);
        let make = || -> Result<u32, ()> {
            made.set(made.get() + 1);
            Ok(made.get())
        };
        let pool = Pool::new(0);
        {
            let a = pool.take(make).unwrap();
            let b = pool.take(make).unwrap();
            assert_eq!((*a, *b, made.get()), (0, 1, 1));
        }
        // Both went back: two more takes make nothing new.
        let c = pool.take(make).unwrap();
        let d = pool.take(make).unwrap();
        assert_eq!(made.get(), 1);
        assert_ne!(*c, *d);
        drop((c, d));
        assert!(pool.take(|| Err::<u32, &str>("unused")).is_ok());
    }
}
