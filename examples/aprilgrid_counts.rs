//! Diagnostic: AprilGrid tags found in an image at a decimation, with and without edge refinement.
//! Usage: cargo run --release --example aprilgrid_counts -- IMAGE...
use stereotag::visual::tags::{AprilGridDetector, TagDetector};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    for path in std::env::args().skip(1) {
        let img = stereotag::io::load_gray(std::path::Path::new(&path))?;
        for decimate in [1.0f32, 1.5, 2.0, 3.0] {
            for refine in [true, false] {
                let n = AprilGridDetector::new(decimate, refine)?
                    .detect(&img)?
                    .len();
                println!("{path}: decimate {decimate} refine {refine}: {n}");
            }
        }
    }
    Ok(())
}
