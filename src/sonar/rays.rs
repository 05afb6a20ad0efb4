//! A counting grid of thin rays: the beam model of a laser. Each beam makes every cell it
//! crosses before its return a miss and the cell of its return a hit (no cone, no arc); a beam
//! with no return is a miss up to the range given. Cells are occupied by the same counting rule
//! and thresholds as the sonar's grid ([`super::grid::CountingGrid`]).

use super::grid::{GridConfig, GridError, GridGeometry, OccupancyMap};

/// The thin-ray counting grid.
#[derive(Debug, Clone)]
pub struct RayGrid {
    config: GridConfig,
    geometry: GridGeometry,
    hits: Vec<u32>,
    misses: Vec<u32>,
    /// The cells of the ray being walked (each counted once a ray).
    visited: Vec<usize>,
}

impl RayGrid {
    /// An empty grid.
    pub fn new(config: GridConfig) -> Result<Self, GridError> {
        config.validate()?;
        let geometry = GridGeometry::from_config(&config);
        let n = geometry.width * geometry.height;
        Ok(RayGrid {
            config,
            geometry,
            hits: vec![0; n],
            misses: vec![0; n],
            visited: Vec::new(),
        })
    }

    /// Inserts one beam from `origin` (metres) along `bearing_rad`: a return at `range_m`, or
    /// none within `reach_m` (`range_m` `None`).
    pub fn insert(
        &mut self,
        origin: [f64; 2],
        bearing_rad: f64,
        range_m: Option<f64>,
        reach_m: f64,
    ) {
        let length = range_m.unwrap_or(reach_m);
        if !(length.is_finite() && length > 0.0) {
            return;
        }
        let g = &self.geometry;
        let (dx, dy) = (bearing_rad.cos(), bearing_rad.sin());
        let end = g.cell_of(origin[0] + length * dx, origin[1] + length * dy);
        // Quarter-cell steps: no cell the ray crosses for more than a quarter cell is missed.
        let step = 0.25 * g.resolution_m;
        let n = (length / step).ceil() as usize;
        self.visited.clear();
        for k in 0..n {
            let s = k as f64 * step;
            let Some((c, r)) = g.cell_of(origin[0] + s * dx, origin[1] + s * dy) else {
                continue;
            };
            if Some((c, r)) == end && range_m.is_some() {
                break;
            }
            let idx = r * g.width + c;
            if self.visited.last() != Some(&idx) {
                self.visited.push(idx);
            }
        }
        for &idx in &self.visited {
            self.misses[idx] += 1;
        }
        if let (Some((c, r)), Some(_)) = (end, range_m) {
            self.hits[r * g.width + c] += 1;
        }
    }

    /// Hit and miss tallies of a cell.
    pub fn counts(&self, idx: usize) -> (u32, u32) {
        (self.hits[idx], self.misses[idx])
    }

    /// The map: a cell's share of hits where it has at least `min_evidence` beams.
    pub fn map(&self) -> OccupancyMap {
        let enough = self.config.min_evidence.max(1);
        OccupancyMap {
            geometry: self.geometry.clone(),
            occupancy: self
                .hits
                .iter()
                .zip(&self.misses)
                .map(|(&h, &m)| (h + m >= enough).then(|| h as f64 / (h + m) as f64))
                .collect(),
            occupied_threshold: self.config.occupied_threshold,
            free_threshold: self.config.free_threshold,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_beam_misses_the_cells_before_its_return_and_hits_the_last() {
        let config = GridConfig {
            width_cells: 10,
            height_cells: 3,
            resolution_m: 1.0,
            origin_m: [0.0, 0.0],
            min_evidence: 1,
            ..GridConfig::default()
        };
        let mut grid = RayGrid::new(config).unwrap();
        for _ in 0..3 {
            grid.insert([0.5, 1.5], 0.0, Some(6.2), 20.0);
        }
        for c in 0..6 {
            assert_eq!(grid.counts(10 + c), (0, 3), "cell {c}");
        }
        assert_eq!(grid.counts(16), (3, 0));
        assert_eq!(grid.counts(17), (0, 0));
        // No return: misses up to the reach, off the grid beyond.
        grid.insert([0.5, 0.5], 0.0, None, 30.0);
        assert_eq!(grid.counts(9), (0, 1));
        let map = grid.map();
        assert!(map.is_occupied(16) && map.is_free(12) && map.occupancy[20].is_none());
    }
}
