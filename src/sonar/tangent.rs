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

use std::cmp::Reverse;
use std::collections::BinaryHeap;

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
    /// The normal of the tangent line at `a`, in [0, pi): `a` wrapped into [0, 2 pi), less pi
    /// past pi.
    pub normal: f64,
    /// Whether `normal` is the wrapped `a` less pi (the line's offset then changes sign).
    pub flipped: bool,
    /// The nearest whole step to `normal` (180 for a normal just short of pi).
    pub normal_cell: usize,
}

/// The accumulator's directions inside the cone of half-width `half_cone_rad` around `beam_rad`,
/// in increasing order.
pub fn cone_steps(beam_rad: f64, half_cone_rad: f64) -> impl Iterator<Item = ConeStep> {
    steps_between(cone_range(beam_rad, half_cone_rad))
}

/// The indices `k` of [`cone_steps`].
pub fn cone_range(beam_rad: f64, half_cone_rad: f64) -> std::ops::RangeInclusive<i64> {
    let step = ANGLE_STEP_DEG.to_radians();
    let lo = ((beam_rad - half_cone_rad) / step).ceil() as i64;
    let hi = ((beam_rad + half_cone_rad) / step).floor() as i64;
    lo..=hi
}

/// Steps whose sines and cosines are kept in a table: three turns either way (a beam's angle
/// comes from a trajectory's heading, which need not be wrapped).
const TABLE_STEPS: i64 = 3 * 360;

/// The steps `ks` with their sines and cosines: looked up for the usual angles (each was
/// computed as `(k * step).sin_cos()`, so the values are the same), computed beyond.
pub fn steps_between(ks: std::ops::RangeInclusive<i64>) -> impl Iterator<Item = ConeStep> {
    static TABLE: std::sync::OnceLock<Vec<ConeStep>> = std::sync::OnceLock::new();
    let step = ANGLE_STEP_DEG.to_radians();
    let at = move |k: i64| {
        let a = k as f64 * step;
        let (sin, cos) = a.sin_cos();
        let wrapped = a.rem_euclid(std::f64::consts::TAU);
        let flipped = wrapped >= std::f64::consts::PI;
        let normal = if flipped {
            wrapped - std::f64::consts::PI
        } else {
            wrapped
        };
        ConeStep {
            k,
            sin,
            cos,
            normal,
            flipped,
            // `round` (the normal lies within rounding of a whole step, far from a half).
            normal_cell: (normal / step + 0.5) as usize,
        }
    };
    let table = TABLE.get_or_init(|| (-TABLE_STEPS..=TABLE_STEPS).map(at).collect());
    ks.map(move |k| match usize::try_from(k + TABLE_STEPS) {
        Ok(i) if i < table.len() => table[i],
        _ => at(k),
    })
}

/// The largest error of [`fast_atan2`], radians (its polynomial's is 1.2e-5 measured over a
/// turn; this leaves room).
pub const FAST_ATAN2_ERROR: f64 = 2e-5;

/// `y.atan2(x)` to within [`FAST_ATAN2_ERROR`]: a polynomial in the ratio of the smaller
/// coordinate to the larger, the octant restored after. Abramowitz and Stegun 4.4.49 (error
/// about 1e-5).
pub fn fast_atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    if ax == 0.0 && ay == 0.0 {
        return 0.0;
    }
    let t = ax.min(ay) / ax.max(ay);
    let t2 = t * t;
    let mut a = t
        * (0.999_866_0
            + t2 * (-0.330_299_5 + t2 * (0.180_141_0 + t2 * (-0.085_133_0 + t2 * 0.020_835_1))));
    if ay > ax {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 {
        -a
    } else {
        a
    }
}

/// The largest error of [`fast_acos`], radians (its polynomial's is 6.8e-5 by Abramowitz and
/// Stegun; this leaves room).
pub const FAST_ACOS_ERROR: f64 = 1e-4;

/// `x.acos()` to within [`FAST_ACOS_ERROR`] for `x` in [-1, 1]: Abramowitz and Stegun 4.4.45,
/// `sqrt(1 - |x|)` times a cubic, mirrored for negative `x`.
pub fn fast_acos(x: f64) -> f64 {
    let a = x.abs();
    let r =
        (1.0 - a).sqrt() * (1.570_728_8 + a * (-0.212_114_4 + a * (0.074_261_0 - a * 0.018_729_3)));
    if x < 0.0 {
        std::f64::consts::PI - r
    } else {
        r
    }
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
}

/// The strongest cell of a [`LineVotes`] grid whose counts only go down, found again after each
/// change without a look at the whole grid: a heap of the cells' counts, a cell's entry renewed
/// when it is found stale. Searching the whole grid again for each wall took a building's walls 0.1 s.
pub struct Strongest(BinaryHeap<(u32, Reverse<usize>)>);

impl Strongest {
    /// The cells of `votes` with `at_least` votes (1 at least): a caller that stops below a
    /// count leaves the cells under it out of the heap (most cells of a grid hold a vote or two).
    pub fn new(votes: &LineVotes, at_least: u32) -> Self {
        let cells = votes.counts.iter().enumerate();
        Self(
            cells
                .filter(|(_, &c)| c >= at_least.max(1))
                .map(|(i, &c)| (c, Reverse(i)))
                .collect(),
        )
    }

    /// The cells `cells` of `votes` (those with `at_least` votes among them, 1 at least).
    pub fn of_cells(votes: &LineVotes, cells: &[usize], at_least: u32) -> Self {
        let counts = cells.iter().map(|&i| (votes.counts[i], i));
        Self(
            counts
                .filter(|&(c, _)| c >= at_least.max(1))
                .map(|(c, i)| (c, Reverse(i)))
                .collect(),
        )
    }

    /// The cell with the most votes now (the first of several: the lowest index),
    /// `None` when every count is zero. Counts may only have gone down since the last call.
    pub fn next(&mut self, votes: &LineVotes) -> Option<(usize, u32)> {
        while let Some(&(count, Reverse(i))) = self.0.peek() {
            let now = votes.counts[i];
            if now == count {
                return Some((i, count));
            }
            self.0.pop();
            if now > 0 {
                self.0.push((now, Reverse(i)));
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fast_arccosine_is_within_its_bound() {
        for k in 0..=200_000 {
            let x = -1.0 + k as f64 * 1e-5;
            let x = x.clamp(-1.0, 1.0);
            let e = fast_acos(x) - x.acos();
            assert!(e.abs() < FAST_ACOS_ERROR, "{x}: {e}");
        }
    }

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
        assert_eq!(Strongest::new(&votes, 1).next(&votes), None);
        votes.counts = vec![1, 4, 0, 4, 2, 0];
        let mut strongest = Strongest::new(&votes, 1);
        assert_eq!(strongest.next(&votes), Some((1, 4)));
        assert!((votes.offset_m(1) - 0.0).abs() < 1e-12);
        // Counts going down: the heap's stale entries give way to the cells' counts now.
        votes.counts[1] = 0;
        votes.counts[3] = 1;
        assert_eq!(strongest.next(&votes), Some((4, 2)));
        assert_eq!(
            Strongest::of_cells(&votes, &[0, 3], 1).next(&votes),
            Some((0, 1))
        );
        let empty = LineVotes::new(0, 3, 0.0);
        assert_eq!(Strongest::new(&empty, 1).next(&empty), None);
    }
}
