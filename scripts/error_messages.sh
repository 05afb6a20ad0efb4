#!/usr/bin/env bash
# Every bad-input case of tests/bad_input.rs (and a few more), run through the binary: prints the
# command, its exit status and its whole stderr, so that two versions' messages can be diffed
# (`diff <(scripts/error_messages.sh) <(STEREOTAG=other scripts/error_messages.sh)`).
# STEREOTAG picks the binary (default: the release build). Files go to a fixed scratch directory
# (removed first), so the paths in the messages are the same from run to run.
set -uo pipefail
cd "$(dirname "$0")/.."
bin=${STEREOTAG:-${CARGO_TARGET_DIR:-target}/release/stereotag}
[ -x "$bin" ] || { echo "no binary at $bin: cargo build --release" >&2; exit 1; }
t=/tmp/stereotag-error-messages
rm -rf "$t"
mkdir -p "$t"

run() {
  echo "\$ stereotag $*"
  "$bin" "$@" >/dev/null 2>"$t/stderr"
  echo "exit $?"
  # Progress bars and the timing of a run are not messages.
  grep -v -e '\[=*>* *\]' "$t/stderr" | sed -e 's/in [0-9.]* s/in T s/'
}

good_run() {
  mkdir -p "$1"
  printf 'format: stereotag-run/1\nrobot:\n  sonar:\n    name: two\n    sensors:\n      - {x_m: 0.2, y_m: 0.0, bearing_rad: 0.0}\n      - {x_m: 0.0, y_m: 0.2, bearing_rad: 1.5708}\n' > "$1/run.yaml"
  printf 't_s,x_m,y_m,theta_rad\n0,2.5,2.5,0\n1,2.6,2.5,0\n' > "$1/odometry.csv"
  printf 't_s,sensor,range_m\n0,0,1.0\n0,1,\n1,0,0.9\n1,1,1.2\n' > "$1/sonar.csv"
}

# map_with FILE CONTENT: maps a good run with FILE replaced.
n=0
map_with() {
  n=$((n + 1))
  good_run "$t/run$n"
  printf "$2" > "$t/run$n/$1"
  run map --run "$t/run$n" --out "$t/map$n"
}

good_run "$t/good"
run -q map --run "$t/good" --out "$t/goodmap"
run map --run "$t/good" --out "$t/goodmap"
map_with odometry.csv 't_s,x_m,y_m,theta_rad\n0,2.5,2.5,0\n\n1,100002.6,2.5,0\n'
map_with odometry.csv 't_s,x_m,y_m,theta_rad\n0,-10,-10,0\n1,-9.9,-10,0\n'
map_with sonar.csv 't_s,sensor,range_m\n0,0,1.0\n0,1\n'
map_with odometry.csv 't_s,x_m,y_m,theta_rad\n0,2.5,abc,0\n'
map_with odometry.csv 't_s,x_m,y_m,theta_rad\n0,2.5,NaN,0\n'
map_with sonar.csv 't_s,sensor,range_m\n0,0,inf\n'
map_with sonar.csv 't_s,sensor,range_m\n0,0,-0.5\n'
map_with sonar.csv 't_s,sensor,range_m\n0,7,1.0\n'
map_with odometry.csv 't_s,x_m,y_m,theta_rad\n1,2.5,2.5,0\n0.5,2.5,2.5,0\n'
map_with sonar.csv 'time,sensor,range\n0,0,1.0\n'
map_with run.yaml 'format: stereotag-run/1\nrobot:\n  sonar:\n    name: two\n    max_range_m: far\n    sensors: []\n'
map_with run.yaml 'format: stereotag-run/1\ncolour: red\nrobot:\n  sonar: {name: a, sensors: []}\n'
map_with run.yaml 'format: stereotag-run/0\nrobot:\n  sonar: {name: a, sensors: [{x_m: 0, y_m: 0, bearing_rad: 0}]}\n'
run map --run "$t/good" --out "$t/gtmap" --poses ground-truth
printf 'resolution_m: -1\n' > "$t/mapping.yaml"
run map --run "$t/good" --out "$t/cfgmap" --config "$t/mapping.yaml"

printf 'start: {x_m: 1, y_m: 1}\nwalls:\n  - polyline_m: [[0, 0]]\n' > "$t/w.yaml"
run simulate --world "$t/w.yaml" --out "$t/simrun"
run simulate --world /nonexistent/world.yaml --out "$t/simrun"
printf 'start: {x_m: 0.05, y_m: 1}\nwalls:\n  - {polyline_m: [[0, 0], [4, 0], [4, 3], [0, 3]], closed: true}\n' > "$t/w2.yaml"
run simulate --world "$t/w2.yaml" --out "$t/simrun"
run simulate --world samples/office/world.yaml --layout ring --out "$t/simrun"

printf 'not a png' > "$t/bad.png"
run detect "$t/bad.png"
run detect /nonexistent/left.png
run detect --family tag99 "$t/bad.png"
photo=../shared/data/apriltag_test/34139872896_defdb2f8d9_c.jpg
run detect --decimate 0.5 "$photo"
run detect --backend kornia --decimate 1.5 "$photo"
run demo --decimate 0.5 --no-rerun --out "$t/demo"
run detect --rig calibration/rigs/default.yaml "$photo" "$photo"
run detect --rig calibration/rigs/default.yaml "$photo"
for bad in 1,2 1,2,x 1,2,inf; do
  run render --world samples/office/world.yaml --out "$t/pair" --pose "$bad"
done

# A run with one rendered pair.
good_run "$t/pairrun"
"$bin" -q render --world samples/office/world.yaml --pose 1.0,6.3,2.35 --out "$t/pair"
mkdir -p "$t/pairrun/stereo"
mv "$t/pair/left.png" "$t/pairrun/stereo/l.png"
mv "$t/pair/right.png" "$t/pairrun/stereo/r.png"
rm -rf "$t/pair"
printf 't_s,left,right\n0.5,stereo/l.png,stereo/r.png\n' > "$t/pairrun/stereo.csv"
cp calibration/rigs/default.yaml "$t/pairrun/rig.yaml"
sed -i 's/^robot:$/robot:\n  rig: rig.yaml/' "$t/pairrun/run.yaml"
run survey --run "$t/good" --out "$t/s1" --no-rerun
mkdir -p "$t/earlier"
run survey --run "$t/good" --out "$t/s2" --no-rerun --calibration-from "$t/earlier"
printf '{"landmarks": []}' > "$t/earlier/landmarks.json"
run survey --run "$t/good" --out "$t/s3" --no-rerun --calibration-from "$t/earlier"
run survey --run "$t/pairrun" --out "$t/s4" --no-rerun
run survey --run "$t/pairrun" --out "$t/s5" --no-rerun --backend kornia
run survey --run "$t/pairrun" --out "$t/s6" --no-rerun --backend kornia --decimate 1.5
run survey --run "$t/pairrun" --out "$t/s4" --no-rerun
run survey --run "$t/pairrun" --out "$t/s7" --no-rerun --save "$t/x.txt"
printf 'gate_chi2: 0\n' > "$t/fuse0.yaml"
run survey --run "$t/pairrun" --out "$t/s8" --no-rerun --config "$t/fuse0.yaml"
mv "$t/pairrun/stereo/r.png" "$t/r.png"
run survey --run "$t/pairrun" --out "$t/s9" --no-rerun
mv "$t/r.png" "$t/pairrun/stereo/r.png"
sed -i 's/\[640, 480\]/[752, 480]/' "$t/pairrun/rig.yaml"
run survey --run "$t/pairrun" --out "$t/s10" --no-rerun
sed -i 's/  rig: rig.yaml//' "$t/pairrun/run.yaml"
run survey --run "$t/pairrun" --out "$t/s11" --no-rerun

mkdir -p "$t/survey"
printf '{"landmarks": [{"id": 1, "family": "tag36h11"}]}' > "$t/survey/landmarks.json"
run localize --survey "$t/survey" --run "$t/good" --out "$t/loc"
printf '{"landmarks": [], "odometry_calibration": {"turn_scale_error": 3.0, "heading_drift_rad_per_m": 0.0, "distance_scale_error": 0.0}}' > "$t/survey/landmarks.json"
run localize --survey "$t/survey" --run "$t/good" --out "$t/loc"
printf '{"landmarks": []}' > "$t/survey/landmarks.json"
printf 'normal_rad,offset_m,from_x_m,from_y_m,to_x_m,to_y_m,readings,rms_m\n0,1,1,0,1,2,20,0.01\n0,1,1,0,1,two,20,0.01\n' > "$t/survey/walls_corrected.csv"
run localize --survey "$t/survey" --run "$t/good" --out "$t/loc"
rm "$t/survey/walls_corrected.csv"
printf 'sonar_sigma_m: -0.01\n' > "$t/fuse.yaml"
run localize --survey "$t/survey" --run "$t/good" --out "$t/loc" --config "$t/fuse.yaml"
run localize --survey "$t/survey" --run "$t/good" --out "$t/loc2"
run plan --map "$t/nomap" --out "$t/plan"
run plan --map "$t/goodmap" --out "$t/plan"
run plan --map "$t/goodmap" --tags "$t/survey/landmarks.json" --out "$t/plan2"

checker=calibration/targets/checkerboard_9x6.yaml
run calibrate --target $checker --left ../shared/data/mrpt_stereo_calib/0_left.jpg --right ../shared/data/aprilgrid_frames/EuRoC.png --no-rerun --out "$t/cal"
run calibrate --target $checker --left '../shared/data/mrpt_stereo_calib/*_left.jpg' --right ../shared/data/mrpt_stereo_calib/0_right.jpg --no-rerun --out "$t/cal"
run calibrate --target $checker --left "$t/none/*.png" --right "$t/none/*.png" --no-rerun --out "$t/cal"
run calibrate --target $checker --left '../shared/data/mrpt_stereo_calib/0_*.jpg' --right '../shared/data/mrpt_stereo_calib/1_*.jpg' --no-rerun --out "$t/cal"
run calibrate --target $checker --out "$t/cal"
run calibrate --target calibration/targets/aprilgrid_6x6.yaml --corners-left ../shared/data/euroc_aprilgrid/calib/cam_april/cam0 --corners-right ../shared/data/euroc_aprilgrid/calib/cam_april/cam1 --out "$t/cal"
run calibrate --target calibration/targets/aprilgrid_6x6.yaml --corners-left ../shared/data/euroc_aprilgrid/calib/cam_april/cam0 --corners-right ../shared/data/euroc_aprilgrid/calib/cam_april/cam1 --resolution 752by480 --out "$t/cal"
printf 'target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\n' > "$t/t.yaml"
run calibrate --target "$t/t.yaml" --left '../shared/data/mrpt_stereo_calib/*_left.jpg' --right '../shared/data/mrpt_stereo_calib/*_right.jpg' --no-rerun --out "$t/cal"
printf 'target_type: aprilgrid\ntagCols: six\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n' > "$t/t.yaml"
run calibrate --target "$t/t.yaml" --left '../shared/data/mrpt_stereo_calib/*_left.jpg' --right '../shared/data/mrpt_stereo_calib/*_right.jpg' --no-rerun --out "$t/cal"
printf 'target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\ncolour: red\n' > "$t/t.yaml"
run calibrate --target "$t/t.yaml" --left '../shared/data/mrpt_stereo_calib/*_left.jpg' --right '../shared/data/mrpt_stereo_calib/*_right.jpg' --no-rerun --out "$t/cal"
printf '# a ring of circles\ntarget_type: circles\n' > "$t/t.yaml"
run calibrate --target "$t/t.yaml" --left '../shared/data/mrpt_stereo_calib/*_left.jpg' --right '../shared/data/mrpt_stereo_calib/*_right.jpg' --no-rerun --out "$t/cal"
run rig /nonexistent/rig.yaml --out "$t/rigout"
run config --default colours
run render --calibration-sequence 3 --target "$t/t.yaml" --out "$t/calseq"
printf 'target_type: charuco\ndictionary: DICT_4X4_50\nsquaresX: 20\nsquaresY: 20\nsquareLength: 0.03\nmarkerLength: 0.02\n' > "$t/t.yaml"
run calibrate --target "$t/t.yaml" --left '../shared/data/mrpt_stereo_calib/*_left.jpg' --right '../shared/data/mrpt_stereo_calib/*_right.jpg' --no-rerun --out "$t/cal"
printf 'target_type: boards\nboards:\n  - {target_type: charuco, dictionary: DICT_4X4_50, squaresX: 5, squaresY: 4, squareLength: 0.04, markerLength: 0.03}\n  - {target_type: charuco, dictionary: DICT_4X4_50, squaresX: 5, squaresY: 4, squareLength: 0.04, markerLength: 0.03}\n' > "$t/t.yaml"
run calibrate --target "$t/t.yaml" --left '../shared/data/mrpt_stereo_calib/*_left.jpg' --right '../shared/data/mrpt_stereo_calib/*_right.jpg' --no-rerun --out "$t/cal"
# import: logs that are not what they say.
printf '#ROSBAG V2.0\n' > "$t/old.bag"
run import --bag "$t/old.bag" --out "$t/imp"
mkdir -p "$t/emptybag"
run import --bag "$t/emptybag" --out "$t/imp"
printf '\x89MCAP0\r\n\x01' > "$t/cut.mcap"
run import --bag "$t/cut.mcap" --out "$t/imp"
run import --bag "$t/cut.mcap" --odometry "$t/odom.tum" --out "$t/imp"
run import --carmen ../shared/data/radish/aces-corrected.log.gz --out "$t/imp"
run import --asl "$t/emptybag" --out "$t/imp"
