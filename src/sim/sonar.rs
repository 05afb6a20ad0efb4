//! Simulated sonar: each transducer's cone sampled by rays against the walls and people, with
//! specular echoes, corner reflectors, weak edges, multipath, noise and drop-outs.

use crate::geometry::{wrap_angle, Pose2};
use crate::sonar::SonarLayout;
use crate::world::World;
use nalgebra::Vector2;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Sonar physics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SonarPhysics {
    /// Constant part of the range noise, metres (ours: 1 cm).
    pub range_sigma_m: f64,
    /// Part of the range noise proportional to the range (ours: 1%).
    pub range_sigma_frac: f64,
    /// Probability that a reading with an echo is lost: 2.3%, measured on the UCI wall-following
    /// robot (readings whose two neighbouring sonars both saw a wall within 1 m; see
    /// [`dropout_rate_from_ring`]).
    pub dropout_prob: f64,
    /// A ray echoes from a wall only within this angle of its normal (ours: 10 degrees).
    pub roughness_deg: f64,
    /// Probability that a cone with no direct echo reports a long multipath reading (ours: 0.2).
    pub multipath_prob: f64,
    /// Probability that a convex edge or a wall end inside the cone echoes (ours: 0.3).
    pub edge_echo_prob: f64,
    /// Probability that a person in the cone echoes (ours: 0.9).
    pub person_echo_prob: f64,
    /// Rays sampled across the cone (ours: 31, one per degree).
    pub rays_per_cone: usize,
    /// Shortest range the transducer can report (ours: 0.1 m).
    pub min_range_m: f64,
}

impl Default for SonarPhysics {
    fn default() -> Self {
        Self {
            range_sigma_m: 0.01,
            range_sigma_frac: 0.01,
            dropout_prob: 0.023,
            roughness_deg: 10.0,
            multipath_prob: 0.2,
            edge_echo_prob: 0.3,
            person_echo_prob: 0.9,
            rays_per_cone: 31,
            min_range_m: 0.1,
        }
    }
}

/// Simulates one sonar reading from `world_from_sensor` at time `t_s`.
pub fn simulate_reading(
    world: &World,
    t_s: f64,
    world_from_sensor: Pose2,
    layout: &SonarLayout,
    physics: &SonarPhysics,
    rng: &mut impl Rng,
) -> Option<f64> {
    let half = 0.5 * layout.cone_rad;
    let max = layout.max_range_m;
    let o = world_from_sensor.position();
    let roughness = physics.roughness_deg.to_radians().cos();
    let person_echoes = rng.random::<f64>() < physics.person_echo_prob;
    let mut best = f64::INFINITY;
    let mut axis_range = max;
    let n = physics.rays_per_cone;
    for k in 0..n {
        let a = world_from_sensor.theta - half + layout.cone_rad * k as f64 / (n - 1) as f64;
        let dir = Vector2::new(a.cos(), a.sin());
        let wall = world.ray_cast_walls(o, dir, max);
        if k == n / 2 {
            axis_range = wall.map_or(max, |h| h.range_m);
        }
        if person_echoes {
            if let Some(p) = world.ray_cast_people(t_s, o, dir, wall.map_or(max, |h| h.range_m)) {
                best = best.min(p.range_m);
            }
        }
        if let Some(h) = wall {
            if h.normal.dot(&-dir) >= roughness {
                best = best.min(h.range_m);
            }
        }
    }
    for v in &world.vertices {
        let d = v.position - o;
        let dist = d.norm();
        if dist > max || dist >= best || dist < 1e-6 {
            continue;
        }
        if wrap_angle(d.y.atan2(d.x) - world_from_sensor.theta).abs() > half {
            continue;
        }
        let concave = v.is_concave_from(o);
        if !concave && (dist > 0.7 * max || rng.random::<f64>() >= physics.edge_echo_prob) {
            continue;
        }
        if world.line_of_sight(o, o + d * ((dist - 0.02) / dist)) {
            best = dist;
        }
    }
    if best.is_finite() {
        if rng.random::<f64>() < physics.dropout_prob {
            return None;
        }
        let sigma = physics.range_sigma_m + physics.range_sigma_frac * best;
        let r = best + sigma * rng.sample::<f64, _>(rand_distr::StandardNormal);
        return (r <= max).then_some(r.max(physics.min_range_m));
    }
    if rng.random::<f64>() < physics.multipath_prob {
        let r = axis_range * rng.random_range(1.3..2.0);
        return (r <= max).then_some(r);
    }
    None
}

/// Share of no-echo readings among readings of a sonar ring whose two neighbouring transducers
/// both saw something nearer than `near_m`: an estimate of the random drop-out rate.
/// `rows` hold one range per transducer in ring order; `no_echo_m` is the value meaning no echo.
pub fn dropout_rate_from_ring(rows: &[Vec<f64>], near_m: f64, no_echo_m: f64) -> Option<f64> {
    let (mut n, mut lost) = (0usize, 0usize);
    for row in rows {
        let k = row.len();
        for i in 0..k {
            let (l, r) = (row[(i + k - 1) % k], row[(i + 1) % k]);
            if l < near_m && r < near_m {
                n += 1;
                lost += (row[i] >= no_echo_m) as usize;
            }
        }
    }
    (n > 0).then(|| lost as f64 / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn corridor() -> World {
        crate::world::rectangle_world(6.0, 3.0, Pose2::new(2.0, 1.5, 0.0))
    }

    #[test]
    fn perpendicular_wall_echoes_at_its_distance() {
        let w = corridor();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let physics = SonarPhysics {
            dropout_prob: 0.0,
            range_sigma_m: 0.0,
            range_sigma_frac: 0.0,
            ..Default::default()
        };
        let r = simulate_reading(
            &w,
            0.0,
            Pose2::new(5.0, 1.5, 0.0),
            &SonarLayout::frontal5(),
            &physics,
            &mut rng,
        );
        assert!((r.unwrap() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn steep_wall_gives_no_direct_echo() {
        let w = corridor();
        let physics = SonarPhysics {
            multipath_prob: 0.0,
            edge_echo_prob: 0.0,
            dropout_prob: 0.0,
            ..Default::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // 50 degrees off the wall normal, no corner in the cone.
        let r = simulate_reading(
            &w,
            0.0,
            Pose2::new(3.0, 1.5, 40f64.to_radians()),
            &SonarLayout::frontal5(),
            &physics,
            &mut rng,
        );
        assert!(r.is_none(), "{r:?}");
    }
}
