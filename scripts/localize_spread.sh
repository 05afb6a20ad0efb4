#!/usr/bin/env bash
# Localisation on a real building, judged over a spread of runs rather than one (issue 34: real
# logs). Session 54 found one localisation of freiburg-079 chaotic: the range sigma moved by a
# tenth of a millimetre (0.0337 -> 0.03366 m) took one drifted run from 0.96 m to 3.51 m. So a
# change is judged here by the median and the tail over many runs:
#   1. the log imported as sonar (`import --carmen --as-sonar frontal5`) and surveyed with no tags;
#   2. its odometry drifted three ways as wheels drift (scripts/drift_odometry.py: distance scale,
#      turn scale, heading bias per metre, seeds 1-3), and kept undrifted;
#   3. each of the four runs localised against the survey at the default settings and with the
#      range noise set to each of seven constants from 2.8 to 4 cm (around the survey's measured
#      scatter, `walls.range_residual_sigma_m`: 3.4 cm);
#   4. the ATE of each of the 32 localisations printed beside its odometry's, then their median,
#      mean, how many end over 1 m off and how many worse than their odometry.
# The survey's walls were fitted to the very ranges localised here, which flatters any method that
# matches ranges with a map: scripts/localize_split.sh localises against a survey of other ranges.
#   scripts/localize_spread.sh [LOG] [OUT_DIR]     FLAGS adds localize flags to every run
# A second call with the same OUT_DIR reuses the survey and the runs (about 2 minutes for the 32).
log=${1:-../shared/data/radish/freiburg-079-corrected.log.gz}
out=${2:-localize_spread}
# shellcheck source=scripts/real_log_localize.sh
. "$(dirname "$0")/real_log_localize.sh"
import_log
[ -f "$out/survey/landmarks.json" ] ||
  "$bin" -q survey --run "$out/run" --out "$out/survey" --no-rerun --force
survey_for() { echo "$out/survey"; }
runs=()
drifted "$out/run"
sigmas=(default 0.028 0.030 0.032 0.034 0.036 0.038 0.040)
localize_table
