//! Figures: how well a map, its features, a trajectory and a survey match the truth, and the
//! metrics a report holds.

pub mod map;
