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


def _plane(k, plane, directions):
    """Two directions (2, 2k) spanning the sets' plane: given, or coordinates ``plane`` = (i, j) of the
    phase space (x_0 … x_{k−1}, v_0 … v_{k−1}), or by default every x together against every v
    ((1, …, 1, 0, …)/√k and (0, …, 0, 1, …)/√k: ω of the pair is 1)."""
    n = 2 * k
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
    """DΦ(z)·U for points z (m, 2k) and directions U (m, r, 2k): (m, r, 2k) and the method used.

    Complex step (one call on m·r rows) when the map's complex evaluation reproduces the real one to
    1e-13, else 8th-order central differences with step 2⁻¹⁰·max(|z|, 1) along each unit direction
    (eight calls)."""
    m, r, n = U.shape
    k = n // 2
    Z = np.repeat(z[:, None, :], r, axis=1).reshape(m * r, n)
    Uf = U.reshape(m * r, n)
    base = None
    if method in ("auto", "complex step"):
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", np.exceptions.ComplexWarning)
                X = Z + 1j * CS_STEP * Uf
                x1, v1 = _call(step, X[:, :k], X[:, k:], h)
                x0, v0 = _call(step, z[:, :k], z[:, k:], h)
            F, base = np.concatenate([x1, v1], axis=1), np.concatenate([x0, v0], axis=1)
            ref = np.repeat(base[:, None, :], r, axis=1).reshape(m * r, n)
            usable = np.iscomplexobj(F) and np.all(np.abs(F.real - ref) <= 1e-13 * np.maximum(np.abs(ref), 1.0))
        except (TypeError, ValueError):
            usable = False
        if usable:
            return (F.imag / CS_STEP).reshape(m, r, n), "complex step"
        if method == "complex step":
            raise ValueError("the step map does not keep complex arithmetic through (complex step unusable)")
    norm = np.linalg.norm(Uf, axis=1, keepdims=True)
    norm = np.where(norm > 0, norm, 1.0)
    delta = FD_STEP * np.maximum(np.max(np.abs(Z), axis=1, keepdims=True), 1.0)   # along the unit direction
    D = np.zeros((m * r, n))
    for kk, w in FD_ORDER8:
        for sgn in (1.0, -1.0):
            X = Z + sgn * kk * delta * Uf / norm
            with np.errstate(all="ignore"):
                x1, v1 = _call(step, X[:, :k], X[:, k:], h)
            D += sgn * w * np.concatenate([x1, v1], axis=1)
    return (D / delta * norm).reshape(m, r, n), "central differences"


def map_defect(step, z, h, probes=PROBES, method="auto", seed=0, dense=None):
    """The relative one-step defect of the canonical form at points z (m, 2k): (value, method, kind).

    ``dense`` (default: 2k ≤ DENSE_UP_TO): max |BᵀJB − J| over the size of its terms, B the Jacobian
    from 2k JVPs; else the largest over ``probes`` random pairs (u, w) (normal, from numpy's generator
    of ``seed``) of |ω(Bu, Bw) − ω(u, w)| over the size of the terms of both.  NaN where the map
    failed (non-finite values)."""
    m, n = z.shape
    k = n // 2
    dense = n <= DENSE_UP_TO if dense is None else dense
    if dense:
        E = np.broadcast_to(np.eye(n), (m, n, n))
        DB, used = jvp(step, z, np.ascontiguousarray(E), h, method)          # rows: B e_j
        B = np.swapaxes(DB, 1, 2)
        Jc = np.block([[np.zeros((k, k)), -np.eye(k)], [np.eye(k), np.zeros((k, k))]])
        pull = np.swapaxes(B, 1, 2) @ Jc @ B
        size = np.abs(np.swapaxes(B, 1, 2)) @ np.abs(Jc) @ np.abs(B) + np.abs(Jc)
        val = np.max(np.abs(pull - Jc), axis=(1, 2)) / np.max(size, axis=(1, 2))
        return (float(np.max(val)) if np.all(np.isfinite(val)) else math.nan), used, "dense"
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((m, 2 * probes, n)) / math.sqrt(n)
    BU, used = jvp(step, z, U, h, method)
    u, w, a, b = U[:, 0::2], U[:, 1::2], BU[:, 0::2], BU[:, 1::2]
    o_out, s_out = _omega(a, b, k)
    o_in, s_in = _omega(u, w, k)
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


def _invariants(z, k, P, kind):
    import invariants
    x, v = z[..., :k], z[..., k:]
    f = invariants.first_invariant if kind == "I1" else invariants.second_invariant
    return f(x, "canonical", p=v, period=P)


def audit_map(step, point, h, *, steps=100, output_every=None, loop_points=1024, radius=0.1, plane=None,
              directions=None, surface=None, period=None, defect_points=4, levels=3, probes=PROBES,
              method="auto", seed=0, name="map", progress=None) -> dict:
    """The whole audit of a canonical step map around the phase-space point ``point`` = (x0, v0).

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
    x0, v0 = (np.asarray(a, dtype=float) for a in point)
    if x0.ndim != 1 or x0.shape != v0.shape or x0.size == 0:
        raise ValueError(f"point must be (x0, v0), two 1-D arrays of the same length k, got shapes {x0.shape}, "
                         f"{v0.shape}")
    if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(v0))):
        raise ValueError("point (x0, v0) must be finite")
    h = float(h)
    if not math.isfinite(h) or h == 0.0:
        raise ValueError(f"h must be finite and non-zero, got {h}")
    steps = int(steps)
    every = max(1, steps // 50) if output_every is None else int(output_every)
    if steps < 1 or every < 1:
        raise ValueError("steps and output_every must be positive")
    k = x0.size
    from invariants.forms import _periods
    P = _periods(period, k)
    z0 = np.concatenate([x0, v0])
    D = _plane(k, plane, directions)
    loop = _loop(z0, D, float(radius), int(loop_points))
    sets = {"I1": loop}
    if surface is not None:
        sets["I2"] = _surface(z0, D, float(radius), *surface).reshape(-1, 2 * k)
    shapes = {"I1": loop.shape, "I2": None if surface is None else (int(surface[0]), int(surface[1]), 2 * k)}
    hs = [h * 2.0 ** -l for l in range(int(levels))]
    sel = np.linspace(0, loop.shape[0], int(defect_points), endpoint=False).astype(int)
    report = {"scene": name if not isinstance(step, dict) else "maps", "h": h, "steps": steps, "T": h * steps,
              "system": f"canonical map, k = {k} ({2 * k}-dimensional phase space)",
              "thresholds": {"roundoff": ROUNDOFF, "resolved": RESOLVED, "defect_floor": DEFECT_FLOOR},
              "defect_points": loop[sel].tolist() if 2 * k <= 64 else f"{len(sel)} points of the loop",
              "sets": {"loop": {"points": int(loop_points), "radius": float(radius),
                                "plane": "all x against all v" if plane is None and directions is None
                                else (list(plane) if plane is not None else "given directions")},
                       "surface": None if surface is None else {"n_sigma": int(surface[0]), "n_tau": int(surface[1])},
                       "period": None if P is None else P.tolist()},
              "discrimination": None,       # the canonical form is not constant along a general map
              "candidates": []}
    for nm, s in maps.items():
        entry = {"name": nm, "role": "candidate", "kind": "canonical map", "breakdown_step": None, "drift": {},
                 "t": [], "errors": {}, "defect": {}, "jacobian": None}
        _drift(entry, s, sets, shapes, k, P, h, steps, every, progress)
        entry["defect"], entry["jacobian"] = _defect_study(s, loop[sel], hs, probes, method, seed,
                                                           None if progress is None else
                                                           (lambda hk, nm=nm: progress(f"{nm}: one-step defect at h = {hk:g}")))
        report["candidates"].append(entry)
    return report


def _defect_study(step, z, hs, probes, method, seed, progress):
    """({'canonical': {h, defect, order, verdict}}, the Jacobian method) of a map at points z over
    the step sizes hs, judged against the method's floor as :func:`integrators.audit.defect_study`."""
    vals, used, kinds = [], [], set()
    for hk in hs:
        if progress:
            progress(hk)
        try:
            v, u, kind = map_defect(step, z, hk, probes, method, seed)
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
    return ({"canonical": {"h": hs, "defect": arr.tolist(), "order": order, "verdict": verdict}},
            ", ".join(sorted(set(used))) + f" ({', '.join(sorted(kinds))})")


def _drift(entry, step, sets, shapes, k, P, h, steps, every, progress):
    from invariants.growth import growth_law
    from ..service.statuses import relative_error
    z = np.concatenate([sets[key] for key in sets], axis=0)
    cut = np.cumsum([sets[key].shape[0] for key in sets])[:-1]
    t, values, res = [0.0], {key: [] for key in sets}, {key: 0.0 for key in sets}

    def record(z):
        for key, part in zip(sets, np.split(z, cut)):
            v = _invariants(part.reshape(shapes[key]), k, P, key)
            values[key].append(v.value)
            res[key] = max(res[key], v.resolution)

    record(z)
    broke = None
    for n in range(1, steps + 1):
        with np.errstate(all="ignore"):
            try:
                x1, v1 = _call(step, z[:, :k], z[:, k:], h)
                z = np.concatenate([x1, v1], axis=1).astype(float)
            except Exception as exc:         # the map raised: every point stops here
                entry["error"] = f"{type(exc).__name__}: {exc}"
                z = np.full_like(z, np.nan)
        if not np.all(np.isfinite(z)):
            broke = n
            break
        if n % every == 0 or n == steps:
            t.append(n * h)
            record(z)
        if progress and n % every == 0:
            progress(f"step {n}/{steps}")
    t = np.array(t)
    for key in sets:
        err = relative_error(values[key])
        g = growth_law(t, err) if broke is None else None
        emax, rate, verdict = drift_verdict(t, err, broke is not None, res[key], law=g)
        entry["drift"][f"{key}/canonical"] = {
            "max_error": emax, "drift_rate": rate, "verdict": verdict, "resolution": res[key],
            "near_floor": bool(ROUNDOFF < emax <= 10 * ROUNDOFF) if math.isfinite(emax) else False,
            "growth_law": None if g is None else g.law, "growth_exponent": None if g is None else g.exponent,
            "growth_exponent_error": None if g is None else g.exponent_error, "growth_onset": None if g is None else g.onset,
            "value_at_start": values[key][0]}
        entry["errors"][f"{key}/canonical"] = err.tolist()
    entry["t"], entry["breakdown_step"] = t.tolist(), broke
