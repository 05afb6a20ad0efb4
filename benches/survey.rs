//! Speed of a whole survey (issue 5: the museum run in <= 2 s on two cores, reading its images
//! included, rendering not). The museum is simulated and rendered once (seed 1, about 40 s), then
//! `stereotag survey --no-rerun` is timed as a user runs it, process start to exit; the references
//! in the same group are the same survey with the C library's own `min_white_black_diff` (5),
//! without the visual odometry (`visual_odometry: false`, tag sightings and wheels only), and with
//! the C library decimating by 1.5 (`--decimate 1.5`: faster, misses some far tags).

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
    for (name, min_contrast, extra) in [
        (
            "min_contrast_5 (C library default, reference)",
            "5",
            &[][..],
        ),
        (
            "min_contrast_30, no visual odometry (reference)",
            "30",
            &["--config", no_vo.as_str()][..],
        ),
        (
            "min_contrast_30, decimate 1.5 (faster, fewer far tags)",
            "30",
            &["--decimate", "1.5"][..],
        ),
        ("min_contrast_30 (survey default)", "30", &[][..]),
    ] {
        let mut args = vec![
            "survey",
            "--run",
            run.as_str(),
            "--out",
            out.as_str(),
            "--force",
            "--no-rerun",
            "--min-contrast",
            min_contrast,
        ];
        args.extend(extra);
        group.bench_function(name, |b| b.iter(|| stereotag(&args)));
    }
    group.finish();
}

criterion_group!(benches, survey);
criterion_main!(benches);
