//! Which of a bag's topics is which: named, or found by type.

use super::BagTopics;
use crate::io::rosbag::{Bag, TopicInfo};
use crate::io::IoError;
use crate::workflow::{Error, Result};

/// `sensor_msgs/msg/Image`.
pub const IMAGE: &str = "sensor_msgs/msg/Image";
/// `sensor_msgs/msg/CompressedImage`.
pub const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
/// `sensor_msgs/msg/CameraInfo`.
pub const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
/// `nav_msgs/msg/Odometry`.
pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";
/// `sensor_msgs/msg/Range`.
pub const RANGE: &str = "sensor_msgs/msg/Range";
/// `sensor_msgs/msg/LaserScan`.
pub const LASER_SCAN: &str = "sensor_msgs/msg/LaserScan";
/// `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";

/// The topics chosen for each role.
#[derive(Debug, Clone)]
pub(super) struct Roles {
    pub(super) left: Option<String>,
    pub(super) right: Option<String>,
    pub(super) left_info: Option<String>,
    pub(super) right_info: Option<String>,
    pub(super) odom: String,
    pub(super) sonar: Vec<String>,
    pub(super) scan: Option<String>,
    pub(super) ground_truth: Option<String>,
    pub(super) tf: Vec<String>,
}

/// Whether `name` matches a glob of `*` (any characters) and `?` (one).
pub(super) fn glob_match(glob: &str, name: &str) -> bool {
    pub(super) fn go(g: &[char], n: &[char]) -> bool {
        match g.split_first() {
            None => n.is_empty(),
            Some(('*', rest)) => (0..=n.len()).any(|i| go(rest, &n[i..])),
            Some(('?', rest)) => !n.is_empty() && go(rest, &n[1..]),
            Some((c, rest)) => n.first() == Some(c) && go(rest, &n[1..]),
        }
    }
    let (g, n): (Vec<char>, Vec<char>) = (glob.chars().collect(), name.chars().collect());
    go(&g, &n)
}

/// The left and right camera among two image topics, by the words their names use for the two
/// cameras: `left`/`right`, `infra1`/`infra2` (RealSense), `cam0`/`cam1` (Kalibr, EuRoC).
/// `None` unless there are exactly two topics and the pairs of words that tell them apart agree.
pub(super) fn stereo_pair(names: &[&str]) -> Option<(usize, usize)> {
    if names.len() != 2 {
        return None;
    }
    let lower: Vec<String> = names.iter().map(|n| n.to_lowercase()).collect();
    let mut told: Vec<(usize, usize)> = [("left", "right"), ("infra1", "infra2"), ("cam0", "cam1")]
        .iter()
        .filter_map(|(l, r)| {
            let has = |i: usize, w: &str| lower[i].contains(w);
            if has(0, l) && has(1, r) && !has(0, r) && !has(1, l) {
                Some((0, 1))
            } else if has(1, l) && has(0, r) && !has(1, r) && !has(0, l) {
                Some((1, 0))
            } else {
                None
            }
        })
        .collect();
    told.dedup();
    match told.as_slice() {
        [one] => Some(*one),
        _ => None,
    }
}

/// An error about the bag's topics, listing them.
pub(super) fn topic_error(bag: &Bag, what: String) -> Error {
    IoError::content(
        &bag.path,
        format!("{what}. The bag's topics:\n{}", bag.topic_list()),
    )
    .into()
}

impl Roles {
    pub(super) fn choose(bag: &Bag, asked: &BagTopics, laser_as_sonar: bool) -> Result<Roles> {
        let of_type = |types: &[&str]| -> Vec<&TopicInfo> {
            bag.topics
                .iter()
                .filter(|t| types.contains(&t.type_name.as_str()))
                .collect()
        };
        let named = |name: &str, types: &[&str], flag: &str| -> Result<String> {
            match bag.topic(name) {
                Some(t) if types.contains(&t.type_name.as_str()) => Ok(t.name.clone()),
                Some(t) => Err(topic_error(
                    bag,
                    format!(
                        "{flag} {name}: its type is {}, not {}",
                        t.type_name,
                        types.join(" or ")
                    ),
                )),
                None => Err(topic_error(bag, format!("{flag} {name}: no such topic"))),
            }
        };
        for t in &bag.topics {
            if t.encoding != "cdr" && t.type_name.contains("/msg/") {
                tracing::warn!(
                    "{}: topic {} is encoded as `{}`, not CDR: passed over",
                    bag.path.display(),
                    t.name,
                    t.encoding
                );
            }
        }
        let images = [IMAGE, COMPRESSED_IMAGE];
        let (left, right) = match (&asked.left, &asked.right) {
            (Some(l), Some(r)) => (
                Some(named(l, &images, "--left")?),
                Some(named(r, &images, "--right")?),
            ),
            (None, None) => {
                let all = of_type(&images);
                let names: Vec<&str> = all.iter().map(|t| t.name.as_str()).collect();
                match (all.len(), stereo_pair(&names)) {
                    (0, _) => (None, None),
                    (_, Some((l, r))) => (Some(names[l].to_owned()), Some(names[r].to_owned())),
                    _ => {
                        return Err(topic_error(
                            bag,
                            format!(
                                "cannot tell the left and right image topics among {}: name them with --left and --right",
                                names.join(", ")
                            ),
                        ))
                    }
                }
            }
            _ => {
                return Err(Error::Request(
                    "give both --left and --right, or neither (found by their names)".into(),
                ))
            }
        };
        let ground_truth = asked
            .ground_truth
            .as_deref()
            .map(|g| named(g, &[ODOMETRY], "--ground-truth"))
            .transpose()?;
        let odom = match &asked.odom {
            Some(o) => named(o, &[ODOMETRY], "--odom")?,
            None => {
                let all: Vec<&TopicInfo> = of_type(&[ODOMETRY])
                    .into_iter()
                    .filter(|t| Some(&t.name) != ground_truth.as_ref())
                    .collect();
                match all.as_slice() {
                    [one] => one.name.clone(),
                    [] => {
                        return Err(topic_error(
                            bag,
                            format!("no {ODOMETRY} topic: a run needs the wheel odometry"),
                        ))
                    }
                    _ => {
                        return Err(topic_error(
                            bag,
                            "several odometry topics: name the wheel odometry with --odom (and a simulator's truth with --ground-truth)".into(),
                        ))
                    }
                }
            }
        };
        let sonar: Vec<String> = if laser_as_sonar {
            Vec::new()
        } else if asked.sonar.is_empty() {
            of_type(&[RANGE]).iter().map(|t| t.name.clone()).collect()
        } else {
            let mut found = Vec::new();
            for glob in &asked.sonar {
                let hits: Vec<&TopicInfo> = bag
                    .topics
                    .iter()
                    .filter(|t| glob_match(glob, &t.name))
                    .collect();
                if hits.is_empty() {
                    return Err(topic_error(
                        bag,
                        format!("--sonar {glob}: no topic matches"),
                    ));
                }
                for t in hits {
                    if t.type_name != RANGE {
                        return Err(topic_error(
                            bag,
                            format!(
                                "--sonar {glob}: {} is a {}, not a {RANGE}",
                                t.name, t.type_name
                            ),
                        ));
                    }
                    if !found.contains(&t.name) {
                        found.push(t.name.clone());
                    }
                }
            }
            found
        };
        let scan =
            match (&asked.scan, laser_as_sonar) {
                (Some(s), _) => Some(named(s, &[LASER_SCAN], "--scan")?),
                (None, false) => {
                    match of_type(&[LASER_SCAN]).as_slice() {
                        [one] => Some(one.name.clone()),
                        [] => None,
                        several => {
                            tracing::warn!(
                        "{}: several laser topics ({}): none is imported; name one with --scan",
                        bag.path.display(),
                        several.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
                    );
                            None
                        }
                    }
                }
                (None, true) => match of_type(&[LASER_SCAN]).as_slice() {
                    [one] => Some(one.name.clone()),
                    [] => {
                        return Err(topic_error(
                            bag,
                            format!("--as-sonar needs a laser: no {LASER_SCAN} topic"),
                        ))
                    }
                    _ => {
                        return Err(topic_error(
                            bag,
                            "several laser topics: name one with --scan".into(),
                        ))
                    }
                },
            };
        if sonar.is_empty() && scan.is_none() {
            let lasers = of_type(&[LASER_SCAN]);
            return Err(topic_error(
                bag,
                if lasers.is_empty() {
                    format!("no {RANGE} or {LASER_SCAN} topic: a run needs sonar or a laser")
                } else {
                    format!(
                        "no {RANGE} topic and several lasers: name the laser with --scan (one of {})",
                        lasers.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
                    )
                },
            ));
        }
        let info_of = |image: &Option<String>| -> Option<String> {
            let image = image.as_ref()?;
            let base = image.strip_suffix("/compressed").unwrap_or(image);
            let mut ns = base;
            while let Some(cut) = ns.rfind('/') {
                ns = &ns[..cut];
                let candidate = format!("{ns}/camera_info");
                if bag
                    .topic(&candidate)
                    .is_some_and(|t| t.type_name == CAMERA_INFO)
                {
                    return Some(candidate);
                }
            }
            None
        };
        let tf = ["/tf_static", "/tf"]
            .iter()
            .filter(|n| bag.topic(n).is_some_and(|t| t.type_name == TF_MESSAGE))
            .map(|n| n.to_string())
            .collect();
        Ok(Roles {
            left_info: info_of(&left),
            right_info: info_of(&right),
            left,
            right,
            odom,
            sonar,
            scan,
            ground_truth,
            tf,
        })
    }

    pub(super) fn uses(&self, topic: &str) -> bool {
        self.role_of(topic) != "not used"
    }

    pub(super) fn role_of(&self, topic: &str) -> String {
        let is = |t: &Option<String>| t.as_deref() == Some(topic);
        if is(&self.left) {
            "left images".into()
        } else if is(&self.right) {
            "right images".into()
        } else if is(&self.left_info) {
            "left camera_info".into()
        } else if is(&self.right_info) {
            "right camera_info".into()
        } else if self.odom == topic {
            "odometry".into()
        } else if is(&self.ground_truth) {
            "ground truth".into()
        } else if is(&self.scan) {
            "laser (as sonar)".into()
        } else if let Some(k) = self.sonar.iter().position(|s| s == topic) {
            format!("sonar {k}")
        } else if self.tf.iter().any(|t| t == topic) {
            "tf".into()
        } else {
            "not used".into()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_two_cameras_are_told_apart_by_their_names() {
        assert_eq!(
            stereo_pair(&["/stereo/right/image_raw", "/stereo/left/image_raw"]),
            Some((1, 0))
        );
        assert_eq!(
            stereo_pair(&[
                "/camera/infra1/image_rect_raw",
                "/camera/infra2/image_rect_raw"
            ]),
            Some((0, 1))
        );
        assert_eq!(
            stereo_pair(&["/cam0/image_raw", "/cam1/image_raw"]),
            Some((0, 1))
        );
        assert_eq!(stereo_pair(&["/left/cam0", "/left/cam1"]), Some((0, 1)));
        assert_eq!(stereo_pair(&["/right/cam1", "/left/cam0"]), Some((1, 0)));
        // Words that disagree, three topics, or none of the words: not told.
        assert_eq!(stereo_pair(&["/left/cam1", "/right/cam0"]), None);
        assert_eq!(stereo_pair(&["/a/image", "/b/image"]), None);
        assert_eq!(
            stereo_pair(&["/left/image", "/right/image", "/left/image/compressed"]),
            None
        );
    }
}
