//! A run's stereo pairs → tag sightings and visual turns: every pair read from the run directory,
//! its tags detected, triangulated and moved into the robot frame, and the turn between
//! consecutive pictures measured by the visual odometry; in parallel, runs of pairs per thread.

use super::{Error, Result};
use crate::camera::StereoRig;
use crate::dataset::RunDataset;
use crate::geometry::pose_at;
use crate::io;
use crate::progress::Progress;
use crate::visual::sightings::{sightings_from_pair, TagSighting};
use crate::visual::stereo::StereoConfig;
use crate::visual::tags::{Backend, DetectorConfig, TagDetector, TagFamily};
use crate::visual::vo::{frame_pairs, relative_motion, VisualTurn, VoConfig, VoImage};
use crate::world::World;
use rayon::prelude::*;
use std::path::Path;

/// How a run's stereo pairs are searched for tags.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectOptions {
    /// The detector.
    pub backend: Backend,
    /// Tag families to look for; empty: the world's, else tag36h11.
    pub families: Vec<TagFamily>,
    /// Decimation before quad detection (the C library takes fractions, kornia whole factors).
    pub decimate: f32,
    /// Smallest white-to-black grey difference around a tile for it to be searched.
    pub min_contrast: u8,
    /// Edge length of the tags the world does not give (enables the size check, and is the
    /// size `landmarks.json` gives), metres: per tag with a default.
    pub tag_sizes: crate::visual::sightings::TagSizes,
    /// Measure the turns between pictures with the visual odometry as well.
    pub visual_odometry: bool,
    /// Keep each pair's images for the recording.
    pub keep_images: bool,
    /// Take the default mounting ([`crate::io::default_mounting`]) for a rig that does not say
    /// where it sits on the robot, rather than stop (see [`crate::io::load_mounted_rig`]).
    pub default_mounting: bool,
}

/// A tag's printed edge length when known: the world file's, else the table's (its own, else
/// the default).
pub fn known_tag_size(
    world: Option<&crate::world::World>,
    sizes: &crate::visual::sightings::TagSizes,
    family: TagFamily,
    id: u32,
) -> Option<f64> {
    world
        .and_then(|w| w.tags.iter().find(|t| t.id == id && t.family == family))
        .map(|t| t.size_m)
        .or_else(|| sizes.of(family, id))
}

/// The survey's default `decimate` for a backend: 1.5 for the C library (the museum survey in
/// 2 s on two cores, docs/RESULTS.md *Speed*), 1 for kornia-apriltag, which decimates by whole
/// factors.
pub fn survey_decimate(backend: Backend) -> f32 {
    match backend {
        Backend::ApriltagC => 1.5,
        Backend::Kornia | Backend::KorniaLibrary => 1.0,
    }
}

/// The survey's default `min_contrast`: a printed tag's black border on white is far above it
/// even when dim, sensor noise and wall texture mostly below (30 and 40 find the same tags on
/// the ten office and museum runs, 60 on office and museum seed 1; 40 finds the same 47 in the
/// C library's test photos as 5).
pub const SURVEY_MIN_CONTRAST: u8 = 40;

impl DetectOptions {
    /// The survey's tuned detector settings for `backend`: decimation [`survey_decimate`],
    /// contrast floor [`SURVEY_MIN_CONTRAST`], the families of the world (or tag36h11), visual
    /// odometry on, no images kept.
    pub fn survey(backend: Backend) -> Self {
        Self {
            backend,
            families: Vec::new(),
            decimate: survey_decimate(backend),
            min_contrast: SURVEY_MIN_CONTRAST,
            tag_sizes: Default::default(),
            visual_odometry: true,
            keep_images: false,
            default_mounting: false,
        }
    }
}

/// A stereo pair kept for the recording.
pub enum KeptPair {
    /// Decoded (left, right), to be compressed while the survey's single-threaded stages run.
    Decoded(image::GrayImage, image::GrayImage),
    /// Already compressed (JPEG left, right): a run too long to hold decoded.
    Jpeg(Vec<u8>, Vec<u8>),
}

/// What the pairs of a run gave (nothing for a run without cameras).
#[derive(Default)]
pub struct RunSightings {
    /// Every tag sighting, in the order of the pairs.
    pub sightings: Vec<TagSighting>,
    /// The turns the cameras measured between pictures.
    pub visual: Vec<VisualTurn>,
    /// For each pair, its images when kept for the recording.
    pub images: Vec<Option<KeptPair>>,
    /// Sightings left out: triangulated below the floor or far above any wall (a wrong rig
    /// mounting, or a false match between the cameras); see [`plausible_height_m`].
    pub implausible_height: usize,
}

/// Heights (robot frame z, metres) a tag may be triangulated at: from 0.3 m below the floor to
/// 0.5 m above the highest wall of the world, or 3.5 m without one (a home's ceiling is under
/// 3 m).
pub fn plausible_height_m(world: Option<&World>) -> (f64, f64) {
    let (low, high) = crate::visual::sightings::TAG_HEIGHT_RANGE_M;
    let top = world
        .and_then(|w| w.walls.iter().map(|wall| wall.height_m).reduce(f64::max))
        .map_or(high, |h| h + 0.5);
    (low, top)
}

/// Most memory the decoded pairs kept for the recording may take, bytes; a longer run's pairs
/// are compressed as they are detected instead (slower: the encoder then competes with the
/// detectors), so memory stays bounded whatever the run's length.
const KEPT_DECODED_BYTES: usize = 1 << 30;

/// One in how many pairs without a tag the recording keeps (ours: 3, about every metre of
/// travel or 60 degrees of turn: the office demo's recording then costs under 20% of its survey).
const RECORD_EVERY: usize = 3;

/// Consecutive pairs worked through in order by one thread, so that a picture's images are
/// decoded and prepared for the visual odometry once, for both turns it ends and starts (only a
/// turn that crosses into the next run of pairs decodes its last picture again).
const RUN_OF_PAIRS: usize = 16;

/// Whether stereo pair `frame` goes into the recording: every pair a tag was found in, and one in
/// [`RECORD_EVERY`] of the others (the pictures taken for the visual odometry alone, more than
/// half of the office demo's). Compressing the pairs is most of what a recording costs; between
/// two recorded pairs the viewer shows the earlier one.
fn recorded(frame: usize, tag_found: bool) -> bool {
    tag_found || frame.is_multiple_of(RECORD_EVERY)
}

/// Whether a run's pairs, `pairs` of `pixels` each image, are too many to keep decoded.
fn compress_while_detecting(pairs: usize, pixels: usize) -> bool {
    pairs.saturating_mul(2 * pixels) > KEPT_DECODED_BYTES
}

/// The families to look for: those asked, else the world's and those the tag sizes table names
/// (`--tag-sizes`; with no world, its default size stands for tags of the default family,
/// tag36h11), else tag36h11.
fn families(options: &DetectOptions, world: Option<&World>) -> Vec<TagFamily> {
    let mut families = options.families.clone();
    if families.is_empty() {
        families = world
            .map(|w| w.tags.iter().map(|t| t.family).collect())
            .unwrap_or_default();
        let sizes = &options.tag_sizes;
        families.extend(sizes.by_tag.keys().map(|t| t.family));
        if world.is_none() && sizes.default_m.is_some() {
            families.push(TagFamily::Tag36h11);
        }
        families.sort();
        families.dedup();
    }
    if families.is_empty() {
        families.push(TagFamily::Tag36h11);
    }
    families
}

/// The planned edge length of a tag (family, id) when known, metres.
type KnownSize<'a> = Box<dyn Fn(TagFamily, u32) -> Option<f64> + Sync + 'a>;

/// Everything the pairs of one run share while they are worked through.
struct Shared<'a> {
    run_dir: &'a Path,
    run: &'a RunDataset,
    rig: &'a StereoRig,
    rect: crate::camera::Rectification,
    known_size: KnownSize<'a>,
    stereo: StereoConfig,
    vo: VoConfig,
    /// The pairs of pictures whose motion the visual odometry measures: pair `k` to `next[k]`.
    next: Vec<Option<usize>>,
    keep_images: bool,
    compress_now: bool,
}

/// What one pair gave.
struct PerPair {
    sightings: Vec<TagSighting>,
    /// Its images, when the recording keeps them.
    kept: Option<KeptPair>,
    /// The turn from this picture to the next one the visual odometry measures from it.
    turn: Option<VisualTurn>,
}

/// A picture a visual-odometry turn starts from: its index, its images prepared, and the picture
/// the turn ends at.
struct TurnStart {
    frame: usize,
    left: VoImage,
    right: VoImage,
    to: usize,
}

/// Detects and triangulates the tags of every stereo pair of `run` (read from `run_dir`), and
/// measures the turns between its pictures when asked, in parallel; `world` gives the tag sizes
/// and families when known. Progress: one step per pair.
///
/// ```no_run
/// use std::path::Path;
/// use stereotag::progress::Silent;
/// use stereotag::visual::tags::Backend;
/// use stereotag::workflow::sightings::{detect_run, DetectOptions};
/// use stereotag::workflow::{load_run, survey::load_run_rig};
///
/// let dir = Path::new("runs/office");
/// let run = load_run(dir)?;
/// let rig = load_run_rig(dir, &run, false)?.expect("the run has stereo pairs");
/// let options = DetectOptions::survey(Backend::ApriltagC);
/// let seen = detect_run(&options, dir, &run, &rig, None, &Silent)?;
/// for s in &seen.sightings {
///     println!("{:.1} s: tag {} at {:?} m from the robot", s.t_s, s.id, s.position_in_robot_m);
/// }
/// # Ok::<(), stereotag::workflow::Error>(())
/// ```
pub fn detect_run(
    options: &DetectOptions,
    run_dir: &Path,
    run: &RunDataset,
    rig: &StereoRig,
    world: Option<&World>,
    progress: &dyn Progress,
) -> Result<RunSightings> {
    check_decimate(options.decimate)?;
    let config = DetectorConfig {
        families: families(options, world),
        decimate: options.decimate,
        min_contrast: options.min_contrast,
        ..DetectorConfig::default()
    };
    let detectors = Pool::new(options.backend.detector(config.clone())?); // a bad setting fails here, once
    let compress_now = compress_while_detecting(
        run.stereo.len(),
        (rig.left.width as usize) * (rig.left.height as usize),
    );
    if options.keep_images && compress_now {
        tracing::info!(
            "{} stereo pairs: compressing them for the recording as they are detected",
            run.stereo.len()
        );
    }
    let vo = VoConfig::default();
    let mut next: Vec<Option<usize>> = vec![None; run.stereo.len()];
    if options.visual_odometry {
        let times: Vec<f64> = run.stereo.iter().map(|e| e.t_s).collect();
        for (a, b) in frame_pairs(&times, &run.odometry, &vo) {
            next[a] = Some(b);
        }
    }
    let tag_sizes = options.tag_sizes.clone();
    let shared = Shared {
        run_dir,
        run,
        rig,
        rect: rig.rectify(),
        known_size: Box::new(move |family: TagFamily, id: u32| {
            known_tag_size(world, &tag_sizes, family, id)
        }),
        stereo: StereoConfig::default(),
        vo,
        next,
        keep_images: options.keep_images,
        compress_now,
    };
    progress.start("detect", run.stereo.len() as u64);
    let starts: Vec<usize> = (0..run.stereo.len()).step_by(RUN_OF_PAIRS).collect();
    let per_run: Vec<Result<Vec<PerPair>>> = starts
        .par_iter()
        .map_init(
            || detectors.take(|| options.backend.detector(config.clone())),
            |detector, &first| {
                let detector = detector
                    .as_mut()
                    .map_err(|e| Error::Request(e.to_string()))?;
                shared.run_of_pairs(detector.as_mut(), first, progress)
            },
        )
        .collect();
    progress.finish();
    let mut out = RunSightings::default();
    for r in per_run {
        for pair in r? {
            out.sightings.extend(pair.sightings);
            out.images.push(pair.kept);
            out.visual.extend(pair.turn);
        }
    }
    leave_out_implausible_heights(&mut out, world);
    tracing::info!(
        "{} tag sightings in {} stereo pairs",
        out.sightings.len(),
        run.stereo.len()
    );
    if options.visual_odometry {
        let tried = shared.next.iter().flatten().count();
        tracing::info!(
            "visual odometry: the turn between {} of {tried} pairs of pictures measured",
            out.visual.len()
        );
    }
    Ok(out)
}

/// Leaves out the sightings triangulated at heights no tag can be at, saying how many once.
fn leave_out_implausible_heights(out: &mut RunSightings, world: Option<&World>) {
    let (low, high) = plausible_height_m(world);
    let plausible = |s: &TagSighting| (low..=high).contains(&s.position_in_robot_m[2]);
    if let Some(first) = out.sightings.iter().find(|s| !plausible(s)) {
        let left_out = out.sightings.iter().filter(|s| !plausible(s)).count();
        tracing::warn!(
            "{left_out} tag sightings left out: triangulated outside {low}..{high} m of height \
             (the first: tag {} at {:.2} m in pair {}); is the rig's robot_from_left right?",
            first.id,
            first.position_in_robot_m[2],
            first.frame
        );
        out.sightings.retain(plausible);
        out.implausible_height = left_out;
    }
}

/// A `decimate` the detectors take (finite, at least 1), or the error naming it.
pub fn check_decimate(decimate: f32) -> Result<()> {
    if crate::visual::tags::valid_decimation(decimate) {
        Ok(())
    } else {
        Err(Error::Request(format!(
            "--decimate {decimate}: must be at least 1"
        )))
    }
}

/// A run image, read and checked against its camera.
fn load_checked(path: &Path, camera: &crate::camera::Camera) -> Result<image::GrayImage> {
    let image = io::load_gray(path)?;
    io::check_image_size(&image, camera, path, "the rig")?;
    Ok(image)
}

impl Shared<'_> {
    /// The pairs from `first` on, [`RUN_OF_PAIRS`] of them at most, in order.
    fn run_of_pairs(
        &self,
        detector: &mut dyn TagDetector,
        first: usize,
        progress: &dyn Progress,
    ) -> Result<Vec<PerPair>> {
        let (run, rig) = (self.run, self.rig);
        let last = (first + RUN_OF_PAIRS).min(run.stereo.len());
        let mut out: Vec<PerPair> = Vec::with_capacity(last - first);
        let mut from: Option<TurnStart> = None;
        for (frame, entry) in run.stereo.iter().enumerate().take(last).skip(first) {
            let left = load_checked(&self.run_dir.join(&entry.left), &rig.left)?;
            let right = load_checked(&self.run_dir.join(&entry.right), &rig.right)?;
            let (sightings, rejected) = sightings_from_pair(
                detector,
                rig,
                &self.rect,
                &left,
                &right,
                (entry.t_s, frame),
                &*self.known_size,
                &self.stereo,
            )?;
            let tag_found = !sightings.is_empty() || !rejected.is_empty();
            for s in &sightings {
                let [x, y, z] = s.position_in_robot_m;
                tracing::trace!(
                    "pair {frame} (t = {:.2} s): {} {} at ({x:.3}, {y:.3}, {z:.3}) m from the robot, edge {:.3} m",
                    entry.t_s,
                    s.family,
                    s.id,
                    s.size_m
                );
            }
            for r in rejected {
                tracing::debug!(
                    "pair {frame} (t = {:.1} s): tag {} rejected: {}",
                    entry.t_s,
                    r.id,
                    r.reason
                );
            }
            let ends = from.as_ref().is_some_and(|f| f.to == frame);
            let starts = self.next[frame].is_some();
            if ends || starts {
                let here = VoImage::new(&left);
                if let Some(start) = from.take().filter(|_| ends) {
                    out[start.frame - first].turn = self.visual_turn(&start, &here);
                }
                if let Some(to) = self.next[frame] {
                    from = Some(TurnStart {
                        frame,
                        left: here,
                        right: VoImage::new(&right),
                        to,
                    });
                }
            }
            out.push(PerPair {
                sightings,
                kept: self.kept(frame, tag_found, left, right),
                turn: None,
            });
            progress.advance(1);
        }
        // A turn into the next run of pairs: its last picture decoded here as well.
        if let Some(start) = from {
            let image = load_checked(&self.run_dir.join(&run.stereo[start.to].left), &rig.left)?;
            let here = VoImage::new(&image);
            out[start.frame - first].turn = self.visual_turn(&start, &here);
        }
        Ok(out)
    }

    /// The pair's images as the recording keeps them, if it does.
    fn kept(
        &self,
        frame: usize,
        tag_found: bool,
        left: image::GrayImage,
        right: image::GrayImage,
    ) -> Option<KeptPair> {
        match (
            self.keep_images && recorded(frame, tag_found),
            self.compress_now,
        ) {
            (false, _) => None,
            (true, false) => Some(KeptPair::Decoded(left, right)),
            (true, true) => crate::viz::jpeg_pair(&left, &right).map(|(l, r)| KeptPair::Jpeg(l, r)),
        }
    }

    /// The turn from picture `start` to the left image `next` of the picture it ends at,
    /// measured by the visual odometry from the odometry's; `None` when the pictures do not show
    /// it (too little texture in common).
    fn visual_turn(&self, start: &TurnStart, next: &VoImage) -> Option<VisualTurn> {
        let run = self.run;
        let (a, b) = (&run.stereo[start.frame], &run.stereo[start.to]);
        let prior = pose_at(&run.odometry, a.t_s)?.between(&pose_at(&run.odometry, b.t_s)?);
        match relative_motion(
            self.rig,
            (&start.left, &start.right),
            next,
            &prior,
            &self.vo,
        ) {
            Ok(m) => Some(m.turn(a.t_s, b.t_s)),
            Err(e) => {
                tracing::debug!(
                    "visual odometry, pictures at {:.2} s and {:.2} s: {e}",
                    a.t_s,
                    b.t_s
                );
                None
            }
        }
    }
}

/// Values lent to parallel jobs and given back when a job ends, so that each is built about once
/// per thread: rayon's `map_init` calls its init for every split of the work, and a tag detector
/// builds its families' decoding tables when it is made.
struct Pool<T> {
    free: std::sync::Mutex<Vec<T>>,
}

impl<T> Pool<T> {
    /// A pool holding `first`.
    fn new(first: T) -> Self {
        Self {
            free: std::sync::Mutex::new(vec![first]),
        }
    }

    /// A value from the pool, or a new one from `make` when every value is lent.
    fn take<E>(
        &self,
        make: impl FnOnce() -> std::result::Result<T, E>,
    ) -> std::result::Result<Pooled<'_, T>, E> {
        let free = self.free.lock().unwrap_or_else(|e| e.into_inner()).pop();
        let item = match free {
            Some(item) => item,
            None => make()?,
        };
        Ok(Pooled {
            item: Some(item),
            pool: self,
        })
    }
}

/// A value lent by a [`Pool`]; it goes back when dropped.
struct Pooled<'p, T> {
    item: Option<T>,
    pool: &'p Pool<T>,
}

impl<T> std::ops::Deref for Pooled<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.item.as_ref().expect("lent until dropped")
    }
}

impl<T> std::ops::DerefMut for Pooled<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        self.item.as_mut().expect("lent until dropped")
    }
}

impl<T> Drop for Pooled<'_, T> {
    fn drop(&mut self) {
        if let Some(item) = self.item.take() {
            self.pool
                .free
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(item);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_families_come_from_the_flags_else_the_world_and_the_sizes_table() {
        let mut options = DetectOptions::survey(crate::visual::tags::Backend::ApriltagC);
        assert_eq!(families(&options, None), vec![TagFamily::Tag36h11]);
        for family in [TagFamily::Tag25h9, TagFamily::TagStandard41h12] {
            options
                .tag_sizes
                .by_tag
                .insert(crate::visual::tags::TagId { family, id: 3 }, 0.08);
        }
        assert_eq!(
            families(&options, None),
            vec![TagFamily::Tag25h9, TagFamily::TagStandard41h12]
        );
        // A default size is for the tags not listed: of the default family.
        options.tag_sizes.default_m = Some(0.16);
        assert_eq!(
            families(&options, None),
            vec![
                TagFamily::Tag25h9,
                TagFamily::Tag36h11,
                TagFamily::TagStandard41h12
            ]
        );
        options.families = vec![TagFamily::Tag16h5];
        assert_eq!(families(&options, None), vec![TagFamily::Tag16h5]);
    }

    #[test]
    fn sightings_below_the_floor_or_far_above_the_walls_are_left_out() {
        let at = |frame: usize, z: f64| TagSighting {
            t_s: frame as f64,
            frame,
            id: frame as u32,
            family: TagFamily::Tag36h11,
            size_m: 0.16,
            position_in_robot_m: [2.0, 0.0, z],
            covariance_m2: [[0.0; 3]; 3],
            yaw_in_robot_rad: 0.0,
            yaw_sigma_rad: 0.1,
            pitch_rad: 0.0,
            roll_rad: 0.0,
            corners_px: None,
        };
        let mut seen = RunSightings {
            sightings: vec![at(0, 1.2), at(1, 4.8), at(2, -0.6), at(3, 3.4)],
            ..RunSightings::default()
        };
        leave_out_implausible_heights(&mut seen, None);
        let kept: Vec<usize> = seen.sightings.iter().map(|s| s.frame).collect();
        assert_eq!(kept, [0, 3]);
        assert_eq!(seen.implausible_height, 2);
        assert_eq!(plausible_height_m(None), (-0.3, 3.5));
    }
    use std::cell::Cell;

    #[test]
    fn a_pool_makes_a_value_only_when_every_value_is_lent() {
        let made = Cell::new(0);
        let make = || -> std::result::Result<u32, ()> {
            made.set(made.get() + 1);
            Ok(made.get())
        };
        let pool = Pool::new(0);
        {
            let a = pool.take(make).unwrap();
            let b = pool.take(make).unwrap();
            assert_eq!((*a, *b, made.get()), (0, 1, 1));
        }
        // Both went back: two more takes make nothing new.
        let c = pool.take(make).unwrap();
        let d = pool.take(make).unwrap();
        assert_eq!(made.get(), 1);
        assert_ne!(*c, *d);
        drop((c, d));
        assert!(pool.take(|| Err::<u32, &str>("unused")).is_ok());
    }

    /// Every pair with a tag is recorded, one in three of the others.
    #[test]
    fn the_recording_keeps_every_tag_pair_and_a_third_of_the_others() {
        assert!((0..30).all(|k| recorded(k, true)));
        assert_eq!((0..30).filter(|&k| recorded(k, false)).count(), 10);
    }

    /// The museum's 468 pairs of 640x480 (288 MB decoded) are kept decoded; a run of hours is
    /// compressed as it is detected, so the recording never holds more than 1 GiB of pixels.
    #[test]
    fn a_long_run_is_compressed_as_it_is_detected() {
        let vga = 640 * 480;
        assert!(!compress_while_detecting(468, vga));
        assert!(!compress_while_detecting(1700, vga));
        assert!(compress_while_detecting(1800, vga));
        assert!(compress_while_detecting(usize::MAX, vga));
    }
}
