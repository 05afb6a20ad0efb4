//! Command-line interface: argument parsing, error reporting, progress. The only module that uses
//! clap, anyhow and indicatif.

mod config;
mod demo;
mod detect;
mod map;
mod render;
mod rig;
mod simulate;

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
    /// Render the stereo pair a robot sees at a pose, with ground truth of every tag in view.
    ///
    /// Example: stereotag render --world samples/office/world.yaml --pose 1.2,5.8,2.3 --out pair
    Render(render::Render),
    /// Check a stereo rig file and export it for OpenCV and ROS (with its Bouguet rectification).
    ///
    /// Example: stereotag rig calibration/rigs/default.yaml --out rig_export
    Rig(rig::Rig),
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
            || e.is::<stereotag::grid::GridError>()
            || e.is::<stereotag::pipeline::PipelineError>()
            || e.is::<stereotag::sim::SimError>()
            || e.is::<UsageError>()
            || e.is::<stereotag::tags::TagError>()
            || e.is::<stereotag::render::RenderError>()
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
        Command::Detect(c) => c.run(),
        Command::Rig(c) => c.run(),
        Command::Render(c) => c.run(),
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
    let style = indicatif::ProgressStyle::with_template(
        "{msg:>10} [{bar:40}] {pos}/{len} s simulated ({eta} left)",
    )
    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
    .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
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
