#!/usr/bin/env python3
"""Writes ChArUco test views drawn by OpenCV, with the truth and OpenCV's own detections.

OpenCV draws the board (cv2.aruco.CharucoBoard.generateImage); each view is that drawing seen
by a 640x480 pinhole camera (fx = fy = 600, principal point at the centre) from a board pose:
the drawing is smoothed to the view's scale and warped (cv2.warpPerspective), then given 2
grey levels of noise. `views.json` holds, per view, the board pose, the true pixel of every
inner corner in the image (pixel centres at integer coordinates, OpenCV's and ours) and what
OpenCV's CharucoDetector finds (ids and corners), so a test can compare both with the truth.

Usage: pip install opencv-python-headless; python3 scripts/opencv_charuco.py OUT_DIR
(tests/fixtures/charuco holds its output).
"""
import json
import sys
from pathlib import Path

import cv2
import numpy as np

A = cv2.aruco
SQUARES = (8, 6)
SQUARE_M, MARKER_M = 0.03, 0.022
# The boards: an ArUco one, and one of OpenCV's AprilTag dictionary (whose tags OpenCV draws
# upside down against the AprilTag library's own).
BOARDS = {"board": "DICT_5X5_100", "board_apriltag": "DICT_APRILTAG_36h11"}
K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])
PX_PER_M = 8000.0  # the drawing: 0.1 mm a pixel
MARGIN_PX = 200

# Board poses: rotation vector (radians) and translation (metres) of the board in the camera,
# and the board.
POSES = {
    "tilted": ([0.35, -0.3, 0.1], [-0.12, -0.09, 0.45], "board"),
    "steep": ([-0.1, 0.85, 0.5], [-0.08, -0.1, 0.42], "board"),
    "partial": ([0.2, 0.2, -0.25], [-0.05, -0.02, 0.3], "board"),
    "upside_down": ([0.25, 0.1, 3.14159], [0.12, 0.1, 0.5], "board"),
    "apriltag": ([-0.3, 0.25, 0.4], [-0.11, -0.07, 0.42], "board_apriltag"),
}


def main(out):
    out.mkdir(parents=True, exist_ok=True)
    size = (int(SQUARES[0] * SQUARE_M * PX_PER_M) + 2 * MARGIN_PX,
            int(SQUARES[1] * SQUARE_M * PX_PER_M) + 2 * MARGIN_PX)
    boards, drawings = {}, {}
    for name, dictionary in BOARDS.items():
        boards[name] = A.CharucoBoard(SQUARES, SQUARE_M, MARKER_M,
                                      A.getPredefinedDictionary(getattr(A, dictionary)))
        drawings[name] = boards[name].generateImage(size, marginSize=MARGIN_PX, borderBits=1)
        (out / f"{name}.yaml").write_text(
            f"# The board of these views: OpenCV's CharucoBoard((8, 6), 0.03, 0.022, {dictionary}).\n"
            f"target_type: charuco\ndictionary: {dictionary}\nsquaresX: {SQUARES[0]}\n"
            f"squaresY: {SQUARES[1]}\nsquareLength: {SQUARE_M}\nmarkerLength: {MARKER_M}\n")
    # Drawing pixel (centre convention) of a board point in metres.
    S = np.array([[PX_PER_M, 0, MARGIN_PX - 0.5], [0, PX_PER_M, MARGIN_PX - 0.5], [0, 0, 1]])
    rng = np.random.default_rng(7)
    views = {}
    for name, (rvec, t, board) in POSES.items():
        corners = boards[board].getChessboardCorners()
        detector = A.CharucoDetector(boards[board])
        drawing = drawings[board]
        R, _ = cv2.Rodrigues(np.array(rvec))
        H = K @ np.column_stack([R[:, 0], R[:, 1], np.array(t)])  # board metres -> image
        M = H @ np.linalg.inv(S)  # drawing -> image
        # Smooth the drawing to the view's scale before sampling it (no aliasing).
        scale = np.sqrt(abs(np.linalg.det(M[:2, :2] / M[2, 2])))
        sigma = max(0.4 / scale, 0.3)
        src = cv2.GaussianBlur(drawing, (0, 0), sigma)
        image = cv2.warpPerspective(src, M, (640, 480), flags=cv2.INTER_LINEAR,
                                    borderValue=128).astype(np.float64)
        image = np.clip(image * 0.8 + 25 + rng.normal(0, 2, image.shape), 0, 255).astype(np.uint8)
        cv2.imwrite(str(out / f"{name}.png"), image)
        truth = []
        for k, p in enumerate(corners):
            q = H @ np.array([p[0], p[1], 1.0])
            u, v = q[0] / q[2], q[1] / q[2]
            if 3 <= u <= 636 and 3 <= v <= 476:
                truth.append({"id": k, "px": [u, v]})
        found, ids, _, _ = detector.detectBoard(image)
        opencv = [] if ids is None else [
            {"id": int(i), "px": [float(c[0]), float(c[1])]}
            for i, c in zip(ids.ravel(), np.asarray(found).reshape(-1, 2))]
        views[name] = {"board": board, "rvec": rvec, "t": t, "truth": truth, "opencv": opencv}
        print(f"{name}: {len(truth)} corners in view, OpenCV finds {len(opencv)}", file=sys.stderr)
    meta = {"boards": BOARDS, "squaresX": SQUARES[0], "squaresY": SQUARES[1],
            "squareLength": SQUARE_M, "markerLength": MARKER_M, "K": K.tolist(),
            "opencv": cv2.__version__, "views": views}
    (out / "views.json").write_text(json.dumps(meta, indent=1))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
