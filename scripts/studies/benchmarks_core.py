"""The compiled step engine against the numpy engine it replaced, side by side (docs/benchmarks.md).

    python scripts/studies/benchmarks_core.py [--points 10000] [--out docs/figures/benchmark_core.json]

Measured in one run on this machine, every number next to the one it is compared with:

* throughput on guiding_centre_symmetric (h = 10, 10,000 points near the default loop, 10 steps
  after 2 warm-up steps): compiled on 1 and 2 threads, the numpy engine (integrators/reference.py,
  the engine every run used before), for every projection with GLRK1, GLRK2, SRK3 and GLRK4;
* one trajectory: steps per second of each engine (10⁵ steps compiled, 300 numpy), and the
  wall time of 10⁶ steps of the barely passing tokamak orbit with GLRK2-symmetric;
* start-up: a fresh process integrating one point with an empty kernel cache (generation and
  compilation) and again with the cache filled;
* memory: tracemalloc peak per point of a 10⁵-point GLRK2-symmetric run (state and outputs; the
  kernel's per-thread scratch is a few KiB in all);
* a cProfile of a GLRK2-symmetric integrate call on 10,000 points.
"""
import argparse
import cProfile
import io
import json
import os
import platform
import pstats
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

import integrators
import invariants
from integrators.engine import get_threads, march, set_threads

ROOT = Path(__file__).resolve().parents[2]
from integrators import reference


def points(n, rng):
    q0 = invariants.loop("guiding_centre", n)
    return q0 + 1e-3 * rng.standard_normal(q0.shape)


def compiled_rate(system, q, tab, proj, h, steps, threads):
    set_threads(threads)
    eng = integrators.Engine(system, integrators.tableau(tab), proj, h)
    st = eng.state(q)
    eng.advance(st, 1, 2)                      # warm-up: the guess then extrapolates
    its0 = st.iterations.sum()
    t0 = time.perf_counter()
    eng.advance(st, 3, steps)
    wall = time.perf_counter() - t0
    return q.shape[0] * steps / wall, (st.iterations.sum() - its0) / (q.shape[0] * steps)


def numpy_rate(system, q, tab, proj, h, steps):
    stepper = reference.Stepper(system, integrators.tableau(tab), proj, h)
    st = reference.State(q, system.theta(q), np.zeros_like(q), h, stepper.s)
    for k in range(2):
        reference.advance(stepper, st, (k + 1) * h)
    t0 = time.perf_counter()
    for k in range(steps):
        reference.advance(stepper, st, (k + 3) * h)
    return q.shape[0] * steps / (time.perf_counter() - t0)


def startup(tmp):
    """Seconds for a fresh process to integrate one point: empty caches, then filled ones."""
    env = dict(os.environ, POINCARE_CACHE=str(Path(tmp) / "poincare"), NUMBA_CACHE_DIR=str(Path(tmp) / "numba"))
    code = ("import time; t = time.perf_counter(); import integrators; "
            "s = integrators.system('point_vortices'); "
            "integrators.integrate(s, s.defaults['q0'], tableau='GLRK2', projection='symmetric', steps=10); "
            "print(time.perf_counter() - t)")
    out = []
    for _ in range(2):
        r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        out.append(float(r.stdout.strip()))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=10000)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--tableaus", nargs="+", default=["GLRK1", "GLRK2", "SRK3", "GLRK4"])
    ap.add_argument("--out", default=str(ROOT / "docs" / "figures" / "benchmark_core.json"))
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    gc = integrators.system("guiding_centre_symmetric")
    h = 10.0
    q = points(args.points, rng)
    cores = get_threads()
    integrators.integrate(gc, q[:2], tableau="GLRK2", projection="symmetric",
                          h=h, steps=2)    # compile outside the timings

    rows = []
    for tab in args.tableaus:
        for proj in integrators.PROJECTIONS:
            one, its = compiled_rate(gc, q, tab, proj, h, args.steps, 1)
            two, _ = compiled_rate(gc, q, tab, proj, h, args.steps, 2)
            old = numpy_rate(gc, q, tab, proj, h, 3)
            rows.append(dict(tableau=tab, projection=proj, compiled_1_thread=one, compiled_2_threads=two,
                             numpy=old, speedup=one / old, threads_ratio=two / one, newton=its))
            print(f"{tab:6s} {proj:10s} compiled {one:10,.0f} (2 threads {two:10,.0f}, x{two / one:4.2f})  "
                  f"numpy {old:9,.0f}  x{one / old:5.1f}  newton/step {its:.2f}", flush=True)
    set_threads(1)

    # one trajectory
    single = []
    for tab, proj in (("GLRK1", "none"), ("GLRK2", "symmetric")):
        c, _ = compiled_rate(gc, q[:1], tab, proj, h, 100000, 1)
        o = numpy_rate(gc, q[:1], tab, proj, h, 300)
        single.append(dict(tableau=tab, projection=proj, compiled=c, numpy=o, speedup=c / o))
        print(f"one trajectory {tab}-{proj}: compiled {c:,.0f} steps/s, numpy {o:,.0f}, x{c / o:.0f}", flush=True)
    tok = integrators.system("guiding_centre_tokamak")
    u, h_tok = tok.defaults["orbits"]["barely passing"]       # (R, Z, φ, u) = (2.5, 0, 0, u), the paper's h
    q_tok = np.array([[2.5, 0.0, 0.0, u]])
    eng = integrators.Engine(tok, integrators.tableau("GLRK2"), "symmetric", h_tok)
    st = eng.state(q_tok)
    t0 = time.perf_counter()
    march(eng, st, 0, 1_000_000, 1_000_000)
    tokamak = dict(steps=1_000_000, wall=time.perf_counter() - t0, completed=bool(st.live[0]),
                   newton=float(st.iterations[0] / max(st.steps[0], 1)))
    print("tokamak orbit, 10^6 steps GLRK2-symmetric:", tokamak, flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        first, cached = startup(tmp)
    print(f"start-up: empty cache {first:.1f} s, cached {cached:.2f} s", flush=True)

    # memory: state and outputs of a 10^5-point run (begin and end points stored)
    n_mem = 100_000
    qm = points(n_mem, rng)
    tracemalloc.start()
    integrators.integrate(gc, qm, tableau="GLRK2", projection="symmetric", h=h, steps=10, save_every=10)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    print(f"tracemalloc peak: {peak / n_mem:.0f} bytes per point at {n_mem} points", flush=True)

    # the invariants (all three forms) next to one compiled GLRK2-symmetric step of the same points
    loop = invariants.loop("guiding_centre", 2000)
    surf = invariants.surface("guiding_centre", 100, 100)

    def timed(f, reps=5):
        f()
        t0 = time.perf_counter()
        for _ in range(reps):
            f()
        return (time.perf_counter() - t0) / reps

    lam_l, lam_s = 1e-3 * np.ones_like(loop), 1e-3 * np.ones_like(surf)
    t_I1 = timed(lambda: [invariants.first_invariant(loop, fm, system=gc, p=gc.theta(loop), lam=lam_l, h=h)
                          for fm in invariants.FORMS])
    t_I2 = timed(lambda: [invariants.second_invariant(surf, fm, system=gc, p=gc.theta(surf), lam=lam_s, h=h)
                          for fm in invariants.FORMS])
    r_loop, _ = compiled_rate(gc, loop, "GLRK2", "symmetric", h, 10, 1)
    r_surf, _ = compiled_rate(gc, surf.reshape(-1, 4), "GLRK2", "symmetric", h, 10, 1)
    inv = dict(I1_all_forms_2000=t_I1, step_2000=2000 / r_loop, I2_all_forms_100x100=t_I2, step_10000=10000 / r_surf)
    print("invariants vs one compiled GLRK2-symmetric step on one thread [s]:", inv, flush=True)

    pr = cProfile.Profile()
    pr.enable()
    integrators.integrate(gc, q, tableau="GLRK2", projection="symmetric", h=h, steps=20, save_every=5)
    pr.disable()
    buf = io.StringIO()
    pstats.Stats(pr, stream=buf).sort_stats("tottime").print_stats(8)
    profile = buf.getvalue()
    print(profile)

    meta = dict(machine=platform.platform(), processor=platform.processor(), python=platform.python_version(),
                numpy=np.__version__, numba=__import__("numba").__version__, cores=cores, points=args.points,
                steps=args.steps, command=" ".join(["python", "scripts/studies/benchmarks_core.py"] + sys.argv[1:]))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(dict(meta=meta, rows=rows, single=single, tokamak=tokamak,
                                              startup=dict(empty_cache=first, cached=cached),
                                              memory_bytes_per_point=peak / n_mem, invariants=inv,
                                              profile=profile), indent=1))


if __name__ == "__main__":
    main()
