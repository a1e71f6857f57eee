"""Can a scene tell symplectic maps from others?  A check before an audit or a comparison run.

Some systems preserve the forms under maps that are not symplectic in general: with ϑ linear in q,
Ω̄ is constant; on the paper's Lotka–Volterra model even the standard projection is exactly
symplectic (λ₁ ≡ 0 and ϑ₂ linear kill its error terms; SPEC Part 4).  An audit there reports
"symplectic" for every candidate, which is no finding.  :func:`discrimination` measures it: the
one-step noncanonical defect (:func:`integrators.audit.defects`) of maps known not to be
symplectic in general, the standard projection of GLRK1 and GLRK2, at the scene's step size and on
sample points of its sets.  Where even they stay at the defect floor, the scene cannot discriminate,
and the function says so in one line (and why, where the structure shows it).
"""
from __future__ import annotations

import numpy as np

from .defect import DEFECT_FLOOR, defects

PROBES = (("GLRK1", "standard"), ("GLRK2", "standard"))   # not symplectic in general (sec:projection_methods)
METHOD = "central differences"      # the real engine only: no complex specialisation to compile for a run


def discrimination(system, points, h, npoints=4):
    """None when the scene's system, sets and step size tell the probes' defects from round-off;
    otherwise a one-line reason.  ``points`` (n, d) the scene's sample points."""
    from .. import tableau
    from .candidates import stepper_map
    points = np.asarray(points, dtype=float).reshape(-1, system.d)
    sel = np.linspace(0, points.shape[0], min(npoints, points.shape[0]), endpoint=False).astype(int)
    q = points[sel]
    floor = DEFECT_FLOOR[METHOD]
    worst = 0.0
    for tab, proj in PROBES:
        with np.errstate(all="ignore"):
            d, _ = defects(stepper_map(tableau(tab), proj), system, q, h, METHOD, reads=set())
        v = d["noncanonical"]
        if not np.isfinite(v):
            return None                     # a probe failed here: no claim either way
        worst = max(worst, v)
    if worst > floor:
        return None
    why = ""
    TT = system.ddtheta(q)
    if np.all(TT == 0.0):
        why = " (ϑ is linear in q, so Ω̄ is constant)"
    names = " and ".join(f"{t}-{p}" for t, p in PROBES)
    return (f"this scene cannot tell symplectic projections from others{why}: {names}, not symplectic in "
            f"general, keep Ω̄ to a relative one-step defect of {worst:.0e} here (floor {floor:g}) at h = {h:g}; "
            "a 'symplectic' or 'round-off' verdict of a projected method on it is no finding (point vortices and "
            "the tokamak field show the defects); maps of other kinds are still told apart")
