//! A stereo renderer that challenges a detector the way real images do.
//!
//! Every pixel of the *distorted* image is traced through the camera model into the world: the
//! pixel is unprojected (undistorted) to a ray, and the ray meets the floor, the ceiling, the
//! walls (vertical planes over their segments, up to their height) or a tag (a square on its wall,
//! drawn from the family's true code bits with a white quiet zone). Four samples per pixel
//! (2 x 2 jittered strata; `n x n` with [`Renderer::with_samples`]) give anti-aliased edges. Surfaces carry a mild procedural texture; light falls
//! off with distance, the lens vignettes, and the sensor adds Gaussian noise; optionally the robot
//! moves during the exposure (motion blur: each sample sees the scene from one of 16 poses along
//! the motion). The same inputs and
//! seed give the same bytes.
//!
//! Ground truth: each tag whose four corners are in front of the camera, inside the image, facing
//! it and not hidden behind a wall, with the corners' pixel positions (C library corner order,
//! pixel centres at integer coordinates) in both images and their 3D positions in the world.

pub mod board;
mod first_walls;
mod mask;
mod paint;
mod rays;
mod scene;
mod truth;
mod walls_grid;

use mask::*;
use paint::*;
pub(crate) use paint::{texture, TAG_BLACK, TAG_WHITE};
use rays::*;
use scene::*;
use truth::*;
pub use truth::{visible_tags, TagVisibility};

use crate::camera::StereoRig;
use crate::geometry::Pose2;
use crate::visual::tags::TagFamily;
use crate::world::World;
use image::GrayImage;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::Serialize;

/// Renderer settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderConfig {
    /// Ceiling height, metres (ours: 2.5 m).
    pub ceiling_m: f64,
    /// Sensor noise, grey levels, one sigma (ours: 2).
    pub noise_sigma: f64,
    /// Brightness loss at the image corners from vignetting (ours: 30%).
    pub vignetting: f64,
    /// Distance at which the light has halved, metres (ours: 6 m).
    pub light_half_distance_m: f64,
    /// Seed of the sensor noise.
    pub seed: u64,
    /// Motion blur: how far the robot moves during the exposure, in its own frame (x forward,
    /// y left, metres; turn, radians), centred on the pose rendered (whose truth is given);
    /// `None` for a still exposure (ours).
    pub motion: Option<Pose2>,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            ceiling_m: 2.5,
            noise_sigma: 2.0,
            vignetting: 0.3,
            light_half_distance_m: 6.0,
            seed: 1,
            motion: None,
        }
    }
}

/// Errors of the renderer.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A tag's family has no code book here.
    #[error("tag {id}: family {family} cannot be rendered (tag36h11, tag25h9, tag16h5, tagStandard41h12 and the ArUco dictionaries can)")]
    UnknownFamily {
        /// Tag id.
        id: u32,
        /// Its family.
        family: TagFamily,
    },
    /// A tag id beyond the family's codes.
    #[error("tag {id}: {family} has only {count} codes")]
    IdOutOfRange {
        /// Tag id.
        id: u32,
        /// Family.
        family: TagFamily,
        /// Codes in the family.
        count: usize,
    },
    /// Boards that cannot share a sheet.
    #[error("{0}")]
    Boards(String),
}

/// Ground truth of one tag in a rendered pair.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TagTruth {
    /// Id.
    pub id: u32,
    /// Family.
    pub family: TagFamily,
    /// Corners in the world, metres (C library order).
    pub corners_world_m: [[f64; 3]; 4],
    /// Centre in the world, metres.
    pub centre_world_m: [f64; 3],
    /// Corners in the left image, pixels.
    pub left_corners_px: [[f64; 2]; 4],
    /// Corners in the right image, pixels.
    pub right_corners_px: [[f64; 2]; 4],
    /// Centre in the left camera frame, metres.
    pub centre_in_left_m: [f64; 3],
}

/// A rendered stereo pair with its ground truth.
#[derive(Debug, Clone)]
pub struct RenderedPair {
    /// Left image.
    pub left: GrayImage,
    /// Right image.
    pub right: GrayImage,
    /// The robot pose it was rendered from.
    pub world_from_robot: Pose2,
    /// `world_from_left` camera pose.
    pub world_from_left: Isometry3<f64>,
    /// Tags visible in both images.
    pub tags: Vec<TagTruth>,
}

/// `world_from_left` for a robot pose.
pub fn world_from_left(rig: &StereoRig, world_from_robot: &Pose2) -> Isometry3<f64> {
    let robot = Isometry3::from_parts(
        Translation3::new(world_from_robot.x, world_from_robot.y, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, world_from_robot.theta),
    );
    robot * rig.robot_from_left
}

/// Poses through a blurred exposure.
const MOTION_STEPS: usize = 16;

/// A renderer for one rig: the rays of every pixel sample are computed once, so rendering many
/// pairs costs only the tracing.
#[derive(Debug, Clone)]
pub struct Renderer {
    pub(crate) rig: StereoRig,
    left: RayTable,
    right: RayTable,
    /// Trace pixels away from every edge with one ray (see [`Renderer::with_every_sample`]).
    adaptive: bool,
    /// Bin the walls of large worlds in a grid (see [`Renderer::with_every_wall_tested`]).
    wall_grid: bool,
}

impl Renderer {
    /// Prepares the ray tables of both cameras, four samples per pixel (2 x 2 jittered strata).
    pub fn new(rig: &StereoRig) -> Self {
        Self::with_samples(rig, 2)
    }

    /// Prepares the ray tables of both cameras with `n x n` jittered samples per pixel (more
    /// samples come closer to a sensor that integrates light over each pixel's whole area).
    pub fn with_samples(rig: &StereoRig, n: usize) -> Self {
        Self {
            rig: rig.clone(),
            left: RayTable::new(&rig.left, n),
            right: RayTable::new(&rig.right, n),
            adaptive: true,
            wall_grid: true,
        }
    }

    /// Traces every sample of every pixel. By default a pixel that no edge crosses (no wall's
    /// end, foot or top, no tag, no horizon; found by tracing every edge of the scene into the
    /// image, a point at least every 1.5 px) is traced with one ray, its samples' mean: all its
    /// samples meet the same surface, which is shaded once per pixel anyway. The images differ
    /// from these only by where in such a pixel its texture and light are taken (office views:
    /// at most one grey level); rendering takes about half the time. Motion-blurred exposures
    /// and fisheyes always trace every sample.
    pub fn with_every_sample(mut self) -> Self {
        self.adaptive = false;
        self
    }

    /// Tests every wall for every ray. By default a world of more than 64 walls (a building
    /// traced from a map) has its walls binned in a uniform grid that each ray walks nearest cell
    /// first, stopping at the first hit; the pictures are the same to the byte. This is the
    /// reference the grid is measured against (`cargo bench --bench visual -- render_building`).
    pub fn with_every_wall_tested(mut self) -> Self {
        self.wall_grid = false;
        self
    }

    /// Renders the stereo pair seen from a robot pose.
    pub fn render(
        &self,
        world: &World,
        world_from_robot: Pose2,
        config: &RenderConfig,
    ) -> Result<RenderedPair, RenderError> {
        self.render_culled(world, world_from_robot, config, true)
    }

    /// [`Renderer::render`], with or without leaving out the walls and tags no camera can see
    /// (the same images either way; `false` is for checking that).
    fn render_culled(
        &self,
        world: &World,
        world_from_robot: Pose2,
        config: &RenderConfig,
        cull: bool,
    ) -> Result<RenderedPair, RenderError> {
        let staged = self.stage(world, world_from_robot, config, cull)?;
        let (left, right) =
            self.render_exposure(&staged.scene, &staged.left, &staged.right, config);
        let truth = truths(
            world,
            &staged.scene.tags,
            &self.rig,
            &staged.world_from_left,
            config,
        );
        Ok(RenderedPair {
            left,
            right,
            world_from_robot,
            world_from_left: staged.world_from_left,
            tags: truth,
        })
    }

    /// The scene (culled or not) and the cameras' poses through the exposure.
    fn stage(
        &self,
        world: &World,
        world_from_robot: Pose2,
        config: &RenderConfig,
        cull: bool,
    ) -> Result<Staged, RenderError> {
        let rig = &self.rig;
        let tags = world
            .tags
            .iter()
            .map(tag_paint)
            .collect::<Result<Vec<_>, _>>()?;
        let wl = world_from_left(rig, &world_from_robot);
        let exposure: Vec<Isometry3<f64>> = match config.motion {
            Some(m) => (0..MOTION_STEPS)
                .map(|j| {
                    let t = (j as f64 + 0.5) / MOTION_STEPS as f64 - 0.5;
                    let step = Pose2::new(m.x * t, m.y * t, m.theta * t);
                    world_from_left(rig, &world_from_robot.compose(&step))
                })
                .collect(),
            None => vec![wl],
        };
        let right = self.right_exposure(&exposure);
        let views: Vec<(Isometry3<f64>, f64)> = exposure
            .iter()
            .map(|p| (*p, self.left.max_off_axis_rad))
            .chain(right.iter().map(|p| (*p, self.right.max_off_axis_rad)))
            .collect();
        let wedges = if cull {
            ViewWedges::new(&views)
        } else {
            ViewWedges { wedges: None }
        };
        let walls: Vec<WallSpan> = world
            .walls
            .iter()
            .filter(|w| {
                let s = &w.segment;
                wedges.sees((s.a.x, s.a.y), (s.b.x, s.b.y))
            })
            .map(WallSpan::new)
            .collect();
        // Tags seen from above: the diagonals of their square (quiet zone included), a segment
        // across the width of a tag on a wall.
        let tags_in_view = (0..tags.len())
            .filter(|&k| {
                let t = &tags[k];
                let half = 0.5 * t.total_cells as f64 * t.cell_m;
                [t.right + t.up, t.right - t.up].iter().any(|d| {
                    let (a, b) = (t.centre - d * half, t.centre + d * half);
                    wedges.sees((a.x, a.y), (b.x, b.y))
                })
            })
            .collect();
        let mut scene = Scene::new(walls, tags, tags_in_view, config.ceiling_m);
        scene.walk_grid = self.wall_grid;
        if let ([left], [right]) = (&exposure[..], &right[..]) {
            scene.prove_first_walls(&[
                (*left, self.left.max_off_axis_rad),
                (*right, self.right.max_off_axis_rad),
            ]);
        }
        Ok(Staged {
            scene,
            left: exposure,
            right,
            world_from_left: wl,
        })
    }
}

/// A scene ready to render: what the cameras can see, and their poses through the exposure.
struct Staged {
    scene: Scene,
    left: Vec<Isometry3<f64>>,
    right: Vec<Isometry3<f64>>,
    /// The left camera at mid-exposure (the pose the truth is for).
    world_from_left: Isometry3<f64>,
}

impl Renderer {
    /// Both images of a scene given by its tracer, the left camera at `world_from_left`; each
    /// image's noise seeded from `config.seed` and its side.
    pub(crate) fn render_both(
        &self,
        trace: &dyn PixelTracer,
        world_from_left: &Isometry3<f64>,
        config: &RenderConfig,
    ) -> (GrayImage, GrayImage) {
        let left = std::slice::from_ref(world_from_left);
        self.render_exposure(trace, left, &self.right_exposure(left), config)
    }

    /// The right camera's poses through an exposure, from the left camera's.
    fn right_exposure(&self, left: &[Isometry3<f64>]) -> Vec<Isometry3<f64>> {
        let left_from_right = self.rig.left_from_right();
        left.iter().map(|wl| wl * left_from_right).collect()
    }

    /// Both images with the cameras moving through `left` and `right` (their poses during the
    /// exposure, evenly spaced in time).
    fn render_exposure(
        &self,
        trace: &dyn PixelTracer,
        left: &[Isometry3<f64>],
        right: &[Isometry3<f64>],
        config: &RenderConfig,
    ) -> (GrayImage, GrayImage) {
        let rig = &self.rig;
        let seed = config.seed.wrapping_mul(2);
        // Side by side, so that one camera's serial steps overlap the other's tracing.
        rayon::join(
            || {
                render_camera(
                    trace,
                    &rig.left,
                    &self.left,
                    left,
                    config,
                    seed,
                    self.adaptive,
                )
            },
            || {
                let (camera, table) = (&rig.right, &self.right);
                render_camera(trace, camera, table, right, config, seed + 1, self.adaptive)
            },
        )
    }
}

/// Renders the stereo pair seen from a robot pose (prepares a [`Renderer`] each call; keep one
/// to render many pairs).
pub fn render_pair(
    world: &World,
    rig: &StereoRig,
    world_from_robot: Pose2,
    config: &RenderConfig,
) -> Result<RenderedPair, RenderError> {
    Renderer::new(rig).render(world, world_from_robot, config)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Culling by the cameras' view wedges changes no pixel: poses all over the office and the
    /// museum, every heading in 30 degree steps, the default rig and a fisheye-free tilt.
    #[test]
    fn culling_what_no_camera_sees_changes_no_pixel() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let rig = crate::io::load_rig(&root.join("calibration/rigs/default.yaml")).unwrap();
        let renderer = Renderer::with_samples(&rig, 1);
        let config = RenderConfig::default();
        for (name, spots) in [
            ("office", [(1.0, 6.3), (3.3, 3.7), (6.5, 0.6)]),
            ("museum", [(5.0, 4.0), (9.0, 7.0), (15.5, 0.5)]),
        ] {
            let path = root.join(format!("samples/{name}/world.yaml"));
            let world = crate::io::load_world(&path).unwrap().world;
            for (x, y) in spots {
                for k in 0..12 {
                    let pose = Pose2::new(x, y, (k as f64 * 30.0).to_radians());
                    let culled = renderer.render_culled(&world, pose, &config, true).unwrap();
                    let all = renderer
                        .render_culled(&world, pose, &config, false)
                        .unwrap();
                    assert!(
                        culled.left == all.left && culled.right == all.right,
                        "{name} at {pose:?}"
                    );
                }
            }
        }
    }

    /// The wall grid and the proven first walls change no pixel: willow (traced from a building
    /// map, overlapping walls) and the office and museum with the grid forced on their few walls,
    /// every heading in 30 degree steps.
    #[test]
    fn the_wall_grid_changes_no_pixel() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let rig = crate::io::load_rig(&root.join("calibration/rigs/default.yaml")).unwrap();
        let renderer = Renderer::with_samples(&rig, 1);
        let config = RenderConfig::default();
        let mut proven = Vec::new();
        for (name, spots) in [
            ("willow", [(5.0, 7.0), (3.0, 9.0), (9.0, 4.5)]),
            ("office", [(1.0, 6.3), (3.3, 3.7), (6.5, 0.6)]),
            ("museum", [(5.0, 4.0), (9.0, 7.0), (15.5, 0.5)]),
        ] {
            let path = root.join(format!("samples/{name}/world.yaml"));
            let world = crate::io::load_world(&path).unwrap().world;
            for (x, y) in spots {
                for k in 0..12 {
                    let pose = Pose2::new(x, y, (k as f64 * 30.0).to_radians());
                    let staged = renderer.stage(&world, pose, &config, true).unwrap();
                    let mut gridded = staged.scene;
                    gridded.grid = walls_grid::WallGrid::new(&gridded.walls);
                    assert!(gridded.grid.is_some());
                    gridded.prove_first_walls(&[
                        (staged.left[0], renderer.left.max_off_axis_rad),
                        (staged.right[0], renderer.right.max_off_axis_rad),
                    ]);
                    assert_eq!(gridded.first_walls.len(), 2);
                    for f in &gridded.first_walls {
                        proven.push(f.proven_share());
                    }
                    let (l, r) =
                        renderer.render_exposure(&gridded, &staged.left, &staged.right, &config);
                    let linear = gridded.without_grid();
                    let (l0, r0) =
                        renderer.render_exposure(&linear, &staged.left, &staged.right, &config);
                    assert!(l == l0 && r == r0, "{name} at {pose:?}");
                }
            }
        }
        // The proofs are not vacuous: most wedges have one.
        let mean = proven.iter().sum::<f64>() / proven.len() as f64;
        eprintln!(
            "{:.0}% of the wedges with a proven first wall",
            100.0 * mean
        );
        assert!(mean > 0.5, "{mean}");
    }

    /// The pixels left out of the detail mask really are crossed by no edge: every sample of
    /// each meets the surface its mean ray meets (and none a tag). Poses all over the office, the
    /// museum and willow, every heading in 30 degree steps, close to walls and tags included.
    #[test]
    fn every_sample_of_a_pixel_off_the_mask_meets_one_surface() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let rig = crate::io::load_rig(&root.join("calibration/rigs/default.yaml")).unwrap();
        let renderer = Renderer::new(&rig);
        let config = RenderConfig::default();
        let kind = |s: Surface| match s {
            Surface::Tag(_) => Surface::Tag(0.0),
            other => other,
        };
        let (mut pixels, mut masked) = (0usize, 0usize);
        let spots: [(&str, &[(f64, f64)]); 4] = [
            ("office", &[(1.0, 6.3), (0.4, 7.1), (3.3, 3.7), (6.5, 0.6)]),
            ("museum", &[(5.0, 4.0), (9.0, 7.0), (15.5, 0.5), (0.5, 0.5)]),
            // Walls traced from a real building map: many short walls and wall ends, some
            // overlapping (which, traced ray by ray, once let rounding pick the wall).
            ("willow", &[(5.0, 7.0)]),
            // The same with its walls in the grid and the edges they hide left out of the mask,
            // as a building's are.
            ("willow+occlusion", &[(5.0, 7.0), (3.0, 9.0), (9.0, 4.5)]),
        ];
        for (name, spots) in spots {
            let (file, occluded) = match name.strip_suffix("+occlusion") {
                Some(file) => (file, true),
                None => (name, false),
            };
            let path = root.join(format!("samples/{file}/world.yaml"));
            let world = crate::io::load_world(&path).unwrap().world;
            for &(x, y) in spots {
                for k in 0..12 {
                    let pose = Pose2::new(x, y, (k as f64 * 30.0).to_radians());
                    let mut staged = renderer.stage(&world, pose, &config, true).unwrap();
                    if occluded {
                        staged.scene.grid = walls_grid::WallGrid::new(&staged.scene.walls);
                        staged.scene.occlusion_mask = true;
                    }
                    for (camera, table, at) in [
                        (&rig.left, &renderer.left, &staged.left[0]),
                        (&rig.right, &renderer.right, &staged.right[0]),
                    ] {
                        let mask = staged.scene.detail(camera, table, at).unwrap();
                        let (origin, rotation) =
                            (at.translation.vector, at.rotation.to_rotation_matrix());
                        for (i, &on) in mask.iter().enumerate() {
                            pixels += 1;
                            if on {
                                masked += 1;
                                continue;
                            }
                            let (_, mean) = staged.scene.hit(&origin, &(rotation * table.mean[i]));
                            assert!(!matches!(mean, Surface::Tag(_)), "{name} {pose:?} px {i}");
                            for ray in &table.rays[i * 4..i * 4 + 4] {
                                let (_, s) = staged.scene.hit(&origin, &(rotation * ray));
                                assert_eq!(
                                    kind(s),
                                    kind(mean),
                                    "{name} {pose:?}: pixel ({}, {})",
                                    i % camera.width as usize,
                                    i / camera.width as usize
                                );
                            }
                        }
                    }
                }
            }
        }
        eprintln!(
            "{:.1}% of the pixels traced with all their samples",
            100.0 * masked as f64 / pixels as f64
        );
    }

    /// Rendering one ray for the pixels off the detail mask changes the images little: the
    /// texture and light of those pixels are taken at their samples' mean ray rather than at
    /// the mean of their samples' points.
    #[test]
    fn one_ray_for_pixels_off_the_mask_changes_little() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let rig = crate::io::load_rig(&root.join("calibration/rigs/default.yaml")).unwrap();
        let adaptive = Renderer::new(&rig);
        let every = Renderer::new(&rig).with_every_sample();
        let config = RenderConfig::default();
        let path = root.join("samples/office/world.yaml");
        let world = crate::io::load_world(&path).unwrap().world;
        let (mut worst, mut sum, mut count) = (0i32, 0u64, 0u64);
        for k in 0..12 {
            let pose = Pose2::new(1.0, 6.3, (k as f64 * 30.0).to_radians());
            let a = adaptive.render(&world, pose, &config).unwrap();
            let e = every.render(&world, pose, &config).unwrap();
            for (pa, pe) in [(&a.left, &e.left), (&a.right, &e.right)] {
                for (va, ve) in pa.as_raw().iter().zip(pe.as_raw()) {
                    let d = (*va as i32 - *ve as i32).abs();
                    worst = worst.max(d);
                    sum += d as u64;
                    count += 1;
                }
            }
        }
        let mean = sum as f64 / count as f64;
        eprintln!("largest difference {worst} grey levels, mean {mean:.3}");
        assert!(mean < 0.2, "mean difference {mean} grey levels");
    }
}
