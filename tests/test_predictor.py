"""The stage predictor (issue 55): the last step's stages extrapolated, corrected by the extrapolated
defects of the last steps, each step at the order that did best on the step before, and a Jacobian
at the guess where the last guess was good (integrators/kernel.py, _guess and _remember).

The iteration counts are the engine's arithmetic, not the machine's speed: they hold anywhere."""
import numpy as np
import pytest

import integrators
import invariants
from integrators import kernel

OLD = integrators.Tolerances(predictor="extrapolate")      # the engine's rule before the defects
FIELDS = ("q", "p", "Lam", "iterations", "steps", "breakdown_time", "live", "defects", "orders", "have_lu")


def protocol_points(n=32):
    """Points near the default loop of the guiding centre (docs/benchmarks.md's protocol)."""
    rng = np.random.default_rng(1)
    q0 = invariants.loop("guiding_centre", n)
    return q0 + 1e-3 * rng.standard_normal(q0.shape)


def iterations_per_step(tab, proj, q0, tolerances=None, steps=50, lanes=None):
    sy = integrators.system("guiding_centre_symmetric")
    eng = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0, tolerances=tolerances)
    st = eng.state(q0)
    eng.advance(st, 1, steps, lanes=lanes)
    assert st.live.all()
    return st.iterations.sum() / st.steps.sum()


@pytest.mark.parametrize("tab,proj,bound", [("GLRK2", "symmetric", 3.5), ("GLRK2", "standard", 5.0),
                                            ("GLRK4", "symmetric", 3.5), ("SRK3", "symmetric", 3.5)])
def test_newton_iterations_per_step_on_the_benchmark_protocol(tab, proj, bound):
    """guiding_centre_symmetric, h = 10, 32 points near the default loop, 50 steps from the start
    (the first steps' shorter history included): mean residual evaluations per point-step within
    the issue's bounds (the engine before: 6.50, 8.48, 5.60, 6.46), and fewer than the old rule's."""
    q0 = protocol_points()
    new = iterations_per_step(tab, proj, q0)
    assert new <= bound
    assert new < 0.65 * iterations_per_step(tab, proj, q0, OLD)


@pytest.mark.parametrize("tab", ["GLRK4", "GLRK6"])
def test_one_orbit_takes_at_most_three_and_a_half_iterations_a_step(tab):
    """One trajectory (W = 1) of GLRK4- and GLRK6-symmetric, 50 steps: ≤ 3.5 (before: 5.59, 4.87)."""
    assert iterations_per_step(tab, "symmetric", protocol_points(3)[:1], lanes=1) <= 3.5


def test_glrk1_unprojected_takes_fewer_iterations_than_before():
    """GLRK1-none: the unprojected midpoint rule's stages carry a parasitic two-step wiggle, which no
    smooth extrapolation follows; the predictor still saves iterations (the issue's 4.0 is not
    reached: docs/benchmarks.md)."""
    q0 = protocol_points()
    assert iterations_per_step("GLRK1", "none", q0) < iterations_per_step("GLRK1", "none", q0, OLD) - 0.5


@pytest.mark.parametrize("tab,proj", [("GLRK2", "symmetric"), ("SRK3", "symplectic"), ("LobIIIA3", "standard"),
                                      ("GLRK1", "none"), ("GLRK3", "midpoint")])
def test_lanes_blocks_and_split_calls_give_the_same_bits(tab, proj):
    """19 points, 25 steps (the whole history in use): W = 8, W = 16, blocks of 5 and the run split
    into calls of 7, 1 and 17 steps give W = 1's bits in every field, the predictor's included."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = protocol_points(19)
    eng = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0)

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
    """The double-double engine: fewer iterations with the defects than with extrapolation alone,
    and W = 8 gives W = 1's bits."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = protocol_points(8)
    out = {}
    for name, tol in (("new", None), ("old", OLD)):
        eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 10.0, tolerances=tol,
                                 precision="double-double")
        for W in (1, kernel.LANES):
            st = eng.state(q0)
            eng.advance(st, 1, 20, lanes=W)
            out[name, W] = st
    for f in ("q", "p", "Lam", "iterations", "defects", "orders"):
        assert np.array_equal(getattr(out["new", 1], f), getattr(out["new", kernel.LANES], f)), f
    assert out["new", 1].iterations.sum() < 0.8 * out["old", 1].iterations.sum()


def test_tolerances_check_the_predictor_settings():
    for bad in (dict(depth=0), dict(depth=kernel.DEPTH + 1), dict(depth=2.0), dict(trust=-1.0), dict(jacobian_age=0),
                dict(trust=float("nan")), dict(predictor="taylor")):
        with pytest.raises(ValueError):
            integrators.Tolerances(**bad)


def test_the_lanes_report_their_jacobians():
    """LaneUse.jacobians: every trusted step takes one at its guess (GLRK2-symmetric, 16 lanes:
    1.00 a group step on these 64 points), and Tolerances(jacobian_age=2) lets a lane whose
    factors are one step old keep them (in lockstep a group still factorises when any lane asks:
    on 10⁴ points near the loop 0.51 a group step, on these 64 it stays 1.00)."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = protocol_points(64)
    eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 10.0)
    st = eng.state(q0)
    use = eng.advance(st, 1, 50, lanes=kernel.WIDE)
    assert 0.9 < use.jacobians / use.rounds <= 1.1
    one = eng.state(q0[:1])
    use = eng.advance(one, 1, 50, lanes=1)
    assert 0.9 * 50 <= use.jacobians <= 1.1 * 50 and use.rounds == 50
    aged = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", 10.0,
                              tolerances=integrators.Tolerances(jacobian_age=2))
    one = aged.state(q0[:1])
    use = aged.advance(one, 1, 50, lanes=1)
    assert use.jacobians <= 0.7 * 50 and one.iterations.sum() / 50 <= 3.5
