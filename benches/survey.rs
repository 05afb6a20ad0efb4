//! Speed of a whole survey (issue 5: the museum run in <= 2 s on two cores, reading its images
//! included, rendering not). The museum is simulated and rendered once (seed 1, about 40 s), then
//! `stereotag survey --no-rerun` is timed as a user runs it, process start to exit; the reference
//! in the same group is the same survey with the C library's own `min_white_black_diff` (5).

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
    let mut group = c.benchmark_group("museum_survey");
    group.sample_size(10);
    for (name, min_contrast) in [
        ("min_contrast_5 (C library default, reference)", "5"),
        ("min_contrast_30 (survey default)", "30"),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                stereotag(&[
                    "survey",
                    "--run",
                    &run,
                    "--out",
                    &out,
                    "--force",
                    "--no-rerun",
                    "--min-contrast",
                    min_contrast,
                ])
            })
        });
    }
    group.finish();
}

criterion_group!(benches, survey);
criterion_main!(benches);
