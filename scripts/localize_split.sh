#!/usr/bin/env bash
# Localisation on a real building against a survey of *other* ranges (issue 34: real logs).
# scripts/localize_spread.sh localises the very log its survey was made from: the walls were
# fitted to the ranges being localised, which flatters any method that matches ranges with a map
# (session 55: a particle filter on the survey's grid ended 7-10 cm off there, and 4-17 m off
# here). This cuts the log in two halves at its middle time (scripts/split_run.py), surveys each
# half with no tags, and localises the other half against it: as logged and with its odometry
# drifted three ways (scripts/drift_odometry.py, the drifts of localize_spread.sh), each at the
# default range noise and at three constant range sigmas (the outcome of one run is chaotic).
# Prints each localised ATE beside the odometry's, then the median, the mean, how many runs end
# over 1 m off and how many end worse than their odometry.
#   scripts/localize_split.sh [LOG] [OUT_DIR]     FLAGS adds localize flags to every run
# A second call with the same OUT_DIR reuses the surveys and the runs. Each localisation takes
# about a minute on two cores (session 64; a run whose sigma grows searches the walls for its pose
# often), so the 32 take about half an hour; a shorter `sigmas` list below makes a quicker
# comparison.
log=${1:-../shared/data/radish/freiburg-079-corrected.log.gz}
out=${2:-localize_split}
# shellcheck source=scripts/real_log_localize.sh
. "$(dirname "$0")/real_log_localize.sh"
import_log
mid=$(python3 -c 'import csv,sys; t=[float(r[0]) for r in list(csv.reader(open(sys.argv[1])))[1:]]; print((t[0]+t[-1])/2)' "$out/run/odometry.csv")
[ -f "$out/first/run.yaml" ] || python3 "$here/split_run.py" "$out/run" "$out/first" 0 "$mid"
[ -f "$out/second/run.yaml" ] || python3 "$here/split_run.py" "$out/run" "$out/second" "$mid" 1e12
runs=()
for half in first second; do
  [ -f "$out/survey_$half/landmarks.json" ] ||
    "$bin" -q survey --run "$out/$half" --out "$out/survey_$half" --no-rerun --force
  drifted "$out/$half"
done
# Each half is localised against the other half's survey.
survey_for() { case "$(basename "$1")" in first*) echo "$out/survey_second" ;; *) echo "$out/survey_first" ;; esac; }
sigmas=(default 0.030 0.034 0.038)
localize_table
