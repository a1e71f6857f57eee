"""What crosses into the kernel, by name: the constants of the lane widths and the predictor, the
flat tableau, the projection's :class:`Plan`, Newton's rule (:class:`Newton`), the state's arrays
(:class:`StateArrays`), the scratch layout of a group of lanes (:class:`Scratch`, :class:`Flags`,
:class:`IntScratch`, made by :func:`layout`) and the records a step reads (:class:`Step`,
:class:`Group`).  Python makes the arrays (integrators/engine.py); the kernel turns them back into
these records once per block (:func:`_records`, :func:`_newton_rule`), and no code below reads one
by position."""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit
from numba.np.unsafe.ndarray import to_fixed_tuple

from ..projections import PRE_UNKNOWN
from ..simd import _at

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

Plan = namedtuple("Plan", "pre pre_at post post_at sigma alpha lobatto")
Plan.__doc__ = """A projection as the kernel reads it (made from Projection.codes): ``pre`` one of PRE_*,
``pre_at``/``post_at`` where ϑ_q of the pre/post terms is taken (START, MIDPOINT, END), ``post``
whether the step ends on the constraint, ``sigma`` the post term's weight σ and ``alpha`` the pre
term's α (q̃ = q̄ + αΛ, p̃ = p̄ + α ϑ_q(x_pre)ᵀΛ; the paper's rows: α = 1, σ = 1 or R(∞)), ``lobatto``
whether the tableau has the Lobatto constraint μ (eq:vprk_lobatto)."""

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


# -- the scratch: named offsets into one buffer per group of W points ---------------------------

Scratch = namedtuple("Scratch", [
    # stage values: Q_i, ϑ(Q_i), ϑ_q, ϑ_qq, ∇H, ∇²H, G_i = ϑ_q(Q_i)ᵀY_i − h∇H(Q_i), K_i = ∂G_i/∂Q_i
    "Q", "th", "T", "TT", "dH", "HH", "G", "K",
    # ϑ_q(Q_i) e_i: the linear part of ϑ over Q_i's rounding error e_i (:func:`_stages`, plain doubles)
    "tE",
    # what forming G_i in doubles dropped (its products' and sums' roundings, :func:`_stages`)
    "Ge",
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
    "own", "pown",                # ... and that coordinate's own |value| (the settled approach's grid)
    "done", "ok", "stale", "prev", "its", "norm", "nan", "finite",   # Newton's per-lane bookkeeping
    "exact",                      # the last iteration's factors were taken at its own iterate (_judge)
    "rounded", "rounds",          # the dithered approach: the iterate was rounded; roundings this solve
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
        Q=sd, tE=sd, Ge=sd, th=sd, T=s * dd, TT=s * dd * d, dH=sd, HH=s * dd, G=sd, K=s * dd,
        pth=3 * d, pT=3 * dd, pTT=3 * dd * d, pdH=3 * d, pHH=3 * dd,
        **dict.fromkeys(D_VECTORS, d),
        z=nz, zev=nz, r=nz, Jt=nz * nz, S=2 * dd, PL=dd, pz=d, pzev=d, pr=d, pJ=dd, guess=sd + 2 * d,
        base=sd + 2 * d, D=DEPTH * (sd + 2 * d), dh=DEPTH * d, gram=RECURRENCE * (RECURRENCE + 1),
        ar=sd + 2 * d,
        q=d, p=d, lam=d, qc=d, pc=d, Y=sd, mu=d, lu=nz * nz, jz=nz, jq=d, jl=d))
    F = _offsets(Flags, dict(dict.fromkeys(Flags._fields[:-1], 1), scale=nz, pscale=d, own=nz, pown=d))
    IP = _offsets(IntScratch, dict(piv=nz, pivt=nz, ipiv=d, pt=1))
    return S, F, IP


Newton = namedtuple("Newton", "tol stall stall_complex maxiter refresh floor horizon accept velocity depth trust age every least rec "
                               "carry fine dither settle settle_accept")
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
``fine`` (64 ulps of the number type) that stops halving is at the round-off floor (:func:`_judge`);
an iterate reached by an update larger than ``dither`` (> 0; double unknowns only) is rounded to a grid
of about that size (:func:`_update`); the first iterate reached by an update of at most ``settle`` (> 0;
double unknowns only) is rounded to a grid of about that size and the update after the one taken there
ends the solve where it is at most ``settle_accept`` (:func:`_settle`)."""

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


Pair = namedtuple("Pair", "k tab plan h newton")
Pair.__doc__ = """What every step of a pair reads, as :func:`advance`, :func:`refactor` and :func:`probe` take
it (made by integrators.engine.Engine.pair, the one place): the parameter values ``k`` (float64),
the flat tableau ``tab`` (:func:`flat_tableau`), the :class:`Plan` as a plain tuple ``plan``, the step
size ``h`` and Newton's rule ``newton`` (the float64 array of a :class:`Newton` record)."""

Span = namedtuple("Span", "t0 first nsteps")
Span.__doc__ = """The steps a call takes: ``nsteps`` of them, the one numbered ``first`` aiming at t0 + first·h."""

Shape = namedtuple("Shape", "dim proto lay block")
Shape.__doc__ = """How a call is laid out: ``dim`` d zeros (so that d is a compile-time constant: one
compilation per dimension, loops over coordinates unrolled), ``proto`` W zeros of the number type (the
lane width W, and int or float for the scratch), ``lay`` the :func:`layout` as three int64 arrays, and
``block`` the points a thread takes at a time."""

Outputs = namedtuple("Outputs", "rounds snap every")
Outputs.__doc__ = """What a call writes besides the state: ``rounds`` (int64, a row per block, its columns
:data:`ROUNDS`), the outputs ``snap`` = (q, p, Λ, mark) and their cadence ``every`` (0: none)."""

Orders = namedtuple("Orders", "depth ordy ordl trust age")
Orders.__doc__ = """Names for the columns of :class:`StateArrays`' ``orders`` (int64, a row per point): the
predictor's state of a point between calls (the :class:`Flags` of the same names)."""
ORDERS = Orders(*range(len(Orders._fields)))

Rounds = namedtuple("Rounds", "steps iterations jacobians")
Rounds.__doc__ = """Names for the columns of :class:`Outputs`' ``rounds``: a block's group steps, Newton
iterations and Jacobians (:func:`_block`)."""
ROUNDS = Rounds(*range(len(Rounds._fields)))

N_SCRATCH, N_FLAGS, N_INT = len(Scratch._fields), len(Flags._fields), len(IntScratch._fields)
N_NEWTON = len(Newton._fields)


@njit(inline='always', **_OPTS)
def _records(lay):
    """The :func:`layout` records from their arrays (Engine._layout)."""
    return (Scratch(*to_fixed_tuple(lay[0], N_SCRATCH)), Flags(*to_fixed_tuple(lay[1], N_FLAGS)),
            IntScratch(*to_fixed_tuple(lay[2], N_INT)))


Unknowns = namedtuple("Unknowns", "L M nz")
Unknowns.__doc__ = """The layout of a step's Newton unknowns z = [Y_1 … Y_s, Λ (coupled projections), μ
(Lobatto tableaus)]: where Λ and μ start (``L``, ``M``; each s·d where it is absent) and how many
there are (``nz``).  Made by :func:`unknowns` (kernel) and :func:`unknowns_of` (Python), the one
place of this layout."""


def unknowns_of(s, d, coupled, lobatto):
    """:class:`Unknowns` of a pair with s stages in dimension d (Engine.nz, the state's arrays)."""
    M = s * d + (d if coupled else 0)
    return Unknowns(s * d, M, M + (d if lobatto else 0))


@njit(inline='always', **_OPTS)
def unknowns(plan, s, d):
    """:class:`Unknowns` of the step with :class:`Plan` ``plan`` (the kernel's, by the same rule)."""
    sd = s * d
    M = sd + d if plan.pre == PRE_UNKNOWN else sd
    return Unknowns(sd, M, M + d if plan.lobatto else M)


@njit(inline='always', **_OPTS)
def _newton_rule(c):
    """The :class:`Newton` record from its array (Tolerances.array)."""
    return Newton(*to_fixed_tuple(c, N_NEWTON))


@njit(inline='always', **_OPTS)
def _runtime(k, like):
    """The integer k as a value the compiler cannot fold into a constant (``like`` is any runtime
    integer): a literal argument would compile the callee once per value (``_newton``'s mode)."""
    return like - like + k
