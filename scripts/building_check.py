#!/usr/bin/env python3
"""Places tags on the walls a real robot faced along its path, for issue 33's building check.

Reads a ROS map (map.yaml + map.pgm, as `stereotag map` writes them) and the path
(ground_truth.csv: t_s,x_m,y_m,theta_rad), casts a ray ahead of the robot every metre of the path,
and keeps the places where it meets a straight stretch of wall (0.8 m, free in front) 1.2-3 m ahead
within 25 degrees of the wall's normal; where that gives fewer places the renderer shows than
tags wanted, rays 20 degrees to either side of the heading are tried as well.
It keeps those the renderer shows from the pose that faced them (`stereotag render`: a traced
wall can stand in front of a tag placed on the map's cells), takes COUNT spread along the path (by
distance travelled, at least 4 m apart) and writes WORLD_OUT: the HEADER file (name, start, map,
simulation) and the tags (0.16 m tag36h11, 0.45 m up, 6 cm in front of the wall).

    building_check.py MAP_YAML GROUND_TRUTH_CSV HEADER STEREOTAG_BINARY WORLD_OUT [COUNT]
"""
import csv
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np
import yaml  # PyYAML, which evo (installed by .ci/run) brings


def read_pgm(path):
    with open(path, "rb") as f:
        data = f.read()
    fields, pos = [], 0
    while len(fields) < 4:
        while data[pos : pos + 1].isspace():
            pos += 1
        if data[pos : pos + 1] == b"#":
            pos = data.index(b"\n", pos)
            continue
        end = pos
        while not data[end : end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    assert fields[0] == b"P5", "a binary PGM"
    w, h = int(fields[1]), int(fields[2])
    return np.frombuffer(data[pos + 1 : pos + 1 + w * h], dtype=np.uint8).reshape(h, w)


def main():
    map_yaml, truth_csv, header, binary, world_out = sys.argv[1:6]
    count = int(sys.argv[6]) if len(sys.argv) > 6 else 7
    meta = yaml.safe_load(open(map_yaml))
    res = float(meta["resolution"])
    origin = [float(v) for v in meta["origin"][:2]]
    image = read_pgm(os.path.join(os.path.dirname(map_yaml), meta["image"]))
    h, w = image.shape
    occupied = image < 50  # map_server: black is occupied

    def cell(x, y):
        c, r = int((x - origin[0]) / res), h - 1 - int((y - origin[1]) / res)
        return (r, c) if 0 <= r < h and 0 <= c < w else None

    def wall_normal(x, y, toward):
        # The occupied cells within 0.4 m: their principal direction is the wall's.
        pts = []
        for dy in np.arange(-0.4, 0.41, res):
            for dx in np.arange(-0.4, 0.41, res):
                rc = cell(x + dx, y + dy)
                if rc and occupied[rc]:
                    pts.append((x + dx, y + dy))
        if len(pts) < 4:
            return None
        p = np.array(pts) - np.mean(pts, axis=0)
        vals, vecs = np.linalg.eigh(p.T @ p)
        if vals[0] > 0.2 * vals[1]:
            return None  # a corner or clutter, not a straight wall
        n = vecs[:, 0]
        return n if n @ toward > 0 else -n

    path = [(float(r["t_s"]), float(r["x_m"]), float(r["y_m"]), float(r["theta_rad"]))
            for r in csv.DictReader(open(truth_csv))]

    def faced(offsets_deg):
        """Places on straight walls met by rays from the path, at these angles off the heading,
        one a metre of travel at most."""
        candidates, travelled, last = [], 0.0, None
        for t, x, y, heading in path:
            if last is not None:
                travelled += math.hypot(x - last[0], y - last[1])
            last = (x, y)
            if candidates and travelled - candidates[-1][0] < 1.0:
                continue
            for off in offsets_deg:
                th = heading + math.radians(off)
                place = wall_ahead(x, y, th)
                if place is not None:
                    candidates.append((travelled, place, (x, y, heading)))
                    break
        return candidates

    def wall_ahead(x, y, th):
        d, free = 0.0, None
        while d < 3.0:
            px, py = x + d * math.cos(th), y + d * math.sin(th)
            rc = cell(px, py)
            if rc is None:
                break
            if occupied[rc]:
                break
            free = (px, py, d)
            d += 0.01
        if free is None or d >= 3.0 or free[2] < 1.2:
            return None
        n = wall_normal(free[0], free[1], np.array([x - free[0], y - free[1]]))
        if n is None:
            return None
        # A straight stretch of wall +-0.4 m along: occupied just behind the face, free in front.
        along = np.array([-n[1], n[0]])
        hit = np.array(free[:2])
        for k in np.arange(-0.4, 0.41, 0.1):
            behind, front = cell(*(hit + k * along - 0.15 * n)), cell(*(hit + k * along + 0.2 * n))
            if behind is None or front is None or not occupied[behind] or occupied[front]:
                return None
        incidence = math.degrees(math.acos(max(-1.0, min(1.0, -(n @ [math.cos(th), math.sin(th)])))))
        if incidence > 25.0:
            return None
        return (free[0] + 0.06 * n[0], free[1] + 0.06 * n[1], math.atan2(n[1], n[0]))

    # Straight ahead first; where that finds fewer places the renderer shows than tags wanted
    # (a building of long corridors), rays 20 degrees to either side as well.
    candidates = faced([0.0])
    seen = rendered(candidates, header, binary, world_out) if candidates else []
    if len(seen) < count:
        candidates = faced([0.0, -20.0, 20.0])
        seen = rendered(candidates, header, binary, world_out) if candidates else []
    if not candidates:
        sys.exit("no wall faced along the path")
    total = candidates[-1][0]
    chosen = []
    for k in range(count):
        want = total * (k + 0.5) / count
        for i in sorted(seen, key=lambda i: abs(candidates[i][0] - want)):
            tag = candidates[i][1]
            if all(math.hypot(tag[0] - o[0], tag[1] - o[1]) >= 4.0 for o in chosen):
                chosen.append(tag)
                break
    with open(world_out, "w") as f:
        f.write(open(header).read())
        f.write(tags_yaml(chosen))
    print(f"{len(candidates)} places faced along {total:.0f} m of path, {len(seen)} of them seen "
          f"whole by the renderer from where the robot faced them; {len(chosen)} taken",
          file=sys.stderr)


def tags_yaml(tags):
    return "tags:\n" + "".join(
        f"  - {{id: {i}, size_m: 0.16, position_m: [{x:.3f}, {y:.3f}, 0.45], yaw_rad: {yaw:.4f}}}\n"
        for i, (x, y, yaw) in enumerate(tags))


def rendered(candidates, header, binary, world_out):
    """The candidates the renderer shows whole from the pose that faced them (a traced wall
    can stand in front of a tag placed on the map's cells)."""
    base = os.path.dirname(os.path.abspath(world_out))
    trial = os.path.join(base, "candidates.yaml")
    with open(trial, "w") as f:
        f.write(open(header).read())
        f.write(tags_yaml([c[1] for c in candidates]))
    seen = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (_, _, (x, y, th)) in enumerate(candidates):
            subprocess.run([binary, "-q", "render", "--world", trial, "--pose", f"{x},{y},{th}",
                            "--out", tmp, "--force"], check=True)
            truth = json.load(open(os.path.join(tmp, "truth.json")))
            if any(t["id"] == i for t in truth["tags"]):
                seen.append(i)
    return seen


if __name__ == "__main__":
    main()
