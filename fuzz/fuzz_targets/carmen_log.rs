//! A CARMEN log (ODOM, FLASER, RLASER, ROBOTLASER1 lines), read by `io::carmen::parse_carmen`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = stereotag::io::carmen::parse_carmen(std::path::Path::new("fuzz.log"), text);
    }
});
