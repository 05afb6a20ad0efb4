//! Corner accuracy on a rendered calibration sequence (`stereotag render --calibration-sequence`):
//! detects the board in every left and right image as `stereotag calibrate` does and compares
//! each corner with the truth. Prints the found share and the error median, 95th percentile and
//! maximum, in pixels.
//!
//! `cargo run --release --example board_corner_errors -- DIR`

use stereotag::calib::{Target, TargetDetector};

/// Corner id and pixel.
type Points = Vec<(u32, [f64; 2])>;

fn main() -> anyhow::Result<()> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_default());
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json"))?)?;
    let target: Target = serde_json::from_value(truth["target"].clone())?;
    let mut detector = TargetDetector::new(&target)?;
    let (mut errors, mut raw_errors, mut expected) = (Vec::new(), Vec::new(), 0usize);
    for frame in truth["frames"].as_array().into_iter().flatten() {
        for side in ["left", "right"] {
            let image = stereotag::io::load_gray(&dir.join(frame[side].as_str().unwrap_or("")))?;
            let key = format!("{side}_px");
            let want: std::collections::HashMap<u64, [f64; 2]> = frame["corners"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|c| {
                    Some((
                        c["id"].as_u64()?,
                        serde_json::from_value(c[&key].clone()).ok()?,
                    ))
                })
                .collect();
            expected += want.len();
            let view = detector.detect(&image)?;
            let found: Points = view.corners.iter().map(|c| (c.id, c.px)).collect();
            let raw: Points = view
                .tags
                .iter()
                .flat_map(|t| (0..4).map(move |k| (t.id * 4 + k as u32, t.corners_px[k])))
                .collect();
            if std::env::var("DUMP").is_ok() {
                for (id, p) in &found {
                    if let Some(w) = want.get(&(*id as u64)) {
                        eprintln!(
                            "E {} {side} {id} {:.4} {:.4} {:.4} {:.1} {:.1}",
                            frame[side],
                            (p[0] - w[0]).hypot(p[1] - w[1]),
                            p[0] - w[0],
                            p[1] - w[1],
                            w[0],
                            w[1]
                        );
                    }
                }
            }
            for (out, list) in [(&mut errors, &found), (&mut raw_errors, &raw)] {
                for (id, p) in list {
                    if let Some(w) = want.get(&(*id as u64)) {
                        out.push((p[0] - w[0]).hypot(p[1] - w[1]));
                    }
                }
            }
        }
    }
    let stats = |e: &mut Vec<f64>| {
        e.sort_by(f64::total_cmp);
        let q = |f: f64| {
            e.get(((e.len() as f64 * f) as usize).min(e.len().saturating_sub(1)))
                .copied()
                .unwrap_or(f64::NAN)
        };
        format!(
            "{} corners, median {:.3} px, p95 {:.3} px, max {:.3} px",
            e.len(),
            q(0.5),
            q(0.95),
            e.last().copied().unwrap_or(f64::NAN)
        )
    };
    println!("expected {expected} corners in view");
    println!("detected: {}", stats(&mut errors));
    if !raw_errors.is_empty() {
        println!("before X-corner refinement: {}", stats(&mut raw_errors));
    }
    Ok(())
}
