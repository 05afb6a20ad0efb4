//! Scores of a map and its features against a known world.
//!
//! * **Occupied precision**: of the cells the map calls occupied, the share within one cell
//!   (8-neighbourhood) of a true wall cell.
//! * **Occupied recall**: of the true wall cells the map has observed (counts in the cell itself),
//!   the share with an occupied map cell within one cell.
//! * **Free accuracy**: of the cells the map calls free, the share that hold no wall.
//! * **Feature precision**: of the features, the share within 15 cm of a true corner (a wall end
//!   point: room corner, pillar edge, door jamb).
//! * **Feature recall**: of the true corners that came within 1.5 m of a sonar with a clear line of
//!   sight, the share with a feature within 15 cm.

use crate::sonar::grid::{GridGeometry, OccupancyMap};
use crate::sonar::hough::Feature;
use crate::world::World;
use nalgebra::Point2;
use serde::Serialize;

/// A feature matches a true corner within this distance: 15 cm (issue 2).
pub const FEATURE_TOLERANCE_M: f64 = 0.15;
/// Corners this close to a sonar position count for recall: 1.5 m (issue 2).
pub const CORNER_VISIBLE_M: f64 = 1.5;

/// Map scores.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MapScore {
    /// See the module docs.
    pub occupied_precision: f64,
    /// See the module docs.
    pub occupied_recall: f64,
    /// See the module docs.
    pub free_accuracy: f64,
}

/// Feature scores.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FeatureScore {
    /// See the module docs.
    pub precision: f64,
    /// See the module docs.
    pub recall: f64,
    /// Features found.
    pub features: usize,
    /// True corners that came near a sonar.
    pub reachable_corners: usize,
}

fn ratio(num: usize, den: usize) -> f64 {
    if den == 0 {
        f64::NAN
    } else {
        num as f64 / den as f64
    }
}

/// Points this close below a cell boundary are taken to lie on it: 1 µm.
const BOUNDARY_M: f64 = 1e-6;

/// Cells crossed by a wall. A wall lying on a boundary between cells (the samples' walls at whole
/// multiples of the cell size) is given to the cell above the boundary, as exact arithmetic would:
/// without the nudge, rounding decides (16.0 m from an origin at -0.2 m is cell 80.99999999999999,
/// from 0 it is 80).
pub fn wall_cells(world: &World, g: &GridGeometry) -> Vec<bool> {
    let mut truth = vec![false; g.width * g.height];
    let step = 0.25 * g.resolution_m;
    for w in &world.walls {
        let n = (w.segment.length() / step).ceil().max(1.0) as usize;
        for k in 0..=n {
            let p = w.segment.a + (w.segment.b - w.segment.a) * (k as f64 / n as f64);
            if let Some((c, r)) = g.cell_of(p.x + BOUNDARY_M, p.y + BOUNDARY_M) {
                truth[r * g.width + c] = true;
            }
        }
    }
    truth
}

fn any_near(flags: &[bool], g: &GridGeometry, idx: usize) -> bool {
    let (c0, r0) = ((idx % g.width) as i64, (idx / g.width) as i64);
    for dr in -1..=1 {
        for dc in -1..=1 {
            let (c, r) = (c0 + dc, r0 + dr);
            if c >= 0
                && r >= 0
                && c < g.width as i64
                && r < g.height as i64
                && flags[r as usize * g.width + c as usize]
            {
                return true;
            }
        }
    }
    false
}

/// Scores a map against the world's walls.
pub fn score_map(map: &OccupancyMap, world: &World) -> MapScore {
    score_map_against(map, &wall_cells(world, &map.geometry))
}

/// Scores a map against reference wall cells on its own grid (row-major from the bottom row, as
/// [`wall_cells`] gives them, or the occupied cells of a reference map such as a laser's).
///
/// # Panics
/// When `truth` is not one flag a cell of the map's grid.
pub fn score_map_against(map: &OccupancyMap, truth: &[bool]) -> MapScore {
    let g = &map.geometry;
    assert_eq!(
        truth.len(),
        g.width * g.height,
        "the reference is on another grid"
    );
    let occupied: Vec<bool> = (0..truth.len()).map(|i| map.is_occupied(i)).collect();
    let (mut occ, mut occ_ok, mut walls_seen, mut walls_found, mut free, mut free_ok) =
        (0, 0, 0, 0, 0, 0);
    for i in 0..truth.len() {
        if occupied[i] {
            occ += 1;
            occ_ok += any_near(truth, g, i) as usize;
        }
        if truth[i] && map.occupancy[i].is_some() {
            walls_seen += 1;
            walls_found += any_near(&occupied, g, i) as usize;
        }
        if map.is_free(i) {
            free += 1;
            free_ok += (!truth[i]) as usize;
        }
    }
    MapScore {
        occupied_precision: ratio(occ_ok, occ),
        occupied_recall: ratio(walls_found, walls_seen),
        free_accuracy: ratio(free_ok, free),
    }
}

/// Scores features against the world's true corners; `sonar_positions` are where the sonars were.
pub fn score_features(
    features: &[Feature],
    world: &World,
    sonar_positions: &[Point2<f64>],
) -> FeatureScore {
    let near_corner = |x: f64, y: f64| {
        world
            .vertices
            .iter()
            .any(|v| (v.position.x - x).hypot(v.position.y - y) <= FEATURE_TOLERANCE_M)
    };
    let good = features
        .iter()
        .filter(|f| near_corner(f.x_m, f.y_m))
        .count();
    let mut reachable = 0;
    let mut found = 0;
    for v in &world.vertices {
        let seen = sonar_positions.iter().any(|s| {
            let d = v.position - s;
            let dist = d.norm();
            // Stop just short of the corner so its own walls do not block the view.
            dist <= CORNER_VISIBLE_M
                && world.line_of_sight(*s, s + d * ((dist - 0.03).max(0.0) / dist.max(1e-9)))
        });
        if !seen {
            continue;
        }
        reachable += 1;
        if features
            .iter()
            .any(|f| (v.position.x - f.x_m).hypot(v.position.y - f.y_m) <= FEATURE_TOLERANCE_M)
        {
            found += 1;
        }
    }
    FeatureScore {
        precision: ratio(good, features.len()),
        recall: ratio(found, reachable),
        features: features.len(),
        reachable_corners: reachable,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Pose2, Segment};
    use crate::world::Wall;

    fn one_wall(a: [f64; 2], b: [f64; 2]) -> World {
        let wall = Wall {
            segment: Segment {
                a: Point2::new(a[0], a[1]),
                b: Point2::new(b[0], b[1]),
            },
            height_m: 2.0,
        };
        World::new(
            vec![wall],
            vec![],
            vec![],
            vec![],
            Pose2::new(1.0, 1.0, 0.0),
        )
    }

    fn geometry(origin: f64) -> GridGeometry {
        GridGeometry {
            width: 100,
            height: 100,
            resolution_m: 0.2,
            origin_m: [origin, origin],
        }
    }

    #[test]
    fn a_wall_on_a_cell_boundary_gets_the_same_cell_whatever_the_origin() {
        // x = 16 m is a cell boundary with either origin; 16.2 / 0.2 rounds down to 80.99999...
        let world = one_wall([16.0, 1.1], [16.0, 1.9]);
        for origin in [0.0, -0.2] {
            let g = geometry(origin);
            let truth = wall_cells(&world, &g);
            let row = ((1.5 - origin) / 0.2).floor() as usize;
            let cols: Vec<f64> = (0..g.width)
                .filter(|&c| truth[row * g.width + c])
                .map(|c| origin + c as f64 * 0.2)
                .collect();
            assert_eq!(cols.len(), 1, "origin {origin}");
            assert!((cols[0] - 16.0).abs() < 1e-9, "origin {origin}: {cols:?}");
        }
    }
}
