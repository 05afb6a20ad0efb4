//! A directory of EuRoC / yac corner CSV files (two views), read by `io::load_corner_csvs`.
#![no_main]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let p = common::parts(data, 2);
    common::write("corners/1.csv", p[0]);
    common::write("corners/2.csv", p[1]);
    let _ = stereotag::io::load_corner_csvs(&common::scratch().join("corners"));
});
