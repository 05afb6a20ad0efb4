//! Diagnostic: where a survey's detection time goes on a run: decoding the PNGs, detecting.
//! Usage: cargo run --release --example survey_speed -- RUN_DIR [DECIMATE] [MIN_CONTRAST]
use std::time::Instant;
use stereotag::io;
use stereotag::visual::stereo::detect_pair;
use stereotag::visual::tags::{CDetector, DetectorConfig, TagDetector};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).ok_or("usage: RUN_DIR")?);
    let decimate: f32 = std::env::args().nth(2).map_or(Ok(1.0), |s| s.parse())?;
    let min_contrast: u8 = std::env::args().nth(3).map_or(Ok(5), |s| s.parse())?;
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
        min_contrast,
        ..DetectorConfig::default()
    })?;
    let t = Instant::now();
    let (mut found, mut found_right) = (0, 0);
    for (l, r) in &pairs {
        let (a, b) = detect_pair(&mut det, l, r)?;
        found += a.len();
        found_right += b.len();
    }
    let detect = t.elapsed().as_secs_f64();
    println!("{} pairs: decode {decode:.2} s, detect (decimate {decimate}, min contrast {min_contrast}) {detect:.2} s, {found} left and {found_right} right detections (one thread)", pairs.len());
    let t = Instant::now();
    let mut with_tags = 0;
    for (l, _) in &pairs {
        with_tags += usize::from(!det.detect(l)?.is_empty());
    }
    let left_only = t.elapsed().as_secs_f64();
    println!(
        "left images alone: {left_only:.2} s; {with_tags} of {} pairs show a tag",
        pairs.len()
    );
    Ok(())
}
