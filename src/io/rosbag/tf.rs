//! The transforms of a bag's `/tf_static` and `/tf`: where each sensor sits on the robot.
//!
//! tf is a tree: every frame has one parent. A sensor's mount is the chain from the robot's base
//! frame to the sensor's frame through their nearest common ancestor. Sensors are taken to be
//! fixed on the robot: a transform published on `/tf` is taken at its first value, and how far it
//! later moved is kept so the importer can warn.

use super::cdr::Transform;
use nalgebra::Isometry3;
use std::collections::BTreeMap;

/// One frame's link to its parent.
#[derive(Debug, Clone)]
struct Link {
    parent: String,
    parent_from_child: Isometry3<f64>,
    /// Published on `/tf` (else `/tf_static`).
    dynamic: bool,
    /// Largest distance (m) and angle (rad) a later `/tf` value moved from the first.
    moved: (f64, f64),
}

/// The tf tree of a bag.
#[derive(Debug, Clone, Default)]
pub struct TfTree {
    links: BTreeMap<String, Link>,
}

/// Why a frame cannot be placed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TfError {
    /// The frame is not in any transform.
    #[error("no transform names frame `{frame}` (frames in /tf and /tf_static: {known})")]
    Unknown {
        /// The frame asked for.
        frame: String,
        /// The frames the bag has.
        known: String,
    },
    /// The two frames are in different trees.
    #[error("frames `{from}` and `{to}` are not connected by /tf or /tf_static (their roots: `{from_root}`, `{to_root}`)")]
    Disconnected {
        /// The base.
        from: String,
        /// The frame asked for.
        to: String,
        /// The base's root.
        from_root: String,
        /// The frame's root.
        to_root: String,
    },
}

/// Frames never written as a parent's or child's name with a leading slash (ROS 1 habit).
fn frame_name(name: &str) -> &str {
    name.trim_start_matches('/')
}

impl TfTree {
    /// Adds the transforms of one message (`dynamic`: from `/tf`).
    pub fn add(&mut self, transforms: &[Transform], dynamic: bool) {
        for t in transforms {
            let child = frame_name(&t.child_frame_id).to_owned();
            let parent = frame_name(&t.header.frame_id).to_owned();
            match self.links.get_mut(&child) {
                // A static transform replaces a dynamic one; a later static one replaces the
                // earlier (tf2's rule); a dynamic one after the first is only measured.
                Some(link) if dynamic => {
                    if link.dynamic && link.parent == parent {
                        let d = link.parent_from_child.inverse() * t.parent_from_child;
                        link.moved.0 = link.moved.0.max(d.translation.vector.norm());
                        link.moved.1 = link.moved.1.max(d.rotation.angle());
                    }
                }
                _ => {
                    self.links.insert(
                        child,
                        Link {
                            parent,
                            parent_from_child: t.parent_from_child,
                            dynamic,
                            moved: (0.0, 0.0),
                        },
                    );
                }
            }
        }
    }

    /// Whether a frame is known.
    pub fn knows(&self, frame: &str) -> bool {
        let frame = frame_name(frame);
        self.links.contains_key(frame) || self.links.values().any(|l| l.parent == frame)
    }

    /// The frames known, in name order.
    pub fn frames(&self) -> Vec<String> {
        let mut all: Vec<String> = self
            .links
            .iter()
            .flat_map(|(c, l)| [c.clone(), l.parent.clone()])
            .collect();
        all.sort();
        all.dedup();
        all
    }

    /// The chain from `frame` up to its root: each ancestor with `ancestor_from_frame`, the frame
    /// itself first (a tree with a cycle stops after as many steps as it has links).
    fn chain(&self, frame: &str) -> Vec<(String, Isometry3<f64>)> {
        let mut out = vec![(frame.to_owned(), Isometry3::identity())];
        while out.len() <= self.links.len() {
            let (name, pose) = out.last().expect("not empty");
            let Some(link) = self.links.get(name) else {
                break;
            };
            let up = link.parent_from_child * pose;
            out.push((link.parent.clone(), up));
        }
        out
    }

    /// `base_from_frame`, through the nearest common ancestor.
    pub fn lookup(&self, base: &str, frame: &str) -> Result<Isometry3<f64>, TfError> {
        let (base, frame) = (frame_name(base), frame_name(frame));
        for f in [base, frame] {
            if !self.knows(f) {
                return Err(TfError::Unknown {
                    frame: f.to_owned(),
                    known: self.frames().join(", "),
                });
            }
        }
        let up_from_base = self.chain(base);
        let up_from_frame = self.chain(frame);
        for (name, ancestor_from_frame) in &up_from_frame {
            if let Some((_, ancestor_from_base)) = up_from_base.iter().find(|(n, _)| n == name) {
                return Ok(ancestor_from_base.inverse() * ancestor_from_frame);
            }
        }
        Err(TfError::Disconnected {
            from: base.to_owned(),
            to: frame.to_owned(),
            from_root: up_from_base.last().expect("not empty").0.clone(),
            to_root: up_from_frame.last().expect("not empty").0.clone(),
        })
    }

    /// The `/tf` links on the chain from `base` to `frame` that moved after their first value,
    /// with how far (m, rad).
    pub fn moved_between(&self, base: &str, frame: &str) -> Vec<(String, f64, f64)> {
        let (base, frame) = (frame_name(base), frame_name(frame));
        let up_base: Vec<String> = self.chain(base).into_iter().map(|c| c.0).collect();
        let up_frame: Vec<String> = self.chain(frame).into_iter().map(|c| c.0).collect();
        up_base
            .iter()
            .chain(&up_frame)
            .filter(|n| !(up_base.contains(n) && up_frame.contains(n)))
            .filter_map(|n| {
                let l = self.links.get(n)?;
                (l.dynamic && (l.moved.0 > 1e-3 || l.moved.1 > 1e-3))
                    .then(|| (n.clone(), l.moved.0, l.moved.1))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::super::cdr::Header;
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn t(parent: &str, child: &str, x: f64, yaw: f64) -> Transform {
        Transform {
            header: Header {
                stamp_ns: 0,
                frame_id: parent.into(),
            },
            child_frame_id: child.into(),
            parent_from_child: Isometry3::from_parts(
                Translation3::new(x, 0.0, 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            ),
        }
    }

    #[test]
    fn a_sensor_is_placed_through_the_common_ancestor() {
        let mut tree = TfTree::default();
        tree.add(
            &[
                t("base_footprint", "base_link", 0.0, 0.0),
                t("base_link", "sonar_0", 0.2, 0.5),
                t("/base_link", "camera_link", 0.1, 0.0),
                t("camera_link", "camera_optical", 0.0, 0.0),
            ],
            false,
        );
        tree.add(&[t("odom", "base_footprint", 5.0, 1.0)], true);
        let s = tree.lookup("base_link", "sonar_0").unwrap();
        assert!((s.translation.x - 0.2).abs() < 1e-12);
        // Between two sensors: up to base_link and down again.
        let c = tree.lookup("sonar_0", "camera_optical").unwrap();
        assert!((c.translation.vector.norm() - 0.1).abs() < 1e-12);
        // The moving odom link is not on the way.
        let b = tree.lookup("base_footprint", "sonar_0").unwrap();
        assert!((b.translation.x - 0.2).abs() < 1e-12);
        assert!(tree.moved_between("base_link", "sonar_0").is_empty());
    }

    #[test]
    fn unknown_and_disconnected_frames_say_what_the_bag_has() {
        let mut tree = TfTree::default();
        tree.add(
            &[
                t("base_link", "laser", 0.1, 0.0),
                t("map", "odom", 0.0, 0.0),
            ],
            false,
        );
        let e = tree.lookup("base_link", "sonar_3").unwrap_err().to_string();
        assert!(
            e.contains("sonar_3") && e.contains("base_link, laser, map, odom"),
            "{e}"
        );
        let e = tree.lookup("base_link", "odom").unwrap_err().to_string();
        assert!(e.contains("not connected"), "{e}");
    }

    #[test]
    fn a_moving_dynamic_link_is_reported() {
        let mut tree = TfTree::default();
        tree.add(&[t("base_link", "pan", 0.0, 0.0)], true);
        tree.add(&[t("base_link", "pan", 0.0, 0.3)], true);
        let moved = tree.moved_between("base_link", "pan");
        assert_eq!(moved.len(), 1);
        assert!((moved[0].2 - 0.3).abs() < 1e-9);
    }
}
