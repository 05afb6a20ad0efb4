//! The online filter: the EKF run over a survey's odometry, sightings and visual turns as they
//! stream in, with re-solves of the graph of the run so far.

use crate::fusion::ekf::Ekf;
use crate::fusion::events::{events, Event};
use crate::fusion::landmark::Extras;
use crate::fusion::measurement::sighting_measurement;
use crate::fusion::{
    associate, Conflict, FuseConfig, Landmark, Observations, OdometryCalibration, OfflineKept,
};
use crate::geometry::{pose_at, wrap_angle, Pose2, StampedPose};
use crate::sonar::hough::Feature;
use crate::visual::sightings::TagSighting;
use crate::visual::tags::TagId;
use nalgebra::Vector2;

/// The result of the online filter.
#[derive(Debug, Clone)]
pub struct OnlineResult {
    /// Filtered pose at each odometry time.
    pub trajectory: Vec<StampedPose>,
    /// Landmarks at the end of the run.
    pub landmarks: Vec<Landmark>,
    /// Sightings fused (indices into the input).
    pub accepted: Vec<usize>,
    /// Sightings gated out (indices into the input).
    pub rejected: Vec<usize>,
    /// Consistency problems found.
    pub conflicts: Vec<Conflict>,
    /// Filtered pose at each sighting (same order as the input), used to start the offline pass.
    pub pose_at_sighting: Vec<Pose2>,
    /// Normalised innovation squared of each accepted update (for consistency plots).
    pub nis: Vec<Nis>,
    /// Position sigma of the pose (√ of the largest eigenvalue) at each odometry time, metres.
    pub sigma_m: Vec<f64>,
    /// Each re-solve of the graph of the run so far ([`FuseConfig::online_resolve`]).
    pub resolves: Vec<OnlineResolve>,
    /// Visual turns fused.
    pub visual_fused: usize,
    /// Visual turns gated out.
    pub visual_rejected: usize,
    /// Loop hypotheses tested ([`FuseConfig::loop_test`]): gated-out re-sightings of a landmark
    /// tried as a loop closure.
    pub loop_tests: usize,
}

/// The normalised innovation squared of one accepted sighting: about 3 on average (its degrees
/// of freedom) when the filter's covariance is honest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nis {
    /// When, seconds.
    pub t_s: f64,
    /// The NIS.
    pub value: f64,
}

/// One re-solve of the online graph: what the filter took from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnlineResolve {
    /// When, seconds (an odometry time).
    pub t_s: f64,
    /// The odometry calibration found (the filter predicts with it from then on).
    pub odometry_calibration: OdometryCalibration,
    /// How far the solve moved the filter's pose, metres.
    pub moved_m: f64,
    /// How far it turned the filter's heading, radians.
    pub turned_rad: f64,
    /// Gated-out re-sightings this solve took in as a loop closure (0 for a routine re-solve).
    pub loop_sightings: usize,
}

/// Travel between two re-solves of the online graph, at least (metres; see
/// [`FuseConfig::online_resolve`]).
const RESOLVE_MIN_TRAVEL_M: f64 = 5.0;
/// Travel between two re-solves of the online graph as a share of the travel so far, at least:
/// the solves grow with the run, so they come less often as it goes on (about eight on the
/// museum's 165 m, 0.17 s in all; with 0.1 instead of 0.25 there are fourteen, 0.31 s, for an
/// online ATE within 1 cm of this one's on the office and museum sample runs).
const RESOLVE_SHARE: f64 = 0.25;
/// Travel before a landmark whose loop hypothesis failed is tried again, metres; doubled after
/// each further failure (a moved tag is seen again and again, and each test solves the run so
/// far: a tag seen for 500 m after it was moved costs about eight tests, not 250).
const LOOP_RETEST_TRAVEL_M: f64 = 2.0;

/// Runs the online filter over a run: odometry predicts, sightings and visual turns update as
/// they arrive, and now and then the graph of the run so far is re-solved
/// ([`FuseConfig::online_resolve`]). `corners` are the Hough features a new landmark is matched
/// with; `calibration` (the same robot's odometry errors, found by an earlier survey) corrects
/// the odometry from the start until a re-solve finds the run's own.
pub fn run_online(
    obs: &Observations<'_>,
    corners: &[Feature],
    config: &FuseConfig,
    calibration: Option<OdometryCalibration>,
) -> OnlineResult {
    let mut filter = OnlineFilter::new(obs, corners, config, calibration);
    let first_t = obs.odometry.first().map_or(f64::NEG_INFINITY, |p| p.t_s);
    let mut pending = events(obs.sightings, obs.visual, first_t, config)
        .into_iter()
        .peekable();
    for (i, sample) in obs.odometry.iter().enumerate() {
        let mut seen_again = false;
        while let Some((t, event)) = pending.next_if(|&(t, _)| t <= sample.t_s) {
            let odom = pose_at(obs.odometry, t).unwrap_or(sample.pose);
            filter.advance(odom);
            seen_again |= filter.handle(event);
        }
        filter.advance(sample.pose);
        filter.record(sample.t_s);
        let closed =
            !filter.gated.is_empty() && filter.loop_test_on() && filter.test_loop(i, sample.t_s);
        if !closed && filter.resolve_due(seen_again) {
            filter.resolve(i, sample.t_s);
        }
        filter.gated.clear();
    }
    // Sightings after the last odometry sample: fused at the last pose.
    for (_, event) in pending {
        if let Event::Sighting(k) = event {
            filter.sighting(k);
        }
    }
    filter.finish()
}

/// The online filter's state as it works through a run.
struct OnlineFilter<'a> {
    obs: &'a Observations<'a>,
    corners: &'a [Feature],
    config: &'a FuseConfig,
    ekf: Ekf,
    extras: Vec<Extras>,
    result: OnlineResult,
    last_odom: Pose2,
    /// The visual turn whose start the heading copy holds.
    cloned_for: Option<usize>,
    /// The earlier survey's odometry calibration, the re-solves' prior.
    prior: Option<OdometryCalibration>,
    /// The calibration the odometry is corrected with now.
    calibration: Option<OdometryCalibration>,
    travel: f64,
    travel_at_solve: f64,
    /// Re-sightings of known landmarks gated out since the last odometry sample.
    gated: Vec<usize>,
    /// Per landmark whose loop hypothesis failed: the travel from which it is tried again and
    /// the gap before the next try after that.
    loop_retry: std::collections::HashMap<TagId, (f64, f64)>,
}

impl<'a> OnlineFilter<'a> {
    fn new(
        obs: &'a Observations<'a>,
        corners: &'a [Feature],
        config: &'a FuseConfig,
        calibration: Option<OdometryCalibration>,
    ) -> Self {
        let (ekf, start) = Ekf::at_start(obs.odometry);
        let n = obs.odometry.len();
        Self {
            obs,
            corners,
            config,
            ekf,
            extras: Vec::new(),
            result: OnlineResult {
                trajectory: Vec::with_capacity(n),
                landmarks: Vec::new(),
                accepted: Vec::new(),
                rejected: Vec::new(),
                conflicts: Vec::new(),
                pose_at_sighting: vec![start; obs.sightings.len()],
                nis: Vec::new(),
                sigma_m: Vec::with_capacity(n),
                resolves: Vec::new(),
                visual_fused: 0,
                visual_rejected: 0,
                loop_tests: 0,
            },
            last_odom: start,
            cloned_for: None,
            prior: calibration,
            calibration,
            travel: 0.0,
            travel_at_solve: 0.0,
            gated: Vec::new(),
            loop_retry: std::collections::HashMap::new(),
        }
    }

    /// Predicts with the odometry up to `odom`.
    fn advance(&mut self, odom: Pose2) {
        let (_, path) = self.ekf.advance_calibrated(
            &mut self.last_odom,
            odom,
            self.calibration.as_ref(),
            self.config,
        );
        self.travel += path;
    }

    /// Handles one event; true when it was a sighting of a landmark seen before, fused.
    fn handle(&mut self, event: Event) -> bool {
        match event {
            Event::TurnStarts(j) => {
                self.ekf.clone_heading();
                self.cloned_for = Some(j);
                false
            }
            Event::TurnEnds(j) => {
                if self.cloned_for == Some(j) {
                    let v = &self.obs.visual[j];
                    let var = v.sigma_rad * v.sigma_rad;
                    if self
                        .ekf
                        .update_turn(v.turn_rad, var, self.config.visual_gate_chi2)
                    {
                        self.result.visual_fused += 1;
                    } else {
                        self.result.visual_rejected += 1;
                    }
                }
                self.ekf.drop_clone();
                self.cloned_for = None;
                false
            }
            Event::Sighting(k) => {
                let known = self.ekf.slot(&self.obs.sightings[k].key()).is_some();
                let fused = self.sighting(k);
                if known && !fused {
                    self.gated.push(k);
                }
                known && fused
            }
        }
    }

    /// Fuses sighting `k` at the current pose; true when fused.
    fn sighting(&mut self, k: usize) -> bool {
        self.result.pose_at_sighting[k] = self.ekf.pose();
        fuse_sighting(
            &mut self.ekf,
            &mut self.extras,
            &self.obs.sightings[k],
            k,
            self.corners,
            self.config,
            &mut self.result,
        )
    }

    /// Notes the filtered pose and its sigma at odometry time `t_s`.
    fn record(&mut self, t_s: f64) {
        self.result.trajectory.push(StampedPose {
            t_s,
            pose: self.ekf.pose(),
        });
        self.result.sigma_m.push(self.ekf.position_sigma_m());
    }

    /// Whether to re-solve now: a landmark was seen again and the robot has travelled far
    /// enough since the last solve.
    fn resolve_due(&self, seen_again: bool) -> bool {
        let since = self.travel - self.travel_at_solve;
        self.config.online_resolve
            && self.config.calibrate_odometry
            && seen_again
            && since >= RESOLVE_MIN_TRAVEL_M.max(RESOLVE_SHARE * self.travel)
    }

    /// Re-solves the graph of the run up to odometry sample `i` (at `t_s`) and goes on from its
    /// pose, landmarks and odometry calibration.
    fn resolve(&mut self, i: usize, t_s: f64) {
        self.travel_at_solve = self.travel;
        let so_far = OnlineResult {
            landmarks: self.ekf.landmarks(&self.extras),
            ..self.result.clone()
        };
        let solved = self.solve_up_to(i, &so_far, self.config);
        self.adopt(&solved, t_s, 0);
    }

    /// Whether gated-out re-sightings are tried as loop closures.
    fn loop_test_on(&self) -> bool {
        self.config.loop_test && self.config.online_resolve && self.config.calibrate_odometry
    }

    /// The loop hypothesis for the re-sightings gated out since the last sample: their
    /// landmarks are the ones seen before, however far the odometry drifted. Every gated-out
    /// sighting of those landmarks joins the graph of the run so far, which is solved; the
    /// hypothesis holds when the solution explains each of them (chi-square 99%), leaves at
    /// most 1% of all sightings unexplained, and bends the odometry no more than its noise
    /// allows (its whitened residuals under the chi-square 99% point of their degrees of
    /// freedom). Then the filter goes on from that solution with the sightings fused; else they
    /// stay gated out, the landmark is tried again after [`LOOP_RETEST_TRAVEL_M`] (doubling),
    /// and what never passes is left to [`find_conflicts`] to report as a moved tag or a
    /// duplicate id. True when a loop closed (a failed test leaves a due re-solve due).
    fn test_loop(&mut self, i: usize, t_s: f64) -> bool {
        let sightings = self.obs.sightings;
        let travel = self.travel;
        let retry = &self.loop_retry;
        let tags: std::collections::BTreeSet<TagId> = self
            .gated
            .iter()
            .map(|&k| sightings[k].key())
            .filter(|tag| retry.get(tag).is_none_or(|&(from_m, _)| travel >= from_m))
            .collect();
        if tags.is_empty() {
            return false;
        }
        self.result.loop_tests += 1;
        let (joining, still_out): (Vec<usize>, Vec<usize>) = self
            .result
            .rejected
            .iter()
            .partition(|&&k| tags.contains(&sightings[k].key()));
        let mut hypothesis = OnlineResult {
            landmarks: self.ekf.landmarks(&self.extras),
            rejected: still_out.clone(),
            ..self.result.clone()
        };
        hypothesis.accepted.extend(&joining);
        hypothesis
            .accepted
            .sort_by(|&a, &b| sightings[a].t_s.total_cmp(&sightings[b].t_s));
        // First with the Huber kernel, which reaches a large correction from far away; then,
        // when the kernel left the loop open as an outlier, by least squares (the hypothesis is
        // that every sighting holds). A failed hypothesis is not news: the solves' own warnings
        // stay quiet.
        let least_squares = FuseConfig {
            huber_sigma: f64::INFINITY,
            ..self.config.clone()
        };
        let explains = |solved: &super::OfflineResult| {
            solved.kept == OfflineKept::Solution
                && joining.iter().all(|k| !solved.inconsistent.contains(k))
                && solved.inconsistent.len() * 100 <= solved.sightings
                && solved.odometry_chi2[1] <= chi2_99(3 * solved.odometry_factors)
        };
        let mut closed = None;
        for config in [self.config, &least_squares] {
            let solved = tracing::dispatcher::with_default(&tracing::Dispatch::none(), || {
                self.solve_up_to(i, &hypothesis, config)
            });
            if explains(&solved) {
                closed = Some(solved);
                break;
            }
        }
        let Some(solved) = closed else {
            for tag in tags {
                let gap = self
                    .loop_retry
                    .get(&tag)
                    .map_or(LOOP_RETEST_TRAVEL_M, |&(_, gap)| 2.0 * gap);
                self.loop_retry.insert(tag, (travel + gap, gap));
            }
            return false;
        };
        tracing::debug!(
            "t = {t_s:.1} s: {} re-sighting(s) of tag(s) {:?} close a loop (odometry chi-square {:.0} for {} factors)",
            joining.len(),
            tags.iter().map(|t| t.id).collect::<Vec<_>>(),
            solved.odometry_chi2[1],
            solved.odometry_factors
        );
        for tag in &tags {
            self.loop_retry.remove(tag);
        }
        for &k in &joining {
            if let Some(slot) = self.ekf.slot(&sightings[k].key()) {
                self.extras[slot].add(&sightings[k]);
            }
        }
        self.result.accepted = hypothesis.accepted;
        self.result.rejected = still_out;
        self.adopt(&solved, t_s, joining.len());
        true
    }

    /// The graph of the run up to odometry sample `i`, solved from `so_far`.
    fn solve_up_to(
        &self,
        i: usize,
        so_far: &OnlineResult,
        config: &FuseConfig,
    ) -> super::OfflineResult {
        let up_to_now = Observations {
            odometry: &self.obs.odometry[..=i],
            ..*self.obs
        };
        super::offline::resolve_online(&up_to_now, so_far, config, self.prior.as_ref())
    }

    /// Goes on from a solve's pose, landmarks and odometry calibration.
    fn adopt(&mut self, solved: &super::OfflineResult, t_s: f64, loop_sightings: usize) {
        let (Some(c), Some(now)) = (solved.odometry_calibration, solved.trajectory.last()) else {
            return;
        };
        self.travel_at_solve = self.travel;
        let was = self.ekf.pose();
        self.result.resolves.push(OnlineResolve {
            t_s,
            odometry_calibration: c,
            moved_m: (now.pose.x - was.x).hypot(now.pose.y - was.y),
            turned_rad: wrap_angle(now.pose.theta - was.theta),
            loop_sightings,
        });
        if let Some(last) = self.result.trajectory.last_mut() {
            last.pose = now.pose;
        }
        self.calibration = Some(c);
        let x = &mut self.ekf.x;
        x[0] = now.pose.x;
        x[1] = now.pose.y;
        x[2] = now.pose.theta;
        for (slot, l) in solved.landmarks.iter().enumerate() {
            x[3 + 3 * slot] = l.position_m[0];
            x[3 + 3 * slot + 1] = l.position_m[1];
            x[3 + 3 * slot + 2] = l.yaw_rad;
        }
        // The heading copy belongs to the state before the solve: the turn under way is left to
        // the next solve.
        self.ekf.drop_clone();
        self.cloned_for = None;
    }

    /// The result, with the landmarks at the end and the conflicts found.
    fn finish(mut self) -> OnlineResult {
        self.result.landmarks = self.ekf.landmarks(&self.extras);
        self.result.conflicts = find_conflicts(self.obs.sightings, &self.result, self.config);
        self.result
    }
}

/// The chi-square 99% point with `dof` degrees of freedom (Wilson and Hilferty's
/// approximation: within 0.5% from 3 degrees of freedom up).
fn chi2_99(dof: usize) -> f64 {
    let k = dof.max(1) as f64;
    let h = 2.0 / (9.0 * k);
    k * (1.0 - h + 2.326_348 * h.sqrt()).powi(3)
}

/// Fuses one sighting (a new landmark, or an update when it passes the gate); true when fused.
fn fuse_sighting(
    ekf: &mut Ekf,
    extras: &mut Vec<Extras>,
    sighting: &TagSighting,
    index: usize,
    corners: &[Feature],
    config: &FuseConfig,
    result: &mut OnlineResult,
) -> bool {
    let (z, r) = sighting_measurement(sighting, config);
    let key = sighting.key();
    let slot = match ekf.slot(&key) {
        Some(slot) => {
            let (y, s, jac) = ekf.innovation(slot, &z, &r);
            let Some(s_inv) = s.try_inverse() else {
                result.rejected.push(index);
                return false;
            };
            let d2 = (y.transpose() * s_inv * y)[0];
            if d2 > config.gate_chi2 {
                result.rejected.push(index);
                return false;
            }
            ekf.update(&y, &s, &jac, &r);
            result.nis.push(Nis {
                t_s: sighting.t_s,
                value: d2,
            });
            slot
        }
        None => {
            let slot = ekf.add(key, &z, &r);
            let (xy, cov) = ekf.landmark_xy_cov(slot);
            extras.push(Extras {
                corner: associate(&xy, &cov, corners, config),
                ..Extras::default()
            });
            slot
        }
    };
    extras[slot].add(sighting);
    result.accepted.push(index);
    true
}

/// Groups gated-out sightings by place and reports the places seen often enough.
fn find_conflicts(
    sightings: &[TagSighting],
    online: &OnlineResult,
    config: &FuseConfig,
) -> Vec<Conflict> {
    let mut places: Vec<(usize, Vec<usize>, Vector2<f64>)> = Vec::new(); // (landmark, members, sum)
    for &k in &online.rejected {
        let s = &sightings[k];
        let Some(l) = online
            .landmarks
            .iter()
            .position(|l| l.id == s.id && l.family == s.family)
        else {
            continue;
        };
        let world = online.pose_at_sighting[k].transform_point(nalgebra::Point2::new(
            s.position_in_robot_m[0],
            s.position_in_robot_m[1],
        ));
        let w = Vector2::new(world.x, world.y);
        match places.iter_mut().find(|(pl, members, sum)| {
            *pl == l && (sum / members.len() as f64 - w).norm() <= config.conflict_radius_m
        }) {
            Some((_, members, sum)) => {
                members.push(k);
                *sum += w;
            }
            None => places.push((l, vec![k], w)),
        }
    }
    places
        .into_iter()
        .filter(|(l, members, sum)| {
            let at = sum / members.len() as f64;
            let lm = &online.landmarks[*l].position_m;
            members.len() >= config.conflict_min_sightings
                && (at - Vector2::new(lm[0], lm[1])).norm() >= config.conflict_min_distance_m
        })
        .map(|(l, members, sum)| {
            let lm = &online.landmarks[l];
            let first_t_s = members
                .iter()
                .map(|&k| sightings[k].t_s)
                .fold(f64::INFINITY, f64::min);
            let seen_again = online.accepted.iter().any(|&k| {
                sightings[k].id == lm.id
                    && sightings[k].family == lm.family
                    && sightings[k].t_s > first_t_s
            });
            let at = sum / members.len() as f64;
            Conflict {
                id: lm.id,
                family: lm.family,
                kind: if seen_again { "duplicate id" } else { "moved" }.into(),
                landmark_m: [lm.position_m[0], lm.position_m[1]],
                seen_at_m: [at.x, at.y],
                sightings: members.len(),
                first_t_s,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::testing::obs;
    use crate::fusion::testing::square_run;
    use crate::metrics::ate_m;

    /// Given the robot's odometry errors by an earlier survey, the online filter tracks the first
    /// lap too, which it otherwise dead-reckons until the loop closes.
    #[test]
    fn an_earlier_surveys_calibration_helps_the_first_lap() {
        let (odom, truth, sightings, _) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let first_lap = |r: &OnlineResult| {
            let half = r.trajectory.len() / 2;
            ate_m(&r.trajectory[..half], &truth[..half]).unwrap()
        };
        // The square's wheels: turns 3% long, 0.01 rad of false turn and 1% more distance per metre.
        let known = OdometryCalibration {
            turn_scale_error: 1.0 / 1.03 - 1.0,
            heading_drift_rad_per_m: -0.01,
            distance_scale_error: 1.0 / 1.01 - 1.0,
        };
        let plain = first_lap(&run_online(
            &obs(&odom, &sightings, &[]),
            &[],
            &config,
            None,
        ));
        let given = first_lap(&run_online(
            &obs(&odom, &sightings, &[]),
            &[],
            &config,
            Some(known),
        ));
        assert!(
            given < 0.3 * plain,
            "first lap: {given} m given, {plain} m plain"
        );
    }

    /// Over four laps of the biased square, the filter that re-solves the run so far learns the
    /// odometry's errors and tracks the later laps far better than the plain EKF.
    #[test]
    fn re_solving_online_learns_the_odometry_errors() {
        let (odom, truth, sightings, _) = square_run(0.01, 4);
        let later = |r: &OnlineResult| {
            let half = r.trajectory.len() / 2;
            ate_m(&r.trajectory[half..], &truth[half..]).unwrap()
        };
        let plain = run_online(
            &obs(&odom, &sightings, &[]),
            &[],
            &FuseConfig {
                online_resolve: false,
                ..FuseConfig::default()
            },
            None,
        );
        let resolved = run_online(
            &obs(&odom, &sightings, &[]),
            &[],
            &FuseConfig::default(),
            None,
        );
        assert!(plain.resolves.is_empty());
        assert!(resolved.resolves.len() >= 2, "{:?}", resolved.resolves);
        // The last re-solve found the wheels' errors: turns 3% long, 0.01 rad of false turn per
        // metre (the simulated odometry's own, see `square_run`).
        let c = resolved.resolves.last().unwrap().odometry_calibration;
        assert!(
            (c.turn_scale_error + 0.03 / 1.03).abs() < 0.005
                && (c.heading_drift_rad_per_m + 0.01).abs() < 0.002,
            "{c:?}"
        );
        let (a, b) = (later(&plain), later(&resolved));
        assert!(b < 0.25 * a, "later laps: plain {a} m, re-solved {b} m");
    }

    /// Odometry drifting 2-12% of distance (and three times that in turn scale): the gate alone
    /// takes the re-sightings after the first lap for moved tags (8 or more "moved"); the loop
    /// test closes every loop and the offline pass lands within 4 cm.
    #[test]
    fn a_loop_closes_however_far_the_odometry_drifted() {
        for bias in [0.02, 0.05, 0.12] {
            let (odom, truth, sightings, _) = square_run(bias, 3);
            let observations = obs(&odom, &sightings, &[]);
            let gate_alone = FuseConfig {
                loop_test: false,
                ..FuseConfig::default()
            };
            let without = run_online(&observations, &[], &gate_alone, None);
            assert!(
                without.conflicts.len() >= 8,
                "bias {bias}: {:?}",
                without.conflicts
            );
            let config = FuseConfig::default();
            let online = run_online(&observations, &[], &config, None);
            let closed: usize = online.resolves.iter().map(|r| r.loop_sightings).sum();
            let offline = crate::fusion::run_offline(&observations, &online, &config, None);
            let ate = ate_m(&offline.trajectory, &truth).unwrap();
            assert!(
                online.conflicts.is_empty() && online.rejected.is_empty() && closed >= 1,
                "bias {bias}: {} rejected, {:?}",
                online.rejected.len(),
                online.conflicts
            );
            assert!(ate < 0.04, "bias {bias}: offline ATE {ate} m");
        }
    }

    /// Tag 1 of [`square_run`] moved by 1 m along x, to (4, 5), after the first lap: its
    /// sightings from then on are of the moved tag, seen from the true poses.
    fn move_tag_1_after_the_first_lap(truth: &[StampedPose], sightings: &mut [TagSighting]) {
        let lap_end = truth[truth.len() / 2].t_s;
        for s in sightings
            .iter_mut()
            .filter(|s| s.id == 1 && s.t_s > lap_end)
        {
            let pose = truth.iter().find(|p| p.t_s == s.t_s).unwrap().pose;
            let moved = pose
                .inverse()
                .transform_point(nalgebra::Point2::new(4.0, 5.0));
            s.position_in_robot_m = [moved.x, moved.y, 0.5];
        }
    }

    /// A tag moved by 1 m after the first lap while the odometry drifts 3%: still reported as
    /// moved, its loop hypothesis rejected.
    #[test]
    fn a_moved_tag_is_caught_while_the_odometry_drifts() {
        let (odom, truth, mut sightings, _) = square_run(0.03, 2);
        move_tag_1_after_the_first_lap(&truth, &mut sightings);
        let online = run_online(
            &obs(&odom, &sightings, &[]),
            &[],
            &FuseConfig::default(),
            None,
        );
        assert!(online.loop_tests >= 1);
        let moved: Vec<_> = online
            .conflicts
            .iter()
            .map(|c| (c.id, c.kind.as_str()))
            .collect();
        assert_eq!(moved, vec![(1, "moved")], "{:?}", online.conflicts);
    }

    #[test]
    fn a_moved_tag_is_reported_not_fused() {
        let (odom, truth, mut sightings, _) = square_run(0.0, 2);
        move_tag_1_after_the_first_lap(&truth, &mut sightings);
        let online = run_online(
            &obs(&odom, &sightings, &[]),
            &[],
            &FuseConfig::default(),
            None,
        );
        assert_eq!(online.conflicts.len(), 1, "{:?}", online.conflicts);
        let c = &online.conflicts[0];
        assert_eq!((c.id, c.kind.as_str()), (1, "moved"));
        assert!((c.seen_at_m[0] - 4.0).abs() < 0.1 && (c.seen_at_m[1] - 5.0).abs() < 0.1);
        let l = online.landmarks.iter().find(|l| l.id == 1).unwrap();
        assert!((l.position_m[0] - 5.0).abs() < 0.05, "{l:?}");
    }

    #[test]
    fn a_tag_is_matched_with_the_corner_it_marks() {
        let (odom, _, sightings, _) = square_run(0.0, 2);
        let corner = |x: f64, y: f64| Feature {
            x_m: x,
            y_m: y,
            votes: 80,
            sightings: 1,
            spread_deg: 90.0,
            kind: crate::sonar::hough::FeatureKind::Corner,
        };
        let corners = vec![corner(4.95, 0.1), corner(2.5, 2.5)];
        let online = run_online(
            &obs(&odom, &sightings, &[]),
            &corners,
            &FuseConfig::default(),
            None,
        );
        let tag0 = online.landmarks.iter().find(|l| l.id == 0).unwrap();
        let m = tag0.matched_corner.expect("tag 0 matched");
        assert_eq!((m.x_m, m.y_m), (4.95, 0.1));
        let tag2 = online.landmarks.iter().find(|l| l.id == 2).unwrap();
        assert!(tag2.matched_corner.is_none());
    }
}
