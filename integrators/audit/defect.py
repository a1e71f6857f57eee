"""The one-step symplecticity defect: Jacobians of a step map (complex step or 8th-order central
differences) and the pull-back of each form (see :mod:`integrators.audit`)."""
from __future__ import annotations

import math
import warnings

import numpy as np

from ..kernel import COMPLEX_STEP as CS_STEP
from .candidates import _call

DEFECT_FLOOR = {"complex step": 1e-13, "central differences": 1e-10}   # relative defect = "symplectic"
FD_ORDER8 = ((1, 4 / 5), (2, -1 / 5), (3, 4 / 105), (4, -1 / 280))
READ_THRESHOLD = 1e-8   # a map whose outputs move less than this per unit of an input ignores it
FD_STEP = 2.0 ** -10    # relative step of the central differences (truncation ~δ⁸, noise ~ulp/δ)


def jacobian(step, q, p, lam, h, system, method="auto"):
    """DΦ of x = (q, p, λ) ↦ Φ(x) at m points: (m, 3d, 3d), the method used, and Φ(x).

    'complex step' (exact to round-off, used when the map keeps complex arithmetic through: its
    real part must reproduce the real evaluation to 1e-13), else 8th-order central differences
    with relative step 2⁻¹⁰ (on the point vortices it agrees with complex step to 1e-12; the
    steps 2⁻⁷ and 2⁻⁵ were truncation-limited at 1e-9 and 1e-4).
    """
    m, d = q.shape
    x0 = np.concatenate([q, p, lam], axis=1)
    base = _call(step, q, p, lam, h, system)
    f0 = np.concatenate(base, axis=1)
    n = 3 * d
    if method in ("auto", "complex step"):
        X = np.repeat(x0[:, None, :].astype(complex), n, axis=1)          # (m, n, n)
        X[:, np.arange(n), np.arange(n)] += 1j * CS_STEP
        X = X.reshape(m * n, n)
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", np.exceptions.ComplexWarning)   # a real-only map: fall back
                out = _call(step, X[:, :d], X[:, d:2 * d], X[:, 2 * d:], h, system)
            F = np.concatenate(out, axis=1).reshape(m, n, n)
            scale = np.maximum(np.abs(f0), 1.0)[:, None, :]
            usable = np.iscomplexobj(F) and np.all(np.abs(F.real - f0[:, None, :]) <= 1e-13 * scale)
        except Exception:
            usable = False
        if usable:
            return np.swapaxes(F.imag / CS_STEP, 1, 2), "complex step", base
        if method == "complex step":
            raise ValueError("the step map does not support complex arguments")
    delta = FD_STEP * np.maximum(np.abs(x0), 1.0)                          # (m, n)
    D = np.zeros((m, n, n))
    for k, w in FD_ORDER8:
        for sgn in (1.0, -1.0):
            X = np.repeat(x0[:, None, :], n, axis=1)
            X[:, np.arange(n), np.arange(n)] += sgn * k * delta
            X = X.reshape(m * n, n)
            with np.errstate(all="ignore"):
                out = _call(step, X[:, :d], X[:, d:2 * d], X[:, 2 * d:], h, system)
            F = np.concatenate(out, axis=1).reshape(m, n, n)
            D += sgn * w * np.swapaxes(F, 1, 2) / delta[:, None, :]
    return D, "central differences", base


def _relative(M_out, M_in, A):
    """max |Aᵀ M_out A − M_in| / max(|A|ᵀ|M_out||A| + |M_in|) per point: (m,)."""
    At = np.swapaxes(A, -1, -2)
    pull = At @ M_out @ A
    size = np.abs(At) @ np.abs(M_out) @ np.abs(A) + np.abs(M_in)
    return np.max(np.abs(pull - M_in), axis=(-2, -1)) / np.max(size, axis=(-2, -1))


def defects(step, system, q, h, method="auto", reads=None):
    """Relative one-step defects {form: value or None} at points q (m, d), and the Jacobian method.

    A form is None when the map does not read the inputs the form lives on (see module doc).
    λ_n is the λ the map itself returns after one step from (q, ϑ(q), 0).  ``reads``: the set of
    inputs besides q the map uses ({'p'}, {'lam'}, ...); None detects it from the Jacobian (an
    input whose derivatives are below READ_THRESHOLD of the largest is only a solver guess).
    """
    from invariants import corrected_omega
    m, d = q.shape
    p = system.theta(q)
    _, _, lam = _call(step, q, p, np.zeros_like(q), h, system)
    lam = np.where(np.isfinite(lam), lam, 0.0)
    D, used, (q1, p1, lam1) = jacobian(step, q, p, lam, h, system, method)
    if not (np.all(np.isfinite(D)) and np.all(np.isfinite(q1))):
        return {"noncanonical": math.nan, "canonical": math.nan, "corrected": math.nan}, used
    iq, ip, il = slice(0, d), slice(d, 2 * d), slice(2 * d, 3 * d)
    out = {}
    # noncanonical: along p = ϑ(q): dq'/dq = D_qq + D_qp ϑ_q
    T = system.dtheta(q)
    Aq = D[:, iq, iq] + D[:, iq, ip] @ T
    out["noncanonical"] = float(np.max(_relative(system.Omega(q1), system.Omega(q), Aq)))
    if reads is None:       # a user map: it reads an input if the outputs depend on it beyond round-off
        size = max(float(np.max(np.abs(D))), 1.0)
        reads = set()
        if np.max(np.abs(D[:, :, ip])) > READ_THRESHOLD * size:
            reads.add("p")
        if np.max(np.abs(D[:, :, il])) > READ_THRESHOLD * size:
            reads.add("lam")
    reads_p, reads_l = "p" in reads, "lam" in reads
    if reads_p:
        Jc = np.block([[np.zeros((d, d)), -np.eye(d)], [np.eye(d), np.zeros((d, d))]])
        B = D[:, :2 * d, :2 * d]
        out["canonical"] = float(np.max(_relative(Jc, Jc, B)))
    else:
        out["canonical"] = None
    if reads_l:
        idx = np.r_[0:d, 2 * d:3 * d]
        C = D[:, idx][:, :, idx]
        C = C.copy()
        C[:, :, :d] += D[:, idx][:, :, ip] @ T                 # still along p = ϑ(q)
        out["corrected"] = float(np.max(_relative(corrected_omega(system, q1, lam1, h),
                                                  corrected_omega(system, q, lam, h), C)))
    else:
        out["corrected"] = None
    return out, used


def fit_order(hs, values, floor):
    """Slope of log(value) against log(h) over the values above 10 × floor (None if < 3 such)."""
    hs, v = np.asarray(hs, float), np.asarray(values, float)
    keep = np.isfinite(v) & (v > 10 * floor)
    if keep.sum() < 3:
        return None
    return float(np.polyfit(np.log(np.abs(hs[keep])), np.log(v[keep]), 1)[0])


def fit_order_small_h(hs, values, floor, levels=3):
    """Slope of log(value) against log(h) over the ``levels`` smallest h whose values are above 10 ×
    floor (None if < 3 such): the asymptotic order of a quantity that is not monotone at large h (a
    one-step error |I(h) − I(0)| changes sign where h is far from the asymptotic range)."""
    hs, v = np.asarray(hs, float), np.asarray(values, float)
    keep = np.flatnonzero(np.isfinite(v) & (v > 10 * floor))
    keep = keep[np.argsort(np.abs(hs[keep]))][:levels]
    if len(keep) < 3:
        return None
    return float(np.polyfit(np.log(np.abs(hs[keep])), np.log(v[keep]), 1)[0])


def defect_study(step, system, q, h, levels=5, method="auto", reads=None):
    """Defects for h·2^-k, k < levels: {form: {'h', 'defect', 'order', 'verdict'}}, and the method(s).

    The Jacobian method is chosen per h (complex step where the map's complex evaluation is
    usable, else central differences); each defect is judged against its method's floor.
    """
    hs = [h * 2.0 ** -k for k in range(levels)]
    rows, used = [], []
    for hk in hs:
        r, u = defects(step, system, q, hk, method, reads)
        rows.append(r)
        used.append(u)
    floors = np.array([DEFECT_FLOOR[u] for u in used])
    out = {}
    for form in ("canonical", "noncanonical", "corrected"):
        vals = [r[form] for r in rows]
        if any(v is None for v in vals):
            out[form] = {"h": hs, "defect": None, "order": None, "verdict": "n/a (map does not read "
                         + ("p_n" if form == "canonical" else "λ_n") + ")"}
            continue
        vals = np.array([float(v) for v in vals])
        if not np.all(np.isfinite(vals)):
            verdict = "step failed"
        elif np.all(vals <= floors):
            verdict = "symplectic"
        else:
            verdict = "not symplectic"
        out[form] = {"h": hs, "defect": vals.tolist(), "order": fit_order(hs, vals, floors.max()),
                     "verdict": verdict}
    if len(set(used)) == 1:
        summary = used[0]
    else:
        odd = [f"{hk:g}" for hk, u in zip(hs, used) if u != used[0]]
        summary = f"{used[0]} (central differences at h = {', '.join(odd)})" if used[0] == "complex step" \
            else f"{used[0]} (complex step at h = {', '.join(odd)})"
    return out, summary
