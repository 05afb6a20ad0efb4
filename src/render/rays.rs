//! Each pixel's sample rays, precomputed through the camera model; the light; and the image of
//! one camera traced row by row in parallel, with sensor noise.

use super::*;
use crate::camera::Camera;
use image::GrayImage;
use nalgebra::{Isometry3, Point2, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

/// Unit ray directions in the camera frame of the samples of every pixel, row-major.
#[derive(Debug, Clone)]
pub(crate) struct RayTable {
    /// Samples per pixel (`n x n` strata).
    pub(super) per_pixel: usize,
    /// `per_pixel` rays per pixel.
    pub(super) rays: Vec<Vector3<f64>>,
    /// The mean direction of each pixel's samples.
    pub(super) mean: Vec<Vector3<f64>>,
    /// Whether the pixel's rays exist (a fisheye's pixels beyond its field have none).
    pub(super) valid: Vec<bool>,
    /// Largest angle of a ray from the optical axis, radians.
    pub(super) max_off_axis_rad: f64,
}

/// A deterministic point in [0, 1)² for sample `k` of pixel `i`.
pub(super) fn jitter(i: u64, k: u64) -> (f64, f64) {
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
    pub(super) fn new(camera: &Camera, n: usize) -> Self {
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
pub(super) type Wedge = ((f64, f64), [(f64, f64); 2]);

/// The horizontal wedges that hold the cones of the cameras' rays, for culling what no camera
/// can see.
pub(super) struct ViewWedges {
    /// Per view: the camera's position and the inward normals of the wedge's two sides; `None`
    /// when some cone takes in the vertical (a fisheye, a steep tilt) and nothing is culled.
    pub(super) wedges: Option<Vec<Wedge>>,
}

impl ViewWedges {
    /// Wedges of `views`: camera poses in the world with the largest angle of their rays from the
    /// optical axis.
    pub(super) fn new(views: &[(Isometry3<f64>, f64)]) -> Self {
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
    pub(super) fn sees(&self, a: (f64, f64), b: (f64, f64)) -> bool {
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
    pub(super) half_distance_m: f64,
}

impl Light {
    /// Light at distance `t` (0.2 for a ray that meets nothing).
    #[inline]
    pub(super) fn at(self, t: f64) -> f64 {
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

pub(super) fn render_camera(
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
