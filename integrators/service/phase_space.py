"""Phase spaces given by nothing but step maps (docs/systems.md, "A map with no formula in a scene").

A scene's ``[system]`` without formulas:

* ``degrees_of_freedom = k`` makes a :class:`PhaseSpace`: coordinates q = (x_0 … x_{k−1}, v_0 … v_{k−1})
  of dimension d = 2k with the canonical one-form v·dx, and the run's ``step_maps`` taken as
  canonical maps ``step(x, v, h) -> (x, v)`` on (n, k) arrays;
* ``dimension = d`` with ``one_form = "file.py:theta"`` makes a :class:`OneFormSpace`: a degenerate
  Lagrangian ϑ(q)·q̇ − H(q) whose ϑ is code, a batched ``theta(q) -> (n, d)``, and maps
  ``step(q, h) -> q`` on (n, d) arrays.

Either way the state's p is ϑ(q) after every step, so the invariant ∮ p·dq (∫∫ dp ∧ dq) of the
engine's canonical form is ∮ ϑ·dq (∫∫ dϑ): the driver, the HDF5 file, MPI, resume and the plots
treat such a space as any system; what needs a formula (the compiled engine, the corrected form,
Ω̄'s checks) is not offered.  The energy error is there when the scene names a batched energy.
"""
from __future__ import annotations

import numpy as np


class _BlackBox:
    black_box = True
    has_momentum = False
    equilibrium = None

    def __init__(self, d, name, period, energy):
        self.d, self.name, self.energy, self.params = int(d), name, energy, {}
        self.period = period

    def in_domain(self, q):
        """Every finite point is in the domain (a periodic coordinate may lie anywhere)."""
        return np.all(np.isfinite(np.asarray(q)), axis=-1)

    def H(self, q):
        """The scene's energy at points (n, d), checked: n real values."""
        if self.energy is None:
            raise ValueError(f"{self.name}: no energy function was given (system.energy)")
        q = np.asarray(q, dtype=float)
        e = np.asarray(self._energy(q))
        if e.shape != (q.shape[0],) or e.dtype.kind not in "fiu":
            raise ValueError(f"system.energy must return ({q.shape[0]},) real values for {q.shape[0]} points, got "
                             f"shape {e.shape} of {e.dtype}")
        return e.astype(float)

    def engine_step(self, step):
        """The engine's contract ``(q, p, lam, h, system) -> (q, p, lam)`` around the scene's map:
        p = ϑ(q₁), lam = 0."""
        def wrapped(q, p, lam, h, system):
            q1 = self._advance(step, q, h)
            return q1, self.theta(q1), np.zeros_like(q1)
        return wrapped


class PhaseSpace(_BlackBox):
    """The canonical phase space of ``k`` degrees of freedom of black-box maps ``step(x, v, h) -> (x, v)``.

    period : the positions' periods (a number, or one per x; None or 0: not periodic): the
        invariants unwrap the sets' samples there (invariants.first_invariant's ``period``)
    energy : a batched ``energy(x, v) -> (n,)`` for the energy error, or None
    """

    form = "canonical"

    def __init__(self, k, name="canonical", period=None, energy=None):
        from invariants.forms import _periods
        P = _periods(period, int(k))
        # one entry per coordinate of q, as invariants take them: the v's are not periodic
        super().__init__(2 * int(k), name, None if P is None else tuple(P.tolist()) + (0.0,) * int(k), energy)
        self.k = int(k)

    def __repr__(self):
        return f"PhaseSpace(k={self.k}, name={self.name!r})"

    @property
    def coordinates(self):
        return [f"x{i}" for i in range(self.k)] + [f"v{i}" for i in range(self.k)]

    def theta(self, q):
        """ϑ(q) = (v, 0): the canonical one-form v·dx."""
        q = np.asarray(q)
        return np.concatenate([q[..., self.k:], np.zeros_like(q[..., self.k:])], axis=-1)

    def _energy(self, q):
        return self.energy(q[:, :self.k], q[:, self.k:])

    def _advance(self, step, q, h):
        k = self.k
        got = step(q[:, :k], q[:, k:], h)
        if not isinstance(got, (tuple, list)) or len(got) != 2:
            raise ValueError("a canonical map must return (x, v), got "
                             + (f"{len(got)} values" if isinstance(got, (tuple, list)) else type(got).__name__))
        x1, v1 = (np.asarray(a) for a in got)
        if x1.shape != (q.shape[0], k) or v1.shape != (q.shape[0], k):
            raise ValueError(f"returned shapes {x1.shape}, {v1.shape} for inputs {(q.shape[0], k)}")
        return np.concatenate([x1, v1], axis=1)


class OneFormSpace(_BlackBox):
    """d coordinates with the one-form ``theta(q) -> (n, d)`` of code, of black-box maps ``step(q, h) -> q``.

    period : the coordinates' periods (a number, or one per coordinate; None or 0: not periodic)
    energy : a batched ``energy(q) -> (n,)`` for the energy error, or None
    """

    form = "noncanonical"

    def __init__(self, d, one_form, name="one-form", period=None, energy=None):
        from invariants.forms import _periods
        P = _periods(period, int(d))
        super().__init__(d, name, None if P is None else tuple(P.tolist()), energy)
        self.one_form = one_form

    def __repr__(self):
        return f"OneFormSpace(d={self.d}, name={self.name!r})"

    @property
    def coordinates(self):
        return [f"q{i}" for i in range(self.d)]

    def theta(self, q):
        """The scene's one-form at points (n, d), checked: an array of q's shape, real."""
        q = np.asarray(q, dtype=float)
        t = np.asarray(self.one_form(q))
        if t.shape != q.shape or t.dtype.kind not in "fiu":
            raise ValueError(f"system.one_form must return real values of q's shape {q.shape}, got shape {t.shape} "
                             f"of {t.dtype}")
        return t.astype(float)

    def _energy(self, q):
        return self.energy(q)

    def _advance(self, step, q, h):
        q1 = np.asarray(step(q, h))
        if q1.shape != q.shape:
            raise ValueError(f"returned shape {q1.shape} for input {q.shape}")
        return q1
