//! Figures: how well a map, its features, a trajectory and a survey match the truth, and the
//! metrics a report holds. The one home of every score, so that a figure is computed one way.

pub mod localize;
pub mod map;
pub mod survey;
pub mod trajectory;

pub use localize::{
    error_growth, localization_metrics, position_nees, score_localization, GrowthBin,
    LocalizationCounts, LocalizationScores, Located, GROWTH_BANDS_M,
};
pub use survey::{
    score_sonar_map, score_survey, survey_metrics, LandmarkErrors, SonarScores, SurveyScores,
    TrajectoryErrors, TruthScores, TurnErrors, WorldScores,
};
pub use trajectory::{align_se2, at_truth, ate_m, Scored};
