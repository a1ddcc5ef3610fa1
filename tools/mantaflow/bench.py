#!/usr/bin/env python3
"""Side-by-side timing of MantaFlow and cellflip on the same breaking dams (50², 100², 64³).

Configurations per case (MantaFlow: $MANTA_BIN manta_dam.py; cellflip: `cellflip bench --warmup 1
--steps S-1`):
  manta-flip-min      MantaFlow FLIP, flip01's pipeline (cellflip's algorithm)
  manta-flip-surface  flip02/04 style: particle level set, ghost-fluid pressure, resampling, RK4
  manta-flip-idp      min + Kugelstadt's implicit density projection (IDP)
  cellflip-flip       cellflip flip (pressure tolerance 1e-9; flip has no band options)
  cellflip-flip-tol   cellflip flip at MantaFlow's effective tolerance (3e-5 in 2D, 6e-5 in 3D)
  cellflip-ccp        cellflip ccp, no band
  cellflip-ccp-band   cellflip ccp with the band (paths), 3D only
  *-1t                MantaFlow FLIP / cellflip flip on 1 thread (the others use 2)
Each round runs every configuration once, in an order rotated per round, each after waiting for the
machine to be mostly idle (< 25% busy, up to --max-wait s). A run's figure is its median ms/step over
steps 2..S (MantaFlow: own timer around the whole step; cellflip: bench's median step). MantaFlow
runs with the default OpenMP wait policy: it spins, so time on an idle machine only.

usage (cwd: the project root; cellflip from $CELLFLIP, default ./target/release/cellflip):
  MANTA_BIN=<built manta> python3 tools/mantaflow/bench.py \\
      [--rounds 5] [--only 2d50,2d100,3d64] [--configs NAME,...] [--max-wait 1800]
Appends every run to $OUT/bench.jsonl ($OUT default: a new temp dir); prints a line per run, then the
table of medians over rounds (ms/step, min..max, PCG iterations), the ratios, and last:
  bench: cellflip/MantaFlow median ms/step: flip/FLIP <case> r ..., ccp/IDP <case> r ...
"""
import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
_B = os.environ.get("CELLFLIP", "./target/release/cellflip")
CELLFLIP = os.path.abspath(_B) if os.sep in _B else (shutil.which(_B) or _B)
MANTA = os.environ.get("MANTA_BIN", "")

# dam-2d / dam-3d (the built-in scenes) as flip without the emitter, at MantaFlow's effective
# pressure tolerance (its cgAccuracy 1e-3 absolute is about 3e-5 / 6e-5 of the rhs here)
TOL_SCENES = {
    "dam2d_tol.toml": '''name = "dam2d-tol3e-5"
description = "dam-2d without the emitter (for the MantaFlow comparison)"
dim = 2

[domain]
size = [1.0, 1.0]
cells = 50

[simulation]
method = "flip"
duration = 8.0
ppc = 4
max_dt = 0.01
max_speed = 6.0
pressure_tolerance = 3e-5

[[fluid]]
shape = "box"
min = [0.0, 0.0]
max = [0.3, 0.6]
''',
    "dam3d_tol.toml": '''name = "dam3d-tol6e-5"
description = "dam-3d, flip, no band, pressure_tolerance 6e-5 (for the MantaFlow comparison)"
dim = 3

[domain]
size = [1.0, 1.0, 1.0]
cells = 50

[simulation]
method = "flip"
duration = 3.0
ppc = 8
max_dt = 0.01
max_speed = 6.0
pressure_tolerance = 6e-5

[[fluid]]
shape = "box"
min = [0.0, 0.0, 0.35]
max = [0.3, 0.6, 0.65]
''',
}
CASES = {
    "2d50": dict(dim=2, res=50, steps=200, scene="dam-2d", tol="dam2d_tol.toml", band=[]),
    "2d100": dict(dim=2, res=100, steps=200, scene="dam-2d", tol="dam2d_tol.toml", band=[]),
    "3d64": dict(dim=3, res=64, steps=30, scene="dam-3d", tol="dam3d_tol.toml", band=["--band", "none"]),
}
NAMES = ["manta-flip-min", "manta-flip-surface", "manta-flip-idp", "cellflip-flip", "cellflip-flip-tol", "cellflip-ccp",
         "cellflip-ccp-band", "manta-flip-min-1t", "cellflip-flip-1t"]


def configs(case, work):
    c = CASES[case]
    tol = os.path.join(work, c["tol"])
    mbase = [MANTA, os.path.join(HERE, "manta_dam.py"), "--dim", str(c["dim"]), "--res", str(c["res"]), "--steps", str(c["steps"])]
    cbase = [CELLFLIP, "bench", "--res", str(c["res"]), "--steps", str(c["steps"] - 1), "--warmup", "1"]
    out = [
        ("manta-flip-min", "manta", mbase + ["--variant", "min"], {"OMP_NUM_THREADS": "2"}),
        ("cellflip-flip", "cellflip", cbase + ["--scene", c["scene"], "--method", "flip"], {"RAYON_NUM_THREADS": "2"}),
        ("manta-flip-surface", "manta", mbase + ["--variant", "surface", "--integ", "rk4"], {"OMP_NUM_THREADS": "2"}),
        ("manta-flip-idp", "manta", mbase + ["--variant", "idp"], {"OMP_NUM_THREADS": "2"}),
        ("cellflip-flip-tol", "cellflip", cbase + ["--scene", tol], {"RAYON_NUM_THREADS": "2"}),
        ("cellflip-ccp", "cellflip", cbase + ["--scene", c["scene"], "--method", "ccp"] + c["band"], {"RAYON_NUM_THREADS": "2"}),
        ("manta-flip-min-1t", "manta", mbase + ["--variant", "min"], {"OMP_NUM_THREADS": "1"}),
        ("cellflip-flip-1t", "cellflip", cbase + ["--scene", c["scene"], "--method", "flip"], {"RAYON_NUM_THREADS": "1"}),
    ]
    if c["dim"] == 3:
        out.append(("cellflip-ccp-band", "cellflip", cbase + ["--scene", c["scene"], "--method", "ccp", "--band", "paths"], {"RAYON_NUM_THREADS": "2"}))
    return out


def busy_fraction(secs=1.0):
    def snap():
        v = [int(x) for x in open("/proc/stat").readline().split()[1:]]
        return sum(v), v[3] + v[4]
    t0, i0 = snap()
    time.sleep(secs)
    t1, i1 = snap()
    return 1.0 - (i1 - i0) / max(1, t1 - t0)


def wait_quiet(max_wait, limit=0.25):
    """Wait until the machine is mostly idle before a timed run."""
    waited = 0
    b = busy_fraction()
    while b > limit and waited < max_wait:
        time.sleep(15)
        waited += 16
        b = busy_fraction()
    return b, waited


def run_one(case, name, kind, cmd, env_add, work, max_wait):
    busy, waited = wait_quiet(max_wait)
    env = dict(os.environ)
    env.update(env_add)
    load0 = open("/proc/loadavg").read().split()[0]
    js = None
    if kind == "manta":
        js = os.path.join(work, f"tmp_{case}_{name}.json")
        cmd = cmd + ["--out", js]
    t0 = time.time()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=work)
    rec = {"busy_before": busy, "waited_s": waited, "case": case, "config": name, "cmd": " ".join(cmd), "env": env_add,
           "load1_before": float(load0), "load1_after": float(open("/proc/loadavg").read().split()[0]),
           "proc_wall_s": time.time() - t0, "rc": p.returncode, "time": time.strftime("%H:%M:%S")}
    if p.returncode != 0:
        rec["err"] = (p.stdout + p.stderr)[-2000:]
        return rec
    if kind == "manta":
        r = json.load(open(js))
        st = r["steps"][1:]
        rec["median_ms"] = statistics.median(s["ms"] for s in st)
        rec["mean_ms"] = statistics.mean(s["ms"] for s in st)
        rec["stage_median_ms"] = {k: statistics.median(s["stages_ms"][k] for s in st) for k in st[0]["stages_ms"]}
        its = [int(x) for x in re.findall(r"Iterations:(\d+)", p.stdout + p.stderr)]
        if name.startswith("manta-flip-idp"):  # two CG solves per step: IDP's, then the pressure
            rec["idp_iter_mean"] = statistics.mean(its[0::2]) if its else None
            its = its[1::2]
        rec["pcg_iter_mean"] = statistics.mean(its) if its else None
        rec["pcg_iter_median"] = statistics.median(its) if its else None
        rec["dt_mean"] = statistics.mean(s["dt"] for s in r["steps"])
        rec["sim_time_s"] = r["sim_time_s"]
        rec["particles_end"] = r["np_end"]
    else:
        out = p.stdout
        m = re.search(r"^\s*step\s+([0-9.]+)\s*$", out, re.M)
        rec["median_ms"] = float(m.group(1)) if m else None
        rec["stage_median_ms"] = {k: float(v) for k, v in re.findall(r"^\s{2}(\w+)\s+([0-9.]+)\s*$", out, re.M)}
        m = re.search(r"median PCG iterations (\d+)", out)
        rec["pcg_iter_median"] = int(m.group(1)) if m else None
        m = re.search(r"(\d+) particles, (\d+) fluid cells", out)
        if m:
            rec["particles"] = int(m.group(1))
        rec["stdout"] = out[-1500:]
    return rec


def table(recs, cases):
    """Medians over rounds (the summarize step of the original)."""
    recs = [r for r in recs if r["rc"] == 0 and r.get("median_ms") is not None]
    med = {}
    print("\n## median over rounds of each run's median ms/step (min..max, n; PCG iterations)")
    print("| config | " + " | ".join(cases) + " |")
    print("|---|" + "---|" * len(cases))
    for n in NAMES:
        row = []
        for c in cases:
            v = [r["median_ms"] for r in recs if r["case"] == c and r["config"] == n]
            it = [r["pcg_iter_median"] for r in recs if r["case"] == c and r["config"] == n and r.get("pcg_iter_median") is not None]
            if not v:
                row.append("-")
                continue
            med[(n, c)] = statistics.median(v)
            row.append("%.2f (%.2f..%.2f, n=%d; it %s)" % (med[(n, c)], min(v), max(v), len(v), ("%g" % statistics.median(it)) if it else "-"))
        if any(x != "-" for x in row):
            print("| %s | %s |" % (n, " | ".join(row)))
    print("\n## ratios (cellflip / MantaFlow, medians)")
    for num, den in [("cellflip-flip", "manta-flip-min"), ("cellflip-flip-tol", "manta-flip-min"), ("cellflip-flip", "manta-flip-surface"),
                     ("cellflip-ccp", "manta-flip-min"), ("cellflip-ccp-band", "manta-flip-min"), ("cellflip-ccp", "manta-flip-idp"),
                     ("cellflip-flip-1t", "manta-flip-min-1t")]:
        rs = "  ".join("%s %.2f" % (c, med[(num, c)] / med[(den, c)]) for c in cases if (num, c) in med and (den, c) in med)
        if rs:
            print("%-18s / %-20s %s" % (num, den, rs))
    if recs:
        loads = [r["load1_before"] for r in recs]
        print("\nload1 before runs: median %.2f, max %.2f; rounds %d; failed runs: see rc in bench.jsonl" % (
            statistics.median(loads), max(loads), len(set(r["round"] for r in recs))))
    parts = []
    for lab, num, den in [("flip/FLIP", "cellflip-flip", "manta-flip-min"), ("ccp/IDP", "cellflip-ccp", "manta-flip-idp")]:
        rs = " ".join("%s %.2f" % (c, med[(num, c)] / med[(den, c)]) for c in cases if (num, c) in med and (den, c) in med)
        parts.append(f"{lab} {rs or '-'}")
    print("bench: cellflip/MantaFlow median ms/step: " + ", ".join(parts))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--only", default="2d50,2d100,3d64")
    ap.add_argument("--tag", default="main")
    ap.add_argument("--configs", default="", help="comma-separated subset of config names")
    ap.add_argument("--max-wait", type=int, default=1800, help="s to wait for a quiet machine before each run")
    a = ap.parse_args()
    if not MANTA or not os.access(MANTA, os.X_OK):
        ap.error("set MANTA_BIN to a built manta binary (mantaflow/build.sh prints it)")
    if not os.access(CELLFLIP, os.X_OK):
        ap.error(f"no cellflip binary at {CELLFLIP} (set CELLFLIP or build the project)")
    work = os.path.abspath(os.environ.get("OUT") or tempfile.mkdtemp(prefix="manta-bench-"))
    os.makedirs(work, exist_ok=True)
    for f, text in TOL_SCENES.items():
        with open(os.path.join(work, f), "w") as fh:
            fh.write(text)
    outf = os.path.join(work, "bench.jsonl")
    cases = a.only.split(",")
    want = set(a.configs.split(",")) if a.configs else None
    recs = []
    for rnd in range(a.rounds):
        for case in cases:
            cf = [c for c in configs(case, work) if want is None or c[0] in want]
            k = rnd % len(cf)
            cf = cf[k:] + cf[:k]  # rotate the order each round
            for name, kind, cmd, env in cf:
                rec = run_one(case, name, kind, cmd, env, work, a.max_wait)
                rec["round"] = rnd
                rec["tag"] = a.tag
                recs.append(rec)
                with open(outf, "a") as f:
                    f.write(json.dumps(rec) + "\n")
                print("%s r%d %-6s %-20s %8s ms/step  load %.2f busy %.2f waited %ds rc %d%s" % (
                    rec["time"], rnd, case, name, ("%.2f" % rec["median_ms"]) if rec.get("median_ms") is not None else "-",
                    rec["load1_before"], rec["busy_before"], rec["waited_s"], rec["rc"],
                    "" if rec["rc"] == 0 else "  " + rec.get("err", "")[-200:].replace("\n", " | ")), flush=True)
    print(f"runs: {outf}")
    table(recs, cases)


if __name__ == "__main__":
    main()
