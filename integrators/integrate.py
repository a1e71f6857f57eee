"""`integrate`: advance many points with one (tableau, projection) pair.

The state of a point is (q, p, Λ, compensation terms, last stage values).  Every
step advances all live points together; a point whose step fails (Newton does not
converge, a value is not finite, or q leaves the system's domain) is frozen at
its last good state and its ``breakdown_time`` is set to the time the failed step
was aiming for.  The others go on.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

from .projections import Stepper
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

    @property
    def mean_newton_iterations(self) -> float:
        """Mean Newton iterations per point-step."""
        taken = self.steps_taken.sum()
        return float(self.newton_iterations.sum() / taken) if taken else math.nan


class State:
    """Mutable per-point state of a run (all arrays have a leading points axis)."""

    def __init__(self, q, p, lam, h, s):
        n, d = q.shape
        self.q = q.copy()
        self.p = p.copy()
        self.Lam = h * lam
        self.q_comp = np.zeros_like(q)
        self.p_comp = np.zeros_like(q)
        self.Y = np.zeros((n, s, d))              # stage displacements of the last step
        self.mu = np.zeros_like(q)
        self.have_history = np.zeros(n, dtype=bool)
        self.live = np.ones(n, dtype=bool)
        self.breakdown_time = np.full(n, np.inf)
        self.iterations = np.zeros(n, dtype=np.int64)
        self.steps = np.zeros(n, dtype=np.int64)
        # inverse Jacobians of the last step's solve, reused by the next one (allocated at the
        # first step, when the size of the step's system is known); not part of a checkpoint:
        # call forget_jacobians() wherever a run may be resumed from, so that a resumed run is
        # bitwise the run it continues
        self.jinv = None
        self.have_jinv = np.zeros(n, dtype=bool)

    def forget_jacobians(self):
        """Start every point's next solve from a fresh Jacobian."""
        self.have_jinv[:] = False


def _kahan(x, comp, inc):
    """Compensated x + inc; returns (new x, new compensation)."""
    y = inc + comp
    t = x + y
    return t, y - (t - x)


def _attempt(stepper, state, idx, guess, mu0, reuse=True):
    """One step for the points idx from the given guesses; returns (ok, new values)."""
    sysm = stepper.system
    q = state.q[idx]
    if state.jinv is None or state.jinv.shape[1] != stepper.nz:
        state.jinv = np.empty((state.q.shape[0], stepper.nz, stepper.nz))
        state.have_jinv[:] = False
    known = state.have_jinv[idx] if reuse else np.zeros(idx.size, dtype=bool)
    # while every point is live, Newton refreshes the inverses in place (no gather, no copy back)
    jinv = state.jinv if idx.size == state.q.shape[0] else state.jinv[idx]
    with np.errstate(all="ignore"):
        res = stepper.step(q, state.p[idx], state.Lam[idx], guess, mu0, jinv, known)
        q_new, qc_new = _kahan(q, state.q_comp[idx], res.inc_q)
        if res.inc_p is None:
            p_new, pc_new = res.p, state.p_comp[idx]
        else:
            p_new, pc_new = _kahan(state.p[idx], state.p_comp[idx], res.inc_p)
        ok = res.ok & sysm.in_domain(q_new) & np.all(np.isfinite(p_new), axis=1)
        ok &= np.all(np.isfinite(res.Lam), axis=1)
    return ok, (q_new, qc_new, p_new, pc_new, res)


def _commit(state, idx, ok, new):
    q_new, qc_new, p_new, pc_new, res = new
    good = idx[ok]
    state.q[good], state.q_comp[good] = q_new[ok], qc_new[ok]
    state.p[good], state.p_comp[good] = p_new[ok], pc_new[ok]
    state.Lam[good] = res.Lam[ok]
    state.Y[good] = res.Y[ok]
    if res.mu is not None:
        state.mu[good] = res.mu[ok]
    state.have_history[good] = True
    if res.jinv is not state.jinv:
        state.jinv[good] = res.jinv[ok]
    state.have_jinv[idx] = ok
    state.iterations[idx] += res.iterations
    state.steps[good] += 1


CHUNK = 20000    # points advanced together; larger batches spill out of the cache (docs/benchmarks.md)


def advance(stepper: Stepper, state: State, t_next: float, chunk: int = CHUNK):
    """Advance every live point of ``state`` by one step (in place), ``chunk`` points at a time.

    A point whose step fails from the extrapolated guess (and the last step's Jacobian) is
    tried once more from the vector-field guess h·q̇(q_n) and a fresh Jacobian before it is
    declared broken down.  The chunking changes no bits (a point's step does not depend on its
    batch); it keeps the working arrays small: at 200,000 points one batch runs at 99k
    point-steps/s, chunks of 20,000 at 136k.
    """
    live = np.flatnonzero(state.live)
    for k in range(0, live.size, chunk):
        _advance(stepper, state, live[k:k + chunk], t_next)


def _advance(stepper, state, idx, t_next):
    if idx.size == 0:
        return
    fresh = ~state.have_history[idx]
    guess = stepper.extrapolate(state.Y[idx])
    if fresh.any():
        guess[fresh] = stepper.first_guess(state.q[idx[fresh]])
    ok, new = _attempt(stepper, state, idx, guess, state.mu[idx])
    _commit(state, idx, ok, new)
    retry = ~ok & ~fresh
    if retry.any():
        ridx = idx[retry]
        ok_r, new_r = _attempt(stepper, state, ridx, stepper.first_guess(state.q[ridx]), np.zeros_like(state.q[ridx]),
                              reuse=False)
        _commit(state, ridx, ok_r, new_r)
        ok[retry] = ok_r
    bad = idx[~ok]
    state.live[bad] = False
    state.breakdown_time[bad] = t_next


def _as_points(q0, d, what):
    q0 = np.array(q0, dtype=float)
    if q0.ndim == 1:
        q0 = q0[None, :]
    if q0.ndim != 2 or q0.shape[1] != d:
        raise ValueError(f"{what} must have shape (d,) or (npoints, d) with d = {d}, got {np.shape(q0)}")
    return q0


def integrate(system, q0, tableau="GLRK2", projection="symmetric", h=None, steps=100, save_every=1,
              p0=None, lam0=None, t0=0.0, progress: Callable[[int, int], None] | None = None,
              chunk: int | None = None) -> Solution:
    """Integrate points of a degenerate Lagrangian system with a (projected) VPRK method.

    Parameters
    ----------
    system : System
    q0 : (d,) or (npoints, d) initial positions, finite and inside the system's domain
    tableau : Tableau or built-in name
    projection : 'none' | 'standard' | 'symmetric' | 'symplectic' | 'midpoint'
    h : time step (default: the system's paper value); may be negative
    steps : number of steps; save_every : output cadence in steps
    p0 : (npoints, d) initial momenta (default ϑ(q0); only 'none' can start off the constraint)
    lam0 : (npoints, d) initial λ for the symplectic projection (default 0)
    progress : optional callback(step, steps)
    chunk : advance the points in chunks of this size (results are bitwise the same)

    Returns
    -------
    Solution
    """
    tab = tableau if isinstance(tableau, Tableau) else builtin_tableau(tableau)
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
    steps, save_every = int(steps), int(save_every)
    q0 = _as_points(q0, system.d, "q0")
    bad = ~system.in_domain(q0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"initial point {k} = {q0[k].tolist()} is not finite or outside the domain of {system.name}")
    p0 = system.theta(q0) if p0 is None else _as_points(p0, system.d, "p0")
    lam0 = np.zeros_like(q0) if lam0 is None else _as_points(lam0, system.d, "lam0")
    stepper = Stepper(system, tab, projection, h)
    n = q0.shape[0]
    nsave = steps // save_every + 1
    out_t = t0 + h * save_every * np.arange(nsave)
    out_q = np.empty((nsave, n, system.d))
    out_p = np.empty_like(out_q)
    out_l = np.empty_like(out_q)
    chunk = n if not chunk else int(chunk)
    states = [State(q0[k:k + chunk], p0[k:k + chunk], lam0[k:k + chunk], h, tab.s) for k in range(0, n, chunk)]

    def record(k):
        out_q[k] = np.concatenate([st.q for st in states])
        out_p[k] = np.concatenate([st.p for st in states])
        out_l[k] = np.concatenate([st.Lam for st in states]) / h

    record(0)
    for step in range(1, steps + 1):
        for st in states:
            advance(stepper, st, t0 + step * h)
        if step % save_every == 0:
            record(step // save_every)
            for st in states:     # as the driver does at its checkpoints: same bits as a scene run
                st.forget_jacobians()
        if progress is not None:
            progress(step, steps)
    cat = lambda name: np.concatenate([getattr(st, name) for st in states])
    return Solution(t=out_t, q=out_q, p=out_p, lam=out_l, breakdown_time=cat("breakdown_time"),
                    newton_iterations=cat("iterations"), steps_taken=cat("steps"),
                    tableau=tab.name, projection=projection, h=h)
