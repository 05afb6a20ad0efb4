//! ROS 2 bags as runs: stereo pairs matched by stamp, odometry, sonar `Range` topics (or a
//! `LaserScan` turned into sonar-like readings), the sensors placed by tf and the rig from the two
//! `CameraInfo` messages.
//!
//! The run's frame: with `--ground-truth` (a simulator's or motion capture's `Odometry`), the
//! ground truth's frame, the odometry moved to start at the ground truth's pose at its first
//! message; otherwise the robot's pose at the first odometry message (the odometry moved to start
//! at the origin, heading along x), whatever the `odom` frame's origin was when the bag began.
//! Times start at the earliest stamp of the messages imported.

mod pictures;
mod rig;
mod sonar;
mod topics;

pub use topics::{CAMERA_INFO, COMPRESSED_IMAGE, IMAGE, LASER_SCAN, ODOMETRY, RANGE, TF_MESSAGE};

use pictures::{bytes_per_pixel, picture_file, Pairing, Picture, PictureData, PAIR_BATCH};
use topics::{topic_error, Roles};

/// Left and right images further apart than this are not a pair, by default (milliseconds):
/// hardware-triggered stereo cameras stamp both images alike; 10 ms is under a third of a 30 Hz
/// camera's frame time, so no image can pair with its neighbour's partner.
pub const DEFAULT_SYNC_MS: f64 = 10.0;
use super::{anchored, flat, time_ordered};
use crate::camera::StereoRig;
use crate::dataset::{RobotDescription, RunDataset, RunMeta, StereoEntry, RUN_FORMAT};
use crate::geometry::StampedPose;
use crate::io::rosbag::cdr::{self, CameraInfo, CdrError};
use crate::io::rosbag::tf::TfTree;
use crate::io::rosbag::{message_error, Bag, Message};
use crate::io::{self, IoError, OutputDir};
use crate::progress::Progress;
use crate::sonar::grid::GridConfig;
use crate::sonar::map::MappingConfig;
use crate::sonar::SonarLayout;
use crate::workflow::Result;
use nalgebra::Isometry3;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};

/// Which topics are which: each `None` (or empty) is found by its message type when the bag has
/// one topic of that type (for the images: two topics, told apart by `left`/`right`, `infra1`/
/// `infra2` or `cam0`/`cam1` in their names).
#[derive(Debug, Clone, Default)]
pub struct BagTopics {
    /// The left camera's `Image` or `CompressedImage` topic.
    pub left: Option<String>,
    /// The right camera's.
    pub right: Option<String>,
    /// The wheel odometry (`Odometry`).
    pub odom: Option<String>,
    /// The sonars (`Range`), names or globs (`*` any characters, `?` one); empty: every `Range`
    /// topic, in name order.
    pub sonar: Vec<String>,
    /// The laser (`LaserScan`), used with `as_sonar`.
    pub scan: Option<String>,
    /// A ground-truth trajectory (`Odometry` from a simulator or motion capture); none by
    /// default.
    pub ground_truth: Option<String>,
}

/// What to import.
#[derive(Debug, Clone)]
pub struct BagRequest<'a> {
    /// The bag directory (`metadata.yaml` and `.mcap` files) or `.mcap` file.
    pub bag: &'a Path,
    /// The run directory to write.
    pub out: &'a Path,
    /// Which topics to read.
    pub topics: BagTopics,
    /// The robot's frame in tf, whose pose the odometry gives and where sensors are placed from.
    pub base_frame: String,
    /// Largest difference of stamps between a left and a right image of a pair, milliseconds.
    pub sync_ms: f64,
    /// A Kalibr camchain for the cameras instead of their `CameraInfo`.
    pub rig: Option<&'a Path>,
    /// Turn the laser into this sonar ring (instead of the `Range` topics).
    pub as_sonar: Option<SonarLayout>,
    /// Replace the output directory if it exists.
    pub force: bool,
}

/// One topic of the bag, what it was read as.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TopicSummary {
    /// The topic.
    pub topic: String,
    /// Its type.
    pub type_name: String,
    /// Its messages.
    pub messages: usize,
    /// Messages a second.
    pub rate_hz: f64,
    /// The longest time without a message, seconds.
    pub largest_gap_s: f64,
    /// What it was read as (`left images`, `sonar 2`, ...), or `not used`.
    pub used_as: String,
}

/// What was read and written (also `import.json` in the run directory).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BagSummary {
    /// The bag read.
    pub bag: String,
    /// Its topics.
    pub topics: Vec<TopicSummary>,
    /// The stamp of the run's time 0, seconds (ROS time).
    pub start_s: f64,
    /// Seconds from the first to the last stamp imported.
    pub duration_s: f64,
    /// Stereo pairs written.
    pub pairs: usize,
    /// Left images with no right image within the sync tolerance.
    pub unmatched_left: usize,
    /// Right images with no left image within it.
    pub unmatched_right: usize,
    /// The sync tolerance, milliseconds.
    pub sync_ms: f64,
    /// Image width and height.
    pub image_size: Option<[u32; 2]>,
    /// Where the rig came from.
    pub rig_from: Option<String>,
    /// Odometry poses written.
    pub odometry_poses: usize,
    /// Odometry messages a little out of time order, re-ordered.
    pub odometry_reordered: usize,
    /// Odometry messages left out: their stamp goes back more than the tolerance.
    pub odometry_dropped: usize,
    /// How the run's frame was fixed.
    pub frame: String,
    /// Messages stamped 0, timed by their log time instead.
    pub stamps_from_log_time: usize,
    /// Sonar readings written.
    pub readings: usize,
    /// Of those, with an echo.
    pub echoes: usize,
    /// Of those, nearer than the sonar's minimum (REP 117's `-inf`), written at the minimum.
    pub too_close: usize,
    /// Range messages left out: `NaN`, or a finite range below the minimum.
    pub ranges_left_out: usize,
    /// Laser scans read (turned into sonar readings with `--as-sonar`).
    pub scans: usize,
    /// The laser as the run's lidar (without `--as-sonar`).
    pub lidar: Option<crate::workflow::import::LidarImport>,
    /// Whether a ground truth was written.
    pub ground_truth: bool,
    /// With a ground truth, how far the odometry strays from it
    /// ([`crate::workflow::import::OdometryAgainstTruth`]).
    pub odometry_against_ground_truth: Option<crate::workflow::import::OdometryAgainstTruth>,
    /// The grid fitted to the run: lower-left corner (m).
    pub grid_origin_m: [f64; 2],
    /// Cells across and up.
    pub grid_cells: [usize; 2],
}

/// Imports a ROS 2 bag as a run directory (see the module's documentation for its frame and
/// times). The bag is checked whole before anything is written; on any error nothing is.
pub fn import_bag(
    request: &BagRequest<'_>,
    progress: &dyn Progress,
) -> Result<(RunDataset, BagSummary)> {
    let bag = Bag::open(request.bag)?;
    let roles = Roles::choose(&bag, &request.topics, request.as_sonar.is_some())?;
    if request.rig.is_none() {
        let sides = [
            (&roles.left, &roles.left_info),
            (&roles.right, &roles.right_info),
        ];
        if let Some((Some(images), _)) =
            sides.iter().find(|(i, info)| i.is_some() && info.is_none())
        {
            return Err(topic_error(
                &bag,
                format!("no {CAMERA_INFO} beside {images} (looked for camera_info in its namespaces): pass --rig camchain.yaml"),
            ));
        }
    }
    let dir = OutputDir::create(request.out, request.force)?;
    let mut gathered = Gathered::new(&roles, request.sync_ms, request.bag, dir.path(""));
    progress.start(
        "import",
        roles
            .left
            .as_ref()
            .map_or(0, |t| bag.topic(t).map_or(0, |t| t.count)) as u64,
    );
    bag.messages(
        |t| roles.uses(&t.name),
        |m| gathered.take(&roles, m, progress),
    )?;
    gathered.flush_pairs(&roles, progress)?;
    progress.finish();
    let run = gathered.into_run(&bag, &roles, request)?;
    let (run, mut summary, rig) = run;
    summary.topics = bag
        .topics
        .iter()
        .map(|t| TopicSummary {
            topic: t.name.clone(),
            type_name: t.type_name.clone(),
            messages: t.count,
            rate_hz: t.rate_hz(),
            largest_gap_s: t.largest_gap_ns as f64 * 1e-9,
            used_as: roles.role_of(&t.name),
        })
        .collect();
    io::save_run(&dir.path(""), &run)?;
    if let Some(rig) = &rig {
        io::save_rig(&dir.path("rig.yaml"), rig)?;
    }
    io::save_json(&dir.path("import.json"), &summary)?;
    dir.commit()?;
    report(&summary, request.out);
    Ok((run, summary))
}

/// What was read, on stderr.
fn report(summary: &BagSummary, out: &Path) {
    for t in &summary.topics {
        tracing::info!(
            "  {:<32} {:<32} {:>6} msgs {:>7.2} Hz  largest gap {:>6.2} s  {}",
            t.topic,
            t.type_name,
            t.messages,
            t.rate_hz,
            t.largest_gap_s,
            t.used_as
        );
    }
    tracing::info!(
        "imported {}: {} stereo pairs ({} left and {} right images unmatched within {} ms), {} odometry poses, {} sonar readings ({} echoes){}; {} -> {}",
        summary.bag,
        summary.pairs,
        summary.unmatched_left,
        summary.unmatched_right,
        summary.sync_ms,
        summary.odometry_poses,
        summary.readings,
        summary.echoes,
        if summary.ground_truth { ", ground truth" } else { "" },
        summary.frame,
        out.display()
    );
}

/// A pair written: its files and their sizes.
type WrittenPair = ([String; 2], [[u32; 2]; 2]);

/// One ranging message.
struct RangeRow {
    stamp_ns: i64,
    sensor: usize,
    range: f32,
}

/// The first of a sensor's messages: its frame and cone.
#[derive(Clone)]
struct RangeSensor {
    frame: String,
    field_of_view: f32,
    min_range: f32,
    max_range: f32,
}

/// What the messages gave, as they are read.
struct Gathered {
    bag: PathBuf,
    dir: PathBuf,
    tf: TfTree,
    infos: [Option<CameraInfo>; 2],
    image_frames: [Option<String>; 2],
    sizes: [Option<([u32; 2], usize)>; 2],
    pairing: Pairing,
    batch: Vec<(Picture, Picture)>,
    stereo: Vec<(i64, StereoEntry)>,
    odom: Vec<(i64, String, Isometry3<f64>)>,
    truth: Vec<(i64, String, Isometry3<f64>)>,
    sensors: Vec<Option<RangeSensor>>,
    ranges: Vec<RangeRow>,
    scans: Vec<(i64, String, cdr::LaserScan)>,
    stamps_from_log_time: usize,
}

/// A message's stamp: its header's, or its log time when the header is 0.
fn stamp_of(header_ns: i64, m: &Message<'_>, fallback: &mut usize) -> i64 {
    if header_ns != 0 {
        return header_ns;
    }
    *fallback += 1;
    m.log_time_ns as i64
}

impl Gathered {
    fn new(roles: &Roles, sync_ms: f64, bag: &Path, dir: PathBuf) -> Self {
        Gathered {
            bag: bag.to_owned(),
            dir,
            tf: TfTree::default(),
            infos: [None, None],
            image_frames: [None, None],
            sizes: [None, None],
            pairing: Pairing {
                tolerance_ns: (sync_ms * 1e6).round() as i64,
                pending: [VecDeque::new(), VecDeque::new()],
                unmatched: [0, 0],
            },
            batch: Vec::new(),
            stereo: Vec::new(),
            odom: Vec::new(),
            truth: Vec::new(),
            sensors: vec![None; roles.sonar.len()],
            ranges: Vec::new(),
            scans: Vec::new(),
            stamps_from_log_time: 0,
        }
    }

    /// Takes one message of a used topic.
    fn take(
        &mut self,
        roles: &Roles,
        m: &Message<'_>,
        progress: &dyn Progress,
    ) -> std::result::Result<(), IoError> {
        let bad = |e: CdrError| m.error(format!("cannot decode the {}: {e}", m.topic.type_name));
        let name = m.topic.name.as_str();
        let side = if roles.left.as_deref() == Some(name) {
            Some(0)
        } else if roles.right.as_deref() == Some(name) {
            Some(1)
        } else {
            None
        };
        if let Some(side) = side {
            let (header, data) = if m.topic.type_name == IMAGE {
                let image = cdr::Image::decode(m.data).map_err(bad)?;
                if bytes_per_pixel(&image.encoding).is_none() {
                    return Err(m.error(format!(
                        "image encoding `{}` is not read (mono8, mono16, rgb8, bgr8, rgba8, bgra8)",
                        image.encoding
                    )));
                }
                let data = PictureData::Raw {
                    width: image.width,
                    height: image.height,
                    encoding: image.encoding,
                    big_endian: image.big_endian,
                    step: image.step,
                    data: image.data.to_vec(),
                };
                (image.header, data)
            } else {
                let image = cdr::CompressedImage::decode(m.data).map_err(bad)?;
                let format = image.format.to_lowercase();
                let ext = if format.contains("jpeg") || format.contains("jpg") {
                    "jpg"
                } else if format.contains("png") {
                    "png"
                } else {
                    return Err(m.error(format!(
                        "compressed image format `{}` is not read (jpeg, png)",
                        image.format
                    )));
                };
                let data = PictureData::Compressed {
                    ext,
                    data: image.data.to_vec(),
                };
                (image.header, data)
            };
            if self.image_frames[side].is_none() {
                self.image_frames[side] = Some(header.frame_id.clone());
            }
            let picture = Picture {
                stamp_ns: stamp_of(header.stamp_ns, m, &mut self.stamps_from_log_time),
                index: m.index,
                log_time_ns: m.log_time_ns,
                data,
            };
            if let Some(pair) = self.pairing.push(side, picture) {
                self.batch.push(pair);
                if self.batch.len() >= PAIR_BATCH {
                    self.flush_pairs(roles, progress)?;
                }
            }
            return Ok(());
        }
        if roles.tf.iter().any(|t| t == name) {
            let transforms = cdr::decode_tf(m.data).map_err(bad)?;
            self.tf.add(&transforms, name == "/tf");
        } else if roles.left_info.as_deref() == Some(name)
            || roles.right_info.as_deref() == Some(name)
        {
            let k = usize::from(
                roles.right_info.as_deref() == Some(name)
                    && roles.left_info.as_deref() != Some(name),
            );
            if self.infos[k].is_none() {
                self.infos[k] = Some(CameraInfo::decode(m.data).map_err(bad)?);
            }
        } else if roles.odom == name || roles.ground_truth.as_deref() == Some(name) {
            let o = cdr::Odometry::decode(m.data).map_err(bad)?;
            let t = stamp_of(o.header.stamp_ns, m, &mut self.stamps_from_log_time);
            let row = (t, o.child_frame_id, o.pose);
            if roles.odom == name {
                self.odom.push(row);
            } else {
                self.truth.push(row);
            }
        } else if let Some(k) = roles.sonar.iter().position(|s| s == name) {
            let r = cdr::Range::decode(m.data).map_err(bad)?;
            if self.sensors[k].is_none() {
                if !(r.field_of_view > 0.0
                    && r.field_of_view < std::f32::consts::PI
                    && r.max_range > 0.0)
                {
                    return Err(m.error(format!(
                        "field_of_view {} rad and max_range {} m: a sonar needs a cone in (0, pi) and a positive reach",
                        r.field_of_view, r.max_range
                    )));
                }
                self.sensors[k] = Some(RangeSensor {
                    frame: r.header.frame_id.clone(),
                    field_of_view: r.field_of_view,
                    min_range: r.min_range,
                    max_range: r.max_range,
                });
            }
            self.ranges.push(RangeRow {
                stamp_ns: stamp_of(r.header.stamp_ns, m, &mut self.stamps_from_log_time),
                sensor: k,
                range: r.range,
            });
        } else if roles.scan.as_deref() == Some(name) {
            let s = cdr::LaserScan::decode(m.data).map_err(bad)?;
            let t = stamp_of(s.header.stamp_ns, m, &mut self.stamps_from_log_time);
            self.scans.push((t, s.header.frame_id.clone(), s));
        }
        Ok(())
    }

    /// Encodes and writes the pairs waiting (on every core).
    fn flush_pairs(
        &mut self,
        roles: &Roles,
        progress: &dyn Progress,
    ) -> std::result::Result<(), IoError> {
        let batch = std::mem::take(&mut self.batch);
        let first = self.stereo.len();
        if first == 0 && !batch.is_empty() {
            for side in ["left", "right"] {
                let d = self.dir.join("stereo").join(side);
                std::fs::create_dir_all(&d).map_err(|e| IoError::file(&d, e))?;
            }
        }
        let topics = [
            roles.left.clone().unwrap_or_default(),
            roles.right.clone().unwrap_or_default(),
        ];
        let written: Vec<std::result::Result<WrittenPair, IoError>> = batch
            .par_iter()
            .enumerate()
            .map(|(k, (l, r))| {
                let mut names = [String::new(), String::new()];
                let mut sizes = [[0; 2]; 2];
                for (side, p) in [l, r].into_iter().enumerate() {
                    let (bytes, ext, size) = picture_file(p).map_err(|e| {
                        message_error(&self.bag, &topics[side], p.index, p.log_time_ns, e)
                    })?;
                    let name = format!("stereo/{}/{:06}.{ext}", ["left", "right"][side], first + k);
                    let path = self.dir.join(&name);
                    std::fs::write(&path, bytes).map_err(|e| IoError::file(&path, e))?;
                    names[side] = name;
                    sizes[side] = size;
                }
                progress.advance(1);
                Ok((names, sizes))
            })
            .collect();
        for ((l, r), w) in batch.iter().zip(written) {
            let ([left, right], sizes) = w?;
            for (side, p) in [l, r].into_iter().enumerate() {
                match self.sizes[side] {
                    None => self.sizes[side] = Some((sizes[side], p.index)),
                    Some((size, index)) if size != sizes[side] => {
                        return Err(message_error(
                            &self.bag,
                            &topics[side],
                            p.index,
                            p.log_time_ns,
                            format!(
                                "the image is {} x {}, message {index} was {} x {}: a camera's images must all be one size",
                                sizes[side][0], sizes[side][1], size[0], size[1]
                            ),
                        ));
                    }
                    Some(_) => {}
                }
            }
            self.stereo.push((
                l.stamp_ns,
                StereoEntry {
                    t_s: 0.0,
                    left,
                    right,
                },
            ));
        }
        Ok(())
    }
}

/// A `float32` as the decimal it was written from (2.1, not 2.0999999046325684).
fn decimal(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(x as f64)
}

/// A tf lookup as an error naming the bag.
fn mount(tf: &TfTree, bag: &Path, base: &str, frame: &str, what: &str) -> Result<Isometry3<f64>> {
    let pose = tf.lookup(base, frame).map_err(|e| {
        IoError::content(
            bag,
            format!(
                "{what} (frame `{frame}`) cannot be placed on the robot (--base-frame {base}): {e}"
            ),
        )
    })?;
    for (link, m, rad) in tf.moved_between(base, frame) {
        tracing::warn!(
            "{}: the /tf link to `{link}`, between `{base}` and {what}, moved {m:.3} m and {:.2} degrees during the bag; its first value is used",
            bag.display(),
            rad.to_degrees()
        );
    }
    Ok(pose)
}

impl Gathered {
    /// The run and summary from what was gathered, and the rig (when there are pictures).
    fn into_run(
        mut self,
        bag: &Bag,
        roles: &Roles,
        request: &BagRequest<'_>,
    ) -> Result<(RunDataset, BagSummary, Option<StereoRig>)> {
        let path = request.bag;
        let base = request.base_frame.as_str();
        for s in 0..2 {
            self.pairing.unmatched[s] += self.pairing.pending[s].len();
        }
        let stamps = self
            .odom
            .iter()
            .map(|o| o.0)
            .chain(self.truth.iter().map(|o| o.0))
            .chain(self.ranges.iter().map(|r| r.stamp_ns))
            .chain(self.stereo.iter().map(|e| e.0))
            .chain(self.scans.iter().map(|s| s.0));
        let (t0, t1) = stamps.fold((i64::MAX, i64::MIN), |(a, b), t| (a.min(t), b.max(t)));
        let seconds = |t: i64| (t - t0) as f64 * 1e-9;
        // The base frame's pose from a pose of another frame fixed on the robot.
        let mut to_base: BTreeMap<String, Isometry3<f64>> = BTreeMap::new();
        let mut in_base =
            |rows: &[(i64, String, Isometry3<f64>)], what: &str| -> Result<Vec<StampedPose>> {
                let mut out = Vec::with_capacity(rows.len());
                for (t, child, pose) in rows {
                    let child = child.trim_start_matches('/');
                    let pose = if child.is_empty() || child == base {
                        *pose
                    } else {
                        if !to_base.contains_key(child) {
                            let m = mount(&self.tf, path, child, base, what)?;
                            to_base.insert(child.to_owned(), m);
                        }
                        pose * to_base[child]
                    };
                    out.push(StampedPose {
                        t_s: seconds(*t),
                        pose: flat(&pose),
                    });
                }
                Ok(out)
            };
        let odometry = in_base(&self.odom, "the odometry's child frame")?;
        let truth = in_base(&self.truth, "the ground truth's child frame")?;
        let odometry = time_ordered(odometry);
        if odometry.dropped > 0 {
            tracing::warn!(
                "{}: {}: {} messages left out: their stamp goes back more than {} s (the first at t = {:.3} s)",
                path.display(),
                roles.odom,
                odometry.dropped,
                io::REORDER_TOLERANCE_S,
                odometry.first_dropped_s
            );
        }
        if odometry.reordered > 0 {
            tracing::warn!(
                "{}: {}: {} messages a little out of time order, re-ordered",
                path.display(),
                roles.odom,
                odometry.reordered
            );
        }
        if odometry.poses.is_empty() {
            return Err(topic_error(
                bag,
                format!("{} has no messages: a run needs odometry", roles.odom),
            ));
        }
        let mut truth = truth;
        truth.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        let (trajectory, frame) = anchored(
            &odometry.poses,
            &truth,
            roles.ground_truth.as_deref().unwrap_or(""),
        );

        let (layout, sonar, too_close, left_out) = self.sonar(bag, roles, request, &seconds)?;
        let lidar = self.lidar(request, &seconds)?;
        if let Some((_, _, l)) = &lidar {
            if l.scans_left_out > 0 {
                tracing::warn!(
                    "{}: {} laser scans of another field of view, beam count or mounting than the first left out",
                    request.bag.display(),
                    l.scans_left_out
                );
            }
        }

        // The rig.
        let (rig, rig_from, image_size) = if roles.left.is_some() && !self.stereo.is_empty() {
            let (rig, from) = self.rig(bag, roles, request)?;
            (Some(rig.0), Some(from), Some(rig.1))
        } else {
            if roles.left.is_some() {
                tracing::warn!(
                    "{}: no stereo pair matched: the run has no pictures",
                    path.display()
                );
            }
            (None, None, None)
        };
        let mut stereo: Vec<StereoEntry> = self
            .stereo
            .iter()
            .map(|(t, e)| StereoEntry {
                t_s: seconds(*t),
                ..e.clone()
            })
            .collect();
        stereo.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        let ground_truth = (!truth.is_empty()).then_some(truth);
        let against_truth = super::check_odometry_against_truth(
            (
                &trajectory,
                &format!("{}: the odometry ({})", path.display(), roles.odom),
            ),
            ground_truth.as_deref().map(|truth| {
                (
                    truth,
                    roles.ground_truth.as_deref().unwrap_or("the ground truth"),
                )
            }),
            "is it the ground truth's topic, or a simulator's odometry without noise?",
        );
        let ranging = match &lidar {
            Some((l, _, _)) => l.beam_layout(),
            None => layout.clone(),
        };
        let grid = GridConfig::fitted(ground_truth.as_deref().unwrap_or(&trajectory), &ranging)
            .unwrap_or_else(|| {
                tracing::warn!(
                    "{}: the run spans over 1 km: run.yaml keeps the paper's grid; set mapping.grid",
                    path.display()
                );
                GridConfig::default()
            });
        let summary = BagSummary {
            bag: path.display().to_string(),
            topics: Vec::new(),
            start_s: t0 as f64 * 1e-9,
            duration_s: (t1 - t0) as f64 * 1e-9,
            pairs: stereo.len(),
            unmatched_left: self.pairing.unmatched[0],
            unmatched_right: self.pairing.unmatched[1],
            sync_ms: request.sync_ms,
            image_size,
            rig_from,
            odometry_poses: trajectory.len(),
            odometry_reordered: odometry.reordered,
            odometry_dropped: odometry.dropped,
            frame: frame.clone(),
            stamps_from_log_time: self.stamps_from_log_time,
            readings: sonar.len(),
            echoes: sonar.iter().filter(|r| r.range_m.is_some()).count(),
            too_close,
            ranges_left_out: left_out,
            scans: self.scans.len(),
            lidar: lidar.as_ref().map(|l| l.2.clone()),
            ground_truth: ground_truth.is_some(),
            odometry_against_ground_truth: against_truth,
            grid_origin_m: grid.origin_m,
            grid_cells: [grid.width_cells, grid.height_cells],
        };
        if self.stamps_from_log_time > 0 {
            tracing::warn!(
                "{}: {} messages are stamped 0: timed by their log time instead",
                path.display(),
                self.stamps_from_log_time
            );
        }
        let run = RunDataset {
            meta: RunMeta {
                format: RUN_FORMAT.into(),
                robot: RobotDescription {
                    sonar: layout,
                    lidar: lidar.as_ref().map(|l| l.0.clone()),
                    ranging: None,
                    rig: rig.as_ref().map(|_| "rig.yaml".to_owned()),
                    robot_from_left: None,
                },
                world: None,
                mapping: Some(MappingConfig {
                    grid,
                    ..MappingConfig::default()
                }),
                notes: format!(
                    "imported from the ROS 2 bag {} by stereotag import; the run's frame is {frame}; times from stamp {:.9} s",
                    path.display(),
                    t0 as f64 * 1e-9
                ),
            },
            odometry: trajectory,
            sonar,
            stereo,
            ground_truth,
            lidar: lidar.map(|l| l.1).unwrap_or_default(),
        };
        Ok((run, summary, rig))
    }
}
