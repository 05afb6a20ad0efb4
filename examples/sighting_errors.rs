//! Diagnostic: each tag sighting of a simulated run against the truth (position and yaw error
//! in sigmas). Usage: cargo run --release --example sighting_errors -- RUN_DIR
use stereotag::fusion::TagSighting;
use stereotag::geometry::pose_at;
use stereotag::io;
use stereotag::visual::sightings::sightings_from_pair;
use stereotag::visual::stereo::StereoConfig;
use stereotag::visual::tags::{CDetector, DetectorConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).ok_or("usage: RUN_DIR")?);
    let run = io::load_run(&dir)?;
    let world = io::load_world(&dir.join(run.meta.world.as_ref().ok_or("no world")?))?.world;
    let rig = io::load_rig(&dir.join(run.meta.robot.rig.as_ref().ok_or("no rig")?))?;
    let rect = rig.rectify();
    let mut det = CDetector::new(DetectorConfig {
        decimate: 1.0,
        ..DetectorConfig::default()
    })?;
    let truth = run.ground_truth.as_ref().ok_or("no truth")?;
    println!("t_s,id,range_m,ex_m,ey_m,sx_m,sy_m,eyaw_rad,syaw_rad");
    for (k, e) in run.stereo.iter().enumerate() {
        let l = io::load_gray(&dir.join(&e.left))?;
        let r = io::load_gray(&dir.join(&e.right))?;
        let (s, _) = sightings_from_pair(
            &mut det,
            &rig,
            &rect,
            &l,
            &r,
            (e.t_s, k),
            &|_, _| Some(0.16),
            &StereoConfig::default(),
        )?;
        let pose = pose_at(truth, e.t_s).ok_or("time")?;
        for t in s {
            let TagSighting {
                id,
                position_in_robot_m: p,
                covariance_m2: c,
                yaw_in_robot_rad,
                yaw_sigma_rad,
                ..
            } = t;
            let tag = world.tags.iter().find(|x| x.id == id).ok_or("tag")?;
            let local = pose
                .inverse()
                .transform_point(nalgebra::Point2::new(tag.position_m[0], tag.position_m[1]));
            let yaw = stereotag::geometry::wrap_angle(tag.yaw_rad - pose.theta);
            println!(
                "{:.2},{id},{:.2},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}",
                e.t_s,
                local.coords.norm(),
                p[0] - local.x,
                p[1] - local.y,
                c[0][0].sqrt(),
                c[1][1].sqrt(),
                stereotag::geometry::wrap_angle(yaw_in_robot_rad - yaw),
                yaw_sigma_rad
            );
        }
    }
    Ok(())
}
