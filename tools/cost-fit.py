#!/usr/bin/env python3
"""Refit the cost model of `cellflip report --plan` (docs/cluster.md, "The cost model").

Each method's wall time per step is `a x units + b x cells` nanoseconds, one pair (a, b) per
method and dimension (`MethodType::step_cost` in the method's folder). This script reads the
measured runs of one or more report.csv files (each made by `cellflip report --docs`, or by
`--merge` of a sweep's jobs), pairs every run with its job of `cellflip report --plan` for the
same matrix (the units of the liquid the plan counts, its cells and steps), and for each method and
dimension finds the (a, b) >= 0 that keeps every job of the default matrix within `--cap` (1.9x,
inside the 2x of tests/it/sweep.rs) either way and, within that, makes the largest ratio either
way of the other matrices' jobs (the paper's, whose target is 1.5x) as small as it can; the
default matrix's jobs alone are centred when no other matrix is given or none can be kept within
the cap.

    python3 tools/cost-fit.py default=docs/results/report.csv paper=docs/results-paper/report.csv

prints the fitted pairs (to paste into each method's `step_cost`) and a markdown table of every
job's estimate against its measurement (docs/cluster.md). The measured wall time of a run is its
stages' time per simulated second times the plan's duration, as tests/it/sweep.rs takes it (a
run stopped over its budget is extrapolated). Run it from the repository's root after `cargo
build --release`; `--bin PATH` names another binary (the one that ran the jobs). The constants
are one machine's: where a page holds runs of several kinds (report.csv's `machine`), `--speed
KIND=F` counts the runs of KIND at F times their measured time, F being how much faster that
kind ran the jobs that ran on both (docs/cluster.md, "The cost model").
"""

import argparse
import csv
import math
import re
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
        res = re.search(r"-r(\d+)-s", f[0])
        jobs.append(
            dict(
                id=f[0],
                res=res.group(1) if res else None,
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
    """Each measured row with its job: within a scene and method, a job that names its
    resolution (`-r150-` in its id) takes the row of that resolution, and the jobs at the
    scene's own size take the rows left, in order (the report writes them in the plan's order);
    jobs without a row (not run) are left out, a row without a job is refused."""
    by_key = defaultdict(list)
    for j in jobs:
        by_key[(j["scene"], j["method"])].append(j)
    rows_by_key = defaultdict(list)
    for r in rows:
        rows_by_key[(r["scene"], r["method"])].append(r)
    pairs = []
    for key, rs in rows_by_key.items():
        named = {j["res"]: j for j in by_key.get(key, []) if j["res"] is not None}
        own = [j for j in by_key.get(key, []) if j["res"] is None]
        for r in rs:
            j = named.pop(r["res"], None) or (own.pop(0) if own else None)
            if j is None:
                sys.exit(f"{path}: {key[0]} {key[1]} {r['res']}: a run with no job in the plan")
            measured = float(r["ms_per_sim_s"]) / 1e3 * j["sim_s"]
            pairs.append(
                dict(
                    j,
                    dim=int(r["dim"]),
                    measured=measured,
                    source=path,
                    res=r["res"],
                    run_steps=float(r["steps"]),
                    machine=r.get("machine", ""),
                    status=r["status"],
                )
            )
    return pairs


def fit(points, cap):
    """(a, b) >= 0 in ns for `points`: every ratio of estimate to measurement of the default
    matrix within `cap` either way where some (a, b) allows it, and within that the largest
    ratio either way of the other matrices' points as small as can be (all points alike when
    only the default matrix is given). A search over the direction of (a, b); for each, the
    best scale is the geometric middle of the other matrices' extreme ratios, clamped to the
    scales that keep the default's within `cap`. Gives a, b and the worst ratio per matrix."""

    def at(theta):
        ca, cb = math.cos(theta), math.sin(theta)
        logs = [math.log(p["steps"] * (ca * p["particles"] + cb * p["cells"]) / p["measured"]) for p in points]
        default = [x for x, p in zip(logs, points) if p["matrix"] == "default"]
        others = [x for x, p in zip(logs, points) if p["matrix"] != "default"] or default
        lo, hi = -math.log(cap) - min(default or [0.0]), math.log(cap) - max(default or [0.0])
        s = min(max(-(min(others) + max(others)) / 2, lo), hi) if lo <= hi else -(min(default) + max(default)) / 2
        worst = max(abs(x + s) for x in others)
        spread = max(abs(x + s) for x in default or [0.0])
        return (lo > hi, spread if lo > hi else worst), s, ca, cb

    lo, hi = 0.0, math.pi / 2
    best = 0.0
    for _ in range(6):
        grid = [lo + (hi - lo) * i / 400 for i in range(401)]
        best = min(grid, key=lambda t: at(t)[0])
        step = (hi - lo) / 400
        lo, hi = max(0.0, best - 2 * step), min(math.pi / 2, best + 2 * step)
    _, s, ca, cb = at(best)
    a, b = round(math.exp(s) * ca * 1e9), round(math.exp(s) * cb * 1e9)
    return a, b, worst_ratios(points, a, b)


def estimate(p, a, b):
    return p["steps"] * (a * p["particles"] + b * p["cells"]) * 1e-9


def worst_ratios(points, a, b):
    worst = defaultdict(lambda: 1.0)
    for p in points:
        r = estimate(p, a, b) / p["measured"]
        worst[p["matrix"]] = max(worst[p["matrix"]], r, 1 / r)
    return dict(worst)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csvs", nargs="+", metavar="MATRIX=REPORT.CSV")
    ap.add_argument("--bin", default="target/release/cellflip")
    ap.add_argument("--cap", type=float, default=1.9, help="the default matrix's bound either way (1.9)")
    ap.add_argument(
        "--speed",
        action="append",
        default=[],
        metavar="KIND=F",
        help="the runs of this kind of machine (report.csv's `machine` begins with KIND) took 1/F of "
        "the time they would have taken on the machine fitted: their measured times count F times "
        "(repeatable; the constants are one machine's, and a page may hold runs of several)",
    )
    a = ap.parse_args()
    points = []
    for arg in a.csvs:
        matrix, _, path = arg.partition("=")
        points += [dict(p, matrix=matrix) for p in pair(plan(a.bin, matrix), runs(path), path)]
    for arg in a.speed:
        kind, _, f = arg.partition("=")
        on = [p for p in points if p["machine"].startswith(kind)]
        if not on:
            sys.exit(f"--speed {arg}: no run on a machine {kind!r}")
        for p in on:
            p["measured"] *= float(f)
    groups = defaultdict(list)
    for p in points:
        groups[(p["method"], p["dim"])].append(p)
    fitted = {key: fit(ps, a.cap) for key, ps in sorted(groups.items())}
    for method in sorted({m for m, _ in fitted}):
        pairs = [fitted.get((method, d)) for d in (2, 3)]
        text = ", ".join(f"({f[0]}.0, {f[1]}.0)" if f else "none" for f in pairs)
        worst = "; ".join(
            f"{d}D " + ", ".join(f"{m} {w:.2f}x" for m, w in f[2].items()) for d, f in zip((2, 3), pairs) if f
        )
        print(f"{method}: StepCost::of(dim, [{text}])  worst ratio either way: {worst}")
    print()
    print("| matrix | scene | method | res | steps est. / run | wall s est. | wall s measured | est. / measured |")
    print("|---|---|---|---|---|---|---|---|")
    for p in points:
        fa, fb, _ = fitted[(p["method"], p["dim"])]
        est = estimate(p, fa, fb)
        stopped = " (stopped)" if p["status"].startswith("over budget") else ""
        print(
            f"| {p['matrix']} | {p['scene']} | {p['method']} | {p['res']} | {p['steps']:.0f} / {p['run_steps']:.0f}{stopped} | "
            f"{est:.2f} | {p['measured']:.2f} | {est / p['measured']:.2f} |"
        )


if __name__ == "__main__":
    main()
