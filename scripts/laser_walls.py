#!/usr/bin/env python3
"""Walls a laser confirms (issue 31, item 2): a sonar map's straight walls scored against the walls
of a lidar map of the same log (both `stereotag map --poses ground-truth`; the lidar map agrees
with the full laser at 0.95 occupied precision and recall, `tests/import_carmen.rs`).

Recall, over the stretches with enough readings: every reference wall, on each side, collects the
sonar echoes that face it as the wall step counts support (the wall's normal inside the cone, the
range within 4.5 cm of the sensor's distance to the line, the sensor on that side) at the log's
true poses; their feet along the wall are split where two lie further apart than the wall step's
gap, and a stretch with at least its readings (12 and 0.5 m, or for a run sampled sparser than a
reading every 15 cm the wall step's sparse rule: 12 x 0.15 / spacing readings, 5 at least, and
2.5 spacings) is one the sonar had enough readings for. Recall is the share of those stretches'
length (every 5 cm) within 10 cm of a sonar face of like direction (10 degrees).

Precision: the share of the sonar faces' length (every 5 cm) within 10 cm of a reference face of
like direction.

  scripts/laser_walls.py SONAR_RUN LIDAR_MAP_DIR SONAR_MAP_DIR
e.g. stereotag import --carmen ../shared/data/radish/aces-corrected.log.gz --out runs/aces_lidar
     stereotag import --carmen ../shared/data/radish/aces-corrected.log.gz --as-sonar frontal5 --out runs/aces
     stereotag map --run runs/aces_lidar --poses ground-truth --out maps/aces_lidar
     stereotag map --run runs/aces --poses ground-truth --out maps/aces
     scripts/laser_walls.py runs/aces maps/aces_lidar maps/aces
"""
import argparse
import csv
import json
import math

import numpy as np
import yaml

SUPPORT_M = 0.045
NEAR_M = 0.10
LIKE_DEG = 10.0
STEP_M = 0.05


def walls(path):
    return [
        (float(r["normal_rad"]), (float(r["from_x_m"]), float(r["from_y_m"])),
         (float(r["to_x_m"]), float(r["to_y_m"])))
        for r in csv.DictReader(open(path))
    ]


def seg_dist(p, a, b):
    dx, dy = b[0] - a[0], b[1] - a[1]
    l2 = dx * dx + dy * dy
    t = 0.0 if l2 == 0 else max(0.0, min(1.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2))
    return math.hypot(p[0] - a[0] - t * dx, p[1] - a[1] - t * dy)


def like(n1, n2):
    """Directions within LIKE_DEG of each other, either sense."""
    d = (n1 - n2 + math.pi / 2) % math.pi - math.pi / 2
    return abs(d) < math.radians(LIKE_DEG)


def near_a_face(p, normal, faces):
    return any(like(normal, n) and seg_dist(p, a, b) <= NEAR_M for n, a, b in faces)


def echoes(run):
    """Sensor x, y, beam direction and range of every echo, at the run's true poses."""
    meta = yaml.safe_load(open(f"{run}/run.yaml"))
    sonar = meta["robot"]["sonar"]
    truth = np.loadtxt(f"{run}/ground_truth.csv", delimiter=",", skiprows=1, ndmin=2)
    rows = np.genfromtxt(f"{run}/sonar.csv", delimiter=",", skip_header=1, filling_values=np.inf,
                         ndmin=2)
    rows = rows[rows[:, 2] < sonar["max_range_m"] - 1e-6]
    t = rows[:, 0]
    x = np.interp(t, truth[:, 0], truth[:, 1])
    y = np.interp(t, truth[:, 0], truth[:, 2])
    th = np.interp(t, truth[:, 0], np.unwrap(truth[:, 3]))
    k = rows[:, 1].astype(int)
    sx = np.array([s["x_m"] for s in sonar["sensors"]])[k]
    sy = np.array([s["y_m"] for s in sonar["sensors"]])[k]
    sb = np.array([s["bearing_rad"] for s in sonar["sensors"]])[k]
    px = x + np.cos(th) * sx - np.sin(th) * sy
    py = y + np.sin(th) * sx + np.cos(th) * sy
    return px, py, th + sb, rows[:, 2], sonar["cone_rad"] / 2


def wall_step_settings(sonar_map):
    """The readings and gap the wall step asks on this map's run (its sparse rule)."""
    spacing = json.load(open(f"{sonar_map}/report.json"))["metrics"].get("sampling.spacing_m") or 0
    if spacing > 0.15:
        return max(5, min(12, round(12 * 0.15 / spacing))), max(0.5, 2.5 * spacing)
    return 12, 0.5


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    ap.add_argument("lidar_map")
    ap.add_argument("sonar_map")
    args = ap.parse_args()
    reference = walls(f"{args.lidar_map}/walls.csv")
    faces = walls(f"{args.sonar_map}/walls.csv")
    px, py, beam, rng, half = echoes(args.run)
    min_readings, gap = wall_step_settings(args.sonar_map)
    enough = covered = 0.0
    stretches = 0
    for normal, a, b in reference:
        length = math.dist(a, b)
        t = math.atan2(b[1] - a[1], b[0] - a[0])
        ux, uy = math.cos(t), math.sin(t)
        for side in (1, -1):
            nx, ny = -uy * side, ux * side  # towards the sensors of this side
            off_axis = np.angle(np.exp(1j * (beam - math.atan2(-ny, -nx))))
            d = (px - a[0]) * nx + (py - a[1]) * ny
            facing = (np.abs(off_axis) <= half) & (d > 0) & (np.abs(d - rng) <= SUPPORT_M)
            along = (px[facing] - a[0]) * ux + (py[facing] - a[1]) * uy
            feet = np.sort(along[(along >= 0) & (along <= length)])
            if len(feet) < min_readings:
                continue
            cuts = np.nonzero(np.diff(feet) > gap)[0]
            for first, last in zip(np.r_[0, cuts + 1], np.r_[cuts, len(feet) - 1]):
                if last - first + 1 < min_readings:
                    continue
                lo, hi = feet[first], feet[last]
                n = max(1, int((hi - lo) / STEP_M))
                stretches += 1
                for j in range(n):
                    q = lo + (hi - lo) * (j + 0.5) / n
                    p = (a[0] + ux * q, a[1] + uy * q)
                    enough += (hi - lo) / n
                    covered += (hi - lo) / n * near_a_face(p, normal, faces)
    total = confirmed = 0.0
    for normal, a, b in faces:
        length = math.dist(a, b)
        n = max(1, int(length / STEP_M))
        for j in range(n):
            p = (a[0] + (b[0] - a[0]) * (j + 0.5) / n, a[1] + (b[1] - a[1]) * (j + 0.5) / n)
            total += length / n
            confirmed += length / n * near_a_face(p, normal, reference)
    print(json.dumps({
        "sonar_faces": len(faces),
        "sonar_faces_length_m": round(total, 1),
        "precision": round(confirmed / total, 3) if total else None,
        "stretches_with_enough_readings": stretches,
        "stretches_length_m": round(enough, 1),
        "recall": round(covered / enough, 3) if enough else None,
        "wall_step": {"min_readings": min_readings, "max_gap_m": round(gap, 2)},
    }, indent=1))


if __name__ == "__main__":
    main()
