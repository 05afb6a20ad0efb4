//! Diagnostic: time of the visual odometry's stages on a run's stereo pairs.
//! Usage: cargo run --release --example vo_speed -- RUN_DIR
use std::time::Instant;
use stereotag::geometry::pose_at;
use stereotag::io;
use stereotag::visual::vo::{relative_motion, VoConfig, VoImage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).ok_or("usage: RUN_DIR")?);
    let run = io::load_run(&dir)?;
    let rig = io::load_rig(&dir.join("rig.yaml"))?;
    let n = run.stereo.len().min(100);
    let t = Instant::now();
    let grays: Vec<_> = run.stereo[..n]
        .iter()
        .map(|e| {
            (
                io::load_gray(&dir.join(&e.left)).unwrap(),
                io::load_gray(&dir.join(&e.right)).unwrap(),
            )
        })
        .collect();
    let decode = t.elapsed().as_secs_f64() / (2 * n) as f64;
    // As a survey streams them: each image prepared once, dropped after its last use.
    let config = VoConfig::default();
    let (mut prep, mut motion, mut ok) = (0.0, 0.0, 0);
    let t = Instant::now();
    let mut last = (VoImage::new(&grays[0].0), VoImage::new(&grays[0].1));
    prep += t.elapsed().as_secs_f64();
    for (k, (left, right)) in grays.iter().enumerate().skip(1) {
        let t = Instant::now();
        let next = (VoImage::new(left), VoImage::new(right));
        prep += t.elapsed().as_secs_f64();
        let (a, b) = (&run.stereo[k - 1], &run.stereo[k]);
        let prior = pose_at(&run.odometry, a.t_s)
            .unwrap()
            .between(&pose_at(&run.odometry, b.t_s).unwrap());
        let t = Instant::now();
        if relative_motion(&rig, (&last.0, &last.1), &next.0, &prior, &config).is_ok() {
            ok += 1;
        }
        motion += t.elapsed().as_secs_f64();
        last = next;
    }
    let prep = prep / (2 * n) as f64;
    let motion = motion / (n - 1) as f64;
    println!("{n} pairs: decode {:.2} ms/image, prepare {:.2} ms/image, motion {:.2} ms/pair ({ok} of {} found)", decode * 1e3, prep * 1e3, motion * 1e3, n - 1);
    Ok(())
}
