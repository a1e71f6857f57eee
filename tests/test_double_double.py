"""The double-double engine: the compiled kernel's third specialisation (the same source on
integrators/ddouble.py numbers, one point at a time).

* one step of every admissible pair (Lobatto IIIA/IIIB with their constraint weights d too) on two systems (Lotka–Volterra: log; the massless
  charged particle: sin, cos) agrees with a 50-digit mpmath computation of the same equations
  (integrators/oracle.py) to 1e-28;
* a point's bits do not depend on its block or the thread count;
* below double's floor: GLRK3-standard's order 6 shows on errors under 1e-17;
* ``integrate(..., precision="double-double")`` returns the low parts.
"""
import mpmath
import numpy as np
import pytest

import integrators
from integrators.ddouble import split, value
from integrators.engine import Engine, State, set_threads
from integrators.projections import PROJECTIONS, admission
from integrators.oracle import Oracle

SYSTEMS = {"lotka_volterra_2d": ([1.2, 0.9], 0.1), "massless_charged_particle": ([0.3, 0.2], 0.2)}
TABLEAUS = ("GLRK1", "GLRK2", "GLRK3", "GLRK4", "SRK3", "RadIIA2", "RadIIA3", "LobIIIA2", "LobIIIA3", "LobIIIA4",
            "LobIIIB2", "LobIIIB3", "LobIIIB4", "LobIIIC3", "LobIIID3", "LobIIIE3")


@pytest.mark.parametrize("sysname", sorted(SYSTEMS))
@pytest.mark.parametrize("tabname", TABLEAUS)
def test_one_step_agrees_with_50_digit_mpmath(sysname, tabname):
    sy, tab = integrators.system(sysname), integrators.tableau(tabname)
    q0, h = SYSTEMS[sysname]
    checked = 0
    for proj in PROJECTIONS:
        if admission(tab, proj):
            continue
        oracle = Oracle(sy, tab, proj, h)
        q = [mpmath.mpf(x) for x in q0]
        p = oracle.th(q)
        state = State.double_double(np.array([q0]), np.array([[split(x) for x in p]]), np.zeros((1, 2)), h, tab.s)
        Engine(sy, tab, proj, h).advance(state, 1, 1)
        assert state.live[0]
        q1, p1, L1 = oracle.step(q, p, [0, 0])
        for got, want in ((state.q, q1), (state.p, p1), (state.Lam, L1)):
            for m in range(2):
                err = abs(value(*got[0, m]) - want[m]) / max(abs(want[m]), 1)
                assert err < 1e-28, (proj, float(err))
        checked += 1
    assert checked >= 2


def _points(n=21):
    rng = np.random.default_rng(3)
    return 1.0 + 0.2 * rng.standard_normal((n, 2))


def _run(q, block, threads, steps=20):
    sy, tab = integrators.system("lotka_volterra_2d"), integrators.tableau("GLRK2")
    e = Engine(sy, tab, "symmetric", 0.1)
    from integrators.engine import theta_dd
    q2 = np.stack([q, np.zeros_like(q)], axis=-1)
    st = State.double_double(q2, theta_dd(sy, q2), np.zeros_like(q), 0.1, tab.s)
    set_threads(threads)
    try:
        e.advance(st, 1, steps, block=block)
    finally:
        set_threads(None)
    return st.checkpoint()


def test_bits_do_not_depend_on_block_or_threads():
    q = _points()
    ref = _run(q, 64, 1)
    for block, threads in ((1, 1), (5, 2), (7, 2)):
        got = _run(q, block, threads)
        assert all(np.array_equal(ref[k], got[k]) for k in ref), (block, threads)
    assert ref["q"].shape == (21, 2, 2) and np.any(ref["q"][..., 1] != 0)


def test_order_six_below_double_round_off():
    """GLRK3-standard on Lotka–Volterra to t = 1 (the paper's order 6; GLRK3-none has 4, which the
    double-double run also gives: 4.008): the error against h = 0.1/64 falls as h⁶ from
    3e-14 to 8e-18, below double's round-off (1e-16)."""
    sy = integrators.system("lotka_volterra_2d")
    q0 = [[1.2, 0.9]]

    def final(h):
        sol = integrators.integrate(sy, q0, tableau="GLRK3", projection="standard",
                                    h=h, steps=round(1.0 / h), save_every=round(1.0 / h),
                                    precision="double-double")
        return [value(sol.q[-1, 0, m], sol.q_lo[-1, 0, m]) for m in range(2)]

    ref = final(0.1 / 64)
    errs = [max(abs(a - b) for a, b in zip(final(h), ref)) for h in (0.025, 0.0125, 0.00625)]
    orders = [float(mpmath.log(errs[i] / errs[i + 1], 2)) for i in range(2)]
    assert all(5.7 < o < 6.3 for o in orders), orders
    assert errs[-1] < 1e-17, errs


def test_integrate_returns_the_low_parts():
    sy = integrators.system("lotka_volterra_2d")
    sol = integrators.integrate(sy, [[1.2, 0.9], [1.0, 1.1]], tableau="GLRK2", projection="symmetric",
                                h=0.1, steps=10, save_every=5,
                                precision="double-double")
    assert sol.precision == "double-double" and sol.q.shape == sol.q_lo.shape == (3, 2, 2)
    assert np.all(np.abs(sol.q_lo) <= np.spacing(np.abs(sol.q)))          # |lo| ≤ ½ ulp(hi), normalised
    double = integrators.integrate(sy, [[1.2, 0.9], [1.0, 1.1]], tableau="GLRK2", projection="symmetric",
                                   h=0.1, steps=10, save_every=5)
    assert double.q_lo is None and np.max(np.abs(double.q - sol.q)) < 1e-13
    assert np.array_equal(sol.q[0], [[1.2, 0.9], [1.0, 1.1]]) and not sol.q_lo[0].any()
    with pytest.raises(ValueError, match="precision"):
        integrators.integrate(sy, [[1.2, 0.9]], tableau="GLRK2", projection="none", h=0.1, steps=2, precision="quad")


@pytest.mark.parametrize("sysname,q0", [("point_vortices", [1.0, 0.1, 1.0, -0.1]),
                                        ("guiding_centre_tokamak", [2.5, 0.0, 0.0, 0.3425]),
                                        ("lotka_volterra_2d", [1.2, 0.9])])
def test_generated_point_functions_are_double_double_exact(sysname, q0):
    """ϑ and H of the generated double-double code against mpmath at 50 digits, with the parameters'
    doubles taken exactly: a product of two parameters (γ₁γ₂ of the vortices, B₀R₀ of the tokamak)
    must not round to double (it did: the vortices' solution was 5e-17 off a 40-digit reference)."""
    import sympy
    from integrators.engine import scalars_dd, theta_dd
    sy = integrators.system(sysname)
    mpmath.mp.dps = 50
    exact = {k: sympy.Rational(float(v)) for k, v in sy.params.items()}
    th = sympy.lambdify(sy.q, [t.subs(exact) for t in sy.theta_expr], "mpmath")
    H = sympy.lambdify(sy.q, sy.H_expr.subs(exact), "mpmath")
    x = [mpmath.mpf(v) for v in q0]
    q2 = np.array([[[v, 0.0] for v in q0]])
    got_th, got_H = theta_dd(sy, q2)[0], scalars_dd(sy, q2)[0, 0]
    for m, want in enumerate(th(*x)):
        assert abs(value(*got_th[m]) - want) <= 1e-30 * max(abs(want), 1), (m, float(value(*got_th[m]) - want))
    want = H(*x)
    assert abs(value(*got_H) - want) <= 1e-30 * max(abs(want), 1), float(value(*got_H) - want)


# -- double-double lanes: W points in two vectors (integrators.simd's DDVec) ----------------------

DD_SYSTEMS = ("lotka_volterra_2d", "massless_charged_particle")


@pytest.mark.parametrize("sysname", DD_SYSTEMS)
def test_double_double_lanes_give_the_scalar_paths_bits_on_every_pair(sysname):
    """11 points (a group of 8 and one of 3 beside 5 empty lanes), 3 steps, W = 8 against W = 1 in
    double-double: every field of the state (high and low parts) bitwise equal, for every admissible
    pair (log on Lotka–Volterra, sin and cos on the charged particle: functions taken lane by lane)."""
    from integrators import TABLEAU_NAMES, kernel
    sy = integrators.system(sysname)
    rng = np.random.default_rng(5)
    q0 = np.array(SYSTEMS[sysname][0]) * (1 + 0.02 * rng.standard_normal((11, sy.d)))
    h = SYSTEMS[sysname][1]
    bad, checked = {}, 0
    for tab in TABLEAU_NAMES:
        for proj in PROJECTIONS:
            if admission(integrators.tableau(tab), proj):
                continue
            eng = Engine(sy, integrators.tableau(tab), proj, h, precision="double-double")
            states = []
            for W in (1, kernel.LANES):
                st = eng.state(q0)
                eng.advance(st, 1, 3, lanes=W)
                states.append(st.checkpoint())
            diff = [k for k in states[0] if not np.array_equal(states[0][k], states[1][k])]
            if diff:
                bad[(tab, proj)] = diff
            checked += 1
    assert not bad, bad
    assert checked > 100 and np.any(states[1]["q"][..., 1] != 0)


def test_mixed_double_double_lanes_each_point_gets_the_bits_it_has_alone():
    """Lotka–Volterra at h = 0.9, where some points leave the domain while their lane neighbours go
    on with other Newton iteration counts: in double-double lanes each point's state is bitwise its
    state alone (W = 1), for blocks that split the lanes differently and for two threads."""
    from integrators import kernel
    sy = integrators.system("lotka_volterra_2d")
    rng = np.random.default_rng(7)
    q0 = np.abs(np.array([1.0, 1.0]) * (1 + 0.6 * rng.standard_normal((21, 2)))) + 0.05
    eng = Engine(sy, integrators.tableau("GLRK2"), "symmetric", 0.9, precision="double-double")

    def run(q, W, block=64, threads=None):
        st = eng.state(q)
        set_threads(threads)
        try:
            eng.advance(st, 1, 12, lanes=W, block=block)
        finally:
            set_threads(None)
        return st.checkpoint()

    together = run(q0, kernel.LANES)
    assert 0 < together["live"].sum() < len(q0)
    assert len(np.unique(together["iterations"][together["live"]])) > 1
    for block, threads in ((5, 1), (16, 2)):
        got = run(q0, kernel.LANES, block, threads)
        assert all(np.array_equal(together[k], got[k]) for k in together), (block, threads)
    for i in range(len(q0)):
        alone = run(q0[i:i + 1], 1)
        for k in together:
            assert np.array_equal(together[k][i], alone[k][0]), (i, k)


# -- a scene in double-double ------------------------------------------------------------------------

DD_SCENE = """
name = "lv_dd"
[system]
name = "lotka_volterra_2d"
[loop]
shape = "ellipse"
points = 16
params = { d = 2, center = [1.0, 1.0], radii = [0.05, 0.05] }
[surface]
shape = "rectangle"
n_sigma = 8
n_tau = 8
params = { d = 2, center = [1.0, 1.0], size = [0.02, 0.02] }
[run]
tableaus = ["GLRK2"]
projections = ["none", "symmetric"]
h = 0.1
steps = 40
output_every = 4
precision = "double-double"
"""


def test_a_double_double_scene_says_so_keeps_the_low_parts_and_resumes_bitwise(tmp_path, monkeypatch):
    """run.precision = "double-double": the file says so, the checkpoint keeps the low parts, the
    constraint error of the symmetric projection is double-double's (below 1e-26, where the same
    scene in double sits at double's round-off), and a run stopped after output 8 of GLRK2-none
    (states every 3rd output) resumes to the uninterrupted run's bits."""
    import h5py
    from integrators.service import driver, reader
    from integrators.service.scene import parse_scene
    from helpers import dump, same, stop_at_output_8
    scene = parse_scene(DD_SCENE)
    assert scene.precision == "double-double"
    full, part, dbl = tmp_path / "full.h5", tmp_path / "part.h5", tmp_path / "double.h5"
    driver.run(scene, full, progress=False)
    driver.run(parse_scene(DD_SCENE.replace('precision = "double-double"', "")), dbl, progress=False)
    run, double = reader.read_run(full), reader.read_run(dbl)
    assert run.precision == "double-double" and double.precision == "double"
    with h5py.File(full) as f:
        ck = f["runs/GLRK2-symmetric/checkpoint/a"]
        assert ck["q"].shape == (80, 2, 2) and np.any(ck["q"][..., 1] != 0)
    sym, sym_double = run["GLRK2-symmetric"].errors, double["GLRK2-symmetric"].errors
    assert np.max(sym["constraint"]) < 1e-26 < np.max(sym_double["constraint"])
    # the energy errors agree to double's round-off of them (the same truncation error)
    assert np.allclose(sym["energy"][1:], sym_double["energy"][1:], rtol=1e-6, atol=1e-15)
    stop_at_output_8(scene, part, monkeypatch)
    driver.run(scene, part, progress=False, resume=True)
    assert same(dump(full, skip=("wall_clock",)), dump(part, skip=("wall_clock",)))


def test_an_unknown_precision_is_refused_in_one_line():
    from integrators.service.scene import SceneError, parse_scene
    with pytest.raises(SceneError, match="run.precision must be one of"):
        parse_scene(DD_SCENE.replace('"double-double"', '"quad"'))


def test_defect_orders_below_double_floor():
    """The one-step Ω̄ defect of GLRK2- and GLRK3-standard on the massless charged particle, where
    double's audit reads nothing below ~1e-13: in double-double the defects fall as h^(2s+2), to
    below 1e-20 (integrators.audit.defect_dd; docs/audit.md)."""
    from integrators.audit.defect_dd import defect_study_dd
    sy = integrators.system("massless_charged_particle")
    q = np.array([[1.0, 1.0], [1.01, 0.99], [0.99, 1.005]])
    for tab, order in (("GLRK2", 6), ("GLRK3", 8)):
        r = defect_study_dd(sy, integrators.tableau(tab), "standard", q, 0.2, levels=4)
        assert r["order"] is not None and abs(r["order"] - order) < 0.3, (tab, r)
        assert r["floor"] < 1e-25 and min(r["defect"]) < (1e-16 if tab == "GLRK2" else 1e-20), r
