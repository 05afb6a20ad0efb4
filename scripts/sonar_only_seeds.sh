#!/usr/bin/env bash
# The sonar's own correction (issue 31, item 3): a world simulated without cameras
# (`simulate --no-stereo`) for each seed, surveyed, and per seed the ATE of the odometry and of
# the offline pass, their ratio, the sonar's matched keyframes, and the corrected map's occupied
# precision beside the map the ground-truth poses give; then the odometry calibration the sonar
# alone estimated (turn scale and distance scale errors: the simulated wheels' are about +0.010
# and 0.000) and the offline and odometry heading errors, degrees, where the robot first leaves
# its start (0.3 m away: after the look-around, which the offline pass cannot correct where the
# sonar hears nothing while it turns).
#   scripts/sonar_only_seeds.sh WORLD SEED...     e.g. scripts/sonar_only_seeds.sh samples/museum/world.yaml 1 2 3 4 5
set -euo pipefail
world=${1:?usage: $0 WORLD SEED...}
shift
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
printf 'seed\tate_odometry_m\tate_offline_m\tratio\tmatches\tkeyframes\tprecision_corrected\tprecision_ground_truth\tseconds\tturn_scale\tdistance_scale\theading_offline_deg\theading_odometry_deg\n'
for seed in "$@"; do
  "$bin" -q simulate --world "$world" --no-stereo --seed "$seed" --out "$tmp/run" --force >/dev/null
  "$bin" -q survey --run "$tmp/run" --out "$tmp/survey" --no-rerun --force >/dev/null
  python3 - "$tmp/survey" "$seed" <<'PY'
import json, math, sys
survey, seed = sys.argv[1], sys.argv[2]
r = json.load(open(survey + "/report.json"))
m = r["metrics"]
o, f = m["ate_m.odometry"], m["ate_m.offline"]


def tum(name):
    rows = [l.split() for l in open(survey + "/trajectory_" + name + ".tum") if not l.startswith("#")]
    return [(float(t), float(x), float(y), 2.0 * math.atan2(float(qz), float(qw)))
            for t, x, y, _, _, _, qz, qw in rows]


def heading_error_deg(estimate, truth, t):
    est = min(estimate, key=lambda p: abs(p[0] - t))
    return math.degrees(math.remainder(est[3] - truth[3], 2.0 * math.pi))


truth = tum("ground_truth")
leaves = next((p for p in truth if math.hypot(p[1] - truth[0][1], p[2] - truth[0][2]) > 0.3), truth[-1])
nan = float("nan")
print("%s\t%.3f\t%.3f\t%.2f\t%d\t%d\t%.3f\t%.3f\t%.1f\t%+.4f\t%+.4f\t%+.1f\t%+.1f" % (
      seed, o, f, f / o,
      m.get("offline.sonar_matches", 0), m.get("offline.keyframes", 0),
      m.get("map_corrected.occupied_precision", nan),
      m.get("map_ground_truth.occupied_precision", nan),
      r.get("timings_s", {}).get("fuse_sonar", nan),
      m.get("offline.odometry_turn_scale_error", nan),
      m.get("offline.odometry_distance_scale_error", nan),
      heading_error_deg(tum("offline"), leaves, leaves[0]),
      heading_error_deg(tum("odometry"), leaves, leaves[0])))
PY
done
