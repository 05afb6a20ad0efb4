use super::UsageError;
use std::path::PathBuf;
use stereotag::calibrate::{calibrate_stereo, CalibConfig};
use stereotag::io::{self, OutputDir, Target};

/// Arguments of `stereotag calibrate`.
#[derive(Debug, clap::Args)]
pub struct Calibrate {
    /// Calibration target (Kalibr target YAML), e.g. calibration/targets/aprilgrid_6x6.yaml.
    #[arg(long)]
    target: PathBuf,
    /// Left images (a glob). Corner detection in images is not built yet: use --corners-left.
    #[arg(long)]
    left: Option<String>,
    /// Right images (a glob).
    #[arg(long)]
    right: Option<String>,
    /// Directory of left corners already detected (EuRoC / yac CSV, one file per view).
    #[arg(long)]
    corners_left: Option<PathBuf>,
    /// Directory of right corners already detected.
    #[arg(long)]
    corners_right: Option<PathBuf>,
    /// Image size WIDTHxHEIGHT (needed without --fix-intrinsics).
    #[arg(long)]
    resolution: Option<String>,
    /// Keep this rig file's intrinsics and distortion; solve right_from_left only.
    #[arg(long, value_name = "RIG")]
    fix_intrinsics: Option<PathBuf>,
    /// Output directory: camchain.yaml, opencv_stereo.yaml, left.yaml, right.yaml, report.json,
    /// calibration.rrd.
    #[arg(long)]
    out: PathBuf,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    /// A raw stereo pair (LEFT RIGHT) to rectify with the result: writes rectified.png, the pair
    /// side by side with epipolar lines every 32 rows.
    #[arg(long, num_args = 2, value_names = ["LEFT", "RIGHT"])]
    rectify_pair: Vec<PathBuf>,
    #[command(flatten)]
    rerun: super::RerunArgs,
}

impl Calibrate {
    pub fn run(&self) -> anyhow::Result<()> {
        let started = std::time::Instant::now();
        let target = io::load_target(&self.target)?;
        let (Some(cl), Some(cr)) = (&self.corners_left, &self.corners_right) else {
            let what = if self.left.is_some() || self.right.is_some() {
                "corner detection in images (--left/--right) is not built yet"
            } else {
                "no input"
            };
            return Err(UsageError(format!(
                "{what}: pass --corners-left DIR --corners-right DIR with corners already detected (EuRoC CSV)"
            ))
            .into());
        };
        let left = io::load_corner_csvs(cl)?;
        let right = io::load_corner_csvs(cr)?;
        let mut config = CalibConfig::default();
        let resolution = match (&self.fix_intrinsics, &self.resolution) {
            (Some(rig_path), _) => {
                let rig = io::load_rig(rig_path)?;
                let res = (rig.left.width, rig.left.height);
                config.fixed_intrinsics = Some((rig.left, rig.right));
                res
            }
            (None, Some(r)) => parse_resolution(r)?,
            (None, None) => {
                return Err(UsageError(
                    "--resolution WIDTHxHEIGHT is needed when the intrinsics are not fixed".into(),
                )
                .into())
            }
        };
        let calib = calibrate_stereo(&left, &right, resolution, &config)?;
        let dir = OutputDir::create(&self.out, self.force)?;
        super::rig::write_rig_exports(&dir, &calib.rig)?;
        let t = calib.rig.right_from_left.translation.vector;
        let (roll, pitch, yaw) = calib.rig.right_from_left.rotation.euler_angles();
        let intr = |c: &stereotag::camera::Camera| serde_json::json!({"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "distortion": format!("{:?}", c.distortion)});
        let report = serde_json::json!({
            "metrics": {
                "rms_px": calib.rms_px,
                "rms_left_px": calib.rms_left_px,
                "rms_right_px": calib.rms_right_px,
                "views_used": calib.views.len(),
                "outliers": calib.outliers.len(),
                "baseline_m": t.norm(),
                "epipolar_error_px": calib.epipolar_error_px,
                "coverage_left": calib.coverage.0,
                "coverage_right": calib.coverage.1,
            },
            "timings_s": {"total": started.elapsed().as_secs_f64()},
            "target": serde_json::to_value(&target)?,
            "intrinsics_fixed": self.fix_intrinsics.is_some(),
            "left": intr(&calib.rig.left),
            "right": intr(&calib.rig.right),
            "right_from_left": {"t_m": [t.x, t.y, t.z], "roll_pitch_yaw_rad": [roll, pitch, yaw]},
            "sigmas": calib.sigmas,
            "per_view": calib.views,
            "outliers": calib.outliers,
            "coverage_counts": {"cols": 8, "rows": 6, "left": calib.coverage_counts.0, "right": calib.coverage_counts.1},
            "warnings": calib.warnings,
        });
        io::save_json(&dir.path("report.json"), &report)?;
        let rectified = match self.rectify_pair.as_slice() {
            [l, r] => {
                let img = rectified_pair(&calib.rig, &io::load_gray(l)?, &io::load_gray(r)?);
                img.save(dir.path("rectified.png"))
                    .map_err(|e| anyhow::anyhow!("writing rectified.png: {e}"))?;
                Some(img)
            }
            _ => None,
        };
        let recorder = super::recorder(
            &self.rerun,
            "stereotag calibration",
            &dir.path("calibration.rrd"),
        )?;
        #[cfg(feature = "rerun")]
        if let Some(rec) = recorder {
            let md = format!(
                "# stereotag calibration\n\n```json\n{}\n```\n",
                serde_json::to_string_pretty(&report["metrics"])?
            );
            stereotag::viz::log_calibration(&rec, &calib, &md, rectified.as_ref())?;
            rec.finish()?;
        }
        #[cfg(not(feature = "rerun"))]
        let _ = (recorder, rectified);
        dir.commit()?;
        tracing::info!(
            "{} views, {} outliers left out; RMS {:.3} px (left {:.3}, right {:.3}); baseline {:.2} mm ± {:.2}",
            calib.views.len(),
            calib.outliers.len(),
            calib.rms_px,
            calib.rms_left_px,
            calib.rms_right_px,
            t.norm() * 1e3,
            calib.sigmas.get("baseline_m").copied().unwrap_or(f64::NAN) * 1e3
        );
        for o in &calib.outliers {
            tracing::info!(
                "  outlier: view {} {} corner {}: {:.2} px",
                o.view,
                o.camera,
                o.id,
                o.error_px
            );
        }
        for w in &calib.warnings {
            tracing::warn!("{w}");
        }
        if let Target::Checkerboard { .. } = target {
            tracing::debug!("checkerboard target");
        }
        Ok(())
    }
}

fn parse_resolution(s: &str) -> Result<(u32, u32), UsageError> {
    let bad = || {
        UsageError(format!(
            "--resolution {s}: expected WIDTHxHEIGHT, e.g. 752x480"
        ))
    };
    let (w, h) = s.split_once('x').ok_or_else(bad)?;
    let (w, h) = (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
    if w == 0 || h == 0 {
        return Err(bad());
    }
    Ok((w, h))
}

/// Rows between the epipolar lines drawn on `rectified.png`.
const EPIPOLAR_LINE_ROWS: u32 = 32;

/// Both images rectified, side by side, with horizontal lines: corresponding points of a good
/// calibration lie on the same line.
fn rectified_pair(
    rig: &stereotag::camera::StereoRig,
    left: &image::GrayImage,
    right: &image::GrayImage,
) -> image::GrayImage {
    let rect = rig.rectify();
    let l = rect.rectify_image(&rig.left, &rect.left_rotation, left);
    let r = rect.rectify_image(&rig.right, &rect.right_rotation, right);
    let (w, h) = (l.width() + r.width(), l.height().max(r.height()));
    let mut out = image::GrayImage::new(w, h);
    image::imageops::replace(&mut out, &l, 0, 0);
    image::imageops::replace(&mut out, &r, l.width() as i64, 0);
    for y in (EPIPOLAR_LINE_ROWS / 2..h).step_by(EPIPOLAR_LINE_ROWS as usize) {
        for x in 0..w {
            out.put_pixel(x, y, image::Luma([255]));
        }
    }
    out
}
