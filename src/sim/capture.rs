//! When a simulated robot takes its stereo pictures: whenever a tag is in view, and every so
//! often for the visual odometry; and the sensor-noise seed of each picture.

use crate::camera::StereoRig;
use crate::geometry::{wrap_angle, StampedPose};
use crate::render::{RenderConfig, RenderError, TagVisibility};
use crate::world::World;
use nalgebra::Vector3;

/// When to take stereo pictures along a run: whenever a tag is in view of both cameras within
/// `max_range_m`, at most once per `min_travel_m` of travel or `min_turn_rad` of turn; and, for the
/// visual odometry, with no tag in view as well once the robot has moved `every` since the last
/// picture.
#[derive(Debug, Clone, PartialEq)]
pub struct CapturePolicy {
    /// Farthest tag worth a picture (ours: 6 m; a 16 cm tag is still 12 px wide there).
    pub max_range_m: f64,
    /// Least travel between pictures (ours: 0.15 m).
    pub min_travel_m: f64,
    /// Least turn between pictures (ours: 10 degrees).
    pub min_turn_rad: f64,
    /// Travel (m) or turn (rad) after which a picture is taken whatever is in view (ours: 0.3 m
    /// or 20 degrees, so that consecutive pictures share most of what they see); `None` for
    /// pictures of tags only.
    pub every: Option<(f64, f64)>,
}

impl Default for CapturePolicy {
    fn default() -> Self {
        Self {
            max_range_m: 6.0,
            min_travel_m: 0.15,
            min_turn_rad: 10f64.to_radians(),
            every: Some((0.3, 20f64.to_radians())),
        }
    }
}

/// The stamped true poses at which pictures are taken.
pub fn plan_captures(
    world: &World,
    rig: &StereoRig,
    trajectory: &[StampedPose],
    policy: &CapturePolicy,
    config: &RenderConfig,
) -> Result<Vec<StampedPose>, RenderError> {
    let tags = TagVisibility::new(world)?;
    let mut out: Vec<StampedPose> = Vec::new();
    for p in trajectory {
        if let Some(last) = out.last() {
            let moved = (p.pose.x - last.pose.x).hypot(p.pose.y - last.pose.y);
            let turned = wrap_angle(p.pose.theta - last.pose.theta).abs();
            if moved < policy.min_travel_m && turned < policy.min_turn_rad {
                continue;
            }
            if policy
                .every
                .is_some_and(|(m, rad)| moved >= m || turned >= rad)
            {
                out.push(*p);
                continue;
            }
        } else if policy.every.is_some() {
            out.push(*p);
            continue;
        }
        let seen = tags.seen(rig, &p.pose, config);
        if seen
            .iter()
            .any(|t| Vector3::from(t.centre_in_left_m).norm() <= policy.max_range_m)
        {
            out.push(*p);
        }
    }
    Ok(out)
}

/// The sensor-noise seed of picture `k` of a run simulated with `seed`: `(seed - 1) x 10^6 + k + 1`,
/// so that runs of different seeds get independent noise even where their poses agree (a run with
/// perfect odometry), and seed 1 keeps the images it always had.
pub fn render_seed(seed: u64, k: usize) -> u64 {
    seed.wrapping_sub(1)
        .wrapping_mul(1_000_000)
        .wrapping_add(k as u64 + 1)
}

#[cfg(test)]
mod tests {
    use super::render_seed;

    #[test]
    fn each_run_seed_gets_its_own_picture_noise() {
        assert_eq!(render_seed(1, 0), 1);
        assert_eq!(render_seed(1, 41), 42);
        let mut seeds: Vec<u64> = (1..=5)
            .flat_map(|s| (0..1000).map(move |k| render_seed(s, k)))
            .collect();
        seeds.sort_unstable();
        seeds.dedup();
        assert_eq!(seeds.len(), 5000);
    }
}
