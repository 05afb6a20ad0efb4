#![deny(missing_docs)]
//! stereotag: map a home with sonar and keep the robot's pose honest with stereo AprilTag landmarks.
//!
//! The crate follows the ApriAlpha map-building method: an occupancy grid built from sonar by the
//! *simple counting* rule ([`sonar::grid`]), corner features found in the sonar arcs by a Hough
//! transform ([`sonar::hough`]), and AprilTags at those corners seen by a stereo camera
//! ([`visual`]), fused with odometry ([`fusion`]). Each module owns one stage; [`io`] alone reads
//! and writes files.

pub mod calib;
pub mod camera;
pub mod dataset;
pub mod fusion;
pub mod geometry;
pub mod imgproc;
pub mod io;
pub mod metrics;
pub mod plan;
pub mod progress;
pub mod render;
pub mod sim;
pub mod sonar;
pub mod visual;
pub mod viz;
pub mod workflow;
pub mod world;
