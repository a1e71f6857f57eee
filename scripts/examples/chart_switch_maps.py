"""The chart-switch example for ``poincare audit --map`` (docs/stellarators.md, "The chart switch").

Two noncanonical step maps of White's guiding centre in a boozmn field, GLRK2-symmetric at the
file's default h, and what the command line needs beside each (``--theta``, ``--point``, ``--energy``):

* ``axis_step``: the axis chart (x, y, ζ, ρ), nothing singular at the magnetic axis;
* ``switch_step``: the polar chart (r, θ, ζ, ρ) with SIMPLE's switch (r, θ) → (−r, θ + π) after a
  step that ends at r < 0 (:mod:`integrators.audit.chart_switch`).

The start is the guiding centre of :func:`integrators.audit.chart_switch.axis_family` whose orbit
passes the axis closest in :func:`~integrators.audit.chart_switch.closest_start`'s run; the field is
the shipped circular tokamak's, or the boozmn file named by the environment variable ``BOOZMN``
(``li383`` for the shipped NCSX-like one). From the repository root::

    M=scripts/examples/chart_switch_maps.py
    poincare audit --map $M:axis_step --theta $M:axis_theta --point $M:axis_point --energy $M:axis_energy \
        --h 2.7 --steps 400 --output-every 4 --loop-points 256 --radius 0.00465 --plane 0 1 --points 2 --levels 2
    poincare audit --map $M:switch_step --theta $M:polar_theta --point $M:polar_point --energy $M:polar_energy \
        --period 0 6.283185307179586 0 0 --h 2.7 --steps 400 --output-every 4 --loop-points 256 \
        --radius 0.00465 --plane 0 1 --points 2 --levels 2

(h is the file's default, the radius 10⁻³ r₁: ``python scripts/examples/chart_switch_maps.py`` prints
both commands for the file chosen.)
"""
from __future__ import annotations

import functools
import os

import numpy as np

from integrators.audit.chart_switch import axis_step as _axis_step
from integrators.audit.chart_switch import boozmn_path, closest_start, polar_system, switch_step as _switch_step, \
    to_polar


@functools.lru_cache(maxsize=None)
def _systems():
    polar, axis = polar_system(boozmn_path(os.environ.get("BOOZMN", "circular")))
    return polar, axis, _axis_step(axis), _switch_step(polar), closest_start(axis)


def axis_step(q, h):
    return _systems()[2](q, h)


def switch_step(q, h):
    return _systems()[3](q, h)


def axis_theta(q):
    return _systems()[1].theta(q)


def polar_theta(q):
    return _systems()[0].theta(q)


def axis_energy(q):
    return _systems()[1].H(q)


def polar_energy(q):
    return _systems()[0].H(q)


def axis_point():
    return _systems()[4]


def polar_point():
    return to_polar(_systems()[4][None])[0]


if __name__ == "__main__":
    polar, axis, *_ = _systems()
    h = axis.defaults["h"]
    r = 1e-3 * np.sqrt(2 * axis.param_values["psi_edge"])
    tail = f"--h {h!r} --steps 400 --output-every 4 --loop-points 256 --radius {r:.3g} --plane 0 1 --points 2 --levels 2"
    if os.environ.get("BOOZMN"):
        tail = f"{tail}   # with BOOZMN={os.environ['BOOZMN']} set"
    m = "scripts/examples/chart_switch_maps.py"
    print(f"poincare audit --map {m}:axis_step --theta {m}:axis_theta --point {m}:axis_point "
          f"--energy {m}:axis_energy {tail}")
    print(f"poincare audit --map {m}:switch_step --theta {m}:polar_theta --point {m}:polar_point "
          f"--energy {m}:polar_energy --period 0 {2 * np.pi!r} 0 0 {tail}")
