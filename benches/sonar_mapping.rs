//! Speed of the sonar half: grid insertion and Hough voting per reading at 20 cm and 5 cm cells,
//! `map` on a simulated 30-minute museum run against the run's own duration, and how `map`'s time
//! grows with the readings (issue 31, item 5): museum runs of 5, 15, 30 and 60 minutes and the
//! two real building logs of `../shared/data/radish` (as sonar, ground-truth poses), each against
//! the counting grid alone on the same readings (the reference: what inserting the readings
//! costs). Criterion's throughput is readings per second; the per-reading figures are printed.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use std::hint::black_box;
use std::path::Path;
use stereotag::dataset::PoseSource;
use stereotag::sonar::grid::{CountingGrid, GridConfig, LogOddsGrid, OccupancyGrid};
use stereotag::sonar::hough::{Accumulator, HoughConfig};
use stereotag::sonar::map::map_trajectory;
use stereotag::sonar::{PlacedReading, SonarLayout};

fn museum_readings() -> (
    stereotag::dataset::RunDataset,
    stereotag::sonar::map::MappingConfig,
) {
    let loaded =
        stereotag::io::load_world(Path::new("samples/museum/world.yaml")).expect("museum sample");
    let mut config = loaded.simulation.clone();
    config.exploration.duration_s = 1800.0;
    let out = stereotag::sim::simulate(&loaded.world, &config, |_| {}).expect("simulation");
    (
        out.run,
        loaded.mapping.expect("the museum sets its mapping"),
    )
}

fn per_reading(c: &mut Criterion) {
    let (run, _) = museum_readings();
    let readings: Vec<PlacedReading> =
        run.placed_readings(run.ground_truth.as_deref().unwrap_or(&run.odometry));
    let layout = SonarLayout::frontal5();
    let mut group = c.benchmark_group("per_reading");
    for (res, cells) in [(0.2, 120), (0.05, 480)] {
        let config = GridConfig {
            resolution_m: res,
            width_cells: cells,
            height_cells: cells,
            ..GridConfig::default()
        };
        group.bench_with_input(
            BenchmarkId::new("grid_counting", format!("{}cm", res * 100.0)),
            &config,
            |b, cfg| {
                let mut g =
                    CountingGrid::new(cfg.clone(), layout.cone_rad, layout.max_range_m).unwrap();
                let mut i = 0;
                b.iter(|| {
                    g.insert(black_box(&readings[i % readings.len()]));
                    i += 1;
                })
            },
        );
        group.bench_with_input(
            BenchmarkId::new("grid_log_odds", format!("{}cm", res * 100.0)),
            &config,
            |b, cfg| {
                let mut g =
                    LogOddsGrid::new(cfg.clone(), layout.cone_rad, layout.max_range_m).unwrap();
                let mut i = 0;
                b.iter(|| {
                    g.insert(black_box(&readings[i % readings.len()]));
                    i += 1;
                })
            },
        );
    }
    for (rho, name) in [(0.1, "hough_vote/10cm"), (0.05, "hough_vote/5cm")] {
        let config = HoughConfig {
            rho_step_m: rho,
            ..HoughConfig::default()
        };
        group.bench_function(name, |b| {
            let mut acc = Accumulator::new(&config);
            let mut i = 0;
            b.iter(|| {
                acc.vote(
                    black_box(&readings[i % readings.len()]),
                    0.5 * layout.cone_rad,
                    config.arc_sample_m,
                );
                i += 1;
                if i % readings.len() == 0 {
                    acc.clear();
                }
            })
        });
    }
    group.finish();
}

fn whole_run(c: &mut Criterion) {
    let (run, mapping) = museum_readings();
    let duration = run.odometry.last().map_or(0.0, |p| p.t_s);
    let mut group = c.benchmark_group("map_museum_run");
    group.sample_size(10);
    group.bench_function("map_run", |b| {
        b.iter(|| {
            map_trajectory(
                &run.sonar_log(),
                run.trajectory(PoseSource::Odometry).unwrap(),
                &mapping,
            )
            .unwrap()
        })
    });
    group.finish();
    let start = std::time::Instant::now();
    let n = 5;
    for _ in 0..n {
        black_box(
            map_trajectory(
                &run.sonar_log(),
                run.trajectory(PoseSource::Odometry).unwrap(),
                &mapping,
            )
            .unwrap(),
        );
    }
    let secs = start.elapsed().as_secs_f64() / n as f64;
    println!(
        "museum run: {:.0} s simulated, {} readings, mapped in {:.4} s = {:.0}x faster than real time",
        duration,
        run.sonar.len(),
        secs,
        duration / secs
    );
}

/// A real CARMEN log of `../shared/data/radish`, imported as frontal sonar; `None` when the data
/// is not there.
fn radish_run(log: &str, dir: &Path) -> Option<stereotag::dataset::RunDataset> {
    let path = Path::new("../shared/data/radish").join(log);
    if !path.exists() {
        println!("{} not found: the real logs are left out", path.display());
        return None;
    }
    let out = dir.join(log);
    let request = stereotag::workflow::import::CarmenRequest {
        carmen: &path,
        out: &out,
        as_sonar: Some(SonarLayout::frontal5()),
        force: true,
    };
    stereotag::workflow::import::import_carmen(&request).expect("the log imports");
    Some(stereotag::io::load_run(&out).expect("the imported run loads"))
}

fn growth(c: &mut Criterion) {
    let loaded =
        stereotag::io::load_world(Path::new("samples/museum/world.yaml")).expect("museum sample");
    let mut runs = Vec::new();
    for minutes in [5, 15, 30, 60] {
        let mut config = loaded.simulation.clone();
        config.exploration.duration_s = minutes as f64 * 60.0;
        let run = stereotag::sim::simulate(&loaded.world, &config, |_| {})
            .expect("simulation")
            .run;
        let mapping = loaded.mapping.clone().expect("the museum sets its mapping");
        runs.push((format!("museum {minutes} min"), run, mapping));
    }
    let tmp = tempfile::tempdir().expect("temporary directory");
    for log in ["freiburg-079-corrected.log.gz", "aces-corrected.log.gz"] {
        if let Some(run) = radish_run(log, tmp.path()) {
            let mapping = run.meta.mapping.clone().unwrap_or_default();
            runs.push((log.replace("-corrected.log.gz", ""), run, mapping));
        }
    }
    let mut group = c.benchmark_group("map_growth");
    group.sample_size(10);
    for (name, run, mapping) in &runs {
        let truth = run
            .trajectory(PoseSource::GroundTruth)
            .expect("the run has ground truth");
        let readings = run.sonar.len();
        group.throughput(criterion::Throughput::Elements(readings as u64));
        group.bench_function(BenchmarkId::new("map", name), |b| {
            b.iter(|| map_trajectory(&run.sonar_log(), truth, mapping).unwrap())
        });
        group.bench_function(
            BenchmarkId::new("counting grid alone (reference)", name),
            |b| {
                b.iter(|| {
                    stereotag::sonar::map::counting_map_along(&run.sonar_log(), truth, mapping)
                        .unwrap()
                })
            },
        );
    }
    group.finish();
    for (name, run, mapping) in &runs {
        let truth = run.trajectory(PoseSource::GroundTruth).unwrap();
        let n = 5;
        let start = std::time::Instant::now();
        for _ in 0..n {
            black_box(map_trajectory(&run.sonar_log(), truth, mapping).unwrap());
        }
        let secs = start.elapsed().as_secs_f64() / n as f64;
        println!(
            "{name}: {} readings, map {:.1} ms = {:.2} us a reading",
            run.sonar.len(),
            secs * 1e3,
            secs * 1e6 / run.sonar.len() as f64
        );
    }
}

criterion_group!(benches, per_reading, whole_run, growth);
criterion_main!(benches);
