#!/usr/bin/env python3
"""Refit the cost model of `cellflip report --plan` (docs/cluster.md, "The cost model").

Each method's wall time per step is `a x particles + b x cells` nanoseconds, one pair (a, b) per
method and dimension (`MethodType::step_cost` in the method's folder). This script reads the
measured runs of one or more report.csv files (each made by `cellflip report --docs`, or by
`--merge` of a sweep's jobs), pairs every run with its job of `cellflip report --plan` for the
same matrix (the plan's particles held, cells and steps), and for each method and dimension
finds the (a, b) >= 0 whose largest ratio of estimate to measurement, either way, is smallest.

    python3 tools/cost-fit.py default=docs/results/report.csv paper=docs/results-paper/report.csv

prints the fitted pairs (to paste into each method's `step_cost`) and a markdown table of every
job's estimate against its measurement (docs/cluster.md). The measured wall time of a run is its
stages' time per simulated second times the plan's duration, as tests/it/sweep.rs takes it (a
run stopped over its budget is extrapolated). Run it from the repository's root after `cargo
build --release`; `--bin PATH` names another binary (the one that ran the jobs).
"""

import argparse
import csv
import math
import subprocess
import sys
from collections import defaultdict


def plan(binary, matrix):
    """The plan's jobs of `matrix`: dicts with scene, method, cells, particles, sim_s, steps."""
    out = subprocess.run(
        [binary, "report", "--matrix", matrix, "--plan"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    jobs = []
    for line in out.splitlines():
        if line.startswith("#") or not line.strip():
            continue
        # id, scene (a label may hold spaces), method, then seven numbers
        f = line.split()
        n = f[-7:]
        jobs.append(
            dict(
                id=f[0],
                scene=" ".join(f[1:-8]),
                method=f[-8],
                cells=float(n[0]),
                particles=float(n[1]),
                sim_s=float(n[4]),
                steps=float(n[5]),
            )
        )
    return jobs


def runs(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def pair(jobs, rows, path):
    """Each measured row with its job: the rows of a scene and method follow their jobs' order
    (the report writes them in the plan's order); a scene and method with no rows (jobs not
    run) is left out, one with some rows missing is refused."""
    by_key = defaultdict(list)
    for j in jobs:
        by_key[(j["scene"], j["method"])].append(j)
    rows_by_key = defaultdict(list)
    for r in rows:
        rows_by_key[(r["scene"], r["method"])].append(r)
    pairs = []
    for key, rs in rows_by_key.items():
        js = by_key.get(key, [])
        if len(js) != len(rs):
            sys.exit(f"{path}: {key[0]} {key[1]}: {len(rs)} runs but {len(js)} jobs in the plan")
        for j, r in zip(js, rs):
            measured = float(r["ms_per_sim_s"]) / 1e3 * j["sim_s"]
            pairs.append(dict(j, dim=int(r["dim"]), measured=measured, source=path))
    return pairs


def fit(points):
    """(a, b) >= 0 in ns minimising max |log(estimate / measured)| over `points`, by a search
    over the direction of (a, b) (for each, the best scale is the geometric middle of the
    ratios' extremes), refined around the best direction."""

    def spread(theta):
        ca, cb = math.cos(theta), math.sin(theta)
        ratios = [p["steps"] * (ca * p["particles"] + cb * p["cells"]) / p["measured"] for p in points]
        lo, hi = min(ratios), max(ratios)
        return hi / lo, 1.0 / math.sqrt(lo * hi), ca, cb

    lo, hi = 0.0, math.pi / 2
    best = None
    for _ in range(6):
        grid = [lo + (hi - lo) * i / 400 for i in range(401)]
        scored = sorted((spread(t)[0], t) for t in grid)
        best = scored[0][1]
        step = (hi - lo) / 400
        lo, hi = max(0.0, best - 2 * step), min(math.pi / 2, best + 2 * step)
    worst, scale, ca, cb = spread(best)
    a, b = scale * ca * 1e9, scale * cb * 1e9
    return a, b, math.sqrt(worst)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csvs", nargs="+", metavar="MATRIX=REPORT.CSV")
    ap.add_argument("--bin", default="target/release/cellflip")
    a = ap.parse_args()
    points = []
    for arg in a.csvs:
        matrix, _, path = arg.partition("=")
        points += pair(plan(a.bin, matrix), runs(path), path)
    groups = defaultdict(list)
    for p in points:
        groups[(p["method"], p["dim"])].append(p)
    fitted = {}
    for (method, dim), ps in sorted(groups.items()):
        fitted[(method, dim)] = fit(ps)
    for method in sorted({m for m, _ in fitted}):
        pairs = [fitted.get((method, d)) for d in (2, 3)]
        text = ", ".join(f"({f[0]:.0f}.0, {f[1]:.0f}.0)" if f else "none" for f in pairs)
        worst = ", ".join(f"{f[2]:.2f}x" if f else "-" for f in pairs)
        print(f"{method}: StepCost::of(dim, [{text}])  worst ratio either way 2D, 3D: {worst}")
    print()
    print("| scene | method | cells | steps | wall s est. | wall s measured | est. / measured |")
    print("|---|---|---|---|---|---|---|")
    for p in points:
        fa, fb, _ = fitted[(p["method"], p["dim"])]
        est = p["steps"] * (fa * p["particles"] + fb * p["cells"]) * 1e-9
        print(
            f"| {p['scene']} | {p['method']} | {p['cells']:.0f} | {p['steps']:.0f} | {est:.2f} | "
            f"{p['measured']:.2f} | {est / p['measured']:.2f} |"
        )


if __name__ == "__main__":
    main()
