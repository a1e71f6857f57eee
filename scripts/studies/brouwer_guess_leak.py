"""Where a pair's round-off drifts although Newton iterates to its floor: the momentum map's drift
and the bias of k steps from the run's own states (docs/brouwer.md, "Where the bound is not met").

For a system with a Noether momentum P (point vortices: the angular momentum) that a pair keeps
exactly or within a bounded oscillation in exact arithmetic, P of the double run minus P of the
double-double run is round-off alone and needs no reference energy: its RMS over the starts, the
mean over the starts at the end (a bias common to the starts shows as |mean/RMS| near 1) and the
slope of log RMS against log step (½ a random walk, 1 a drift).  Then, from the double run's states
(q_n, Λ_n) at every 7th step, ``--ksteps`` steps in double and in double-double from the same state:
the mean of P's difference after k steps over every start and state, with its standard error.  A
bias that appears only after several steps, none after one, comes from what a step carries to the
next (the predictor's history), not from the step's equations.

    python scripts/studies/brouwer_guess_leak.py --pairs point_vortices:GLRK3:symplectic \\
        --steps 50000 --ksteps 64 --rule 'extrapolate={"predictor": "extrapolate"}'

Each rule is a Tolerances(**JSON) beside the default (``now``); every measurement uses the study's
16 starts about the system's default start (brouwer_law.degenerate).  About 3-4 minutes a pair and
rule with ``--ksteps 64`` on 2 cores beside other jobs (the double-double steps from 114,000 states).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

import integrators
from integrators.engine import scalars_dd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from brouwer_law import degenerate  # noqa: E402  (the study's starts)

OUTPUTS = 8


def momentum(system, q, q_lo=None):
    """The Noether momentum in double-double at q (+ q_lo), as one float64 per point (hi + lo)."""
    lead = q.shape[:-1]
    lo = np.zeros_like(q) if q_lo is None else q_lo
    m = scalars_dd(system, np.stack([q.reshape(-1, q.shape[-1]), lo.reshape(-1, q.shape[-1])], -1))[:, 1, :]
    return m[:, 0].reshape(lead), m[:, 1].reshape(lead)


def difference(system, a, b):
    """P(a) − P(b) per point, a a double solution's q and b a double-double one's (q, q_lo)."""
    ah, al = momentum(system, a)
    bh, bl = momentum(system, *b)
    return (ah - bh) + (al - bl)


def drift(system, q0, tab, proj, h, steps, tol):
    every = steps // OUTPUTS
    dd = integrators.integrate(system, q0, tableau=tab, projection=proj, h=h, steps=steps, save_every=every,
                               precision="double-double")
    sol = integrators.integrate(system, q0, tableau=tab, projection=proj, h=h, steps=steps, save_every=every,
                                tolerances=tol)
    r = difference(system, sol.q, (dd.q, dd.q_lo))
    r = r - r[0]
    ph, pl = momentum(system, dd.q, dd.q_lo)
    e_dd = (ph - ph[0]) + (pl - pl[0])
    rms = np.sqrt(np.mean(r[1:] ** 2, axis=1))
    slope = float(np.polyfit(np.log(np.arange(1, OUTPUTS + 1)), np.log(rms), 1)[0])
    return dict(rms=[float(v) for v in rms], mean_over_rms=float(np.mean(r[-1]) / rms[-1]), slope=slope,
                dd_rms=float(np.sqrt(np.mean(e_dd[-1] ** 2))),
                iterations=float(sol.newton_iterations.sum() / (steps * q0.shape[0])))


def ksteps(system, q0, tab, proj, h, steps, K, tol):
    sol = integrators.integrate(system, q0, tableau=tab, projection=proj, h=h, steps=steps, save_every=1,
                                tolerances=tol)
    Q, L = sol.q[:-1:7].reshape(-1, system.d), sol.lam[:-1:7].reshape(-1, system.d)
    a = integrators.integrate(system, Q, tableau=tab, projection=proj, h=h, steps=K, lam0=L, tolerances=tol)
    b = integrators.integrate(system, Q, tableau=tab, projection=proj, h=h, steps=K, lam0=L,
                              precision="double-double")
    out = []
    k = 1
    while k <= K:
        d = difference(system, a.q[k], (b.q[k], b.q_lo[k]))
        out.append(dict(k=k, mean=float(d.mean()), se=float(d.std() / np.sqrt(d.size)), rms=float(d.std())))
        k *= 2
    return dict(states=int(Q.shape[0]), bias=out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", required=True, type=lambda s: [p.split(":") for p in s.split(",")],
                    help="system:tableau:projection,...")
    ap.add_argument("--steps", type=int, default=50_000)
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--ksteps", type=int, default=0, help="also the bias of k = 1, 2, 4 … K steps (0: not)")
    ap.add_argument("--rule", action="append", default=[], metavar="NAME=JSON")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    rules = {"now": integrators.Tolerances()}
    for r in args.rule:
        name, _, spec = r.partition("=")
        rules[name] = integrators.Tolerances(**json.loads(spec))
    rows = []
    for sysname, tab, proj in args.pairs:
        system, q0 = degenerate(sysname, args.starts)
        h = float(system.defaults["h"])
        for name, tol in rules.items():
            row = dict(system=sysname, tableau=tab, projection=proj, rule=name, h=h, steps=args.steps,
                       drift=drift(system, q0, tab, proj, h, args.steps, tol))
            dr = row["drift"]
            print(f"{sysname} {tab}-{proj} [{name}] it./step {dr['iterations']:.2f}: P double − dd, RMS at "
                  f"{args.steps // OUTPUTS}…{args.steps} steps {' '.join(f'{v:.1e}' for v in dr['rms'])}; mean/RMS "
                  f"{dr['mean_over_rms']:+.2f}, slope {dr['slope']:.2f} (the dd run's own P moves {dr['dd_rms']:.1e})",
                  flush=True)
            if args.ksteps:
                row["ksteps"] = ks = ksteps(system, q0, tab, proj, h, args.steps, args.ksteps, tol)
                for b in ks["bias"]:
                    print(f"    k = {b['k']:3d} steps from {ks['states']} states: mean {b['mean']:+.2e} ± {b['se']:.1e} "
                          f"(RMS {b['rms']:.1e})", flush=True)
            rows.append(row)
            if args.json:                       # after every row: a run stopped part-way keeps what it measured
                Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
