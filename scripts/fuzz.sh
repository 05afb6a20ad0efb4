#!/usr/bin/env bash
# Fuzzes every parser with cargo-fuzz (libFuzzer, AddressSanitizer, debug assertions on):
#
#   bash scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]     # default 600 s, all targets
#
# Needs the nightly toolchain and `cargo install cargo-fuzz`. Seeds each corpus from the repo's
# samples and ../shared/data (fuzz/corpus is not committed), runs each target for the given time
# (two at a time on two cores), and prints the executions and any crash per target. A crash
# leaves its input in fuzz/artifacts/TARGET/; reproduce it with
# `cargo +nightly fuzz run TARGET fuzz/artifacts/TARGET/crash-...`. With FUZZ_FAIL_ON_CRASH=1
# (CI) it exits 1 when a target left a crash input.
set -euo pipefail
cd "$(dirname "$0")/.."
secs="${1:-600}"
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(run_dataset world_yaml rig_yaml target_yaml corners_csv survey_files image_detect carmen_log ros2_bag)
fi
export CARGO_TARGET_DIR="${CARGO_FUZZ_TARGET_DIR:-$HOME/.cache/stereotag-fuzz-target}"
# The targets write each input to a scratch directory of their process (fuzz_targets/common.rs):
# all of them under one directory, taken away at the end (192 were left in /tmp by CI runs).
scratch="$(mktemp -d "${TMPDIR:-/tmp}/stereotag-fuzz.XXXXXX")"
trap 'rm -rf "$scratch"' EXIT
export TMPDIR="$scratch"
nul() { printf '\0'; }
seed() {
    local t="$1" d="fuzz/corpus/$1"
    mkdir -p "$d"
    case "$t" in
        run_dataset)
            { printf 'format: stereotag-run/1\nrobot:\n  sonar:\n    name: two\n    sensors:\n      - {x_m: 0.2, y_m: 0.0, bearing_rad: 0.0}\n      - {x_m: 0.0, y_m: 0.2, bearing_rad: 1.5708}\n'; nul
              printf 't_s,x_m,y_m,theta_rad\n0,2.5,2.5,0\n1,2.6,2.5,0.1\n'; nul
              printf 't_s,sensor,range_m\n0,0,1.0\n0,1,\n1,0,0.9\n'; nul
              printf 't_s,left,right\n0.5,stereo/l.png,stereo/r.png\n'; nul
              printf 't_s,x_m,y_m,theta_rad\n0,2.5,2.5,0\n'; } > "$d/seed1" ;;
        world_yaml)
            for w in samples/*/world.yaml; do cp "$w" "$d/$(basename "$(dirname "$w")")"; done
            { cat samples/willow/world.yaml; nul; cat samples/willow/*.yaml 2>/dev/null | head -20; } > "$d/willow_map" ;;
        rig_yaml) cp calibration/rigs/*.yaml "$d/" ;;
        carmen_log)
            for l in ../shared/data/radish/*.log.gz; do
                [ -f "$l" ] && zcat "$l" | sed -n 1,40p > "$d/$(basename "$l" .log.gz)"
            done
            printf 'ROBOTLASER1 0 -1.5 3.0 1.5 80 0.01 0 3 1 2 3 0 1.2 2.0 0.0 1.0 2.0 0.0 0 0 0 0 0 101.0 host 101.1\n' > "$d/robotlaser" ;;
        ros2_bag)
            # A two-pair bag of every message type, written by rosbags from a tiny run.
            local r
            r="$(mktemp -d)"
            mkdir -p "$r/run/stereo"
            cp calibration/rigs/default.yaml "$r/run/rig.yaml"
            printf 'robot:\n  rig: rig.yaml\n  sonar: {name: two, cone_rad: 0.5, max_range_m: 2.1, sensors: [{x_m: 0.2, y_m: 0.0, bearing_rad: 0.0}, {x_m: 0.0, y_m: 0.2, bearing_rad: 1.57}]}\n' > "$r/run/run.yaml"
            printf 't_s,x_m,y_m,theta_rad\n0,1,1,0\n1,1.2,1,0.1\n' > "$r/run/odometry.csv"
            cp "$r/run/odometry.csv" "$r/run/ground_truth.csv"
            printf 't_s,sensor,range_m\n0,0,1.5\n0,1,\n1,0,1.4\n1,1,\n' > "$r/run/sonar.csv"
            printf 't_s,left,right\n0,stereo/a.png,stereo/a.png\n1,stereo/a.png,stereo/a.png\n' > "$r/run/stereo.csv"
            python3 -c "from PIL import Image; Image.new('L', (8, 6), 128).save('$r/run/stereo/a.png')" 2>/dev/null &&
                python3 scripts/run_to_bag.py "$r/run" "$r/bag" --laser samples/office/world.yaml >/dev/null 2>&1 &&
                cp "$r/bag/bag.mcap" "$d/two_pairs.mcap" || echo "fuzz: no bag seed (python3 with rosbags and PIL writes it)" >&2
            rm -rf "$r"
            printf '\x00\x01\x00\x00\x07\x00\x00\x00\x00\x00\x00\x00\x05\x00\x00\x00odom\x00' > "$d/cdr_header" ;;
        target_yaml) cp calibration/targets/*.yaml "$d/" ;;
        corners_csv)
            local c=../shared/data/euroc_aprilgrid/calib/cam_april/cam0
            if [ -d "$c" ]; then
                ls "$c" | head -2 | { read -r a; read -r b; { cat "$c/$a"; nul; cat "$c/$b"; } > "$d/euroc"; }
            fi ;;
        survey_files)
            { printf '{"format":"stereotag-survey/1","landmarks":[]}'; nul
              printf 'kind,x_m,y_m,theta_rad,rho_m\n'; nul
              printf 'image: occ.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n'; nul
              printf 'P5\n2 2\n255\n\x00\xff\x80\x10'; nul
              printf 't_s,x_m,y_m,theta_rad\n0,1,1,0\n'; nul
              printf 'normal_rad,offset_m,from_x_m,from_y_m,to_x_m,to_y_m,readings,rms_m\n0,1,1,0,1,2,20,0.01\n'; } > "$d/seed1" ;;
        image_detect)
            python3 - "$d" <<'PY' || true
import sys, glob, os
out = sys.argv[1]
try:
    import cv2
except ImportError:
    sys.exit(0)
for i, p in enumerate(sorted(glob.glob('../shared/data/apriltag_test/*'))[:4] + sorted(glob.glob('../shared/data/aprilgrid_frames/*.png'))[:2] + sorted(glob.glob('../shared/data/mrpt_stereo_calib/*_left.jpg'))[:1]):
    g = cv2.imread(p, cv2.IMREAD_GRAYSCALE)
    if g is None:
        continue
    s = 256 / max(g.shape)
    g = cv2.resize(g, (int(g.shape[1] * s), int(g.shape[0] * s)))
    cv2.imwrite(os.path.join(out, f'seed{i}.png'), g)
PY
            ;;
    esac
}
run() {
    local t="$1" log="fuzz/logs/$1.log"
    rm -f "fuzz/logs/$t.done"
    seed "$t"
    cargo +nightly fuzz run -O -a "$t" "fuzz/corpus/$t" -- -max_total_time="$secs" -timeout=20 \
        -rss_limit_mb=4096 -print_final_stats=1 > "$log" 2>&1 || true
    local runs crash
    runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
    crash=$(ls "fuzz/artifacts/$t" 2>/dev/null | wc -l)
    echo "$t: $runs executions in $secs s, $crash crash inputs"
    # Marks a run that got to its end: one stopped by `set -e` in its subshell has none.
    [ "$runs" = "?" ] || touch "fuzz/logs/$t.done"
}
mkdir -p fuzz/logs
cargo +nightly fuzz build -O -a
for ((i = 0; i < ${#targets[@]}; i += 2)); do
    run "${targets[i]}" &
    if [ $((i + 1)) -lt ${#targets[@]} ]; then run "${targets[i + 1]}" & fi
    wait
done
if [ "${FUZZ_FAIL_ON_CRASH:-0}" = 1 ]; then
    for t in "${targets[@]}"; do
        if [ ! -e "fuzz/logs/$t.done" ]; then
            echo "fuzz: $t did not run to its end (see fuzz/logs/$t.log)" >&2
            exit 1
        fi
        if [ -n "$(ls "fuzz/artifacts/$t" 2>/dev/null)" ]; then
            echo "fuzz: $t left crash inputs in fuzz/artifacts/$t" >&2
            exit 1
        fi
    done
fi
