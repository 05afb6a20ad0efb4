#!/usr/bin/env bash
# Issue 33's building check, built from a real log: a Radish building (CARMEN log with corrected
# poses) imported as a lidar run and mapped on its corrected poses; the map traced into a world
# (a `map:` raster world, as a user traces their ROS map); tags placed on the walls the robot
# faced along its real path (scripts/building_check.py); the robot simulated along that path
# (`simulate --along`: sonar, stereo pictures, wheel odometry drifting about 4% of distance:
# 1% distance scale, 2% turn scale, 0.004 rad/m heading drift); then surveyed. Prints the
# survey's figures.
#   scripts/building_check.sh [LOG] [OUT_DIR]      default: freiburg-079, building_check/
set -euo pipefail
log=${1:-../shared/data/radish/freiburg-079-corrected.log.gz}
out=${2:-building_check}
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
here=$(cd "$(dirname "$0")" && pwd)
rm -rf "$out"
mkdir -p "$out"
"$bin" -q import --carmen "$log" --out "$out/real"
"$bin" -q map --run "$out/real" --out "$out/map" --poses ground-truth
start=$(sed -n 2p "$out/real/ground_truth.csv")
IFS=, read -r _ x y th <<<"$start"
{
  echo "name: $(basename "$log" .log.gz) (traced from its laser map)"
  echo "start: {x_m: $x, y_m: $y, theta_rad: $th}"
  echo "map: {yaml: map/map.yaml, wall_height_m: 2.5, simplify_m: 0.05, min_blob_cells: 4}"
  # Wheels: left +0.94%, right +1.06% (1% distance scale, 0.004 rad/m of heading drift over the
  # 0.3 m wheel base), wheel base 2% off (2% turn scale), 2 mm/sqrt(m) of random error.
  echo "simulation:"
  echo "  odometry: {left_scale_error: 0.0094, right_scale_error: 0.0106, wheel_base_error: 0.02, random_m_per_sqrt_m: 0.002}"
} > "$out/header.yaml"
python3 "$here/building_check.py" "$out/map/map.yaml" "$out/real/ground_truth.csv" \
  "$out/header.yaml" "$bin" "$out/world.yaml" 7
"$bin" -q simulate --world "$out/world.yaml" --along "$out/real/ground_truth.csv" --out "$out/run" --seed 1
"$bin" survey --run "$out/run" --out "$out/survey" --no-rerun
python3 - "$out/survey/report.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))["metrics"]
for k in sorted(m):
    if k.split(".")[0] in ("ate_m", "landmarks", "sightings", "visual", "offline", "conflicts"):
        print(f"{k}\t{m[k]:.4g}")
PY
