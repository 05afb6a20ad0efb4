//! Occupancy grids from sonar arcs: the paper's *simple counting* rule and a Bayesian log-odds grid.
//!
//! Each reading is a cone (the sensor's beam) cut at the measured range. Cells on the arc band at
//! the range (one cell thick) are *hits*; cells inside the cone before the band are *misses*.
//! Simple counting keeps the two tallies per cell and reports `C = hits / (hits + misses)`.
//! Near readings are trusted more, as in the paper: under 600 mm a hit counts 10 and a miss 2;
//! otherwise both count 1. The log-odds grid adds `log(p/(1-p))` of an inverse sensor model per
//! hit or miss instead, over the very same cells, so the two can be compared like for like.

use crate::geometry::wrap_angle;
use crate::sonar::{BeamModel, PlacedReading, SonarLayout};
use serde::{Deserialize, Serialize};

/// Settings of a grid. Defaults are the paper's office experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GridConfig {
    /// Cells along x: 80 in the paper's office (120 in the museum).
    pub width_cells: usize,
    /// Cells along y: 80 in the paper's office.
    pub height_cells: usize,
    /// Cell size: 20 cm in the paper.
    pub resolution_m: f64,
    /// World position of the lower-left corner of the grid; the paper puts the origin at (0, 0)
    /// and starts the robot at (2.5 m, 2.5 m) so all readings fall in the first quadrant.
    pub origin_m: [f64; 2],
    /// Readings nearer than this count more: 600 mm in the paper.
    pub near_range_m: f64,
    /// Hit weight of a near reading: 10 in the paper.
    pub near_hit: u32,
    /// Miss weight of a near reading: 2 in the paper.
    pub near_miss: u32,
    /// Hit weight of other readings: 1 in the paper.
    pub far_hit: u32,
    /// Miss weight of other readings: 1 in the paper.
    pub far_miss: u32,
    /// A cell with occupancy above this is occupied (ours: 0.5, an even split of the evidence).
    pub occupied_threshold: f64,
    /// A cell with occupancy below this is free (ours: 0.2).
    pub free_threshold: f64,
    /// Cells with less evidence than this (summed weights; updates for log-odds) stay unknown
    /// (ours: 6, six far readings or one near one, so a few far hits from multipath echoes behind
    /// a wall do not make a wall).
    pub min_evidence: u32,
    /// Whether the floor follows how densely the run samples
    /// ([`crate::sonar::map::MappingConfig::for_run`]): `min_evidence` for runs with a reading
    /// every 15 cm of travel or closer, scaled down (to 2 at least) for sparser ones. On by
    /// default.
    pub floor_follows_sampling: bool,
    /// Whether a reading with no echo marks its whole cone as free. Off by default: a specular
    /// wall returns no echo, so silence is no proof of free space.
    pub no_echo_is_free: bool,
}

impl Default for GridConfig {
    fn default() -> Self {
        Self {
            width_cells: 80,
            height_cells: 80,
            resolution_m: 0.2,
            origin_m: [0.0, 0.0],
            near_range_m: 0.6,
            near_hit: 10,
            near_miss: 2,
            far_hit: 1,
            far_miss: 1,
            occupied_threshold: 0.5,
            free_threshold: 0.2,
            min_evidence: 6,
            floor_follows_sampling: true,
            no_echo_is_free: false,
        }
    }
}

/// Errors in grid settings.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum GridError {
    /// A setting is out of range.
    #[error("mapping setting `{key}` = {value} is invalid: {reason}")]
    Invalid {
        /// The key.
        key: &'static str,
        /// Its value.
        value: f64,
        /// What is expected.
        reason: &'static str,
    },
}

/// The paper's cell size, metres (the fitted grids' for sonar).
const FITTED_CELL_M: f64 = 0.2;

/// Margin around the trajectory and the sensors' reach in a fitted grid, metres.
const FITTED_MARGIN_M: f64 = 1.0;
/// Largest fitted grid side, cells (1 km at 20 cm): a longer run is a reset or a glitch in its
/// odometry more often than a building.
const FITTED_MAX_CELLS: usize = 5000;

impl GridConfig {
    /// The paper's settings on a grid of 20 cm cells over `trajectory` and the reach of the
    /// sonars of `layout`, with a margin; `None` when the trajectory is empty or the grid would
    /// be over 1 km on a side.
    pub fn fitted(
        trajectory: &[crate::geometry::StampedPose],
        layout: &crate::sonar::SonarLayout,
    ) -> Option<GridConfig> {
        let reach = layout.max_range_m
            + layout
                .sensors
                .iter()
                .map(|s| s.x_m.hypot(s.y_m))
                .fold(0.0, f64::max)
            + FITTED_MARGIN_M;
        let cell = FITTED_CELL_M;
        let first = trajectory.first()?;
        let (lo, hi) = trajectory.iter().fold(
            ([first.pose.x, first.pose.y], [first.pose.x, first.pose.y]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p.pose.x), lo[1].min(p.pose.y)],
                    [hi[0].max(p.pose.x), hi[1].max(p.pose.y)],
                )
            },
        );
        let origin_m = [
            ((lo[0] - reach) / cell).floor() * cell,
            ((lo[1] - reach) / cell).floor() * cell,
        ];
        let cells = |from: f64, to: f64| ((to + reach - from) / cell).ceil().max(1.0) as usize;
        let (width_cells, height_cells) = (cells(origin_m[0], hi[0]), cells(origin_m[1], hi[1]));
        (width_cells <= FITTED_MAX_CELLS && height_cells <= FITTED_MAX_CELLS).then(|| GridConfig {
            origin_m,
            width_cells,
            height_cells,
            resolution_m: cell,
            ..GridConfig::default()
        })
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), GridError> {
        let bad = |key, value: f64, reason| Err(GridError::Invalid { key, value, reason });
        if !(self.resolution_m.is_finite() && self.resolution_m > 0.0) {
            return bad(
                "grid.resolution_m",
                self.resolution_m,
                "must be a positive number of metres",
            );
        }
        if self.width_cells == 0
            || self.height_cells == 0
            || self.width_cells * self.height_cells > 100_000_000
        {
            return bad(
                "grid.width_cells",
                self.width_cells as f64,
                "grid must have between 1 and 1e8 cells",
            );
        }
        if !(0.0..=1.0).contains(&self.occupied_threshold)
            || !(0.0..=1.0).contains(&self.free_threshold)
        {
            return bad(
                "grid.occupied_threshold",
                self.occupied_threshold,
                "thresholds must lie in [0, 1]",
            );
        }
        if !self.origin_m.iter().all(|v| v.is_finite()) {
            return bad("grid.origin_m", self.origin_m[0], "must be finite");
        }
        Ok(())
    }
}

/// What a reading says about a cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellEvidence {
    /// On the arc at the measured range.
    Hit,
    /// Inside the cone, before the arc.
    Miss,
}

/// Geometry shared by both grids: cell indexing and the cone traversal.
#[derive(Debug, Clone, PartialEq)]
pub struct GridGeometry {
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// Cell size, metres.
    pub resolution_m: f64,
    /// Lower-left corner, metres.
    pub origin_m: [f64; 2],
}

impl GridGeometry {
    /// From the settings.
    pub fn from_config(c: &GridConfig) -> Self {
        Self {
            width: c.width_cells,
            height: c.height_cells,
            resolution_m: c.resolution_m,
            origin_m: c.origin_m,
        }
    }

    /// Indices of the grid's cells within `reach` cells (a square) of the cell holding `point`,
    /// which may lie off the grid (a wall on its edge): those that exist.
    pub fn cells_around(&self, point: (f64, f64), reach: i64) -> impl Iterator<Item = usize> + '_ {
        let c0 = ((point.0 - self.origin_m[0]) / self.resolution_m).floor() as i64;
        let r0 = ((point.1 - self.origin_m[1]) / self.resolution_m).floor() as i64;
        let (w, h) = (self.width as i64, self.height as i64);
        (r0 - reach..=r0 + reach)
            .filter(move |r| (0..h).contains(r))
            .flat_map(move |r| {
                (c0 - reach..=c0 + reach)
                    .filter(move |c| (0..w).contains(c))
                    .map(move |c| (r * w + c) as usize)
            })
    }

    /// Cell containing a world point, as (column, row from the bottom).
    pub fn cell_of(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let cx = ((x - self.origin_m[0]) / self.resolution_m).floor();
        let cy = ((y - self.origin_m[1]) / self.resolution_m).floor();
        if cx < 0.0 || cy < 0.0 || cx >= self.width as f64 || cy >= self.height as f64 {
            return None;
        }
        Some((cx as usize, cy as usize))
    }

    /// Centre of a cell in the world, metres.
    pub fn centre(&self, col: usize, row: usize) -> [f64; 2] {
        [
            self.origin_m[0] + (col as f64 + 0.5) * self.resolution_m,
            self.origin_m[1] + (row as f64 + 0.5) * self.resolution_m,
        ]
    }

    /// Calls `visit(index, evidence)` for each cell the reading says something about.
    /// `range_m` is the arc radius; with `hit == false` the whole cone up to it is a miss.
    pub fn for_each_cone_cell(
        &self,
        reading: &PlacedReading,
        half_cone_rad: f64,
        range_m: f64,
        hit: bool,
        mut visit: impl FnMut(usize, CellEvidence),
    ) {
        let p = reading.world_from_sensor;
        let band = 0.5 * self.resolution_m;
        let reach = range_m + band;
        let lo = self.cell_index_clamped(p.x - reach, p.y - reach);
        let hi = self.cell_index_clamped(p.x + reach, p.y + reach);
        let (Some(lo), Some(hi)) = (lo, hi) else {
            return;
        };
        // Whether a cell's centre lies outside the cone: by the cosine of its angle off the axis,
        // and by the angle itself only when that cosine is within rounding of the cone's edge
        // (so the cells are exactly those the angle gives; the arctangent per cell was a third
        // of a map's grid time).
        let (sin, cos) = p.theta.sin_cos();
        let edge = half_cone_rad.cos();
        let outside = |cx: f64, cy: f64, d: f64| {
            if half_cone_rad >= std::f64::consts::PI {
                return false;
            }
            let off_axis = (cos * cx + sin * cy) / d;
            if (off_axis - edge).abs() > 1e-9 {
                off_axis < edge
            } else {
                wrap_angle(cy.atan2(cx) - p.theta).abs() > half_cone_rad
            }
        };
        for row in lo.1..=hi.1 {
            let cy = self.origin_m[1] + (row as f64 + 0.5) * self.resolution_m - p.y;
            for col in lo.0..=hi.0 {
                let cx = self.origin_m[0] + (col as f64 + 0.5) * self.resolution_m - p.x;
                let d = (cx * cx + cy * cy).sqrt();
                if d > reach {
                    continue;
                }
                // Cells the sensor sits in are always inside the beam.
                if d > band && outside(cx, cy, d) {
                    continue;
                }
                let idx = row * self.width + col;
                if hit && d >= range_m - band {
                    visit(idx, CellEvidence::Hit);
                } else if d < range_m - band {
                    visit(idx, CellEvidence::Miss);
                }
            }
        }
    }

    /// Calls `visit(index, evidence)` for each cell a thin ray crosses ([`crate::sonar::BeamModel::Ray`]):
    /// every cell from the sensor's up to the cell at `range_m` along the beam is a miss, except
    /// that cell itself, a hit when `hit`. Cells are walked exactly (Amanatides and Woo), each
    /// once; the ray's part off the grid is passed over.
    pub fn for_each_ray_cell(
        &self,
        reading: &PlacedReading,
        range_m: f64,
        hit: bool,
        mut visit: impl FnMut(usize, CellEvidence),
    ) {
        let p = reading.world_from_sensor;
        let (dx, dy) = (p.theta.cos(), p.theta.sin());
        let res = self.resolution_m;
        // Position in cell units.
        let (x0, y0) = (
            (p.x - self.origin_m[0]) / res,
            (p.y - self.origin_m[1]) / res,
        );
        let length = range_m / res;
        if !(x0.is_finite() && y0.is_finite() && length.is_finite()) {
            return;
        }
        let end = (
            (x0 + length * dx).floor() as i64,
            (y0 + length * dy).floor() as i64,
        );
        let (mut cx, mut cy) = (x0.floor() as i64, y0.floor() as i64);
        let step = |d: f64| if d > 0.0 { 1 } else { -1 };
        let (sx, sy) = (step(dx), step(dy));
        // Distance along the ray (cell units) to the next vertical and horizontal cell edges.
        let next = |c: i64, s: i64, o: f64, d: f64| {
            if d == 0.0 {
                f64::INFINITY
            } else {
                ((c + (s > 0) as i64) as f64 - o) / d
            }
        };
        let (mut tx, mut ty) = (next(cx, sx, x0, dx), next(cy, sy, y0, dy));
        let (ddx, ddy) = (
            if dx == 0.0 {
                f64::INFINITY
            } else {
                1.0 / dx.abs()
            },
            if dy == 0.0 {
                f64::INFINITY
            } else {
                1.0 / dy.abs()
            },
        );
        let inside = |c: i64, r: i64| {
            (c >= 0 && r >= 0 && (c as usize) < self.width && (r as usize) < self.height)
                .then(|| r as usize * self.width + c as usize)
        };
        // A ray crosses at most this many cells (a guard against rounding at the end cell).
        let most = (length.abs().ceil() as usize) * 2 + 2;
        for _ in 0..most {
            if (cx, cy) == end {
                break;
            }
            if let Some(idx) = inside(cx, cy) {
                visit(idx, CellEvidence::Miss);
            }
            if tx < ty {
                cx += sx;
                tx += ddx;
            } else {
                cy += sy;
                ty += ddy;
            }
            if tx.min(ty) > length + ddx.min(ddy) {
                break;
            }
        }
        if let (true, Some(idx)) = (hit, inside(end.0, end.1)) {
            visit(idx, CellEvidence::Hit);
        }
    }

    fn cell_index_clamped(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let cx = ((x - self.origin_m[0]) / self.resolution_m).floor();
        let cy = ((y - self.origin_m[1]) / self.resolution_m).floor();
        if cx.is_nan() || cy.is_nan() {
            return None;
        }
        Some((
            cx.clamp(0.0, (self.width - 1) as f64) as usize,
            cy.clamp(0.0, (self.height - 1) as f64) as usize,
        ))
    }
}

/// A finished occupancy map: per cell the probability of being occupied, or `None` if unseen.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyMap {
    /// Geometry.
    pub geometry: GridGeometry,
    /// Row-major from the bottom row.
    pub occupancy: Vec<Option<f64>>,
    /// Above this: occupied.
    pub occupied_threshold: f64,
    /// Below this: free.
    pub free_threshold: f64,
}

/// A laser's returns are mapped for matching its scans on cells this size, metres: 5 cm (the
/// usual lidar map's; the 20 cm counting grid's cell centres lie up to 14 cm from the wall points
/// in them, more than a scan's match tolerates).
pub const RETURN_CELL_M: f64 = 0.05;

/// A cell of [`returns_map`] is occupied when at least this many returns fell in it: one alone
/// may be a person walking by.
pub const MIN_RETURNS: u32 = 2;

/// Where a laser's returns (`placed`, those with an echo: [`SonarLayout::echo`]) fell, on cells of
/// [`RETURN_CELL_M`] over the extent of `extent`: occupied where [`MIN_RETURNS`] or more did,
/// unknown elsewhere (the rays' free space is not traced: a scan is matched with what it hits).
/// `localize` matches a later run's scans with it (`returns_corrected.pgm`), as the survey's
/// own correction matched each scan with the older returns; a ROS map_server file of it is what a
/// likelihood-field localiser (AMCL's) reads.
pub fn returns_map(
    placed: &[PlacedReading],
    extent: &GridGeometry,
    layout: &SonarLayout,
) -> OccupancyMap {
    let geometry = GridGeometry {
        width: (extent.width as f64 * extent.resolution_m / RETURN_CELL_M).ceil() as usize,
        height: (extent.height as f64 * extent.resolution_m / RETURN_CELL_M).ceil() as usize,
        resolution_m: RETURN_CELL_M,
        origin_m: extent.origin_m,
    };
    let mut counts = vec![0u32; geometry.width * geometry.height];
    for p in placed {
        let Some(range) = layout.echo(p.range_m) else {
            continue;
        };
        let at = p.world_from_sensor;
        let (x, y) = (at.x + range * at.theta.cos(), at.y + range * at.theta.sin());
        if let Some((col, row)) = geometry.cell_of(x, y) {
            counts[row * geometry.width + col] += 1;
        }
    }
    OccupancyMap {
        occupancy: counts
            .iter()
            .map(|&n| (n >= MIN_RETURNS).then_some(1.0))
            .collect(),
        geometry,
        occupied_threshold: 0.5,
        free_threshold: 0.2,
    }
}

impl OccupancyMap {
    /// Whether a cell is occupied.
    pub fn is_occupied(&self, idx: usize) -> bool {
        self.occupancy
            .get(idx)
            .copied()
            .flatten()
            .is_some_and(|c| c > self.occupied_threshold)
    }

    /// Whether a cell is free.
    pub fn is_free(&self, idx: usize) -> bool {
        self.occupancy
            .get(idx)
            .copied()
            .flatten()
            .is_some_and(|c| c < self.free_threshold)
    }

    /// Number of cells that have been observed.
    pub fn known_cells(&self) -> usize {
        self.occupancy.iter().filter(|c| c.is_some()).count()
    }

    /// The part of the map whose cells meet the rectangle from `lo` to `hi` (metres), on the same
    /// cells; the whole map when the rectangle covers it, an empty one when it misses it.
    pub fn cropped(&self, lo: [f64; 2], hi: [f64; 2]) -> OccupancyMap {
        let g = &self.geometry;
        let cells =
            |v: f64, origin: f64, n: usize| ((v - origin) / g.resolution_m).clamp(0.0, n as f64);
        let c0 = cells(lo[0], g.origin_m[0], g.width).floor() as usize;
        let c1 = cells(hi[0], g.origin_m[0], g.width).ceil() as usize;
        let r0 = cells(lo[1], g.origin_m[1], g.height).floor() as usize;
        let r1 = cells(hi[1], g.origin_m[1], g.height).ceil() as usize;
        let (width, height) = (c1.saturating_sub(c0), r1.saturating_sub(r0));
        let mut occupancy = Vec::with_capacity(width * height);
        for row in r0..r0 + height {
            occupancy
                .extend_from_slice(&self.occupancy[row * g.width + c0..row * g.width + c0 + width]);
        }
        OccupancyMap {
            geometry: GridGeometry {
                width,
                height,
                resolution_m: g.resolution_m,
                origin_m: [
                    g.origin_m[0] + c0 as f64 * g.resolution_m,
                    g.origin_m[1] + r0 as f64 * g.resolution_m,
                ],
            },
            occupancy,
            occupied_threshold: self.occupied_threshold,
            free_threshold: self.free_threshold,
        }
    }

    /// The rectangle the observed cells cover, `(lower-left, upper-right)` corners in metres;
    /// `None` when nothing was observed.
    pub fn known_extent(&self) -> Option<([f64; 2], [f64; 2])> {
        let g = &self.geometry;
        let half = 0.5 * g.resolution_m;
        let mut known = self
            .occupancy
            .iter()
            .enumerate()
            .filter(|(_, c)| c.is_some());
        let first = known.next()?.0;
        let start = g.centre(first % g.width, first / g.width);
        let (lo, hi) = known.fold((start, start), |(lo, hi), (i, _)| {
            let [x, y] = g.centre(i % g.width, i / g.width);
            ([lo[0].min(x), lo[1].min(y)], [hi[0].max(x), hi[1].max(y)])
        });
        Some(([lo[0] - half, lo[1] - half], [hi[0] + half, hi[1] + half]))
    }
}

/// Both grids insert readings the same way.
pub trait OccupancyGrid {
    /// Adds one reading.
    fn insert(&mut self, reading: &PlacedReading);
    /// The map so far.
    fn map(&self) -> OccupancyMap;
    /// Adds many readings.
    fn insert_all(&mut self, readings: &[PlacedReading]) {
        for r in readings {
            self.insert(r);
        }
    }
}

/// What both grids share: their settings and cells, and the beam they update (a sonar's cone or
/// a laser's ray).
#[derive(Debug, Clone)]
struct ConeCells {
    config: GridConfig,
    geometry: GridGeometry,
    beam: BeamModel,
    half_cone_rad: f64,
    max_range_m: f64,
}

impl ConeCells {
    fn new(config: GridConfig, cone_rad: f64, max_range_m: f64) -> Result<Self, GridError> {
        config.validate()?;
        Ok(Self {
            geometry: GridGeometry::from_config(&config),
            config,
            beam: BeamModel::Cone,
            half_cone_rad: 0.5 * cone_rad,
            max_range_m,
        })
    }

    fn for_layout(config: GridConfig, layout: &SonarLayout) -> Result<Self, GridError> {
        Ok(Self {
            beam: layout.beam,
            ..Self::new(config, layout.cone_rad, layout.max_range_m)?
        })
    }

    fn cells(&self) -> usize {
        self.geometry.width * self.geometry.height
    }

    /// How far the reading reaches and whether it ends in an echo: a range within the sensor's
    /// reach, or (when no echo counts as free) its whole reach without one.
    fn extent(&self, r: &PlacedReading) -> Option<(f64, bool)> {
        match r.range_m {
            Some(range) if range.is_finite() && range >= 0.0 && range <= self.max_range_m => {
                Some((range, true))
            }
            Some(_) | None if self.config.no_echo_is_free => Some((self.max_range_m, false)),
            _ => None,
        }
    }

    /// Visits the cells the reading's cone says something about, with what it says.
    fn visit(
        &self,
        reading: &PlacedReading,
        range: f64,
        hit: bool,
        visit: impl FnMut(usize, CellEvidence),
    ) {
        match self.beam {
            BeamModel::Cone => {
                self.geometry
                    .for_each_cone_cell(reading, self.half_cone_rad, range, hit, visit)
            }
            BeamModel::Ray => self.geometry.for_each_ray_cell(reading, range, hit, visit),
        }
    }

    /// The map of these cells with each cell's occupancy (`None`: too little evidence).
    fn map(&self, occupancy: Vec<Option<f64>>) -> OccupancyMap {
        OccupancyMap {
            geometry: self.geometry.clone(),
            occupancy,
            occupied_threshold: self.config.occupied_threshold,
            free_threshold: self.config.free_threshold,
        }
    }

    /// Whether `n` observations of a cell are enough to say something about it.
    fn enough(&self, n: u32) -> bool {
        n >= self.config.min_evidence.max(1)
    }
}

/// A laser's hit counts this many times its weight: 16. At 20 cm cells a beam that ends on a wall
/// seen at an angle `a` to it first crosses about `1 / tan a` of the wall's cells: from a corridor's
/// middle, 1 m from its walls, the returns 10-15 m along a wall have crossed 10-15 of its cells,
/// so a wall cell there sees one beam end in it for every 10-15 that pass by. With hits counted 16
/// times, a cell is occupied (above an even split) when more than one in 17 of the beams through it
/// ends there. (gmapping's counting rule takes a quarter at 5 cm cells; Cartographer's hit and
/// miss odds, 0.55 and 0.49, weigh a hit as five misses.) Against the full laser on the Radish
/// logs (docs/RESULTS.md): 5 gave freiburg-079 a recall of 0.913, 16 gives 0.957, with
/// [`RAY_MIN_RETURNS`] keeping aces' precision above 0.95.
pub const RAY_HIT_WEIGHT: u32 = 16;

/// A laser's cell is occupied only with at least this many returns: 2. One return is no wall yet
/// (a stray reflection, a leg walking by); without it, the heavy hit weight would call such cells
/// occupied on a sparse log (aces, a scan every 3 s: precision 0.946 with one return, 0.957 with
/// two).
pub const RAY_MIN_RETURNS: u32 = 2;

/// The paper's simple counting grid.
#[derive(Debug, Clone)]
pub struct CountingGrid {
    cells: ConeCells,
    hits: Vec<u32>,
    misses: Vec<u32>,
    /// Returns that ended in each cell, unweighted (for [`RAY_MIN_RETURNS`]).
    returns: Vec<u32>,
}

impl CountingGrid {
    /// An empty grid for sensors with the given beam width and maximum range.
    pub fn new(config: GridConfig, cone_rad: f64, max_range_m: f64) -> Result<Self, GridError> {
        Ok(Self::over(ConeCells::new(config, cone_rad, max_range_m)?))
    }

    fn over(cells: ConeCells) -> Self {
        let n = cells.cells();
        Self {
            cells,
            hits: vec![0; n],
            misses: vec![0; n],
            returns: vec![0; n],
        }
    }

    /// An empty grid for the sensors of `layout` (their beam model, width and range).
    pub fn for_layout(config: GridConfig, layout: &SonarLayout) -> Result<Self, GridError> {
        Ok(Self::over(ConeCells::for_layout(config, layout)?))
    }

    /// Cells with some evidence, but less than the floor (`min_evidence`): left unknown.
    pub fn cells_below_floor(&self) -> usize {
        self.hits
            .iter()
            .zip(&self.misses)
            .filter(|(&h, &m)| {
                let evidence = self.evidence(h, m);
                evidence > 0 && !self.cells.enough(evidence)
            })
            .count()
    }

    /// The evidence of a cell with `h` weighted hits and `m` misses. A laser's evidence is its
    /// beams (a hit weighs more in the share, not in the count): one return with five beams by
    /// is no wall yet.
    fn evidence(&self, h: u32, m: u32) -> u32 {
        match self.cells.beam {
            BeamModel::Cone => h + m,
            BeamModel::Ray => h / RAY_HIT_WEIGHT + m,
        }
    }

    /// Hit and miss tallies of a cell.
    pub fn counts(&self, idx: usize) -> (u32, u32) {
        (
            self.hits.get(idx).copied().unwrap_or(0),
            self.misses.get(idx).copied().unwrap_or(0),
        )
    }
}

impl OccupancyGrid for CountingGrid {
    fn insert(&mut self, reading: &PlacedReading) {
        let Some((range, hit)) = self.cells.extent(reading) else {
            return;
        };
        let config = &self.cells.config;
        let near = hit && range < config.near_range_m;
        let (wh, wm) = if near {
            (config.near_hit, config.near_miss)
        } else {
            (config.far_hit, config.far_miss)
        };
        let wh = match self.cells.beam {
            BeamModel::Cone => wh,
            BeamModel::Ray => wh * RAY_HIT_WEIGHT,
        };
        let (hits, misses, returns) = (&mut self.hits, &mut self.misses, &mut self.returns);
        self.cells.visit(reading, range, hit, |idx, e| match e {
            CellEvidence::Hit => {
                hits[idx] += wh;
                returns[idx] += 1;
            }
            CellEvidence::Miss => misses[idx] += wm,
        });
    }

    /// The readings in two halves on two threads, each counted on its own cells, then added:
    /// counts do not depend on the order they came in (a map waits for this grid before anything
    /// else of it starts).
    fn insert_all(&mut self, readings: &[PlacedReading]) {
        if readings.len() < PARALLEL_READINGS || rayon::current_num_threads() < 2 {
            readings.iter().for_each(|r| self.insert(r));
            return;
        }
        let (first, second) = readings.split_at(readings.len() / 2);
        let mut other = Self::over(self.cells.clone());
        rayon::join(
            || first.iter().for_each(|r| self.insert(r)),
            || second.iter().for_each(|r| other.insert(r)),
        );
        for (mine, theirs) in [
            (&mut self.hits, &other.hits),
            (&mut self.misses, &other.misses),
            (&mut self.returns, &other.returns),
        ] {
            mine.iter_mut().zip(theirs).for_each(|(m, t)| *m += t);
        }
    }

    fn map(&self) -> OccupancyMap {
        let ray = self.cells.beam == BeamModel::Ray;
        let occupancy = self
            .hits
            .iter()
            .zip(&self.misses)
            .zip(&self.returns)
            .map(|((&h, &m), &n)| {
                let h = if ray && n < RAY_MIN_RETURNS { 0 } else { h };
                self.cells
                    .enough(self.evidence(h, m))
                    .then(|| h as f64 / (h + m) as f64)
            })
            .collect();
        self.cells.map(occupancy)
    }
}

/// From this many readings on, a counting grid counts them on two threads
/// ([`CountingGrid::insert_all`]).
const PARALLEL_READINGS: usize = 8192;

/// Log-odds of an occupied cell given a hit: inverse sensor model p = 0.7.
pub const LOG_ODDS_HIT: f32 = 0.847_298;
/// Log-odds of an occupied cell given a miss: inverse sensor model p = 0.4.
pub const LOG_ODDS_MISS: f32 = -0.405_465;
/// Log-odds are clamped to +-this so a cell can still change its mind.
pub const LOG_ODDS_CLAMP: f32 = 8.0;

/// A Bayesian log-odds grid over the same cone cells.
#[derive(Debug, Clone)]
pub struct LogOddsGrid {
    cells: ConeCells,
    log_odds: Vec<f32>,
    seen: Vec<u32>,
}

impl LogOddsGrid {
    /// An empty grid.
    pub fn new(config: GridConfig, cone_rad: f64, max_range_m: f64) -> Result<Self, GridError> {
        Ok(Self::over(ConeCells::new(config, cone_rad, max_range_m)?))
    }

    fn over(cells: ConeCells) -> Self {
        let n = cells.cells();
        Self {
            cells,
            log_odds: vec![0.0; n],
            seen: vec![0; n],
        }
    }
}

impl LogOddsGrid {
    /// An empty grid for the sensors of `layout` (their beam model, width and range).
    pub fn for_layout(config: GridConfig, layout: &SonarLayout) -> Result<Self, GridError> {
        Ok(Self::over(ConeCells::for_layout(config, layout)?))
    }
}

impl OccupancyGrid for LogOddsGrid {
    fn insert(&mut self, reading: &PlacedReading) {
        let Some((range, hit)) = self.cells.extent(reading) else {
            return;
        };
        let (lo, seen) = (&mut self.log_odds, &mut self.seen);
        self.cells.visit(reading, range, hit, |idx, e| {
            let step = match e {
                CellEvidence::Hit => LOG_ODDS_HIT,
                CellEvidence::Miss => LOG_ODDS_MISS,
            };
            lo[idx] = (lo[idx] + step).clamp(-LOG_ODDS_CLAMP, LOG_ODDS_CLAMP);
            seen[idx] += 1;
        });
    }

    fn map(&self) -> OccupancyMap {
        let occupancy = self
            .log_odds
            .iter()
            .zip(&self.seen)
            .map(|(&l, &s)| {
                self.cells
                    .enough(s)
                    .then(|| 1.0 - 1.0 / (1.0 + (l as f64).exp()))
            })
            .collect();
        self.cells.map(occupancy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;

    #[test]
    fn the_grid_covers_the_trajectory_and_the_reach() {
        let t = [
            crate::geometry::StampedPose {
                t_s: 0.0,
                pose: Pose2::new(-3.0, 1.0, 0.0),
            },
            crate::geometry::StampedPose {
                t_s: 1.0,
                pose: Pose2::new(40.0, 12.0, 0.0),
            },
        ];
        let g = GridConfig::fitted(&t, &crate::sonar::SonarLayout::frontal5()).unwrap();
        let reach = 2.1 + 0.2 + FITTED_MARGIN_M;
        assert!(g.origin_m[0] <= -3.0 - reach && g.origin_m[1] <= 1.0 - reach);
        assert!(g.origin_m[0] + g.width_cells as f64 * FITTED_CELL_M >= 40.0 + reach);
        assert!(g.origin_m[1] + g.height_cells as f64 * FITTED_CELL_M >= 12.0 + reach);
        assert_eq!(g.resolution_m, FITTED_CELL_M);
    }

    #[test]
    fn a_run_over_a_kilometre_gets_no_fitted_grid() {
        let t: Vec<crate::geometry::StampedPose> = [0.0, 2000.0]
            .iter()
            .map(|&x| crate::geometry::StampedPose {
                t_s: x,
                pose: Pose2::new(x, 0.0, 0.0),
            })
            .collect();
        assert!(GridConfig::fitted(&t, &crate::sonar::SonarLayout::frontal5()).is_none());
        assert!(GridConfig::fitted(&[], &crate::sonar::SonarLayout::frontal5()).is_none());
    }

    #[test]
    fn cropping_keeps_the_cells_and_their_place() {
        let geometry = GridGeometry {
            width: 10,
            height: 8,
            resolution_m: 0.5,
            origin_m: [-1.0, 2.0],
        };
        let occupancy = (0..80).map(|i| Some(i as f64 / 80.0)).collect();
        let map = OccupancyMap {
            geometry,
            occupancy,
            occupied_threshold: 0.65,
            free_threshold: 0.35,
        };
        // Cells 2..5 across (x from 0.0 to 1.5 m) and 1..3 up (y from 2.5 to 3.5 m).
        let crop = map.cropped([0.1, 2.6], [1.4, 3.4]);
        assert_eq!((crop.geometry.width, crop.geometry.height), (3, 2));
        assert_eq!(crop.geometry.origin_m, [0.0, 2.5]);
        assert_eq!(crop.occupancy[0], map.occupancy[10 + 2]);
        assert_eq!(crop.occupancy[5], map.occupancy[20 + 4]);
        // A rectangle past the map keeps the whole map; one beside it, nothing.
        assert_eq!(map.cropped([-9.0, -9.0], [9.0, 9.0]), map);
        assert!(map.cropped([20.0, 20.0], [30.0, 30.0]).occupancy.is_empty());
    }

    #[test]
    fn a_near_reading_marks_arc_occupied_and_cone_free() {
        let config = GridConfig {
            min_evidence: 1,
            ..GridConfig::default()
        };
        let mut g = CountingGrid::new(config, 30f64.to_radians(), 2.1).unwrap();
        let r = PlacedReading {
            t_s: 0.0,
            world_from_sensor: Pose2::new(2.5, 2.5, 0.0),
            range_m: Some(0.55),
        };
        g.insert(&r);
        let geo = GridGeometry::from_config(&GridConfig::default());
        let (c, rw) = geo.cell_of(3.05, 2.5).unwrap();
        assert_eq!(g.counts(rw * geo.width + c), (10, 0));
        let (c, rw) = geo.cell_of(2.7, 2.5).unwrap();
        assert_eq!(g.counts(rw * geo.width + c), (0, 2));
        let m = g.map();
        assert!(m.is_occupied(rw * geo.width + c + 2));
        assert!(m.is_free(rw * geo.width + c));
    }

    #[test]
    fn many_readings_counted_on_two_threads_count_as_one_by_one() {
        let readings: Vec<PlacedReading> = (0..3 * PARALLEL_READINGS)
            .map(|k| {
                let f = k as f64;
                PlacedReading {
                    t_s: f,
                    world_from_sensor: Pose2::new(
                        2.5 + (f * 0.37).sin() * 2.0,
                        2.5 + (f * 0.91).cos() * 2.0,
                        f * 0.731,
                    ),
                    range_m: (k % 7 != 0).then_some(0.3 + (k % 19) as f64 * 0.1),
                }
            })
            .collect();
        let new = || CountingGrid::new(GridConfig::default(), 30f64.to_radians(), 2.1).unwrap();
        let (mut together, mut one_by_one) = (new(), new());
        together.insert_all(&readings);
        readings.iter().for_each(|r| one_by_one.insert(r));
        assert_eq!(together.hits, one_by_one.hits);
        assert_eq!(together.misses, one_by_one.misses);
        assert_eq!(together.returns, one_by_one.returns);
        assert!(together.hits.iter().any(|&h| h > 0));
    }

    /// A cell holding two returns is occupied, one holding a single return (a person walking
    /// by) unknown; a return beyond the range used or with no echo is left out.
    #[test]
    fn returns_map_holds_the_cells_returns_fell_in_twice() {
        let extent = GridGeometry {
            width: 10,
            height: 10,
            resolution_m: 0.2,
            origin_m: [0.0, 0.0],
        };
        let at = |x: f64, range_m: Option<f64>| PlacedReading {
            t_s: 0.0,
            world_from_sensor: Pose2::new(x, 0.5, 0.0),
            range_m,
        };
        let placed = [
            at(0.0, Some(1.01)),
            at(0.5, Some(0.52)), // the same 5 cm cell, x = 1.01 and 1.02
            at(0.0, Some(0.31)), // alone
            at(0.0, Some(1.5)),  // at the range used: no echo
            at(0.0, None),
        ];
        let layout = SonarLayout {
            max_range_m: 1.5,
            ..SonarLayout::frontal5()
        };
        let map = returns_map(&placed, &extent, &layout);
        assert_eq!(map.geometry.resolution_m, RETURN_CELL_M);
        assert_eq!((map.geometry.width, map.geometry.height), (40, 40));
        let (col, row) = map.geometry.cell_of(1.01, 0.5).unwrap();
        assert!(map.is_occupied(row * 40 + col));
        assert_eq!(map.known_cells(), 1);
    }
}
