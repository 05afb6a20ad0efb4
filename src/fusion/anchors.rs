//! Anchors: tags whose poses are known beforehand (a floor plan, a WPILib field layout), given to
//! a survey so that it is solved in their frame rather than the robot's start: a first rigid fit
//! of the online landmarks to them places the run, and each is a prior on its landmark in the
//! offline graph with its stated sigmas.

use crate::fusion::Landmark;
use crate::geometry::{wrap_angle, Pose2};
use crate::visual::tags::TagId;

/// A tag whose pose is known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anchor {
    /// The tag.
    pub tag: TagId,
    /// Its centre, metres (z is kept for the record: the survey is planar).
    pub position_m: [f64; 3],
    /// The direction it faces (out of its face, counter-clockwise from x), radians, when known.
    pub yaw_rad: Option<f64>,
    /// Sigma of its position, metres.
    pub sigma_m: f64,
    /// Sigma of its facing, radians.
    pub sigma_rad: f64,
}

/// Why the anchors cannot place a survey.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnchorError {
    /// None of the anchored tags was surveyed.
    #[error("none of the {listed} anchored tags was seen in the run (surveyed: {surveyed})")]
    NoneSeen {
        /// How many anchors were given.
        listed: usize,
        /// The tags surveyed.
        surveyed: String,
    },
    /// One anchored tag seen, with no facing given: the frame's rotation is not determined.
    #[error(
        "only {} {} of the anchors was seen and it gives no facing (yaw): the frame's rotation \
         is not determined; give its yaw or anchor a second tag", .0.family, .0.id
    )]
    Underdetermined(TagId),
}

/// The rigid motion `anchors_from_survey` that best puts the surveyed landmarks on their anchors:
/// with two anchored landmarks or more, their positions fitted by least squares weighted by the
/// anchors' sigmas (2D Kabsch); with one, its position and facing.
pub fn anchor_frame(landmarks: &[Landmark], anchors: &[Anchor]) -> Result<Pose2, AnchorError> {
    let pairs: Vec<(&Landmark, &Anchor)> = anchors
        .iter()
        .filter_map(|a| {
            landmarks
                .iter()
                .find(|l| l.family == a.tag.family && l.id == a.tag.id)
                .map(|l| (l, a))
        })
        .collect();
    match pairs.as_slice() {
        [] => Err(AnchorError::NoneSeen {
            listed: anchors.len(),
            surveyed: landmarks
                .iter()
                .map(|l| format!("{} {}", l.family, l.id))
                .collect::<Vec<_>>()
                .join(", "),
        }),
        [(l, a)] => {
            let yaw = a.yaw_rad.ok_or(AnchorError::Underdetermined(a.tag))?;
            let theta = wrap_angle(yaw - l.yaw_rad);
            let (s, c) = theta.sin_cos();
            let [x, y, _] = l.position_m;
            Ok(Pose2::new(
                a.position_m[0] - (c * x - s * y),
                a.position_m[1] - (s * x + c * y),
                theta,
            ))
        }
        _ => Ok(fit_positions(&pairs)),
    }
}

/// Weighted 2D Kabsch over the landmark-anchor pairs.
fn fit_positions(pairs: &[(&Landmark, &Anchor)]) -> Pose2 {
    let weight = |a: &Anchor| 1.0 / a.sigma_m.max(1e-6).powi(2);
    let total: f64 = pairs.iter().map(|(_, a)| weight(a)).sum();
    let centroid = |f: &dyn Fn(&Landmark, &Anchor) -> [f64; 2]| {
        pairs.iter().fold([0.0; 2], |acc, (l, a)| {
            let p = f(l, a);
            let w = weight(a) / total;
            [acc[0] + w * p[0], acc[1] + w * p[1]]
        })
    };
    let cl = centroid(&|l, _| [l.position_m[0], l.position_m[1]]);
    let ca = centroid(&|_, a| [a.position_m[0], a.position_m[1]]);
    let (mut sin, mut cos) = (0.0, 0.0);
    for (l, a) in pairs {
        let w = weight(a);
        let (lx, ly) = (l.position_m[0] - cl[0], l.position_m[1] - cl[1]);
        let (ax, ay) = (a.position_m[0] - ca[0], a.position_m[1] - ca[1]);
        cos += w * (lx * ax + ly * ay);
        sin += w * (lx * ay - ly * ax);
    }
    let theta = sin.atan2(cos);
    let (s, c) = theta.sin_cos();
    Pose2::new(
        ca[0] - (c * cl[0] - s * cl[1]),
        ca[1] - (s * cl[0] + c * cl[1]),
        theta,
    )
}

/// How far a surveyed landmark ended from its anchor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnchorResidual {
    /// The tag.
    pub tag: TagId,
    /// Distance from the anchor, metres.
    pub distance_m: f64,
    /// Facing difference (surveyed minus anchored), radians, when the anchor gives one.
    pub yaw_rad: Option<f64>,
    /// The distance over the anchor's sigma.
    pub sigmas: f64,
}

/// Each anchor's residual in the solved survey; anchors whose tag was not surveyed are left out.
pub fn anchor_residuals(landmarks: &[Landmark], anchors: &[Anchor]) -> Vec<AnchorResidual> {
    anchors
        .iter()
        .filter_map(|a| {
            let l = landmarks
                .iter()
                .find(|l| l.family == a.tag.family && l.id == a.tag.id)?;
            let distance_m =
                (l.position_m[0] - a.position_m[0]).hypot(l.position_m[1] - a.position_m[1]);
            Some(AnchorResidual {
                tag: a.tag,
                distance_m,
                yaw_rad: a.yaw_rad.map(|y| wrap_angle(l.yaw_rad - y)),
                sigmas: distance_m / a.sigma_m.max(1e-9),
            })
        })
        .collect()
}

/// The anchor that puts tag `tag` at the origin, facing along x: `--origin-tag` (1 mm, 0.001 rad:
/// it defines the frame).
pub fn origin_anchor(tag: TagId) -> Anchor {
    Anchor {
        tag,
        position_m: [0.0; 3],
        yaw_rad: Some(0.0),
        sigma_m: 1e-3,
        sigma_rad: 1e-3,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visual::tags::TagFamily;

    fn landmark(id: u32, x: f64, y: f64, yaw: f64) -> Landmark {
        Landmark {
            id,
            family: TagFamily::Tag36h11,
            size_m: 0.16,
            size_triangulated_m: 0.16,
            size_spread: 0.0,
            position_m: [x, y, 0.3],
            yaw_rad: yaw,
            pitch_rad: 0.0,
            roll_rad: 0.0,
            covariance_m2: [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-4]],
            orientation_sigma_rad: [0.01; 3],
            observations: 3,
            matched_corner: None,
        }
    }

    fn anchor(id: u32, p: Pose2, yaw: Option<f64>) -> Anchor {
        Anchor {
            tag: TagId {
                family: TagFamily::Tag36h11,
                id,
            },
            position_m: [p.x, p.y, 0.3],
            yaw_rad: yaw,
            sigma_m: 0.01,
            sigma_rad: 0.01,
        }
    }

    /// Landmarks surveyed in the start's frame are put on their anchors by the frame found, from
    /// two positions or from one position and its facing; one without a facing is refused.
    #[test]
    fn the_anchor_frame_puts_the_landmarks_on_their_anchors() {
        let truth = Pose2::new(3.0, -1.5, 2.2);
        let surveyed = [
            landmark(1, 1.0, 2.0, 0.3),
            landmark(2, 4.0, -1.0, -1.2),
            landmark(3, -2.0, 0.5, 3.0),
        ];
        let placed =
            |l: &Landmark| truth.compose(&Pose2::new(l.position_m[0], l.position_m[1], l.yaw_rad));
        let two = [
            anchor(1, placed(&surveyed[0]), None),
            anchor(2, placed(&surveyed[1]), None),
        ];
        let one = [anchor(
            3,
            placed(&surveyed[2]),
            Some(placed(&surveyed[2]).theta),
        )];
        for anchors in [&two[..], &one[..]] {
            let found = anchor_frame(&surveyed, anchors).unwrap();
            assert!(
                (found.x - truth.x).abs() < 1e-9
                    && (found.y - truth.y).abs() < 1e-9
                    && wrap_angle(found.theta - truth.theta).abs() < 1e-9,
                "{found:?}"
            );
        }
        let no_yaw = [anchor(3, placed(&surveyed[2]), None)];
        assert!(matches!(
            anchor_frame(&surveyed, &no_yaw),
            Err(AnchorError::Underdetermined(_))
        ));
        let unseen = [anchor(9, truth, None)];
        let err = anchor_frame(&surveyed, &unseen).unwrap_err().to_string();
        assert!(
            err.contains("none of the 1 anchored tags") && err.contains("tag36h11 2"),
            "{err}"
        );
    }
}
