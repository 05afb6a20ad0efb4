//! The tag families: their names, the code tables both backends decode with, and each tag's
//! printed pattern (what the renderer draws).

use super::aruco::ArucoDictionary;
use serde::{Deserialize, Serialize};

/// The tag families: the four AprilTag families and OpenCV's ArUco dictionaries, which both
/// backends detect, and Kalibr's AprilGrid tags. Written in files by the AprilTag library's
/// names (`tag36h11`, ...) and OpenCV's (`DICT_4X4_50`, ...), and ordered by them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TagFamily {
    /// tag36h11, the default: the family of the paper's landmarks and of Kalibr's AprilGrid.
    Tag36h11,
    /// tag25h9.
    Tag25h9,
    /// tag16h5.
    Tag16h5,
    /// tagStandard41h12.
    TagStandard41h12,
    /// Kalibr's AprilGrid tags: tag36h11's codes with a 2-bit black border, found by the
    /// AprilGrid detector ([`super::AprilGridDetector`]) alone.
    Aprilgrid36h11,
    /// One of OpenCV's ArUco dictionaries (`DICT_4X4_50` ... `DICT_7X7_1000`).
    Aruco(ArucoDictionary),
}

impl Serialize for TagFamily {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for TagFamily {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        /// Reads a name where it stands (so an error points at it).
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = TagFamily;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                write!(f, "{}", TagFamily::NAMES)
            }
            fn visit_str<E: serde::de::Error>(self, name: &str) -> Result<TagFamily, E> {
                TagFamily::from_name(name).ok_or_else(|| {
                    E::custom(format!(
                        "unknown tag family {name:?}: expected {}",
                        TagFamily::NAMES
                    ))
                })
            }
        }
        deserializer.deserialize_str(Name)
    }
}

impl PartialOrd for TagFamily {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for TagFamily {
    /// By name, as the files list them.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.name().cmp(other.name())
    }
}

impl std::fmt::Display for TagFamily {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A tag: its family and id (ids are unique within a family).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TagId {
    /// The family.
    pub family: TagFamily,
    /// The id.
    pub id: u32,
}

/// The AprilTag families the tag detectors look for (not the AprilGrid's, which its own detector
/// finds; the ArUco dictionaries are detectable too, [`TagFamily::is_detectable`]).
pub const DETECTABLE_FAMILIES: [TagFamily; 4] = [
    TagFamily::Tag36h11,
    TagFamily::Tag25h9,
    TagFamily::Tag16h5,
    TagFamily::TagStandard41h12,
];

impl TagFamily {
    /// Bit errors corrected by default: 2 for tag36h11 and tagStandard41h12 (minimum Hamming
    /// distance 11 and 12: the C library's own default), 1 for tag25h9 (9), 0 for tag16h5 (5: on
    /// the EuRoC pair and the AprilGrid frames every corrected 16h5 code is texture).
    pub fn default_max_hamming(&self) -> usize {
        match self {
            TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 | TagFamily::TagStandard41h12 => 2,
            TagFamily::Tag25h9 => 1,
            TagFamily::Tag16h5 => 0,
            TagFamily::Aruco(d) => d.default_max_hamming(),
        }
    }

    /// What `--family` and the files take, for error messages.
    pub const NAMES: &'static str = "tag36h11, tag25h9, tag16h5, tagStandard41h12, \
        aprilgrid36h11 (Kalibr's AprilGrid tags, also tag36h11b2) or an OpenCV ArUco dictionary \
        (DICT_4X4_50 ... DICT_7X7_1000)";

    /// Whether the tag detectors find it (all but Kalibr's AprilGrid tags, which the AprilGrid
    /// detector finds).
    pub fn is_detectable(&self) -> bool {
        !matches!(self, TagFamily::Aprilgrid36h11)
    }

    /// The name the AprilTag library uses.
    pub fn name(&self) -> &'static str {
        match self {
            TagFamily::Tag36h11 => "tag36h11",
            TagFamily::Tag25h9 => "tag25h9",
            TagFamily::Tag16h5 => "tag16h5",
            TagFamily::TagStandard41h12 => "tagStandard41h12",
            TagFamily::Aprilgrid36h11 => "aprilgrid36h11",
            TagFamily::Aruco(d) => d.name(),
        }
    }

    /// A family from its name: the library's, `aprilgrid36h11` (also `tag36h11b2`, the
    /// 2-bit-border name) for Kalibr's AprilGrid tags, or OpenCV's name of an ArUco dictionary
    /// (`DICT_APRILTAG_16h5`, `_25h9` and `_36h11` are the AprilTag families).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "tag36h11b2" => return Some(TagFamily::Aprilgrid36h11),
            "DICT_APRILTAG_16h5" => return Some(TagFamily::Tag16h5),
            "DICT_APRILTAG_25h9" => return Some(TagFamily::Tag25h9),
            "DICT_APRILTAG_36h11" => return Some(TagFamily::Tag36h11),
            _ => {}
        }
        DETECTABLE_FAMILIES
            .into_iter()
            .chain([TagFamily::Aprilgrid36h11])
            .find(|f| f.name() == name)
            .or_else(|| {
                name.to_ascii_uppercase()
                    .starts_with("DICT_")
                    .then(|| ArucoDictionary::from_name(name).map(TagFamily::Aruco))
                    .flatten()
            })
    }

    pub(super) fn kornia(&self) -> kornia_apriltag::family::TagFamilyKind {
        use kornia_apriltag::family::TagFamilyKind as K;
        match self {
            TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 => K::Tag36H11,
            TagFamily::Tag25h9 => K::Tag25H9,
            TagFamily::Tag16h5 => K::Tag16H5,
            TagFamily::TagStandard41h12 => K::TagStandard41H12,
            TagFamily::Aruco(_) => match self.tables() {
                Some(t) => K::Custom(std::sync::Arc::new(t.clone())),
                None => K::Tag36H11,
            },
        }
    }

    /// The C library's family (null if its constructor fails); free it with [`Self::c_destroy`].
    pub(super) fn c_create(&self) -> *mut apriltag_sys::apriltag_family_t {
        if let TagFamily::Aruco(d) = self {
            return d.c_create();
        }
        // SAFETY: the library's constructors take nothing and return an owned family.
        unsafe {
            match self {
                TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 => apriltag_sys::tag36h11_create(),
                TagFamily::Tag25h9 => apriltag_sys::tag25h9_create(),
                TagFamily::Tag16h5 => apriltag_sys::tag16h5_create(),
                TagFamily::TagStandard41h12 => apriltag_sys::tagStandard41h12_create(),
                TagFamily::Aruco(_) => std::ptr::null_mut(),
            }
        }
    }

    /// Frees a family from [`Self::c_create`] of the same kind.
    ///
    /// # Safety
    /// `family` came from `self.c_create()`, is not null, and is used by no live detector.
    pub(super) unsafe fn c_destroy(&self, family: *mut apriltag_sys::apriltag_family_t) {
        // SAFETY: as the caller promises.
        unsafe {
            match self {
                TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 => {
                    apriltag_sys::tag36h11_destroy(family)
                }
                TagFamily::Tag25h9 => apriltag_sys::tag25h9_destroy(family),
                TagFamily::Tag16h5 => apriltag_sys::tag16h5_destroy(family),
                TagFamily::TagStandard41h12 => apriltag_sys::tagStandard41h12_destroy(family),
                TagFamily::Aruco(d) => d.c_destroy(family),
            }
        }
    }
}

/// A tag's printed pattern as the AprilTag library draws it (`apriltag_to_image`): a square of
/// cells, row-major from the top-left, `true` where white.
#[derive(Debug, Clone, PartialEq)]
pub struct TagImage {
    /// Cells across the whole pattern, the library's 1-cell white border included.
    pub total_cells: usize,
    /// Cells across the black square whose corners are the tag's corners.
    pub black_square_cells: usize,
    /// Row-major, `total_cells²` entries.
    pub white: Vec<bool>,
}

impl TagFamily {
    /// The family's code tables (built once per process: kornia builds a decoding table with them).
    pub(super) fn tables(&self) -> Option<&'static kornia_apriltag::family::TagFamily> {
        use kornia_apriltag::family::TagFamily as K;
        use std::sync::OnceLock;
        static T36: OnceLock<Option<K>> = OnceLock::new();
        static T25: OnceLock<Option<K>> = OnceLock::new();
        static T16: OnceLock<Option<K>> = OnceLock::new();
        static T41: OnceLock<Option<K>> = OnceLock::new();
        type Cached = OnceLock<Option<K>>;
        static ARUCO: [Cached; 16] = [const { OnceLock::new() }; 16];
        if let TagFamily::Aruco(d) = self {
            return ARUCO
                .get(d.index())?
                .get_or_init(|| d.kornia_family())
                .as_ref();
        }
        let (cell, make): (&Cached, fn() -> Option<K>) = match self {
            TagFamily::Tag36h11 | TagFamily::Aprilgrid36h11 => (&T36, || K::tag36_h11().ok()),
            TagFamily::Tag25h9 => (&T25, || K::tag25_h9().ok()),
            TagFamily::Tag16h5 => (&T16, || K::tag16_h5().ok()),
            TagFamily::TagStandard41h12 => (&T41, || K::tagstandard41_h12().ok()),
            TagFamily::Aruco(_) => return None,
        };
        cell.get_or_init(make).as_ref()
    }

    /// Number of ids in the family.
    pub fn code_count(&self) -> usize {
        self.tables().map_or(0, |f| f.code_data.len())
    }

    /// The printed pattern of tag `id`, from the family's true code bits; `None` past the last id.
    pub fn code_image(&self, id: u32) -> Option<TagImage> {
        let family = self.tables()?;
        let code = *family.code_data.get(id as usize)?;
        let tw = family.total_width as i64;
        let border = (tw - family.width_at_border as i64) / 2;
        let inside = |v: i64| v >= border && v < tw - border;
        let mut white: Vec<bool> = (0..tw * tw)
            .map(|i| {
                let (x, y) = (i % tw, i / tw);
                if family.reversed_border {
                    // Reversed-border families: black but for a one-cell white ring around the
                    // corner square (`apriltag_to_image`); the code bits lie inside and outside
                    // it.
                    let ring = |v: i64| v == border || v == tw - 1 - border;
                    (ring(x) && inside(y)) || (ring(y) && inside(x))
                } else {
                    !(inside(x) && inside(y))
                }
            })
            .collect();
        for i in 0..family.nbits {
            if code & (1usize << (family.nbits - i - 1)) != 0 {
                let (x, y) = (
                    family.bit_x[i] as i64 + border,
                    family.bit_y[i] as i64 + border,
                );
                if (0..tw).contains(&x) && (0..tw).contains(&y) {
                    white[(y * tw + x) as usize] = true;
                }
            }
        }
        Some(TagImage {
            total_cells: tw as usize,
            black_square_cells: family.width_at_border,
            white,
        })
    }
}
