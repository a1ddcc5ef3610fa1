#!/usr/bin/env python3
"""Volume over a run, cellflip beside MantaFlow on the same breaking dam (issue 72 item 2).

For each method, cellflip's flip / idp / nbflip against MantaFlow's FLIP (manta_dam.py --variant
min) / FLIP + IDP (--variant idp) / narrow-band FLIP (--variant nbflip), on the dam of cellflip's
scenes/dam-2d.toml or dam-3d.toml (its emitter left out: MantaFlow's dam has none), the same cells,
particles per cell and simulated duration. Both sides' volume is cellflip's eq. volume in % of V*
(cellflip's side by cellflip's own `cell_volume`; MantaFlow's from its particles, and for nbflip
its level set, by volume_measure.py); MantaFlow's nbflip also logs its level set's liquid cells
(phi < 0) in % of those at the start.

usage (cwd: the project root; cellflip from $CELLFLIP, default ./target/release/cellflip):
  MANTA_BIN=<built manta> python3 tools/mantaflow/volume.py --dim 3 --res 64 --duration 3
      [--methods flip,idp,nbflip] [--side both|cellflip|manta|none] [--band-r 6] [--seeds K]
      [--data tools/mantaflow/reference-volume] [--png docs/img/reference-volume-dam-3d-64.png]
      [--manta-args "--ghost-fluid 0"] [--cellflip-sim "pressure_tolerance = 3e-5"]
--seeds K runs an ensemble: seeds 1..K (cellflip --seed s; MantaFlow --seed s-1, 0 its own
sampling; --seed-from S runs S..K only, keeping the CSVs of the others), then the plot shades each
side's range over the seeds and the table compares their means and every pair of single runs.
--side cellflip reruns cellflip's side only and compares it with the MantaFlow CSVs kept in --data
(no MANTA_BIN needed); --side none only redraws the plot and the table from the CSVs.
Writes to --data, per method: cellflip-<method>-<case>.csv and manta-<method>-<case>.csv
(<case> as dam3d-64-3s, then -seed<s> for s > 1; columns time_s, volume_percent[,
phi_volume_percent], ...), the table table-<case>.md (and .json) and the runs' commands, scenes,
binaries and wall times in runs-<case>.json; the plot to --png
(default docs/img/reference-volume-dam-<dim>d-<res>.png). Prints the table last.
"""
import argparse
import csv
import datetime
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
_B = os.environ.get("CELLFLIP", os.path.join(ROOT, "target/release/cellflip"))
CELLFLIP = os.path.abspath(_B) if os.sep in _B else (shutil.which(_B) or _B)
MANTA = os.environ.get("MANTA_BIN", "")

VARIANT = {"flip": "min", "idp": "idp", "nbflip": "nbflip"}
MANTA_LABEL = {"flip": "MantaFlow FLIP", "idp": "MantaFlow FLIP + IDP", "nbflip": "MantaFlow narrow-band FLIP"}
TARGET = {"flip": 5.0, "idp": 5.0, "nbflip": 10.0}  # points (issue 72 item 2)


def case_name(a):
    return "dam%dd-%d-%gs" % (a.dim, a.res, a.duration)


def scene_file(a, work):
    """cellflip's dam scene of this dimension without its emitter (dam-2d pours water in from 2.5 s)."""
    src = os.path.join(ROOT, "scenes", "dam-%dd.toml" % a.dim)
    text = open(src).read()
    text = text.split("\n[[emitter]]")[0].rstrip() + "\n"
    text = re.sub(r'^# As in the author.*\n', "", text, flags=re.M)
    text = re.sub(r'^name = "([^"]+)"', r'name = "\1-no-emitter"', text, count=1, flags=re.M)
    text = re.sub(r'^description = .*$', 'description = "%s without its emitter (tools/mantaflow/volume.py)"' % os.path.basename(src), text, count=1, flags=re.M)
    for kv in (x.strip() for x in a.cellflip_sim.split(";")):
        if kv:  # an experiment: a [simulation] key set (or replaced)
            k = kv.split("=")[0].strip()
            text = re.sub(r"^%s\s*=.*\n" % re.escape(k), "", text, flags=re.M)
            text = text.replace("[simulation]\n", "[simulation]\n%s\n" % kv, 1)
    path = os.path.join(work, "dam-%dd-no-emitter.toml" % a.dim)
    with open(path, "w") as f:
        f.write(text)
    return path


def rrd_series(path):
    """(step, sim_time s, volume %, particles) per step from a cellflip recording's metrics."""
    import rerun as rr
    cols = {}
    for c in rr.experimental.RrdReader(path).stream().to_chunks():
        ent = c.entity_path
        if ent not in ("/metrics/volume_percent", "/metrics/particles"):
            continue
        rb = c.to_record_batch()
        names = rb.schema.names
        step = rb.column(names.index("step")).to_numpy()
        st = rb.column(names.index("sim_time")).cast("int64").to_numpy() * 1e-9
        val = [v[0] for v in rb.column(names.index("Scalars:scalars")).to_pylist()]
        d = cols.setdefault(ent, {})
        for s, t, v in zip(step, st, val):
            d[int(s)] = (float(t), float(v))
    vol = cols["/metrics/volume_percent"]
    parts = cols.get("/metrics/particles", {})
    return [(s, vol[s][0], vol[s][1], parts.get(s, (0, float("nan")))[1]) for s in sorted(vol)]


def sfx(seed):
    return "" if seed == 1 else "-seed%d" % seed


def snapshot_cellflip(work):
    """A copy of the cellflip binary for the whole batch (a build may replace it meanwhile), with
    what identifies it: its build time and hash, and the commit with the tree's changed sources."""
    import hashlib
    dst = os.path.join(work, "cellflip")
    shutil.copy2(CELLFLIP, dst)
    h = hashlib.sha256(open(dst, "rb").read()).hexdigest()[:12]
    dirty = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--", "src", "Cargo.toml", "Cargo.lock"],
                           capture_output=True, text=True).stdout.split("\n")
    info = {"binary_built": datetime.datetime.fromtimestamp(os.path.getmtime(CELLFLIP), datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC"),
            "binary_sha256": h, "commit": git_head(), "uncommitted_sources": [l[3:] for l in dirty if l.strip()]}
    return dst, info


def run_cellflip(a, method, work, data, runs, seed=1):
    scene = scene_file(a, work)
    rrd = os.path.join(work, "cellflip-%s.rrd" % method)
    cmd = [a.cellflip_bin, "run", scene, "--method", method, "--res", str(a.res), "--duration", "%g" % a.duration,
           "--seed", str(seed), "--save", rrd, "--record-every", "1000000", "-q"]
    if method == "nbflip":
        cmd += ["--band-r", str(a.band_r)]
    if a.dim == 3:
        cmd += ["--no-surface"]
    env = dict(os.environ, RAYON_NUM_THREADS=str(a.threads))
    t0 = time.time()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.time() - t0
    if p.returncode != 0:
        sys.exit("cellflip failed (%s):\n%s" % (" ".join(cmd), (p.stdout + p.stderr)[-3000:]))
    rows = rrd_series(rrd)
    out = os.path.join(data, "cellflip-%s-%s%s.csv" % (method, case_name(a), sfx(seed)))
    with open(out, "w") as f:
        f.write("time_s,volume_percent,step,particles\n")
        for s, t, v, n in rows:
            f.write("%.6f,%.6f,%d,%d\n" % (t, v, s, n))
    os.remove(rrd)
    runs["cellflip-" + method + sfx(seed)] = {"cmd": shown([CELLFLIP] + cmd[1:]).replace(work, "$TMP"),
                                  "scene": open(scene).read(), "wall_s": round(wall, 1), "steps": rows[-1][0],
                                  "threads": a.threads, "date": today(), "binary": a.cellflip_info}
    print("cellflip %-7s %5d steps  %7.1f s wall  -> %s" % (method, rows[-1][0], wall, os.path.relpath(out)), flush=True)


def run_manta(a, method, work, data, runs, seed=1):
    if not MANTA or not os.access(MANTA, os.X_OK):
        sys.exit("set MANTA_BIN to a built manta binary (tools/mantaflow/build.sh prints it)")
    out = os.path.join(data, "manta-%s-%s%s.csv" % (method, case_name(a), sfx(seed)))
    js = os.path.join(work, "manta-%s.json" % method)
    cmd = [MANTA, os.path.join(HERE, "manta_dam.py"), "--dim", str(a.dim), "--res", str(a.res), "--duration", "%g" % a.duration,
           "--variant", VARIANT[method], "--volume-csv", out, "--out", js]
    if seed > 1:
        cmd += ["--seed", str(seed - 1)]
    cmd += a.manta_args.split()
    if method == "nbflip":
        cmd += ["--band-r", str(a.band_r)]
    env = dict(os.environ, OMP_NUM_THREADS=str(a.threads))
    t0 = time.time()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=work)
    wall = time.time() - t0
    if p.returncode != 0 or "DONE" not in p.stdout + p.stderr:
        sys.exit("MantaFlow failed (%s):\n%s" % (" ".join(cmd), (p.stdout + p.stderr)[-3000:]))
    r = json.load(open(js))
    runs["manta-" + method + sfx(seed)] = {"cmd": "$MANTA_BIN " + shown(cmd[1:]).replace(work, "$TMP"),
                               "wall_s": round(wall, 1), "sim_wall_s": round(r["wall_s"], 1), "steps": len(r["steps"]),
                               "threads": a.threads, "np0": r["np0"], "date": today(), "manta_src": a.manta_commit}
    print("manta    %-7s %5d steps  %7.1f s wall  -> %s" % (method, len(r["steps"]), wall, os.path.relpath(out)), flush=True)


def shown(cmd):
    return " ".join(os.path.relpath(x, ROOT) if x.startswith(ROOT) else x for x in cmd)


def git_head():
    try:
        return subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def today():
    return datetime.date.today().isoformat()


def read_csv(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def compare(c, m, key, target):
    """Largest |cellflip - MantaFlow| over the union of both sides' times (each linearly
    interpolated), the time of it, and the first time and the share of the run over `target`."""
    tend = min(c["time_s"][-1], m["time_s"][-1])
    t = np.union1d(c["time_s"], m["time_s"])
    t = t[t <= tend + 1e-12]
    d = np.interp(t, c["time_s"], c["volume_percent"]) - np.interp(t, m["time_s"], m[key])
    i = int(np.argmax(np.abs(d)))
    over = np.abs(d) > target
    # share of the time over the target (trapezoid on the union of samples)
    dt = np.diff(t)
    share = float(np.sum(dt * over[1:]) / max(1e-12, t[-1] - t[0]))
    first = float(t[np.argmax(over)]) if over.any() else None
    return {"max_abs": float(abs(d[i])), "signed": float(d[i]), "at": float(t[i]), "first_over": first, "share_over": share}


def stats(v):
    return {"min": float(v.min()), "max": float(v.max()), "mean": float(v.mean()), "end": float(v[-1])}


def ensemble(runs, key, tend):
    """Each run's `key` on a common grid of times up to `tend`: (t, runs x times)."""
    t = np.linspace(0.0, tend, 801)
    return t, np.array([np.interp(t, r["time_s"], r[key]) for r in runs])


def table_and_plot(a, data, png):
    case = case_name(a)
    rows = []
    panels = []
    for method in a.methods:
        load = lambda side: [read_csv(p) for p in (os.path.join(data, "%s-%s-%s%s.csv" % (side, method, case, sfx(k)))
                                                   for k in range(1, a.seeds + 1)) if os.path.exists(p)]
        cs, ms = load("cellflip"), load("manta")
        if not (cs and ms):
            print("(%s: no CSV of %s in %s: skipped)" % (method, "cellflip" if not cs else "MantaFlow", data))
            continue
        c, m = cs[0], ms[0]
        cmp_ = compare(c, m, "volume_percent", TARGET[method])
        row = {"method": method, "cellflip": stats(c["volume_percent"]), "manta": stats(m["volume_percent"]), "diff": cmp_}
        if "phi_volume_percent" in m:
            row["manta_phi"] = stats(m["phi_volume_percent"])
            row["diff_phi"] = compare(c, m, "phi_volume_percent", TARGET[method])
        ens = None
        if len(cs) > 1 and len(ms) > 1:
            tend = min(min(r["time_s"][-1] for r in cs), min(r["time_s"][-1] for r in ms))
            t, C = ensemble(cs, "volume_percent", tend)
            _, M = ensemble(ms, "volume_percent", tend)
            d = C.mean(0) - M.mean(0)
            i = int(np.argmax(np.abs(d)))
            ens = {"t": t, "C": C, "M": M}
            row["ensemble"] = {"seeds": [len(cs), len(ms)], "mean_max_abs": float(abs(d[i])), "mean_signed": float(d[i]),
                               "at": float(t[i]), "spread_cellflip": float((C.max(0) - C.min(0)).max()),
                               "spread_manta": float((M.max(0) - M.min(0)).max()),
                               "ranges_apart": float(np.maximum(0, np.maximum(C.min(0) - M.max(0), M.min(0) - C.max(0))).max()),
                               "cellflip_mean": stats(C.mean(0)), "manta_mean": stats(M.mean(0))}
            pairs = [compare(x, y, "volume_percent", TARGET[method]) for x in cs for y in ms]
            worst = max(pairs, key=lambda q: q["max_abs"])
            row["ensemble"].update({"pairs": len(pairs), "pairs_over": sum(q["max_abs"] > TARGET[method] for q in pairs),
                                    "pairs_max_abs": worst["max_abs"], "pairs_max_at": worst["at"],
                                    "pairs_first_over": min([q["first_over"] for q in pairs if q["first_over"] is not None], default=None)})
        rows.append(row)
        panels.append((method, c, m, cmp_, ens))
    if not rows:
        return
    dimtxt = "%dD dam, %d%s cells, %g s" % (a.dim, a.res, "²" if a.dim == 2 else "³", a.duration)
    f = lambda s: "%.1f / %.1f / %.1f / %.1f" % (s["min"], s["max"], s["mean"], s["end"])
    ov = lambda d: "-" if d["first_over"] is None else "%.2f s (%.0f%%)" % (d["first_over"], 100 * d["share_over"])
    lines = ["| %s | volume %% min / max / mean / end: cellflip | MantaFlow | max \\|cellflip - MantaFlow\\| (signed, at t) | target | over the target from (share of the run) |" % dimtxt,
             "|---|---|---|---|---|---|"]
    for r in rows:
        d = r["diff"]
        lines.append("| %s | %s | %s | %.1f (%+.1f at %.2f s) | %g: %s | %s |" % (
            r["method"], f(r["cellflip"]), f(r["manta"]), d["max_abs"], d["signed"], d["at"], TARGET[r["method"]],
            "met" if d["max_abs"] <= TARGET[r["method"]] else "not met", ov(d)))
        if "manta_phi" in r:
            d = r["diff_phi"]
            lines.append("| nbflip against MantaFlow's phi < 0 cells | %s | %s | %.1f (%+.1f at %.2f s) | (%g) | %s |" % (
                f(r["cellflip"]), f(r["manta_phi"]), d["max_abs"], d["signed"], d["at"], TARGET["nbflip"], ov(d)))
    ens_rows = [r for r in rows if "ensemble" in r]
    if ens_rows:
        lines += ["", "| %s, ensembles | seeds (cellflip, MantaFlow) | mean volume %% min / max / mean / end: cellflip | MantaFlow | max \\|difference of the means\\| (signed, at t) | largest spread over seeds: cellflip | MantaFlow | largest gap between the two ranges | seed pairs over the target (largest difference, at t; first time over) |" % dimtxt,
                  "|---|---|---|---|---|---|---|---|---|"]
        for r in ens_rows:
            e = r["ensemble"]
            lines.append("| %s | %d, %d | %s | %s | %.1f (%+.1f at %.2f s) | %.1f | %.1f | %.1f | %d of %d (%.1f at %.2f s; %s) |" % (
                r["method"], e["seeds"][0], e["seeds"][1], f(e["cellflip_mean"]), f(e["manta_mean"]), e["mean_max_abs"],
                e["mean_signed"], e["at"], e["spread_cellflip"], e["spread_manta"], e["ranges_apart"],
                e["pairs_over"], e["pairs"], e["pairs_max_abs"], e["pairs_max_at"],
                "-" if e["pairs_first_over"] is None else "%.2f s" % e["pairs_first_over"]))
    text = "\n".join(lines) + "\n"
    with open(os.path.join(data, "table-%s.md" % case), "w") as fh:
        fh.write(text)
    with open(os.path.join(data, "table-%s.json" % case), "w") as fh:
        json.dump(rows, fh, indent=1)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axs = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.9), squeeze=False)
    for ax, (method, c, m, d, ens) in zip(axs[0], panels):
        vals = [c["volume_percent"], m["volume_percent"], m.get("phi_volume_percent", m["volume_percent"])]
        if ens:
            vals += [ens["C"].ravel(), ens["M"].ravel()]
        lo, hi = min(v.min() for v in vals), max(v.max() for v in vals)
        if ens:
            ax.fill_between(ens["t"], ens["C"].min(0), ens["C"].max(0), color="C0", alpha=0.18, lw=0,
                            label="cellflip, range over %d seeds" % len(ens["C"]))
            ax.fill_between(ens["t"], ens["M"].min(0), ens["M"].max(0), color="C3", alpha=0.18, lw=0,
                            label="MantaFlow, range over %d seeds" % len(ens["M"]))
        ax.plot(c["time_s"], c["volume_percent"], color="C0", lw=1.3, label="cellflip %s" % method)
        ax.plot(m["time_s"], m["volume_percent"], color="C3", lw=1.3, label=MANTA_LABEL[method])
        if "phi_volume_percent" in m:
            ax.plot(m["time_s"], m["phi_volume_percent"], color="C3", lw=0.9, ls="--", label="MantaFlow nbflip: phi < 0 cells")
        ax.axhline(100, color="0.6", lw=0.6)
        ax.set_title("%s: max |diff| %.1f at %.2f s (target %g)" % (method, d["max_abs"], d["at"], TARGET[method]), fontsize=9)
        ax.set_xlabel("simulated time (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best")
        ax.set_ylim(lo - 0.1 * (hi - lo) - 1, max(hi + 0.05 * (hi - lo) + 1, 102))
        ax.set_ylabel("volume, % of V* (eq. volume)")
    note = "; ".join(x for x in (("MantaFlow " + a.manta_args) if a.manta_args else "",
                                 ("cellflip " + a.cellflip_sim) if a.cellflip_sim else "") if x)
    fig.suptitle("Volume over time, cellflip and MantaFlow, %s%s" % (dimtxt, "\n(%s)" % note if note else ""), fontsize=10)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(png)), exist_ok=True)
    fig.savefig(png, dpi=110)
    print("plot -> %s" % os.path.relpath(png))
    print()
    print(text)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--dim", type=int, choices=[2, 3], required=True)
    ap.add_argument("--res", type=int, required=True)
    ap.add_argument("--duration", type=float, required=True, help="simulated seconds, both sides")
    ap.add_argument("--methods", default="flip,idp,nbflip")
    ap.add_argument("--side", default="both", choices=["both", "cellflip", "manta", "none"])
    ap.add_argument("--band-r", type=int, default=6, help="nbflip's R, both sides (cellflip's dam scenes set band_r = 6)")
    ap.add_argument("--seed-from", type=int, default=1, help="run seeds from this one (those before kept)")
    ap.add_argument("--cellflip-sim", default="", help="[simulation] keys for cellflip's scene, 'k = v; k2 = v2' (an experiment: use another --data)")
    ap.add_argument("--manta-args", default="", help="more arguments for manta_dam.py (an experiment: use another --data)")
    ap.add_argument("--seeds", type=int, default=1, help="run seeds 1..K (an ensemble); plot and table use those found")
    ap.add_argument("--threads", type=int, default=2, help="OMP_NUM_THREADS / RAYON_NUM_THREADS")
    ap.add_argument("--data", default=os.path.join(HERE, "reference-volume"))
    ap.add_argument("--png", default="")
    ap.add_argument("--manta-commit", default=os.environ.get("MANTA_COMMIT", "4944451"), help="recorded in runs-<case>.json")
    a = ap.parse_args()
    a.methods = [m for m in a.methods.split(",") if m]
    for m in a.methods:
        if m not in VARIANT:
            ap.error("unknown method %s (flip, idp, nbflip)" % m)
    if a.side in ("both", "cellflip") and not os.access(CELLFLIP, os.X_OK):
        ap.error("no cellflip binary at %s (set CELLFLIP or build the project)" % CELLFLIP)
    os.makedirs(a.data, exist_ok=True)
    png = a.png or os.path.join(ROOT, "docs", "img", "reference-volume-dam-%dd-%d.png" % (a.dim, a.res))
    runs_path = os.path.join(a.data, "runs-%s.json" % case_name(a))
    runs = json.load(open(runs_path)) if os.path.exists(runs_path) else {}
    work = tempfile.mkdtemp(prefix="volume-")
    try:
        if a.side in ("both", "cellflip"):
            a.cellflip_bin, a.cellflip_info = snapshot_cellflip(work)
        for seed in range(a.seed_from, a.seeds + 1):
            for method in a.methods:
                if a.side in ("both", "manta"):
                    run_manta(a, method, work, a.data, runs, seed)
                if a.side in ("both", "cellflip"):
                    run_cellflip(a, method, work, a.data, runs, seed)
                with open(runs_path, "w") as f:
                    json.dump(runs, f, indent=1)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    table_and_plot(a, a.data, png)


if __name__ == "__main__":
    main()
