//! A Kalibr calibration target file, read by `io::load_target`.
#![no_main]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let path = common::write("target.yaml", data);
    let _ = stereotag::io::load_target(&path);
});
