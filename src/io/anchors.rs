//! Anchor files: known tag poses a survey is solved in the frame of. A WPILib AprilTag field
//! layout (JSON: `tags` with `ID` and `pose`, as `survey` writes `layout.json`), or a YAML list.

use super::{read_text, IoError};
use crate::fusion::Anchor;
use crate::visual::tags::{TagFamily, TagId};
use serde::Deserialize;
use std::path::Path;

/// The YAML form.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AnchorsFile {
    anchors: Vec<AnchorEntry>,
}

/// One anchor in YAML.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AnchorEntry {
    #[serde(default = "super::survey::default_family")]
    family: TagFamily,
    id: u32,
    x_m: f64,
    y_m: f64,
    #[serde(default)]
    z_m: f64,
    yaw_deg: Option<f64>,
    sigma_m: Option<f64>,
    sigma_deg: Option<f64>,
}

/// The WPILib layout's form (its `field` is not needed).
#[derive(Debug, Deserialize)]
struct WpilibLayout {
    tags: Vec<WpilibTag>,
}

#[derive(Debug, Deserialize)]
struct WpilibTag {
    #[serde(rename = "ID")]
    id: u32,
    pose: WpilibPose,
}

#[derive(Debug, Deserialize)]
struct WpilibPose {
    translation: WpilibTranslation,
    rotation: WpilibRotation,
}

#[derive(Debug, Deserialize)]
struct WpilibTranslation {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Debug, Deserialize)]
struct WpilibRotation {
    quaternion: WpilibQuaternion,
}

#[derive(Debug, Deserialize)]
#[allow(non_snake_case)]
struct WpilibQuaternion {
    W: f64,
    X: f64,
    Y: f64,
    Z: f64,
}

/// Reads known tag poses: a WPILib field layout (`.json`; tag36h11, the facing from each
/// quaternion's yaw, the sigmas `default_sigma` (metres, radians), since the format has none) or
/// YAML:
///
/// ```yaml
/// anchors:
///   - {id: 0, x_m: 0.0, y_m: 3.2, z_m: 0.4, yaw_deg: -90, sigma_m: 0.01, sigma_deg: 1}
///   - {id: 5, x_m: 6.5, y_m: 0.0}           # facing unknown, default sigmas
/// ```
///
/// (`family:` when not tag36h11; `yaw_deg` the direction the tag faces, out of its face.) The
/// numbers must be finite, the sigmas positive, and no tag listed twice; errors name the file
/// and the tag.
///
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("anchors.yaml");
/// std::fs::write(&path, "anchors:\n  - {id: 0, x_m: 1.0, y_m: 2.0, yaw_deg: 90}\n")?;
/// let anchors = stereotag::io::load_anchors(&path, (0.01, 0.02))?;
/// assert_eq!(anchors[0].position_m, [1.0, 2.0, 0.0]);
/// assert!((anchors[0].yaw_rad.unwrap() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
/// assert_eq!((anchors[0].sigma_m, anchors[0].sigma_rad), (0.01, 0.02));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn load_anchors(path: &Path, default_sigma: (f64, f64)) -> Result<Vec<Anchor>, IoError> {
    let text = read_text(path)?;
    let json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let anchors: Vec<Anchor> = if json {
        let layout: WpilibLayout = serde_json::from_str(&text).map_err(|e| {
            IoError::line(
                path,
                e.line() as u64,
                format!(
                    "{} (a WPILib AprilTag field layout)",
                    super::at_column(e.column(), &e.to_string(), e.line())
                ),
            )
        })?;
        layout
            .tags
            .into_iter()
            .map(|t| {
                let q = &t.pose.rotation.quaternion;
                let yaw =
                    (2.0 * (q.W * q.Z + q.X * q.Y)).atan2(1.0 - 2.0 * (q.Y * q.Y + q.Z * q.Z));
                let p = &t.pose.translation;
                Anchor {
                    tag: TagId {
                        family: TagFamily::Tag36h11,
                        id: t.id,
                    },
                    position_m: [p.x, p.y, p.z],
                    yaw_rad: Some(yaw),
                    sigma_m: default_sigma.0,
                    sigma_rad: default_sigma.1,
                }
            })
            .collect()
    } else {
        let file: AnchorsFile = super::parse_yaml(path, &text)?;
        file.anchors
            .into_iter()
            .map(|a| Anchor {
                tag: TagId {
                    family: a.family,
                    id: a.id,
                },
                position_m: [a.x_m, a.y_m, a.z_m],
                yaw_rad: a.yaw_deg.map(f64::to_radians),
                sigma_m: a.sigma_m.unwrap_or(default_sigma.0),
                sigma_rad: a.sigma_deg.map_or(default_sigma.1, f64::to_radians),
            })
            .collect()
    };
    if anchors.is_empty() {
        return Err(IoError::content(path, "no anchors listed"));
    }
    let mut seen = std::collections::BTreeSet::new();
    for a in &anchors {
        let name = format!("{} {}", a.tag.family, a.tag.id);
        let finite =
            a.position_m.iter().all(|v| v.is_finite()) && a.yaw_rad.is_none_or(f64::is_finite);
        if !finite {
            return Err(IoError::content(
                path,
                format!("{name}: a pose that is not a finite number"),
            ));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(a.sigma_m) || !positive(a.sigma_rad) {
            return Err(IoError::content(
                path,
                format!(
                    "{name}: sigmas must be positive (sigma_m {}, sigma_deg {})",
                    a.sigma_m,
                    a.sigma_rad.to_degrees()
                ),
            ));
        }
        if !seen.insert(a.tag) {
            return Err(IoError::content(path, format!("{name} is listed twice")));
        }
    }
    Ok(anchors)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(name: &str, text: &str) -> Result<Vec<Anchor>, String> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        load_anchors(&path, (0.01, 0.02)).map_err(|e| e.to_string())
    }

    /// A WPILib layout as `survey` writes it reads back, each tag's facing from its quaternion.
    #[test]
    fn a_wpilib_layout_gives_positions_and_facings() {
        let (s, c) = (0.5f64 * 1.2).sin_cos();
        let json = format!(
            r#"{{"tags": [{{"ID": 4, "pose": {{"translation": {{"x": 1.5, "y": -2.0, "z": 0.4}},
               "rotation": {{"quaternion": {{"W": {c}, "X": 0.0, "Y": 0.0, "Z": {s}}}}}}}}}],
               "field": {{"length": 3.0, "width": 2.0}}}}"#
        );
        let a = load("layout.json", &json).unwrap();
        assert_eq!(a.len(), 1);
        assert_eq!(a[0].tag.id, 4);
        assert_eq!(a[0].position_m, [1.5, -2.0, 0.4]);
        assert!((a[0].yaw_rad.unwrap() - 1.2).abs() < 1e-12);
        assert_eq!((a[0].sigma_m, a[0].sigma_rad), (0.01, 0.02));
    }

    /// Bad anchor files are refused, naming the file and the tag or line.
    #[test]
    fn bad_anchor_files_are_refused_saying_why() {
        for (name, text, expect) in [
            (
                "a.yaml",
                "anchors:\n  - {id: 1, x_m: 0, y_m: 0}\n  - {id: 1, x_m: 1, y_m: 0}\n",
                "tag36h11 1 is listed twice",
            ),
            (
                "a.yaml",
                "anchors:\n  - {id: 1, x_m: .nan, y_m: 0}\n",
                "not a finite number",
            ),
            (
                "a.yaml",
                "anchors:\n  - {id: 1, x_m: 0, y_m: 0, sigma_m: 0}\n",
                "sigmas must be positive",
            ),
            (
                "a.yaml",
                "anchors:\n  - {id: 1, x_m: 0, y_m: 0, colour: red}\n",
                "a.yaml:2",
            ),
            ("a.yaml", "anchors: []\n", "no anchors listed"),
            ("a.json", "{\"tags\": [{\"ID\": 1}]}", "a.json:1"),
        ] {
            let err = load(name, text).unwrap_err();
            assert!(err.contains(name), "{err}");
            assert!(err.contains(expect), "{name} {text:?}: {err}");
            // The line is said once, where every error says it.
            assert!(!err.contains(" at line "), "{err}");
        }
    }
}
