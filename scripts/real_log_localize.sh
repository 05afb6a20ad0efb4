# shellcheck shell=bash
# Shared by scripts/localize_spread.sh and scripts/localize_split.sh (sourced, not run): a real
# log imported as sonar, runs drifted as wheels drift, and a table of localisations over range
# sigmas. Each script sets `log`, `out` and `sigmas`, defines `survey_for RUN` (the survey a run
# is localised against), and calls these in turn.
set -euo pipefail
FLAGS=${FLAGS:-}
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

# import_log: $log imported as sonar (`import --carmen --as-sonar frontal5`) into $out/run; a
# directory this call makes is taken away again when the log does not import.
import_log() {
  [ -d "$out" ] || trap 'rm -rf "$out"' EXIT
  mkdir -p "$out"
  [ -f "$out/run/run.yaml" ] ||
    "$bin" -q import --carmen "$log" --as-sonar frontal5 --out "$out/run" --force
  trap - EXIT
}

# drifted SRC: SRC's odometry drifted three ways (scripts/drift_odometry.py; the drifts of
# docs/RESULTS.md, "The same with a drifting odometry": scale, turn scale, bias, seed) into
# SRC_drift_1..3, each added to the array `runs` after SRC.
drifted() {
  local d scale turn bias seed dir
  runs+=("$1")
  for d in "1.01 0.99 0.1 1" "0.98 1.01 -0.2 2" "1.00 1.00 0.05 3"; do
    read -r scale turn bias seed <<<"$d"
    dir="$1_drift_$seed"
    [ -f "$dir/run.yaml" ] || python3 "$here/drift_odometry.py" "$1" "$dir" --scale "$scale" \
      --turn-scale "$turn" --bias-deg-per-m "$bias" --seed "$seed" >/dev/null
    runs+=("$dir")
  done
}

# localize_table: every run of `runs` localised against `survey_for RUN` at each range sigma of
# `sigmas` ("default": the settings' own, else a constant sigma); prints the localised / odometry
# ATE of each, then the median, mean, how many end over 1 m off and how many worse than their
# odometry.
localize_table() {
  local s r pair all=() config
  printf 'range_sigma_m'
  for r in "${runs[@]}"; do printf '\t%s' "$(basename "$r")"; done
  printf '\n'
  for s in "${sigmas[@]}"; do
    config=()
    if [ "$s" != default ]; then
      printf 'sonar_sigma_m: %s\nsonar_sigma_frac: 0.0\n' "$s" > "$out/sigma_$s.yaml"
      config=(--config "$out/sigma_$s.yaml")
    fi
    printf '%s' "$s"
    for r in "${runs[@]}"; do
      # shellcheck disable=SC2086 # FLAGS is split into flags on purpose
      "$bin" -q localize --survey "$(survey_for "$r")" --run "$r" --out "$out/loc" --no-rerun \
        --force "${config[@]}" $FLAGS >/dev/null
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
print("localised ATE over %d runs (localised/odometry): median %.3f m, mean %.3f m, %d over 1 m; "
      "median ratio to the odometry's %.2f, %d worse than their odometry" %
      (len(pairs), statistics.median(loc), statistics.mean(loc), sum(a > 1.0 for a in loc),
       statistics.median(a / o for a, o in pairs), sum(a > o for a, o in pairs)))
PY
}
