//! How a localised run's error grows with the distance travelled since the last sighting.

use crate::fusion::LocalizeResult;
use crate::geometry::StampedPose;
use crate::metrics::{at_truth, ate_m};
use serde::Serialize;

/// Error statistics of a localised run over one band of distance since the last sighting.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GrowthBin {
    /// Band start, metres travelled since the last fused sighting.
    pub from_m: f64,
    /// Band end, metres.
    pub to_m: f64,
    /// Odometry samples in the band.
    pub samples: usize,
    /// Mean filter sigma, metres.
    pub mean_sigma_m: f64,
    /// RMS position error against ground truth at its stamps whose nearest pose lies in the
    /// band, metres (`None` without ground truth, or with none of its stamps in the band).
    pub rms_error_m: Option<f64>,
}

/// Bands of distance since the last sighting used by [`error_growth`], metres.
pub const GROWTH_BANDS_M: [f64; 7] = [0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0];

/// How the error grows with the distance travelled since the last sighting.
pub fn error_growth(result: &LocalizeResult, truth: Option<&[StampedPose]>) -> Vec<GrowthBin> {
    let mut bins: Vec<GrowthBin> = GROWTH_BANDS_M
        .iter()
        .enumerate()
        .map(|(i, &from_m)| GrowthBin {
            from_m,
            to_m: GROWTH_BANDS_M.get(i + 1).copied().unwrap_or(f64::INFINITY),
            samples: 0,
            mean_sigma_m: 0.0,
            rms_error_m: truth.map(|_| 0.0),
        })
        .collect();
    let band = |i: usize| {
        let d = result.since_sighting_m.get(i).copied().unwrap_or(0.0);
        GROWTH_BANDS_M.iter().rposition(|&from| d >= from)
    };
    for i in 0..result.trajectory.len() {
        let Some(bin) = band(i).map(|b| &mut bins[b]) else {
            continue;
        };
        bin.samples += 1;
        bin.mean_sigma_m += result.sigma_m.get(i).copied().unwrap_or(0.0);
    }
    // The error where the truth was measured, in the band of the estimate's pose nearest then.
    let mut scored = vec![0usize; bins.len()];
    for s in truth
        .into_iter()
        .flat_map(|t| at_truth(&result.trajectory, t))
    {
        if let Some(b) = band(s.index) {
            let e = &mut bins[b].rms_error_m;
            *e = e.map(|sum| {
                sum + (s.estimate.x - s.truth.x).powi(2) + (s.estimate.y - s.truth.y).powi(2)
            });
            scored[b] += 1;
        }
    }
    for (b, n) in bins.iter_mut().zip(scored) {
        b.mean_sigma_m /= b.samples.max(1) as f64;
        b.rms_error_m = b
            .rms_error_m
            .filter(|_| n > 0)
            .map(|s| (s / n as f64).sqrt());
    }
    bins.retain(|b| b.samples > 0);
    bins
}

/// A localisation against the run's ground truth ([`score_localization`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalizationScores {
    /// ATE of the run's odometry as logged, metres (`None`: no overlap with the truth).
    pub ate_odometry_m: Option<f64>,
    /// ATE of the odometry the filter ran on, when a survey's calibration corrected it
    /// (`Some(None)`: corrected, but no overlap).
    pub ate_odometry_calibrated_m: Option<Option<f64>>,
    /// ATE of the localised trajectory, metres.
    pub ate_localized_m: Option<f64>,
    /// Mean position NEES per degree of freedom where the pose is known (about 1 when the
    /// reported sigma is honest, below when cautious).
    pub nees_located: f64,
    /// The same from the first instant (an unknown start's guess counts near 0).
    pub nees_from_start: f64,
    /// The largest error over the worst-direction sigma, from the first instant.
    pub worst_error_over_sigma: f64,
    /// When the filter first knew where it was, and its ATE from then on (`None`: never).
    pub located: Option<Located>,
}

/// A localisation from the time its filter first knew where the robot was
/// ([`LocalizationScores::located`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// That time, seconds.
    pub from_t_s: f64,
    /// The ATE from then on, metres (`None`: no overlap with the truth).
    pub ate_m: Option<f64>,
}

/// Scores a localisation against the truth. `odometry` is the odometry the filter ran on
/// (`run_odometry` corrected with a survey's calibration when `calibrated`).
pub fn score_localization(
    result: &LocalizeResult,
    run_odometry: &[StampedPose],
    odometry: &[StampedPose],
    calibrated: bool,
    truth: &[StampedPose],
) -> LocalizationScores {
    let c = sigma_consistency(result, truth);
    let located = result.located.iter().position(|&l| l).map(|first| Located {
        from_t_s: result.trajectory[first].t_s,
        ate_m: ate_m(&result.trajectory[first..], truth),
    });
    LocalizationScores {
        ate_odometry_m: ate_m(run_odometry, truth),
        ate_odometry_calibrated_m: calibrated.then(|| ate_m(odometry, truth)),
        ate_localized_m: ate_m(&result.trajectory, truth),
        nees_located: c.nees_located,
        nees_from_start: c.nees_all,
        worst_error_over_sigma: c.worst,
        located,
    }
}

impl LocalizationScores {
    /// Adds the scores to `report.json`'s metrics (`ate_m.*`, `nees.*`, `located.from_t_s`).
    pub fn add_to(&self, metrics: &mut serde_json::Map<String, serde_json::Value>) {
        metrics.insert("ate_m.odometry".into(), self.ate_odometry_m.into());
        if let Some(ate) = self.ate_odometry_calibrated_m {
            metrics.insert("ate_m.odometry_calibrated".into(), ate.into());
        }
        metrics.insert("ate_m.localized".into(), self.ate_localized_m.into());
        metrics.insert("nees.position_mean".into(), self.nees_located.into());
        metrics.insert(
            "nees.position_mean_from_start".into(),
            self.nees_from_start.into(),
        );
        metrics.insert(
            "error_over_sigma.max".into(),
            self.worst_error_over_sigma.into(),
        );
        if let Some(Located { from_t_s, ate_m }) = self.located {
            metrics.insert("located.from_t_s".into(), from_t_s.into());
            metrics.insert("ate_m.located".into(), ate_m.into());
        }
    }
}

/// What a localisation fused and, with its [`LocalizationScores`], the figures of `localize`'s
/// `report.json`.
pub fn localization_metrics(
    result: &LocalizeResult,
    calibrated: bool,
    scores: Option<&LocalizationScores>,
    counts: LocalizationCounts,
) -> serde_json::Map<String, serde_json::Value> {
    let mut metrics = serde_json::Map::new();
    metrics.insert("sightings.fused".into(), result.accepted.len().into());
    metrics.insert("sightings.gated_out".into(), result.rejected.len().into());
    metrics.insert("sightings.unknown_tag".into(), result.unknown.len().into());
    metrics.insert("walls.surveyed".into(), counts.walls.into());
    metrics.insert("ranges.fused".into(), result.ranges_fused().into());
    metrics.insert("ranges.gated_out".into(), result.ranges_gated_out().into());
    metrics.insert(
        "ranges.at_shortest_range".into(),
        counts.ranges_at_shortest.into(),
    );
    if !result.scan_outcomes.is_empty() || result.scans_unmatched > 0 {
        let fused = result.scan_outcomes.iter().filter(|o| o.1).count();
        metrics.insert("scans.fused".into(), fused.into());
        let gated_out = result.scan_outcomes.len() - fused;
        metrics.insert("scans.gated_out".into(), gated_out.into());
        metrics.insert("scans.unmatched".into(), result.scans_unmatched.into());
        let relocalised = result.relocalised_by_scans_t_s.len();
        metrics.insert("scans.relocalised".into(), relocalised.into());
    }
    let relocalised = result.relocalised_t_s.len() + result.relocalised_by_scans_t_s.len();
    metrics.insert("relocalised".into(), relocalised.into());
    metrics.insert("wall_fixes".into(), result.wall_fixed_t_s.len().into());
    metrics.insert("visual.turns".into(), counts.visual_turns.into());
    metrics.insert("visual.fused".into(), result.visual_fused.into());
    metrics.insert("visual.gated_out".into(), result.visual_rejected.into());
    metrics.insert(
        "odometry.calibrated".into(),
        f64::from(u8::from(calibrated)).into(),
    );
    if let Some(scores) = scores {
        scores.add_to(&mut metrics);
    }
    metrics
}

/// The position NEES per degree of freedom of an `error` (x, y, metres) under a position
/// covariance `[xx, xy, yy]`: `eᵀ P⁻¹ e / 2`, about 1 on average when the covariance is honest.
pub fn position_nees(error: [f64; 2], covariance: [f64; 3]) -> f64 {
    let ([ex, ey], [xx, xy, yy]) = (error, covariance);
    let det = (xx * yy - xy * xy).max(1e-18);
    (yy * ex * ex - 2.0 * xy * ex * ey + xx * ey * ey) / det / 2.0
}

/// How well the reported position covariance covers the error (no alignment: the survey's frame
/// is the truth's).
struct Consistency {
    /// Mean position NEES per degree of freedom (`eᵀ P⁻¹ e / 2`: about 1 when honest, below when
    /// cautious) over the samples where the pose is known.
    nees_located: f64,
    /// The same from the first instant (an unknown start's guess, with its huge covariance,
    /// counts near 0).
    nees_all: f64,
    /// The largest `e / σ` from the first instant, with the worst-direction sigma.
    worst: f64,
}

fn sigma_consistency(result: &LocalizeResult, truth: &[StampedPose]) -> Consistency {
    let (mut all, mut n_all, mut located, mut n_located, mut worst) =
        (0.0, 0usize, 0.0, 0usize, 0.0f64);
    for s in at_truth(&result.trajectory, truth) {
        let i = s.index;
        let (ex, ey) = (s.estimate.x - s.truth.x, s.estimate.y - s.truth.y);
        let nees = position_nees([ex, ey], result.position_covariance[i]);
        all += nees;
        n_all += 1;
        if result.located[i] {
            located += nees;
            n_located += 1;
        }
        worst = worst.max(ex.hypot(ey) / result.sigma_m[i].max(1e-9));
    }
    Consistency {
        nees_located: located / n_located.max(1) as f64,
        nees_all: all / n_all.max(1) as f64,
        worst,
    }
}

/// What the localisation had to work with, for its report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LocalizationCounts {
    /// Surveyed walls the sonar was matched against.
    pub walls: usize,
    /// Visual turns measured.
    pub visual_turns: usize,
    /// Echoes at the sonar's shortest range, not taken as distances
    /// ([`crate::sonar::SonarLayout::at_shortest_range`]).
    pub ranges_at_shortest: usize,
}
