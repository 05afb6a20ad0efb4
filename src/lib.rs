#![deny(missing_docs)]
//! stereotag: map a home with sonar and keep the robot's pose honest with stereo AprilTag
//! landmarks.
//!
//! The crate follows the ApriAlpha map-building method: an occupancy grid built from sonar by the
//! *simple counting* rule, room corners found in the sonar arcs by a Hough transform, and
//! AprilTags placed at those corners seen by a stereo camera, triangulated, matched with the
//! corners and fused with the odometry, online and offline over the whole run.
//!
//! # Where things are
//!
//! | half | modules |
//! |---|---|
//! | sonar: grid, corners, walls | [`sonar`] ([`sonar::grid`], [`sonar::hough`], [`sonar::corners`], [`sonar::walls`], [`sonar::map`]) |
//! | visual: tags, stereo, visual odometry | [`visual`] ([`visual::tags`], [`visual::stereo`], [`visual::vo`], [`visual::sightings`]), on [`camera`], [`imgproc`], [`geometry`] |
//! | calibration | [`calib`] (targets, chessboard, AprilGrid, initial guess, bundle adjustment) |
//! | fusion | [`fusion`] (online filter, offline pose graph, localisation) |
//! | worlds and runs | [`world`], [`dataset`], [`sim`] (the simulator), [`render`] (its cameras) |
//! | figures | [`metrics`] |
//! | files and recordings | [`io`] (every file read or written), [`viz`] (Rerun) |
//! | jobs end to end | [`workflow`] (what the `stereotag` command runs), [`progress`], [`plan`] |
//!
//! A stage takes data and returns data; [`io`] alone touches files; a [`workflow`] loads inputs,
//! runs the stages and writes a directory that appears whole or not at all.
//!
//! # Example
//!
//! Simulate two and a half minutes of a robot exploring the bundled office, with the stereo
//! pictures, then survey the run: the tags it saw become landmarks.
//!
//! ```
//! use std::path::Path;
//! use stereotag::progress::Silent;
//! use stereotag::sim::capture::CapturePolicy;
//! use stereotag::visual::tags::Backend;
//! use stereotag::viz::RecordingRequest;
//! use stereotag::workflow::sightings::DetectOptions;
//! use stereotag::workflow::simulate::{simulate, Pictures, SimSettings, SimulateRequest};
//! use stereotag::workflow::survey::{survey, SurveyRequest};
//!
//! # fn main() -> Result<(), stereotag::workflow::Error> {
//! let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
//! let tmp = tempfile::tempdir().unwrap();
//! let run = tmp.path().join("run");
//! simulate(
//!     &SimulateRequest {
//!         world: &repo.join("samples/office/world.yaml"),
//!         out: &run,
//!         settings: SimSettings {
//!             seed: Some(1),
//!             duration_s: Some(150.0),
//!             ..SimSettings::default()
//!         },
//!         pictures: Some(Pictures {
//!             rig: &repo.join("calibration/rigs/default.yaml"),
//!             policy: CapturePolicy::default(),
//!             default_mounting: false,
//!         }),
//!         force: false,
//!         along: None,
//!     },
//!     &Silent,
//! )?;
//! let surveyed = survey(
//!     &SurveyRequest {
//!         run_dir: &run,
//!         out: &tmp.path().join("survey"),
//!         world: None, // the run names its world: the survey is scored against it
//!         config: None,
//!         calibration_from: None,
//!         detect: DetectOptions::survey(Backend::ApriltagC),
//!         force: false,
//!         recording: RecordingRequest::none(),
//!         anchors: Default::default(), // the frame is the robot's start
//!         estimate_mounting: false,
//!     },
//!     &Silent,
//! )?;
//! for l in &surveyed.survey.landmarks {
//!     println!("tag {} at {:?} m", l.id, l.position_m);
//! }
//! assert!(!surveyed.survey.landmarks.is_empty());
//! // Scored against the world's planned tag places: within centimetres.
//! let scored = surveyed.scores.world.expect("the run names its world");
//! assert!(scored.landmarks.median_m.is_some_and(|m| m < 0.02));
//! // Every figure also lies in `report.json`'s metrics, by key.
//! assert_eq!(
//!     surveyed.metrics["landmarks.median_error_m"],
//!     scored.landmarks.median_m.unwrap()
//! );
//! # Ok(())
//! # }
//! ```

pub mod calib;
pub mod camera;
pub mod dataset;
pub mod fusion;
pub mod geometry;
pub mod imgproc;
pub mod io;
pub mod metrics;
pub mod picture;
pub mod plan;
pub mod progress;
pub mod render;
pub mod sim;
pub mod sonar;
pub mod visual;
pub mod viz;
pub mod workflow;
pub mod world;
