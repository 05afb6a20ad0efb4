//! Speed of a whole survey (issue 5: the museum run in <= 2 s on two cores, reading its images
//! included, rendering not). The museum is simulated and rendered once (seed 1, about 40 s), then
//! `stereotag survey --no-rerun` is timed as a user runs it, process start to exit, at its defaults
//! (`--decimate 1.5 --min-contrast 40`); the references in the same group are the same survey with
//! the C library's own settings (`min_white_black_diff` 5, no decimation), at full resolution
//! (`--decimate 1`: finds the farthest tags as well), and without the visual odometry
//! (`visual_odometry: false`, tag sightings and wheels only).

use criterion::{criterion_group, criterion_main, Criterion};
use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_stereotag");

fn stereotag(args: &[&str]) {
    let status = Command::new(BIN)
        .arg("-q")
        .args(args)
        .status()
        .expect("stereotag runs");
    assert!(status.success(), "stereotag {args:?} failed");
}

fn survey(c: &mut Criterion) {
    let tmp = tempfile::tempdir().expect("temporary directory");
    let run = tmp.path().join("run");
    let out = tmp.path().join("survey");
    let path = |p: &Path| p.to_str().expect("UTF-8 path").to_owned();
    let (run, out) = (path(&run), path(&out));
    stereotag(&[
        "simulate",
        "--world",
        "samples/museum/world.yaml",
        "--seed",
        "1",
        "--out",
        &run,
    ]);
    let no_vo = tmp.path().join("no_visual_odometry.yaml");
    std::fs::write(&no_vo, "visual_odometry: false\n").expect("writing the fusion settings");
    let no_vo = path(&no_vo);
    let mut group = c.benchmark_group("museum_survey");
    group.sample_size(10);
    for (name, extra) in [
        (
            "C library's settings: min_contrast 5, decimate 1 (reference)",
            &["--min-contrast", "5", "--decimate", "1"][..],
        ),
        (
            "full resolution: decimate 1 (reference)",
            &["--decimate", "1"][..],
        ),
        (
            "no visual odometry (reference)",
            &["--config", no_vo.as_str()][..],
        ),
        ("survey default: decimate 1.5, min_contrast 40", &[][..]),
    ] {
        let mut args = vec![
            "survey",
            "--run",
            run.as_str(),
            "--out",
            out.as_str(),
            "--force",
            "--no-rerun",
        ];
        args.extend(extra);
        group.bench_function(name, |b| b.iter(|| stereotag(&args)));
    }
    group.finish();
}

criterion_group!(benches, survey);
criterion_main!(benches);
