//! What the fusion stage works on: a run's odometry and what its cameras saw.

use crate::geometry::StampedPose;
use crate::visual::sightings::TagSighting;
use crate::visual::vo::VisualTurn;

/// A run's odometry, time-ordered, with the tag sightings and the turns the cameras measured
/// between pictures (both time-ordered, within the odometry's time span or not).
#[derive(Debug, Clone, Copy, Default)]
pub struct Observations<'a> {
    /// Dead reckoning, `world_from_robot` at each time.
    pub odometry: &'a [StampedPose],
    /// Tag sightings.
    pub sightings: &'a [TagSighting],
    /// Visual turns.
    pub visual: &'a [VisualTurn],
}

impl<'a> Observations<'a> {
    /// The odometry alone.
    pub fn odometry(odometry: &'a [StampedPose]) -> Self {
        Self {
            odometry,
            ..Self::default()
        }
    }
}
