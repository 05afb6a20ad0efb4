#!/usr/bin/env bash
# The sonar's own correction (issue 31, item 3): a world simulated without cameras
# (`simulate --no-stereo`) for each seed, surveyed, and per seed the ATE of the odometry and of
# the offline pass, their ratio, the sonar's matched keyframes, and the corrected map's occupied
# precision beside the map the ground-truth poses give.
#   scripts/sonar_only_seeds.sh WORLD SEED...     e.g. scripts/sonar_only_seeds.sh samples/museum/world.yaml 1 2 3 4 5
set -euo pipefail
world=${1:?usage: $0 WORLD SEED...}
shift
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
printf 'seed\tate_odometry_m\tate_offline_m\tratio\tmatches\tkeyframes\tprecision_corrected\tprecision_ground_truth\tseconds\n'
for seed in "$@"; do
  "$bin" -q simulate --world "$world" --no-stereo --seed "$seed" --out "$tmp/run" --force >/dev/null
  "$bin" -q survey --run "$tmp/run" --out "$tmp/survey" --no-rerun --force >/dev/null
  python3 - "$tmp/survey/report.json" "$seed" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
m = r["metrics"]
o, f = m["ate_m.odometry"], m["ate_m.offline"]
print("%s\t%.3f\t%.3f\t%.2f\t%d\t%d\t%.3f\t%.3f\t%.1f" % (sys.argv[2], o, f, f / o,
      m.get("offline.sonar_matches", 0), m.get("offline.keyframes", 0),
      m.get("map_corrected.occupied_precision", float("nan")),
      m.get("map_ground_truth.occupied_precision", float("nan")),
      r.get("timings_s", {}).get("fuse_sonar", float("nan"))))
PY
done
