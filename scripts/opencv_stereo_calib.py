#!/usr/bin/env python3
"""OpenCV's whole stereo calibration of chessboard pairs, timed: findChessboardCorners +
cornerSubPix on every image, calibrateCamera for each camera, stereoCalibrate with the
intrinsics fixed (as ../shared/data/mrpt_stereo_calib/reference_opencv.py). For measuring
stereotag against OpenCV only: `pip install opencv-python-headless numpy`.

  scripts/opencv_stereo_calib.py COLS ROWS 'LEFT_GLOB' 'RIGHT_GLOB'

Prints one JSON line: seconds (image reading excluded; read_seconds the reading), pairs used, per-camera and stereo RMS.
"""
import glob, json, sys, time
import cv2, numpy as np

cols, rows = int(sys.argv[1]), int(sys.argv[2])
lefts, rights = sorted(glob.glob(sys.argv[3])), sorted(glob.glob(sys.argv[4]))
read_start = time.perf_counter()
images = [(cv2.imread(l, cv2.IMREAD_GRAYSCALE), cv2.imread(r, cv2.IMREAD_GRAYSCALE)) for l, r in zip(lefts, rights)]
read_seconds = time.perf_counter() - read_start
crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 30, 0.01)
board = np.array([[x, y, 0] for y in range(rows) for x in range(cols)], np.float32)
start = time.perf_counter()
obj, L, R = [], [], []
for gl, gr in images:
    found = []
    for g in (gl, gr):
        ok, c = cv2.findChessboardCorners(g, (cols, rows), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            break
        found.append(cv2.cornerSubPix(g, c, (11, 11), (-1, -1), crit))
    if len(found) == 2:
        obj.append(board); L.append(found[0]); R.append(found[1])
size = images[0][0].shape[::-1]
rl, KL, DL, _, _ = cv2.calibrateCamera(obj, L, size, None, None, flags=cv2.CALIB_FIX_K3)
rr, KR, DR, _, _ = cv2.calibrateCamera(obj, R, size, None, None, flags=cv2.CALIB_FIX_K3)
rs, *rest = cv2.stereoCalibrate(obj, L, R, KL, DL, KR, DR, size, flags=cv2.CALIB_FIX_INTRINSIC)
seconds = time.perf_counter() - start
print(json.dumps({"seconds": seconds, "read_seconds": read_seconds, "pairs": len(images), "pairs_used": len(obj),
                  "rms_left_px": rl, "rms_right_px": rr, "stereo_rms_px": rs,
                  "baseline_squares": float(np.linalg.norm(rest[5]))}))
