//! How noisy a run's measurements were, told by the run itself: the variance components of the
//! solved offline graph (Förstner's estimate). Each group of residual rows weighed with one
//! noise model (the odometry's translation; its heading where turning makes most of the
//! modelled noise, and where travelling does; the sightings; the visual turns) gets a factor on
//! its variance: the group's summed squared whitened residuals over its redundancy, the rows
//! less the trace of the group's block of the hat matrix `J Σ Jᵀ` (`Σ` the solution's
//! covariance), taken by Hutchinson's estimator with random signs on the group's rows through
//! the sparse Cholesky the solver uses. The factors are iterated, each round moving the solution
//! by a Gauss-Newton step under the new weights, since each group's share depends on the others'.
//!
//! What it is for: the odometry's noise model ([`crate::fusion::FuseConfig`]) is set to cover
//! any robot's wheels; a survey measures this robot's, and `localize` predicts with it. The
//! simulated homes' seed-1 surveys find the translation at 0.13-0.18 of the model, the turns at
//! 0.34-0.56 and the drift at about 0.8; predicting with the model, `localize`'s position NEES on
//! the office was 0.16-0.31, with the measured noise 0.43-1.01 (docs/RESULTS.md).
//!
//! The solution's covariance under the measured noise ([`SolutionCovariance`]) then places the
//! survey's corrected walls: how far each may be off, and how they err together.

use super::graph::{Graph, Linearised, Noise, Vector};
use std::collections::HashMap;
use tiny_solver::linear::sparse::SparseLinearSolver;

/// The groups, in the order of [`NoiseScales::redundancy`].
const GROUPS: [Noise; 5] = [
    Noise::OdometryTranslation,
    Noise::OdometryTurning,
    Noise::OdometryDrift,
    Noise::Sighting,
    Noise::Turn,
];
/// Random probes of Hutchinson's trace estimator, on each group's residual rows (32: every
/// group's redundancy within 1-2 of 128 probes' on the sample surveys; probes on the variables
/// scattered by tens: the office's odometry translation 19-20 here, 36 there).
const PROBES: usize = 16;
/// Rounds of the iteration at most (it settles within 1% in 3-4 on the sample surveys).
const ROUNDS: usize = 6;
/// A group's factor is estimated only from this much redundancy: its sigma then scatters by
/// about a fifth, `1 / √(2 r)` (the simulated office's odometry translation has 20).
const MIN_REDUNDANCY: f64 = 10.0;

/// The measured noise of a run's groups of measurements, each as a factor on its model's sigma
/// (1: as modelled; 0.5: half as noisy), with the redundancy it rests on; `None` where a group has
/// too little (a redundancy under 10).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseScales {
    /// The odometry's translation, on [`crate::fusion::FuseConfig::odometry_sigma_m_per_sqrt_m`].
    pub odometry_translation: Option<f64>,
    /// The odometry's heading changes where turning makes most of their modelled noise, on the
    /// heading noise per radian turned ([`crate::fusion::FuseConfig::heading_sigma_per_sqrt_rad`]
    /// and its calibrated value).
    pub odometry_turning: Option<f64>,
    /// ... where travelling does, on
    /// [`crate::fusion::FuseConfig::heading_sigma_per_sqrt_m`].
    pub odometry_drift: Option<f64>,
    /// The tag sightings'.
    pub sightings: Option<f64>,
    /// The visual turns'.
    pub turns: Option<f64>,
    /// Each group's redundancy (odometry translation, turning, drift, sightings, visual turns).
    pub redundancy: [f64; 5],
}

/// The variance components of `graph` solved at `values`; `None` when its information is
/// singular or it holds no measurement.
pub(super) fn variance_components(
    graph: &Graph,
    values: &HashMap<String, Vector>,
) -> Option<NoiseScales> {
    let linear = Linearised::at(&graph.problem, values);
    let (rows, cols) = (linear.jacobian.nrows(), linear.jacobian.ncols());
    let group_of = groups_of_rows(graph, rows)?;
    let mut count = [0usize; GROUPS.len()];
    for g in group_of.iter().flatten() {
        count[*g] += 1;
    }
    if count.iter().all(|&c| c == 0) {
        return None;
    }
    // Random signs on the residual rows: group g's k-th probe is z on its rows, 0 elsewhere.
    let probes = rademacher(rows, PROBES);
    let mut variance = [1.0f64; GROUPS.len()];
    let mut redundancy = [0.0f64; GROUPS.len()];
    let mut solver = tiny_solver::linear::SparseCholeskySolver::new();
    for round in 0..ROUNDS {
        let weight: Vec<f64> = group_of
            .iter()
            .map(|g| g.map_or(1.0, |g| 1.0 / variance[g].sqrt()))
            .collect();
        let jacobian = weighted(&linear.jacobian, &weight);
        let information = Linearised::information(&jacobian)?;
        // Each group's probes carried into the variables: Jgᵀ zg.
        // ... and, last, the gradient `Jᵀ e` under these weights: the solution moves by a
        // Gauss-Newton step as the weights change (the residuals are those of a solution
        // weighed as modelled; a group given too much weight keeps too little of the misfit).
        let gradient = GROUPS.len() * PROBES;
        let mut rhs = faer::Mat::<f64>::zeros(cols, gradient + 1);
        for c in 0..cols {
            let at = jacobian.row_idx_of_col_raw(c);
            for (&v, &r) in jacobian.val_of_col(c).iter().zip(at) {
                rhs[(c, gradient)] += v * weight[r] * linear.residuals[(r, 0)];
                if let Some(g) = group_of[r] {
                    for k in 0..PROBES {
                        rhs[(c, g * PROBES + k)] += v * probes[(r, k)];
                    }
                }
            }
        }
        let solved = solver.solve_jtj(&rhs, &information)?;
        let mut residuals: Vec<f64> = (0..rows).map(|r| linear.residuals[(r, 0)]).collect();
        for c in 0..cols {
            let at = linear.jacobian.row_idx_of_col_raw(c);
            for (&v, &r) in linear.jacobian.val_of_col(c).iter().zip(at) {
                residuals[r] -= v * solved[(c, gradient)];
            }
        }
        let mut chi2 = [0.0f64; GROUPS.len()];
        for (r, g) in group_of.iter().enumerate() {
            if let Some(g) = *g {
                chi2[g] += (weight[r] * residuals[r]).powi(2);
            }
        }
        let mut settled = true;
        for g in 0..GROUPS.len() {
            // zgᵀ Jg Σ Jgᵀ zg: the probes' estimate of the trace of the group's block of the hat
            // matrix, whose complement is the group's redundancy.
            let mut trace = 0.0;
            for c in 0..cols {
                for k in 0..PROBES {
                    trace += rhs[(c, g * PROBES + k)] * solved[(c, g * PROBES + k)];
                }
            }
            redundancy[g] = count[g] as f64 - trace / PROBES as f64;
            if redundancy[g] >= MIN_REDUNDANCY && chi2[g].is_finite() {
                let factor = chi2[g] / redundancy[g];
                settled &= (factor - 1.0).abs() < 0.01;
                variance[g] *= factor;
            }
        }
        if settled {
            tracing::debug!("variance components settled after {} rounds", round + 1);
            break;
        }
    }
    let scale = |g: usize| {
        (redundancy[g] >= MIN_REDUNDANCY && variance[g].is_finite() && variance[g] > 0.0)
            .then(|| variance[g].sqrt())
    };
    Some(NoiseScales {
        odometry_translation: scale(0),
        odometry_turning: scale(1),
        odometry_drift: scale(2),
        sightings: scale(3),
        turns: scale(4),
        redundancy,
    })
}

/// The group (its index in [`GROUPS`]) of each of a graph's `rows` residual rows; `None` for a
/// row of no group (a prior, a range off a wall), and as a whole when a row's noise is of none.
fn groups_of_rows(graph: &Graph, rows: usize) -> Option<Vec<Option<usize>>> {
    let mut group_of = vec![None; rows];
    for &(r, noise) in graph.measured_rows.iter().filter(|(r, _)| *r < rows) {
        group_of[r] = Some(GROUPS.iter().position(|n| *n == noise)?);
    }
    Some(group_of)
}

/// `jacobian` with each row multiplied by its `weight`.
fn weighted(
    jacobian: &faer::sparse::SparseColMat<usize, f64>,
    weight: &[f64],
) -> faer::sparse::SparseColMat<usize, f64> {
    let mut out = jacobian.clone();
    for c in 0..jacobian.ncols() {
        let at = jacobian.row_idx_of_col_raw(c);
        for (v, &r) in out.val_of_col_mut(c).iter_mut().zip(at) {
            *v *= weight[r];
        }
    }
    out
}

/// The offline solution's covariance with the noise the run measured, kept to answer for
/// linear functions of the keyframe poses ([`SolutionCovariance::of`]): the graph's information
/// (`JᵀJ` of its whitened residuals, each group's rows weighed by the noise measured) and where
/// each keyframe pose's columns lie.
#[derive(Debug, Clone)]
pub struct SolutionCovariance {
    information: faer::sparse::SparseColMat<usize, f64>,
    /// Each keyframe's time and first column (`None`: held fixed).
    keyframes: Vec<(f64, Option<usize>)>,
}

/// A linear function of the keyframe poses: `Σ gᵀ δpose[k]` over its `(k, g)`, `g` the
/// gradient over the keyframe's x, y (metres) and heading (radians).
pub type PoseFunction = Vec<(usize, nalgebra::Vector3<f64>)>;

impl SolutionCovariance {
    /// `graph` solved at `values`, with each group's rows weighed by the noise the run
    /// measured (`scales`; a group not measured as modelled), its keyframes at `times`; `None`
    /// when a row's group is unknown.
    pub(super) fn at(
        graph: &Graph,
        values: &HashMap<String, Vector>,
        scales: &NoiseScales,
        times: &[f64],
    ) -> Option<Self> {
        let linear = Linearised::at(&graph.problem, values);
        let measured = [
            scales.odometry_translation,
            scales.odometry_turning,
            scales.odometry_drift,
            scales.sightings,
            scales.turns,
        ];
        let weight: Vec<f64> = groups_of_rows(graph, linear.jacobian.nrows())?
            .iter()
            .map(|g| g.and_then(|g| measured[g]).map_or(1.0, |s| 1.0 / s))
            .collect();
        let information = Linearised::information(&weighted(&linear.jacobian, &weight))?;
        let total = information.ncols();
        let keyframes = times
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                let c = linear.columns.get(&super::graph::pose_name(i)).copied();
                (t, c.filter(|&c| c + 3 <= total))
            })
            .collect();
        Some(Self {
            information,
            keyframes,
        })
    }

    /// The keyframe nearest in time to `t_s`; `None` with no keyframe.
    pub fn keyframe_at(&self, t_s: f64) -> Option<usize> {
        let after = self.keyframes.partition_point(|k| k.0 < t_s);
        [
            after.checked_sub(1),
            (after < self.keyframes.len()).then_some(after),
        ]
        .into_iter()
        .flatten()
        .min_by(|&a, &b| {
            (self.keyframes[a].0 - t_s)
                .abs()
                .total_cmp(&(self.keyframes[b].0 - t_s).abs())
        })
    }

    /// The covariance matrix of `functions` of the keyframe poses (one solve of the
    /// information against all of them; a keyframe held fixed counts as known); `None` when
    /// the information is singular.
    pub fn of(&self, functions: &[PoseFunction]) -> Option<nalgebra::DMatrix<f64>> {
        if functions.is_empty() {
            return Some(nalgebra::DMatrix::zeros(0, 0));
        }
        let total = self.information.ncols();
        let mut rhs = faer::Mat::<f64>::zeros(total, functions.len());
        for (j, f) in functions.iter().enumerate() {
            for (k, g) in f {
                if let Some(Some(c)) = self.keyframes.get(*k).map(|k| k.1) {
                    for r in 0..3 {
                        rhs[(c + r, j)] += g[r];
                    }
                }
            }
        }
        let x =
            tiny_solver::linear::SparseCholeskySolver::new().solve_jtj(&rhs, &self.information)?;
        let n = functions.len();
        let rows: Vec<Vec<usize>> = (0..n)
            .map(|a| (0..total).filter(|&r| rhs[(r, a)] != 0.0).collect())
            .collect();
        let cov = nalgebra::DMatrix::from_fn(n, n, |a, b| {
            rows[a]
                .iter()
                .map(|&r| rhs[(r, a)] * x[(r, b)])
                .sum::<f64>()
        });
        cov.iter().all(|v| v.is_finite()).then_some(cov)
    }
}

/// `k` columns of `n` random signs (a fixed seed: the same run gives the same estimate).
fn rademacher(n: usize, k: usize) -> faer::Mat<f64> {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    faer::Mat::from_fn(n, k, |_, _| {
        // splitmix64
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        if (z ^ (z >> 31)) & 1 == 0 {
            1.0
        } else {
            -1.0
        }
    })
}
