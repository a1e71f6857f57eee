"""Batched Newton iteration with a per-point convergence mask.

Each point iterates until its own update is below ``tol`` (relative to its own
scale) or stops shrinking at round-off level; converged points leave the active
set, so a point's iterates never depend on the other points in the batch.
"""
from __future__ import annotations

import numpy as np

EPS = np.finfo(float).eps
COMPLEX_STEP = 1e-30   # the audit's complex-step size: imaginary parts are derivatives × this


def invert_batched(J):
    """Inverses of a stack of matrices; a singular matrix gives a NaN inverse instead of raising.

    J : (n, m, m) -> (n, m, m).  Each matrix is inverted on its own (LAPACK per matrix), so the
    result for one point does not depend on the others.
    """
    try:
        return np.linalg.inv(J)
    except np.linalg.LinAlgError:
        out = np.full_like(J, np.nan)
        for k in range(J.shape[0]):  # rare path: isolate the singular points
            try:
                out[k] = np.linalg.inv(J[k])
            except np.linalg.LinAlgError:
                pass
        return out


def apply_batched(M, r):
    """M r for stacks (n, m, m) and (n, m).

    numpy's stacked matmul multiplies each matrix by its vector on its own, so a point's
    bits do not depend on the batch (tests/test_integrate.py checks this bitwise).
    """
    return np.matmul(M, r[..., None])[..., 0]


def newton(fun, z0, scale, *, tol=4 * EPS, stall=1e-10, maxiter=40, refresh=0.03, jinv=None, known=None):
    """Solve fun(idx, z)[0] = 0 for every row of z.

    Newton's method with the exact Jacobian, kept while it works: the Jacobian is evaluated
    and inverted at the first iteration (unless the caller hands in an inverse from the last
    step, ``jinv``/``known``) and again for any point whose update shrank by less than the
    factor ``refresh`` in its last iteration.  Between refreshes an iteration costs one
    residual evaluation and a matrix–vector product.  Every decision is per point, so a
    point's iterates never depend on the rest of the batch.  ``refresh = 0.03`` (rather than
    0.25) halves the cost of a Lotka–Volterra step, where a carried Jacobian often contracts by
    only 0.1–0.2 per iteration (13.5 → 5.7 iterations per step), and changes nothing measurable
    for the guiding centre (docs/benchmarks.md, history item 6).

    Parameters
    ----------
    fun : callable(idx, z, jacobian) -> (r, J, extras); idx (m,) indices of active rows,
          z (m, nz), r (m, nz) residuals, J (m, nz, nz) Jacobians (None when ``jacobian`` is
          False), extras a dict of (m, ...) arrays computed along with the residual
    z0 : (n, nz) initial guess (not modified)
    scale : (n, nz) positive scale of each unknown
    jinv : optional (n, nz, nz) inverse Jacobians to start from (e.g. the last step's); it is
           updated in place with every refresh, so the caller can carry it to the next solve
    known : (n,) bool, rows of ``jinv`` that hold a usable inverse (the others start fresh)
    tol : converged when max |δ|/scale ≤ tol.  For complex z (complex-step derivatives, used by
          the audit, perturbations i·COMPLEX_STEP) the imaginary part, read as a derivative, must
          meet the same test.
    stall : also converged when max |δ|/scale ≤ stall and the update no longer
            halves (the iteration has reached its round-off floor)

    Returns
    -------
    z : (n, nz) solution: the last iterate at which the residual was evaluated, whose
        Newton update was below tolerance
    converged : (n,) bool, iterations : (n,) int
    extras : dict of (n, ...) arrays, ``fun``'s extras at that iterate
    """
    z = z0.copy()
    n, nz = z.shape
    complex_step = np.iscomplexobj(z)
    if complex_step:      # derivatives: accept a round-off floor only when it is a tight one
        stall = min(stall, 1e-13)
    converged = np.zeros(n, dtype=bool)
    iterations = np.zeros(n, dtype=np.int64)
    previous = np.full(n, np.inf)
    if jinv is None:
        Jinv = np.empty((n, nz, nz), dtype=z.dtype)
        stale = np.ones(n, dtype=bool)       # needs a fresh Jacobian
    else:
        Jinv = jinv
        stale = np.ones(n, dtype=bool) if known is None else ~known
    z_eval = z.copy()
    extras = {}

    def keep(rows, ex):
        for key, val in ex.items():
            if key not in extras:
                extras[key] = np.full((n,) + val.shape[1:], np.nan, dtype=val.dtype)
            extras[key][rows] = val
    active = np.arange(n)
    for _ in range(maxiter):
        if active.size == 0:
            break
        everyone = active.size == n          # plain views instead of gathers while all iterate
        sel = slice(None) if everyone else active
        za = z[sel]
        fresh = stale[sel]
        z_eval[sel] = za
        if fresh.all():
            r, J, ex = fun(active, za, True)
            keep(sel, ex)
            if everyone:
                Jinv[...] = invert_batched(J)
            else:
                Jinv[active] = invert_batched(J)
        else:
            r = np.empty_like(za)
            if fresh.any():
                r[fresh], J, ex = fun(active[fresh], za[fresh], True)
                keep(active[fresh], ex)
                Jinv[active[fresh]] = invert_batched(J)
            r[~fresh], _, ex = fun(active[~fresh], za[~fresh], False)
            keep(active[~fresh], ex)
        delta = -apply_batched(Jinv[sel], r)
        za = za + delta
        z[sel] = za
        iterations[sel] += 1
        size = np.max(np.abs(delta.real) / scale[sel], axis=1)
        if complex_step:       # the derivative (imaginary part) must converge too, to its own scale
            size = np.maximum(size, np.max(np.abs(delta.imag) / (COMPLEX_STEP * scale[sel]), axis=1))
        prev = previous[sel]
        bad = ~np.isfinite(size) | ~np.all(np.isfinite(za), axis=1)
        with np.errstate(invalid="ignore"):
            theta = np.where(np.isfinite(prev), size / prev, np.inf)   # contraction; unknown at first
        # converged: the update is below tol, or a round-off floor is reached.  (Stopping on the
        # error predicted from the contraction, θ/(1 − θ)·|δ|, left constraint errors of 1e-12.)
        done = (size <= tol) | ((size <= stall) & np.isfinite(theta) & (theta > 0.5))
        done &= ~bad
        stale[sel] = np.isfinite(theta) & (theta > refresh)
        previous[sel] = size
        converged[active[done]] = True
        active = active[~(done | bad)]
    return z_eval, converged, iterations, extras
