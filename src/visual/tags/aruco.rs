//! OpenCV's ArUco dictionaries (`DICT_4X4_50` ... `DICT_7X7_1000`) as tag families both
//! backends decode: an ArUco marker is an AprilTag-like square, `n x n` code cells inside a
//! one-cell black border, so each dictionary becomes a family with its code cells listed in four
//! quarters that a quarter turn maps onto each other (the AprilTag library's `rotate90` is then
//! a turn of the marker), and the centre cell last when `n` is odd.

use super::aruco_codes::{ArucoEntry, DICTIONARIES};

/// One of OpenCV's predefined ArUco dictionaries (`DICT_4X4_50` ... `DICT_7X7_1000`), by its
/// OpenCV name. `DICT_ARUCO_ORIGINAL` is not one: two of its codes are quarter turns of each
/// other, so a marker's id and orientation cannot both be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ArucoDictionary(u8);

impl ArucoDictionary {
    /// Every dictionary, in OpenCV's order.
    pub fn all() -> impl Iterator<Item = Self> {
        (0..DICTIONARIES.len() as u8).map(Self)
    }

    /// The dictionary named `name` (OpenCV's name, `DICT_5X5_100`; case does not matter, and
    /// the `DICT_` may be left out).
    pub fn from_name(name: &str) -> Option<Self> {
        let upper = name.to_ascii_uppercase();
        let full = if upper.starts_with("DICT_") {
            upper
        } else {
            format!("DICT_{upper}")
        };
        Self::all().find(|d| d.name() == full)
    }

    /// Its place in OpenCV's order.
    pub(super) fn index(&self) -> usize {
        self.0 as usize
    }

    fn entry(&self) -> &'static ArucoEntry {
        &DICTIONARIES[self.index()]
    }

    /// OpenCV's name.
    pub fn name(&self) -> &'static str {
        self.entry().name
    }

    /// Code cells across a marker (4 to 7).
    pub fn cells(&self) -> usize {
        self.entry().cells
    }

    /// Number of markers.
    pub fn count(&self) -> usize {
        self.entry().count
    }

    /// The least number of cells in which two markers differ, in any quarter turn.
    pub fn min_hamming(&self) -> u32 {
        self.entry().min_hamming
    }

    /// Bit errors corrected by default: OpenCV's rule (60% of the dictionary's
    /// `maxCorrectionBits`, rounded down), at most 2 as for tag36h11: 0 for the 4x4
    /// dictionaries, 1 for 5x5, 2 for 6x6 and 7x7.
    pub fn default_max_hamming(&self) -> usize {
        ((self.entry().max_correction_bits * 6 / 10) as usize).min(2)
    }

    /// The code cells as the family lists them (x, y in the black square's cells, the border at
    /// 0 and `n + 1`): the cells of one quarter, then each quarter turned a quarter turn
    /// clockwise as printed from the previous, then the centre when `n` is odd.
    pub(super) fn layout(&self) -> Vec<(i8, i8)> {
        let n = self.cells() as i8;
        // One quarter: x in 1..=ceil(n/2), y in 1..=floor(n/2); its turns tile the rest.
        let quarter: Vec<(i8, i8)> = (1..=n / 2)
            .flat_map(|y| (1..=(n + 1) / 2).map(move |x| (x, y)))
            .collect();
        let mut cells = Vec::with_capacity((n * n) as usize);
        let mut turned = quarter;
        for _ in 0..4 {
            cells.extend(turned.iter().copied());
            turned = turned.iter().map(|&(x, y)| (n + 1 - y, x)).collect();
        }
        if n % 2 == 1 {
            cells.push((n / 2 + 1, n / 2 + 1));
        }
        cells
    }

    /// Every marker's code in the family's bit order ([`Self::layout`], first cell most
    /// significant), 1 where white.
    pub(super) fn codes(&self) -> Vec<u64> {
        let n = self.cells();
        let layout = self.layout();
        let nbits = layout.len();
        self.entry().codes[..self.count()]
            .iter()
            .map(|&printed| {
                layout.iter().enumerate().fold(0u64, |code, (j, &(x, y))| {
                    let (r, c) = (y as usize - 1, x as usize - 1);
                    let bit = (printed >> (n * n - 1 - (r * n + c))) & 1;
                    code | bit << (nbits - 1 - j)
                })
            })
            .collect()
    }

    /// The family as kornia-apriltag's tables describe one (our decoder reads them).
    pub(super) fn kornia_family(&self) -> Option<kornia_apriltag::family::TagFamily> {
        use kornia_apriltag::decoder::{QuickDecode, SharpeningBuffer};
        let n = self.cells();
        let layout = self.layout();
        let codes: Vec<usize> = self.codes().into_iter().map(|c| c as usize).collect();
        let max_hamming = self.default_max_hamming().min(3) as u8;
        Some(kornia_apriltag::family::TagFamily {
            name: self.name().to_string(),
            width_at_border: n + 2,
            reversed_border: false,
            total_width: n + 4,
            nbits: n * n,
            bit_x: layout.iter().map(|c| c.0).collect(),
            bit_y: layout.iter().map(|c| c.1).collect(),
            min_hamming: self.min_hamming() as u8,
            quick_decode: QuickDecode::new(n * n, &codes, max_hamming).ok()?,
            code_data: codes,
            sharpening_buffer: SharpeningBuffer::new((n + 4) * (n + 4)),
        })
    }

    /// The family as the C library takes one, owned by the caller: free it with
    /// [`Self::c_destroy`].
    pub(super) fn c_create(&self) -> *mut apriltag_sys::apriltag_family_t {
        let n = self.cells();
        let layout = self.layout();
        let leak_u32 = |v: Vec<u32>| Box::into_raw(v.into_boxed_slice()) as *mut u32;
        let codes = Box::into_raw(self.codes().into_boxed_slice()) as *mut u64;
        let name = std::ffi::CString::new(self.name()).unwrap_or_default();
        Box::into_raw(Box::new(apriltag_sys::apriltag_family_t {
            ncodes: self.count() as u32,
            codes,
            width_at_border: (n + 2) as i32,
            total_width: (n + 4) as i32,
            reversed_border: false,
            nbits: (n * n) as u32,
            bit_x: leak_u32(layout.iter().map(|c| c.0 as u32).collect()),
            bit_y: leak_u32(layout.iter().map(|c| c.1 as u32).collect()),
            h: self.min_hamming(),
            name: name.into_raw(),
            impl_: std::ptr::null_mut(),
        }))
    }

    /// Frees a family from [`Self::c_create`].
    ///
    /// # Safety
    /// `family` came from `self.c_create()` and is used by no live detector (which has freed
    /// the decoding table it hung on the family).
    pub(super) unsafe fn c_destroy(&self, family: *mut apriltag_sys::apriltag_family_t) {
        let nbits = self.cells() * self.cells();
        // SAFETY: every pointer was made by `c_create` from a boxed slice of this length (or
        // `CString::into_raw`), and is freed once, here.
        unsafe {
            let f = Box::from_raw(family);
            drop(Box::from_raw(std::ptr::slice_from_raw_parts_mut(
                f.codes,
                self.count(),
            )));
            drop(Box::from_raw(std::ptr::slice_from_raw_parts_mut(
                f.bit_x, nbits,
            )));
            drop(Box::from_raw(std::ptr::slice_from_raw_parts_mut(
                f.bit_y, nbits,
            )));
            drop(std::ffi::CString::from_raw(f.name));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quarter_turn_of_the_layout_is_a_shift_by_a_quarter() {
        for d in ArucoDictionary::all() {
            let n = d.cells() as i8;
            let layout = d.layout();
            assert_eq!(layout.len(), (n * n) as usize, "{}", d.name());
            let mut seen = std::collections::BTreeSet::new();
            assert!(layout.iter().all(|c| seen.insert(*c)), "{}", d.name());
            let q = layout.len() / 4;
            for (j, &(x, y)) in layout[..4 * q].iter().enumerate() {
                assert_eq!(layout[(j + q) % (4 * q)], (n + 1 - y, x), "{}", d.name());
            }
        }
    }

    /// The black square of `family`'s tag `id` as printed, `1` where white, row by row.
    fn printed(family: super::super::TagFamily, id: u32) -> Vec<String> {
        let t = family.code_image(id).unwrap();
        let (tw, n) = (t.total_cells, t.black_square_cells);
        let b = (tw - n) / 2;
        (b..b + n)
            .map(|y| {
                (b..b + n)
                    .map(|x| if t.white[y * tw + x] { '1' } else { '0' })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn markers_print_as_opencv_draws_them() {
        use super::super::TagFamily;
        // cv2.aruco.generateImageMarker(DICT_4X4_50, 0, 6, borderBits=1) (OpenCV 5.1).
        let d = TagFamily::from_name("DICT_4X4_50").unwrap();
        assert_eq!(
            printed(d, 0),
            ["000000", "010110", "001010", "000110", "000100", "000000"]
        );
        // OpenCV's DICT_APRILTAG_* marker 0 is the AprilTag library's tag 0 turned upside down
        // (generateImageMarker(DICT_APRILTAG_16h5, 0, 6, borderBits=1), ...).
        let turned = |rows: Vec<String>| -> Vec<String> {
            rows.iter()
                .rev()
                .map(|r| r.chars().rev().collect())
                .collect()
        };
        for (name, family, opencv) in [
            (
                "DICT_APRILTAG_16h5",
                TagFamily::Tag16h5,
                &["000000", "011010", "010000", "011000", "001000", "000000"][..],
            ),
            (
                "DICT_APRILTAG_25h9",
                TagFamily::Tag25h9,
                &[
                    "0000000", "0100010", "0111110", "0010010", "0110100", "0101010", "0000000",
                ][..],
            ),
            (
                "DICT_APRILTAG_36h11",
                TagFamily::Tag36h11,
                &[
                    "00000000", "00010000", "00110100", "00001010", "00001100", "01011100",
                    "01010110", "00000000",
                ][..],
            ),
        ] {
            assert_eq!(TagFamily::from_name(name), Some(family));
            assert_eq!(turned(printed(family, 0)), opencv, "{name}");
        }
    }

    #[test]
    fn dictionaries_are_found_by_opencv_names() {
        let d = ArucoDictionary::from_name("DICT_5X5_100").unwrap();
        assert_eq!((d.cells(), d.count()), (5, 100));
        assert_eq!(
            ArucoDictionary::from_name("4x4_50").map(|d| d.count()),
            Some(50)
        );
        assert!(ArucoDictionary::from_name("DICT_ARUCO_ORIGINAL").is_none());
        assert_eq!(ArucoDictionary::all().count(), 16);
    }
}
