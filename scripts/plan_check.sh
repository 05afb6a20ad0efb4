#!/usr/bin/env bash
# How well `plan --tags` predicts the localisation error: survey one seed (the demo's steps), map its
# run with ground-truth poses, predict the error with the surveyed tags (with the walls and with
# the tags alone), localise the runs of other seeds against the survey, and compare the RMS of the
# prediction with the RMS error the robot had, over the map cells it drove through.
#   scripts/plan_check.sh [WORLD] [SURVEY_SEED] [RUN_SEEDS...]   e.g. scripts/plan_check.sh samples/office/world.yaml 1 2 3 4 5
set -euo pipefail
world=${1:-samples/office/world.yaml}
survey_seed=${2:-1}
shift 2 || shift $#
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(2)
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$bin" -q demo --world "$world" --seed "$survey_seed" --out "$tmp/survey" --no-rerun >/dev/null
"$bin" -q map --poses ground-truth --run "$tmp/survey/run" --out "$tmp/gt_map"
"$bin" -q plan --map "$tmp/gt_map" --tags "$tmp/survey/landmarks.json" --out "$tmp/plan_walls"
"$bin" -q plan --map "$tmp/gt_map" --tags "$tmp/survey/landmarks.json" --out "$tmp/plan_tags" --no-walls
printf 'survey\trun\twalls: predicted_m\tmeasured_m\ttags only: predicted_m\tmeasured_m\n'
for r in "${seeds[@]}"; do
  "$bin" -q demo --world "$world" --seed "$r" --out "$tmp/run$r" --no-rerun >/dev/null
  "$bin" -q localize --survey "$tmp/survey" --run "$tmp/run$r/run" --out "$tmp/loc_walls" --no-rerun --force >/dev/null
  "$bin" -q localize --survey "$tmp/survey" --run "$tmp/run$r/run" --out "$tmp/loc_tags" --no-rerun --no-walls --force >/dev/null
  python3 - "$tmp" "$survey_seed" "$r" <<'PY'
import csv, math, sys
tmp, s, r = sys.argv[1:4]
import re
text = open(f"{tmp}/gt_map/map.yaml").read()
res = float(re.search(r"^resolution:\s*(\S+)", text, re.M).group(1))
# origin: [x, y, yaw] or a block list
ox, oy = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", re.search(r"^origin:(.*?)(?=^\w)", text, re.M | re.S).group(1))[:2]]
cell = lambda x, y: (math.floor((x - ox) / res), math.floor((y - oy) / res))
row = [s, r]
for kind in ("walls", "tags"):
    pred = {cell(float(p["x_m"]), float(p["y_m"])): float(p["error_m"])
            for p in csv.DictReader(open(f"{tmp}/plan_{kind}/predicted_error.csv"))}
    p2 = m2 = n = 0
    for q in csv.DictReader(open(f"{tmp}/loc_{kind}/localization.csv")):
        gx, gy = float(q["gt_x_m"]), float(q["gt_y_m"])
        p = pred.get(cell(gx, gy))
        if p is not None:
            p2 += p * p
            m2 += (float(q["x_m"]) - gx) ** 2 + (float(q["y_m"]) - gy) ** 2
            n += 1
    row += ["%.3f" % math.sqrt(p2 / n), "%.3f" % math.sqrt(m2 / n)] if n else ["nan", "nan"]
print("\t".join(row))
PY
done
