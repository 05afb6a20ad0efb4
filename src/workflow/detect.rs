//! Detect tags in images; with a rig, triangulate the tags of a stereo pair.

use super::{Error, Result};
use crate::io;
use crate::visual::stereo::{detect_pair, triangulate_tags, Rejection, StereoConfig, StereoTag};
use crate::visual::tags::{Backend, DetectorConfig, TagDetection};
use std::path::{Path, PathBuf};

/// What to detect in.
#[derive(Debug, Clone)]
pub struct DetectRequest<'a> {
    /// The images (any format the image crate reads; colour and 16-bit become 8-bit grey).
    pub images: &'a [PathBuf],
    /// A stereo rig: the images are a LEFT RIGHT pair and the tags are triangulated.
    pub rig: Option<&'a Path>,
    /// The tags' edge length, to reject pairs whose triangulated size disagrees, metres.
    pub tag_size_m: Option<f64>,
    /// Corner noise assumed for the covariance, pixels.
    pub sigma_px: f64,
    /// The detector.
    pub backend: Backend,
    /// Its settings.
    pub config: DetectorConfig,
}

/// What was found.
#[derive(Debug, Clone)]
pub enum DetectOutput {
    /// Each image with its detections, in the order given.
    Images(Vec<(PathBuf, Vec<TagDetection>)>),
    /// The tags of a stereo pair, triangulated, and the left detections without a partner.
    Stereo {
        /// Tags found in both images.
        tags: Vec<StereoTag>,
        /// Why the others were not triangulated.
        rejected: Vec<Rejection>,
    },
}

/// Detects the tags of every image, or triangulates a pair with a rig. Every image is read
/// before anything is detected, so a bad file fails first.
pub fn detect(request: &DetectRequest<'_>) -> Result<DetectOutput> {
    let mut detector = request.backend.detector(request.config.clone())?;
    let images = request
        .images
        .iter()
        .map(|p| io::load_gray(p))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    if let Some(rig_path) = request.rig {
        let [left, right] = &images[..] else {
            return Err(Error::Request(format!(
                "--rig needs exactly two images, LEFT and RIGHT; got {}",
                images.len()
            )));
        };
        let rig = io::load_rig(rig_path)?;
        let rig_name = format!("the rig {}", rig_path.display());
        io::check_image_size(left, &rig.left, &request.images[0], &rig_name)?;
        io::check_image_size(right, &rig.right, &request.images[1], &rig_name)?;
        let rect = rig.rectify();
        let config = StereoConfig {
            sigma_px: request.sigma_px,
            ..StereoConfig::default()
        };
        let (in_left, in_right) = detect_pair(detector.as_mut(), left, right)?;
        let (tags, rejected) = triangulate_tags(
            &rig,
            &rect,
            &in_left,
            &in_right,
            request.tag_size_m,
            &config,
        );
        return Ok(DetectOutput::Stereo { tags, rejected });
    }
    let mut found = Vec::with_capacity(images.len());
    for (path, image) in request.images.iter().zip(&images) {
        found.push((path.clone(), detector.detect(image)?));
    }
    Ok(DetectOutput::Images(found))
}
