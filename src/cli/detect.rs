use super::UsageError;
use std::path::PathBuf;
use stereotag::io;
use stereotag::visual::stereo::{detect_pair, triangulate_tags, StereoConfig};
use stereotag::visual::tags::{CDetector, DetectorConfig, KorniaDetector, TagDetector, TagFamily};

/// Which detector.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Backend {
    /// kornia-apriltag's segmentation and tag families with our port of the C library's quad
    /// fit and decoding (pure Rust).
    Kornia,
    /// kornia-apriltag's own pipeline end to end (for comparison: it finds fewer tags).
    KorniaLibrary,
    /// The AprilRobotics C library.
    ApriltagC,
}

/// Arguments of `stereotag detect`.
#[derive(Debug, clap::Args)]
pub struct Detect {
    /// Images (any format the image crate reads; colour and 16-bit are converted to 8-bit grey).
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Stereo rig file (Kalibr camchain): the images are a LEFT RIGHT pair; tags are triangulated.
    #[arg(long)]
    rig: Option<PathBuf>,
    /// Tag edge length in metres, to reject pairs whose triangulated size disagrees.
    #[arg(long)]
    tag_size_m: Option<f64>,
    /// Corner noise assumed for the covariance, pixels.
    #[arg(long, default_value_t = 0.3)]
    sigma_px: f64,
    /// Detector backend.
    #[arg(long, value_enum, default_value = "apriltag-c")]
    backend: Backend,
    /// Tag family: tag36h11, tag25h9, tag16h5 or tagStandard41h12 (repeat for several).
    #[arg(long, default_value = "tag36h11")]
    family: Vec<String>,
    /// Decimation before quad detection (1 = full resolution).
    #[arg(long, default_value_t = 2.0)]
    decimate: f32,
    /// Turn edge refinement off.
    #[arg(long)]
    no_refine_edges: bool,
    /// Keep the backend's own corners (no sub-pixel edge fit of ours on top).
    #[arg(long)]
    no_subpixel: bool,
    /// Sharpening of the decoded bits.
    #[arg(long, default_value_t = 0.25)]
    sharpening: f64,
    /// Smallest white-to-black grey difference around a 4x4 tile for it to be searched (both
    /// backends; 5 is both libraries' default). 30 makes detection 5-10x faster on indoor
    /// images; lower it for dim or low-contrast tags.
    #[arg(long, default_value_t = 5)]
    min_contrast: u8,
}

impl Detect {
    pub fn run(&self) -> anyhow::Result<()> {
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
        super::check_decimate(self.decimate)?;
        let config = DetectorConfig {
            families,
            decimate: self.decimate,
            refine_edges: !self.no_refine_edges,
            sharpening: self.sharpening,
            subpixel: !self.no_subpixel,
            min_contrast: self.min_contrast,
            ..DetectorConfig::default()
        };
        let mut detector: Box<dyn TagDetector> = match self.backend {
            Backend::Kornia => Box::new(KorniaDetector::new(config)?),
            Backend::KorniaLibrary => Box::new(KorniaDetector::library(config)?),
            Backend::ApriltagC => Box::new(CDetector::new(config)?),
        };
        // Read every image first, so a bad file fails before anything is printed.
        let images = self
            .images
            .iter()
            .map(|p| io::load_gray(p))
            .collect::<Result<Vec<_>, _>>()?;
        if let Some(rig_path) = &self.rig {
            return self.run_stereo(rig_path, &images, detector.as_mut());
        }
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

    fn run_stereo(
        &self,
        rig_path: &std::path::Path,
        images: &[image::GrayImage],
        detector: &mut dyn TagDetector,
    ) -> anyhow::Result<()> {
        let [left, right] = images else {
            return Err(UsageError(format!(
                "--rig needs exactly two images, LEFT and RIGHT; got {}",
                images.len()
            ))
            .into());
        };
        let rig = io::load_rig(rig_path)?;
        let rig_name = format!("the rig {}", rig_path.display());
        check_image_size(left, &rig.left, &self.images[0], &rig_name)?;
        check_image_size(right, &rig.right, &self.images[1], &rig_name)?;
        let rect = rig.rectify();
        let config = StereoConfig {
            sigma_px: self.sigma_px,
            ..StereoConfig::default()
        };
        let (in_left, in_right) = detect_pair(detector, left, right)?;
        let (tags, rejected) =
            triangulate_tags(&rig, &rect, &in_left, &in_right, self.tag_size_m, &config);
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({ "detections": tags, "rejected": rejected })
            )?
        );
        Ok(())
    }
}

/// An error naming the image when its size is not the camera's (`rig` says which rig, for the
/// message).
pub(crate) fn check_image_size(
    img: &image::GrayImage,
    cam: &stereotag::camera::Camera,
    path: &std::path::Path,
    rig: &str,
) -> Result<(), UsageError> {
    if img.dimensions() == (cam.width, cam.height) {
        return Ok(());
    }
    Err(UsageError(format!(
        "{}: image is {}x{} but {rig} says {}x{}",
        path.display(),
        img.width(),
        img.height(),
        cam.width,
        cam.height
    )))
}
