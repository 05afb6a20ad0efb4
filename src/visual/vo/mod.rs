//! Visual odometry: the robot's planar motion between two stereo frames, from the texture of the
//! home the cameras see.
//!
//! Wheel odometry measures distance well and heading badly: a few millimetres of random wheel
//! error per metre turn the heading by about half a degree per √m, and only a landmark can undo
//! that. The cameras see walls, floor and furniture all the time, so the image motion between two
//! frames measures the turn directly. For frames `a` (a stereo pair) and `b` (its left image):
//!
//! 1. corners (Shi-Tomasi's response, the strongest of each cell of a grid) in the left image of
//!    `a`, found at pyramid level 1 where the sensor noise is smoothed away (our own: kornia's
//!    `gftt_response` at full resolution took longer than the whole motion);
//! 2. each matched along its epipolar line in the right image of `a` by normalised
//!    cross-correlation (a quarter-resolution search, then quarter-pixel steps at full resolution)
//!    and triangulated;
//! 3. each looked for in the left image of `b` around where the wheel odometry puts it (a
//!    half-resolution search, then a full-resolution one with a parabola through the peak);
//! 4. the planar motion `robot_a_from_robot_b` that best reprojects the points into `b`
//!    (Gauss-Newton from the wheel odometry, Huber weights, points off by more than three sigma
//!    left out), with its covariance from the reprojection residuals.
//!
//! Walls and floors here carry a soft, cloudy texture (painted plaster, carpet): kornia-imgproc's
//! pyramidal Lucas-Kanade tracker, tried first, wandered off on it (median 150 px from the right place on the
//! rendered office), so points are matched by correlation, which needs a peak that stands out.

mod matching;
mod pyramid;
mod solve;

use matching::*;
pub use pyramid::VoImage;
use pyramid::*;
use solve::*;

use crate::camera::StereoRig;
use crate::geometry::Pose2;
use nalgebra::{Matrix3, Point2, Point3, Vector3};

/// Settings of the visual odometry.
#[derive(Debug, Clone, PartialEq)]
pub struct VoConfig {
    /// Grid of cells the corners are spread over (columns, rows).
    pub grid: (usize, usize),
    /// Weakest corner kept, as a share of the strongest in the image (texture corners are a
    /// thousand times weaker than a tag's).
    pub min_response_share: f32,
    /// Nearest and farthest point matched between the cameras, metres.
    pub depth_range_m: (f64, f64),
    /// How far from where the wheel odometry puts it a point is looked for in the next frame,
    /// pixels (a degree of heading error is 8 px with the default rig).
    pub search_radius_px: f64,
    /// Least normalised cross-correlation of a match.
    pub min_correlation: f32,
    /// Least margin of a match over the best correlation elsewhere.
    pub min_margin: f32,
    /// Largest change of a point's apparent size between the frames (the ratio of its depths,
    /// less one) for it to be matched (ours: 0.4); its patch is resampled to the size it will
    /// have before it is looked for.
    pub max_scale_change: f64,
    /// Points in agreement needed for a motion, at least.
    pub min_inliers: usize,
    /// Huber width of the reprojection residuals, pixels.
    pub huber_px: f64,
    /// Floor of the residual sigma behind the covariance, pixels.
    pub sigma_floor_px: f64,
    /// Factor on the variance from the reprojection residuals: the matches of one frame share
    /// errors the residuals do not show (ours: 1.8, so that the mean squared turn error over its
    /// variance, `visual.turn_nees` in a survey's report, is 0.7-1.2 on the office and museum
    /// sample runs and on a building-scale run along a real path).
    pub variance_scale: f64,
    /// Least travel and turn between two frames whose motion is measured (ours: 0.25 m, 15
    /// degrees): closer frames add their errors without adding much motion.
    pub min_spacing: (f64, f64),
    /// Most travel and turn between two frames whose motion is measured (ours: 1 m, 45 degrees:
    /// beyond that too little of one frame is seen in the other).
    pub max_spacing: (f64, f64),
    /// Sigma of the wheel odometry's forward travel between two frames, metres: a floor plus a
    /// share of the distance (ours: 2 mm + 1%).
    pub forward_sigma: (f64, f64),
    /// Sigma of the sideways slip between two frames, metres: a floor plus a share of the
    /// distance (ours: 0.5 mm + 0.2%, the simulated wheels' random error over a step). A
    /// differential-drive robot does not move sideways: between two frames its path's chord
    /// points off its first heading by a share of the turn that the wheels' path gives (half on
    /// an arc, all of it when it turned on the spot and then drove), whatever the turn's size.
    /// The images alone tell a turn from a sideways step poorly when most of what they see lies
    /// at one depth (0.24 degrees RMS turn error on a rendered office run without this, 0.03
    /// with it); the path's shape tells them apart without the wheels' turn, which the images'
    /// is to correct.
    pub slip_sigma: (f64, f64),
}

impl Default for VoConfig {
    fn default() -> Self {
        Self {
            grid: (12, 9),
            min_response_share: 1e-4,
            depth_range_m: (0.3, 20.0),
            search_radius_px: 24.0,
            min_correlation: 0.8,
            min_margin: 0.05,
            max_scale_change: 0.4,
            min_inliers: 12,
            huber_px: 1.0,
            sigma_floor_px: 0.05,
            variance_scale: 1.8,
            min_spacing: (0.25, 15f64.to_radians()),
            max_spacing: (1.0, 45f64.to_radians()),
            forward_sigma: (0.002, 0.01),
            slip_sigma: (0.0005, 0.002),
        }
    }
}

/// Why two frames gave no motion.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VoError {
    /// Too few points survived.
    #[error("only {found} points agree (at least {needed} needed)")]
    TooFewPoints {
        /// How many.
        found: usize,
        /// How many needed.
        needed: usize,
    },
    /// An image is not of the rig's size.
    #[error("image is {found:?} pixels, the rig's camera {expected:?}")]
    WrongSize {
        /// Found (width, height).
        found: (usize, usize),
        /// Expected (width, height).
        expected: (usize, usize),
    },
}

/// The motion between two frames as the cameras saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct VisualMotion {
    /// `robot_a_from_robot_b`.
    pub motion: Pose2,
    /// Covariance of `(x, y, theta)`.
    pub covariance: Matrix3<f64>,
    /// Points that agreed.
    pub inliers: usize,
    /// Points found in both frames.
    pub tracked: usize,
    /// RMS reprojection residual of the inliers, pixels.
    pub rms_px: f64,
}

/// A turn of the robot the cameras measured between two frames: what the fusion stage takes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct VisualTurn {
    /// Time of the first frame, seconds.
    pub from_t_s: f64,
    /// Time of the second frame, seconds.
    pub to_t_s: f64,
    /// The turn between them, radians (counter-clockwise positive).
    pub turn_rad: f64,
    /// Its sigma, radians.
    pub sigma_rad: f64,
}

impl VisualMotion {
    /// The turn of this motion between frames taken at `from_t_s` and `to_t_s`.
    pub fn turn(&self, from_t_s: f64, to_t_s: f64) -> VisualTurn {
        VisualTurn {
            from_t_s,
            to_t_s,
            turn_rad: self.motion.theta,
            sigma_rad: self.covariance[(2, 2)].max(0.0).sqrt(),
        }
    }
}

/// The pairs of frames (indices into `times`, time order) whose motion is measured: from each
/// chosen frame to the first one at least [`VoConfig::min_spacing`] away by the odometry (or the
/// last frame before it, when that is farther than [`VoConfig::max_spacing`]); a pair still
/// farther apart than that is left out, and the chain starts again from its second frame.
pub fn frame_pairs(
    times: &[f64],
    odometry: &[crate::geometry::StampedPose],
    config: &VoConfig,
) -> Vec<(usize, usize)> {
    let pose = |t: f64| crate::geometry::pose_at(odometry, t);
    let apart = |a: usize, b: usize, (m, rad): (f64, f64)| match (pose(times[a]), pose(times[b])) {
        (Some(pa), Some(pb)) => {
            let d = pa.between(&pb);
            d.x.hypot(d.y) >= m || d.theta.abs() >= rad
        }
        _ => true,
    };
    let mut order: Vec<usize> = (0..times.len()).collect();
    order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
    let mut pairs = Vec::new();
    let Some(&first) = order.first() else {
        return pairs;
    };
    let mut from = first;
    let mut previous = first;
    for &k in &order[1..] {
        if apart(from, k, config.min_spacing) {
            // Step back to the frame before when this one is already too far.
            let to = if previous != from && apart(from, k, config.max_spacing) {
                previous
            } else {
                k
            };
            if !apart(from, to, config.max_spacing) {
                pairs.push((from, to));
            }
            from = to;
            if to == previous && previous != k && apart(from, k, config.min_spacing) {
                if !apart(from, k, config.max_spacing) {
                    pairs.push((from, k));
                }
                from = k;
            }
        }
        previous = k;
    }
    pairs
}

/// The planar motion `robot_a_from_robot_b` between frame `a` (its stereo pair) and frame `b`
/// (its left image), starting from the wheel odometry's `prior`.
pub fn relative_motion(
    rig: &StereoRig,
    (a_left, a_right): (&VoImage, &VoImage),
    b_left: &VoImage,
    prior: &Pose2,
    config: &VoConfig,
) -> Result<VisualMotion, VoError> {
    for (image, camera) in [
        (a_left, &rig.left),
        (a_right, &rig.right),
        (b_left, &rig.left),
    ] {
        let expected = (camera.width as usize, camera.height as usize);
        if image.size() != expected {
            return Err(VoError::WrongSize {
                found: image.size(),
                expected,
            });
        }
    }
    let points = stereo_points(rig, a_left, a_right, config);
    let b_from_a = camera_motion(rig, prior);
    let observations: Vec<(Vector3<f64>, Point2<f64>)> = points
        .iter()
        .filter_map(|p| {
            let moved = b_from_a * Point3::from(p.in_left);
            // A patch the motion magnifies or shrinks much no longer matches its image.
            let scale = p.in_left.z / moved.z.max(1e-6);
            if (scale - 1.0).abs() > config.max_scale_change {
                return None;
            }
            let guess = rig.left.project(&moved.coords)?;
            let found = track(a_left, b_left, p.px, guess, scale, config)?;
            Some((p.in_left, found))
        })
        .collect();
    let mut motion = solve_planar(rig, &observations, prior, config)?;
    motion.tracked = observations.len();
    Ok(motion)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::StampedPose;
    use crate::render::{RenderConfig, Renderer};
    use std::path::Path;

    /// The corner response as first written, pixel by pixel.
    fn plain_corner_response(level: &Level) -> Vec<f32> {
        let (w, h) = (level.image.w, level.image.h);
        let s = level.image.data.as_slice();
        let mut gxx = vec![0.0f32; w * h];
        let mut gyy = vec![0.0f32; w * h];
        let mut gxy = vec![0.0f32; w * h];
        for y in 1..h.saturating_sub(1) {
            for x in 1..w - 1 {
                let at = |dx: usize, dy: usize| s[(y + dy - 1) * w + x + dx - 1];
                let gx =
                    (at(2, 0) + 2.0 * at(2, 1) + at(2, 2)) - (at(0, 0) + 2.0 * at(0, 1) + at(0, 2));
                let gy =
                    (at(0, 2) + 2.0 * at(1, 2) + at(2, 2)) - (at(0, 0) + 2.0 * at(1, 0) + at(2, 0));
                let i = y * w + x;
                gxx[i] = gx * gx;
                gyy[i] = gy * gy;
                gxy[i] = gx * gy;
            }
        }
        // 5 x 5 box sums: along rows, then along columns.
        let box5 = |v: &[f32]| -> Vec<f32> {
            let mut rows = vec![0.0f32; w * h];
            for y in 0..h {
                let r = &v[y * w..(y + 1) * w];
                for x in 2..w.saturating_sub(2) {
                    rows[y * w + x] = r[x - 2] + r[x - 1] + r[x] + r[x + 1] + r[x + 2];
                }
            }
            let mut out = vec![0.0f32; w * h];
            for y in 2..h.saturating_sub(2) {
                for x in 0..w {
                    out[y * w + x] = (y - 2..=y + 2).map(|yy| rows[yy * w + x]).sum();
                }
            }
            out
        };
        let (a, b, c) = (box5(&gxx), box5(&gyy), box5(&gxy));
        a.iter()
            .zip(&b)
            .zip(&c)
            .map(|((a, b), c)| 0.5 * (a + b) - (0.25 * (a - b) * (a - b) + c * c).sqrt())
            .collect()
    }

    /// The left picture of the office from (2, 2) m facing 40 degrees, prepared.
    fn office_view() -> VoImage {
        let (world, rig) = office_and_rig();
        let pair = Renderer::new(&rig)
            .render(&world, Pose2::new(2.0, 2.0, 0.7), &RenderConfig::default())
            .unwrap();
        VoImage::new(&pair.left)
    }

    /// Correlations worked a row at a time are the position-by-position ones, whichever way the
    /// positions run, on every level, with and without integral images, and at the borders.
    #[test]
    fn correlations_a_row_at_a_time_are_the_single_ones() {
        let image = office_view();
        for (level, half) in [
            (&image.full, 7),
            (&image.full, 5),
            (&image.half, 4),
            (&image.quarter, 3),
        ] {
            let (w, h) = (level.width(), level.height());
            let reference = patch_at(level, w / 2, h / 2, half).unwrap();
            let forward: Vec<(i64, i64)> = (0..w).map(|x| (x, h / 3)).collect();
            let backward: Vec<(i64, i64)> =
                forward.iter().rev().map(|&(x, _)| (x, h / 2)).collect();
            let grid = square((w / 3, h / 2), 6);
            let corner = square((half, half), 3);
            let scattered = vec![(5, 5), (40, 9), (39, 9), (38, 10), (w - 1, h - 1), (12, 12)];
            for positions in [forward, backward, grid, corner, scattered] {
                let many = level.correlate_at(&reference, &positions, half);
                assert_eq!(many.len(), positions.len());
                for (&(x, y), s) in positions.iter().zip(many) {
                    match level.correlate(&reference, x, y, half) {
                        // The same products, summed in another order in f32.
                        Some(one) => assert!((one - s).abs() < 1e-4, "({x}, {y}): {one} vs {s}"),
                        None => assert_eq!(s, f32::NEG_INFINITY, "({x}, {y})"),
                    }
                }
            }
        }
    }

    #[test]
    fn the_corner_response_is_the_plain_one_exactly() {
        let image = office_view();
        for level in [&image.half, &image.quarter] {
            assert_eq!(corner_response(level), plain_corner_response(level));
        }
    }

    fn office_and_rig() -> (crate::world::World, StereoRig) {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let world = crate::io::load_world(&root.join("samples/office/world.yaml"))
            .unwrap()
            .world;
        let rig = crate::io::load_rig(&root.join("calibration/rigs/default.yaml")).unwrap();
        (world, rig)
    }

    /// Rendered office views, turns on the spot (the start's look-around), steps forward and
    /// back and curves forward and backward, each measured from a wheel prior 0.5 degrees off
    /// in turn, 1 cm in travel and 1 mm sideways (about the slip sigma over such a step; a 5 mm
    /// slip, a 4.5-sigma one, moves the diagonal step's turn by 0.06 degrees, 4.0 sigmas): RMS
    /// turn error under 0.1 degrees (the wheels' over such steps: 0.2-0.7 degrees), none over
    /// 0.25, each within four of its sigmas (2.2 at most here).
    #[test]
    fn the_turn_between_two_rendered_views_is_measured() {
        let (world, rig) = office_and_rig();
        let renderer = Renderer::new(&rig);
        let render = |pose: Pose2, seed: u64| {
            let pair = renderer
                .render(
                    &world,
                    pose,
                    &RenderConfig {
                        seed,
                        ..RenderConfig::default()
                    },
                )
                .unwrap();
            (VoImage::new(&pair.left), VoImage::new(&pair.right))
        };
        let config = VoConfig::default();
        let mut squares = 0.0;
        let cases = [
            (Pose2::new(2.5, 2.5, 1.2), Pose2::new(2.5, 2.5, 1.55)),
            (Pose2::new(2.5, 2.5, -2.0), Pose2::new(2.5, 2.5, -2.3)),
            (Pose2::new(1.5, 2.0, 0.8), Pose2::new(1.7, 2.2, 0.9)),
            (Pose2::new(1.0, 1.0, 0.0), Pose2::new(1.3, 1.0, 0.0)),
            (Pose2::new(5.0, 6.0, -1.6), Pose2::new(5.0, 5.7, -1.5)),
            (Pose2::new(0.6, 4.0, 1.57), Pose2::new(0.6, 4.3, 1.8)),
            // Backing up 0.35 m on an arc while turning 17 degrees (a real robot's path does).
            (Pose2::new(3.0, 3.0, 0.5), {
                let (turn, travel) = (-0.3f64, -0.35);
                let curvature = turn / travel;
                Pose2::new(3.0, 3.0, 0.5).compose(&Pose2::new(
                    turn.sin() / curvature,
                    (1.0 - turn.cos()) / curvature,
                    turn,
                ))
            }),
            (
                Pose2::new(2.0, 5.0, -0.7),
                Pose2::new(2.0, 5.0, -0.7).compose(&Pose2::new(-0.3, 0.0, 0.0)),
            ),
        ];
        for (k, (a, b)) in cases.iter().enumerate() {
            let truth = a.between(b);
            let prior = Pose2::new(
                truth.x + 0.01,
                truth.y - 0.001,
                truth.theta + 0.5f64.to_radians(),
            );
            let (al, ar) = render(*a, 2 * k as u64 + 1);
            let (bl, _) = render(*b, 2 * k as u64 + 2);
            let m = relative_motion(&rig, (&al, &ar), &bl, &prior, &config).unwrap();
            let error = (m.motion.theta - truth.theta).to_degrees();
            let sigma = m.covariance[(2, 2)].sqrt().to_degrees();
            assert!(
                error.abs() < 0.25 && error.abs() < 4.0 * sigma,
                "{a:?} -> {b:?}: turn off by {error} degrees (sigma {sigma}, {} inliers)",
                m.inliers
            );
            squares += error * error;
        }
        let rms = (squares / cases.len() as f64).sqrt();
        assert!(rms < 0.1, "RMS turn error {rms} degrees");
    }

    /// Images of another size than the rig's are refused by name, not matched.
    #[test]
    fn images_of_the_wrong_size_are_refused() {
        let (_, rig) = office_and_rig();
        let small = VoImage::new(&image::GrayImage::new(320, 240));
        let err = relative_motion(
            &rig,
            (&small, &small),
            &small,
            &Pose2::default(),
            &VoConfig::default(),
        );
        assert_eq!(
            err.unwrap_err(),
            VoError::WrongSize {
                found: (320, 240),
                expected: (640, 480)
            }
        );
        // A blank view has nothing to match.
        let blank = VoImage::new(&image::GrayImage::from_pixel(640, 480, image::Luma([128])));
        let err = relative_motion(
            &rig,
            (&blank, &blank),
            &blank,
            &Pose2::default(),
            &VoConfig::default(),
        );
        assert!(matches!(err, Err(VoError::TooFewPoints { .. })), "{err:?}");
    }

    /// Frames every 10 cm along a straight drive are paired 30 cm apart; before a 2 m gap (a
    /// stretch with no pictures) the last frame is paired with the one before, however close,
    /// and the chain starts again after the gap.
    #[test]
    fn frames_are_paired_a_little_apart_and_not_across_a_gap() {
        let odometry: Vec<StampedPose> = (0..=100)
            .map(|i| StampedPose {
                t_s: i as f64,
                pose: Pose2::new(0.1 * i as f64, 0.0, 0.0),
            })
            .collect();
        let times: Vec<f64> = (0..=20).chain(40..=50).map(|i| i as f64).collect();
        let pairs = frame_pairs(&times, &odometry, &VoConfig::default());
        let as_times: Vec<(f64, f64)> = pairs.iter().map(|&(a, b)| (times[a], times[b])).collect();
        assert_eq!(
            as_times,
            vec![
                (0.0, 3.0),
                (3.0, 6.0),
                (6.0, 9.0),
                (9.0, 12.0),
                (12.0, 15.0),
                (15.0, 18.0),
                (18.0, 20.0),
                (40.0, 43.0),
                (43.0, 46.0),
                (46.0, 49.0)
            ]
        );
    }
}
