use super::UsageError;
use std::path::PathBuf;
use stereotag::calib::{calibrate_stereo, CalibConfig};
use stereotag::io::{self, OutputDir, Target};

/// Arguments of `stereotag calibrate`.
#[derive(Debug, clap::Args)]
pub struct Calibrate {
    /// Calibration target (Kalibr target YAML), e.g. calibration/targets/aprilgrid_6x6.yaml.
    #[arg(long)]
    target: PathBuf,
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
    /// Lens model of the free calibration: radtan (Kalibr pinhole-radtan) or equidistant
    /// (pinhole-equi, for fisheye lenses).
    #[arg(long, value_enum, default_value_t = Model::Radtan)]
    model: Model,
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

/// Lens models on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Model {
    /// Radial-tangential k1, k2, p1, p2.
    Radtan,
    /// Equidistant (Kannala-Brandt) k1..k4, for fisheye lenses.
    Equidistant,
}

impl Calibrate {
    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let started = std::time::Instant::now();
        let target = io::load_target(&self.target)?;
        let mut view_images = ViewImages::new();
        let (left, right, image_size, misses) = match (
            &self.corners_left,
            &self.corners_right,
            &self.left,
            &self.right,
        ) {
            (Some(cl), Some(cr), _, _) => (
                io::load_corner_csvs(cl)?,
                io::load_corner_csvs(cr)?,
                None,
                Vec::new(),
            ),
            (_, _, Some(gl), Some(gr)) => {
                let d = detect_views(&target, gl, gr, quiet, !self.rerun.no_rerun)?;
                view_images = d.images;
                (d.left, d.right, Some(d.resolution), d.misses)
            }
            _ => {
                return Err(UsageError(
                    "pass --left GLOB --right GLOB (images) or --corners-left DIR --corners-right DIR (EuRoC CSV)".into(),
                )
                .into())
            }
        };
        let detect_s = started.elapsed().as_secs_f64();
        let mut config = CalibConfig {
            model: match self.model {
                Model::Radtan => stereotag::calib::LensModel::Radtan,
                Model::Equidistant => stereotag::calib::LensModel::Equidistant,
            },
            ..CalibConfig::default()
        };
        let resolution = match (&self.fix_intrinsics, &self.resolution, image_size) {
            (Some(rig_path), _, _) => {
                let rig = io::load_rig(rig_path)?;
                let res = (rig.left.width, rig.left.height);
                if image_size.is_some_and(|s| s != res) {
                    let (w, h) = image_size.unwrap_or_default();
                    return Err(UsageError(format!(
                        "{}: the rig is {}x{} but the images are {w}x{h}",
                        rig_path.display(),
                        res.0,
                        res.1
                    ))
                    .into());
                }
                config.fixed_intrinsics = Some((rig.left, rig.right));
                res
            }
            (None, Some(r), _) => parse_resolution(r)?,
            (None, None, Some(size)) => size,
            (None, None, None) => {
                return Err(UsageError(
                    "--resolution WIDTHxHEIGHT is needed with corner files when the intrinsics are not fixed".into(),
                )
                .into())
            }
        };
        let calib = calibrate_stereo(&left, &right, resolution, &config).inspect_err(|e| {
            if matches!(e, stereotag::calib::CalibError::TooFewViews { .. }) {
                for m in &misses {
                    tracing::warn!("no usable board in {m}");
                }
            }
        })?;
        let solve_s = started.elapsed().as_secs_f64() - detect_s;
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
            "timings_s": {"read_and_detect": detect_s, "solve": solve_s, "total": started.elapsed().as_secs_f64()},
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
            super::Recording::Calibration,
            &dir.path("calibration.rrd"),
        )?;
        #[cfg(feature = "rerun")]
        if let Some(rec) = recorder {
            let md = format!(
                "# stereotag calibration\n\n```json\n{}\n```\n",
                serde_json::to_string_pretty(&report["metrics"])?
            );
            stereotag::viz::log_calibration(&rec, &calib, &md, rectified.as_ref(), &view_images)?;
            rec.finish()?;
        }
        #[cfg(not(feature = "rerun"))]
        let _ = (recorder, rectified, view_images);
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

/// Files matching a glob with `*` in its last component, sorted.
fn glob(pattern: &str) -> Result<Vec<PathBuf>, UsageError> {
    let path = std::path::Path::new(pattern);
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let parts: Vec<&str> = name.split('*').collect();
    let matches = |s: &str| {
        let (first, last) = (parts[0], parts[parts.len() - 1]);
        if parts.len() == 1 {
            return s == first;
        }
        if !s.starts_with(first) || !s.ends_with(last) || s.len() < first.len() + last.len() {
            return false;
        }
        let mut rest = &s[first.len()..s.len() - last.len()];
        for p in &parts[1..parts.len() - 1] {
            match rest.find(p) {
                Some(i) => rest = &rest[i + p.len()..],
                None => return false,
            }
        }
        true
    };
    let entries = std::fs::read_dir(dir)
        .map_err(|e| UsageError(format!("{pattern}: {}: {e}", dir.display())))?;
    let mut out: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .filter(|e| matches(&e.file_name().to_string_lossy()))
        .map(|e| e.path())
        .collect();
    out.sort();
    if out.is_empty() {
        return Err(UsageError(format!("{pattern}: no file matches")));
    }
    Ok(out)
}

/// Each view's left and right images as JPEG, for the recording.
type ViewImages = std::collections::BTreeMap<String, (Vec<u8>, Vec<u8>)>;

/// Corners detected in the images of both cameras, with the image size, why views were lost and
/// the images for the recording.
struct Detected {
    left: stereotag::calib::ViewCorners,
    right: stereotag::calib::ViewCorners,
    resolution: (u32, u32),
    misses: Vec<String>,
    images: ViewImages,
}

/// Detects the target's corners in every left and right image, pairs in parallel.
fn detect_views(
    target: &Target,
    left: &str,
    right: &str,
    quiet: bool,
    keep_images: bool,
) -> anyhow::Result<Detected> {
    use rayon::prelude::*;
    use stereotag::calib::{aprilgrid_corners, chessboard_board_corners, Corner};
    use stereotag::visual::tags::TagDetector;
    let (lf, rf) = (glob(left)?, glob(right)?);
    if lf.len() != rf.len() {
        return Err(UsageError(format!(
            "{} left images but {} right images: the pairs must match",
            lf.len(),
            rf.len()
        ))
        .into());
    }
    let bar = super::progress(lf.len() as u64, "detect", quiet);
    // One AprilGrid detector per worker thread (the C detector is not shared).
    let init = || match target {
        Target::Aprilgrid(_) => stereotag::visual::tags::AprilGridMultiScale::new().map(Some),
        Target::Checkerboard(_) => Ok(None),
    };
    type Found = (Vec<Corner>, Option<String>);
    let detect = |grid: &mut Option<stereotag::visual::tags::AprilGridMultiScale>,
                  image: &image::GrayImage|
     -> anyhow::Result<Found> {
        Ok(match (target, grid) {
            (Target::Aprilgrid(g), Some(detector)) => {
                let found = detector.detect(image)?;
                let points = stereotag::calib::chessboard::refine_aprilgrid(
                    image,
                    &found,
                    g.tag_cols,
                    g.tag_spacing,
                );
                let corners =
                    aprilgrid_corners(&points, g.tag_cols, g.tag_rows, g.tag_size, g.tag_spacing);
                let note = format!("{} AprilGrid tags", found.len());
                (corners, Some(note).filter(|_| found.is_empty()))
            }
            (Target::Checkerboard(c), _) => {
                match stereotag::calib::chessboard::detect_chessboard(
                    image,
                    c.target_cols,
                    c.target_rows,
                ) {
                    Ok(px) => (
                        chessboard_board_corners(
                            &px,
                            c.target_cols,
                            c.col_spacing_m,
                            c.row_spacing_m,
                        ),
                        None,
                    ),
                    Err(miss) => (Vec::new(), Some(miss.to_string())),
                }
            }
            (Target::Aprilgrid(_), None) => {
                anyhow::bail!("no AprilGrid detector was made for this thread")
            }
        })
    };
    /// A pair's name, size, corners found in each image and JPEGs for the recording.
    type PairFound = anyhow::Result<(String, (u32, u32), Found, Found, Option<(Vec<u8>, Vec<u8>)>)>;
    let pairs: Vec<PairFound> = lf
        .par_iter()
        .zip(&rf)
        .map_init(init, |grid, (l, r)| {
            let grid = grid.as_mut().map_err(|e| anyhow::anyhow!("{e}"))?;
            let (li, ri) = (io::load_gray(l)?, io::load_gray(r)?);
            if li.dimensions() != ri.dimensions() {
                return Err(UsageError(format!(
                    "{} is {}x{} but {} is {}x{}: left and right images must be the same size",
                    l.display(),
                    li.width(),
                    li.height(),
                    r.display(),
                    ri.width(),
                    ri.height()
                ))
                .into());
            }
            let name = l
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            #[cfg(feature = "rerun")]
            let jpegs = keep_images
                .then(|| stereotag::viz::jpeg_pair(&li, &ri))
                .flatten();
            // Without the recording there is nothing to keep the images for.
            #[cfg(not(feature = "rerun"))]
            let jpegs: Option<(Vec<u8>, Vec<u8>)> = {
                let _ = keep_images;
                None
            };
            let found = (
                name,
                li.dimensions(),
                detect(grid, &li)?,
                detect(grid, &ri)?,
                jpegs,
            );
            bar.inc(1);
            Ok(found)
        })
        .collect();
    bar.finish_and_clear();
    let mut out = Detected {
        left: Default::default(),
        right: Default::default(),
        resolution: (0, 0),
        misses: Vec::new(),
        images: ViewImages::new(),
    };
    for ((pair, l), r) in pairs.into_iter().zip(&lf).zip(&rf) {
        let (name, size, (lc, lmiss), (rc, rmiss), jpegs) = pair?;
        if let Some(j) = jpegs {
            out.images.insert(name.clone(), j);
        }
        if out.resolution != (0, 0) && out.resolution != size {
            return Err(UsageError(format!(
                "{} is {}x{} but the images before it are {}x{}: one camera, one size",
                l.display(),
                size.0,
                size.1,
                out.resolution.0,
                out.resolution.1
            ))
            .into());
        }
        out.resolution = size;
        for (path, miss) in [(l, lmiss), (r, rmiss)] {
            if let Some(m) = miss {
                tracing::info!("{}: {m}", path.display());
                out.misses.push(format!("{}: {m}", path.display()));
            }
        }
        tracing::debug!("{name}: {} left, {} right corners", lc.len(), rc.len());
        out.left.insert(name.clone(), lc);
        out.right.insert(name, rc);
    }
    Ok(out)
}
