//! The visual half: AprilTags detected in each image, triangulated from the stereo pair, and
//! the robot's turn between pictures measured from the images.

pub mod sightings;
pub mod stereo;
pub mod tags;
pub mod vo;
