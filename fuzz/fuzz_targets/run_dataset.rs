//! A run dataset: run.yaml, odometry.csv, sonar.csv, stereo.csv and ground_truth.csv from one
//! input split at NUL bytes, read by `io::load_run`.
#![no_main]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let p = common::parts(data, 5);
    for (name, bytes) in ["run.yaml", "odometry.csv", "sonar.csv", "stereo.csv", "ground_truth.csv"]
        .iter()
        .zip(&p)
    {
        common::write(&format!("run/{name}"), bytes);
    }
    let _ = stereotag::io::load_run(&common::scratch().join("run"));
});
