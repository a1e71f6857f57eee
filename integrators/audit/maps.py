"""The audit of a black-box canonical step map in any dimension (docs/audit.md, "Step maps in any dimension").

A canonical map is ``step(x, v, h) -> (x, v)`` on arrays of shape (n, k): n independent points, k
degrees of freedom, positions x and momenta v (phase space of dimension 2k, the form dv ∧ dx).
Nothing symbolic is needed: the map is called on batches of points and differentiated along
directions (Jacobian–vector products), never as a 2k × 2k matrix unless 2k ≤ ``DENSE_UP_TO``.

* **Drift**: a loop (and optionally a surface) around a phase-space point, in a plane spanned by
  two directions, is advanced ``steps`` steps; the canonical I₁ = ∮ v·dx (I₂ = ∫∫ dv ∧ dx) with
  the positions' ``period`` gives e(t) = |I(t) − I(0)|/|I(0)|, judged as :func:`audit` judges it.
* **Defect**: at points of the loop, for h, h/2, …, the pull-back defect of the canonical form.
  Matrix-free: over random probe pairs (u, w), ω(DΦu, DΦw) − ω(u, w) relative to the size of the
  terms summed; two Jacobian–vector products a pair, by complex step when the map keeps complex
  arithmetic through (its real part reproducing the real evaluation), else by 8th-order central
  differences.  Up to ``DENSE_UP_TO`` phase-space dimensions the dense Jacobian is used instead
  (2k JVPs), as :func:`integrators.audit.defects` does.  Memory is O(n·k) per call, never O(k²).
* **Noncanonical maps** (``theta=``): ``step(q, h) -> q`` with a batched one-form ϑ(q) of code; the
  form is dϑ, evaluated at z and Φ(z) by JVPs of ϑ (:func:`noncanonical_defect`, :func:`two_form`).
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from ..kernel import COMPLEX_STEP as CS_STEP
from .defect import DEFECT_FLOOR, FD_ORDER8, FD_STEP, fit_order, fit_order_small_h
from .drift import ROUNDOFF, RESOLVED, drift_verdict
from invariants.forms import MIN_POINTS

DENSE_UP_TO = 32          # phase-space dimensions up to which the defect takes the dense Jacobian
UPWARD = 6                # a defect below the floor at every h is looked for up to h·2^UPWARD (_defect_study)
PROBES = 8                # probe pairs of the matrix-free defect (docs/audit.md: how many are enough)
METHODS = ("auto", "complex step", "central differences")   # how the defect differentiates a map
STATE_COPIES = 8          # the drift's peak memory in copies of the sets' state (7 measured at d = 8,192:
                          # 7.4 GiB for a 1.07 GB state; the map's temporaries and the invariants' FFTs)


NAMES = {key: key for key in ("h", "steps", "output_every", "loop_points", "radius", "surface", "defect_points",
                               "levels", "probes", "method", "period", "k")}   # how audit_map's caller names them


def _whole(value, name, least=1):
    """``value`` as an int of at least ``least``; a one-line ValueError naming ``name`` otherwise."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or int(value) != value or value < least:
        raise ValueError(f"{name} must be a whole number of at least {least}, got {value!r}")
    return int(value)


def check_arguments(n, h, *, steps=100, output_every=None, loop_points=1024, radius=0.1, surface=None,
                    defect_points=4, levels=3, probes=PROBES, method="auto", noncanonical=False, names=None):
    """The one validation of a map audit's arguments and sizes, shared by :func:`audit_map` and
    ``poincare audit --map`` (which calls it before it builds an example): a one-line ValueError
    naming the argument as the caller does (``names``: {argument: name}, e.g. ``--loop-points``),
    and the memory judged from the sizes alone, before anything is allocated.  ``n``: the phase-space dimension (2k; d with a
    one-form).  Returns the arguments made whole: (h, steps, every, loop_points, surface,
    defect_points, levels, probes)."""
    nm = {**NAMES, **(names or {})}
    n = _whole(n, "the dimension")
    if noncanonical and n % 2:
        raise ValueError(f"a one-form on d = {n} coordinates (odd) is degenerate: dϑ has a kernel and no map can "
                         "be symplectic for it; a degenerate Lagrangian ϑ(q)·q̇ − H(q) needs an even d")
    if isinstance(h, (bool, np.bool_)) or not isinstance(h, (int, float, np.integer, np.floating)):
        raise ValueError(f"{nm['h']} must be a number, got {h!r}")
    h = float(h)
    steps = _whole(steps, nm["steps"])
    every = max(1, steps // 50) if output_every is None else _whole(output_every, nm["output_every"])
    loop_points = _whole(loop_points, nm["loop_points"], MIN_POINTS)
    levels = _whole(levels, nm["levels"])
    defect_points = _whole(defect_points, nm["defect_points"])
    probes = _whole(probes, nm["probes"])
    if defect_points > loop_points:
        raise ValueError(f"{nm['defect_points']} = {defect_points} is more than the loop's {loop_points} points "
                         "(the defect is taken at points of the loop)")
    if not math.isfinite(h) or h == 0.0:
        raise ValueError(f"{nm['h']} must be finite and non-zero, got {h!r}")
    smallest = abs(h) * 2.0 ** (1 - levels)
    if smallest < np.finfo(float).tiny:
        raise ValueError(f"{nm['h']} = {h!r} with {nm['levels']} = {levels}: the smallest step size h/2^{levels - 1} = "
                         f"{smallest:.3g} is below the smallest normal double ({np.finfo(float).tiny:.3g}): no "
                         "step map can resolve it")
    if not math.isfinite(h * steps):
        raise ValueError(f"{nm['h']} × {nm['steps']} = {h!r} × {steps} is not a finite time")
    if isinstance(radius, (bool, np.bool_)) or not isinstance(radius, (int, float, np.integer, np.floating)) \
            or not math.isfinite(radius) or radius <= 0:
        raise ValueError(f"{nm['radius']} must be a positive number (the loop's radius in phase space), got {radius!r}")
    if method not in METHODS:
        raise ValueError(f"{nm['method']} must be one of {', '.join(map(repr, METHODS))}, got {method!r}")
    if surface is not None:
        if np.ndim(surface) != 1 or len(surface) != 2:
            raise ValueError(f"{nm['surface']} must be (n_sigma, n_tau), two whole numbers, got {surface!r}")
        surface = tuple(_whole(x, f"{nm['surface']}'s {w}", MIN_POINTS) for x, w in zip(surface, ("n_sigma", "n_tau")))
    rows = loop_points + (0 if surface is None else surface[0] * surface[1])
    dense = n <= DENSE_UP_TO
    needs = {f"the sets ({rows:,} points of {n:,} coordinates, {STATE_COPIES} copies while advanced)":
             STATE_COPIES * 8.0 * rows * n,
             f"the defect ({defect_points} points × {n if dense else 2 * probes} directions)":
             2 * STATE_COPIES * 16.0 * defect_points * (n if dense else 2 * probes) * n}
    if noncanonical and surface is not None:
        needs[f"the surface's two-form ({surface[0] * surface[1]:,} points of {n} × {n})"] = \
            4 * 8.0 * surface[0] * surface[1] * n * n
    from ..service.scene_checks import available_memory
    free = available_memory()
    what, need = max(needs.items(), key=lambda kv: kv[1])
    fewer = (f"fewer {nm['defect_points']}" if "defect" in what else
             f"fewer {nm['loop_points']}" if surface is None or loop_points >= surface[0] * surface[1] else
             f"a smaller {nm['surface']}")
    if free is not None and need > free:
        raise ValueError(f"the audit needs about {need / 2**30:,.1f} GiB of memory for {what}; this machine has "
                         f"{free / 2**30:,.1f} GiB available: use {fewer}{' or a smaller ' + nm['k'] if nm['k'] != 'k' else ''}")
    return h, steps, every, loop_points, surface, defect_points, levels, probes


def _as_map(step, name="map"):
    if not callable(step):
        raise TypeError(f"the step map {name!r} must be callable as step(x, v, h) -> (x, v), got {type(step).__name__}")
    return step


def _call(step, x, v, h):
    """The map on (n, k) arrays, checked: two arrays of the inputs' shape, real where the inputs are."""
    got = step(x, v, h)
    if not isinstance(got, (tuple, list)) or len(got) != 2:
        raise ValueError(f"the step map must return (x, v), got {type(got).__name__}"
                         + (f" of {len(got)}" if isinstance(got, (tuple, list)) else ""))
    x1, v1 = (np.asarray(a) for a in got)
    if x1.shape != x.shape or v1.shape != v.shape:
        raise ValueError(f"the step map returned shapes {x1.shape}, {v1.shape} for inputs {x.shape}, {v.shape}")
    if not np.iscomplexobj(x) and (np.iscomplexobj(x1) or np.iscomplexobj(v1)):
        raise ValueError("the step map returned complex values for real inputs (an imaginary part is not dropped)")
    return x1, v1


def _plane(n, plane, directions, canonical=True):
    """Two directions (2, n) spanning the sets' plane: given, or coordinates ``plane`` = (i, j) of the
    phase space (x_0 … x_{k−1}, v_0 … v_{k−1}), or by default every x together against every v
    ((1, …, 1, 0, …)/√k and (0, …, 0, 1, …)/√k: ω of the pair is 1), or with ``plane="every"`` the
    same unscaled (the loop's radius in every coordinate, as Barham & Burby's study takes it: ω of
    the pair is k); a noncanonical map's default is the coordinates (0, 1)."""
    k = n // 2
    if plane is None and directions is None and not canonical:
        plane = (0, 1)
    if directions is not None:
        D = np.asarray(directions, dtype=float)
        if D.shape != (2, n) or not np.all(np.isfinite(D)):
            raise ValueError(f"directions must be two finite vectors of length 2k = {n}, got shape {D.shape}")
        if np.linalg.matrix_rank(D) < 2:
            raise ValueError("directions must be two independent vectors")
        return D
    D = np.zeros((2, n))
    if plane is None or (isinstance(plane, str) and plane == "every"):
        if not canonical:
            raise ValueError('plane="every" turns every x against its own v: a canonical map\'s loop (a noncanonical '
                             "map's plane is two coordinates, or directions=)")
        D[0, :k] = D[1, k:] = 1.0 if plane == "every" else 1.0 / math.sqrt(k)
        return D
    if isinstance(plane, str):
        raise ValueError(f'plane must be two coordinates (i, j) or "every", got {plane!r}')
    i, j = (int(a) for a in plane)
    if not (0 <= i < n and 0 <= j < n and i != j):
        raise ValueError(f"plane must name two different phase-space coordinates in 0 … {n - 1}, got {plane}")
    D[0, i] = D[1, j] = 1.0
    return D


def _omega(a, b, k):
    """ω(a, b) = a_v·b_x − a_x·b_v (dv ∧ dx) and the size of its terms, for rows of (…, 2k)."""
    ax, av, bx, bv = a[..., :k], a[..., k:], b[..., :k], b[..., k:]
    return (np.sum(av * bx, axis=-1) - np.sum(ax * bv, axis=-1),
            np.sum(np.abs(av * bx), axis=-1) + np.sum(np.abs(ax * bv), axis=-1))


def jvp(step, z, U, h, method="auto", period=None):
    """DΦ(z)·U for points z (m, 2k) and directions U (m, r, 2k) of a canonical map: (m, r, 2k) and
    the method used (:func:`row_jvp`; ``period``: the phase space's periods, (2k,) or None)."""
    k = z.shape[1] // 2

    def rows(Z):
        x1, v1 = _call(step, Z[:, :k], Z[:, k:], h)
        return np.concatenate([x1, v1], axis=1)
    return row_jvp(rows, z, U, method, period)


def _unwrapped(d, period):
    """Differences of a map's outputs with whole periods of its periodic outputs taken out: a map
    that wraps its positions into [0, P) may wrap two nearby evaluations differently."""
    if period is None:
        return d
    P = np.asarray(period, dtype=float)
    per = P > 0
    if not per.any():
        return d
    d = np.array(d, dtype=float)
    d[..., per] -= P[per] * np.round(d[..., per] / P[per])
    return d


def row_jvp(f, z, U, method="auto", period=None):
    """Df(z)·U of a batched function f: (M, n) -> (M, n') on rows, at points z (m, n) along
    directions U (m, r, n): (m, r, n') and the method used.

    Complex step (one call on m·r rows) when f's complex evaluation reproduces the real one to
    1e-13 of the value and 1e-11 of its derivative's reach (a stretching map amplifies rounding), else 8th-order central differences with step 2⁻¹⁰·max(|z|, 1) along each unit direction
    (eight calls).  ``period`` (n',) (0: not periodic): outputs that f wraps are compared and
    differenced modulo their period (a position wrapped into [0, P) by one evaluation and not by
    its neighbour is not a jump of P)."""
    m, r, n = U.shape
    Z = np.repeat(z[:, None, :], r, axis=1).reshape(m * r, n)
    Uf = U.reshape(m * r, n)
    if method in ("auto", "complex step"):
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", np.exceptions.ComplexWarning)
                F = np.asarray(f(Z + 1j * CS_STEP * Uf))
                base = np.asarray(f(z))
            ref = np.repeat(base[:, None, :], r, axis=1).reshape(m * r, -1)
            # the real parts agree to round-off carried through the map: 1e-13 of the value, and 1e-11 of
            # the derivative's reach |Df·u| |z|/|u| (a stretching map amplifies its inputs' rounding, in
            # the direction of most stretch up to ~√n times more than along a random u)
            reach = np.abs(F.imag) / CS_STEP * (np.maximum(np.max(np.abs(Z), axis=1, keepdims=True), 1.0)
                                                / np.maximum(np.linalg.norm(Uf, axis=1, keepdims=True), 1e-300)) \
                if np.iscomplexobj(F) and F.shape == ref.shape else 0.0
            usable = np.iscomplexobj(F) and F.shape == ref.shape and \
                np.all(np.abs(_unwrapped(F.real - ref, period)) <= 1e-13 * np.maximum(np.abs(ref), 1.0) + 1e-11 * reach)
        except (TypeError, ValueError):
            usable = False
        if usable:
            return (F.imag / CS_STEP).reshape(m, r, -1), "complex step"
        if method == "complex step":
            raise ValueError("the map does not keep complex arithmetic through (complex step unusable)")
    norm = np.linalg.norm(Uf, axis=1, keepdims=True)
    norm = np.where(norm > 0, norm, 1.0)
    delta = FD_STEP * np.maximum(np.max(np.abs(Z), axis=1, keepdims=True), 1.0)   # along the unit direction
    D = 0.0
    with np.errstate(all="ignore"):
        base = None if period is None else np.asarray(f(Z), dtype=float)
    for kk, w in FD_ORDER8:
        for sgn in (1.0, -1.0):
            with np.errstate(all="ignore"):
                g = np.asarray(f(Z + sgn * kk * delta * Uf / norm), dtype=float)
                D = D + sgn * w * (g if base is None else _unwrapped(g - base, period))
    return (D / delta * norm).reshape(m, r, -1), "central differences"


def map_defect(step, z, h, probes=PROBES, method="auto", seed=0, dense=None, theta=None, period=None):
    """The relative one-step defect of the canonical form at points z (m, 2k): (value, method, kind).
    With ``theta`` (a batched one-form ϑ(q) -> (m, d)) the map is ``step(q, h) -> q`` on (m, d) and
    the form dϑ, evaluated matrix-free at z and at Φ(z) (:func:`noncanonical_defect`).

    ``dense`` (default: 2k ≤ DENSE_UP_TO): max |BᵀJB − J| over the size of its terms, B the Jacobian
    from 2k JVPs; else the largest over ``probes`` random pairs (u, w) (normal, from numpy's generator
    of ``seed``) of |ω(Bu, Bw) − ω(u, w)| over the size of the terms of both.  NaN where the map
    failed (non-finite values).  ``period``: the phase space's periods ((2k,), or (d,) with ``theta``;
    0 where not periodic), which a map's wrapped outputs are differenced modulo."""
    m, n = z.shape
    k = n // 2
    dense = n <= DENSE_UP_TO if dense is None else dense
    if theta is not None:
        return noncanonical_defect(step, theta, z, h, probes, method, seed, dense, period)
    if dense:
        E = np.broadcast_to(np.eye(n), (m, n, n))
        DB, used = jvp(step, z, np.ascontiguousarray(E), h, method, period)  # rows: B e_j
        B = np.swapaxes(DB, 1, 2)
        Jc = np.block([[np.zeros((k, k)), -np.eye(k)], [np.eye(k), np.zeros((k, k))]])
        return _pullback(B, Jc, Jc), used, "dense"
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((m, 2 * probes, n)) / math.sqrt(n)
    BU, used = jvp(step, z, U, h, method, period)
    u, w, a, b = U[:, 0::2], U[:, 1::2], BU[:, 0::2], BU[:, 1::2]
    o_out, s_out = _omega(a, b, k)
    o_in, s_in = _omega(u, w, k)
    val = np.abs(o_out - o_in) / (s_out + s_in)
    return (float(np.max(val)) if np.all(np.isfinite(val)) else math.nan), used, f"{probes} probe pairs"


def _pullback(B, O0, O1):
    """max over points of |BᵀΩ₁B − Ω₀| over the size of its terms (|Bᵀ||Ω₁||B| + |Ω₀|): the dense
    defect; NaN where a value is not finite."""
    pull = np.swapaxes(B, 1, 2) @ O1 @ B
    size = np.abs(np.swapaxes(B, 1, 2)) @ np.abs(O1) @ np.abs(B) + np.abs(O0)
    val = np.max(np.abs(pull - O0), axis=(1, 2)) / np.max(size, axis=(1, 2))
    return float(np.max(val)) if np.all(np.isfinite(val)) else math.nan


def _rows(step, h):
    """A noncanonical map ``step(q, h) -> q`` as a function of rows, checked: an array of q's shape,
    real where q is."""
    def f(Z):
        got = np.asarray(step(Z, h))
        if got.shape != Z.shape:
            raise ValueError(f"the step map returned shape {got.shape} for input {Z.shape}")
        if not np.iscomplexobj(Z) and np.iscomplexobj(got):
            raise ValueError("the step map returned complex values for real inputs (an imaginary part is not dropped)")
        return got
    return f


def _one_form(theta):
    """ϑ as a function of rows, checked: an array of q's shape."""
    def f(Z):
        got = np.asarray(theta(Z))
        if got.shape != Z.shape:
            raise ValueError(f"theta(q) must return an array of q's shape {Z.shape}, got {got.shape}")
        return got
    return f


def two_form(theta, z, method="auto"):
    """Ω(z) = Jᵀ − J, J_ij = ∂ϑ_i/∂q_j, of dϑ at points z (…, d): (…, d, d) from d JVPs of ϑ a point,
    so that dϑ(a, b) = aᵀΩb (dv ∧ dx for ϑ = (v, 0)).  For surfaces of moderate d."""
    shape, d = z.shape[:-1], z.shape[-1]
    zz = z.reshape(-1, d)
    DJ, _ = row_jvp(_one_form(theta), zz, np.ascontiguousarray(np.broadcast_to(np.eye(d), (zz.shape[0], d, d))), method)
    J = np.swapaxes(DJ, 1, 2)                 # DJ[:, j] = J e_j
    return (np.swapaxes(J, 1, 2) - J).reshape(shape + (d, d))


def noncanonical_defect(step, theta, z, h, probes=PROBES, method="auto", seed=0, dense=None, period=None):
    """The one-step defect of dϑ under ``step(q, h) -> q`` at points z (m, d): (value, method, kind).

    Matrix-free: over random probe pairs (u, w), |dϑ_{Φ(z)}(DΦu, DΦw) − dϑ_z(u, w)| over the size of
    the terms summed, dϑ_z(a, b) = b·(Ja) − a·(Jb) with J = Dϑ(z) applied by JVPs of ϑ (four a pair,
    two of the map); ``dense`` (default d ≤ DENSE_UP_TO): max |BᵀΩ(Φ(z))B − Ω(z)| over the size of its
    terms with B and Ω from d JVPs each, as for a canonical map."""
    m, n = z.shape
    dense = n <= DENSE_UP_TO if dense is None else dense
    f, th = _rows(step, h), _one_form(theta)
    with np.errstate(all="ignore"):
        z1 = np.asarray(f(z), dtype=float)
    if dense:
        DB, used = row_jvp(f, z, np.ascontiguousarray(np.broadcast_to(np.eye(n), (m, n, n))), method, period)
        B = np.swapaxes(DB, 1, 2)
        return _pullback(B, two_form(theta, z, method), two_form(theta, z1, method)), used, "dense"
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((m, 2 * probes, n)) / math.sqrt(n)
    BU, used = row_jvp(f, z, U, method, period)
    JU, _ = row_jvp(th, z, U, method)
    JBU, _ = row_jvp(th, z1, BU, method)

    def form(A, JA):             # dϑ(a, b) = b·(Ja) − a·(Jb) of the pairs (rows 2i, 2i + 1), and its terms' size
        a, b, ja, jb = A[:, 0::2], A[:, 1::2], JA[:, 0::2], JA[:, 1::2]
        return (np.sum(b * ja, axis=-1) - np.sum(a * jb, axis=-1),
                np.sum(np.abs(b * ja), axis=-1) + np.sum(np.abs(a * jb), axis=-1))
    (o_out, s_out), (o_in, s_in) = form(BU, JBU), form(U, JU)
    val = np.abs(o_out - o_in) / (s_out + s_in)
    return (float(np.max(val)) if np.all(np.isfinite(val)) else math.nan), used, f"{probes} probe pairs"


def _loop(z0, D, radius, n):
    tau = np.arange(n) / n
    c, s = np.cos(2 * np.pi * tau), np.sin(2 * np.pi * tau)
    return z0 + radius * (c[:, None] * D[0] + s[:, None] * D[1])


def _surface(z0, D, radius, ns, nt):
    from invariants.spectral import chebyshev_points
    a, b = np.meshgrid(2 * chebyshev_points(ns) - 1, 2 * chebyshev_points(nt) - 1, indexing="ij")
    return z0 + radius * (a[..., None] * D[0] + b[..., None] * D[1])


INVARIANT_COLUMNS = 256   # a canonical loop of more degrees of freedom has its I₁ summed over blocks of this many


def _invariants(z, k, P, kind, theta=None):
    """The set's canonical invariant (positions' periods P), or with ``theta`` its noncanonical one
    (∮ ϑ·dq, ∫∫ dϑ with Ω from :func:`two_form`; P one entry per coordinate).  A canonical loop of
    more than ``INVARIANT_COLUMNS`` degrees of freedom: :func:`_blocked_first_invariant`."""
    import invariants
    f = invariants.first_invariant if kind == "I1" else invariants.second_invariant
    if theta is not None:
        form = _one_form(theta) if kind == "I1" else (lambda Q: two_form(theta, Q))
        return f(z, form, period=P)
    x, v = z[..., :k], z[..., k:]
    if kind == "I1" and k > INVARIANT_COLUMNS:
        return _blocked_first_invariant(x, v, P)
    return f(x, "canonical", p=v, period=P)


def _blocked_first_invariant(x, v, P):
    """The canonical I₁ = Σ_i ∮ v_i dx_i of a loop (N, k) as the sum of its blocks of
    ``INVARIANT_COLUMNS`` coordinate pairs, each with its monitor, so that the transforms' temporaries
    are a block's (five states of the whole loop at once): the value is the blocks' values summed in
    order (a fixed block size: the same bits whatever the machine); ``error`` and the round-off are
    the blocks' summed (a sum of bounds bounds the sum); ``resolution`` the largest of the blocks'
    (each read against its own value, so at least the whole loop's spectral reading) and of the
    summed error over |I₁|, as :func:`invariants.forms._value` reads it; the first block's reason."""
    from invariants import spectral
    from invariants.forms import UNDER_RESOLVED, InvariantValue
    import invariants
    k, C = x.shape[1], INVARIANT_COLUMNS
    parts = [invariants.first_invariant(x[:, a:a + C], "canonical", p=v[:, a:a + C],
                                        period=None if P is None else P[a:a + C]) for a in range(0, k, C)]
    value = 0.0
    for b in parts:
        value += b.value
    rounding = sum(b.roundoff * abs(b.value) for b in parts)          # each block's error holds its round-off
    pure = sum(b.error for b in parts) - rounding
    reason = next((b.reason for b in parts if b.reason), "")
    reading = spectral.relative(pure, value) if pure > 2.0 * rounding else 0.0      # as invariants.forms._value
    res = max([reading, 1.0 if reason else 0.0] + [b.resolution for b in parts])
    return InvariantValue(value, float(res), bool(res > UNDER_RESOLVED), float(pure + rounding),
                          float(spectral.relative(rounding, value)), reason, 1)


def audit_map(step, point, h, *, steps=100, output_every=None, loop_points=1024, radius=0.1, plane=None,
              directions=None, surface=None, period=None, defect_points=4, levels=3, probes=PROBES,
              method="auto", seed=0, name="map", progress=None, theta=None, energy=None) -> dict:
    """The whole audit of a canonical step map around the phase-space point ``point`` = (x0, v0).

    With ``theta``, a batched one-form ϑ(q) -> (n, d) (a degenerate Lagrangian ϑ(q)·q̇ − H(q) whose
    ϑ is code), the maps are noncanonical ``step(q, h) -> q`` on (n, d) arrays, ``point`` is q0 (1-D,
    length d), ``period`` one entry per coordinate, the default plane the coordinates (0, 1), and the
    form audited is dϑ (I₁ = ∮ ϑ·dq; a surface's I₂ takes Ω = Dϑᵀ − Dϑ, d JVPs a point: d ≤ 64).

    ``energy``: a batched energy(x, v) -> (n,) (with ``theta``: energy(q)); the report's
    ``energy_error`` is then max over the sets' points of |H − H(0)|/|H(0)| (|H − H(0)| where H(0) = 0)
    at every output, and ``energy_growth_law`` its growth law.

    step : ``step(x, v, h) -> (x, v)`` on (n, k) arrays, each row on its own (or a dict {name: step}:
        several maps audited on the same sets, in one report)
    point : (x0, v0), 1-D arrays of length k
    h : the step size, or a list of step sizes: a sweep (:func:`_sweep`, one report for all of them,
        the sets and their I(0) built once; with ``steps=1`` the one-step mode, whose verdict is
        |I(h) − I(0)|/|I(0)| against h)
    steps, output_every : steps of the drift run, outputs every (default steps/50)
    loop_points, radius, plane, directions : the loop z0 + radius(cos 2πτ d₁ + sin 2πτ d₂); the
        directions d₁, d₂ given (two vectors of length 2k), or the coordinates ``plane`` = (i, j) of
        (x_0 … x_{k−1}, v_0 … v_{k−1}), or ``plane="every"`` (radius ``radius`` in every coordinate:
        x_i = x0_i + r cos 2πτ, v_i = v0_i + r sin 2πτ), or by default all x against all v scaled by
        1/√k (see :func:`_plane`).  The loop turns clockwise in each (x_i, v_i) plane, so I₁ = ∮ v·dx
        is −πr² a coordinate pair
    surface : (n_σ, n_τ) for a square of half-side ``radius`` in the same plane at Chebyshev points
        (I₂), or None
    period : the positions' periods (a number, or one per x coordinate; None or 0: not periodic)
    defect_points, levels, probes, method, seed : the defect at ``defect_points`` points of the loop
        for h·2⁻ˡ, l < ``levels`` (a sweep: at its own step sizes), by :func:`map_defect`
    Returns the JSON-able report of :func:`integrators.audit.audit` (``text_report``,
    ``plot_report`` read it), with the loop's description under ``"sets"``.

    The image of the loop after the first step is searched for jumps (:mod:`integrators.audit.jumps`):
    a map whose image jumps is ``discontinuous`` where its point-wise defect would say symplectic,
    with I₁ over the continuous pieces before and after the step (``"discontinuity"``).

    Every argument and size is checked first (:func:`check_arguments`; the plane must carry area of
    the form, a period must be one the loop's steps can tell from a wrap): a one-line ValueError,
    nothing allocated.  An under-resolved drift carries its ``under_resolved_reason``.
    """
    maps = step if isinstance(step, dict) else {name: step}
    if not maps:
        raise ValueError("no step map given (an empty dict)")
    for nm, s in maps.items():
        _as_map(s, nm)
    if theta is not None and not callable(theta):
        raise TypeError(f"theta must be callable as theta(q) -> (n, d), got {type(theta).__name__}")
    z0 = _start(point, theta)
    n = z0.size
    k = n // 2
    sweep = isinstance(h, (list, tuple)) or (isinstance(h, np.ndarray) and h.ndim == 1)
    if sweep and len(h) == 0:
        raise ValueError("h must be a step size or a non-empty list of them, got an empty list")
    hs = []
    for hk in (h if sweep else [h]):
        hk, steps, every, loop_points, surface, defect_points, levels, probes = check_arguments(
            n, hk, steps=steps, output_every=output_every, loop_points=loop_points, radius=radius, surface=surface,
            defect_points=defect_points, levels=levels, probes=probes, method=method, noncanonical=theta is not None)
        hs.append(hk)
    if sweep and len(set(hs)) != len(hs):
        raise ValueError(f"h lists a step size twice: {hs}")
    from invariants.forms import _periods
    P = _periods(period, n if theta is not None else k)
    if theta is not None and surface is not None and n > 2 * DENSE_UP_TO:
        raise ValueError(f"a surface of a noncanonical map takes Ω = Dϑᵀ − Dϑ, {n} × {n} a point: up to "
                         f"d = {2 * DENSE_UP_TO}; audit the loop (surface=None)")
    D = _plane(n, plane, directions, canonical=theta is None)
    sets, shapes = _sets(z0, k, D, radius, loop_points, surface, P, theta, method)
    loop = sets["I1"]
    N = loop.shape[0]
    form = "canonical" if theta is None else "noncanonical"
    sel = np.linspace(0, loop.shape[0], defect_points, endpoint=False).astype(int)
    points = loop[sel].copy()             # the defect's points
    report = {"scene": name if not isinstance(step, dict) else "maps", "h": hs if sweep else hs[0], "steps": steps,
              "T": [hk * steps for hk in hs] if sweep else hs[0] * steps,
              "system": f"canonical map, k = {k} ({2 * k}-dimensional phase space)" if theta is None else
              f"noncanonical map with a one-form of code, d = {n}",
              "thresholds": {"roundoff": ROUNDOFF, "resolved": RESOLVED, "defect_floor": DEFECT_FLOOR},
              "defect_points": points.tolist() if n <= 64 else f"{len(sel)} points of the loop",
              "sets": _sets_description(loop_points, radius, plane, directions, surface, P, theta is None),
              "discrimination": None,       # the canonical form is not constant along a general map
              "candidates": []}
    invariant = (lambda part, key: _invariants(part, k, P, key, theta))
    start = _start_values(sets, shapes, invariant)          # I(0) of every set, once for every map and h
    del sets, loop                        # each run builds its sets afresh (the same bits), so that a run
    fresh = (lambda: _sets(z0, k, D, radius, loop_points, surface, P, theta, method)[0])   # holds two states
    Pz = None if P is None else (P if theta is not None else np.concatenate([P, np.zeros(k)]))
    ctx = dict(k=k, z0=z0, D=D, radius=float(radius), Pz=Pz, theta=theta, scale=abs(start["I1"].value))
    for nm, s in maps.items():
        say = None if progress is None else (lambda msg, nm=nm: progress(f"{nm}: {msg}"))
        runs = []
        for hk in hs:
            entry = {"name": nm, "role": "candidate", "kind": f"{form} map", "h": hk, "breakdown_step": None,
                     "drift": {}, "t": [], "errors": {}, "defect": {}, "jacobian": None, "discontinuity": None}
            advance = _mapped(s, hk, k, theta)
            with np.errstate(all="ignore"):  # a map's overflow is its breakdown or its NaN defect: reported, not warned
                _drift(entry, _blocked(advance), fresh, shapes, invariant, form, steps, hk, every,
                       None if say is None else (lambda msg, hk=hk: say(f"h = {hk:g}: {msg}")),
                       _energy(energy, k, theta), start=start,
                       first=lambda z1, entry=entry, advance=advance: _look_for_jumps(entry, advance, z1[:N], ctx))
            runs.append(entry)
        levels_h = sorted(hs, key=abs, reverse=True) if sweep else [hs[0] * 2.0 ** -l for l in range(levels)]
        with np.errstate(all="ignore"):
            defect, jacobian = _defect_study(
                s, points, levels_h, probes, method, seed,
                None if say is None else (lambda hk: say(f"one-step defect at h = {hk:g}")), theta, Pz)
        if not sweep:
            entry = runs[0]
            entry["defect"], entry["jacobian"] = defect, jacobian
            _judge_jumps(entry["defect"][form], entry["discontinuity"])
            report["candidates"].append(entry)
        else:
            report["candidates"].append(_sweep_entry(nm, form, hs, runs, defect, jacobian, steps))
    if sweep:
        report["sweep"] = {"h": hs, "mode": "one step" if steps == 1 else f"{steps} steps"}
    return report


def _mapped(step, h, k, theta):
    """The map at step size h as a function of rows (x, v joined; or q)."""
    return _advance(step, k, h) if theta is None else _rows(step, h)


BLOCK_BYTES = 64 * 2 ** 20     # the sets are advanced in blocks of rows of about this size (two states at most)


def _blocked(advance):
    """``advance`` on rows, block by block into one output array: the map's temporaries are a block's,
    whatever the sets' size (each row is advanced on its own, so the result is the same bits)."""
    def f(z):
        rows = max(1, BLOCK_BYTES // (8 * z.shape[1]))
        if z.shape[0] <= rows:
            return advance(z)
        out = np.empty_like(z)
        for a in range(0, z.shape[0], rows):
            out[a:a + rows] = advance(z[a:a + rows])
        return out
    return f


def _start_values(sets, shapes, invariant):
    """Every set's invariant at t = 0 (an InvariantValue by key): computed once for every map and h."""
    return {key: invariant(sets[key].reshape(shapes[key]), key) for key in sets}


def _look_for_jumps(entry, advance, image, ctx):
    """The entry's ``discontinuity`` from the loop's image after one step (:mod:`integrators.audit.jumps`),
    with I₁ over the continuous pieces where the image jumps."""
    from .jumps import find_jumps, piecewise_first_invariant
    z0, D, r, k = ctx["z0"], ctx["D"], ctx["radius"], ctx["k"]

    def at(tau):
        tau = np.asarray(tau, dtype=float)
        return z0 + r * (np.cos(2 * np.pi * tau)[:, None] * D[0] + np.sin(2 * np.pi * tau)[:, None] * D[1])
    found = find_jumps(advance, at, image, ctx["Pz"])
    found["piecewise"] = None
    if found["verdict"] == "jumps" and found["candidates"] > found["bisected"]:
        found["reason"] += (f"; no I₁ over the continuous pieces: {found['candidates'] - found['bisected']} candidate "
                            "gaps were not bisected, so the pieces are not known")
    elif found["verdict"] == "jumps":
        one_form = (_one_form(ctx["theta"]) if ctx["theta"] is not None else
                    (lambda Z: np.concatenate([Z[:, k:], np.zeros_like(Z[:, k:])], axis=1)))
        try:
            found["piecewise"] = piecewise_first_invariant(advance, at, found["jumps"], one_form, ctx["Pz"],
                                                           ctx["scale"])
        except Exception as exc:        # the map raised on a piece's points: the jumps stand, no piecewise I₁
            found["piecewise"] = None
            found["reason"] += f"; no piecewise I₁ (the map raised: {type(exc).__name__}: {exc})"
    entry["discontinuity"] = found


def _judge_jumps(d, jumps):
    """A defect verdict ``d`` told of the image's jumps: ``symplectic`` point by point becomes
    ``discontinuous`` (the defect cannot see a jump, and the closed loop's I₁ is not the map's invariant)."""
    if jumps is None or jumps["verdict"] != "jumps":
        return
    pw = jumps.get("piecewise")
    piece = ("" if not pw else f"; I₁ over the loop's {pw['pieces']} continuous piece{'s' if pw['pieces'] != 1 else ''} moves by {pw['change']:.2g} "
             f"of itself in one step" + ("" if pw["settled"] else " (the pieces' sums did not settle: a jump hides inside)"))
    if d["verdict"] == "symplectic":
        d["verdict"] = "discontinuous"
        d["reason"] = ("the defect is at its floor where the map is smooth, but " + jumps["reason"]
                       + ": the point-wise defect cannot see a jump, and I₁ over the closed loop is not this map's "
                       "invariant" + piece)
    else:
        d["reason"] = (d.get("reason", "") + "; " if d.get("reason") else "") + jumps["reason"] + piece


def _sweep_entry(name, form, hs, runs, defect, jacobian, steps):
    """One map's entry of a sweep: its runs by h, the defect study over the sweep's step sizes, the
    one-step errors (steps = 1) and a verdict at every h."""
    d = defect[form]
    family = d["verdict"]                      # the verdict over the sweep (a larger h can decide a small one)
    floor = DEFECT_FLOOR["central differences" if "central differences" in jacobian else "complex step"]
    one = None
    key = f"I1/{form}"
    if steps == 1:
        e = [r["errors"][key][-1] if r["errors"].get(key) and r["breakdown_step"] is None else math.nan for r in runs]
        res = [r["drift"][key]["resolution"] if key in r["drift"] else math.nan for r in runs]
        e_arr = np.array(e, dtype=float)
        # the floor at each h: round-off, or the two values' own uncertainty (error + round-off) if larger
        floors = [max(ROUNDOFF, (r["uncertainty"][key][0] + r["uncertainty"][key][-1]) / abs(r["drift"][key]["value_at_start"]))
                  if key in r.get("uncertainty", {}) and r["drift"][key]["value_at_start"] else ROUNDOFF for r in runs]
        order = fit_order_small_h(hs, e_arr, max(floors))   # |I(h) − I(0)| can change sign at large h
        above = [x > f and rr <= RESOLVED for x, rr, f in zip(e, res, floors)]
        verdicts = []
        for x, rr, f in zip(e, res, floors):
            verdicts.append("broke down" if not math.isfinite(x) else
                            "under-resolved" if rr > RESOLVED and x > f else
                            "not symplectic" if x > f else
                            "not symplectic (below the floor at this h)" if any(above) else "round-off")
        one = {"h": hs, "error": e, "floor": floors, "resolution": res, "order": order, "verdict": verdicts}
    verdicts = []
    for i, (hk, r) in enumerate(zip(hs, runs)):
        at = d["h"].index(hk) if hk in d["h"] else None
        v = d["defect"][at] if at is not None and d["defect"] else math.nan
        if family == "not symplectic":
            why = ("its defect is above the floor here" if math.isfinite(v) and v > floor else
                   "its defect is below the floor at this h, above it at larger h" + (
                       f" (order {d['order']:.2f})" if d.get("order") is not None else ""))
            verdict = "not symplectic"
        else:
            verdict, why = family, d.get("reason", "")
        jumps = r["discontinuity"]
        if jumps is not None and jumps["verdict"] == "jumps":
            sub = {"verdict": verdict, "reason": why}
            _judge_jumps(sub, jumps)
            verdict, why = sub["verdict"], sub["reason"]
        if one is not None and verdict == "symplectic" and one["verdict"][i].startswith("not symplectic"):
            verdict, why = "not symplectic", (f"I₁ moves by {one['error'][i]:.2g} of itself in one step although the "
                                              "defect is at its floor")
        drift = r["drift"].get(key, {})
        if verdict == "symplectic" and (one["verdict"][i] == "under-resolved" if one is not None else
                                        drift.get("verdict") == "under-resolved"):
            verdict, why = "cannot tell at this h", ("the defect is at its floor, but the loop's image is under-resolved "
                                                     f"({drift.get('under_resolved_reason') or 'its monitor'}): a "
                                                     "jump or a fold its points cannot resolve")
        if r["breakdown_step"] is not None and verdict == "symplectic":
            verdict, why = "broke down", f"a point broke down at step {r['breakdown_step']}"
        verdicts.append({"h": hk, "verdict": verdict, "reason": why})
    return {"name": name, "role": "candidate", "kind": f"{form} map", "jacobian": jacobian, "defect": defect,
            "runs": runs, "one_step": one, "verdicts": verdicts}


def _sets(z0, k, D, radius, loop_points, surface, P, theta, method):
    """({"I1": loop rows, "I2": surface rows}, their shapes) in the plane of D, checked: the plane
    carries area of the form, the periods are ones the loop's steps can tell from a wrap."""
    n = z0.size
    _check_area(D, z0, k, theta, method)
    loop = _loop(z0, D, float(radius), loop_points)
    sets = {"I1": loop}
    if surface is not None:
        sets["I2"] = _surface(z0, D, float(radius), *surface).reshape(-1, n)
    if P is not None:
        _check_period(loop, P if theta is not None else np.concatenate([P, np.zeros(k)]))
    return sets, {"I1": loop.shape, "I2": None if surface is None else (surface[0], surface[1], n)}


def _check_area(D, z0, k, theta, method):
    """Refuse a plane that carries no area of the form audited (ω(d₁, d₂) = 0 at the loop's centre):
    every loop there has I₁ = 0 for every map, and a relative error has no scale."""
    if theta is None:
        o, size = _omega(D[0], D[1], k)
        hint = "; turn it in a position and its own momentum, plane=(i, k + i), or leave plane out"
    else:
        JD, _ = row_jvp(_one_form(theta), z0[None], D[None], method)
        a, b, ja, jb = D[0], D[1], JD[0, 0], JD[0, 1]
        o, size = float(b @ ja - a @ jb), float(np.abs(b * ja).sum() + np.abs(a * jb).sum())
        hint = " at the point; choose two coordinates that dϑ pairs"
        if not math.isfinite(o):
            raise ValueError("theta(q) is not finite near the point (its derivative there is not finite)")
    if abs(o) <= 1e-12 * max(size, 1e-300):
        raise ValueError(f"the loop's plane carries no area of the form: {'ω' if theta is None else 'dϑ'}(d₁, d₂) = "
                         f"{o:.3g}, so I₁ = 0 for every map and no relative error exists{hint}")


def _check_period(loop, P):
    """Refuse a period that the loop's own sampling cannot tell from a wrap: a periodic coordinate
    whose step between neighbouring points of the (unwrapped) loop is a quarter period or more."""
    step = np.concatenate([np.max(np.abs(np.diff(loop[:, c:c + 512], axis=0, append=loop[:1, c:c + 512])), axis=0)
                           for c in range(0, loop.shape[1], 512)])          # by blocks of columns: no whole-state temporary
    bad = np.flatnonzero((P > 0) & (step >= P / 4))
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"period {P[i]:.6g} of coordinate {i} is not a period of this loop: its points step by up to "
                         f"{step[i]:.3g} there, a quarter of the period or more, so a wrap cannot be told from a step "
                         "(give the coordinate's real period, or 0 where it is not periodic)")


def _sets_description(loop_points, radius, plane, directions, surface, P, canonical):
    """The report's "sets": the loop, the surface and the periods, as the user gave them."""
    where = (plane if isinstance(plane, str) else list(plane) if plane is not None else "given directions" if directions is not None else
             "all x against all v" if canonical else [0, 1])
    return {"loop": {"points": int(loop_points), "radius": float(radius), "plane": where},
            "surface": None if surface is None else {"n_sigma": int(surface[0]), "n_tau": int(surface[1])},
            "period": None if P is None else P.tolist()}


def _start(point, theta):
    """The phase-space point of the sets: (x0, v0) joined, or with ``theta`` the point q0 itself."""
    if theta is not None:
        z0 = np.asarray(point, dtype=float)
        if z0.ndim != 1 or z0.size < 2:
            raise ValueError(f"point must be q0, a 1-D array of the map's d ≥ 2 coordinates, got shape {z0.shape}")
    else:
        if (np.ndim(point) != 2 if isinstance(point, np.ndarray) else not isinstance(point, (tuple, list))) \
                or len(point) != 2:
            raise ValueError(f"point must be (x0, v0), two 1-D arrays of the same length k, got "
                             f"{'one array of shape ' + str(np.shape(point)) if isinstance(point, np.ndarray) else type(point).__name__}"
                             " (a noncanonical map's q0 goes with theta=)")
        x0, v0 = (np.asarray(a, dtype=float) for a in point)
        if x0.ndim != 1 or x0.shape != v0.shape or x0.size == 0:
            raise ValueError(f"point must be (x0, v0), two 1-D arrays of the same length k, got shapes {x0.shape}, "
                             f"{v0.shape}")
        z0 = np.concatenate([x0, v0])
    if not np.all(np.isfinite(z0)):
        raise ValueError("point must be finite")
    return z0


def _advance(step, k, h):
    """A canonical map as a function of rows z = (x, v)."""
    def f(z):
        x1, v1 = _call(step, z[:, :k], z[:, k:], h)
        return np.concatenate([x1, v1], axis=1)
    return f


def _defect_study(step, z, hs, probes, method, seed, progress, theta=None, period=None):
    """({form: {h, defect, order, verdict}}, the Jacobian method) of a map at points z over the step
    sizes hs (the canonical form, or dϑ with ``theta``), judged against the method's floor as
    :func:`integrators.audit.defect_study`.

    A defect below the floor at every one of hs does not make a map symplectic: a map whose defect
    is C·hᵖ falls below it once h is small enough (RK2 in a PIC code at dt = 2⁻¹⁰: 1.7e-14 and
    3.4e-15 against the floor 1e-13, order 3 at larger dt).  So the study then goes up, h·2, h·4, …
    h·2^UPWARD: the first defect above the floor makes the verdict "not symplectic" (``above_from``:
    that h; the order fitted over every level above the floor; ``below_floor_at_h``: true); a map that
    fails before any defect rises leaves "cannot tell at this h"; defects below the floor all the way
    up make it "symplectic"."""
    def one(hk, how=method):
        if progress:
            progress(hk)
        try:
            return map_defect(step, z, hk, probes, how, seed, theta=theta, period=period)
        except Exception as exc:         # the user's map raised: a verdict, not a traceback
            return math.nan, f"none ({type(exc).__name__}: {exc})", "—"

    vals, used, kinds = [], [], set()
    for hk in hs:
        v, u, kind = one(hk)
        vals.append(v)
        used.append(u)
        kinds.add(kind)
    floors = np.array([DEFECT_FLOOR.get(u, np.inf) for u in used])
    arr = np.array(vals, dtype=float)
    extra = {}
    if not np.all(np.isfinite(arr)):
        verdict = "step failed"
    elif not np.all(arr <= floors):
        verdict = "not symplectic"
    else:
        verdict = "symplectic"
        up_h, up_v, up_f = [], [], []
        first = None                     # the first larger h whose defect is above the floor
        # the larger steps by the levels' own method: a map differentiated by complex step at h is not
        # judged at 64h by central differences, whose truncation on a map of few derivatives (a PIC
        # step with spline shapes) reads as a defect
        how = "complex step" if set(used) == {"complex step"} else method
        span = abs(max(hs, key=abs)) / abs(min(hs, key=abs))
        for l in range(1, UPWARD + 1):
            hk = max(hs, key=abs) * 2.0 ** l
            v, u, kind = one(hk, how)
            if not math.isfinite(v):
                if first is None:
                    why = ("fails" if how != "complex step" else "fails, or its complex evaluation is no longer its real "
                           "one,")
                    if span * 2.0 ** (l - 1) >= 2.0 ** UPWARD:    # below the floor over 64× in h: enough
                        extra = {"upward": {"h": up_h, "defect": up_v},
                                 "reason": f"every defect is below the floor from h = {hs[-1]:g} up to "
                                           f"{(up_h or hs)[-1] if up_h else hs[0]:g} (the map {why} at {hk:g})"}
                    else:
                        verdict = "cannot tell at this h"
                        extra = {"reason": f"every defect is below the floor at h = {hs[-1]:g} … {hs[0]:g}, and the "
                                           f"map {why} at {hk:g}, so no larger step can show one"}
                    first = -1.0         # (stopped; not a level above the floor)
                break
            up_h.append(hk)
            up_v.append(v)
            up_f.append(DEFECT_FLOOR.get(u, np.inf))
            kinds.add(kind)
            if first is None and v > up_f[-1]:
                first = hk
            if first is not None and sum(x > 10 * f for x, f in zip(up_v, up_f)) >= 3:
                break                    # enough above the floor for an order
        if first == -1.0:
            first = None
        elif first is not None:
            verdict = "not symplectic"
            allh, allv = list(hs) + up_h, np.concatenate([arr, up_v])
            order = fit_order(allh, allv, max(floors.max(), max(up_f))) if np.all(np.isfinite(up_f)) else None
            extra = {"below_floor_at_h": True, "above_from": first, "upward": {"h": up_h, "defect": up_v},
                     "order": order,
                     "reason": f"every defect is below the floor at h = {hs[-1]:g} … {hs[0]:g}; at {first:g} it is "
                               f"{up_v[up_h.index(first)]:.2g}"
                               + (f", and it grows as h^{order:.2f}" if order is not None else "")}
        elif verdict == "symplectic" and "reason" not in extra:
            extra = {"upward": {"h": up_h, "defect": up_v},
                     "reason": f"every defect is below the floor from h = {hs[-1]:g} up to {up_h[-1]:g}"}
    order = fit_order(hs, arr, floors.max()) if np.all(np.isfinite(floors)) else None
    entry = {"h": hs, "defect": arr.tolist(), "order": order, "verdict": verdict, **extra}
    return ({"canonical" if theta is None else "noncanonical": entry},
            ", ".join(sorted(set(used))) + f" ({', '.join(sorted(kinds))})")


def _energy(energy, k, theta):
    """The energy of rows z, checked: (n,) reals; or None."""
    if energy is None:
        return None
    if not callable(energy):
        raise TypeError(f"energy must be callable, got {type(energy).__name__}")

    def H(z):
        e = np.asarray(energy(z) if theta is not None else energy(z[:, :k], z[:, k:]))
        if e.shape != (z.shape[0],) or e.dtype.kind not in "fiu":
            raise ValueError(f"energy must return ({z.shape[0]},) real values, got shape {e.shape} of {e.dtype}")
        return e.astype(float)
    return H


def _drift(entry, advance, fresh, shapes, invariant, form, steps, h, every, progress, energy=None, start=None,
           first=None):
    """The sets advanced ``steps`` steps by ``advance(z) -> z`` (rows), ``invariant(part, key)`` at
    every output (and ``energy(z)``): the entry's drift, errors, energy error and its growth law, and
    the breakdown step.  ``start``: the sets' invariants at t = 0 already computed (by key);
    ``first(z1)`` is called with the sets' rows after the first step; ``fresh()`` builds the sets
    ({key: rows}), here, so that nothing else holds them once the first step is taken."""
    sets = fresh()
    from invariants.growth import growth_law
    from ..service.statuses import relative_error
    z = np.concatenate([sets[key] for key in sets], axis=0) if len(sets) > 1 else sets[next(iter(sets))]
    # (one set: its rows themselves; the map returns new arrays, so the set is not changed)
    cut = np.cumsum([sets[key].shape[0] for key in sets])[:-1]
    sets = list(sets)                        # the keys: the rows are z's alone now
    t, values, res = [0.0], {key: [] for key in sets}, {key: 0.0 for key in sets}
    bounds = {key: [] for key in sets}
    why = {key: "" for key in sets}          # the first reason a set was under-resolved, where one is given

    def record(z, given=None):
        for key, part in zip(sets, np.split(z, cut)):
            v = given[key] if given is not None else invariant(part.reshape(shapes[key]), key)
            values[key].append(v.value)
            bounds[key].append(v.error + v.roundoff * abs(v.value))      # the value's own uncertainty
            res[key] = max(res[key], v.resolution)
            if v.under_resolved and not why[key]:
                why[key] = f"from t = {t[-1]:g}: " + (
                    v.reason or f"the set's monitor reads {v.resolution:.2g} (> {RESOLVED:g}): more loop points, "
                                "a smaller radius or fewer steps")

    record(z, start)
    if energy is not None:
        H0 = energy(z)
        scale = np.where(H0 != 0, np.abs(H0), 1.0)
        entry["energy_error"] = [0.0]
    broke = None
    for n in range(1, steps + 1):
        with np.errstate(all="ignore"):
            try:
                z = np.asarray(advance(z), dtype=float)
            except Exception as exc:         # the map raised: every point stops here
                entry["error"] = f"{type(exc).__name__}: {exc}"
                z = np.full_like(z, np.nan)
        if not np.all(np.isfinite(z)):
            broke = n
            break
        if n == 1 and first is not None:
            first(z)
        if n % every == 0 or n == steps:
            t.append(n * h)
            record(z)
            if energy is not None:
                entry["energy_error"].append(float(np.max(np.abs(energy(z) - H0) / scale)))
        if progress and n % every == 0:
            progress(f"step {n}/{steps}")
    t = np.array(t)
    for key in sets:
        err = relative_error(values[key])
        g = growth_law(t, err) if broke is None else None
        emax, rate, verdict = drift_verdict(t, err, broke is not None, res[key], law=g)
        entry["drift"][f"{key}/{form}"] = {
            "max_error": emax, "drift_rate": rate, "verdict": verdict, "resolution": res[key],
            "near_floor": bool(ROUNDOFF < emax <= 10 * ROUNDOFF) if math.isfinite(emax) else False,
            "growth_law": None if g is None else g.law, "growth_exponent": None if g is None else g.exponent,
            "growth_exponent_error": None if g is None else g.exponent_error, "growth_onset": None if g is None else g.onset,
            "value_at_start": values[key][0], "under_resolved_reason": why[key] or None}
        entry["errors"][f"{key}/{form}"] = err.tolist()
        entry.setdefault("uncertainty", {})[f"{key}/{form}"] = bounds[key]
    entry["t"], entry["breakdown_step"] = t.tolist(), broke
    if energy is not None:
        g = growth_law(t, entry["energy_error"]) if broke is None else None
        entry["energy_growth_law"] = None if g is None else g.law
        entry["energy_growth_exponent"] = None if g is None else g.exponent
