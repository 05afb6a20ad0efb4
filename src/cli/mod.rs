//! Command-line interface: argument parsing, error reporting, progress. The only module that uses
//! clap, anyhow and indicatif.

mod calibrate;
mod config;
mod demo;
mod detect;
mod import;
mod localize;
mod map;
mod plan;
mod render;
mod rig;
mod samples;
mod simulate;
mod survey;

use clap::{CommandFactory, Parser, Subcommand};
use std::path::PathBuf;
use stereotag::visual::tags::TagFamily;

/// Map a home with sonar and keep the robot's pose honest with stereo AprilTag landmarks.
#[derive(Debug, Parser)]
#[command(name = "stereotag", version, about, long_about = None)]
#[command(
    after_help = "Example:\n  stereotag demo\n  stereotag simulate --world samples/office/world.yaml --out runs/office\n  stereotag map --run runs/office --out maps/office"
)]
pub struct Cli {
    /// Print errors only: no progress bars, warnings or summaries (data asked for on standard
    /// output, such as `detect`'s JSON, is still printed).
    #[arg(
        short,
        long,
        global = true,
        display_order = 1000,
        conflicts_with = "verbose"
    )]
    quiet: bool,
    /// Print more: -v adds each stage's details (tags rejected and why, failed visual turns,
    /// solver steps); -vv adds every picture's detections. RUST_LOG overrides both.
    #[arg(short, long, global = true, display_order = 1001, action = clap::ArgAction::Count)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Simulate a robot exploring the office sample with its stereo camera, then survey the run:
    /// writes the run to out/run and the survey (landmarks, maps, trajectories, report,
    /// survey.rrd) to out.
    ///
    /// Example: stereotag demo --out out
    Demo(demo::Demo),
    /// Write the samples, calibration targets and rigs built into stereotag to a directory, to
    /// edit them (commands read the built-in copies of `samples/...` and `calibration/...` when
    /// the files are not there).
    ///
    /// Example: stereotag samples --out .
    Samples(samples::Samples),
    /// Simulate a robot exploring a world; writes a run dataset.
    ///
    /// Example: stereotag simulate --world samples/office/world.yaml --out runs/office
    Simulate(simulate::Simulate),
    /// Bring a robot's log in as a run dataset: a ROS 2 bag (stereo images, odometry, sonar or
    /// laser, tf), an ASL/EuRoC folder or a CARMEN log (Radish), a laser optionally turned into
    /// sonar-like readings.
    ///
    /// Example: stereotag import --bag robot_run/ --out runs/robot
    ///
    /// Example: stereotag import --asl MH_01/ --odometry MH_01.tum --out runs/mh01
    ///
    /// Example: stereotag import --carmen ../shared/data/radish/aces-corrected.log.gz --as-sonar frontal5 --out runs/aces
    Import(import::Import),
    /// Build the occupancy grids, Hough corner features and walls of a run, scored if the world is known, with a recording (map.rrd).
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
    /// Calibrate a stereo rig, or one camera (--images), from chessboard or AprilGrid images (or
    /// corners already detected): Zhang initialisation, bundle adjustment of the cameras and
    /// right_from_left with outliers listed; writes Kalibr, OpenCV and ROS files, a report and a
    /// Rerun recording.
    ///
    /// Example: stereotag calibrate --target calibration/targets/checkerboard_9x6.yaml --images 'cam0/*.png' --out calib-cam0
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

/// Whether log lines may be coloured: standard error is a terminal and `NO_COLOR` is not set
/// (<https://no-color.org>).
fn colour_on_stderr() -> bool {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
}

/// Set by Ctrl-C or SIGTERM: from then on the handler ends the process.
static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Ctrl-C or SIGTERM: removes the outputs under construction and exits with 130, as a shell
/// does for a command stopped by SIGINT.
fn interrupted() {
    INTERRUPTED.store(true, std::sync::atomic::Ordering::SeqCst);
    let removed = stereotag::io::remove_partial_outputs();
    if removed > 0 {
        eprintln!("interrupted: the unfinished output was removed");
    } else {
        eprintln!("interrupted");
    }
    std::process::exit(130);
}

/// Prints `text` to standard output. A reader that went away (`stereotag detect .. | head`) is
/// not an error: the rest is not wanted.
pub(crate) fn print_out(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Errors caused by the user's input: exit status 2.
fn is_input_error(err: &anyhow::Error) -> bool {
    err.chain().any(|e| {
        e.downcast_ref::<stereotag::workflow::Error>()
            .is_some_and(stereotag::workflow::Error::is_bad_input)
            || e.is::<stereotag::io::IoError>()
            || e.is::<UsageError>()
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
        .with_ansi(colour_on_stderr())
        .with_writer(std::io::stderr)
        .init();
    if let Err(e) = ctrlc::set_handler(interrupted) {
        tracing::debug!("no Ctrl-C handler: {e}");
    }
    let result = match &cli.command {
        Command::Demo(c) => c.run(cli.quiet),
        Command::Samples(c) => c.run(cli.quiet),
        Command::Simulate(c) => c.run(cli.quiet),
        Command::Import(c) => c.run(cli.quiet),
        Command::Map(c) => c.run(cli.quiet),
        Command::Survey(c) => c.run(cli.quiet),
        Command::Localize(c) => c.run(cli.quiet),
        Command::Calibrate(c) => c.run(cli.quiet),
        Command::Plan(c) => c.run(),
        Command::Detect(c) => c.run(),
        Command::Rig(c) => c.run(),
        Command::Render(c) => c.run(cli.quiet),
        Command::Config(c) => c.run(),
        Command::Completions { shell } => {
            let mut script = Vec::new();
            clap_complete::generate(*shell, &mut Cli::command(), "stereotag", &mut script);
            print_out(&String::from_utf8_lossy(&script))
        }
    };
    if INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst) {
        // The work failed because its output was being removed under it, or ended while it was:
        // the handler says so and exits 130; nothing else is to be said.
        loop {
            std::thread::park();
        }
    }
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

/// Progress bars on stderr, one per stage of a workflow (none with `--quiet`).
pub(crate) struct Bars {
    quiet: bool,
    bar: std::sync::Mutex<Option<indicatif::ProgressBar>>,
}

impl Bars {
    /// Bars, or none at all when `quiet`.
    pub(crate) fn new(quiet: bool) -> Self {
        Self {
            quiet,
            bar: std::sync::Mutex::new(None),
        }
    }

    fn with(&self, f: impl FnOnce(&indicatif::ProgressBar)) {
        if let Some(bar) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            f(bar);
        }
    }
}

impl stereotag::progress::Progress for Bars {
    fn start(&self, stage: &str, total: u64) {
        if self.quiet {
            return;
        }
        let bar = indicatif::ProgressBar::new(total);
        // A stage whose steps are not counted shows that it runs and for how long.
        let template = match total {
            0 => "{msg:>10} {spinner} {elapsed}",
            _ => "{msg:>10} [{bar:40}] {pos}/{len} ({eta} left)",
        };
        let style = indicatif::ProgressStyle::with_template(template)
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> ");
        bar.set_style(style);
        if total == 0 {
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
        }
        bar.set_message(stage.to_string());
        if let Some(old) = self
            .bar
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .replace(bar)
        {
            old.finish_and_clear();
        }
    }

    fn advance(&self, steps: u64) {
        self.with(|b| b.inc(steps));
    }

    fn set(&self, done: u64) {
        self.with(|b| b.set_position(done));
    }

    fn finish(&self) {
        if let Some(bar) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
            bar.finish_and_clear();
        }
    }
}

/// Where a command's Rerun recording goes.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RerunArgs {
    /// Write the recording to this .rrd file instead of the output directory's (named in
    /// --out's help).
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

impl RerunArgs {
    /// The recording these flags ask for.
    pub(crate) fn request(&self) -> Result<stereotag::viz::RecordingRequest, UsageError> {
        if let Some(p) = self.save.as_ref().filter(|p| !stereotag::viz::is_rrd(p)) {
            return Err(UsageError(format!(
                "--save {}: expected a .rrd file name",
                p.display()
            )));
        }
        if self.spawn && !stereotag::viz::viewer_on_path() {
            return Err(UsageError(format!(
                "--spawn: no Rerun viewer (`rerun`) on PATH; install it with `pip install rerun-sdk=={}`, or write the recording with --save FILE.rrd and open it later",
                stereotag::viz::VIEWER_VERSION
            )));
        }
        Ok(stereotag::viz::RecordingRequest {
            off: self.no_rerun,
            save: self.save.clone(),
            spawn: self.spawn,
            connect: self.connect.clone(),
        })
    }
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

/// The families named by `--family` flags.
pub(crate) fn families(names: &[String]) -> Result<Vec<TagFamily>, UsageError> {
    names
        .iter()
        .map(|f| {
            TagFamily::from_name(f)
                .ok_or_else(|| UsageError(format!("--family {f}: expected {}", TagFamily::NAMES)))
        })
        .collect()
}
