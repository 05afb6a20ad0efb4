#!/usr/bin/env bash
# Survey figures over several seeds: simulate, render, survey (the demo's steps) for each seed and
# print one row of report.json metrics per run (KEYS="a b ..." picks other report.json metrics).
#   scripts/survey_seeds.sh [WORLD] [SEEDS...]     e.g. scripts/survey_seeds.sh samples/museum/world.yaml 1 2 3 4 5
set -euo pipefail
# FLAGS: detector flags for every demo and localize, e.g. FLAGS="--decimate 1" (full resolution).
FLAGS=${FLAGS:-}
world=${1:-samples/office/world.yaml}
shift || true
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(1 2 3 4 5)
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
keys=${KEYS:-"ate_m.odometry ate_m.online ate_m.offline landmarks.median_error_m map.occupied_precision map.occupied_recall map_online.occupied_precision map_online.occupied_recall map_corrected.occupied_precision map_corrected.occupied_recall map_ground_truth.occupied_precision map_ground_truth.occupied_recall"}
printf 'seed'; for k in $keys; do printf '\t%s' "$k"; done; printf '\n'
for s in "${seeds[@]}"; do
  "$bin" -q demo --world "$world" --seed "$s" --out "$tmp/$s" --no-rerun $FLAGS >/dev/null
  python3 - "$tmp/$s/report.json" "$s" $keys <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))["metrics"]
print(sys.argv[2] + "".join("\t%.3f" % (m.get(k) or float("nan")) for k in sys.argv[3:]))
PY
done
