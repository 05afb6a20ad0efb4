//! Latency of the streaming localiser (issue 34: per stereo pair and per odometry step, single
//! thread, 640x480). The office is surveyed once (the demo, seed 1, no recording) and a second
//! day's run simulated (seed 2, about a minute together); then its data are fed to a
//! `StereoLocalizer` in time order as a robot feeds them, and each call is timed. The reference
//! in the same group is the tag detection and triangulation of the same pairs alone (what any
//! use of a pair costs), so the figure is a ratio: what localising adds to seeing the tags.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};
use stereotag::dataset::RunDataset;
use stereotag::fusion::{FuseConfig, Start, StereoLocalizer};
use stereotag::progress::Silent;
use stereotag::visual::sightings::sightings_from_pair;
use stereotag::visual::stereo::StereoConfig;
use stereotag::visual::tags::{Backend, DetectorConfig, TagDetector, TagFamily};
use stereotag::viz::RecordingRequest;
use stereotag::workflow::localize::{SurveyUse, SurveyedMap};
use stereotag::workflow::sightings::{survey_decimate, DetectOptions, SURVEY_MIN_CONTRAST};

/// Pairs of the run held in memory and cycled through.
const PAIRS: usize = 120;

/// The survey's detector settings, one thread.
fn detector() -> Box<dyn TagDetector + Send> {
    Backend::ApriltagC
        .detector(DetectorConfig {
            families: vec![TagFamily::Tag36h11],
            decimate: survey_decimate(Backend::ApriltagC),
            min_contrast: SURVEY_MIN_CONTRAST,
            ..DetectorConfig::default()
        })
        .expect("C detector")
}

/// What the localiser is fed: the survey and the run, its first [`PAIRS`] pairs loaded.
struct Fixture {
    map: SurveyedMap,
    run: RunDataset,
    rig: stereotag::camera::StereoRig,
    pairs: Vec<(f64, image::GrayImage, image::GrayImage)>,
}

impl Fixture {
    fn new(dir: &Path) -> Self {
        let survey = dir.join("survey");
        stereotag::workflow::demo::demo(
            &stereotag::workflow::demo::DemoRequest {
                world: Path::new("samples/office/world.yaml"),
                out: &survey,
                seed: Some(1),
                rig: None,
                detect: DetectOptions::survey(Backend::ApriltagC),
                force: false,
                recording: RecordingRequest::none(),
            },
            &Silent,
        )
        .expect("the office survey");
        let run_dir = dir.join("run2");
        stereotag::workflow::simulate::simulate(
            &stereotag::workflow::simulate::SimulateRequest {
                world: Path::new("samples/office/world.yaml"),
                out: &run_dir,
                settings: stereotag::workflow::simulate::SimSettings {
                    seed: Some(2),
                    ..Default::default()
                },
                pictures: Some(stereotag::workflow::simulate::Pictures {
                    rig: Path::new(stereotag::io::DEFAULT_RIG),
                    policy: Default::default(),
                    default_mounting: false,
                }),
                force: false,
                along: None,
            },
            &Silent,
        )
        .expect("the second day's run");
        let map = SurveyedMap::load(&survey, SurveyUse::default()).expect("the survey");
        let run = stereotag::workflow::load_run(&run_dir).expect("the run");
        let rig = stereotag::workflow::survey::load_run_rig(&run_dir, &run, false)
            .expect("the rig")
            .expect("the run has pictures");
        let pairs = run
            .stereo
            .iter()
            .take(PAIRS)
            .map(|e| {
                let load = |p: &str| stereotag::io::load_gray(&run_dir.join(p)).expect("image");
                (e.t_s, load(&e.left), load(&e.right))
            })
            .collect();
        Self {
            map,
            rig,
            run,
            pairs,
        }
    }

    /// A localiser at the run's start.
    fn localizer(&self) -> StereoLocalizer {
        let filter = self.map.localizer(
            FuseConfig::default(),
            Start::Survey,
            Some(&self.run.meta.robot.sonar),
        );
        StereoLocalizer::new(filter, self.rig.clone(), detector())
    }
}

/// Feeds the run in time order from its start, timing only the calls `timed` picks (0 odometry,
/// 1 range, 2 pair), `iters` of them; starts again from the run's start at the end of the pairs
/// held.
fn feed(fixture: &Fixture, timed: u8, iters: u64) -> Duration {
    let run = &fixture.run;
    let end_t = fixture.pairs.last().map_or(0.0, |p| p.0);
    let mut inputs: Vec<(f64, u8, usize)> = Vec::new();
    inputs.extend(run.odometry.iter().enumerate().map(|(i, p)| (p.t_s, 0, i)));
    inputs.extend(run.sonar.iter().enumerate().map(|(i, r)| (r.t_s, 1, i)));
    inputs.extend(fixture.pairs.iter().enumerate().map(|(i, p)| (p.0, 2, i)));
    inputs.retain(|i| i.0 <= end_t);
    inputs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut total = Duration::ZERO;
    let mut done = 0;
    while done < iters {
        let mut localizer = fixture.localizer();
        for &(t_s, what, i) in &inputs {
            if done >= iters {
                break;
            }
            let started = Instant::now();
            match what {
                0 => {
                    black_box(localizer.odometry(t_s, run.odometry[i].pose));
                }
                1 => {
                    black_box(localizer.range(&run.sonar[i]));
                }
                _ => {
                    let (_, left, right) = &fixture.pairs[i];
                    black_box(localizer.stereo_pair(t_s, left, right).expect("pair"));
                }
            }
            if what == timed {
                total += started.elapsed();
                done += 1;
            }
        }
    }
    total
}

fn localizer(c: &mut Criterion) {
    let tmp = tempfile::tempdir().expect("temporary directory");
    let fixture = Fixture::new(tmp.path());
    let mut group = c.benchmark_group("streaming_localizer");
    let rect = fixture.rig.rectify();
    let mut reference = detector();
    let mut k = 0;
    group.bench_function(
        "pair: detect and triangulate the tags alone (reference)",
        |b| {
            b.iter(|| {
                let (t_s, left, right) = &fixture.pairs[k % fixture.pairs.len()];
                k += 1;
                black_box(
                    sightings_from_pair(
                        reference.as_mut(),
                        &fixture.rig,
                        &rect,
                        left,
                        right,
                        (*t_s, k),
                        &|_, _| None,
                        &StereoConfig::default(),
                    )
                    .expect("detection"),
                )
            })
        },
    );
    group.bench_function(
        "pair: StereoLocalizer::stereo_pair (tags, visual turn, fusion)",
        |b| b.iter_custom(|iters| feed(&fixture, 2, iters)),
    );
    group.bench_function("odometry step: StereoLocalizer::odometry", |b| {
        b.iter_custom(|iters| feed(&fixture, 0, iters))
    });
    group.bench_function("range reading: StereoLocalizer::range", |b| {
        b.iter_custom(|iters| feed(&fixture, 1, iters))
    });
    group.finish();
}

criterion_group!(benches, localizer);
criterion_main!(benches);
