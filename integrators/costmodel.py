"""The engine's Newton cost as coded: floating-point operations of an iteration and of a Jacobian,
read off the generated point function and the kernel's loops, and the iterations, Jacobians and
Newton work a step on the stage predictor's protocol.

The counts are the engine's arithmetic, not the machine's speed: tests assert them
(tests/test_predictor.py) and the benchmarks divide measured time by them
(scripts/studies/engine_lanes.py, scripts/studies/benchmarks_predictor.py).  They are a lower bound:
selects, loads and bookkeeping are not counted.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .codegen import load_module
from .engine import Engine
from .projections import PRE_UNKNOWN
from .systems import system
from .tableaus import tableau


def _ops(lines) -> int:
    """The arithmetic operators on the right-hand sides of ``lines`` (unary signs and ``**`` left out)."""
    return sum(len(re.findall(r"(?<![*(eE])[-+*/](?![*])", ln.split("=", 1)[1])) for ln in lines if "=" in ln)


def _evaluate_real(system) -> str:
    """The source of the generated ``_evaluate_real`` of ``system``."""
    text = Path(load_module(system).__file__).read_text()
    return text.split("def _evaluate_real")[1].split("def _evaluate_complex")[0]


def flops_per_iteration(system, tableau, eng) -> int:
    """Floating-point operations of one Newton iteration as coded (residual and solve; the Jacobian
    and its factorisation, refreshed now and then, are left out)."""
    light = [ln for ln in _evaluate_real(system).splitlines() if ln.startswith("    _x") or ln.startswith("    st(")]
    ev = _ops([ln.replace("st(", "x = (") for ln in light])
    s, d, nz = tableau.s, system.d, eng.nz
    stages = s * (d * (4 * s) + ev + d * (2 * d) + 2 * d) + d * 8 * s          # Q, ϑ…, G, Σ b
    rows = s * d * (4 * s + 3)                                                  # the stage residuals
    coupled = eng.plan.pre == PRE_UNKNOWN
    proj = (ev + 2 * d * d + 6 * d) if coupled else 0
    solve = 2 * nz * nz + 4 * nz                                                # substitutions, update, norm
    return stages + rows + proj + solve


def jacobian_flops(system, tableau, eng) -> int:
    """The extra floating-point operations of a Jacobian as coded, over a residual evaluation: the
    point function's second derivatives at each stage (and at the coupled projection's point), the
    contractions K_i, the assembly of the nz × nz matrix and its LU (2nz³/3)."""
    body = _evaluate_real(system)
    need = body.split("if _need:")[1] if "if _need:" in body else ""
    extra_ev = _ops([ln.replace("st(", "x = (") for ln in need.splitlines()
                     if ln.startswith("        _x") or ln.startswith("        st(")])
    s, d, nz = tableau.s, system.d, eng.nz
    coupled = eng.plan.pre == PRE_UNKNOWN
    evals = s + (1 if coupled else 0)
    stage = s * (2 * d ** 3 + 2 * d * d) + s * s * d * d * (3 + 2 * s)
    proj = d * d * (s * (3 + 2 * s) + 4 * s + 10) if coupled else 0
    return evals * extra_ev + stage + proj + 2 * nz ** 3 // 3 + nz * nz


def protocol_points(loop):
    """The stage predictor's protocol points (docs/benchmarks.md): the points of ``loop`` (the guiding
    centre's default loop, ``invariants.loop("guiding_centre", n)``), each moved by 10⁻³ × a normal
    deviate (numpy's generator of seed 1)."""
    rng = np.random.default_rng(1)
    return loop + 1e-3 * rng.standard_normal(loop.shape)


def newton_per_step(tab, proj, q0, tolerances=None, steps=50, lanes=None):
    """guiding_centre_symmetric, h = 10, ``steps`` steps of ``q0`` from the start: the mean Newton
    iterations and Jacobians per point-step (the Jacobians per point with lanes=1) and the Newton
    work, iterations + Jacobians × the pair's Jacobian in iterations (:func:`jacobian_flops` over
    :func:`flops_per_iteration`)."""
    sy = system("guiding_centre_symmetric")
    eng = Engine(sy, tableau(tab), proj, 10.0, tolerances=tolerances)
    st = eng.state(q0)
    use = eng.advance(st, 1, steps, lanes=lanes)
    if not st.live.all():
        raise RuntimeError(f"{tab}-{proj}: a protocol point broke down")
    its, jacs = st.iterations.sum() / st.steps.sum(), use.jacobians / st.steps.sum()
    cost = jacobian_flops(sy, eng.tableau, eng) / flops_per_iteration(sy, eng.tableau, eng)
    return its, jacs, its + cost * jacs
