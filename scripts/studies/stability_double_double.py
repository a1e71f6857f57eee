"""The paper's questions that lie under double's round-off, re-run in double-double
(integrators.integrate(..., precision="double-double"); docs/results.md, "Below double precision").

    python scripts/studies/stability_double_double.py lv-breakdown [--steps 400000] [--pairs GLRK2 GLRK4] [--json F] [--png F]

lv-breakdown: the unprojected Gauss–Legendre runs on Lotka–Volterra (q₀ = (1, 1), h = 0.1, p₀ = ϑ(q₀)),
the paper's breakdown case (about 250,000 steps for GLRK2 in the paper, 74,191 in double here): the
breakdown step in double and in double-double, and the energy error |H − H₀|/|H₀| every --every steps
of both runs (H evaluated in double on the rounded state: enough to see a growth of many orders).
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

import integrators


def lv_breakdown(args):
    sy = integrators.system("lotka_volterra_2d")
    out = {"case": "lotka_volterra_2d, q0 = (1, 1), h = 0.1, projection none", "runs": []}
    for name in args.pairs:
        for prec in ("double", "double-double"):
            t0 = time.perf_counter()
            sol = integrators.integrate(sy, [1.0, 1.0], tableau=name, projection="none", h=0.1, steps=args.steps,
                                        save_every=args.every, precision=prec)
            wall = time.perf_counter() - t0
            q = sol.q[:, 0] if sol.q_lo is None else sol.q[:, 0] + sol.q_lo[:, 0]
            H = sy.H(q)
            bt = float(sol.breakdown_time[0])
            ok = np.isfinite(H) & (sol.t < bt)              # the outputs before the breakdown
            err = np.abs(H - H[0]) / abs(H[0])
            run = {"pair": f"{name}-none", "precision": prec, "steps": args.steps,
                   "breakdown_step": None if not np.isfinite(bt) else int(round(bt / 0.1)),
                   "steps_taken": int(sol.steps_taken[0]), "wall_s": round(wall, 2),
                   "t": sol.t[ok].tolist(), "energy_error": err[ok].tolist()}
            out["runs"].append(run)
            print(f"{name}-none {prec:14s} breakdown step {run['breakdown_step']}, {run['steps_taken']} steps taken, "
                  f"{wall:.1f} s; energy error at 10 %, 50 %, 90 % of the taken steps: "
                  + ", ".join(f"{err[ok][int(f * (ok.sum() - 1))]:.2e}" for f in (0.1, 0.5, 0.9)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", choices=["lv-breakdown"])
    ap.add_argument("--steps", type=int, default=400000)
    ap.add_argument("--every", type=int, default=1000)
    ap.add_argument("--pairs", nargs="+", default=["GLRK2"])
    ap.add_argument("--json", default=None)
    ap.add_argument("--png", default=None)
    args = ap.parse_args(argv)
    out = lv_breakdown(args)
    out["command"] = "python scripts/studies/stability_double_double.py " + " ".join(argv or __import__("sys").argv[1:])
    if args.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(7, 4))
        for r in out["runs"]:
            t, e = np.array(r["t"]), np.array(r["energy_error"])
            end = f"breaks down at step {r['breakdown_step']:,}" if r["breakdown_step"] else f"completes {r['steps']:,} steps"
            ax.loglog(t[t > 0], np.maximum(e[t > 0], 1e-34), "-" if r["precision"] == "double" else "--",
                      lw=1, label=f"{r['pair']} {r['precision']} ({end})")
        ax.set_xlabel("t")
        ax.set_ylabel("|H − H₀|/|H₀|")
        ax.set_title("Lotka–Volterra, h = 0.1, no projection: double against double-double", fontsize=10)
        ax.legend(fontsize=7)
        ax.grid(True, lw=0.3)
        fig.tight_layout()
        fig.savefig(args.png, dpi=100)
        print(f"wrote {args.png}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
