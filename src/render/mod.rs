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

use crate::camera::{Camera, StereoRig};
use crate::geometry::Pose2;
use crate::visual::tags::{TagFamily, DETECTABLE_FAMILIES};
use crate::world::{Tag, World};
use image::GrayImage;
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
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
    #[error("tag {id}: family {family} cannot be rendered (tag36h11, tag25h9, tag16h5 and tagStandard41h12 can)")]
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

/// A tag ready to draw: its frame on the wall and its bits.
struct TagPaint {
    centre: Vector3<f64>,
    normal: Vector3<f64>,
    right: Vector3<f64>,
    /// Cell size, metres (the black square is `width_at_border` cells).
    cell_m: f64,
    /// `1 / cell_m`.
    cells_per_m: f64,
    /// Cells across the drawn area, quiet zone included.
    total_cells: i64,
    /// `true` where a cell is white, row-major over `total_cells`.
    white: Vec<bool>,
}

/// A tag's printed face stands this far in front of its wall, metres (so the wall never shows
/// through it); its drawn corners and its true corners both lie on that face.
const TAG_STANDOFF_M: f64 = 0.001;

/// White cells drawn around the black square (the standard image has 1; we draw 2 so a tag on
/// a textured wall keeps its quiet zone).
const QUIET_ZONE_CELLS: i64 = 2;

fn tag_paint(tag: &Tag) -> Result<TagPaint, RenderError> {
    let family = Some(tag.family)
        .filter(|f| DETECTABLE_FAMILIES.contains(f))
        .ok_or(RenderError::UnknownFamily {
            id: tag.id,
            family: tag.family,
        })?;
    let image = family
        .code_image(tag.id)
        .ok_or_else(|| RenderError::IdOutOfRange {
            id: tag.id,
            family: tag.family,
            count: family.code_count(),
        })?;
    let tw = image.total_cells as i64;
    let img = &image.white;
    // Add the quiet zone.
    let total = tw + 2 * QUIET_ZONE_CELLS;
    let mut white = vec![true; (total * total) as usize];
    for y in 0..tw {
        for x in 0..tw {
            white[((y + QUIET_ZONE_CELLS) * total + x + QUIET_ZONE_CELLS) as usize] =
                img[(y * tw + x) as usize];
        }
    }
    let (s, c) = tag.yaw_rad.sin_cos();
    let normal = Vector3::new(c, s, 0.0);
    Ok(TagPaint {
        centre: Vector3::from(tag.position_m),
        normal,
        right: Vector3::new(-s, c, 0.0),
        cell_m: tag.size_m / image.black_square_cells as f64,
        cells_per_m: image.black_square_cells as f64 / tag.size_m,
        total_cells: total,
        white,
    })
}

impl TagPaint {
    /// The tag's corners in the world, C order: tag image bottom-left, bottom-right, top-right,
    /// top-left of the black square (tag frame (-1, 1), (1, 1), (1, -1), (-1, -1), y down).
    fn corners(&self, size_m: f64) -> [Vector3<f64>; 4] {
        let h = 0.5 * size_m;
        let down = Vector3::new(0.0, 0.0, -1.0);
        let face = self.centre + self.normal * TAG_STANDOFF_M;
        [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)]
            .map(|(x, y)| face + self.right * (x * h) + down * (y * h))
    }

    /// Where the ray meets the tag, when nearer than `best` plus 2 mm: the distance as a
    /// fraction, and the albedo there.
    #[inline]
    fn hit(
        &self,
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
        best: Fraction,
    ) -> Option<(Fraction, f64)> {
        let den = -dir.dot(&self.normal);
        if den <= 1e-9 {
            return None; // seen from behind or edge-on
        }
        let num = (origin - self.centre).dot(&self.normal) - TAG_STANDOFF_M;
        if num <= 0.0 || num * best.den >= (best.num + 0.002 * best.den) * den {
            return None;
        }
        // The point met, relative to the centre, times `den`.
        let q = (origin - self.centre) * den + dir * num;
        let half = 0.5 * self.total_cells as f64 * den;
        let col = q.dot(&self.right) * self.cells_per_m + half;
        let row = -q.z * self.cells_per_m + half;
        let total = self.total_cells as f64 * den;
        if col < 0.0 || row < 0.0 || col >= total || row >= total {
            return None;
        }
        let k = 1.0 / den;
        let cell = ((row * k) as i64).min(self.total_cells - 1) * self.total_cells
            + ((col * k) as i64).min(self.total_cells - 1);
        let white = self.white[cell as usize];
        Some((
            Fraction { num, den },
            if white { TAG_WHITE } else { TAG_BLACK },
        ))
    }

    /// Whether a ray passes within `margin_rad` of the tag's drawn square (the margin is
    /// taken on the tag's plane, where it grows as the ray's incidence grazes).
    fn covers(&self, origin: &Vector3<f64>, dir: &Vector3<f64>, margin_rad: f64) -> bool {
        let den = -dir.dot(&self.normal);
        let num = (origin - self.centre).dot(&self.normal) - TAG_STANDOFF_M;
        if den <= 1e-9 || num <= 0.0 {
            return false;
        }
        let t = num / den;
        let p = origin + dir * t - self.centre;
        let half = 0.5 * self.total_cells as f64 * self.cell_m + margin_rad * t / den;
        p.dot(&self.right).abs() <= half && p.z.abs() <= half
    }
}

/// A distance along a ray kept as `num / den` (`den` >= 0; `den` = 0 is infinitely far), so
/// that comparing candidates costs no division.
#[derive(Debug, Clone, Copy)]
struct Fraction {
    num: f64,
    den: f64,
}

impl Fraction {
    const INFINITE: Self = Self { num: 1.0, den: 0.0 };

    fn value(self) -> f64 {
        if self.den > 0.0 {
            self.num / self.den
        } else {
            f64::INFINITY
        }
    }
}

/// Albedo of a tag's white paper.
pub(crate) const TAG_WHITE: f64 = 0.92;
/// Albedo of a tag's black ink.
pub(crate) const TAG_BLACK: f64 = 0.08;

/// `x.floor()` without the libm call the baseline x86-64 target makes of it (no SSE4.1 round
/// instruction); exact for |x| < 2^52.
#[inline]
fn fast_floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// Side of the value-noise lattice; the texture repeats every this many lattice cells (32 m on
/// the floor's coarse octave, 6.4 m on its fine one).
const LATTICE: usize = 256;

/// The lattice values in [-1, 1], hashed once from their coordinates.
fn lattice() -> &'static [f32; LATTICE * LATTICE] {
    static TABLE: std::sync::OnceLock<Box<[f32; LATTICE * LATTICE]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut table = Box::new([0f32; LATTICE * LATTICE]);
        for (k, value) in table.iter_mut().enumerate() {
            let (i, j) = ((k % LATTICE) as u64, (k / LATTICE) as u64);
            let mut h =
                i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ j.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
            h ^= h >> 29;
            h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            h ^= h >> 32;
            *value = ((h & 0xFFFF) as f64 / 32767.5 - 1.0) as f32;
        }
        table
    })
}

/// A smooth, deterministic texture value in [-1, 1] (value noise on a periodic lattice).
#[inline]
pub(crate) fn texture(u: f64, v: f64) -> f64 {
    let table = lattice();
    let (i, j) = (fast_floor(u), fast_floor(v));
    // The fractions and the blend in f32, as the lattice is stored.
    let (fu, fv) = ((u - i) as f32, (v - j) as f32);
    let (su, sv) = (fu * fu * (3.0 - 2.0 * fu), fv * fv * (3.0 - 2.0 * fv));
    const MASK: usize = LATTICE - 1;
    let (i0, j0) = (i as i64 as usize & MASK, j as i64 as usize & MASK);
    let (i1, j1) = ((i0 + 1) & MASK, (j0 + 1) & MASK);
    let at = |i: usize, j: usize| table[(j * LATTICE + i) & (LATTICE * LATTICE - 1)];
    let a = at(i0, j0) + (at(i1, j0) - at(i0, j0)) * su;
    let b = at(i0, j1) + (at(i1, j1) - at(i0, j1)) * su;
    (a + (b - a) * sv) as f64
}

/// A wall as [`Scene::hit`] tests it: its floor segment `a + u e`, `u` in [0, 1], and its
/// height; `unit` is `e` normalised (the texture's axis along the wall).
#[derive(Debug, Clone, Copy)]
struct WallSpan {
    a: (f64, f64),
    e: (f64, f64),
    unit: (f64, f64),
    height_m: f64,
}

impl WallSpan {
    fn new(wall: &crate::world::Wall) -> Self {
        let (a, b) = (wall.segment.a, wall.segment.b);
        let e = (b.x - a.x, b.y - a.y);
        let length = e.0.hypot(e.1).max(1e-12);
        Self {
            a: (a.x, a.y),
            e,
            unit: (e.0 / length, e.1 / length),
            height_m: wall.height_m,
        }
    }
}

/// The scene as the renderer sees it.
struct Scene {
    /// The walls that can be in view.
    walls: Vec<WallSpan>,
    tags: Vec<TagPaint>,
    /// The tags that can be in view (indices into `tags`).
    tags_in_view: Vec<usize>,
    ceiling_m: f64,
}

/// What a ray meets first.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Surface {
    Sky,
    Floor,
    Ceiling,
    /// A wall, by its place in [`Scene::walls`].
    Wall(usize),
    /// A tag, with its albedo where the ray meets it.
    Tag(f64),
}

impl Scene {
    /// Distance along a ray to the first surface, and the surface.
    fn hit(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> (f64, Surface) {
        let mut best = (Fraction::INFINITE, Surface::Sky);
        if dir.z < -1e-9 {
            best = (
                Fraction {
                    num: origin.z,
                    den: -dir.z,
                },
                Surface::Floor,
            );
        } else if dir.z > 1e-9 {
            let num = self.ceiling_m - origin.z;
            best = (Fraction { num, den: dir.z }, Surface::Ceiling);
        }
        if dir.x * dir.x + dir.y * dir.y > 1e-24 {
            // Each wall as origin + t dir (t along the 3D ray) meeting a + u e, u in [0, 1]:
            // t = tn / d and u = un / d, with the signs folded into the numerators so that d > 0.
            for (k, w) in self.walls.iter().enumerate() {
                let (ex, ey) = w.e;
                let denom = dir.x * ey - dir.y * ex;
                let (wx, wy) = (w.a.0 - origin.x, w.a.1 - origin.y);
                let (tn, un) = (wx * ey - wy * ex, wx * dir.y - wy * dir.x);
                let (tn, un, d) = if denom < 0.0 {
                    (-tn, -un, -denom)
                } else {
                    (tn, un, denom)
                };
                // Nearer by more than a part in 10^9: of walls that overlap (traced maps have
                // them) the first always wins, rather than rounding deciding ray by ray.
                if d < 1e-12
                    || tn <= 1e-9 * d
                    || tn * best.0.den >= best.0.num * d * (1.0 - 1e-9)
                    || un < 0.0
                    || un > d
                {
                    continue;
                }
                // The height met, times d.
                let z = origin.z * d + dir.z * tn;
                if z < 0.0 || z > w.height_m * d {
                    continue;
                }
                best = (Fraction { num: tn, den: d }, Surface::Wall(k));
            }
        }
        for &k in &self.tags_in_view {
            if let Some((t, albedo)) = self.tags[k].hit(origin, dir, best.0) {
                best = (t, Surface::Tag(albedo));
            }
        }
        (best.0.value(), best.1)
    }

    /// Albedo of a surface at a point on it.
    fn shade(&self, surface: Surface, p: &Vector3<f64>) -> f64 {
        match surface {
            Surface::Sky => 0.5,
            Surface::Tag(albedo) => albedo,
            Surface::Floor => {
                0.35 + 0.08 * texture(p.x * 8.0, p.y * 8.0) + 0.04 * texture(p.x * 40.0, p.y * 40.0)
            }
            Surface::Ceiling => 0.8 + 0.02 * texture(p.x, p.y),
            Surface::Wall(k) => {
                let w = &self.walls[k];
                let along = (p.x - w.a.0) * w.unit.0 + (p.y - w.a.1) * w.unit.1;
                0.62 + 0.06 * texture(along * 6.0, p.z * 6.0)
                    + 0.03 * texture(along * 30.0, p.z * 30.0)
            }
        }
    }
}

/// Surfaces of one pixel shaded once each by [`Scene`]'s [`PixelTracer`]; samples on any further
/// surface (a pixel on many edges at once) are shaded one by one.
const SHADED_PER_PIXEL: usize = 4;

impl PixelTracer for Scene {
    /// Tags are painted per sample (their bits must stay sharp); the textured surfaces (walls,
    /// floor, ceiling), whose texture changes little within a pixel, are shaded once per pixel
    /// and surface, at the mean of the samples' points on it. The light, which changes even less
    /// within a pixel, is taken once per surface at the samples' mean distance.
    fn radiance_sum(&self, rays: &[(Vector3<f64>, Vector3<f64>)], light: Light) -> f64 {
        if let [(origin, dir)] = rays {
            let (t, surface) = self.hit(origin, dir);
            return self.shade(surface, &(origin + dir * t)) * light.at(t);
        }
        // Per surface: the sum of the samples' points on it, of their distances, and their count.
        let mut groups = [(Surface::Sky, Vector3::zeros(), 0.0, 0u32); SHADED_PER_PIXEL];
        let mut n = 0;
        let mut sum = 0.0;
        // The tags' samples: albedo sum, distance sum, count.
        let mut tag = (0.0, 0.0, 0u32);
        for (origin, dir) in rays {
            let (t, surface) = self.hit(origin, dir);
            match surface {
                Surface::Sky => sum += self.shade(surface, origin) * light.at(t),
                Surface::Tag(albedo) => tag = (tag.0 + albedo, tag.1 + t, tag.2 + 1),
                _ => {
                    let p = origin + dir * t;
                    if let Some(g) = groups[..n].iter_mut().find(|g| g.0 == surface) {
                        g.1 += p;
                        g.2 += t;
                        g.3 += 1;
                    } else if n < SHADED_PER_PIXEL {
                        groups[n] = (surface, p, t, 1);
                        n += 1;
                    } else {
                        sum += self.shade(surface, &p) * light.at(t);
                    }
                }
            }
        }
        // 1 / count without a division.
        const INVERSE: [f64; 5] = [0.0, 1.0, 0.5, 1.0 / 3.0, 0.25];
        let inverse = |count: u32| match INVERSE.get(count as usize) {
            Some(&v) => v,
            None => 1.0 / count as f64,
        };
        for (surface, p, t, count) in &groups[..n] {
            let k = inverse(*count);
            sum += self.shade(*surface, &(p * k)) * light.at(t * k) * *count as f64;
        }
        if tag.2 > 0 {
            sum += tag.0 * light.at(tag.1 * inverse(tag.2));
        }
        sum
    }

    fn detail(
        &self,
        camera: &Camera,
        table: &RayTable,
        world_from_camera: &Isometry3<f64>,
    ) -> Option<Vec<bool>> {
        let reach = table.max_off_axis_rad + 2f64.to_radians();
        if reach >= 80f64.to_radians() {
            return None; // a fisheye: its edges do not project as a pinhole's do
        }
        let view = View {
            camera,
            camera_from_world: world_from_camera.inverse(),
            tan_reach: reach.tan(),
        };
        let mut mask = Mask::new(camera);
        // Each wall's foot, top (or where it meets the ceiling) and ends.
        for wall in &self.walls {
            let a = Vector3::new(wall.a.0, wall.a.1, 0.0);
            let b = a + Vector3::new(wall.e.0, wall.e.1, 0.0);
            let up = Vector3::new(0.0, 0.0, wall.height_m.min(self.ceiling_m));
            for (p, q) in [(a, b), (a + up, b + up), (a, a + up), (b, b + up)] {
                view.trace(&p, &q, &mut |x, y| mask.mark_around(x, y));
            }
        }
        // Tags: every pixel they cover (their cells are edges too).
        for &k in &self.tags_in_view {
            let tag = &self.tags[k];
            let half = 0.5 * tag.total_cells as f64 * tag.cell_m;
            let face = tag.centre + tag.normal * TAG_STANDOFF_M;
            let corners = [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)]
                .map(|(x, y)| face + tag.right * (x * half) + Vector3::z() * (y * half));
            if corners.iter().all(|c| view.holds(c)) {
                let mut bounds = [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ];
                for j in 0..4 {
                    view.trace(&corners[j], &corners[(j + 1) % 4], &mut |x, y| {
                        bounds = [
                            bounds[0].min(x),
                            bounds[1].min(y),
                            bounds[2].max(x),
                            bounds[3].max(y),
                        ];
                    });
                }
                // A pixel's margin for the outline's points being up to EDGE_STEP_PX apart.
                let [x0, y0, x1, y1] = bounds;
                mask.mark_box([x0 - 1.0, y0 - 1.0, x1 + 1.0, y1 + 1.0]);
            } else {
                // Partly out of view: the pixels whose mean ray meets it, 2 px around.
                let rotation = world_from_camera.rotation.to_rotation_matrix();
                let origin = world_from_camera.translation.vector;
                let margin = 2.0 / camera.fx.min(camera.fy);
                for (on, ray) in mask.on.iter_mut().zip(&table.mean) {
                    *on |= tag.covers(&origin, &(rotation * ray), margin);
                }
            }
        }
        // The horizon, where the floor and the ceiling (or nothing) meet far away.
        let rotation = world_from_camera.rotation.to_rotation_matrix();
        let lift = rotation.matrix().row(2).transpose();
        let up: Vec<bool> = table.mean.par_iter().map(|r| lift.dot(r) > 0.0).collect();
        for i in 0..up.len() {
            let (col, row) = (i % mask.w, i / mask.w);
            let right = col + 1 < mask.w && up[i + 1] != up[i];
            let below = row + 1 < mask.h && up[i + mask.w] != up[i];
            if right || below {
                mask.mark_around(col as f64, row as f64);
                mask.mark_around(col as f64 + 1.0, row as f64 + 1.0);
            }
        }
        Some(mask.on)
    }
}

/// Pixels of one image marked for all their samples.
struct Mask {
    w: usize,
    h: usize,
    on: Vec<bool>,
}

impl Mask {
    fn new(camera: &Camera) -> Self {
        let (w, h) = (camera.width as usize, camera.height as usize);
        Self {
            w,
            h,
            on: vec![false; w * h],
        }
    }

    /// Marks the pixel nearest to a point of an edge and its 8 neighbours: with the edge's
    /// points at most [`EDGE_STEP_PX`] apart, every pixel the edge crosses is marked.
    fn mark_around(&mut self, x: f64, y: f64) {
        self.mark_box([x - 1.0, y - 1.0, x + 1.0, y + 1.0]);
    }

    /// Marks the pixels whose square meets `[x0, y0, x1, y1]`.
    fn mark_box(&mut self, [x0, y0, x1, y1]: [f64; 4]) {
        let (w, h) = (self.w as f64, self.h as f64);
        if !(x0 <= x1 && y0 <= y1) || x1 < -0.5 || y1 < -0.5 || x0 > w - 0.5 || y0 > h - 0.5 {
            return;
        }
        // Pixel c's square is [c - 0.5, c + 0.5].
        let first = |v: f64| (-fast_floor(0.5 - v)).max(0.0) as usize;
        let last = |v: f64, n: f64| fast_floor(v + 0.5).min(n - 1.0) as usize;
        let (c0, c1) = (first(x0), last(x1, w));
        let (r0, r1) = (first(y0), last(y1, h));
        for row in r0..=r1 {
            self.on[row * self.w + c0..=row * self.w + c1].fill(true);
        }
    }
}

/// A camera for tracing the scene's edges into its image.
struct View<'a> {
    camera: &'a Camera,
    camera_from_world: Isometry3<f64>,
    /// Tangent of the largest angle off the optical axis that any pixel sees, with a margin.
    tan_reach: f64,
}

/// Largest distance between the image points of a traced edge, pixels. Any pixel the edge
/// crosses then has its centre within 1 + 0.75 px of the nearest point rounded to a pixel, so
/// within one pixel (both are whole pixels): marking 3 x 3 pixels around each point is enough.
const EDGE_STEP_PX: f64 = 1.5;

/// Nearest distance in front of a camera an edge is traced at, metres.
const EDGE_NEAR_M: f64 = 0.01;

impl View<'_> {
    /// The sides of the pyramid that holds everything the camera sees, each >= 0 inside.
    fn sides(&self, c: &Vector3<f64>) -> [f64; 5] {
        let r = self.tan_reach * c.z;
        [c.z - EDGE_NEAR_M, r - c.x, r + c.x, r - c.y, r + c.y]
    }

    /// Whether a world point is inside that pyramid.
    fn holds(&self, p: &Vector3<f64>) -> bool {
        let c = self
            .camera_from_world
            .transform_point(&Point3::from(*p))
            .coords;
        self.sides(&c).iter().all(|&v| v >= 0.0)
    }

    /// Calls `f` with image points of the world segment `p`-`q`, at most [`EDGE_STEP_PX`]
    /// apart, along the part of it the camera can see.
    fn trace(&self, p: &Vector3<f64>, q: &Vector3<f64>, f: &mut dyn FnMut(f64, f64)) {
        let c0 = self
            .camera_from_world
            .transform_point(&Point3::from(*p))
            .coords;
        let c1 = self
            .camera_from_world
            .transform_point(&Point3::from(*q))
            .coords;
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for (v0, v1) in self.sides(&c0).into_iter().zip(self.sides(&c1)) {
            if v0 < 0.0 && v1 < 0.0 {
                return;
            } else if v0 < 0.0 {
                lo = lo.max(v0 / (v0 - v1));
            } else if v1 < 0.0 {
                hi = hi.min(v0 / (v0 - v1));
            }
        }
        if lo > hi {
            return;
        }
        let (a, b) = (c0 + (c1 - c0) * lo, c0 + (c1 - c0) * hi);
        let (Some(pa), Some(pb)) = (self.camera.project(&a), self.camera.project(&b)) else {
            return;
        };
        self.subdivide(&a, &b, pa, pb, 0, f);
        f(pb.x, pb.y);
    }

    /// Emits `pa` and the points between `a` and `b` (not `pb`), halving until they are at
    /// most [`EDGE_STEP_PX`] apart (at least 8 pieces, for the bend of the lens); a piece with
    /// both ends well beyond the same side of the image is not followed further.
    fn subdivide(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        pa: Point2<f64>,
        pb: Point2<f64>,
        depth: u32,
        f: &mut dyn FnMut(f64, f64),
    ) {
        const MIN_DEPTH: u32 = 3;
        const MAX_DEPTH: u32 = 18;
        // Pixels beyond the image's border a piece of 1/8 of an edge or less cannot bend back
        // over.
        const OUTSIDE_PX: f64 = 8.0;
        let (w, h) = (self.camera.width as f64, self.camera.height as f64);
        let outside = (pa.x < -OUTSIDE_PX && pb.x < -OUTSIDE_PX)
            || (pa.y < -OUTSIDE_PX && pb.y < -OUTSIDE_PX)
            || (pa.x > w + OUTSIDE_PX && pb.x > w + OUTSIDE_PX)
            || (pa.y > h + OUTSIDE_PX && pb.y > h + OUTSIDE_PX);
        if depth >= MIN_DEPTH && outside {
            return;
        }
        if depth < MAX_DEPTH && (depth < MIN_DEPTH || (pa - pb).norm() > EDGE_STEP_PX) {
            let m = (a + b) * 0.5;
            if let Some(pm) = self.camera.project(&m) {
                self.subdivide(a, &m, pa, pm, depth + 1, f);
                self.subdivide(&m, b, pm, pb, depth + 1, f);
                return;
            }
        }
        f(pa.x, pa.y);
    }
}

/// `world_from_left` for a robot pose.
pub fn world_from_left(rig: &StereoRig, world_from_robot: &Pose2) -> Isometry3<f64> {
    let robot = Isometry3::from_parts(
        Translation3::new(world_from_robot.x, world_from_robot.y, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, world_from_robot.theta),
    );
    robot * rig.robot_from_left
}

/// Unit ray directions in the camera frame of the samples of every pixel, row-major.
#[derive(Debug, Clone)]
pub(crate) struct RayTable {
    /// Samples per pixel (`n x n` strata).
    per_pixel: usize,
    /// `per_pixel` rays per pixel.
    rays: Vec<Vector3<f64>>,
    /// The mean direction of each pixel's samples.
    mean: Vec<Vector3<f64>>,
    /// Whether the pixel's rays exist (a fisheye's pixels beyond its field have none).
    valid: Vec<bool>,
    /// Largest angle of a ray from the optical axis, radians.
    max_off_axis_rad: f64,
}

/// A deterministic point in [0, 1)² for sample `k` of pixel `i`.
fn jitter(i: u64, k: u64) -> (f64, f64) {
    let mut h = i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (k + 1).wrapping_mul(0xD1B5_4A32_D192_ED03);
    h ^= h >> 31;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 29;
    let a = (h & 0xFFFF_FFFF) as f64 / 4_294_967_296.0;
    let b = (h >> 32) as f64 / 4_294_967_296.0;
    (a, b)
}

impl RayTable {
    /// Rays of `n x n` jittered strata per pixel.
    fn new(camera: &Camera, n: usize) -> Self {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let n = n.max(1);
        let per_pixel = n * n;
        let mut rays = vec![Vector3::zeros(); w * h * per_pixel];
        let mut valid = vec![false; w * h];
        rays.par_chunks_mut(per_pixel)
            .zip(valid.par_iter_mut())
            .enumerate()
            .for_each(|(i, (out, ok))| {
                let (col, row) = ((i % w) as f64, (i / w) as f64);
                *ok = out.iter_mut().enumerate().all(|(k, ray)| {
                    // Jittered strata: a fixed pseudo-random point inside each of the n x n
                    // cells of the pixel, so edge positions are not quantised to 1/n pixel
                    // along a line.
                    let (ju, jv) = jitter(i as u64, k as u64);
                    let du = -0.5 + ((k % n) as f64 + ju) / n as f64;
                    let dv = -0.5 + ((k / n) as f64 + jv) / n as f64;
                    let Some(p) = camera.unproject(&Point2::new(col + du, row + dv)) else {
                        return false;
                    };
                    *ray = Vector3::new(p.x, p.y, 1.0).normalize();
                    true
                });
            });
        let mean = rays
            .par_chunks(per_pixel)
            .map(|rs| {
                rs.iter()
                    .sum::<Vector3<f64>>()
                    .try_normalize(1e-12)
                    .unwrap_or_else(Vector3::zeros)
            })
            .collect();
        let max_off_axis_rad = rays
            .par_chunks(per_pixel)
            .zip(valid.par_iter())
            .filter(|(_, &ok)| ok)
            .flat_map_iter(|(rs, _)| rs.iter().map(|r| r.z.clamp(-1.0, 1.0).acos()))
            .reduce(|| 0.0, f64::max);
        Self {
            per_pixel,
            rays,
            mean,
            valid,
            max_off_axis_rad,
        }
    }
}

/// One camera's wedge seen from above: its apex (the camera) and the inward normals of its sides.
type Wedge = ((f64, f64), [(f64, f64); 2]);

/// The horizontal wedges that hold the cones of the cameras' rays, for culling what no camera
/// can see.
struct ViewWedges {
    /// Per view: the camera's position and the inward normals of the wedge's two sides; `None`
    /// when some cone takes in the vertical (a fisheye, a steep tilt) and nothing is culled.
    wedges: Option<Vec<Wedge>>,
}

impl ViewWedges {
    /// Wedges of `views`: camera poses in the world with the largest angle of their rays from the
    /// optical axis.
    fn new(views: &[(Isometry3<f64>, f64)]) -> Self {
        let mut wedges = Vec::new();
        for (pose, off_axis) in views {
            let axis = pose.rotation * Vector3::z();
            let elevation = axis.z.clamp(-1.0, 1.0).asin();
            // A degree of margin for the wedge's straight sides.
            let cone = off_axis + 1f64.to_radians();
            if cone >= std::f64::consts::FRAC_PI_2 - elevation.abs() {
                return Self { wedges: None };
            }
            let half = (cone.sin() / elevation.cos()).min(1.0).asin();
            let azimuth = axis.y.atan2(axis.x);
            let normals = [-1.0, 1.0].map(|side: f64| {
                let a = azimuth + side * half;
                // Inward normal of the side at azimuth `a`.
                (side * a.sin(), -side * a.cos())
            });
            let o = pose.translation.vector;
            wedges.push(((o.x, o.y), normals));
        }
        Self {
            wedges: Some(wedges),
        }
    }

    /// Whether the segment `a`-`b` (seen from above) crosses any wedge: clipped to both sides
    /// of one, something is left.
    fn sees(&self, a: (f64, f64), b: (f64, f64)) -> bool {
        let Some(wedges) = &self.wedges else {
            return true;
        };
        wedges.iter().any(|(o, normals)| {
            let (ax, ay, bx, by) = (a.0 - o.0, a.1 - o.1, b.0 - o.0, b.1 - o.1);
            let (mut lo, mut hi) = (0.0f64, 1.0f64);
            for (nx, ny) in normals {
                let (ha, hb) = (nx * ax + ny * ay, nx * bx + ny * by);
                if ha < 0.0 && hb < 0.0 {
                    return false;
                } else if ha < 0.0 {
                    lo = lo.max(ha / (ha - hb));
                } else if hb < 0.0 {
                    hi = hi.min(ha / (ha - hb));
                }
            }
            lo <= hi
        })
    }
}

/// The light reaching a surface: falls off with its distance from the camera (the robot's lamp).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Light {
    /// Distance at which the light has halved, metres.
    half_distance_m: f64,
}

impl Light {
    /// Light at distance `t` (0.2 for a ray that meets nothing).
    #[inline]
    fn at(self, t: f64) -> f64 {
        if t.is_finite() {
            let r = t / self.half_distance_m;
            1.0 / (1.0 + r * r)
        } else {
            0.2
        }
    }
}

/// A scene as the cameras see it: the sum over one pixel's sample rays `(origin, direction)` of
/// the albedo met times the light at its distance.
pub(crate) trait PixelTracer: Sync {
    /// The sum over the rays of albedo times light.
    fn radiance_sum(&self, rays: &[(Vector3<f64>, Vector3<f64>)], light: Light) -> f64;

    /// The pixels (row-major) whose samples may not all meet the same surface, seen by `camera`
    /// (the rays of `table`) at `world_from_camera`; the others are traced with their samples'
    /// mean ray. `None` (the default): every pixel gets all its samples.
    fn detail(
        &self,
        _camera: &Camera,
        _table: &RayTable,
        _world_from_camera: &Isometry3<f64>,
    ) -> Option<Vec<bool>> {
        None
    }
}

/// Any function giving the distance and albedo along one ray traces a pixel ray by ray.
impl<F> PixelTracer for F
where
    F: Fn(&Vector3<f64>, &Vector3<f64>) -> (f64, f64) + Sync,
{
    fn radiance_sum(&self, rays: &[(Vector3<f64>, Vector3<f64>)], light: Light) -> f64 {
        rays.iter()
            .map(|(origin, dir)| {
                let (t, albedo) = self(origin, dir);
                albedo * light.at(t)
            })
            .sum()
    }
}

fn render_camera(
    trace: &dyn PixelTracer,
    camera: &Camera,
    table: &RayTable,
    exposure: &[Isometry3<f64>],
    config: &RenderConfig,
    seed: u64,
    adaptive: bool,
) -> GrayImage {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let detail = match exposure {
        [still] if adaptive && table.per_pixel > 1 => trace.detail(camera, table, still),
        _ => None,
    };
    // The camera's poses through the exposure (one for a still one): each sample of a pixel
    // sees the scene from one of them, picked by a hash so neighbours differ.
    let poses: Vec<(Vector3<f64>, nalgebra::Rotation3<f64>)> = exposure
        .iter()
        .map(|p| (p.translation.vector, p.rotation.to_rotation_matrix()))
        .collect();
    let half_diag2 = (0.5 * w as f64).powi(2) + (0.5 * h as f64).powi(2);
    let vignette = |col: usize, row: usize| {
        let r2 = ((col as f64 - camera.cx).powi(2) + (row as f64 - camera.cy).powi(2)) / half_diag2;
        1.0 - config.vignetting * r2.min(1.0)
    };
    let noise = Normal::new(0.0, config.noise_sigma.max(0.0))
        .unwrap_or_else(|_| Normal::new(0.0, 0.0).expect("zero sigma"));
    let mut pixels = vec![0u8; w * h];
    pixels
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(row, pixel_row)| {
            let light = Light {
                half_distance_m: config.light_half_distance_m,
            };
            let mut world_rays = Vec::with_capacity(table.per_pixel);
            let mut radiance = vec![0.0f64; w];
            for (col, px) in radiance.iter_mut().enumerate() {
                let i = row * w + col;
                if !table.valid[i] {
                    continue;
                }
                world_rays.clear();
                if detail.as_ref().is_some_and(|d| !d[i]) {
                    // Every sample meets the surface the mean ray meets, which is shaded
                    // once per pixel anyway.
                    let (origin, rotation) = &poses[0];
                    world_rays.push((*origin, rotation * table.mean[i]));
                    let sum = trace.radiance_sum(&world_rays, light);
                    *px = sum * vignette(col, row);
                    continue;
                }
                let rays = &table.rays[i * table.per_pixel..(i + 1) * table.per_pixel];
                world_rays.extend(rays.iter().enumerate().map(|(k, ray)| {
                    let (origin, rotation) = &poses[if poses.len() > 1 {
                        (jitter(i as u64, (k + 1000) as u64).0 * poses.len() as f64) as usize
                            % poses.len()
                    } else {
                        0
                    }];
                    (*origin, rotation * ray)
                }));
                let sum = trace.radiance_sum(&world_rays, light);
                *px = sum / table.per_pixel as f64 * vignette(col, row);
            }
            // One noise stream per row (seed, row): deterministic whatever the thread count.
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                seed.wrapping_mul(1_000_003).wrapping_add(row as u64),
            );
            for (o, r) in pixel_row.iter_mut().zip(&radiance) {
                // Rounded to nearest (no libm call: the value is clamped non-negative first).
                *o = ((r * 255.0 + noise.sample(&mut rng)).clamp(0.0, 255.0) + 0.5) as u8;
            }
        });
    GrayImage::from_raw(w as u32, h as u32, pixels).unwrap_or_default()
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
        let walls = world
            .walls
            .iter()
            .filter(|w| {
                let s = &w.segment;
                wedges.sees((s.a.x, s.a.y), (s.b.x, s.b.y))
            })
            .map(WallSpan::new)
            .collect();
        // Tags seen from above are segments across their width (quiet zone included).
        let tags_in_view = (0..tags.len())
            .filter(|&k| {
                let t = &tags[k];
                let half = 0.5 * t.total_cells as f64 * t.cell_m;
                let (a, b) = (t.centre - t.right * half, t.centre + t.right * half);
                wedges.sees((a.x, a.y), (b.x, b.y))
            })
            .collect();
        let scene = Scene {
            walls,
            tags,
            tags_in_view,
            ceiling_m: config.ceiling_m,
        };
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

/// Ground truth of the tags visible in both cameras.
fn truths(
    world: &World,
    paints: &[TagPaint],
    rig: &StereoRig,
    wl: &Isometry3<f64>,
    config: &RenderConfig,
) -> Vec<TagTruth> {
    let wr = wl * rig.left_from_right();
    // Every wall, for what may hide a corner (the ceiling far above: only walls occlude).
    let occluders = Scene {
        walls: world.walls.iter().map(WallSpan::new).collect(),
        tags: Vec::new(),
        tags_in_view: Vec::new(),
        ceiling_m: config.ceiling_m + 100.0,
    };
    let mut truth = Vec::new();
    for (tag, paint) in world.tags.iter().zip(paints) {
        let corners = paint.corners(tag.size_m);
        let see = |cam: &Camera, world_from_cam: &Isometry3<f64>| -> Option<[[f64; 2]; 4]> {
            let eye = world_from_cam.translation.vector;
            if (eye - paint.centre).dot(&paint.normal) <= 0.0 {
                return None;
            }
            let mut out = [[0.0; 2]; 4];
            for (i, c) in corners.iter().enumerate() {
                let p = world_from_cam.inverse_transform_point(&Point3::from(*c));
                let px = cam.project(&p.coords)?;
                if px.x < 0.0
                    || px.y < 0.0
                    || px.x > cam.width as f64 - 1.0
                    || px.y > cam.height as f64 - 1.0
                {
                    return None;
                }
                // Nothing nearer along the ray to the corner (pulled 1 cm towards the camera).
                let d = c - eye;
                let (t, _) = occluders.hit(&eye, &d.normalize());
                if t < d.norm() - 0.01 {
                    return None;
                }
                out[i] = [px.x, px.y];
            }
            Some(out)
        };
        let (Some(l), Some(r)) = (see(&rig.left, wl), see(&rig.right, &wr)) else {
            continue;
        };
        let c_left = wl.inverse_transform_point(&Point3::from(paint.centre));
        truth.push(TagTruth {
            id: tag.id,
            family: tag.family,
            corners_world_m: corners.map(|c| [c.x, c.y, c.z]),
            centre_world_m: [paint.centre.x, paint.centre.y, paint.centre.z],
            left_corners_px: l,
            right_corners_px: r,
            centre_in_left_m: [c_left.x, c_left.y, c_left.z],
        });
    }
    truth
}

/// The tags of a world as the renderer paints them, to find which are in view without
/// rendering.
pub struct TagVisibility<'a> {
    world: &'a World,
    paints: Vec<TagPaint>,
}

impl<'a> TagVisibility<'a> {
    /// The world's tags, ready to be looked for; fails on a tag the renderer cannot paint.
    pub fn new(world: &'a World) -> Result<Self, RenderError> {
        let paints = world
            .tags
            .iter()
            .map(tag_paint)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { world, paints })
    }

    /// The tags a robot at `world_from_robot` sees in both cameras.
    pub fn seen(
        &self,
        rig: &StereoRig,
        world_from_robot: &Pose2,
        config: &RenderConfig,
    ) -> Vec<TagTruth> {
        truths(
            self.world,
            &self.paints,
            rig,
            &world_from_left(rig, world_from_robot),
            config,
        )
    }
}

/// The tags a robot at `world_from_robot` sees in both cameras, without rendering.
pub fn visible_tags(
    world: &World,
    rig: &StereoRig,
    world_from_robot: Pose2,
    config: &RenderConfig,
) -> Result<Vec<TagTruth>, RenderError> {
    Ok(TagVisibility::new(world)?.seen(rig, &world_from_robot, config))
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
        let spots: [(&str, &[(f64, f64)]); 3] = [
            ("office", &[(1.0, 6.3), (0.4, 7.1), (3.3, 3.7), (6.5, 0.6)]),
            ("museum", &[(5.0, 4.0), (9.0, 7.0), (15.5, 0.5), (0.5, 0.5)]),
            // Walls traced from a real building map: many short walls and wall ends, some
            // overlapping (which, traced ray by ray, once let rounding pick the wall).
            ("willow", &[(5.0, 7.0)]),
        ];
        for (name, spots) in spots {
            let path = root.join(format!("samples/{name}/world.yaml"));
            let world = crate::io::load_world(&path).unwrap().world;
            for &(x, y) in spots {
                for k in 0..12 {
                    let pose = Pose2::new(x, y, (k as f64 * 30.0).to_radians());
                    let staged = renderer.stage(&world, pose, &config, true).unwrap();
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
