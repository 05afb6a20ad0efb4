//! The run dataset survives a write and a read.

mod common;

use stereotag::io::{load_run, load_world, save_run};
use stereotag::sim::simulate;

#[test]
fn simulated_run_round_trips() {
    let loaded = load_world(&common::sample("office/world.yaml")).unwrap();
    let mut config = loaded.simulation.clone();
    config.exploration.duration_s = 60.0;
    let out = simulate(&loaded.world, &config, |_| {}).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    save_run(tmp.path(), &out.run).unwrap();
    let back = load_run(tmp.path()).unwrap();
    assert_eq!(back.meta, out.run.meta);
    assert_eq!(back.sonar.len(), out.run.sonar.len());
    assert_eq!(back.odometry.len(), out.run.odometry.len());
    for (a, b) in back.sonar.iter().zip(&out.run.sonar) {
        assert_eq!(a.sensor, b.sensor);
        assert_eq!(a.range_m.is_some(), b.range_m.is_some());
        assert!((a.range_m.unwrap_or(0.0) - b.range_m.unwrap_or(0.0)).abs() <= 5e-5);
    }
    for (a, b) in back.odometry.iter().zip(&out.run.odometry) {
        assert!((a.pose.x - b.pose.x).abs() <= 5e-6 && (a.pose.theta - b.pose.theta).abs() <= 5e-7);
    }
    assert!(back.ground_truth.is_some());
}

#[test]
fn simulate_takes_stereo_pictures_when_tags_are_in_view() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    use stereotag::workflow::simulate::{simulate, Pictures, SimSettings, SimulateRequest};
    simulate(
        &SimulateRequest {
            world: &common::sample("office/world.yaml"),
            out: &out,
            settings: SimSettings::default(),
            pictures: Some(Pictures {
                rig: &common::root().join(stereotag::io::DEFAULT_RIG),
                policy: Default::default(),
                default_mounting: false,
            }),
            force: false,
            along: None,
        },
        &stereotag::progress::Silent,
    )
    .unwrap();
    let run = load_run(&out).unwrap();
    assert!(run.stereo.len() >= 5, "{} pairs", run.stereo.len());
    for e in &run.stereo {
        assert!(out.join(&e.left).exists() && out.join(&e.right).exists());
    }
    let rig = stereotag::io::load_rig(&out.join(run.meta.robot.rig.as_deref().unwrap())).unwrap();
    assert_eq!(rig.left.width, 640);
}
