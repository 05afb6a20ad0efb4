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
    /// `trinary`, `scale` or `raw` (map_server's modes); we write `scale`.
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

/// Grey value ROS uses for unknown cells.
const ROS_UNKNOWN: u8 = 205;

/// Writes `<stem>.pgm` and `<stem>.yaml` in map_server's convention.
pub fn save_ros_map(dir: &Path, stem: &str, map: &OccupancyMap) -> Result<(), IoError> {
    let g = &map.geometry;
    let mut pixels = vec![ROS_UNKNOWN; g.width * g.height];
    for row in 0..g.height {
        for col in 0..g.width {
            if let Some(c) = map.occupancy[row * g.width + col] {
                // map_server reads occupancy as (255 - value) / 255.
                pixels[(g.height - 1 - row) * g.width + col] =
                    (255.0 * (1.0 - c)).round().clamp(0.0, 255.0) as u8;
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
        mode: Some("scale".into()),
        resolution: g.resolution_m,
        origin: [g.origin_m[0], g.origin_m[1], 0.0],
        negate: 0,
        occupied_thresh: map.occupied_threshold,
        free_thresh: map.free_threshold,
    };
    let path = dir.join(format!("{stem}.yaml"));
    write_file(&path, to_yaml(&path, &yaml)?.as_bytes())
}

/// Reads and checks a ROS map's YAML and its grey image.
fn read_ros_map(yaml_path: &Path) -> Result<(RosMapYaml, image::GrayImage), IoError> {
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
        .to_luma8();
    Ok((meta, img))
}

/// Reads a ROS map as a wall raster: every cell that is not free (occupied or unknown) is an
/// obstacle, so the unknown space behind walls is solid.
pub fn load_ros_map(yaml_path: &Path) -> Result<Raster, IoError> {
    let (meta, img) = read_ros_map(yaml_path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let obstacle = img
        .pixels()
        .map(|p| {
            let v = p.0[0] as f64;
            let occ = if meta.negate != 0 {
                v / 255.0
            } else {
                (255.0 - v) / 255.0
            };
            occ > meta.free_thresh
        })
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

/// Reads a ROS map as an occupancy map: occupancy `(255 − v) / 255` per pixel (or `v / 255` with
/// `negate`), and the grey of unknown cells (205) as unknown.
pub fn load_ros_occupancy(yaml_path: &Path) -> Result<OccupancyMap, IoError> {
    let (meta, img) = read_ros_map(yaml_path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut occupancy = vec![None; w * h];
    for (x, y, p) in img.enumerate_pixels() {
        let v = p.0[0];
        if v == ROS_UNKNOWN {
            continue;
        }
        let occ = if meta.negate != 0 {
            v as f64 / 255.0
        } else {
            (255.0 - v as f64) / 255.0
        };
        occupancy[(h - 1 - y as usize) * w + x as usize] = Some(occ);
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

/// Header of `walls.csv`.
const WALLS_HEADER: &str = "normal_rad,offset_m,from_x_m,from_y_m,to_x_m,to_y_m,readings,rms_m";

/// Writes `walls.csv`: one wall face per row (see [`WallSegment`]).
pub fn save_walls_csv(path: &Path, walls: &[WallSegment]) -> Result<(), IoError> {
    let mut s = format!("{WALLS_HEADER}\n");
    for w in walls {
        let _ = writeln!(
            s,
            "{:.6},{:.5},{:.5},{:.5},{:.5},{:.5},{},{:.5}",
            w.normal_rad,
            w.offset_m,
            w.from_m[0],
            w.from_m[1],
            w.to_m[0],
            w.to_m[1],
            w.readings,
            w.rms_m
        );
    }
    write_file(path, s.as_bytes())
}

/// Reads `walls.csv`, naming the line of the first bad row.
pub fn load_walls_csv(path: &Path) -> Result<Vec<WallSegment>, IoError> {
    let text = read_text(path)?;
    let names: Vec<&str> = WALLS_HEADER.split(',').collect();
    csv_rows(path, &text, WALLS_HEADER)?
        .into_iter()
        .map(|(line_no, f)| {
            let v = |k: usize| finite_field(path, line_no, names[k], f[k]);
            Ok(WallSegment {
                normal_rad: v(0)?,
                offset_m: v(1)?,
                from_m: [v(2)?, v(3)?],
                to_m: [v(4)?, v(5)?],
                readings: count_field(path, line_no, names[6], f[6])?,
                rms_m: v(7)?,
            })
        })
        .collect()
}
