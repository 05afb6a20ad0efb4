#![deny(missing_docs)]
//! stereotag: map a home with sonar and keep the robot's pose honest with stereo AprilTag landmarks.
//!
//! The crate follows the ApriAlpha map-building method: an occupancy grid built from sonar by the
//! *simple counting* rule ([`grid`]), corner features found in the sonar arcs by a Hough transform
//! ([`hough`]), and (in later stages) AprilTags at those corners seen by a stereo camera. Each module
//! owns one stage; [`io`] alone reads and writes files.
//!
//! Data flows one way: [`world`] → [`sim`] → [`run`] dataset → [`grid`] → [`hough`] → [`score`].

pub mod board;
pub mod calibrate;
pub mod camera;
pub mod chessboard;
pub mod fuse;
pub mod geometry;
pub mod grid;
pub mod hough;
pub mod io;
pub mod pipeline;
pub mod plan;
pub mod render;
pub mod run;
pub mod score;
pub mod sim;
pub mod sonar;
pub mod stereo;
mod subpixel;
mod tagquads;
pub mod tags;
#[cfg(feature = "rerun")]
pub mod viz;
pub mod vo;
pub mod wallmap;
pub mod walls;
pub mod world;
