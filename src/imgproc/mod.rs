//! Image processing shared by the detectors, the calibration and the visual odometry: a grey
//! image as floats with bilinear sampling ([`Plane`], the one resampler), the 5-tap binomial
//! blur ([`blur`]), and zero-mean unit-norm patches for normalised cross-correlation ([`ncc`]).
//!
//! The AprilTag C library's own arithmetic (its `value_for_pixel` and homography) is kept in
//! its port, `visual::tags::quads`, so that the port decodes bit for bit as the library does.

pub mod blur;
pub mod ncc;
mod plane;

pub use plane::Plane;
