//! The paper's exploration: drive straight until an obstacle, follow its boundary at a fixed
//! distance with the obstacle on the right until the first corner met while following is reached
//! again; then head for the least-known region of the robot's own counting grid, going round
//! obstacles on the way, until the explored area stops growing. Ours adds a look-around at the
//! start and a second drive of the first boundary loop, and drives out of places it is stuck in.
//! The controller senses walls with an ideal proximity sensor (the simulator's geometry).

use crate::geometry::{wrap_angle, Pose2};
use crate::sonar::grid::{CountingGrid, OccupancyGrid, OccupancyMap};
use crate::world::World;
use nalgebra::{Point2, Vector2};
use serde::{Deserialize, Serialize};

/// Exploration and motion settings. Defaults are the paper's office experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ExplorationConfig {
    /// Forward speed: 0.1 m/s in the paper.
    pub speed_mps: f64,
    /// Turning rate (ours: 0.5 rad/s).
    pub turn_rate_rad_s: f64,
    /// Boundary-following distance, robot centre to obstacle: 50 cm (office), 35 cm (museum).
    pub follow_distance_m: f64,
    /// Sample the sonars every this much travel: 5 cm (office), 10 cm (museum).
    pub sample_travel_m: f64,
    /// ... or this much turning: 9 degrees (office), 15 (museum).
    pub sample_turn_deg: f64,
    /// Time budget, seconds (ours: 30 minutes).
    pub duration_s: f64,
    /// Robot radius for collisions (ours: 0.2 m).
    pub robot_radius_m: f64,
    /// True wheel base (ours: 0.3 m).
    pub wheel_base_m: f64,
    /// Simulation step (ours: 50 ms).
    pub step_s: f64,
    /// Exploration ends when the explored area grew less than this fraction over the last three
    /// targets (ours: 2%).
    pub min_growth: f64,
    /// A target not reached in this time is given up (ours: 150 s).
    pub target_timeout_s: f64,
    /// When exploration ends, drive the first boundary loop's path once more (through targets
    /// every [`REVISIT_SPACING_M`] along it, in odometry), so every tag seen on the loop is seen
    /// again: the loop closure an offline survey needs (ours: on; off gives the paper's run).
    pub revisit_loop: bool,
    /// Turn once on the spot before exploring, so the tags in view of the known start pose are
    /// seen before any drift: they anchor the survey to the start (ours: on; off gives the paper's
    /// run).
    pub look_around_at_start: bool,
}

impl Default for ExplorationConfig {
    fn default() -> Self {
        Self {
            speed_mps: 0.1,
            turn_rate_rad_s: 0.5,
            follow_distance_m: 0.5,
            sample_travel_m: 0.05,
            sample_turn_deg: 9.0,
            duration_s: 1800.0,
            robot_radius_m: 0.2,
            wheel_base_m: 0.3,
            step_s: 0.05,
            min_growth: 0.02,
            target_timeout_s: 150.0,
            revisit_loop: true,
            look_around_at_start: true,
        }
    }
}

#[derive(Debug, Clone)]
enum Mode {
    /// Turn on the spot at the start, this much odometry turn still to go.
    LookAround { remaining_rad: f64 },
    /// Drive straight, or towards a target.
    Straight { target: Option<Point2<f64>> },
    /// Follow the boundary with the obstacle on the right.
    Follow(FollowState),
}

#[derive(Debug, Clone)]
struct FollowState {
    target: Option<Point2<f64>>,
    /// Distance to the target (odometry) when the obstacle was met.
    hit_distance_m: f64,
    travel_m: f64,
    /// (travel, heading) history for corner detection.
    history: Vec<(f64, f64)>,
    first_corner: Option<(Point2<f64>, f64)>,
}

/// Travel over which a heading change counts as a corner (ours: 0.6 m).
const CORNER_WINDOW_M: f64 = 0.6;
/// Heading change that makes a corner (ours: 60 degrees, as 1.047 rad: the seeded sample runs
/// were made with this rounding, `FRAC_PI_3` would change them).
const CORNER_TURN_RAD: f64 = 1.047;
/// Bearings of the follower's ray fan: from 120 degrees right to 90 degrees left (-2.094 and
/// 1.571 rad, rounded as the seeded sample runs were made).
const FOLLOW_FAN_RAD: (f64, f64) = (-2.094, 1.571);
/// Rays in the follower's fan (one per 5 degrees).
const FOLLOW_FAN_RAYS: usize = 42;
/// Radius of the arc on which the follower rounds a concave corner (ours: 0.4 m).
const CORNER_ARC_M: f64 = 0.4;
/// The explored area must have stalled over at least this long to end exploration (ours: 120 s).
const GROWTH_WINDOW_S: f64 = 120.0;
/// Following gives up a target after this much travel (ours: 10 m).
const BUG_GIVE_UP_M: f64 = 10.0;
/// The first boundary is abandoned after this much travel if it never closes (ours: 150 m).
const BOUNDARY_GIVE_UP_M: f64 = 150.0;

/// The robot counts as stuck when its odometry position has stayed within this radius (ours:
/// 0.5 m) ...
const STUCK_RADIUS_M: f64 = 0.5;
/// ... over this long (ours: 60 s, ten times what the sample worlds' corners take to round).
const STUCK_WINDOW_S: f64 = 60.0;

/// Spacing of the revisit targets along the first boundary loop, metres of travel.
pub const REVISIT_SPACING_M: f64 = 1.0;
/// A revisit target within this distance (odometry) counts as reached, metres.
pub const REVISIT_REACHED_M: f64 = 0.6;
/// A revisit target not reached in this many times its travel time (at the configured speed,
/// [`REVISIT_SPACING_M`] apart) is skipped.
pub const REVISIT_TIMEOUT_TRAVEL_TIMES: f64 = 10.0;

/// Seconds after which a revisit target not reached is skipped.
fn revisit_timeout_s(e: &ExplorationConfig) -> f64 {
    REVISIT_TIMEOUT_TRAVEL_TIMES * REVISIT_SPACING_M / e.speed_mps
}

/// One exploration decision when a target is needed: `Err(reason)` when exploring is over, else
/// the mode that pursues the next target.
#[allow(clippy::too_many_arguments)]
fn explore_step(
    pick_target: &mut bool,
    mode: &Mode,
    odom: Pose2,
    t: f64,
    grid: &CountingGrid,
    failed: &mut Vec<Point2<f64>>,
    known_history: &mut Vec<(f64, usize)>,
    targets: &mut Vec<Point2<f64>>,
    target_started: &mut f64,
    e: &ExplorationConfig,
) -> Result<Mode, String> {
    *pick_target = false;
    if let Mode::Straight { target: Some(tg) }
    | Mode::Follow(FollowState {
        target: Some(tg), ..
    }) = mode
    {
        if (odom.position() - tg).norm() >= 0.3 {
            failed.push(*tg);
        }
    }
    let map = grid.map();
    let now = map.known_cells();
    known_history.push((t, now));
    // Compare with the area three targets and at least two minutes ago.
    let old = known_history
        .iter()
        .rev()
        .skip(3)
        .find(|(t_old, _)| t - t_old >= GROWTH_WINDOW_S)
        .map(|&(_, k)| k);
    if let Some(old) = old {
        if (now as f64) < old as f64 * (1.0 + e.min_growth) {
            return Err("explored area stopped growing".into());
        }
    }
    match choose_target(&map, odom.position(), failed, e.robot_radius_m) {
        Some(tg) => {
            targets.push(tg);
            *target_started = t;
            Ok(Mode::Straight { target: Some(tg) })
        }
        None => Err("no reachable unexplored region left".into()),
    }
}

/// The odometry position once a second over the last [`STUCK_WINDOW_S`], to tell a robot that
/// stays put.
#[derive(Debug, Default)]
struct StuckWatch {
    recent: std::collections::VecDeque<(f64, Point2<f64>)>,
    next_t_s: f64,
}

impl StuckWatch {
    /// Notes the position (once a second); true when it has stayed within [`STUCK_RADIUS_M`]
    /// over the whole window.
    fn observe(&mut self, t: f64, here: Point2<f64>) -> bool {
        if t < self.next_t_s {
            return false;
        }
        self.next_t_s = t + 1.0;
        self.recent.push_back((t, here));
        while self
            .recent
            .front()
            .is_some_and(|(t0, _)| t - t0 > STUCK_WINDOW_S)
        {
            self.recent.pop_front();
        }
        let spans = self
            .recent
            .front()
            .is_some_and(|(t0, _)| t - t0 >= STUCK_WINDOW_S - 1.0);
        spans
            && self
                .recent
                .iter()
                .all(|(_, p)| (p - here).norm() < STUCK_RADIUS_M)
    }
}

/// Where a stuck robot drives to (odometry frame): up to 1.5 m along the most open of 72
/// directions around it, stopping the follow distance short of what is there.
fn escape_target(world: &World, truth: Pose2, odom: Pose2, e: &ExplorationConfig) -> Point2<f64> {
    let (bearing, open) = (0..72)
        .map(|k| {
            let bearing = k as f64 * std::f64::consts::TAU / 72.0;
            let open = clearance(
                world,
                truth.position(),
                truth.theta + bearing,
                e.robot_radius_m,
                50.0,
            );
            (bearing, open)
        })
        .fold((0.0, f64::NEG_INFINITY), |best, c| {
            if c.1 > best.1 {
                c
            } else {
                best
            }
        });
    let heading = odom.theta + bearing;
    let go = (open - e.follow_distance_m).clamp(0.3, 1.5);
    odom.position() + Vector2::new(heading.cos(), heading.sin()) * go
}

/// Free distance ahead of the robot centre along `heading`, over a band as wide as the robot.
fn clearance(world: &World, p: Point2<f64>, heading: f64, radius: f64, max: f64) -> f64 {
    let dir = Vector2::new(heading.cos(), heading.sin());
    let side = Vector2::new(-dir.y, dir.x);
    [-1.0, -0.5, 0.0, 0.5, 1.0]
        .iter()
        .map(|k| {
            let o = p + side * (k * radius);
            world.ray_cast_walls(o, dir, max).map_or(max, |h| h.range_m)
        })
        .fold(max, f64::min)
}

/// Returns the command (v, w) and possibly a new mode.
fn control(
    world: &World,
    truth: Pose2,
    odom: Pose2,
    mode: &Mode,
    e: &ExplorationConfig,
) -> (f64, f64, Option<Mode>) {
    let d = e.follow_distance_m;
    let p = truth.position();
    let front = clearance(world, p, truth.theta, e.robot_radius_m, 3.0);
    let steer_to = |heading_err: f64| -> (f64, f64) {
        if heading_err.abs() > 0.5 {
            (0.0, e.turn_rate_rad_s * heading_err.signum())
        } else {
            (
                e.speed_mps,
                (1.5 * heading_err).clamp(-e.turn_rate_rad_s, e.turn_rate_rad_s),
            )
        }
    };
    match mode {
        Mode::LookAround { remaining_rad } => {
            if *remaining_rad <= 0.0 {
                (0.0, 0.0, Some(Mode::Straight { target: None }))
            } else {
                (0.0, e.turn_rate_rad_s, None)
            }
        }
        Mode::Straight { target } => {
            let heading_err = match target {
                Some(tg) => {
                    let to = tg - odom.position();
                    wrap_angle(to.y.atan2(to.x) - odom.theta)
                }
                None => 0.0,
            };
            // Only an obstacle in the direction of travel stops us (not one we are turning away from).
            if front < d && heading_err.abs() <= 0.5 {
                let hit_distance_m =
                    target.map_or(f64::INFINITY, |tg| (tg - odom.position()).norm());
                let f = FollowState {
                    target: *target,
                    hit_distance_m,
                    travel_m: 0.0,
                    history: Vec::new(),
                    first_corner: None,
                };
                return (0.0, 0.0, Some(Mode::Follow(f)));
            }
            let (v, w) = steer_to(heading_err);
            (v, w, None)
        }
        Mode::Follow(f) => {
            // Leaving conditions.
            if let Some(tg) = f.target {
                let to = tg - odom.position();
                let dist = to.norm();
                let bearing = to.y.atan2(to.x);
                // Bearing in the true frame: odometry and truth differ by the drift; use the
                // odometry's heading error applied to the true heading.
                let true_bearing = truth.theta + wrap_angle(bearing - odom.theta);
                let open =
                    clearance(world, p, true_bearing, e.robot_radius_m, 1.5) >= 1.0_f64.min(dist);
                if (open && dist < f.hit_distance_m - 0.2) || f.travel_m > BUG_GIVE_UP_M {
                    return (0.0, 0.0, Some(Mode::Straight { target: Some(tg) }));
                }
            } else {
                let mut f2 = f.clone();
                if f2.first_corner.is_none() {
                    if let Some(&(_, old)) = f2
                        .history
                        .iter()
                        .rev()
                        .find(|(s, _)| f2.travel_m - s >= CORNER_WINDOW_M)
                    {
                        if wrap_angle(odom.theta - old).abs() > CORNER_TURN_RAD {
                            f2.first_corner = Some((odom.position(), f2.travel_m));
                        }
                    }
                    f2.history
                        .retain(|(s, _)| f2.travel_m - s < 2.0 * CORNER_WINDOW_M);
                    return follow_command(world, truth, e, front, Some(Mode::Follow(f2)));
                }
                if let Some((corner, at)) = f2.first_corner {
                    if (f2.travel_m - at > 3.0 && (odom.position() - corner).norm() < 0.4)
                        || f2.travel_m > BOUNDARY_GIVE_UP_M
                    {
                        return (0.0, 0.0, Some(Mode::Straight { target: None }));
                    }
                }
            }
            follow_command(world, truth, e, front, None)
        }
    }
}

fn follow_command(
    world: &World,
    truth: Pose2,
    e: &ExplorationConfig,
    front: f64,
    next: Option<Mode>,
) -> (f64, f64, Option<Mode>) {
    let d = e.follow_distance_m;
    let p = truth.position();
    if front < CORNER_ARC_M + d {
        // A wall ahead: round the corner on an arc (in place only when already too close), so the
        // sonar sees the corner from positions spread around it.
        let v = if front < 0.8 * d { 0.0 } else { e.speed_mps };
        return (
            v,
            e.turn_rate_rad_s
                .min(e.speed_mps / CORNER_ARC_M)
                .max(if v == 0.0 { e.turn_rate_rad_s } else { 0.0 }),
            next,
        );
    }
    // The nearest obstacle ahead or on the right, by a fan of rays (a virtual range finder). The
    // fan stops short of straight behind so a wall just turned away from is not followed again.
    let mut nearest: Option<(f64, f64)> = None;
    for k in 0..=FOLLOW_FAN_RAYS {
        let bearing = FOLLOW_FAN_RAD.0
            + (FOLLOW_FAN_RAD.1 - FOLLOW_FAN_RAD.0) * k as f64 / FOLLOW_FAN_RAYS as f64;
        let a = truth.theta + bearing;
        if let Some(h) = world.ray_cast_walls(p, Vector2::new(a.cos(), a.sin()), d + 1.0) {
            if nearest.is_none_or(|(r, _)| h.range_m < r) {
                nearest = Some((h.range_m, a));
            }
        }
    }
    let (v, w) = match nearest {
        None => (e.speed_mps, -e.speed_mps / d), // lost the wall: arc to the right to find it
        Some((dist, towards)) => {
            let desired =
                towards + std::f64::consts::FRAC_PI_2 - (2.0 * (dist - d)).clamp(-1.0, 1.0);
            let err = wrap_angle(desired - truth.theta);
            if err.abs() > 0.8 && dist < d {
                (0.0, e.turn_rate_rad_s * err.signum())
            } else if err.abs() > 0.8 {
                // Not too close: turn while creeping on, so two obstacles pulling opposite ways
                // (a door's jambs) cannot hold the robot turning back and forth on the spot.
                (0.5 * e.speed_mps, e.turn_rate_rad_s * err.signum())
            } else {
                (
                    e.speed_mps,
                    (2.0 * err).clamp(-e.turn_rate_rad_s, e.turn_rate_rad_s),
                )
            }
        }
    };
    (v, w, next)
}

/// The frontier cell (unknown, next to known free space, reachable through free space) whose
/// surroundings are least known, preferring near ones; `None` when no frontier is reachable.
fn choose_target(
    map: &OccupancyMap,
    from: Point2<f64>,
    failed: &[Point2<f64>],
    robot_radius: f64,
) -> Option<Point2<f64>> {
    let g = &map.geometry;
    let (w, h) = (g.width as i64, g.height as i64);
    let inflate = (robot_radius / g.resolution_m).ceil() as i64;
    let blocked: Vec<bool> = (0..map.occupancy.len())
        .map(|i| {
            let (c, r) = ((i as i64) % w, (i as i64) / w);
            (-inflate..=inflate).any(|dr| {
                (-inflate..=inflate).any(|dc| {
                    let (cc, rr) = (c + dc, r + dr);
                    cc >= 0
                        && rr >= 0
                        && cc < w
                        && rr < h
                        && map.is_occupied((rr * w + cc) as usize)
                })
            })
        })
        .collect();
    let (c0, r0) = g.cell_of(from.x, from.y)?;
    let start = r0 * g.width + c0;
    let mut dist = vec![u32::MAX; map.occupancy.len()];
    dist[start] = 0;
    let mut queue = std::collections::VecDeque::from([start]);
    let mut best: Option<(f64, usize)> = None;
    let radius = (1.0 / g.resolution_m).round() as i64;
    while let Some(i) = queue.pop_front() {
        let (c, r) = ((i as i64) % w, (i as i64) / w);
        for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let (cc, rr) = (c + dc, r + dr);
            if cc < 0 || rr < 0 || cc >= w || rr >= h {
                continue;
            }
            let j = (rr * w + cc) as usize;
            if dist[j] != u32::MAX || blocked[j] {
                continue;
            }
            dist[j] = dist[i] + 1;
            if map.occupancy[j].is_none() {
                // A frontier cell: score by unknown cells around, minus travel.
                let [x, y] = g.centre(cc as usize, rr as usize);
                if failed.iter().any(|f| (f.x - x).hypot(f.y - y) < 1.0) {
                    continue;
                }
                let mut unknown = 0;
                for ddr in -radius..=radius {
                    for ddc in -radius..=radius {
                        let (a, b) = (cc + ddc, rr + ddr);
                        if a >= 0
                            && b >= 0
                            && a < w
                            && b < h
                            && map.occupancy[(b * w + a) as usize].is_none()
                        {
                            unknown += 1;
                        }
                    }
                }
                let score = unknown as f64 - 2.0 * dist[j] as f64 * g.resolution_m;
                if best.is_none_or(|(s, _)| score > s) {
                    best = Some((score, j));
                }
            } else if map.is_free(j) {
                queue.push_back(j);
            }
        }
    }
    best.map(|(_, j)| {
        let [x, y] = g.centre(j % g.width, j / g.width);
        Point2::new(x, y)
    })
}

/// The explorer's state over a run: the mode, the targets chosen and given up, the first
/// boundary loop and its second drive, the stuck watch.
pub(super) struct Explorer {
    mode: Mode,
    /// Set when the first boundary loop ends: exploration goes on by targets.
    pick_target: bool,
    /// Exploration targets chosen, in order.
    pub(super) targets: Vec<Point2<f64>>,
    failed: Vec<Point2<f64>>,
    target_started: f64,
    stuck_watch: StuckWatch,
    escapes: usize,
    known_history: Vec<(f64, usize)>,
    /// The first boundary loop as odometry positions.
    loop_path: Vec<Point2<f64>>,
    loop_done: bool,
    /// The revisit queue once exploring ends, and why it ended.
    revisit: Option<(std::collections::VecDeque<Point2<f64>>, String)>,
}

impl Explorer {
    /// An explorer at the start of a run.
    pub(super) fn new(e: &ExplorationConfig) -> Self {
        Self {
            mode: if e.look_around_at_start {
                Mode::LookAround {
                    remaining_rad: std::f64::consts::TAU,
                }
            } else {
                Mode::Straight { target: None }
            },
            pick_target: false,
            targets: Vec::new(),
            failed: Vec::new(),
            target_started: 0.0,
            stuck_watch: StuckWatch::default(),
            escapes: 0,
            known_history: Vec::new(),
            loop_path: Vec::new(),
            loop_done: false,
            revisit: None,
        }
    }

    /// Chooses the next target when there is none to pursue; `Some(why)` when exploring is
    /// over. Revisit targets are odometry positions near walls that drift may have put inside
    /// one: they count as reached sooner and are given up sooner.
    pub(super) fn next_target(
        &mut self,
        t: f64,
        odom: Pose2,
        grid: &CountingGrid,
        e: &ExplorationConfig,
    ) -> Option<String> {
        let (reach_m, timeout_s) = if self.revisit.is_some() {
            (REVISIT_REACHED_M, revisit_timeout_s(e))
        } else {
            (0.3, e.target_timeout_s)
        };
        let needs_target = self.pick_target
            || match &self.mode {
                Mode::Straight { target: Some(tg) } => {
                    (odom.position() - tg).norm() < reach_m || t - self.target_started > timeout_s
                }
                Mode::Follow(FollowState {
                    target: Some(tg), ..
                }) => {
                    (self.revisit.is_some() && (odom.position() - tg).norm() < reach_m)
                        || t - self.target_started > timeout_s
                }
                _ => false,
            };
        if !needs_target {
            return None;
        }
        if let Some((queue, explore_end)) = self.revisit.as_mut() {
            // Revisiting the first loop: the next point of it, whether this one was reached.
            return match queue.pop_front() {
                Some(tg) => {
                    self.target_started = t;
                    self.mode = Mode::Straight { target: Some(tg) };
                    None
                }
                None => Some(format!("{explore_end}; first boundary loop driven again")),
            };
        }
        let reason = match explore_step(
            &mut self.pick_target,
            &self.mode,
            odom,
            t,
            grid,
            &mut self.failed,
            &mut self.known_history,
            &mut self.targets,
            &mut self.target_started,
            e,
        ) {
            Ok(next) => {
                self.mode = next;
                return None;
            }
            Err(reason) => reason,
        };
        if !(e.revisit_loop && self.loop_path.len() > 1) {
            return Some(reason);
        }
        // Start the loop again from its point nearest to where the robot is.
        let here = odom.position();
        let start = (0..self.loop_path.len())
            .min_by(|&a, &b| {
                (self.loop_path[a] - here)
                    .norm()
                    .total_cmp(&(self.loop_path[b] - here).norm())
            })
            .unwrap_or(0);
        let mut queue: std::collections::VecDeque<Point2<f64>> = self.loop_path[start..]
            .iter()
            .chain(&self.loop_path[..=start])
            .copied()
            .collect();
        let first = queue.pop_front().unwrap_or(here);
        self.target_started = t;
        self.mode = Mode::Straight {
            target: Some(first),
        };
        self.revisit = Some((queue, reason));
        None
    }

    /// When the robot has stayed put too long (circling in a pocket of clutter, or turning
    /// between targets it cannot see): gives the target up and drives out along the most open
    /// direction.
    pub(super) fn unstick(
        &mut self,
        t: f64,
        world: &World,
        (truth, odom): (Pose2, Pose2),
        e: &ExplorationConfig,
    ) {
        if !self.stuck_watch.observe(t, odom.position())
            || matches!(self.mode, Mode::LookAround { .. })
        {
            return;
        }
        if let Mode::Straight { target: Some(tg) }
        | Mode::Follow(FollowState {
            target: Some(tg), ..
        }) = &self.mode
        {
            if self.revisit.is_none() {
                self.failed.push(*tg);
            }
        }
        self.mode = Mode::Straight {
            target: Some(escape_target(world, truth, odom, e)),
        };
        self.target_started = t;
        self.stuck_watch.recent.clear();
        self.escapes += 1;
    }

    /// The command `(v, w)` now, switching mode when the controller says so.
    pub(super) fn command(
        &mut self,
        world: &World,
        (truth, odom): (Pose2, Pose2),
        e: &ExplorationConfig,
    ) -> (f64, f64) {
        let (v, w, next_mode) = control(world, truth, odom, &self.mode, e);
        if let Some(m) = next_mode {
            // The first boundary loop closed (or was abandoned): choose a target next step.
            self.pick_target = matches!(
                (&self.mode, &m),
                (Mode::Follow(_), Mode::Straight { target: None })
            );
            self.loop_done |= self.pick_target;
            self.mode = m;
        }
        (v, w)
    }

    /// Notes a step of `ds` metres and `dth` radians (as the encoders saw it) ending at `odom`.
    pub(super) fn moved(&mut self, ds: f64, dth: f64, odom: Pose2) {
        if let Mode::LookAround { remaining_rad } = &mut self.mode {
            *remaining_rad -= dth.abs();
        }
        if let Mode::Follow(f) = &mut self.mode {
            f.travel_m += ds.abs();
            f.history.push((f.travel_m, odom.theta));
            let on_first_loop = f.target.is_none() && !self.loop_done;
            if on_first_loop
                && self
                    .loop_path
                    .last()
                    .is_none_or(|last| (odom.position() - last).norm() >= REVISIT_SPACING_M)
            {
                self.loop_path.push(odom.position());
            }
        }
    }

    /// Why the run ended, with the times the robot was driven out of where it was stuck.
    pub(super) fn end_reason(&self, mut reason: String) -> String {
        if self.escapes > 0 {
            reason.push_str(&format!(
                "; stuck {} time{} (within {STUCK_RADIUS_M} m for {STUCK_WINDOW_S} s), driven out",
                self.escapes,
                if self.escapes == 1 { "" } else { "s" }
            ));
        }
        reason
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{simulate, SimConfig};

    fn corridor() -> World {
        crate::world::rectangle_world(6.0, 3.0, Pose2::new(2.0, 1.5, 0.0))
    }

    /// A robot that cannot get anywhere (a box hardly larger than itself) is found stuck once
    /// its odometry has stayed within 0.5 m for a minute, and the run says so.
    #[test]
    fn a_robot_that_cannot_move_on_is_found_stuck() {
        let w = crate::world::rectangle_world(0.9, 0.9, Pose2::new(0.45, 0.45, 0.0));
        let mut c = SimConfig::default();
        c.exploration.duration_s = 600.0;
        let out = simulate(&w, &c, |_| {}).unwrap();
        assert!(
            out.end_reason.contains("stuck 1 time"),
            "{}",
            out.end_reason
        );
    }

    /// On willow (seed 5) the robot, sent to a revisit target, used to circle a pocket of
    /// clutter at (6.2, 3.0) m for the last 1100 s of the run. It is now found stuck, driven out,
    /// and never stays within 0.5 m for two minutes.
    #[test]
    fn a_robot_circling_a_pocket_is_driven_out() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let loaded = crate::io::load_world(&root.join("samples/willow/world.yaml")).unwrap();
        let c = SimConfig {
            seed: 5,
            ..loaded.simulation
        };
        let out = simulate(&loaded.world, &c, |_| {}).unwrap();
        assert!(out.end_reason.contains("stuck"), "{}", out.end_reason);
        let truth = out.run.ground_truth.unwrap();
        let end = truth.last().unwrap().t_s;
        for (i, a) in truth.iter().enumerate() {
            if end - a.t_s < 120.0 {
                break;
            }
            let far = truth[i..]
                .iter()
                .take_while(|b| b.t_s - a.t_s <= 120.0)
                .map(|b| (b.pose.position() - a.pose.position()).norm())
                .fold(0.0, f64::max);
            assert!(
                far >= 0.5,
                "within {far:.2} m of {:?} from t = {} s for 120 s",
                a.pose,
                a.t_s
            );
        }
    }

    /// A stuck robot drives out along the most open direction: facing the end wall of a corridor,
    /// it heads back down the corridor, the follow distance short of the far end at most 1.5 m.
    #[test]
    fn the_way_out_is_the_most_open_direction() {
        let w = corridor();
        let e = ExplorationConfig::default();
        let truth = Pose2::new(0.5, 1.5, std::f64::consts::PI);
        // The odometry has drifted: the target is in its frame.
        let odom = Pose2::new(0.7, 1.4, std::f64::consts::PI + 0.1);
        let target = escape_target(&w, truth, odom, &e);
        let rel = odom.inverse().transform_point(target);
        // Straight behind the robot in its own frame, 1.5 m away.
        assert!((rel.coords.norm() - 1.5).abs() < 1e-9, "{rel}");
        assert!(rel.x < -1.45, "{rel}");
    }
}
