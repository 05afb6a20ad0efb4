#!/usr/bin/env bash
# Anchored survey figures (issue 34): for each seed, simulate the world, move the run's odometry
# to start at (0, 0, 0) as ROS odometry does (the run's frame is then not the world's), survey it
# with two tags anchored to 1 cm (their world poses moved 7 mm and 6 mm, sigma 1 cm), and print
# each landmark's error against the world's tags (the anchored ones and the others).
#   scripts/anchor_seeds.sh [WORLD] [SEEDS...]   e.g. scripts/anchor_seeds.sh samples/museum/world.yaml 1 2 3 4 5
set -euo pipefail
# FLAGS: more survey flags, e.g. FLAGS="--decimate 1" (full resolution).
FLAGS=${FLAGS:-}
world=${1:-samples/office/world.yaml}
shift || true
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(1 2 3 4 5)
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# The first two tags of the world, anchored (the others are what is measured).
python3 - "$world" > "$tmp/anchors.yaml" <<'PY'
import sys, yaml
tags = yaml.safe_load(open(sys.argv[1]))["tags"]
print("anchors:")
for t, (dx, dy) in zip(tags[:2], [(0.007, 0.0), (0.0, -0.006)]):
    x, y, z = t["position_m"]
    print(f"  - {{id: {t['id']}, x_m: {x + dx}, y_m: {y + dy}, z_m: {z}, sigma_m: 0.01}}")
PY
printf 'seed\tanchor residuals (m)\tother landmarks: max error (m)\tmedian (m)\n'
for s in "${seeds[@]}"; do
  "$bin" -q simulate --world "$world" --seed "$s" --out "$tmp/run$s" >/dev/null
  python3 - "$tmp/run$s/odometry.csv" <<'PY'
import math, sys
p = sys.argv[1]
lines = open(p).read().splitlines()
rows = [l.split(",") for l in lines[1:] if l.strip()]
_, x0, y0, th0 = map(float, rows[0])
c, s = math.cos(th0), math.sin(th0)
out = [lines[0]]
for r in rows:
    t, x, y, th = map(float, r)
    dx, dy = x - x0, y - y0
    out.append(f"{r[0]},{c*dx + s*dy:.6f},{-s*dx + c*dy:.6f},{math.atan2(math.sin(th - th0), math.cos(th - th0)):.6f}")
open(p, "w").write("\n".join(out) + "\n")
PY
  "$bin" -q survey --run "$tmp/run$s" --out "$tmp/survey$s" --anchors "$tmp/anchors.yaml" --no-rerun $FLAGS >/dev/null
  python3 - "$world" "$tmp/survey$s" "$s" <<'PY'
import json, math, statistics, sys, yaml
tags = {t["id"]: t for t in yaml.safe_load(open(sys.argv[1]))["tags"]}
anchored = list(tags)[:2]
landmarks = json.load(open(sys.argv[2] + "/landmarks.json"))["landmarks"]
m = json.load(open(sys.argv[2] + "/report.json"))["metrics"]
err = {l["id"]: math.dist(l["position_m"][:2], tags[l["id"]]["position_m"][:2]) for l in landmarks}
others = [e for i, e in err.items() if i not in anchored]
res = " ".join("%.4f" % m.get(f"anchors.tag36h11_{i}.residual_m", float("nan")) for i in anchored)
print(f"{sys.argv[3]}\t{res}\t%.4f\t%.4f" % (max(others, default=float("nan")), statistics.median(others) if others else float("nan")))
PY
done
