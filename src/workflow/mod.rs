//! The jobs users run, end to end: each loads its inputs through [`crate::io`], runs the stages,
//! writes its outputs into a directory that appears whole or not at all, and returns what a caller
//! prints. The `stereotag` command line is one thin caller of these functions; a program can be
//! another.
//!
//! | job | function |
//! |---|---|
//! | simulate a robot in a world, pictures included | [`simulate::simulate`] |
//! | bring a ROS 2 bag or a CARMEN log in as a run | [`import::import_bag`], [`import::import_carmen`] |
//! | the sonar map of a run | [`map::map`] |
//! | survey a run: landmarks, corrected trajectory and map | [`survey::survey`] |
//! | track a later run against a survey | [`localize::localize`] |
//! | propose tag places from a sonar map | [`plan::plan`] |
//! | calibrate a stereo rig from images or corners | [`calibrate::calibrate`] |
//! | detect tags in images, triangulate a pair | [`detect::detect`] |
//! | render pairs, sequences, calibration views | [`render`] |
//! | check and export a rig | [`rig::export_rig`] |
//! | the demo: simulate the office and survey it | [`demo::demo`] |
//!
//! A stage never reads a file itself: workflows are where files and stages meet.

pub mod calibrate;
pub mod demo;
pub mod detect;
pub mod import;
pub mod localize;
pub mod map;
pub mod plan;
pub mod render;
pub mod rig;
pub mod sightings;
pub mod simulate;
pub mod survey;

use crate::dataset::RunDataset;
use crate::geometry::{odometry_jumps, JUMP_SPEED_MPS};
use crate::io::IoError;
use std::path::{Path, PathBuf};

/// What can go wrong in a workflow. [`Error::is_bad_input`] tells the caller's mistakes (a bad
/// file, a bad setting, an output that exists) from failures of the tool itself.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written, or holds something wrong.
    #[error(transparent)]
    Io(#[from] IoError),
    /// Bad grid settings.
    #[error(transparent)]
    Grid(#[from] crate::sonar::grid::GridError),
    /// The simulation refused its world or settings.
    #[error("simulating {}: {cause}", world.display())]
    Sim {
        /// The world file.
        world: PathBuf,
        /// Why.
        cause: crate::sim::SimError,
    },
    /// A tag detector refused its settings.
    #[error(transparent)]
    Tag(#[from] crate::visual::tags::TagError),
    /// A world could not be rendered.
    #[error(transparent)]
    Render(#[from] crate::render::RenderError),
    /// The calibration failed.
    #[error(transparent)]
    Calib(#[from] crate::calib::CalibError),
    /// The recording could not be opened or written.
    #[error(transparent)]
    Record(#[from] crate::viz::VizError),
    /// The request cannot be done as asked (the message says what to change).
    #[error("{0}")]
    Request(String),
    /// A failure while doing `what`.
    #[error("{what}: {cause}")]
    During {
        /// What was being done, e.g. "recording the survey".
        what: &'static str,
        /// What went wrong.
        cause: Box<Error>,
    },
}

impl Error {
    /// Whether the error is the caller's to fix (bad input: exit status 2 on the command line)
    /// rather than a failure of the tool (1).
    pub fn is_bad_input(&self) -> bool {
        match self {
            Error::Io(_)
            | Error::Grid(_)
            | Error::Sim { .. }
            | Error::Tag(_)
            | Error::Render(_)
            | Error::Calib(_)
            | Error::Request(_) => true,
            Error::Record(e) => e.is_bad_input(),
            Error::During { .. } => false,
        }
    }

    /// `self` as a failure while doing `what`.
    pub(crate) fn during(self, what: &'static str) -> Self {
        Error::During {
            what,
            cause: Box::new(self),
        }
    }
}

/// The result of a workflow.
pub type Result<T> = std::result::Result<T, Error>;

/// Loads a run directory and warns about each odometry jump in it (a reset or glitch in a log:
/// everything after it is placed with it), naming the line of `odometry.csv`. A run whose range
/// sensor is its lidar ([`RunDataset::ranging`]) comes with the laser's beams in place of the
/// sonar ([`RunDataset::with_lidar_as_ranges`]), saying so.
pub fn load_run(run_dir: &Path) -> Result<RunDataset> {
    let run = crate::io::load_run(run_dir)?;
    let sonar_unused = !run.sonar.is_empty() && run.meta.robot.ranging.is_none();
    let (run, beyond) = run.with_lidar_as_ranges();
    if let (Some(lidar), crate::dataset::RangeSensor::Lidar) =
        (&run.meta.robot.lidar, run.ranging())
    {
        let returns = run.sonar.iter().filter(|r| r.range_m.is_some()).count() + beyond;
        tracing::info!(
            "ranges from the lidar: {} scans of {} beams{}",
            run.lidar.len(),
            lidar.beams,
            if sonar_unused {
                " (the run's sonar is not used: set robot.ranging: sonar in run.yaml to map with it)"
            } else {
                ""
            }
        );
        if beyond > 0 {
            tracing::warn!(
                "{beyond} of {returns} lidar returns ({:.0}%) lie beyond mapped_range_m ({} m) and are not used (robot.lidar.mapped_range_m in run.yaml)",
                100.0 * beyond as f64 / returns.max(1) as f64,
                lidar.mapped_range_m
            );
        }
    }
    let jumps = odometry_jumps(&run.odometry);
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
            JUMP_SPEED_MPS
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

/// The mapping settings of a run: `given` (a `--config` file), else run.yaml's, else the paper's
/// on a grid of 20 cm cells fitted to the run's odometry and the sonars' reach (said once; the
/// paper's own 16 m grid when the run spans over 1 km). Either way the Hough accumulator reaches
/// the grid's farthest corner, so no echo on the grid is left out of it.
pub fn mapping_of_run(
    run: &RunDataset,
    given: Option<crate::sonar::map::MappingConfig>,
) -> crate::sonar::map::MappingConfig {
    let mut config = given.or_else(|| run.meta.mapping.clone()).unwrap_or_else(|| {
        let mut config = crate::sonar::map::MappingConfig::default();
        match crate::sonar::grid::GridConfig::fitted(&run.odometry, &run.meta.robot.sonar) {
            Some(grid) => {
                tracing::info!(
                    "run.yaml sets no grid: {} x {} cells of {} m from ({:.1}, {:.1}) m, fitted to the odometry and the sonars' reach",
                    grid.width_cells,
                    grid.height_cells,
                    grid.resolution_m,
                    grid.origin_m[0],
                    grid.origin_m[1]
                );
                config.grid = grid;
            }
            None => tracing::warn!(
                "run.yaml sets no grid and the odometry spans over 1 km (a reset or a glitch?): the paper's grid is used; set mapping.grid"
            ),
        }
        config
    });
    let g = &config.grid;
    let far = [0.0, g.width_cells as f64 * g.resolution_m]
        .iter()
        .flat_map(|dx| {
            [0.0, g.height_cells as f64 * g.resolution_m]
                .map(|dy| (g.origin_m[0] + dx).hypot(g.origin_m[1] + dy))
        })
        .fold(0.0, f64::max);
    let hough = &mut config.hough;
    if far + hough.rho_step_m > hough.rho_max_m {
        hough.rho_max_m = far + hough.rho_step_m;
    }
    config
}

/// The world file of a run: the one given, else the one run.yaml names if it exists (with a
/// warning when it names one that is not there: the run was moved, or its world deleted).
pub fn world_of_run(given: Option<&Path>, run_dir: &Path, run: &RunDataset) -> Option<PathBuf> {
    given.map(Path::to_path_buf).or_else(|| {
        let named = run_dir.join(run.meta.world.as_ref()?);
        if named.exists() {
            return Some(named);
        }
        tracing::warn!(
            "{} names the world {}, which is not there: going on without it (nothing is scored against it, and tag sizes come from elsewhere); give --world to use it",
            run_dir.join("run.yaml").display(),
            named.display()
        );
        None
    })
}

/// The world of a run, loaded (see [`world_of_run`]).
pub fn load_world_of_run(
    given: Option<&Path>,
    run_dir: &Path,
    run: &RunDataset,
) -> Result<Option<crate::world::World>> {
    Ok(world_of_run(given, run_dir, run)
        .as_deref()
        .map(crate::io::load_world)
        .transpose()?
        .map(|w| w.world))
}

/// Runs `f`, passing every event on to the subscriber in use as before, and returns with its
/// result the warnings `f` printed on this thread: what reading a run's files warned of (rows
/// re-ordered, an odometry jump, a world named but missing), which the readers print rather
/// than return, for `report.json`. Warnings printed on other threads are not kept.
pub(crate) fn capturing_warnings<T>(f: impl FnOnce() -> T) -> (T, Vec<String>) {
    let kept = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let capture = tracing::Dispatch::new(Capture {
        inner: tracing::dispatcher::get_default(Clone::clone),
        kept: kept.clone(),
        level: tracing::level_filters::LevelFilter::current(),
    });
    let out = tracing::dispatcher::with_default(&capture, f);
    let kept = kept.lock().map(|k| k.clone()).unwrap_or_default();
    (out, kept)
}

/// A subscriber that hands everything to `inner` and keeps the message of each warning.
struct Capture {
    inner: tracing::Dispatch,
    kept: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
    /// The most verbose level any subscriber takes, as it was (`inner`'s own hint is not public).
    level: tracing::level_filters::LevelFilter,
}

/// Whether an event is a warning (not an error: a workflow returns its errors).
fn is_warning(metadata: &tracing::Metadata<'_>) -> bool {
    metadata.is_event() && *metadata.level() == tracing::Level::WARN
}

/// The `message` field of an event.
#[derive(Default)]
struct Message(String);

impl tracing::field::Visit for Message {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
}

impl tracing::Subscriber for Capture {
    fn register_callsite(
        &self,
        metadata: &'static tracing::Metadata<'static>,
    ) -> tracing::subscriber::Interest {
        match self.inner.register_callsite(metadata) {
            never if never.is_never() && is_warning(metadata) => {
                tracing::subscriber::Interest::sometimes()
            }
            interest => interest,
        }
    }
    fn max_level_hint(&self) -> Option<tracing::level_filters::LevelFilter> {
        Some(self.level.max(tracing::level_filters::LevelFilter::WARN))
    }
    fn enabled(&self, metadata: &tracing::Metadata<'_>) -> bool {
        is_warning(metadata) || self.inner.enabled(metadata)
    }
    fn new_span(&self, span: &tracing::span::Attributes<'_>) -> tracing::span::Id {
        self.inner.new_span(span)
    }
    fn record(&self, span: &tracing::span::Id, values: &tracing::span::Record<'_>) {
        self.inner.record(span, values)
    }
    fn record_follows_from(&self, span: &tracing::span::Id, follows: &tracing::span::Id) {
        self.inner.record_follows_from(span, follows)
    }
    fn event(&self, event: &tracing::Event<'_>) {
        if is_warning(event.metadata()) {
            let mut message = Message::default();
            event.record(&mut message);
            if let Ok(mut kept) = self.kept.lock() {
                kept.push(message.0);
            }
        }
        // Kept even when nothing prints it (no subscriber, or one that leaves warnings out).
        if self.inner.enabled(event.metadata()) {
            self.inner.event(event)
        }
    }
    fn enter(&self, span: &tracing::span::Id) {
        self.inner.enter(span)
    }
    fn exit(&self, span: &tracing::span::Id) {
        self.inner.exit(span)
    }
    fn clone_span(&self, id: &tracing::span::Id) -> tracing::span::Id {
        self.inner.clone_span(id)
    }
    fn try_close(&self, id: tracing::span::Id) -> bool {
        self.inner.try_close(id)
    }
}

/// The warnings a workflow prints as it runs, kept for its recording and its caller.
#[derive(Debug, Default)]
pub(crate) struct Warnings(pub(crate) Vec<String>);

impl Warnings {
    /// Prints `text` as a warning and keeps it.
    pub(crate) fn warn(&mut self, text: String) {
        tracing::warn!("{text}");
        self.0.push(text);
    }
}

/// `to` relative to the directory `from_dir` (both as given, made absolute first).
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The warnings printed while reading come back with the result, once each, whether or not
    /// a subscriber prints them; everything still reaches the subscriber in use.
    #[test]
    fn the_warnings_printed_while_reading_are_kept() {
        // No subscriber: nothing prints, the warnings are kept all the same.
        let (out, kept) = capturing_warnings(|| {
            tracing::warn!("rows re-ordered");
            tracing::info!("a grid fitted");
            7
        });
        assert_eq!((out, kept), (7, vec!["rows re-ordered".to_string()]));
        // A subscriber that prints warnings and information: it gets both, as before.
        let printed = std::sync::Arc::new(std::sync::Mutex::new(Vec::<u8>::new()));
        let sink = printed.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_max_level(tracing::Level::INFO)
            .with_ansi(false)
            .with_writer(move || Writer(sink.clone()))
            .finish();
        let kept = tracing::subscriber::with_default(subscriber, || {
            capturing_warnings(|| {
                tracing::warn!("an odometry jump at t = {:.1} s", 12.0);
                tracing::info!("ranges from the lidar");
                tracing::debug!("not printed");
            })
            .1
        });
        assert_eq!(kept, ["an odometry jump at t = 12.0 s"]);
        let printed = String::from_utf8(printed.lock().unwrap().clone()).unwrap();
        assert!(
            printed.contains("an odometry jump at t = 12.0 s"),
            "{printed}"
        );
        assert!(printed.contains("ranges from the lidar"), "{printed}");
        assert!(!printed.contains("not printed"), "{printed}");
        assert_eq!(printed.matches("odometry jump").count(), 1, "{printed}");
    }

    /// A shared buffer the test's subscriber writes to.
    struct Writer(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);

    impl std::io::Write for Writer {
        fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(bytes);
            Ok(bytes.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
}
