use super::UsageError;
use std::path::PathBuf;
use stereotag::io;
use stereotag::tags::{CDetector, DetectorConfig, KorniaDetector, TagDetector, TagFamily};

/// Which detector.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Backend {
    /// kornia-apriltag (pure Rust).
    Kornia,
    /// The AprilRobotics C library.
    ApriltagC,
}

/// Arguments of `stereotag detect`.
#[derive(Debug, clap::Args)]
pub struct Detect {
    /// Images (any format the image crate reads; colour and 16-bit are converted to 8-bit grey).
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Stereo rig file: detect in a LEFT RIGHT pair and triangulate (not built yet).
    #[arg(long)]
    rig: Option<PathBuf>,
    /// Detector backend.
    #[arg(long, value_enum, default_value = "apriltag-c")]
    backend: Backend,
    /// Tag family: tag36h11, tag25h9, tag16h5 or tagStandard41h12 (repeat for several).
    #[arg(long, default_value = "tag36h11")]
    family: Vec<String>,
    /// Decimation before quad detection (1 = full resolution).
    #[arg(long, default_value_t = 2)]
    decimate: u32,
    /// Turn edge refinement off.
    #[arg(long)]
    no_refine_edges: bool,
    /// Sharpening of the decoded bits.
    #[arg(long, default_value_t = 0.25)]
    sharpening: f64,
}

impl Detect {
    pub fn run(&self) -> anyhow::Result<()> {
        if self.rig.is_some() {
            return Err(UsageError(
                "detect --rig (stereo triangulation) is not built yet; detect each image alone"
                    .into(),
            )
            .into());
        }
        let families = self
            .family
            .iter()
            .map(|f| {
                TagFamily::from_name(f).ok_or_else(|| {
                    UsageError(format!(
                        "--family {f}: expected tag36h11, tag25h9, tag16h5 or tagStandard41h12"
                    ))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        if self.decimate == 0 {
            return Err(UsageError("--decimate must be at least 1".into()).into());
        }
        let config = DetectorConfig {
            families,
            decimate: self.decimate,
            refine_edges: !self.no_refine_edges,
            sharpening: self.sharpening,
            ..DetectorConfig::default()
        };
        let mut detector: Box<dyn TagDetector> = match self.backend {
            Backend::Kornia => Box::new(KorniaDetector::new(config)?),
            Backend::ApriltagC => Box::new(CDetector::new(config)?),
        };
        // Read every image first, so a bad file fails before anything is printed.
        let images = self
            .images
            .iter()
            .map(|p| io::load_gray(p))
            .collect::<Result<Vec<_>, _>>()?;
        let mut all = Vec::new();
        for (path, image) in self.images.iter().zip(&images) {
            for d in detector.detect(image)? {
                let mut v = serde_json::to_value(&d)?;
                if self.images.len() > 1 {
                    v["image"] = serde_json::Value::String(path.display().to_string());
                }
                all.push(v);
            }
        }
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "detections": all }))?
        );
        Ok(())
    }
}
