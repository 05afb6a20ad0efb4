#!/usr/bin/env python3
"""Corners a laser confirms (issue 31, item 2): reference corners derived from a CARMEN log's full
laser scans, independently of stereotag's own code, and the corners of a stereotag map scored
against them.

How the reference is made, scan by scan, at the log's (corrected) poses:
  1. the returns within 10 m, in beam order, are cut into runs where two neighbouring returns lie
     further apart than max(0.15 m, 3 x the beam spacing at their range);
  2. each run is split and merged into straight pieces (split where a return lies more than 8 cm off
     the chord: aces ranges come in 5 cm steps); a piece of at least 6 returns, 0.4 m long and 4 cm RMS
     off its least-squares line
     is a wall seen by that scan;
  3. two pieces that follow each other in the whole scan split the same way (a corner whose second
     wall is seen at a grazing angle breaks the runs) and meet at 50-130 degrees give a corner
     where their lines cross, when that lies within 0.25 m of both pieces' facing returns: a
     crossing;
  4. a piece that ends a run, where the next run (the next beam on) lies more than 0.3 m further
     away, ends there: a wall end (a door jamb, a pillar's edge); a piece that ends where something
     nearer hides it, or at the scan's edge, is not;
  5. every scan's corners are pooled in the world frame and grouped (within 0.15 m of a group's
     first); a group seen by at least 3 scans spanning at least 5 s (a person standing by is not a
     corner) is a reference corner, at its members' median.

A map corner is confirmed when a reference corner lies within --tolerance-m (0.15 m, as issue 31
measured). Precision = confirmed / map corners; recall = reference corners with a map corner within
the tolerance / reference corners in the part of the building the map knows. The baseline is the
same precision for every occupied cell of the map (what corners picked at random would score).

  scripts/laser_corners.py LOG.gz MAP_DIR [--corners corners.csv] [--png overlay.png]
e.g. stereotag import --carmen ../shared/data/radish/aces-corrected.log.gz --as-sonar frontal5 --out runs/aces
     stereotag map --run runs/aces --poses ground-truth --out maps/aces
     scripts/laser_corners.py ../shared/data/radish/aces-corrected.log.gz maps/aces --png aces.png
"""
import argparse
import gzip
import json
import math
import sys

import numpy as np

sys.path.insert(0, __import__("os").path.dirname(__file__))
from building_check import read_pgm  # noqa: E402 (the same directory's PGM reader)

MAX_RANGE_M = 10.0
SPLIT_M = 0.08
MIN_RETURNS = 6
MIN_LENGTH_M = 0.4
MAX_RMS_M = 0.04
CORNER_DEG = (50.0, 130.0)
CROSSING_REACH_M = 0.25
END_JUMP_M = 0.3
GROUP_M = 0.15
MIN_SCANS = 3
MIN_SPAN_S = 5.0


def read_scans(path):
    """(t, laser pose (x, y, theta), ranges, angles) of every FLASER line."""
    opener = gzip.open if path.endswith(".gz") else open
    offset = 0.0
    scans = []
    with opener(path, "rt", errors="replace") as f:
        for line in f:
            fields = line.split()
            if not fields:
                continue
            if fields[0] == "PARAM" and len(fields) > 2 and fields[1] == "robot_frontlaser_offset":
                offset = float(fields[2])
            if fields[0] != "FLASER":
                continue
            n = int(fields[1])
            ranges = np.array([float(v) for v in fields[2:2 + n]])
            x, y, th = (float(v) for v in fields[2 + n:5 + n])
            t = float(fields[-1])
            step = math.pi / (n - 1 if n % 2 == 1 else n)
            angles = -math.pi / 2 + step * np.arange(n)
            pose = (x + offset * math.cos(th), y + offset * math.sin(th), th)
            scans.append((t, pose, ranges, angles, step))
    return scans


def fit_line(p):
    """Centroid, unit direction and RMS distance of points p (k x 2) from their best line."""
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c, full_matrices=False)
    rms = s[1] / math.sqrt(len(p)) if len(s) > 1 else 0.0
    return c, vt[0], rms


def split(p, lo, hi, out):
    """Split-and-merge of p[lo:hi] (in order) into pieces whose returns lie within SPLIT_M of
    their chord: appends (lo, hi) index pairs."""
    a, b = p[lo], p[hi - 1]
    chord = b - a
    length = np.hypot(*chord)
    if hi - lo <= 2 or length < 1e-9:
        out.append((lo, hi))
        return
    normal = np.array([-chord[1], chord[0]]) / length
    d = np.abs((p[lo:hi] - a) @ normal)
    k = int(np.argmax(d))
    if d[k] > SPLIT_M and 0 < k < hi - lo - 1:
        split(p, lo, lo + k + 1, out)
        split(p, lo + k, hi, out)
    else:
        out.append((lo, hi))


def wall_pieces(pts, lo, hi):
    """The straight pieces of pts[lo:hi] (split and merged), each a wall (centroid, direction,
    first and past-the-last index) or None."""
    pieces = []
    split(pts, lo, hi, pieces)
    walls = []
    for a, b in pieces:
        q = pts[a:b]
        if b - a < MIN_RETURNS or np.hypot(*(q[-1] - q[0])) < MIN_LENGTH_M:
            walls.append(None)
            continue
        c, d, rms = fit_line(q)
        walls.append((c, d, a, b) if rms <= MAX_RMS_M else None)
    return walls


def scan_corners(ranges, angles, step):
    """Corners of one scan in the laser frame: crossings and wall ends, as (x, y, kind)."""
    ok = (ranges > 0.05) & (ranges < MAX_RANGE_M)
    idx = np.flatnonzero(ok)
    if len(idx) < MIN_RETURNS:
        return []
    pts = np.stack([ranges[idx] * np.cos(angles[idx]), ranges[idx] * np.sin(angles[idx])], axis=1)
    # Runs of neighbouring returns.
    runs = []
    start = 0
    for i in range(1, len(idx) + 1):
        if i == len(idx):
            runs.append((start, i))
            break
        gap = np.hypot(*(pts[i] - pts[i - 1]))
        reach = max(0.15, 3 * ranges[idx[i]] * step * (idx[i] - idx[i - 1]))
        if gap > reach:
            runs.append((start, i))
            start = i
    corners = []
    walls = []  # every straight piece of the scan, in beam order (None: not a wall)
    ends = []  # (run index, which end, the wall at it)
    for r, (lo, hi) in enumerate(runs):
        first = len(walls)
        walls.extend(wall_pieces(pts, lo, hi))
        ends.append((r, 0, walls[first]))
        ends.append((r, 1, walls[-1]))
    # Crossings of pieces that follow each other in the whole scan's split (a corner whose
    # second wall is seen at a grazing angle breaks the runs): their lines cross near both.
    scan_walls = wall_pieces(pts, 0, len(pts))
    for w0, w1 in zip(scan_walls, scan_walls[1:]):
        if w0 is None or w1 is None:
            continue
        (c0, d0, _, b0), (c1, d1, a1, _) = w0, w1
        angle = math.degrees(math.acos(min(1.0, abs(float(d0 @ d1)))))
        if angle < 180.0 - CORNER_DEG[1]:
            continue  # the acute angle between the lines: 50-90 degrees
        s_ = np.linalg.solve(np.array([d0, -d1]).T, c1 - c0)
        x = c0 + s_[0] * d0
        if max(np.hypot(*(x - pts[b0 - 1])), np.hypot(*(x - pts[a1]))) <= CROSSING_REACH_M:
            corners.append((x[0], x[1], "crossing"))
    # Wall ends: a run's first or last piece, where the neighbouring run lies further away.
    for r, end, w in ends:
        if w is None:
            continue
        c, d, a, b = w
        lo, hi = runs[r]
        if end == 0:
            if r == 0 or a != lo:
                continue  # the scan's edge, or the run's first piece is no wall
            here, there = idx[lo], idx[runs[r - 1][1] - 1]
            point = pts[a]
        else:
            if r == len(runs) - 1 or b != hi:
                continue
            here, there = idx[hi - 1], idx[runs[r + 1][0]]
            point = pts[b - 1]
        if abs(here - there) > 2:
            continue  # beams without a return between: nothing known beyond
        if ranges[there] - ranges[here] < END_JUMP_M:
            continue  # hidden by something nearer, or no jump at all
        foot = c + ((point - c) @ d) * d
        corners.append((foot[0], foot[1], "end"))
    return corners


def reference_corners(scans):
    """Every scan's corners in the world frame, grouped; groups seen often enough, over time."""
    obs = []
    for t, (x, y, th), ranges, angles, step in scans:
        cth, sth = math.cos(th), math.sin(th)
        for cx, cy, kind in scan_corners(ranges, angles, step):
            obs.append((x + cth * cx - sth * cy, y + sth * cx + cth * cy, t, kind))
    groups = []  # [x0, y0, [members]]
    cells = {}
    for o in obs:
        key = (math.floor(o[0] / GROUP_M), math.floor(o[1] / GROUP_M))
        home = None
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for g in cells.get((key[0] + dx, key[1] + dy), []):
                    if math.hypot(o[0] - g[0], o[1] - g[1]) <= GROUP_M:
                        home = g
                        break
                if home:
                    break
            if home:
                break
        if home is None:
            home = [o[0], o[1], []]
            groups.append(home)
            cells.setdefault(key, []).append(home)
        home[2].append(o)
    out = []
    for _, _, members in groups:
        times = sorted(m[2] for m in members)
        if len(members) >= MIN_SCANS and times[-1] - times[0] >= MIN_SPAN_S:
            xs = np.median([m[0] for m in members])
            ys = np.median([m[1] for m in members])
            kinds = [m[3] for m in members]
            out.append((xs, ys, max(sorted(set(kinds)), key=kinds.count), len(members)))
    return out, obs


def read_map(map_dir):
    """The map's occupied and known cells (rows from the top), origin and resolution, by ROS
    map_server's trinary rule: occupancy (255 - grey) / 255 above occupied_thresh is occupied,
    below free_thresh free, between unknown."""
    import yaml
    meta = yaml.safe_load(open(f"{map_dir}/map.yaml"))
    res = float(meta["resolution"])
    origin = [float(v) for v in meta["origin"][:2]]
    img = read_pgm(f"{map_dir}/{meta['image']}")
    p = (255.0 - img) / 255.0
    occupied = p > float(meta["occupied_thresh"])
    known = occupied | (p < float(meta["free_thresh"]))
    return occupied, known, origin, res


def read_corners(path):
    out = []
    with open(path) as f:
        next(f)
        for line in f:
            v = line.strip().split(",")
            if len(v) >= 2:
                out.append((float(v[0]), float(v[1])))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log")
    ap.add_argument("map_dir")
    ap.add_argument("--corners", help="corners CSV (default MAP_DIR/corners.csv)")
    ap.add_argument("--tolerance-m", type=float, default=0.15)
    ap.add_argument("--png", help="overlay picture to write")
    ap.add_argument("--json", help="reference corners to write")
    a = ap.parse_args()
    scans = read_scans(a.log)
    ref, obs = reference_corners(scans)
    occupied, known, origin, res = read_map(a.map_dir)
    h, w = occupied.shape

    def cell(x, y):
        c, r = int((x - origin[0]) / res), int((y - origin[1]) / res)
        return (h - 1 - r, c) if 0 <= c < w and 0 <= r < h else None

    corners = read_corners(a.corners or f"{a.map_dir}/corners.csv")
    refxy = np.array([(r[0], r[1]) for r in ref]) if ref else np.zeros((0, 2))

    def near_ref(x, y):
        return len(refxy) > 0 and np.min(np.hypot(refxy[:, 0] - x, refxy[:, 1] - y)) <= a.tolerance_m

    confirmed = [near_ref(x, y) for x, y in corners]
    # Reference corners where the map knows the building (its cell or a neighbour known).
    def known_near(x, y):
        c = cell(x, y)
        if c is None:
            return False
        r0, c0 = c
        return bool(known[max(0, r0 - 1):r0 + 2, max(0, c0 - 1):c0 + 2].any())

    in_map = [r for r in ref if known_near(r[0], r[1])]
    cxy = np.array(corners) if corners else np.zeros((0, 2))
    found = [len(cxy) > 0 and np.min(np.hypot(cxy[:, 0] - r[0], cxy[:, 1] - r[1])) <= a.tolerance_m
             for r in in_map]
    rows, cols = np.nonzero(occupied)
    occ_xy = [(origin[0] + (c + 0.5) * res, origin[1] + (h - 1 - r + 0.5) * res) for r, c in zip(rows, cols)]
    baseline = np.mean([near_ref(x, y) for x, y in occ_xy]) if occ_xy else float("nan")
    result = {
        "scans": len(scans),
        "corner_observations": len(obs),
        "reference_corners": len(ref),
        "reference_crossings": sum(1 for r in ref if r[2] == "crossing"),
        "reference_ends": sum(1 for r in ref if r[2] == "end"),
        "reference_corners_in_map": len(in_map),
        "map_corners": len(corners),
        "confirmed": int(sum(confirmed)),
        "precision": (sum(confirmed) / len(corners)) if corners else float("nan"),
        "recall": (sum(found) / len(in_map)) if in_map else float("nan"),
        "occupied_cells_precision_baseline": float(baseline),
        "tolerance_m": a.tolerance_m,
    }
    print(json.dumps(result, indent=1))
    if a.json:
        json.dump([{"x_m": r[0], "y_m": r[1], "kind": r[2], "scans": r[3]} for r in ref],
                  open(a.json, "w"), indent=1)
    if a.png:
        import cv2
        scale = 4  # pixels per cell
        img = np.full((h * scale, w * scale, 3), 205, np.uint8)
        big = lambda m: np.kron(m, np.ones((scale, scale), bool))
        img[big(known & ~occupied)] = (255, 255, 255)
        img[big(occupied)] = (40, 40, 40)

        def px(x, y):
            return (int((x - origin[0]) / res * scale), int(h * scale - (y - origin[1]) / res * scale))

        for t, (x, y, th), ranges, angles, _ in scans[::5]:
            ok = ranges < MAX_RANGE_M
            xs = x + ranges[ok] * np.cos(th + angles[ok])
            ys = y + ranges[ok] * np.sin(th + angles[ok])
            for u, v in zip(xs[::2], ys[::2]):
                p = px(u, v)
                if 0 <= p[0] < w * scale and 0 <= p[1] < h * scale:
                    img[p[1], p[0]] = (200, 160, 120)
        for x, y, kind, _ in ref:
            cv2.circle(img, px(x, y), 5, (0, 170, 0) if kind == "crossing" else (0, 200, 200), 2)
        for (x, y), ok in zip(corners, confirmed):
            p = px(x, y)
            cv2.drawMarker(img, p, (200, 80, 0) if ok else (0, 0, 230), cv2.MARKER_TILTED_CROSS, 10, 2)
        legend = [("laser returns", (200, 160, 120)), ("reference crossing", (0, 170, 0)),
                  ("reference wall end", (0, 200, 200)), ("map corner, confirmed", (200, 80, 0)),
                  ("map corner, not confirmed", (0, 0, 230))]
        bar = np.full((24 + 18 * len(legend), img.shape[1], 3), 255, np.uint8)
        title = "%s: precision %.2f (%d of %d), recall %.2f, occupied-cell baseline %.2f" % (
            a.map_dir.rstrip("/").split("/")[-1], result["precision"], result["confirmed"],
            len(corners), result["recall"], baseline)
        cv2.putText(bar, title, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        for i, (name, colour) in enumerate(legend):
            y = 36 + 18 * i
            cv2.circle(bar, (14, y - 4), 5, colour, -1)
            cv2.putText(bar, name, (26, y), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.imwrite(a.png, np.vstack([bar, img]))
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except OSError as e:
        print(f"laser_corners.py: {e.filename}: {e.strerror}", file=sys.stderr)
        sys.exit(2)
    except (ValueError, KeyError, IndexError) as e:
        print(f"laser_corners.py: cannot read the log or the map: {e!r}", file=sys.stderr)
        sys.exit(2)
