#!/usr/bin/env bash
# Localisation over every pair of seeds: survey each seed (the demo's steps), then localise every
# other seed's run against each survey, with the surveyed walls and with the tags alone. Prints the
# localised ATE (m) per pair.
#   scripts/localize_pairs.sh [WORLD] [SEEDS...]     e.g. scripts/localize_pairs.sh samples/office/world.yaml 1 2 3 4
set -euo pipefail
# FLAGS: detector flags for every demo and localize, e.g. FLAGS="--decimate 1" (full resolution).
FLAGS=${FLAGS:-}
world=${1:-samples/office/world.yaml}
shift || true
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(1 2 3 4)
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for s in "${seeds[@]}"; do
  "$bin" -q demo --world "$world" --seed "$s" --out "$tmp/$s" --no-rerun $FLAGS >/dev/null
done
ate() {
  python3 -c 'import json,sys; print("%.3f" % json.load(open(sys.argv[1]))["metrics"]["ate_m.localized"])' "$1"
}
printf 'survey\trun\twith_walls_m\ttags_only_m\n'
for s in "${seeds[@]}"; do
  for r in "${seeds[@]}"; do
    [ "$s" = "$r" ] && continue
    "$bin" -q localize --survey "$tmp/$s" --run "$tmp/$r/run" --out "$tmp/loc" --no-rerun --force $FLAGS >/dev/null
    a=$(ate "$tmp/loc/report.json")
    "$bin" -q localize --survey "$tmp/$s" --run "$tmp/$r/run" --out "$tmp/loc" --no-rerun --no-walls --force $FLAGS >/dev/null
    b=$(ate "$tmp/loc/report.json")
    printf '%s\t%s\t%s\t%s\n' "$s" "$r" "$a" "$b"
  done
done
