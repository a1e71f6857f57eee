"""Batched Newton iteration with a per-point convergence mask.

Each point iterates until its own update is below ``tol`` (relative to its own
scale) or stops shrinking at round-off level; converged points leave the active
set, so a point's iterates never depend on the other points in the batch.
"""
from __future__ import annotations

import numpy as np

EPS = np.finfo(float).eps


def solve_batched(J, r):
    """Solve J x = r for a stack of matrices; singular systems give NaN rows instead of raising.

    J : (n, m, m), r : (n, m) -> (n, m)
    """
    try:
        return np.linalg.solve(J, r[..., None])[..., 0]
    except np.linalg.LinAlgError:
        out = np.full_like(r, np.nan)
        for k in range(J.shape[0]):  # rare path: isolate the singular points
            try:
                out[k] = np.linalg.solve(J[k], r[k])
            except np.linalg.LinAlgError:
                pass
        return out


def newton(fun, z0, scale, *, tol=4 * EPS, stall=1e-10, maxiter=30):
    """Solve fun(idx, z)[0] = 0 for every row of z.

    Parameters
    ----------
    fun : callable(idx, z) -> (r, J); idx (m,) indices of active rows, z (m, nz),
          r (m, nz) residuals, J (m, nz, nz) Jacobians
    z0 : (n, nz) initial guess (not modified)
    scale : (n, nz) positive scale of each unknown
    tol : converged when max |δ|/scale ≤ tol
    stall : also converged when max |δ|/scale ≤ stall and the update no longer
            halves (the iteration has reached its round-off floor)

    Returns
    -------
    z : (n, nz) solution, converged : (n,) bool, iterations : (n,) int
    """
    z = z0.copy()
    n = z.shape[0]
    converged = np.zeros(n, dtype=bool)
    failed = np.zeros(n, dtype=bool)
    iterations = np.zeros(n, dtype=np.int64)
    previous = np.full(n, np.inf)
    active = np.arange(n)
    for _ in range(maxiter):
        if active.size == 0:
            break
        r, J = fun(active, z[active])
        delta = solve_batched(J, -r)
        z[active] += delta
        iterations[active] += 1
        size = np.max(np.abs(delta) / scale[active], axis=1)
        bad = ~np.isfinite(size) | ~np.all(np.isfinite(z[active]), axis=1)
        done = (size <= tol) | ((size <= stall) & (size > 0.5 * previous[active]))
        done &= ~bad
        previous[active] = size
        converged[active[done]] = True
        failed[active[bad]] = True
        active = active[~(done | bad)]
    return z, converged, iterations
