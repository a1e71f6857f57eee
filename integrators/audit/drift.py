"""Invariant drift of a candidate over a scene's run, and its verdict (see :mod:`integrators.audit`)."""
from __future__ import annotations

import math
import sys

import numpy as np

from invariants.forms import UNDER_RESOLVED as RESOLVED   # the one resolution threshold (invariants.forms)
from .candidates import Candidate, _call

from invariants.growth import ROUNDOFF, growth_law   # the one classifier of how errors grow

VERDICTS = {"round-off": "round-off", "bounded": "bounded", "random walk": "random walk", "linear": "drifting",
            "faster": "growing", "undetermined": "undetermined"}   # the growth law's name in the audit


def drift_verdict(t, err, broke, resolution=0.0, law=None):
    """(max error, drift rate, verdict) of one error series e(t); see the module doc.

    The verdict is the series' growth law (invariants.growth) in the audit's words: ``round-off``,
    ``bounded``, ``random walk``, ``drifting`` (linear), ``growing`` (faster than linear) or
    ``undetermined`` (too few outputs), unless a point broke down or the set was under-resolved.
    resolution : the largest resolution monitor of the sample set over the run; above RESOLVED
    the error may be sampling error rather than the integrator's.  ``law``: the series'
    GrowthLaw when already computed.
    """
    t, err = np.asarray(t, float), np.asarray(err, float)
    if broke:
        return float(np.nanmax(err, initial=0.0)) if np.isfinite(err).any() else math.nan, math.nan, "broke down"
    emax = float(np.max(err))
    span = t[-1] - t[0] if t.size > 1 else 0.0
    # the fit in units of the run's length: t of tiny steps would underflow in polyfit's scaling
    rate = float(np.polyfit((t - t[0]) / span, err, 1)[0] / span) if span > 0 else math.nan
    if resolution > RESOLVED and emax > ROUNDOFF:
        return emax, rate, "under-resolved"
    law = growth_law(t, err) if law is None else law
    return emax, rate, VERDICTS[law.law]


def run_drift(cand: Candidate, scene, progress=None):
    """Advance the scene's samples with the candidate; returns t, {'I1/form': e(t)}, breakdown step."""
    from ..service.diagnostics import Diagnostics
    from ..service.statuses import relative_error
    system = scene.system()
    q0 = scene.points(system)
    h = scene.h
    diag = Diagnostics(scene, system, q0)
    q, p, lam = q0.copy(), system.theta(q0), np.zeros_like(q0)
    live = np.ones(q0.shape[0], dtype=bool)
    rows, first_break = [diag.row(0.0, q, p, lam, live)], None
    if cand.kind == "pair":           # the compiled engine's time loop, as a batch run takes it
        from ..engine import Engine, Hooks, march
        engine = Engine(system, cand.tableau, cand.projection, h)
        state = engine.state(q0, p, lam)

        def on_output(k):
            rows.append(diag.row(k * h, state.q, state.p, state.Lam / h, state.live))

        march(engine, state, 0, scene.steps, scene.output_every, Hooks(on_output, progress))
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
            series[key] = relative_error([r[key] for r in rows])
    return t, series, first_break, resolution
