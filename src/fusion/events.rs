//! A run's sightings and visual turns as events in time order, as the filters take them.

use crate::fusion::FuseConfig;
use crate::visual::sightings::TagSighting;
use crate::visual::vo::VisualTurn;

/// What the online filter does at a moment of the run, in the order it does them at one time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Event {
    /// A visual turn ends: fuse it.
    TurnEnds(usize),
    /// A tag sighting.
    Sighting(usize),
    /// A visual turn starts: copy the heading.
    TurnStarts(usize),
}

/// The sightings and, when `config` uses them, the visual turns that start at or after `from_t_s`
/// (the odometry's first time) as events in time order.
pub(crate) fn events(
    sightings: &[TagSighting],
    visual: &[VisualTurn],
    from_t_s: f64,
    config: &FuseConfig,
) -> Vec<(f64, Event)> {
    let mut events: Vec<(f64, Event)> = sightings
        .iter()
        .enumerate()
        .map(|(k, s)| (s.t_s, Event::Sighting(k)))
        .collect();
    if config.visual_odometry {
        for (j, v) in visual
            .iter()
            .enumerate()
            .filter(|(_, v)| v.from_t_s >= from_t_s)
        {
            events.push((v.from_t_s, Event::TurnStarts(j)));
            events.push((v.to_t_s, Event::TurnEnds(j)));
        }
    }
    events.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    events
}
