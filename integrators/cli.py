"""The `poincare` command line.

Until the scene driver lands, ``poincare run`` advances a loop of points of a
built-in system with chosen (tableau, projection) pairs and prints the energy,
momentum and constraint errors.  Bad input exits non-zero with one line.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def _demo_loop(system, n):
    """A loop of n points around the system's default initial point (small ellipse in q¹, q²)."""
    q0 = np.array(system.defaults["q0"], dtype=float)
    tau = np.arange(n) / n
    pts = np.repeat(q0[None], n, axis=0)
    pts[:, 0] += 0.05 * np.cos(2 * np.pi * tau)
    pts[:, 1] += 0.05 * np.sin(2 * np.pi * tau)
    return pts


def cmd_run(args) -> int:
    import integrators
    system = integrators.system(args.system)
    h = args.h if args.h is not None else system.defaults["h"]
    for tab in args.tableau:                 # validate everything before any output
        integrators.tableau(tab)
    if args.points < 1 or args.steps < 1:
        raise ValueError("--points and --steps must be positive")
    q = _demo_loop(system, args.points)
    print(f"{system}  points={args.points}  h={h:g}  steps={args.steps}")
    print(f"{'pair':24s} {'status':8s} {'max|ΔH/H|':>11s} {'max|ΔP|':>11s} {'max|p−ϑ(q)|':>12s} {'newton/step':>11s} {'wall [s]':>9s}")
    for tab in args.tableau:
        for proj in args.projection:
            t0 = time.perf_counter()
            sol = integrators.integrate(system, q, tableau=tab, projection=proj, h=h, steps=args.steps,
                                        save_every=max(1, args.steps // 100))
            wall = time.perf_counter() - t0
            qs = sol.q
            H = system.H(qs)
            dH = np.nanmax(np.abs((H - H[0]) / H[0]))
            dP = np.nanmax(np.abs(system.momentum(qs) - system.momentum(qs[0]))) if system.has_momentum else np.nan
            con = np.nanmax(np.abs(sol.p - system.theta(qs)))
            broke = int(np.isfinite(sol.breakdown_time).sum())
            status = "ok" if broke == 0 else f"{broke} broke"
            print(f"{tab + '-' + proj:24s} {status:8s} {dH:11.3e} {dP:11.3e} {con:12.3e} {sol.mean_newton_iterations:11.2f} {wall:9.2f}")
    return 0


def cmd_list(args) -> int:
    import integrators
    if args.what == "tableaus":
        for name in integrators.TABLEAU_NAMES:
            print(integrators.tableau(name))
    else:
        for name in integrators.SYSTEM_NAMES:
            print(integrators.system(name))
    return 0


def build_parser():
    import integrators
    ap = argparse.ArgumentParser(prog="poincare", description="Poincaré integral invariant diagnostics of projected variational integrators.")
    sub = ap.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="advance a loop of points and report conserved-quantity errors")
    run.add_argument("--system", default="guiding_centre_symmetric", choices=integrators.SYSTEM_NAMES)
    run.add_argument("--tableau", nargs="+", default=["GLRK1", "GLRK2", "SRK3"])
    run.add_argument("--projection", nargs="+", default=list(integrators.PROJECTIONS), choices=integrators.PROJECTIONS)
    run.add_argument("--points", type=int, default=200)
    run.add_argument("--steps", type=int, default=200)
    run.add_argument("--h", type=float, default=None)
    run.set_defaults(func=cmd_run)
    ls = sub.add_parser("list", help="list built-in tableaus or systems")
    ls.add_argument("what", choices=["tableaus", "systems"])
    ls.set_defaults(func=cmd_list)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as exc:
        print(f"poincare: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("poincare: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
