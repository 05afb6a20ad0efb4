use super::survey::Backend;
use std::path::PathBuf;
use stereotag::visual::tags::DetectorConfig;
use stereotag::workflow::detect::{detect, DetectOutput, DetectRequest};

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
    /// Tag family: tag36h11, tag25h9, tag16h5, tagStandard41h12, aprilgrid36h11 (alias
    /// tag36h11b2: Kalibr's AprilGrid tags, with their 2-bit border; searched at their own
    /// decimations), or an OpenCV ArUco dictionary by its name (DICT_4X4_50 ... DICT_7X7_1000)
    /// (repeat for several).
    #[arg(long, default_value = "tag36h11")]
    family: Vec<String>,
    /// Decimation before quad detection (1 = full resolution; default: the survey's, 1.5 with
    /// the C library and 1 with kornia).
    #[arg(long)]
    decimate: Option<f32>,
    /// Bit errors corrected (default: each family's safe number: 2 for tag36h11 and
    /// tagStandard41h12, 1 for tag25h9, 0 for tag16h5; for ArUco OpenCV's 60% of the
    /// dictionary's correctable bits, at most 2: 0 for 4x4, 1 for 5x5, 2 for 6x6 and 7x7).
    #[arg(long)]
    max_hamming: Option<usize>,
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
        let families = super::families(&self.family)?;
        let decimate = self
            .decimate
            .unwrap_or(stereotag::workflow::sightings::survey_decimate(
                self.backend.into(),
            ));
        super::check_decimate(decimate)?;
        let output = detect(&DetectRequest {
            images: &self.images,
            rig: self.rig.as_deref(),
            tag_size_m: self.tag_size_m,
            sigma_px: self.sigma_px,
            backend: self.backend.into(),
            config: DetectorConfig {
                families,
                decimate,
                max_hamming: self.max_hamming,
                refine_edges: !self.no_refine_edges,
                sharpening: self.sharpening,
                subpixel: !self.no_subpixel,
                min_contrast: self.min_contrast,
            },
        })?;
        let json = match output {
            DetectOutput::Stereo { tags, rejected } => {
                serde_json::json!({ "detections": tags, "rejected": rejected })
            }
            DetectOutput::Images(found) => {
                let several = found.len() > 1;
                let mut all = Vec::new();
                for (path, detections) in found {
                    for d in detections {
                        let mut v = serde_json::to_value(&d)?;
                        if several {
                            v["image"] = serde_json::Value::String(path.display().to_string());
                        }
                        all.push(v);
                    }
                }
                serde_json::json!({ "detections": all })
            }
        };
        super::print_out(&(serde_json::to_string_pretty(&json)? + "\n"))?;
        Ok(())
    }
}
