//! Landmarks: the surveyed tags, the Hough corner each is matched with, and the sightings that
//! disagree with them.

use crate::fusion::FuseConfig;
use crate::geometry::wrap_angle;
use crate::sonar::hough::Feature;
use crate::visual::tags::{TagFamily, TagId};
use nalgebra::{Matrix2, Vector2};
use serde::Serialize;

/// A Hough corner a landmark was matched with.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct CornerMatch {
    /// Corner position, metres.
    pub x_m: f64,
    /// Corner position, metres.
    pub y_m: f64,
    /// Votes of the Hough peak.
    pub votes: u32,
    /// Squared Mahalanobis distance of the match (0 when read from a file that lacks it).
    #[serde(default)]
    pub distance_chi2: f64,
}

/// A surveyed tag (as `landmarks.json` holds it, see `io::LandmarkRecord`).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct Landmark {
    /// Tag id.
    pub id: u32,
    /// Tag family.
    pub family: TagFamily,
    /// Edge length, metres: the printed size when known (a world file, `--tag-sizes`,
    /// `--tag-size-m`), else the mean triangulated one.
    pub size_m: f64,
    /// The mean triangulated edge length, metres (0 in files older than it).
    #[serde(default)]
    pub size_triangulated_m: f64,
    /// The sightings' triangulated sizes' standard deviation over their mean (0 in files older
    /// than it).
    #[serde(default)]
    pub size_spread: f64,
    /// Tag centre in the world, metres (z is the mean of the sightings).
    pub position_m: [f64; 3],
    /// Direction the tag faces, radians from the world x axis.
    pub yaw_rad: f64,
    /// Covariance of the centre, m² (x, y from the filter; z from the spread of the sightings).
    pub covariance_m2: [[f64; 3]; 3],
    /// Sightings fused.
    pub observations: usize,
    /// The Hough corner matched, if any.
    pub matched_corner: Option<CornerMatch>,
}

/// Sightings of one id that disagree with its landmark.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Conflict {
    /// Tag id.
    pub id: u32,
    /// Tag family.
    pub family: TagFamily,
    /// `"moved"` (never seen at the first place again) or `"duplicate id"` (seen at both).
    pub kind: String,
    /// Where the landmark is, metres.
    pub landmark_m: [f64; 2],
    /// Where the conflicting sightings put it, metres.
    pub seen_at_m: [f64; 2],
    /// Number of conflicting sightings.
    pub sightings: usize,
    /// Time of the first conflicting sighting, seconds.
    pub first_t_s: f64,
}

/// Matches a landmark at `xy` with covariance `cov` to the nearest Hough corner within the gate.
pub fn associate(
    xy: &Vector2<f64>,
    cov: &Matrix2<f64>,
    corners: &[Feature],
    config: &FuseConfig,
) -> Option<CornerMatch> {
    let s = cov + Matrix2::identity() * config.corner_sigma_m.powi(2);
    let s_inv = s.try_inverse()?;
    corners
        .iter()
        .map(|f| {
            let d = Vector2::new(f.x_m - xy.x, f.y_m - xy.y);
            (f, (d.transpose() * s_inv * d)[0])
        })
        .filter(|(_, d2)| *d2 <= config.association_chi2)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(f, d2)| CornerMatch {
            x_m: f.x_m,
            y_m: f.y_m,
            votes: f.votes,
            distance_chi2: d2,
        })
}

/// Per-landmark running sums of what the planar state does not hold.
#[derive(Default, Clone)]
pub(crate) struct Extras {
    pub(crate) z_sum: f64,
    pub(crate) z_sq: f64,
    pub(crate) size_sum: f64,
    pub(crate) size_sq: f64,
    pub(crate) n: usize,
    pub(crate) corner: Option<CornerMatch>,
}

/// A landmark from the filter's estimate of it and the running sums of its sightings.
pub(crate) fn landmark_from(
    key: &TagId,
    xy: Vector2<f64>,
    yaw: f64,
    cov: &Matrix2<f64>,
    extra: &Extras,
) -> Landmark {
    let n = extra.n.max(1) as f64;
    let z = extra.z_sum / n;
    let var_z = (extra.z_sq / n - z * z).max(0.0) / n + 1e-6;
    Landmark {
        id: key.id,
        family: key.family,
        size_m: extra.size_sum / n,
        size_triangulated_m: extra.size_sum / n,
        size_spread: ((extra.size_sq / n - (extra.size_sum / n).powi(2)).max(0.0)).sqrt()
            / (extra.size_sum / n).max(1e-9),
        position_m: [xy.x, xy.y, z],
        yaw_rad: wrap_angle(yaw),
        covariance_m2: [
            [cov[(0, 0)], cov[(0, 1)], 0.0],
            [cov[(1, 0)], cov[(1, 1)], 0.0],
            [0.0, 0.0, var_z],
        ],
        observations: extra.n,
        matched_corner: extra.corner,
    }
}
