//! The offline pose graph: a variable per keyframe pose and per landmark (and the odometry
//! calibration), and its factors, added in a fixed order so that the solution is reproducible:
//! the calibration's prior, the first pose's, the odometry between keyframes, the tag
//! sightings, the visual turns, the corner priors.

use super::factors::{
    sqrt_information, BetweenFactor, PoseFactor, PriorFactor, TagFactor, TurnFactor,
    WallDirectionFactor, WallRangeFactor,
};
use super::keyframes::Keyframes;
use super::OdometryCalibration;
use crate::fusion::measurement::{
    calibrated_odometry_covariance, odometry_covariance, sighting_measurement, PIVOT_RADIUS_M,
};
use crate::fusion::{Anchor, FuseConfig, Observations, OnlineResult};
use crate::geometry::{wrap_angle, Pose2};
use crate::visual::tags::TagId;
use crate::visual::vo::VisualTurn;
use std::collections::{BTreeMap, HashMap};
use tiny_solver::na as sna;

/// A variable's value, as the solver holds it.
pub(super) type Vector = sna::DVector<f64>;

/// Name of the odometry calibration variable.
pub(super) const CALIBRATION: &str = "odometry_calibration";
/// Prior sigmas of the odometry calibration `[a, c, s]`: 5% turn scale, 0.02 rad/m heading drift,
/// 2% distance scale (weak: wheel errors of a few percent at most).
pub(super) const CALIBRATION_PRIOR_SIGMA: [f64; 3] = [0.05, 0.02, 0.02];
/// Prior sigmas of the odometry calibration when an earlier survey of the same robot gives it:
/// about what one survey's estimate scatters by (turn scale 0.0066-0.0106 for 0.0100 over the
/// office's and museum's sample runs, heading drift -0.0059 to -0.0082 for -0.0067 rad/m).
const CALIBRATION_FROM_SURVEY_SIGMA: [f64; 3] = [0.004, 0.002, 0.004];

/// Prior sigma of the distance scale's error when the wheels' own distance is taken as right
/// ([`CalibrationPrior::Wheels`]): 0.01%, the scale held.
const WHEEL_DISTANCE_SIGMA: f64 = 1e-4;
/// Prior sigmas of the turn scale's error and the heading drift when the odometry was already
/// corrected by the walls' directions' turn scale and drift ([`CalibrationPrior::Wheels`]): 0.1% and
/// 0.4 mrad/m, a quarter and a fifth of what one survey's estimate scatters by. The directions hold
/// every heading of a sonar-only run against the building's axes, silent stretches included; the
/// matches, predicted along the odometry where the sonar heard nothing, give back about the turn
/// scale they were predicted with (0.002-0.006 for the simulated wheels' 0.010 on the museum, seeds
/// 1-5, against 0.0075-0.0112 from the directions; docs/RESULTS.md, "The walls' turns").
const TURNS_HELD_SIGMA: [f64; 2] = [0.001, 0.0004];

/// What the odometry calibration's prior says before the graph is solved.
#[derive(Debug, Clone, Copy)]
pub(super) enum CalibrationPrior<'a> {
    /// No error, within a few percent ([`CALIBRATION_PRIOR_SIGMA`]), with parts of it held at
    /// no error: the distance scale when the wheels' distance is taken as right
    /// (`hold_distance`, [`WHEEL_DISTANCE_SIGMA`]), the turn scale and heading drift when the
    /// odometry was corrected by the walls' directions' (`hold_turns`, [`TURNS_HELD_SIGMA`]).
    Wheels {
        /// The distance scale held.
        hold_distance: bool,
        /// The turn scale and heading drift held.
        hold_turns: bool,
    },
    /// An earlier survey's calibration, within what one survey's estimate scatters by
    /// ([`CALIBRATION_FROM_SURVEY_SIGMA`]).
    Survey(&'a OdometryCalibration),
}

/// Whether the wheels' errors `c` lie within two sigmas of [`CALIBRATION_PRIOR_SIGMA`]: the prior
/// does not hold such a calibration back, so the odometry it corrects keeps no systematic error
/// beyond what the calibrated turn noise covers (wheels off by more, 12% say, are corrected only
/// in part, and their arcs keep the uncalibrated noise).
pub(super) fn within_prior(c: &OdometryCalibration) -> bool {
    let found = [
        c.turn_scale_error,
        c.heading_drift_rad_per_m,
        c.distance_scale_error,
    ];
    found
        .iter()
        .zip(CALIBRATION_PRIOR_SIGMA)
        .all(|(v, sigma)| v.abs() <= 2.0 * sigma)
}
/// Inverse sigma of the prior that anchors the first pose where the odometry starts (1 mm,
/// 1 mrad: the survey's frame is its start).
const START_SQRT_INFO: f64 = 1e3;
/// ... and when anchors are given (1 m, 1 rad: the anchors fix the frame; this only keeps the
/// start near where their first fit put it).
const START_SQRT_INFO_ANCHORED: f64 = 1.0;

/// Name of the camera mounting error variable (`config.estimate_mounting`).
pub(super) const MOUNTING: &str = "mounting";
/// Prior sigmas of the mounting error `[x, y, yaw]`: 0.3 m, 0.3 m, 0.3 rad (weak: a tape
/// measure does better; the prior only keeps an unobserved direction from wandering).
pub(super) const MOUNTING_PRIOR_SIGMA: [f64; 3] = [0.3, 0.3, 0.3];

/// Name of keyframe `i`'s pose variable.
pub(super) fn pose_name(i: usize) -> String {
    format!("p{i}")
}

/// Name of landmark `i`'s variable.
pub(super) fn landmark_name(i: usize) -> String {
    format!("l{i}")
}

/// A problem ready for the solver: its factors, its variables' starting values, and how many
/// factors it holds.
pub(super) struct Graph {
    pub(super) problem: tiny_solver::Problem,
    pub(super) init: HashMap<String, sna::DVector<f64>>,
    pub(super) factors: usize,
    /// The sighting factors again, with their variables, to judge a solution by
    /// ([`Graph::sightings_consistent`]).
    pub(super) sightings: Vec<(Vec<String>, TagFactor)>,
    /// Which sighting (its index in the observations) each of `sightings` is.
    pub(super) sighting_index: Vec<usize>,
    /// The odometry factors again, with their variables ([`Graph::odometry_chi2`]).
    pub(super) odometry: Vec<(Vec<String>, BetweenFactor)>,
    /// The residual row of each measurement, and the noise model it is weighed with
    /// ([`super::noise`]).
    pub(super) measured_rows: Vec<(usize, Noise)>,
}

/// The noise models a graph's measurements are weighed with, whose scale the run itself can
/// tell ([`super::noise::variance_components`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Noise {
    /// The odometry's translation between keyframes.
    OdometryTranslation,
    /// The odometry's heading change between keyframes, where its modelled noise is mostly
    /// the turn's (per radian turned).
    OdometryTurning,
    /// ... where it is mostly the travel's (per metre travelled).
    OdometryDrift,
    /// The tag sightings.
    Sighting,
    /// The visual turns.
    Turn,
}

/// A sighting is consistent with a solution when its whitened residual's squared norm is below
/// this: 11.34, the chi-square 99% point with 3 degrees of freedom.
pub(super) const SIGHTING_CHI2_99: f64 = 11.34;

/// How a graph's sightings agree with a solution ([`Graph::sighting_check`]).
pub(super) struct SightingCheck {
    /// Sightings consistent with it.
    pub(super) consistent: usize,
    /// The others (their indices in the observations).
    pub(super) inconsistent: Vec<usize>,
}

impl Graph {
    /// How the sightings agree with `values` ([`SIGHTING_CHI2_99`]): how many are consistent,
    /// and which (their indices in the observations) are not.
    pub(super) fn sighting_check(
        &self,
        values: &HashMap<String, sna::DVector<f64>>,
    ) -> SightingCheck {
        let mut check = SightingCheck {
            consistent: 0,
            inconsistent: Vec::new(),
        };
        for (d2, &k) in squared_norms(&self.sightings, values).zip(&self.sighting_index) {
            match d2 {
                Some(d2) if d2 <= SIGHTING_CHI2_99 => check.consistent += 1,
                Some(_) => check.inconsistent.push(k),
                None => {}
            }
        }
        check
    }

    /// The odometry factors' summed squared whitened residuals under `values` (chi-square with
    /// three degrees of freedom a factor when the odometry's noise is as modelled).
    pub(super) fn odometry_chi2(&self, values: &HashMap<String, sna::DVector<f64>>) -> f64 {
        squared_norms(&self.odometry, values).flatten().sum()
    }
}

/// Each factor's squared whitened residual under `values`, in the factors' order (`None` where
/// a variable is missing).
fn squared_norms<'a, F: tiny_solver::factors::Factor<f64>>(
    factors: &'a [(Vec<String>, F)],
    values: &'a HashMap<String, sna::DVector<f64>>,
) -> impl Iterator<Item = Option<f64>> + 'a {
    factors.iter().map(|(variables, factor)| {
        let params = variables
            .iter()
            .map(|v| values.get(v).cloned())
            .collect::<Option<Vec<_>>>()?;
        Some(factor.residual_func(&params).norm_squared())
    })
}

impl Graph {
    fn add(
        &mut self,
        dim: usize,
        variables: &[&str],
        factor: Box<dyn tiny_solver::factors::FactorImpl + Send>,
        robust: bool,
        config: &FuseConfig,
    ) {
        let loss = robust.then(|| {
            Box::new(tiny_solver::loss_functions::HuberLoss::new(
                config.huber_sigma.max(1e-3),
            )) as Box<dyn tiny_solver::loss_functions::Loss + Send>
        });
        self.problem
            .add_residual_block(dim, variables, factor, loss);
        self.factors += 1;
    }

    /// [`Graph::add`] for a measurement whose rows are weighed with the `noise` models (one a
    /// row), its rows noted.
    fn add_measured(
        &mut self,
        noise: &[Noise],
        variables: &[&str],
        factor: Box<dyn tiny_solver::factors::FactorImpl + Send>,
        robust: bool,
        config: &FuseConfig,
    ) {
        let first = self.problem.total_residual_dimension;
        self.add(noise.len(), variables, factor, robust, config);
        self.measured_rows
            .extend(noise.iter().enumerate().map(|(i, &n)| (first + i, n)));
    }
}

/// The graph of a run over its keyframes, started from `online`, anchored at the odometry's
/// first pose, with the odometry calibration's prior `prior`. With `calibrated_arcs` (a calibration is known and
/// [`within_prior`]), turns along arcs that no visual turn measures are weighed with the
/// calibrated turn noise ([`add_odometry`]).
pub(super) fn build(
    obs: &Observations<'_>,
    keyframes: &Keyframes,
    visual: &[&VisualTurn],
    online: &OnlineResult,
    config: &FuseConfig,
    (first, prior, calibrated_arcs): (Pose2, CalibrationPrior<'_>, bool),
    anchors: &[Anchor],
) -> Graph {
    let mut graph = Graph {
        problem: tiny_solver::Problem::new(),
        init: HashMap::new(),
        factors: 0,
        sightings: Vec::new(),
        sighting_index: Vec::new(),
        odometry: Vec::new(),
        measured_rows: Vec::new(),
    };
    for (i, kf) in keyframes.frames.iter().enumerate() {
        graph.init.insert(
            pose_name(i),
            sna::DVector::from_vec(vec![kf.init.x, kf.init.y, kf.init.theta]),
        );
    }
    for (i, l) in online.landmarks.iter().enumerate() {
        graph.init.insert(
            landmark_name(i),
            sna::DVector::from_vec(vec![l.position_m[0], l.position_m[1], l.yaw_rad]),
        );
    }
    if config.calibrate_odometry {
        add_calibration_prior(&mut graph, prior, config);
    }
    let anchored = add_anchor_priors(&mut graph, online, anchors, config);
    let start = PriorFactor {
        measured: vec![first.x, first.y, first.theta],
        sqrt_info: vec![
            if anchored {
                START_SQRT_INFO_ANCHORED
            } else {
                START_SQRT_INFO
            };
            3
        ],
    };
    graph.add(3, &[&pose_name(0)], Box::new(start), false, config);
    add_odometry(
        &mut graph,
        obs,
        keyframes,
        (visual, calibrated_arcs),
        config,
    );
    if config.estimate_mounting && !keyframes.of_sighting.is_empty() {
        graph
            .init
            .insert(MOUNTING.to_owned(), sna::DVector::zeros(3));
        let prior = PriorFactor {
            measured: vec![0.0; 3],
            sqrt_info: MOUNTING_PRIOR_SIGMA.iter().map(|s| 1.0 / s).collect(),
        };
        graph.add(3, &[MOUNTING], Box::new(prior), false, config);
    }
    add_sightings(&mut graph, obs, keyframes, online, config);
    add_turns(&mut graph, keyframes, visual, config);
    if config.corner_factors {
        add_corner_priors(&mut graph, online, config);
    }
    graph
}

/// A range is put in the graph only when the starting values place it this close to the range
/// expected off the face in its beam, metres: 0.3 m (a wall pass starts from a solved survey;
/// further off, the face is likelier the wrong one).
pub(super) const WALL_RANGE_GATE_M: f64 = 0.3;
/// At most this many of a layout's sensors give ranges to the graph, evenly spread (a laser's
/// hundreds of beams add little over a few dozen and cost much).
const WALL_RANGE_SENSORS: usize = 32;

/// Range factors off the walls of `sonar` (held fixed): per keyframe interval and sensor, the
/// first reading that the starting values place against a face in its beam within
/// [`WALL_RANGE_GATE_M`] of its expected range, tied to the keyframe before it by the odometry
/// between them; robust (Huber), each with the sonar's sigma and the wall's. Returns how many.
pub(super) fn add_wall_ranges(
    graph: &mut Graph,
    obs: &Observations<'_>,
    keyframes: &Keyframes,
    sonar: &crate::fusion::SonarInput<'_>,
    config: &FuseConfig,
) -> usize {
    let frames = &keyframes.frames;
    // The odometry corrected with the calibration the starting values hold (a turn in place of
    // a few percent off swings a sensor off the robot's centre by centimetres).
    let calibration = graph.init.get(CALIBRATION).map(|c| OdometryCalibration {
        turn_scale_error: c[0],
        heading_drift_rad_per_m: c[1],
        distance_scale_error: c[2],
    });
    let odometry = calibration.map_or_else(|| obs.odometry.to_vec(), |c| c.apply(obs.odometry));
    let sensors = sonar.layout.sensors.len();
    let every = sensors.div_ceil(WALL_RANGE_SENSORS).max(1);
    let mut used = std::collections::HashSet::new();
    let mut added = 0;
    for reading in sonar.readings {
        if reading.sensor % every != 0 {
            continue;
        }
        let j = frames.partition_point(|kf| kf.t_s <= reading.t_s);
        let (Some(j), Some(sensor)) = (j.checked_sub(1), sonar.layout.sensors.get(reading.sensor))
        else {
            continue;
        };
        if used.contains(&(j, reading.sensor)) {
            continue;
        }
        let (Some(from), Some(to), Some(start)) = (
            crate::geometry::pose_at(&odometry, frames[j].t_s),
            crate::geometry::pose_at(&odometry, reading.t_s),
            graph.init.get(&pose_name(j)),
        ) else {
            continue;
        };
        let delta = from.between(&to);
        let at = Pose2::new(start[0], start[1], start[2]).compose(&delta);
        let Some(m) = crate::fusion::wall_in_beam(sonar, reading, at) else {
            continue;
        };
        if (m.range_m - m.expected_m).abs() > WALL_RANGE_GATE_M {
            continue;
        }
        let wall = &sonar.walls[m.wall];
        let sigma = ((config.sonar_sigma_m + config.sonar_sigma_frac * m.range_m).powi(2)
            + config.wall_sigma_m.powi(2))
        .sqrt();
        let factor = WallRangeFactor {
            delta: [delta.x, delta.y, delta.theta],
            sensor: [sensor.x_m, sensor.y_m, sensor.bearing_rad],
            normal_rad: wall.normal_rad,
            offset_m: wall.offset_m,
            ray: sonar.layout.beam == crate::sonar::BeamModel::Ray,
            measured: m.range_m,
            sqrt_info: 1.0 / sigma,
        };
        graph.add(1, &[&pose_name(j)], Box::new(factor), true, config);
        used.insert((j, reading.sensor));
        added += 1;
    }
    added
}

/// The sonar's matched keyframes ([`super::scan_match`]): every keyframe started at the pose the
/// matching gave it, and a robust prior on each matched one at its match, with the match's
/// covariance. Returns the matched keyframes.
pub(super) fn add_matched_poses(
    graph: &mut Graph,
    matches: &super::scan_match::ScanMatches,
    config: &FuseConfig,
) -> Vec<usize> {
    for (i, p) in matches.poses.iter().enumerate() {
        graph.init.insert(
            pose_name(i),
            sna::DVector::from_vec(vec![p.x, p.y, p.theta]),
        );
    }
    for &(k, p, covariance) in &matches.matched {
        let factor = PoseFactor {
            measured: [p.x, p.y, p.theta],
            sqrt_info: sqrt_information(&covariance),
        };
        graph.add(3, &[&pose_name(k)], Box::new(factor), true, config);
    }
    matches.matched.iter().map(|m| m.0).collect()
}

/// Name of the building's wall direction variable ([`add_wall_directions`]).
pub(super) const AXES: &str = "wall_axes";
/// The walls' directions ([`super::wall_directions`]) as factors on their keyframes' headings,
/// against one variable for the building's wall direction ([`AXES`]), robust; only when most lie
/// along two directions at right angles, and then only those that do
/// ([`super::wall_directions::along_axes`]). Returns how many were added.
pub(super) fn add_wall_directions(
    graph: &mut Graph,
    directions: &[super::wall_directions::WallDirection],
    frames: &[super::keyframes::Keyframe],
    config: &FuseConfig,
) -> usize {
    let seen = super::wall_directions::by_odometry(directions, frames);
    let Some(axes) = super::wall_directions::along_axes(&seen) else {
        return 0;
    };
    graph
        .init
        .insert(AXES.into(), sna::DVector::from_vec(vec![axes.axes_rad]));
    let mut added = 0;
    for (d, _) in directions.iter().zip(&axes.along).filter(|(_, &a)| a) {
        let factor = WallDirectionFactor {
            normal_rad: d.normal_rad,
            sqrt_info: 1.0 / (axes.sigma_scale * d.sigma_rad),
        };
        graph.add(
            1,
            &[&pose_name(d.keyframe), AXES],
            Box::new(factor),
            true,
            config,
        );
        added += 1;
    }
    added
}

/// The odometry calibration's variable and its prior.
fn add_calibration_prior(graph: &mut Graph, prior: CalibrationPrior<'_>, config: &FuseConfig) {
    let (mean, sigma) = match prior {
        CalibrationPrior::Survey(c) => (
            vec![
                c.turn_scale_error,
                c.heading_drift_rad_per_m,
                c.distance_scale_error,
            ],
            CALIBRATION_FROM_SURVEY_SIGMA,
        ),
        CalibrationPrior::Wheels {
            hold_distance,
            hold_turns,
        } => {
            let [turn, drift, scale] = CALIBRATION_PRIOR_SIGMA;
            let [turn, drift] = if hold_turns {
                TURNS_HELD_SIGMA
            } else {
                [turn, drift]
            };
            let scale = if hold_distance {
                WHEEL_DISTANCE_SIGMA
            } else {
                scale
            };
            (vec![0.0; 3], [turn, drift, scale])
        }
    };
    graph
        .init
        .insert(CALIBRATION.into(), sna::DVector::from_vec(mean.clone()));
    let factor = PriorFactor {
        measured: mean,
        sqrt_info: sigma.iter().map(|s| 1.0 / s).collect(),
    };
    graph.add(3, &[CALIBRATION], Box::new(factor), false, config);
}

/// Odometry between consecutive keyframes; path and turn summed over the samples between them.
/// With `calibrated_arcs`, where no visual turn spans an interval and the graph estimates the
/// calibration from tags or visual turns, its turn noise along arcs is the calibrated odometry's
/// ([`calibrated_odometry_covariance`]).
fn add_odometry(
    graph: &mut Graph,
    obs: &Observations<'_>,
    keyframes: &Keyframes,
    (visual, calibrated_arcs): (&[&VisualTurn], bool),
    config: &FuseConfig,
) {
    let (odometry, frames) = (obs.odometry, &keyframes.frames);
    let calibrated = calibrated_arcs
        && config.calibrate_odometry
        && !(keyframes.of_sighting.is_empty() && visual.is_empty());
    // Intervals (by their end keyframe) that a visual turn spans.
    let mut seen_turning = vec![false; frames.len()];
    for v in visual {
        if let (Some(&a), Some(&b)) = (
            keyframes.at_time.get(&v.from_t_s.to_bits()),
            keyframes.at_time.get(&v.to_t_s.to_bits()),
        ) {
            if a < b {
                seen_turning[a + 1..=b].fill(true);
            }
        }
    }
    let mut sample = 0;
    for i in 1..frames.len() {
        let (a, b) = (&frames[i - 1], &frames[i]);
        let mut path = 0.0;
        let mut turn = 0.0;
        let mut pivot = 0.0;
        let mut signed_turn = 0.0;
        let mut prev = a.odom;
        while sample < odometry.len() && odometry[sample].t_s <= a.t_s {
            sample += 1;
        }
        let mut j = sample;
        let mut step = |d: Pose2| {
            let (ds, dth) = (d.x.hypot(d.y), wrap_angle(d.theta));
            path += ds;
            turn += dth.abs();
            signed_turn += dth;
            if ds < PIVOT_RADIUS_M * dth.abs() {
                pivot += dth.abs();
            }
        };
        while j < odometry.len() && odometry[j].t_s < b.t_s {
            step(prev.between(&odometry[j].pose));
            prev = odometry[j].pose;
            j += 1;
        }
        step(prev.between(&b.odom));
        let delta = a.odom.between(&b.odom);
        let cov = if calibrated && !seen_turning[i] {
            calibrated_odometry_covariance(path, turn, pivot, config)
        } else {
            odometry_covariance(path, turn, config)
        };
        let (p0, p1) = (pose_name(i - 1), pose_name(i));
        let mut vars: Vec<&str> = vec![&p0, &p1];
        if config.calibrate_odometry {
            vars.push(CALIBRATION);
        }
        let factor = BetweenFactor {
            measured: [delta.x, delta.y, wrap_angle(delta.theta)],
            sqrt_info: sqrt_information(&cov),
            turn_rad: signed_turn,
            path_m: path,
        };
        graph
            .odometry
            .push((vars.iter().map(|v| v.to_string()).collect(), factor.clone()));
        // The covariance is diagonal: the whitened rows are the translation's and the heading's,
        // the heading's weighed mostly by the turn's noise or by the travel's.
        let drift = config.heading_sigma_per_sqrt_m.powi(2) * path;
        let noise = [
            Noise::OdometryTranslation,
            Noise::OdometryTranslation,
            if 2.0 * drift >= cov[(2, 2)] {
                Noise::OdometryDrift
            } else {
                Noise::OdometryTurning
            },
        ];
        graph.add_measured(&noise, &vars, Box::new(factor), false, config);
    }
}

/// Each fused sighting between its keyframe and its landmark, under the Huber kernel.
fn add_sightings(
    graph: &mut Graph,
    obs: &Observations<'_>,
    keyframes: &Keyframes,
    online: &OnlineResult,
    config: &FuseConfig,
) {
    let slot_of: BTreeMap<TagId, usize> = online
        .landmarks
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let tag = TagId {
                family: l.family,
                id: l.id,
            };
            (tag, i)
        })
        .collect();
    for (&k, &kf) in &keyframes.of_sighting {
        let s = &obs.sightings[k];
        let Some(&l) = slot_of.get(&s.key()) else {
            continue;
        };
        let (z, r) = sighting_measurement(s, config);
        let factor = TagFactor {
            measured: [z.x, z.y, z.z],
            sqrt_info: sqrt_information(&r),
        };
        let mut vars = vec![pose_name(kf), landmark_name(l)];
        if config.estimate_mounting {
            vars.push(MOUNTING.to_owned());
        }
        graph.sightings.push((vars.clone(), factor.clone()));
        graph.sighting_index.push(k);
        let names: Vec<&str> = vars.iter().map(String::as_str).collect();
        graph.add_measured(
            &[Noise::Sighting; 3],
            &names,
            Box::new(factor),
            true,
            config,
        );
    }
}

/// Each visual turn between the keyframes at its ends, under the Huber kernel.
fn add_turns(
    graph: &mut Graph,
    keyframes: &Keyframes,
    visual: &[&VisualTurn],
    config: &FuseConfig,
) {
    for v in visual {
        let (Some(&a), Some(&b)) = (
            keyframes.at_time.get(&v.from_t_s.to_bits()),
            keyframes.at_time.get(&v.to_t_s.to_bits()),
        ) else {
            continue;
        };
        if a == b {
            continue;
        }
        let factor = TurnFactor {
            measured: v.turn_rad,
            sqrt_info: 1.0 / v.sigma_rad.max(1e-6),
        };
        let vars = [pose_name(a), pose_name(b)];
        graph.add_measured(
            &[Noise::Turn],
            &[&vars[0], &vars[1]],
            Box::new(factor),
            true,
            config,
        );
    }
}

/// A prior on each landmark matched with a Hough corner, at the corner.
fn add_corner_priors(graph: &mut Graph, online: &OnlineResult, config: &FuseConfig) {
    for (i, l) in online.landmarks.iter().enumerate() {
        if let Some(c) = l.matched_corner {
            let factor = PriorFactor {
                measured: vec![c.x_m, c.y_m],
                sqrt_info: vec![1.0 / config.corner_sigma_m; 2],
            };
            graph.add(2, &[&landmark_name(i)], Box::new(factor), false, config);
        }
    }
}

/// A prior on each landmark that has an anchor, at the anchor with its sigmas (its facing too
/// when given, unwrapped to the landmark's start); whether any landmark has one.
fn add_anchor_priors(
    graph: &mut Graph,
    online: &OnlineResult,
    anchors: &[Anchor],
    config: &FuseConfig,
) -> bool {
    let mut any = false;
    for (i, l) in online.landmarks.iter().enumerate() {
        let Some(a) = anchors
            .iter()
            .find(|a| a.tag.family == l.family && a.tag.id == l.id)
        else {
            continue;
        };
        let mut measured = vec![a.position_m[0], a.position_m[1]];
        let mut sqrt_info = vec![1.0 / a.sigma_m.max(1e-6); 2];
        if let Some(yaw) = a.yaw_rad {
            measured.push(l.yaw_rad + wrap_angle(yaw - l.yaw_rad));
            sqrt_info.push(1.0 / a.sigma_rad.max(1e-6));
        }
        let dim = measured.len();
        let factor = PriorFactor {
            measured,
            sqrt_info,
        };
        graph.add(dim, &[&landmark_name(i)], Box::new(factor), false, config);
        any = true;
    }
    any
}

/// A problem linearised at `values`: its whitened residuals, their Jacobian (one column per
/// free tangent direction), and each variable's first column.
pub(super) struct Linearised {
    pub(super) residuals: faer::Mat<f64>,
    pub(super) jacobian: faer::sparse::SparseColMat<usize, f64>,
    pub(super) columns: HashMap<String, usize>,
}

impl Linearised {
    /// `problem` at `values`.
    pub(super) fn at(problem: &tiny_solver::Problem, values: &HashMap<String, Vector>) -> Self {
        let blocks = problem.initialize_parameter_blocks(values);
        let columns = problem.get_variable_name_to_col_idx_dict(&blocks);
        let total: usize = columns
            .keys()
            .map(|k| blocks[k].tangent_size() - blocks[k].fixed_variables.len())
            .sum();
        let structure = problem.build_symbolic_structure(&blocks, total, &columns);
        let (residuals, jacobian) =
            problem.compute_residual_and_jacobian(&blocks, &columns, &structure);
        Self {
            residuals,
            jacobian,
            columns,
        }
    }

    /// The information `JᵀJ` of a Jacobian.
    pub(super) fn information(
        jacobian: &faer::sparse::SparseColMat<usize, f64>,
    ) -> Option<faer::sparse::SparseColMat<usize, f64>> {
        Some(jacobian.as_ref().transpose().to_col_major().ok()? * jacobian.as_ref())
    }
}

/// The marginal covariance of variable `name` (of `dim` numbers) at `values`: the inverse of the
/// problem's information (JᵀJ of its whitened residuals) restricted to it, through the sparse
/// Cholesky the solver itself uses; `None` when the information is singular.
pub(super) fn marginal_covariance(
    problem: &tiny_solver::Problem,
    values: &HashMap<String, Vector>,
    name: &str,
    dim: usize,
) -> Option<nalgebra::DMatrix<f64>> {
    use tiny_solver::linear::sparse::SparseLinearSolver;
    let linear = Linearised::at(problem, values);
    let first = *linear.columns.get(name)?;
    let jtj = Linearised::information(&linear.jacobian)?;
    let total = jtj.ncols();
    let rhs = faer::Mat::<f64>::from_fn(total, dim, |r, c| f64::from(u8::from(r == first + c)));
    let x = tiny_solver::linear::SparseCholeskySolver::new().solve_jtj(&rhs, &jtj)?;
    let cov = nalgebra::DMatrix::from_fn(dim, dim, |r, c| x[(first + r, c)]);
    cov.iter().all(|v| v.is_finite()).then_some(cov)
}
