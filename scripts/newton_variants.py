"""Stage predictors and Newton refresh thresholds, side by side on the lane engine (docs/benchmarks.md).

    python scripts/newton_variants.py [--points 10000] [--out docs/figures/newton_variants.json]

For each pair: point-steps per second (best of two runs) and Newton iterations per step of the
compiled engine in lanes, one thread, guiding_centre_symmetric at h = 10 with the benchmark's
10⁴ points near the default loop (2 warm-up steps, then 10 steps in one call), for

* the predictor (``Tolerances.predictor``): ``extrapolate``, the Lagrange polynomial through the
  last step's stage values (the default), or ``velocity``, the same with h·q̇(q_n) as one more
  node (one evaluation and a d × d solve a step);
* the Jacobian refresh threshold (``Tolerances.refresh``): 0.01 (the default) and 0.1.

A third variant, extrapolating from two steps, was tried with the numpy engine before the compiled
one existed: no gain for s ≥ 2, and it wrecks the SRK3 guess (integrators/reference.py).
"""
import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

import integrators
import invariants
from integrators.engine import Tolerances, set_threads

ROOT = Path(__file__).resolve().parents[1]
PAIRS = [("GLRK2", "symmetric"), ("GLRK1", "none"), ("SRK3", "symmetric"), ("GLRK4", "symmetric"),
         ("GLRK2", "symplectic"), ("LobIIIA3", "standard")]
VARIANTS = [(p, r) for p in ("extrapolate", "velocity") for r in (0.01, 0.1)]


def measure(sy, q0, tab, proj, predictor, refresh, reps=2):
    eng = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0,
                             tolerances=Tolerances(predictor=predictor, refresh=refresh))
    best, its = 0.0, float("nan")
    for _ in range(reps):
        st = eng.state(q0)
        eng.advance(st, 1, 2)
        i0, s0 = st.iterations.sum(), st.steps.sum()
        t = time.perf_counter()
        eng.advance(st, 3, 10)
        dt = time.perf_counter() - t
        best = max(best, 10 * len(q0) / dt)
        its = (st.iterations.sum() - i0) / (st.steps.sum() - s0)
    return best, float(its)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=10000)
    ap.add_argument("--out", default=str(ROOT / "docs/figures/newton_variants.json"))
    args = ap.parse_args()
    sy = integrators.system("guiding_centre_symmetric")
    rng = np.random.default_rng(0)
    q0 = invariants.loop("guiding_centre", args.points) + 1e-3 * rng.standard_normal((args.points, sy.d))
    set_threads(1)
    rows = []
    for tab, proj in PAIRS:
        row = dict(pair=f"{tab}-{proj}")
        for pred, refresh in VARIANTS:
            rate, its = measure(sy, q0, tab, proj, pred, refresh)
            row[f"{pred}/{refresh}"] = dict(point_steps_per_s=rate, iterations_per_step=its)
        rows.append(row)
        print(f"{row['pair']:>20}: " + " | ".join(
            f"{k} {v['point_steps_per_s']:>10,.0f} ({v['iterations_per_step']:.2f} it.)" for k, v in row.items()
            if k != "pair"), flush=True)
    set_threads(None)
    Path(args.out).write_text(json.dumps(dict(machine=platform.processor() or platform.machine(),
                                              points=args.points, rows=rows), indent=1) + "\n")


if __name__ == "__main__":
    main()
