#!/usr/bin/env python3
"""Copy the part of a run directory between two times: every CSV's rows with t_s in [FROM, TO).

A real log is one run; cut in two, one half can be surveyed and the other localised against
that survey, so that the ranges localised are not the ones the survey's walls were fitted to
(scripts/localize_split.sh).

    scripts/split_run.py RUN OUT FROM_S TO_S
"""
import pathlib
import shutil
import sys


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__.strip().splitlines()[-1].strip())
    run, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    try:
        lo, hi = float(sys.argv[3]), float(sys.argv[4])
    except ValueError:
        sys.exit(f"FROM_S and TO_S must be times in seconds, not {sys.argv[3]!r} and {sys.argv[4]!r}")
    if not (run / "run.yaml").is_file():
        sys.exit(f"{run / 'run.yaml'}: no such file (is {run} a run directory?)")
    if out.exists():
        sys.exit(f"{out} exists: give a new directory")
    if (run / "stereo").exists():
        sys.exit(f"{run}: runs with pictures are not cut (only CSV data is)")
    # Everything is read and cut before anything is written: a bad row leaves no half-made copy.
    cut = {}
    for f in sorted(run.iterdir()):
        if f.suffix != ".csv":
            continue
        lines = f.read_text().splitlines()
        kept = []
        for n, line in enumerate(lines[1:], start=2):
            if not line:
                continue
            try:
                t = float(line.split(",", 1)[0])
            except ValueError:
                sys.exit(f"{f}:{n}: the first column is not a time in seconds: {line[:60]!r}")
            if lo <= t < hi:
                kept.append(line)
        cut[f.name] = "\n".join(lines[:1] + kept) + "\n"
    out.mkdir(parents=True)
    for f in sorted(run.iterdir()):
        if f.name in cut:
            (out / f.name).write_text(cut[f.name])
        elif f.is_file():
            shutil.copy(f, out / f.name)


if __name__ == "__main__":
    main()
