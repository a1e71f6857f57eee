"""The compiled engine's results and speed, for comparing two versions of the kernel side by side.

    python scripts/tools/engine_bits.py dump FILE.npz [PREDICTOR | undithered | unsettled]   # every admissible pair on three systems, 15 steps
    python scripts/tools/engine_bits.py compare A.npz B.npz
    python scripts/tools/engine_bits.py speed [PAIR ...]   # point-steps/s, 10^4 points, 1 thread, best of 3

Run ``dump`` and ``speed`` on each version (e.g. in a clone checked out at the older commit, with its
own numba cache), then ``compare``.  The change that made Newton's tolerances runtime data was
checked this way: 1,710 arrays (q, p, Λ, iterations, breakdown times of 342 pairs) bitwise equal;
GLRK2-symmetric 359-365k against 358-363k point-steps/s and GLRK1-none 1.11M against 1.11-1.13M
(docs/engine.md)."""
import sys
import time

import numpy as np

import integrators
import invariants
from integrators.projections import admission


def dump(path, predictor=None):
    """``predictor``: Tolerances.predictor (None: the default); "extrapolate" gives the bits of the
    engine before issue 55, to compare with a dump made there; "undithered" the default rule without
    the dithered approach (``Tolerances(dither=False, settle=False)``), the engine's bits before it; "unsettled" the
    default without the settled approach (``Tolerances(settle=False)``), the engine's bits before it
    was the default."""
    tol = integrators.Tolerances() if predictor is None else integrators.Tolerances(dither=False, settle=False) \
        if predictor == "undithered" else integrators.Tolerances(settle=False) if predictor == "unsettled" \
        else integrators.Tolerances(predictor=predictor)
    out = {}
    cases = (("guiding_centre_symmetric", 10.0, invariants.loop("guiding_centre", 64)),
             ("point_vortices", 0.1, np.array([[1, 0.1, 1, -0.1]])
              + 1e-3 * np.random.default_rng(1).standard_normal((16, 4))),
             ("lotka_volterra_2d", 0.1, np.array([[1.0, 1.0]]) + 0.1 * np.random.default_rng(2).random((16, 2))))
    for name, h, q0 in cases:
        sy = integrators.system(name)
        for tab in integrators.TABLEAU_NAMES:
            T = integrators.tableau(tab)
            for proj in integrators.PROJECTIONS:
                if admission(T, proj):
                    continue
                e = integrators.Engine(sy, T, proj, h, tolerances=tol)
                st = e.state(q0)
                e.advance(st, 1, 15)
                for f in ("q", "p", "Lam", "iterations", "breakdown_time"):
                    out[f"{name}/{tab}/{proj}/{f}"] = getattr(st, f).copy()
    np.savez(path, **out)
    print(f"wrote {len(out)} arrays to {path}")


def compare(a, b):
    A, B = np.load(a), np.load(b)
    differ = [k for k in A if k not in B or not np.array_equal(A[k], B[k], equal_nan=True)]
    print(f"{len(A)} arrays, {len(differ)} differ" + (f": {differ[:10]}" if differ else ""))
    if differ:
        _moved(A, B, differ)
    return 1 if differ or set(A) != set(B) else 0


def _moved(A, B, differ):
    """How far the arrays that differ moved: the largest difference of q, p and Λ relative to the
    engine's scale, max(largest |value| of the array, 1) (Λ of round-off size reads as absolute),
    where both are finite; the breakdown times that changed, and the
    Newton iterations summed over every pair in each file."""
    for f in ("q", "p", "Lam"):
        keys = [k for k in differ if k.endswith("/" + f) and k in B]
        rel = [(np.nanmax(np.abs(A[k] - B[k])) / max(np.nanmax(np.abs(A[k])), 1.0), k) for k in keys
               if np.isfinite(A[k]).all() and np.isfinite(B[k]).all()]
        if rel:
            r, k = max(rel)
            print(f"  {f}: {len(keys)} differ, at most {r:.2g} of scale ({k})")
    moved = [k for k in differ if k.endswith("/breakdown_time")]
    print(f"  breakdown times moved in {len(moved)} pairs" + (f": {moved[:10]}" if moved else ""))
    its = [sum(float(np.sum(X[k])) for k in X if k.endswith("/iterations")) for X in (A, B)]
    print(f"  Newton iterations: {its[0]:,.0f} -> {its[1]:,.0f} ({its[1] / its[0]:.3f})")


def speed(pairs=("GLRK2-symmetric", "GLRK2-symplectic", "GLRK1-none")):
    """guiding_centre_symmetric at h = 10 from 10⁴ points of its default loop: 10 steps after 2."""
    integrators.set_threads(1)
    sy = integrators.system("guiding_centre_symmetric")
    q0 = invariants.loop("guiding_centre", 10000)
    for tab, proj in (p.split("-") for p in pairs):
        e = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0)
        best = []
        for _ in range(3):
            st = e.state(q0)
            e.advance(st, 1, 2)
            t = time.perf_counter()
            e.advance(st, 3, 10)
            best.append(time.perf_counter() - t)
        print(f"{tab}-{proj}: {10 * 10000 / min(best):,.0f} point-steps/s")


if __name__ == "__main__":
    cmd = sys.argv[1:2]
    if cmd == ["dump"] and len(sys.argv) in (3, 4):
        dump(*sys.argv[2:])
    elif cmd == ["compare"] and len(sys.argv) == 4:
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    elif cmd == ["speed"]:
        speed(*([sys.argv[2:]] if len(sys.argv) > 2 else []))
    else:
        sys.exit(__doc__)
