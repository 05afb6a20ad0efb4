//! Survey outputs: `landmarks.json`, the WPILib `layout.json` and `trajectory.csv` (DESIGN.md), and
//! `visual_turns.csv` (ours).

use super::{read_text, write_file, IoError};
use crate::dataset::RunDataset;
use crate::fusion::{Landmark, OdometryCalibration, Survey};
use crate::geometry::{pose_within, StampedPose};
use crate::world::World;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// One entry of `landmarks.json` (keys fixed by DESIGN.md): the landmark's own keys, with its
/// matched corner as `{x_m, y_m, votes, distance_chi2}`, and the planned position.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LandmarkRecord {
    /// The surveyed tag.
    #[serde(flatten)]
    pub landmark: Landmark,
    /// Where the world file planned the tag, if known.
    pub planned_position_m: Option<[f64; 3]>,
    /// The tag's orientation as a unit quaternion `[x, y, z, w]` (`world_from_tag`, x the
    /// outward normal, z up the printed tag): yaw, pitch and roll together.
    #[serde(default)]
    pub orientation_xyzw: [f64; 4],
    /// The pose's covariance over `(x, y, z, roll, pitch, yaw)`, metres and radians.
    #[serde(default)]
    pub covariance_6x6: [[f64; 6]; 6],
}

impl LandmarkRecord {
    /// The record of a landmark, with where the world planned it.
    pub fn new(landmark: Landmark, planned_position_m: Option<[f64; 3]>) -> Self {
        let q = nalgebra::UnitQuaternion::from_rotation_matrix(&landmark.rotation());
        Self {
            orientation_xyzw: [q.i, q.j, q.k, q.w],
            covariance_6x6: landmark.pose_covariance(),
            landmark,
            planned_position_m,
        }
    }
}

/// The whole `landmarks.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LandmarksFile {
    /// The landmarks, sorted by family and id.
    pub landmarks: Vec<LandmarkRecord>,
    /// The robot's odometry calibration the survey's offline pass estimated (ours, beyond
    /// DESIGN.md's keys; `localize` corrects a later run's odometry with it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odometry_calibration: Option<OdometryCalibration>,
    /// How noisy the calibrated odometry was against the fusion's odometry noise model, as a
    /// factor on its sigmas (ours, beside `odometry_calibration`): the survey's offline residuals
    /// tell it ([`crate::fusion::NoiseScales`]); `localize` predicts with the model scaled by it
    /// ([`crate::fusion::FuseConfig::with_odometry_noise_scale`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odometry_noise_scale: Option<crate::fusion::OdometryNoiseScale>,
    /// `[x, y, theta]` (metres, radians) of the run's odometry frame in the survey's, when the
    /// survey is not in its start's frame (`--anchors`, `--origin-tag`): `localize` moves a later
    /// run's odometry by it, as the survey did its run's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_from_odometry: Option<[f64; 3]>,
}

/// Largest magnitude of each odometry calibration term a file may give (50% scale errors, 0.5
/// rad of drift per metre: far beyond any working robot's wheels).
const CALIBRATION_LIMIT: f64 = 0.5;

/// The odometry noise scales a file may give (a robot twenty times quieter or noisier than the
/// model is a file gone wrong).
const NOISE_SCALE_LIMITS: (f64, f64) = (0.05, 20.0);

/// Writes `landmarks.json`.
pub fn save_landmarks(path: &Path, file: &LandmarksFile) -> Result<(), IoError> {
    super::save_json(path, file)
}

/// Reads `landmarks.json`, checking the numbers are finite and the covariances symmetric.
pub fn load_landmarks(path: &Path) -> Result<LandmarksFile, IoError> {
    let text = read_text(path)?;
    let file: LandmarksFile = serde_json::from_str(&text).map_err(|e| {
        let message = super::at_column(e.column(), &e.to_string(), e.line());
        IoError::line(path, e.line() as u64, message)
    })?;
    for (i, l) in file.landmarks.iter().map(|r| &r.landmark).enumerate() {
        let numbers = l
            .position_m
            .iter()
            .chain(l.covariance_m2.iter().flatten())
            .chain([&l.yaw_rad, &l.pitch_rad, &l.roll_rad])
            .chain(&l.orientation_sigma_rad)
            .chain(std::iter::once(&l.size_m));
        if numbers.into_iter().any(|v| !v.is_finite()) {
            return Err(IoError::content(
                path,
                format!("landmarks[{i}] (tag {}): numbers must be finite", l.id),
            ));
        }
        let c = &l.covariance_m2;
        if c[0][0] < 0.0 || c[1][1] < 0.0 || c[2][2] < 0.0 {
            return Err(IoError::content(
                path,
                format!(
                    "landmarks[{i}] (tag {}): covariance_m2 has a negative variance",
                    l.id
                ),
            ));
        }
    }
    if let Some(c) = &file.odometry_calibration {
        let terms = [
            ("turn_scale_error", c.turn_scale_error),
            ("heading_drift_rad_per_m", c.heading_drift_rad_per_m),
            ("distance_scale_error", c.distance_scale_error),
        ];
        if let Some((name, v)) = terms
            .iter()
            .find(|(_, v)| !v.is_finite() || v.abs() > CALIBRATION_LIMIT)
        {
            return Err(IoError::content(
                path,
                format!("odometry_calibration.{name} = {v}: expected a finite value within +-{CALIBRATION_LIMIT}"),
            ));
        }
    }
    if let Some(s) = &file.odometry_noise_scale {
        let terms = [
            ("translation", s.translation),
            ("turning", s.turning),
            ("drift", s.drift),
        ];
        let (low, high) = NOISE_SCALE_LIMITS;
        if let Some((name, v)) = terms.iter().find(|(_, v)| !(low..=high).contains(v)) {
            return Err(IoError::content(
                path,
                format!(
                    "odometry_noise_scale.{name} = {v}: expected a factor within {low} to {high}"
                ),
            ));
        }
    }
    if let Some(f) = file
        .frame_from_odometry
        .filter(|f| !f.iter().all(|v| v.is_finite()))
    {
        return Err(IoError::content(
            path,
            format!("frame_from_odometry {f:?}: expected three finite numbers"),
        ));
    }
    Ok(file)
}

/// Writes a WPILib AprilTag field layout: each tag's pose with x out of the tag face, and the
/// field's length (x) and width (y), metres: the home's extent from the survey's origin, as
/// `home` gives it (the corrected map's observed cells), and at least the landmarks' extent.
/// WPILib puts the field's corner at the origin: a home reaching below x = 0 or y = 0 (the robot
/// started inside it) is cut there in WPILib's tools, which the log says.
pub fn save_wpilib_layout(
    path: &Path,
    landmarks: &[Landmark],
    home: Option<([f64; 2], [f64; 2])>,
) -> Result<(), IoError> {
    let (mut max_x, mut max_y) = home.map_or((0.0f64, 0.0f64), |(_, hi)| (hi[0], hi[1]));
    let tags: Vec<_> = landmarks
        .iter()
        .map(|l| {
            max_x = max_x.max(l.position_m[0]);
            max_y = max_y.max(l.position_m[1]);
            let q = nalgebra::UnitQuaternion::from_rotation_matrix(&l.rotation());
            serde_json::json!({
                "ID": l.id,
                "pose": {
                    "translation": {"x": l.position_m[0], "y": l.position_m[1], "z": l.position_m[2]},
                    "rotation": {"quaternion": {"W": q.w, "X": q.i, "Y": q.j, "Z": q.k}}
                }
            })
        })
        .collect();
    if let Some((lo, _)) = home.filter(|(lo, _)| lo[0] < -0.5 || lo[1] < -0.5) {
        tracing::info!(
            "{}: the home reaches ({:.1}, {:.1}) m, below the field's corner at the survey's origin; WPILib tools show only x, y >= 0",
            // The file's name: it is written in a directory that becomes the output when whole.
            path.file_name().unwrap_or(path.as_os_str()).to_string_lossy(),
            lo[0],
            lo[1]
        );
    }
    let layout = serde_json::json!({
        "tags": tags,
        "field": {"length": max_x, "width": max_y}
    });
    super::save_json(path, &layout)
}

/// The survey's pictures: the raw map with the odometry and its Hough corners, the online map
/// with the online filter's trajectory, the corrected map with the offline trajectory (the
/// ground truth beside it when known) and the landmarks, and both Hough accumulators.
fn save_survey_pictures(dir: &Path, run: &RunDataset, s: &Survey) -> Result<(), IoError> {
    use crate::picture::{colours, Mark, Overlay, Path as Line};
    let truth = || {
        run.ground_truth
            .as_deref()
            .map(|t| Line::trajectory("ground truth", colours::GROUND_TRUTH, t))
    };
    let raw = Overlay {
        paths: vec![Line::trajectory(
            "odometry",
            colours::ODOMETRY,
            &run.odometry,
        )],
        marks: Mark::corners(&s.raw.features_offline),
        mark_legend: vec![("Hough corner", colours::CORNER)],
        ..Overlay::default()
    };
    super::save_map_png(
        &dir.join("map.png"),
        &s.raw.counting,
        "map.png: sonar map on the odometry's poses",
        &raw,
    )?;
    let online = Overlay {
        paths: vec![Line::trajectory(
            "online",
            colours::ONLINE,
            &s.online.trajectory,
        )],
        ..Overlay::default()
    };
    super::save_map_png(
        &dir.join("map_online.png"),
        &s.online_map,
        "map_online.png: sonar map on the online filter's poses",
        &online,
    )?;
    let corrected = Overlay {
        paths: truth()
            .into_iter()
            .chain([Line::trajectory(
                "offline",
                colours::OFFLINE,
                &s.offline.trajectory,
            )])
            .collect(),
        marks: Mark::landmarks(&s.landmarks),
        mark_legend: vec![("landmark", colours::LANDMARK)],
        ..Overlay::default()
    };
    super::save_map_png(
        &dir.join("map_corrected.png"),
        &s.corrected.counting,
        "map_corrected.png: sonar map on the offline poses, with the landmarks",
        &corrected,
    )?;
    super::save_accumulator_png(
        &dir.join("hough.png"),
        &s.raw.accumulator,
        "hough.png: Hough accumulator of the odometry's map",
    )?;
    super::save_accumulator_png(
        &dir.join("hough_corrected.png"),
        &s.corrected.accumulator,
        "hough_corrected.png: Hough accumulator of the corrected map",
    )
}

/// The trajectories of a survey, all at the odometry times.
#[derive(Debug, Clone, Copy)]
pub struct Trajectories<'a> {
    /// Dead reckoning.
    pub odometry: &'a [StampedPose],
    /// Online filter.
    pub online: &'a [StampedPose],
    /// Offline pose graph.
    pub offline: &'a [StampedPose],
    /// Ground truth, when known (interpolated to the odometry times).
    pub ground_truth: Option<&'a [StampedPose]>,
}

/// Writes `trajectory.csv` with the DESIGN.md header; gt columns empty when unknown.
pub fn save_trajectory_csv(path: &Path, t: &Trajectories<'_>) -> Result<(), IoError> {
    let mut s = String::from(
        "t_s,odom_x_m,odom_y_m,odom_theta_rad,online_x_m,online_y_m,online_theta_rad,\
         offline_x_m,offline_y_m,offline_theta_rad,gt_x_m,gt_y_m,gt_theta_rad\n",
    );
    let pose = |p: Option<crate::geometry::Pose2>| match p {
        Some(p) => format!("{:.5},{:.5},{:.6}", p.x, p.y, p.theta),
        None => ",,".to_string(),
    };
    for (i, o) in t.odometry.iter().enumerate() {
        let _ = writeln!(
            s,
            "{:.4},{},{},{},{}",
            o.t_s,
            pose(Some(o.pose)),
            pose(t.online.get(i).map(|p| p.pose)),
            pose(t.offline.get(i).map(|p| p.pose)),
            pose(t.ground_truth.and_then(|g| pose_within(g, o.t_s))),
        );
    }
    write_file(path, s.as_bytes())
}

/// Writes a planar trajectory in the TUM format (`timestamp tx ty tz qx qy qz qw`, one pose a
/// line, the heading as a rotation about z), which `evo_traj` and `evo_ape` read.
pub fn save_tum(path: &Path, poses: &[StampedPose]) -> Result<(), IoError> {
    let mut s = String::from("# timestamp tx ty tz qx qy qz qw (stereotag; z up, metres)\n");
    for p in poses {
        let (qz, qw) = (0.5 * p.pose.theta).sin_cos();
        let _ = writeln!(
            s,
            "{:.6} {:.6} {:.6} 0 0 0 {:.9} {:.9}",
            p.t_s, p.pose.x, p.pose.y, qz, qw
        );
    }
    write_file(path, s.as_bytes())
}

/// The truth for the TUM files beside an estimate whose poses are `at`: evo associates poses by
/// time. Where the truth's own stamps are among `at`'s (a simulated run; a CARMEN import, whose
/// odometry has a pose at every laser scan), the truth at those stamps alone: the reports score
/// there ([`crate::metrics::at_truth`]), and evo over the files then gives their figures (aces:
/// 440 stamps of 7,374, where the truth interpolated across its gaps scored 0.204 m against the
/// reports' 0.073). Otherwise (fewer than half of the truth's stamps in `at`'s span are among
/// them), the truth interpolated at every time of `at`.
pub fn truth_at(truth: &[StampedPose], at: &[StampedPose]) -> Vec<StampedPose> {
    let measured = |t: f64| {
        let i = truth.partition_point(|g| g.t_s < t - TRUTH_STAMP_S);
        truth.get(i).filter(|g| (g.t_s - t).abs() <= TRUTH_STAMP_S)
    };
    let shared: Vec<StampedPose> = at
        .iter()
        .filter_map(|p| {
            measured(p.t_s).map(|g| StampedPose {
                t_s: p.t_s,
                pose: g.pose,
            })
        })
        .collect();
    let (first, last) = match (at.first(), at.last()) {
        (Some(a), Some(b)) => (a.t_s, b.t_s),
        _ => return Vec::new(),
    };
    let in_span = truth
        .iter()
        .filter(|g| (first..=last).contains(&g.t_s))
        .count();
    if !shared.is_empty() && 2 * shared.len() >= in_span {
        return shared;
    }
    at.iter()
        .filter_map(|p| pose_within(truth, p.t_s).map(|pose| StampedPose { t_s: p.t_s, pose }))
        .collect()
}

/// Two stamps this close (seconds) are one ([`truth_at`]): the CSVs write them to 0.1 ms.
const TRUTH_STAMP_S: f64 = 1e-6;

/// Header of `visual_turns.csv`.
pub const VISUAL_TURNS_HEADER: &str =
    "from_t_s,to_t_s,turn_rad,sigma_rad,odom_turn_rad,gt_turn_rad";

/// Writes the turns the visual odometry measured, beside the odometry's (and the truth's, when
/// known) over the same frames.
pub fn save_visual_turns_csv(
    path: &Path,
    turns: &[crate::visual::vo::VisualTurn],
    odometry: &[crate::geometry::StampedPose],
    ground_truth: Option<&[crate::geometry::StampedPose]>,
) -> Result<(), IoError> {
    let turn_of = |trajectory: &[crate::geometry::StampedPose],
                   v: &crate::visual::vo::VisualTurn| match (
        pose_within(trajectory, v.from_t_s),
        pose_within(trajectory, v.to_t_s),
    ) {
        (Some(a), Some(b)) => format!("{:.6}", crate::geometry::wrap_angle(b.theta - a.theta)),
        _ => String::new(),
    };
    let mut s = format!("{VISUAL_TURNS_HEADER}\n");
    for v in turns {
        let _ = writeln!(
            s,
            "{:.4},{:.4},{:.6},{:.6},{},{}",
            v.from_t_s,
            v.to_t_s,
            v.turn_rad,
            v.sigma_rad,
            turn_of(odometry, v),
            ground_truth.map_or(String::new(), |g| turn_of(g, v)),
        );
    }
    write_file(path, s.as_bytes())
}

/// Writes every survey output into `dir` (DESIGN.md's survey outputs: the maps and their
/// pictures, corners, walls, visual turns, `landmarks.json`, `layout.json`, `trajectory.csv` and
/// `report.json` with the metrics, timings, conflicts, the planned-versus-surveyed table and the
/// `warnings` printed).
pub fn save_survey(
    dir: &Path,
    run: &RunDataset,
    world: Option<&World>,
    s: &Survey,
    metrics: &BTreeMap<String, f64>,
    timings: &BTreeMap<String, f64>,
    warnings: &[String],
) -> Result<(), IoError> {
    save_survey_pictures(dir, run, s)?;
    super::save_ros_map(dir, "map", &s.raw.counting)?;
    super::save_features_csv(&dir.join("corners.csv"), &s.raw.features_offline)?;
    super::save_ros_map(dir, "map_online", &s.online_map)?;
    super::save_ros_map(dir, "map_corrected", &s.corrected.counting)?;
    super::save_features_csv(
        &dir.join("corners_corrected.csv"),
        &s.corrected.features_offline,
    )?;
    super::save_walls_csv(&dir.join("walls_corrected.csv"), &s.corrected.walls)?;
    if let Some(returns) = &s.returns {
        super::save_ros_map(dir, "returns_corrected", returns)?;
    }
    if let Some(c) = &s.walls_covariance {
        super::save_walls_covariance_csv(
            &dir.join("walls_corrected_covariance.csv"),
            &s.corrected.walls,
            c,
        )?;
    }
    super::save_visual_turns_csv(
        &dir.join("visual_turns.csv"),
        &s.visual,
        &run.odometry,
        run.ground_truth.as_deref(),
    )?;
    let planned = |l: &Landmark| {
        world
            .and_then(|w| w.tag(l.family, l.id))
            .map(|t| t.position_m)
    };
    let mut landmarks = s.landmarks.clone();
    landmarks.sort_by(|a, b| (&a.family, a.id).cmp(&(&b.family, b.id)));
    let records = landmarks
        .iter()
        .map(|l| LandmarkRecord::new(l.clone(), planned(l)))
        .collect();
    super::save_landmarks(
        &dir.join("landmarks.json"),
        &LandmarksFile {
            landmarks: records,
            odometry_calibration: s.offline.odometry_calibration,
            // Measured on the calibrated odometry: meant only with its calibration.
            odometry_noise_scale: s
                .offline
                .noise
                .filter(|n| {
                    [n.odometry_translation, n.odometry_turning, n.odometry_drift]
                        .iter()
                        .any(Option::is_some)
                })
                // A part the residuals cannot tell is left as modelled.
                .map(|n| crate::fusion::OdometryNoiseScale {
                    translation: n.odometry_translation.unwrap_or(1.0),
                    turning: n.odometry_turning.unwrap_or(1.0),
                    drift: n.odometry_drift.unwrap_or(1.0),
                })
                .filter(|_| s.offline.odometry_calibration.is_some()),
            frame_from_odometry: s.frame_from_odometry.map(|f| [f.x, f.y, f.theta]),
        },
    )?;
    super::save_wpilib_layout(
        &dir.join("layout.json"),
        &landmarks,
        s.corrected.counting.known_extent(),
    )?;
    super::save_trajectory_csv(
        &dir.join("trajectory.csv"),
        &Trajectories {
            odometry: &run.odometry,
            online: &s.online.trajectory,
            offline: &s.offline.trajectory,
            ground_truth: run.ground_truth.as_deref(),
        },
    )?;
    save_tum(&dir.join("trajectory_odometry.tum"), &run.odometry)?;
    save_tum(&dir.join("trajectory_online.tum"), &s.online.trajectory)?;
    save_tum(&dir.join("trajectory_offline.tum"), &s.offline.trajectory)?;
    if let Some(truth) = run.ground_truth.as_deref() {
        save_tum(
            &dir.join("trajectory_ground_truth.tum"),
            &truth_at(truth, &run.odometry),
        )?;
    }
    let displacement: Vec<_> = landmarks
        .iter()
        .filter_map(|l| {
            let p = planned(l)?;
            let d = [
                l.position_m[0] - p[0],
                l.position_m[1] - p[1],
                l.position_m[2] - p[2],
            ];
            Some(serde_json::json!({
                "id": l.id, "family": l.family, "planned_m": p, "surveyed_m": l.position_m,
                "displacement_m": d, "distance_m": (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(),
            }))
        })
        .collect();
    let finite: BTreeMap<_, _> = metrics
        .iter()
        .map(|(k, v)| (k.clone(), v.is_finite().then_some(*v)))
        .collect();
    let report = serde_json::json!({
        "metrics": finite,
        "timings_s": timings,
        "conflicts": s.online.conflicts,
        "planned_vs_surveyed": displacement,
        "warnings": warnings,
    });
    super::save_json(&dir.join("report.json"), &report)?;
    Ok(())
}

/// The header of `localization.csv`.
pub const LOCALIZATION_HEADER: &str = "t_s,odom_x_m,odom_y_m,odom_theta_rad,x_m,y_m,theta_rad,sigma_m,since_sighting_m,gt_x_m,gt_y_m,gt_theta_rad";

/// Writes `localization.csv`: at each odometry time the odometry as logged, the localised pose,
/// its sigma, the distance since the last sighting and, when known, the true pose.
pub fn save_localization_csv(
    path: &Path,
    odometry: &[StampedPose],
    result: &crate::fusion::LocalizeResult,
    truth: Option<&[StampedPose]>,
) -> Result<(), IoError> {
    let mut csv = format!("{LOCALIZATION_HEADER}\n");
    for (i, (o, p)) in odometry.iter().zip(&result.trajectory).enumerate() {
        let gt = truth
            .and_then(|t| pose_within(t, o.t_s))
            .map_or(",,".to_string(), |g| {
                format!("{:.5},{:.5},{:.6}", g.x, g.y, g.theta)
            });
        let _ = writeln!(
            csv,
            "{:.4},{:.5},{:.5},{:.6},{:.5},{:.5},{:.6},{:.5},{:.4},{gt}",
            o.t_s,
            o.pose.x,
            o.pose.y,
            o.pose.theta,
            p.pose.x,
            p.pose.y,
            p.pose.theta,
            result.sigma_m[i],
            result.since_sighting_m[i],
        );
    }
    write_file(path, csv.as_bytes())
}

/// A tag sizes file (`survey --tag-sizes`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TagSizesFile {
    /// The size of every tag not listed, metres.
    #[serde(default)]
    default: Option<f64>,
    /// Per tag.
    #[serde(default)]
    tags: Vec<TagSizeEntry>,
}

/// One tag's size.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TagSizeEntry {
    /// Family (default tag36h11).
    #[serde(default = "default_family")]
    family: crate::visual::tags::TagFamily,
    /// Id.
    id: u32,
    /// Printed edge length (the black square), metres.
    size_m: f64,
}

pub(super) fn default_family() -> crate::visual::tags::TagFamily {
    crate::visual::tags::TagFamily::Tag36h11
}

/// Reads a tag sizes file: `default: 0.16` and `tags:` a list of `{id: 3, size_m: 0.08}` (with
/// `family:` when not tag36h11). Sizes must be positive and finite; a tag listed twice is an
/// error naming it.
///
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("sizes.yaml");
/// std::fs::write(&path, "default: 0.16\ntags:\n  - {id: 3, size_m: 0.08}\n")?;
/// let sizes = stereotag::io::load_tag_sizes(&path)?;
/// use stereotag::visual::tags::TagFamily::Tag36h11;
/// assert_eq!((sizes.of(Tag36h11, 3), sizes.of(Tag36h11, 4)), (Some(0.08), Some(0.16)));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn load_tag_sizes(path: &Path) -> Result<crate::visual::sightings::TagSizes, IoError> {
    let file: TagSizesFile = super::parse_yaml(path, &read_text(path)?)?;
    let good = |v: f64| v.is_finite() && v > 0.0;
    if file.default.is_some_and(|d| !good(d)) {
        return Err(IoError::content(
            path,
            "default: a tag size must be a positive number of metres",
        ));
    }
    let mut sizes = crate::visual::sightings::TagSizes {
        default_m: file.default,
        ..Default::default()
    };
    for t in file.tags {
        let key = crate::visual::tags::TagId {
            family: t.family,
            id: t.id,
        };
        if !good(t.size_m) {
            return Err(IoError::content(
                path,
                format!(
                    "{} {}: size_m {} is not a positive number of metres",
                    t.family, t.id, t.size_m
                ),
            ));
        }
        if sizes.by_tag.insert(key, t.size_m).is_some() {
            return Err(IoError::content(
                path,
                format!("{} {} is listed twice", t.family, t.id),
            ));
        }
    }
    Ok(sizes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A truth whose stamps are among the estimate's is written at those alone (where the
    /// reports score); one whose stamps are not, interpolated at the estimate's within its span.
    #[test]
    fn the_truth_is_written_where_it_was_measured_when_the_estimate_has_those_times() {
        let estimate: Vec<StampedPose> = (0..=4)
            .map(|k| StampedPose::along_x(0.5 * k as f64, 9.0))
            .collect();
        let truth = [
            StampedPose::along_x(0.0, 0.0),
            StampedPose::along_x(1.0, 1.0),
            StampedPose::along_x(2.0, 2.0),
        ];
        let written = truth_at(&truth, &estimate);
        assert_eq!(written, truth);
        let between = [
            StampedPose::along_x(0.25, 0.0),
            StampedPose::along_x(1.25, 1.0),
        ];
        let written = truth_at(&between, &estimate);
        let times: Vec<f64> = written.iter().map(|p| p.t_s).collect();
        assert_eq!(times, [0.5, 1.0]);
        assert!((written[0].pose.x - 0.25).abs() < 1e-12);
        assert!(truth_at(&truth, &[]).is_empty());
    }
}
