"""The compiled step engine: the per-point state, the one time loop, and the system's point functions.

Every run — :func:`integrators.integrate`, the MPI driver, ``poincare audit`` and the scripts —
advances points through :class:`Engine` and :func:`march`:

* :class:`State` owns everything a point carries from step to step.  Its
  :data:`CHECKPOINT_FIELDS` are the checkpoint schema of the HDF5 files.  The Newton factors it
  keeps from step to step are not stored; where they were taken is (``jac_z``, ``jac_q``,
  ``jac_lam``), and a state read from a checkpoint rebuilds them bitwise before its first step
  (:func:`integrators.kernel.refactor`).  So a run split into calls anywhere (outputs,
  ``save_every``, checkpoints, resumes) is bitwise the run in one call.
* :class:`Engine` is one (tableau, projection) pair for a system and a step size.  The tableau
  and the projection are runtime data of the compiled kernel (:mod:`integrators.kernel`): one
  compilation serves every pair and every system.
* The system enters as small compiled functions generated from its symbolic ϑ and H
  (:func:`integrators.codegen.point_functions`: the generated source, its cache and its printer
  live there); parameter values are runtime data, so ``with_params`` compiles nothing.

Threads: :func:`set_threads` (numba's pool; results are bitwise the same for any count).
"""
from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
import time
from typing import NamedTuple

import numba
import numpy as np
import sympy

from . import kernel
from .codegen import load_module, point_functions, post_entry
from .ddouble import scale_array
from .kernel import DEPTH, LANES, RECURRENCE, Newton, Pair, lane_width, layout, scalars_dd_points, theta_dd_points
from .projections import admission, projection_record
from .systems import system_from
from .tableaus import tableau

BLOCK = 64                     # points per block of the kernel's thread loop (any value gives the same bits)


class LaneUse(NamedTuple):
    """What one :meth:`Engine.advance` call asked of the lanes: ``W`` points a group, ``rounds`` group
    steps and ``iterations`` the Newton iterations they ran, summed over the blocks.  The point-steps
    the call made (the rise of ``State.steps``) over W · rounds is the share of lane steps that did
    work (1: no lane ever idled); the points' iterations (the rise of ``State.iterations``) over
    W · iterations that of lane iterations (a lane that converged waits for its group's slowest);
    ``jacobians`` the Jacobians the groups evaluated and factorised (every lane of a group at once)."""
    W: int
    rounds: int
    iterations: int
    jacobians: int

CHECKPOINT_FIELDS = ("q", "p", "Lam", "q_comp", "p_comp", "Y", "mu", "have_history", "live", "breakdown_time",
                     "iterations", "steps", "have_lu", "jac_z", "jac_q", "jac_lam", "defects", "orders")


def set_threads(n: int | None):
    """Use ``n`` threads over points (None: numba's default, every core)."""
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS if n is None else max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))


def max_threads() -> int:
    """The most threads over points numba can run here (NUMBA_NUM_THREADS: the cores, by default)."""
    return int(numba.config.NUMBA_NUM_THREADS)


def kernel_cached() -> bool:
    """Whether numba's on-disk cache already holds a compiled step kernel (a first run compiles it)."""
    try:
        return os.path.exists(kernel.advance._cache._cache_file._index_path)
    except AttributeError:          # another numba's internals: say nothing rather than guess
        return True


def compile_kernel(d, W, precision="double"):
    """Compile (or load from numba's cache) the kernel's specialisation for dimension ``d``, ``W``
    lanes and ``precision``.  A specialisation depends on nothing else (a system enters as function
    pointers of one type, the tableau and the projection as data), so a stand-in system of that
    dimension (ϑ and H polynomials) compiles the one every system of dimension d uses."""
    q = sympy.symbols(f"x0:{d}")
    theta = [q[i + 1] if i % 2 == 0 else -q[i - 1] for i in range(d)]
    sy = system_from(theta, sum(x * x for x in q) / 2, list(q), name="kernel_stand_in")
    eng = Engine(sy, tableau("GLRK1"), "none", 0.1, precision=precision)
    st = eng.state(np.ones((W, d)))
    st.live[:] = False
    eng.advance(st, 1, 1, lanes=W)


def compile_kernels(specs):
    """Compile the kernel specialisations ``specs`` ((d, W, precision) each) at the same time, one
    child process each, at most one per core: a first run that needs several (16 and 8 lanes, say)
    waits for the longest instead of their sum.  The children only fill numba's cache; the caller
    then loads them.  Returns the specs whose child failed (the caller compiles those itself, and
    meets their error there)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root] + [x for x in os.environ.get("PYTHONPATH", "").split(
        os.pathsep) if x]))
    for key in [k for k in env if k.startswith(("PMI_", "MPI_LOCAL", "HYDRA_", "OMPI_"))]:
        env.pop(key)                    # a child is no MPI rank of the run
    code = "import sys, integrators.engine as e; e.compile_kernel(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3])"
    failed, pending = [], list(specs)
    cores = max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))
    while pending:
        batch, pending = pending[:cores], pending[cores:]
        procs = [(spec, subprocess.Popen([sys.executable, "-c", code, str(spec[0]), str(spec[1]), spec[2]], env=env,
                                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)) for spec in batch]
        failed += [spec for spec, p in procs if p.wait() != 0]
    return failed


def get_threads() -> int:
    return numba.get_num_threads()


# -- the state and the engine --------------------------------------------------------------------

class Output(NamedTuple):
    """The points at one output inside an :meth:`Engine.advance_outputs` call: q, p, Λ (= hλ), live
    and breakdown time as a call ending there would leave them in the :class:`State` (the same
    shapes; a point that broke down earlier holds its frozen state, as the State does).  What an
    output needs of a state, without its Newton factors and predictor table."""
    q: np.ndarray
    p: np.ndarray
    Lam: np.ndarray
    live: np.ndarray
    breakdown_time: np.ndarray

    def nearest(self):
        """(q, p, Λ) as doubles, as :meth:`State.nearest`."""
        return State.nearest(self)


class State:
    """The per-point state of a run (leading points axis on every array).

    ``q, p`` positions and momenta (p as the method computes it); ``Lam`` = hλ of the last step;
    ``q_comp, p_comp`` compensated-summation terms; ``Y`` (n, s, d) the last step's stage
    displacements and ``mu`` its Lobatto multiplier (the next step's guesses); ``have_history``
    whether a point has taken a step; ``live`` whether it has not broken down; ``breakdown_time``
    (inf if never); ``iterations`` Newton iterations summed; ``steps`` steps taken; ``have_lu``
    whether it carries Newton factors into its next step, and where they were taken: ``jac_z``
    (n, s + 2, d) the iterate (its first nz = s·d (+ d) (+ d) entries, flat), ``jac_q``, ``jac_lam``
    (n, d) that step's q_n and Λ_n.  These are :data:`CHECKPOINT_FIELDS`.  The factors themselves
    (``lu``, ``piv``: n·nz² numbers) are not; a state made from a checkpoint rebuilds them before
    its first step (``needs_factors``; :func:`integrators.kernel.refactor`), bitwise.
    """

    def __init__(self, q, p, lam, h, s, dtype=np.float64):
        q = np.asarray(q)
        n, d = q.shape
        dt = np.dtype(dtype)
        self.q = np.array(q, dtype=dt, order="C")
        self.p = np.array(p, dtype=dt, order="C")
        self.Lam = np.ascontiguousarray(h * np.asarray(lam, dtype=dt))
        self.q_comp = np.zeros((n, d), dt)
        self.p_comp = np.zeros((n, d), dt)
        self.Y = np.zeros((n, s, d), dt)
        self.mu = np.zeros((n, d), dt)
        self.have_history = np.zeros(n, dtype=bool)
        self.live = np.ones(n, dtype=bool)
        self.breakdown_time = np.full(n, np.inf)
        self.iterations = np.zeros(n, dtype=np.int64)
        self.steps = np.zeros(n, dtype=np.int64)
        self.lu = np.empty((n, 0, 0), dt)
        self.piv = np.empty((n, 0), np.int64)
        self.have_lu = np.zeros(n, dtype=bool)
        self.jac_z = np.zeros((n, s + 2, d), dt)
        self.jac_q = np.zeros((n, d), dt)
        self.jac_lam = np.zeros((n, d), dt)
        self.defects = np.zeros((n, DEPTH * (s + 2), d), dt)
        self.orders = np.zeros((n, 5), dtype=np.uint8)
        self.needs_factors = False      # have_lu read from a checkpoint: lu, piv to be rebuilt

    @classmethod
    def from_checkpoint(cls, fields, h):
        """A state from the :data:`CHECKPOINT_FIELDS` of a checkpoint (arrays copied)."""
        q = np.asarray(fields["q"])
        q1 = q[..., 0] if q.ndim == 3 else q          # (a double-double checkpoint: (n, d, 2) value arrays)
        st = cls(q1, q1, np.zeros_like(q1), h, fields["Y"].shape[1])
        for name in CHECKPOINT_FIELDS:
            setattr(st, name, np.ascontiguousarray(fields[name]).copy())
        st.needs_factors = bool(st.have_lu.any())
        return st

    @classmethod
    def schema(cls, n, d, s, precision="double") -> dict:
        """{field: (shape, dtype)} of the checkpoint of n points (what the HDF5 file preallocates),
        read off a one-point state so the fields and their types are defined only here (a
        double-double state's value arrays have a last axis of 2: hi, lo)."""
        z = np.zeros((1, d))
        one = cls.double_double(z, z, z, 1.0, s) if precision == "double-double" else cls(z, z, z, 1.0, s)
        return {name: ((n,) + getattr(one, name).shape[1:], getattr(one, name).dtype) for name in CHECKPOINT_FIELDS}

    def nearest(self):
        """(q, p, Λ = hλ) as doubles: the arrays themselves, or a double-double state's high parts
        (each the double nearest its value: the kernel keeps |lo| ≤ ½ ulp(hi)).  What the invariants
        and the stored points are computed from."""
        if self.q.ndim == 3:
            return self.q[..., 0], self.p[..., 0], self.Lam[..., 0]
        return self.q, self.p, self.Lam

    def checkpoint(self) -> dict:
        return {name: getattr(self, name) for name in CHECKPOINT_FIELDS}

    def forget_jacobians(self):
        """Start every point's next solve from a fresh Jacobian (not done by any run: a study of
        what the carried factors change)."""
        self.have_lu[:] = False
        self.needs_factors = False

    @classmethod
    def double_double(cls, q, p, lam, h, s):
        """A double-double state: ``q``, ``p``, ``lam`` as (n, d, 2) arrays of (hi, lo) pairs (or (n, d)
        doubles, taken exactly); every value array of the state gets the same last axis of 2 (the
        kernel reads it as double-doubles: integrators/ddouble.py)."""
        def pairs(x):
            x = np.asarray(x, dtype=np.float64)
            return np.ascontiguousarray(np.stack([x, np.zeros_like(x)], axis=-1) if x.ndim == 2 else x)
        q2, p2, l2 = pairs(q), pairs(p), pairs(lam)
        st = cls(q2[..., 0], p2[..., 0], np.zeros(q2.shape[:2]), h, s)
        st.q, st.p = q2.copy(), p2.copy()
        st.Lam = scale_array(np.ascontiguousarray(l2), float(h))
        for name in ("q_comp", "p_comp", "mu", "jac_q", "jac_lam"):
            setattr(st, name, np.zeros_like(q2))
        st.Y = np.zeros(st.Y.shape + (2,))
        st.jac_z = np.zeros(st.jac_z.shape + (2,))
        st.defects = np.zeros(st.defects.shape + (2,))
        st.lu = np.empty(st.lu.shape + (2,))
        return st

    @property
    def precision(self) -> str:
        return "double-double" if self.q.ndim == 3 else "double"

    def _tuple(self, nz):
        if self.lu.shape[1] != nz:
            n = self.q.shape[0]
            self.lu = np.empty((n, nz, nz) + self.q.shape[2:], self.q.dtype)   # (double-double: a last axis of 2)
            self.piv = np.empty((n, nz), np.int64)
            self.needs_factors = bool(self.have_lu.any())     # factors noted but not at hand: rebuilt
        u8 = lambda x: x.view(np.uint8)
        return (self.q, self.p, self.Lam, self.q_comp, self.p_comp, self.Y, self.mu, u8(self.have_history),
                u8(self.live), self.breakdown_time, self.iterations, self.steps, self.lu, self.piv, u8(self.have_lu),
                self.jac_z, self.jac_q, self.jac_lam, self.defects, self.orders)


FIXED_TOL = 4 * np.finfo(np.float64).eps   # a fixed Newton tolerance of 4 ulps: faster, and its round-off drifts (docs/brouwer.md)
DITHER = 2.0 ** -45                         # Tolerances.dither: iterates after larger updates rounded to 64 ulps of scale
SETTLE = 2.0 ** -48                         # Tolerances.settle: the first iterate after an update within 16 ulps of scale rounded to 8 of its own
SETTLE_ACCEPT = 2.0 ** -60                  # ... and the solve ends where the update after the next is within 1/256 ulp of scale


@dataclasses.dataclass(frozen=True)
class Tolerances:
    """Newton's stopping rule in the compiled engine, as runtime data (one compilation for any values).

    tol : converged when max |δ|/scale ≤ tol; under ``predictor="defects"`` not before the
        second iteration.  Default 0: Newton goes on until its update stops halving (``stall``
        below), so every step ends at the round-off floor of its equations.  A fixed tolerance
        (``FIXED_TOL``, 4 eps) stops one iteration short of it, from a guess whose error is
        smooth in time, and leaves a remainder of the same sign step after step: the round-off
        of the energy then drifts where Brouwer's law is √t (Hairer, McLachlan & Razakarivony,
        BIT 48, 2008; docs/brouwer.md), for 4-30 % more speed
    stall : converged when the update is ≤ stall and no longer halves (the round-off floor;
        default 1e-10)
    stall_complex : the same for the audit's complex-step derivatives (default 1e-13)
    maxiter : iterations before a step counts as failed (default 40)
    refresh : a fresh Jacobian after an iteration that contracted by less than this (default 0.01)
    predictor : the next step's guess of its stages, Λ and μ: ``"defects"`` (default) the Lagrange
        polynomial through the last step's stage values, corrected by the extrapolated errors of
        that polynomial on the last ``depth`` steps, Λ and μ extrapolated the same way
        (:func:`integrators.kernel._guess`); ``"extrapolate"`` the polynomial alone, Λ_n and μ_n as
        they are (the engine's predictor until the defects were added); ``"velocity"`` that
        polynomial with h·q̇(q_n) as one more node (one evaluation and a d × d solve a step;
        :func:`predictor`)
    depth : how many steps' defects ``"defects"`` keeps, 1 … kernel.DEPTH (default 8); each step
        uses the order that would have done best on the step before
    trust : a step whose last guess was off by at most this (relative to max(|q|, 1)), and by
        more than the refresh floor, starts its Newton from a Jacobian at the guess; the others
        from the factors carried from the last step (default 1e-3; ``"defects"`` only: the other
        predictors always carry them).  From a guess within the floor the carried factors converge
        in the two iterations every step takes, whatever their age
    trust_max_unknowns : ... and only in pairs of at most this many Newton unknowns (default 16:
        GLRK1, GLRK2 and SRK3 with any projection on d = 4); a larger LU costs more than the
        iterations it saves, so those pairs keep the carried factors (docs/benchmarks.md)
    refresh_floor : no fresh Jacobian after an update of at most this size (relative, like tol),
        however little it contracted: that small, the ratio measures round-off, not the factors
        (default 1e-12, about 4,500 ulps; ``"defects"`` only: the other predictors refresh after
        every poorly contracting iteration; scaled to double-double like tol)
    trust_floor : ... and no Jacobian at a guess within this either (default 1e-7; 0: the refresh
        floor alone).  The unprojected and symplectically projected pairs' guesses end near 10⁻⁸ on
        long runs, where the carried factors converge in three or four iterations and a Jacobian at
        every step costs more than it saves (docs/benchmarks.md, "The stage predictor")
    refresh_horizon : ... and only where those factors, at the rate θ of that iteration, would not
        converge within this many more iterations (θ^horizon·|δ| > tol).  Default 0: no such test;
        -1: 2 + ⌈unknowns / 4⌉, about a Jacobian's cost in iterations plus the two it takes after
        (3 for GLRK1-none, 5 for GLRK2-symmetric, 9 for GLRK6-symmetric on d = 4).  It saves
        Jacobians (GLRK2- and SRK3-symmetric with the carried factors 1.1-1.4x faster in lanes),
        but a lane then stops at tol with factors that contract by up to 0.5 an iteration, so
        each step leaves an error of a few ulps in the same direction and round-off grows about
        ten times faster (docs/benchmarks.md): not the default (``"defects"`` only)
    jacobian_age : ... once the carried factors are at least this many steps old (default 1:
        every trusted step; 2 takes about half the Jacobians for about one more iteration a step,
        but lanes in lockstep factorise whenever one of them asks, so it pays only where the
        group's points keep in phase: docs/benchmarks.md)
    jacobian_every : ... and only at the steps whose number is a multiple of this; at the others
        the factors of the last due step are carried (default 1: every step).  A schedule by step
        number keeps the lanes of a group factorising together, which a point's own history does
        not: 2 ran GLRK2- and SRK3-symmetric 1.1-1.2x faster in lanes on the guiding centre before
        the recurrence, but one orbit in the tokamak field 13 % slower (its carried factors then
        need refreshing within the step): docs/benchmarks.md
    recurrence : the coefficients (0 … kernel.RECURRENCE, default 4; 0: none) of a linear
        recurrence fitted to the last DEPTH defects, whose prediction competes with the
        polynomial orders (``"defects"`` only; :func:`integrators.kernel._recurrence`): it follows
        uniform rotations and the parasitic two-step wiggles that the polynomials follow poorly
    dither : round the guess, and each Newton iterate reached by an update larger than 2⁻⁴⁵
        (relative, like tol), to a grid of 64 ulps of its scale, so that Newton's last iterations
        approach the solution from a side that changes from step to step rather than the side the
        guess comes from (default False; double unknowns only: not the audit's complex-step values,
        not double-double).  Dithered, Newton's floor test is strict: the update right after a
        rounding is never the floor, and an update within 64 ulps that no longer halves is the floor
        only after a fresh Jacobian or once it stops shrinking (the carried factors go on within
        that band, refreshed where they contract by less than 0.8).  The first version lacked that
        and stopped lanes up to 32 ulps of their scale from the solution (P_ζ of near-axis Boozer
        orbits off by 1.3e-12 instead of 6e-15, tests/test_boozer.py).  Over the 63 degenerate
        pairs of docs/brouwer.md the round-off exponents average 0.498 against 0.518 without it
        (the engine before the settled approach; 51 against 44 at most 0.55): it removes the point
        vortices' GLRK3-symmetric drift but leaves GLRK3-symplectic at 0.66 ± 0.04, and costs 2-51 %
        more Newton iterations, so it is not the default; with it the settled approach is off (:func:`integrators.kernel.newton._update`; docs/brouwer.md, "A last
        approach that does not depend on the guess")
    settle : the settled approach (default True; with ``tol`` 0, not ``dither``, double unknowns
        only, and only in the pairs whose guesses take Jacobians: at most ``trust_max_unknowns``
        Newton unknowns, ``"defects"``): the first Newton iterate of a solve reached by an update of
        at most 2⁻⁴⁸ of its scale (16 ulps) is rounded to a grid of 8 ulps of each coordinate's own
        size (|q|, not max(|q|, 1)), and the solve ends at the iterate after the next where its
        update is at most 2⁻⁶⁰ of scale (else the floor test goes on).  Where Newton stops at the
        floor depends on the side it comes from, and a guess whose error is smooth in time comes
        from the same side step after step; a grid point's offset from the solution does not
        depend on the guess (:func:`integrators.kernel.newton._settle`).  Over 64 starts and 5·10⁴
        steps the point vortices' GLRK3-symmetric, -symplectic, -midpoint and SRK3-symmetric
        energy round-off then walks (exponents 0.50, 0.49, 0.51, 0.41; with ``settle=False`` 0.69,
        0.75, 0.67, 0.62 and |mean/RMS| 0.37-0.82), and so does GLRK3-symmetric's angular momentum
        (2·10⁵ steps: n^0.53 against n^0.98); over the 63 degenerate pairs of docs/brouwer.md the
        exponents average 0.485 against 0.518, none above 0.55 by twice its spread (two with
        ``settle=False``).  It costs Newton iterations: ×1.22 (median; 1.10-1.30) on the 43 of
        those pairs it acts on, and on the predictor's protocol 0.69-1.20 of the Newton work of
        ``Tolerances(predictor="extrapolate", tol=FIXED_TOL)`` against 0.58-1.00 with
        ``settle=False``: the bound on the round-off's growth over the iterations
        (docs/brouwer.md, "The settled approach, the default").  ``settle=False`` is bitwise the
        engine before it was the default.  Its grid in ulps of max(|q|, 1), as first made, was
        hundreds of ulps of a near-axis coordinate (x, y ≈ 0.004) and left P_ζ of near-axis Boozer
        orbits at 1.14e-13 (tests/test_boozer.py: 4.3e-14 in the coordinates' own ulps); ending the
        solve within 2 ulps instead of 2⁻⁶⁰ takes iterates a few ulps off (Kepler's round-off
        3-7.5×)
    accept_unconverged : take a finite iterate that has not converged after ``maxiter`` iterations
        instead of failing the step (GeometricIntegrators.jl's rule: a point then stops only at a
        non-finite value or outside the domain; scripts/studies/stability_breakdown.py --stopping-rule)

    ``Tolerances(predictor="extrapolate", tol=FIXED_TOL, dither=False)`` is the polynomial guess alone
    at a fixed tolerance and ``Tolerances(tol=FIXED_TOL, dither=False)`` the defects' guess at a fixed
    tolerance, bitwise the rules docs/benchmarks-history.md compares; ``Tolerances(settle=False)`` the
    default before the settled approach.
    """

    tol: float = 0.0
    stall: float = 1e-10
    stall_complex: float = 1e-13
    maxiter: int = 40
    refresh: float = 0.01
    accept_unconverged: bool = False
    predictor: str = "defects"
    depth: int = 8
    trust: float = 1e-3
    trust_max_unknowns: int = 16
    refresh_floor: float = 1e-12
    trust_floor: float = 1e-7
    refresh_horizon: int = 0
    jacobian_age: int = 1
    jacobian_every: int = 1
    recurrence: int = 4
    dither: bool = False
    settle: bool = True

    def __post_init__(self):
        if self.predictor not in PREDICTORS:
            raise ValueError(f"Tolerances.predictor must be one of {', '.join(PREDICTORS)}, got {self.predictor!r}")
        if isinstance(self.depth, bool) or not isinstance(self.depth, (int, np.integer)) or \
                not 1 <= self.depth <= DEPTH:
            raise ValueError(f"Tolerances.depth must be an integer from 1 to {DEPTH}, got {self.depth!r}")
        for name in ("tol", "stall", "stall_complex", "refresh", "trust", "refresh_floor", "trust_floor"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"Tolerances.{name} must be a finite number ≥ 0, got {v!r}")
        if isinstance(self.jacobian_age, bool) or not isinstance(self.jacobian_age, (int, np.integer)) or \
                not 1 <= self.jacobian_age <= 255:
            raise ValueError(f"Tolerances.jacobian_age must be an integer from 1 to 255, got {self.jacobian_age!r}")
        if isinstance(self.jacobian_every, bool) or not isinstance(self.jacobian_every, (int, np.integer)) or \
                not 1 <= self.jacobian_every <= 255:
            raise ValueError(f"Tolerances.jacobian_every must be an integer from 1 to 255, got {self.jacobian_every!r}")
        if isinstance(self.recurrence, bool) or not isinstance(self.recurrence, (int, np.integer)) or \
                not 0 <= self.recurrence <= RECURRENCE:
            raise ValueError(f"Tolerances.recurrence must be an integer from 0 (none) to {RECURRENCE}, "
                             f"got {self.recurrence!r}")
        if isinstance(self.trust_max_unknowns, bool) or not isinstance(self.trust_max_unknowns, (int, np.integer)) \
                or self.trust_max_unknowns < 0:
            raise ValueError("Tolerances.trust_max_unknowns must be an integer ≥ 0, "
                             f"got {self.trust_max_unknowns!r}")
        if isinstance(self.refresh_horizon, bool) or not isinstance(self.refresh_horizon, (int, np.integer)) \
                or not -1 <= self.refresh_horizon <= 64:
            raise ValueError(f"Tolerances.refresh_horizon must be an integer from -1 to 64, got {self.refresh_horizon!r}")
        for name in ("dither", "settle"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"Tolerances.{name} must be True or False, got {getattr(self, name)!r}")
        if isinstance(self.maxiter, bool) or not isinstance(self.maxiter, (int, np.integer)) or self.maxiter < 1:
            raise ValueError(f"Tolerances.maxiter must be a positive integer, got {self.maxiter!r}")

    def horizon(self, unknowns):
        """The refresh horizon for a pair of ``unknowns`` Newton unknowns (``refresh_horizon``;
        0: none)."""
        return 2 + -(-int(unknowns) // 4) if self.refresh_horizon < 0 else self.refresh_horizon

    def array(self, double_double=False, unknowns=0) -> np.ndarray:
        """The rule as the kernel reads it for a pair of ``unknowns`` Newton unknowns: one float64
        array in the order of the kernel's :data:`~integrators.kernel.Newton` record (its one owner),
        filled by name.  With ``double_double``, tol, stall, the refresh floor, the trust floor and the
        64 ulps below which an update that stops halving is round-off (``fine``) scaled from
        double's eps to 2⁻¹⁰⁴ (the same rule, one number type down)."""
        scale = 2.0 ** -104 / np.finfo(np.float64).eps if double_double else 1.0
        defects = self.predictor == "defects"
        fresh = defects and unknowns <= self.trust_max_unknowns
        values = dict(tol=self.tol * scale, stall=self.stall * scale, stall_complex=self.stall_complex,
                      maxiter=float(self.maxiter), refresh=self.refresh,
                      floor=self.refresh_floor * scale if defects else 0.0,
                      horizon=float(self.horizon(unknowns)) if defects else 0.0,
                      accept=1.0 if self.accept_unconverged else 0.0,
                      velocity=1.0 if self.predictor == "velocity" else 0.0,
                      depth=float(self.depth) if self.predictor == "defects" else 0.0,
                      trust=self.trust if fresh else -1.0,
                      age=float(self.jacobian_age), every=float(self.jacobian_every),
                      least=2.0 if defects else 1.0, rec=float(self.recurrence) if defects else 0.0,
                      carry=max(self.trust_floor, self.refresh_floor) * scale if defects else 0.0,
                      fine=64 * np.finfo(np.float64).eps * scale,
                      dither=DITHER if self.dither and not double_double else 0.0,
                      settle=SETTLE if self.settle and fresh and not self.dither and self.tol == 0
                      and not double_double else 0.0,
                      settle_accept=SETTLE_ACCEPT)
        return np.array([values[name] for name in Newton._fields], dtype=np.float64)


def theta_dd(system, q2):
    """ϑ(q) in double-double at the points q2 (n, d, 2) of (hi, lo) pairs: (n, d, 2)."""
    q2 = np.ascontiguousarray(q2, dtype=np.float64)
    n, d = q2.shape[:2]
    out = np.zeros_like(q2)
    ev, _ = point_functions(system, precision="double-double")
    k = system.param_vector()
    theta_dd_points(ev, k, q2, out, np.zeros(2 * d * d), np.zeros(2 * d * d * d), np.zeros(2 * d), np.zeros(2 * d * d))
    return out


def scalars_dd(system, q2):
    """H and the Noether momentum (0 without one) in double-double at the points q2 (n, d, 2):
    (n, 2, 2), [:, 0] H and [:, 1] the momentum as (hi, lo) pairs."""
    q2 = np.ascontiguousarray(q2, dtype=np.float64)
    out = np.zeros((q2.shape[0], 2, 2))
    k = system.param_vector()
    scalars_dd_points(load_module(system, "double-double").scalars_dd, k, q2, out)
    return out


class Engine:
    """The step map Φ_h of one (tableau, projection) pair for a system, compiled.

    ``advance(state, first, nsteps)`` advances every live point of ``state`` by ``nsteps`` steps;
    ``tolerances`` (a :class:`Tolerances`) sets Newton's stopping rule.
    """

    def __init__(self, system, tableau, projection, h, tolerances=None, precision="double"):
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {', '.join(map(repr, PRECISIONS))}, got {precision!r}")
        self.precision = precision
        why = admission(tableau, projection)
        if why:
            raise ValueError(why)
        self.system, self.tableau, self.h = system, tableau, float(h)
        self.projection = projection
        self.record = rec = projection_record(projection)
        s, d = tableau.s, system.d
        lob = tableau.d is not None
        self.plan = kernel.Plan(*rec.codes(tableau), lob)
        self.post = kernel.PAPER if rec.post_term is None else rec.post_term
        self._entry = None if rec.post_term is None else post_entry(rec.post_term)
        self.nz = kernel.unknowns_of(s, d, rec.coupled, lob).nz
        self.k = system.param_vector()
        self.tolerances = tolerances if tolerances is not None else Tolerances()
        if not isinstance(self.tolerances, Tolerances):
            raise ValueError(f"tolerances must be an integrators.engine.Tolerances, got {type(tolerances).__name__}")
        self.tab = kernel.flat_tableau(tableau, predictor(tableau.c, self.tolerances.predictor))
        self._cfg = self.tolerances.array(unknowns=self.nz)
        self._cfg_dd = self.tolerances.array(double_double=True, unknowns=self.nz)
        self._functions = {}

    @property
    def width(self):
        """W of this pair's vector path on real states of many points: kernel.WIDE (16) for Newton
        systems of at most kernel.WIDE_NZ unknowns, kernel.LANES (8) above
        (:func:`integrators.kernel.lane_width`)."""
        return lane_width(self.nz)

    def lanes_for(self, n, double_double=False):
        """The W a call on ``n`` points takes by default: 1 below kernel.LANES points; kernel.LANES
        for double-double states; else :func:`integrators.kernel.lane_width` (16 lanes for a small
        Newton system and at least kernel.WIDE_POINTS points, 8 otherwise)."""
        return 1 if n < LANES else (LANES if double_double else lane_width(self.nz, n))

    def warm(self, q):
        """Compile now (or load from numba's cache) what a call on the points ``q`` (n, d) will run:
        the kernel's specialisation for this dimension, precision and default W, and the system's
        point function of that W.  Nothing is advanced (the state's points are not live)."""
        q = np.asarray(q, dtype=np.float64)
        W = self.lanes_for(q.shape[0], self.precision == "double-double")
        st = self.state(np.repeat(q[:1], W, axis=0))
        st.live[:] = False
        self.advance(st, 1, 1, lanes=W)

    def pair(self, newton=None):
        """What every step of this pair reads, as the kernel takes it (:class:`integrators.kernel.Pair`):
        the parameter values, the flat tableau, the projection's plan, h and Newton's rule (``newton``:
        the array of a :class:`integrators.kernel.Newton` record; None: this engine's for doubles).
        The one place the kernel's pair data is made."""
        return Pair(self.k, self.tab, tuple(self.plan), self.h, self._cfg if newton is None else newton)

    def _layout(self):
        """kernel.layout of this pair as the three int64 arrays the kernel takes."""
        if not hasattr(self, "_lay"):
            self._lay = tuple(np.array(rec, dtype=np.int64) for rec in layout(self.tableau.s, self.system.d, self.nz))
        return self._lay

    def state(self, q, p=None, lam=None, dtype=np.float64):
        """The state of points q (n, d) with p = ϑ(q) unless given and λ = 0 unless given; in the
        engine's precision (double-double: q, p, λ may be (n, d, 2) pairs or doubles, taken exactly,
        and ϑ(q) is evaluated in double-double).  A projected pair (a projection after Ψ_h) starts on
        the constraint: p = ϑ(q) whatever is given, as the map (q, p, λ) ↦ (q₁, p₁, λ₁) of a
        projected step reads no p (its later steps start from the p its solve left there)."""
        fresh = p is None or self.record.post
        if self.precision == "double-double":
            q = np.asarray(q, dtype=np.float64)
            q2 = np.ascontiguousarray(np.stack([q, np.zeros_like(q)], axis=-1) if q.ndim == 2 else q)
            p = theta_dd(self.system, q2) if fresh else p
            lam = np.zeros(q2.shape[:2]) if lam is None else lam
            return State.double_double(q2, p, lam, self.h, self.tableau.s)
        q = np.asarray(q)
        p = self.system.theta(q) if fresh else p
        lam = np.zeros_like(q) if lam is None else lam
        return State(q, p, lam, self.h, self.tableau.s, dtype)

    def advance(self, state, first, nsteps, t0=0.0, block=BLOCK, lanes=None):
        """Steps number first … first + nsteps − 1 (step k aims at t0 + k·h) for every live point.
        The numbers matter beyond the times: the default takes its Jacobians by a schedule of step
        numbers (``Tolerances.jacobian_every``), so a run split into calls gives the bits of one
        call when each call goes on from the last one's number.

        ``lanes``: W, points advanced together in SIMD lanes (1, kernel.LANES or kernel.WIDE; None:
        :meth:`lanes_for` the state's points).  Any choice gives the same bits.  Returns the :class:`LaneUse` of the call
        (how many group steps the lanes took)."""
        return self._advance(state, first, nsteps, t0, block, lanes, 0, 0)

    def advance_outputs(self, state, first, nsteps, every, t0=0.0, block=BLOCK, lanes=None):
        """:meth:`advance`, and the outputs inside the call: for every step number n = k·every with
        first ≤ n < first + nsteps − 1 (the call's last step is ``state`` itself), an
        :class:`Output` of every point's q, p, Λ, live and breakdown time as they were after step n,
        the same values that a call ending at n would leave in ``state`` (bits included).  A point
        keeps its lane through the whole call, so its Newton factors and predictor table are not
        moved through memory at every output (docs/benchmarks.md, "What a call costs").  Returns
        (LaneUse, [(n, Output)]).
        """
        every = int(every)
        if every < 1:
            raise ValueError(f"every must be a positive number of steps, got {every!r}")
        last = int(first) + int(nsteps) - 1
        steps = list(range(-(-int(first) // every) * every, last, every))
        live0, bt0 = state.live.copy(), state.breakdown_time.copy()
        use, snap = self._advance(state, first, nsteps, t0, block, lanes, every, len(steps))
        sq, sp, sl, mark = snap
        outs = []
        for k, n in enumerate(steps):
            got = mark[k] != 0
            keep = got.reshape((-1,) + (1,) * (state.q.ndim - 1))
            outs.append((n, Output(np.where(keep, sq[k], state.q), np.where(keep, sp[k], state.p),
                                   np.where(keep, sl[k], state.Lam), got,
                                   np.where(live0 & ~got, state.breakdown_time, bt0))))
        return use, outs

    def _advance(self, state, first, nsteps, t0, block, lanes, every, K):
        spec = self._specialise(state, lanes)
        rounds = self._rounds(state, block)
        arrays = state._tuple(self.nz)
        if state.needs_factors:
            self._refactor(state, arrays, spec.number == "double-double", spec.number == "complex step")
        shape = (K,) + state.q.shape
        snap = (np.empty(shape, state.q.dtype), np.empty(shape, state.q.dtype), np.empty(shape, state.q.dtype),
                np.zeros((K, state.q.shape[0]), np.uint8))
        records = (self.pair(spec.newton), kernel.Span(float(t0), int(first), int(nsteps)), arrays,
                   kernel.Shape((0,) * self.system.d, spec.proto, self._layout(), int(block)),
                   kernel.Outputs(rounds, snap, int(every) if K > 0 else 0))
        if self._entry is not None:             # a post term of the projection's own, cached
            self._entry(spec.ev, spec.inside, *records)
        else:                                   # the paper's (or a post term without source: uncached)
            kernel.advance(spec.ev, spec.inside, self.post, *records)
        use = LaneUse(spec.lanes, *(int(x) for x in rounds.sum(axis=0)))
        return (use, snap) if every else use

    def _specialise(self, state, lanes=None):
        """The :class:`Specialisation` a call on ``state`` takes: its number type (a double-double
        state: (n, d, 2) values; complex step: complex values, always W = 1), the lane width (``lanes``,
        or :meth:`lanes_for` the state's points; W = 1 where the system's functions have no lane
        form), the point functions of that specialisation (compiled once per engine) and what the
        kernel is handed for it (Newton's rule with TOL and STALL scaled to 2⁻¹⁰⁴ for double-double;
        the prototype of a lane value: W zeros of the number type)."""
        dd = state.q.ndim == 3
        W = self.lanes_for(state.q.shape[0], dd) if lanes is None else lanes
        if W not in (1, kernel.LANES, kernel.WIDE) or (dd and W == kernel.WIDE):
            widths = f"1 or {kernel.LANES}" if dd else f"1, {kernel.LANES} or {kernel.WIDE}"
            raise ValueError(f"lanes must be {widths}, got {lanes!r}")
        cplx = not dd and bool(np.iscomplexobj(state.q))
        number = "double-double" if dd else "complex step" if cplx else "double"
        W = 1 if cplx else W
        key = ("dd", W) if dd else (cplx, W)
        if key not in self._functions:
            if dd:
                ev, inside = point_functions(self.system, lanes=W, precision="double-double")
            else:
                ev, inside = point_functions(self.system, cplx, lanes=W)
            if ev is None:              # no lane form of one of the system's functions
                ev, inside = point_functions(self.system, precision="double-double") if dd else \
                    point_functions(self.system, cplx)
                W = 1
            self._functions[key] = ev, inside, W
        ev, inside, W = self._functions[key]
        return Specialisation(number, W, ev, inside, self._cfg_dd if dd else self._cfg,
                              (0.0,) * W if dd else (0,) * W)

    def _refactor(self, state, arrays, double_double, cplx):
        """The Newton factors of a state that notes them but does not hold them (read from a
        checkpoint), rebuilt where they were taken, by the scalar path (kernel.refactor)."""
        key = ("dd", 1) if double_double else (cplx, 1)
        if key not in self._functions:
            ev, inside = point_functions(self.system, cplx, precision="double-double") if double_double else \
                point_functions(self.system, cplx)
            self._functions[key] = ev, inside, 1
        ev = self._functions[key][0]
        kernel.refactor(ev, self.pair(), arrays,
                        kernel.Shape((0,) * self.system.d, (0.0,) if double_double else (0,), self._layout(), 1))
        state.needs_factors = False

    @staticmethod
    def _rounds(state, block):
        if int(block) < 1:
            raise ValueError(f"block must be a positive number of points, got {block!r}")
        return np.zeros((-(-state.q.shape[0] // int(block)), 3), dtype=np.int64)


class MapEngine:
    """A user's batched step map ``step(q, p, lam, h, system) -> (q, p, lam)`` (the audit's contract)
    behind the Engine interface, so a scene's ``run.step_maps`` go through the same time loop, driver,
    checkpoints and plots.  The map is called once per step on the live points; a point whose result
    is not finite or leaves the domain breaks down there, and a map that raises stops every live
    point at that step (one line on stderr).  Bits are the map's own business: a map that treats
    each point on its own gives the same file for any rank count.  On a canonical
    phase space of black-box maps (integrators.service.phase_space) the map is ``step(x, v, h) -> (x, v)`` or ``step(q, h) -> q``."""

    def __init__(self, step, system, h, name="map"):
        if getattr(system, "black_box", False):
            step = system.engine_step(step)
        self.step, self.system, self.h, self.name = step, system, float(h), name
        self.nz = 0

    def state(self, q, p=None, lam=None):
        q = np.asarray(q, dtype=np.float64)
        p = self.system.theta(q) if p is None else p
        lam = np.zeros_like(q) if lam is None else lam
        return State(q, p, lam, self.h, 1)

    def advance(self, state, first, nsteps, t0=0.0, block=BLOCK):
        h, sy = self.h, self.system
        for j in range(nsteps):
            idx = np.flatnonzero(state.live)
            if idx.size == 0:
                return
            q, p, lam = state.q[idx], state.p[idx], state.Lam[idx] / h
            try:
                with np.errstate(all="ignore"):
                    got = tuple(np.asarray(x) for x in self.step(q, p, lam, h, sy))
                    if len(got) != 3 or any(x.dtype.kind not in "fiub" for x in got):
                        raise ValueError("returned " + (f"{len(got)} arrays" if len(got) != 3 else "values of types "
                                         + ", ".join(str(x.dtype) for x in got)) + " (real q, p, lam are expected: "
                                         "an imaginary part is not dropped)")
                    q1, p1, l1 = (x.astype(np.float64) for x in got)
                if q1.shape != q.shape or p1.shape != q.shape or l1.shape != q.shape:
                    raise ValueError(f"returned shapes {q1.shape}, {p1.shape}, {l1.shape} for {q.shape}")
            except Exception as exc:      # the user's map failed: its points stop here, the run goes on
                print(f"poincare: step map {self.name} raised {type(exc).__name__}: {exc} at step {first + j}; "
                      "its points stop there", file=sys.stderr)
                q1 = np.full_like(q, np.nan)
                p1 = l1 = q1
            good = np.all(np.isfinite(q1) & np.isfinite(p1) & np.isfinite(l1), axis=1)
            good &= sy.in_domain(np.where(np.isfinite(q1), q1, 0.0))
            ok, bad = idx[good], idx[~good]
            state.q[ok], state.p[ok], state.Lam[ok] = q1[good], p1[good], h * l1[good]
            state.steps[ok] += 1
            state.have_history[ok] = True
            state.live[bad] = False
            state.breakdown_time[bad] = t0 + (first + j) * h


class Specialisation(NamedTuple):
    """What selects the compiled code of a kernel call, in one place (:meth:`Engine._specialise`):
    ``number`` ("double", "complex step" or "double-double") and ``lanes`` (W), with that
    specialisation's point functions ``ev``, ``inside`` and what the kernel is handed for it:
    ``newton`` (Tolerances.array, scaled for double-double) and ``proto`` (W zeros of the number
    type, which selects the kernel's lane type).  Any W gives a point the same bits."""
    number: str
    lanes: int
    ev: object
    inside: object
    newton: np.ndarray
    proto: tuple


PREDICTORS = ("defects", "extrapolate", "velocity")
PRECISIONS = ("double", "double-double")


def predictor(c, kind="extrapolate"):
    """The stage guess E (s × (s + 1)) of the next step: Y_i ≈ Σ_j E_ij Y_j + E_is h·q̇(q_n), Y_j the
    last step's stage displacements (h times the stage velocities, at nodes c_j − 1).

    ``"extrapolate"`` (and ``"defects"``, which corrects it in the kernel): the Lagrange polynomial
    through the Y_j, evaluated at c_i (last column zero).
    ``"velocity"``: the same with h·q̇(q_n) at node 0 (one degree more); a stage at c_j = 1 sits on
    that node and is left out.
    """
    c = np.asarray(c, dtype=np.float64)
    s = c.size
    E = np.zeros((s, s + 1))
    if kind in ("extrapolate", "defects"):
        E[:, :s] = _lagrange_matrix(c - 1.0, c)
    elif kind == "velocity":
        keep = np.flatnonzero(np.abs(c - 1.0) > 1e-12)
        L = _lagrange_matrix(np.r_[c[keep] - 1.0, 0.0], c)
        E[:, keep] = L[:, :-1]
        E[:, s] = L[:, -1]
    else:
        raise ValueError(f"unknown predictor {kind!r}")
    return E


def _lagrange_matrix(nodes, targets):
    """E with E_ij = ℓ_j(targets_i) for the Lagrange basis on ``nodes``: the next step's stage guess
    from the last step's stage values (nodes c_j − 1 extrapolated to c_i).  One step's stages only:
    extrapolating from two steps gains nothing for s ≥ 2 and spoils the guess for SRK3
    (docs/benchmarks-history.md)."""
    E = np.ones((len(targets), len(nodes)))
    for i, x in enumerate(targets):
        for j, xj in enumerate(nodes):
            for k, xk in enumerate(nodes):
                if k != j:
                    E[i, j] *= (x - xk) / (xj - xk)
    return E


SNAPSHOT_BYTES = 32 << 20     # march's outputs inside one call (q, p, Λ of every point): at most this


class Hooks(NamedTuple):
    """What :func:`march` calls back, each optional: ``on_output(step)`` (or ``on_output(step,
    output)``), ``progress(step)``, ``check()`` and ``light(step)``."""
    on_output: object = None
    progress: object = None
    check: object = None
    light: object = None


def march(engine, state, start, stop, every, hooks=Hooks(), t0=0.0, target=0.25, block=BLOCK):
    """The time loop: advance ``state`` from step ``start`` to ``stop``, calling back ``hooks``
    (:class:`Hooks`).

    After every step that is a multiple of ``every``, ``on_output(step)`` is called (a checkpoint
    may be written there).  The kernel is called for as many steps as take about ``target`` seconds
    (never past an output), with ``progress(step)`` and ``check()`` (which may raise to stop the
    run) between calls; how the steps are grouped, and ``every``, change no bits (the state carries
    Newton's factors across calls, and a checkpoint notes where they were taken).  Returns the seconds spent advancing.

    ``light(step)``: True where the output at ``step`` needs only the points' q, p, Λ, live and
    breakdown times (not a checkpoint).  Then a call may run past such outputs
    (:meth:`Engine.advance_outputs`) and ``on_output(step, output)`` is called with an
    :class:`Output` in place of the state, the same values; the call ends at the next output that is
    not light.  On paper_poincare's points a call of 10 steps cost 1.5× the steps of one long call
    (docs/benchmarks.md, "What a call costs").  Engines without ``advance_outputs`` (a step map)
    end every call at an output, as without ``light``.
    """
    on_output, progress, check, light = hooks
    outputs = light is not None and hasattr(engine, "advance_outputs")
    if outputs:     # outputs of one call held at once: at most SNAPSHOT_BYTES
        most = max(1, SNAPSHOT_BYTES // max(1, 3 * state.q.nbytes))
    step, batch, spent = start, 1, 0.0
    while step < stop:
        if check is not None:
            check()
        to_output = every - step % every
        n = max(1, min(batch, stop - step))
        if not outputs:
            n = min(n, to_output)
        else:                     # on to the first output that is not light (or holds too many before it)
            o, k = step + to_output, 0
            while o < step + n and light(o) and k < most:
                o, k = o + every, k + 1
            n = min(n, o - step)
        t = time.perf_counter()
        if outputs and n > to_output:
            _, inside = engine.advance_outputs(state, step + 1, n, every, t0, block)
        else:
            engine.advance(state, step + 1, n, t0, block)
            inside = []
        dt = time.perf_counter() - t
        spent += dt
        step += n
        batch = int(min(max(1, n * target / dt if dt > 0 else 2 * n), 4 * n, 1 << 20))
        if on_output is not None:
            for at, out in inside:
                on_output(at, out)
            if step % every == 0:
                on_output(step)
        if progress is not None:
            progress(step)
    return spent
