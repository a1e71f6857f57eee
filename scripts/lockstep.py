"""Where the step engine's time goes, before changing it (issue 43, docs/benchmarks.md).

    python scripts/lockstep.py [--points 4000] [--out docs/figures/lockstep.json]

Three measurements on guiding_centre_symmetric, h = 10, one thread:

* **Idle lanes.** Points near the default loop (``loop``, Gaussian 1e-3) and spread uniformly over
  the loop's bounding box (``box``), advanced one step at a time: per step, each point's Newton
  iterations and, per group of W = 8 consecutive points (the lanes a group runs in lockstep), the
  most any of them took.  ``idle`` = 1 − mean / group mean of the maximum: the share of lane
  iterations spent waiting on a slower lane, the most that lanes taking up new points could save.
  These are counts: the same on any machine.
* **One orbit.** The time of one W = 1 step of GLRK2/4/6-symmetric (20,000 steps, best of 3), next
  to the time of the s point-function evaluations an iteration makes (scalar, one after another)
  and of one 8-lane evaluation of the same s points (what evaluating the stages in lanes would
  cost), with and without the second derivatives the Jacobian needs.
* **Small dense LU.** The kernel's ``lu_factor`` and ``lu_solve`` for the pairs' sizes nz, at W = 1
  and W = 8 (per call, copying the matrix in included).
"""
import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
from numba import njit

import integrators
import invariants
from integrators.codegen import point_functions
from integrators.engine import set_threads
from integrators.kernel import lu_factor, lu_solve
from integrators.simd import _at, lanes

ROOT = Path(__file__).resolve().parents[1]
PAIRS = (("GLRK2", "symmetric"), ("GLRK1", "none"), ("SRK3", "symmetric"), ("GLRK4", "symmetric"))


def point_sets(n, rng):
    q0 = invariants.loop("guiding_centre", n)
    lo, hi = q0.min(0), q0.max(0)
    return {"loop": q0 + 1e-3 * rng.standard_normal(q0.shape), "box": lo + (hi - lo) * rng.random(q0.shape)}


def idle_lanes(system, sets, steps=10, W=8):
    out = {}
    for tab, proj in PAIRS:
        for name, q in sets.items():
            eng = integrators.Engine(system, integrators.tableau(tab), proj, 10.0)
            st = eng.state(q)
            eng.advance(st, 1, 2)
            per = []
            for j in range(steps):
                before = st.iterations.copy()
                eng.advance(st, 3 + j, 1)
                per.append(st.iterations - before)
            per = np.array(per)
            groups = per[:, :per.shape[1] // W * W].reshape(steps, -1, W)
            mean, worst = float(per.mean()), float(groups.max(axis=2).mean())
            out[f"{tab}-{proj} {name}"] = dict(iterations=mean, group_max=worst, idle=1 - mean / worst,
                                              live=int(st.live.sum()), points=int(q.shape[0]))
    return out


@njit
def _evaluate_scalar(ev, q, k, s, reps, need, th, T, TT, dH, HH):
    d = q.shape[1]
    for _ in range(reps):
        for i in range(s):
            ev(_at(q[i], 0), _at(k, 0), need, _at(th, i * d), _at(T, i * d * d), _at(TT, i * d * d * d),
               _at(dH, i * d), _at(HH, i * d * d))


@njit
def _evaluate_lanes(ev, qp, k, reps, need, th, T, TT, dH, HH):
    for _ in range(reps):
        ev(_at(qp, 0), _at(k, 0), need, _at(th, 0), _at(T, 0), _at(TT, 0), _at(dH, 0), _at(HH, 0))


def evaluations(system, q, reps=200000):
    """ns per iteration's worth of evaluations: s scalar calls, or one 8-lane call."""
    d = system.d
    ev1, _ = point_functions(system, False)
    ev8, _ = point_functions(system, False, lanes=8)
    k = np.array([float(v) for v in system.params.values()])
    q8 = np.ascontiguousarray(q[:8])
    packed = np.ascontiguousarray(q8.T).ravel()
    out = {}
    for need in (False, True):
        for s in (2, 4, 6):
            b = [np.zeros(8 * x) for x in (d, d * d, d * d * d, d, d * d)]
            _evaluate_scalar(ev1, q8, k, s, 10, need, *b)
            _evaluate_lanes(ev8, packed, k, 10, need, *b)
            t = time.perf_counter()
            _evaluate_scalar(ev1, q8, k, s, reps, need, *b)
            scalar = (time.perf_counter() - t) / reps
            t = time.perf_counter()
            _evaluate_lanes(ev8, packed, k, reps, need, *b)
            lane = (time.perf_counter() - t) / reps
            out[f"s={s} second={need}"] = dict(scalar_ns=scalar * 1e9, lanes_ns=lane * 1e9)
    return out


def one_orbit(system, q, steps=20000):
    out = {}
    for tab in ("GLRK2", "GLRK4", "GLRK6"):
        eng = integrators.Engine(system, integrators.tableau(tab), "symmetric", 10.0)
        best, its = np.inf, 0.0
        for _ in range(3):
            st = eng.state(q[:1])
            eng.advance(st, 1, 2)
            i0 = st.iterations.sum()
            t = time.perf_counter()
            eng.advance(st, 3, steps)
            best = min(best, time.perf_counter() - t)
            its = (st.iterations.sum() - i0) / steps
        out[f"{tab}-symmetric"] = dict(step_ns=best / steps * 1e9, iterations=float(its), nz=eng.nz)
    return out


@njit
def _factor(A0, A, piv, n, reps, P):
    for _ in range(reps):
        A[:] = A0
        lu_factor(lanes(A, 0, P), lanes(piv, 0, P), n)


@njit
def _solve(A, piv, x0, x, n, reps, P):
    for _ in range(reps):
        x[:] = x0
        lu_solve(lanes(A, 0, P), lanes(piv, 0, P), lanes(x, 0, P), n)


def dense_lu(sizes, rng, reps=20000):
    out = {}
    for n in sizes:
        for W in (1, 8):
            P = (0,) * W
            A0 = rng.standard_normal(n * n * W)
            A, piv = A0.copy(), np.zeros(n * W, np.int64)
            x0 = rng.standard_normal(n * W)
            x = x0.copy()
            _factor(A0, A, piv, n, 10, P)
            _solve(A, piv, x0, x, n, 10, P)
            t = time.perf_counter()
            _factor(A0, A, piv, n, reps, P)
            tf = (time.perf_counter() - t) / reps
            t = time.perf_counter()
            _solve(A, piv, x0, x, n, reps, P)
            ts = (time.perf_counter() - t) / reps
            out[f"nz={n} W={W}"] = dict(factor_ns=tf * 1e9, solve_ns=ts * 1e9)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=4000)
    ap.add_argument("--out", default=str(ROOT / "docs/figures/lockstep.json"))
    args = ap.parse_args()
    set_threads(1)
    rng = np.random.default_rng(1)
    system = integrators.system("guiding_centre_symmetric")
    sets = point_sets(args.points, rng)
    res = dict(machine=platform.processor() or platform.machine(), date=time.strftime("%Y-%m-%d"),
               idle=idle_lanes(system, sets), one_orbit=one_orbit(system, sets["loop"]),
               evaluations=evaluations(system, sets["loop"]), lu=dense_lu((8, 12, 20, 28), rng))
    Path(args.out).write_text(json.dumps(res, indent=1))
    print("idle lanes (Newton iterations a step: mean, group-of-8 maximum, idle share)")
    for key, v in res["idle"].items():
        print(f"  {key:24s} {v['iterations']:5.2f} {v['group_max']:5.2f} {v['idle']:5.1%}  live {v['live']}/{v['points']}")
    print("one orbit (W = 1): ns a step, iterations a step, nz")
    for key, v in res["one_orbit"].items():
        print(f"  {key:24s} {v['step_ns']:7.0f} {v['iterations']:5.2f} {v['nz']}")
    print("point functions: ns for s scalar evaluations / one 8-lane evaluation")
    for key, v in res["evaluations"].items():
        print(f"  {key:24s} {v['scalar_ns']:6.0f} {v['lanes_ns']:6.0f}")
    print("small dense LU: ns a factorisation / a solve")
    for key, v in res["lu"].items():
        print(f"  {key:24s} {v['factor_ns']:7.0f} {v['solve_ns']:6.0f}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
