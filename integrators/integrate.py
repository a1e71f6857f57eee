"""`integrate`: advance many points with one (tableau, projection) pair.

The points go through the compiled engine (integrators/engine.py): a point whose step fails
(Newton does not converge, a value is not finite, or q leaves the system's domain) is frozen at
its last good state and its ``breakdown_time`` is set to the time the failed step was aiming
for.  The others go on.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

from .ddouble import divide_array
from .engine import BLOCK, PRECISIONS, Engine, Hooks, Tolerances, march
from .tableaus import Tableau, tableau as builtin_tableau


@dataclasses.dataclass
class Solution:
    """Result of :func:`integrate`.

    Attributes
    ----------
    t : (nsave,) output times
    q, p : (nsave, npoints, d) positions and momenta (p as the method computes it;
        for projected methods p = ϑ(q) up to round-off)
    lam : (nsave, npoints, d) Lagrange multipliers λ (zero without projection)
    breakdown_time : (npoints,) time of the first failed step, inf if none
    newton_iterations : (npoints,) Newton iterations summed over all steps taken
    steps_taken : (npoints,) number of successful steps
    tableau, projection, h : what produced it
    precision : "double" or "double-double"
    q_lo, p_lo, lam_lo : with ``precision="double-double"``, the low parts: the result is the exact
        sum q + q_lo (each pair a double-double, integrators/ddouble.py); None in double
    """

    t: np.ndarray
    q: np.ndarray
    p: np.ndarray
    lam: np.ndarray
    breakdown_time: np.ndarray
    newton_iterations: np.ndarray
    steps_taken: np.ndarray
    tableau: str
    projection: str
    h: float
    precision: str = "double"
    q_lo: np.ndarray | None = None
    p_lo: np.ndarray | None = None
    lam_lo: np.ndarray | None = None

    @property
    def mean_newton_iterations(self) -> float:
        """Mean Newton iterations per point-step."""
        taken = self.steps_taken.sum()
        return float(self.newton_iterations.sum() / taken) if taken else math.nan


def _as_points(q0, d, what):
    q0 = np.array(q0, dtype=float)
    if q0.ndim == 1:
        q0 = q0[None, :]
    if q0.ndim < 2 or q0.shape[-1] != d:
        raise ValueError(f"{what} must have shape (d,), (npoints, d) or (..., d) with d = {d}, got {np.shape(q0)}")
    return q0


def _checked_steps(system, h, steps, save_every):
    """(h, steps, save_every) as numbers the run can take (h: the system's default if None)."""
    if h is None:
        h = system.defaults.get("h")
        if h is None:
            raise ValueError("h not given and the system has no default")
    h = float(h)
    if not math.isfinite(h) or h == 0.0:
        raise ValueError(f"h must be finite and non-zero, got {h}")
    if int(steps) != steps or steps < 0:
        raise ValueError(f"steps must be a non-negative integer, got {steps}")
    if int(save_every) != save_every or save_every < 1:
        raise ValueError(f"save_every must be a positive integer, got {save_every}")
    return h, int(steps), int(save_every)


def _checked_points(system, q0, p0, lam0):
    """(q0 as (n, d), the set's leading shape, p0 as (n, d) or None for ϑ(q0), λ0 as (n, d)); every
    initial point finite and inside the domain."""
    q0 = _as_points(q0, system.d, "q0")
    lead = q0.shape[:-1]                    # a loop (N,) or a surface (nσ, nτ): the set's shape travels along
    q0 = q0.reshape(-1, system.d)
    bad = ~system.in_domain(q0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"initial point {k} = {q0[k].tolist()} is not finite or outside the domain of {system.name}")
    p0 = None if p0 is None else _as_points(p0, system.d, "p0").reshape(q0.shape)
    lam0 = np.zeros_like(q0) if lam0 is None else _as_points(lam0, system.d, "lam0").reshape(q0.shape)
    return q0, lead, p0, lam0


def integrate(system, q0, *, tableau="GLRK2", projection="symmetric", h=None, steps=100, save_every=1,
              p0=None, lam0=None, t0=0.0, progress: Callable[[int, int], None] | None = None,
              chunk: int | None = None, precision: str = "double", tolerances: Tolerances | None = None) -> Solution:
    """Integrate points of a degenerate Lagrangian system with a (projected) VPRK method.

    Every argument after ``q0`` is keyword-only: ``integrate(system, q0, tableau="GLRK4",
    projection="midpoint", h=0.1, steps=1000)``.

    Parameters
    ----------
    system : System
    q0 : (d,), (npoints, d) or (..., d) initial positions, finite and inside the system's domain; the
        solution keeps the leading shape, so a surface (nσ, nτ, d) comes back as (nsave, nσ, nτ, d)
        and ``invariants.along(solution, ...)`` gives its I₂ at every saved time
    tableau : Tableau or built-in name
    projection : 'none' | 'standard' | 'symmetric' | 'symplectic' | 'midpoint', or a
        :class:`integrators.projections.Projection` record of one's own (docs/engine.md, "Adding a
        projection")
    h : time step (default: the system's paper value); may be negative
    steps : number of steps; save_every : output cadence in steps
    p0 : (npoints, d) initial momenta (default ϑ(q0); only 'none' can start off the constraint)
    lam0 : (npoints, d) initial λ for the symplectic projection (default 0)
    progress : optional callback(step, steps)
    chunk : points per block of the engine's thread loop (results are bitwise the same for any)
    precision : ``"double"`` or ``"double-double"``: the same kernel on double-double numbers
        (about 32 digits; integrators/ddouble.py), in lanes as double is, Newton to a few
        double-double ulps; q0, p0, lam0 are taken exactly as doubles, p0 defaults to ϑ(q0) in
        double-double, and every state comes back as two arrays whose exact sum is the result
        (``q`` and ``q_lo``, ``p`` and ``p_lo``, ``lam`` and ``lam_lo``).
    tolerances : Newton's stopping and refresh rule (:class:`integrators.Tolerances`; default the
        engine's).  ``Tolerances(refresh=0.1)`` refreshes the Jacobian less often: one orbit of
        GLRK4- and GLRK6-symmetric 1.13x and 1.37x faster, GLRK1-none 0.90x, in last bits of its
        own (docs/benchmarks-history.md, "the levers that change bits")

    Returns
    -------
    Solution
    """
    tab = tableau if isinstance(tableau, Tableau) else builtin_tableau(tableau)
    h, steps, save_every = _checked_steps(system, h, steps, save_every)
    q0, lead, p0, lam0 = _checked_points(system, q0, p0, lam0)
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be 'double' or 'double-double', got {precision!r}")
    if chunk is not None and (not float(chunk).is_integer() or int(chunk) < 1):
        raise ValueError(f"chunk must be a positive whole number of points, got {chunk!r}")
    engine = Engine(system, tab, projection, h, precision=precision, tolerances=tolerances)
    state = engine.state(q0, p0, lam0)         # (double-double: the doubles taken exactly, ϑ(q0) in double-double)
    n = q0.shape[0]
    nsave = steps // save_every + 1
    out_t = t0 + h * save_every * np.arange(nsave)
    dd = precision == "double-double"
    out_q = np.empty((nsave, n, system.d) + ((2,) if dd else ()))
    out_p = np.empty_like(out_q)
    out_l = np.empty_like(out_q)

    def record(step, out=None):
        k = step // save_every
        at = state if out is None else out       # (an engine.Output inside a longer call: the same values)
        out_q[k], out_p[k] = at.q, at.p
        out_l[k] = divide_array(at.Lam, h) if dd else at.Lam / h

    record(0)
    march(engine, state, 0, steps, save_every,
          Hooks(on_output=record, progress=None if progress is None else (lambda step: progress(step, steps)),
                light=lambda step: True), t0=t0, block=int(chunk) if chunk is not None else BLOCK)
    full = (nsave,) + lead + (system.d,)
    lo = {}
    if dd:
        lo = dict(q_lo=out_q[..., 1].reshape(full), p_lo=out_p[..., 1].reshape(full),
                  lam_lo=out_l[..., 1].reshape(full))
        out_q, out_p, out_l = out_q[..., 0], out_p[..., 0], out_l[..., 0]
    return Solution(t=out_t, q=out_q.reshape(full), p=out_p.reshape(full), lam=out_l.reshape(full),
                    breakdown_time=state.breakdown_time.reshape(lead).copy(),
                    newton_iterations=state.iterations.reshape(lead).copy(), steps_taken=state.steps.reshape(lead).copy(),
                    tableau=tab.name, projection=engine.record.name, h=h, precision=precision, **lo)
