//! The scene a ray meets: floor, ceiling, walls up to their height and tags, the nearest
//! surface shaded with its texture and light.

use super::first_walls::FirstWalls;
use super::walls_grid::Occlusion;
use super::*;
use crate::camera::Camera;
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;

/// A distance along a ray kept as `num / den` (`den` >= 0; `den` = 0 is infinitely far), so
/// that comparing candidates costs no division.
#[derive(Debug, Clone, Copy)]
pub(super) struct Fraction {
    pub(super) num: f64,
    pub(super) den: f64,
}

impl Fraction {
    const INFINITE: Self = Self { num: 1.0, den: 0.0 };

    pub(super) fn value(self) -> f64 {
        if self.den > 0.0 {
            self.num / self.den
        } else {
            f64::INFINITY
        }
    }
}

/// A wall as [`Scene::hit`] tests it: its floor segment `a + u e`, `u` in [0, 1], and its
/// height; `unit` is `e` normalised (the texture's axis along the wall).
#[derive(Debug, Clone, Copy)]
pub(super) struct WallSpan {
    pub(super) a: (f64, f64),
    pub(super) e: (f64, f64),
    pub(super) unit: (f64, f64),
    pub(super) height_m: f64,
}

impl WallSpan {
    pub(super) fn new(wall: &crate::world::Wall) -> Self {
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
pub(super) struct Scene {
    /// The walls that can be in view.
    pub(super) walls: Vec<WallSpan>,
    /// The walls binned for rays to walk, for worlds of many walls
    /// ([`super::walls_grid::GRID_FROM_WALLS`]).
    pub(super) grid: Option<super::walls_grid::WallGrid>,
    /// Rays walk the grid (else they test every wall: the reference it is measured against).
    pub(super) walk_grid: bool,
    /// Leave out of the detail mask the wall edges that walls reaching the ceiling hide (with
    /// the grid, for worlds of many walls: most of their walls are behind others).
    pub(super) occlusion_mask: bool,
    /// Per still camera, the wall each wedge of its rays meets first where that is proven (with
    /// the grid; see [`super::first_walls`]).
    pub(super) first_walls: Vec<FirstWalls>,
    pub(super) tags: Vec<TagPaint>,
    /// The tags that can be in view (indices into `tags`).
    pub(super) tags_in_view: Vec<usize>,
    pub(super) ceiling_m: f64,
}

/// What a ray meets first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Surface {
    Sky,
    Floor,
    Ceiling,
    /// A wall, by its place in [`Scene::walls`].
    Wall(usize),
    /// A tag, with its albedo where the ray meets it.
    Tag(f64),
}

impl Scene {
    /// A scene of these walls and tags; the walls binned in a grid when there are many.
    pub(super) fn new(
        walls: Vec<WallSpan>,
        tags: Vec<TagPaint>,
        tags_in_view: Vec<usize>,
        ceiling_m: f64,
    ) -> Self {
        let grid = if walls.len() > super::walls_grid::GRID_FROM_WALLS {
            super::walls_grid::WallGrid::new(&walls)
        } else {
            None
        };
        let occlusion_mask =
            grid.is_some() && walls.len() > super::walls_grid::OCCLUSION_FROM_WALLS;
        Self {
            walls,
            occlusion_mask,
            walk_grid: true,
            grid,
            first_walls: Vec::new(),
            tags,
            tags_in_view,
            ceiling_m,
        }
    }

    /// Proves the first walls of the wedges of rays of cameras standing still at these poses,
    /// whose rays lie within the given angles of their axes (with the grid only: a world of few
    /// walls tests them all).
    pub(super) fn prove_first_walls(&mut self, views: &[(Isometry3<f64>, f64)]) {
        let Some(grid) = self.grid.as_ref().filter(|_| self.walk_grid) else {
            return;
        };
        self.first_walls = views
            .iter()
            .filter_map(|(pose, off_axis_rad)| {
                FirstWalls::new(
                    grid,
                    &self.walls,
                    self.ceiling_m,
                    &pose.translation.vector,
                    &(pose.rotation * Vector3::z()),
                    *off_axis_rad,
                )
            })
            .collect();
    }

    /// The scene without its wall grid: every wall tested for every ray (for comparisons).
    #[cfg(test)]
    pub(super) fn without_grid(mut self) -> Self {
        self.walk_grid = false;
        self.first_walls.clear();
        self
    }

    /// Distance along a ray to the first surface, and the surface.
    pub(super) fn hit(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> (f64, Surface) {
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
            let proven = self.first_walls.iter().find_map(|f| f.lookup(origin, dir));
            if let Some(k) = proven {
                let w = &self.walls[k];
                if let Some(t) = wall_hit((w.a, w.e, w.height_m), origin, dir, best.0) {
                    best = (t, Surface::Wall(k));
                }
            } else {
                self.walk(origin, dir, &mut best);
            }
        }
        for &k in &self.tags_in_view {
            if let Some((t, albedo)) = self.tags[k].hit(origin, dir, best.0) {
                best = (t, Surface::Tag(albedo));
            }
        }
        (best.0.value(), best.1)
    }

    /// The nearest wall along a ray nearer than `best`, walking the grid (or testing every wall
    /// without one).
    fn walk(&self, origin: &Vector3<f64>, dir: &Vector3<f64>, best: &mut (Fraction, Surface)) {
        match self.grid.as_ref().filter(|_| self.walk_grid) {
            None => {
                for (k, w) in self.walls.iter().enumerate() {
                    if let Some(t) = wall_hit((w.a, w.e, w.height_m), origin, dir, best.0) {
                        *best = (t, Surface::Wall(k));
                    }
                }
            }
            // Cell by cell, nearest first: a wall's hit is taken in the cell that holds it (its
            // parameter before the cell's exit; its walls in increasing index, so overlapping
            // walls resolve as one by one), and the walk stops at the first cell that leaves
            // something nearer than its exit.
            Some(grid) => grid.walk((origin.x, origin.y), (dir.x, dir.y), |cell| {
                for w in grid.walls(cell) {
                    if let Some(t) = wall_hit((w.a, w.e, w.height_m), origin, dir, best.0) {
                        if t.num <= cell.exit_t * t.den {
                            *best = (t, Surface::Wall(w.k as usize));
                        }
                    }
                }
                best.0.num > cell.exit_t * best.0.den
            }),
        }
    }

    /// Albedo of a surface at a point on it.
    pub(super) fn shade(&self, surface: Surface, p: &Vector3<f64>) -> f64 {
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
pub(super) const SHADED_PER_PIXEL: usize = 4;

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
        // Each wall's foot, top (or where it meets the ceiling) and ends; in a large world, not
        // where the walls that reach the ceiling hide them.
        let eye = world_from_camera.translation.vector;
        let mut occlusion = self
            .grid
            .as_ref()
            .filter(|_| self.occlusion_mask)
            .map(|g| Occlusion::new(g, self.ceiling_m, (eye.x, eye.y)));
        // The ends, each traced once: the walls of a polyline (a traced map's) share theirs.
        let mut ends = std::collections::HashSet::new();
        for wall in &self.walls {
            let far = (wall.a.0 + wall.e.0, wall.a.1 + wall.e.1);
            if occlusion
                .as_ref()
                .is_some_and(|o| o.hides_segment(wall.a, far))
            {
                continue;
            }
            let a = Vector3::new(wall.a.0, wall.a.1, 0.0);
            let b = a + Vector3::new(wall.e.0, wall.e.1, 0.0);
            let height_m = wall.height_m.min(self.ceiling_m);
            let up = Vector3::new(0.0, 0.0, height_m);
            for (p, q) in [(a, b), (a + up, b + up)] {
                match occlusion.as_mut() {
                    None => view.trace(&p, &q, &mut |x, y| mask.mark_around(x, y)),
                    Some(occlusion) => view.trace_points(&p, &q, &mut |x, y, c| {
                        let w = world_from_camera.transform_point(&nalgebra::Point3::from(*c));
                        if !occlusion.hidden((w.x, w.y)) {
                            mask.mark_around(x, y);
                        }
                    }),
                }
            }
            for end in [a, b] {
                let key = (end.x.to_bits(), end.y.to_bits(), height_m.to_bits());
                // An end is hidden or not at every height alike.
                if ends.insert(key) && !occlusion.as_mut().is_some_and(|o| o.hidden((end.x, end.y)))
                {
                    view.trace(&end, &(end + up), &mut |x, y| mask.mark_around(x, y));
                }
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

/// Where the ray meets a wall (its floor segment `a + u e`, between the floor and its height)
/// when that is nearer than `best` by more than a part in 10^9: of walls that overlap (traced
/// maps have them) the first tested always wins, rather than rounding deciding ray by ray.
#[inline]
fn wall_hit(
    (a, e, height_m): ((f64, f64), (f64, f64), f64),
    origin: &Vector3<f64>,
    dir: &Vector3<f64>,
    best: Fraction,
) -> Option<Fraction> {
    // The wall as origin + t dir (t along the 3D ray) meeting a + u e, u in [0, 1]:
    // t = tn / d and u = un / d, with the signs folded into the numerators so that d > 0.
    let (ex, ey) = e;
    let denom = dir.x * ey - dir.y * ex;
    let (wx, wy) = (a.0 - origin.x, a.1 - origin.y);
    let (tn, un) = (wx * ey - wy * ex, wx * dir.y - wy * dir.x);
    let (tn, un, d) = if denom < 0.0 {
        (-tn, -un, -denom)
    } else {
        (tn, un, denom)
    };
    if d < 1e-12
        || tn <= 1e-9 * d
        || tn * best.den >= best.num * d * (1.0 - 1e-9)
        || un < 0.0
        || un > d
    {
        return None;
    }
    // The height met, times d.
    let z = origin.z * d + dir.z * tn;
    if z < 0.0 || z > height_m * d {
        return None;
    }
    Some(Fraction { num: tn, den: d })
}
