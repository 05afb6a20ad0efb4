//! Tags as the renderer paints them (the family's true code bits, a white quiet zone, printed
//! just in front of their wall) and the procedural texture of walls and floors.

use super::*;
use crate::world::Tag;
use nalgebra::Vector3;

/// A tag ready to draw: its frame on the wall and its bits.
pub(super) struct TagPaint {
    pub(super) centre: Vector3<f64>,
    pub(super) normal: Vector3<f64>,
    pub(super) right: Vector3<f64>,
    /// Up the printed tag (the world's up for a tag on a wall).
    pub(super) up: Vector3<f64>,
    /// Cell size, metres (the black square is `width_at_border` cells).
    pub(super) cell_m: f64,
    /// `1 / cell_m`.
    pub(super) cells_per_m: f64,
    /// Cells across the drawn area, quiet zone included.
    pub(super) total_cells: i64,
    /// `true` where a cell is white, row-major over `total_cells`.
    pub(super) white: Vec<bool>,
}

/// A tag's printed face stands this far in front of its wall, metres (so the wall never shows
/// through it); its drawn corners and its true corners both lie on that face.
pub(super) const TAG_STANDOFF_M: f64 = 0.001;

/// White cells drawn around the black square (the standard image has 1; we draw 2 so a tag on
/// a textured wall keeps its quiet zone).
pub(super) const QUIET_ZONE_CELLS: i64 = 2;

pub(super) fn tag_paint(tag: &Tag) -> Result<TagPaint, RenderError> {
    let family =
        Some(tag.family)
            .filter(|f| f.is_detectable())
            .ok_or(RenderError::UnknownFamily {
                id: tag.id,
                family: tag.family,
            })?;
    let image = family
        .code_image(tag.id)
        .ok_or_else(|| RenderError::IdOutOfRange {
            id: tag.id,
            family: tag.family,
            count: family.code_count(),
        })?;
    let tw = image.total_cells as i64;
    let img = &image.white;
    // Add the quiet zone.
    let total = tw + 2 * QUIET_ZONE_CELLS;
    let mut white = vec![true; (total * total) as usize];
    for y in 0..tw {
        for x in 0..tw {
            white[((y + QUIET_ZONE_CELLS) * total + x + QUIET_ZONE_CELLS) as usize] =
                img[(y * tw + x) as usize];
        }
    }
    let r = tag.rotation();
    Ok(TagPaint {
        centre: Vector3::from(tag.position_m),
        normal: r * Vector3::x(),
        right: r * Vector3::y(),
        up: r * Vector3::z(),
        cell_m: tag.size_m / image.black_square_cells as f64,
        cells_per_m: image.black_square_cells as f64 / tag.size_m,
        total_cells: total,
        white,
    })
}

impl TagPaint {
    /// The tag's corners in the world, C order: tag image bottom-left, bottom-right, top-right,
    /// top-left of the black square (tag frame (-1, 1), (1, 1), (1, -1), (-1, -1), y down).
    pub(super) fn corners(&self, size_m: f64) -> [Vector3<f64>; 4] {
        let h = 0.5 * size_m;
        let down = -self.up;
        let face = self.centre + self.normal * TAG_STANDOFF_M;
        [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)]
            .map(|(x, y)| face + self.right * (x * h) + down * (y * h))
    }

    /// Where the ray meets the tag, when nearer than `best` plus 2 mm: the distance as a
    /// fraction, and the albedo there.
    #[inline]
    pub(super) fn hit(
        &self,
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
        best: Fraction,
    ) -> Option<(Fraction, f64)> {
        let den = -dir.dot(&self.normal);
        if den <= 1e-9 {
            return None; // seen from behind or edge-on
        }
        let num = (origin - self.centre).dot(&self.normal) - TAG_STANDOFF_M;
        if num <= 0.0 || num * best.den >= (best.num + 0.002 * best.den) * den {
            return None;
        }
        // The point met, relative to the centre, times `den`.
        let q = (origin - self.centre) * den + dir * num;
        let half = 0.5 * self.total_cells as f64 * den;
        let col = q.dot(&self.right) * self.cells_per_m + half;
        let row = -q.dot(&self.up) * self.cells_per_m + half;
        let total = self.total_cells as f64 * den;
        if col < 0.0 || row < 0.0 || col >= total || row >= total {
            return None;
        }
        let k = 1.0 / den;
        let cell = ((row * k) as i64).min(self.total_cells - 1) * self.total_cells
            + ((col * k) as i64).min(self.total_cells - 1);
        let white = self.white[cell as usize];
        Some((
            Fraction { num, den },
            if white { TAG_WHITE } else { TAG_BLACK },
        ))
    }

    /// Whether a ray passes within `margin_rad` of the tag's drawn square (the margin is
    /// taken on the tag's plane, where it grows as the ray's incidence grazes).
    pub(super) fn covers(
        &self,
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
        margin_rad: f64,
    ) -> bool {
        let den = -dir.dot(&self.normal);
        let num = (origin - self.centre).dot(&self.normal) - TAG_STANDOFF_M;
        if den <= 1e-9 || num <= 0.0 {
            return false;
        }
        let t = num / den;
        let p = origin + dir * t - self.centre;
        let half = 0.5 * self.total_cells as f64 * self.cell_m + margin_rad * t / den;
        p.dot(&self.right).abs() <= half && p.dot(&self.up).abs() <= half
    }
}

/// Albedo of a tag's white paper.
pub(crate) const TAG_WHITE: f64 = 0.92;
/// Albedo of a tag's black ink.
pub(crate) const TAG_BLACK: f64 = 0.08;

/// `x.floor()` without the libm call the baseline x86-64 target makes of it (no SSE4.1 round
/// instruction); exact for |x| < 2^52.
#[inline]
pub(super) fn fast_floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// Side of the value-noise lattice; the texture repeats every this many lattice cells (32 m on
/// the floor's coarse octave, 6.4 m on its fine one).
pub(super) const LATTICE: usize = 256;

/// The lattice values in [-1, 1], hashed once from their coordinates.
pub(super) fn lattice() -> &'static [f32; LATTICE * LATTICE] {
    static TABLE: std::sync::OnceLock<Box<[f32; LATTICE * LATTICE]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut table = Box::new([0f32; LATTICE * LATTICE]);
        for (k, value) in table.iter_mut().enumerate() {
            let (i, j) = ((k % LATTICE) as u64, (k / LATTICE) as u64);
            let mut h =
                i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ j.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
            h ^= h >> 29;
            h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            h ^= h >> 32;
            *value = ((h & 0xFFFF) as f64 / 32767.5 - 1.0) as f32;
        }
        table
    })
}

/// A smooth, deterministic texture value in [-1, 1] (value noise on a periodic lattice).
#[inline]
pub(crate) fn texture(u: f64, v: f64) -> f64 {
    let table = lattice();
    let (i, j) = (fast_floor(u), fast_floor(v));
    // The fractions and the blend in f32, as the lattice is stored.
    let (fu, fv) = ((u - i) as f32, (v - j) as f32);
    let (su, sv) = (fu * fu * (3.0 - 2.0 * fu), fv * fv * (3.0 - 2.0 * fv));
    const MASK: usize = LATTICE - 1;
    let (i0, j0) = (i as i64 as usize & MASK, j as i64 as usize & MASK);
    let (i1, j1) = ((i0 + 1) & MASK, (j0 + 1) & MASK);
    let at = |i: usize, j: usize| table[(j * LATTICE + i) & (LATTICE * LATTICE - 1)];
    let a = at(i0, j0) + (at(i1, j0) - at(i0, j0)) * su;
    let b = at(i0, j1) + (at(i1, j1) - at(i0, j1)) * su;
    (a + (b - a) * sv) as f64
}
