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
//! cell and back (breadth-first distance over free cells).

use crate::grid::OccupancyMap;
use crate::hough::{Feature, FeatureKind};
use serde::Serialize;
use std::collections::VecDeque;

/// Settings of the planner. Defaults say where they come from.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
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
    /// Position error right after a sighting, metres (ours: 2 cm, the surveyed landmark error).
    pub sighting_error_m: f64,
    /// Odometry drift per metre travelled, metres (ours: 3 cm/m, about what the office runs show
    /// for the simulated wheel errors between sightings).
    pub drift_m_per_m: f64,
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
            sighting_error_m: 0.02,
            drift_m_per_m: 0.03,
            corner_clearance_m: 0.3,
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
    /// Share of the free cells that see at least one proposed tag.
    pub coverage: f64,
    /// Free cells of the map.
    pub free_cells: usize,
    /// Predicted position error, mean over free cells, metres.
    pub predicted_error_mean_m: f64,
    /// Predicted position error, worst free cell, metres.
    pub predicted_error_max_m: f64,
}

/// Plans tag positions over a map's corners.
pub fn plan_tags(map: &OccupancyMap, corners: &[Feature], config: &PlanConfig) -> Plan {
    let g = &map.geometry;
    let free: Vec<usize> = (0..g.width * g.height)
        .filter(|&i| map.is_free(i))
        .collect();
    let covers: Vec<Vec<usize>> = corners
        .iter()
        .map(|c| covered(map, c, &free, config))
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
    let (mean, max) = predicted_error(map, &free, &seen, config);
    Plan {
        tags: chosen,
        coverage: if free.is_empty() {
            0.0
        } else {
            covered_count as f64 / free.len() as f64
        },
        free_cells: free.len(),
        predicted_error_mean_m: mean,
        predicted_error_max_m: max,
    }
}

/// Free cells in range and in line of sight of a corner.
fn covered(map: &OccupancyMap, c: &Feature, free: &[usize], config: &PlanConfig) -> Vec<usize> {
    let g = &map.geometry;
    free.iter()
        .copied()
        .filter(|&i| {
            let (x, y) = g.centre(i % g.width, i / g.width);
            let d = (x - c.x_m).hypot(y - c.y_m);
            d <= config.capture_range_m && line_of_sight(map, (x, y), (c.x_m, c.y_m), config)
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

/// Mean and worst predicted error over the free cells: breadth-first distance to a covered cell.
fn predicted_error(
    map: &OccupancyMap,
    free: &[usize],
    seen: &[bool],
    config: &PlanConfig,
) -> (f64, f64) {
    let g = &map.geometry;
    let mut dist = vec![usize::MAX; seen.len()];
    let mut queue = VecDeque::new();
    for &i in free {
        if seen[i] {
            dist[i] = 0;
            queue.push_back(i);
        }
    }
    while let Some(i) = queue.pop_front() {
        let (col, row) = (i % g.width, i / g.width);
        let neighbours = [
            (col > 0).then(|| i - 1),
            (col + 1 < g.width).then(|| i + 1),
            (row > 0).then(|| i - g.width),
            (row + 1 < g.height).then(|| i + g.width),
        ];
        for j in neighbours.into_iter().flatten() {
            if dist[j] == usize::MAX && map.is_free(j) {
                dist[j] = dist[i] + 1;
                queue.push_back(j);
            }
        }
    }
    if free.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let errors: Vec<f64> = free
        .iter()
        .map(|&i| {
            // A cell no tag can be reached from: the whole map's extent as the distance.
            let cells = if dist[i] == usize::MAX {
                g.width + g.height
            } else {
                dist[i]
            };
            config.sighting_error_m + config.drift_m_per_m * 2.0 * cells as f64 * g.resolution_m
        })
        .collect();
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    let max = errors.iter().copied().fold(0.0, f64::max);
    (mean, max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridGeometry;

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
            &PlanConfig {
                capture_range_m: 6.0,
                ..PlanConfig::default()
            },
        );
        // A corner of each room covers it; the wall hides the other room.
        assert_eq!(plan.tags.len(), 2, "{plan:?}");
        let left = plan.tags.iter().filter(|t| t.x_m < 4.1).count();
        assert_eq!(left, 1, "{plan:?}");
        assert!(plan.coverage > 0.9, "{}", plan.coverage);
        assert!(plan.predicted_error_max_m < 0.1);
    }

    #[test]
    fn a_short_range_leaves_cells_uncovered_and_predicts_more_error() {
        let (map, corners) = two_rooms();
        let wide = plan_tags(
            &map,
            &corners,
            &PlanConfig {
                capture_range_m: 6.0,
                ..PlanConfig::default()
            },
        );
        let short = plan_tags(
            &map,
            &corners,
            &PlanConfig {
                capture_range_m: 2.0,
                ..PlanConfig::default()
            },
        );
        assert!(short.coverage < wide.coverage);
        assert!(short.predicted_error_mean_m > wide.predicted_error_mean_m);
    }
}
