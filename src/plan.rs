//! Landmark planning: from the Hough corners of a first, sonar-only run, propose where tags should
//! go so the robot sees one often enough, and predict the localisation error with them.
//!
//! A candidate is a corner feature of the map (room corners first: a tag at a concave corner is
//! seen from the whole room). It *covers* a free cell when the cell is within the camera's capture
//! range of it and the straight line between them crosses no occupied cell. Tags are chosen
//! greedily, each time the candidate that covers the most free cells not yet covered, at least
//! [`PlanConfig::min_separation_m`] from the ones chosen, until the covered share reaches
//! [`PlanConfig::target_coverage`] or [`PlanConfig::max_tags`] are chosen. The predicted error at a
//! free cell is the sighting error plus the odometry drift over the way to the nearest covered
//! cell and back (the shortest way over free cells). Where the map's straight walls (`walls.csv`
//! from `stereotag map`) are within sonar range, `localize` holds the robot to them between
//! sightings, and the error there is [`PlanConfig::wall_sighting_error_m`] and
//! [`PlanConfig::wall_drift_m_per_m`] instead of [`PlanConfig::sighting_error_m`] and
//! [`PlanConfig::drift_m_per_m`]. The defaults are for a robot that measures its turns with its
//! cameras between sightings (`localize`'s default); [`PlanConfig::wheels_only`] for one that
//! does not.

use crate::sonar::grid::OccupancyMap;
use crate::sonar::hough::{Feature, FeatureKind};
use crate::sonar::walls::WallSegment;
use serde::Serialize;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Settings of the planner. Defaults say where they come from.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PlanConfig {
    /// Largest distance at which a tag is useful, metres (ours: 3 m, the capture policy's range).
    pub capture_range_m: f64,
    /// Share of the free cells that should see a tag (ours: 0.9).
    pub target_coverage: f64,
    /// Tags at most (the method selected five in the museum).
    pub max_tags: usize,
    /// Smallest distance between two chosen tags, metres (ours: 1.5 m; two tags in one corner
    /// add little).
    pub min_separation_m: f64,
    /// Position error right after a sighting, metres (ours: 2.5 cm: `localize --no-walls` with
    /// the cameras' turns on the 12 pairs of office seeds 1-4, 2.1-2.7 cm RMS in the first 2 m
    /// after a sighting; 3 cm without the cameras' turns, against surveys 4 cm off).
    pub sighting_error_m: f64,
    /// Position error right after a sighting where a mapped wall is within
    /// [`Self::wall_range_m`], metres (ours: 0.8 cm: `localize` against the office walls with the
    /// cameras' turns, survey seed 1, runs 2-5: 0.6-1.0 cm RMS in the first 0.5 m after a
    /// sighting; 3 cm without the cameras' turns).
    pub wall_sighting_error_m: f64,
    /// Drift per metre travelled between sightings, metres, with the odometry corrected by the
    /// survey's calibration as `localize` does (ours: 0.3 cm/m: `localize --no-walls` with the
    /// cameras' turns, 3.0 cm RMS at 2-4 m after a sighting, 4.4 cm at 4-8 m; 0.7 cm/m without
    /// them, 4 cm at 2-4 m, 6.7 cm at 4-8 m).
    pub drift_m_per_m: f64,
    /// Drift per metre where a mapped wall is within [`Self::wall_range_m`] (ours: 0.06 cm/m:
    /// the same runs, 1.1-1.9 cm RMS at 4-8 m after a sighting; with these two the prediction's
    /// RMS over the cells driven is 1.1-1.2 cm against 1.0-1.2 cm measured,
    /// `scripts/plan_check.sh`; 0.15 cm/m without the cameras' turns).
    pub wall_drift_m_per_m: f64,
    /// A wall holds the robot when it is at most this far in front of the wall's face, metres
    /// (ours: 1.5 m, inside the sonars' 2.1 m).
    pub wall_range_m: f64,
    /// Cells this close to a corner do not block its view, metres (its own walls).
    pub corner_clearance_m: f64,
}

impl Default for PlanConfig {
    fn default() -> Self {
        Self {
            capture_range_m: 3.0,
            target_coverage: 0.9,
            max_tags: 12,
            min_separation_m: 1.5,
            sighting_error_m: 0.025,
            wall_sighting_error_m: 0.008,
            drift_m_per_m: 0.003,
            wall_drift_m_per_m: 0.0006,
            wall_range_m: 1.5,
            corner_clearance_m: 0.3,
        }
    }
}

impl PlanConfig {
    /// The error model of a robot that does not measure its turns with its cameras between
    /// sightings (`localize` with `visual_odometry: false`, or a run with pictures of tags only).
    pub fn wheels_only() -> Self {
        Self {
            sighting_error_m: 0.03,
            wall_sighting_error_m: 0.03,
            drift_m_per_m: 0.007,
            wall_drift_m_per_m: 0.0015,
            ..Self::default()
        }
    }
}

/// A proposed tag position.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProposedTag {
    /// Where, metres (the corner).
    pub x_m: f64,
    /// Where, metres.
    pub y_m: f64,
    /// Votes of the corner.
    pub votes: u32,
    /// What the grid says the corner is.
    pub kind: FeatureKind,
    /// Free cells it covers that no tag chosen before covers.
    pub new_cells: usize,
}

/// The plan.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Plan {
    /// Proposed tags, in the order chosen.
    pub tags: Vec<ProposedTag>,
    /// Coverage and predicted error with them.
    #[serde(flatten)]
    pub prediction: Prediction,
}

/// The predicted localisation error with a set of tags.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Prediction {
    /// Share of the free cells that see at least one tag.
    pub coverage: f64,
    /// Free cells of the map.
    pub free_cells: usize,
    /// Predicted position error, mean over free cells, metres.
    pub predicted_error_mean_m: f64,
    /// Predicted position error, worst free cell, metres.
    pub predicted_error_max_m: f64,
    /// Share of the free cells a mapped wall holds (0 without walls).
    pub wall_held: f64,
    /// Free cells with no way over free cells to a covered one (left out of the mean and worst).
    pub unreachable_cells: usize,
    /// Predicted error at each cell of the map (row-major), metres; `None` where the cell is not
    /// free or no covered cell can be reached.
    #[serde(skip)]
    pub cell_errors_m: Vec<Option<f64>>,
}

impl Prediction {
    /// "predicted error mean M m, worst W m", or why there is none (a map without free cells,
    /// or none that reaches a cell seeing a tag), for a summary line.
    pub fn error_summary(&self) -> String {
        if self.predicted_error_mean_m.is_finite() && self.predicted_error_max_m.is_finite() {
            format!(
                "predicted error mean {:.3} m, worst {:.3} m",
                self.predicted_error_mean_m, self.predicted_error_max_m
            )
        } else if self.free_cells == 0 {
            "no predicted error: the map has no free cells".to_owned()
        } else {
            "no predicted error: no free cell reaches one that sees a tag".to_owned()
        }
    }
}

/// Predicts the localisation error with tags at `tags` (x, y in metres), the map's `walls`
/// holding the robot where they are in range (none: tags only).
pub fn predict(
    map: &OccupancyMap,
    tags: &[[f64; 2]],
    walls: &[WallSegment],
    config: &PlanConfig,
) -> Prediction {
    let g = &map.geometry;
    let free = free_cells(map);
    let mut seen = vec![false; g.width * g.height];
    for t in tags {
        for i in covered(map, (t[0], t[1]), &free, config) {
            seen[i] = true;
        }
    }
    prediction(map, &free, &seen, walls, config)
}

/// Coverage and predicted error, given which cells see a tag.
fn prediction(
    map: &OccupancyMap,
    free: &[usize],
    seen: &[bool],
    walls: &[WallSegment],
    config: &PlanConfig,
) -> Prediction {
    let n_seen = free.iter().filter(|&&i| seen[i]).count();
    let held = wall_held(map, free, walls, config);
    let field = predicted_error(map, free, seen, &held, config);
    Prediction {
        coverage: share(n_seen, free.len()),
        free_cells: free.len(),
        predicted_error_mean_m: field.mean_m,
        predicted_error_max_m: field.max_m,
        wall_held: share(held.iter().filter(|&&h| h).count(), free.len()),
        unreachable_cells: field.unreachable,
        cell_errors_m: field.cells_m,
    }
}

fn share(n: usize, of: usize) -> f64 {
    if of == 0 {
        0.0
    } else {
        n as f64 / of as f64
    }
}

fn free_cells(map: &OccupancyMap) -> Vec<usize> {
    let g = &map.geometry;
    (0..g.width * g.height)
        .filter(|&i| map.is_free(i))
        .collect()
}

/// Whether each cell (indexed like the map) lies in front of a wall's face, within
/// [`PlanConfig::wall_range_m`] of it and between its ends.
fn wall_held(
    map: &OccupancyMap,
    free: &[usize],
    walls: &[WallSegment],
    config: &PlanConfig,
) -> Vec<bool> {
    let g = &map.geometry;
    let mut held = vec![false; g.width * g.height];
    for &i in free {
        let [x, y] = g.centre(i % g.width, i / g.width);
        // The range a sonar facing the wall head-on would measure from here (a hair of cone:
        // the beam's angle to the normal rounds to about 1e-16 rad).
        held[i] = walls.iter().any(|w| {
            w.expected_range([x, y], w.normal_rad + std::f64::consts::PI, 1e-9, 0.0)
                .is_some_and(|d| d <= config.wall_range_m)
        });
    }
    held
}

/// Plans tag positions over a map's corners; the map's `walls` (may be empty) enter the
/// predicted error.
pub fn plan_tags(
    map: &OccupancyMap,
    corners: &[Feature],
    walls: &[WallSegment],
    config: &PlanConfig,
) -> Plan {
    let g = &map.geometry;
    let free = free_cells(map);
    let covers: Vec<Vec<usize>> = corners
        .iter()
        .map(|c| covered(map, (c.x_m, c.y_m), &free, config))
        .collect();
    let mut seen = vec![false; g.width * g.height];
    let mut chosen: Vec<ProposedTag> = Vec::new();
    let mut covered_count = 0usize;
    while chosen.len() < config.max_tags
        && (covered_count as f64) < config.target_coverage * free.len() as f64
    {
        let best = corners
            .iter()
            .zip(&covers)
            .filter(|(c, _)| {
                chosen
                    .iter()
                    .all(|t| (t.x_m - c.x_m).hypot(t.y_m - c.y_m) >= config.min_separation_m)
            })
            .map(|(c, cells)| (c, cells, cells.iter().filter(|&&i| !seen[i]).count()))
            .filter(|(_, _, n)| *n > 0)
            // Room corners before edges, then the most new cells, then the strongest corner.
            .max_by_key(|(c, _, n)| (c.kind == FeatureKind::Corner, *n, c.votes));
        let Some((c, cells, n)) = best else { break };
        for &i in cells {
            seen[i] = true;
        }
        covered_count += n;
        chosen.push(ProposedTag {
            x_m: c.x_m,
            y_m: c.y_m,
            votes: c.votes,
            kind: c.kind,
            new_cells: n,
        });
    }
    Plan {
        tags: chosen,
        prediction: prediction(map, &free, &seen, walls, config),
    }
}

/// Free cells in range and in line of sight of a tag at `at` (metres).
fn covered(map: &OccupancyMap, at: (f64, f64), free: &[usize], config: &PlanConfig) -> Vec<usize> {
    let g = &map.geometry;
    free.iter()
        .copied()
        .filter(|&i| {
            let [x, y] = g.centre(i % g.width, i / g.width);
            let d = (x - at.0).hypot(y - at.1);
            d <= config.capture_range_m && line_of_sight(map, (x, y), at, config)
        })
        .collect()
}

fn line_of_sight(
    map: &OccupancyMap,
    from: (f64, f64),
    to: (f64, f64),
    config: &PlanConfig,
) -> bool {
    let g = &map.geometry;
    let d = (to.0 - from.0).hypot(to.1 - from.1);
    let steps = (d / (0.5 * g.resolution_m)).ceil() as usize;
    (0..=steps).all(|k| {
        let f = k as f64 / steps.max(1) as f64;
        let (x, y) = (from.0 + (to.0 - from.0) * f, from.1 + (to.1 - from.1) * f);
        if (to.0 - x).hypot(to.1 - y) <= config.corner_clearance_m {
            return true;
        }
        g.cell_of(x, y)
            .is_none_or(|(col, row)| !map.is_occupied(row * g.width + col))
    })
}

/// The predicted error over a map.
struct ErrorField {
    /// Per cell, metres (`None`: not free, or no covered cell reachable).
    cells_m: Vec<Option<f64>>,
    /// Mean over the reachable free cells.
    mean_m: f64,
    /// Worst reachable free cell.
    max_m: f64,
    /// Free cells from which no covered cell can be reached.
    unreachable: usize,
}

/// The predicted error at each free cell: the sighting error plus the drift over the shortest way
/// from a covered cell, there and back (Dijkstra over free cells, each step costing its length
/// times the drift where it lands). A cell held by a wall starts from the smaller wall sighting
/// error, and a cell beside it is predicted from it when that is less: the robot drives out of
/// the walls' reach with the error they left it, and drifts from there.
fn predicted_error(
    map: &OccupancyMap,
    free: &[usize],
    seen: &[bool],
    held: &[bool],
    config: &PlanConfig,
) -> ErrorField {
    let g = &map.geometry;
    let step_um = |j: usize| {
        let rate = if held[j] {
            config.wall_drift_m_per_m
        } else {
            config.drift_m_per_m
        };
        (rate * g.resolution_m * 1e6).round() as u64
    };
    // Drift in micrometres, so the heap orders integers.
    let mut drift = vec![u64::MAX; seen.len()];
    for &i in free {
        if seen[i] {
            drift[i] = 0;
        }
    }
    relax(map, &mut drift, step_um);
    let mut error_um = drift;
    for &i in free {
        if error_um[i] != u64::MAX {
            let floor = if held[i] {
                config.wall_sighting_error_m
            } else {
                config.sighting_error_m
            };
            error_um[i] = (floor * 1e6).round() as u64 + 2 * error_um[i];
        }
    }
    relax(map, &mut error_um, |j| 2 * step_um(j));
    let mut cells_m = vec![None; seen.len()];
    let mut unreachable = 0;
    for &i in free {
        if error_um[i] == u64::MAX {
            unreachable += 1;
        } else {
            cells_m[i] = Some(error_um[i] as f64 * 1e-6);
        }
    }
    let errors: Vec<f64> = cells_m.iter().flatten().copied().collect();
    let (mean_m, max_m) = if errors.is_empty() {
        (f64::NAN, f64::NAN)
    } else {
        (
            errors.iter().sum::<f64>() / errors.len() as f64,
            errors.iter().copied().fold(0.0, f64::max),
        )
    };
    ErrorField {
        cells_m,
        mean_m,
        max_m,
        unreachable,
    }
}

/// Lowers each free cell's `cost` to the least over its free neighbours' plus `step` of the cell
/// (Dijkstra from every cell with a finite cost; `u64::MAX` is unreached).
fn relax(map: &OccupancyMap, cost: &mut [u64], step: impl Fn(usize) -> u64) {
    let width = map.geometry.width;
    let height = map.geometry.height;
    let mut heap: BinaryHeap<_> = (0..cost.len())
        .filter(|&i| cost[i] != u64::MAX)
        .map(|i| Reverse((cost[i], i)))
        .collect();
    while let Some(Reverse((d, i))) = heap.pop() {
        if d > cost[i] {
            continue;
        }
        let (col, row) = (i % width, i / width);
        let neighbours = [
            (col > 0).then(|| i - 1),
            (col + 1 < width).then(|| i + 1),
            (row > 0).then(|| i - width),
            (row + 1 < height).then(|| i + width),
        ];
        for j in neighbours.into_iter().flatten() {
            if map.is_free(j) {
                let dj = d + step(j);
                if dj < cost[j] {
                    cost[j] = dj;
                    heap.push(Reverse((dj, j)));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sonar::grid::GridGeometry;

    /// Two 4 m x 4 m rooms side by side (0.1 m cells), joined by a door in the middle wall.
    fn two_rooms() -> (OccupancyMap, Vec<Feature>) {
        let (w, h) = (82, 42);
        let geometry = GridGeometry {
            width: w,
            height: h,
            resolution_m: 0.1,
            origin_m: [0.0, 0.0],
        };
        let mut occupancy = vec![Some(0.0); w * h];
        for row in 0..h {
            for col in 0..w {
                let wall = col == 0 || col == w - 1 || row == 0 || row == h - 1;
                let middle = col == 41 && !(19..=23).contains(&row);
                if wall || middle {
                    occupancy[row * w + col] = Some(1.0);
                }
            }
        }
        let map = OccupancyMap {
            geometry,
            occupancy,
            occupied_threshold: 0.65,
            free_threshold: 0.2,
        };
        let corner = |x: f64, y: f64| Feature {
            x_m: x,
            y_m: y,
            votes: 60,
            sightings: 1,
            spread_deg: 90.0,
            kind: FeatureKind::Corner,
        };
        let corners = vec![
            corner(0.15, 0.15),
            corner(4.0, 4.0),
            corner(8.0, 0.15),
            corner(4.3, 0.2),
        ];
        (map, corners)
    }

    #[test]
    fn one_tag_per_room_and_none_twice_in_a_room() {
        let (map, corners) = two_rooms();
        let plan = plan_tags(
            &map,
            &corners,
            &[],
            &PlanConfig {
                capture_range_m: 6.0,
                ..PlanConfig::default()
            },
        );
        // A corner of each room covers it; the wall hides the other room.
        assert_eq!(plan.tags.len(), 2, "{plan:?}");
        let left = plan.tags.iter().filter(|t| t.x_m < 4.1).count();
        assert_eq!(left, 1, "{plan:?}");
        assert!(
            plan.prediction.coverage > 0.9,
            "{}",
            plan.prediction.coverage
        );
        assert!(plan.prediction.predicted_error_max_m < 0.1);
    }

    /// The inner faces of the two rooms' outer walls.
    fn room_walls() -> Vec<WallSegment> {
        let face = |normal_rad: f64, offset_m: f64, from_m: [f64; 2], to_m: [f64; 2]| WallSegment {
            normal_rad,
            offset_m,
            from_m,
            to_m,
            readings: 50,
            rms_m: 0.01,
            sigma_m: None,
        };
        use std::f64::consts::{FRAC_PI_2, PI};
        vec![
            // Bottom (y = 0.1, seen from above), top (y = 4.1), left (x = 0.1), right (x = 8.1).
            face(FRAC_PI_2, 0.1, [0.1, 0.1], [8.1, 0.1]),
            face(3.0 * FRAC_PI_2, -4.1, [8.1, 4.1], [0.1, 4.1]),
            face(0.0, 0.1, [0.1, 4.1], [0.1, 0.1]),
            face(PI, -8.1, [8.1, 0.1], [8.1, 4.1]),
        ]
    }

    #[test]
    fn walls_in_range_hold_the_robot_and_lower_the_predicted_error() {
        let (map, _) = two_rooms();
        let config = PlanConfig {
            capture_range_m: 1.5,
            ..PlanConfig::wheels_only()
        };
        let tags = [[0.15, 0.15]];
        let bare = predict(&map, &tags, &[], &config);
        let walled = predict(&map, &tags, &room_walls(), &config);
        assert_eq!(bare.wall_held, 0.0);
        // Everything within 1.5 m of an outer wall: the rooms but for a band through the middle.
        assert!(walled.wall_held > 0.7, "{}", walled.wall_held);
        assert_eq!(walled.coverage, bare.coverage);
        // The drift part (above the sighting error) at least halves.
        let drift = |p: &Prediction| p.predicted_error_mean_m - config.sighting_error_m;
        assert!(
            drift(&walled) < 0.5 * drift(&bare),
            "{} vs {}",
            walled.predicted_error_mean_m,
            bare.predicted_error_mean_m
        );
        // Seen cells keep the sighting error; the far room is reached through the door.
        assert_eq!(bare.unreachable_cells, 0);
        let far = map.geometry.cell_of(7.5, 3.5).unwrap();
        let far = bare.cell_errors_m[far.1 * map.geometry.width + far.0].unwrap();
        let near = map.geometry.cell_of(0.5, 0.5).unwrap();
        let near = bare.cell_errors_m[near.1 * map.geometry.width + near.0].unwrap();
        assert_eq!(near, config.sighting_error_m);
        assert!(far > near + 2.0 * config.drift_m_per_m * 7.0, "{far}");
        // With the cameras' turns a held cell seen by a tag starts from the smaller error.
        let visual = PlanConfig {
            capture_range_m: 1.5,
            ..PlanConfig::default()
        };
        let walled = predict(&map, &tags, &room_walls(), &visual);
        let near = map.geometry.cell_of(0.5, 0.5).unwrap();
        let near = walled.cell_errors_m[near.1 * map.geometry.width + near.0].unwrap();
        assert_eq!(near, visual.wall_sighting_error_m);
    }

    #[test]
    fn a_pocket_no_tag_can_reach_is_counted_apart() {
        let (mut map, _) = two_rooms();
        // Wall off a 4 x 6-cell pocket in the right room's top corner.
        let w = map.geometry.width;
        let pocket_walls = (34..41)
            .map(|row| (76, row))
            .chain((77..81).map(|col| (col, 34)));
        for (col, row) in pocket_walls {
            map.occupancy[row * w + col] = Some(1.0);
        }
        let config = PlanConfig::default();
        let p = predict(&map, &[[0.15, 0.15]], &[], &config);
        assert_eq!(p.unreachable_cells, 4 * 6);
        assert!(p.predicted_error_max_m.is_finite() && p.predicted_error_max_m < 1.0);
    }

    /// Without a tag no free cell has a predicted error, and the summary says why, not NaN.
    #[test]
    fn no_tag_predicts_no_error_and_says_why() {
        let (map, _) = two_rooms();
        let none = predict(&map, &[], &[], &PlanConfig::default());
        assert!(none.free_cells > 0 && none.predicted_error_mean_m.is_nan());
        assert_eq!(
            none.error_summary(),
            "no predicted error: no free cell reaches one that sees a tag"
        );
        let one = predict(&map, &[[0.15, 0.15]], &[], &PlanConfig::default());
        assert!(one.error_summary().starts_with("predicted error mean 0."));
    }

    #[test]
    fn a_short_range_leaves_cells_uncovered_and_predicts_more_error() {
        let (map, corners) = two_rooms();
        let wide = plan_tags(
            &map,
            &corners,
            &[],
            &PlanConfig {
                capture_range_m: 6.0,
                ..PlanConfig::default()
            },
        );
        let short = plan_tags(
            &map,
            &corners,
            &[],
            &PlanConfig {
                capture_range_m: 2.0,
                ..PlanConfig::default()
            },
        );
        assert!(short.prediction.coverage < wide.prediction.coverage);
        assert!(short.prediction.predicted_error_mean_m > wide.prediction.predicted_error_mean_m);
    }
}
