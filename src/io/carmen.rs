//! CARMEN log files, the format of the classic 2D SLAM data sets (Radish): `ODOM`, `FLASER`,
//! `RLASER` and `ROBOTLASER1` lines, plain or gzip (`.gz`). Other lines (`PARAM`, `NEFF`,
//! `SYNC`, comments) are counted and passed over.
//!
//! Line formats (CARMEN 0.7 logger):
//! - `ODOM x y theta tv rv accel ipc_timestamp host logger_timestamp`
//! - `FLASER n r1 .. rn x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp`
//!   (`RLASER` the same for the rear laser): `n` ranges over 180 degrees, right to left; `x y
//!   theta` the laser's pose when the log was made (the corrected pose in a `*-corrected` log).
//! - `ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode n r1 .. rn
//!   m e1 .. em laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv forward_safety
//!   side_safety turn_axis ipc_timestamp host logger_timestamp`

use super::IoError;
use crate::geometry::{Pose2, StampedPose};
use std::collections::BTreeMap;
use std::io::Read as _;
use std::path::Path;

/// One laser scan of a log.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Time (the IPC timestamp), seconds as logged.
    pub t_s: f64,
    /// Bearing of the first range in the robot frame, radians (0 ahead, positive left).
    pub start_rad: f64,
    /// Angle between two ranges, radians.
    pub step_rad: f64,
    /// The ranges, metres.
    pub ranges_m: Vec<f64>,
    /// The pose logged with the scan (the corrected pose in a `*-corrected` log).
    pub pose: Pose2,
    /// Where the laser sits on the robot (x forward, y left, heading).
    pub laser_in_robot: Pose2,
    /// The line it was read from.
    pub line: u64,
}

/// What a CARMEN log holds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CarmenLog {
    /// `ODOM` poses, as logged (times as logged).
    pub odometry: Vec<StampedPose>,
    /// Laser scans, front and rear, as logged.
    pub scans: Vec<LaserScan>,
    /// Lines of other kinds, by their first word, counted.
    pub other_lines: BTreeMap<String, usize>,
}

/// Reads a CARMEN log (gzip when its name ends in `.gz`).
pub fn read_carmen(path: &Path) -> Result<CarmenLog, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::file(path, e))?;
    let text = if path.extension().is_some_and(|e| e == "gz") {
        let mut text = String::new();
        flate2::read::MultiGzDecoder::new(bytes.as_slice())
            .read_to_string(&mut text)
            .map_err(|e| IoError::content(path, format!("cannot decompress the log: {e}")))?;
        text
    } else {
        String::from_utf8(bytes)
            .map_err(|_| IoError::content(path, "the log is not text (a gzip log needs .gz)"))?
    };
    parse_carmen(path, &text)
}

/// [`read_carmen`] of a log's text (`path` names it in errors).
pub fn parse_carmen(path: &Path, text: &str) -> Result<CarmenLog, IoError> {
    let mut log = CarmenLog::default();
    for (index, raw) in text.lines().enumerate() {
        let line = index as u64 + 1;
        let words: Vec<&str> = raw.split_whitespace().collect();
        let Some(&kind) = words.first() else {
            continue;
        };
        let fields = Fields {
            path,
            line,
            kind,
            words: &words[1..],
        };
        match kind {
            "ODOM" => {
                fields.need(
                    9,
                    "x y theta tv rv accel ipc_timestamp host logger_timestamp",
                )?;
                log.odometry.push(StampedPose {
                    t_s: fields.number(6)?,
                    pose: Pose2::new(fields.number(0)?, fields.number(1)?, fields.number(2)?),
                });
            }
            "FLASER" | "RLASER" => log.scans.push(old_laser(&fields, kind == "RLASER")?),
            "ROBOTLASER1" => log.scans.push(robot_laser(&fields)?),
            _ => *log.other_lines.entry(kind.to_string()).or_default() += 1,
        }
    }
    Ok(log)
}

/// The words of one line after its kind.
struct Fields<'a> {
    path: &'a Path,
    line: u64,
    kind: &'a str,
    words: &'a [&'a str],
}

impl Fields<'_> {
    /// An error unless there are at least `n` words, naming what they should be.
    fn need(&self, n: usize, what: &str) -> Result<(), IoError> {
        if self.words.len() < n {
            return Err(IoError::line(
                self.path,
                self.line,
                format!(
                    "{}: {} fields, {n} expected ({what})",
                    self.kind,
                    self.words.len()
                ),
            ));
        }
        Ok(())
    }

    /// Word `i` as a finite number.
    fn number(&self, i: usize) -> Result<f64, IoError> {
        let word = self.words.get(i).copied().unwrap_or("");
        word.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                IoError::line(
                    self.path,
                    self.line,
                    format!(
                        "{}: field {} `{word}` is not a finite number",
                        self.kind,
                        i + 1
                    ),
                )
            })
    }

    /// Word `i` as a count (at most `max`).
    fn count(&self, i: usize, max: usize) -> Result<usize, IoError> {
        let word = self.words.get(i).copied().unwrap_or("");
        word.parse::<usize>()
            .ok()
            .filter(|&n| n <= max)
            .ok_or_else(|| {
                IoError::line(
                    self.path,
                    self.line,
                    format!(
                        "{}: field {} `{word}` is not a count of readings",
                        self.kind,
                        i + 1
                    ),
                )
            })
    }

    /// `n` numbers from word `from`.
    fn numbers(&self, from: usize, n: usize) -> Result<Vec<f64>, IoError> {
        (from..from + n).map(|i| self.number(i)).collect()
    }
}

/// Largest number of ranges in one scan we take (a guard against a corrupt count).
const MAX_RANGES: usize = 100_000;

/// A `FLASER` or `RLASER` line: 180 degrees right to left (the rear laser turned round).
fn old_laser(f: &Fields<'_>, rear: bool) -> Result<LaserScan, IoError> {
    f.need(1, "the number of ranges")?;
    let n = f.count(0, MAX_RANGES)?;
    f.need(
        n + 10,
        &format!("{n} ranges, then x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp"),
    )?;
    // 181 or 361 ranges span 180 degrees end to end; 180 or 360 leave the last step out.
    let step_rad = std::f64::consts::PI / if n % 2 == 1 { n - 1 } else { n }.max(1) as f64;
    let turn = if rear { std::f64::consts::PI } else { 0.0 };
    Ok(LaserScan {
        t_s: f.number(n + 7)?,
        start_rad: -std::f64::consts::FRAC_PI_2 + turn,
        step_rad,
        ranges_m: f.numbers(1, n)?,
        pose: Pose2::new(f.number(n + 1)?, f.number(n + 2)?, f.number(n + 3)?),
        laser_in_robot: Pose2::new(0.0, 0.0, turn),
        line: f.line,
    })
}

/// A `ROBOTLASER1` line: the laser's own angles and its pose on the robot.
fn robot_laser(f: &Fields<'_>) -> Result<LaserScan, IoError> {
    f.need(
        8,
        "type start_angle fov resolution max_range accuracy remission_mode n",
    )?;
    let n = f.count(7, MAX_RANGES)?;
    f.need(n + 9, "the ranges, then the number of remissions")?;
    let m = f.count(8 + n, MAX_RANGES)?;
    let rest = 9 + n + m;
    f.need(
        rest + 14,
        "the ranges and remissions, then laser_x laser_y laser_theta robot_x robot_y robot_theta \
         tv rv forward_safety side_safety turn_axis ipc_timestamp host logger_timestamp",
    )?;
    let laser = Pose2::new(f.number(rest)?, f.number(rest + 1)?, f.number(rest + 2)?);
    let robot = Pose2::new(
        f.number(rest + 3)?,
        f.number(rest + 4)?,
        f.number(rest + 5)?,
    );
    Ok(LaserScan {
        t_s: f.number(rest + 11)?,
        start_rad: f.number(1)?,
        step_rad: f.number(3)?,
        ranges_m: f.numbers(8, n)?,
        pose: robot,
        laser_in_robot: robot.inverse().compose(&laser),
        line: f.line,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_each_kind_of_line_and_counts_the_others() {
        let text = "# a comment\nPARAM robot_length 0.5\n\
            ODOM 1.0 2.0 0.5 0.1 0.0 0.0 100.25 host 100.3\n\
            FLASER 3 1.0 2.0 3.0 1.0 2.0 0.5 1.1 2.1 0.5 100.5 host 100.6\n\
            RLASER 3 4.0 5.0 6.0 1.0 2.0 0.5 1.1 2.1 0.5 100.75 host 100.8\n\
            ROBOTLASER1 0 -1.5 3.0 1.5 80 0.01 0 3 1 2 3 0 1.2 2.0 0.0 1.0 2.0 0.0 0 0 0 0 0 101.0 host 101.1\n";
        let log = parse_carmen(Path::new("t.log"), text).unwrap();
        assert_eq!(log.odometry.len(), 1);
        assert_eq!(log.odometry[0].t_s, 100.25);
        assert_eq!(log.scans.len(), 3);
        let front = &log.scans[0];
        assert_eq!(front.ranges_m, [1.0, 2.0, 3.0]);
        assert!((front.step_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(front.t_s, 100.5);
        assert!((log.scans[1].laser_in_robot.theta.abs() - std::f64::consts::PI).abs() < 1e-12);
        let robot_laser = &log.scans[2];
        assert_eq!(robot_laser.t_s, 101.0);
        assert!((robot_laser.laser_in_robot.x - 0.2).abs() < 1e-9);
        assert_eq!(log.other_lines["PARAM"], 1);
        assert_eq!(log.other_lines["#"], 1);
    }

    #[test]
    fn a_short_line_is_an_error_naming_the_line_and_what_is_missing() {
        let err = parse_carmen(Path::new("t.log"), "ODOM 1 2 3\nFLASER 3 1 2\n").unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("t.log:1") && text.contains("ODOM: 3 fields, 9 expected"),
            "{text}"
        );
        let err = parse_carmen(Path::new("t.log"), "FLASER 3 1 2\n").unwrap_err();
        assert!(
            err.to_string().contains("FLASER: 3 fields, 13 expected"),
            "{err}"
        );
        let err = parse_carmen(Path::new("t.log"), "FLASER x 1 2\n").unwrap_err();
        assert!(err.to_string().contains("not a count"), "{err}");
    }
}
