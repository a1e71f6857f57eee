"""Points in SIMD lanes give every point the bits of the scalar path (integrators/kernel/, integrators/simd/).

The kernel advances W = kernel.LANES (8) or kernel.WIDE (16) points in lockstep with every decision
per lane; these tests hold it to its promise: a point's bits are those it gets alone on the scalar
path (W = 1), for every admissible pair at both widths, for lanes that break down or need other
iteration counts beside it, and for blocks that end part-way through a group of lanes."""
import numpy as np
import pytest

import integrators
import invariants
from integrators import kernel
from integrators.projections import PROJECTIONS, admission

PAIRS = [(t, p) for t in integrators.TABLEAU_NAMES for p in PROJECTIONS
         if admission(integrators.tableau(t), p) is None]
FIELDS = ("q", "p", "Lam", "q_comp", "p_comp", "Y", "mu", "have_history", "live", "breakdown_time", "iterations",
          "steps")


def _run(eng, q0, steps, lanes, block=64):
    st = eng.state(q0)
    eng.advance(st, 1, steps, block=block, lanes=lanes)
    return st


def _same(a, b):
    return [f for f in FIELDS if not np.array_equal(getattr(a, f), getattr(b, f))]


@pytest.mark.parametrize("sysname", ["point_vortices", "lotka_volterra_2d", "guiding_centre_tokamak"])
def test_lanes_give_the_scalar_paths_bits_on_every_pair(sysname, rng):
    """19 points (W = 8: two groups and one of 3 with 5 empty lanes; W = 16: one group and one of 3
    with 13 empty lanes), 3 steps, W = 8 and W = 16 against W = 1: every field of the state bitwise
    equal, for all 114 admissible pairs."""
    sy = integrators.system(sysname)
    q0 = np.array(sy.defaults["q0"]) * (1 + 0.02 * rng.standard_normal((19, sy.d)))
    bad = {}
    for tab, proj in PAIRS:
        eng = integrators.Engine(sy, integrators.tableau(tab), proj, sy.defaults["h"])
        alone = _run(eng, q0, 3, 1)
        for W in (kernel.LANES, kernel.WIDE):
            diff = _same(alone, _run(eng, q0, 3, W))
            if diff:
                bad[(tab, proj, W)] = diff
    assert not bad, bad


def test_small_newton_systems_take_sixteen_lanes():
    """A pair's default width follows its Newton unknowns and the call's points (kernel.lane_width):
    16 lanes up to 28 unknowns (every pair at d = 4) from kernel.WIDE_POINTS points on, else 8;
    states of fewer than 8 points run alone, double-double ones in 8 lanes."""
    sy = integrators.system("guiding_centre_symmetric")          # d = 4
    q0 = invariants.loop("guiding_centre", kernel.WIDE_POINTS)
    for tab, proj, nz, W in (("GLRK1", "none", 4, 16), ("GLRK2", "symmetric", 12, 16),
                             ("SRK3", "symmetric", 16, 16), ("GLRK6", "symmetric", 28, 16)):
        eng = integrators.Engine(sy, integrators.tableau(tab), proj, 1.0)
        assert (eng.nz, eng.width) == (nz, W), (tab, proj)
        assert eng.advance(eng.state(q0), 1, 1).W == W
        assert eng.advance(eng.state(q0[:kernel.WIDE_POINTS - 1]), 1, 1).W == 8
        assert eng.advance(eng.state(q0[:7]), 1, 1).W == 1
    with pytest.raises(ValueError, match="lanes must be 1 or 8"):
        eng.advance(integrators.Engine(sy, integrators.tableau("GLRK1"), "none", 1.0,
                                       precision="double-double").state(q0), 1, 1, lanes=kernel.WIDE)


def test_mixed_lanes_each_point_gets_the_bits_it_has_alone(rng):
    """Lotka–Volterra at a step so large that some points leave the domain (break down) while their
    lane neighbours go on, and neighbours need different Newton iteration counts: each point's
    state after the run is bitwise the state it reaches alone (one point, the scalar path), also
    with blocks that split the groups of lanes differently."""
    sy = integrators.system("lotka_volterra_2d")
    q0 = np.abs(np.array(sy.defaults["q0"]) * (1 + 0.6 * rng.standard_normal((21, sy.d)))) + 0.05
    eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 0.9)
    together = _run(eng, q0, 12, kernel.LANES)
    assert 0 < together.live.sum() < len(q0)                   # breakdowns beside survivors
    assert len(np.unique(together.iterations[together.live])) > 1
    for W, block in ((kernel.LANES, 5), (kernel.LANES, 16), (kernel.WIDE, 64), (kernel.WIDE, 7)):
        assert not _same(together, _run(eng, q0, 12, W, block=block)), (W, block)
    for i in range(len(q0)):
        alone = _run(eng, q0[i:i + 1], 12, 1)
        for f in FIELDS:
            assert np.array_equal(getattr(together, f)[i], getattr(alone, f)[0]), (i, f)


def test_the_lane_kernel_agrees_with_the_scalar_kernel_across_calls_and_resumes(rng):
    """Steps grouped into different kernel calls (as at outputs and checkpoints) give the same bits
    on W = 8 and W = 16 as on W = 1, and as one call."""
    sy = integrators.system("guiding_centre_tokamak")
    q0 = np.array(sy.defaults["q0"]) * (1 + 0.02 * rng.standard_normal((13, sy.d)))
    eng = integrators.Engine(sy, integrators.tableau("SRK3"), "midpoint", sy.defaults["h"])
    states = []
    for W in (1, kernel.LANES, kernel.WIDE):
        st = eng.state(q0)
        eng.advance(st, 1, 2, lanes=W)
        eng.advance(st, 3, 3, lanes=W)
        states.append(st)
    one = eng.state(q0)
    eng.advance(one, 1, 5, lanes=kernel.LANES)
    assert not _same(states[0], states[1]) and not _same(states[0], states[2]) and not _same(states[0], one)


def _rounds_with_refill(busy, W, block):
    """The group steps of lanes that take up the next point as soon as theirs is done: the live
    points in order, in blocks of ``block``, point i holding its lane for busy[i] steps (0: dead,
    never taken up)."""
    total, live = 0, [b for b in busy if b > 0]
    for lo in range(0, len(live), block):
        queue = live[lo:lo + block]
        lanes, rounds = queue[:W], 0
        queue = queue[W:]
        while lanes:
            rounds += 1
            lanes = [b - 1 for b in lanes]
            for j, b in enumerate(lanes):
                if b == 0 and queue:
                    lanes[j] = queue.pop(0)
            lanes = [b for b in lanes if b > 0]
        total += rounds
    return total


def test_lanes_are_refilled_and_each_point_keeps_its_bits(rng):
    """A lane whose point breaks down or has taken its steps takes up the next live point of the
    block (integrators/kernel/blocks.py, _block): over two calls, with points dead from the start and
    points breaking down in between, every point's bits equal W = 1's, and the group steps the
    kernel reports are exactly those of in-order refilling, each point holding its lane for the
    group steps it takes alone (its steps, one more for each second try and for a breakdown) —
    fewer than groups of fixed lanes would take.  The Newton iterations it reports are the points'
    own at W = 1."""
    sy = integrators.system("lotka_volterra_2d")
    n, calls = 40, ((1, 6), (7, 6))
    q0 = np.abs(np.array(sy.defaults["q0"]) * (1 + 0.6 * rng.standard_normal((n, sy.d)))) + 0.05
    eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 0.9)
    busy = np.zeros((len(calls), n), dtype=int)              # each point's group steps when alone
    for i in range(n):
        st = eng.state(q0[i:i + 1])
        st.live[:] = i % 3 != 0
        for c, (first, steps) in enumerate(calls):
            busy[c, i] = eng.advance(st, first, steps, lanes=1).rounds
    states = {}
    for W, block in ((1, 64), (kernel.LANES, 64), (kernel.LANES, 16), (kernel.LANES, 5), (kernel.WIDE, 64),
                     (kernel.WIDE, 21)):
        st = eng.state(q0)
        st.live[::3] = False                                  # dead before the first call
        for c, (first, steps) in enumerate(calls):
            before_its = st.iterations.sum()
            use = eng.advance(st, first, steps, block=block, lanes=W)
            assert use.W == W
            assert use.rounds == _rounds_with_refill(list(busy[c]), W, block), (W, block, first)
            its = st.iterations.sum() - before_its                # one lane: the group's iterations are its own
            assert use.iterations == its if W == 1 else its <= W * use.iterations < W * its
            if block == 64 and W > 1 and c == 0:
                fixed = sum(max(busy[0, i:i + W]) for i in range(0, n, W))
                assert use.rounds < fixed                          # dead lanes were refilled
        states[W, block] = st
    alone = states[1, 64]
    assert 0 < alone.live.sum() < n - len(range(0, n, 3))     # breakdowns beside survivors
    assert (busy.sum(axis=0) > alone.steps + ~alone.live).any()   # and second tries
    for key, st in states.items():
        assert not _same(alone, st), key


def test_dead_points_are_skipped_and_live_ones_packed():
    """Eight live points among sixteen fill one group: 5 steps take 5 group steps, not 10."""
    sy = integrators.system("point_vortices")
    eng = integrators.Engine(sy, integrators.tableau("GLRK1"), "none", 0.1)
    q0 = np.array(sy.defaults["q0"]) * (1 + 1e-3 * np.arange(16))[:, None]
    st = eng.state(q0)
    st.live[1::2] = False
    use = eng.advance(st, 1, 5, lanes=kernel.LANES)
    assert use.rounds == 5 and st.steps.tolist() == [5, 0] * 8
    assert eng.advance(st, 6, 0, lanes=kernel.LANES).rounds == 0 and st.steps.sum() == 40


def test_lanes_must_be_one_or_a_kernel_width():
    sy = integrators.system("point_vortices")
    eng = integrators.Engine(sy, integrators.tableau("GLRK1"), "none", 0.1)
    with pytest.raises(ValueError, match="lanes must be 1, 8 or 16, got 3"):
        eng.advance(eng.state(np.array([sy.defaults["q0"]])), 1, 1, lanes=3)


@pytest.mark.parametrize("tab,proj", [("GLRK2", "symmetric"), ("SRK3", "symmetric"), ("LobIIIA3", "standard"),
                                      ("GLRK1", "none")])
def test_the_velocity_predictor_keeps_the_lanes_bits_and_saves_iterations(tab, proj, rng):
    """Tolerances(predictor="velocity") (the stage guess with h·q̇(q_n) as one more node): W = 8
    gives W = 1's bits, a stage at c = 1 (SRK3, Lobatto) is left out of the nodes, and on the
    guiding centre at h = 10 the Gauss pairs need fewer Newton iterations than with extrapolation
    alone, both with the carried factors (0.4–0.6 fewer a step, docs/benchmarks-history.md)."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = invariants.loop("guiding_centre", 11) + 1e-3 * rng.standard_normal((11, sy.d))
    tableau = integrators.tableau(tab)
    E = integrators.engine.predictor(tableau.c, "velocity")
    assert np.allclose(E.sum(axis=1), 1.0)                     # it reproduces constants
    c = np.asarray(tableau.c, dtype=float)
    assert np.allclose(E[:, :-1] @ (c - 1.0), c)                # and straight lines (node 0 adds 0)
    vel = integrators.Engine(sy, tableau, proj, 10.0, tolerances=integrators.Tolerances(predictor="velocity"))
    assert not _same(_run(vel, q0, 12, 1), _run(vel, q0, 12, kernel.LANES))
    if tab.startswith("GLRK"):
        ext = integrators.Engine(sy, tableau, proj, 10.0, tolerances=integrators.Tolerances(predictor="extrapolate"))
        a, b = _run(ext, q0, 12, kernel.LANES), _run(vel, q0, 12, kernel.LANES)
        assert b.live.all() and a.live.all()
        assert b.iterations.sum() < a.iterations.sum() - 0.2 * a.steps.sum()


def test_predictor_must_be_known():
    with pytest.raises(ValueError, match="predictor"):
        integrators.Tolerances(predictor="taylor")


@pytest.mark.parametrize("rule", [dict(), dict(dither=True)])
def test_the_rounding_newton_rules_give_the_scalar_paths_bits(rule, rng):
    """The settled approach (the default, Tolerances.settle) and the dithered one (opt-in,
    Tolerances.dither) round Newton iterates to a grid, lane by lane: 19 points of the point
    vortices, 30 steps (the predictor's history full, so the rounding acts on the guess's last
    approach), W = 8 and W = 16 against W = 1, every field bitwise equal; and the rule does change
    the run against Tolerances(settle=False), which rounds nothing (else this tests nothing)."""
    sy = integrators.system("point_vortices")
    q0 = np.array(sy.defaults["q0"]) * (1 + 0.02 * rng.standard_normal((19, sy.d)))
    moved = 0
    for tab, proj in (("GLRK3", "symmetric"), ("GLRK3", "symplectic"), ("SRK3", "midpoint"), ("GLRK2", "standard")):
        eng = integrators.Engine(sy, integrators.tableau(tab), proj, sy.defaults["h"],
                                 tolerances=integrators.Tolerances(**rule))
        alone = _run(eng, q0, 30, 1)
        for W in (kernel.LANES, kernel.WIDE):
            assert not _same(alone, _run(eng, q0, 30, W)), (tab, proj, W)
        plain = integrators.Engine(sy, integrators.tableau(tab), proj, sy.defaults["h"],
                                   tolerances=integrators.Tolerances(settle=False))
        moved += bool(_same(alone, _run(plain, q0, 30, 1)))
    assert moved == 4
