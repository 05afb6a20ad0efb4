//! Every file format: run datasets, world files, stereo rigs, maps, feature lists and reports.
//!
//! Readers check everything a stage relies on (finite numbers, sensor ids, time order) and name
//! the file and line of the first problem. Writers go through [`OutputDir`], which builds the
//! output under a temporary name and renames it into place, so a failure leaves nothing half-written.

mod anchors;
pub mod asl;
mod bundled;
mod calib;
pub mod carmen;
mod maps;
mod output;
mod rig;
pub mod rosbag;
mod run;
mod survey;
mod world;

pub use anchors::load_anchors;
pub use bundled::{bundled, extract as extract_bundled, FILES as BUNDLED_FILES};
pub use calib::{load_corner_csvs, load_target, save_corner_csvs, save_corners_vnl};
pub use maps::{
    load_features_csv, load_ros_map, load_ros_occupancy, load_walls_covariance_csv, load_walls_csv,
    save_accumulator_png, save_features_csv, save_gray_png, save_map_png, save_rgb_png,
    save_ros_map, save_walls_covariance_csv, save_walls_csv, RosMapYaml,
};
pub use output::{remove_partial_outputs, OutputDir, PartialFile};
pub use rig::{
    default_mounting, load_mounted_rig, load_rig, parse_rig, robot_from_forward_camera,
    save_camera_exports_noted, save_camera_info, save_opencv_stereo, save_rig, save_rig_exports,
    save_rig_exports_noted, save_rig_noted, Camchain, KalibrCamera, DEFAULT_RIG,
};
pub use run::{load_run, read_poses, read_uci_sonar_ring, save_run, REORDER_TOLERANCE_S};
pub use survey::{
    load_landmarks, load_tag_sizes, save_landmarks, save_localization_csv, save_survey,
    save_trajectory_csv, save_tum, save_visual_turns_csv, save_wpilib_layout, truth_at,
    LandmarkRecord, LandmarksFile, Trajectories, LOCALIZATION_HEADER, VISUAL_TURNS_HEADER,
};
pub use world::{load_world, LoadedWorld, WorldFile};

use std::path::{Path, PathBuf};

/// Errors reading or writing files. Each names the file, and the line or key where it can.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file could not be opened, read or written.
    #[error("{path}: {cause}")]
    File {
        /// The file.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// A problem at a line of a text file.
    #[error("{path}:{line}: {message}")]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: u64,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A problem with a file as a whole, or a key in it.
    #[error("{path}: {message}")]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The output directory exists and `--force` was not given.
    #[error("{path} already exists; pass --force to replace it")]
    OutputExists {
        /// The directory.
        path: PathBuf,
    },
}

impl IoError {
    pub(crate) fn file(path: &Path, source: std::io::Error) -> Self {
        IoError::File {
            path: path.to_path_buf(),
            cause: source,
        }
    }
    pub(crate) fn content(path: &Path, message: impl Into<String>) -> Self {
        IoError::Content {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
    pub(crate) fn line(path: &Path, line: u64, message: impl Into<String>) -> Self {
        IoError::Line {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }
}

/// Writes a camera picture as an 8-bit grey PNG that is quick to read back: fast deflate with the
/// `Up` filter on every row decodes in half the time of the adaptive filter choice (0.43 vs
/// 0.80 ms for a 640 x 480 picture of the museum) for 8% more bytes, and a survey reads every
/// picture of a run.
pub fn save_camera_png(path: &Path, image: &image::GrayImage) -> Result<(), IoError> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    PngEncoder::new_with_quality(&mut bytes, CompressionType::Fast, FilterType::Up)
        .write_image(
            image.as_raw(),
            image.width(),
            image.height(),
            image::ExtendedColorType::L8,
        )
        .map_err(|e| IoError::content(path, format!("cannot encode PNG: {e}")))?;
    std::fs::write(path, bytes).map_err(|e| IoError::file(path, e))
}

/// Reads an image as 8-bit grey. Colour becomes Rec. 601 luma (`0.299 R + 0.587 G + 0.114 B`, as
/// JPEG's Y plane, OpenCV's `cvtColor` and the AprilTag C library's loader); 16-bit is scaled to 8 bits.
pub fn load_gray(path: &Path) -> Result<image::GrayImage, IoError> {
    let img = image::ImageReader::open(path)
        .map_err(|e| IoError::file(path, e))?
        .with_guessed_format()
        .map_err(|e| IoError::file(path, e))?
        .decode()
        .map_err(|e| IoError::content(path, format!("cannot decode the image: {e}")))?;
    if !img.color().has_color() {
        return Ok(img.into_luma8());
    }
    let rgb = img.into_rgb8();
    let (w, h) = rgb.dimensions();
    // ITU-R BT.601 luma (OpenCV's weights), rounded, in integers (which vectorise).
    let luma = rgb
        .as_raw()
        .chunks_exact(3)
        .map(|p| ((299 * p[0] as u32 + 587 * p[1] as u32 + 114 * p[2] as u32 + 500) / 1000) as u8)
        .collect();
    image::GrayImage::from_raw(w, h, luma)
        .ok_or_else(|| IoError::content(path, "image buffer has the wrong size"))
}

/// An error naming the image when its size is not the camera's (`rig` says which rig, for the
/// message).
pub fn check_image_size(
    image: &image::GrayImage,
    camera: &crate::camera::Camera,
    path: &Path,
    rig: &str,
) -> Result<(), IoError> {
    if image.dimensions() == (camera.width, camera.height) {
        return Ok(());
    }
    Err(IoError::content(
        path,
        format!(
            "image is {}x{} but {rig} says {}x{}",
            image.width(),
            image.height(),
            camera.width,
            camera.height
        ),
    ))
}

/// The data rows of a CSV file with a fixed header: (1-based line number, trimmed fields), blank
/// lines skipped; a wrong header or field count names the line.
pub(crate) fn csv_rows<'a>(
    path: &Path,
    text: &'a str,
    header: &str,
) -> Result<Vec<(u64, Vec<&'a str>)>, IoError> {
    let mut lines = text.lines().enumerate();
    let first = lines.next().map(|(_, l)| l.trim()).unwrap_or("");
    if first != header {
        return Err(IoError::line(
            path,
            1,
            format!("expected the header `{header}`, found `{first}`"),
        ));
    }
    let n = header.split(',').count();
    let mut rows = Vec::new();
    for (i, line) in lines {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != n {
            return Err(IoError::line(
                path,
                i as u64 + 1,
                format!("expected {n} fields ({header}), found {}", fields.len()),
            ));
        }
        rows.push((i as u64 + 1, fields));
    }
    Ok(rows)
}

/// The files matching a glob with `*` in its last component (any number of them, as in
/// `cam0/*.png`), sorted; an error when none does.
pub fn glob(pattern: &str) -> Result<Vec<PathBuf>, IoError> {
    let path = Path::new(pattern);
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
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
        .map_err(|e| IoError::content(Path::new(pattern), format!("{}: {e}", dir.display())))?;
    let mut out: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .filter(|e| matches(&e.file_name().to_string_lossy()))
        .map(|e| e.path())
        .collect();
    out.sort();
    if out.is_empty() {
        return Err(IoError::content(Path::new(pattern), "no file matches"));
    }
    Ok(out)
}

/// Creates a directory and its parents.
pub fn create_dir(path: &Path) -> Result<(), IoError> {
    std::fs::create_dir_all(path).map_err(|e| IoError::file(path, e))
}

/// Reads a whole text file (or the built-in copy of a sample, target or rig: [`bundled`]).
pub(crate) fn read_text(path: &Path) -> Result<String, IoError> {
    String::from_utf8(bundled::read(path)?)
        .map_err(|_| IoError::content(path, "not a UTF-8 text file"))
}

/// Parses YAML into `T`, with the file, line and column of the first error.
pub fn parse_yaml<T: serde::de::DeserializeOwned>(path: &Path, text: &str) -> Result<T, IoError> {
    serde_yaml_ng::from_str(text).map_err(|e| match e.location() {
        Some(loc) => IoError::line(
            path,
            loc.line() as u64,
            at_column(loc.column(), &e.to_string(), loc.line()),
        ),
        None => IoError::content(path, e.to_string()),
    })
}

/// A parser's message for an error at `line` and `column`, after the file and line every error
/// starts with: "column C: " and the message without the " at line L column C" serde's parsers
/// end it with (said twice before).
pub(crate) fn at_column(column: usize, message: &str, line: usize) -> String {
    let message = message
        .strip_suffix(&format!(" at line {line} column {column}"))
        .unwrap_or(message);
    format!("column {column}: {message}")
}

/// Serialises to YAML.
pub(crate) fn to_yaml<T: serde::Serialize>(path: &Path, value: &T) -> Result<String, IoError> {
    serde_yaml_ng::to_string(value).map_err(|e| IoError::content(path, e.to_string()))
}

/// Writes a file.
pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    std::fs::write(path, bytes).map_err(|e| IoError::file(path, e))
}

/// The mapping settings of a YAML file (`stereotag config --default mapping`, `map --config`),
/// checked.
pub fn load_mapping_config(path: &Path) -> Result<crate::sonar::map::MappingConfig, IoError> {
    let config = parse_yaml(path, &read_text(path)?)?;
    check_mapping(path, &config, "")?;
    Ok(config)
}

/// Checks mapping settings read from `path` (under `key`, e.g. `mapping.`), naming the file.
pub(crate) fn check_mapping(
    path: &Path,
    config: &crate::sonar::map::MappingConfig,
    key: &str,
) -> Result<(), IoError> {
    config
        .grid
        .validate()
        .and_then(|()| config.walls.validate())
        .map_err(|e| IoError::content(path, format!("{key}{e}")))
}

/// The fusion settings of a YAML file (`stereotag config --default fuse`), checked, or the
/// defaults when no file is given.
pub fn load_fuse_config(path: Option<&Path>) -> Result<crate::fusion::FuseConfig, IoError> {
    let Some(p) = path else {
        return Ok(crate::fusion::FuseConfig::default());
    };
    let config: crate::fusion::FuseConfig = parse_yaml(p, &read_text(p)?)?;
    config
        .validate()
        .map_err(|e| IoError::content(p, e.to_string()))?;
    Ok(config)
}

/// The kinds of settings files, each with its defaults.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Settings {
    /// Grid and Hough settings (`mapping:` of a world or run file, `map --config`).
    Mapping,
    /// Simulation settings (`simulation:` of a world file).
    Simulation,
    /// Fusion settings (`survey --config`, `localize --config`).
    Fuse,
    /// Tag planning settings.
    Plan,
}

impl Settings {
    /// The kind of settings called `name` (`mapping`, `simulation`, `fuse` or `plan`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "mapping" => Some(Self::Mapping),
            "simulation" => Some(Self::Simulation),
            "fuse" => Some(Self::Fuse),
            "plan" => Some(Self::Plan),
            _ => None,
        }
    }

    /// The defaults as YAML, ready to edit, each setting under a comment saying what it is
    /// (its documentation).
    pub fn default_yaml(self) -> String {
        fn commented<T: serde::Serialize + schemars::JsonSchema + Default>() -> String {
            // Plain structs of numbers and flags always serialise.
            let yaml = serde_yaml_ng::to_string(&T::default()).unwrap_or_default();
            with_comments(&yaml, schemars::schema_for!(T).as_value())
        }
        match self {
            Self::Mapping => commented::<crate::sonar::map::MappingConfig>(),
            Self::Simulation => commented::<crate::sim::SimConfig>(),
            Self::Fuse => commented::<crate::fusion::FuseConfig>(),
            Self::Plan => commented::<crate::plan::PlanConfig>(),
        }
    }
}

/// `yaml` (block style, as serde_yaml writes a struct) with the description that `schema` gives
/// each key written as `# ...` lines above it.
fn with_comments(yaml: &str, schema: &serde_json::Value) -> String {
    // The schema of each open mapping, innermost last, with its keys' indentation.
    let mut open: Vec<(usize, &serde_json::Value)> = Vec::new();
    let mut out = String::new();
    for line in yaml.lines() {
        let indent = line.len() - line.trim_start().len();
        let key = line
            .trim_start()
            .split_once(':')
            .map(|(k, _)| k)
            .filter(|k| !k.is_empty() && !k.starts_with('-') && !k.contains(' '));
        if let Some(key) = key {
            while open.last().is_some_and(|(i, _)| *i > indent) {
                open.pop();
            }
            let parent = match open.last() {
                Some((i, s)) if *i == indent => Some(*s),
                None if indent == 0 => Some(schema),
                _ => None,
            };
            let field = parent.and_then(|p| property(schema, p, key));
            if let Some(text) = field
                .and_then(|f| f.get("description"))
                .and_then(|d| d.as_str())
            {
                for comment in wrap(text, 98usize.saturating_sub(indent)) {
                    out += &format!("{:indent$}# {comment}\n", "");
                }
            }
            if line.trim_end().ends_with(':') {
                if let Some(f) = field {
                    // A nested mapping: its keys come on the next lines, indented.
                    open.push((indent + 2, f));
                }
            }
        }
        out += line;
        out.push('\n');
    }
    out
}

/// The schema of property `key` of object schema `of`, references into `root` followed. It keeps
/// the field's own description; a nested struct's properties are found through [`resolve`].
fn property<'a>(
    root: &'a serde_json::Value,
    of: &'a serde_json::Value,
    key: &str,
) -> Option<&'a serde_json::Value> {
    resolve(root, of).get("properties")?.get(key)
}

/// `schema` with a `$ref` (or a nullable `anyOf` around one) replaced by its definition.
fn resolve<'a>(
    root: &'a serde_json::Value,
    schema: &'a serde_json::Value,
) -> &'a serde_json::Value {
    let target = schema.get("$ref").or_else(|| {
        schema
            .get("anyOf")
            .and_then(|a| a.as_array())
            .and_then(|a| a.iter().find_map(|s| s.get("$ref")))
    });
    target
        .and_then(|r| r.as_str())
        .and_then(|r| r.strip_prefix("#/"))
        .and_then(|r| r.split('/').try_fold(root, |node, part| node.get(part)))
        .unwrap_or(schema)
}

/// `text` (a doc comment: paragraphs of lines) as lines of at most `width` characters.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line += word;
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// Writes a value as pretty JSON.
pub fn save_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), IoError> {
    let text =
        serde_json::to_string_pretty(value).map_err(|e| IoError::content(path, e.to_string()))?;
    write_file(path, format!("{text}\n").as_bytes())
}
