#!/usr/bin/env bash
# Speed of the whole chessboard stereo calibration (detection + solve), stereotag against OpenCV
# on the same images: 13 rendered 640x480 chessboard pairs of the default rig (as OpenCV's own
# sample, 13 pairs of a 9x6 board at 640x480, which ../shared/data does not hold), and the 4 real
# MRPT pairs (1024x768 photos of a 9x6 board). Prints both times (best of 3) and the ratio.
# Needs opencv-python-headless (pip), for the measurement only.
#
#   bash scripts/bench_chessboard_calib.sh
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/stereotag-target}"
cargo build --release -q
bin="$CARGO_TARGET_DIR/release/stereotag"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$bin" -q render --calibration-sequence 13 --target calibration/targets/checkerboard_9x6.yaml \
    --seed 7 --out "$work/seq"

# measure NAME LEFT_GLOB RIGHT_GLOB
measure() {
    local name=$1 left=$2 right=$3 best=999
    for i in 1 2 3; do
        s=$(date +%s.%N)
        "$bin" -q calibrate --target calibration/targets/checkerboard_9x6.yaml \
            --left "$left" --right "$right" --no-rerun --force --out "$work/cal-$name"
        e=$(date +%s.%N)
        best=$(python3 -c "print(min($best, $e - $s))")
    done
    python3 - "$work/cal-$name" "$best" "$name" "$left" "$right" <<'PY'
import json, subprocess, sys
out, ours, name, left, right = sys.argv[1], float(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5]
runs = [json.loads(subprocess.check_output(["python3", "scripts/opencv_stereo_calib.py", "9", "6",
        left, right])) for _ in range(3)]
cv = min(r["seconds"] for r in runs)
cv_read = min(r["seconds"] + r["read_seconds"] for r in runs)
rep = json.load(open(f"{out}/report.json"))["metrics"]
print(f"{name}:")
print(f"  stereotag: {ours:.3f} s (whole process: read, detect, solve, write), {rep['views_used']} pairs, RMS {rep['rms_px']:.3f} px")
print(f"  OpenCV:    {cv:.3f} s (detect + calibrateCamera x2 + stereoCalibrate, reading excluded), "
      f"{runs[0]['pairs_used']} pairs, stereo RMS {runs[0]['stereo_rms_px']:.3f} px")
print(f"  OpenCV with its image reading: {cv_read:.3f} s")
print(f"  ratio stereotag / OpenCV: {ours / cv:.2f} (with OpenCV's reading: {ours / cv_read:.2f})")
PY
}
measure "13 rendered 640x480 pairs" "$work/seq/left/*.png" "$work/seq/right/*.png"
measure "4 real MRPT 1024x768 pairs" "../shared/data/mrpt_stereo_calib/*_left.jpg" \
    "../shared/data/mrpt_stereo_calib/*_right.jpg"
