#!/usr/bin/env bash
# A digest of everything the seeded workflows write, to check that a change of code keeps them
# byte-identical: simulate (office, museum, willow; seed 1, pictures included), survey, map,
# localize, plan, render, detect, calibrate (rendered AprilGrid, MRPT chessboard photos, EuRoC
# corners). Times are left out of report.json (they change from run to run); so are the Rerun
# recordings (they hold the time they were made).
#   scripts/output_digest.sh OUT_DIR > digest.txt      then diff two digests
# STEREOTAG picks the binary (default: the release build).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/output_digest.sh OUT_DIR}
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || { echo "no binary at $bin: cargo build --release" >&2; exit 1; }
rm -rf "$out"
mkdir -p "$out"
st() { "$bin" -q "$@"; }

for w in office museum willow; do
  st simulate --world samples/$w/world.yaml --seed 1 --out "$out/$w-run"
  st survey --run "$out/$w-run" --out "$out/$w-survey" --no-rerun
  st map --run "$out/$w-run" --out "$out/$w-map" --poses ground-truth
done
st simulate --world samples/office/world.yaml --seed 2 --out "$out/office-run2"
st localize --survey "$out/office-survey" --run "$out/office-run2" --out "$out/office-loc" --no-rerun
st plan --map "$out/museum-map" --out "$out/museum-plan"
st plan --map "$out/office-map" --tags "$out/office-survey/landmarks.json" --out "$out/office-pred"
st render --world samples/office/world.yaml --pose 1.0,6.3,2.35 --out "$out/pair"
st detect --rig calibration/rigs/default.yaml --tag-size-m 0.16 "$out/pair/left.png" "$out/pair/right.png" > "$out/detect_pair.json"
for b in apriltag-c kornia kornia-library; do
  st detect --backend $b --decimate 1 ../shared/data/apriltag_test/*.jpg > "$out/detect_$b.json"
done
st render --calibration-sequence 12 --target calibration/targets/aprilgrid_6x6.yaml --out "$out/calseq"
st calibrate --target calibration/targets/aprilgrid_6x6.yaml --left "$out/calseq/left/*.png" \
  --right "$out/calseq/right/*.png" --out "$out/calib-grid" --no-rerun
st calibrate --target calibration/targets/checkerboard_9x6.yaml \
  --left '../shared/data/mrpt_stereo_calib/*_left.jpg' --right '../shared/data/mrpt_stereo_calib/*_right.jpg' \
  --out "$out/calib-mrpt" --no-rerun
st calibrate --target calibration/targets/aprilgrid_6x6.yaml \
  --corners-left ../shared/data/euroc_aprilgrid/calib/cam_april/cam0 --corners-right ../shared/data/euroc_aprilgrid/calib/cam_april/cam1 \
  --fix-intrinsics calibration/rigs/euroc_official.yaml --out "$out/calib-euroc" --no-rerun
# Free intrinsics from these corners fail the calibration's checks (issue 32): written anyway, to
# keep their numbers in the digest.
st calibrate --target calibration/targets/aprilgrid_6x6.yaml \
  --corners-left ../shared/data/euroc_aprilgrid/calib/cam_april/cam0 --corners-right ../shared/data/euroc_aprilgrid/calib/cam_april/cam1 \
  --resolution 752x480 --out "$out/calib-euroc-free" --no-rerun --force-write

# report.json without its times (and the per-reading speeds derived from them).
find "$out" -name report.json | while read -r f; do
  jq -S 'del(.timings_s) | if .metrics then .metrics |= with_entries(select(.key | test("us_per_reading|timings") | not)) else . end' "$f" > "$f.tmp"
  mv "$f.tmp" "$f"
done
(cd "$out" && find . -type f ! -name '*.rrd' | sort | xargs sha256sum)
