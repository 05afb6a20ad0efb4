#!/usr/bin/env bash
# Speed of the whole chessboard stereo calibration (detection + solve), stereotag against OpenCV
# on the same images: 13 rendered 640x480 chessboard pairs of the default rig. Prints both times
# (best of 3) and the ratio. Needs opencv-python-headless (pip), for the measurement only.
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
best_ours=999
for i in 1 2 3; do
    s=$(date +%s.%N)
    "$bin" -q calibrate --target calibration/targets/checkerboard_9x6.yaml \
        --left "$work/seq/left/*.png" --right "$work/seq/right/*.png" \
        --no-rerun --out "$work/cal$i"
    e=$(date +%s.%N)
    best_ours=$(python3 -c "print(min($best_ours, $e - $s))")
done
python3 - "$work" "$best_ours" <<'PY'
import json, subprocess, sys
work, ours = sys.argv[1], float(sys.argv[2])
runs = [json.loads(subprocess.check_output(["python3", "scripts/opencv_stereo_calib.py", "9", "6",
        f"{work}/seq/left/*.png", f"{work}/seq/right/*.png"])) for _ in range(3)]
cv = min(r["seconds"] for r in runs)
rep = json.load(open(f"{work}/cal1/report.json"))["metrics"]
print(f"stereotag: {ours:.3f} s (whole process: read, detect, solve, write), {rep['views_used']} pairs, RMS {rep['rms_px']:.3f} px")
print(f"OpenCV:    {cv:.3f} s (detect + calibrateCamera x2 + stereoCalibrate, reading excluded), "
      f"{runs[0]['pairs_used']} pairs, stereo RMS {runs[0]['stereo_rms_px']:.3f} px")
print(f"ratio stereotag / OpenCV: {ours / cv:.2f}")
PY
