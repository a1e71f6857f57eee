"""Throughput of the batched step map and the invariants (docs/benchmarks.md).

    python scripts/benchmark_core.py [--points 10000] [--steps 5] [--out docs/figures/benchmark_core.json]

For guiding_centre_symmetric (h = 10) and every (tableau, projection) pair asked
for: point-steps per second of the batched path (10,000 points, median of three runs of
5 steps after two warm-up steps, so the extrapolated initial guess is in use), the same code advancing the
points one at a time (``chunk=1``, on a subset), their ratio, the mean Newton
iterations per step; a cProfile of GLRK2-symmetric; tracemalloc peaks of 10 and
100 steps (nothing stored per step); and the cost of I₁ (2,000 points) and I₂
(100×100) with all three forms next to one integrator step of those points.
"""
import argparse
import cProfile
import io
import json
import platform
import pstats
import time
import tracemalloc
from pathlib import Path

import numpy as np

import integrators
import invariants
from integrators.integrate import State, advance
from integrators.projections import Stepper

ROOT = Path(__file__).resolve().parents[1]


def points(n, rng):
    q0 = invariants.loop("guiding_centre", n)
    return q0 + 1e-3 * rng.standard_normal(q0.shape)


def throughput(system, q, tab, proj, h, steps, chunk=None):
    stepper = Stepper(system, integrators.tableau(tab), proj, h)
    n = q.shape[0]
    chunk = chunk or n
    states = [State(q[k:k + chunk], system.theta(q[k:k + chunk]), np.zeros_like(q[k:k + chunk]), h, stepper.s)
              for k in range(0, n, chunk)]
    for k in range(2):                                  # warm-up: the guess then extrapolates two steps
        for st in states:
            advance(stepper, st, (k + 1) * h)
    its0 = sum(st.iterations.sum() for st in states)
    t0 = time.perf_counter()
    for k in range(steps):
        for st in states:
            advance(stepper, st, (k + 3) * h)
    wall = time.perf_counter() - t0
    its = sum(st.iterations.sum() for st in states) - its0
    return n * steps / wall, its / (n * steps)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=10000)
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--loop-points", type=int, default=100, help="points for the one-at-a-time loop")
    ap.add_argument("--repeats", type=int, default=3, help="batched timings per pair; the median is reported")
    ap.add_argument("--tableaus", nargs="+", default=["GLRK1", "GLRK2", "SRK3", "GLRK4"])
    ap.add_argument("--out", default=str(ROOT / "docs" / "figures" / "benchmark_core.json"))
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    gc = integrators.system("guiding_centre_symmetric")
    h = 10.0
    q = points(args.points, rng)
    gc.ddtheta(q[:1]); gc.ddH(q[:1])          # compile the generated code outside the timings
    rows = []
    for tab in args.tableaus:
        for proj in integrators.PROJECTIONS:
            runs = [throughput(gc, q, tab, proj, h, args.steps) for _ in range(args.repeats)]
            batched, its = float(np.median([r[0] for r in runs])), runs[0][1]
            single, _ = throughput(gc, q[: args.loop_points], tab, proj, h, 2, chunk=1)
            rows.append(dict(tableau=tab, projection=proj, batched=batched, per_point=single,
                             ratio=batched / single, newton=its))
            print(f"{tab:6s} {proj:10s} batched {batched:10.0f} pt-steps/s   one-by-one {single:8.0f}   "
                  f"ratio {batched / single:6.1f}   newton/step {its:.2f}", flush=True)

    # profile of the headline pair
    pr = cProfile.Profile()
    pr.enable()
    throughput(gc, q, "GLRK2", "symmetric", h, 3)
    pr.disable()
    buf = io.StringIO()
    pstats.Stats(pr, stream=buf).sort_stats("tottime").print_stats(12)
    profile = buf.getvalue()
    print(profile)

    # memory: a run of 10 and of 100 steps storing only the end points
    peaks = {}
    for steps in (10, 100):
        tracemalloc.start()
        integrators.integrate(gc, q, tableau="GLRK2", projection="symmetric", h=h, steps=steps, save_every=steps)
        peaks[steps] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    print("tracemalloc peak (MiB):", {k: v / 2**20 for k, v in peaks.items()})

    # invariants vs one step
    loop = invariants.loop("guiding_centre", 2000)
    surf = invariants.surface("guiding_centre", 100, 100)
    lam_l, lam_s = 1e-3 * np.ones_like(loop), 1e-3 * np.ones_like(surf)

    def timed(f, reps=5):
        f()
        t0 = time.perf_counter()
        for _ in range(reps):
            f()
        return (time.perf_counter() - t0) / reps

    t_I1 = timed(lambda: [invariants.first_invariant(loop, fm, system=gc, p=gc.theta(loop), lam=lam_l, h=h)
                          for fm in invariants.FORMS])
    t_I2 = timed(lambda: [invariants.second_invariant(surf, fm, system=gc, p=gc.theta(surf), lam=lam_s, h=h)
                          for fm in invariants.FORMS])
    r_loop, _ = throughput(gc, loop, "GLRK2", "symmetric", h, 3)
    r_surf, _ = throughput(gc, surf.reshape(-1, 4), "GLRK2", "symmetric", h, 3)
    inv = dict(I1_all_forms_2000=t_I1, step_2000=2000 / r_loop, I2_all_forms_100x100=t_I2, step_10000=10000 / r_surf)
    print("invariants vs one GLRK2-symmetric step [s]:", inv)
    meta = dict(machine=platform.platform(), processor=platform.processor(), python=platform.python_version(),
                numpy=np.__version__, points=args.points, steps=args.steps)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(dict(meta=meta, rows=rows, tracemalloc_peak_bytes=peaks,
                                              invariants=inv, profile=profile), indent=1))


if __name__ == "__main__":
    main()
