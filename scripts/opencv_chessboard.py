#!/usr/bin/env python3
"""OpenCV's chessboard corners for the same images, for measuring stereotag against OpenCV.

Not a dependency of stereotag: `pip install opencv-python-headless numpy`.

  scripts/opencv_chessboard.py COLS ROWS IMAGE...            # JSON lines like the example
  scripts/opencv_chessboard.py --compare OURS.jsonl COLS ROWS IMAGE...
      # per image: corner differences (median, max) between stereotag and OpenCV, in pixels

OpenCV settings are those of ../shared/data/mrpt_stereo_calib/reference_opencv.py:
findChessboardCorners(ADAPTIVE_THRESH | NORMALIZE_IMAGE), cornerSubPix(11x11, 30 it, 0.01).
"""
import json, sys, time
import cv2, numpy as np

def opencv_corners(path, cols, rows):
    g = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    t = time.perf_counter()
    ok, c = cv2.findChessboardCorners(g, (cols, rows), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if ok:
        crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 30, 0.01)
        c = cv2.cornerSubPix(g, c, (11, 11), (-1, -1), crit)
    ms = (time.perf_counter() - t) * 1e3
    return (c.reshape(-1, 2) if ok else None), ms

def main():
    args = sys.argv[1:]
    ours = None
    if args and args[0] == '--compare':
        ours = {}
        for line in open(args[1]):
            d = json.loads(line)
            ours[d['image']] = d
        args = args[2:]
    cols, rows, images = int(args[0]), int(args[1]), args[2:]
    for path in images:
        c, ms = opencv_corners(path, cols, rows)
        if ours is None:
            print(json.dumps({'image': path, 'ms': ms, 'corners': None if c is None else c.tolist()}))
            continue
        o = ours.get(path, {})
        if c is None or 'corners' not in o:
            print(f"{path}: opencv {'found' if c is not None else 'missed'}, stereotag {'found' if 'corners' in o else 'missed'}")
            continue
        a = np.array(o['corners'])
        d = np.linalg.norm(a - c, axis=1)
        flipped = np.linalg.norm(a[::-1] - c, axis=1)
        order = 'same order'
        if np.median(flipped) < np.median(d):
            d, order = flipped, 'reversed order'
        print(f"{path}: {order}, difference median {np.median(d):.3f} px, max {d.max():.3f} px; "
              f"time stereotag {o['ms']:.1f} ms, opencv {ms:.1f} ms")

if __name__ == '__main__':
    main()
