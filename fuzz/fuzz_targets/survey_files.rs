//! The files a later command reads back: a survey's landmarks.json and walls_corrected.csv
//! (`localize`), a map's features.csv and ROS occupancy map (`plan`), a pose CSV (`render
//! --poses`).
#![no_main]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let p = common::parts(data, 6);
    let _ = stereotag::io::load_landmarks(&common::write("landmarks.json", p[0]));
    let _ = stereotag::io::load_features_csv(&common::write("features.csv", p[1]));
    common::write("occ.pgm", p[3]);
    let _ = stereotag::io::load_ros_occupancy(&common::write("occ.yaml", p[2]));
    let _ = stereotag::io::read_poses(&common::write("poses.csv", p[4]));
    let _ = stereotag::io::load_walls_csv(&common::write("walls.csv", p[5]));
});
