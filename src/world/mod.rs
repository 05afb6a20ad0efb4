//! The world a robot moves in: walls, landmark tags, calibration targets and walking people.
//!
//! Walls are vertical planes standing on line segments. A world may also come from an occupancy
//! raster (a ROS map): [`walls_from_raster`] traces the boundary of the obstacle cells and simplifies
//! it into segments (Douglas-Peucker), so every later stage sees one kind of geometry.
//!
//! The *true corners* of a world are the segment end points: where two walls meet at an angle
//! (a room corner or a pillar's edge) or where a wall ends in the open (a door jamb). They are the
//! points that the sonar Hough transform is meant to find.

use crate::geometry::{ray_hit_circle, Pose2, RayHit, Segment};
use crate::visual::tags::TagFamily;
use nalgebra::{Point2, Vector2};
use serde::{Deserialize, Serialize};

/// Default wall height: a typical home's ceiling.
pub const DEFAULT_WALL_HEIGHT_M: f64 = 2.5;

/// A wall: a vertical plane on a floor segment.
#[derive(Debug, Clone, PartialEq)]
pub struct Wall {
    /// Floor segment, metres in the world frame.
    pub segment: Segment,
    /// Height, metres.
    pub height_m: f64,
}

/// An AprilTag fixed to a wall.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tag {
    /// Tag id within its family.
    pub id: u32,
    /// Tag family, as the AprilTag library names it.
    #[serde(default = "default_family")]
    pub family: TagFamily,
    /// Edge length of the black square, metres.
    pub size_m: f64,
    /// Centre of the tag in the world, metres.
    pub position_m: [f64; 3],
    /// Direction the tag faces (its outward normal), radians from the world x axis.
    pub yaw_rad: f64,
    /// How far the tag's face is turned up from the vertical, radians: 0 on a wall, 0.52 for a
    /// tag leaning back 30 degrees, pi/2 on the floor facing up, -pi/2 on the ceiling.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub pitch_rad: f64,
    /// How far the tag is turned about its normal, radians (counter-clockwise as one faces it).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub roll_rad: f64,
    /// The room corner the tag marks, if it marks one.
    #[serde(default)]
    pub corner_m: Option<[f64; 2]>,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Tag {
    /// `world_from_tag`'s rotation, in the tag frame stereotag uses throughout (x the outward
    /// normal, y to the right as one faces the tag, z up the printed tag): yaw about the world's
    /// z, then pitch (the normal raised by `pitch_rad`), then roll about the normal.
    pub fn rotation(&self) -> nalgebra::Rotation3<f64> {
        tag_rotation(self.roll_rad, self.pitch_rad, self.yaw_rad)
    }
}

/// `world_from_tag`'s rotation from a tag's roll, pitch and yaw (see [`Tag::rotation`]).
pub fn tag_rotation(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> nalgebra::Rotation3<f64> {
    nalgebra::Rotation3::from_euler_angles(roll_rad, -pitch_rad, yaw_rad)
}

/// A tag's roll, pitch and yaw from `world_from_tag`'s rotation (see [`Tag::rotation`]).
pub fn tag_roll_pitch_yaw(rotation: &nalgebra::Rotation3<f64>) -> [f64; 3] {
    let (roll, pitch, yaw) = rotation.euler_angles();
    [roll, -pitch, yaw]
}

fn default_family() -> TagFamily {
    TagFamily::Tag36h11
}

/// A calibration target standing in the world (used by the calibration renderer).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlacedTarget {
    /// Kalibr target YAML file, relative to the world file.
    pub target: String,
    /// Centre of the target, metres.
    pub position_m: [f64; 3],
    /// Direction the target faces, radians.
    pub yaw_rad: f64,
}

/// A person walking a path back and forth: a moving obstacle that returns sonar echoes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Person {
    /// Way points, metres; the person walks them in order and back.
    pub path_m: Vec<[f64; 2]>,
    /// Walking speed, m/s.
    #[serde(default = "default_walk_speed")]
    pub speed_mps: f64,
    /// Radius of the body seen by sonar, metres.
    #[serde(default = "default_body_radius")]
    pub radius_m: f64,
}

fn default_walk_speed() -> f64 {
    0.8
}
fn default_body_radius() -> f64 {
    0.2
}

impl Person {
    /// Position at time `t_s` (walking the path there and back, starting at its first point).
    pub fn position_at(&self, t_s: f64) -> Option<Point2<f64>> {
        let pts: Vec<Point2<f64>> = self
            .path_m
            .iter()
            .map(|p| Point2::new(p[0], p[1]))
            .collect();
        let first = *pts.first()?;
        let legs: Vec<f64> = pts.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
        let total: f64 = legs.iter().sum();
        if total <= 0.0 || self.speed_mps <= 0.0 {
            return Some(first);
        }
        let mut s = (t_s * self.speed_mps) % (2.0 * total);
        if s > total {
            s = 2.0 * total - s;
        }
        for (w, len) in pts.windows(2).zip(&legs) {
            if s <= *len {
                return Some(w[0] + (w[1] - w[0]) * (s / len.max(1e-12)));
            }
            s -= len;
        }
        pts.last().copied()
    }
}

/// Kind of a true corner.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VertexKind {
    /// Two walls meeting at an angle.
    Corner,
    /// A wall ending in the open (door jamb, wall end).
    End,
}

/// A true corner of the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Vertex {
    /// Position, metres.
    pub position: Point2<f64>,
    /// Corner or open end.
    pub kind: VertexKind,
    /// Unit directions along the walls leaving the vertex, sorted by angle (one for an end).
    pub directions: Vec<Vector2<f64>>,
}

impl Vertex {
    /// Whether a sonar at `viewer` sees this vertex as a concave corner (a corner reflector that
    /// sends the echo straight back) rather than a convex edge or wall end (a weak diffraction).
    pub fn is_concave_from(&self, viewer: Point2<f64>) -> bool {
        if self.directions.len() < 2 {
            return false;
        }
        let angle = |d: &Vector2<f64>| d.y.atan2(d.x);
        let v = viewer - self.position;
        let view = angle(&v);
        // The viewer lies in the free sector between two angularly adjacent walls, and that
        // sector is narrower than 180 degrees.
        let n = self.directions.len();
        (0..n).any(|i| {
            let a = angle(&self.directions[i]);
            let b = angle(&self.directions[(i + 1) % n]);
            let gap = (b - a).rem_euclid(std::f64::consts::TAU);
            let into = (view - a).rem_euclid(std::f64::consts::TAU);
            gap > 1e-6 && gap < std::f64::consts::PI - 1e-6 && into > 0.0 && into < gap
        })
    }
}

/// Everything the simulator and the scorer know about a place.
#[derive(Debug, Clone, Default)]
pub struct World {
    /// Walls.
    pub walls: Vec<Wall>,
    /// Landmark tags.
    pub tags: Vec<Tag>,
    /// Calibration targets.
    pub targets: Vec<PlacedTarget>,
    /// People walking about.
    pub people: Vec<Person>,
    /// Where the robot starts (`world_from_robot`).
    pub start: Pose2,
    /// The true corners, derived from the walls by [`World::new`].
    pub vertices: Vec<Vertex>,
}

/// End points closer than this are one vertex (metres).
const VERTEX_MERGE_M: f64 = 0.02;
/// Walls whose directions differ by less than this are collinear: their joint is no corner.
const COLLINEAR_RAD: f64 = 0.26; // 15 degrees

impl World {
    /// The tag of `family` and `id`, if the world has it.
    pub fn tag(&self, family: TagFamily, id: u32) -> Option<&Tag> {
        self.tags.iter().find(|t| t.id == id && t.family == family)
    }

    /// A world from its parts; the true corners are derived from the walls.
    pub fn new(
        walls: Vec<Wall>,
        tags: Vec<Tag>,
        targets: Vec<PlacedTarget>,
        people: Vec<Person>,
        start: Pose2,
    ) -> Self {
        let vertices = vertices_of(&walls);
        Self {
            walls,
            tags,
            targets,
            people,
            start,
            vertices,
        }
    }

    /// Axis-aligned bounds of the walls: (min, max), metres.
    pub fn bounds(&self) -> (Point2<f64>, Point2<f64>) {
        let mut lo = Point2::new(f64::INFINITY, f64::INFINITY);
        let mut hi = Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
        for w in &self.walls {
            for p in [w.segment.a, w.segment.b] {
                lo = Point2::new(lo.x.min(p.x), lo.y.min(p.y));
                hi = Point2::new(hi.x.max(p.x), hi.y.max(p.y));
            }
        }
        (lo, hi)
    }

    /// The first wall a ray meets, within `max_m`.
    pub fn ray_cast_walls(
        &self,
        origin: Point2<f64>,
        dir: Vector2<f64>,
        max_m: f64,
    ) -> Option<RayHit> {
        let mut best: Option<RayHit> = None;
        for w in &self.walls {
            if let Some(h) = w
                .segment
                .ray_hit(origin, dir, best.map_or(max_m, |b| b.range_m))
            {
                best = Some(h);
            }
        }
        best
    }

    /// The first person a ray meets at time `t_s`, within `max_m`.
    pub fn ray_cast_people(
        &self,
        t_s: f64,
        origin: Point2<f64>,
        dir: Vector2<f64>,
        max_m: f64,
    ) -> Option<RayHit> {
        let mut best: Option<RayHit> = None;
        for p in &self.people {
            let Some(c) = p.position_at(t_s) else {
                continue;
            };
            if let Some(h) = ray_hit_circle(
                origin,
                dir,
                c,
                p.radius_m,
                best.map_or(max_m, |b| b.range_m),
            ) {
                best = Some(h);
            }
        }
        best
    }

    /// The nearest wall point to `p` within `max_m`, with its distance.
    pub fn nearest_wall_point(&self, p: Point2<f64>, max_m: f64) -> Option<(Point2<f64>, f64)> {
        let mut best: Option<(Point2<f64>, f64)> = None;
        for w in &self.walls {
            let q = w.segment.closest_point(p);
            let d = (p - q).norm();
            if d <= max_m && best.is_none_or(|b| d < b.1) {
                best = Some((q, d));
            }
        }
        best
    }

    /// Whether the straight line from `a` to `b` crosses no wall.
    pub fn line_of_sight(&self, a: Point2<f64>, b: Point2<f64>) -> bool {
        let d = b - a;
        let len = d.norm();
        if len < 1e-9 {
            return true;
        }
        self.ray_cast_walls(a, d / len, len - 1e-6).is_none()
    }
}

fn vertices_of(walls: &[Wall]) -> Vec<Vertex> {
    // Collect end points with the direction of the wall leaving them, then merge coincident ones.
    let mut ends: Vec<(Point2<f64>, Vector2<f64>)> = Vec::new();
    for w in walls {
        let d = w.segment.b - w.segment.a;
        let len = d.norm();
        if len < 1e-9 {
            continue;
        }
        ends.push((w.segment.a, d / len));
        ends.push((w.segment.b, -d / len));
    }
    let mut used = vec![false; ends.len()];
    let mut out = Vec::new();
    for i in 0..ends.len() {
        if used[i] {
            continue;
        }
        used[i] = true;
        let mut dirs = vec![ends[i].1];
        for j in i + 1..ends.len() {
            if !used[j] && (ends[j].0 - ends[i].0).norm() < VERTEX_MERGE_M {
                used[j] = true;
                dirs.push(ends[j].1);
            }
        }
        let position = ends[i].0;
        dirs.sort_by(|a, b| a.y.atan2(a.x).total_cmp(&b.y.atan2(b.x)));
        match dirs.len() {
            1 => out.push(Vertex {
                position,
                kind: VertexKind::End,
                directions: dirs,
            }),
            2 => {
                // Opposite directions: a straight joint, not a corner.
                let angle = dirs[0].dot(&dirs[1]).clamp(-1.0, 1.0).acos();
                if (std::f64::consts::PI - angle) > COLLINEAR_RAD {
                    out.push(Vertex {
                        position,
                        kind: VertexKind::Corner,
                        directions: dirs,
                    });
                }
            }
            // Three or more walls meet (a T joint): one vertex, concave on the narrow sides.
            _ => out.push(Vertex {
                position,
                kind: VertexKind::Corner,
                directions: dirs,
            }),
        }
    }
    out
}

/// An occupancy raster: `width * height` cells, row 0 at the *top* (as in a PGM image).
#[derive(Debug, Clone)]
pub struct Raster {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `true` where the cell is an obstacle, row-major from the top row.
    pub obstacle: Vec<bool>,
    /// Cell size, metres.
    pub resolution_m: f64,
    /// World position of the lower-left corner of the bottom-left cell, metres.
    pub origin_m: [f64; 2],
}

impl Raster {
    fn is_obstacle(&self, col: i64, row: i64) -> bool {
        // Outside the raster counts as obstacle so that the traced boundary is closed.
        if col < 0 || row < 0 || col >= self.width as i64 || row >= self.height as i64 {
            return true;
        }
        self.obstacle[row as usize * self.width + col as usize]
    }

    /// Removes obstacle blobs smaller than `min_cells` (laser speckle in scanned maps).
    pub fn remove_specks(&mut self, min_cells: usize) {
        let mut label = vec![false; self.obstacle.len()];
        for start in 0..self.obstacle.len() {
            if !self.obstacle[start] || label[start] {
                continue;
            }
            let mut blob = vec![start];
            label[start] = true;
            let mut k = 0;
            while k < blob.len() {
                let i = blob[k];
                k += 1;
                let (r, c) = ((i / self.width) as i64, (i % self.width) as i64);
                for (dr, dc) in [
                    (-1, 0),
                    (1, 0),
                    (0, -1),
                    (0, 1),
                    (-1, -1),
                    (-1, 1),
                    (1, -1),
                    (1, 1),
                ] {
                    let (rr, cc) = (r + dr, c + dc);
                    if rr < 0 || cc < 0 || rr >= self.height as i64 || cc >= self.width as i64 {
                        continue;
                    }
                    let j = rr as usize * self.width + cc as usize;
                    if self.obstacle[j] && !label[j] {
                        label[j] = true;
                        blob.push(j);
                    }
                }
            }
            if blob.len() < min_cells {
                for i in blob {
                    self.obstacle[i] = false;
                }
            }
        }
    }
}

/// Traces the boundary between obstacle and free cells of a raster and simplifies each closed
/// boundary into wall segments with at most `tolerance_m` deviation (Douglas-Peucker).
pub fn walls_from_raster(raster: &Raster, tolerance_m: f64, height_m: f64) -> Vec<Wall> {
    use std::collections::HashMap;
    // Lattice vertices are (col, row) corners with row counted from the top; each boundary edge is
    // directed so that the free cell lies on its left when looking along it in image coordinates.
    let mut out_edges: HashMap<(i64, i64), Vec<(i64, i64)>> = HashMap::new();
    for row in 0..raster.height as i64 {
        for col in 0..raster.width as i64 {
            if raster.is_obstacle(col, row) {
                continue;
            }
            // Free cell: an edge on each side that borders an obstacle, walking the cell clockwise
            // in image coordinates (y down), so edges chain consistently around each free region.
            if raster.is_obstacle(col, row - 1) {
                out_edges
                    .entry((col, row))
                    .or_default()
                    .push((col + 1, row));
            }
            if raster.is_obstacle(col + 1, row) {
                out_edges
                    .entry((col + 1, row))
                    .or_default()
                    .push((col + 1, row + 1));
            }
            if raster.is_obstacle(col, row + 1) {
                out_edges
                    .entry((col + 1, row + 1))
                    .or_default()
                    .push((col, row + 1));
            }
            if raster.is_obstacle(col - 1, row) {
                out_edges
                    .entry((col, row + 1))
                    .or_default()
                    .push((col, row));
            }
        }
    }
    let mut starts: Vec<(i64, i64)> = out_edges.keys().copied().collect();
    starts.sort_unstable();
    let mut walls = Vec::new();
    for s in starts {
        while let Some(next) = out_edges.get_mut(&s).and_then(|v| v.pop()) {
            let mut chain = vec![s, next];
            let mut cur = next;
            while cur != s {
                let Some(n) = out_edges.get_mut(&cur).and_then(|v| v.pop()) else {
                    break;
                };
                chain.push(n);
                cur = n;
            }
            let pts: Vec<Point2<f64>> = chain
                .iter()
                .map(|&(c, r)| {
                    Point2::new(
                        raster.origin_m[0] + c as f64 * raster.resolution_m,
                        raster.origin_m[1]
                            + (raster.height as i64 - r) as f64 * raster.resolution_m,
                    )
                })
                .collect();
            let simple = simplify_closed(&pts, tolerance_m);
            for w in simple.windows(2) {
                walls.push(Wall {
                    segment: Segment::new(w[0], w[1]),
                    height_m,
                });
            }
        }
    }
    walls
}

fn simplify_closed(pts: &[Point2<f64>], tol: f64) -> Vec<Point2<f64>> {
    if pts.len() < 4 {
        return pts.to_vec();
    }
    // Split the loop at its first point and the point farthest from it, then simplify each half.
    let far = (1..pts.len() - 1)
        .max_by(|&a, &b| {
            (pts[a] - pts[0])
                .norm()
                .total_cmp(&(pts[b] - pts[0]).norm())
        })
        .unwrap_or(1);
    let mut out = douglas_peucker(&pts[..=far], tol);
    out.pop();
    out.extend(douglas_peucker(&pts[far..], tol));
    out
}

fn douglas_peucker(pts: &[Point2<f64>], tol: f64) -> Vec<Point2<f64>> {
    if pts.len() < 3 {
        return pts.to_vec();
    }
    let seg = Segment::new(pts[0], pts[pts.len() - 1]);
    let (idx, dmax) = pts[1..pts.len() - 1]
        .iter()
        .enumerate()
        .map(|(i, p)| (i + 1, seg.distance_to(*p)))
        .fold((0, -1.0), |acc, x| if x.1 > acc.1 { x } else { acc });
    if dmax > tol {
        let mut left = douglas_peucker(&pts[..=idx], tol);
        left.pop();
        left.extend(douglas_peucker(&pts[idx..], tol));
        left
    } else {
        vec![pts[0], pts[pts.len() - 1]]
    }
}

/// A closed rectangular room from (0, 0) to (`width_m`, `height_m`), for tests.
#[cfg(test)]
pub(crate) fn rectangle_world(width_m: f64, height_m: f64, start: Pose2) -> World {
    let p = |x, y| Point2::new(x, y);
    let pts = [
        p(0.0, 0.0),
        p(width_m, 0.0),
        p(width_m, height_m),
        p(0.0, height_m),
        p(0.0, 0.0),
    ];
    let walls = pts
        .windows(2)
        .map(|w| Wall {
            segment: Segment::new(w[0], w[1]),
            height_m: DEFAULT_WALL_HEIGHT_M,
        })
        .collect();
    World::new(walls, vec![], vec![], vec![], start)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_room() -> World {
        rectangle_world(4.0, 3.0, Pose2::new(1.0, 1.0, 0.0))
    }

    #[test]
    fn room_has_four_concave_corners() {
        let w = square_room();
        assert_eq!(w.vertices.len(), 4);
        assert!(w.vertices.iter().all(|v| v.kind == VertexKind::Corner));
        for v in &w.vertices {
            assert!(v.is_concave_from(Point2::new(2.0, 1.5)), "{v:?}");
        }
        // Seen from outside, beyond both of its walls, a room corner is convex.
        let corner = w
            .vertices
            .iter()
            .find(|v| v.position == Point2::new(4.0, 0.0))
            .unwrap();
        assert!(!corner.is_concave_from(Point2::new(5.0, -1.0)));
    }

    #[test]
    fn raster_box_traces_to_four_walls() {
        // A 10 x 8 free area inside a one-cell obstacle border.
        let (w, h) = (12, 10);
        let mut obstacle = vec![false; w * h];
        for r in 0..h {
            for c in 0..w {
                obstacle[r * w + c] = r == 0 || c == 0 || r == h - 1 || c == w - 1;
            }
        }
        let raster = Raster {
            width: w,
            height: h,
            obstacle,
            resolution_m: 0.1,
            origin_m: [0.0, 0.0],
        };
        let walls = walls_from_raster(&raster, 0.01, 2.5);
        assert_eq!(walls.len(), 4, "{walls:?}");
        let total: f64 = walls.iter().map(|w| w.segment.length()).sum();
        assert!((total - 2.0 * (1.0 + 0.8)).abs() < 1e-9);
    }

    #[test]
    fn person_walks_there_and_back() {
        let p = Person {
            path_m: vec![[0.0, 0.0], [2.0, 0.0]],
            speed_mps: 1.0,
            radius_m: 0.2,
        };
        assert!((p.position_at(1.0).unwrap().x - 1.0).abs() < 1e-12);
        assert!((p.position_at(3.0).unwrap().x - 1.0).abs() < 1e-12);
    }
}
