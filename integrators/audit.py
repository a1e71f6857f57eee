"""Symplecticity audit of a one-step map (SPEC Part 4): which forms does it preserve?

A *candidate* is a batched one-step map

    step(q, p, lam, h, system) -> (q_new, p_new, lam_new)

on arrays of shape (n, d) (n points, d = system.d), with ``h`` a float and ``system`` an
:class:`integrators.System`.  It must be a pure function of its arguments (no state kept
between calls: the audit calls it on perturbed copies of the same points), advance every
row independently, and return new arrays.  ``lam`` is the Lagrange multiplier λ of the
projections (Λ = hλ); a map without one returns it unchanged or as zeros.  A map may mark a
failed point by returning non-finite values in its row.  If the map also accepts complex
arrays (written with plain arithmetic, no ``float()``/``abs`` on inputs), the audit
differentiates it by complex step; otherwise by 8th-order central differences.

Built-in (tableau, projection) pairs and tableau files are wrapped into such maps by
:func:`stepper_map`.

Two measurements (docs/audit.md has the thresholds and the table for the built-ins):

* **Invariant drift.**  The candidate advances the loop and surface of a scene; I₁ and I₂ in
  the scene's forms give e(t) = |I(t) − I(0)|/|I(0)|.  Reported: max e, the drift rate (slope
  of a least-squares line through e(t)) and a verdict:

  - ``broke down``: a sample point failed before the end;
  - ``round-off``: max e ≤ ``ROUNDOFF``;
  - ``under-resolved``: the set's resolution monitor (invariants.forms) exceeded ``RESOLVED`` at
    some output, so e may be sampling error: refine the loop or surface;
  - ``drifting``: the mean of e over the last quarter of the run exceeds ``DRIFT_RATIO`` × the
    largest e of the first quarter (a linear drift gives 3.5, a bounded oscillation
    resolved by the run ≤ 1, a √t random walk about 1.9);
  - ``bounded``: otherwise.

* **One-step symplecticity defect.**  At sample points x = (q, ϑ(q), λ) the Jacobian DΦ of
  x ↦ Φ(x) gives, per form, the pull-back defect (relative to the size of the terms summed,
  so that round-off reads ~1e-16 whatever the scale):

  - noncanonical: DΦ_qᵀ Ω̄(q') DΦ_q − Ω̄(q), DΦ_q = dq'/dq along the constraint p = ϑ(q);
  - canonical: Bᵀ J B − J on (q, p), B = ∂(q', p')/∂(q, p), J the matrix of dp∧dq (only for maps
    that read p_n: a projected map starts from p_n = ϑ(q_n), on which the canonical and the
    noncanonical form agree);
  - corrected: Cᵀ Ω_λ(q', λ') C − Ω_λ(q, λ) on (q, λ), C = ∂(q', λ')/∂(q, λ), Ω_λ of
    eq:symplectic_projection_two_form (our sign, docs/conventions.md) (only for maps that
    read λ_n: the symplectic projection).

  for h, h/2, h/4, …; the order p of defect ∝ h^p is fitted over the values above the floor.
"""
from __future__ import annotations

import dataclasses
import math
import sys
import warnings
from pathlib import Path
from typing import Callable

import numpy as np

from .kernel import COMPLEX_STEP as CS_STEP

ROUNDOFF = 1e-11        # max relative invariant error still called round-off
DRIFT_RATIO = 2.0       # last-quarter mean / first-quarter max above which an error drifts
DEFECT_FLOOR = {"complex step": 1e-13, "central differences": 1e-10}   # relative defect = "symplectic"
FD_ORDER8 = ((1, 4 / 5), (2, -1 / 5), (3, 4 / 105), (4, -1 / 280))
from invariants.forms import UNDER_RESOLVED as RESOLVED   # the one resolution threshold (invariants.forms)
READ_THRESHOLD = 1e-8   # a map whose outputs move less than this per unit of an input ignores it
FD_STEP = 2.0 ** -10    # relative step of the central differences (truncation ~δ⁸, noise ~ulp/δ)


@dataclasses.dataclass
class Candidate:
    """A step map to audit.  ``reads`` says which inputs besides q it uses (None: detect)."""

    name: str
    step: Callable
    kind: str                       # 'pair' (built-in tableau/file + projection) or 'function'
    tableau: object = None
    projection: str | None = None
    reads: set | None = None        # inputs besides q the map uses; None: detect from the Jacobian


def stepper_map(tableau, projection) -> Callable:
    """The step map of a (tableau, projection) pair as a pure batched function.

    One call is one step of the compiled engine from the vector-field guess (no history): the
    Newton solution does not depend on the guess beyond its tolerance.  Accepts complex arrays:
    the engine's complex128 specialisation carries the derivatives (complex step) through the
    Newton solve.  A point whose step fails is NaN.
    """
    from .engine import Engine
    cache = {}

    def step(q, p, lam, h, system):
        key = (id(system), float(h))
        if key not in cache:
            cache[key] = Engine(system, tableau, projection, h)
        engine = cache[key]
        q, p, lam = (np.asarray(x) for x in (q, p, lam))
        dtype = np.complex128 if any(np.iscomplexobj(x) for x in (q, p, lam)) else np.float64
        st = engine.state(q, p, lam, dtype=dtype)
        engine.advance(st, 1, 1)
        q1, p1, lam1 = st.q, st.p, st.Lam / h
        bad = ~st.live
        for x in (q1, p1, lam1):
            x[bad] = np.nan
        return q1, p1, lam1

    return step


def load_function(spec: str) -> Callable:
    """``module:function`` or ``path/to/file.py:function`` -> the callable (ValueError if not found)."""
    from .plugins import load_callable
    return load_callable(spec, "step map")


def candidates_from(spec: str, projections=None) -> list[Candidate]:
    """Candidates named by a CLI argument: a built-in tableau, a tableau TOML file, or module:function.

    A tableau is audited with every projection in ``projections`` that it admits (default: all
    five; the symmetric, symplectic and midpoint projections need |R(∞)| = 1).
    """
    from .projections import PROJECTIONS, admission
    from .tableaus import TABLEAU_NAMES, tableau, tableau_from_file
    if spec in TABLEAU_NAMES:
        tab = tableau(spec)
    elif spec.endswith(".toml"):
        tab = tableau_from_file(spec)
    elif ":" in spec:
        fn = load_function(spec)
        if projections:
            raise ValueError("--projection applies to tableaus only, not to a step function")
        return [Candidate(spec.rsplit(":", 1)[1], fn, "function")]
    else:
        raise ValueError(f"candidate '{spec}' is not a built-in tableau ({', '.join(TABLEAU_NAMES)}), "
                         "a .toml tableau file, or module:function")
    wanted = list(projections) if projections else list(PROJECTIONS)
    for p in wanted:
        if p not in PROJECTIONS:
            raise ValueError(f"unknown projection '{p}'; choose from {', '.join(PROJECTIONS)}")
    ok = [p for p in wanted if admission(tab, p) is None]
    if not ok:
        raise ValueError(f"{tab.name} has R(∞) = {tab.R_inf:g}: none of {', '.join(wanted)} applies")
    return [pair_candidate(tab, p) for p in ok]


def pair_candidate(tab, projection) -> Candidate:
    """A built-in or file tableau with a projection.  Only 'none' reads p_n (the projected maps
    start from p_n = ϑ(q_n)) and only 'symplectic' reads λ_n (the others take it as a guess)."""
    reads = {"none": {"p"}, "symplectic": {"lam"}}.get(projection, set())
    return Candidate(f"{tab.name}-{projection}", stepper_map(tab, projection), "pair", tab, projection, reads)


# -- Jacobians -------------------------------------------------------------------------------

def _call(step, q, p, lam, h, system):
    out = step(q, p, lam, h, system)
    if not (isinstance(out, tuple) and len(out) == 3):
        raise ValueError("the step map must return a tuple (q, p, lam)")
    return tuple(np.asarray(x) for x in out)


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


# -- invariant drift -----------------------------------------------------------------------

def drift_verdict(t, err, broke, resolution=0.0):
    """(max error, drift rate, verdict) of one error series e(t); see the module doc.

    resolution : the largest resolution monitor of the sample set over the run; above
    RESOLVED the error may be sampling error rather than the integrator's.
    """
    t, err = np.asarray(t, float), np.asarray(err, float)
    if broke:
        return float(np.nanmax(err, initial=0.0)) if np.isfinite(err).any() else math.nan, math.nan, "broke down"
    emax = float(np.max(err))
    rate = float(np.polyfit(t - t[0], err, 1)[0]) if t.size > 1 else math.nan
    if emax <= ROUNDOFF:
        return emax, rate, "round-off"
    if resolution > RESOLVED:
        return emax, rate, "under-resolved"
    k = max(1, (t.size - 1) // 4)
    first = np.max(err[: k + 1])
    last = np.mean(err[-k:])
    return emax, rate, ("drifting" if last > DRIFT_RATIO * first else "bounded")


def run_drift(cand: Candidate, scene, progress=None):
    """Advance the scene's samples with the candidate; returns t, {'I1/form': e(t)}, breakdown step."""
    from .driver import Diagnostics
    system = scene.system()
    pts = [a.reshape(-1, system.d) for a in (scene.loop_points(), scene.surface_points()) if a is not None]
    q0 = np.concatenate(pts)
    h = scene.h
    diag = Diagnostics(scene, system, q0)
    q, p, lam = q0.copy(), system.theta(q0), np.zeros_like(q0)
    live = np.ones(q0.shape[0], dtype=bool)
    rows, first_break = [diag.row(0.0, q, p, lam, live)], None
    if cand.kind == "pair":           # the compiled engine's time loop, as a batch run takes it
        from .engine import Engine, march
        engine = Engine(system, cand.tableau, cand.projection, h)
        state = engine.state(q0, p, lam)

        def on_output(k):
            rows.append(diag.row(k * h, state.q, state.p, state.Lam / h, state.live))

        march(engine, state, 0, scene.steps, scene.output_every, on_output, progress)
        broke = np.isfinite(state.breakdown_time)
        if broke.any():
            first_break = int(round(float(np.min(state.breakdown_time[broke])) / h))
    else:                             # a user's step map, called on the live points
        for k in range(1, scene.steps + 1):
            if live.any():
                with np.errstate(all="ignore"):
                    try:
                        q1, p1, l1 = _call(cand.step, q[live], p[live], lam[live], h, system)
                    except Exception as exc:     # the user's map raised: every point stops here
                        print(f"audit: {cand.name} raised {type(exc).__name__}: {exc} at step {k}", file=sys.stderr)
                        q1 = np.full_like(q[live], np.nan)
                        p1, l1 = q1, q1
                good = np.all(np.isfinite(q1) & np.isfinite(p1) & np.isfinite(l1), axis=1)
                good &= system.in_domain(np.where(np.isfinite(q1), q1, 0.0))
                idx = np.flatnonzero(live)
                q[idx[good]], p[idx[good]], lam[idx[good]] = q1[good], p1[good], l1[good]
                live[idx[~good]] = False
            if first_break is None and not live.all():
                first_break = k
            if k % scene.output_every == 0:
                rows.append(diag.row(k * h, q, p, lam, live))
            if progress:
                progress(k)
    t = np.array([r["t"] for r in rows])
    resolution = {key[len("resolution/"):]: float(np.nanmax([r[key] for r in rows]))
                  for key in rows[0] if key.startswith("resolution/")}
    series = {}
    for key in rows[0]:
        if key.startswith("I1/") or key.startswith("I2/"):
            v = np.array([r[key] for r in rows])
            with np.errstate(all="ignore"):
                series[key] = np.abs(v - v[0]) / abs(v[0])
    return t, series, first_break, resolution


# -- the audit -------------------------------------------------------------------------------

def audit(candidates, scene, *, references=(), defect_points=4, levels=5, method="auto", progress=None,
          drift=True, defect=True):
    """Run both measurements (or the one asked for) for every candidate and reference.

    Returns the JSON-able report (see :func:`text_report` for its reading).
    """
    system = scene.system()
    pts = scene.loop_points() if scene.loop is not None else scene.surface_points().reshape(-1, system.d)
    sel = np.linspace(0, pts.shape[0], defect_points, endpoint=False).astype(int)
    qd = pts[sel]
    report = {"scene": scene.name, "system": scene.system_name, "h": scene.h, "steps": scene.steps,
              "T": scene.h * scene.steps, "thresholds": {"roundoff": ROUNDOFF, "drift_ratio": DRIFT_RATIO, "resolved": RESOLVED,
                                                         "defect_floor": DEFECT_FLOOR},
              "defect_points": qd.tolist(), "candidates": []}
    for cand, role in [(c, "candidate") for c in candidates] + [(c, "reference") for c in references]:
        entry = {"name": cand.name, "role": role, "kind": cand.kind, "breakdown_step": None, "drift": {},
                 "t": [], "errors": {}, "defect": {}, "jacobian": None}
        if drift:
            if progress:
                progress(f"{cand.name}: invariant drift over {scene.steps} steps")
            t, series, broke, resolution = run_drift(cand, scene)
            for key, err in series.items():
                res = resolution.get(key.split("/")[0], 0.0)
                emax, rate, verdict = drift_verdict(t, err, broke is not None, res)
                entry["drift"][key] = {"max_error": emax, "drift_rate": rate, "verdict": verdict, "resolution": res}
            entry.update(breakdown_step=broke, t=t.tolist(), errors={k: v.tolist() for k, v in series.items()})
        if defect:
            if progress:
                progress(f"{cand.name}: one-step defects at {len(qd)} points, {levels} step sizes")
            try:
                entry["defect"], entry["jacobian"] = defect_study(cand.step, system, qd, scene.h, levels, method,
                                                                  cand.reads)
            except Exception as exc:      # the user's map raised: a verdict, not a traceback
                why = f"step failed ({cand.name} raised {type(exc).__name__}: {exc})"
                entry["defect"] = {form: {"h": [scene.h * 2.0 ** -k for k in range(levels)], "defect": None,
                                          "order": None, "verdict": why}
                                   for form in ("canonical", "noncanonical", "corrected")}
                entry["jacobian"] = "none (the map raised)"
        report["candidates"].append(entry)
    return report


def _fmt(x, spec=".1e"):
    if x is None:
        return "—"
    if isinstance(x, float) and not math.isfinite(x):
        return "nan"
    return format(x, spec)


def text_report(report) -> str:
    """The human-readable report."""
    lines = [f"Symplecticity audit on scene '{report['scene']}' ({report['system']}, h = {report['h']:g}, "
             f"{report['steps']} steps, T = {report['T']:g})",
             f"thresholds: round-off ≤ {ROUNDOFF:g}; drifting when last-quarter mean > {DRIFT_RATIO:g} × "
             f"first-quarter max; defect floor {DEFECT_FLOOR['complex step']:g} (complex step), "
             f"{DEFECT_FLOOR['central differences']:g} (central differences)", "",
             "Invariant drift: max |I(t) − I(0)|/|I(0)|, drift rate [1/time], resolution monitor, verdict"]
    for c in report["candidates"]:
        head = f"  {c['name']} ({c['role']})" + (f" — a point broke down at step {c['breakdown_step']}"
                                                  if c["breakdown_step"] else "")
        lines.append(head)
        for key, r in c["drift"].items():
            lines.append(f"    {key:18s} {_fmt(r['max_error']):>9s} {_fmt(r['drift_rate'], '+.1e'):>9s} "
                         f"{_fmt(r['resolution']):>9s}  {r['verdict']}")
    lines += ["", "One-step symplecticity defect (relative) for h, h/2, …, fitted order in h, verdict"]
    for c in report["candidates"]:
        lines.append(f"  {c['name']} ({c['role']}, Jacobian by {c['jacobian']})")
        for form, r in c["defect"].items():
            vals = " ".join(f"{_fmt(v):>8s}" for v in r["defect"]) if r["defect"] else ""
            order = f"order {r['order']:.2f}" if r["order"] is not None else ""
            lines.append(f"    {form:13s} {vals:45s} {order:11s} {r['verdict']}")
    return "\n".join(lines)


def plot_report(report, directory) -> list[Path]:
    """Two PNGs: invariant errors against time, defects against h."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    cands = report["candidates"]
    colour = {c["name"]: f"C{k % 10}" for k, c in enumerate(cands)}     # one colour per candidate throughout
    style = {c["name"]: "-" if c["role"] == "candidate" else "--" for c in cands}
    forms = ("canonical", "noncanonical", "corrected")
    invs = sorted({k.split("/")[0] for c in cands for k in c["errors"]})
    fig, axes = plt.subplots(max(len(invs), 1), 3, figsize=(12, 3.2 * max(len(invs), 1)), squeeze=False)
    for row, inv in zip(axes, invs):
        for ax, form in zip(row, forms):
            key = f"{inv}/{form}"
            for c in cands:
                if key in c["errors"]:
                    e = np.maximum(np.array(c["errors"][key], float), 1e-17)
                    ax.semilogy(c["t"], e, style[c["name"]], color=colour[c["name"]], label=c["name"])
            ax.axhline(ROUNDOFF, color="grey", lw=0.5)
            ax.set_title(key, fontsize=9)
            ax.set_xlabel("t")
        row[0].set_ylabel("|I(t) − I(0)| / |I(0)|")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8)
    fig.suptitle(f"invariant errors, scene {report['scene']} (grey: round-off threshold)", fontsize=10)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    p1 = directory / "audit_invariants.png"
    fig.savefig(p1, dpi=80)
    plt.close(fig)
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), squeeze=False)
    for ax, form in zip(axes[0], forms):
        for c in cands:
            r = c["defect"].get(form)
            if r and r["defect"]:
                ax.loglog(np.abs(r["h"]), np.maximum(r["defect"], 1e-18), "o" + style[c["name"]],
                          color=colour[c["name"]], label=c["name"], ms=3)
        ax.axhline(DEFECT_FLOOR["complex step"], color="grey", lw=0.5)
        ax.set_title(f"{form} defect", fontsize=9)
        ax.set_xlabel("h")
    axes[0][0].set_ylabel("relative defect")
    handles = [plt.Line2D([], [], color=colour[c["name"]], ls=style[c["name"]], marker="o", ms=3) for c in cands]
    fig.legend(handles, [c["name"] for c in cands], loc="lower center", ncol=min(len(cands), 4), fontsize=8)
    fig.suptitle("one-step symplecticity defect (grey: complex-step floor; absent: the map does not read "
                 "the form's inputs)", fontsize=9)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    p2 = directory / "audit_defects.png"
    fig.savefig(p2, dpi=80)
    plt.close(fig)
    return [p1, p2]
