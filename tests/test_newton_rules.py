"""Newton's opt-in rule for speed (issue 97): the plain first iteration (Tolerances.plain_first).

What is asserted is what the rule promises: the first iteration's residual in plain arithmetic
moves no point a solve ends at by more than round-off, and it gives the scalar path's bits in every
lane width, as every rule does.  Its round-off walk is a study (scripts/studies/brouwer_rules_quick.py, docs/brouwer.md),
its speed a benchmark (scripts/tools/speed_parts.py, docs/benchmarks.md).
"""
import copy

import numpy as np
import pytest

import integrators
from integrators import kernel

FIELDS = ("q", "p", "Lam", "q_comp", "p_comp", "Y", "mu", "iterations", "live", "breakdown_time", "steps")
PAIRS = (("GLRK2", "symmetric"), ("GLRK1", "none"), ("GLRK3", "symplectic"), ("GLRK2", "standard"),
         ("SRK3", "midpoint"), ("GLRK4", "symmetric"))
FAST = dict(settle=False, plain_first=True)


def _points(sy, n, rng):
    return np.array(sy.defaults["q0"]) * (1 + 0.02 * rng.standard_normal((n, sy.d)))


def _run(eng, q0, steps, lanes=None, state=None):
    st = eng.state(q0) if state is None else state
    eng.advance(st, 1 if state is None else int(st.steps.max()) + 1, steps, lanes=lanes)
    return st


@pytest.mark.parametrize("tab, proj", PAIRS)
def test_the_plain_first_iteration_ends_at_the_same_floor(tab, proj, rng):
    """Point vortices, 64 points, 20 steps under Tolerances(settle=False) (the predictor's history
    full), then one step from copies of that state with and without plain_first: q, p at most 4 ulps
    of max(|q|, 1) apart (both end at the floor of the same equations), and a run with it moved
    from the run without (else this tests nothing)."""
    sy = integrators.system("point_vortices")
    q0 = _points(sy, 64, rng)
    h = sy.defaults["h"]
    rule = dict(settle=False)
    base = integrators.Engine(sy, integrators.tableau(tab), proj, h, tolerances=integrators.Tolerances(**rule))
    plain = integrators.Engine(sy, integrators.tableau(tab), proj, h,
                               tolerances=integrators.Tolerances(**rule, plain_first=True))
    st = _run(base, q0, 20, lanes=1)
    a, b = copy.deepcopy(st), copy.deepcopy(st)
    _run(base, q0, 1, lanes=1, state=a)
    _run(plain, q0, 1, lanes=1, state=b)
    assert a.live.all() and b.live.all()
    assert np.abs(a.q - b.q).max() <= 4 * np.spacing(np.maximum(np.abs(a.q), 1.0)).max()
    assert np.abs(a.p - b.p).max() <= 4 * np.spacing(np.maximum(np.abs(a.p), 1.0)).max()
    moved = _run(plain, q0, 20, lanes=1)
    assert any(not np.array_equal(getattr(moved, f), getattr(st, f)) for f in ("q", "p", "Y", "iterations"))


def test_the_fast_rules_give_the_scalar_paths_bits(rng):
    """19 points of the point vortices, 30 steps, settle=False and plain_first together:
    W = 8 and W = 16 against W = 1, every field bitwise equal, on four pairs."""
    sy = integrators.system("point_vortices")
    q0 = _points(sy, 19, rng)
    for tab, proj in PAIRS[:4]:
        eng = integrators.Engine(sy, integrators.tableau(tab), proj, sy.defaults["h"],
                                 tolerances=integrators.Tolerances(**FAST))
        alone = _run(eng, q0, 30, lanes=1)
        for W in (kernel.LANES, kernel.WIDE):
            other = _run(eng, q0, 30, lanes=W)
            assert [f for f in FIELDS if not np.array_equal(getattr(alone, f), getattr(other, f))] == [], (tab, proj, W)


def test_the_rule_is_runtime_data():
    """plain_first is one number of the kernel's Newton record (no compilation of its own), 0 by default."""
    at = kernel.Newton._fields.index("plain")
    assert integrators.Tolerances().array()[at] == 0.0
    assert integrators.Tolerances(plain_first=True).array()[at] == 1.0
    assert integrators.Tolerances(plain_first=True).array(double_double=True)[at] == 1.0
