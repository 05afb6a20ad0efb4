//! Diagnostic: visual odometry against the truth on frames rendered along a simulated run.
//! Usage: cargo run --release --example vo_check -- RUN_DIR WORLD [SECONDS] [STEP_M] [STEP_DEG]
use rayon::prelude::*;
use stereotag::geometry::pose_at;
use stereotag::geometry::wrap_angle;
use stereotag::io;
use stereotag::render::{RenderConfig, Renderer};
use stereotag::visual::vo::{relative_motion, VoConfig, VoImage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dir = std::path::PathBuf::from(&args[1]);
    let world = io::load_world(std::path::Path::new(&args[2]))?.world;
    let secs: f64 = args.get(3).map_or(Ok(200.0), |s| s.parse())?;
    let step_m: f64 = args.get(4).map_or(Ok(0.3), |s| s.parse())?;
    let step_deg: f64 = args.get(5).map_or(Ok(20.0), |s| s.parse())?;
    let run = io::load_run(&dir)?;
    let rig = io::load_rig(&dir.join("rig.yaml"))?;
    let gt = run.ground_truth.clone().ok_or("no truth")?;
    let mut frames = vec![gt[0]];
    for p in &gt {
        if p.t_s > secs {
            break;
        }
        let l = frames.last().unwrap();
        if (p.pose.x - l.pose.x).hypot(p.pose.y - l.pose.y) >= step_m
            || wrap_angle(p.pose.theta - l.pose.theta).abs() >= step_deg.to_radians()
        {
            frames.push(*p);
        }
    }
    let renderer = Renderer::new(&rig);
    let t = std::time::Instant::now();
    let pairs: Vec<(image::GrayImage, image::GrayImage)> = frames
        .par_iter()
        .enumerate()
        .map(|(k, f)| {
            let pair = renderer
                .render(
                    &world,
                    f.pose,
                    &RenderConfig {
                        seed: k as u64 + 7,
                        ..RenderConfig::default()
                    },
                )
                .unwrap();
            (pair.left, pair.right)
        })
        .collect();
    eprintln!(
        "{} frames rendered in {:.1} s",
        frames.len(),
        t.elapsed().as_secs_f64()
    );
    let t = std::time::Instant::now();
    let images: Vec<(VoImage, VoImage)> = pairs
        .iter()
        .map(|(l, r)| (VoImage::new(l), VoImage::new(r)))
        .collect();
    eprintln!(
        "prepared in {:.2} ms per image",
        t.elapsed().as_secs_f64() * 1e3 / (2 * pairs.len()) as f64
    );
    let config = VoConfig::default();
    let t = std::time::Instant::now();
    let mut errs = Vec::new();
    let (mut sum_vo, mut sum_odo, mut sum_true) = (0.0, 0.0, 0.0);
    for k in 1..frames.len() {
        let (a, b) = (frames[k - 1], frames[k]);
        let oa = pose_at(&run.odometry, a.t_s).unwrap();
        let ob = pose_at(&run.odometry, b.t_s).unwrap();
        let prior = oa.between(&ob);
        let truth = a.pose.between(&b.pose);
        match relative_motion(
            &rig,
            (&images[k - 1].0, &images[k - 1].1),
            &images[k].0,
            &prior,
            &config,
        ) {
            Ok(m) => {
                let e = wrap_angle(m.motion.theta - truth.theta);
                let eo = wrap_angle(prior.theta - truth.theta);
                sum_vo += e;
                sum_odo += eo;
                sum_true += truth.theta;
                errs.push(e);
                println!(
                    "{k:4} t={:7.2} turn={:7.2}deg move={:.3}m  vo_err={:8.4}deg (sd {:.4}) odo_err={:8.4}deg  xy_err=({:6.1},{:6.1})mm inl={}/{} rms={:.2}px",
                    b.t_s,
                    truth.theta.to_degrees(),
                    truth.x.hypot(truth.y),
                    e.to_degrees(),
                    m.covariance[(2, 2)].sqrt().to_degrees(),
                    eo.to_degrees(),
                    (m.motion.x - truth.x) * 1e3,
                    (m.motion.y - truth.y) * 1e3,
                    m.inliers,
                    m.tracked,
                    m.rms_px
                );
            }
            Err(e) => println!("{k:4} t={:7.2} FAILED {e}", b.t_s),
        }
    }
    let n = errs.len() as f64;
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    eprintln!(
        "{} of {} pairs; vo {:.1} ms/pair; yaw error rms {:.4} deg; summed: vo {:.3} deg, odometry {:.3} deg over {:.1} deg turned",
        errs.len(),
        frames.len() - 1,
        t.elapsed().as_secs_f64() * 1e3 / (frames.len() - 1) as f64,
        rms.to_degrees(),
        sum_vo.to_degrees(),
        sum_odo.to_degrees(),
        sum_true.to_degrees()
    );
    Ok(())
}
