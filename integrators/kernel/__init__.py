"""The compiled step engine's kernel: (projected) VPRK steps of W points at once, in numba.

Nothing here knows a system, a tableau or a projection by name.  The system enters as compiled
point functions generated from its symbolic ϑ and H by :mod:`integrators.codegen`:

    ev(q, k, need, th, T, TT, dH, HH)   ϑ, ϑ_q [k, i], ∇H and, when ``need``, ϑ_qq [k, i, j], ∇²H at q
    inside(q, k) -> bool                 q is finite and inside the system's domain (one point)

with ``k`` the parameter values and every matrix flattened row-major; the W-lane ``ev`` takes
lane-interleaved arrays.  The tableau is one flat array made and read only here
(:func:`flat_tableau`, :func:`_coefficients`), the projection a :class:`Plan` made by
:class:`integrators.projections.Projection` from the paper's table.  So one compilation serves
every system, tableau and projection; the dtype (float64 for runs, complex128 for the audit's
complex-step derivatives), the dimension d and the lane count W make the others.

**Lanes.**  The code is written once against :mod:`integrators.simd`: given W-lane pointers it
advances W points in lockstep, every arithmetic operation a packed instruction over the lanes;
given plain pointers (W = 1) it is the scalar path, one point at a time (the single-trajectory
path and the complex-step audit).  Every decision stays per point: Newton's convergence, the
Jacobian refresh, the retry and the breakdown are per-lane masks; a lane that has converged is held
at its solution while the others iterate; a lane that asks for fresh factors gets them (all lanes
are factorised, only the lanes that asked keep theirs), and pivoting is per lane.  So a point's
bits are those of the scalar path whatever W, whichever points share its lanes, and for any thread
or rank count (tests/test_lanes.py).  No fastmath, no fused multiply–add.

The unknowns of a step are z = [Y_1 … Y_s, Λ (coupled projections), μ (Lobatto)] with
Y_i = h V_i the stage displacements and Λ = hλ (see integrators/projections.py); where each part
starts is :class:`Unknowns`, made in one place (``records.unknowns``, ``unknowns_of``).  Newton uses the
exact Jacobian, factorised by a small dense LU with partial pivoting and kept across iterations and
steps while it contracts.  The state records where each point's factors were taken (the iterate z,
and q_n and Λ_n of that step): :func:`refactor` rebuilds the same factors from it, so a run resumed
from a checkpoint, or split into calls anywhere, is bitwise the run in one call.

**The modules, by role** (each imports only those above it):

    records     what crosses into the kernel, by name: constants, Plan, Newton, StateArrays, the scratch layout
    linalg      per-lane LU, ϑ_q products, error-free sums
    equations   the step's equations and their Jacobian (eq:vprk_1 - eq:vprk_3, the coupled projections' rows)
    projection  the post term: the paper's (project) and a projection's own (post_term)
    newton      Newton's method on W lanes and its stopping rule
    predictor   the guess each step starts from
    step        one step of W points: Newton, the projection, the compensated sums, the commit
    blocks      the entry points: advance, refactor, probe

This package exports what the rest of the code uses; the tests reach the others by module.
"""
from __future__ import annotations

from ..projections import END, MIDPOINT, PRE_NONE, PRE_PREVIOUS, PRE_UNKNOWN, START
from .blocks import advance, advance_argument, probe, refactor, scalars_dd_points, theta_dd_points
from .equations import evaluate, exact_points
from .linalg import _weighted_sum, apply, contract, rounding, transpose_apply
from .predictor import _guess, _recurrence
from .projection import PAPER, post_term, project
from .records import (AR, COMPLEX_STEP, DEPTH, LANES, ORDERS, RECURRENCE, ROUNDS, WIDE, WIDE_NZ, WIDE_POINTS, Coefficients,
                      Newton, Outputs, Pair, Plan, Shape, Span, StateArrays, Unknowns, flat_tableau, lane_width, layout,
                      unknowns_of)

__all__ = ["END", "MIDPOINT", "PRE_NONE", "PRE_PREVIOUS", "PRE_UNKNOWN", "START", "advance", "advance_argument", "probe",
           "refactor", "scalars_dd_points", "theta_dd_points", "exact_points", "_weighted_sum", "_guess", "_recurrence",
           "PAPER", "post_term", "project", "AR", "COMPLEX_STEP", "DEPTH", "LANES", "RECURRENCE", "WIDE", "WIDE_NZ",
           "WIDE_POINTS", "Coefficients", "Newton", "Plan", "StateArrays", "flat_tableau", "lane_width", "layout", "ORDERS",
           "ROUNDS", "Outputs", "Pair", "Shape", "Span", "Unknowns", "unknowns_of", "evaluate", "apply", "contract", "rounding", "transpose_apply"]
