//! The run dataset directory (DESIGN.md): `run.yaml`, `odometry.csv`, `sonar.csv`, `stereo.csv`,
//! `ground_truth.csv`, and `lidar.csv` for a robot with a laser.

use super::{csv_rows, parse_yaml, read_text, to_yaml, write_file, IoError};
use crate::dataset::{LidarScan, RunDataset, RunMeta, StereoEntry, RUN_FORMAT};
use crate::geometry::Pose2;
use crate::geometry::StampedPose;
use crate::sonar::SonarReading;
use std::fmt::Write as _;
use std::path::Path;

const POSE_HEADER: &str = "t_s,x_m,y_m,theta_rad";
const SONAR_HEADER: &str = "t_s,sensor,range_m";
const STEREO_HEADER: &str = "t_s,left,right";

fn number(path: &Path, line: u64, name: &str, field: &str) -> Result<f64, IoError> {
    match field.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(IoError::line(
            path,
            line,
            format!("{name} is {v}; expected a finite number"),
        )),
        Err(_) => Err(IoError::line(
            path,
            line,
            format!("{name} `{field}` is not a number"),
        )),
    }
}

/// How far back in time a row may go, seconds, and still be taken (re-ordered, with a
/// warning): real logs interleave their sensors' rows a little out of order; a larger jump is a
/// broken file and an error.
pub const REORDER_TOLERANCE_S: f64 = 0.5;

/// The time order of a file's rows as they are read.
struct TimeOrder<'a> {
    path: &'a Path,
    latest: f64,
    late_rows: usize,
    first_late_line: u64,
    most_late_s: f64,
}

impl<'a> TimeOrder<'a> {
    fn new(path: &'a Path) -> Self {
        Self {
            path,
            latest: f64::NEG_INFINITY,
            late_rows: 0,
            first_late_line: 0,
            most_late_s: 0.0,
        }
    }

    /// Takes the time of the row at `line`: an error when it goes back more than the tolerance.
    fn check(&mut self, line: u64, t: f64) -> Result<(), IoError> {
        if t >= self.latest {
            self.latest = t;
            return Ok(());
        }
        let late = self.latest - t;
        if late > REORDER_TOLERANCE_S {
            return Err(IoError::line(
                self.path,
                line,
                format!(
                    "time {t} s goes backwards by {late:.3} s (an earlier row is at {} s); rows \
                     out of order by up to {REORDER_TOLERANCE_S} s are re-ordered, larger jumps \
                     are errors",
                    self.latest
                ),
            ));
        }
        if self.late_rows == 0 {
            self.first_late_line = line;
        }
        self.late_rows += 1;
        self.most_late_s = self.most_late_s.max(late);
        Ok(())
    }

    /// Puts `rows` in time order (stable) when some were late, saying so once.
    fn finish<T>(self, mut rows: Vec<T>, time: impl Fn(&T) -> f64) -> Vec<T> {
        if self.late_rows > 0 {
            tracing::warn!(
                "{}: {} rows out of time order by up to {:.3} s (the first at line {}) re-ordered",
                self.path.display(),
                self.late_rows,
                self.most_late_s,
                self.first_late_line
            );
            rows.sort_by(|a, b| time(a).total_cmp(&time(b)));
        }
        rows
    }
}

/// Reads a pose CSV (`t_s,x_m,y_m,theta_rad`, time-ordered), as odometry.csv and ground_truth.csv.
pub fn read_poses(path: &Path) -> Result<Vec<StampedPose>, IoError> {
    let text = read_text(path)?;
    let mut order = TimeOrder::new(path);
    let rows = csv_rows(path, &text, POSE_HEADER)?
        .into_iter()
        .map(|(line, f)| {
            let t = number(path, line, "t_s", f[0])?;
            order.check(line, t)?;
            let x = number(path, line, "x_m", f[1])?;
            let y = number(path, line, "y_m", f[2])?;
            let th = number(path, line, "theta_rad", f[3])?;
            Ok(StampedPose {
                t_s: t,
                pose: Pose2::new(x, y, th),
            })
        })
        .collect::<Result<Vec<_>, IoError>>()?;
    Ok(order.finish(rows, |p| p.t_s))
}

fn read_sonar(path: &Path, sensors: usize) -> Result<Vec<SonarReading>, IoError> {
    let text = read_text(path)?;
    let mut order = TimeOrder::new(path);
    let rows = csv_rows(path, &text, SONAR_HEADER)?
        .into_iter()
        .map(|(line, f)| {
            let t = number(path, line, "t_s", f[0])?;
            order.check(line, t)?;
            let sensor: usize = f[1].parse().map_err(|_| {
                IoError::line(path, line, format!("sensor `{}` is not a sensor index (0, 1, ...)", f[1]))
            })?;
            if sensor >= sensors {
                return Err(IoError::line(
                    path,
                    line,
                    if sensors == 0 {
                        format!("sensor {sensor}: run.yaml's sonar layout has no sensors (a run without sonar has no readings)")
                    } else {
                        format!("unknown sensor {sensor}: run.yaml's sonar layout has {sensors} sensors (0..{})", sensors - 1)
                    },
                ));
            }
            let range_m = if f[2].is_empty() {
                None
            } else {
                let r = number(path, line, "range_m", f[2])?;
                if r < 0.0 {
                    return Err(IoError::line(path, line, format!("range_m is {r}; expected >= 0 or empty for no echo")));
                }
                Some(r)
            };
            Ok(SonarReading { t_s: t, sensor, range_m })
        })
        .collect::<Result<Vec<_>, IoError>>()?;
    Ok(order.finish(rows, |r| r.t_s))
}

fn read_stereo(path: &Path) -> Result<Vec<StereoEntry>, IoError> {
    let text = read_text(path)?;
    let mut order = TimeOrder::new(path);
    let rows = csv_rows(path, &text, STEREO_HEADER)?
        .into_iter()
        .map(|(line, f)| {
            let t = number(path, line, "t_s", f[0])?;
            order.check(line, t)?;
            if f[1].is_empty() || f[2].is_empty() {
                return Err(IoError::line(
                    path,
                    line,
                    "left and right image paths must not be empty",
                ));
            }
            Ok(StereoEntry {
                t_s: t,
                left: f[1].to_string(),
                right: f[2].to_string(),
            })
        })
        .collect::<Result<Vec<_>, IoError>>()?;
    Ok(order.finish(rows, |e| e.t_s))
}

/// The header of `lidar.csv` for a laser of `beams` beams: `t_s,r0,r1,...`.
fn lidar_header(beams: usize) -> String {
    let mut h = String::from("t_s");
    for k in 0..beams {
        let _ = write!(h, ",r{k}");
    }
    h
}

/// Reads `lidar.csv`: `t_s,r0,...,r<beams-1>`, one scan a row, time-ordered; an empty range is no
/// return. Ranges below `range_min_m` or at or beyond `range_max_m` are no returns too.
fn read_lidar(
    path: &Path,
    lidar: &crate::dataset::LidarDescription,
) -> Result<Vec<LidarScan>, IoError> {
    let text = read_text(path)?;
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, l)| l.trim()).unwrap_or("");
    if header != lidar_header(lidar.beams) {
        let columns = header.split(',').count();
        return Err(IoError::line(
            path,
            1,
            format!(
                "expected the header `t_s,r0,...,r{}` (run.yaml's lidar has {} beams), found {} columns starting `{}`",
                lidar.beams - 1,
                lidar.beams,
                columns,
                header.chars().take(40).collect::<String>()
            ),
        ));
    }
    let mut order = TimeOrder::new(path);
    let mut scans = Vec::new();
    for (i, line) in lines {
        let (line_no, line) = (i as u64 + 1, line.trim());
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != lidar.beams + 1 {
            return Err(IoError::line(
                path,
                line_no,
                format!(
                    "expected {} fields (the time and {} ranges), found {}",
                    lidar.beams + 1,
                    lidar.beams,
                    fields.len()
                ),
            ));
        }
        let t = number(path, line_no, "t_s", fields[0])?;
        order.check(line_no, t)?;
        let ranges_m = fields[1..]
            .iter()
            .enumerate()
            .map(|(k, f)| {
                if f.is_empty() {
                    return Ok(None);
                }
                let r = number(path, line_no, &format!("r{k}"), f)?;
                if r < 0.0 {
                    return Err(IoError::line(
                        path,
                        line_no,
                        format!("r{k} is {r}; expected >= 0 or empty for no return"),
                    ));
                }
                Ok((r >= lidar.range_min_m && r < lidar.range_max_m).then_some(r))
            })
            .collect::<Result<Vec<_>, IoError>>()?;
        scans.push(LidarScan { t_s: t, ranges_m });
    }
    Ok(order.finish(scans, |s| s.t_s))
}

/// Reads a run dataset directory.
pub fn load_run(dir: &Path) -> Result<RunDataset, IoError> {
    if !dir.is_dir() {
        return Err(IoError::content(
            dir,
            "not a run directory (expected run.yaml, odometry.csv, sonar.csv)",
        ));
    }
    let meta_path = dir.join("run.yaml");
    let meta: RunMeta = parse_yaml(&meta_path, &read_text(&meta_path)?)?;
    if let Some(m) = &meta.mapping {
        super::check_mapping(&meta_path, m, "`mapping`: ")?;
    }
    if meta.format != RUN_FORMAT {
        return Err(IoError::content(
            &meta_path,
            format!(
                "format is `{}`; this stereotag reads `{RUN_FORMAT}`",
                meta.format
            ),
        ));
    }
    let layout = &meta.robot.sonar;
    if !(layout.cone_rad > 0.0
        && layout.cone_rad < std::f64::consts::PI
        && layout.max_range_m > 0.0
        && layout.min_range_m >= 0.0
        && layout.min_range_m < layout.max_range_m)
        || layout
            .sensors
            .iter()
            .any(|s| !(s.x_m.is_finite() && s.y_m.is_finite() && s.bearing_rad.is_finite()))
    {
        return Err(IoError::content(
            &meta_path,
            "robot.sonar: cone_rad must be in (0, pi), max_range_m positive, min_range_m (if given) \
             from 0 up to max_range_m, sensor poses finite",
        ));
    }
    if let Some(lidar) = &meta.robot.lidar {
        lidar
            .check()
            .map_err(|e| IoError::content(&meta_path, format!("robot.lidar: {e}")))?;
    } else if meta.robot.ranging == Some(crate::dataset::RangeSensor::Lidar) {
        return Err(IoError::content(
            &meta_path,
            "robot.ranging is lidar but robot.lidar describes no laser",
        ));
    }
    let odometry = read_poses(&dir.join("odometry.csv"))?;
    if odometry.is_empty() {
        return Err(IoError::content(
            &dir.join("odometry.csv"),
            "no poses: the run needs odometry",
        ));
    }
    let sonar = read_sonar(&dir.join("sonar.csv"), meta.robot.sonar.sensors.len())?;
    let stereo_path = dir.join("stereo.csv");
    let stereo = if stereo_path.exists() {
        read_stereo(&stereo_path)?
    } else {
        Vec::new()
    };
    let gt_path = dir.join("ground_truth.csv");
    let ground_truth = if gt_path.exists() {
        Some(read_poses(&gt_path)?)
    } else {
        None
    };
    let lidar = match &meta.robot.lidar {
        Some(l) => read_lidar(&dir.join("lidar.csv"), l)?,
        None => Vec::new(),
    };
    Ok(RunDataset {
        meta,
        odometry,
        sonar,
        stereo,
        ground_truth,
        lidar,
    })
}

fn poses_csv(poses: &[StampedPose]) -> String {
    let mut s = format!("{POSE_HEADER}\n");
    for p in poses {
        let _ = writeln!(
            s,
            "{:.4},{:.5},{:.5},{:.6}",
            p.t_s, p.pose.x, p.pose.y, p.pose.theta
        );
    }
    s
}

/// Writes a run dataset into `dir` (which must exist).
pub fn save_run(dir: &Path, run: &RunDataset) -> Result<(), IoError> {
    let meta_path = dir.join("run.yaml");
    write_file(&meta_path, to_yaml(&meta_path, &run.meta)?.as_bytes())?;
    write_file(
        &dir.join("odometry.csv"),
        poses_csv(&run.odometry).as_bytes(),
    )?;
    let mut s = format!("{SONAR_HEADER}\n");
    for r in &run.sonar {
        match r.range_m {
            Some(m) => writeln!(s, "{:.4},{},{:.4}", r.t_s, r.sensor, m),
            None => writeln!(s, "{:.4},{},", r.t_s, r.sensor),
        }
        .ok();
    }
    write_file(&dir.join("sonar.csv"), s.as_bytes())?;
    let mut s = format!("{STEREO_HEADER}\n");
    for e in &run.stereo {
        let _ = writeln!(s, "{:.4},{},{}", e.t_s, e.left, e.right);
    }
    write_file(&dir.join("stereo.csv"), s.as_bytes())?;
    if let Some(gt) = &run.ground_truth {
        write_file(&dir.join("ground_truth.csv"), poses_csv(gt).as_bytes())?;
    }
    if let Some(lidar) = &run.meta.robot.lidar {
        let mut s = lidar_header(lidar.beams);
        s.push('\n');
        for scan in &run.lidar {
            let _ = write!(s, "{:.4}", scan.t_s);
            for r in &scan.ranges_m {
                match r {
                    Some(m) => write!(s, ",{m:.3}"),
                    None => write!(s, ","),
                }
                .ok();
            }
            s.push('\n');
        }
        write_file(&dir.join("lidar.csv"), s.as_bytes())?;
    }
    Ok(())
}

/// Reads the UCI wall-following sonar file (`S1..S24,OUTPUT` rows): one range vector per row.
pub fn read_uci_sonar_ring(path: &Path) -> Result<Vec<Vec<f64>>, IoError> {
    let text = read_text(path)?;
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('S') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        let ranges = fields
            .iter()
            .take(fields.len().saturating_sub(1))
            .map(|f| number(path, i as u64 + 1, "range", f.trim()))
            .collect::<Result<Vec<f64>, _>>()?;
        rows.push(ranges);
    }
    Ok(rows)
}
