//! The walls' directions hold the heading where the sonar hears nothing to match: indoors, the
//! walls mostly run along two directions at right angles. Near a keyframe, a sonar that slides
//! along a straight wall gives ranges that lie on one line (each echo comes back along the wall's
//! normal, from the foot of the perpendicular, when that lies in the cone); the line's normal, in
//! the keyframe's frame, is a measurement of the keyframe's heading modulo a quarter turn once
//! the building's wall direction is known. A laser sees such walls whole: a straight piece of
//! one scan gives its normal directly ([`scan_directions`]), and holds the heading of a run whose
//! scans match their older returns only now and then (aces, a scan every 3 s: drifted six ways,
//! 0.5-0.9 m offline where the matches alone left 1.8-3.8 m). The graph estimates that direction
//! with the poses ([`super::graph::add_wall_directions`]); a run whose walls do not mostly run
//! along two directions at right angles gets none of these factors.

use super::keyframes::Keyframe;
use crate::fusion::FuseConfig;
use crate::geometry::{pose_at, wrap_angle, Pose2, StampedPose};
use crate::sonar::{BeamModel, SonarLayout, SonarReading};

/// A wall one sonar slid along near a keyframe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct WallDirection {
    /// The keyframe.
    pub(super) keyframe: usize,
    /// The direction of the wall's normal, from the sensor towards the wall, in the keyframe's
    /// frame, radians.
    pub(super) normal_rad: f64,
    /// Its sigma, radians.
    pub(super) sigma_rad: f64,
}

/// The readings fitted at a keyframe are those taken within this travel of it, metres, either
/// way ...
const REACH_M: f64 = 1.0;
/// ... and while the odometry's heading is within this of the keyframe's (a turn's scale error
/// would bend the line): 10 degrees.
const MAX_TURN_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// A line needs this many echoes of one sensor ...
const MIN_ECHOES: usize = 8;
/// ... whose feet on the wall spread this far along it, metres (the direction's sigma is the
/// ranges' over the spread) ...
const MIN_SPAN_M: f64 = 0.8;
/// ... of which this share lies within three sigmas of the line (a person or a chair in front of
/// the wall gives shorter ranges) ...
const MIN_INLIER_SHARE: f64 = 0.8;
/// ... and whose whitened residuals' RMS is at most this.
const MAX_WHITENED_RMS: f64 = 2.0;
/// Directions tried across the cones' common part: 0.1 degree apart, then refined.
const SCAN_STEP_RAD: f64 = 0.1 * std::f64::consts::PI / 180.0;
/// A line whose best direction lies this near an end of the cones' common part is left out: the
/// wall may lie outside a cone, whose echo then does not come back along the normal.
const EDGE_MARGIN_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// The direction's sigma is at least this: a quarter of a degree (the odometry over the window).
const SIGMA_FLOOR_RAD: f64 = 0.25 * std::f64::consts::PI / 180.0;

/// A wall direction is taken as along the building's axes when, against the nearest of them, it
/// lies within this of the median of its neighbours' ([`AXES_NEIGHBOURS`]; the directions are
/// placed by the odometry, whose heading drifts slowly): 4 degrees; others (a slanted wall, a
/// false line) are left out.
const AXES_GATE_RAD: f64 = 4.0 * std::f64::consts::PI / 180.0;
/// The neighbours a direction is judged against: this many either side, in time.
const AXES_NEIGHBOURS: usize = 4;
/// The walls run along two directions at right angles when this share of the directions found
/// passes [`AXES_GATE_RAD`]; otherwise no direction is used.
const MIN_AXES_SHARE: f64 = 0.6;
/// A normal spread's sigma over its median absolute deviation.
const MAD_TO_SIGMA: f64 = 1.4826;

/// Where a run's walls run ([`along_axes`]).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Axes {
    /// One of the four directions the walls' normals lie along, radians (the others a quarter
    /// turn apart), by the first few walls.
    pub(super) axes_rad: f64,
    /// Which of the directions lie along them.
    pub(super) along: Vec<bool>,
    /// What their sigmas are to be scaled by, at least 1: the spread of their offsets against
    /// their neighbours' over the sigmas the fits gave (a real building's walls are not all at
    /// right angles to a tenth of a degree: freiburg-079 as sonar, a median 2 degrees off its
    /// axes, where the simulated museum's are 0.4).
    pub(super) sigma_scale: f64,
}

/// Whether walls seen in directions `seen` (each the normal's direction in the world by a
/// drifting heading, in time order, and its sigma) run along two directions at right angles:
/// [`MIN_AXES_SHARE`] of them within [`AXES_GATE_RAD`] of their neighbours' offset from the
/// axes. `None` when they do not.
pub(super) fn along_axes(seen: &[(f64, f64)]) -> Option<Axes> {
    let quarter = |a: f64| wrap_angle(4.0 * a) / 4.0;
    // The axes by the first few (the heading has drifted least), and each direction's offset
    // from them: the heading's drift so far, and the direction's own error.
    let (s, c) = seen
        .iter()
        .take(2 * AXES_NEIGHBOURS + 1)
        .fold((0.0, 0.0), |(s, c), (a, _)| {
            (s + (4.0 * a).sin(), c + (4.0 * a).cos())
        });
    let axes_rad = f64::atan2(s, c) / 4.0;
    let offsets: Vec<f64> = seen.iter().map(|(a, _)| quarter(a - axes_rad)).collect();
    // Each offset against its neighbours' median.
    let off_neighbours: Vec<f64> = (0..offsets.len())
        .map(|i| {
            let from = i.saturating_sub(AXES_NEIGHBOURS);
            let to = (i + AXES_NEIGHBOURS + 1).min(offsets.len());
            let mut near: Vec<f64> = offsets[from..to].to_vec();
            near.sort_by(f64::total_cmp);
            offsets[i] - near[near.len() / 2]
        })
        .collect();
    let along: Vec<bool> = off_neighbours
        .iter()
        .map(|d| d.abs() <= AXES_GATE_RAD)
        .collect();
    let taken = along.iter().filter(|&&a| a).count();
    let mut whitened: Vec<f64> = seen
        .iter()
        .zip(&off_neighbours)
        .zip(&along)
        .filter(|(_, &a)| a)
        .map(|(((_, sigma), off), _)| (off / sigma).abs())
        .collect();
    whitened.sort_by(f64::total_cmp);
    let sigma_scale = whitened
        .get(whitened.len() / 2)
        .map_or(1.0, |m| (MAD_TO_SIGMA * m).max(1.0));
    tracing::debug!(
        "{taken} of {} wall directions lie along two directions at right angles, their sigmas scaled by {sigma_scale:.2}",
        seen.len()
    );
    (taken > 0 && taken as f64 >= MIN_AXES_SHARE * seen.len() as f64).then_some(Axes {
        axes_rad,
        along,
        sigma_scale,
    })
}

/// Each of `found` (on `frames`) in the world by the odometry, whose heading drifts smoothly (the
/// same in every try of the sonar's correction, whatever its starting values), and its sigma:
/// what [`along_axes`] judges.
pub(super) fn by_odometry(found: &[WallDirection], frames: &[Keyframe]) -> Vec<(f64, f64)> {
    found
        .iter()
        .map(|d| (frames[d.keyframe].odom.theta + d.normal_rad, d.sigma_rad))
        .collect()
}

/// The heading correction the walls' directions give each keyframe's odometry heading, and its
/// sigma, the building's axes at `axes_rad` (as a correction by the directions found them):
/// `None` where no wall was slid along or its direction is not along the axes.
pub(super) fn heading_corrections(
    frames: &[Keyframe],
    odometry: &[StampedPose],
    readings: &[SonarReading],
    layout: &SonarLayout,
    config: &FuseConfig,
    axes_rad: f64,
) -> Vec<Option<(f64, f64)>> {
    let mut out = vec![None; frames.len()];
    let found = wall_directions(frames, odometry, readings, layout, config);
    let seen = by_odometry(&found, frames);
    let Some(axes) = along_axes(&seen) else {
        return out;
    };
    for ((d, (world, _)), along) in found.iter().zip(&seen).zip(&axes.along) {
        if *along {
            let off = wrap_angle(4.0 * (world - axes_rad)) / 4.0;
            out[d.keyframe] = Some((-off, axes.sigma_scale * d.sigma_rad));
        }
    }
    out
}

/// The walls sonars slid along near the keyframes, one a keyframe at most (the surest), each
/// stretch of readings used once; for a laser, the straight pieces of its scans
/// ([`scan_directions`]).
pub(super) fn wall_directions(
    frames: &[Keyframe],
    odometry: &[StampedPose],
    readings: &[SonarReading],
    layout: &SonarLayout,
    config: &FuseConfig,
) -> Vec<WallDirection> {
    if odometry.len() < 2 {
        return Vec::new();
    }
    if layout.beam == BeamModel::Ray {
        return scan_directions(frames, odometry, readings, layout);
    }
    let path = crate::geometry::distance_travelled(odometry);
    let mut found = Vec::new();
    let mut used_until = f64::NEG_INFINITY;
    for (k, frame) in frames.iter().enumerate() {
        let Some((from, to)) = window(odometry, &path, frame) else {
            continue;
        };
        if from <= used_until {
            continue;
        }
        let first = readings.partition_point(|r| r.t_s < from);
        let last = readings.partition_point(|r| r.t_s <= to);
        let best = (0..layout.sensors.len())
            .filter_map(|sensor| {
                let echoes: Vec<Echo> = readings[first..last]
                    .iter()
                    .filter(|r| r.sensor == sensor)
                    .filter_map(|r| {
                        let range = r.range_m.filter(|&m| layout.measures(m))?;
                        let robot = pose_at(odometry, r.t_s)?;
                        let at = frame
                            .odom
                            .between(&robot)
                            .compose(&layout.sensors[sensor].robot_from_sensor());
                        Some(Echo {
                            sensor: at,
                            range_m: range,
                            weight: (config.sonar_sigma_m + config.sonar_sigma_frac * range)
                                .powi(-2),
                        })
                    })
                    .collect();
                fit_line(&echoes, layout.cone_rad / 2.0)
            })
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((normal_rad, sigma_rad)) = best {
            tracing::trace!(
                "wall direction at keyframe {k} (t {:.1} s): normal {:.2} deg, sigma {:.2} deg",
                frame.t_s,
                normal_rad.to_degrees(),
                sigma_rad.to_degrees()
            );
            found.push(WallDirection {
                keyframe: k,
                normal_rad,
                sigma_rad,
            });
            used_until = to;
        }
    }
    found
}

/// A laser's straight pieces: returns of one scan, neighbours by beam, each within this of the
/// line through its piece (aces' ranges come in 5 cm steps) ...
const SCAN_SPLIT_M: f64 = 0.08;
/// ... a piece ends where the next return is further than this from the last, over the beams'
/// spacing at its range (a door, a gap, another wall behind) ...
const SCAN_GAP_BEAMS: f64 = 3.0;
/// ... and makes a wall with this many returns ...
const SCAN_MIN_RETURNS: usize = 8;
/// ... over this length, metres ...
const SCAN_MIN_SPAN_M: f64 = 1.0;
/// ... whose spread about its line is at most this, metres.
const SCAN_MAX_RMS_M: f64 = 0.04;
/// The returns' own noise about a wall, metres, at least: aces' 5 cm steps give 1.4 cm.
const SCAN_NOISE_FLOOR_M: f64 = 0.015;

/// The walls a laser's scans see: at each keyframe, of its latest scan (each scan once), the
/// straight piece that fixes its direction best. The scan's returns are split at gaps and where
/// they leave the chord between a piece's ends ([`SCAN_SPLIT_M`]); a piece long and straight
/// enough is a wall, whose normal's direction (sensor to wall, in the keyframe's frame) has the
/// sigma of a line fitted to its returns.
fn scan_directions(
    frames: &[Keyframe],
    odometry: &[StampedPose],
    readings: &[SonarReading],
    layout: &SonarLayout,
) -> Vec<WallDirection> {
    let spacing = layout
        .sensors
        .windows(2)
        .map(|w| wrap_angle(w[1].bearing_rad - w[0].bearing_rad).abs())
        .fold(f64::INFINITY, f64::min);
    let spacing = if spacing.is_finite() { spacing } else { 0.0 };
    let mut found = Vec::new();
    let mut used = f64::NEG_INFINITY;
    for (k, frame) in frames.iter().enumerate() {
        let last = readings.partition_point(|r| r.t_s <= frame.t_s);
        let Some(t) = last.checked_sub(1).map(|i| readings[i].t_s) else {
            continue;
        };
        if t <= used {
            continue;
        }
        used = t;
        let Some(robot) = pose_at(odometry, t) else {
            continue;
        };
        let at = frame.odom.between(&robot);
        let first = readings[..last].partition_point(|r| r.t_s < t);
        let mut scan: Vec<(usize, f64, (f64, f64))> = readings[first..last]
            .iter()
            .filter_map(|r| {
                let range = r.range_m.filter(|&m| layout.measures(m))?;
                let beam = at.compose(&layout.sensors.get(r.sensor)?.robot_from_sensor());
                let (s, c) = beam.theta.sin_cos();
                Some((r.sensor, range, (beam.x + range * c, beam.y + range * s)))
            })
            .collect();
        scan.sort_by_key(|p| p.0);
        let mut pieces = Vec::new();
        let mut start = 0;
        for i in 1..=scan.len() {
            let gap = i == scan.len() || {
                let (a, b) = (scan[i - 1], scan[i]);
                let reach = SCAN_GAP_BEAMS * spacing * a.1.max(b.1) * (b.0 - a.0) as f64;
                (b.2 .0 - a.2 .0).hypot(b.2 .1 - a.2 .1) > reach.max(0.05)
            };
            if gap {
                split(&scan[start..i], &mut pieces);
                start = i;
            }
        }
        // Where the laser was (every beam leaves from its mounting).
        let laser = layout
            .sensors
            .first()
            .map_or(at, |s| at.compose(&s.robot_from_sensor()));
        let best = pieces
            .iter()
            .filter_map(|piece| wall_of(piece, (laser.x, laser.y)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((normal_rad, sigma_rad)) = best {
            found.push(WallDirection {
                keyframe: k,
                normal_rad,
                sigma_rad,
            });
        }
    }
    found
}

/// Splits a run of neighbouring returns where they leave the chord between its ends by more than
/// [`SCAN_SPLIT_M`], into `pieces` of [`SCAN_MIN_RETURNS`] or more.
fn split(run: &[(usize, f64, (f64, f64))], pieces: &mut Vec<Vec<(f64, f64)>>) {
    if run.len() < SCAN_MIN_RETURNS {
        return;
    }
    let (a, b) = (run[0].2, run[run.len() - 1].2);
    let length = (b.0 - a.0).hypot(b.1 - a.1).max(1e-9);
    let off =
        |p: (f64, f64)| ((b.0 - a.0) * (a.1 - p.1) - (a.0 - p.0) * (b.1 - a.1)).abs() / length;
    let (i, worst) = run
        .iter()
        .enumerate()
        .map(|(i, p)| (i, off(p.2)))
        .fold((0, 0.0), |m, x| if x.1 > m.1 { x } else { m });
    if worst > SCAN_SPLIT_M && i > 0 && i + 1 < run.len() {
        split(&run[..=i], pieces);
        split(&run[i..], pieces);
    } else {
        pieces.push(run.iter().map(|p| p.2).collect());
    }
}

/// A straight piece as a wall seen from `sensor`: its normal's direction (sensor to wall) and
/// that direction's sigma, when long and straight enough ([`SCAN_MIN_SPAN_M`],
/// [`SCAN_MAX_RMS_M`]).
fn wall_of(piece: &[(f64, f64)], sensor: (f64, f64)) -> Option<(f64, f64)> {
    let n = piece.len() as f64;
    let (mx, my) = piece
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p.0 / n, y + p.1 / n));
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in piece {
        let (dx, dy) = (p.0 - mx, p.1 - my);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    // The line's direction is the scatter's major axis; its normal the minor one.
    let along = 0.5 * f64::atan2(2.0 * sxy, sxx - syy);
    let (s, c) = along.sin_cos();
    let spread: f64 = piece
        .iter()
        .map(|p| (c * (p.0 - mx) + s * (p.1 - my)).powi(2))
        .sum();
    let across: f64 = piece
        .iter()
        .map(|p| (-s * (p.0 - mx) + c * (p.1 - my)).powi(2))
        .sum();
    let rms = (across / n).sqrt();
    let span = piece
        .iter()
        .map(|p| c * (p.0 - mx) + s * (p.1 - my))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(t), hi.max(t))
        });
    if span.1 - span.0 < SCAN_MIN_SPAN_M || rms > SCAN_MAX_RMS_M {
        return None;
    }
    let mut normal = along + std::f64::consts::FRAC_PI_2;
    if normal.cos() * (mx - sensor.0) + normal.sin() * (my - sensor.1) < 0.0 {
        normal += std::f64::consts::PI;
    }
    let sigma = (rms.max(SCAN_NOISE_FLOOR_M) / spread.sqrt()).max(SIGMA_FLOOR_RAD);
    Some((wrap_angle(normal), sigma))
}

/// The span of time around `frame` within [`REACH_M`] of travel and [`MAX_TURN_RAD`] of heading
/// of it, by the odometry.
fn window(odometry: &[StampedPose], path: &[f64], frame: &Keyframe) -> Option<(f64, f64)> {
    let at = odometry
        .partition_point(|p| p.t_s < frame.t_s)
        .min(odometry.len() - 1);
    let heading = odometry[at].pose.theta;
    let within = |i: usize| {
        (path[i] - path[at]).abs() <= REACH_M
            && wrap_angle(odometry[i].pose.theta - heading).abs() <= MAX_TURN_RAD
    };
    if !within(at) {
        return None;
    }
    let mut from = at;
    while from > 0 && within(from - 1) {
        from -= 1;
    }
    let mut to = at;
    while to + 1 < odometry.len() && within(to + 1) {
        to += 1;
    }
    Some((odometry[from].t_s, odometry[to].t_s))
}

/// One echo in the keyframe's frame: where its sensor was, the range, its weight (an inverse
/// variance).
#[derive(Clone, Copy)]
struct Echo {
    sensor: Pose2,
    range_m: f64,
    weight: f64,
}

/// The line that the echoes' arcs all touch at their cones' common direction: its normal's
/// direction (sensor to wall) and that direction's sigma, or `None` when the echoes do not lie on
/// one straight wall ([`MIN_ECHOES`], [`MIN_SPAN_M`], [`MIN_INLIER_SHARE`], [`MAX_WHITENED_RMS`],
/// [`EDGE_MARGIN_RAD`]). A wall with normal `u` at offset `d` is touched by an echo at range `r`
/// from a sensor at `c` when `u . c + r = d`.
fn fit_line(echoes: &[Echo], half_cone_rad: f64) -> Option<(f64, f64)> {
    if echoes.len() < MIN_ECHOES {
        return None;
    }
    let fitted = fit_among(echoes, half_cone_rad)?;
    // Once more without the echoes off it (a person, a chair before the wall).
    let inliers: Vec<Echo> = echoes
        .iter()
        .filter(|e| residual(e, fitted.0, fitted.1).powi(2) * e.weight <= 9.0)
        .copied()
        .collect();
    if inliers.len() < MIN_ECHOES || (inliers.len() as f64) < MIN_INLIER_SHARE * echoes.len() as f64
    {
        return None;
    }
    let (normal, offset) = fit_among(&inliers, half_cone_rad)?;
    let chi2: f64 = inliers
        .iter()
        .map(|e| residual(e, normal, offset).powi(2) * e.weight)
        .sum();
    if chi2 / (inliers.len() - 2) as f64 > MAX_WHITENED_RMS.powi(2) {
        return None;
    }
    // The feet along the wall: their spread, and the direction's information.
    let along = |e: &Echo| -normal.sin() * e.sensor.x + normal.cos() * e.sensor.y;
    let (lo, hi) = inliers
        .iter()
        .map(along)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(t), hi.max(t))
        });
    if hi - lo < MIN_SPAN_M {
        return None;
    }
    let weights: f64 = inliers.iter().map(|e| e.weight).sum();
    let mean = inliers.iter().map(|e| e.weight * along(e)).sum::<f64>() / weights;
    let information: f64 = inliers
        .iter()
        .map(|e| e.weight * (along(e) - mean).powi(2))
        .sum();
    let sigma = information.recip().sqrt().max(SIGMA_FLOOR_RAD);
    Some((wrap_angle(normal), sigma))
}

/// How far an echo's arc falls from the wall with normal at `normal` and offset `offset`.
fn residual(e: &Echo, normal: f64, offset: f64) -> f64 {
    normal.cos() * e.sensor.x + normal.sin() * e.sensor.y + e.range_m - offset
}

/// The weighted least-squares line over the directions every echo's cone holds (strictly inside
/// by [`EDGE_MARGIN_RAD`]): its normal's direction and offset.
fn fit_among(echoes: &[Echo], half_cone_rad: f64) -> Option<(f64, f64)> {
    // The cones' common directions, relative to the first echo's bearing.
    let base = echoes.first()?.sensor.theta;
    let (mut lo, mut hi) = (-half_cone_rad, half_cone_rad);
    for e in echoes {
        let b = wrap_angle(e.sensor.theta - base);
        lo = lo.max(b - half_cone_rad);
        hi = hi.min(b + half_cone_rad);
    }
    if hi - lo <= 2.0 * EDGE_MARGIN_RAD {
        return None;
    }
    let weights: f64 = echoes.iter().map(|e| e.weight).sum();
    let cost = |phi: f64| {
        let normal = base + phi;
        let (s, c) = normal.sin_cos();
        let offset = echoes
            .iter()
            .map(|e| e.weight * (c * e.sensor.x + s * e.sensor.y + e.range_m))
            .sum::<f64>()
            / weights;
        let sum = echoes
            .iter()
            .map(|e| e.weight * residual(e, normal, offset).powi(2))
            .sum::<f64>();
        (sum, offset)
    };
    let steps = ((hi - lo) / SCAN_STEP_RAD).ceil() as usize;
    let (best, _) = (0..=steps)
        .map(|i| lo + (hi - lo) * i as f64 / steps as f64)
        .map(|phi| (phi, cost(phi).0))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    // A parabola through the best step and its neighbours.
    let h = (hi - lo) / steps as f64;
    let (c0, c1, c2) = (cost(best - h).0, cost(best).0, cost(best + h).0);
    let curvature = c0 - 2.0 * c1 + c2;
    let refined = if curvature > 0.0 {
        best + 0.5 * h * (c0 - c2) / curvature
    } else {
        best
    };
    if refined < lo + EDGE_MARGIN_RAD || refined > hi - EDGE_MARGIN_RAD {
        return None;
    }
    Some((base + refined, cost(refined).1))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Echoes of a side sonar sliding 2 m along a wall that runs 4 degrees off the robot's path,
    /// with a centimetre of noise and a person in front of the wall once.
    fn along_a_wall(slant_rad: f64) -> Vec<Echo> {
        let mut noise = 0.37f64;
        (0..20)
            .map(|i| {
                let x = -1.0 + 0.1 * i as f64;
                // The wall: y = 0.6 + x tan(slant); the sensor looks left (bearing 90 degrees).
                let distance = (0.6 + x * slant_rad.tan()) * slant_rad.cos();
                noise = (noise * 7.3 + 0.11).fract();
                let person = if i == 7 { -0.4 } else { 0.0 };
                Echo {
                    sensor: Pose2::new(x, 0.0, std::f64::consts::FRAC_PI_2),
                    range_m: distance + 0.02 * (noise - 0.5) + person,
                    weight: 0.015f64.powi(-2),
                }
            })
            .collect()
    }

    #[test]
    fn a_wall_slid_along_gives_its_normal() {
        let slant = 4f64.to_radians();
        let (normal, sigma) = fit_line(&along_a_wall(slant), 15f64.to_radians()).unwrap();
        // The normal points from the sensor to the wall: 90 degrees plus the slant.
        let error = wrap_angle(normal - (std::f64::consts::FRAC_PI_2 + slant));
        assert!(error.abs() < 3.0 * sigma, "{error} against {sigma}");
        assert!(sigma < 1f64.to_radians(), "{sigma}");
    }

    /// Walls along axes 20 degrees off the start's, seen by a heading that drifts a tenth of a
    /// degree a wall, each a fifth of a degree off (a fixed pseudo-random spread), and a wall
    /// slanted 30 degrees every tenth.
    fn seen_along_axes() -> Vec<(f64, f64)> {
        let mut noise = 0.61f64;
        (0..60)
            .map(|i| {
                noise = (noise * 5.7 + 0.31).fract();
                let wall = if i % 10 == 9 {
                    30.0
                } else {
                    (i % 4) as f64 * 90.0
                };
                let deg = 20.0 + wall + 0.1 * i as f64 + 0.4 * (noise - 0.5);
                (wrap_angle(deg.to_radians()), 0.3f64.to_radians())
            })
            .collect()
    }

    #[test]
    fn walls_at_right_angles_are_found_along_a_drifting_heading() {
        let axes = along_axes(&seen_along_axes()).expect("the walls run at right angles");
        // The first few walls say where the axes are, before the heading drifted far.
        let off = wrap_angle(4.0 * (axes.axes_rad - 20f64.to_radians())) / 4.0;
        assert!(off.abs() < 1f64.to_radians(), "{}", off.to_degrees());
        // Every slanted wall is left out, every other taken; the fits' sigmas hold.
        for (i, along) in axes.along.iter().enumerate() {
            assert_eq!(*along, i % 10 != 9, "wall {i}");
        }
        assert_eq!(axes.sigma_scale, 1.0);
    }

    #[test]
    fn walls_in_every_direction_are_not_along_axes() {
        let seen: Vec<(f64, f64)> = (0..60)
            .map(|i| (wrap_angle((i as f64 * 37.0).to_radians()), 0.005))
            .collect();
        assert_eq!(along_axes(&seen), None);
        assert_eq!(along_axes(&[]), None);
    }

    #[test]
    fn directions_scattered_wider_than_their_fits_say_get_wider_sigmas() {
        // The same walls, their fits claiming a fiftieth of a degree.
        let seen: Vec<(f64, f64)> = seen_along_axes()
            .into_iter()
            .map(|(a, _)| (a, 0.02f64.to_radians()))
            .collect();
        let axes = along_axes(&seen).expect("along axes");
        assert!(axes.sigma_scale > 2.0, "{}", axes.sigma_scale);
    }

    /// A laser of 180 beams a degree apart in a 6 x 4 m room with a round pillar, at `at` (the
    /// odometry's pose and the keyframe's), its ranges in 5 cm steps as aces logs them; one scan.
    fn laser_in_a_room(
        at: Pose2,
    ) -> (
        Vec<Keyframe>,
        Vec<StampedPose>,
        Vec<SonarReading>,
        SonarLayout,
    ) {
        let sensors = (0..180)
            .map(|k| crate::sonar::SonarSensor {
                x_m: 0.0,
                y_m: 0.0,
                bearing_rad: (k as f64 - 90.0).to_radians(),
            })
            .collect();
        let layout = SonarLayout {
            name: "lidar".into(),
            beam: BeamModel::Ray,
            cone_rad: 1f64.to_radians(),
            max_range_m: 20.0,
            min_range_m: 0.0,
            sensors,
        };
        let range = |bearing: f64| {
            let (s, c) = (at.theta + bearing).sin_cos();
            let walls = [
                (3.0 - at.x) / c,
                (-3.0 - at.x) / c,
                (2.0 - at.y) / s,
                (-2.0 - at.y) / s,
            ];
            let wall = walls
                .into_iter()
                .filter(|t| *t > 0.0)
                .fold(f64::INFINITY, f64::min);
            // The pillar: 0.3 m across, at (1.5, 1.0).
            let (px, py) = (1.5 - at.x, 1.0 - at.y);
            let along = px * c + py * s;
            let miss = (px * s - py * c).abs();
            let pillar = if along > 0.0 && miss < 0.15 {
                along - (0.15f64.powi(2) - miss * miss).sqrt()
            } else {
                f64::INFINITY
            };
            (wall.min(pillar) / 0.05).round() * 0.05
        };
        let readings = layout
            .sensors
            .iter()
            .enumerate()
            .map(|(sensor, s)| SonarReading {
                t_s: 0.5,
                sensor,
                range_m: Some(range(s.bearing_rad)),
            })
            .collect();
        let odometry = vec![
            StampedPose { t_s: 0.0, pose: at },
            StampedPose { t_s: 1.0, pose: at },
        ];
        let frames = vec![Keyframe {
            t_s: 1.0,
            odom: at,
            init: at,
        }];
        (frames, odometry, readings, layout)
    }

    #[test]
    fn a_laser_scan_gives_a_walls_normal_in_the_keyframes_frame() {
        let heading = 20f64.to_radians();
        let (frames, odometry, readings, layout) = laser_in_a_room(Pose2::new(0.5, -0.3, heading));
        let config = FuseConfig::default();
        let found = wall_directions(&frames, &odometry, &readings, &layout, &config);
        assert_eq!(found.len(), 1, "one direction a scan: {found:?}");
        let d = found[0];
        // The room's walls' normals lie along the world's axes: in the robot's frame, a quarter
        // turn apart from minus the heading.
        let off = wrap_angle(4.0 * (d.normal_rad + heading)) / 4.0;
        assert!(
            off.abs() < (3.0 * d.sigma_rad).max(0.2f64.to_radians()),
            "{} deg off, sigma {} deg",
            off.to_degrees(),
            d.sigma_rad.to_degrees()
        );
        assert!(
            d.sigma_rad < 0.5f64.to_radians(),
            "{}",
            d.sigma_rad.to_degrees()
        );
        // Another keyframe on the same scan does not measure it again.
        let at = frames[0].odom;
        let twice: Vec<Keyframe> = [0.8, 1.0]
            .map(|t_s| Keyframe {
                t_s,
                odom: at,
                init: at,
            })
            .into();
        assert_eq!(
            wall_directions(&twice, &odometry, &readings, &layout, &config).len(),
            1
        );
    }

    #[test]
    fn a_wall_outside_the_cone_or_a_short_stretch_gives_nothing() {
        // Slanted 20 degrees: its normal lies outside a 30-degree cone about the bearing.
        assert!(fit_line(&along_a_wall(20f64.to_radians()), 15f64.to_radians()).is_none());
        let short: Vec<Echo> = along_a_wall(0.0).into_iter().take(8).collect();
        assert!(fit_line(&short, 15f64.to_radians()).is_none());
    }
}
