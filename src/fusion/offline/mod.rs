//! The offline pass (the method's a-posteriori correction): a pose graph over keyframes of the
//! whole run, solved by Levenberg-Marquardt, its keyframe corrections interpolated along the
//! odometry.

mod factors;
mod graph;
mod interpolate;
mod keyframes;
mod mounting;
mod noise;
pub use noise::{NoiseScales, PoseFunction, SolutionCovariance};
pub(crate) mod scan_match;
mod wall_directions;

use crate::fusion::{FuseConfig, Landmark, Observations, OnlineResult};
use crate::geometry::{wrap_angle, Pose2, StampedPose};
use factors::corrected_increment;
use graph::SightingCheck;
pub use mounting::{estimate_mounting, MOUNTING_STRETCH_M};
use serde::{Deserialize, Serialize};

/// The result of the offline pass.
#[derive(Debug, Clone)]
pub struct OfflineResult {
    /// Corrected pose at each odometry time.
    pub trajectory: Vec<StampedPose>,
    /// Landmarks from the graph (covariances from the online filter).
    pub landmarks: Vec<Landmark>,
    /// Keyframes of the graph.
    pub keyframes: usize,
    /// Factors of the graph.
    pub factors: usize,
    /// Whether the solver converged: it stopped on its own criteria (not at the iteration
    /// limit: one more iteration changes the cost by less than a part in 10^6) and its solution
    /// was kept.
    pub converged: bool,
    /// Which estimate the pass returns: the solver's, or where it started (the online estimate)
    /// when the solver failed or its solution explains fewer sightings.
    pub kept: OfflineKept,
    /// The graph's cost where the solver started and where it ended.
    pub cost: [f64; 2],
    /// Sightings consistent (chi-square 99%) with the start and with the solution, of all.
    pub sightings_consistent: [usize; 2],
    /// Sightings in the graph.
    pub sightings: usize,
    /// The sightings (indices into the observations) inconsistent (chi-square 99%) with the
    /// estimate returned.
    pub inconsistent: Vec<usize>,
    /// The odometry factors' summed squared whitened residuals where the solver started and in
    /// the estimate returned (chi-square with `3 × odometry_factors` degrees of freedom when the
    /// odometry's noise is as modelled).
    pub odometry_chi2: [f64; 2],
    /// Odometry factors in the graph.
    pub odometry_factors: usize,
    /// Range factors off the walls in the graph ([`run_offline_walls`]; 0 in a pass without).
    pub wall_ranges: usize,
    /// Keyframes held where the sonar's latest ranges matched the grid of its older ones
    /// ([`run_offline_sonar`]; 0 in a pass without).
    pub sonar_matches: usize,
    /// Keyframes whose heading is held by the direction of a wall a sonar slid along, the walls
    /// running along two directions at right angles ([`run_offline_sonar`]): in the graph of the
    /// correction by the walls' directions alone (then [`Self::sonar_matches`] is 0), or in the
    /// matching, whose predictions they corrected. 0 in a pass without, and when the walls do
    /// not.
    pub sonar_wall_directions: usize,
    /// The direction of the building's walls the sonar's directions found, radians (one of four a
    /// quarter turn apart), when a correction by them was kept.
    pub wall_axes_rad: Option<f64>,
    /// The share of the run's echoes that agree with the others placed along the odometry and
    /// along the sonar's correction ([`run_offline_sonar`]; `None` in a pass without): the
    /// correction is kept only when it raises the share by 3 points.
    pub sonar_agreement: Option<[f64; 2]>,
    /// Whether the sonar's correction (kept or not: the one [`Self::sonar_agreement`] scores)
    /// took the wheels' distance as right (its distance scale held), the echoes agreeing better
    /// along it than along the one that estimated the scale ([`run_offline_sonar`]; false in a
    /// pass without). True also for a correction by the walls' directions alone
    /// ([`Self::sonar_wall_directions`] without matches), which holds the wheels' distance.
    pub sonar_wheel_distance: bool,
    /// Whether the sonar's matches were made along the odometry corrected by the turn scale and
    /// heading drift of the walls' directions' try, which the graph then held
    /// ([`run_offline_sonar`]; false in a pass without).
    pub sonar_turns_from_walls: bool,
    /// The run's start before the sonar's (or lidar's) first echo ([`run_offline_sonar`]; `None`
    /// in a pass without, and when nothing echoed).
    pub sonar_silent_start: Option<SilentStart>,
    /// The odometry calibration found, when estimated and the solver converged.
    pub odometry_calibration: Option<OdometryCalibration>,
    /// The camera's planar mounting error, when estimated
    /// ([`FuseConfig::estimate_mounting`]) and the solution kept.
    pub mounting: Option<MountingEstimate>,
    /// How noisy the odometry, the sightings and the visual turns were against their models, as
    /// the solution's residuals tell (its variance components); `None` for a solution not kept, a graph
    /// without sightings, and the online pass's re-solves.
    pub noise: Option<NoiseScales>,
    /// The solution's covariance with the noise the run measured ([`Self::noise`]); `None`
    /// unless measured, and in a pass with ranges off walls (walls mapped from the run's own
    /// trajectory are no independent check on it).
    pub covariance: Option<SolutionCovariance>,
    /// What the pass says of the estimate it returns, as it printed them (warnings): nothing to
    /// correct the odometry against, a solution or the sonar's correction not kept, a solver
    /// failure, a long silent start on the wheels alone ([`SilentStart`]).
    pub notes: Vec<String>,
}

/// The start of a run corrected by its sonar alone ([`run_offline_sonar`]), up to its first
/// echo. Until then the robot went on its wheels alone, and so does the map's orientation about
/// the start, which nothing later can see again: the walls and matches hold the rest of the run
/// to the map, not the map to the start. (The simulated museum's look-around is silent, its
/// first leg across the hall nearly so: turned about the start to fit the truth best, the
/// corrected maps of its seeds 1, 4 and 5 without stereo turn by 2.1, 1.4 and 0.7 degrees, and
/// seed 1's then scores 0.958 in occupied precision, where its ground-truth-pose map scores
/// 0.951; docs/RESULTS.md.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SilentStart {
    /// How long after the odometry's first pose the first echo came, seconds.
    pub duration_s: f64,
    /// Travel and turn (summed, unsigned) on the odometry until then, metres and radians.
    pub path_m: f64,
    /// See `path_m`.
    pub turn_rad: f64,
    /// The heading sigma the odometry's noise model gives over it, radians.
    pub heading_sigma_rad: f64,
}

/// A silent start whose heading sigma is above this (1 degree: 17 cm at 10 m from the start)
/// is warned about.
const SILENT_START_WARN_RAD: f64 = 0.0175;

impl SilentStart {
    /// The odometry's start up to `until_s`, with its heading sigma under `config`'s noise.
    fn of(odometry: &[StampedPose], until_s: f64, config: &FuseConfig) -> Self {
        let (mut path_m, mut turn_rad) = (0.0, 0.0);
        for w in odometry.windows(2).take_while(|w| w[1].t_s <= until_s) {
            let d = w[0].pose.between(&w[1].pose);
            path_m += d.x.hypot(d.y);
            turn_rad += wrap_angle(d.theta).abs();
        }
        let variance =
            crate::fusion::measurement::odometry_covariance(path_m, turn_rad, config)[(2, 2)];
        Self {
            // An echo before the odometry's first pose: no silent start.
            duration_s: (until_s - odometry.first().map_or(until_s, |p| p.t_s)).max(0.0),
            path_m,
            turn_rad,
            heading_sigma_rad: variance.sqrt(),
        }
    }

    /// The warning for a start long enough to matter, naming the `sensor`.
    fn warning(&self, sensor: &str) -> Option<String> {
        (self.heading_sigma_rad > SILENT_START_WARN_RAD).then(|| {
            format!(
                "the {sensor} heard nothing for the first {:.0} s of the run ({:.1} m and {:.0} degrees of turning on the wheels alone): the map's orientation about the start rests on the wheels there (heading sigma about {:.1} degrees by the odometry's noise model, {:.2} m at 10 m from the start) and nothing later can correct it; start a run within the {sensor}'s reach of a wall to tie the map to its start",
                self.duration_s,
                self.path_m,
                self.turn_rad.to_degrees(),
                self.heading_sigma_rad.to_degrees(),
                10.0 * self.heading_sigma_rad
            )
        })
    }
}

/// Prints `result`'s notes as warnings ([`OfflineResult::notes`]), once, as a pass returns it
/// (not each time a try is solved: the sonar's correction solves two side by side).
fn announced(result: OfflineResult) -> OfflineResult {
    for n in &result.notes {
        tracing::warn!("{n}");
    }
    result
}

/// The camera's planar mounting error the offline pass found: where the sightings must be moved
/// in the robot frame to agree with the odometry, `m` with the tag at `m ∘ z` from the robot for a
/// sighting `z`. The corrected mounting is `m ∘ robot_from_left` (x, y and yaw: height, roll and
/// pitch do not show in a planar survey).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountingEstimate {
    /// `m`: x, y (metres) and yaw (radians) in the robot frame.
    pub correction: Pose2,
    /// Its marginal covariance; `None` when the graph cannot give one (singular information).
    pub covariance: Option<nalgebra::Matrix3<f64>>,
}

impl MountingEstimate {
    /// The sigmas of `(x, y, yaw)`, when known.
    pub fn sigmas(&self) -> Option<[f64; 3]> {
        self.covariance
            .map(|c| [0, 1, 2].map(|i| c[(i, i)].max(0.0).sqrt()))
    }

    /// `robot_from_left` corrected.
    pub fn corrected(
        &self,
        robot_from_left: &nalgebra::Isometry3<f64>,
    ) -> nalgebra::Isometry3<f64> {
        let m = nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::new(self.correction.x, self.correction.y, 0.0),
            nalgebra::UnitQuaternion::from_axis_angle(
                &nalgebra::Vector3::z_axis(),
                self.correction.theta,
            ),
        );
        m * robot_from_left
    }
}

/// The estimate the offline pass returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OfflineKept {
    /// The solver's solution.
    Solution,
    /// The online estimate the solver started from.
    Start,
    /// The online estimate, unsolved: the run holds nothing to correct the odometry against
    /// (no tag sightings, no visual turns).
    Nothing,
}

impl OfflineKept {
    /// `solution` or `start`.
    pub fn as_str(&self) -> &'static str {
        match self {
            OfflineKept::Solution => "solution",
            OfflineKept::Start => "start",
            OfflineKept::Nothing => "nothing to correct against",
        }
    }
}

/// Systematic odometry errors as the offline pass estimates them: an odometry increment of
/// signed turn `dθ` over a path `ds` truly turned `dθ (1 + turn_scale_error) +
/// heading_drift_rad_per_m ds` and travelled `ds (1 + distance_scale_error)`. The same robot's
/// later runs can be corrected with it ([`OdometryCalibration::apply`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OdometryCalibration {
    /// Relative error of the turns (a wheel base off by 1% gives about 0.01).
    pub turn_scale_error: f64,
    /// Heading drift per metre travelled, radians (unequal wheel scales).
    pub heading_drift_rad_per_m: f64,
    /// Relative error of the distances.
    pub distance_scale_error: f64,
}

impl OdometryCalibration {
    /// An odometry increment `delta` (in the frame of its start) over `path_m` with signed turn
    /// `turn_rad`, corrected: the turn scaled and drift added, the translation turned by half the
    /// extra turn and scaled (the offline pass's own model of an interval).
    pub fn correct(&self, delta: Pose2, turn_rad: f64, path_m: f64) -> Pose2 {
        let [x, y, theta] = corrected_increment(
            [
                self.turn_scale_error,
                self.heading_drift_rad_per_m,
                self.distance_scale_error,
            ],
            [delta.x, delta.y, delta.theta],
            turn_rad,
            path_m,
        );
        Pose2::new(x, y, theta)
    }

    /// This calibration, then `more` on top of it (one found on odometry already corrected by
    /// this one), as one: the scales multiply, the drifts add.
    pub fn then(&self, more: &OdometryCalibration) -> OdometryCalibration {
        OdometryCalibration {
            turn_scale_error: (1.0 + self.turn_scale_error) * (1.0 + more.turn_scale_error) - 1.0,
            heading_drift_rad_per_m: self.heading_drift_rad_per_m
                + more.heading_drift_rad_per_m * (1.0 + self.distance_scale_error),
            distance_scale_error: (1.0 + self.distance_scale_error)
                * (1.0 + more.distance_scale_error)
                - 1.0,
        }
    }

    /// A whole odometry log corrected increment by increment, from the same first pose.
    pub fn apply(&self, odometry: &[StampedPose]) -> Vec<StampedPose> {
        let Some(first) = odometry.first() else {
            return Vec::new();
        };
        let mut pose = first.pose;
        let mut out = vec![*first];
        for w in odometry.windows(2) {
            let d = w[0].pose.between(&w[1].pose);
            let step = Pose2::new(d.x, d.y, wrap_angle(d.theta));
            pose = pose.compose(&self.correct(step, step.theta, d.x.hypot(d.y)));
            out.push(StampedPose {
                t_s: w[1].t_s,
                pose,
            });
        }
        out
    }
}

/// The method's a-posteriori pass: a pose graph over the whole run (keyframes, odometry, tag
/// sightings, visual turns), started from the `online` estimate and solved by
/// Levenberg-Marquardt; with `prior` (an earlier survey's odometry calibration) the calibration
/// is estimated near it instead of near no error.
pub fn run_offline(
    obs: &Observations<'_>,
    online: &OnlineResult,
    config: &FuseConfig,
    prior: Option<&OdometryCalibration>,
) -> OfflineResult {
    run_offline_anchored(obs, online, config, prior, &[])
}

/// [`run_offline`] with `anchors`: each anchored landmark held near its anchor by a prior with
/// the anchor's sigmas, and the first pose only loosely held where `online` starts (1 m, 1 rad),
/// so that the survey is solved in the anchors' frame (`obs` and `online` are already in it:
/// see [`crate::fusion::anchor_frame`]).
pub fn run_offline_anchored(
    obs: &Observations<'_>,
    online: &OnlineResult,
    config: &FuseConfig,
    prior: Option<&OdometryCalibration>,
    anchors: &[crate::fusion::Anchor],
) -> OfflineResult {
    without_sonar(obs, online, config, (prior, anchors), true)
}

/// The pass on the tags, visual turns and odometry alone, measuring the noise
/// ([`OfflineResult::noise`]) when `measure_noise`.
fn without_sonar(
    obs: &Observations<'_>,
    online: &OnlineResult,
    config: &FuseConfig,
    (prior, anchors): (Option<&OdometryCalibration>, &[crate::fusion::Anchor]),
    measure_noise: bool,
) -> OfflineResult {
    let sonar = (SonarUse::None, measure_noise);
    announced(solve(obs, online, config, (prior, None), anchors, sonar))
}

/// [`run_offline`] as the online pass re-solves the run so far: the same, without measuring the
/// noise ([`OfflineResult::noise`]).
pub(crate) fn resolve_online(
    obs: &Observations<'_>,
    online: &OnlineResult,
    config: &FuseConfig,
    prior: Option<&OdometryCalibration>,
) -> OfflineResult {
    without_sonar(obs, online, config, (prior, &[]), false)
}

/// The offline pass of a run with nothing else to correct its odometry against (no tag
/// sightings, no visual turns): the sonar's latest ranges at each keyframe are matched with the
/// counting grid (on `grid`) of its older readings, placed along the trajectory corrected so far,
/// and the matched keyframes hold the graph near where they matched (robust priors); the
/// odometry and its calibration carry the correction between them. A sonar run is first
/// corrected by the directions of the walls its sonars slid along alone, when the walls run at
/// right angles (`wall_directions`); when that correction makes the echoes agree, the headings
/// the matches are predicted along are corrected by the walls too. Of the tries, the one along
/// which the echoes agree best is taken. With no match, nothing is corrected
/// ([`OfflineKept::Nothing`]), as in [`run_offline`].
pub fn run_offline_sonar(
    obs: &Observations<'_>,
    online: &OnlineResult,
    config: &FuseConfig,
    sonar: &crate::fusion::SonarInput<'_>,
    grid: &crate::sonar::grid::GridConfig,
) -> OfflineResult {
    // The wheels' distance scale estimated with the rest of the calibration, or taken as right:
    // the matches hold the robot across the walls far better than along them, and the scale
    // they found scattered from -2.9% to +2.6% about the simulated wheels' 0 (office and museum,
    // seeds 1-5). Either way can be the better one: the scale is estimated only when the run's
    // echoes agree with one another clearly better along that correction ([`SCALE_MIN_GAIN`];
    // docs/RESULTS.md, "How good the judge between the tries is").
    // First the walls' directions alone (a sonar sliding along a wall, a laser's straight pieces:
    // `wall_directions`). When the echoes agree clearly better along their correction than along
    // the odometry, the building's axes it found correct the headings the matches are predicted
    // along: a match's grid is placed along the trajectory corrected so far, and where the sonar
    // heard nothing for a while (the simulated museum's hall) the odometry's heading has drifted
    // and the matches pull the run onto a bent map.
    let directions = sonar_passes(
        obs,
        online,
        config,
        SonarTry {
            sonar,
            grid,
            hold: SonarHold::Directions,
            first: None,
            axes: None,
            turns_held: false,
        },
    );
    let agreement = |trajectory: &[StampedPose]| {
        scan_match::agreement(trajectory, sonar.readings, sonar.layout, grid).unwrap_or(0.0)
    };
    let odometry_agreement = agreement(obs.odometry);
    // A try's axes and calibration are given only when its solution is kept.
    let directions_agreement =
        (directions.kept == OfflineKept::Solution).then(|| agreement(&directions.trajectory));
    let axes = directions
        .wall_axes_rad
        .filter(|_| directions_agreement.is_some_and(|a| a >= odometry_agreement + SONAR_MIN_GAIN));
    // The directions hold every heading of the run against the building's axes, silent
    // stretches included, so their turn scale and heading drift are the run's: the matched tries
    // start from the odometry they correct, and hold them. The matches alone give back about the
    // turn scale their predictions were made with, the odometry's where the sonar heard nothing
    // (docs/RESULTS.md, "The walls' turns").
    let turns = directions
        .odometry_calibration
        .filter(|_| directions.wall_axes_rad.is_some())
        .filter(graph::within_prior);
    let turned = turns.map(|c| c.apply(obs.odometry));
    let matched = Observations {
        odometry: turned.as_deref().unwrap_or(obs.odometry),
        ..*obs
    };
    // The two matched tries' first passes match the same ranges along the same odometry:
    // matched once.
    let first = matched.odometry.first().and_then(|first| {
        let visual = keyframes::turns_used(&matched, config);
        let frames = keyframes::choose(&matched, &visual, online, config, first.pose).frames;
        scan_match::sequential(
            &frames,
            matched.odometry,
            sonar.readings,
            sonar.layout,
            grid,
            config,
            &axes.map_or_else(Vec::new, |a| {
                wall_directions::heading_corrections(
                    &frames,
                    matched.odometry,
                    sonar.readings,
                    sonar.layout,
                    config,
                    a,
                )
            }),
        )
    });
    let passes = |hold| {
        let result = sonar_passes(
            &matched,
            online,
            config,
            SonarTry {
                sonar,
                grid,
                hold,
                first: first.as_ref(),
                axes,
                turns_held: turns.is_some(),
            },
        );
        match turns {
            Some(turns) => OfflineResult {
                odometry_calibration: result.odometry_calibration.map(|c| turns.then(&c)),
                sonar_turns_from_walls: true,
                ..result
            },
            None => result,
        }
    };
    let (estimated, wheels) = rayon::join(
        || passes(SonarHold::Matches),
        || passes(SonarHold::MatchesWheelDistance),
    );
    let score =
        |r: &OfflineResult| (r.kept == OfflineKept::Solution).then(|| agreement(&r.trajectory));
    let mut tries = vec![(score(&estimated), estimated), (score(&wheels), wheels)];
    tries.push((directions_agreement, directions));
    let best = taken(&tries.iter().map(|t| t.0).collect::<Vec<_>>());
    let sensor = crate::dataset::RangeSensor::from(sonar.layout.beam).name();
    let names = [
        "the distance scale estimated",
        "the wheels' distance taken as right",
        "the walls' directions alone (no matched place)",
    ];
    let scored: Vec<String> = tries
        .iter()
        .zip(names)
        .filter_map(|((s, _), name)| s.map(|s| format!("{name} {:.1}%", 100.0 * s)))
        .collect();
    if scored.len() > 1 {
        tracing::info!(
            "the {sensor}'s corrections tried, by how well its ranges agree with one another along them: {}; taken: {}",
            scored.join(", "),
            names[best]
        );
    }
    let (after, mut result) = tries.swap_remove(best);
    match result.sonar_matches {
        0 if result.sonar_wall_directions > 0 => tracing::info!(
            "no tag sightings and no visual turns: the headings of {} of {} keyframes held by the direction of a wall a sonar slid along",
            result.sonar_wall_directions,
            result.keyframes
        ),
        matches => tracing::info!(
            "no tag sightings and no visual turns: the {sensor}'s latest ranges matched its older readings at {matches} of {} keyframes{}{}",
            result.keyframes,
            match result.sonar_wall_directions {
                0 => String::new(),
                d => format!(", predicted along headings {d} walls' directions corrected"),
            },
            match (result.sonar_turns_from_walls, turns) {
                (true, Some(t)) => format!(
                    ", along the odometry's turns corrected by the walls' directions (turn scale {:+.2}%, heading drift {:+.2} mrad/m, held)",
                    100.0 * t.turn_scale_error,
                    1e3 * t.heading_drift_rad_per_m
                ),
                _ => String::new(),
            }
        ),
    }
    result.sonar_silent_start = scan_match::first_echo_s(sonar.readings, sonar.layout)
        .map(|t| SilentStart::of(obs.odometry, t, config));
    // Kept only when the run's ranges agree with one another clearly better along it than along
    // the odometry: matches off a biased grid can bend an already good odometry.
    if let Some(after) = after {
        let before = odometry_agreement;
        result.sonar_agreement = Some([before, after]);
        tracing::info!(
            "the {sensor}'s ranges agree with one another {:.1}% along the odometry, {:.1}% along the {sensor}'s correction",
            100.0 * before,
            100.0 * after
        );
        if after < before + SONAR_MIN_GAIN {
            let mut notes = vec![format!(
                "the {sensor}'s correction is not kept: its ranges agree with one another hardly better along it ({:.1}%) than along the odometry ({:.1}%)",
                100.0 * after,
                100.0 * before
            )];
            let odometry = solve(
                obs,
                online,
                config,
                (None, None),
                &[],
                (SonarUse::None, false),
            );
            notes.extend(odometry.notes.iter().cloned());
            return announced(OfflineResult {
                sonar_agreement: result.sonar_agreement,
                sonar_wheel_distance: result.sonar_wheel_distance,
                sonar_turns_from_walls: result.sonar_turns_from_walls,
                sonar_silent_start: result.sonar_silent_start,
                notes,
                ..odometry
            });
        }
    }
    if let Some(w) = result
        .sonar_silent_start
        .filter(|_| result.kept == OfflineKept::Solution)
        .and_then(|s| s.warning(sensor))
    {
        result.notes.push(w);
    }
    announced(result)
}

/// The sonar's own correction ([`run_offline_sonar`]): [`SONAR_PASSES`] passes, each from the
/// odometry corrected by the calibration the ones before found, the keyframes held as the try
/// says; the first pass takes the try's `first` matches when given.
fn sonar_passes(
    obs: &Observations<'_>,
    online: &OnlineResult,
    config: &FuseConfig,
    sonar_try: SonarTry<'_>,
) -> OfflineResult {
    let wheel_distance = sonar_try.hold != SonarHold::Matches;
    let pass = |obs: &Observations<'_>, first| {
        let sonar = SonarUse::ScanMatch(SonarTry { first, ..sonar_try });
        solve(obs, online, config, (None, None), &[], (sonar, false))
    };
    let mut result = OfflineResult {
        sonar_wheel_distance: wheel_distance,
        ..pass(obs, sonar_try.first)
    };
    // Each pass's calibration makes the next pass's predictions better, and so its matches.
    for _ in 1..SONAR_PASSES {
        let Some(total) = result.odometry_calibration else {
            break;
        };
        let odometry = total.apply(obs.odometry);
        let next = pass(
            &Observations {
                odometry: &odometry,
                ..*obs
            },
            None,
        );
        let Some(more) = next.odometry_calibration else {
            break;
        };
        result = OfflineResult {
            odometry_calibration: Some(total.then(&more)),
            sonar_wheel_distance: wheel_distance,
            ..next
        };
    }
    result
}

/// Which of the sonar's tries is taken, from the echoes' agreement along each (`None`: not
/// kept), in the order the distance scale estimated, the wheels' distance, the walls' directions
/// alone (absent for a lidar): the wheels' distance unless the estimated scale agrees clearly
/// better ([`SCALE_MIN_GAIN`]), then the directions alone if they agree better still.
fn taken(agreement: &[Option<f64>]) -> usize {
    let matched = match (agreement[0], agreement[1]) {
        (Some(estimated), Some(wheels)) if estimated < wheels + SCALE_MIN_GAIN => 1,
        (None, Some(_)) => 1,
        _ => 0,
    };
    match agreement.get(2).copied().flatten() {
        Some(alone) if agreement[matched].is_none_or(|a| alone > a) => 2,
        _ => matched,
    }
}

/// The sonar's correction with the distance scale estimated is taken over the one with the
/// wheels' distance only when its echoes agree with one another by this much more (a share):
/// the wheels' distance is the simpler account, and a point of agreement is within what one
/// run's echoes scatter by. Over forty simulated runs and freiburg-079 drifted three ways, the
/// three it changed all came out better (museum seed 14 0.332 -> 0.249 m, office seed 1 0.089 ->
/// 0.088 m, freiburg-079's drift 3 0.297 -> 0.283 m; docs/RESULTS.md).
const SCALE_MIN_GAIN: f64 = 0.01;

/// Passes of the sonar's own correction: each starts from the odometry corrected by the
/// calibration the passes before it found (in trials one pass left the simulated museum's
/// offline ATE at 0.37-0.85 of the odometry's; three give 0.08-0.27 on the office and museum,
/// seeds 1-5).
const SONAR_PASSES: usize = 3;
/// The sonar's correction is kept only when it raises the share of ranges that agree with the
/// others ([`scan_match::agreement`]) by this much: by 10-13 points on the simulated office and
/// museum (offline ATE a tenth to a quarter of the odometry's), by 0.8 on freiburg-079, whose
/// odometry is already within 4 cm and which the correction took to 39 cm.
const SONAR_MIN_GAIN: f64 = 0.03;

/// What the sonar gives the offline graph.
#[derive(Clone, Copy)]
enum SonarUse<'a> {
    /// Nothing.
    None,
    /// Range factors off its walls, held fixed ([`run_offline_walls`]).
    Walls(&'a crate::fusion::SonarInput<'a>),
    /// Keyframe poses matched with its own older readings and headings held by the walls'
    /// directions ([`run_offline_sonar`]), as the try says.
    ScanMatch(SonarTry<'a>),
}

/// One try of the sonar's own correction ([`run_offline_sonar`]).
#[derive(Clone, Copy)]
struct SonarTry<'a> {
    sonar: &'a crate::fusion::SonarInput<'a>,
    grid: &'a crate::sonar::grid::GridConfig,
    /// How the keyframes are held.
    hold: SonarHold,
    /// The first pass's matches, made before along the same odometry; made by the pass when
    /// `None`.
    first: Option<&'a scan_match::ScanMatches>,
    /// The building's axes the matches' predicted headings are corrected to, when found.
    axes: Option<f64>,
    /// The odometry was corrected by the walls' directions' turn scale and heading drift: the
    /// graph holds them ([`graph::CalibrationPrior::Wheels`]).
    turns_held: bool,
}

/// How the sonar's own correction ([`run_offline_sonar`]) holds the keyframes: three tries, of
/// which the one the echoes agree with best is taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SonarHold {
    /// Where the latest ranges matched the older readings ([`scan_match`]), the matches
    /// predicted along headings the walls' directions corrected when the directions' try found
    /// the building's axes ([`wall_directions`]); the wheels' distance scale estimated.
    Matches,
    /// The same with the wheels' distance scale held (the matches hold the robot across the
    /// walls far better than along them: the scale they found scattered from -2.9% to +2.6%
    /// about the simulated wheels' 0).
    MatchesWheelDistance,
    /// By the walls' directions alone, the wheels' distance held: tried first; its axes then
    /// correct the headings the matches are predicted along.
    Directions,
}

/// The offline pass again, with the walls holding the trajectory between tag sightings: started
/// from `solved` (a pass without walls over the same observations), every keyframe interval gets
/// a range factor per sensor off the face of `sonar.walls` in its beam (walls mapped from
/// `solved`'s trajectory, held fixed; tied to the keyframe before by the odometry, robust,
/// gated at 0.3 m), and the graph is solved again. Kept, as any offline solution, only when it
/// explains at least as many sightings as `solved` does.
pub fn run_offline_walls(
    obs: &Observations<'_>,
    online: &OnlineResult,
    solved: &OfflineResult,
    config: &FuseConfig,
    anchors: &[crate::fusion::Anchor],
    sonar: &crate::fusion::SonarInput<'_>,
) -> OfflineResult {
    let mut start = online.clone();
    start.pose_at_sighting = obs
        .sightings
        .iter()
        .zip(&online.pose_at_sighting)
        .map(|(s, &p)| crate::geometry::pose_at(&solved.trajectory, s.t_s).unwrap_or(p))
        .collect();
    start.trajectory = solved.trajectory.clone();
    start.landmarks = solved.landmarks.clone();
    let calibration = solved.odometry_calibration.as_ref();
    announced(solve(
        obs,
        &start,
        config,
        (None, calibration),
        anchors,
        (SonarUse::Walls(sonar), true),
    ))
}

/// The offline pass from `online`: the calibration's prior centred on `prior` (else on no
/// error) and started at `init` (else at the prior's centre); with the sonar, what it gives
/// ([`SonarUse`]). Its notes are not printed here ([`announced`]).
fn solve(
    obs: &Observations<'_>,
    online: &OnlineResult,
    config: &FuseConfig,
    (prior, init): (Option<&OdometryCalibration>, Option<&OdometryCalibration>),
    anchors: &[crate::fusion::Anchor],
    (sonar, measure_noise): (SonarUse<'_>, bool),
) -> OfflineResult {
    let Some(first) = obs.odometry.first() else {
        return OfflineResult {
            trajectory: Vec::new(),
            landmarks: online.landmarks.clone(),
            keyframes: 0,
            factors: 0,
            converged: false,
            kept: OfflineKept::Start,
            cost: [0.0; 2],
            sightings_consistent: [0; 2],
            sightings: 0,
            inconsistent: Vec::new(),
            odometry_chi2: [0.0; 2],
            odometry_factors: 0,
            wall_ranges: 0,
            sonar_matches: 0,
            sonar_wall_directions: 0,
            wall_axes_rad: None,
            sonar_agreement: None,
            sonar_wheel_distance: false,
            sonar_turns_from_walls: false,
            sonar_silent_start: None,
            odometry_calibration: None,
            mounting: None,
            noise: None,
            covariance: None,
            notes: vec!["the run has no odometry: nothing to solve".into()],
        };
    };
    let visual = keyframes::turns_used(obs, config);
    let keyframes = keyframes::choose(obs, &visual, online, config, first.pose);
    // The calibration known so far: the online pass's latest re-solve's, else an earlier
    // survey's.
    let known = online
        .resolves
        .last()
        .map(|r| r.odometry_calibration)
        .or(prior.copied());
    let calibrated_arcs = known.as_ref().is_some_and(graph::within_prior);
    let calibration_prior = match (prior, sonar) {
        (Some(c), _) => graph::CalibrationPrior::Survey(c),
        (None, SonarUse::ScanMatch(t)) => graph::CalibrationPrior::Wheels {
            hold_distance: t.hold != SonarHold::Matches,
            hold_turns: t.turns_held,
        },
        (None, _) => graph::CalibrationPrior::Wheels {
            hold_distance: false,
            hold_turns: false,
        },
    };
    let mut graph = graph::build(
        obs,
        &keyframes,
        &visual,
        online,
        config,
        (first.pose, calibration_prior, calibrated_arcs),
        anchors,
    );
    if let (Some(c), true) = (init, graph.init.contains_key(graph::CALIBRATION)) {
        graph.init.insert(
            graph::CALIBRATION.into(),
            graph::Vector::from_vec(vec![
                c.turn_scale_error,
                c.heading_drift_rad_per_m,
                c.distance_scale_error,
            ]),
        );
    }
    let wall_ranges = match sonar {
        SonarUse::Walls(w) => graph::add_wall_ranges(&mut graph, obs, &keyframes, w, config),
        _ => 0,
    };
    let mut headings_held = 0;
    let sonar_matches = match sonar {
        SonarUse::ScanMatch(t) if t.hold != SonarHold::Directions => {
            let made = t.first.is_none().then(|| {
                let headings = t.axes.map_or_else(Vec::new, |a| {
                    wall_directions::heading_corrections(
                        &keyframes.frames,
                        obs.odometry,
                        t.sonar.readings,
                        t.sonar.layout,
                        config,
                        a,
                    )
                });
                scan_match::sequential(
                    &keyframes.frames,
                    obs.odometry,
                    t.sonar.readings,
                    t.sonar.layout,
                    t.grid,
                    config,
                    &headings,
                )
            });
            t.first
                .or(made.as_ref().and_then(Option::as_ref))
                .map_or_else(Vec::new, |m| {
                    headings_held = m.headings_held;
                    graph::add_matched_poses(&mut graph, m, config)
                })
        }
        _ => Vec::new(),
    };
    let direction_factors = match sonar {
        SonarUse::ScanMatch(t) if t.hold == SonarHold::Directions => {
            let found = wall_directions::wall_directions(
                &keyframes.frames,
                obs.odometry,
                t.sonar.readings,
                t.sonar.layout,
                config,
            );
            graph::add_wall_directions(&mut graph, &found, &keyframes.frames, config)
        }
        _ => 0,
    };
    // The directions held the graph's headings, or the headings the matches were made along.
    let sonar_wall_directions = direction_factors.max(headings_held);
    let options = tiny_solver::OptimizerOptions {
        max_iteration: config.max_iterations,
        ..Default::default()
    };
    use tiny_solver::Optimizer;
    // Odometry alone corrects nothing: a solve would return its start and an odometry
    // calibration it cannot observe.
    let nothing = graph.sightings.is_empty()
        && visual.is_empty()
        && sonar_matches.is_empty()
        && direction_factors == 0;
    let mut notes = Vec::new();
    if nothing {
        notes.push(format!(
            "the offline pass has nothing to correct the odometry against (no tag sightings, no visual turns{}): it keeps the online estimate and estimates no odometry calibration",
            match sonar {
                SonarUse::ScanMatch(..) => ", no place where the ranges matched their own older readings",
                _ => "",
            }
        ));
    }
    let solution = (!nothing)
        .then(|| {
            tiny_solver::LevenbergMarquardtOptimizer::default().optimize(
                &graph.problem,
                &graph.init,
                Some(options),
            )
        })
        .flatten();
    // Never worse without saying so: the solution is kept when it explains at least as many
    // sightings as the start (the solver lowers the cost, but a wrong loop can lower it by
    // bending the trajectory away from the sightings it cannot explain); converged means the
    // solver stopped on its own, not at its iteration limit.
    let cost_of = |values: &std::collections::HashMap<String, graph::Vector>| {
        graph
            .problem
            .compute_cost(&graph.problem.initialize_parameter_blocks(values))
    };
    let start_cost = cost_of(&graph.init);
    let start = graph.sighting_check(&graph.init);
    let start_consistent = start.consistent;
    let (kept, values, end_cost, end, converged) = match solution {
        Some(values) => {
            let end_cost = cost_of(&values);
            let end = graph.sighting_check(&values);
            let end_consistent = end.consistent;
            if end_consistent >= start_consistent && end_cost.is_finite() {
                let once_more = tiny_solver::LevenbergMarquardtOptimizer::default().optimize(
                    &graph.problem,
                    &values,
                    Some(tiny_solver::OptimizerOptions {
                        max_iteration: 1,
                        ..Default::default()
                    }),
                );
                let settled = once_more
                    .map(|v| cost_of(&v))
                    .is_some_and(|c| (end_cost - c).abs() <= 1e-6 * end_cost.max(1e-12));
                (OfflineKept::Solution, values, end_cost, end, settled)
            } else {
                notes.push(format!(
                    "the offline pass keeps the online estimate: its solution explains {end_consistent} of {} sightings, the online estimate {start_consistent} (graph cost {start_cost:.1} -> {end_cost:.1})",
                    graph.sightings.len()
                ));
                // The start is returned: its sightings are the ones to report.
                let init = graph.init.clone();
                let end = SightingCheck {
                    consistent: end_consistent,
                    inconsistent: start.inconsistent.clone(),
                };
                (OfflineKept::Start, init, end_cost, end, false)
            }
        }
        None if nothing => {
            let init = graph.init.clone();
            (OfflineKept::Nothing, init, start_cost, start, false)
        }
        None => {
            notes.push("the offline solver failed (NaN cost): the online estimate is kept".into());
            let init = graph.init.clone();
            let end = SightingCheck {
                consistent: 0,
                inconsistent: start.inconsistent.clone(),
            };
            (OfflineKept::Start, init, f64::NAN, end, false)
        }
    };
    let solved: Vec<Pose2> = (0..keyframes.frames.len())
        .map(|i| {
            values
                .get(&graph::pose_name(i))
                .map_or(keyframes.frames[i].init, |v| {
                    Pose2::new(v[0], v[1], wrap_angle(v[2]))
                })
        })
        .collect();
    let landmarks = online
        .landmarks
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let mut l = l.clone();
            if let Some(v) = values.get(&graph::landmark_name(i)) {
                l.position_m[0] = v[0];
                l.position_m[1] = v[1];
                l.yaw_rad = wrap_angle(v[2]);
            }
            l
        })
        .collect();
    let mounting = values
        .get(graph::MOUNTING)
        .filter(|_| kept == OfflineKept::Solution)
        .map(|v| MountingEstimate {
            correction: Pose2::new(v[0], v[1], wrap_angle(v[2])),
            covariance: graph::marginal_covariance(&graph.problem, &values, graph::MOUNTING, 3)
                .map(|c| nalgebra::Matrix3::from_fn(|r, k| c[(r, k)])),
        });
    let noise = (measure_noise && kept == OfflineKept::Solution && !graph.sightings.is_empty())
        .then(|| noise::variance_components(&graph, &values))
        .flatten();
    let measured = |n: &noise::NoiseScales| {
        [
            n.odometry_translation,
            n.odometry_turning,
            n.odometry_drift,
            n.sightings,
            n.turns,
        ]
        .iter()
        .any(Option::is_some)
    };
    if noise.as_ref().is_some_and(|n| !measured(n)) {
        tracing::info!(
            "noise against the models not measured: the offline graph has too few redundant measurements"
        );
    }
    if let Some(n) = noise.as_ref().filter(|n| measured(n)) {
        let say = |v: Option<f64>| v.map_or("not measured".to_owned(), |v| format!("{v:.2}"));
        // Redundancy is never negative; a rounding's -0 (nothing measured) prints as 0.
        let r = |k: usize| n.redundancy[k].max(0.0) + 0.0;
        tracing::info!(
            "noise against the models, from the offline residuals (redundancy): odometry translation {} ({:.0}), turning {} ({:.0}), drift {} ({:.0}); sightings {} ({:.0}); visual turns {} ({:.0})",
            say(n.odometry_translation),
            r(0),
            say(n.odometry_turning),
            r(1),
            say(n.odometry_drift),
            r(2),
            say(n.sightings),
            r(3),
            say(n.turns),
            r(4)
        );
    }
    let covariance = match (&noise, sonar) {
        (Some(n), SonarUse::None) => {
            let times: Vec<f64> = keyframes.frames.iter().map(|k| k.t_s).collect();
            noise::SolutionCovariance::at(&graph, &values, n, &times)
        }
        _ => None,
    };
    OfflineResult {
        mounting,
        noise,
        covariance,
        notes,
        trajectory: interpolate::corrected(obs.odometry, &keyframes.frames, &solved),
        landmarks,
        keyframes: keyframes.frames.len(),
        factors: graph.factors,
        converged,
        kept,
        cost: [start_cost, end_cost],
        sightings_consistent: [start_consistent, end.consistent],
        sightings: graph.sightings.len(),
        inconsistent: end.inconsistent,
        odometry_chi2: [
            graph.odometry_chi2(&graph.init),
            graph.odometry_chi2(&values),
        ],
        odometry_factors: graph.odometry.len(),
        wall_ranges,
        sonar_matches: sonar_matches.len(),
        sonar_wall_directions,
        wall_axes_rad: values
            .get(graph::AXES)
            .filter(|_| kept == OfflineKept::Solution)
            .map(|v| v[0]),
        sonar_agreement: None,
        sonar_wheel_distance: false,
        sonar_turns_from_walls: false,
        sonar_silent_start: None,
        odometry_calibration: values
            .get(graph::CALIBRATION)
            .filter(|_| kept == OfflineKept::Solution && config.calibrate_odometry)
            .map(|v| OdometryCalibration {
                turn_scale_error: v[0],
                heading_drift_rad_per_m: v[1],
                distance_scale_error: v[2],
            }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::run_online;
    use crate::fusion::testing::obs;
    use crate::fusion::testing::{square_run, turns_of};
    use crate::metrics::ate_m;

    /// The calibration model matches the wheels: the office simulated with the default wheel
    /// errors and no random noise (wheel base 1% long: turns scaled by 1.01; wheels -0.1% and
    /// +0.1%: 2 x 0.001 / 0.3 m = 0.00667 rad of false turn per metre), corrected with those
    /// values, follows the truth.
    #[test]
    fn the_calibration_undoes_the_wheels_errors() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let world = crate::io::load_world(&root.join("samples/office/world.yaml"))
            .unwrap()
            .world;
        let mut config = crate::sim::SimConfig::default();
        config.odometry.random_m_per_sqrt_m = 0.0;
        config.exploration.duration_s = 300.0;
        let run = crate::sim::simulate(&world, &config, |_| {}).unwrap().run;
        let truth = run.ground_truth.as_deref().unwrap();
        let calibration = OdometryCalibration {
            turn_scale_error: config.odometry.wheel_base_error,
            heading_drift_rad_per_m: (config.odometry.left_scale_error
                - config.odometry.right_scale_error)
                / config.exploration.wheel_base_m,
            distance_scale_error: 0.0,
        };
        let raw = ate_m(&run.odometry, truth).unwrap();
        let corrected = ate_m(&calibration.apply(&run.odometry), truth).unwrap();
        assert!(raw > 0.1, "raw odometry ATE {raw}");
        assert!(corrected < 0.02, "corrected {corrected} (raw {raw})");
        // A calibration of nothing changes nothing.
        let none = OdometryCalibration {
            turn_scale_error: 0.0,
            heading_drift_rad_per_m: 0.0,
            distance_scale_error: 0.0,
        };
        assert!((ate_m(&none.apply(&run.odometry), truth).unwrap() - raw).abs() < 1e-9);
    }

    /// The cameras' turns keep the heading where no tag is seen: two laps of a square with 1%
    /// wheel errors and no sighting at all, online and offline.
    #[test]
    fn visual_turns_hold_the_heading_without_a_tag() {
        let (odom, truth, _, _) = square_run(0.01, 2);
        let turns = turns_of(&truth, 5, 0.001);
        let config = FuseConfig::default();
        let online = run_online(&obs(&odom, &[], &turns), &[], &config, None);
        let offline = run_offline(&obs(&odom, &[], &turns), &online, &config, None);
        let raw = ate_m(&odom, &truth).unwrap();
        let on = ate_m(&online.trajectory, &truth).unwrap();
        let off = ate_m(&offline.trajectory, &truth).unwrap();
        assert_eq!(online.visual_fused, turns.len());
        assert!(
            on < 0.2 * raw && off < 0.2 * raw,
            "odometry {raw}, online {on}, offline {off}"
        );
        // Without them (or with the setting off) the heading walks with the wheels.
        let off_config = FuseConfig {
            visual_odometry: false,
            ..config
        };
        let blind = run_online(&obs(&odom, &[], &turns), &[], &off_config, None);
        assert_eq!(blind.visual_fused, 0);
        assert!(ate_m(&blind.trajectory, &truth).unwrap() > 0.5 * raw);
    }

    #[test]
    fn online_and_offline_beat_odometry_on_a_biased_loop() {
        let (odom, truth, sightings, tags) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let online = run_online(&obs(&odom, &sightings, &[]), &[], &config, None);
        let offline = run_offline(&obs(&odom, &sightings, &[]), &online, &config, None);
        let ate_odom = ate_m(&odom, &truth).unwrap();
        let ate_online = ate_m(&online.trajectory, &truth).unwrap();
        let ate_offline = ate_m(&offline.trajectory, &truth).unwrap();
        assert!(offline.converged);
        assert_eq!(offline.kept, OfflineKept::Solution);
        assert!(offline.cost[1] < offline.cost[0], "{:?}", offline.cost);
        assert!(offline.sightings > 0);
        assert!(offline.sightings_consistent[1] >= offline.sightings_consistent[0]);
        assert!(ate_odom > 0.2, "odometry ATE {ate_odom}");
        assert!(
            ate_online < 0.5 * ate_odom,
            "online {ate_online} odometry {ate_odom}"
        );
        assert!(
            ate_offline < 0.2 * ate_odom,
            "offline {ate_offline} odometry {ate_odom}"
        );
        assert_eq!(online.landmarks.len(), tags.len());
        for l in &offline.landmarks {
            let t = tags[l.id as usize];
            let e = (l.position_m[0] - t[0]).hypot(l.position_m[1] - t[1]);
            assert!(e < 0.05, "tag {} error {e}", l.id);
        }
        assert!(
            online.conflicts.is_empty(),
            "{:?} rejected {}",
            online.conflicts,
            online.rejected.len()
        );
    }

    /// Walls hold the path between tags: a square driven twice with biased wheels inside four
    /// walls 1 m beyond its sides, a sonar looking right at them, and only two of the four
    /// corner tags seen; the pass with the walls' ranges ends nearer the truth than the pass
    /// without, and keeps every sighting consistent.
    #[test]
    fn walls_hold_the_path_between_tags() {
        use crate::fusion::testing::{face, ranges_off_faces};
        use crate::sonar::{BeamModel, SonarLayout, SonarSensor};
        let (_, truth, sightings, _) = square_run(0.02, 2);
        let sightings: Vec<_> = sightings.into_iter().filter(|s| s.id % 2 == 0).collect();
        // Wheels 2% long and a heading that wanders (about 0.01 rad per sqrt(m), which the
        // calibration cannot take out), from the true increments.
        let mut odom = vec![truth[0]];
        let mut state = 12345u64;
        for (k, w) in truth.windows(2).enumerate() {
            let step = w[0].pose.between(&w[1].pose);
            // Uniform in [-0.005, 0.005] rad a 0.1 m step (sigma 0.0029).
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let wobble = 0.01 * ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5);
            let step = Pose2::new(step.x * 1.02, step.y * 1.02, step.theta * 1.02 + wobble);
            let pose = odom[k].pose.compose(&step);
            odom.push(StampedPose {
                t_s: w[1].t_s,
                pose,
            });
        }
        let walls = [
            face(90.0, -0.5, [-0.5, -0.5], [5.5, -0.5]),
            face(180.0, -5.5, [5.5, -0.5], [5.5, 5.5]),
            face(270.0, -5.5, [5.5, 5.5], [-0.5, 5.5]),
            face(0.0, -0.5, [-0.5, 5.5], [-0.5, -0.5]),
        ];
        let layout = SonarLayout {
            name: "right".into(),
            beam: BeamModel::Cone,
            cone_rad: 30f64.to_radians(),
            max_range_m: 2.1,
            min_range_m: 0.0,
            sensors: vec![SonarSensor {
                x_m: 0.0,
                y_m: -0.2,
                bearing_rad: -std::f64::consts::FRAC_PI_2,
            }],
        };
        let readings = ranges_off_faces(&truth, &layout, &walls);
        let sonar = crate::fusion::SonarInput {
            readings: &readings,
            layout: &layout,
            walls: &walls,
            walls_covariance: None,
        };
        let config = FuseConfig::default();
        let o = obs(&odom, &sightings, &[]);
        let online = run_online(&o, &[], &config, None);
        let first = run_offline(&o, &online, &config, None);
        let held = run_offline_walls(&o, &online, &first, &config, &[], &sonar);
        let (before, after) = (
            ate_m(&first.trajectory, &truth).unwrap(),
            ate_m(&held.trajectory, &truth).unwrap(),
        );
        eprintln!(
            "{} wall ranges: ATE {before:.4} -> {after:.4} m (odometry {:.3})",
            held.wall_ranges,
            ate_m(&odom, &truth).unwrap()
        );
        assert!(held.wall_ranges > 50, "{}", held.wall_ranges);
        assert_eq!(held.kept, OfflineKept::Solution);
        assert_eq!(held.sightings_consistent[1], held.sightings);
        assert!(after < 0.7 * before, "ATE {before} -> {after}");
    }

    /// Stopped at its iteration limit the solver's solution is kept, but it is not converged.
    #[test]
    fn a_solver_stopped_at_its_limit_is_not_converged() {
        let (odom, _, sightings, _) = square_run(0.01, 2);
        let config = FuseConfig {
            max_iterations: 1,
            ..FuseConfig::default()
        };
        let online = run_online(&obs(&odom, &sightings, &[]), &[], &config, None);
        let offline = run_offline(&obs(&odom, &sightings, &[]), &online, &config, None);
        assert!(!offline.converged);
    }

    /// A solution that explains fewer sightings than where the solver started is not returned:
    /// an earlier survey's odometry calibration, wildly wrong (50% scale errors), bends the
    /// solution away from the sightings (21 of them consistent at the start, 2 after).
    #[test]
    fn the_start_is_kept_when_the_solution_explains_fewer_sightings() {
        let (odom, _, sightings, _) = square_run(0.01, 2);
        let config = FuseConfig::default();
        let online = run_online(&obs(&odom, &sightings, &[]), &[], &config, None);
        let wrong = OdometryCalibration {
            turn_scale_error: 0.5,
            heading_drift_rad_per_m: 0.2,
            distance_scale_error: 0.5,
        };
        let offline = run_offline(&obs(&odom, &sightings, &[]), &online, &config, Some(&wrong));
        assert_eq!(offline.kept, OfflineKept::Start);
        assert!(!offline.converged);
        assert_eq!(offline.trajectory.len(), online.trajectory.len());
    }

    /// The sonar's tries: the wheels' distance unless the estimated scale agrees a point better;
    /// the walls' directions alone when they agree better than the matched try taken.
    #[test]
    fn the_estimated_scale_is_taken_only_when_it_agrees_clearly_better() {
        assert_eq!(taken(&[Some(0.70), Some(0.69), Some(0.5)]), 0);
        assert_eq!(taken(&[Some(0.697), Some(0.696), Some(0.5)]), 1);
        assert_eq!(taken(&[Some(0.68), Some(0.69)]), 1);
        assert_eq!(taken(&[None, Some(0.69)]), 1);
        assert_eq!(taken(&[Some(0.60), None, None]), 0);
        // The directions alone against the matched try taken, not against the other one.
        assert_eq!(taken(&[Some(0.705), Some(0.70), Some(0.702)]), 2);
        assert_eq!(taken(&[Some(0.72), Some(0.70), Some(0.71)]), 0);
        assert_eq!(taken(&[None, None, Some(0.5)]), 2);
        assert_eq!(taken(&[None, None, None]), 0);
    }

    /// A silent start's travel, turn and heading sigma are the odometry's up to the first echo,
    /// and only one whose heading sigma passes a degree is warned about.
    #[test]
    fn a_silent_start_is_measured_up_to_the_first_echo() {
        let config = FuseConfig::default();
        // A full turn on the spot in 36 steps, then 2 m straight on in 20, a step a second.
        let mut odometry = Vec::new();
        let mut pose = Pose2::new(1.0, 2.0, 0.0);
        for k in 0..=56 {
            odometry.push(StampedPose {
                t_s: 10.0 + k as f64,
                pose,
            });
            let step = if k < 36 {
                Pose2::new(0.0, 0.0, std::f64::consts::TAU / 36.0)
            } else {
                Pose2::new(0.1, 0.0, 0.0)
            };
            pose = pose.compose(&step);
        }
        let silent = SilentStart::of(&odometry, 10.0 + 46.0, &config);
        assert!((silent.duration_s - 46.0).abs() < 1e-9);
        assert!((silent.path_m - 1.0).abs() < 1e-9, "{silent:?}");
        assert!((silent.turn_rad - std::f64::consts::TAU).abs() < 1e-9);
        let expected = (config.heading_sigma_per_sqrt_rad.powi(2) * std::f64::consts::TAU
            + config.heading_sigma_per_sqrt_m.powi(2) * 1.0
            + 1e-12)
            .sqrt();
        assert!((silent.heading_sigma_rad - expected).abs() < 1e-12);
        let warning = silent
            .warning("sonar")
            .expect("4.3 degrees is warned about");
        assert!(
            warning.contains("heard nothing for the first 46 s"),
            "{warning}"
        );
        assert!(warning.contains("360 degrees of turning"), "{warning}");
        // Two steps straight on before the first echo: a heading sigma of 0.26 degrees.
        let short = SilentStart::of(&odometry[36..], 10.0 + 38.0, &config);
        assert!((short.path_m - 0.2).abs() < 1e-9 && short.turn_rad == 0.0);
        assert!(short.warning("sonar").is_none());
        // An echo before the odometry begins.
        let none = SilentStart::of(&odometry, 5.0, &config);
        assert_eq!(
            (none.duration_s, none.path_m, none.turn_rad),
            (0.0, 0.0, 0.0)
        );
        assert!(none.warning("sonar").is_none());
    }

    /// Where nothing else measures a turn and the tags observe a calibration that its prior does
    /// not hold back, the graph weighs a turn along an arc with the calibrated turn noise and a
    /// pivot with the uncalibrated one;
    /// where a visual turn spans the interval, or nothing observes the calibration (no tag, no
    /// visual turn), every turn keeps the uncalibrated noise.
    #[test]
    fn a_pivot_keeps_the_uncalibrated_turn_noise() {
        use crate::visual::sightings::TagSighting;
        use crate::visual::vo::VisualTurn;
        // Straight sides whose wheels turn 0.001 rad every 0.1 m (an arc 100 m across), and
        // corners turned on the spot.
        let (odom, truth, sightings, _) = square_run(0.01, 1);
        let config = FuseConfig::default();
        let noise = |sightings: &[TagSighting], turns: &[VisualTurn]| {
            let obs = obs(&odom, sightings, turns);
            let online = run_online(&obs, &[], &config, None);
            let visual = keyframes::turns_used(&obs, &config);
            let frames = keyframes::choose(&obs, &visual, &online, &config, odom[0].pose);
            let wheels = graph::CalibrationPrior::Wheels {
                hold_distance: false,
                hold_turns: false,
            };
            let start = (odom[0].pose, wheels, true);
            let graph = graph::build(&obs, &frames, &visual, &online, &config, start, &[]);
            // Each interval's path, turn and heading sigma.
            graph
                .odometry
                .iter()
                .map(|(_, f)| (f.path_m, f.turn_rad.abs(), 1.0 / f.sqrt_info[2][2]))
                .collect::<Vec<_>>()
        };
        let sigma = |path: f64, turn: f64, per_sqrt_rad: f64| {
            (per_sqrt_rad.powi(2) * turn + config.heading_sigma_per_sqrt_m.powi(2) * path + 1e-12)
                .sqrt()
        };
        let (uncalibrated, calibrated) = (
            config.heading_sigma_per_sqrt_rad,
            config.calibrated_heading_sigma_per_sqrt_rad,
        );
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b;
        let with_tags = noise(&sightings, &[]);
        let pivots: Vec<_> = with_tags
            .iter()
            .filter(|f| f.0 < 1e-9 && f.1 > 0.1)
            .collect();
        let arcs: Vec<_> = with_tags
            .iter()
            .filter(|f| f.0 > 0.1 && f.1 < 0.05)
            .collect();
        assert!(pivots.len() >= 4 && arcs.len() >= 10, "{with_tags:?}");
        for &&(path, turn, s) in &pivots {
            assert!(
                close(s, sigma(path, turn, uncalibrated)),
                "pivot {turn} rad: {s}"
            );
        }
        for &&(path, turn, s) in &arcs {
            assert!(close(s, sigma(path, turn, calibrated)), "arc {path} m: {s}");
        }
        // Wheels 12% off are more than the calibration's prior lets it correct: their arcs keep
        // the uncalibrated noise (`solve` builds their graph without `calibrated_arcs`).
        let far_off = OdometryCalibration {
            turn_scale_error: -0.26,
            heading_drift_rad_per_m: -0.12,
            distance_scale_error: -0.11,
        };
        assert!(!graph::within_prior(&far_off));
        assert!(graph::within_prior(&OdometryCalibration {
            turn_scale_error: 0.01,
            heading_drift_rad_per_m: -0.0067,
            distance_scale_error: 0.0,
        }));
        // Visual turns over the whole run, or nothing that observes the calibration.
        let turns = turns_of(&truth, 1, 0.001);
        for (what, intervals) in [
            ("turns", noise(&sightings, &turns)),
            ("none", noise(&[], &[])),
        ] {
            for &(path, turn, s) in &intervals {
                assert!(
                    close(s, sigma(path, turn, uncalibrated)),
                    "{what}: {path} m, {turn} rad"
                );
            }
        }
    }

    /// The noise the offline residuals tell is the odometry's own: eight laps of the square with
    /// random odometry noise at half the model's sigmas, then at one and a half times, each of
    /// its three parts measured within a third (0.42-0.62 and 1.38-1.78 when written; without
    /// the Gauss-Newton step under the new weights the translation at 1.5 came out 1.02).
    #[test]
    fn the_residuals_tell_how_noisy_the_odometry_was() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let config = FuseConfig::default();
        let (clean, truth, sightings, _) = square_run(0.0, 8);
        for factor in [0.5, 1.5] {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
            let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
            let mut odom = vec![clean[0]];
            for w in clean.windows(2) {
                let d = w[0].pose.between(&w[1].pose);
                let (path, turn) = (d.x.hypot(d.y), d.theta.abs());
                let t = factor * config.odometry_sigma_m_per_sqrt_m * path.sqrt();
                let h = factor
                    * (config.heading_sigma_per_sqrt_rad.powi(2) * turn
                        + config.heading_sigma_per_sqrt_m.powi(2) * path)
                        .sqrt();
                let noisy = Pose2::new(
                    d.x + t * normal(),
                    d.y + t * normal(),
                    d.theta + h * normal(),
                );
                let last = odom.last().unwrap().pose;
                odom.push(StampedPose {
                    t_s: w[1].t_s,
                    pose: last.compose(&noisy),
                });
            }
            // The tags seen with 5 mm and 0.01 rad of noise (an exact sighting would leave the
            // odometry's residuals to be told apart from nothing).
            let seen: Vec<_> = sightings
                .iter()
                .map(|s| {
                    let mut s = s.clone();
                    s.position_in_robot_m[0] += 0.005 * normal();
                    s.position_in_robot_m[1] += 0.005 * normal();
                    s.yaw_in_robot_rad += 0.01 * normal();
                    s
                })
                .collect();
            let o = obs(&odom, &seen, &[]);
            let online = run_online(&o, &[], &config, None);
            let offline = run_offline(&o, &online, &config, None);
            let noise = offline.noise.expect("measured");
            let measured = [
                noise.odometry_translation,
                noise.odometry_turning,
                noise.odometry_drift,
            ];
            for (name, m) in ["translation", "turning", "drift"].iter().zip(measured) {
                let m = m.unwrap_or_else(|| panic!("{name}: too little redundancy {noise:?}"));
                assert!(
                    (m / factor - 1.0).abs() < 1.0 / 3.0,
                    "{name}: {m} for {factor} ({noise:?}); ATE {}",
                    ate_m(&offline.trajectory, &truth).unwrap()
                );
            }
        }
    }
}
