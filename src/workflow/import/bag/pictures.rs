//! A bag's pictures: left and right matched by stamp, and written as files.

use std::collections::VecDeque;

/// Images wait this long (ns) for their partner, past the sync tolerance, before they are
/// counted unmatched: a bag's topics are written in about time order, not exactly.
pub(super) const PAIRING_WAIT_NS: i64 = 2_000_000_000;

/// Pairs encoded at once (on every core) before they are written.
pub(super) const PAIR_BATCH: usize = 16;

/// A picture waiting for its partner or to be written.
pub(super) struct Picture {
    pub(super) stamp_ns: i64,
    pub(super) index: usize,
    pub(super) log_time_ns: u64,
    pub(super) data: PictureData,
}

pub(super) enum PictureData {
    /// A raw image, its pixels copied.
    Raw {
        width: u32,
        height: u32,
        encoding: String,
        big_endian: bool,
        step: u32,
        data: Vec<u8>,
    },
    /// A compressed image, written as it is.
    Compressed { ext: &'static str, data: Vec<u8> },
}

/// The raw encodings read: bytes a pixel.
pub(super) fn bytes_per_pixel(encoding: &str) -> Option<usize> {
    match encoding {
        "mono8" | "8UC1" => Some(1),
        "mono16" | "16UC1" => Some(2),
        "rgb8" | "bgr8" => Some(3),
        "rgba8" | "bgra8" => Some(4),
        _ => None,
    }
}

/// A picture as a file: its bytes, extension and size.
pub(super) fn picture_file(
    p: &Picture,
) -> std::result::Result<(Vec<u8>, &'static str, [u32; 2]), String> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    match &p.data {
        PictureData::Compressed { ext, data } => {
            let size = image::ImageReader::new(std::io::Cursor::new(data))
                .with_guessed_format()
                .map_err(|e| e.to_string())?
                .into_dimensions()
                .map_err(|e| format!("cannot read the compressed image: {e}"))?;
            Ok((data.clone(), ext, [size.0, size.1]))
        }
        PictureData::Raw {
            width,
            height,
            encoding,
            big_endian,
            step,
            data,
        } => {
            let (w, h) = (*width as usize, *height as usize);
            let bpp = bytes_per_pixel(encoding).expect("checked when taken");
            if (*step as usize) < w * bpp || data.len() < *step as usize * h || w == 0 || h == 0 {
                return Err(format!(
                    "{w} x {h} {encoding} needs {} bytes a row and {} in all; step is {step}, data {} bytes",
                    w * bpp,
                    w * bpp * h,
                    data.len()
                ));
            }
            let rows = data.chunks(*step as usize).take(h);
            let mut out = Vec::new();
            let encoder =
                PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Up);
            let written = if bpp == 2 {
                // PNG stores 16-bit samples big-endian; the encoder takes them in native order.
                let pixels: Vec<u8> = rows
                    .flat_map(|r| r[..w * 2].chunks(2))
                    .flat_map(|b| {
                        let v = if *big_endian {
                            u16::from_be_bytes([b[0], b[1]])
                        } else {
                            u16::from_le_bytes([b[0], b[1]])
                        };
                        v.to_ne_bytes()
                    })
                    .collect();
                encoder.write_image(&pixels, *width, *height, image::ExtendedColorType::L16)
            } else {
                // Colour as Rec. 601 luma, as `io::load_gray` reads colour files.
                let (r, b) = if encoding.starts_with("bgr") {
                    (2, 0)
                } else {
                    (0, 2)
                };
                let pixels: Vec<u8> = rows
                    .flat_map(|row| row[..w * bpp].chunks(bpp))
                    .map(|px| {
                        if bpp == 1 {
                            px[0]
                        } else {
                            (0.299 * px[r] as f64 + 0.587 * px[1] as f64 + 0.114 * px[b] as f64)
                                .round()
                                .min(255.0) as u8
                        }
                    })
                    .collect();
                encoder.write_image(&pixels, *width, *height, image::ExtendedColorType::L8)
            };
            written.map_err(|e| format!("cannot encode PNG: {e}"))?;
            Ok((out, "png", [*width, *height]))
        }
    }
}

/// Left and right pictures matched by stamp.
pub(super) struct Pairing {
    pub(super) tolerance_ns: i64,
    pub(super) pending: [VecDeque<Picture>; 2],
    pub(super) unmatched: [usize; 2],
}

impl Pairing {
    /// Takes a picture of `side` (0 left, 1 right); returns a pair when it completes one.
    pub(super) fn push(&mut self, side: usize, p: Picture) -> Option<(Picture, Picture)> {
        let horizon = p.stamp_ns - self.tolerance_ns - PAIRING_WAIT_NS;
        for s in 0..2 {
            while self.pending[s]
                .front()
                .is_some_and(|q| q.stamp_ns < horizon)
            {
                self.pending[s].pop_front();
                self.unmatched[s] += 1;
            }
        }
        let other = &mut self.pending[1 - side];
        let best = other
            .iter()
            .enumerate()
            .map(|(j, q)| (j, (q.stamp_ns - p.stamp_ns).abs()))
            .filter(|&(_, d)| d <= self.tolerance_ns)
            .min_by_key(|&(_, d)| d);
        if let Some((j, _)) = best {
            let q = other.remove(j).expect("found");
            return Some(if side == 0 { (p, q) } else { (q, p) });
        }
        let own = &mut self.pending[side];
        let at = own.partition_point(|q| q.stamp_ns <= p.stamp_ns);
        own.insert(at, p);
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(encoding: &str, width: u32, step: u32, data: Vec<u8>, big_endian: bool) -> Picture {
        Picture {
            stamp_ns: 0,
            index: 0,
            log_time_ns: 0,
            data: PictureData::Raw {
                width,
                height: 2,
                encoding: encoding.into(),
                big_endian,
                step,
                data,
            },
        }
    }

    fn decoded(p: &Picture) -> image::DynamicImage {
        let (bytes, ext, _) = picture_file(p).unwrap();
        assert_eq!(ext, "png");
        image::load_from_memory(&bytes).unwrap()
    }

    #[test]
    fn colour_becomes_luma_and_row_padding_is_dropped() {
        // 2 x 2 bgr8 with one byte of padding a row: pure blue, green / red, white.
        let data = vec![
            255, 0, 0, 0, 255, 0, 9, //
            0, 0, 255, 255, 255, 255, 9,
        ];
        let img = decoded(&raw("bgr8", 2, 7, data, false)).into_luma8();
        assert_eq!(img.as_raw(), &vec![29, 150, 76, 255]);
    }

    #[test]
    fn sixteen_bit_keeps_its_values_in_either_byte_order() {
        let be = vec![0x12, 0x34, 0xff, 0x00, 0, 1, 0x80, 0];
        let img = decoded(&raw("mono16", 2, 4, be, true)).into_luma16();
        assert_eq!(img.as_raw(), &vec![0x1234, 0xff00, 1, 0x8000]);
        let le = vec![0x34, 0x12, 0, 0, 0, 0, 0, 0];
        let img = decoded(&raw("16UC1", 2, 4, le, false)).into_luma16();
        assert_eq!(img.as_raw()[0], 0x1234);
    }

    #[test]
    fn a_short_buffer_is_an_error_not_a_panic() {
        let err = picture_file(&raw("rgb8", 4, 12, vec![0; 20], false)).unwrap_err();
        assert!(err.contains("needs 12 bytes a row"), "{err}");
    }

    #[test]
    fn pairs_match_within_the_tolerance_and_the_rest_are_counted() {
        let at = |t_ms: i64| Picture {
            stamp_ns: t_ms * 1_000_000,
            index: 0,
            log_time_ns: 0,
            data: PictureData::Compressed {
                ext: "png",
                data: Vec::new(),
            },
        };
        let mut p = Pairing {
            tolerance_ns: 10_000_000,
            pending: [VecDeque::new(), VecDeque::new()],
            unmatched: [0, 0],
        };
        assert!(p.push(0, at(0)).is_none());
        // A right image 4 ms later pairs; one 30 ms from any left waits.
        assert!(p
            .push(1, at(4))
            .is_some_and(|(l, r)| l.stamp_ns == 0 && r.stamp_ns == 4_000_000));
        assert!(p.push(1, at(130)).is_none());
        assert!(p.push(0, at(100)).is_none());
        // Seconds later both waiting images are given up.
        assert!(p.push(0, at(5000)).is_none());
        assert_eq!(p.unmatched, [1, 1]);
    }
}
