//! Progress of long work and the time its stages take, reported to whoever runs it: the command
//! line draws bars from it, a program embedding the library may show it or ignore it
//! ([`Silent`]).
//!
//! A workflow announces each stage with [`Progress::start`] (its name and number of steps),
//! reports steps as they are done (from worker threads too, hence `Sync`) and closes the stage
//! with [`Progress::finish`].

/// Receives a workflow's progress. Every method does nothing by default.
pub trait Progress: Sync {
    /// A stage of `total` steps starts (e.g. `"detect"`, 779 stereo pairs); 0 for a stage whose
    /// steps are not counted (the command line shows its name and the time it has taken).
    fn start(&self, _stage: &str, _total: u64) {}
    /// `steps` more steps of the current stage are done.
    fn advance(&self, _steps: u64) {}
    /// The current stage has done `done` steps in all.
    fn set(&self, _done: u64) {}
    /// The current stage is over.
    fn finish(&self) {}
}

/// Progress that goes nowhere.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {}

/// Runs `f` as an uncounted stage `name` of `progress` ([`Progress::start`] with no total).
pub(crate) fn staged<T>(progress: &dyn Progress, name: &str, f: impl FnOnce() -> T) -> T {
    progress.start(name, 0);
    let out = f();
    progress.finish();
    out
}

/// Runs `f`, noting its wall-clock time in seconds under `name` (a stage of a report's
/// `timings_s`).
pub(crate) fn timed<T>(
    name: &str,
    timings: &mut std::collections::BTreeMap<String, f64>,
    f: impl FnOnce() -> T,
) -> T {
    let t = std::time::Instant::now();
    let out = f();
    timings.insert(name.to_owned(), t.elapsed().as_secs_f64());
    out
}
