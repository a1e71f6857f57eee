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
Y_i = h V_i the stage displacements and Λ = hλ (see integrators/projections.py).  Newton uses the
exact Jacobian, factorised by a small dense LU with partial pivoting and kept across iterations and
steps while it contracts.  The state records where each point's factors were taken (the iterate z,
and q_n and Λ_n of that step): :func:`refactor` rebuilds the same factors from it, so a run resumed
from a checkpoint, or split into calls anywhere, is bitwise the run in one call.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, prange, types
from numba.np.unsafe.ndarray import to_fixed_tuple
from numba.extending import overload

from .ddouble import DDType, dd

# where ϑ and its derivatives are evaluated (the point slots of the scratch and a projection's
# `at`), and the perturbation before Ψ_h: codes owned by integrators.projections
from .projections import END, MIDPOINT, PRE_NONE, PRE_PREVIOUS, PRE_UNKNOWN, START  # noqa: F401 (PRE_NONE: the codes by name)
from .simd import DDVec, LanePtr, Vec, _at, anyl, at, elem, elem3, is_complex, ld, ldi, lget, lanes, lmask, lset, mand, \
    mnot, mor, nlanes, plain, put, put3, raw, re, sel, st, sti, step_measure

_OPTS = dict(cache=True, error_model="numpy", nogil=True)

COMPLEX_STEP = 1e-30    # the audit's complex-step size: imaginary parts are derivatives × this
# (Newton's tolerances, iteration limit and refresh threshold are run-time data: their one owner is
# integrators.engine.Tolerances)

LANES = 8               # W of the vector path: 8 doubles fill an AVX-512 register, two AVX2 ones
WIDE = 16               # W for Newton systems up to WIDE_NZ unknowns (real states): two registers of
WIDE_NZ = 28            # lanes, whose independent chains hide each other's latency in the LU and the
#                         solve: every pair at d = 4 (GLRK6-symmetric has 28).  Once the scratch was
#                         aligned (_aligned), 16 lanes beat 8 by 1.25-1.31x at 16-28 unknowns too
#                         (SRK3-, GLRK4-, GLRK5-, GLRK6-, LobIIIB4-symmetric; docs/benchmarks.md,
#                         "Aligned lanes"); the old bound of 12 was measured on unaligned scratch
#                         (docs/benchmarks-history.md, "Sixteen lanes for small Newton systems").
DEPTH = 8               # the stage predictor's memory: the defects of the last DEPTH steps' guesses
RECURRENCE = 4          # the most coefficients of the defects' fitted linear recurrence (_recurrence)
AR = float(DEPTH + 1)   # the order (F.ordy, F.ordl) that stands for the recurrence's prediction
#                         (:func:`_guess`; how many a pair uses is Newton.depth, run-time data)
WIDE_POINTS = 1024      # ... and only for calls of at least this many points: a second width is a
#                         second compilation of the kernel (~35 s a dimension), paid where a run is
#                         long enough to gain it back, not by every small scene and test.


def lane_width(nz, n=WIDE_POINTS):
    """W of a real state's vector path for a pair with ``nz`` Newton unknowns and a call on ``n``
    points (n >= LANES): WIDE up to WIDE_NZ unknowns for at least WIDE_POINTS points, else LANES.
    Any W gives a point the same bits (tests/test_lanes.py)."""
    return WIDE if nz <= WIDE_NZ and n >= WIDE_POINTS else LANES

# -- the projection as the kernel reads it ------------------------------------------------------

Plan = namedtuple("Plan", "pre pre_at post post_at sigma lobatto")
Plan.__doc__ = """A projection as the kernel reads it (made by Projection.plan): ``pre`` one of PRE_*,
``pre_at``/``post_at`` where ϑ_q of the pre/post terms is taken (START, MIDPOINT, END), ``post``
whether the step ends on the constraint, ``sigma`` the post term's weight, ``lobatto`` whether the
tableau has the Lobatto constraint μ (eq:vprk_lobatto)."""

# -- the tableau's flat layout, made and read here only ----------------------------------------

Coefficients = namedtuple("Coefficients", "a a_lo abar abar_lo b b_lo d d_lo E")


def flat_tableau(tableau, E):
    """[a, a_lo, ā, ā_lo, b, b_lo, d, d_lo, E] as one float64 array (double + correction coefficients,
    the Lobatto constraint vector d with its correction, zero when unused, and the stage guess E,
    s × (s + 1): the next stages from the last step's s stage values and h·q̇(q_n),
    :func:`integrators.engine.predictor`).  The double kernel reads d alone (as it always has); the
    double-double kernel d + d_lo (:func:`_lobatto`)."""
    s = tableau.s
    d, d_lo = np.zeros(s), np.zeros(s)
    if tableau.d is not None:
        d = np.asarray(tableau.d, dtype=np.float64)
        exact = tableau.exact.get("d") if tableau.exact else None
        if exact is not None:
            import mpmath
            with mpmath.workdps(60):
                d_lo = np.array([float(mpmath.mpf(x) - mpmath.mpf(float(hi))) for x, hi in zip(exact, d)])
    parts = (tableau.a, tableau.a_lo, tableau.abar, tableau.abar_lo, tableau.b, tableau.b_lo, d, d_lo, E)
    return np.concatenate([np.asarray(x, dtype=np.float64).ravel() for x in parts])


@njit(inline='always', **_OPTS)
def _coefficients(tb, s):
    ss = s * s
    return Coefficients(_at(tb, 0), _at(tb, ss), _at(tb, 2 * ss), _at(tb, 3 * ss), _at(tb, 4 * ss),
                        _at(tb, 4 * ss + s), _at(tb, 4 * ss + 2 * s), _at(tb, 4 * ss + 3 * s), _at(tb, 4 * ss + 4 * s))


def lobatto_d(c, i, like):
    """The Lobatto weight d_i (eq:vprk_lobatto) in the precision of ``like``: the double d_i, or for
    a double-double ``like`` the double-double d_i + d_lo_i."""


def lobatto_ratio(c, i, like):
    """d_i / b_i in the precision of ``like`` (double: d_i / b_i of the doubles, as always)."""


@overload(lobatto_d, inline="always")
def _lobatto_d(c, i, like):
    if isinstance(like, (DDType, DDVec)):
        return lambda c, i, like: dd(c.d[i], c.d_lo[i])
    return lambda c, i, like: c.d[i]


@overload(lobatto_ratio, inline="always")
def _lobatto_ratio(c, i, like):
    if isinstance(like, (DDType, DDVec)):
        return lambda c, i, like: dd(c.d[i], c.d_lo[i]) / dd(c.b[i], c.b_lo[i])
    return lambda c, i, like: c.d[i] / c.b[i]


def exact_points(like):
    """Whether the equations see the points they are evaluated at exactly (a compile-time constant):
    in plain doubles a point q̄ + x is rounded to double, and what the rounding drops, e (:func:`rounding`),
    enters the residual as ϑ_q e, so that the residual resolves every increment to its own size
    (:func:`_residual`); double-double values carry their own low part and complex-step values a
    derivative, so there the points are taken as they are."""


@overload(exact_points, inline="always")
def _exact_points(like):
    yes = isinstance(like, (Vec, types.Float))
    return lambda like: yes


@njit(inline='always', **_OPTS)
def rounding(a, b, s):
    """(a + b) − s exactly, for s = fl(a + b) (Knuth's TwoSum)."""
    bb = s - a
    return (a - (s - bb)) + (b - bb)


@njit(**_OPTS)
def product_rounding(a, b, p):
    """a·b − p exactly, for p = fl(a·b) (Dekker's TwoProduct with Veltkamp's splitting: no fused
    multiply-add, so the same bits on every machine; exact while |a|, |b| < 2⁹⁹⁶)."""
    ca = 134217729.0 * a                    # 2²⁷ + 1
    ah = ca - (ca - a)
    al = a - ah
    cb = 134217729.0 * b
    bh = cb - (cb - b)
    bl = b - bh
    return ((ah * bh - p) + ah * bl + al * bh) + al * bl


@njit(**_OPTS)
def _weighted_sum(wt, wt_lo, o, v, s, d, m):
    """Σ_i (wt_{o+i} + wt_lo_{o+i}) v_{i,m} as (the sum rounded to double, what that rounding
    dropped): each product's and each addition's rounding error is kept (:func:`product_rounding`,
    :func:`rounding`) and summed apart, so the pair is the sum to O(ε²) of its size (Ogita, Rump
    and Oishi's Dot2).  Compiled apart, not inlined into numba's IR (LLVM still inlines it): the
    same bits and speed, and 10 s less compilation per kernel (docs/benchmarks-history.md)."""
    x = ld(v, m)
    acc = wt[o] * x
    err = product_rounding(wt[o], x, acc) + wt_lo[o] * x
    for i in range(1, s):
        x = ld(v, i * d + m)
        pr = wt[o + i] * x
        t = acc + pr
        err = err + ((rounding(acc, pr, t) + product_rounding(wt[o + i], x, pr)) + wt_lo[o + i] * x)
        acc = t
    out = acc + err
    return out, err - (out - acc)


# -- the scratch: named offsets into one buffer per group of W points ---------------------------

Scratch = namedtuple("Scratch", [
    # stage values: Q_i, ϑ(Q_i), ϑ_q, ϑ_qq, ∇H, ∇²H, G_i = ϑ_q(Q_i)ᵀY_i − h∇H(Q_i), K_i = ∂G_i/∂Q_i
    "Q", "th", "T", "TT", "dH", "HH", "G", "K",
    # ϑ_q(Q_i) e_i: the linear part of ϑ over Q_i's rounding error e_i (:func:`_stages`, plain doubles)
    "tE",
    # the point slots START, MIDPOINT, END: ϑ, ϑ_q, ϑ_qq, ∇H, ∇²H
    "pth", "pT", "pTT", "pdH", "pHH",
    # d-vectors
    "qbar", "pbar", "q0", "pb", "sY", "sG", "q1", "p1", "mid", "tl", "qh", "ph", "vf", "inc", "qn", "qcn", "pn",
    "pcn", "ln", "sYs", "eQ", "qbe", "qhe", "pbe", "pwe", "phe", "sYe", "sGe", "ince", "qr",
    # Newton: unknowns, evaluated iterate, residual, fresh Jacobian, projection's Newton, guesses
    "z", "zev", "r", "Jt", "S", "PL", "pz", "pzev", "pr", "pJ", "guess",
    # the predictor: this step's base guess (stages, Λ, μ) and the last steps' defects from theirs
    # (the guess itself, ``guess``, has the same layout: s·d stages, then Λ, then μ)
    "base", "D",
    # the recurrence: the last DEPTH defects, the normal equations of its fit, its prediction of δ
    "dh", "gram", "ar",
    # the points' own state while the group is advanced; jz, jq, jl: where its factors lu were taken
    "q", "p", "lam", "qc", "pc", "Y", "mu", "lu", "jz", "jq", "jl",
    "size"])
Scratch.__doc__ = "Offsets (in logical elements; × W in memory) of the scratch buffers of a group."

Flags = namedtuple("Flags", [
    "scale", "pscale",            # every unknown relative to its coordinate's size (nz, d)
    "done", "ok", "stale", "prev", "its", "norm", "nan", "finite",   # Newton's per-lane bookkeeping
    "exact",                      # the last iteration's factors were taken at its own iterate (_judge)
    "have", "hist", "live", "active", "okstep", "tbrk", "itn", "stp",   # the points' step flags
    "jn",                         # the steps a lane's point has taken in this call
    "depth",                      # the predictor's defects the lane's point holds (0 … DEPTH)
    "ordy", "ordl",               # the order of the defects' extrapolation: stages, multipliers
    "trust",                      # the last guess was good: a Jacobian at the guess, not carried
    "age",                        # the steps since the lane's factors were taken
    "held",                       # whether the lane holds a point (IntScratch.pt)
    "retry",                      # the lane's step failed once: its next _step is the second try
    "gits",                       # (lane 0) the Newton iterations the group has run
    "gjac",                       # (lane 0) the Jacobians it has evaluated and factorised
    "size"])
Flags.__doc__ = "Offsets of the per-lane real (never complex) bookkeeping."

IntScratch = namedtuple("IntScratch", "piv pivt ipiv pt size")


D_VECTORS = Scratch._fields[Scratch._fields.index("qbar"):Scratch._fields.index("qr") + 1]


def _offsets(record, sizes):
    """record(offset of each field, in the order of the fields, …, total): the buffers laid end to end."""
    out, at_ = [], 0
    for name in record._fields[:-1]:
        out.append(at_)
        at_ += sizes[name]
    return record(*out, at_)


def layout(s, d, nz):
    """The three scratch layouts of a group (:class:`Scratch`, :class:`Flags`, :class:`IntScratch`),
    each buffer's size given by its name: the offsets in the order of the fields, the total last.
    Made in Python (Engine._layout, probe) and handed to the kernel as three int64 arrays, which it
    turns back into the records (:func:`_records`: numba's parallel loop takes no named tuples)."""
    dd, sd = d * d, s * d
    S = _offsets(Scratch, dict(
        Q=sd, tE=sd, th=sd, T=s * dd, TT=s * dd * d, dH=sd, HH=s * dd, G=sd, K=s * dd,
        pth=3 * d, pT=3 * dd, pTT=3 * dd * d, pdH=3 * d, pHH=3 * dd,
        **dict.fromkeys(D_VECTORS, d),
        z=nz, zev=nz, r=nz, Jt=nz * nz, S=2 * dd, PL=dd, pz=d, pzev=d, pr=d, pJ=dd, guess=sd + 2 * d,
        base=sd + 2 * d, D=DEPTH * (sd + 2 * d), dh=DEPTH * d, gram=RECURRENCE * (RECURRENCE + 1),
        ar=sd + 2 * d,
        q=d, p=d, lam=d, qc=d, pc=d, Y=sd, mu=d, lu=nz * nz, jz=nz, jq=d, jl=d))
    F = _offsets(Flags, dict(dict.fromkeys(Flags._fields[:-1], 1), scale=nz, pscale=d))
    IP = _offsets(IntScratch, dict(piv=nz, pivt=nz, ipiv=d, pt=1))
    return S, F, IP


Newton = namedtuple("Newton", "tol stall stall_complex maxiter refresh floor horizon accept velocity depth trust age every least rec "
                               "carry fine")
Newton.__doc__ = """Newton's stopping rule and the predictor as the kernel reads them (the float64 array of
:meth:`integrators.engine.Tolerances.array`, by name): converged at max |δ|/scale ≤ ``tol``, or ≤
``stall`` (``stall_complex`` for complex-step values) once the update stops halving; at most
``maxiter`` iterations; a fresh Jacobian after an iteration that contracted by less than
``refresh`` while its update was larger than ``floor`` (below it the ratio is round-off's) and
the factors would not reach ``tol`` within ``horizon`` more iterations at that rate (0: no such
test);
``accept`` (≠ 0) takes a finite unconverged iterate after maxiter; ``velocity`` (≠ 0)
adds h·q̇(q_n) to the stage predictor; ``depth`` (0 … DEPTH) how many of the last steps' defects
correct the guess (:func:`_guess`); a step whose last guess was off by at most ``trust`` (relative)
and by more than ``carry`` (from closer, the carried factors converge in about three iterations)
starts its Newton from a Jacobian at the guess instead of the factors carried from the last step
(negative: never) once those factors are ``age`` steps old, at the steps whose number is a multiple of
``every`` (so the lanes of a group take theirs together); a lane converges at its ``least``-th
iteration at the earliest (2 with the defects: the guess itself is never the solution); ``rec``
coefficients (0: none) of the defects' fitted linear recurrence (:func:`_recurrence`); an update of at most
``fine`` (64 ulps of the number type) that stops halving is at the round-off floor (:func:`_judge`)."""

StateArrays = namedtuple("StateArrays", "q p Lam q_comp p_comp Y mu have_history live breakdown_time iterations steps "
                                        "lu piv have_lu jac_z jac_q jac_lam defects orders")
StateArrays.__doc__ = """The per-point arrays of integrators.engine.State as the kernel takes them (State._tuple:
a plain tuple in this order, the boolean flags viewed as uint8; value arrays with a last axis of 2
in double-double)."""

MODE_MAIN, MODE_POST = 0, 1     # what _newton solves: the step's equations, or the consecutive projection

Step = namedtuple("Step", "post k h tb plan cfg")
Step.__doc__ = """What a step of a pair reads besides the point functions, by name (made once per block in
:func:`_block`): the projection's ``post`` term (PAPER, or a projection's own compiled function:
:func:`post_term`), the parameters ``k``, the step size ``h``, the flat tableau ``tb``, the
:class:`Plan` and Newton's rule ``cfg`` (a :class:`Newton` record).  The point functions ``ev`` and
``inside`` travel beside it: inside a tuple numba would make them first-class function values,
called through a pointer it cannot see through (measured: 20-25 % of a step's time)."""

Group = namedtuple("Group", "w S f F ip IP qr")
Group.__doc__ = """The scratch of one group of W lanes, by name (made once per block in :func:`_block`): the
value buffer ``w`` and its :class:`Scratch` offsets ``S``, the real bookkeeping ``f`` and its :class:`Flags`
``F``, the integers ``ip`` and their :class:`IntScratch` ``IP``, and ``qr`` (d doubles: one lane's
q_{n+1} for the domain test)."""


N_SCRATCH, N_FLAGS, N_INT = len(Scratch._fields), len(Flags._fields), len(IntScratch._fields)


@njit(inline='always', **_OPTS)
def _records(lay):
    """The :func:`layout` records from their arrays (Engine._layout)."""
    return (Scratch(*to_fixed_tuple(lay[0], N_SCRATCH)), Flags(*to_fixed_tuple(lay[1], N_FLAGS)),
            IntScratch(*to_fixed_tuple(lay[2], N_INT)))


@njit(inline='always', **_OPTS)
def _newton_rule(c):
    return Newton(c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10], c[11], c[12], c[13], c[14], c[15],
                  c[16])


@njit(inline='always', **_OPTS)
def _runtime(k, like):
    """The integer k as a value the compiler cannot fold into a constant (``like`` is any runtime
    integer): a literal argument would compile the callee once per value (``_newton``'s mode)."""
    return like - like + k


# -- small dense linear algebra, per lane ---------------------------------------------------------

def pivot(A, piv, col, n):
    """Partial pivoting of column ``col``, each lane on its own: the first row at or below col whose
    |real part| is strictly the largest becomes the pivot (piv[col]), and rows col and that one swap
    (the whole row, as LAPACK does)."""


@overload(pivot, inline="always")
def _pivot(A, piv, col, n):
    if _real_lanes(A):
        def vector(A, piv, col, n):       # W real lanes: the search by compares and selects
            best = abs(ld(A, col * n + col))
            p = sel(best == best, float(col), float(col))
            for i in range(col + 1, n):
                v = abs(ld(A, i * n + col))
                larger = v > best
                best = sel(larger, v, best)
                p = sel(larger, float(i), p)
            sti(piv, col, p)
            for i in range(col + 1, n):
                swap = p == float(i)
                if anyl(swap):
                    for j in range(n):
                        a, b = ld(A, col * n + j), ld(A, i * n + j)
                        st(A, col * n + j, sel(swap, b, a))
                        st(A, i * n + j, sel(swap, a, b))
        return vector

    def lanewise(A, piv, col, n):         # one lane, complex-step or double-double values: lane by lane
        for l in range(nlanes(A)):
            p = col
            best = abs(re(lget(A, col * n + col, l)))
            for i in range(col + 1, n):
                v = abs(re(lget(A, i * n + col, l)))
                if v > best:
                    best, p = v, i
            lset(piv, col, l, p)
            if p != col:
                for j in range(n):
                    tmp = lget(A, col * n + j, l)
                    lset(A, col * n + j, l, lget(A, p * n + j, l))
                    lset(A, p * n + j, l, tmp)
    return lanewise


@njit(inline='always', **_OPTS)
def lu_factor(A, piv, n):
    """In-place LU of the n×n row-major A with partial pivoting, each lane its own pivots (chosen on
    the real part, so the complex-step specialisation pivots exactly as the real one).  A zero pivot
    is left in place: the solve then gives inf/NaN, which the Newton iteration reads as a failure."""
    for col in range(n):
        pivot(A, piv, col, n)
        inv = 1.0 / ld(A, col * n + col)
        for i in range(col + 1, n):
            f = ld(A, i * n + col) * inv
            st(A, i * n + col, f)
            nonzero = f != 0.0
            if not anyl(mnot(nonzero)):           # every lane eliminates: no selects needed
                for j in range(col + 1, n):
                    st(A, i * n + j, ld(A, i * n + j) - f * ld(A, col * n + j))
            elif anyl(nonzero):
                for j in range(col + 1, n):
                    x = ld(A, i * n + j)
                    st(A, i * n + j, sel(nonzero, x - f * ld(A, col * n + j), x))


def _real_lanes(A):
    """Whether A is a pointer to W > 1 lanes of doubles (the vector forms of the pivoting)."""
    return isinstance(A, LanePtr) and A.W > 1 and A.dtype == types.float64


def permute(piv, x, n):
    """x[i] ⇄ x[piv[i]] for i = 0 … n − 1, each lane with its own pivots (the row swaps of
    :func:`lu_factor` applied to a right-hand side)."""


@overload(permute, inline="always")
def _permute(piv, x, n):
    if _real_lanes(x):
        def vector(piv, x, n):            # W real lanes: compares and selects, nothing lane by lane
            for i in range(n):
                p = ldi(piv, i)
                if anyl(p != float(i)):
                    xi = ld(x, i)
                    new = xi
                    for r in range(i + 1, n):
                        here = p == float(r)
                        if anyl(here):
                            xr = ld(x, r)
                            st(x, r, sel(here, xi, xr))
                            new = sel(here, xr, new)
                    st(x, i, new)
        return vector

    def lanewise(piv, x, n):              # one lane, complex-step or double-double values
        for i in range(n):
            for l in range(nlanes(x)):
                p = lget(piv, i, l)
                if p != i:
                    tmp = lget(x, i, l)
                    lset(x, i, l, lget(x, p, l))
                    lset(x, p, l, tmp)
    return lanewise


@njit(inline='always', **_OPTS)
def lu_solve(A, piv, x, n):
    """Solve A x = b in place (x holds b on entry) with the factors of :func:`lu_factor`."""
    permute(piv, x, n)
    for i in range(n):
        acc = ld(x, i)
        for j in range(i):
            acc = acc - ld(A, i * n + j) * ld(x, j)
        st(x, i, acc)
    for i in range(n - 1, -1, -1):
        acc = ld(x, i)
        for j in range(i + 1, n):
            acc = acc - ld(A, i * n + j) * ld(x, j)
        st(x, i, acc / ld(A, i * n + i))


@njit(inline='always', **_OPTS)
def _tapply(T, v, out, d):
    """out_m = Σ_l T[l, m] v_l  (ϑ_qᵀ v)."""
    for m in range(d):
        acc = ld(T, m) * ld(v, 0)
        for l in range(1, d):
            acc = acc + ld(T, l * d + m) * ld(v, l)
        st(out, m, acc)


@njit(inline='always', **_OPTS)
def _apply(T, v, out, d):
    """out_l = Σ_m T[l, m] v_m  (ϑ_q v)."""
    for l in range(d):
        acc = ld(T, l * d) * ld(v, 0)
        for m in range(1, d):
            acc = acc + ld(T, l * d + m) * ld(v, m)
        st(out, l, acc)


@njit(inline='always', **_OPTS)
def _contract(TT, v, out, d):
    """out[m, n] = Σ_l TT[l, m, n] v_l  (∂(ϑ_qᵀ v)/∂q)."""
    dd = d * d
    for mn in range(dd):
        acc = ld(TT, mn) * ld(v, 0)
        for l in range(1, d):
            acc = acc + ld(TT, l * dd + mn) * ld(v, l)
        st(out, mn, acc)


@njit(inline='always', **_OPTS)
def _eval(ev, k, x, need, w, S, slot, d):
    """ϑ and its derivatives at x into point slot ``slot`` (START, MIDPOINT or END)."""
    dd = d * d
    ev(raw(x), k, need, raw(at(w, S.pth + slot * d)), raw(at(w, S.pT + slot * dd)),
       raw(at(w, S.pTT + slot * dd * d)), raw(at(w, S.pdH + slot * d)), raw(at(w, S.pHH + slot * dd)))


# -- the step's equations ---------------------------------------------------------------------

@njit(inline='always', **_OPTS)
def _stages(z, jac, ev, k, h, c, q0, s, d, w, S):
    """Q_i = q̃ + Σ_j a_ij Y_j, their ϑ, ϑ_q, ∇H, and G_i = ϑ_q(Q_i)ᵀY_i − h∇H(Q_i) (eq:vprk_1,
    eq:vprk_3); with ``jac`` also K_i = ∂G_i/∂Q_i.  Then Σ b_i Y_i and Σ b_i G_i (sY, sG), double +
    correction weights.  In plain doubles every sum is formed to O(ε²) (:func:`_weighted_sum`):
    ϑ_q(Q_i) e_i goes to tE, e_i what forming Q_i in doubles dropped (Σ_j a_ij Y_j's rounding,
    q̃ + that sum's, q̃'s own ``S.eQ``: :func:`exact_points`), and what rounding the two sums to
    double dropped to ``S.sYe``, ``S.sGe``."""
    dd = d * d
    ddd = dd * d
    Q, th, T, TT, dH, HH = at(w, S.Q), at(w, S.th), at(w, S.T), at(w, S.TT), at(w, S.dH), at(w, S.HH)
    G, K, sY, sG = at(w, S.G), at(w, S.K), at(w, S.sY), at(w, S.sG)
    exact = exact_points(ld(q0, 0))
    e0, e, tE = at(w, S.eQ), at(w, S.tl), at(w, S.tE)
    for i in range(s):
        for m in range(d):
            if exact:                           # Σ_j a_ij Y_j to O(ε²), its error into e_i
                x, xe = _weighted_sum(c.a, c.a_lo, i * s, z, s, d, m)
                Qm = ld(q0, m) + x
                st(Q, i * d + m, Qm)
                st(e, m, (rounding(ld(q0, m), x, Qm) + xe) + ld(e0, m))
                continue
            acc = c.a[i * s] * ld(z, m)
            for j in range(1, s):
                acc = acc + c.a[i * s + j] * ld(z, j * d + m)
            cor = c.a_lo[i * s] * ld(z, m)
            for j in range(1, s):
                cor = cor + c.a_lo[i * s + j] * ld(z, j * d + m)
            x = acc + cor
            Qm = ld(q0, m) + x
            st(Q, i * d + m, Qm)
        ev(raw(at(Q, i * d)), k, jac, raw(at(th, i * d)), raw(at(T, i * dd)), raw(at(TT, i * ddd)),
           raw(at(dH, i * d)), raw(at(HH, i * dd)))
        if exact:
            _apply(at(T, i * dd), e, at(tE, i * d), d)
        Gi = at(G, i * d)
        _tapply(at(T, i * dd), at(z, i * d), Gi, d)
        for m in range(d):
            st(Gi, m, ld(Gi, m) - h * ld(dH, i * d + m))
        if jac:
            Ki = at(K, i * dd)
            _contract(at(TT, i * ddd), at(z, i * d), Ki, d)
            for mn in range(dd):
                st(Ki, mn, ld(Ki, mn) - h * ld(HH, i * dd + mn))
    for m in range(d):
        if exact:                               # the increments to O(ε²): what rounding them drops
            y, ye = _weighted_sum(c.b, c.b_lo, 0, z, s, d, m)       # goes to sYe, sGe
            g, ge = _weighted_sum(c.b, c.b_lo, 0, G, s, d, m)
            st(sY, m, y)
            st(sG, m, g)
            st(w, S.sYe + m, ye)
            st(w, S.sGe + m, ge)
            continue
        acc = c.b[0] * ld(z, m)
        cor = c.b_lo[0] * ld(z, m)
        accg = c.b[0] * ld(G, m)
        corg = c.b_lo[0] * ld(G, m)
        for i in range(1, s):
            acc = acc + c.b[i] * ld(z, i * d + m)
            cor = cor + c.b_lo[i] * ld(z, i * d + m)
            accg = accg + c.b[i] * ld(G, i * d + m)
            corg = corg + c.b_lo[i] * ld(G, i * d + m)
        st(sY, m, acc + cor)
        st(sG, m, accg + corg)


@njit(inline='always', **_OPTS)
def _residual(z, jac, r, ev, k, h, c, plan, d, s, w, S):
    """The residual of the step's equations; returns the slot of ϑ_q in the pre term.

    R_i = ϑ(Q_i) − p̃ − Σ_j ā_ij G_j (+ μ d_i/b_i)  (eq:vprk_2, eq:vprk_lobatto).  With a coupled
    projection q̃ = q̄ + Λ, p̃ = p̄ + ϑ_q(x_pre)ᵀΛ (eq:symmetric_projection_pre,
    eq:symplectic_midpoint_projection_pre) and the constraint row R_Λ = p_{n+1} − ϑ(q_{n+1}) with
    q_{n+1} = q̃ + Σ b_i Y_i + σΛ, p_{n+1} = p̃ + Σ b_i G_i + σ ϑ_q(x_post)ᵀΛ (the matching _post).

    In plain doubles ϑ at a point is taken as ϑ(x) + ϑ_q(x) e, e what rounding x = q̄ + … to double
    dropped (:func:`exact_points`): ϑ(Q_i) − p̃ is then the increment's own, to its own relative
    precision, not to an ulp of q.  Without it the part of Y below an ulp of q is left where the
    guess put it, and the compensated sum of q_{n+1} accumulates it (a constant of the motion kept
    exactly in exact arithmetic then walks off by whole ulps, one sign: docs/brouwer.md).
    """
    dd = d * d
    sd = s * d
    coupled = plan.pre == PRE_UNKNOWN
    iL = sd
    iM = sd + d if coupled else sd
    qbar, pbar, q0, pb = at(w, S.qbar), at(w, S.pbar), at(w, S.q0), at(w, S.pb)
    sY, sG, q1, p1, mid, tl = at(w, S.sY), at(w, S.sG), at(w, S.q1), at(w, S.p1), at(w, S.mid), at(w, S.tl)
    th, G, pth, pT, tE, pwe = at(w, S.th), at(w, S.G), at(w, S.pth), at(w, S.pT), at(w, S.tE), at(w, S.pwe)
    Lz = at(z, iL)
    exact = exact_points(ld(qbar, 0))
    qbe, e0 = at(w, S.qbe), at(w, S.eQ)
    for m in range(d):
        if coupled:
            q0m = ld(qbar, m) + ld(Lz, m)
            st(q0, m, q0m)
            if exact:
                st(e0, m, ld(qbe, m) + rounding(ld(qbar, m), ld(Lz, m), q0m))
        else:
            st(q0, m, ld(qbar, m))
            if exact:
                st(e0, m, ld(qbe, m))
    _stages(z, jac, ev, k, h, c, q0, s, d, w, S)
    px = START
    if coupled:
        if plan.pre_at == MIDPOINT:        # ϑ_q at the unprojected midpoint q̄_{n+1/2}
            for m in range(d):
                st(mid, m, ld(q0, m) + 0.5 * ld(sY, m))
            _eval(ev, k, mid, jac, w, S, MIDPOINT, d)
            px = MIDPOINT
        _tapply(at(pT, px * dd), Lz, pb, d)
        for m in range(d):
            pbm = ld(pbar, m) + ld(pb, m)
            if exact:
                st(pwe, m, ld(w, S.pbe + m) + rounding(ld(pbar, m), ld(pb, m), pbm))
            st(pb, m, pbm)
    else:
        for m in range(d):
            st(pb, m, ld(pbar, m))
            if exact:
                st(pwe, m, ld(w, S.pbe + m))
    for i in range(s):
        for m in range(d):
            acc = c.abar[i * s] * ld(G, m)
            for j in range(1, s):
                acc = acc + c.abar[i * s + j] * ld(G, j * d + m)
            cor = c.abar_lo[i * s] * ld(G, m)
            for j in range(1, s):
                cor = cor + c.abar_lo[i * s + j] * ld(G, j * d + m)
            rr = ld(th, i * d + m) - ld(pb, m)
            if exact:
                rr = (rr + ld(tE, i * d + m)) - ld(pwe, m)
            rr = rr - (acc + cor)
            if plan.lobatto:
                rr = rr + ld(z, iM + m) * lobatto_ratio(c, i, rr)
            st(r, i * d + m, rr)
    if coupled:
        e1 = at(w, S.qhe)
        for m in range(d):
            a = ld(q0, m) + ld(sY, m)
            q1m = a + plan.sigma * ld(Lz, m)
            st(q1, m, q1m)
            if exact:
                st(e1, m, (ld(e0, m) + ld(w, S.sYe + m)) + rounding(ld(q0, m), ld(sY, m), a)
                   + rounding(a, plan.sigma * ld(Lz, m), q1m))
        _eval(ev, k, q1, jac, w, S, END, d)
        pp = END if plan.post_at == END else px
        _tapply(at(pT, pp * dd), Lz, tl, d)
        if exact:
            _apply(at(pT, END * dd), e1, at(w, S.eQ), d)        # ϑ_q(q_{n+1}) e_{n+1} (q̃'s e0 is used)
        for m in range(d):
            a = ld(pb, m) + ld(sG, m)
            p1m = a + plan.sigma * ld(tl, m)
            st(p1, m, p1m)
            rl = p1m - ld(pth, END * d + m)
            if exact:
                pe = ((ld(pwe, m) + ld(w, S.sGe + m)) + rounding(ld(pb, m), ld(sG, m), a)
                      + rounding(a, plan.sigma * ld(tl, m), p1m))
                rl = (rl + pe) - ld(w, S.eQ + m)
            st(r, iL + m, rl)
    if plan.lobatto:
        for m in range(d):
            z0 = ld(z, m)
            acc = lobatto_d(c, 0, z0) * z0
            for i in range(1, s):
                acc = acc + lobatto_d(c, i, z0) * ld(z, i * d + m)
            st(r, iM + m, acc)
    return px


@njit(inline='always', **_OPTS)
def _stage_jacobian(J, nz, c, plan, d, s, w, S):
    """∂R_i/∂Y_j: a_ij ϑ_q(Q_i) − ā_ij ϑ_q(Q_j)ᵀ − Σ_l ā_il a_lj K_l (− b_j S_x/2 at the midpoint)."""
    dd = d * d
    T, K, Sx = at(w, S.T), at(w, S.K), at(w, S.S)
    mid = plan.pre == PRE_UNKNOWN and plan.pre_at == MIDPOINT
    for i in range(s):
        for j in range(s):
            aij, abij = c.a[i * s + j], c.abar[i * s + j]
            for m in range(d):
                for n in range(d):
                    B = aij * ld(T, i * dd + m * d + n) - abij * ld(T, j * dd + n * d + m)
                    for l in range(s):
                        cc = c.abar[i * s + l] * c.a[l * s + j]
                        if cc != 0.0:
                            B = B - cc * ld(K, l * dd + m * d + n)
                    if mid:
                        B = B - (0.5 * c.b[j]) * ld(Sx, m * d + n)
                    st(J, (i * d + m) * nz + j * d + n, B)


@njit(inline='always', **_OPTS)
def _projection_jacobian(J, nz, px, c, plan, d, s, w, S):
    """The coupled projection's rows and columns: ∂R_i/∂Λ, ∂R_Λ/∂Λ and ∂R_Λ/∂Y_j (the derivatives of
    the pre and post terms of eq:symmetric_projection_pre/_post and the midpoint's)."""
    dd = d * d
    sd = s * d
    iL = sd
    T, K, pT = at(w, S.T), at(w, S.K), at(w, S.pT)
    Sx, S1 = at(w, S.S), at(w, S.S + dd)
    sig = plan.sigma
    Tx = at(pT, px * dd)
    T1 = at(pT, END * dd)
    Tp = T1 if plan.post_at == END else Tx
    spost = S1 if plan.post_at == END else Sx
    upost = (1.0 + sig) if plan.post_at == END else 1.0      # ∂x_post/∂Λ
    cpost = 1.0 if plan.post_at == END else 0.5              # ∂x_post/∂Y_j = cpost b_j
    mid = plan.pre_at == MIDPOINT
    for m in range(d):
        for n in range(d):
            dpb = ld(Tx, n * d + m)                          # ∂p̃/∂Λ = ϑ_q(x_pre)ᵀ (+ S_x at the midpoint)
            if mid:
                dpb = dpb + ld(Sx, m * d + n)
            for i in range(s):
                B = ld(T, i * dd + m * d + n)
                for l in range(s):
                    if c.abar[i * s + l] != 0.0:
                        B = B - c.abar[i * s + l] * ld(K, l * dd + m * d + n)
                st(J, (i * d + m) * nz + iL + n, B - dpb)
            KS = c.b[0] * ld(K, m * d + n)
            for l in range(1, s):
                KS = KS + c.b[l] * ld(K, l * dd + m * d + n)
            st(J, (iL + m) * nz + iL + n, (dpb + sig * ld(Tp, n * d + m) + (sig * upost) * ld(spost, m * d + n)) + KS
               - (1.0 + sig) * ld(T1, m * d + n))
            for j in range(s):
                KB = c.b[0] * c.a[j] * ld(K, m * d + n)
                for l in range(1, s):
                    KB = KB + c.b[l] * c.a[l * s + j] * ld(K, l * dd + m * d + n)
                ey = sig * cpost * ld(spost, m * d + n)
                if mid:
                    ey = ey + 0.5 * ld(Sx, m * d + n)
                st(J, (iL + m) * nz + j * d + n, KB + c.b[j] * ld(T, j * dd + n * d + m) + c.b[j] * ey
                   - c.b[j] * ld(T1, m * d + n))


@njit(inline='always', **_OPTS)
def _main(z, jac, r, J, ev, k, h, tb, plan, d, s, w, S):
    """Residual of the step's equations (:func:`_residual`) and, when ``jac``, their exact Jacobian
    into J (:func:`_stage_jacobian`, :func:`_projection_jacobian`, the Lobatto rows)."""
    c = _coefficients(tb, s)
    px = _residual(z, jac, r, ev, k, h, c, plan, d, s, w, S)
    if not jac:
        return
    dd = d * d
    ddd = dd * d
    sd = s * d
    coupled = plan.pre == PRE_UNKNOWN
    nz = sd + (d if coupled else 0) + (d if plan.lobatto else 0)
    for i in range(nz * nz):
        st(J, i, 0.0)
    Lz, pTT = at(z, sd), at(w, S.pTT)
    if coupled and plan.pre_at == MIDPOINT:
        _contract(at(pTT, MIDPOINT * ddd), Lz, at(w, S.S), d)        # ∂(ϑ_q(M)ᵀΛ)/∂M
    if coupled and plan.post_at == END:
        _contract(at(pTT, END * ddd), Lz, at(w, S.S + dd), d)       # ∂(ϑ_q(q1)ᵀΛ)/∂q1
    _stage_jacobian(J, nz, c, plan, d, s, w, S)
    if coupled:
        _projection_jacobian(J, nz, px, c, plan, d, s, w, S)
    if plan.lobatto:
        iM = sd + d if coupled else sd
        for i in range(s):
            for m in range(d):
                st(J, (i * d + m) * nz + iM + m, c.d[i] / c.b[i])
                st(J, (iM + m) * nz + i * d + m, c.d[i])


@njit(inline='always', **_OPTS)
def project(z, jac, r, J, ev, k, sig, d, w, S):
    """The post term of the consecutive projections (standard, symplectic): ϑ(q̂ + σΛ) = p̂ + σ
    ϑ_q(q̂ + σΛ)ᵀΛ, to be solved for Λ (eq:orthogonal_projection, eq:symplectic_projection_post).

    The contract of every post term (a projection's ``post_term``; :func:`_newton` calls it in
    MODE_POST, d unknowns): from the core's unprojected end point q̂, p̂ (``S.qh``, ``S.ph``, the
    step's q̄ + ΣbY, p̄ + ΣbG) and the iterate Λ = ``z``, write p_{n+1} into ``S.p1``, the d
    residuals into ``r`` and, when ``jac``, their Jacobian ∂r/∂Λ row-major into ``J``.  The kernel
    then takes q_{n+1} = q̂ + σΛ (by compensated summation) and p_{n+1}; ``ev(x, k, jac, …)`` at a
    point slot (:func:`_eval`) gives ϑ and its derivatives.  In plain doubles (``exact_points``)
    ``S.qhe`` and ``S.phe`` hold what rounding q̂ and p̂ to double dropped: a post term resolves Λ
    below an ulp of q when its residual sees its sums exactly, as this one does (ϑ at q̂ + σΛ as
    ϑ + ϑ_q e, e that error plus its own sum's, :func:`rounding`; p̂ + σϑ_qᵀΛ with its errors
    added); one that does not still converges, to an ulp of q."""
    dd = d * d
    qh, ph, q1, p1, tl = at(w, S.qh), at(w, S.ph), at(w, S.q1), at(w, S.p1), at(w, S.tl)
    th1, T1, TT1 = at(w, S.pth + END * d), at(w, S.pT + END * dd), at(w, S.pTT + END * dd * d)
    exact = exact_points(ld(qh, 0))
    e1, te = at(w, S.eQ), at(w, S.tE)
    for m in range(d):
        q1m = ld(qh, m) + sig * ld(z, m)
        st(q1, m, q1m)
        if exact:
            st(e1, m, ld(w, S.qhe + m) + rounding(ld(qh, m), sig * ld(z, m), q1m))
    _eval(ev, k, q1, jac, w, S, END, d)
    _tapply(T1, z, tl, d)
    if exact:
        _apply(T1, e1, te, d)
    for m in range(d):
        p1m = ld(ph, m) + sig * ld(tl, m)
        st(p1, m, p1m)
        rm = p1m - ld(th1, m)
        if exact:
            rm = (rm + (ld(w, S.phe + m) + rounding(ld(ph, m), sig * ld(tl, m), p1m))) - ld(te, m)
        st(r, m, rm)
    if jac:
        S1 = at(w, S.S + dd)
        _contract(TT1, z, S1, d)
        for m in range(d):
            for n in range(d):
                st(J, m * d + n, sig * (ld(T1, n * d + m) - ld(T1, m * d + n)) + (sig * sig) * ld(S1, m * d + n))


PAPER = 0      # ``post`` of the paper's projections: :func:`project`, compiled in (a function argument
#                would key the kernel on a Python object, which numba's cache cannot find again)


def post_term(post, z, jac, r, J, ev, k, sig, d, w, S):
    """The post term ``post`` (PAPER: :func:`project`; else a projection's own compiled function,
    called with the same arguments), chosen when the kernel is compiled."""


@overload(post_term, inline="always")
def _post_term(post, z, jac, r, J, ev, k, sig, d, w, S):
    if isinstance(post, types.Integer):
        return lambda post, z, jac, r, J, ev, k, sig, d, w, S: project(z, jac, r, J, ev, k, sig, d, w, S)
    return lambda post, z, jac, r, J, ev, k, sig, d, w, S: post(z, jac, r, J, ev, k, sig, d, w, S)


@njit(inline='always', **_OPTS)
def _keep_factors(LU, piv, Jt, pivt, stale, nz):
    """The fresh factors Jt, pivt (every lane's) into LU, piv for the lanes that asked (``stale``)."""
    for i in range(nz * nz):
        st(LU, i, sel(stale, ld(Jt, i), ld(LU, i)))
    for i in range(nz):
        sti(piv, i, sel(stale, ldi(pivt, i), ldi(piv, i)))


@njit(inline='always', **_OPTS)
def _note_jacobian(z, stale, nz, d, w, S):
    """The point a fresh Jacobian was taken at (the iterate z, and the step's q_n and Λ_n) into jz,
    jq, jl for the lanes ``stale``."""
    jz, jq, jl, q, lam = at(w, S.jz), at(w, S.jq), at(w, S.jl), at(w, S.q), at(w, S.lam)
    for i in range(nz):
        st(jz, i, sel(stale, ld(z, i), ld(jz, i)))
    for m in range(d):
        st(jq, m, sel(stale, ld(q, m), ld(jq, m)))
        st(jl, m, sel(stale, ld(lam, m), ld(jl, m)))


@njit(inline='always', **_OPTS)
def _update(z, r, done, scale, nz, f, F):
    """z −= δ (r holds −δ) in the lanes not done; per lane the update's size max |δ|/scale
    (``F.norm``), whether it was NaN and whether the new z is finite."""
    size = sel(done, 0.0, 0.0)
    nan = done
    finite = mnot(done)
    for i in range(nz):
        ri = ld(r, i)
        zi = ld(z, i) - ri
        st(z, i, sel(done, ld(z, i), zi))
        v = step_measure(ri, ld(scale, i), COMPLEX_STEP)
        nan = mor(nan, v != v)
        size = sel(v > size, v, size)
        finite = mand(finite, np.isfinite(zi))
    st(f, F.norm, size)
    st(f, F.nan, sel(nan, 1.0, 0.0))
    st(f, F.finite, sel(finite, 1.0, 0.0))


@njit(inline='always', **_OPTS)
def _judge(f, F, tol, stall, fine, refresh, floor, horizon, least):
    """Each lane still iterating after an update: failed (NaN, not finite), converged (size ≤ tol, or
    ≤ fine² (an update of 10⁻²⁸ of its coordinate, far below what even the compensation term of q
    holds: there is nothing left to halve), or ≤ stall once the update stops halving: within ``fine`` (64 ulps), or wherever the
    iteration before was a Newton step with a Jacobian at its own iterate, after which the update
    falls quadratically unless round-off stops it; factors carried from an earlier step or iterate
    can stop halving far above the floor, or even grow, when the guess was poor: stopping there
    left errors of 10⁴ ulps of one sign in single steps (tests/test_boozer.py), so such a lane
    takes a fresh Jacobian and goes on; from its ``least``-th iteration on: with the defects'
    guess 2, because at small steps that guess is often within tol already, and taking it, not the
    iterate after it, left its extrapolation error, a few ulps of the same sign, in every step:
    SRK3-standard on point vortices at h = 2⁻¹³, 16,384 steps, momentum off by 1.0·10⁻¹³ against
    4.6·10⁻¹⁵ from the extrapolation alone) or on, with a fresh Jacobian next time if this
    iteration contracted by θ > ``refresh``, its update was larger than ``floor`` (an update a few
    thousand ulps small measures round-off, not the factors: a Jacobian there was the engine's
    largest waste on high-order pairs, docs/benchmarks.md) and θ^horizon·|δ| > tol: the factors
    would not converge within ``horizon`` more iterations, about what a Jacobian costs in
    iterations plus the two it takes after (``horizon`` 0: the first two tests alone).  Written
    with masks and selects, so W lanes are judged at once (the same comparisons and the one division of the scalar path, lane by lane)."""
    on = ld(f, F.done) == 0.0
    st(f, F.its, ld(f, F.its) + sel(on, 1.0, 0.0))
    sz, prev = ld(f, F.norm), ld(f, F.prev)
    failed = mor(mor(ld(f, F.nan) != 0.0, ld(f, F.finite) == 0.0), mnot(np.isfinite(sz)))
    theta = sel(np.isfinite(prev), sz / prev, np.inf)
    slow = mand(np.isfinite(theta), theta > 0.5)
    floored = mor(mand(mand(sz <= stall, slow), mor(ld(f, F.exact) != 0.0, sz <= fine)), sz <= fine * fine)
    converged = mand(mand(mnot(failed), mor(sz <= tol, floored)), ld(f, F.its) >= least)
    ends = mand(on, mor(failed, converged))
    goes = mand(on, mnot(ends))
    st(f, F.done, sel(ends, 1.0, ld(f, F.done)))
    st(f, F.ok, sel(mand(on, converged), 1.0, ld(f, F.ok)))
    left = sel(goes, np.inf, np.inf)             # |δ| after ``horizon`` more iterations at rate θ
    if horizon > 0.0:
        left = sz
        for _ in range(int(horizon)):
            left = left * theta
    tired = mand(mand(np.isfinite(theta), theta > refresh), mand(mor(sz > floor, slow), left > tol))   # slow: not floored
    st(f, F.exact, sel(goes, ld(f, F.stale), ld(f, F.exact)))     # this iteration's: the next one's judge
    st(f, F.stale, sel(goes, sel(tired, 1.0, 0.0), ld(f, F.stale)))
    st(f, F.prev, sel(goes, sz, prev))


@njit(**_OPTS)
def _newton(mode, z, zev, r, nz, LU, piv, known, ev, P, d, s, g):
    """Newton's method with the exact Jacobian, kept while it contracts, for every active lane.

    ``mode`` MODE_MAIN solves the step's equations (:func:`_main`), MODE_POST the consecutive projection
    (its post term ``P.post``: :func:`project` for the paper's).  A lane's Jacobian is evaluated and factorised at its first iteration (unless
    ``known``: LU and piv hold its last step's factors) and again after an iteration that shrank
    its update by less than REFRESH.  A lane has converged when max |δ|/scale ≤ STALL once the
    update stops halving within 64 ulps or after an exact Newton step (older factors that stop
    halving above that are refreshed, not taken for the floor: :func:`_judge`), or ≤ TOL (0 by default: every step ends at its round-off floor, so what
    it leaves is round-off and not a remainder of one sign: Brouwer's law, docs/brouwer.md); for complex z the imaginary part, read as a derivative, must pass the
    same test.  A lane that is done is held at its solution ``zev`` (the last iterate at which its
    residual was evaluated; every buffer the equations fill holds that evaluation) while the others
    go on.  Lanes to solve: ``f.active``; the outcome per lane in ``f.ok`` and ``f.its``.  The
    tolerances are runtime data, ``P.cfg`` a :class:`Newton` record (:class:`integrators.engine.Tolerances`);
    with ``cfg.accept`` a finite iterate that has not converged after ``cfg.maxiter`` iterations is
    taken (GeometricIntegrators.jl's stopping rule).
    """
    W = nlanes(z)           # (mode and nz arrive as runtime ints: a literal would compile this twice)
    w, S, f, F, ip, IP, cfg = g.w, g.S, g.f, g.F, g.ip, g.IP, P.cfg
    tol, refresh = cfg.tol, cfg.refresh
    active = ld(f, F.active) != 0.0
    st(f, F.done, sel(active, 0.0, 1.0))
    st(f, F.ok, 0.0)
    st(f, F.its, 0.0)
    st(f, F.prev, np.inf)
    st(f, F.stale, sel(mand(active, mnot(known)), 1.0, 0.0))
    st(f, F.exact, 0.0)
    scale = at(f, F.scale if mode == MODE_MAIN else F.pscale)
    Jt = at(w, S.Jt if mode == MODE_MAIN else S.pJ)
    pivt = at(ip, IP.pivt)
    for _ in range(int(cfg.maxiter)):
        done = ld(f, F.done) != 0.0
        if not anyl(mnot(done)):
            break
        stale = ld(f, F.stale) != 0.0
        for i in range(nz):
            zi = sel(done, ld(zev, i), ld(z, i))
            st(z, i, zi)
            st(zev, i, zi)
        jac = anyl(stale)
        Jx, pivx = (LU, piv) if W == 1 else (Jt, pivt)   # one lane: factorise in place
        if mode == MODE_MAIN:
            _main(z, jac, r, Jx, ev, P.k, P.h, P.tb, P.plan, d, s, w, S)
        else:
            post_term(P.post, z, jac, r, Jx, ev, P.k, P.plan.sigma, d, g.w, g.S)
        if jac:
            lset(f, F.gjac, 0, lget(f, F.gjac, 0) + 1.0)
            lu_factor(Jx, pivx, nz)
            if W > 1:                             # every lane factorised, the lanes that asked keep theirs
                _keep_factors(LU, piv, Jt, pivt, stale, nz)
            if mode == MODE_MAIN:                 # where they were taken: what refactor() rebuilds them from
                _note_jacobian(z, stale, nz, d, w, S)
                st(f, F.age, sel(stale, 0.0, ld(f, F.age)))
        lu_solve(LU, piv, r, nz)                  # r is now −δ
        lset(f, F.gits, 0, lget(f, F.gits, 0) + 1.0)
        _update(z, r, done, scale, nz, f, F)
        _judge(f, F, tol, cfg.stall_complex if is_complex(z) else cfg.stall, cfg.fine, refresh, cfg.floor, cfg.horizon,
               cfg.least)
    for l in range(W):                            # lanes out of iterations
        if lget(f, F.done, l) == 0.0 and cfg.accept != 0 and lget(f, F.its, l) > 0:
            lset(f, F.ok, l, 1.0)


# -- one step of W points ---------------------------------------------------------------------

@njit(inline='always', **_OPTS)
def _none(f, F):
    """A mask with no lane set (of the same type as any other: one compilation of its users)."""
    x = ld(f, F.done)
    return mand(x != x, x == x)


@njit(**_OPTS)
def _velocity(ev, P, q, v, where, d, g):
    """h·q̇(q) into v (lanes ``where``), q̇ solving Ω̄ q̇ = ∇H (eq:euler_lagrange_equations); zero
    where that is not finite."""
    w, S, ip, IP, h = g.w, g.S, g.ip, g.IP, P.h
    _eval(ev, P.k, q, False, w, S, START, d)
    T, dH, PL = at(w, S.pT), at(w, S.pdH), at(w, S.PL)
    for i in range(d):
        for j in range(d):
            st(PL, i * d + j, ld(T, j * d + i) - ld(T, i * d + j))
        st(v, i, ld(dH, i))
    ipiv = at(ip, IP.ipiv)
    lu_factor(PL, ipiv, d)
    lu_solve(PL, ipiv, v, d)
    good = where
    for i in range(d):
        good = mand(good, np.isfinite(ld(v, i)))
    for m in range(d):
        st(v, m, sel(good, h * ld(v, m), 0.0))


@njit(**_OPTS)
def _first_guess(ev, P, q, Y, where, d, s, g):
    """Stage displacements h·q̇(q_n) at every stage (lanes ``where``)."""
    v = at(g.w, g.S.vf)
    _velocity(ev, P, q, v, where, d, g)
    for i in range(s):
        for m in range(d):
            st(Y, i * d + m, sel(where, ld(v, m), ld(Y, i * d + m)))


@njit(inline='always', **_OPTS)
def _prepare(ev, k, plan, d, w, S):
    """q̄, p̄ where Ψ_h starts: projected methods start on the constraint p_n = ϑ(q_n); the symplectic
    projection first adds the last step's Λ_n (eq:symplectic_projection_pre); ϑ_q(q_n) stays in
    the START slot for the symmetric projection's perturbation.  In plain doubles what rounding q̄ and
    p̄ to double dropped goes to ``S.qbe`` and ``S.pbe`` (:func:`exact_points`)."""
    q, p, lam = at(w, S.q), at(w, S.p), at(w, S.lam)
    qbar, pbar, tl, qbe = at(w, S.qbar), at(w, S.pbar), at(w, S.tl), at(w, S.qbe)
    pth, pT = at(w, S.pth), at(w, S.pT)
    exact = exact_points(ld(q, 0))
    if plan.post:
        _eval(ev, k, q, False, w, S, START, d)
    for m in range(d):
        if plan.pre == PRE_PREVIOUS:
            qb = ld(q, m) + ld(lam, m)
            st(qbar, m, qb)
            if exact:
                st(qbe, m, rounding(ld(q, m), ld(lam, m), qb))
        else:
            st(qbar, m, ld(q, m))
            if exact:
                st(qbe, m, 0.0 * ld(q, m))
        st(pbar, m, ld(pth, m) if plan.post else ld(p, m))
    pbe = at(w, S.pbe)
    if exact:
        for m in range(d):
            st(pbe, m, 0.0 * ld(q, m))
    if plan.pre == PRE_PREVIOUS:
        _tapply(pT, lam, tl, d)
        for m in range(d):
            pb = ld(pbar, m) + ld(tl, m)
            if exact:
                st(pbe, m, rounding(ld(pbar, m), ld(tl, m), pb))
            st(pbar, m, pb)


@njit(inline='always', **_OPTS)
def _scale(x):
    """max(|x|, 1), or 1 where that is not finite: the size every unknown is measured against."""
    a = abs(x)
    sc = sel(a > 1.0, a, 1.0)
    return sel(np.isfinite(sc), sc, 1.0)


@njit(**_OPTS)
def _attempt(known, guess, lam0, mu0, ev, inside, P, d, s, nz, g):
    """One step of the lanes ``f.active`` from the stage guess (and the guesses of Λ_{n+1} and μ),
    starting from the kept Newton factors in the lanes ``known``; commits the new state of each lane
    that succeeds.  Per lane: ``f.okstep`` whether it did, ``f.itn`` += iterations."""
    w, S, f, F, ip, IP, plan = g.w, g.S, g.f, g.F, g.ip, g.IP, P.plan
    sd = s * d
    coupled = plan.pre == PRE_UNKNOWN
    iL = sd
    iM = sd + d if coupled else sd
    q, lam = at(w, S.q), at(w, S.lam)
    qbar, pbar, sY, sG, p1 = at(w, S.qbar), at(w, S.pbar), at(w, S.sY), at(w, S.sG), at(w, S.p1)
    z, zev, r = at(w, S.z), at(w, S.zev), at(w, S.r)
    _prepare(ev, P.k, plan, d, w, S)
    for i in range(sd):
        st(z, i, ld(guess, i))
    for m in range(d):
        sc = _scale(ld(q, m))                   # every unknown relative to its coordinate's size
        for i in range(nz // d):
            st(f, F.scale + i * d + m, sc)
        if coupled:
            st(z, iL + m, ld(lam0, m))
        if plan.lobatto:
            st(z, iM + m, ld(mu0, m))
            st(f, F.scale + iM + m, _scale(ld(pbar, m)))
    _newton(_runtime(MODE_MAIN, nz), z, zev, r, nz, at(w, S.lu), at(ip, IP.piv), known, ev, P, d, s, g)
    ok = ld(f, F.ok) != 0.0
    its = ld(f, F.its)
    inc, pn, ln = at(w, S.inc), at(w, S.pn), at(w, S.ln)
    if coupled:                                 # Ψ_h and Λ solved together
        for m in range(d):
            Lm = ld(zev, iL + m)
            a = Lm + ld(sY, m)
            b = plan.sigma * Lm
            im = a + b
            st(inc, m, im)
            if exact_points(Lm):
                st(w, S.ince + m, (ld(w, S.sYe + m) + rounding(Lm, ld(sY, m), a)) + rounding(a, b, im))
            st(pn, m, ld(p1, m))
            st(ln, m, Lm)
    elif plan.post:                             # Ψ_h, then the projection
        qh, ph, sYs = at(w, S.qh), at(w, S.ph), at(w, S.sYs)
        pz, pzev, pr = at(w, S.pz), at(w, S.pzev), at(w, S.pr)
        qhe, qbe, phe, pbe = at(w, S.qhe), at(w, S.qbe), at(w, S.phe), at(w, S.pbe)
        exact = exact_points(ld(qbar, 0))
        for m in range(d):
            st(sYs, m, ld(sY, m))
            qhm = ld(qbar, m) + ld(sY, m)
            st(qh, m, qhm)
            phm = ld(pbar, m) + ld(sG, m)
            st(ph, m, phm)
            if exact:
                st(qhe, m, (ld(qbe, m) + ld(w, S.sYe + m)) + rounding(ld(qbar, m), ld(sY, m), qhm))
                st(phe, m, (ld(pbe, m) + ld(w, S.sGe + m)) + rounding(ld(pbar, m), ld(sG, m), phm))
            st(pz, m, ld(lam0, m))
            st(f, F.pscale + m, _scale(ld(qh, m)))
        _newton(_runtime(MODE_POST, nz), pz, pzev, pr, _runtime(d, nz), at(w, S.PL), at(ip, IP.ipiv), _none(f, F), ev, P,
                d, s, g)
        ok = mand(ok, ld(f, F.ok) != 0.0)
        its = its + ld(f, F.its)
        for m in range(d):
            shift = ld(lam, m) + ld(sYs, m) if plan.pre == PRE_PREVIOUS else ld(sYs, m)
            b = plan.sigma * ld(pzev, m)
            im = shift + b
            st(inc, m, im)
            if exact:
                e = rounding(ld(lam, m), ld(sYs, m), shift) if plan.pre == PRE_PREVIOUS else 0.0 * shift
                st(w, S.ince + m, (ld(w, S.sYe + m) + e) + rounding(shift, b, im))
            st(pn, m, ld(p1, m))
            st(ln, m, ld(pzev, m))
    else:
        for m in range(d):
            st(inc, m, ld(sY, m))
            st(ln, m, 0.0)
            if exact_points(ld(sY, m)):
                st(w, S.ince + m, ld(w, S.sYe + m))
    active = ld(f, F.active) != 0.0
    st(f, F.itn, ld(f, F.itn) + sel(active, its, 0.0))
    _sum_increments(plan, d, w, S)
    for m in range(d):
        ok = mand(ok, mand(np.isfinite(ld(pn, m)), np.isfinite(ld(ln, m))))
    st(f, F.okstep, sel(mand(active, ok), 1.0, 0.0))
    _commit(inside, P, d, s, iM, g)


@njit(inline='always', **_OPTS)
def _sum_increments(plan, d, w, S):
    """q_{n+1} = q_n + inc (and, unprojected, p_{n+1} = p_n + Σ b_i G_i) by compensated summation into
    qn, qcn (pn, pcn); a projected step's pn is already p_{n+1} and keeps its compensation term.  In
    plain doubles what rounding the increment to double dropped (``S.ince``, ``S.sGe``) joins the
    compensation term, so q_{n+1} is the step's own to O(ε²) of the increment (rounded, the
    increment's errors of an ulp of itself added up with one sign on the guiding centre's GLRK4
    pairs: docs/brouwer.md)."""
    q, p, qc, pc, sG = at(w, S.q), at(w, S.p), at(w, S.qc), at(w, S.pc), at(w, S.sG)
    inc, pn, qn, qcn, pcn = at(w, S.inc), at(w, S.pn), at(w, S.qn), at(w, S.qcn), at(w, S.pcn)
    exact = exact_points(ld(q, 0))
    for m in range(d):
        y = ld(inc, m) + (ld(qc, m) + ld(w, S.ince + m)) if exact else ld(inc, m) + ld(qc, m)
        t = ld(q, m) + y
        st(qcn, m, y - (t - ld(q, m)))
        st(qn, m, t)
        if plan.post:
            st(pcn, m, ld(pc, m))
        else:
            y = ld(sG, m) + (ld(pc, m) + ld(w, S.sGe + m)) if exact else ld(sG, m) + ld(pc, m)
            t = ld(p, m) + y
            st(pcn, m, y - (t - ld(p, m)))
            st(pn, m, t)


@njit(inline='always', **_OPTS)
def _commit(inside, P, d, s, iM, g):
    """The lanes whose step succeeded (``f.okstep``) and whose q_{n+1} lies in the domain take the new
    state (q, p, Λ, compensation terms, the stages and μ for the next guess); the others keep theirs."""
    w, S, f, F, qr = g.w, g.S, g.f, g.F, g.qr
    q, p, lam, qc, pc = at(w, S.q), at(w, S.p), at(w, S.lam), at(w, S.qc), at(w, S.pc)
    qn, qcn, pn, pcn, ln, zev = at(w, S.qn), at(w, S.qcn), at(w, S.pn), at(w, S.pcn), at(w, S.ln), at(w, S.zev)
    for l in range(nlanes(w)):
        if lget(f, F.okstep, l) != 0.0:
            for m in range(d):
                qr[m] = re(lget(qn, m, l))
            if not inside(qr, P.k):
                lset(f, F.okstep, l, 0.0)
    commit = ld(f, F.okstep) != 0.0
    if anyl(commit):
        Ys, mus = at(w, S.Y), at(w, S.mu)
        for m in range(d):
            st(q, m, sel(commit, ld(qn, m), ld(q, m)))
            st(qc, m, sel(commit, ld(qcn, m), ld(qc, m)))
            st(p, m, sel(commit, ld(pn, m), ld(p, m)))
            st(pc, m, sel(commit, ld(pcn, m), ld(pc, m)))
            st(lam, m, sel(commit, ld(ln, m), ld(lam, m)))
            if P.plan.lobatto:
                st(mus, m, sel(commit, ld(zev, iM + m), ld(mus, m)))
        for i in range(s * d):
            st(Ys, i, sel(commit, ld(zev, i), ld(Ys, i)))


@njit(inline='always', **_OPTS)
def _base(ev, P, d, s, nl, fresh, g):
    """The guess every predictor starts from, into ``base`` (s·d stages, then Λ (``nl`` = d where
    the projection solves for it, else 0), then μ (Lobatto tableaus)): the
    Lagrange polynomial through the last step's stage values (Y_j at nodes c_j − 1) at the new
    nodes c_i, with h·q̇(q_n) as one more node under ``cfg.velocity``; Λ_n and μ_n as they are."""
    w, S, cfg = g.w, g.S, P.cfg
    c = _coefficients(P.tb, s)
    Ys, v, base, lam, mu = at(w, S.Y), at(w, S.vf), at(w, S.base), at(w, S.lam), at(w, S.mu)
    velocity = cfg.velocity != 0.0
    if velocity:
        _velocity(ev, P, at(w, S.q), v, mnot(fresh), d, g)
    for i in range(s):
        for m in range(d):
            acc = c.E[i * (s + 1)] * ld(Ys, m)
            for j in range(1, s):
                acc = acc + c.E[i * (s + 1) + j] * ld(Ys, j * d + m)
            if velocity:
                acc = acc + c.E[i * (s + 1) + s] * ld(v, m)
            st(base, i * d + m, acc)
    for m in range(nl):
        st(base, s * d + m, ld(lam, m))
    if P.plan.lobatto:
        for m in range(d):
            st(base, s * d + nl + m, ld(mu, m))


@njit(inline='always', **_OPTS)
def _recurrence(m, nb, d, w, S):
    """The defects' next value from a linear recurrence fitted to the last DEPTH of them, into ``ar``.

    δ_j ≈ c_0 δ_{j−1} + … + c_{m−1} δ_{j−m} is fitted by least squares to the first stage's d
    components of the DEPTH − m newest defects (normal equations with a ridge of 10⁻¹⁴ of their
    trace: the defects of a smooth motion are nearly dependent), and then predicts every component:
    δ_{n+1} = Σ_a c_a δ_{n−a} = Σ_k w_k T_k with w_k = (−1)^k Σ_{a ≥ k} c_a C(a, k), straight from
    the difference table.  A polynomial extrapolation is such a recurrence with fixed binomial
    coefficients; a fitted one also follows a uniform rotation (the symmetric guiding centre, to
    round-off) and the parasitic two-step wiggle of the unprojected midpoint rule (GLRK1-none: 2·10⁻⁸
    where the polynomial of order 8 gives 3·10⁻⁴ and the best order 2·10⁻⁶; docs/engine.md).  The first stage's defects come back from their
    differences in ``dh`` (newest first).  Lanes without a full table get a prediction too; the
    caller does not choose it."""
    D, dh, G, ar = at(w, S.D), at(w, S.dh), at(w, S.gram), at(w, S.ar)
    for k in range(DEPTH):
        for i in range(d):
            st(dh, k * d + i, ld(D, k * nb + i))
    for j in range(1, DEPTH):                    # after pass j, dh[j + t] = ∇^t δ_{n−j}: so dh[j] = δ_{n−j}
        for k in range(DEPTH - 1, j - 1, -1):
            for i in range(d):
                st(dh, k * d + i, ld(dh, (k - 1) * d + i) - ld(dh, k * d + i))
    rows = DEPTH - m
    mm = m + 1                                   # G: m rows of m coefficients and the right-hand side
    for a in range(m):
        for b in range(a, mm):
            x0, y0 = (a + 1) * d, (b + 1) * d if b < m else 0
            acc = ld(dh, x0) * ld(dh, y0)
            for j in range(rows):
                for i in range(1 if j == 0 else 0, d):
                    acc = acc + ld(dh, x0 + j * d + i) * ld(dh, y0 + j * d + i)
            st(G, a * mm + b, acc)
            if b < m:
                st(G, b * mm + a, acc)
    tr = ld(G, 0)
    for a in range(1, m):
        tr = tr + ld(G, a * mm + a)
    ridge = 1e-14 * tr / float(m)
    for a in range(m):
        st(G, a * mm + a, ld(G, a * mm + a) + ridge)
    for a in range(m):                           # Gaussian elimination (symmetric positive: no pivots;
        piv = ld(G, a * mm + a)                  # a zero one, where every defect is 0, divides by 1)
        st(G, a * mm + a, sel(piv != 0.0, piv, 1.0))
        inv = 1.0 / ld(G, a * mm + a)
        for b in range(a + 1, m):
            f = ld(G, b * mm + a) * inv
            for c in range(a, mm):
                st(G, b * mm + c, ld(G, b * mm + c) - f * ld(G, a * mm + c))
    for a in range(m - 1, -1, -1):               # the coefficients c_a, in G's last column
        acc = ld(G, a * mm + m)
        for b in range(a + 1, m):
            acc = acc - ld(G, a * mm + b) * ld(G, b * mm + m)
        st(G, a * mm + m, acc / ld(G, a * mm + a))
    for k in range(m):                           # the weights w_k of T_k, into G's first column
        acc = ld(G, k * mm + m)                  # (a = k: C(k, k) = 1)
        binom = 1.0
        for a in range(k + 1, m):
            binom = binom * a / (a - k)          # C(a, k)
            acc = acc + binom * ld(G, a * mm + m)
        st(G, k * mm, -acc if k % 2 else acc)
    for i in range(nb):
        acc = ld(G, 0) * ld(D, i)
        for k in range(1, m):
            acc = acc + ld(G, k * mm) * ld(D, k * nb + i)
        st(ar, i, acc)


@njit(inline='always', **_OPTS)
def _guess(ordy, ordl, depth, rec, nb, sd, w, S):
    """The guess (stages, Λ, μ): ``base`` plus the extrapolated error of the base.  The defects
    δ = solution − base of the last steps are kept as a table of backward differences, T_k = ∇^k δ
    (``D``, newest first); base + T_0 + … + T_{m−1} is the polynomial of degree m − 1 through the
    last m defects, one step on (Newton's backward-difference form), with m per lane: ``ordy`` for
    the stages, ``ordl`` for Λ and μ (0: the base itself; AR: base + the fitted recurrence's
    prediction ``ar``, where ``rec`` > 0).  A step's solution is a smooth function of its q_n, and
    so is the base's error, which this polynomial follows."""
    base, D, guess, ar = at(w, S.base), at(w, S.D), at(w, S.guess), at(w, S.ar)
    for i in range(nb):
        x = ld(base, i)
        acc = x
        order = ordy if i < sd else ordl
        for k in range(depth):
            acc = acc + ld(D, k * nb + i)
            x = sel(order == float(k + 1), acc, x)
        if rec > 0:
            y = ld(base, i) + ld(ar, i)
            x = sel(mand(order == AR, np.isfinite(y)), y, x)
        st(guess, i, x)


@njit(inline='always', **_OPTS)
def _remember(valid, depth, rec, trust, floor, nb, nl, s, d, g):
    """After a step taken from a base (lanes ``valid``): the new defect δ = (Y, Λ, μ)_{n+1} − base
    enters the difference table (T_0 = δ, T_k = T_{k−1} − T_{k−1}^old).  The new T_m is the error
    the guess of order m would have made on this step, so each block (stages; Λ and μ) takes for
    its next guess the order that did best here (among those its history allows), and the lane
    trusts its next stage guess (a Jacobian taken there) when that order's error was at most
    ``trust`` relative to max(|q|, 1), and above ``floor`` (the refresh floor: from a guess that
    close the carried factors converge in the two iterations any start takes, and a Jacobian there
    is waste).  With ``rec`` > 0 the fitted recurrence's prediction (``ar``,
    made before the step from the full table) competes too, as order AR."""
    w, S, f, F = g.w, g.S, g.f, g.F
    base, D, Ys, lam, mu, q = at(w, S.base), at(w, S.D), at(w, S.Y), at(w, S.lam), at(w, S.mu), at(w, S.q)
    cur, inv = at(w, S.guess), at(w, S.tl)       # (the guess is spent; tl is free after _prepare)
    sd = s * d
    held = ld(f, F.depth)
    for m in range(d):
        st(inv, m, 1.0 / _scale(re(ld(q, m))))
    for i in range(nb):
        new = ld(Ys, i) if i < sd else (ld(lam, i - sd) if i < sd + nl else ld(mu, i - sd - nl))
        st(cur, i, new - ld(base, i))
    zero = sel(valid, 0.0, 0.0)
    besty, bestl, ordy, ordl = zero, zero, zero, zero
    ary, arl, arok = zero, zero, held >= float(DEPTH)
    ar = at(w, S.ar)
    for k in range(depth + 1):
        ey, el = zero, zero
        for i in range(nb):
            c = ld(cur, i)
            a = abs(re(c)) * re(ld(inv, i % d))
            if i < sd:
                ey = sel(a > ey, a, ey)
            else:
                el = sel(a > el, a, el)
            if rec > 0 and k == 0:
                e = abs(re(c - ld(ar, i))) * re(ld(inv, i % d))
                arok = mand(arok, np.isfinite(e))
                if i < sd:
                    ary = sel(e > ary, e, ary)
                else:
                    arl = sel(e > arl, e, arl)
            if k < depth:
                old = ld(D, k * nb + i)
                st(D, k * nb + i, sel(valid, c, old))
                st(cur, i, c - old)
        if k == 0:
            besty, bestl = ey, el
        else:
            allowed = held >= float(k)
            better = mand(allowed, ey < besty)
            besty, ordy = sel(better, ey, besty), sel(better, float(k), ordy)
            better = mand(allowed, el < bestl)
            bestl, ordl = sel(better, el, bestl), sel(better, float(k), ordl)
    if rec > 0:
        better = mand(arok, ary < besty)
        besty, ordy = sel(better, ary, besty), sel(better, AR, ordy)
        better = mand(arok, arl < bestl)
        bestl, ordl = sel(better, arl, bestl), sel(better, AR, ordl)
    st(f, F.ordy, sel(valid, ordy, ld(f, F.ordy)))
    st(f, F.ordl, sel(valid, ordl, ld(f, F.ordl)))
    trusted = mand(besty <= trust, besty > floor)
    st(f, F.trust, sel(valid, sel(trusted, 1.0, 0.0), ld(f, F.trust)))
    st(f, F.depth, sel(valid, sel(held < float(depth), held + 1.0, float(depth)), held))


@njit(**_OPTS)
def _step(t_next, n0, ev, inside, P, d, s, nz, g):
    """Advance the live lanes by one step; returns the lanes whose step is over (taken, or broken down).

    The guess (:func:`_guess`): the last step's stages extrapolated, corrected by the last steps'
    defects (``cfg.depth`` of them; none under ``predictor="extrapolate"``).  A step is tried from
    up to three starts before a lane breaks down: (0) the guess, with a Jacobian taken there where
    the lane trusts it (``F.trust``; never where ``cfg.trust`` < 0: ``predictor="extrapolate"``, and pairs above
    ``Tolerances.trust_max_unknowns``) and the step is due (its number, ``n0`` + ``F.jn``, a
    multiple of ``cfg.every``: a schedule by step number, not by the lane's own history, so the
    lanes of a group take their Jacobians at the same steps wherever their points lie), else with
    the factors carried from the last step; if that
    fails, (1) the uncorrected base guess with the other choice (a Jacobian there when none are
    carried; under ``predictor="extrapolate"`` the base is the guess, so this is the same guess
    with a fresh Jacobian); then (2) h·q̇(q_n) at every stage, μ = 0, with a Jacobian taken there.  A first
    step starts at (2).  A lane whose last try fails (Newton does not converge, a value is not
    finite, q leaves the domain) is frozen at its last good state with its breakdown time set to
    ``t_next``.  Each further try is the lane's next call of this
    function (``F.retry``: the next try's number, its step not over), made beside its neighbours'
    next steps instead of in a pass of its own in which they would wait; it computes what a pass of
    its own would."""
    w, S, f, F, cfg = g.w, g.S, g.f, g.F, P.cfg
    live = ld(f, F.live) != 0.0
    fresh = ld(f, F.hist) == 0.0
    tries = ld(f, F.retry)
    last = tries == 2.0
    depth = int(cfg.depth)
    plan = P.plan
    nl = d if (plan.pre == PRE_UNKNOWN or plan.post) else 0     # Λ solved for: predicted too
    sd = s * d
    nb = sd + nl + (d if plan.lobatto else 0)
    _base(ev, P, d, s, nl, fresh, g)
    first_try = tries == 0.0
    rec = int(cfg.rec)
    if rec > 0 and anyl(ld(f, F.depth) >= float(DEPTH)):     # (only a full table chooses it)
        if rec == RECURRENCE:                   # the default as a constant: the fit's loops unroll, and
            _recurrence(RECURRENCE, nb, d, w, S)    # its m × m solve stays in registers (the same arithmetic,
        else:                                   # 0.016-0.018 µs a point-step less: docs/benchmarks.md)
            _recurrence(rec, nb, d, w, S)
    _guess(sel(first_try, ld(f, F.ordy), 0.0), sel(first_try, ld(f, F.ordl), 0.0), depth, rec, nb, sd, w, S)
    guess = at(w, S.guess)
    first = mand(live, mor(fresh, last))        # a first step, or the last try: from h·q̇(q_n)
    if anyl(first):
        _first_guess(ev, P, at(w, S.q), guess, first, d, s, g)
    if plan.lobatto:                            # μ's guess: zero on the last try
        for m in range(d):
            st(guess, sd + nl + m, sel(last, 0.0, ld(guess, sd + nl + m)))
    st(f, F.active, sel(live, 1.0, 0.0))
    have = ld(f, F.have) != 0.0
    every = cfg.every                           # this step's number (n0 + F.jn) a multiple of ``every``
    if every > 1.0:
        for l in range(nlanes(w)):
            n = n0 + lget(f, F.jn, l)
            lset(f, F.okstep, l, 1.0 if n - every * np.floor(n / every) == 0.0 else 0.0)
    else:
        st(f, F.okstep, 1.0)
    due = ld(f, F.okstep) != 0.0                # (okstep is free until _attempt sets it)
    trusted = mand(mand(ld(f, F.trust) != 0.0, due), ld(f, F.age) >= cfg.age)   # carried: try 0 untrusted, try 1 trusted
    known = mand(have, mor(mand(first_try, mnot(trusted)), mand(tries == 1.0, trusted)))
    _attempt(known, guess, at(w, S.guess + sd), at(w, S.guess + sd + nl), ev, inside, P, d, s, nz, g)
    ok = ld(f, F.okstep) != 0.0
    nxt = sel(mor(fresh, last), 3.0, sel(mand(first_try, have), 1.0, 2.0))   # the next try (3: none left)
    retry = mand(live, mand(mnot(ok), nxt < 3.0))
    st(f, F.retry, sel(live, sel(retry, nxt, 0.0), ld(f, F.retry)))
    st(f, F.have, sel(live, sel(ok, 1.0, 0.0), ld(f, F.have)))
    good = mand(live, ok)
    if depth > 0:
        _remember(mand(good, mnot(fresh)), depth, rec, cfg.trust, cfg.carry, nb, nl, s, d, g)
    st(f, F.stp, ld(f, F.stp) + sel(good, 1.0, 0.0))
    age = ld(f, F.age)
    st(f, F.age, sel(good, sel(age < 255.0, age + 1.0, age), age))
    st(f, F.hist, sel(good, 1.0, ld(f, F.hist)))
    broke = mand(live, mand(mnot(ok), mnot(retry)))
    st(f, F.tbrk, sel(broke, t_next, ld(f, F.tbrk)))
    st(f, F.live, sel(broke, 0.0, ld(f, F.live)))
    return mand(live, mnot(retry))


@njit(**_OPTS)
def _gather(st_, pt, l, valid, d, s, nz, g):
    """The state of point ``pt`` into lane ``l``; ``valid`` False leaves the lane empty (it holds
    the point's values, so that its arithmetic stays on ordinary numbers, but it is not live and
    has no factors)."""
    w, S, f, F, ip, IP = g.w, g.S, g.f, g.F, g.ip, g.IP
    q, p, Lam, qc, pc, Y, mu = st_.q, st_.p, st_.Lam, st_.q_comp, st_.p_comp, st_.Y, st_.mu
    hist, live, tbrk, lu, piv, have = st_.have_history, st_.live, st_.breakdown_time, st_.lu, st_.piv, st_.have_lu
    jz, jq, jl = st_.jac_z, st_.jac_q, st_.jac_lam
    for m in range(d):
        lset(w, S.jq + m, l, elem(jq, pt, m))
        lset(w, S.jl + m, l, elem(jl, pt, m))
    for i in range(nz):
        lset(w, S.jz + i, l, elem3(jz, pt, i // d, i % d))
    for m in range(d):
        lset(w, S.q + m, l, elem(q, pt, m))
        lset(w, S.p + m, l, elem(p, pt, m))
        lset(w, S.lam + m, l, elem(Lam, pt, m))
        lset(w, S.qc + m, l, elem(qc, pt, m))
        lset(w, S.pc + m, l, elem(pc, pt, m))
        lset(w, S.mu + m, l, elem(mu, pt, m))
    for i in range(s):
        for m in range(d):
            lset(w, S.Y + i * d + m, l, elem3(Y, pt, i, m))
    for i in range(DEPTH * (s + 2)):
        for m in range(d):
            lset(w, S.D + i * d + m, l, elem3(st_.defects, pt, i, m))
    pr_ = st_.orders
    lset(f, F.depth, l, float(pr_[pt, 0]))
    lset(f, F.ordy, l, float(pr_[pt, 1]))
    lset(f, F.ordl, l, float(pr_[pt, 2]))
    lset(f, F.trust, l, float(pr_[pt, 3]))
    lset(f, F.age, l, float(pr_[pt, 4]))
    known = have[pt] != 0 and valid           # factors kept from the last step
    for i in range(nz):
        for j in range(nz):
            lset(w, S.lu + i * nz + j, l, sel(known, elem3(lu, pt, i, j), 0.0))
        # (a lane's solve runs whether or not its factors are used: its pivots must be rows)
        lset(ip, IP.piv + i, l, piv[pt, i] if known else i)
    lset(f, F.have, l, float(have[pt]))
    lset(f, F.hist, l, float(hist[pt]))
    lset(f, F.live, l, float(live[pt]) if valid else 0.0)
    lset(f, F.tbrk, l, tbrk[pt])
    lset(f, F.itn, l, 0.0)
    lset(f, F.stp, l, 0.0)
    lset(f, F.jn, l, 0.0)
    lset(f, F.held, l, 1.0 if valid else 0.0)
    lset(f, F.retry, l, 0.0)
    lset(ip, IP.pt, l, pt)


@njit(**_OPTS)
def _scatter(st_, pt, l, d, s, nz, g):
    """Lane ``l``'s state back into point ``pt``."""
    w, S, f, F, ip, IP = g.w, g.S, g.f, g.F, g.ip, g.IP
    q, p, Lam, qc, pc, Y, mu = st_.q, st_.p, st_.Lam, st_.q_comp, st_.p_comp, st_.Y, st_.mu
    hist, live, tbrk, lu, piv, have = st_.have_history, st_.live, st_.breakdown_time, st_.lu, st_.piv, st_.have_lu
    itn, stp = st_.iterations, st_.steps
    jz, jq, jl = st_.jac_z, st_.jac_q, st_.jac_lam
    for m in range(d):
        put(jq, pt, m, lget(w, S.jq + m, l))
        put(jl, pt, m, lget(w, S.jl + m, l))
    for i in range(nz):
        put3(jz, pt, i // d, i % d, lget(w, S.jz + i, l))
    for m in range(d):
        put(q, pt, m, lget(w, S.q + m, l))
        put(p, pt, m, lget(w, S.p + m, l))
        put(Lam, pt, m, lget(w, S.lam + m, l))
        put(qc, pt, m, lget(w, S.qc + m, l))
        put(pc, pt, m, lget(w, S.pc + m, l))
        put(mu, pt, m, lget(w, S.mu + m, l))
    for i in range(s):
        for m in range(d):
            put3(Y, pt, i, m, lget(w, S.Y + i * d + m, l))
    for i in range(DEPTH * (s + 2)):
        for m in range(d):
            put3(st_.defects, pt, i, m, lget(w, S.D + i * d + m, l))
    pr_ = st_.orders
    pr_[pt, 0] = int(lget(f, F.depth, l))
    pr_[pt, 1] = int(lget(f, F.ordy, l))
    pr_[pt, 2] = int(lget(f, F.ordl, l))
    pr_[pt, 3] = int(lget(f, F.trust, l))
    pr_[pt, 4] = int(lget(f, F.age, l))
    for i in range(nz):
        for j in range(nz):
            put3(lu, pt, i, j, lget(w, S.lu + i * nz + j, l))
        piv[pt, i] = lget(ip, IP.piv + i, l)
    have[pt] = 1 if lget(f, F.have, l) != 0.0 else 0
    hist[pt] = 1 if lget(f, F.hist, l) != 0.0 else 0
    live[pt] = 1 if lget(f, F.live, l) != 0.0 else 0
    tbrk[pt] = lget(f, F.tbrk, l)
    itn[pt] += int(lget(f, F.itn, l))
    stp[pt] += int(lget(f, F.stp, l))


@njit(inline='always', **_OPTS)
def _next_live(live, order, nxt, hi):
    """The first position at or after ``nxt`` in ``order`` whose point is live (``hi`` when none)."""
    while nxt < hi and live[order[nxt]] == 0:
        nxt += 1
    return nxt


@njit(**_OPTS)
def _record(snap, every, first, l, d, g):
    """Lane ``l``'s point at the end of its step into ``snap`` (:func:`advance`'s outputs) when the step's
    number is an output's (a multiple of ``every`` before the call's last step)."""
    w, S, f, F, ip, IP = g.w, g.S, g.f, g.F, g.ip, g.IP
    n = first - 1 + int(lget(f, F.jn, l))
    if n % every != 0:
        return
    k = n // every - (first - 1) // every - 1
    sq, sp, sl, mark = snap
    if k < 0 or k >= mark.shape[0]:
        return
    pt = lget(ip, IP.pt, l)
    for m in range(d):
        put3(sq, k, pt, m, lget(w, S.q + m, l))
        put3(sp, k, pt, m, lget(w, S.p + m, l))
        put3(sl, k, pt, m, lget(w, S.lam + m, l))
    mark[k, pt] = 1


@njit(**_OPTS)
def _block(WS, FS, IS, QR, order, lo, hi, ev, inside, post, kp, h, tb, plan, t0, first, nsteps, st_, d, s, nz, cfg,
           proto, lay, snap, every):
    """The live points among order[lo … hi − 1] through ``nsteps`` steps each, W (= len(proto))
    lanes at a time, with the thread's scratch arrays; returns the group steps taken, the Newton
    iterations they ran and the Jacobians they took.

    **Lanes are refilled.**  Each lane holds one point and counts its steps (``F.jn``); after every
    step, a lane whose point has taken its ``nsteps`` steps or has broken down hands the point back
    (:func:`_scatter`) and takes up the next live point of the block (:func:`_gather`), which starts
    at its own first step: the lanes of one group may be at different steps, each step aiming at
    its own lane's time.  Points that are not live are never taken up (:func:`advance` leaves them
    out of the blocks), so dead points cost nothing and live ones are packed into full groups.  A
    lane with nothing left to take is empty (not live) until the last lane's point is done.  Nothing
    in a point's arithmetic reads another lane, so its bits are those it gets alone (W = 1 takes the
    points one after another).

    The scratch arrays are arguments (not locals) on purpose: the caller holds them for the whole
    call, while numba would free a local array after its last use as an array, i.e. while the raw
    pointers taken from it are still in use.
    """
    # the records by name, made here (numba's parallel loop takes no named tuples)
    S, F, IP = _records(lay)
    st_ = StateArrays(*st_)
    P = Step(post, kp, h, tb, Plan(*plan), _newton_rule(cfg))
    W = len(proto)
    g = Group(lanes(WS, 0, proto), S, lanes(FS, 0, plain(proto)), F, lanes(IS, 0, plain(proto)), IP, _at(QR, 0))
    f, ip = g.f, g.ip
    live = st_.live
    nxt = _next_live(live, order, lo, hi)
    if nxt == hi or nsteps <= 0:
        return 0, 0, 0
    pad = order[nxt]                              # empty lanes hold this point's values, not live
    held = 0
    for l in range(W):
        if nxt < hi:
            _gather(st_, order[nxt], l, True, d, s, nz, g)
            nxt = _next_live(live, order, nxt + 1, hi)
            held += 1
        else:
            _gather(st_, pad, l, False, d, s, nz, g)
    rounds = 0
    last = float(nsteps)
    while held > 0:
        rounds += 1
        over = _step(t0 + (float(first) + ld(f, F.jn)) * h, float(first), ev, inside, P, d, s, nz, g)
        jn = ld(f, F.jn) + sel(over, 1.0, 0.0)
        st(f, F.jn, jn)
        if every > 0:                             # outputs inside the call: the points that took their step
            taken = mand(over, mand(ld(f, F.held) != 0.0, ld(f, F.live) != 0.0))
            if anyl(taken):
                for l in range(W):
                    if lmask(taken, l):
                        _record(snap, every, first, l, d, g)
        ends = mand(ld(f, F.held) != 0.0, mor(ld(f, F.live) == 0.0, jn >= last))
        if anyl(ends):                            # lanes whose point is done: hand it back, take the next
            for l in range(W):
                if lmask(ends, l):
                    _scatter(st_, lget(ip, IP.pt, l), l, d, s, nz, g)
                    if nxt < hi:
                        _gather(st_, order[nxt], l, True, d, s, nz, g)
                        nxt = _next_live(live, order, nxt + 1, hi)
                    else:
                        lset(f, F.held, l, 0.0)
                        lset(f, F.live, l, 0.0)
                        held -= 1
    return rounds, int(lget(f, F.gits, 0)), int(lget(f, F.gjac, 0))


@njit(**_OPTS)
def _aligned(raw, n):
    """The n elements of ``raw`` from its first 64-byte boundary on (``raw`` holds 16 more).  A lane
    value (W doubles) then never straddles two cache lines: numba aligns arrays to 32 bytes, and a
    scratch array at 32 modulo 64 made every lane load and store a split one.  Which of the two a run
    got was a matter of where its allocations fell, one way for the whole process: the same pair
    measured 0.21 or 0.27 µs a point-step (SRK3-symmetric at W = 16) from one process to the next
    (docs/benchmarks.md, "Aligned lanes")."""
    off = (64 - raw.ctypes.data % 64) % 64 // raw.itemsize
    return raw[off:off + n]


@njit(parallel=True, **_OPTS)
def advance(ev, inside, post, k, tab, plan, h, t0, first, nsteps, block, st_, dim, tolerances, proto, lay, rounds,
            snap, every):
    """Advance every live point of the state tuple ``st_`` by ``nsteps`` steps, the step numbered
    ``first`` aiming at t0 + first·h.  The live points, in their order, are taken ``block`` at a
    time (dead points are left out before blocks are made, so every block but the last is full),
    blocks spread over the threads, and W = len(proto) at a time within a block (``ev`` must be the
    W-lane point function); a point's steps never depend on its block, its lanes, its thread or its
    neighbours.  ``post``: the projection's post term, PAPER for :func:`project` (read only by
    projections solved after Ψ_h); a projection's own compiled function compiles (and does not
    cache) a kernel of its own.

    ``st_``: the :class:`StateArrays` as a plain tuple; ``tolerances``: the float64 array of a
    :class:`Newton` record (:class:`integrators.engine.Tolerances`); ``lay``: :func:`layout` as
    three int64 arrays (Engine._layout); ``rounds`` (int64, a row per block): the steps, the
    Newton iterations and the Jacobians (evaluated and factorised, the projection's solve's
    included) each block's group of lanes ran (:func:`_block`), so point-steps / (W · Σ steps) is
    the share of lane steps that did work, and the points' iterations / (W · Σ iterations) that of
    lane iterations.

    ``snap`` = (q, p, Λ, mark), K outputs of every point, and ``every`` (0: none): after a point's
    step numbered a multiple of ``every`` (the k-th such step after ``first`` − 1, k < K), its q, p,
    Λ go to row k and mark[k, point] = 1; a point that is not live after that step is not recorded
    (:meth:`integrators.engine.Engine.advance_outputs` fills those from its frozen state).  A point
    keeps its lane for the whole call, so a run's outputs cost no trip of its Newton factors and
    predictor table through memory (docs/benchmarks.md, "What a call costs").
    """
    arrays = StateArrays(*st_)
    q, Y, lu = arrays.q, arrays.Y, arrays.lu
    n = q.shape[0]
    d = len(dim)           # ``dim`` is a tuple of d zeros: d is a compile-time constant, one compilation
    #                        per dimension, and the compiler unrolls the loops over coordinates
    s = Y.shape[1]
    nz = lu.shape[1]
    W = len(proto)
    S, F, IP = _records(lay)
    nw, nf, ni = S.size * W, F.size * W, IP.size * W
    kp, tb, cfg = _at(k, 0), _at(tab, 0), _at(tolerances, 0)
    live = arrays.live
    order = np.empty(n, np.int64)               # the live points, in order
    m = 0
    for i in range(n):
        if live[i] != 0:
            order[m] = i
            m += 1
    nblocks = (m + block - 1) // block
    for bi in prange(nblocks):
        WS = _aligned(np.zeros(nw * (q.ndim - 1) + 16, q.dtype), nw * (q.ndim - 1))   # (a double-double state,
        FS = _aligned(np.zeros(nf + 16), nf)                                            # (n, d, 2): two doubles
        IS = _aligned(np.zeros(ni + 16, np.int64), ni)                                  # a value)
        QR = np.zeros(d)
        rounds[bi, 0], rounds[bi, 1], rounds[bi, 2] = _block(
            WS, FS, IS, QR, order, bi * block, min(m, (bi + 1) * block), ev, inside, post, kp, h, tb, plan, t0, first,
            nsteps, st_, d, s, nz, cfg, proto, lay, snap, every)


def advance_argument(sig, name):
    """The numba type of :func:`advance`'s argument ``name`` in its compiled signature ``sig`` (one of
    ``advance.signatures``): which specialisations exist, read by name."""
    import inspect
    return sig[list(inspect.signature(advance.py_func).parameters).index(name)]


@njit(**_OPTS)
def theta_dd_points(ev, k, q2, out, T, TT, dH, HH):
    """ϑ at each double-double point of q2 (n, d, 2) into out (n, d, 2), by the system's
    double-double point function (integrators.engine.theta_dd)."""
    n, d = q2.shape[0], q2.shape[1]
    P = (0.0,)
    for i in range(n):
        ev(lanes(q2, i * d, P), _at(k, 0), False, lanes(out, i * d, P), lanes(T, 0, P), lanes(TT, 0, P),
           lanes(dH, 0, P), lanes(HH, 0, P))


@njit(**_OPTS)
def scalars_dd_points(sc, k, q2, out):
    """H and the momentum at each double-double point of q2 (n, d, 2) into out (n, 2, 2), by the
    system's double-double ``scalars_dd`` (integrators.engine.scalars_dd)."""
    n, d = q2.shape[0], q2.shape[1]
    P = (0.0,)
    for i in range(n):
        sc(lanes(q2, i * d, P), _at(k, 0), lanes(out, i * 2, P))


@njit(**_OPTS)
def refactor(ev, k, tab, plan, h, st_, nz, dim, proto, lay):
    """Rebuild the Newton factors ``lu, piv`` of every point that has them (``have_lu``) from where
    they were taken (``jac_z``, ``jac_q``, ``jac_lam``): the step's equations' Jacobian at that
    iterate, factorised, as :func:`_newton` did (one lane: W = 1, ``ev`` the scalar point function;
    a lane's factors are the scalar path's bits).  What a state read from a checkpoint needs before
    it is advanced, so that the resumed run is bitwise the run it continues.  (One thread: once per
    resume, one Jacobian a point.)"""
    arrays = StateArrays(*st_)
    n = arrays.q.shape[0]
    d = len(dim)
    s = arrays.Y.shape[1]
    S, F, IP = _records(lay)
    kp, tb = _at(k, 0), _at(tab, 0)
    pl = Plan(*plan)
    have, lu, piv = arrays.have_lu, arrays.lu, arrays.piv
    WS = np.zeros(S.size * (arrays.q.ndim - 1), arrays.q.dtype)
    IS = np.zeros(IP.size, np.int64)
    w, ip = lanes(WS, 0, proto), lanes(IS, 0, plain(proto))
    for pt in range(n):
        if have[pt] == 0:
            continue
        for m in range(d):
            lset(w, S.q + m, 0, elem(arrays.jac_q, pt, m))
            lset(w, S.lam + m, 0, elem(arrays.jac_lam, pt, m))
        for i in range(nz):
            lset(w, S.z + i, 0, elem3(arrays.jac_z, pt, i // d, i % d))
        _prepare(ev, kp, pl, d, w, S)
        LU, pv = at(w, S.lu), at(ip, IP.piv)
        _main(at(w, S.z), True, at(w, S.r), LU, ev, kp, h, tb, pl, d, s, w, S)
        lu_factor(LU, pv, nz)
        for i in range(nz):
            for j in range(nz):
                put3(lu, pt, i, j, lget(w, S.lu + i * nz + j, 0))
            piv[pt, i] = lget(ip, IP.piv + i, 0)


@njit(**_OPTS)
def _probe(WS, zz, r, J, ev, k, tab, plan, h, q, p, lam, jac, s, S):
    d = q.shape[0]
    w = lanes(WS, 0, (0,))
    for m in range(d):
        st(w, S.q + m, q[m])
        st(w, S.p + m, p[m])
        st(w, S.lam + m, lam[m])
    _prepare(ev, _at(k, 0), plan, d, w, S)
    _main(_at(zz, 0), jac, _at(r, 0), _at(J, 0), ev, _at(k, 0), h, _at(tab, 0), plan, d, s, w, S)


def probe(ev, k, tab, plan, h, q, p, lam, z, jac, *, s):
    """The step's residual at z (and its Jacobian when ``jac``) for one point (q, p, Λ) of a pair with
    ``s`` stages (``tab`` its :func:`flat_tableau`): the equations Newton solves, for tests (the
    Jacobian against complex-step differences of the residual)."""
    d = q.shape[0]
    nz = z.shape[0]
    S, F, _ = layout(s, d, nz)
    WS = np.zeros(S.size, z.dtype)
    r = np.zeros(nz, z.dtype)
    J = np.zeros(nz * nz, z.dtype)
    zz = z.copy()
    _probe(WS, zz, r, J, ev, k, tab, Plan(*plan), h, q, p, lam, jac, s, S)
    return r, J.reshape((nz, nz))
