#!/usr/bin/env bash
# Speed of `stereotag import --bag` against the bag's own duration, and of `survey` per pair on
# an imported run against the simulated run it came from (issue 30's speed figures):
#
#   bash scripts/bench_import.sh [RATE_HZ]      # default 10 Hz, 640 x 480 mono8 pairs
#
# Simulates the office (709 pairs), writes it as a ROS 2 bag with rosbags re-timed so the pairs
# come at RATE_HZ (raw sensor_msgs/Image) and imports it three times; writes it again at its own
# times, imports it and surveys it and the simulated run five times each, interleaved; prints the best times
# and the ratios.
set -euo pipefail
cd "$(dirname "$0")/.."
rate="${1:-10}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/stereotag-target}" RERUN_ANALYTICS=off
cargo build --release --quiet
bin="$CARGO_TARGET_DIR/release/stereotag"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$bin" simulate --world samples/office/world.yaml --out "$work/run" -q
python3 scripts/run_to_bag.py "$work/run" "$work/bag" --image-rate "$rate"
best() { sort -g | head -1; }
secs() { local s e; s=$(date +%s.%N); "$@" >/dev/null 2>&1; e=$(date +%s.%N); echo "$e - $s" | bc -l; }
import_s=$(for i in 1 2 3; do secs "$bin" import --bag "$work/bag" --out "$work/imported" --ground-truth /ground_truth --force -q; done | best)
pairs=$(($(wc -l < "$work/run/stereo.csv") - 1))
duration=$(python3 -c "import json; print(json.load(open('$work/imported/import.json'))['duration_s'])")
bytes=$(du -sb "$work/bag" | cut -f1)
# The survey of an imported run against the run it came from: the bag at the run's own times
# (the re-timed one would be another run, its robot 17 times faster).
python3 scripts/run_to_bag.py "$work/run" "$work/bag_same_times"
"$bin" import --bag "$work/bag_same_times" --out "$work/imported" --ground-truth /ground_truth --force -q
python3 - "$work" <<'PY'
import sys, yaml
w = sys.argv[1]
a = yaml.safe_load(open(f"{w}/run/run.yaml")); b = yaml.safe_load(open(f"{w}/imported/run.yaml"))
b["mapping"] = a["mapping"]; yaml.safe_dump(b, open(f"{w}/imported/run.yaml", "w"))
PY
# Both with the world (its tag sizes make detection faster; the imported run.yaml names none).
world=samples/office/world.yaml
# Interleaved, best of five each: the two share whatever else the machine is doing.
: > "$work/t_run"; : > "$work/t_imp"
for i in 1 2 3 4 5; do
    secs "$bin" survey --run "$work/run" --world "$world" --out "$work/s1" --force --no-rerun -q >> "$work/t_run"
    secs "$bin" survey --run "$work/imported" --world "$world" --out "$work/s2" --force --no-rerun -q >> "$work/t_imp"
done
survey_run=$(best < "$work/t_run")
survey_imp=$(best < "$work/t_imp")
python3 - "$pairs" "$duration" "$bytes" "$import_s" "$survey_run" "$survey_imp" "$rate" <<'PY'
import sys
pairs, duration, size, imp, srun, simp, rate = map(float, sys.argv[1:])
print(f"bag: {int(pairs)} pairs of 640 x 480 mono8 at {rate:g} Hz, {duration:.1f} s, {size / 1e6:.0f} MB")
print(f"import: {imp:.2f} s = {duration / imp:.1f} times faster than the bag's duration ({1e3 * imp / pairs:.2f} ms a pair)")
print(f"survey per pair: simulated run {1e3 * srun / pairs:.2f} ms, imported run {1e3 * simp / pairs:.2f} ms (ratio {simp / srun:.2f})")
PY
