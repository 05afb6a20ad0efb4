//! Calibration inputs and corners: Kalibr target YAML, corners as EuRoC / yac CSV (read and
//! written) and as mrcal's `corners.vnl` (written).

use super::{parse_yaml, read_text, write_file, IoError};
use crate::calib::{Corner, Target, ViewCorners};
use serde::Deserialize;
use std::path::Path;

/// `target_type` alone (other keys ignored), to pick the variant before its fields are read
/// from the text with their line numbers (an internally tagged enum reads the document into a
/// buffer first and loses them).
#[derive(Deserialize)]
struct TargetKind {
    target_type: String,
}

/// Reads and checks a Kalibr target YAML file.
pub fn load_target(path: &Path) -> Result<Target, IoError> {
    let text = read_text(path)?;
    let kind: TargetKind = parse_yaml(path, &text)?;
    let target = match kind.target_type.as_str() {
        "aprilgrid" => Target::Aprilgrid(parse_yaml(path, &text)?),
        "checkerboard" => Target::Checkerboard(parse_yaml(path, &text)?),
        "tagboard" => Target::Tagboard(parse_yaml(path, &text)?),
        "charuco" => Target::Charuco(parse_yaml(path, &text)?),
        "boards" => Target::Boards(parse_yaml(path, &text)?),
        other => {
            let line = text
                .lines()
                .position(|l| l.trim_start().starts_with("target_type"))
                .map_or(1, |i| i as u64 + 1);
            return Err(IoError::line(
                path,
                line,
                format!(
                    "target_type `{other}`: expected `aprilgrid`, `checkerboard`, `tagboard`, `charuco` or `boards`"
                ),
            ));
        }
    };
    check_target(path, &target)?;
    Ok(target)
}

/// Whether a target's numbers make a board; several boards must be tag or ChArUco boards with
/// no tag on two of them (a tag tells which board it is on).
fn check_target(path: &Path, target: &Target) -> Result<(), IoError> {
    let ok = match target {
        Target::Aprilgrid(g) => {
            g.tag_cols > 0 && g.tag_rows > 0 && g.tag_size > 0.0 && g.tag_spacing >= 0.0
        }
        Target::Checkerboard(c) => {
            c.target_cols > 1 && c.target_rows > 1 && c.row_spacing_m > 0.0 && c.col_spacing_m > 0.0
        }
        Target::Tagboard(b) => {
            b.tag_cols > 0 && b.tag_rows > 0 && b.tag_size > 0.0 && b.tag_spacing >= 0.0
        }
        Target::Charuco(c) => {
            c.check().map_err(|e| IoError::content(path, e))?;
            true
        }
        Target::Boards(several) => {
            if several.boards.is_empty() {
                return Err(IoError::content(path, "boards: the list is empty"));
            }
            let mut seen = std::collections::BTreeMap::new();
            for (k, board) in several.boards.iter().enumerate() {
                let tags = match board {
                    Target::Tagboard(b) => b.layout().into_iter().map(|id| (b.family, id)).collect::<Vec<_>>(),
                    Target::Charuco(c) => c.layout().into_iter().map(|id| (c.dictionary, id)).collect(),
                    _ => {
                        return Err(IoError::content(
                            path,
                            format!(
                                "boards[{k}]: several boards are tag boards and ChArUco boards (whose tags tell them apart), not AprilGrids, chessboards or lists"
                            ),
                        ))
                    }
                };
                check_target(path, board)?;
                for (family, id) in tags {
                    if let Some(other) = seen.insert((family, id), k) {
                        return Err(IoError::content(
                            path,
                            format!("boards[{other}] and boards[{k}] both hold {family} tag {id}: each tag must be on one board"),
                        ));
                    }
                }
            }
            true
        }
    };
    if !ok {
        return Err(IoError::content(
            path,
            "counts must be positive and sizes positive numbers of metres",
        ));
    }
    if let Target::Tagboard(b) = target {
        check_tag_board(path, b)?;
    }
    Ok(())
}

/// Reads a directory of per-frame corner CSV files as EuRoC's calibration data and yac write them:
/// `ts,tag_rows,tag_cols,tag_size,tag_spacing,kp_x,kp_y,p_x,p_y,p_z,tag_id,corner_idx` (a `#` header
/// line). The view name is the file stem (the time stamp).
pub fn load_corner_csvs(dir: &Path) -> Result<ViewCorners, IoError> {
    let mut views = ViewCorners::new();
    let entries = std::fs::read_dir(dir).map_err(|e| IoError::file(dir, e))?;
    let mut paths: Vec<_> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    paths.sort();
    if paths.is_empty() {
        return Err(IoError::content(
            dir,
            "no .csv corner files in this directory",
        ));
    }
    for path in paths {
        let text = read_text(&path)?;
        let mut corners = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line_no = i as u64 + 1;
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') || line.starts_with("ts") {
                continue;
            }
            let f: Vec<&str> = line.split(',').map(str::trim).collect();
            if f.len() != 12 {
                return Err(IoError::line(
                    &path,
                    line_no,
                    format!(
                        "expected 12 fields (ts,tag_rows,tag_cols,tag_size,tag_spacing,kp_x,kp_y,p_x,p_y,p_z,tag_id,corner_idx), found {}",
                        f.len()
                    ),
                ));
            }
            let num = |k: usize, what: &str| -> Result<f64, IoError> {
                f[k].parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        IoError::line(
                            &path,
                            line_no,
                            format!("{what}: `{}` is not a finite number", f[k]),
                        )
                    })
            };
            let int = |k: usize, what: &str| -> Result<u32, IoError> {
                f[k].parse::<u32>().map_err(|_| {
                    IoError::line(
                        &path,
                        line_no,
                        format!("{what}: `{}` is not a whole number", f[k]),
                    )
                })
            };
            let (tag, idx) = (int(10, "tag_id")?, int(11, "corner_idx")?);
            if idx > 3 {
                return Err(IoError::line(
                    &path,
                    line_no,
                    format!("corner_idx: {idx}, expected 0 to 3"),
                ));
            }
            // Corner ids are tag_id × 4 + corner_idx in 32 bits.
            let id = tag.checked_mul(4).map(|t| t + idx).ok_or_else(|| {
                IoError::line(
                    &path,
                    line_no,
                    format!("tag_id: {tag} is too large (at most {})", u32::MAX / 4),
                )
            })?;
            corners.push(Corner {
                id,
                board_m: [num(7, "p_x")?, num(8, "p_y")?, num(9, "p_z")?],
                px: [num(5, "kp_x")?, num(6, "kp_y")?],
            });
        }
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        views.insert(name, corners);
    }
    Ok(views)
}

/// A tag board's family must be one the tag detectors find, and its `ids` one distinct id of
/// that family per position.
fn check_tag_board(path: &Path, b: &crate::calib::TagBoardTarget) -> Result<(), IoError> {
    if !b.family.is_detectable() {
        return Err(IoError::content(
            path,
            format!(
                "family {}: a tag board takes an ordinary family (tag36h11, tag25h9, tag16h5, tagStandard41h12, an ArUco DICT_...); Kalibr's AprilGrid is target_type aprilgrid",
                b.family
            ),
        ));
    }
    crate::calib::check_id_layout(
        &b.layout(),
        (b.tag_cols * b.tag_rows) as usize,
        "positions",
        b.family,
    )
    .map_err(|e| IoError::content(path, e))
}

/// The header line of EuRoC / yac corner files.
const CORNER_CSV_HEADER: &str =
    "#ts,tag_rows,tag_cols,tag_size,tag_spacing,kp_x,kp_y,p_x,p_y,p_z,tag_id,corner_idx";

/// Writes each view's corners into `dir` (created) as EuRoC's calibration data and yac write
/// them, one `<view>.csv` a view, as [`load_corner_csvs`] reads them back. `ts` is the view's
/// name when it is a number (a time stamp), else its index; corner id `k` is written as tag
/// `k / 4`, corner `k % 4` (an AprilGrid's own; a chessboard's corner index round-trips). The
/// target's rows, columns, size and spacing fill their columns (a chessboard: its inner-corner
/// rows and columns, the square size and 0).
pub fn save_corner_csvs(dir: &Path, views: &ViewCorners, target: &Target) -> Result<(), IoError> {
    std::fs::create_dir_all(dir).map_err(|e| IoError::file(dir, e))?;
    let (rows, cols, size, spacing) = match target {
        Target::Aprilgrid(g) => (g.tag_rows, g.tag_cols, g.tag_size, g.tag_spacing),
        Target::Checkerboard(c) => (c.target_rows, c.target_cols, c.col_spacing_m, 0.0),
        Target::Tagboard(b) => (b.tag_rows, b.tag_cols, b.tag_size, b.tag_spacing),
        Target::Charuco(c) => (c.inner().1, c.inner().0, c.square_length, 0.0),
        // Several boards: the corner ids say the board (`BOARD_ID_STRIDE`).
        Target::Boards(_) => (0, 0, 0.0, 0.0),
    };
    for (index, (name, corners)) in views.iter().enumerate() {
        let ts = name
            .parse::<u64>()
            .map_or_else(|_| index.to_string(), |t| t.to_string());
        let mut text = format!("{CORNER_CSV_HEADER}\n");
        for c in corners {
            text.push_str(&format!(
                "{ts},{rows},{cols},{size:.6},{spacing:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{},{}\n",
                c.px[0],
                c.px[1],
                c.board_m[0],
                c.board_m[1],
                c.board_m[2],
                c.id / 4,
                c.id % 4
            ));
        }
        write_file(&dir.join(format!("{name}.csv")), text.as_bytes())?;
    }
    Ok(())
}

/// Writes a chessboard's corners as mrcal's `corners.vnl` (`# filename x y level`): for every
/// image, its `cols x rows` corners in mrcal's order (across each row, rows in turn), a corner
/// not found as `- -` and level `-`, found ones at level 0 (full weight); an image without a
/// board as one line of dashes.
pub fn save_corners_vnl(
    path: &Path,
    images: &[(String, &[Corner])],
    cols: u32,
    rows: u32,
) -> Result<(), IoError> {
    let mut text = String::from("# filename x y level\n");
    for (file, corners) in images {
        if corners.is_empty() {
            text.push_str(&format!("{file} - - -\n"));
            continue;
        }
        for k in 0..cols * rows {
            match corners.iter().find(|c| c.id == k) {
                Some(c) => text.push_str(&format!("{file} {:.6} {:.6} 0\n", c.px[0], c.px[1])),
                None => text.push_str(&format!("{file} - - -\n")),
            }
        }
    }
    write_file(path, text.as_bytes())
}
