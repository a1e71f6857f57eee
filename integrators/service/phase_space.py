"""A canonical phase space given by nothing but a step map (docs/systems.md, "A canonical map in a scene").

A scene's ``[system] degrees_of_freedom = k`` makes a :class:`PhaseSpace`: coordinates
q = (x_0 … x_{k−1}, v_0 … v_{k−1}) of dimension d = 2k with the canonical one-form ϑ(q)·dq = v·dx
(dϑ = dv ∧ dx), no Hamiltonian formula, and the run's ``step_maps`` taken as canonical maps
``step(x, v, h) -> (x, v)`` on (n, k) arrays.  The driver, the HDF5 file, MPI, resume and the plots
treat it as any system; what needs a formula (the compiled engine, the noncanonical and corrected
forms, Ω̄'s checks) is not offered.  The energy error is there when the scene names a batched
``energy(x, v) -> (n,)``.
"""
from __future__ import annotations

import numpy as np


class PhaseSpace:
    """The canonical phase space of ``k`` degrees of freedom of a black-box map.

    period : the positions' periods (a number, or one per x; None or 0: not periodic): the
        invariants unwrap the sets' samples there (invariants.first_invariant's ``period``)
    energy : a batched ``energy(x, v) -> (n,)`` for the energy error, or None
    """

    black_box = True
    has_momentum = False
    equilibrium = None

    def __init__(self, k, name="canonical", period=None, energy=None):
        from invariants.forms import _periods
        self.k, self.d, self.name = int(k), 2 * int(k), name
        P = _periods(period, self.k)
        # one entry per coordinate of q, as invariants take them: the v's are not periodic
        self.period = None if P is None else tuple(P.tolist()) + (0.0,) * self.k
        self.energy = energy
        self.params = {}

    def __repr__(self):
        return f"PhaseSpace(k={self.k}, name={self.name!r})"

    @property
    def coordinates(self):
        return [f"x{i}" for i in range(self.k)] + [f"v{i}" for i in range(self.k)]

    def theta(self, q):
        """ϑ(q) = (v, 0): the canonical one-form v·dx."""
        q = np.asarray(q)
        return np.concatenate([q[..., self.k:], np.zeros_like(q[..., self.k:])], axis=-1)

    def in_domain(self, q):
        """Every finite point is in the domain (a periodic position may lie anywhere)."""
        return np.all(np.isfinite(np.asarray(q)), axis=-1)

    def H(self, q):
        """The scene's ``energy(x, v)`` at points (n, d), checked: n finite-or-not reals."""
        if self.energy is None:
            raise ValueError(f"{self.name}: no energy function was given (system.energy)")
        q = np.asarray(q, dtype=float)
        e = np.asarray(self.energy(q[:, :self.k], q[:, self.k:]))
        if e.shape != (q.shape[0],) or e.dtype.kind not in "fiu":
            raise ValueError(f"system.energy must return ({q.shape[0]},) real values for {q.shape[0]} points, got "
                             f"shape {e.shape} of {e.dtype}")
        return e.astype(float)

    def canonical_step(self, step):
        """The engine's contract ``(q, p, lam, h, system) -> (q, p, lam)`` around a canonical
        ``step(x, v, h) -> (x, v)``: p = ϑ(q₁) = (v₁, 0), lam = 0."""
        k = self.k

        def wrapped(q, p, lam, h, system):
            got = step(q[:, :k], q[:, k:], h)
            if not isinstance(got, (tuple, list)) or len(got) != 2:
                raise ValueError("a canonical map must return (x, v), got "
                                 + (f"{len(got)} values" if isinstance(got, (tuple, list)) else type(got).__name__))
            x1, v1 = (np.asarray(a) for a in got)
            if x1.shape != (q.shape[0], k) or v1.shape != (q.shape[0], k):
                raise ValueError(f"returned shapes {x1.shape}, {v1.shape} for inputs {(q.shape[0], k)}")
            q1 = np.concatenate([x1, v1], axis=1)
            return q1, self.theta(q1), np.zeros_like(q1)
        return wrapped
