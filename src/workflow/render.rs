//! Render what the robot's cameras see: one stereo pair at a pose, a sequence along a pose CSV,
//! or a calibration sequence of a target in front of the rig, each with its ground truth.

use super::Result;
use crate::geometry::Pose2;
use crate::io::{self, OutputDir};
use crate::progress::Progress;
use crate::render::board::{calibration_poses, Board};
use crate::render::{RenderConfig, Renderer};
use std::path::Path;

/// Samples per pixel of scenes (issue 3: at least 4).
pub const SCENE_SAMPLES: usize = 4;
/// Samples per pixel of calibration views: a calibration is judged at hundredths of a pixel,
/// where four jittered samples leave edge noise no real sensor has.
pub const CALIBRATION_SAMPLES: usize = 16;

/// How to render.
#[derive(Debug, Clone)]
pub struct RenderRequest<'a> {
    /// The stereo rig file (the default rig is built in, when its file is not there).
    pub rig: &'a Path,
    /// The output directory.
    pub out: &'a Path,
    /// Samples per pixel, a square number (default: [`SCENE_SAMPLES`], or
    /// [`CALIBRATION_SAMPLES`] for calibration views).
    pub samples: Option<usize>,
    /// Trace every sample of every pixel (by default a pixel no edge crosses gets one ray).
    pub every_sample: bool,
    /// Motion blur: the robot's motion during the exposure, in its own frame.
    pub motion: Option<Pose2>,
    /// Sensor noise seed (frame `k` of a sequence: `seed + k`).
    pub seed: u64,
    /// Replace the output directory if it exists.
    pub force: bool,
}

impl RenderRequest<'_> {
    /// Render settings with the noise seed and the motion.
    fn config(&self, seed: u64) -> RenderConfig {
        RenderConfig {
            seed,
            motion: self.motion,
            ..RenderConfig::default()
        }
    }

    /// The renderer for `rig` with the samples asked (`default` when none).
    fn renderer(&self, rig: &crate::camera::StereoRig, default: usize) -> Renderer {
        let n = self.samples.unwrap_or(default);
        let renderer = Renderer::with_samples(rig, (n as f64).sqrt().round() as usize);
        if self.every_sample {
            renderer.with_every_sample()
        } else {
            renderer
        }
    }
}

/// One pair rendered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairRendered {
    /// Tags in view.
    pub tags: usize,
    /// Rendering time, seconds.
    pub secs: f64,
}

/// Renders the pair a robot at `pose` sees in `world`: `left.png`, `right.png` and `truth.json`
/// (every tag in view, corners in both images and in the world).
pub fn render_pose(request: &RenderRequest<'_>, world: &Path, pose: Pose2) -> Result<PairRendered> {
    let loaded = io::load_world(world)?;
    let rig = io::load_rig(request.rig)?;
    let config = request.config(request.seed);
    let start = std::time::Instant::now();
    let pair = request
        .renderer(&rig, SCENE_SAMPLES)
        .render(&loaded.world, pose, &config)?;
    let secs = start.elapsed().as_secs_f64();
    let dir = OutputDir::create(request.out, request.force)?;
    io::save_camera_png(&dir.path("left.png"), &pair.left)?;
    io::save_camera_png(&dir.path("right.png"), &pair.right)?;
    let truth = serde_json::json!({
        "world_from_robot": [pose.x, pose.y, pose.theta],
        "tags": pair.tags,
    });
    io::save_json(&dir.path("truth.json"), &truth)?;
    dir.commit()?;
    Ok(PairRendered {
        tags: pair.tags.len(),
        secs,
    })
}

/// Renders a pair at every pose of a pose CSV (`t_s,x_m,y_m,theta_rad`): `left/NNNNNN.png`,
/// `right/NNNNNN.png` and one `truth.json` listing every frame; returns the number of pairs.
pub fn render_sequence(
    request: &RenderRequest<'_>,
    world: &Path,
    poses: &Path,
    progress: &dyn Progress,
) -> Result<usize> {
    let poses = io::read_poses(poses)?;
    let loaded = io::load_world(world)?;
    let rig = io::load_rig(request.rig)?;
    let renderer = request.renderer(&rig, SCENE_SAMPLES);
    let dir = sequence_dir(request)?;
    progress.start("render", poses.len() as u64);
    let mut frames = Vec::with_capacity(poses.len());
    for (k, p) in poses.iter().enumerate() {
        let config = request.config(request.seed.wrapping_add(k as u64));
        let pair = renderer.render(&loaded.world, p.pose, &config)?;
        let (left, right) = save_pair(&dir, k, &pair.left, &pair.right)?;
        frames.push(serde_json::json!({
            "t_s": p.t_s,
            "world_from_robot": [p.pose.x, p.pose.y, p.pose.theta],
            "left": left,
            "right": right,
            "tags": pair.tags,
        }));
        progress.advance(1);
    }
    progress.finish();
    io::save_json(
        &dir.path("truth.json"),
        &serde_json::json!({ "frames": frames }),
    )?;
    dir.commit()?;
    Ok(poses.len())
}

/// Renders `n` views of a calibration target in front of the rig (poses spread over the image
/// and tilted): `left/NNNNNN.png`, `right/NNNNNN.png`, `rig.yaml` (the true rig) and
/// `truth.json` (board pose and every corner's true pixel in both images, per view); returns the
/// number of views (fewer than `n` when the board does not fit both images often enough).
pub fn render_calibration_sequence(
    request: &RenderRequest<'_>,
    n: usize,
    target_path: &Path,
    progress: &dyn Progress,
) -> Result<usize> {
    let target = io::load_target(target_path)?;
    let rig = io::load_rig(request.rig)?;
    let board = Board::of_target(&target)?;
    let poses = calibration_poses(&rig, &board, n, request.seed);
    if poses.len() < n {
        tracing::warn!(
            "the whole board fits both images in only {} of {n} views tried: a smaller board or a wider lens helps",
            poses.len()
        );
    }
    let renderer = request.renderer(&rig, CALIBRATION_SAMPLES);
    let dir = sequence_dir(request)?;
    io::save_rig(&dir.path("rig.yaml"), &rig)?;
    progress.start("render", poses.len() as u64);
    let mut frames = Vec::with_capacity(poses.len());
    for (k, pose) in poses.iter().enumerate() {
        let config = RenderConfig {
            seed: request.seed.wrapping_add(k as u64),
            ..RenderConfig::default()
        };
        let view = renderer.render_board(&board, pose, &config);
        let (left, right) = save_pair(&dir, k, &view.left, &view.right)?;
        let q = pose.rotation.coords;
        let t = pose.translation.vector;
        frames.push(serde_json::json!({
            "left": left,
            "right": right,
            "left_from_board": {"t_m": [t.x, t.y, t.z], "q_xyzw": [q.x, q.y, q.z, q.w]},
            "corners": view.corners,
        }));
        progress.advance(1);
    }
    progress.finish();
    io::save_json(
        &dir.path("truth.json"),
        &serde_json::json!({ "target": target, "frames": frames }),
    )?;
    dir.commit()?;
    Ok(poses.len())
}

/// A new output directory with `left/` and `right/`.
fn sequence_dir(request: &RenderRequest<'_>) -> Result<OutputDir> {
    let dir = OutputDir::create(request.out, request.force)?;
    io::create_dir(&dir.path("left"))?;
    io::create_dir(&dir.path("right"))?;
    Ok(dir)
}

/// Writes the `k`th pair of a sequence as `left/NNNNNN.png` and `right/NNNNNN.png`; returns the
/// names.
fn save_pair(
    dir: &OutputDir,
    k: usize,
    left: &image::GrayImage,
    right: &image::GrayImage,
) -> Result<(String, String)> {
    let names = (format!("left/{k:06}.png"), format!("right/{k:06}.png"));
    for (img, name) in [(left, &names.0), (right, &names.1)] {
        io::save_camera_png(&dir.path(name), img)?;
    }
    Ok(names)
}
