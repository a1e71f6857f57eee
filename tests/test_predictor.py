"""The stage predictor (issue 55): the last step's stages extrapolated, corrected by the extrapolated
defects of the last steps, each step at the order that did best on the step before, and a Jacobian
at the guess where the last guess was good (integrators/kernel.py, _guess and _remember).

The iteration counts are the engine's arithmetic, not the machine's speed: they hold anywhere."""
import sys
from pathlib import Path

import numpy as np
import pytest

import integrators
import invariants
from integrators import kernel

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts" / "studies"))
from benchmarks_predictor import jacobian_flops  # noqa: E402  (the flop counts as coded)
from engine_lanes import flops_per_iteration  # noqa: E402

OLD = integrators.Tolerances(predictor="extrapolate")      # the engine's rule before the defects
FIELDS = ("q", "p", "Lam", "iterations", "steps", "breakdown_time", "live", "defects", "orders", "have_lu")


def protocol_points(n=32):
    """Points near the default loop of the guiding centre (docs/benchmarks.md's protocol)."""
    rng = np.random.default_rng(1)
    q0 = invariants.loop("guiding_centre", n)
    return q0 + 1e-3 * rng.standard_normal(q0.shape)


def iterations_per_step(tab, proj, q0, tolerances=None, steps=50, lanes=None):
    return newton_per_step(tab, proj, q0, tolerances, steps, lanes)[0]


def newton_per_step(tab, proj, q0, tolerances=None, steps=50, lanes=None):
    """Mean Newton iterations and Jacobians per point-step (the Jacobians per point with lanes=1),
    and the Newton work: iterations + Jacobians × the pair's Jacobian in iterations, flops as
    coded (scripts/studies/benchmarks_predictor.py --flops)."""
    sy = integrators.system("guiding_centre_symmetric")
    eng = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0, tolerances=tolerances)
    st = eng.state(q0)
    use = eng.advance(st, 1, steps, lanes=lanes)
    assert st.live.all()
    its, jacs = st.iterations.sum() / st.steps.sum(), use.jacobians / st.steps.sum()
    cost = jacobian_flops(sy, eng.tableau, eng) / flops_per_iteration(sy, eng.tableau, eng)
    return its, jacs, its + cost * jacs


FRESH = integrators.Tolerances(trust_max_unknowns=64)      # a Jacobian at every trusted guess


# (pair, points, iterations bound, Newton work bound against the old rule's): one point per lane,
# so that the Jacobians are the points'.  Measured 2026-11-27, with a Jacobian at each trusted
# guess up to 16 unknowns: GLRK2-symmetric 2.40 iterations, work 5.70 against 7.82 (0.73);
# GLRK2-standard 4.38, 8.99 against 11.31 (0.79); SRK3-symmetric 2.46, 6.72 against 8.45 (0.80);
# with the carried factors above 16: GLRK4-symmetric 3.51, 3.81 against 6.57 (0.58);
# GLRK6-symmetric 3.81, 4.07 against 7.05 (0.58); one orbit of GLRK4 / GLRK6: 3.60 / 3.92, work
# 0.57 / 0.52.
WORK = [("GLRK2", "symmetric", 32, 3.5, 0.76), ("GLRK2", "standard", 32, 5.0, 0.83),
        ("SRK3", "symmetric", 32, 3.5, 0.83), ("GLRK4", "symmetric", 32, 4.0, 0.62),
        ("GLRK6", "symmetric", 32, 4.5, 0.62), ("GLRK4", "symmetric", 1, 4.0, 0.62),
        ("GLRK6", "symmetric", 1, 4.5, 0.6)]


@pytest.mark.parametrize("tab,proj,n,its_bound,work_bound", WORK)
def test_newton_work_per_step_on_the_benchmark_protocol(tab, proj, n, its_bound, work_bound):
    """guiding_centre_symmetric, h = 10, points near the default loop, 50 steps from the start (the
    first steps' shorter history included).  The default takes a Jacobian at each trusted guess
    in pairs of at most 16 unknowns (GLRK2, SRK3: the issue's iteration bounds) and keeps the
    carried factors above (GLRK4, GLRK6: a Jacobian there costs 5.4 and 7.6 iterations); the
    refresh floor spares the Jacobians the old rule took on round-off.  The Newton work drops to
    0.52-0.80 of the old rule's (before: 6.50, 8.48, 6.46, 5.60, 4.86 iterations; one orbit 5.59
    and 4.87)."""
    q0 = protocol_points(n) if n > 1 else protocol_points(3)[:1]
    its, jacs, work = newton_per_step(tab, proj, q0, lanes=1)
    old = newton_per_step(tab, proj, q0, OLD, lanes=1)
    assert its <= its_bound and its < old[0]
    assert work <= work_bound * old[2]


@pytest.mark.parametrize("tab,proj,n,bound", [("GLRK2", "symmetric", 32, 3.5), ("GLRK2", "standard", 32, 5.0),
                                              ("GLRK4", "symmetric", 32, 3.5), ("SRK3", "symmetric", 32, 3.5),
                                              ("GLRK4", "symmetric", 1, 3.5), ("GLRK6", "symmetric", 1, 3.5)])
def test_a_jacobian_at_each_trusted_guess_meets_the_issues_iteration_bounds(tab, proj, n, bound):
    """The guess itself: started from a Jacobian there (``trust_max_unknowns`` above the pair's
    unknowns), Newton takes at most the issue's 3.5 (5.0 for GLRK2-standard) iterations a step,
    under 0.65 of the old rule's: 2.41, 4.38, 2.26, 2.48; one orbit 2.28 and 2.70.  It costs a
    Jacobian a step, more than the iterations it saves (test above, docs/benchmarks.md)."""
    q0 = protocol_points(n) if n > 1 else protocol_points(3)[:1]
    new = iterations_per_step(tab, proj, q0, FRESH, lanes=None if n > 1 else 1)
    assert new <= bound
    assert new < 0.65 * iterations_per_step(tab, proj, q0, OLD)


def test_glrk1_unprojected_takes_fewer_iterations_than_before():
    """GLRK1-none: the unprojected midpoint rule's stages carry a parasitic two-step wiggle, which no
    smooth extrapolation follows; the predictor still saves iterations, 0.5 a step with a Jacobian
    at the guess (the issue's 4.0 is not reached: docs/benchmarks.md)."""
    q0 = protocol_points()
    old = iterations_per_step("GLRK1", "none", q0, OLD)
    assert iterations_per_step("GLRK1", "none", q0) < old
    assert iterations_per_step("GLRK1", "none", q0, FRESH) < old - 0.5


@pytest.mark.parametrize("fresh", [False, True], ids=["carried", "fresh"])
@pytest.mark.parametrize("tab,proj", [("GLRK2", "symmetric"), ("SRK3", "symplectic"), ("LobIIIA3", "standard"),
                                      ("GLRK1", "none"), ("GLRK3", "midpoint")])
def test_lanes_blocks_and_split_calls_give_the_same_bits(tab, proj, fresh):
    """19 points, 25 steps (the whole history in use): W = 8, W = 16, blocks of 5 and the run split
    into calls of 7, 1 and 17 steps give W = 1's bits in every field, the predictor's included,
    with the carried factors (the default) and with a Jacobian at each trusted guess."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = protocol_points(19)
    eng = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0, tolerances=FRESH if fresh else None)

    def run(lanes, block=64, calls=(25,)):
        st, first = eng.state(q0), 1
        for n in calls:
            eng.advance(st, first, n, lanes=lanes, block=block)
            first += n
        return st

    one = run(1)
    assert one.orders[:, 0].max() == kernel.DEPTH            # the table filled
    for other in (run(kernel.LANES), run(kernel.WIDE), run(kernel.LANES, block=5), run(1, calls=(7, 1, 17))):
        for f in FIELDS:
            assert np.array_equal(getattr(one, f), getattr(other, f)), f


def test_the_history_grows_a_step_at_a_time_and_orders_stay_within_it():
    """After k steps a point holds min(k − 1, depth) defects (the first step has no base), and the
    orders it uses never exceed what it holds."""
    sy = integrators.system("guiding_centre_symmetric")
    eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 10.0,
                             tolerances=integrators.Tolerances(depth=3))
    st = eng.state(protocol_points(8))
    for k in range(1, 7):
        eng.advance(st, k, 1)
        held = st.orders[:, 0].astype(int)
        assert (held == min(k - 1, 3)).all()
        assert (st.orders[:, 1] <= held).all() and (st.orders[:, 2] <= held).all()


def test_large_steps_fall_back_to_the_carried_factors():
    """At h = 100 (the guess off by more than ``trust``) the lanes keep the carried factors: the
    count stays within 10 % of the old rule's (a Jacobian at a poor guess took 13.5 a step)."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = protocol_points(16)
    its = []
    for tol in (None, OLD):
        eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 100.0, tolerances=tol)
        st = eng.state(q0)
        eng.advance(st, 1, 100)
        assert st.live.all()
        its.append(st.iterations.sum() / st.steps.sum())
    assert its[0] <= 1.1 * its[1]


def test_double_double_takes_the_same_predictor():
    """The double-double engine: fewer iterations with the defects than with extrapolation alone
    (0.86 of them with the carried factors, 0.8 with a Jacobian at the guess, where its quadratic
    convergence spans 32 digits), and W = 8 gives W = 1's bits."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = protocol_points(8)
    out = {}
    for name, tol in (("new", None), ("old", OLD), ("fresh", FRESH)):
        eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 10.0, tolerances=tol,
                                 precision="double-double")
        for W in (1, kernel.LANES):
            st = eng.state(q0)
            eng.advance(st, 1, 20, lanes=W)
            out[name, W] = st
    for f in ("q", "p", "Lam", "iterations", "defects", "orders"):
        assert np.array_equal(getattr(out["new", 1], f), getattr(out["new", kernel.LANES], f)), f
    old = out["old", 1].iterations.sum()
    assert out["new", 1].iterations.sum() < 0.9 * old and out["fresh", 1].iterations.sum() < 0.8 * old


def test_tolerances_check_the_predictor_settings():
    for bad in (dict(depth=0), dict(depth=kernel.DEPTH + 1), dict(depth=2.0), dict(trust=-1.0), dict(jacobian_age=0),
                dict(trust=float("nan")), dict(predictor="taylor"), dict(trust_max_unknowns=-1),
                dict(trust_max_unknowns=1.5), dict(refresh_floor=-1e-12), dict(refresh_horizon=-2),
                dict(refresh_horizon=65), dict(refresh_horizon=True)):
        with pytest.raises(ValueError):
            integrators.Tolerances(**bad)


def test_the_lanes_report_their_jacobians():
    """LaneUse.jacobians (GLRK2-symmetric, 64 points, 16 lanes, 50 steps): the default takes a
    Jacobian at each trusted guess, one a group step; with the carried factors
    (trust_max_unknowns=0) a lane's refresh still factorises its group, 0.96 a group step; and Tolerances(jacobian_age=2) then lets a
    lane whose factors are one step old keep them (in lockstep a group still factorises when any
    lane asks: on 10⁴ points near the loop 0.51 a group step, on these 64 it stays 1.00)."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = protocol_points(64)
    for tol, lo, hi in ((integrators.Tolerances(trust_max_unknowns=0), 0.5, 1.1), (None, 0.9, 1.1)):
        eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 10.0, tolerances=tol)
        st = eng.state(q0)
        use = eng.advance(st, 1, 50, lanes=kernel.WIDE)
        assert lo <= use.jacobians / use.rounds <= hi
    one = eng.state(q0[:1])
    use = eng.advance(one, 1, 50, lanes=1)
    assert 0.9 * 50 <= use.jacobians <= 1.1 * 50 and use.rounds == 50
    aged = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 10.0,
                              tolerances=integrators.Tolerances(jacobian_age=2))
    one = aged.state(q0[:1])
    use = aged.advance(one, 1, 50, lanes=1)
    assert use.jacobians <= 0.7 * 50 and one.iterations.sum() / 50 <= 3.5


def test_the_refresh_floor_spares_jacobians():
    """Without the floor (Tolerances(refresh_floor=0)) the carried factors are refreshed whenever an
    iteration contracts by less than 0.01, also where the update is round-off: GLRK6-symmetric, one
    orbit, 0.4 Jacobians a step; with it 0.04."""
    q0 = protocol_points(3)[:1]
    assert newton_per_step("GLRK6", "symmetric", q0, integrators.Tolerances(refresh_floor=0.0), lanes=1)[1] > 0.2
    assert newton_per_step("GLRK6", "symmetric", q0, lanes=1)[1] < 0.1
