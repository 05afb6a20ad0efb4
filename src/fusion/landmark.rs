//! Landmarks: the surveyed tags, the Hough corner each is matched with, and the sightings that
//! disagree with them.

use crate::fusion::FuseConfig;
use crate::geometry::wrap_angle;
use crate::sonar::hough::Feature;
use crate::visual::sightings::TagSizes;
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

/// The sizes the survey used for its tags (`size_m`), per tag, with no default: the size check
/// of a later run's sightings when nothing else gives the printed sizes.
pub fn surveyed_tag_sizes(landmarks: &[Landmark]) -> TagSizes {
    TagSizes {
        default_m: None,
        by_tag: landmarks
            .iter()
            .filter(|l| l.size_m > 0.0)
            .map(|l| {
                let tag = TagId {
                    family: l.family,
                    id: l.id,
                };
                (tag, l.size_m)
            })
            .collect(),
    }
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
    /// How far the tag's face is turned up from the vertical, radians (the mean of the
    /// sightings; 0 in files older than it). With `yaw_rad` and `roll_rad`, the tag's full
    /// orientation: [`crate::world::Tag::rotation`].
    #[serde(default)]
    pub pitch_rad: f64,
    /// How far the tag is turned about its normal, radians (the mean of the sightings).
    #[serde(default)]
    pub roll_rad: f64,
    /// Covariance of the centre, m² (x, y from the filter; z from the spread of the sightings).
    pub covariance_m2: [[f64; 3]; 3],
    /// Sigmas of roll, pitch and yaw, radians (yaw from the filter; roll and pitch from the
    /// spread of the sightings; 0 in files older than it).
    #[serde(default)]
    pub orientation_sigma_rad: [f64; 3],
    /// Sightings fused.
    pub observations: usize,
    /// The Hough corner matched, if any.
    pub matched_corner: Option<CornerMatch>,
}

impl Landmark {
    /// `world_from_tag`'s rotation (see [`crate::world::Tag::rotation`]).
    pub fn rotation(&self) -> nalgebra::Rotation3<f64> {
        crate::world::tag_rotation(self.roll_rad, self.pitch_rad, self.yaw_rad)
    }

    /// The pose's 6x6 covariance over `(x, y, z, roll, pitch, yaw)`: the centre's, and the
    /// orientation's sigmas (taken as independent of the centre and of each other).
    pub fn pose_covariance(&self) -> [[f64; 6]; 6] {
        let mut c = [[0.0; 6]; 6];
        for (i, row) in self.covariance_m2.iter().enumerate() {
            c[i][..3].copy_from_slice(row);
        }
        for (k, sigma) in self.orientation_sigma_rad.iter().enumerate() {
            c[3 + k][3 + k] = sigma * sigma;
        }
        c
    }
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
    /// Sum of the weights of the sightings' orientations (`1 / yaw_sigma²`: a tag's pitch and
    /// roll come from the depths of its corners, as its yaw does).
    pub(crate) weight: f64,
    pub(crate) pitch_sum: f64,
    pub(crate) pitch_sq: f64,
    /// Weighted sums of the roll's cosine and sine (a circular mean: a tag may be turned by any
    /// angle).
    pub(crate) roll_cos: f64,
    pub(crate) roll_sin: f64,
    pub(crate) n: usize,
    pub(crate) corner: Option<CornerMatch>,
}

impl Extras {
    /// Adds a fused sighting.
    pub(crate) fn add(&mut self, s: &crate::visual::sightings::TagSighting) {
        let z = s.position_in_robot_m[2];
        self.z_sum += z;
        self.z_sq += z * z;
        self.size_sum += s.size_m;
        self.size_sq += s.size_m * s.size_m;
        let w = 1.0 / s.yaw_sigma_rad.max(1e-3).powi(2);
        self.weight += w;
        self.pitch_sum += w * s.pitch_rad;
        self.pitch_sq += w * s.pitch_rad * s.pitch_rad;
        self.roll_cos += w * s.roll_rad.cos();
        self.roll_sin += w * s.roll_rad.sin();
        self.n += 1;
    }
}

/// A landmark from the filter's estimate of it (position, yaw and their covariance) and the
/// running sums of its sightings.
pub(crate) fn landmark_from(
    key: &TagId,
    xy: Vector2<f64>,
    (yaw, var_yaw): (f64, f64),
    cov: &Matrix2<f64>,
    extra: &Extras,
) -> Landmark {
    let n = extra.n.max(1) as f64;
    let z = extra.z_sum / n;
    let var_z = (extra.z_sq / n - z * z).max(0.0) / n + 1e-6;
    let w = extra.weight.max(1e-12);
    let pitch = extra.pitch_sum / w;
    let var_pitch = (extra.pitch_sq / w - pitch * pitch).max(0.0) / n + 1e-6;
    // The circular spread of the rolls: -2 ln R, R the mean resultant length.
    let resultant = extra.roll_cos.hypot(extra.roll_sin) / w;
    let var_roll = (-2.0 * resultant.clamp(1e-12, 1.0).ln()).max(0.0) / n + 1e-6;
    Landmark {
        id: key.id,
        family: key.family,
        size_m: extra.size_sum / n,
        size_triangulated_m: extra.size_sum / n,
        size_spread: ((extra.size_sq / n - (extra.size_sum / n).powi(2)).max(0.0)).sqrt()
            / (extra.size_sum / n).max(1e-9),
        position_m: [xy.x, xy.y, z],
        yaw_rad: wrap_angle(yaw),
        pitch_rad: pitch,
        roll_rad: extra.roll_sin.atan2(extra.roll_cos),
        covariance_m2: [
            [cov[(0, 0)], cov[(0, 1)], 0.0],
            [cov[(1, 0)], cov[(1, 1)], 0.0],
            [0.0, 0.0, var_z],
        ],
        orientation_sigma_rad: [var_roll.sqrt(), var_pitch.sqrt(), var_yaw.max(0.0).sqrt()],
        observations: extra.n,
        matched_corner: extra.corner,
    }
}
