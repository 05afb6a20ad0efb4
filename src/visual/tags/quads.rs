//! The AprilTag C library's quad stage, in Rust, on kornia-apriltag's segmentation.
//!
//! kornia-apriltag 0.2 finds 38 of the 47 tags in the C library's own test photos
//! (`../shared/data/apriltag_test`, decimate 1, no edge refinement) where the C library finds
//! all 47. Measured on those photos (`tests/detect_real.rs`), the gap has two causes:
//! - its decoder samples each bit cell half a pixel off the C library 3.4.5's (kornia's bilinear
//!   `value_for_pixel` has no `- 0.5`), which flips bits on small tags: handed the C library's
//!   own 47 quads, kornia's decoder reads 41;
//! - its quad fit puts 5 of the 47 quads 0.6 to 6 px from the C library's (not traced further:
//!   it fits in single precision and orders cluster points its own way).
//!
//! So [`detect`] keeps kornia-apriltag's adaptive threshold, connected components, tag families
//! and code tables, and does the rest as the C library 3.4.5 does (`apriltag_quad_thresh.c`,
//! `apriltag.c`): boundary clusters between black and white components, the quad fit (points
//! sorted by angle, segmented at the maxima of the line-fit error, four lines intersected),
//! optional edge refinement, the homography, decoding against a grey model of the border,
//! and the reconciliation of overlapping detections of one id.

use super::decode::{decode_quad, reconcile};
use image::GrayImage;
use kornia_apriltag::family::TagFamily as Family;
use kornia_apriltag::utils::Pixel;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// The C library's quad-fit settings (`apriltag_detector_create`'s defaults).
const MAX_NMAXIMA: usize = 10;
const MIN_CLUSTER_PIXELS: usize = 5;
const MAX_LINE_FIT_MSE: f32 = 10.0;
/// Components smaller than this take no part in a cluster.
const MIN_COMPONENT: usize = 25;

/// What the quad stage is asked to do.
pub(crate) struct QuadSettings {
    /// Integer decimation before segmentation (1: none).
    pub decimate: u32,
    /// Refine the quad edges on the full image.
    pub refine_edges: bool,
    /// Sharpening of the decoded bits.
    pub sharpening: f64,
    /// Smallest white-black difference of a tile's neighbourhood.
    pub min_contrast: u8,
}

/// One decoded tag, in the library's pixel-corner convention, corners in the C library's order.
pub(crate) struct Decoded {
    /// Index of the family in the list given to [`detect`].
    pub family: usize,
    /// Tag id.
    pub id: u32,
    /// Bits corrected.
    pub hamming: u32,
    /// Decision margin (larger is surer).
    pub margin: f64,
    /// Corners, tag frame (-1, 1), (1, 1), (1, -1), (-1, -1).
    pub corners: [[f64; 2]; 4],
    /// Centre.
    pub centre: [f64; 2],
}

/// A point between a black and a white pixel, in half pixels, with the direction to white.
#[derive(Clone, Copy, Debug)]
pub(super) struct Pt {
    x: u16,
    y: u16,
    gx: i16,
    gy: i16,
    slope: f32,
}

/// A fitted quad: corners in the (decimated) image, and whether the border is reversed.
#[derive(Clone, Debug)]
pub(super) struct Quad {
    pub(super) p: [[f64; 2]; 4],
    pub(super) reversed_border: bool,
}

/// Detects the tags of `families` in `image`.
pub(crate) fn detect(
    image: &GrayImage,
    families: &[Family],
    settings: &QuadSettings,
) -> Result<Vec<Decoded>, String> {
    let decimate = settings.decimate.max(1) as usize;
    if image.width() < 4 || image.height() < 4 {
        return Ok(Vec::new());
    }
    let small: std::borrow::Cow<'_, GrayImage> = if decimate > 1 {
        std::borrow::Cow::Owned(decimate_image(image, decimate))
    } else {
        std::borrow::Cow::Borrowed(image)
    };
    let (w, h) = (small.width() as usize, small.height() as usize);
    if w < 4 || h < 4 || families.is_empty() {
        return Ok(Vec::new());
    }
    // Boundary points are kept at twice the resolution in 16 bits, as the C library's.
    if w >= 32768 || h >= 32768 {
        return Err(format!(
            "a {w} x {h} image (after decimation) is too large: at most 32767 px either way"
        ));
    }
    let size = kornia_image::ImageSize {
        width: w,
        height: h,
    };
    let src = kornia_image::Image::<u8, 1>::from_size_slice(size, small.as_raw())
        .map_err(|e| e.to_string())?;
    let mut bin = kornia_image::Image::<Pixel, 1>::from_size_val(size, Pixel::Skip)
        .map_err(|e| e.to_string())?;
    let mut tiles = kornia_apriltag::threshold::TileMinMax::new(size, 4);
    kornia_apriltag::threshold::adaptive_threshold_with_split(
        &src,
        &mut bin,
        &mut tiles,
        settings.min_contrast,
        0.5,
    )
    .map_err(|e| e.to_string())?;
    let mut uf = kornia_apriltag::union_find::UnionFind::new(w * h);
    kornia_apriltag::segmentation::find_connected_components(&bin, &mut uf)
        .map_err(|e| e.to_string())?;
    let levels: Vec<u8> = bin.as_slice().iter().map(|&p| p as u8).collect();
    let clusters = gradient_clusters(&levels, w, h, &mut uf);

    let mut tag_width = families
        .iter()
        .map(|f| f.width_at_border)
        .min()
        .unwrap_or(3) as i32;
    if decimate > 1 {
        tag_width /= decimate as i32;
    }
    let tag_width = tag_width.max(3);
    let normal_border = families.iter().any(|f| !f.reversed_border);
    let reversed_border = families.iter().any(|f| f.reversed_border);
    let max_cluster = 2 * (2 * w + 2 * h);
    let mut quads: Vec<Quad> = clusters
        .into_par_iter()
        .filter(|c| c.len() >= MIN_CLUSTER_PIXELS && c.len() <= max_cluster)
        .filter_map(|mut c| fit_quad(&small, &mut c, tag_width, normal_border, reversed_border))
        .collect();
    if decimate > 1 {
        for q in &mut quads {
            for p in &mut q.p {
                p[0] *= decimate as f64;
                p[1] *= decimate as f64;
            }
        }
    }
    let found: Vec<Decoded> = quads
        .into_par_iter()
        .flat_map_iter(|mut quad| {
            if settings.refine_edges {
                refine_edges(image, &mut quad, decimate as f64);
            }
            if !quad.p.iter().flatten().all(|v| v.is_finite()) {
                return Vec::new();
            }
            decode_quad(image, &quad, families, settings.sharpening)
        })
        .collect();
    Ok(reconcile(found))
}

/// The C library's integer decimation: the top-left pixel of each `factor` x `factor` cell.
fn decimate_image(image: &GrayImage, factor: usize) -> GrayImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let (sw, sh) = (1 + (w - 1) / factor, 1 + (h - 1) / factor);
    let raw = image.as_raw();
    let mut out = Vec::with_capacity(sw * sh);
    for y in (0..h).step_by(factor) {
        for x in (0..w).step_by(factor) {
            out.push(raw[y * w + x]);
        }
    }
    GrayImage::from_raw(sw as u32, sh as u32, out).unwrap_or_default()
}

/// A pixel that takes part in no cluster (skipped, or in a component under [`MIN_COMPONENT`]).
const NO_COMPONENT: u32 = u32::MAX;

/// Boundary points between every pair of adjacent black and white components of at least
/// [`MIN_COMPONENT`] pixels, grouped by the pair (`do_gradient_clusters`), each cluster's
/// points in scan order; row strips in parallel, joined in row order.
fn gradient_clusters(
    bin: &[u8],
    w: usize,
    h: usize,
    uf: &mut kornia_apriltag::union_find::UnionFind,
) -> Vec<Vec<Pt>> {
    let comps: Vec<u32> = (0..w * h)
        .map(|i| {
            if bin[i] == 127 {
                return NO_COMPONENT;
            }
            let rep = uf.get_representative(i);
            if uf.get_set_size(rep) < MIN_COMPONENT {
                NO_COMPONENT
            } else {
                rep as u32
            }
        })
        .collect();
    let rows: Vec<usize> = (1..h.saturating_sub(1)).collect();
    let strips: Vec<StripClusters> = rows
        .par_chunks(32)
        .map(|ys| {
            let mut strip = StripClusters::default();
            for &y in ys {
                strip.scan_row(bin, &comps, w, y);
            }
            strip
        })
        .collect();
    let mut index: FxHashMap<u64, usize> = FxHashMap::default();
    let mut clusters: Vec<(u64, Vec<Pt>)> = Vec::new();
    for strip in strips {
        for (id, pts) in strip.clusters {
            match index.get(&id) {
                Some(&k) => clusters[k].1.extend_from_slice(&pts),
                None => {
                    index.insert(id, clusters.len());
                    clusters.push((id, pts));
                }
            }
        }
    }
    clusters.sort_unstable_by_key(|(id, _)| *id);
    clusters.into_iter().map(|(_, c)| c).collect()
}

/// The clusters of a strip of rows.
#[derive(Default)]
struct StripClusters {
    index: FxHashMap<u64, usize>,
    clusters: Vec<(u64, Vec<Pt>)>,
    /// The last cluster added to (most points follow the previous one's).
    last: Option<(u64, usize)>,
}

impl StripClusters {
    fn scan_row(&mut self, bin: &[u8], comps: &[u32], w: usize, y: usize) {
        let mut connected_last = false;
        for x in 1..w - 1 {
            let c0 = comps[y * w + x];
            if c0 == NO_COMPONENT {
                connected_last = false;
                continue;
            }
            let v0 = bin[y * w + x];
            let mut conn = |dx: i32, dy: i32| {
                let i1 = (y as i32 + dy) as usize * w + (x as i32 + dx) as usize;
                let v1 = bin[i1];
                let c1 = comps[i1];
                if v0 as u32 + v1 as u32 != 255 || c1 == NO_COMPONENT {
                    return false;
                }
                let (lo, hi) = if c0 < c1 { (c0, c1) } else { (c1, c0) };
                let g = v1 as i16 - v0 as i16;
                self.push(
                    ((hi as u64) << 32) + lo as u64,
                    Pt {
                        x: (2 * x as i32 + dx) as u16,
                        y: (2 * y as i32 + dy) as u16,
                        gx: dx as i16 * g,
                        gy: dy as i16 * g,
                        slope: 0.0,
                    },
                );
                true
            };
            conn(1, 0);
            conn(0, 1);
            if !connected_last {
                conn(-1, 1);
            }
            connected_last = conn(1, 1);
        }
    }

    fn push(&mut self, id: u64, p: Pt) {
        let k = match self.last {
            Some((last, k)) if last == id => k,
            _ => {
                let k = *self.index.entry(id).or_insert_with(|| {
                    self.clusters.push((id, Vec::new()));
                    self.clusters.len() - 1
                });
                self.last = Some((id, k));
                k
            }
        };
        self.clusters[k].1.push(p);
    }
}

/// Cumulative weighted moments of the points, for line fits over any run of them.
#[derive(Clone, Copy, Default)]
struct Moments {
    mx: f64,
    my: f64,
    mxx: f64,
    myy: f64,
    mxy: f64,
    w: f64,
}

/// Prefix sums of the points' moments, each weighted by the image gradient there
/// (`compute_lfps`).
fn line_fit_moments(cluster: &[Pt], im: &GrayImage) -> Vec<Moments> {
    let (w, h) = (im.width() as i64, im.height() as i64);
    let raw = im.as_raw();
    let px = |x: i64, y: i64| raw[(y * w + x) as usize] as i64;
    let mut acc = Moments::default();
    cluster
        .iter()
        .map(|p| {
            let x = p.x as f64 * 0.5 + 0.5;
            let y = p.y as f64 * 0.5 + 0.5;
            let (ix, iy) = (x as i64, y as i64);
            let mut weight = 1.0;
            if ix > 0 && ix + 1 < w && iy > 0 && iy + 1 < h {
                let gx = px(ix + 1, iy) - px(ix - 1, iy);
                let gy = px(ix, iy + 1) - px(ix, iy - 1);
                weight = ((gx * gx + gy * gy) as f64).sqrt() + 1.0;
            }
            acc.mx += weight * x;
            acc.my += weight * y;
            acc.mxx += weight * x * x;
            acc.mxy += weight * x * y;
            acc.myy += weight * y * y;
            acc.w += weight;
            acc
        })
        .collect()
}

/// A line fitted to points `i0..=i1` (wrapping): (point, unit normal) and the summed and mean
/// squared errors (`fit_line`, with its single-precision square roots).
fn fit_line(m: &[Moments], i0: usize, i1: usize) -> ([f64; 4], f64, f64) {
    let sz = m.len();
    let sub = |a: Moments, b: Moments| Moments {
        mx: a.mx - b.mx,
        my: a.my - b.my,
        mxx: a.mxx - b.mxx,
        myy: a.myy - b.myy,
        mxy: a.mxy - b.mxy,
        w: a.w - b.w,
    };
    let (s, n) = if i0 < i1 {
        let s = if i0 > 0 { sub(m[i1], m[i0 - 1]) } else { m[i1] };
        (s, i1 - i0 + 1)
    } else {
        let t = sub(m[sz - 1], m[i0 - 1]);
        let s = Moments {
            mx: t.mx + m[i1].mx,
            my: t.my + m[i1].my,
            mxx: t.mxx + m[i1].mxx,
            myy: t.myy + m[i1].myy,
            mxy: t.mxy + m[i1].mxy,
            w: t.w + m[i1].w,
        };
        (s, sz - i0 + i1 + 1)
    };
    let ex = s.mx / s.w;
    let ey = s.my / s.w;
    let cxx = s.mxx / s.w - ex * ex;
    let cxy = s.mxy / s.w - ex * ey;
    let cyy = s.myy / s.w - ey * ey;
    let root = (((cxx - cyy) * (cxx - cyy) + 4.0 * cxy * cxy) as f32).sqrt() as f64;
    let eig_small = 0.5 * (cxx + cyy - root);
    let eig = 0.5 * (cxx + cyy + root);
    let (nx1, ny1) = (cxx - eig, cxy);
    let (nx2, ny2) = (cxy, cyy - eig);
    let (m1, m2) = (nx1 * nx1 + ny1 * ny1, nx2 * nx2 + ny2 * ny2);
    let (nx, ny, mm) = if m1 > m2 {
        (nx1, ny1, m1)
    } else {
        (nx2, ny2, m2)
    };
    let length = (mm as f32).sqrt() as f64;
    let line = if length.abs() < 1e-12 {
        [ex, ey, 0.0, 0.0]
    } else {
        [ex, ey, nx / length, ny / length]
    };
    (line, n as f64 * eig_small, eig_small)
}

/// The C library's angle sort (`ptsort`): its sorting networks and merge, so points of equal
/// angle keep the order the C library gives them.
fn ptsort(pts: &mut [Pt], scratch: &mut [Pt]) {
    let before = |a: &Pt, b: &Pt| a.slope - b.slope;
    let maybe_swap = |p: &mut [Pt], a: usize, b: usize| {
        if before(&p[a], &p[b]) > 0.0 {
            p.swap(a, b);
        }
    };
    let sz = pts.len();
    match sz {
        0 | 1 => return,
        2 => {
            maybe_swap(pts, 0, 1);
            return;
        }
        3 => {
            for (a, b) in [(0, 1), (1, 2), (0, 1)] {
                maybe_swap(pts, a, b);
            }
            return;
        }
        4 => {
            for (a, b) in [(0, 1), (2, 3), (0, 2), (1, 3), (1, 2)] {
                maybe_swap(pts, a, b);
            }
            return;
        }
        5 => {
            for (a, b) in [
                (0, 1),
                (3, 4),
                (1, 2),
                (0, 1),
                (0, 3),
                (2, 4),
                (1, 2),
                (2, 3),
                (1, 2),
            ] {
                maybe_swap(pts, a, b);
            }
            return;
        }
        _ => {}
    }
    // The C library merges from a copy of the two sorted halves; `scratch` holds the copy
    // (and, past it, the halves' own scratch): twice `pts`' length and a little more.
    let (tmp, rest) = scratch.split_at_mut(sz);
    tmp.copy_from_slice(pts);
    let (a, b) = tmp.split_at_mut(sz / 2);
    ptsort(a, rest);
    ptsort(b, rest);
    let (mut i, mut j, mut out) = (0, 0, 0);
    while i < a.len() && j < b.len() {
        if before(&a[i], &b[j]) < 0.0 {
            pts[out] = a[i];
            i += 1;
        } else {
            pts[out] = b[j];
            j += 1;
        }
        out += 1;
    }
    pts[out..out + a.len() - i].copy_from_slice(&a[i..]);
    let out = out + a.len() - i;
    pts[out..].copy_from_slice(&b[j..]);
}

/// The four points where the cluster is best split into four lines (`quad_segment_maxima`).
fn segment_maxima(m: &[Moments]) -> Option<[usize; 4]> {
    let sz = m.len();
    let ksz = (sz / 12).min(20);
    if ksz < 2 {
        return None;
    }
    let errs: Vec<f64> = (0..sz)
        .map(|i| fit_line(m, (i + sz - ksz) % sz, (i + ksz) % sz).1)
        .collect();
    // Low-pass filter: sigma 1, cut at 0.05 -> 7 taps.
    let (sigma, cutoff) = (1.0f64, 0.05f64);
    let fsz = 2 * (((-cutoff.ln() * 2.0 * sigma * sigma).sqrt() + 1.0) as usize) + 1;
    let f: Vec<f32> = (0..fsz)
        .map(|i| {
            let j = i as i64 - (fsz / 2) as i64;
            (-((j * j) as f64) / (2.0 * sigma * sigma)).exp() as f32
        })
        .collect();
    let smooth: Vec<f64> = (0..sz)
        .map(|iy| {
            (0..fsz)
                .map(|i| errs[(iy + i + sz - fsz / 2) % sz] * f[i] as f64)
                .sum()
        })
        .collect();
    let mut maxima: Vec<(usize, f64)> = (0..sz)
        .filter(|&i| smooth[i] > smooth[(i + 1) % sz] && smooth[i] > smooth[(i + sz - 1) % sz])
        .map(|i| (i, smooth[i]))
        .collect();
    if maxima.len() < 4 {
        return None;
    }
    if maxima.len() > MAX_NMAXIMA {
        let mut sorted: Vec<f64> = maxima.iter().map(|m| m.1).collect();
        sorted.sort_by(|a, b| b.total_cmp(a));
        let thresh = sorted[MAX_NMAXIMA];
        maxima.retain(|m| m.1 > thresh);
    }
    let max_mse = MAX_LINE_FIT_MSE as f64;
    let max_dot = (10.0 * std::f64::consts::PI / 180.0).cos() as f32 as f64;
    let n = maxima.len();
    let mut best = None;
    let mut best_error = f64::INFINITY;
    for m0 in 0..n.saturating_sub(3) {
        let i0 = maxima[m0].0;
        for m1 in m0 + 1..n - 2 {
            let i1 = maxima[m1].0;
            let (p01, err01, mse01) = fit_line(m, i0, i1);
            if mse01 > max_mse {
                continue;
            }
            for m2 in m1 + 1..n - 1 {
                let i2 = maxima[m2].0;
                let (p12, err12, mse12) = fit_line(m, i1, i2);
                if mse12 > max_mse {
                    continue;
                }
                let dot = p01[2] * p12[2] + p01[3] * p12[3];
                if dot.abs() > max_dot {
                    continue;
                }
                for &(i3, _) in &maxima[m2 + 1..n] {
                    let (_, err23, mse23) = fit_line(m, i2, i3);
                    if mse23 > max_mse {
                        continue;
                    }
                    let (_, err30, mse30) = fit_line(m, i3, i0);
                    if mse30 > max_mse {
                        continue;
                    }
                    let err = err01 + err12 + err23 + err30;
                    if err < best_error {
                        best_error = err;
                        best = Some([i0, i1, i2, i3]);
                    }
                }
            }
        }
    }
    let best = best?;
    (best_error / (sz as f64) < max_mse).then_some(best)
}

/// Where lines `a` and `b` (point, unit normal) cross; `None` when nearly parallel.
fn intersect(a: &[f64; 4], b: &[f64; 4]) -> Option<[f64; 2]> {
    let (a00, a01) = (a[3], -b[3]);
    let (a10, a11) = (-a[2], b[2]);
    let (b0, b1) = (b[0] - a[0], b[1] - a[1]);
    let det = a00 * a11 - a10 * a01;
    if det.abs() < 0.001 {
        return None;
    }
    let l0 = (a11 / det) * b0 + (-a01 / det) * b1;
    Some([a[0] + l0 * a00, a[1] + l0 * a10])
}

/// Fits a quad to one cluster (`fit_quad`); `None` when it does not look like a tag's border.
fn fit_quad(
    im: &GrayImage,
    cluster: &mut [Pt],
    tag_width: i32,
    normal_border: bool,
    reversed_border: bool,
) -> Option<Quad> {
    if cluster.len() < 24 {
        return None;
    }
    let (mut xmin, mut xmax, mut ymin, mut ymax) =
        (cluster[0].x, cluster[0].x, cluster[0].y, cluster[0].y);
    for p in cluster.iter().skip(1) {
        if p.x > xmax {
            xmax = p.x;
        } else if p.x < xmin {
            xmin = p.x;
        }
        if p.y > ymax {
            ymax = p.y;
        } else if p.y < ymin {
            ymin = p.y;
        }
    }
    if (xmax as i32 - xmin as i32) * (ymax as i32 - ymin as i32) < tag_width {
        return None;
    }
    // The C library's small offset of the centre, so points get more varied angles.
    let cx = ((xmin as i32 + xmax as i32) as f64 * 0.5 + 0.05118) as f32;
    let cy = ((ymin as i32 + ymax as i32) as f64 * 0.5 - 0.028581) as f32;
    // `{{-1*(2 << 15), 0}, {2*(2 << 15), 2 << 15}}`.
    let quadrants: [[f32; 2]; 2] = [[-65536.0, 0.0], [131072.0, 65536.0]];
    let mut dot = 0.0f32;
    for p in cluster.iter_mut() {
        let mut dx = p.x as f32 - cx;
        let mut dy = p.y as f32 - cy;
        dot += dx * p.gx as f32 + dy * p.gy as f32;
        let quadrant = quadrants[(dy > 0.0) as usize][(dx > 0.0) as usize];
        if dy < 0.0 {
            dy = -dy;
            dx = -dx;
        }
        if dx < 0.0 {
            let t = dx;
            dx = dy;
            dy = -t;
        }
        p.slope = quadrant + dy / dx;
    }
    let reversed = dot < 0.0;
    if (reversed && !reversed_border) || (!reversed && !normal_border) {
        return None;
    }
    let mut scratch = vec![cluster[0]; 2 * cluster.len() + 64];
    ptsort(cluster, &mut scratch);
    let m = line_fit_moments(cluster, im);
    let idx = segment_maxima(&m)?;
    let mut lines = [[0.0; 4]; 4];
    for i in 0..4 {
        let (line, _, mse) = fit_line(&m, idx[i], idx[(i + 1) & 3]);
        if mse > MAX_LINE_FIT_MSE as f64 {
            return None;
        }
        lines[i] = line;
    }
    let mut p = [[0.0; 2]; 4];
    for i in 0..4 {
        p[i] = intersect(&lines[i], &lines[(i + 1) & 3])?;
    }
    // Too small?
    let tri = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        let l = [dist(a, b), dist(b, c), dist(c, a)];
        let s = (l[0] + l[1] + l[2]) / 2.0;
        (s * (s - l[0]) * (s - l[1]) * (s - l[2])).sqrt()
    };
    let area = tri(p[0], p[1], p[2]) + tri(p[2], p[3], p[0]);
    if area < 0.95 * (tag_width * tag_width) as f64 {
        return None;
    }
    // Every turn must be sharp enough and the same way round.
    let cos_critical = (10.0 * std::f64::consts::PI / 180.0).cos() as f32 as f64;
    for i in 0..4 {
        let (a, b, c) = (p[i], p[(i + 1) & 3], p[(i + 2) & 3]);
        let (dx1, dy1) = (b[0] - a[0], b[1] - a[1]);
        let (dx2, dy2) = (c[0] - b[0], c[1] - b[1]);
        let cos =
            (dx1 * dx2 + dy1 * dy2) / ((dx1 * dx1 + dy1 * dy1) * (dx2 * dx2 + dy2 * dy2)).sqrt();
        if cos > cos_critical || cos < -cos_critical || dx1 * dy2 < dy1 * dx2 {
            return None;
        }
    }
    Some(Quad {
        p,
        reversed_border: reversed,
    })
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
}

/// Moves each edge of the quad to the strongest grey-level step near it (`refine_edges`).
fn refine_edges(im: &GrayImage, quad: &mut Quad, decimate: f64) {
    let (w, h) = (im.width() as i64, im.height() as i64);
    let raw = im.as_raw();
    let sample = |x: f64, y: f64| -> Option<f64> {
        let (xi, yi) = (x.trunc() as i64, y.trunc() as i64);
        let (a, b) = (x - x.trunc(), y - y.trunc());
        if xi < 0 || xi + 1 >= w || yi < 0 || yi + 1 >= h {
            return None;
        }
        let v = |xx: i64, yy: i64| raw[(yy * w + xx) as usize] as f64;
        Some(
            (1.0 - a) * (1.0 - b) * v(xi, yi)
                + a * (1.0 - b) * v(xi + 1, yi)
                + (1.0 - a) * b * v(xi, yi + 1)
                + a * b * v(xi + 1, yi + 1),
        )
    };
    let mut lines = [[0.0f64; 4]; 4];
    for (edge, line) in lines.iter_mut().enumerate() {
        let (a, b) = (quad.p[edge], quad.p[(edge + 1) & 3]);
        let mut nx = b[1] - a[1];
        let mut ny = -b[0] + a[0];
        let mag = (nx * nx + ny * ny).sqrt();
        nx /= mag;
        ny /= mag;
        if quad.reversed_border {
            nx = -nx;
            ny = -ny;
        }
        let nsamples = 16.max((mag / 8.0) as i64);
        let (mut mx, mut my, mut mxx, mut mxy, mut myy, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for s in 0..nsamples {
            let alpha = (1.0 + s as f64) / (nsamples + 1) as f64;
            let x0 = alpha * a[0] + (1.0 - alpha) * b[0];
            let y0 = alpha * a[1] + (1.0 - alpha) * b[1];
            let (mut mn, mut mcount) = (0.0, 0.0);
            let range = (decimate as i64 + 1) as f64;
            let steps_per_unit = 4;
            let step_length = 1.0 / steps_per_unit as f64;
            let max_steps = 2 * steps_per_unit * range as i64 + 1;
            for step in 0..max_steps {
                let nn = -range + step_length * step as f64;
                let Some(g1) = sample(x0 + (nn + 1.0) * nx - 0.5, y0 + (nn + 1.0) * ny - 0.5)
                else {
                    continue;
                };
                let Some(g2) = sample(x0 + (nn - 1.0) * nx - 0.5, y0 + (nn - 1.0) * ny - 0.5)
                else {
                    continue;
                };
                if g1 < g2 {
                    continue;
                }
                let weight = (g2 - g1) * (g2 - g1);
                mn += weight * nn;
                mcount += weight;
            }
            if mcount == 0.0 {
                continue;
            }
            let n0 = mn / mcount;
            let (bx, by) = (x0 + n0 * nx, y0 + n0 * ny);
            mx += bx;
            my += by;
            mxx += bx * bx;
            mxy += bx * by;
            myy += by * by;
            n += 1.0;
        }
        let (ex, ey) = (mx / n, my / n);
        let cxx = mxx / n - ex * ex;
        let cxy = mxy / n - ex * ey;
        let cyy = myy / n - ey * ey;
        let theta = 0.5 * ((-2.0 * cxy) as f32).atan2((cyy - cxx) as f32);
        *line = [ex, ey, theta.cos() as f64, theta.sin() as f64];
    }
    let old = quad.p;
    for i in 0..4 {
        if let Some(c) = intersect(&lines[i], &lines[(i + 1) & 3]) {
            quad.p[(i + 1) & 3] = c;
        } else {
            quad.p[(i + 1) & 3] = old[(i + 1) & 3];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::homography::Homography;
    use crate::visual::tags::decode::{quads_overlap, rotate90};

    #[test]
    fn rotate90_four_times_is_identity() {
        for nbits in [16usize, 25, 36, 41] {
            let w = 0x1234_5678_9abc_def0u64 & ((1u64 << nbits) - 1);
            let mut r = w;
            for _ in 0..4 {
                r = rotate90(r, nbits);
            }
            assert_eq!(r, w, "{nbits} bits");
            assert_ne!(rotate90(w, nbits), w);
        }
    }

    #[test]
    fn ptsort_sorts_by_slope() {
        let mut pts: Vec<Pt> = (0..37)
            .map(|i| Pt {
                x: i,
                y: 0,
                gx: 0,
                gy: 0,
                slope: ((i * 7919) % 37) as f32,
            })
            .collect();
        let mut scratch = pts.clone();
        scratch.extend_from_slice(&pts);
        scratch.extend_from_slice(&pts[..10]);
        ptsort(&mut pts, &mut scratch);
        assert!(pts.windows(2).all(|w| w[0].slope <= w[1].slope));
    }

    #[test]
    fn homography_maps_the_tag_square_onto_the_quad() {
        let p = [[10.0, 20.0], [50.0, 22.0], [48.0, 60.0], [12.0, 58.0]];
        let h = Homography::from_square(&p).unwrap();
        for (t, q) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .zip(p)
        {
            let r = h.project(t.0, t.1);
            assert!(dist(r, q) < 1e-9, "{r:?} vs {q:?}");
        }
    }

    #[test]
    fn tiny_flat_and_noisy_images_give_no_tags_and_no_panic() {
        let families = [kornia_apriltag::family::TagFamily::tag36_h11().unwrap()];
        let mut seed = 12345u32;
        for (w, h) in [
            (0, 0),
            (0, 9),
            (9, 0),
            (1, 1),
            (3, 3),
            (4, 4),
            (5, 700),
            (700, 5),
            (64, 48),
        ] {
            for decimate in [1, 2, 3] {
                for refine_edges in [false, true] {
                    let settings = QuadSettings {
                        decimate,
                        refine_edges,
                        sharpening: 0.25,
                        min_contrast: 5,
                    };
                    let noisy = GrayImage::from_fn(w, h, |_, _| {
                        seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12345);
                        image::Luma([(seed >> 16) as u8])
                    });
                    for img in [GrayImage::new(w, h), noisy] {
                        let found = detect(&img, &families, &settings).unwrap();
                        assert!(found.is_empty(), "{w} x {h}");
                    }
                }
            }
        }
    }

    #[test]
    fn overlapping_quads() {
        let a = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let b = a.map(|p| [p[0] + 5.0, p[1] + 5.0]);
        let c = a.map(|p| [p[0] + 11.0, p[1]]);
        assert!(quads_overlap(&a, &b));
        assert!(!quads_overlap(&a, &c));
    }
}
