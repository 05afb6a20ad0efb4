//! Models checked against the real data in ../shared/data.

mod common;

use stereotag::io::read_uci_sonar_ring;
use stereotag::sim::{dropout_rate_from_ring, SonarPhysics};
use stereotag::sonar::SonarLayout;

#[test]
fn dropout_rate_matches_the_uci_wall_following_robot() {
    let Some(path) = common::shared("sonar/uci_wall_following/sensor_readings_24.data") else {
        eprintln!("shared data not found; skipping");
        return;
    };
    let rows = read_uci_sonar_ring(&path).unwrap();
    assert_eq!(rows.len(), 5456);
    assert!(rows.iter().all(|r| r.len() == 24));
    // No echo reads 5.000 m in that data set.
    let rate = dropout_rate_from_ring(&rows, 1.0, 4.999).unwrap();
    assert!(
        (rate - SonarPhysics::default().dropout_prob).abs() < 0.002,
        "measured {rate}"
    );
}

#[test]
fn pioneer_layout_matches_the_aria_parameter_file() {
    let Some(path) = common::shared("sonar/pioneer_geometry/p3dx-sh.p") else {
        eprintln!("shared data not found; skipping");
        return;
    };
    let text = std::fs::read_to_string(path).unwrap();
    let layout = SonarLayout::pioneer16();
    let mut n = 0;
    for line in text.lines().filter(|l| l.starts_with("SonarUnit")) {
        let f: Vec<f64> = line
            .split_whitespace()
            .skip(1)
            .take(4)
            .map(|v| v.parse().unwrap())
            .collect();
        let s = layout.sensors[f[0] as usize];
        assert!((s.x_m * 1000.0 - f[1]).abs() < 1e-9 && (s.y_m * 1000.0 - f[2]).abs() < 1e-9);
        assert!((s.bearing_rad.to_degrees() - f[3]).abs() < 1e-9);
        n += 1;
    }
    assert_eq!(n, 16);
}

#[test]
fn willow_crop_traces_into_walls_inside_its_bounds() {
    let loaded = stereotag::io::load_world(&common::sample("willow/world.yaml")).unwrap();
    let (lo, hi) = loaded.world.bounds();
    assert!(lo.x >= -1e-9 && lo.y >= -1e-9 && hi.x <= 13.0 + 1e-9 && hi.y <= 12.0 + 1e-9);
    assert!(loaded.world.walls.len() > 20);
}
