//! Maps on disk: ROS map_server pairs (PGM + YAML), the paper's inverse-grey PNG, the Hough
//! accumulator image, `corners.csv` and `walls.csv`.

use super::{csv_rows, parse_yaml, read_text, to_yaml, write_file, IoError};
use crate::sonar::grid::OccupancyMap;
use crate::sonar::hough::{Accumulator, Feature};
use crate::sonar::walls::WallSegment;
use crate::world::Raster;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;

/// A ROS map_server YAML file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RosMapYaml {
    /// Image file, relative to the YAML.
    pub image: String,
    /// `trinary` (when not given), `scale` or `raw` (map_server's modes); we write `trinary`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mode: Option<String>,
    /// Metres per pixel.
    pub resolution: f64,
    /// Pose of the lower-left pixel: x, y, yaw.
    pub origin: [f64; 3],
    /// Whether white means occupied.
    pub negate: u8,
    /// Occupancy above this is occupied.
    pub occupied_thresh: f64,
    /// Occupancy below this is free.
    pub free_thresh: f64,
}

/// The grey of a cell never observed in the maps we write: the middle of the thresholds, so
/// map_server's trinary rule reads it as unknown (-1). (map_saver's 205 with our free threshold
/// 0.2 would read as free: (255 - 205) / 255 = 0.196 < 0.2.)
fn unknown_grey(map: &OccupancyMap) -> u8 {
    let middle = 0.5 * (map.free_threshold + map.occupied_threshold);
    (255.0 * (1.0 - middle)).round().clamp(0.0, 255.0) as u8
}

/// What map_server makes of a pixel's occupancy `(255 - v) / 255` under the thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RosClass {
    Free,
    Occupied,
    /// Between the thresholds: unknown in trinary mode, a scaled value in scale mode.
    Between,
}

fn ros_class(occupancy: f64, free_thresh: f64, occupied_thresh: f64) -> RosClass {
    if occupancy > occupied_thresh {
        RosClass::Occupied
    } else if occupancy < free_thresh {
        RosClass::Free
    } else {
        RosClass::Between
    }
}

/// The grey of an observed cell of occupancy `c`: `255 (1 - c)`, moved by the least that keeps
/// map_server's class of it the map's class of `c` (rounding can carry a cell next to a threshold
/// across it).
fn cell_grey(c: f64, map: &OccupancyMap) -> u8 {
    let (free, occupied) = (map.free_threshold, map.occupied_threshold);
    let want = ros_class(c, free, occupied);
    let start = (255.0 * (1.0 - c)).round().clamp(0.0, 255.0) as i32;
    let read = |v: i32| ros_class((255 - v) as f64 / 255.0, free, occupied);
    (0..=255)
        .flat_map(|d| [start - d, start + d])
        .find(|&v| (0..=255).contains(&v) && read(v) == want)
        .unwrap_or(start) as u8
}

/// Writes `<stem>.pgm` and `<stem>.yaml` for map_server in trinary mode: it reads every cell
/// never observed as unknown (-1), every cell the map holds occupied as 100 and free as 0 (cells
/// between the thresholds are unknown to it too); the grey keeps the map's occupancy otherwise.
pub fn save_ros_map(dir: &Path, stem: &str, map: &OccupancyMap) -> Result<(), IoError> {
    let g = &map.geometry;
    let mut pixels = vec![unknown_grey(map); g.width * g.height];
    for row in 0..g.height {
        for col in 0..g.width {
            if let Some(c) = map.occupancy[row * g.width + col] {
                pixels[(g.height - 1 - row) * g.width + col] = cell_grey(c, map);
            }
        }
    }
    let pgm = dir.join(format!("{stem}.pgm"));
    let mut bytes = format!(
        "P5\n# stereotag occupancy grid\n{} {}\n255\n",
        g.width, g.height
    )
    .into_bytes();
    bytes.extend_from_slice(&pixels);
    write_file(&pgm, &bytes)?;
    let yaml = RosMapYaml {
        image: format!("{stem}.pgm"),
        mode: Some("trinary".into()),
        resolution: g.resolution_m,
        origin: [g.origin_m[0], g.origin_m[1], 0.0],
        negate: 0,
        occupied_thresh: map.occupied_threshold,
        free_thresh: map.free_threshold,
    };
    let path = dir.join(format!("{stem}.yaml"));
    write_file(&path, to_yaml(&path, &yaml)?.as_bytes())
}

/// A pixel as map_server reads it (its documented rule for each mode), as an occupancy: trinary:
/// 1 occupied, 0 free, `None` unknown (between the thresholds); scale: 1, 0, or the occupancy
/// between, `None` only where the pixel is transparent; raw: the value as a percentage, `None`
/// above 100.
fn ros_cell(meta: &RosMapYaml, value: u8, alpha: u8) -> Option<f64> {
    let mode = meta.mode.as_deref().unwrap_or("trinary");
    if mode == "raw" {
        return (value <= 100).then_some(value as f64 / 100.0);
    }
    let occupancy = if meta.negate != 0 {
        value as f64 / 255.0
    } else {
        (255.0 - value as f64) / 255.0
    };
    match (
        mode,
        ros_class(occupancy, meta.free_thresh, meta.occupied_thresh),
    ) {
        ("scale", _) if alpha == 0 => None,
        (_, RosClass::Occupied) => Some(1.0),
        (_, RosClass::Free) => Some(0.0),
        ("scale", RosClass::Between) => Some(occupancy),
        _ => None,
    }
}

/// Reads and checks a ROS map's YAML and its grey image.
fn read_ros_map(yaml_path: &Path) -> Result<(RosMapYaml, image::GrayAlphaImage), IoError> {
    let meta: RosMapYaml = parse_yaml(yaml_path, &read_text(yaml_path)?)?;
    if !(meta.resolution.is_finite() && meta.resolution > 0.0) {
        return Err(IoError::content(
            yaml_path,
            "`resolution` must be a positive number of metres per pixel",
        ));
    }
    if meta.origin.iter().any(|v| !v.is_finite()) || meta.origin[2] != 0.0 {
        return Err(IoError::content(
            yaml_path,
            "`origin` must be finite with yaw 0 (rotated maps are not supported)",
        ));
    }
    let image_path = yaml_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(&meta.image);
    let bytes = super::bundled::read(&image_path)?;
    let img = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| IoError::file(&image_path, e))?
        .decode()
        .map_err(|e| IoError::content(&image_path, format!("cannot read the map image: {e}")))?
        .to_luma_alpha8();
    if let Some(mode) = meta
        .mode
        .as_deref()
        .filter(|m| !["trinary", "scale", "raw"].contains(m))
    {
        return Err(IoError::content(
            yaml_path,
            format!("`mode: {mode}`: map_server's modes are trinary, scale and raw"),
        ));
    }
    Ok((meta, img))
}

/// Reads a ROS map as a wall raster, by map_server's rule: every cell that is not free (occupied
/// or unknown) is an obstacle, so the unknown space behind walls is solid.
pub fn load_ros_map(yaml_path: &Path) -> Result<Raster, IoError> {
    let (meta, img) = read_ros_map(yaml_path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let obstacle = img
        .pixels()
        .map(|p| ros_cell(&meta, p.0[0], p.0[1]).is_none_or(|o| o >= meta.free_thresh))
        .collect();
    Ok(Raster {
        width: w,
        height: h,
        obstacle,
        resolution_m: meta.resolution,
        origin_m: [meta.origin[0], meta.origin[1]],
    })
}

/// Writes a grey image as PNG (the image crate's default compression).
pub fn save_gray_png(path: &Path, image: &image::GrayImage) -> Result<(), IoError> {
    image
        .save(path)
        .map_err(|e| IoError::content(path, format!("cannot write PNG: {e}")))
}

/// Writes a picture of `map` (the picture module's [`map_picture`](crate::picture::map_picture):
/// a fixed scale, axes in metres, unknown distinct from free) with `overlay` drawn on it.
pub fn save_map_png(
    path: &Path,
    map: &OccupancyMap,
    title: &str,
    overlay: &crate::picture::Overlay<'_>,
) -> Result<(), IoError> {
    save_rgb_png(path, &crate::picture::map_picture(map, title, overlay))
}

/// Writes a picture of the Hough accumulator, with its axes.
pub fn save_accumulator_png(path: &Path, acc: &Accumulator, title: &str) -> Result<(), IoError> {
    save_rgb_png(path, &crate::picture::accumulator_picture(acc, title))
}

/// Writes an RGB image as PNG.
pub fn save_rgb_png(path: &Path, image: &image::RgbImage) -> Result<(), IoError> {
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| IoError::content(path, format!("cannot encode PNG: {e}")))?;
    write_file(path, &bytes)
}

/// Writes `corners.csv`: `x_m,y_m,votes,kind`.
pub fn save_features_csv(path: &Path, features: &[Feature]) -> Result<(), IoError> {
    let mut s = format!("{FEATURES_HEADER}\n");
    for f in features {
        let _ = writeln!(
            s,
            "{:.4},{:.4},{},{}",
            f.x_m,
            f.y_m,
            f.votes,
            f.kind.as_str()
        );
    }
    write_file(path, s.as_bytes())
}

/// Reads a ROS map as an occupancy map by map_server's rule for its mode (trinary, scale, raw):
/// what map_server reads as unknown is unknown, occupied is 1 and free 0.
pub fn load_ros_occupancy(yaml_path: &Path) -> Result<OccupancyMap, IoError> {
    let (meta, img) = read_ros_map(yaml_path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut occupancy = vec![None; w * h];
    for (x, y, p) in img.enumerate_pixels() {
        occupancy[(h - 1 - y as usize) * w + x as usize] = ros_cell(&meta, p.0[0], p.0[1]);
    }
    Ok(OccupancyMap {
        geometry: crate::sonar::grid::GridGeometry {
            width: w,
            height: h,
            resolution_m: meta.resolution,
            origin_m: [meta.origin[0], meta.origin[1]],
        },
        occupancy,
        occupied_threshold: meta.occupied_thresh,
        free_threshold: meta.free_thresh,
    })
}

/// Header of `corners.csv`.
const FEATURES_HEADER: &str = "x_m,y_m,votes,kind";

/// A CSV field that must be a finite number.
fn finite_field(path: &Path, line_no: u64, name: &str, s: &str) -> Result<f64, IoError> {
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| {
            IoError::line(
                path,
                line_no,
                format!("{name}: `{s}` is not a finite number"),
            )
        })
}

/// A CSV field that must be a whole number.
fn count_field(path: &Path, line_no: u64, name: &str, s: &str) -> Result<usize, IoError> {
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && v.fract() == 0.0 && *v >= 0.0 && *v <= u32::MAX as f64)
        .map(|v| v as usize)
        .ok_or_else(|| {
            IoError::line(
                path,
                line_no,
                format!("{name}: `{s}` is not a whole number"),
            )
        })
}

/// Reads `corners.csv` (`x_m,y_m,votes,kind`), naming the line of the first bad row.
pub fn load_features_csv(path: &Path) -> Result<Vec<Feature>, IoError> {
    let text = read_text(path)?;
    csv_rows(path, &text, FEATURES_HEADER)?
        .into_iter()
        .map(|(line_no, f)| {
            let kind = match f[3] {
                "corner" => crate::sonar::hough::FeatureKind::Corner,
                "edge" => crate::sonar::hough::FeatureKind::Edge,
                "unknown" => crate::sonar::hough::FeatureKind::Unknown,
                other => {
                    return Err(IoError::line(
                        path,
                        line_no,
                        format!("kind: `{other}`, expected corner, edge or unknown"),
                    ))
                }
            };
            Ok(Feature {
                x_m: finite_field(path, line_no, "x_m", f[0])?,
                y_m: finite_field(path, line_no, "y_m", f[1])?,
                votes: count_field(path, line_no, "votes", f[2])? as u32,
                sightings: 1,
                spread_deg: 0.0,
                kind,
            })
        })
        .collect()
}

/// Header of `walls.csv`: the faces' line, ends and fit, and how well each is placed (`sigma_m`,
/// empty when not measured: a survey's `walls_corrected.csv` has it).
const WALLS_HEADER: &str =
    "normal_rad,offset_m,from_x_m,from_y_m,to_x_m,to_y_m,readings,rms_m,sigma_m";
/// ... as written before `sigma_m` (read still).
const WALLS_HEADER_UNPLACED: &str =
    "normal_rad,offset_m,from_x_m,from_y_m,to_x_m,to_y_m,readings,rms_m";

/// Writes `walls.csv`: one wall face per row (see [`WallSegment`]).
pub fn save_walls_csv(path: &Path, walls: &[WallSegment]) -> Result<(), IoError> {
    let mut s = format!("{WALLS_HEADER}\n");
    for w in walls {
        let _ = writeln!(
            s,
            "{:.6},{:.5},{:.5},{:.5},{:.5},{:.5},{},{:.5},{}",
            w.normal_rad,
            w.offset_m,
            w.from_m[0],
            w.from_m[1],
            w.to_m[0],
            w.to_m[1],
            w.readings,
            w.rms_m,
            w.sigma_m.map_or(String::new(), |v| format!("{v:.5}"))
        );
    }
    write_file(path, s.as_bytes())
}

/// Header of `walls_corrected_covariance.csv`.
const WALLS_COVARIANCE_HEADER: &str = "wall_a,part_a,wall_b,part_b,covariance";
/// The parts of a face's placement error ([`crate::fusion::WALL_PARTS`]): its offset along its
/// normal at its middle (metres) and its turn (radians).
const WALL_PART_NAMES: [&str; crate::fusion::WALL_PARTS] = ["offset", "turn"];

/// Writes the covariance of walls' placement errors ([`crate::fusion::Survey::walls_covariance`],
/// two parts a face: `offset`, metres, and `turn`, radians): a row per pair of parts of the
/// faces whose placement is known ([`WallSegment::sigma_m`]), the faces by their rows in
/// `walls.csv` from 0, each pair once.
pub fn save_walls_covariance_csv(
    path: &Path,
    walls: &[WallSegment],
    covariance: &nalgebra::DMatrix<f64>,
) -> Result<(), IoError> {
    let parts = WALL_PART_NAMES.len();
    let mut s = format!("{WALLS_COVARIANCE_HEADER}\n");
    let placed: Vec<usize> = (0..walls.len().min(covariance.nrows() / parts))
        .filter(|&i| walls[i].sigma_m.is_some())
        .flat_map(|i| (0..parts).map(move |k| parts * i + k))
        .collect();
    for (k, &a) in placed.iter().enumerate() {
        for &b in &placed[k..] {
            let _ = writeln!(
                s,
                "{},{},{},{},{:.6e}",
                a / parts,
                WALL_PART_NAMES[a % parts],
                b / parts,
                WALL_PART_NAMES[b % parts],
                covariance[(a, b)]
            );
        }
    }
    write_file(path, s.as_bytes())
}

/// Reads `walls_corrected_covariance.csv` for `walls` faces into a square matrix, two parts a
/// face (pairs not listed: 0), naming the line of the first bad row: a face past the walls, an
/// unknown part, a number that is not finite, a variance that is not positive, or a pair given
/// twice.
pub fn load_walls_covariance_csv(
    path: &Path,
    walls: usize,
) -> Result<nalgebra::DMatrix<f64>, IoError> {
    let text = read_text(path)?;
    let parts = WALL_PART_NAMES.len();
    let mut out = nalgebra::DMatrix::zeros(parts * walls, parts * walls);
    let mut seen = std::collections::HashSet::new();
    for (line_no, f) in csv_rows(path, &text, WALLS_COVARIANCE_HEADER)? {
        let bad = |m: String| IoError::line(path, line_no, m);
        let part = |k: usize, name: &str| -> Result<usize, IoError> {
            let face = count_field(path, line_no, &format!("wall_{name}"), f[k])?;
            if face >= walls {
                return Err(bad(format!(
                    "wall_{name}: face {face}, but walls_corrected.csv has {walls} faces"
                )));
            }
            let p = WALL_PART_NAMES
                .iter()
                .position(|n| *n == f[k + 1])
                .ok_or_else(|| {
                    bad(format!(
                        "part_{name}: `{}`, expected {}",
                        f[k + 1],
                        WALL_PART_NAMES.join(" or ")
                    ))
                })?;
            Ok(parts * face + p)
        };
        let (a, b) = (part(0, "a")?, part(2, "b")?);
        let v = finite_field(path, line_no, "covariance", f[4])?;
        if a == b && v <= 0.0 {
            return Err(bad(format!("covariance: a variance of {v}, not positive")));
        }
        if !seen.insert((a.min(b), a.max(b))) {
            return Err(bad("this pair of parts is given twice".to_owned()));
        }
        out[(a, b)] = v;
        out[(b, a)] = v;
    }
    Ok(out)
}

/// Reads `walls.csv` (with or without its `sigma_m` column), naming the line of the first bad
/// row.
pub fn load_walls_csv(path: &Path) -> Result<Vec<WallSegment>, IoError> {
    let text = read_text(path)?;
    let header = match text.lines().next().map(str::trim) {
        Some(WALLS_HEADER_UNPLACED) => WALLS_HEADER_UNPLACED,
        _ => WALLS_HEADER,
    };
    let names: Vec<&str> = WALLS_HEADER.split(',').collect();
    csv_rows(path, &text, header)?
        .into_iter()
        .map(|(line_no, f)| {
            let v = |k: usize| finite_field(path, line_no, names[k], f[k]);
            let sigma_m = match f.get(8) {
                None | Some(&"") => None,
                Some(s) => Some(
                    s.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite() && *v > 0.0)
                        .ok_or_else(|| {
                            IoError::line(
                                path,
                                line_no,
                                format!("sigma_m: `{s}` is not a positive number"),
                            )
                        })?,
                ),
            };
            Ok(WallSegment {
                normal_rad: v(0)?,
                offset_m: v(1)?,
                from_m: [v(2)?, v(3)?],
                to_m: [v(4)?, v(5)?],
                readings: count_field(path, line_no, names[6], f[6])?,
                rms_m: v(7)?,
                sigma_m,
            })
        })
        .collect()
}
