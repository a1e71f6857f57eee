"""Long-time stability campaign of sec:numerical_experiments (docs/stability.md).

    python scripts/studies/stability_campaign.py run  --case lotka_volterra --steps 1000000 [--pairs GLRK1:none ...]
                                     [--shard 0/2] [--out docs/figures/stability/a.jsonl]
    python scripts/studies/stability_campaign.py report [--dir docs/figures/stability]      # markdown tables + PNGs

Cases, with the paper's initial conditions and time steps:
  lotka_volterra          q0 = (1, 1), h = 0.1                     (sec:app_lotka_volterra_2d)
  point_vortices          q0 = (1, 0.1, 1, -0.1), h = 0.1          (sec:app_planar_point_vortices)
  tokamak_<orbit>         (R, Z, φ, u) = (2.5, 0, 0, u), h per orbit (app:guiding_centre_dynamics):
                          deeply_trapped (u 0.1, h 5), barely_trapped (0.3375, 3),
                          barely_passing (0.3425, 2.5), deeply_passing (0.5, 2.5)

Every (case, tableau, projection) pair the tableau admits is run for ``--steps`` steps (or the
pairs named with ``--pairs``).  Each finished run is appended as one JSON line to ``--out`` at
once, and a pair already in the output with at least as many steps is skipped, so a killed
campaign loses only the run in progress and resumes where it stopped; ``--shard i/n`` runs every
n-th pair, for n processes side by side.  A run records: completed, or the step at which it broke
down (Newton failed, a value was not finite, or q left the domain); the relative energy error
|H − H₀|/|H₀|, the momentum error |P − P₀|/|P₀| (when the system has a symmetry) and the
constraint error max|p − ϑ(q)| (for unprojected methods), each as its largest value over the run
and as an envelope (the largest value in each of 40 logarithmically spaced windows of steps),
sampled every steps/4000 steps; wall time and Newton iterations per step.
"""
import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import integrators
from integrators import PROJECTIONS, TABLEAU_NAMES
from integrators.integrate import integrate

ROOT = Path(__file__).resolve().parents[2]
DIR = ROOT / "docs" / "figures" / "stability"
ORBITS = {"deeply_trapped": (0.1, 5.0), "barely_trapped": (0.3375, 3.0),
          "barely_passing": (0.3425, 2.5), "deeply_passing": (0.5, 2.5)}
CASES = ["lotka_volterra", "point_vortices"] + [f"tokamak_{o}" for o in ORBITS]
WINDOWS = 40
SAMPLES = 4000


def case_setup(case):
    """(system, q0, h) of a case."""
    if case == "lotka_volterra":
        return integrators.system("lotka_volterra_2d"), np.array([1.0, 1.0]), 0.1
    if case == "point_vortices":
        return integrators.system("point_vortices"), np.array([1.0, 0.1, 1.0, -0.1]), 0.1
    if case.startswith("tokamak_") and case[8:] in ORBITS:
        u, h = ORBITS[case[8:]]
        return integrators.system("guiding_centre_tokamak"), np.array([2.5, 0.0, 0.0, u]), h
    raise SystemExit(f"error: unknown case '{case}'; choose one of {', '.join(CASES)}")


def all_pairs():
    out = []
    for name in TABLEAU_NAMES:
        tab = integrators.tableau(name)
        for proj in PROJECTIONS:
            if proj in ("symmetric", "symplectic", "midpoint") and abs(tab.R_inf) != 1.0:
                continue
            out.append((name, proj))
    return out


def envelope(steps_at, err):
    """Largest error in each of WINDOWS log-spaced windows of steps: (window end steps, maxima)."""
    edges = np.unique(np.geomspace(1, max(steps_at[-1], 1), WINDOWS + 1).round().astype(np.int64))
    ends, maxima = [], []
    lo = 0
    for hi in edges[1:]:
        sel = (steps_at > lo) & (steps_at <= hi)
        if sel.any():
            ends.append(int(hi))
            maxima.append(float(np.max(err[sel])))
        lo = hi
    return ends, maxima


def _3(x):
    """Three significant digits (the JSON lines stay small)."""
    return float(f"{x:.3g}")


def run_one(case, tab, proj, steps):
    system, q0, h = case_setup(case)
    every = max(1, steps // SAMPLES)
    ticks = [0]

    def progress(k, n):
        if n >= 100000 and k * 10 // n > ticks[0]:
            ticks[0] = k * 10 // n
            print(f"    {case} {tab}-{proj}: {ticks[0] * 10} %", file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    sol = integrate(system, q0, tableau=tab, projection=proj, h=h, steps=steps, save_every=every, progress=progress)
    wall = time.perf_counter() - t0
    taken = int(sol.steps_taken[0])
    broke = math.isfinite(sol.breakdown_time[0])
    nvalid = taken // every + 1                     # outputs written before the breakdown
    q, p = sol.q[:nvalid, 0], sol.p[:nvalid, 0]
    steps_at = np.arange(nvalid) * every
    H = system.H(q)
    rec = dict(case=case, tableau=tab, projection=proj, h=h, steps=steps, every=every,
               status="broke down" if broke else "completed", breakdown_step=taken + 1 if broke else None,
               wall_s=round(wall, 2), newton_per_step=round(sol.mean_newton_iterations, 3))
    errs = {"energy": np.abs(H - H[0]) / abs(H[0])}
    if system.has_momentum:
        P = system.momentum(q)
        errs["momentum"] = np.abs(P - P[0]) / (abs(P[0]) if P[0] != 0 else 1.0)
    if proj == "none":
        errs["constraint"] = np.max(np.abs(p - system.theta(q)), axis=-1)
    for key, e in errs.items():
        e = np.where(np.isfinite(e), e, np.inf)
        ends, maxima = envelope(steps_at, e)
        rec[key] = dict(max=_3(e.max()), final=_3(e[-1]), envelope_steps=ends, envelope=[_3(v) for v in maxima])
    return rec


def load(paths):
    recs = []
    for path in paths:
        for line in Path(path).read_text().splitlines():
            if line.strip():
                recs.append(json.loads(line))
    return recs


def cmd_run(args):
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    done = {(r["case"], r["tableau"], r["projection"]): r["steps"] for r in load(out.parent.glob("*.jsonl"))}
    pairs = [tuple(s.split(":")) for s in args.pairs] if args.pairs else all_pairs()
    i, n = (int(x) for x in args.shard.split("/"))
    pairs = pairs[i::n]
    for case in args.case:
        case_setup(case)
        for tab, proj in pairs:
            if done.get((case, tab, proj), 0) >= args.steps:
                continue
            rec = run_one(case, tab, proj, args.steps)
            with out.open("a") as f:
                f.write(json.dumps(rec, separators=(",", ":")) + "\n")
            e = rec["energy"]["max"]
            print(f"{case:24s} {tab:9s} {proj:10s} {rec['status']:10s} "
                  f"{'' if rec['breakdown_step'] is None else rec['breakdown_step']:>8} max|ΔH/H| {e:8.1e} "
                  f"{rec['wall_s']:7.1f} s", flush=True)


def growing(e, steps):
    """True when the energy error grows: its largest value in the last window of steps is more
    than 10× its largest value over the first tenth of the run."""
    ends, env = np.array(e["envelope_steps"]), np.array(e["envelope"])
    early = env[ends <= steps / 10]
    return bool(early.size and env[-1] > 10 * max(early.max(), 1e-16))


def fmt(r):
    """One table cell: max energy error of a completed run (↗: growing), or the breakdown step."""
    if r["status"] == "completed":
        e = r["energy"]
        return f"{e['max']:.0e}" + (" ↗" if growing(e, r["steps"]) else "")
    return f"✗ {r['breakdown_step']}"


def cmd_report(args):
    d = Path(args.dir)
    recs = load(sorted(d.glob("*.jsonl")))
    best = {}
    for r in recs:                      # the longest run of each pair
        key = (r["case"], r["tableau"], r["projection"])
        if key not in best or r["steps"] > best[key]["steps"]:
            best[key] = r
    for case in CASES:
        rows = {k: v for k, v in best.items() if k[0] == case}
        if not rows:
            continue
        stepcounts = sorted({v["steps"] for v in rows.values()})
        print(f"\n#### {case} (steps: {', '.join(f'{s:,}' for s in stepcounts)}; "
              f"cell: largest |ΔH|/|H₀| of a completed run, ↗ where it grows by more than 10× after the first tenth of the run, or ✗ and the step it broke down at)\n")
        print("| tableau | " + " | ".join(PROJECTIONS) + " |")
        print("|---|" + "---|" * len(PROJECTIONS))
        for tab in TABLEAU_NAMES:
            cells = []
            for proj in PROJECTIONS:
                r = rows.get((case, tab, proj))
                cells.append("" if r is None else fmt(r) + ("" if r["steps"] == stepcounts[0] else f" ({r['steps']:.0e})"))
            if any(cells):
                print(f"| {tab} | " + " | ".join(cells) + " |")
        plot_case(case, rows, d / f"{case}.png")


def plot_case(case, rows, path):
    """Energy (top) and momentum (bottom, when the system has one) error envelopes, one panel per projection."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    projs = [p for p in PROJECTIONS if any(k[2] == p for k in rows)]
    keys = ["energy"] + (["momentum"] if any("momentum" in r for r in rows.values()) else [])
    fig, axes = plt.subplots(len(keys), len(projs), figsize=(3.4 * len(projs), 3.0 * len(keys)), sharey="row",
                             squeeze=False)
    cmap = plt.get_cmap("tab20")
    handles = {}
    for row, key in zip(axes, keys):
        for ax, proj in zip(row, projs):
            for i, tab in enumerate(TABLEAU_NAMES):
                r = rows.get((case, tab, proj))
                if r is None or key not in r:
                    continue
                e = r[key]
                x, y = np.array(e["envelope_steps"]), np.clip(np.array(e["envelope"]), 1e-17, 1e3)
                handles[tab] = ax.loglog(x, y, color=cmap(i % 20), lw=1, label=tab)[0]
                if r["status"] != "completed" and len(x):
                    ax.plot(x[-1], y[-1], "x", color=cmap(i % 20), ms=5)
            ax.set_title(f"{proj}: {key}", fontsize=9)
            ax.set_ylim(1e-17, 1e3)
        row[0].set_ylabel(f"max |Δ{'H' if key == 'energy' else 'P'}|/|{'H' if key == 'energy' else 'P'}₀| in window")
    for ax in axes[-1]:
        ax.set_xlabel("step")
    order = [t for t in TABLEAU_NAMES if t in handles]
    fig.legend([handles[t] for t in order], order, loc="center right", fontsize=7)
    fig.suptitle(f"{case}: error envelopes (× = broke down)")
    fig.tight_layout(rect=(0, 0, 0.91, 1))
    fig.savefig(path, dpi=72)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--case", nargs="+", required=True)
    r.add_argument("--steps", type=int, required=True)
    r.add_argument("--pairs", nargs="+", help="TABLEAU:projection ... (default: every admissible pair)")
    r.add_argument("--shard", default="0/1", help="i/n: run every n-th pair starting at i")
    r.add_argument("--out", default=str(DIR / "stability.jsonl"))
    p = sub.add_parser("report")
    p.add_argument("--dir", default=str(DIR))
    args = ap.parse_args()
    (cmd_run if args.cmd == "run" else cmd_report)(args)


if __name__ == "__main__":
    main()
