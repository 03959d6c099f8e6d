#!/usr/bin/python3
"""Compares two study folders (the same grid run locally and through Slurm): the merged table
(study.csv, study.md) and every mission's metrics.json must be equal except the wall-clock fields.

Excluded, because they measure the machine and not the simulation: realtime_factor and wall_s in
metrics.json, the realtime_factor column of study.csv and the RTF column of study.md's run table (the
same simulated seconds take different wall-clock time with a different number of missions side by
side, or on a busy node). Everything else (targets, visits, localization errors, bytes on air, map
accuracy, ...) is a simulation result and must match to the last digit.

Usage: compare_study.py LOCAL_DIR SLURM_DIR   (exit 0 equal, 1 different, 2 bad usage or missing files)
"""
import csv
import json
import os
import sys

WALL_CLOCK_METRICS = {"realtime_factor", "wall_s"}
WALL_CLOCK_CSV_COLUMNS = {"realtime_factor"}


def fail_usage(msg):
    print(f"compare_study: {msg}", file=sys.stderr)
    sys.exit(2)


def read_csv(path):
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        fail_usage(f"{path}: {e.strerror}")
    return [{k: v for k, v in r.items() if k not in WALL_CLOCK_CSV_COLUMNS} for r in rows]


def read_md(path):
    """study.md with the RTF column (the last one) of the run table cut off."""
    try:
        with open(path) as f:
            lines = f.read().splitlines()
    except OSError as e:
        fail_usage(f"{path}: {e.strerror}")
    out, in_runs = [], False
    for line in lines:
        if line.startswith("| run |"):
            in_runs = True
        elif not line.startswith("|"):
            in_runs = False
        if in_runs:
            cells = line.split("|")
            line = "|".join(cells[:-2] + [""])  # "| a | ... | rtf |" -> drop the last cell
        out.append(line)
    return out


def read_metrics(folder):
    runs = {}
    runs_dir = os.path.join(folder, "runs")
    if not os.path.isdir(runs_dir):
        fail_usage(f"{runs_dir}: no such folder")
    for name in sorted(os.listdir(runs_dir)):
        path = os.path.join(runs_dir, name, "metrics.json")
        if not os.path.exists(path):
            continue
        with open(path) as f:
            try:
                m = json.load(f)
            except json.JSONDecodeError as e:
                print(f"compare_study: {path}: not JSON ({e})", file=sys.stderr)
                sys.exit(1)
        runs[name] = {k: v for k, v in m.items() if k not in WALL_CLOCK_METRICS}
    return runs


def main():
    if len(sys.argv) != 3:
        fail_usage("needs LOCAL_DIR SLURM_DIR")
    a, b = sys.argv[1], sys.argv[2]
    problems = []
    ma, mb = read_metrics(a), read_metrics(b)
    if sorted(ma) != sorted(mb):
        problems.append(f"missions differ: {sorted(ma)} against {sorted(mb)}")
    for name in sorted(set(ma) & set(mb)):
        for key in sorted(set(ma[name]) | set(mb[name])):
            if ma[name].get(key) != mb[name].get(key):
                problems.append(f"runs/{name}/metrics.json: {key}: {ma[name].get(key)!r} against {mb[name].get(key)!r}")
    ca, cb = read_csv(os.path.join(a, "study.csv")), read_csv(os.path.join(b, "study.csv"))
    if ca != cb:
        problems.append("study.csv differs (apart from realtime_factor)")
    da, db = read_md(os.path.join(a, "study.md")), read_md(os.path.join(b, "study.md"))
    if da != db:
        diff = [f"  {x!r}\n  {y!r}" for x, y in zip(da, db) if x != y][:5]
        problems.append("study.md differs (apart from the RTF column):\n" + "\n".join(diff))
    if problems:
        print(f"compare_study: {a} and {b} differ:", file=sys.stderr)
        for p in problems:
            print(f"  {p}", file=sys.stderr)
        sys.exit(1)
    print(f"compare_study: {len(ma)} missions, metrics.json, study.csv and study.md equal "
          f"(apart from {', '.join(sorted(WALL_CLOCK_METRICS))})")


if __name__ == "__main__":
    main()
