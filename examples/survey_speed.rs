//! Diagnostic: where a survey's detection time goes on a run: decoding the PNGs, detecting.
//! Usage: cargo run --release --example survey_speed -- RUN_DIR [DECIMATE]
use std::time::Instant;
use stereotag::io;
use stereotag::stereo::detect_pair;
use stereotag::tags::{CDetector, DetectorConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).ok_or("usage: RUN_DIR")?);
    let decimate: u32 = std::env::args().nth(2).map_or(Ok(1), |s| s.parse())?;
    let run = io::load_run(&dir)?;
    let t = Instant::now();
    let mut pairs = Vec::new();
    for e in &run.stereo {
        pairs.push((
            io::load_gray(&dir.join(&e.left))?,
            io::load_gray(&dir.join(&e.right))?,
        ));
    }
    let decode = t.elapsed().as_secs_f64();
    let mut det = CDetector::new(DetectorConfig {
        decimate,
        ..DetectorConfig::default()
    })?;
    let t = Instant::now();
    let mut found = 0;
    for (l, r) in &pairs {
        let (a, _) = detect_pair(&mut det, l, r)?;
        found += a.len();
    }
    let detect = t.elapsed().as_secs_f64();
    println!("{} pairs: decode {decode:.2} s, detect (decimate {decimate}) {detect:.2} s, {found} left detections (one thread)", pairs.len());
    Ok(())
}
