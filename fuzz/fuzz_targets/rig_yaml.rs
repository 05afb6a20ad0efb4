//! A Kalibr camchain rig file, read by `io::load_rig`; a rig that loads is also rectified and
//! written back out (the exports must not panic on what the reader accepted).
#![no_main]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let path = common::write("rig.yaml", data);
    if let Ok(rig) = stereotag::io::load_rig(&path) {
        let _ = rig.rectify();
        let _ = stereotag::io::save_rig(&common::scratch().join("rig_out.yaml"), &rig);
    }
});
