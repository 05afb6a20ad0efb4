//! Diagnostic: the visual odometry of listed pairs of a run's pictures against the truth, with
//! what the solve says about itself (inliers, points tracked, residual RMS, sigma). PAIRS.csv has
//! a header and `from_t_s,to_t_s` rows (the first two columns of a survey's visual_turns.csv).
//! Usage: cargo run --release --example vo_turns -- RUN_DIR PAIRS.csv
use stereotag::geometry::pose_at;
use stereotag::io;
use stereotag::visual::vo::{relative_motion, VoConfig, VoImage};
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dir = std::path::PathBuf::from(&args[1]);
    let run = io::load_run(&dir)?;
    let rig = io::load_rig(&dir.join("rig.yaml"))?;
    let gt = run.ground_truth.clone().ok_or("no truth")?;
    let csv = std::fs::read_to_string(&args[2])?;
    let mut cfg = VoConfig::default();
    if let Ok(v) = std::env::var("SLIP") {
        cfg.slip_sigma = (v.parse()?, 0.0);
    }
    for line in csv.lines().skip(1) {
        let f: Vec<f64> = line
            .split(',')
            .take(2)
            .map(|v| v.trim().parse())
            .collect::<Result<_, _>>()?;
        let (a, b) = (f[0], f[1]);
        let at = |t: f64| {
            run.stereo
                .iter()
                .position(|e| (e.t_s - t).abs() < 1e-6)
                .ok_or(format!("no picture at {t} s"))
        };
        let (ia, ib) = (at(a)?, at(b)?);
        let l = |i: usize, left: bool| {
            let e = &run.stereo[i];
            io::load_gray(&dir.join(if left { &e.left } else { &e.right })).unwrap()
        };
        let prior = pose_at(&run.odometry, a)
            .unwrap()
            .between(&pose_at(&run.odometry, b).unwrap());
        let truth = pose_at(&gt, a).unwrap().between(&pose_at(&gt, b).unwrap());
        let m = relative_motion(
            &rig,
            (&VoImage::new(&l(ia, true)), &VoImage::new(&l(ia, false))),
            &VoImage::new(&l(ib, true)),
            &prior,
            &cfg,
        )?;
        println!("{a:.2}-{b:.2} err {:.3} deg turn {:.1} deg prior err {:.3} deg, {:.3} {:.3} m; truth {:.3} {:.3} m; vo {:.3} {:.3} inliers {} tracked {} rms {:.2} px sigma {:.3} deg",
            (m.motion.theta - truth.theta).to_degrees(), truth.theta.to_degrees(),
            (prior.theta - truth.theta).to_degrees(), prior.x - truth.x, prior.y - truth.y, truth.x, truth.y, m.motion.x, m.motion.y, m.inliers, m.tracked, m.rms_px, m.covariance[(2,2)].sqrt().to_degrees());
    }
    Ok(())
}
