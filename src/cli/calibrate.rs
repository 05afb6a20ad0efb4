use super::{Bars, UsageError};
use std::path::PathBuf;
use stereotag::camera::LensModel;
use stereotag::workflow::calibrate::{calibrate, CalibrateRequest, CalibrationInput};

/// Arguments of `stereotag calibrate`.
#[derive(Debug, clap::Args)]
pub struct Calibrate {
    /// Calibration target (Kalibr target YAML), e.g. calibration/targets/aprilgrid_6x6.yaml.
    #[arg(long)]
    target: PathBuf,
    /// One camera's images, a glob like 'cam0/*.png': calibrates that camera alone (writes
    /// camchain.yaml with cam0 only, opencv_camera.yaml and camera.yaml).
    #[arg(long, conflicts_with_all = ["left", "right", "corners_left", "corners_right", "fix_intrinsics", "rectify_pair"])]
    images: Option<String>,
    /// One camera's corners already detected (EuRoC / yac CSV, one file per view).
    #[arg(long, conflicts_with_all = ["left", "right", "corners_left", "corners_right", "fix_intrinsics", "rectify_pair", "images"])]
    corners: Option<PathBuf>,
    /// Left images, a glob like 'cam0/*.png' (pairs matched in sorted order).
    #[arg(long)]
    left: Option<String>,
    /// Right images, a glob.
    #[arg(long)]
    right: Option<String>,
    /// Directory of left corners already detected (EuRoC / yac CSV, one file per view).
    #[arg(long)]
    corners_left: Option<PathBuf>,
    /// Directory of right corners already detected.
    #[arg(long)]
    corners_right: Option<PathBuf>,
    /// Image size WIDTHxHEIGHT (needed with corner files without --fix-intrinsics; images give it).
    #[arg(long)]
    resolution: Option<String>,
    /// Lens model of the free calibration: radtan (Kalibr pinhole-radtan), or for fisheye
    /// lenses equidistant (pinhole-equi), ds (double sphere, ds-none) or eucm (extended unified,
    /// eucm-none).
    #[arg(long, value_enum, default_value_t = Model::Radtan)]
    model: Model,
    /// Keep this rig file's intrinsics and distortion; solve right_from_left only.
    #[arg(long, value_name = "RIG")]
    fix_intrinsics: Option<PathBuf>,
    /// Output directory: camchain.yaml (Kalibr), opencv_stereo.yaml (OpenCV), left.yaml and
    /// right.yaml (ROS camera_info), report.json, calibration.rrd, and rectified.png with
    /// --rectify-pair.
    #[arg(long)]
    out: PathBuf,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
    /// Write the rig even when the calibration fails its checks (a principal point outside the
    /// image, an undetermined or disagreeing focal length, over 20% outliers, a camera with every
    /// corner rejected); camchain.yaml then says so in its first lines.
    #[arg(long)]
    force_write: bool,
    /// A raw stereo pair (LEFT RIGHT) to rectify with the result: writes rectified.png, the pair
    /// side by side with epipolar lines every 32 rows.
    #[arg(long, num_args = 2, value_names = ["LEFT", "RIGHT"])]
    rectify_pair: Vec<PathBuf>,
    #[command(flatten)]
    rerun: super::RerunArgs,
}

/// Lens models on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Model {
    /// Radial-tangential k1, k2, p1, p2.
    Radtan,
    /// Equidistant (Kannala-Brandt) k1..k4, for fisheye lenses.
    Equidistant,
    /// Double sphere xi, alpha (Kalibr ds-none), for fisheye lenses.
    Ds,
    /// Extended unified alpha, beta (Kalibr eucm-none), for fisheye lenses.
    Eucm,
}

impl Calibrate {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let input = match (
            &self.corners_left,
            &self.corners_right,
            &self.left,
            &self.right,
        ) {
            _ if let Some(images) = &self.images => CalibrationInput::CameraImages(images),
            _ if let Some(dir) = &self.corners => CalibrationInput::CameraCorners(dir),
            (Some(cl), Some(cr), _, _) => CalibrationInput::Corners {
                left: cl,
                right: cr,
            },
            (_, _, Some(gl), Some(gr)) => CalibrationInput::Images {
                left: gl,
                right: gr,
            },
            _ => {
                return Err(UsageError(
                    "pass --left GLOB --right GLOB (a rig's images), --images GLOB (one camera's), or --corners-left DIR --corners-right DIR / --corners DIR (EuRoC CSV)".into(),
                )
                .into())
            }
        };
        // Fixed intrinsics give the resolution; else --resolution, else the images.
        let resolution = match (&self.fix_intrinsics, &self.resolution) {
            (None, Some(r)) => Some(parse_resolution(r)?),
            _ => None,
        };
        let output = calibrate(
            &CalibrateRequest {
                target: &self.target,
                input,
                resolution,
                model: match self.model {
                    Model::Radtan => LensModel::Radtan,
                    Model::Equidistant => LensModel::Equidistant,
                    Model::Ds => LensModel::DoubleSphere,
                    Model::Eucm => LensModel::Eucm,
                },
                fix_intrinsics: self.fix_intrinsics.as_deref(),
                out: &self.out,
                force: self.force,
                force_write: self.force_write,
                rectify_pair: match self.rectify_pair.as_slice() {
                    [l, r] => Some((l.as_path(), r.as_path())),
                    _ => None,
                },
                recording: self.rerun.request()?,
            },
            &Bars::new(quiet),
        )?;
        let calib = &output.calibration;
        if calib.stereo {
            let t = calib.rig.right_from_left.translation.vector;
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
        } else {
            let c = &calib.rig.left;
            let sigma = |k: &str| calib.sigmas.get(k).copied().unwrap_or(f64::NAN);
            tracing::info!(
                "{} views, {} outliers left out; RMS {:.3} px; fx {:.2} ± {:.2}, fy {:.2} ± {:.2}, cx {:.2} ± {:.2}, cy {:.2} ± {:.2} px",
                calib.views.len(),
                calib.outliers.len(),
                calib.rms_px,
                c.fx,
                sigma("camera.fx"),
                c.fy,
                sigma("camera.fy"),
                c.cx,
                sigma("camera.cx"),
                c.cy,
                sigma("camera.cy"),
            );
        }
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
