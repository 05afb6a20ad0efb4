//! The recordings' colours, one name per meaning, so that a trajectory or a verdict has the same
//! colour in every recording.

use rerun::Color;

/// An opaque colour, in a `const`.
const fn rgb(r: u8, g: u8, b: u8) -> Color {
    Color(rerun::datatypes::Rgba32::from_rgb(r, g, b))
}

/// A see-through colour, in a `const`.
const fn rgba(r: u8, g: u8, b: u8, a: u8) -> Color {
    Color(rerun::datatypes::Rgba32::from_unmultiplied_rgba(r, g, b, a))
}

/// The robot's dead reckoning.
pub const ODOMETRY: Color = rgb(230, 80, 60);
/// The online filter's trajectory (and the odometry corrected with a survey's calibration).
pub const ONLINE: Color = rgb(240, 180, 40);
/// The offline (corrected) trajectory, and a localised one.
pub const OFFLINE: Color = rgb(60, 200, 90);
/// A filter's own uncertainty in the plots.
pub const SIGMA: Color = rgb(140, 120, 255);
/// The true trajectory.
pub const GROUND_TRUTH: Color = rgb(200, 200, 200);

/// The world's walls.
pub const WALLS: Color = rgb(150, 150, 150);
/// Tags where the world file plans them.
pub const PLANNED_TAG: Color = rgb(120, 120, 255);
/// The world's true corners.
pub const TRUE_CORNER: Color = rgb(90, 90, 90);
/// Straight wall faces fitted to the sonar.
pub const SURVEYED_WALL: Color = rgb(255, 140, 0);
/// The robot's outline.
pub const ROBOT: Color = Color::WHITE;

/// A surveyed landmark, and a sighting fused.
pub const FUSED: Color = rgb(40, 220, 120);
/// A landmark's covariance ellipsoid (the landmark's colour, see-through).
pub const LANDMARK_COVARIANCE: Color = rgba(40, 220, 120, 120);
/// A sighting, range or conflict that was gated out.
pub const GATED_OUT: Color = rgb(255, 40, 40);
/// A sighting of a tag the survey does not hold.
pub const NOT_SURVEYED: Color = rgb(150, 150, 150);
/// A landmark's association with the Hough corner it marks.
pub const ASSOCIATION: Color = rgb(255, 0, 255);

/// Hough features: a room corner.
pub const CORNER: Color = rgb(255, 60, 200);
/// Hough features: a wall's end.
pub const EDGE: Color = rgb(60, 160, 255);
/// Hough features: not told apart.
pub const UNKNOWN_FEATURE: Color = rgb(200, 200, 0);

/// Sonar cones.
pub const SONAR_BEAM: Color = rgba(0, 200, 255, 160);
/// A sonar range fused against a surveyed wall.
pub const RANGE_FUSED: Color = rgb(0, 200, 255);
/// Tag outlines detected in a camera image.
pub const DETECTION: Color = rgb(40, 255, 120);
/// Tag centres triangulated in the left camera.
pub const TRIANGULATED: Color = rgb(255, 200, 0);
/// Calibration residuals.
pub const RESIDUAL: Color = rgb(255, 80, 80);
/// The left camera's points where both cameras' are drawn together.
pub const LEFT: Color = rgb(80, 180, 255);
/// The right camera's.
pub const RIGHT: Color = rgb(255, 170, 60);
/// Rings of round values on a plot.
pub const RING: Color = rgba(200, 200, 200, 160);
/// A calibration board's outline.
pub const BOARD_OUTLINE: Color = rgba(120, 200, 255, 140);
/// A calibration board's corners.
pub const BOARD_CORNER: Color = rgb(255, 200, 60);
