#!/usr/bin/env bash
# Localisation on a real building against a survey of *other* ranges (issue 34: real logs).
# scripts/localize_spread.sh localises the very log its survey was made from: the walls were
# fitted to the ranges being localised, which flatters any method that matches ranges with a map
# (session 55: a particle filter on the survey's grid ended 8-10 cm off there, and 4-17 m off
# here). This cuts the log in two halves at its middle time (scripts/split_run.py), surveys each
# half with no tags, and localises the other half against it: as logged and with its odometry
# drifted three ways (scripts/drift_odometry.py, the drifts of localize_spread.sh), each at the
# default range noise and at three constant range sigmas (the outcome of one run is chaotic).
# Prints each localised ATE beside the odometry's, then the median, and how many runs end worse
# than their odometry.
#   scripts/localize_split.sh [LOG] [OUT_DIR]     FLAGS adds localize flags to every run
# A second call with the same OUT_DIR reuses the surveys and the runs; the 32 localisations take
# about 3 minutes either way (a run whose sigma grows searches the walls for its pose often).
set -euo pipefail
FLAGS=${FLAGS:-}
log=${1:-../shared/data/radish/freiburg-079-corrected.log.gz}
out=${2:-localize_split}
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
here=$(cd "$(dirname "$0")" && pwd)
# A directory this call makes is taken away again when the log does not import.
[ -d "$out" ] || trap 'rm -rf "$out"' EXIT
mkdir -p "$out"
[ -f "$out/run/run.yaml" ] || "$bin" -q import --carmen "$log" --as-sonar frontal5 --out "$out/run" --force
trap - EXIT
mid=$(python3 -c 'import csv,sys; t=[float(r[0]) for r in list(csv.reader(open(sys.argv[1])))[1:]]; print((t[0]+t[-1])/2)' "$out/run/odometry.csv")
[ -f "$out/first/run.yaml" ] || python3 "$here/split_run.py" "$out/run" "$out/first" 0 "$mid"
[ -f "$out/second/run.yaml" ] || python3 "$here/split_run.py" "$out/run" "$out/second" "$mid" 1e12
drifts=("1.01 0.99 0.1 1" "0.98 1.01 -0.2 2" "1.00 1.00 0.05 3")
runs=()
for half in first second; do
  [ -f "$out/survey_$half/landmarks.json" ] ||
    "$bin" -q survey --run "$out/$half" --out "$out/survey_$half" --no-rerun --force
  runs+=("$half")
  for d in "${drifts[@]}"; do
    read -r scale turn bias seed <<<"$d"
    dir="$out/${half}_drift_$seed"
    [ -f "$dir/run.yaml" ] || python3 "$here/drift_odometry.py" "$out/$half" "$dir" --scale "$scale" \
      --turn-scale "$turn" --bias-deg-per-m "$bias" --seed "$seed" >/dev/null
    runs+=("${half}_drift_$seed")
  done
done
other() { case "$1" in first*) echo second ;; *) echo first ;; esac; }
sigmas=(default 0.030 0.034 0.038)
printf 'range_sigma_m'
for r in "${runs[@]}"; do printf '\t%s' "$r"; done
printf '\n'
all=()
for s in "${sigmas[@]}"; do
  config=()
  if [ "$s" != default ]; then
    printf 'sonar_sigma_m: %s\nsonar_sigma_frac: 0.0\n' "$s" > "$out/sigma_$s.yaml"
    config=(--config "$out/sigma_$s.yaml")
  fi
  printf '%s' "$s"
  for r in "${runs[@]}"; do
    # shellcheck disable=SC2086 # FLAGS is split into flags on purpose
    "$bin" -q localize --survey "$out/survey_$(other "$r")" --run "$out/$r" --out "$out/loc" \
      --no-rerun --force "${config[@]}" $FLAGS >/dev/null
    pair=$(python3 -c 'import json,sys; m=json.load(open(sys.argv[1]))["metrics"]; print("%.3f/%.3f" % (m["ate_m.localized"], m["ate_m.odometry"]))' "$out/loc/report.json")
    all+=("$pair")
    printf '\t%s' "$pair"
  done
  printf '\n'
done
python3 - "${all[@]}" <<'PY'
import statistics, sys
pairs = [tuple(map(float, p.split("/"))) for p in sys.argv[1:]]
loc = [a for a, _ in pairs]
print("localised ATE over %d runs (localised/odometry): median %.3f m, mean %.3f m; median ratio "
      "to the odometry's %.2f; %d of %d worse than their odometry" %
      (len(pairs), statistics.median(loc), statistics.mean(loc),
       statistics.median(a / o for a, o in pairs), sum(a > o for a, o in pairs), len(pairs)))
PY
