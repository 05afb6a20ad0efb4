//! The localiser a robot embeds: stereo pairs, odometry and range readings fed as they arrive,
//! the pose and its covariance after each. A pair's tags are detected, triangulated and moved
//! into the robot frame as a survey does it, and the turn since the last picture far enough back
//! is measured by the visual odometry; both go to a [`Localizer`].

use crate::camera::{Rectification, StereoRig};
use crate::fusion::{surveyed_tag_sizes, Localizer, PoseEstimate, SightingOutcome};
use crate::geometry::Pose2;
use crate::sonar::SonarReading;
use crate::visual::sightings::{sightings_from_pair, TagSighting, TagSizes, TAG_HEIGHT_RANGE_M};
use crate::visual::stereo::StereoConfig;
use crate::visual::tags::{TagDetector, TagError};
use crate::visual::vo::{relative_motion, VisualTurn, VoConfig, VoImage};

/// Why a stereo pair could not be used.
#[derive(Debug, thiserror::Error)]
pub enum PairError {
    /// An image is not of its camera's size.
    #[error("{camera} image is {found:?} pixels, the rig's camera {expected:?}")]
    WrongSize {
        /// `left` or `right`.
        camera: &'static str,
        /// Found (width, height).
        found: (u32, u32),
        /// Expected (width, height).
        expected: (u32, u32),
    },
    /// The tag detector failed.
    #[error(transparent)]
    Detector(#[from] TagError),
}

/// What one stereo pair gave.
#[derive(Debug, Clone)]
pub struct PairUpdate {
    /// The pose after it.
    pub estimate: PoseEstimate,
    /// Its tags, moved into the robot frame, and what became of each.
    pub sightings: Vec<(TagSighting, SightingOutcome)>,
    /// The turn measured from the picture the last turn ended at (or the chain started from)
    /// to this one, and whether it was fused; `None` when no turn ended here.
    pub turn: Option<(VisualTurn, bool)>,
}

/// The picture a visual turn is measured from.
struct TurnStart {
    t_s: f64,
    /// The odometry when it was taken.
    odom: Pose2,
    left: VoImage,
    right: VoImage,
}

/// A [`Localizer`] fed stereo pairs: each pair's tags are detected and triangulated with the rig
/// and fused against the survey, and with [`crate::fusion::FuseConfig::visual_odometry`] the turn from the last
/// picture at least [`VoConfig::min_spacing`] back (by the odometry, and no more than
/// [`VoConfig::max_spacing`]) is measured and fused. Single-threaded: feed it from one thread.
///
/// A turn is measured from the picture the last one ended at; a sighting between lets it go (a
/// sighting moves the pose the turn's start heading was copied from), and the chain starts again
/// from the pair the sighting was in. `localize` over a finished run picks its pairs of pictures
/// knowing the pictures to come ([`crate::visual::vo::frame_pairs`]); this one cannot wait, so its
/// turns may end one picture later.
///
/// ```no_run
/// use stereotag::fusion::{FuseConfig, Localizer, Start, StereoLocalizer};
/// use stereotag::geometry::Pose2;
/// use stereotag::visual::tags::{Backend, DetectorConfig};
///
/// let survey = stereotag::io::load_landmarks(std::path::Path::new("survey/landmarks.json"))?;
/// let rig = stereotag::io::load_rig(std::path::Path::new("survey/camchain.yaml"))?;
/// let landmarks = survey.landmarks.into_iter().map(|r| r.landmark).collect();
/// let filter = Localizer::new(landmarks, FuseConfig::default(), Start::Unknown);
/// let detector = Backend::ApriltagC.detector(DetectorConfig::default())?;
/// let mut localizer = StereoLocalizer::new(filter, rig, detector);
/// // As the robot's data arrive:
/// localizer.odometry(0.0, Pose2::new(0.0, 0.0, 0.0));
/// let (left, right) = (image::GrayImage::new(640, 480), image::GrayImage::new(640, 480));
/// let update = localizer.stereo_pair(0.0, &left, &right)?;
/// println!("at {:?}, sigma {:.3} m", update.estimate.pose, update.estimate.position_sigma_m());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct StereoLocalizer {
    filter: Localizer,
    rig: StereoRig,
    rect: Rectification,
    detector: Box<dyn TagDetector + Send>,
    stereo: StereoConfig,
    vo: VoConfig,
    sizes: TagSizes,
    heights_m: (f64, f64),
    pairs: usize,
    turn: Option<TurnStart>,
}

impl StereoLocalizer {
    /// Feeds `filter` from stereo pairs of `rig` searched with `detector`; each surveyed tag's
    /// size is the one the survey used (`size_m`), and a triangulated size far from it is left
    /// out as in a survey.
    pub fn new(filter: Localizer, rig: StereoRig, detector: Box<dyn TagDetector + Send>) -> Self {
        let rect = rig.rectify();
        let sizes = surveyed_tag_sizes(filter.landmarks());
        Self {
            filter,
            rig,
            rect,
            detector,
            stereo: StereoConfig::default(),
            vo: VoConfig::default(),
            sizes,
            heights_m: TAG_HEIGHT_RANGE_M,
            pairs: 0,
            turn: None,
        }
    }

    /// The same, with the tags' printed sizes given instead of the survey's.
    pub fn with_tag_sizes(mut self, sizes: TagSizes) -> Self {
        self.sizes = sizes;
        self
    }

    /// The same, with sightings triangulated outside `low..=high` metres of height (robot
    /// frame) left out (default [`TAG_HEIGHT_RANGE_M`]).
    pub fn with_height_range(mut self, low: f64, high: f64) -> Self {
        self.heights_m = (low, high);
        self
    }

    /// The filter inside.
    pub fn localizer(&self) -> &Localizer {
        &self.filter
    }

    /// The odometry's pose at `t_s`.
    pub fn odometry(&mut self, t_s: f64, pose: Pose2) -> PoseEstimate {
        self.filter.odometry(t_s, pose);
        self.filter.estimate()
    }

    /// A range reading (sonar or one laser beam), matched against the surveyed walls, at the
    /// last odometry fed (feed the odometry up to the reading's time first).
    pub fn range(&mut self, reading: &SonarReading) -> PoseEstimate {
        self.filter.range(reading);
        self.filter.estimate()
    }

    /// A laser's whole scan (its readings share one time), matched with the survey's returns
    /// when the filter has them ([`Localizer::scan`]), at the last odometry fed: feed the
    /// odometry up to the scan's time first (interpolated between two samples, as `localize`
    /// does: turning at 40 degrees a second, a scan taken 0.16 s before the pose it is matched
    /// from is searched for 6 degrees off).
    pub fn scan(&mut self, readings: &[SonarReading]) -> PoseEstimate {
        self.filter.scan(readings);
        self.filter.estimate()
    }

    /// A stereo pair taken at `t_s`, at the last odometry fed (feed the odometry up to the
    /// pair's time first).
    pub fn stereo_pair(
        &mut self,
        t_s: f64,
        left: &image::GrayImage,
        right: &image::GrayImage,
    ) -> Result<PairUpdate, PairError> {
        for (camera, image, model) in [
            ("left", left, &self.rig.left),
            ("right", right, &self.rig.right),
        ] {
            if image.dimensions() != (model.width, model.height) {
                return Err(PairError::WrongSize {
                    camera,
                    found: image.dimensions(),
                    expected: (model.width, model.height),
                });
            }
        }
        let frame = self.pairs;
        self.pairs += 1;
        let visual = self.filter.config().visual_odometry;
        let odom = self.filter.last_odometry().map(|(_, p)| p);
        let mut here = None;
        let turn = match (visual, odom) {
            (true, Some(odom)) => self.end_turn(t_s, odom, left, &mut here),
            _ => None,
        };
        let sizes = &self.sizes;
        let known = |family, id| sizes.of(family, id);
        let (found, _rejected) = sightings_from_pair(
            self.detector.as_mut(),
            &self.rig,
            &self.rect,
            left,
            right,
            (t_s, frame),
            &known,
            &self.stereo,
        )?;
        let (low, high) = self.heights_m;
        let sightings: Vec<(TagSighting, SightingOutcome)> = found
            .into_iter()
            .filter(|s| (low..=high).contains(&s.position_in_robot_m[2]))
            .map(|s| {
                let outcome = self.filter.sighting(&s);
                (s, outcome)
            })
            .collect();
        if let (true, Some(odom)) = (visual, odom) {
            if !self.filter.turn_open() {
                // The chain starts (again) here.
                self.filter.turn_starts(t_s);
                self.turn = Some(TurnStart {
                    t_s,
                    odom,
                    left: here.unwrap_or_else(|| VoImage::new(left)),
                    right: VoImage::new(right),
                });
            }
        }
        Ok(PairUpdate {
            estimate: self.filter.estimate(),
            sightings,
            turn,
        })
    }

    /// Ends the turn under way at this picture (`left`, at odometry `odom`) when it is far
    /// enough from its start: measured and fused when not too far, let go when it is; `here`
    /// gets the picture prepared for the visual odometry when it was.
    fn end_turn(
        &mut self,
        t_s: f64,
        odom: Pose2,
        left: &image::GrayImage,
        here: &mut Option<VoImage>,
    ) -> Option<(VisualTurn, bool)> {
        let start = self.turn.as_ref()?;
        if !self.filter.turn_open() {
            self.turn = None;
            return None;
        }
        let prior = start.odom.between(&odom);
        let apart = |(m, rad): (f64, f64)| prior.x.hypot(prior.y) >= m || prior.theta.abs() >= rad;
        if !apart(self.vo.min_spacing) {
            return None;
        }
        let start = self.turn.take()?;
        if apart(self.vo.max_spacing) {
            self.filter.drop_turn();
            return None;
        }
        let image = here.insert(VoImage::new(left));
        match relative_motion(
            &self.rig,
            (&start.left, &start.right),
            image,
            &prior,
            &self.vo,
        ) {
            Ok(m) => {
                let turn = m.turn(start.t_s, t_s);
                let fused = self.filter.turn_ends(&turn).unwrap_or(false);
                Some((turn, fused))
            }
            Err(e) => {
                tracing::debug!(
                    "visual odometry, pictures at {:.2} s and {t_s:.2} s: {e}",
                    start.t_s
                );
                self.filter.drop_turn();
                None
            }
        }
    }
}

impl std::fmt::Debug for StereoLocalizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StereoLocalizer")
            .field("filter", &self.filter)
            .field("detector", &self.detector.name())
            .field("pairs", &self.pairs)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::{FuseConfig, Start};
    use crate::visual::tags::{Backend, DetectorConfig};

    fn localizer() -> StereoLocalizer {
        let rig = crate::io::load_rig(std::path::Path::new(crate::io::DEFAULT_RIG)).unwrap();
        let filter = Localizer::new(Vec::new(), FuseConfig::default(), Start::Unknown);
        let detector = Backend::ApriltagC
            .detector(DetectorConfig::default())
            .unwrap();
        StereoLocalizer::new(filter, rig, detector)
    }

    /// A pair of the wrong size is refused, naming the camera, and changes nothing.
    #[test]
    fn a_pair_of_the_wrong_size_is_refused() {
        let mut localizer = localizer();
        localizer.odometry(0.0, Pose2::new(0.0, 0.0, 0.0));
        let (w, h) = (localizer.rig.left.width, localizer.rig.left.height);
        let right = image::GrayImage::new(w / 2, h / 2);
        let err = localizer
            .stereo_pair(0.1, &image::GrayImage::new(w, h), &right)
            .unwrap_err();
        assert!(err.to_string().starts_with("right image is"), "{err}");
        assert_eq!(localizer.pairs, 0);
    }

    /// Before any tag is seen from an unknown start the pose is not located and its sigma is a
    /// building's; blank pictures find nothing and leave it so.
    #[test]
    fn blank_pictures_leave_an_unknown_start_unknown() {
        let mut localizer = localizer();
        let (w, h) = (localizer.rig.left.width, localizer.rig.left.height);
        let blank = image::GrayImage::from_pixel(w, h, image::Luma([128]));
        for k in 0..3 {
            let t = k as f64;
            localizer.odometry(t, Pose2::new(0.3 * t, 0.0, 0.0));
            let update = localizer.stereo_pair(t, &blank, &blank).unwrap();
            assert!(update.sightings.is_empty() && update.turn.is_none());
            assert!(!update.estimate.located);
            assert!(update.estimate.position_sigma_m() >= crate::fusion::UNKNOWN_START_SIGMA_M);
        }
    }
}
