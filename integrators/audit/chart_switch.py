"""A step map that switches charts at the magnetic axis, as SIMPLE does, beside the axis chart's.

SIMPLE (#398) integrates guiding centres in flux coordinates (r, θ, ζ), r ∝ √s, with the field's
radial profiles splined in r on r ≥ 0; a step that ends at r < 0 is mapped to (|r|, θ + π), and the
maintainers trace a random walk of the energy of W7-X alphas to that switch.  This module builds the
same kind of map in a boozmn file's field, so the audit can be shown to tell it from this project's
axis chart (:mod:`integrators.boozer`, where nothing is singular at the axis):

* :func:`polar_system` — White's guiding centre (K = 0) in the polar chart q = (r, θ, ζ, ρ), r =
  √(2ψ) signed: ϑ = (0, r²/2 + ρ r² Ĩ, ρG − ψ_p, 0), H = ρ²B²/2 + μB, with each kept mode's
  b_mn as a quintic spline in r through r ≥ 0 (continued past r = 0 by its first cell's polynomial,
  as a spline in r continues) and the profiles as the axis chart's.  dϑ = r dr∧dθ + … is degenerate
  at r = 0: the chart is singular on the axis.
* :func:`switch_step` — one step of an engine pair in that chart, then (r, θ) → (−r, θ + π) where
  r < 0: the chart switch.
* :func:`axis_step` — one step of the same pair in the axis chart.
* :func:`closest_start` — the start whose orbit passes the axis closest, for the audit.

What the switch does, measured on the circular tokamak file (docs/stellarators.md, "The chart
switch"): guiding centres whose orbits pass the axis closely keep their energy to round-off in the
axis chart and lose it, or break down, in the switching polar chart.
"""
from __future__ import annotations

import math

import numpy as np
import sympy

from ..boozer import profile_fields, read_boozmn, system_from_boozer
from ..splines import Field1, Spline1

RADIAL_NODES = 221          # nodes of the modes' splines in r over [0, 1.1 r₁]


def boozmn_path(spec):
    """``"circular"`` or ``"li383"``: the shipped boozmn files (integrators/service/scenes/); any other
    string is a path."""
    from pathlib import Path
    scenes = Path(__file__).parents[1] / "service" / "scenes"
    shipped = {"circular": scenes / "boozmn_circular_tokamak.nc", "li383": scenes / "boozmn_li383_low_res.nc"}
    return shipped.get(spec, Path(spec))


def polar_system(path, mu=None, modes_tol=1e-4):
    """(the guiding centre of a boozmn file in the polar chart (module docstring), the same in the
    axis chart): parameters, profiles and defaults as :func:`~integrators.boozer.system_from_boozer`'s."""
    from ..systems import System
    bz = read_boozmn(path)
    axis = system_from_boozer(path, mu=mu, modes_tol=modes_tol)
    keep, p, cs, ss = bz.modes(modes_tol)
    r1 = math.sqrt(2 * bz.psi_abs)
    rg = np.linspace(0.0, 1.1 * r1, RADIAL_NODES)
    s = (rg / r1) ** 2
    b = s[:, None] ** (p / 2.0) * cs(s)
    modes = [Spline1(rg, b[:, j]) for j in range(keep.size)]
    r, th, ze, rho = sympy.symbols("r theta zeta rho", real=True)
    mu_s, psi0 = sympy.symbols("mu psi_edge")
    psi = r ** 2 / 2
    G, It, psip = (Field1(psi, i, 0) for i in range(3))
    sigma = int(bz.sign)
    B = sum(Field1(r, 3 + j, 0) * sympy.cos(int(bz.xm[keep[j]]) * sigma * th - int(bz.xn[keep[j]]) * ze)
            for j in range(keep.size))
    theta = [sympy.Integer(0), psi + rho * r ** 2 * It, rho * G - psip, sympy.Integer(0)]
    H = rho ** 2 * B ** 2 / 2 + mu_s * B
    system = System(f"polar:{bz.path}", [r, th, ze, rho], theta, H,
                    {mu_s: axis.param_values["mu"], psi0: bz.psi_abs}, domain=[1 - psi / psi0], defaults={},
                    fields=profile_fields(bz) + modes, source=str(path))
    system.defaults.update(axis.defaults)
    return system, axis


def to_polar(q):
    """Axis-chart points (x, y, ζ, ρ) in the polar chart (r ≥ 0, θ = atan2(y, x))."""
    q = np.asarray(q, float)
    return np.stack([np.hypot(q[:, 0], q[:, 1]), np.arctan2(q[:, 1], q[:, 0]), q[:, 2], q[:, 3]], 1)


def _one_step(system, tableau, projection):
    """``step(q, h) -> q``: one step of the pair from q (an engine per h, made on first use); points
    that break down come back as NaN."""
    from ..engine import Engine
    from ..tableaus import tableau as get_tableau
    engines = {}

    def step(q, h):
        key = float(h)
        if key not in engines:
            engines[key] = Engine(system, get_tableau(tableau), projection, key)
        eng = engines[key]
        st = eng.state(np.asarray(q, float))
        eng.advance(st, 1, 1)
        out = np.array(st.q, dtype=float)
        out[~np.asarray(st.live, bool)] = np.nan
        return out
    return step


def switch_step(system, tableau="GLRK2", projection="symmetric"):
    """``step(q, h) -> q``: one step of the pair in the polar chart, then the chart switch
    (r, θ) → (−r, θ + π) where r < 0 (``step.switches`` counts them).  Points that break down come
    back as NaN."""
    one = _one_step(system, tableau, projection)

    def step(q, h):
        out = one(q, h)
        neg = out[:, 0] < 0
        out[neg, 0] = -out[neg, 0]
        out[neg, 1] = out[neg, 1] + np.pi
        step.switches += int(neg.sum())
        return out
    step.switches = 0
    return step


def axis_step(system, tableau="GLRK2", projection="symmetric"):
    """``step(q, h) -> q``: one step of the pair in the axis chart (no switch, nothing singular)."""
    return _one_step(system, tableau, projection)


def axis_family(axis_system, n=64, spread=1.5, radius=0.02):
    """Trapped guiding centres started on an arc of ``radius`` r₁ about the axis (angles 0 … ``spread``)
    with the defaults' trapped ρ: their orbits pass the axis at distances down to 1e-5 r₁."""
    r1 = math.sqrt(2 * axis_system.param_values["psi_edge"])
    ang = np.linspace(0.0, spread, n)
    rho = axis_system.defaults["trapped"][3]
    return np.stack([radius * r1 * np.cos(ang), radius * r1 * np.sin(ang), 0 * ang, rho + 0 * ang], 1)


def closest_start(axis_system, steps=2000, tableau="GLRK2", projection="symmetric"):
    """The point of :func:`axis_family` whose orbit, ``steps`` steps of the pair at the defaults' h in
    the axis chart, passes the magnetic axis closest: the start of the audit that tells the two
    charts apart (``poincare audit --map``: scripts/examples/chart_switch_maps.py)."""
    q = axis_family(axis_system)
    start = q.copy()
    step, h = axis_step(axis_system, tableau, projection), axis_system.defaults["h"]
    closest = np.hypot(q[:, 0], q[:, 1])
    for _ in range(steps):
        q = step(q, h)
        closest = np.fmin(closest, np.hypot(q[:, 0], q[:, 1]))
    return start[int(np.nanargmin(closest))]
