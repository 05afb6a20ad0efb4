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
                let side = |word: &str| -> Vec<&TopicInfo> {
                    all.iter()
                        .copied()
                        .filter(|t| t.name.to_lowercase().contains(word))
                        .collect()
                };
                let (l, r) = (side("left"), side("right"));
                match (all.len(), l.as_slice(), r.as_slice()) {
                    (0, _, _) => (None, None),
                    (2, [l], [r]) => (Some(l.name.clone()), Some(r.name.clone())),
                    _ => {
                        return Err(topic_error(
                            bag,
                            format!(
                                "cannot tell the left and right image topics among {}: name them with --left and --right",
                                all.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
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
        let scan = match (&asked.scan, laser_as_sonar) {
            (Some(s), _) => Some(named(s, &[LASER_SCAN], "--scan")?),
            (None, false) => None,
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
                    format!("no {RANGE} topic: a run needs sonar")
                } else {
                    format!(
                        "no {RANGE} topic: a run needs sonar; to turn the laser {} into sonar-like readings, pass --as-sonar frontal5 (or pioneer16)",
                        lasers[0].name
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
