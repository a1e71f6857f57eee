"""Speed of the double-double engine (W = 8 lanes and W = 1) side by side with the double engine (W = 8 and W = 1) and
the long-double numpy reference, in point-steps per second on one thread; and the double runs'
distance from the double-double one after the same steps.

    python scripts/studies/benchmarks_double_double.py [--points 1000] [--steps 20] [--system guiding_centre_symmetric]
                                    [--h 10] [--tableaus GLRK2 GLRK4] [--json docs/figures/double_double.json]

Each engine is timed after a warm-up call (compilation excluded), best of --repeat.
"""
from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

import integrators
from integrators import reference
from integrators.engine import Engine, State, set_threads, theta_dd


def points(system, n, seed=0):
    from integrators.service.scene import load_scene
    rng = np.random.default_rng(seed)
    base = load_scene("default").points(system) if system.name == "guiding_centre_symmetric" else None
    if base is not None:
        return base[rng.integers(0, base.shape[0], n)] * (1 + 1e-3 * rng.standard_normal((n, system.d)))
    q0 = np.asarray(system.defaults["q0"], dtype=float)
    return q0 * (1 + 1e-2 * rng.standard_normal((n, system.d)))


def rate(fn, work, repeat):
    fn()                                   # warm-up: compilation, caches
    best = min(_timed(fn) for _ in range(repeat))
    return work / best, best


def _timed(fn):
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--system", default="guiding_centre_symmetric")
    ap.add_argument("--h", type=float, default=10.0)
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--reference-points", type=int, default=50)
    ap.add_argument("--tableaus", nargs="+", default=["GLRK2", "GLRK4"])
    ap.add_argument("--projection", default="symmetric")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    set_threads(1)
    sy = integrators.system(args.system)
    q = points(sy, args.points)
    rows = []
    for name in args.tableaus:
        tab = integrators.tableau(name)
        e = Engine(sy, tab, args.projection, args.h)
        work = args.points * args.steps
        out = {"pair": f"{name}-{args.projection}"}
        for label, W in (("double W=8", 8), ("double W=1", 1)):
            def run(W=W):
                st = e.state(q)
                e.advance(st, 1, args.steps, lanes=W)
                run.q = st.q
            out[label], _ = rate(run, work, args.repeat)
        q2 = np.stack([q, np.zeros_like(q)], axis=-1)
        p2 = theta_dd(sy, q2)

        dd_states = {}
        for label, W in (("double-double W=8", 8), ("double-double W=1", 1)):
            def run_dd(W=W):
                st = State.double_double(q2, p2, np.zeros_like(q), args.h, tab.s)
                e.advance(st, 1, args.steps, lanes=W)
                dd_states[W] = st.checkpoint()
            out[label], _ = rate(run_dd, work, args.repeat)
        out["double-double W=8 bits = W=1 bits"] = all(np.array_equal(dd_states[8][k], dd_states[1][k])
                                                       for k in dd_states[1])
        dd_q = dd_states[8]["q"][..., 0] + dd_states[8]["q"][..., 1]   # (rounded: enough to measure double's distance)
        st = e.state(q)
        e.advance(st, 1, args.steps)
        live = np.isfinite(dd_q).all(axis=1) & np.isfinite(st.q).all(axis=1)
        out["max |q_double - q_dd| / |q|"] = float(np.max(np.abs(st.q[live] - dd_q[live]) / np.maximum(np.abs(dd_q[live]), 1)))
        nr = args.reference_points
        qr = q[:nr].astype(np.longdouble)
        stepper = reference.Stepper(sy, tab, args.projection, args.h)

        def run_ref():
            S = reference.State(qr, sy.theta(qr), np.zeros_like(qr), args.h, stepper.s)
            for k in range(1, args.steps + 1):
                reference.advance(stepper, S, k * args.h)
        out["long double (numpy reference)"], _ = rate(run_ref, nr * args.steps, 1)
        out["double-double W=8 / double W=8"] = out["double-double W=8"] / out["double W=8"]
        out["double-double W=1 / double W=8"] = out["double-double W=1"] / out["double W=8"]
        out["double-double W=8 / long double"] = out["double-double W=8"] / out["long double (numpy reference)"]
        out["double-double W=1 / long double"] = out["double-double W=1"] / out["long double (numpy reference)"]
        rows.append(out)
    meta = {"command": "python scripts/studies/benchmarks_double_double.py " + " ".join(argv or __import__("sys").argv[1:]),
            "machine": platform.processor() or platform.machine(), "threads": 1, "points": args.points,
            "steps": args.steps, "system": args.system, "h": args.h, "rows": rows}
    for r in rows:
        print(r["pair"])
        for k, v in r.items():
            if k != "pair":
                print(f"  {k:34s} {v:12.4g}" if not isinstance(v, bool) else f"  {k:34s} {v!s:>12}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(meta, fh, indent=1)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
