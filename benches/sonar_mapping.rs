//! Speed of the sonar half: grid insertion and Hough voting per reading at 20 cm and 5 cm cells,
//! and `map` on a simulated 30-minute museum run against the run's own duration.

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

criterion_group!(benches, per_reading, whole_run);
criterion_main!(benches);
