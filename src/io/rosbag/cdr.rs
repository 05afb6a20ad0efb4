//! The ROS 2 messages the importer reads, decoded from CDR (OMG XCDR1, the `cdr` message
//! encoding of ROS 2 bags).
//!
//! A message is a 4-byte encapsulation header (`00 01` little-endian, `00 00` big-endian, then two
//! option bytes) and the fields in order, each primitive aligned to its own size counted from the
//! end of the header; a string is a `u32` length (with its terminating NUL) and the bytes; a
//! sequence a `u32` count and its elements; a fixed array its elements only. Fields added to a
//! message after those read here (newer ROS distributions) are passed over.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// Why a message could not be decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CdrError {
    /// The message ends before a field.
    #[error("the message ends at byte {at} while reading {field} (it is {len} bytes)")]
    Truncated {
        /// The field being read.
        field: &'static str,
        /// Offset reached.
        at: usize,
        /// The message's length.
        len: usize,
    },
    /// The encapsulation header is not plain CDR.
    #[error("encapsulation {0:02x?} is not plain CDR (00 00 or 00 01)")]
    Encapsulation([u8; 2]),
    /// A string is not UTF-8 or lacks its NUL.
    #[error("{0} is not a NUL-terminated UTF-8 string")]
    BadString(&'static str),
}

/// A cursor over one CDR message.
pub struct Cdr<'a> {
    bytes: &'a [u8],
    at: usize,
    little: bool,
}

impl<'a> Cdr<'a> {
    /// A cursor after the message's encapsulation header.
    pub fn new(bytes: &'a [u8]) -> Result<Self, CdrError> {
        if bytes.len() < 4 {
            return Err(CdrError::Truncated {
                field: "the encapsulation header",
                at: 0,
                len: bytes.len(),
            });
        }
        let little = match [bytes[0], bytes[1]] {
            [0, 1] => true,
            [0, 0] => false,
            other => return Err(CdrError::Encapsulation(other)),
        };
        Ok(Cdr {
            bytes,
            at: 4,
            little,
        })
    }

    fn take(&mut self, n: usize, align: usize, field: &'static str) -> Result<&'a [u8], CdrError> {
        let body = self.at - 4;
        let start = self.at + (align - body % align) % align;
        let end = start.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(CdrError::Truncated {
                field,
                at: start.min(self.bytes.len()),
                len: self.bytes.len(),
            });
        };
        self.at = end;
        Ok(&self.bytes[start..end])
    }

    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], CdrError> {
        let mut a: [u8; N] = self.take(N, N, field)?.try_into().expect("N bytes");
        if !self.little {
            a.reverse();
        }
        Ok(a)
    }

    /// A `uint8` (or `bool`).
    pub fn u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        Ok(self.take(1, 1, field)?[0])
    }

    /// A `uint32`.
    pub fn u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.array(field)?))
    }

    /// An `int32`.
    pub fn i32(&mut self, field: &'static str) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.array(field)?))
    }

    /// A `float32`.
    pub fn f32(&mut self, field: &'static str) -> Result<f32, CdrError> {
        Ok(f32::from_le_bytes(self.array(field)?))
    }

    /// A `float64`.
    pub fn f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.array(field)?))
    }

    /// `N` `float64`s (a fixed array).
    pub fn f64s<const N: usize>(&mut self, field: &'static str) -> Result<[f64; N], CdrError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(field)?;
        }
        Ok(out)
    }

    /// A sequence's element count, checked against the bytes left (`size` bytes an element).
    fn count(&mut self, size: usize, field: &'static str) -> Result<usize, CdrError> {
        let n = self.u32(field)? as usize;
        if n.saturating_mul(size) > self.bytes.len() - self.at {
            return Err(CdrError::Truncated {
                field,
                at: self.at,
                len: self.bytes.len(),
            });
        }
        Ok(n)
    }

    /// A `string`.
    pub fn string(&mut self, field: &'static str) -> Result<String, CdrError> {
        let n = self.count(1, field)?;
        let raw = self.take(n, 1, field)?;
        match raw.split_last() {
            Some((0, text)) => std::str::from_utf8(text)
                .map(str::to_owned)
                .map_err(|_| CdrError::BadString(field)),
            None => Ok(String::new()),
            _ => Err(CdrError::BadString(field)),
        }
    }

    /// A `uint8[]` sequence, borrowed.
    pub fn bytes(&mut self, field: &'static str) -> Result<&'a [u8], CdrError> {
        let n = self.count(1, field)?;
        self.take(n, 1, field)
    }

    /// A `float32[]` sequence.
    pub fn f32_seq(&mut self, field: &'static str) -> Result<Vec<f32>, CdrError> {
        let n = self.count(4, field)?;
        (0..n).map(|_| self.f32(field)).collect()
    }

    /// A `float64[]` sequence.
    pub fn f64_seq(&mut self, field: &'static str) -> Result<Vec<f64>, CdrError> {
        let n = self.count(8, field)?;
        (0..n).map(|_| self.f64(field)).collect()
    }

    /// `std_msgs/Header`.
    pub fn header(&mut self) -> Result<Header, CdrError> {
        let sec = self.i32("header.stamp.sec")?;
        let nanosec = self.u32("header.stamp.nanosec")?;
        let frame_id = self.string("header.frame_id")?;
        Ok(Header {
            stamp_ns: sec as i64 * 1_000_000_000 + nanosec as i64,
            frame_id,
        })
    }

    /// `geometry_msgs/Pose` or `Transform` (a translation then a quaternion x, y, z, w).
    pub fn isometry(&mut self, field: &'static str) -> Result<Isometry3<f64>, CdrError> {
        let [x, y, z] = self.f64s(field)?;
        let [qx, qy, qz, qw] = self.f64s(field)?;
        Ok(Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz)),
        ))
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// `stamp`, nanoseconds.
    pub stamp_ns: i64,
    /// `frame_id`.
    pub frame_id: String,
}

/// `sensor_msgs/msg/Image`, its pixels borrowed.
#[derive(Debug, Clone, PartialEq)]
pub struct Image<'a> {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `mono8`, `rgb8`, ...
    pub encoding: String,
    /// Multi-byte pixels are big-endian.
    pub big_endian: bool,
    /// Bytes a row.
    pub step: u32,
    /// The pixels.
    pub data: &'a [u8],
}

impl<'a> Image<'a> {
    /// Decodes a message.
    pub fn decode(bytes: &'a [u8]) -> Result<Self, CdrError> {
        let mut c = Cdr::new(bytes)?;
        Ok(Image {
            header: c.header()?,
            height: c.u32("height")?,
            width: c.u32("width")?,
            encoding: c.string("encoding")?,
            big_endian: c.u8("is_bigendian")? != 0,
            step: c.u32("step")?,
            data: c.bytes("data")?,
        })
    }
}

/// `sensor_msgs/msg/CompressedImage`, its bytes borrowed.
#[derive(Debug, Clone, PartialEq)]
pub struct CompressedImage<'a> {
    /// Header.
    pub header: Header,
    /// `jpeg`, `png` (image_transport writes e.g. `mono8; jpeg compressed mono8`).
    pub format: String,
    /// The file's bytes.
    pub data: &'a [u8],
}

impl<'a> CompressedImage<'a> {
    /// Decodes a message.
    pub fn decode(bytes: &'a [u8]) -> Result<Self, CdrError> {
        let mut c = Cdr::new(bytes)?;
        Ok(CompressedImage {
            header: c.header()?,
            format: c.string("format")?,
            data: c.bytes("data")?,
        })
    }
}

/// `sensor_msgs/msg/CameraInfo` (binning and region of interest included, to refuse them).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`.
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Camera matrix, row-major.
    pub k: [f64; 9],
    /// Rectification rotation, row-major.
    pub r: [f64; 9],
    /// Projection matrix, row-major.
    pub p: [f64; 12],
    /// Binning across and down (0 and 1: none).
    pub binning: [u32; 2],
    /// Region of interest: x, y offset, height, width (all 0: the whole image).
    pub roi: [u32; 4],
}

impl CameraInfo {
    /// Decodes a message.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut c = Cdr::new(bytes)?;
        Ok(CameraInfo {
            header: c.header()?,
            height: c.u32("height")?,
            width: c.u32("width")?,
            distortion_model: c.string("distortion_model")?,
            d: c.f64_seq("d")?,
            k: c.f64s("k")?,
            r: c.f64s("r")?,
            p: c.f64s("p")?,
            binning: [c.u32("binning_x")?, c.u32("binning_y")?],
            roi: [
                c.u32("roi.x_offset")?,
                c.u32("roi.y_offset")?,
                c.u32("roi.height")?,
                c.u32("roi.width")?,
            ],
        })
    }
}

/// `nav_msgs/msg/Odometry`: the pose part.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Header (its frame is the odometry's frame, `odom`).
    pub header: Header,
    /// The frame whose pose this is (`base_link`, `base_footprint`).
    pub child_frame_id: String,
    /// `header.frame_id` from `child_frame_id`.
    pub pose: Isometry3<f64>,
}

impl Odometry {
    /// Decodes a message.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut c = Cdr::new(bytes)?;
        Ok(Odometry {
            header: c.header()?,
            child_frame_id: c.string("child_frame_id")?,
            pose: c.isometry("pose.pose")?,
        })
    }
}

/// `sensor_msgs/msg/Range`.
#[derive(Debug, Clone, PartialEq)]
pub struct Range {
    /// Header.
    pub header: Header,
    /// Full width of the cone, radians.
    pub field_of_view: f32,
    /// Nearest range measured, metres.
    pub min_range: f32,
    /// Farthest range measured, metres.
    pub max_range: f32,
    /// The range (REP 117: `+inf` no echo within reach, `-inf` nearer than `min_range`).
    pub range: f32,
}

impl Range {
    /// Decodes a message.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut c = Cdr::new(bytes)?;
        let header = c.header()?;
        let _radiation_type = c.u8("radiation_type")?;
        Ok(Range {
            header,
            field_of_view: c.f32("field_of_view")?,
            min_range: c.f32("min_range")?,
            max_range: c.f32("max_range")?,
            range: c.f32("range")?,
        })
    }
}

/// `sensor_msgs/msg/LaserScan`.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Header.
    pub header: Header,
    /// Bearing of the first range, radians (0 ahead, positive left, in the laser's frame).
    pub angle_min: f32,
    /// Bearing of the last range.
    pub angle_max: f32,
    /// Angle between two ranges.
    pub angle_increment: f32,
    /// Nearest valid range, metres.
    pub range_min: f32,
    /// Farthest valid range, metres.
    pub range_max: f32,
    /// The ranges (outside `range_min..=range_max`, `inf` or `NaN`: no return).
    pub ranges: Vec<f32>,
}

impl LaserScan {
    /// Decodes a message.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut c = Cdr::new(bytes)?;
        let header = c.header()?;
        let angle_min = c.f32("angle_min")?;
        let angle_max = c.f32("angle_max")?;
        let angle_increment = c.f32("angle_increment")?;
        let _time_increment = c.f32("time_increment")?;
        let _scan_time = c.f32("scan_time")?;
        Ok(LaserScan {
            header,
            angle_min,
            angle_max,
            angle_increment,
            range_min: c.f32("range_min")?,
            range_max: c.f32("range_max")?,
            ranges: c.f32_seq("ranges")?,
        })
    }
}

/// One `geometry_msgs/TransformStamped` of a `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq)]
pub struct Transform {
    /// Header: the parent frame and the time.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// `parent_from_child`.
    pub parent_from_child: Isometry3<f64>,
}

/// Decodes a `tf2_msgs/msg/TFMessage`.
pub fn decode_tf(bytes: &[u8]) -> Result<Vec<Transform>, CdrError> {
    let mut c = Cdr::new(bytes)?;
    // A TransformStamped is at least 8 + 4 + 4 + 56 bytes.
    let n = c.count(72, "transforms")?;
    (0..n)
        .map(|_| {
            Ok(Transform {
                header: c.header()?,
                child_frame_id: c.string("child_frame_id")?,
                parent_from_child: c.isometry("transform")?,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little-endian CDR writer for the tests, aligned as the reader expects.
    struct Writer(Vec<u8>);

    impl Writer {
        fn new() -> Self {
            Writer(vec![0, 1, 0, 0])
        }
        fn align(&mut self, n: usize) {
            while !(self.0.len() - 4).is_multiple_of(n) {
                self.0.push(0);
            }
        }
        fn u32(&mut self, v: u32) {
            self.align(4);
            self.0.extend(v.to_le_bytes());
        }
        fn f64(&mut self, v: f64) {
            self.align(8);
            self.0.extend(v.to_le_bytes());
        }
        fn string(&mut self, s: &str) {
            self.u32(s.len() as u32 + 1);
            self.0.extend(s.as_bytes());
            self.0.push(0);
        }
        fn header(&mut self, sec: u32, nsec: u32, frame: &str) {
            self.u32(sec);
            self.u32(nsec);
            self.string(frame);
        }
    }

    #[test]
    fn an_odometry_message_decodes_with_its_alignment() {
        let mut w = Writer::new();
        w.header(12, 500_000_000, "odom");
        w.string("base_link");
        for v in [1.0, 2.0, 0.0, 0.0, 0.0, 0.5f64.sin(), 0.5f64.cos()] {
            w.f64(v);
        }
        let odom = Odometry::decode(&w.0).unwrap();
        assert_eq!(odom.header.stamp_ns, 12_500_000_000);
        assert_eq!(odom.header.frame_id, "odom");
        assert_eq!(odom.child_frame_id, "base_link");
        assert!((odom.pose.translation.x - 1.0).abs() < 1e-12);
        assert!((odom.pose.rotation.euler_angles().2 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_cut_message_is_an_error_naming_the_field() {
        let mut w = Writer::new();
        w.header(1, 0, "odom");
        w.string("base_link");
        w.f64(1.0);
        let err = Odometry::decode(&w.0).unwrap_err();
        assert!(err.to_string().contains("pose.pose"), "{err}");
        // A sequence claiming more elements than bytes is refused before allocating.
        let mut w = Writer::new();
        w.header(1, 0, "tf");
        w.u32(u32::MAX);
        assert!(decode_tf(&w.0).is_err());
        assert!(Cdr::new(&[0, 1]).is_err());
        assert!(Cdr::new(&[0, 7, 0, 0]).is_err());
    }

    #[test]
    fn big_endian_messages_decode_too() {
        let mut b = vec![0, 0, 0, 0];
        b.extend(7u32.to_be_bytes());
        b.extend(9u32.to_be_bytes());
        b.extend(1u32.to_be_bytes());
        b.push(0);
        let mut c = Cdr::new(&b).unwrap();
        let h = c.header().unwrap();
        assert_eq!(h.stamp_ns, 7_000_000_009);
        assert_eq!(h.frame_id, "");
    }
}
