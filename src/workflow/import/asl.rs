//! ASL dataset folders (the EuRoC layout) as runs: the stereo pairs of `cam0` and `cam1` matched
//! by time stamp, the rig from their `sensor.yaml` (`T_BS` the mounting on the body, which is
//! taken as the robot), the odometry from a TUM file and the ground truth from
//! `state_groundtruth_estimate0` when the folder has one. Such a run has no sonar.

use super::{anchored, flat, time_ordered};
use crate::camera::StereoRig;
use crate::dataset::{RobotDescription, RunDataset, RunMeta, StereoEntry, RUN_FORMAT};
use crate::geometry::StampedPose;
use crate::io::asl::{asl_root, read_asl_camera, read_asl_ground_truth, read_tum, AslCamera};
use crate::io::{self, IoError, OutputDir};
use crate::progress::Progress;
use crate::sonar::grid::GridConfig;
use crate::sonar::map::MappingConfig;
use crate::sonar::SonarLayout;
use crate::workflow::{Error, Result};
use rayon::prelude::*;
use serde::Serialize;
use std::path::Path;

/// What to import.
#[derive(Debug, Clone)]
pub struct AslRequest<'a> {
    /// The ASL folder (holding `cam0` and `cam1`, or `mav0/`).
    pub asl: &'a Path,
    /// The odometry, a TUM file (`timestamp tx ty tz qx qy qz qw`, seconds on the images' clock).
    pub odometry: Option<&'a Path>,
    /// The run directory to write.
    pub out: &'a Path,
    /// Largest difference of stamps between a left and a right image of a pair, milliseconds.
    pub sync_ms: f64,
    /// Replace the output directory if it exists.
    pub force: bool,
}

/// What was read and written (also `import.json` in the run directory).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AslSummary {
    /// The folder read.
    pub asl: String,
    /// Pictures listed in `cam0/data.csv` and `cam1/data.csv`.
    pub pictures: [usize; 2],
    /// Stereo pairs written.
    pub pairs: usize,
    /// Left and right pictures with no partner within the sync tolerance.
    pub unmatched: [usize; 2],
    /// The time stamp of the run's time 0, seconds.
    pub start_s: f64,
    /// Seconds from the first to the last time imported.
    pub duration_s: f64,
    /// Odometry poses written.
    pub odometry_poses: usize,
    /// Whether a ground truth was written.
    pub ground_truth: bool,
    /// With a ground truth, how far the odometry strays from it
    /// ([`crate::workflow::import::OdometryAgainstTruth`]).
    pub odometry_against_ground_truth: Option<crate::workflow::import::OdometryAgainstTruth>,
    /// How the run's frame was fixed.
    pub frame: String,
    /// How the pictures were brought in: hard links, or copies where a link cannot be made.
    pub linked: usize,
    /// Copied.
    pub copied: usize,
}

/// Left and right frames matched by stamp within `tolerance_ns` (each used once, in time
/// order), and how many of each side found no partner.
fn pairs(
    left: &[(i64, std::path::PathBuf)],
    right: &[(i64, std::path::PathBuf)],
    tolerance_ns: i64,
) -> (Vec<(usize, usize)>, [usize; 2]) {
    let mut l: Vec<usize> = (0..left.len()).collect();
    let mut r: Vec<usize> = (0..right.len()).collect();
    l.sort_by_key(|&i| left[i].0);
    r.sort_by_key(|&i| right[i].0);
    let (mut i, mut j, mut out) = (0, 0, Vec::new());
    while i < l.len() && j < r.len() {
        let (a, b) = (left[l[i]].0, right[r[j]].0);
        if (a - b).abs() <= tolerance_ns {
            out.push((l[i], r[j]));
            i += 1;
            j += 1;
        } else if a < b {
            i += 1;
        } else {
            j += 1;
        }
    }
    let n = out.len();
    (out, [left.len() - n, right.len() - n])
}

/// Imports an ASL folder as a run: pairs hard-linked (copied where a link cannot be made) into
/// `stereo/`, the rig as `rig.yaml`, the odometry in the ground truth's frame (or starting at the
/// origin), times from the earliest stamp.
pub fn import_asl(
    request: &AslRequest<'_>,
    progress: &dyn Progress,
) -> Result<(RunDataset, AslSummary)> {
    let root = asl_root(request.asl)?;
    let cams: [AslCamera; 2] = [
        read_asl_camera(&root, "cam0")?,
        read_asl_camera(&root, "cam1")?,
    ];
    let Some(odometry_path) = request.odometry else {
        return Err(Error::Request(format!(
            "{}: an ASL folder has no wheel odometry; give one with --odometry FILE (TUM: timestamp tx ty tz qx qy qz qw, seconds)",
            request.asl.display()
        )));
    };
    let (matched, unmatched) = pairs(
        &cams[0].frames,
        &cams[1].frames,
        (request.sync_ms * 1e6).round() as i64,
    );
    if matched.is_empty() {
        return Err(IoError::content(
            &cams[0].list,
            format!(
                "no picture has a partner in {} within {} ms",
                cams[1].list.display(),
                request.sync_ms
            ),
        )
        .into());
    }
    // The pictures' sizes against sensor.yaml (the first of each camera).
    for (k, cam) in cams.iter().enumerate() {
        let i = if k == 0 { matched[0].0 } else { matched[0].1 };
        let first = &cam.frames[i].1;
        let (w, h) = image::image_dimensions(first)
            .map_err(|e| IoError::content(first, format!("cannot read the picture: {e}")))?;
        if [w, h] != [cam.camera.width, cam.camera.height] {
            return Err(IoError::content(
                first,
                format!(
                    "the picture is {w} x {h} but cam{k}/sensor.yaml says {} x {}",
                    cam.camera.width, cam.camera.height
                ),
            )
            .into());
        }
    }
    let tum = read_tum(odometry_path)?;
    if tum.is_empty() {
        return Err(IoError::content(odometry_path, "no poses: the run needs odometry").into());
    }
    let truth = read_asl_ground_truth(&root)?.unwrap_or_default();
    let stamps = matched
        .iter()
        .map(|&(l, _)| cams[0].frames[l].0)
        .chain(truth.iter().map(|t| t.0))
        .chain(tum.iter().map(|t| (t.0 * 1e9).round() as i64));
    let (t0, t1) = stamps.fold((i64::MAX, i64::MIN), |(a, b), t| (a.min(t), b.max(t)));
    let seconds = |ns: i64| (ns - t0) as f64 * 1e-9;
    let odometry = time_ordered(
        tum.iter()
            .map(|(t, p)| StampedPose {
                t_s: t - t0 as f64 * 1e-9,
                pose: flat(p),
            })
            .collect(),
    );
    if odometry.dropped > 0 || odometry.reordered > 0 {
        tracing::warn!(
            "{}: {} poses a little out of time order re-ordered, {} going back over {} s left out",
            odometry_path.display(),
            odometry.reordered,
            odometry.dropped,
            io::REORDER_TOLERANCE_S
        );
    }
    let mut truth: Vec<StampedPose> = truth
        .iter()
        .map(|(t, p)| StampedPose {
            t_s: seconds(*t),
            pose: flat(p),
        })
        .collect();
    truth.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let (trajectory, frame) = anchored(&odometry.poses, &truth, "state_groundtruth_estimate0");

    let dir = OutputDir::create(request.out, request.force)?;
    for side in ["left", "right"] {
        let d = dir.path("stereo").join(side);
        std::fs::create_dir_all(&d).map_err(|e| IoError::file(&d, e))?;
    }
    progress.start("import", matched.len() as u64);
    let brought: Vec<std::result::Result<([String; 2], usize), IoError>> = matched
        .par_iter()
        .map(|&(l, r)| {
            let mut names = [String::new(), String::new()];
            let mut links = 0;
            for (side, (cam, i)) in [(&cams[0], l), (&cams[1], r)].into_iter().enumerate() {
                let from = &cam.frames[i].1;
                let file = from
                    .file_name()
                    .map(|f| f.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let name = format!("stereo/{}/{file}", ["left", "right"][side]);
                let to = dir.path(&name);
                if std::fs::hard_link(from, &to).is_ok() {
                    links += 1;
                } else {
                    std::fs::copy(from, &to).map_err(|e| IoError::file(from, e))?;
                }
                names[side] = name;
            }
            progress.advance(1);
            Ok((names, links))
        })
        .collect();
    progress.finish();
    let mut stereo = Vec::with_capacity(matched.len());
    let mut linked = 0;
    for (&(l, _), b) in matched.iter().zip(brought) {
        let ([left, right], links) = b?;
        linked += links;
        stereo.push(StereoEntry {
            t_s: seconds(cams[0].frames[l].0),
            left,
            right,
        });
    }
    stereo.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let rig = StereoRig {
        left: cams[0].camera,
        right: cams[1].camera,
        right_from_left: cams[1].body_from_camera.inverse() * cams[0].body_from_camera,
        robot_from_left: cams[0].body_from_camera,
        right_from_left_covariance: None,
    };
    let layout = SonarLayout {
        name: "none".into(),
        sensors: Vec::new(),
        ..SonarLayout::frontal5()
    };
    let ground_truth = (!truth.is_empty()).then_some(truth);
    let against_truth = super::check_odometry_against_truth(
        (
            &trajectory,
            &format!("{}: the odometry", odometry_path.display()),
        ),
        ground_truth
            .as_deref()
            .map(|truth| (truth, "the folder's ground truth")),
        "is it the ground truth itself, or an estimate aligned to it?",
    );
    let grid = GridConfig::fitted(ground_truth.as_deref().unwrap_or(&trajectory), &layout)
        .unwrap_or_default();
    let summary = AslSummary {
        asl: request.asl.display().to_string(),
        pictures: [cams[0].frames.len(), cams[1].frames.len()],
        pairs: stereo.len(),
        unmatched,
        start_s: t0 as f64 * 1e-9,
        duration_s: (t1 - t0) as f64 * 1e-9,
        odometry_poses: trajectory.len(),
        ground_truth: ground_truth.is_some(),
        odometry_against_ground_truth: against_truth,
        frame: frame.clone(),
        linked,
        copied: 2 * stereo.len() - linked,
    };
    let run = RunDataset {
        meta: RunMeta {
            format: RUN_FORMAT.into(),
            robot: RobotDescription {
                sonar: layout,
                lidar: None,
                ranging: None,
                rig: Some("rig.yaml".into()),
                robot_from_left: None,
            },
            world: None,
            mapping: Some(MappingConfig {
                grid,
                ..MappingConfig::default()
            }),
            notes: format!(
                "imported from the ASL folder {} by stereotag import (no sonar; the body frame of T_BS is the robot's); the run's frame is {frame}; times from stamp {:.9} s",
                request.asl.display(),
                t0 as f64 * 1e-9
            ),
        },
        odometry: trajectory,
        sonar: Vec::new(),
        stereo,
        ground_truth,
        lidar: Vec::new(),
    };
    io::save_run(&dir.path(""), &run)?;
    io::save_rig(&dir.path("rig.yaml"), &rig)?;
    io::save_json(&dir.path("import.json"), &summary)?;
    dir.commit()?;
    tracing::info!(
        "imported {}: {} stereo pairs ({} left and {} right pictures unmatched within {} ms), {} odometry poses{}; {} -> {}",
        request.asl.display(),
        summary.pairs,
        unmatched[0],
        unmatched[1],
        request.sync_ms,
        summary.odometry_poses,
        if summary.ground_truth { ", ground truth" } else { "" },
        frame,
        request.out.display()
    );
    Ok((run, summary))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn frames_pair_by_stamp_each_once() {
        let f = |ts: &[i64]| -> Vec<(i64, PathBuf)> {
            ts.iter().map(|&t| (t, PathBuf::new())).collect()
        };
        let (m, un) = pairs(&f(&[0, 50, 100, 300]), &f(&[2, 101, 102, 200]), 5);
        assert_eq!(m, vec![(0, 0), (2, 1)]);
        assert_eq!(un, [2, 2]);
    }
}
