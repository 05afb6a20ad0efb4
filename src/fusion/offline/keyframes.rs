//! The offline graph's keyframes: the odometry thinned by travel and turn, plus one at every
//! fused sighting and at both ends of every visual turn within the odometry.

use crate::fusion::{FuseConfig, Observations, OnlineResult};
use crate::geometry::{pose_at, wrap_angle, Pose2};
use crate::visual::vo::VisualTurn;
use std::collections::{BTreeMap, HashMap};

/// One keyframe: the time, the odometry pose and the starting estimate.
pub(super) struct Keyframe {
    pub(super) t_s: f64,
    pub(super) odom: Pose2,
    pub(super) init: Pose2,
}

/// The keyframes and which keyframe each sighting and each visual turn's end falls on.
pub(super) struct Keyframes {
    pub(super) frames: Vec<Keyframe>,
    /// Keyframe of each fused sighting (by its index). Ordered: the tag factors go into the
    /// graph in the order of the sightings, so that the solution does not depend on a hash
    /// order (it did in its last digits).
    pub(super) of_sighting: BTreeMap<usize, usize>,
    /// Keyframe at each anchored time (its bits).
    pub(super) at_time: HashMap<u64, usize>,
}

/// The visual turns the graph uses: all within the odometry's span, when the settings use them.
pub(super) fn turns_used<'a>(obs: &Observations<'a>, config: &FuseConfig) -> Vec<&'a VisualTurn> {
    let (Some(first), Some(last)) = (obs.odometry.first(), obs.odometry.last()) else {
        return Vec::new();
    };
    obs.visual
        .iter()
        .filter(|v| config.visual_odometry && v.from_t_s >= first.t_s && v.to_t_s <= last.t_s)
        .collect()
}

/// Chooses the keyframes of a run with a first odometry pose `first`, each started at the
/// online estimate.
pub(super) fn choose(
    obs: &Observations<'_>,
    visual: &[&VisualTurn],
    online: &OnlineResult,
    config: &FuseConfig,
    first: Pose2,
) -> Keyframes {
    let odometry = obs.odometry;
    let mut anchors: Vec<(f64, Option<usize>)> = online
        .accepted
        .iter()
        .map(|&k| (obs.sightings[k].t_s, Some(k)))
        .chain(
            visual
                .iter()
                .flat_map(|v| [(v.from_t_s, None), (v.to_t_s, None)]),
        )
        .collect();
    anchors.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = Keyframes {
        frames: Vec::new(),
        of_sighting: BTreeMap::new(),
        at_time: HashMap::new(),
    };
    let keyframes = &mut out.frames;
    let mut anchors = anchors.into_iter().peekable();
    let mut last_kf = first;
    for (i, sample) in odometry.iter().enumerate() {
        while let Some(&(t, sighting)) = anchors.peek() {
            if t > sample.t_s && i + 1 < odometry.len() {
                break;
            }
            anchors.next();
            let odom = pose_at(odometry, t).unwrap_or(sample.pose);
            let same = keyframes.last().is_some_and(|kf| (kf.t_s - t).abs() < 1e-9);
            if !same {
                let init = match sighting {
                    Some(k) => online.pose_at_sighting[k],
                    None => pose_at(&online.trajectory, t).unwrap_or(odom),
                };
                keyframes.push(Keyframe { t_s: t, odom, init });
                last_kf = odom;
            }
            let kf = keyframes.len() - 1;
            out.at_time.insert(t.to_bits(), kf);
            if let Some(k) = sighting {
                out.of_sighting.insert(k, kf);
            }
        }
        let d = last_kf.between(&sample.pose);
        let is_end = i == 0 || i + 1 == odometry.len();
        if is_end
            || d.x.hypot(d.y) >= config.keyframe_spacing_m
            || wrap_angle(d.theta).abs() >= config.keyframe_turn_rad
        {
            if keyframes.last().is_some_and(|kf| kf.t_s >= sample.t_s) {
                continue;
            }
            keyframes.push(Keyframe {
                t_s: sample.t_s,
                odom: sample.pose,
                init: online.trajectory.get(i).map_or(sample.pose, |p| p.pose),
            });
            last_kf = sample.pose;
        }
    }
    out
}
