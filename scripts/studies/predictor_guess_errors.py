"""How close each stage guess comes, offline: polynomial extrapolation of the defects against a fitted linear recurrence.

    python scripts/studies/predictor_guess_errors.py            # both tables (~1 min)

The engine's predictor (docs/engine.md, "The predictor") guesses the next step's stages as the base
(the last step's stages extrapolated) plus a prediction of the base's error, the defect δ. This
script records the stage sequences of the old rule (``Tolerances(predictor="extrapolate")``, whose
steps do not depend on any guess of the defects), forms the defects δ_{n+1} = Y_{n+1} − base_n
(and the changes of Λ where the projection solves for it) and measures, step by step, the median of
max |prediction − δ_{n+1}| / max(|q|, 1) for

* ``order k``: the polynomial through the last k defects, one step on (k = 1, 2, 4, 6, 8);
* ``recurrence``: δ_j ≈ c_1 δ_{j−1} + … + c_4 δ_{j−4} fitted by least squares over the last 8
  defects (normal equations with a ridge of 10⁻¹⁴ of their trace, as ``kernel._recurrence``; here
  on every component, where the kernel fits the first stage's and applies the coefficients to all).

1. **protocol**: the 16 points near the default loop of guiding_centre_symmetric (h = 10; the
   benchmark protocol, ``np.random.default_rng(1)``), steps 20–58, median over points and steps.
2. **systems**: one point of each system from its default start, steps 40–148.

numpy only, in double: the errors below about 10⁻¹⁶ relative are the fit's round-off, not the
kernel's (docs/engine.md cites these tables).
"""
import argparse
from math import comb

import numpy as np

import integrators
import invariants
from integrators.engine import predictor as stage_predictor
from integrators.engine import set_threads

ORDERS = (1, 2, 4, 6, 8)


def defects(system, tab, proj, h, q0, steps):
    """(δ (steps − 1, points, components), scale (points,)) from the old rule's stage sequences."""
    e = integrators.Engine(system, integrators.tableau(tab), proj, h,
                           tolerances=integrators.Tolerances(predictor="extrapolate"))
    st = e.state(q0)
    Y, L = [], []
    for n in range(steps):
        e.advance(st, 1 + n, 1, lanes=1)
        Y.append(st.Y.reshape(len(q0), -1).copy())
        L.append(st.Lam.copy())
    Y, L = np.array(Y), np.array(L)
    s, d = e.tableau.s, system.d
    E = stage_predictor(e.tableau.c, "extrapolate")[:, :s]
    base = np.einsum("ij,npjm->npim", E, Y.reshape(len(Y), len(q0), s, d)).reshape(Y.shape)
    D = Y[1:] - base[:-1]
    if proj != "none":
        D = np.concatenate([D, L[1:] - L[:-1]], axis=-1)
    return D, np.maximum(1.0, np.max(np.abs(st.q), axis=1))


def polynomial(D, n, k):
    """δ_{n+1} from the polynomial through δ_{n−k+1} … δ_n (Newton's backward form, one step on)."""
    return sum((-1) ** j * comb(k, j + 1) * D[n - j] for j in range(k))


def recurrence(D, n, m=4, history=8):
    """δ_{n+1} from the recurrence of m coefficients fitted over the last ``history`` defects."""
    js = range(n - (history - m) + 1, n + 1)
    A = np.vstack([np.stack([D[j - k] for k in range(1, m + 1)], axis=1) for j in js])
    b = np.concatenate([D[j] for j in js])
    G = A.T @ A
    c = np.linalg.solve(G + 1e-14 * np.trace(G) / m * np.eye(m), A.T @ b)
    return sum(c[k - 1] * D[n + 1 - k] for k in range(1, m + 1))


def errors(D, scale, first, last):
    """{name: median relative error} over the points and the steps n = first … last − 1."""
    out = {f"order {k}": [] for k in ORDERS} | {"recurrence": []}
    for p in range(D.shape[1]):
        Dp = D[:, p]
        for n in range(first, last):
            for k in ORDERS:
                out[f"order {k}"].append(np.max(np.abs(polynomial(Dp, n, k) - Dp[n + 1])) / scale[p])
            out["recurrence"].append(np.max(np.abs(recurrence(Dp, n) - Dp[n + 1])) / scale[p])
    return {k: float(np.median(v)) for k, v in out.items()}


def show(label, err):
    best = min(ORDERS, key=lambda k: err[f"order {k}"])
    print(f"{label}: recurrence {err['recurrence']:.1e}; order 8 {err['order 8']:.1e}; best order {best} "
          f"{err[f'order {best}']:.1e}  (" + ", ".join(f"{k} {v:.1e}" for k, v in err.items()) + ")", flush=True)


def main():
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    set_threads(1)
    gc = integrators.system("guiding_centre_symmetric")
    rng = np.random.default_rng(1)
    q0 = invariants.loop("guiding_centre", 16) + 1e-3 * rng.standard_normal((16, 4))
    print("1. protocol: 16 points near the loop, guiding_centre_symmetric, h = 10, steps 20-58")
    for tab, proj in (("GLRK2", "symmetric"), ("GLRK1", "none"), ("SRK3", "symplectic")):
        D, scale = defects(gc, tab, proj, 10.0, q0, 60)
        show(f"   {tab}-{proj}", errors(D, scale, 20, len(D) - 1))
    print("2. systems: one point from the default start, steps 40-148")
    loop1 = invariants.loop("guiding_centre", 8)[:1]
    for name, h, tab, proj in (("guiding_centre_symmetric", 10.0, "GLRK1", "none"),
                               ("guiding_centre_symmetric", 10.0, "SRK3", "symplectic"),
                               ("guiding_centre_tokamak", 2.5, "GLRK2", "symmetric"),
                               ("lotka_volterra_2d", 0.1, "GLRK2", "symmetric"),
                               ("point_vortices", 0.1, "GLRK2", "symmetric")):
        sy = integrators.system(name)
        q = loop1 if name == "guiding_centre_symmetric" else np.array(sy.defaults["q0"], dtype=float)[None]
        D, scale = defects(sy, tab, proj, h, q, 150)
        show(f"   {name}, h = {h:g}, {tab}-{proj}", errors(D, scale, 40, len(D) - 1))


if __name__ == "__main__":
    main()
