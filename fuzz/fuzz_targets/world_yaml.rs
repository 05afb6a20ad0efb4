//! A world file (and the ROS map YAML and image it may name), read by `io::load_world`.
#![no_main]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let p = common::parts(data, 3);
    common::write("map.yaml", p[1]);
    common::write("map.pgm", p[2]);
    let world = common::write("world.yaml", p[0]);
    let _ = stereotag::io::load_world(&world);
});
