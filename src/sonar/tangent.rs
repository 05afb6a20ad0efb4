//! The tangent-line Hough transform of sonar readings, shared by the walls near a corner
//! ([`crate::sonar::corners`]) and the walls of a whole map ([`crate::sonar::walls`]).
//!
//! A sonar echo off a flat wall comes from the foot of the perpendicular, so the wall is tangent
//! to the reading's arc: for each direction `a` inside the cone (every [`ANGLE_STEP_DEG`]), the
//! reading votes for the line perpendicular to `a` touching the arc at `sensor + range u(a)`
//! (Tardós et al., "Robust mapping and localization in indoor environments using sonar data",
//! 2002). Lines are binned by their normal's angle and their offset ([`DIST_STEP_M`]) in a
//! [`LineVotes`] grid. Each user folds the lines into the grid its own way: near a corner both
//! sides of a line are one (normals in [0, π)), over a map a wall's face keeps the side it was
//! seen from (normals all round).

/// Angular cell of the accumulators: 1 degree (the cone is 30 degrees, a wall's direction is
/// then fitted to the ranges).
pub const ANGLE_STEP_DEG: f64 = 1.0;
/// Offset cell of the accumulators: 3 cm (range noise is about 1-2 cm).
pub const DIST_STEP_M: f64 = 0.03;

/// One direction inside a reading's cone, a multiple of [`ANGLE_STEP_DEG`]: its index `k`
/// (`a = k` steps) and the sine and cosine of `a`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeStep {
    /// The direction in accumulator steps.
    pub k: i64,
    /// `sin a`.
    pub sin: f64,
    /// `cos a`.
    pub cos: f64,
}

/// The accumulator's directions inside the cone of half-width `half_cone_rad` around `beam_rad`,
/// in increasing order.
pub fn cone_steps(beam_rad: f64, half_cone_rad: f64) -> impl Iterator<Item = ConeStep> {
    let step = ANGLE_STEP_DEG.to_radians();
    let lo = ((beam_rad - half_cone_rad) / step).ceil() as i64;
    let hi = ((beam_rad + half_cone_rad) / step).floor() as i64;
    (lo..=hi).map(move |k| {
        let (sin, cos) = (k as f64 * step).sin_cos();
        ConeStep { k, sin, cos }
    })
}

/// A grid of votes for lines: `n_angle` cells of [`ANGLE_STEP_DEG`] of normal direction by
/// `n_dist` cells of [`DIST_STEP_M`] of offset, offsets from `-reach_m`.
#[derive(Debug, Clone, PartialEq)]
pub struct LineVotes {
    /// Angle cells.
    pub n_angle: usize,
    /// Offset cells.
    pub n_dist: usize,
    /// The offset at the low edge of cell 0 is `-reach_m`.
    pub reach_m: f64,
    /// Votes, angle-major: cell `(ia, id)` at `ia * n_dist + id`.
    pub counts: Vec<u32>,
}

impl LineVotes {
    /// An empty grid.
    pub fn new(n_angle: usize, n_dist: usize, reach_m: f64) -> Self {
        Self {
            n_angle,
            n_dist,
            reach_m,
            counts: vec![0; n_angle * n_dist],
        }
    }

    /// The normal direction of angle cell `ia`, radians.
    pub fn angle_rad(&self, ia: usize) -> f64 {
        ia as f64 * ANGLE_STEP_DEG.to_radians()
    }

    /// The offset at the middle of offset cell `id`, metres.
    pub fn offset_m(&self, id: usize) -> f64 {
        -self.reach_m + (id as f64 + 0.5) * DIST_STEP_M
    }

    /// The cell with the most votes (the first of several), and its votes; `None` for an empty
    /// grid.
    pub fn strongest(&self) -> Option<(usize, u32)> {
        let &v = self.counts.iter().max()?;
        Some((self.counts.iter().position(|&x| x == v).unwrap_or(0), v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cone_holds_every_whole_degree_inside_it() {
        let steps: Vec<i64> = cone_steps(0.5_f64.to_radians(), 15f64.to_radians())
            .map(|s| s.k)
            .collect();
        assert_eq!(steps, (-14..=15).collect::<Vec<_>>());
        let s = cone_steps(90f64.to_radians(), 0.1f64.to_radians())
            .next()
            .unwrap();
        assert!((s.k, s.cos.abs() < 1e-12, (s.sin - 1.0).abs() < 1e-12) == (90, true, true));
    }

    #[test]
    fn the_strongest_cell_is_the_first_with_the_most_votes() {
        let mut votes = LineVotes::new(2, 3, 0.045);
        assert_eq!(votes.strongest(), Some((0, 0)));
        votes.counts = vec![1, 4, 0, 4, 2, 0];
        assert_eq!(votes.strongest(), Some((1, 4)));
        assert!((votes.offset_m(1) - 0.0).abs() < 1e-12);
        assert_eq!(LineVotes::new(0, 3, 0.0).strongest(), None);
    }
}
