#!/usr/bin/env bash
# Localisation from an unknown start (issue 34, item 4): survey seed 1 of a world (the demo's
# steps), then simulate later runs that start elsewhere (1-4 m away, turned up to 180 degrees) and
# localise each with `--start unknown`. Prints per start the ATE once located, the time it took to
# be located, and the position NEES (once located, and from the first instant).
#   scripts/unknown_start.sh [WORLD] [RUN_SEED]      e.g. scripts/unknown_start.sh samples/museum/world.yaml 2
# KEEP=DIR keeps the survey and the runs in DIR and takes them from there when it holds them (a
# second call only localises again: about 20 s instead of 2 minutes); FLAGS adds localize flags,
# e.g. FLAGS="--config loc.yaml" to compare fusion settings on the same runs.
set -euo pipefail
FLAGS=${FLAGS:-}
world=${1:-samples/office/world.yaml}
run_seed=${2:-2}
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || cargo build --release
if [ -n "${KEEP:-}" ]; then
  tmp=$KEEP/$(basename "$(dirname "$world")")_seed$run_seed
  mkdir -p "$tmp"
else
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
fi
[ -f "$tmp/survey/landmarks.json" ] ||
  "$bin" -q demo --world "$world" --seed 1 --out "$tmp/survey" --no-rerun --force >/dev/null
# Starts as "x y theta_rad", by world name: the survey's run starts at (2.5, 2.5, 0) in both.
case "$(basename "$(dirname "$world")")" in
  office) starts=("1.5 2.5 3.1416" "2.5 5.0 1.5708" "5.5 2.5 3.1416" "5.0 5.5 -1.5708" "1.0 6.0 -0.7854") ;;
  museum) starts=("3.5 2.5 3.1416" "2.5 5.0 1.5708" "5.5 2.0 3.1416" "6.0 5.5 -1.5708" "1.0 6.0 -0.7854") ;;
  *) echo "no starts listed for $world" >&2; exit 2 ;;
esac
printf 'start\tdistance_m\tlocated_after_s\tate_located_m\tnees_located\tnees_from_start\terr_over_sigma_max\n'
for st in "${starts[@]}"; do
  read -r x y th <<<"$st"
  run="$tmp/run_${x}_${y}_${th}"
  if [ ! -f "$run/run.yaml" ]; then
    sed "s|^start:.*|start: {x_m: $x, y_m: $y, theta_rad: $th}|" "$world" > "$run.world.yaml"
    "$bin" -q simulate --world "$run.world.yaml" --seed "$run_seed" --out "$run" --force >/dev/null
  fi
  # shellcheck disable=SC2086 # FLAGS is split into flags on purpose
  "$bin" -q localize --survey "$tmp/survey" --run "$run" --out "$tmp/loc" --start unknown \
    --no-rerun --force $FLAGS >/dev/null
  python3 - "$tmp/loc/report.json" "$x" "$y" "$th" <<'PY'
import json, math, sys
m = json.load(open(sys.argv[1]))["metrics"]
x, y, th = map(float, sys.argv[2:5])
d = math.hypot(x - 2.5, y - 2.5)
g = lambda k: m.get(k, float("nan"))
print("%s,%s,%s\t%.2f\t%.1f\t%.4f\t%.2f\t%.2f\t%.1f" % (sys.argv[2], sys.argv[3], sys.argv[4], d,
      g("located.from_t_s"), g("ate_m.located"), g("nees.position_mean"),
      g("nees.position_mean_from_start"), g("error_over_sigma.max")))
PY
done
