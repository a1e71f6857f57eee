"""Sample sets that refine themselves (a scene's ``refine_to``): new points started exactly, never interpolated.

A set's levels nest (:func:`invariants.samples.refined_grid`): a loop N → 2N keeps every old τ, a
Chebyshev surface n → 2n − 1 per direction keeps every old point.  So a finer level is the set's
own points plus new ones, and the new ones have analytic initial positions: they are started at
t = 0 and advanced, with the pair's own integrator and step, to the output where they are first
needed (the catch-up), and from then on alongside.  No point is interpolated, and a point's bits
do not depend on when it was started: the engine's result for a point does not depend on its
batch, and the new points are stepped output interval by output interval as the set's own are
(how a run is split into calls changes no bits), so they are bitwise what they would be had the set
been that fine from the start.

At each output the set's invariants are taken on the coarsest level whose resolution monitor
(the largest over the forms) is at most the threshold; if none is, on the finest (and the set is
under-resolved there).  The rule looks at the output alone, not at the outputs before it, so any
rank computing it gets the same level and the same bits, whatever ran before on that rank.

Who advances the new points: the rank that computes the set's invariants for an output (the
set's task owner for that batch, tasks.Tasks.assign) keeps its own copy of each level's new
points and moves it forward to the outputs it is given (they come in increasing order on a
rank).  A refining set's tasks stay on one rank for a whole pair (tasks.Tasks.assign), so on any
number of ranks that is one catch-up and one advance a pair, done by that rank (docs/scenes.md,
"Self-refining sample sets: what the catch-up costs").
"""
from __future__ import annotations

import time

import numpy as np

from invariants.samples import first_level

from ..engine import Hooks, march


class Refiner:
    """One set's finer levels on one rank for one pair: the new points of each level (level ℓ's
    points that level ℓ − 1 lacks), started at t = 0 when first asked for and advanced on demand.

    spec : the scene's set (with ``refine_to``); engine : a callable returning a fresh engine of
    the pair; base : the scene's folder (user shape functions); every : run.output_every;
    check : the run's stop request (checked between the engine's calls).
    """

    def __init__(self, spec, engine, base, h, every, check=None):
        self.spec, self.engine, self.base, self.h, self.every, self.check = spec, engine, base, h, every, check
        self.levels = {}            # ℓ: [engine, state, step]
        self.seconds = 0.0          # spent advancing new points (the catch-up and after)
        self.point_steps = 0

    def new_points(self, level, step):
        """(q, p, λ, live) of level ``level``'s new points at ``step`` (in level ``level``'s
        row-major order), their state advanced there from wherever it was (t = 0 the first time)."""
        if level not in self.levels:
            fine = self.spec.at_level(level)
            q = np.asarray(fine.sample(self.base), dtype=float)
            q = q.reshape(-1, q.shape[-1])[first_level(self.spec.grid, level).ravel() == level]
            eng = self.engine()
            self.levels[level] = [eng, eng.state(np.ascontiguousarray(q)), 0]
        eng, st, at = self.levels[level]
        if step < at:
            raise RuntimeError(f"refinement asked for step {step} after step {at}: outputs out of order")
        if step > at:
            t0 = time.perf_counter()
            march(eng, st, at, step, self.every, Hooks(check=self.check))
            self.seconds += time.perf_counter() - t0
            self.point_steps += (step - at) * st.q.shape[0]
            self.levels[level][2] = step
        q, p, Lam = st.nearest()
        return q, p, Lam / self.h, st.live

    def grid(self, level, step, base_parts):
        """The set's points at level ``level`` (its grid's shape): the set's own points
        (``base_parts``: q, p, λ, live in the set's grid order) and each finer level's new ones."""
        first = first_level(self.spec.grid, level)
        shape = first.shape
        out = []
        news = [self.new_points(lv, step) for lv in range(1, level + 1)]
        for c, x in enumerate(base_parts):
            x = np.asarray(x)
            tail = x.shape[len(self.spec.grid):]
            full = np.empty(shape + tail, dtype=x.dtype)
            full[first == 0] = x.reshape((-1,) + tail)
            for lv, parts in enumerate(news, start=1):
                full[first == lv] = parts[c]
            out.append(full)
        return out


def refined_values(diagnostics, refiner, spec, forms, q, p, lam, live, step, threshold) -> dict:
    """{(invariant, form): (value, resolution, computed, all live)} at the coarsest level of the
    set whose monitor (the largest over ``forms``) is at most ``threshold`` (the finest if none is),
    and {(invariant, 'points'): the points used}.  q, p, λ, live: the set's own points, in its grid's
    shape.  A level with a broken-down or non-finite point ends the search (a finer level cannot
    mend it)."""
    for level in range(spec.levels + 1):
        if level == 0:
            parts = (q, p, lam, live)
        else:
            parts = refiner.grid(level, step, (q, p, lam, live))
        fine = spec.at_level(level)
        values = diagnostics.set_values(fine, forms, *parts)
        res = [values[(spec.invariant, f)] for f in forms]
        monitor = max(r[1] for r in res) if all(r[2] and r[3] for r in res) else np.nan
        if not monitor > threshold:                 # resolved, or not computed (NaN)
            break
    values[(spec.invariant, "points")] = fine.count
    return values
