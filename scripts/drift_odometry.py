#!/usr/bin/env python3
"""Copy a run directory with its odometry drifted as a wheel odometry drifts.

The Radish logs' odometry is the SLAM-corrected pose (their SOURCE.txt says so): it does not
drift, so localising such a run tests nothing of what the walls or tags correct. This rewrites
odometry.csv from the same increments with a distance scale, a turn scale, a heading bias per
metre and random noise, and leaves everything else (ground truth, ranges, pictures) as it was.

    scripts/drift_odometry.py RUN OUT [--scale 1.01] [--turn-scale 0.99] [--bias-deg-per-m 0.1] [--seed 1]

Then `stereotag localize --survey SURVEY --run OUT ...`: `ate_m.odometry` is the drifted
odometry's error, `ate_m.localized` what the survey's walls and tags make of it.
"""
import argparse
import math
import pathlib
import random
import shutil
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=pathlib.Path)
    ap.add_argument("out", type=pathlib.Path)
    ap.add_argument("--scale", type=float, default=1.01, help="distance scale (1.01: 1%% long)")
    ap.add_argument("--turn-scale", type=float, default=0.99, help="turn scale (a wheel-base error)")
    ap.add_argument("--bias-deg-per-m", type=float, default=0.1,
                    help="heading drift per metre (unequal wheels)")
    ap.add_argument("--noise", type=float, default=0.003,
                    help="random heading noise, rad per sqrt(m); distance noise 1%% a step")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    src = a.run / "odometry.csv"
    if not src.is_file():
        sys.exit(f"{src}: no such file (is {a.run} a run directory?)")
    if a.out.exists():
        sys.exit(f"{a.out} exists: give a new directory")
    rows = []
    with open(src) as f:
        header = f.readline()
        if header.strip() != "t_s,x_m,y_m,theta_rad":
            sys.exit(f"{src}:1: expected the header t_s,x_m,y_m,theta_rad")
        for n, line in enumerate(f, start=2):
            try:
                row = [float(v) for v in line.split(",")]
            except ValueError:
                row = []
            if len(row) != 4:
                sys.exit(f"{src}:{n}: not four numbers: {line.strip()}")
            rows.append(row)
    if not rows:
        sys.exit(f"{src}: no odometry poses")
    rng = random.Random(a.seed)
    out = [rows[0][1:]]
    x, y, th = rows[0][1:]
    for (_, ax, ay, ath), (_, bx, by, bth) in zip(rows, rows[1:]):
        # The increment in the frame of the earlier pose, as the wheels measured it.
        c, s = math.cos(ath), math.sin(ath)
        lx, ly = c * (bx - ax) + s * (by - ay), -s * (bx - ax) + c * (by - ay)
        turn = math.remainder(bth - ath, math.tau)
        d = math.hypot(lx, ly)
        lx *= a.scale * (1.0 + 0.01 * rng.gauss(0.0, 1.0))
        ly *= a.scale
        turn = (turn * a.turn_scale + math.radians(a.bias_deg_per_m) * d
                + a.noise * math.sqrt(d) * rng.gauss(0.0, 1.0))
        c, s = math.cos(th), math.sin(th)
        x, y = x + c * lx - s * ly, y + s * lx + c * ly
        th = math.remainder(th + turn, math.tau)
        out.append([x, y, th])
    # Written beside OUT and renamed into place when whole: a failure leaves no half-written run.
    partial = a.out.with_name(a.out.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    try:
        shutil.copytree(a.run, partial)
        with open(partial / "odometry.csv", "w") as f:
            f.write(header)
            for (t, *_), (px, py, pth) in zip(rows, out):
                f.write(f"{t:.4f},{px:.5f},{py:.5f},{pth:.6f}\n")
        partial.rename(a.out)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    print(f"{a.out}: {len(rows)} odometry poses drifted (scale {a.scale}, turns {a.turn_scale}, "
          f"{a.bias_deg_per_m} deg/m)")


if __name__ == "__main__":
    main()
