"""integrate(): partition independence, breakdown handling, bad input, convergence orders."""
import numpy as np
import pytest

import integrators


def test_partition_independence_bitwise(rng):
    """1000 points as one batch, one at a time and in uneven chunks: identical bits."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = np.array(sy.defaults["q0"]) + 0.1 * rng.standard_normal((1000, 4))
    kw = dict(tableau="GLRK2", projection="symmetric", h=10.0, steps=4)
    batch = integrators.integrate(sy, q0, **kw)
    ones = integrators.integrate(sy, q0, chunk=1, **kw)
    assert np.array_equal(batch.q, ones.q) and np.array_equal(batch.p, ones.p)
    assert np.array_equal(batch.lam, ones.lam)
    # uneven chunks: 1, 7, 300, 692
    pieces, start = [], 0
    for size in (1, 7, 300, 692):
        pieces.append(integrators.integrate(sy, q0[start:start + size], **kw))
        start += size
    assert np.array_equal(batch.q, np.concatenate([s.q for s in pieces], axis=1))
    single = integrators.integrate(sy, q0[517], **kw)
    assert np.array_equal(batch.q[:, 517], single.q[:, 0])


def test_lobatto_IIIA2_breaks_down_and_others_are_unaffected():
    """Paper: LobIIIA2 without projection on Lotka–Volterra (h = 0.1) crashes after about 25 steps."""
    lv = integrators.system("lotka_volterra_2d")
    sol = integrators.integrate(lv, [1, 1], tableau="LobIIIA2", projection="none", h=0.1, steps=100)
    assert 1.0 <= sol.breakdown_time[0] <= 4.0          # 10 to 40 steps
    assert sol.steps_taken[0] == round(sol.breakdown_time[0] / 0.1) - 1
    # frozen: the stored state stops changing after the breakdown
    k = int(sol.steps_taken[0])
    assert np.array_equal(sol.q[k + 1], sol.q[-1])
    # a batch with a failing point: the others are bitwise what they are alone
    safe = np.array([[1.0, 1.0], [1.2, 0.9]])
    mixed = np.vstack([safe[:1], [[0.05, 0.05]], safe[1:]])
    kw = dict(tableau="GLRK2", projection="none", h=0.1, steps=200)
    sol_mixed = integrators.integrate(lv, mixed, **kw)
    sol_safe = integrators.integrate(lv, safe, **kw)
    assert np.isfinite(sol_mixed.breakdown_time[1]) and np.all(np.isinf(sol_mixed.breakdown_time[[0, 2]]))
    assert np.array_equal(sol_mixed.q[:, [0, 2]], sol_safe.q)


@pytest.mark.parametrize("kw,msg", [
    (dict(q0=[[1.0, np.nan]]), "not finite or outside"),
    (dict(q0=[[-1.0, 1.0]]), "outside the domain"),
    (dict(q0=[[1.0, 1.0, 1.0]]), "shape"),
    (dict(h=0.0), "non-zero"),
    (dict(h=np.inf), "finite"),
    (dict(steps=-3), "non-negative"),
    (dict(projection="orthogonal"), "unknown projection"),
    (dict(tableau="RadIIA2", projection="symmetric"), "R\\(∞\\)"),
    (dict(chunk=-5), "chunk must be a positive"),
    (dict(chunk=0), "chunk must be a positive"),
])
def test_bad_input_is_a_clear_error(kw, msg):
    lv = integrators.system("lotka_volterra_2d")
    args = dict(q0=[[1.0, 1.0]], tableau="GLRK2", projection="none", h=0.1, steps=2)
    args.update(kw)
    with pytest.raises(ValueError, match=msg):
        integrators.integrate(lv, args.pop("q0"), **args)


def fitted_order(hs, errs):
    return np.polyfit(np.log(hs), np.log(errs), 1)[0]


# (tableau, projection, expected order of the solution error from tab:convergence_energy)
ORDERS = [("GLRK1", "none", 2), ("GLRK2", "none", 2), ("GLRK1", "symmetric", 2), ("GLRK2", "symmetric", 4),
          ("GLRK2", "standard", 4), ("GLRK2", "symplectic", 4), ("SRK3", "midpoint", 4), ("GLRK2", "midpoint", 4)]


@pytest.mark.parametrize("tab,proj,order", ORDERS)
def test_convergence_order_on_point_vortices(tab, proj, order):
    """Solution error at T = 1 against a GLRK4-symmetric reference with h = 1/640."""
    sy = integrators.system("point_vortices")
    q0 = sy.defaults["q0"]
    ref = integrators.integrate(sy, q0, tableau="GLRK4", projection="symmetric", h=1 / 320, steps=320).q[-1, 0]
    hs = np.array([1 / 5, 1 / 10, 1 / 20])
    errs = [np.max(np.abs(integrators.integrate(sy, q0, tableau=tab, projection=proj, h=h,
                                                steps=round(1 / h)).q[-1, 0] - ref)) for h in hs]
    assert abs(fitted_order(hs, errs) - order) < 0.5, errs


def test_tolerances_reach_the_engine():
    """integrate(..., tolerances=Tolerances(refresh=0.1)) with the carried factors (the predictor
    "extrapolate"; the default's Jacobian at the guess seldom needs a refresh): one orbit of 200
    steps is bitwise the engine's with that rule, refreshes less (more Newton iterations) and
    agrees with the default rule's orbit to below 1e-11 relative: another rounding of the same
    solution."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = np.array(sy.defaults["q0"])[None]
    rule = integrators.Tolerances(refresh=0.1, predictor="extrapolate")
    fast = integrators.integrate(sy, q0, tableau="GLRK4", projection="symmetric",
                                 h=10.0, steps=200, save_every=200, tolerances=rule)
    plain = integrators.integrate(sy, q0, tableau="GLRK4", projection="symmetric", h=10.0, steps=200, save_every=200,
                                  tolerances=integrators.Tolerances(predictor="extrapolate"))
    eng = integrators.Engine(sy, integrators.tableau("GLRK4"), "symmetric", 10.0, tolerances=rule)
    st = eng.state(q0)
    eng.advance(st, 1, 200)
    assert np.array_equal(fast.q[-1], st.q) and np.array_equal(fast.newton_iterations, st.iterations)
    assert fast.newton_iterations.sum() > plain.newton_iterations.sum()
    assert not np.array_equal(fast.q[-1], plain.q[-1])
    assert np.max(np.abs(fast.q[-1] - plain.q[-1]) / np.abs(plain.q[-1]).clip(1.0)) < 1e-11
    with pytest.raises(ValueError, match="tolerances must be"):
        integrators.integrate(sy, q0, tableau="GLRK4", projection="symmetric",
                              h=10.0, steps=2, tolerances={"refresh": 0.1})


def test_every_argument_after_the_points_is_named():
    """integrate(system, q0, *, …): a call that passes the tableau by position is refused rather
    than read as something else."""
    import inspect
    params = list(inspect.signature(integrators.integrate).parameters.values())
    assert [p.name for p in params[:2]] == ["system", "q0"]
    assert all(p.kind is inspect.Parameter.KEYWORD_ONLY for p in params[2:]) and len(params) > 10
    lv = integrators.system("lotka_volterra_2d")
    with pytest.raises(TypeError):
        integrators.integrate(lv, [1.0, 1.0], "GLRK2", "none", h=0.1, steps=1)
