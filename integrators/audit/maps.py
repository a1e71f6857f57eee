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
from .defect import DEFECT_FLOOR, FD_ORDER8, FD_STEP, fit_order
from .drift import ROUNDOFF, RESOLVED, drift_verdict

DENSE_UP_TO = 32          # phase-space dimensions up to which the defect takes the dense Jacobian
PROBES = 8                # probe pairs of the matrix-free defect (docs/audit.md: how many are enough)


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
    ((1, …, 1, 0, …)/√k and (0, …, 0, 1, …)/√k: ω of the pair is 1); a noncanonical map's default
    is the coordinates (0, 1)."""
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
    if plane is None:
        D[0, :k] = D[1, k:] = 1.0 / math.sqrt(k)
        return D
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


def jvp(step, z, U, h, method="auto"):
    """DΦ(z)·U for points z (m, 2k) and directions U (m, r, 2k) of a canonical map: (m, r, 2k) and
    the method used (:func:`row_jvp`)."""
    k = z.shape[1] // 2

    def rows(Z):
        x1, v1 = _call(step, Z[:, :k], Z[:, k:], h)
        return np.concatenate([x1, v1], axis=1)
    return row_jvp(rows, z, U, method)


def row_jvp(f, z, U, method="auto"):
    """Df(z)·U of a batched function f: (M, n) -> (M, n') on rows, at points z (m, n) along
    directions U (m, r, n): (m, r, n') and the method used.

    Complex step (one call on m·r rows) when f's complex evaluation reproduces the real one to
    1e-13, else 8th-order central differences with step 2⁻¹⁰·max(|z|, 1) along each unit direction
    (eight calls)."""
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
            usable = np.iscomplexobj(F) and F.shape == ref.shape and \
                np.all(np.abs(F.real - ref) <= 1e-13 * np.maximum(np.abs(ref), 1.0))
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
    for kk, w in FD_ORDER8:
        for sgn in (1.0, -1.0):
            with np.errstate(all="ignore"):
                D = D + sgn * w * np.asarray(f(Z + sgn * kk * delta * Uf / norm), dtype=float)
    return (D / delta * norm).reshape(m, r, -1), "central differences"


def map_defect(step, z, h, probes=PROBES, method="auto", seed=0, dense=None, theta=None):
    """The relative one-step defect of the canonical form at points z (m, 2k): (value, method, kind).
    With ``theta`` (a batched one-form ϑ(q) -> (m, d)) the map is ``step(q, h) -> q`` on (m, d) and
    the form dϑ, evaluated matrix-free at z and at Φ(z) (:func:`noncanonical_defect`).

    ``dense`` (default: 2k ≤ DENSE_UP_TO): max |BᵀJB − J| over the size of its terms, B the Jacobian
    from 2k JVPs; else the largest over ``probes`` random pairs (u, w) (normal, from numpy's generator
    of ``seed``) of |ω(Bu, Bw) − ω(u, w)| over the size of the terms of both.  NaN where the map
    failed (non-finite values)."""
    m, n = z.shape
    k = n // 2
    dense = n <= DENSE_UP_TO if dense is None else dense
    if theta is not None:
        return noncanonical_defect(step, theta, z, h, probes, method, seed, dense)
    if dense:
        E = np.broadcast_to(np.eye(n), (m, n, n))
        DB, used = jvp(step, z, np.ascontiguousarray(E), h, method)          # rows: B e_j
        B = np.swapaxes(DB, 1, 2)
        Jc = np.block([[np.zeros((k, k)), -np.eye(k)], [np.eye(k), np.zeros((k, k))]])
        return _pullback(B, Jc, Jc), used, "dense"
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((m, 2 * probes, n)) / math.sqrt(n)
    BU, used = jvp(step, z, U, h, method)
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


def noncanonical_defect(step, theta, z, h, probes=PROBES, method="auto", seed=0, dense=None):
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
        DB, used = row_jvp(f, z, np.ascontiguousarray(np.broadcast_to(np.eye(n), (m, n, n))), method)
        B = np.swapaxes(DB, 1, 2)
        return _pullback(B, two_form(theta, z, method), two_form(theta, z1, method)), used, "dense"
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((m, 2 * probes, n)) / math.sqrt(n)
    BU, used = row_jvp(f, z, U, method)
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


def _invariants(z, k, P, kind, theta=None):
    """The set's canonical invariant (positions' periods P), or with ``theta`` its noncanonical one
    (∮ ϑ·dq, ∫∫ dϑ with Ω from :func:`two_form`; P one entry per coordinate)."""
    import invariants
    f = invariants.first_invariant if kind == "I1" else invariants.second_invariant
    if theta is not None:
        form = _one_form(theta) if kind == "I1" else (lambda Q: two_form(theta, Q))
        return f(z, form, period=P)
    x, v = z[..., :k], z[..., k:]
    return f(x, "canonical", p=v, period=P)


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
    at every output.

    step : ``step(x, v, h) -> (x, v)`` on (n, k) arrays, each row on its own (or a dict {name: step}:
        several maps audited on the same sets, in one report)
    point : (x0, v0), 1-D arrays of length k
    h, steps, output_every : step size, steps of the drift run, outputs every (default steps/50)
    loop_points, radius, plane, directions : the loop z0 + radius(cos 2πτ d₁ + sin 2πτ d₂); the
        directions d₁, d₂ given (two vectors of length 2k), or the coordinates ``plane`` = (i, j) of
        (x_0 … x_{k−1}, v_0 … v_{k−1}), or by default all x against all v (see :func:`_plane`)
    surface : (n_σ, n_τ) for a square of half-side ``radius`` in the same plane at Chebyshev points
        (I₂), or None
    period : the positions' periods (a number, or one per x coordinate; None or 0: not periodic)
    defect_points, levels, probes, method, seed : the defect at ``defect_points`` points of the loop
        for h·2⁻ˡ, l < ``levels``, by :func:`map_defect`
    Returns the JSON-able report of :func:`integrators.audit.audit` (``text_report``,
    ``plot_report`` read it), with the loop's description under ``"sets"``.
    """
    maps = step if isinstance(step, dict) else {name: step}
    for nm, s in maps.items():
        _as_map(s, nm)
    z0 = _start(point, theta)
    h = float(h)
    if not math.isfinite(h) or h == 0.0:
        raise ValueError(f"h must be finite and non-zero, got {h}")
    steps = int(steps)
    every = max(1, steps // 50) if output_every is None else int(output_every)
    if steps < 1 or every < 1:
        raise ValueError("steps and output_every must be positive")
    n = z0.size
    k = n // 2
    from invariants.forms import _periods
    P = _periods(period, n if theta is not None else k)
    if theta is not None:
        if not callable(theta):
            raise TypeError(f"theta must be callable as theta(q) -> (n, d), got {type(theta).__name__}")
        if surface is not None and n > 2 * DENSE_UP_TO:
            raise ValueError(f"a surface of a noncanonical map takes Ω = Dϑᵀ − Dϑ, {n} × {n} a point: up to "
                             f"d = {2 * DENSE_UP_TO}; audit the loop (surface=None)")
    D = _plane(n, plane, directions, canonical=theta is None)
    loop = _loop(z0, D, float(radius), int(loop_points))
    sets = {"I1": loop}
    if surface is not None:
        sets["I2"] = _surface(z0, D, float(radius), *surface).reshape(-1, n)
    shapes = {"I1": loop.shape, "I2": None if surface is None else (int(surface[0]), int(surface[1]), n)}
    form = "canonical" if theta is None else "noncanonical"
    hs = [h * 2.0 ** -l for l in range(int(levels))]
    sel = np.linspace(0, loop.shape[0], int(defect_points), endpoint=False).astype(int)
    report = {"scene": name if not isinstance(step, dict) else "maps", "h": h, "steps": steps, "T": h * steps,
              "system": f"canonical map, k = {k} ({2 * k}-dimensional phase space)" if theta is None else
              f"noncanonical map with a one-form of code, d = {n}",
              "thresholds": {"roundoff": ROUNDOFF, "resolved": RESOLVED, "defect_floor": DEFECT_FLOOR},
              "defect_points": loop[sel].tolist() if n <= 64 else f"{len(sel)} points of the loop",
              "sets": _sets_description(loop_points, radius, plane, directions, surface, P, theta is None),
              "discrimination": None,       # the canonical form is not constant along a general map
              "candidates": []}
    for nm, s in maps.items():
        entry = {"name": nm, "role": "candidate", "kind": f"{form} map", "breakdown_step": None, "drift": {},
                 "t": [], "errors": {}, "defect": {}, "jacobian": None}
        advance = _advance(s, k, h) if theta is None else _rows(s, h)
        _drift(entry, advance, sets, shapes, lambda part, key: _invariants(part, k, P, key, theta), form,
               steps, h, every, progress, _energy(energy, k, theta))
        entry["defect"], entry["jacobian"] = _defect_study(s, loop[sel], hs, probes, method, seed,
                                                           None if progress is None else
                                                           (lambda hk, nm=nm: progress(f"{nm}: one-step defect at h = {hk:g}")),
                                                           theta)
        report["candidates"].append(entry)
    return report


def _sets_description(loop_points, radius, plane, directions, surface, P, canonical):
    """The report's "sets": the loop, the surface and the periods, as the user gave them."""
    where = (list(plane) if plane is not None else "given directions" if directions is not None else
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


def _defect_study(step, z, hs, probes, method, seed, progress, theta=None):
    """({form: {h, defect, order, verdict}}, the Jacobian method) of a map at points z over the step
    sizes hs (the canonical form, or dϑ with ``theta``), judged against the method's floor as
    :func:`integrators.audit.defect_study`."""
    vals, used, kinds = [], [], set()
    for hk in hs:
        if progress:
            progress(hk)
        try:
            v, u, kind = map_defect(step, z, hk, probes, method, seed, theta=theta)
        except Exception as exc:         # the user's map raised: a verdict, not a traceback
            v, u, kind = math.nan, f"none ({type(exc).__name__}: {exc})", "—"
        vals.append(v)
        used.append(u)
        kinds.add(kind)
    floors = np.array([DEFECT_FLOOR.get(u, np.inf) for u in used])
    arr = np.array(vals, dtype=float)
    verdict = ("step failed" if not np.all(np.isfinite(arr)) else
               "symplectic" if np.all(arr <= floors) else "not symplectic")
    order = fit_order(hs, arr, floors.max()) if np.all(np.isfinite(floors)) else None
    return ({"canonical" if theta is None else "noncanonical":
             {"h": hs, "defect": arr.tolist(), "order": order, "verdict": verdict}},
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


def _drift(entry, advance, sets, shapes, invariant, form, steps, h, every, progress, energy=None):
    """The sets advanced ``steps`` steps by ``advance(z) -> z`` (rows), ``invariant(part, key)`` at
    every output (and ``energy(z)``): the entry's drift, errors, energy error and breakdown step."""
    from invariants.growth import growth_law
    from ..service.statuses import relative_error
    z = np.concatenate([sets[key] for key in sets], axis=0)
    cut = np.cumsum([sets[key].shape[0] for key in sets])[:-1]
    t, values, res = [0.0], {key: [] for key in sets}, {key: 0.0 for key in sets}

    def record(z):
        for key, part in zip(sets, np.split(z, cut)):
            v = invariant(part.reshape(shapes[key]), key)
            values[key].append(v.value)
            res[key] = max(res[key], v.resolution)

    record(z)
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
            "value_at_start": values[key][0]}
        entry["errors"][f"{key}/{form}"] = err.tolist()
    entry["t"], entry["breakdown_step"] = t.tolist(), broke
