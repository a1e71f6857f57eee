"""What a run records at each output time, split so that the ranks share the work.

Two kinds of work:

* **per point**: the energy, momentum and constraint errors.  Each rank takes the largest over
  the live points it owns (:meth:`Diagnostics.point_errors`); the row holds the largest over the
  ranks.  A maximum does not depend on how the points were split, so the row is bitwise the same
  for any rank count.
* **per sample set and form**: I₁ of the loop and I₂ of the surface in each of the scene's forms
  (:meth:`Diagnostics.invariant`).  These need every point of the set, so each (set, form) is a
  *task* given to one rank (:func:`assign`); the set's points are gathered to the ranks that hold
  one of its tasks, and only the values come back to rank 0.  A task is the same function call on
  the same points whichever rank runs it.

:meth:`Diagnostics.row` does both on one process (the audit, a one-rank run);
:meth:`Diagnostics.combine` turns the pieces from the ranks into the same row.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..simd import _at

# relative cost of one form per sample point, measured on guiding_centre_symmetric (loop of 2,000,
# surface of 100 × 100; docs/scaling.md): only the ratios matter, for the assignment of tasks
COST_PER_POINT = {("I1", "canonical"): 0.25, ("I1", "noncanonical"): 0.20, ("I1", "corrected"): 0.63,
                  ("I2", "canonical"): 1.85, ("I2", "noncanonical"): 1.32, ("I2", "corrected"): 3.68}


def assign_sets(scene, size) -> dict:
    """{(invariant, form): rank} with every form of a set on one rank (the sets longest first to the
    least loaded): a rank computes a set's forms together, sharing the transforms of q
    (invariants.forms), which one form per rank would repeat.  The driver gives each batch's sets
    to the ranks with the least task work so far (tasks.Tasks.assign), so the ranks share the work
    over batches rather than within one; this assignment places a refining set in the first pair.
    Deterministic."""
    load = np.zeros(size)
    out = {}
    sets = [(sum(COST_PER_POINT[(spec.invariant, f)] for f in scene.forms) * spec.count, spec.invariant)
            for spec, _ in scene.sample_sets]
    for cost, inv in sorted(sets, key=lambda t: (-t[0], t[1])):
        r = int(np.argmin(load))
        load[r] += cost
        out.update({(inv, f): r for f in scene.forms})
    return out


def assign(scene, size, busy=None) -> dict:
    """{(invariant, form): rank}: every task of the scene's sets given to a rank, the longest first
    to the least loaded (``busy[r]``: work a rank already has, in the same units; rank 0 writes the
    file).  Deterministic: the same scene and size give the same assignment."""
    load = np.zeros(size) if busy is None else np.array(busy, dtype=float)
    tasks = [(COST_PER_POINT[(spec.invariant, form)] * spec.count, spec.invariant, form)
             for spec, _ in scene.sample_sets for form in scene.forms]
    out = {}
    for cost, inv, form in sorted(tasks, key=lambda t: (-t[0], t[1], t[2])):
        r = int(np.argmin(load))
        out[(inv, form)] = r
        load[r] += cost
    return out


class Diagnostics:
    """The output-time record of a scene's points.

    q0 : the initial points of rows [lo, hi) of the run (the block a rank owns; all of them on one
    process): the reference energy and momentum of each point.
    """

    def __init__(self, scene, system, q0):
        self.scene, self.system = scene, system
        self.dd = getattr(scene, "precision", "double") == "double-double"
        if self.dd:                 # H0 and P0 as double-doubles (n, 2) of the points' exact doubles
            from ..engine import scalars_dd
            q0 = np.asarray(q0, dtype=float)
            hp = scalars_dd(system, np.stack([q0, np.zeros_like(q0)], axis=-1))
            H0, P0 = hp[:, 0], hp[:, 1]
            self.scale = energy_scale(H0[:, 0])
        else:
            H0, P0 = _scalars(system, q0)
            self.scale = energy_scale(H0)
        self.H0 = H0
        self.P0 = P0 if "momentum" in scene.diagnostics else None

    def point_errors(self, q, p, live) -> dict:
        """{'energy_error': …, …}: the largest error over the live points of this block (0 if none; NaN
        if one is NaN).  One compiled pass over the points (the system's generated H, momentum and ϑ);
        for a double-double state (q, p of shape (n, d, 2)) H, the momentum and ϑ are evaluated in
        double-double and each difference is taken there before it is rounded to double."""
        from ..codegen import point_functions, scalar_function
        sc, sy = self.scene, self.system
        if getattr(sy, "black_box", False):
            return self._point_errors_black_box(q, live)
        if np.ndim(q) == 3 or self.dd:         # (doubles in a double-double run: taken exactly)
            pairs = lambda x: x if np.ndim(x) == 3 else np.stack([x, np.zeros_like(x)], axis=-1)
            return self._point_errors_dd(pairs(np.asarray(q, dtype=float)), pairs(np.asarray(p, dtype=float)), live)
        ev, _ = point_functions(sy)
        d = sy.d
        out = np.zeros(3)
        _point_errors(scalar_function(sy), ev, _params(sy), np.ascontiguousarray(q, dtype=float),
                      np.ascontiguousarray(p, dtype=float), np.ascontiguousarray(live, dtype=np.uint8), self.H0,
                      self.scale, self.H0 if self.P0 is None else self.P0, out, np.empty(2), np.empty(d), np.empty(d * d),
                      np.empty(d * d * d), np.empty(d), np.empty(d * d))
        names = (("energy", "energy_error", 0), ("momentum", "momentum_error", 1),
                 ("constraint", "constraint_error", 2))
        return {key: float(out[i]) for what, key, i in names if what in sc.diagnostics}

    def _point_errors_black_box(self, q, live) -> dict:
        """A canonical phase space's energy error, from its system.energy (numpy, the live points)."""
        if "energy" not in self.scene.diagnostics:
            return {}
        live = np.asarray(live, dtype=bool)
        if not live.any():
            return {"energy_error": 0.0}
        with np.errstate(all="ignore"):
            e = np.abs(self.system.H(np.asarray(q)[live]) - self.H0[live]) / self.scale[live]
        return {"energy_error": float(np.max(e))}            # (numpy's max: a NaN wins)

    def _point_errors_dd(self, q, p, live) -> dict:
        from ..engine import scalars_dd, theta_dd
        sy, live = self.system, np.asarray(live, dtype=bool)
        out = np.zeros(3)
        if live.any():
            q, p = np.ascontiguousarray(q[live]), np.asarray(p[live])
            hp, th = scalars_dd(sy, q), theta_dd(sy, q)
            H0 = self.H0[live]
            P0 = (self.P0 if self.P0 is not None else self.H0)[live]
            with np.errstate(all="ignore"):
                errs = (np.abs(dd_difference(hp[:, 0], H0)) / self.scale[live],
                        np.abs(dd_difference(hp[:, 1], P0)),
                        np.max(np.abs(dd_difference(p, th)), axis=1))
            out[:] = [np.max(e) for e in errs]           # (numpy's max: a NaN wins)
        names = (("energy", "energy_error", 0), ("momentum", "momentum_error", 1),
                 ("constraint", "constraint_error", 2))
        return {key: float(out[i]) for what, key, i in names if what in self.scene.diagnostics}

    def invariant(self, spec, form, q, p, lam, live):
        """(value, resolution, computed, reason) of one form of one set's invariant; points shaped as the
        set's grid (``reason``: InvariantValue.reason, "" where the spectrum speaks for itself).

        A set with a broken-down (frozen) point is no longer an advected set: not computed, NaN.
        Points that are not finite give NaN, not computed, too.
        """
        import invariants
        if not live.all():
            return np.nan, np.nan, False, ""
        fn = invariants.first_invariant if spec.invariant == "I1" else invariants.second_invariant
        with np.errstate(all="ignore"):
            try:
                v = fn(q, _computed(self.system, form), system=self.system, p=p, lam=lam, h=self.scene.h,
                       period=_period(self.system))
            except ValueError:          # non-finite values
                return np.nan, np.nan, False, ""
        return v.value, v.resolution, True, v.reason

    def combine(self, t, errors, values) -> dict:
        """The row at time t from the blocks' ``point_errors`` (a list) and the tasks' ``values``
        ({(invariant, form): (value, resolution, computed, all live)}).

        ``resolution/<set>`` is the largest monitor over the forms (NaN when a point broke down or a
        value was not finite); ``resolved/<set>`` is 1 when it is at most invariants.UNDER_RESOLVED;
        ``points_used/<set>`` (a set with ``refine_to``) the points of the level the values are on.
        """
        from invariants import UNDER_RESOLVED
        row = {"t": t}
        for spec, _ in self.scene.sample_sets:
            inv = spec.invariant
            live = all(values[(inv, form)][3] for form in self.scene.forms)
            res = 0.0 if live else np.nan
            for form in self.scene.forms:         # in the scene's order: max() keeps a NaN it meets first
                value, r, computed, _ = values[(inv, form)]
                row[f"{inv}/{form}"] = value
                if live:
                    res = max(res, r) if computed else np.nan
            row[f"resolution/{inv}"] = res
            row[f"resolved/{inv}"] = 1 if res <= UNDER_RESOLVED else 0
            if (inv, "points") in values:    # a set that refines itself: the points its values were taken on
                row[f"points_used/{inv}"] = values[(inv, "points")]
        for key in errors[0] if errors else ():
            row[key] = float(np.max([e[key] for e in errors]))
        return row

    def set_values(self, spec, forms, q, p, lam, live) -> dict:
        """{(invariant, form): (value, resolution, computed, all live)} of one set's points (its grid's shape).

        A set's forms are computed together (invariants.forms.first_invariants / second_invariants
        share their transforms and point values; each value is bitwise what it is alone), so the
        tasks one rank holds cost less than the sum of their parts."""
        import invariants.forms
        if live.all() and len(forms) > 1:
            fn = invariants.forms.first_invariants if spec.invariant == "I1" else invariants.forms.second_invariants
            with np.errstate(all="ignore"):
                try:
                    got = fn(q, [_computed(self.system, f) for f in forms], system=self.system, p=p, lam=lam,
                             h=self.scene.h, period=_period(self.system))
                    got = {f: got[_computed(self.system, f)] for f in forms}
                    out = {(spec.invariant, f): (got[f].value, got[f].resolution, True, True) for f in forms}
                    return _with_reason(out, spec.invariant, [got[f].reason for f in forms])
                except ValueError:      # a non-finite field: each form on its own says which fail
                    pass
        got = {form: self.invariant(spec, form, q, p, lam, live) for form in forms}
        out = {(spec.invariant, form): v[:3] + (bool(live.all()),) for form, v in got.items()}
        return _with_reason(out, spec.invariant, [v[3] for v in got.values()])

    def row(self, t, q, p, lam, live) -> dict:
        """The whole row of points (n, d) on one process."""
        values = {}
        for spec, rows in self.scene.sample_sets:
            shp = spec.grid + (q.shape[1],)
            values.update(self.set_values(spec, self.scene.forms, q[rows].reshape(shp), p[rows].reshape(shp),
                                          lam[rows].reshape(shp), live[rows]))
        return self.combine(t, [self.point_errors(q, p, live)], values)


def _with_reason(values, inv, reasons):
    """``values`` with (inv, "reason"): why the set was under-resolved where its spectrum cannot say
    (InvariantValue.reason: a wrapped coordinate without its period, a period the samples cannot
    tell from a step), when a form's ``reasons`` give one; rank 0 keeps the first as the pair's attribute."""
    why = next((r for r in reasons if r), "")
    if why:
        values[(inv, "reason")] = why
    return values


def zero_invariants(scene, system, q0) -> list:
    """['I1/form', …]: the scene's invariants whose value at t = 0 is zero within its own error
    (|I(0)| ≤ InvariantValue.error, round-off included), such as I₁ of a closed one-form (dϑ = 0):
    their error is reported as |I(t) − I(0)|, since a relative one has no scale (statuses.relative_error)."""
    import invariants
    out = []
    p, lam = system.theta(q0), np.zeros_like(q0)
    for spec, rows in scene.sample_sets:
        shp = spec.grid + (q0.shape[1],)
        fn = invariants.first_invariant if spec.invariant == "I1" else invariants.second_invariant
        for form in scene.forms:
            with np.errstate(all="ignore"):
                try:
                    v = fn(q0[rows].reshape(shp), _computed(system, form), system=system, p=p[rows].reshape(shp),
                           lam=lam[rows].reshape(shp), h=scene.h, period=_period(system))
                except ValueError:        # not finite: the run's own rows say so
                    continue
            if abs(v.value) <= v.error:
                out.append(f"{spec.invariant}/{form}")
    return out


def energy_scale(H0):
    """The scale of each point's energy error |H − H0|/scale: |H0|, a relative error, and 1 where
    H0 = 0 (an absolute error: a relative one has no scale there, and would be NaN at every output)."""
    H0 = np.asarray(H0, dtype=float)
    return np.where(H0 != 0, np.abs(H0), 1.0)


def dd_difference(a, b):
    """a − b rounded to double, for double-double arrays a, b (…, 2) of (hi, lo) pairs: the high
    parts' difference exactly (TwoSum) plus the low parts', so the result is the exact difference to
    about 1e-32 of |a| (where double's a − b would keep only the high parts' rounding)."""
    s = a[..., 0] - b[..., 0]
    bb = s - a[..., 0]
    e = (a[..., 0] - (s - bb)) + (-b[..., 0] - bb)
    return s + (e + (a[..., 1] - b[..., 1]))


def _params(system):
    return system.param_vector()


def _computed(system, form):
    """The form computed for a scene's form: a system of black-box maps holds p = ϑ(q) after every
    step, so its ϑ·dq (noncanonical) is the canonical p·dq of its state, spectral and O(d) a point;
    any other system's form as named."""
    return "canonical" if getattr(system, "black_box", False) else form


def _period(system):
    """The periods of the system's coordinates (a canonical phase space's positions), or None."""
    return getattr(system, "period", None)


def _scalars(system, q):
    """H and the momentum (0 without a symmetry) at every point, by the system's compiled function
    (a canonical phase space: its energy function, or 0 without one)."""
    from ..codegen import scalar_function
    q = np.ascontiguousarray(q, dtype=float)
    if getattr(system, "black_box", False):
        H = system.H(q) if system.energy is not None else np.zeros(q.shape[0])
        return H, np.zeros(q.shape[0])
    out = np.empty((q.shape[0], 2))
    _scalars_at(scalar_function(system), _params(system), q, out)
    return out[:, 0].copy(), out[:, 1].copy()


@njit(cache=True, error_model="numpy")
def _scalars_at(scalars, k, q, out):
    for i in range(q.shape[0]):
        scalars(_at(q, i * q.shape[1]), _at(k, 0), _at(out, 2 * i))


@njit(cache=True, error_model="numpy")
def _point_errors(scalars, ev, k, q, p, live, H0, scale, P0, out, hp, th, T, TT, dH, HH):
    """out = max over live points of |H − H0|/scale (:func:`energy_scale`: |H0|, or 1 where H0 = 0),
    |P − P0|, max_i |p_i − ϑ_i(q)| (a NaN wins, as numpy's max lets it)."""
    n, d = q.shape
    for j in range(3):
        out[j] = 0.0
    for i in range(n):
        if live[i] == 0:
            continue
        scalars(_at(q, i * d), _at(k, 0), _at(hp, 0))
        ev(_at(q, i * d), _at(k, 0), False, _at(th, 0), _at(T, 0), _at(TT, 0), _at(dH, 0), _at(HH, 0))
        c = 0.0
        for m in range(d):
            v = abs(p[i, m] - th[m])
            if v != v or v > c:
                c = v
        for j, v in ((0, abs(hp[0] - H0[i]) / scale[i]), (1, abs(hp[1] - P0[i])), (2, c)):
            if out[j] == out[j] and (v != v or v > out[j]):
                out[j] = v
