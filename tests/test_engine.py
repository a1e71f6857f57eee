"""The compiled step engine against its oracle, the numpy engine (integrators/reference.py), and its
own promises: bits independent of threads and blocks, one compilation for every pair, a disk cache
keyed by the expressions, symbol names that never matter."""
import os
import subprocess
import sys

import numpy as np
import pytest
import sympy

import integrators
from integrators.codegen import generate_source, point_functions
from integrators.engine import FIXED_TOL, set_threads
from integrators.projections import PROJECTIONS, admission

from integrators import reference

EPS = np.finfo(float).eps
PAIRS = [(t, p) for t in integrators.TABLEAU_NAMES for p in PROJECTIONS
         if admission(integrators.tableau(t), p) is None]


def _oracle(system, tab, proj, h, q0, steps):
    st = reference.Stepper(system, integrators.tableau(tab), proj, h)
    S = reference.State(q0, system.theta(q0), np.zeros_like(q0), h, st.s)
    for k in range(1, steps + 1):
        reference.advance(st, S, k * h)
    return S


def _compiled(system, tab, proj, h, q0, steps, tolerances=None):
    eng = integrators.Engine(system, integrators.tableau(tab), proj, h, tolerances=tolerances)
    S = eng.state(q0)
    eng.advance(S, 1, steps)
    return S



def _arg(sig, name):
    from integrators.kernel import advance_argument
    return advance_argument(sig, name)

def test_every_builtin_pair_is_admitted_here():
    assert len(PAIRS) == 114


@pytest.mark.parametrize("sysname", ["point_vortices", "lotka_volterra_2d"])
def test_one_step_agrees_with_the_numpy_engine_on_every_pair(sysname, rng):
    """After one step from the same points, q, p and λ of the two engines agree to a few ulps of
    the point's size (different LU / inverse round-off inside Newton, same converged solution)."""
    sy = integrators.system(sysname)
    q0 = np.array(sy.defaults["q0"]) * (1 + 0.01 * rng.standard_normal((4, sy.d)))
    worst = {}
    for tab, proj in PAIRS:
        a = _oracle(sy, tab, proj, sy.defaults["h"], q0, 1)
        b = _compiled(sy, tab, proj, sy.defaults["h"], q0, 1)
        assert np.array_equal(a.live, b.live), (tab, proj)
        for name in ("q", "p", "Lam"):
            x, y = getattr(a, name), getattr(b, name)
            scale = np.maximum(np.abs(x), 1.0)
            worst[(tab, proj, name)] = float(np.max(np.abs(x - y) / scale) / EPS)
    bad = {k: v for k, v in worst.items() if v > 16}
    assert not bad, bad


def test_many_steps_track_the_numpy_engine():
    """50 steps of every projection with GLRK2 and SRK3 on the guiding centre: the trajectories stay
    within 1e-12 of each other and every point takes the same number of steps."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = np.array([[0.5, 0.0, 0.0, 0.5], [0.3, 0.2, 0.0, 0.4], [0.7, -0.1, 1.0, 0.3]])
    for tab in ("GLRK2", "SRK3"):
        for proj in PROJECTIONS:
            if admission(integrators.tableau(tab), proj):
                continue
            a = _oracle(sy, tab, proj, 10.0, q0, 50)
            b = _compiled(sy, tab, proj, 10.0, q0, 50)
            assert np.array_equal(a.steps, b.steps)
            assert np.max(np.abs(a.q - b.q) / np.maximum(np.abs(a.q), 1.0)) < 1e-12, (tab, proj)


def test_the_same_breakdowns_as_the_numpy_engine():
    """Lotka–Volterra points near the edge of the domain with a large step: the same points break
    down at the same step in both engines, and the others agree.  The numpy engine keeps the
    predictor it was written with (the last step's stages extrapolated, carried factors), so the
    compiled engine runs that rule here (Tolerances(predictor="extrapolate")): the same Newton path,
    where the default's path may end on another rounding of a point that passes within 1e-5 of
    q₁ = 0 (7e-4 apart after 20 steps, measured)."""
    lv = integrators.system("lotka_volterra_2d")
    q0 = np.array([[1.0, 1.0], [0.05, 1.0], [1.0, 0.02], [0.3, 3.0], [2.0, 0.5], [0.01, 0.01]])
    broke = survived = 0
    for tab, proj in (("GLRK2", "none"), ("GLRK2", "symmetric"), ("LobIIIA2", "standard"), ("SRK3", "midpoint")):
        a = _oracle(lv, tab, proj, 0.3, q0, 20)
        b = _compiled(lv, tab, proj, 0.3, q0, 20, integrators.Tolerances(predictor="extrapolate"))
        assert np.array_equal(a.breakdown_time, b.breakdown_time), (tab, proj, a.breakdown_time, b.breakdown_time)
        # (points pass within 1e-5 of q₁ = 0, where ϑ = log(q₂)/q₁ + q₂ amplifies round-off: 6e-12 measured)
        assert np.max(np.abs(a.q[a.live] - b.q[a.live])) < 1e-10
        broke += int(np.isfinite(a.breakdown_time).sum())
        survived += int(a.live.sum())
    assert broke >= 8 and survived >= 8          # (measured: 10 breakdowns at 6 different times, 14 survivors)


def test_bits_do_not_depend_on_threads_or_blocks(rng):
    sy = integrators.system("point_vortices")
    q0 = np.array(sy.defaults["q0"]) * (1 + 0.01 * rng.standard_normal((203, 4)))
    runs = []
    for threads, block in ((1, 64), (2, 64), (2, 1), (1, 7), (2, 1000)):
        set_threads(threads)
        sol = integrators.integrate(sy, q0, tableau="SRK3", projection="symmetric",
                                    steps=30, save_every=10, chunk=block)
        runs.append(sol.q)
    set_threads(None)
    for r in runs[1:]:
        assert np.array_equal(r, runs[0])


def test_one_compilation_serves_every_pair_and_every_parameter_value():
    """The tableau, the projection and the parameter values are runtime data: the kernel has one
    specialisation per (dtype, dimension), and a system with other parameter values shares the
    generated code (same key)."""
    from integrators import kernel
    sy = integrators.system("point_vortices")
    q0 = np.array([sy.defaults["q0"]])
    for tab, proj in (("GLRK1", "none"), ("GLRK3", "symmetric"), ("LobIIIA3", "standard"), ("SRK3", "midpoint")):
        integrators.integrate(sy, q0, tableau=tab, projection=proj, steps=2)
    integrators.integrate(sy.with_params(gamma1=0.3), q0, tableau="GLRK2", projection="symplectic", steps=2)
    real_4d = [sig for sig in kernel.advance.signatures if "complex" not in str(_arg(sig, "st_"))
               and "UniTuple(int64 x 4)" in str(_arg(sig, "dim")) and str(_arg(sig, "proto")) == "UniTuple(int64 x 1)"]
    # (st_, dim, …, proto: one point of doubles is W = 1, (0,); a double-double state's proto is (0.0,),
    #  compiled by other tests of the same process)
    assert len(real_4d) == 1, [str(_arg(s, "st_")) for s in real_4d]
    assert point_functions(sy)[0] is point_functions(sy.with_params(gamma1=0.3))[0]


def test_the_generated_code_is_cached_on_disk_keyed_by_the_expressions(tmp_path):
    """A fresh process writes the generated module into $POINCARE_CACHE; a second one finds it (and
    numba's compiled code beside it); a changed H is another file."""
    env = dict(os.environ, POINCARE_CACHE=str(tmp_path))
    code = ("import integrators, sympy; x, y = sympy.symbols('x y'); "
            "s = integrators.system_from([-y / 2, x / 2], {H}, [x, y]); "
            "print(integrators.integrate(s, [1.0, 0.5], tableau='GLRK2', projection='symmetric', h=0.1, steps=3).q[-1, 0, 0])")
    outs = [subprocess.run([sys.executable, "-c", code.format(H=H)], env=env, capture_output=True, text=True,
                           check=True).stdout for H in ("(x**2 + y**2) / 2", "(x**2 + y**2) / 2", "x**2 + y**2")]
    files = sorted(p.name for p in (tmp_path / "kernels").glob("system_*.py"))
    assert len(files) == 2
    assert outs[0] == outs[1] != outs[2]
    assert any(p.suffix == ".nbi" for p in (tmp_path / "kernels" / "__pycache__").iterdir())


def test_hostile_symbol_names_in_the_compiled_code():
    """Coordinates q, p, out, np and parameters e, pi, sqrt, log, exp, lambda mean those symbols in the
    generated numba code too: the compiled step agrees with the numpy engine, whose generated code
    tests/test_scene.py checks against hand values."""
    q, p, out, np_ = sympy.symbols("q p out np")
    e, pi, sq, lg, ex, lam = sympy.symbols("e pi sqrt log exp lambda")
    theta = [-p * e / 2, q * pi / 2, -np_ * sq, out * lg]
    H = (q ** 2 + p ** 2) * ex / 2 + lam * (out ** 2 + np_ ** 2)
    s = integrators.system_from(theta, H, [q, p, out, np_], params={e: 2.0, pi: 3.0, sq: 5.0, lg: 7.0, ex: 0.5,
                                                                   lam: 0.25})
    src = generate_source(s)
    assert "_q0" in src and "numpy.sqrt" not in src and "numpy.exp" not in src
    q0 = np.array([[1.0, 2.0, 3.0, 4.0]])
    a = _oracle(s, "GLRK2", "symmetric", 0.1, q0, 3)
    b = _compiled(s, "GLRK2", "symmetric", 0.1, q0, 3)
    assert np.max(np.abs(a.q - b.q)) < 1e-14


def test_complex_step_through_the_compiled_newton_solve():
    """The audit's exact Jacobian: the engine's complex128 specialisation carries the derivative through
    the Newton solve; against 8th-order central differences of the real map to 1e-9."""
    from integrators import audit
    sy = integrators.system("point_vortices")
    step = audit.stepper_map(integrators.tableau("GLRK2"), "symmetric")
    q = np.array([sy.defaults["q0"]]) * 1.01
    p, lam = sy.theta(q), np.zeros_like(q)
    Jc, method, _ = audit.jacobian(step, q, p, lam, 0.1, sy, "complex step")
    Jf, method_f, _ = audit.jacobian(step, q, p, lam, 0.1, sy, "central differences")
    assert method == "complex step" and method_f == "central differences"
    assert np.max(np.abs(Jc - Jf)) < 1e-9 * max(1.0, np.max(np.abs(Jc)))


@pytest.mark.skipif(np.finfo(np.longdouble).eps >= np.finfo(np.float64).eps, reason="long double is double here")
def test_the_numpy_engine_in_long_double_has_no_double_round_off():
    """The extended-precision reference of scripts/studies/results_energy_drift.py: the numpy engine run on long
    double arrays (Newton to 4 eps of long double, its Jacobian inverted in double).  GLRK6 +
    symmetric, 50 steps of h = 2 on guiding_centre_symmetric, against the exact flow.

    What the code promises, on any CPU and BLAS: the state stays long double, and its error is
    the rounding of the exact flow itself (computed in double): one ulp in z and u, two ulps of
    the radius in the rotated x and y (measured: 0.25 ulp).  Double's own error is a round-off size that depends
    on the BLAS kernel (7e-15 with OpenBLAS's Haswell kernels, 7.7e-16 with SkylakeX), so it is
    only bounded from above here, far below the method's truncation error."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = np.array([sy.defaults["q0"]])
    exact = sy.exact_flow(q0, 100.0)
    err = {}
    for dt in (np.float64, np.longdouble):
        q = q0.astype(dt)
        st = reference.Stepper(sy, integrators.tableau("GLRK6"), "symmetric", 2.0)
        S = reference.State(q, sy.theta(q), np.zeros_like(q), 2.0, st.s)
        for k in range(1, 51):
            reference.advance(st, S, 2.0 * k)
        assert S.q.dtype == dt and S.live.all()
        err[dt] = np.abs(S.q.astype(float) - exact)
    bound = np.spacing(np.abs(exact))             # z and u: one ulp of the exact value
    bound[:, :2] = 2 * np.spacing(np.hypot(exact[:, 0], exact[:, 1]))[:, None]   # x, y: a rotation's rounding
    assert np.all(err[np.longdouble] <= bound)
    assert err[np.float64].max() < 1e-12


def test_tolerances_are_runtime_data():
    """Newton's stopping rule as data (integrators.Tolerances): one compilation for any values; a
    looser tol costs fewer iterations and moves the result by about that much; maxiter = 1 fails
    every step (Newton does not converge in one iteration from the guess), unless unconverged
    iterates are accepted, and then every point goes on, one iteration a step."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = np.array(sy.defaults["q0"]) + 1e-2 * np.random.default_rng(5).standard_normal((8, 4))
    tab = integrators.tableau("GLRK2")

    def run(tol=None, steps=10):
        e = integrators.Engine(sy, tab, "none", 10.0, tolerances=tol)
        st = e.state(q0)
        e.advance(st, 1, steps)
        return st

    ref = run()
    assert np.array_equal(run(integrators.Tolerances()).q, ref.q)
    assert np.array_equal(run(integrators.Tolerances(tol=0.0, maxiter=40)).q, ref.q)
    fixed = run(integrators.Tolerances(tol=4 * EPS))      # the rule before issue 70: one iteration short
    assert fixed.iterations.sum() < ref.iterations.sum() and 0 < np.max(np.abs(fixed.q - ref.q)) < 1e-13
    loose = run(integrators.Tolerances(tol=1e-8, stall=1e-8))
    assert loose.live.all() and loose.iterations.sum() < ref.iterations.sum()
    assert 0 < np.max(np.abs(loose.q - ref.q)) < 1e-6
    one = run(integrators.Tolerances(maxiter=1))
    assert not one.live.any() and np.all(one.breakdown_time == 10.0)
    taken = run(integrators.Tolerances(maxiter=1, accept_unconverged=True))
    assert taken.live.all() and np.all(taken.iterations == 10) and np.all(taken.steps == 10)
    for bad in (dict(tol=-1.0), dict(maxiter=0), dict(refresh=float("nan")), dict(maxiter=2.5)):
        with pytest.raises(ValueError, match="Tolerances"):
            integrators.Tolerances(**bad)


def test_warm_compiles_the_width_a_call_will_take_and_advances_nothing():
    """Engine.warm(q) compiles the kernel specialisation and lane function that a call on q will
    use (the driver warms every pair's before the first pair, so no pair's wall time holds a
    compilation): 16 lanes for GLRK2-symmetric (12 unknowns) on kernel.WIDE_POINTS points, 8 for
    GLRK4-symmetric on 20 points, 1 for fewer than 8 points; nothing is advanced."""
    from integrators import kernel
    sy = integrators.system("guiding_centre_symmetric")
    q0 = np.tile(sy.defaults["q0"], (kernel.WIDE_POINTS, 1))

    def widths():
        return {len(_arg(sig, "proto")) for sig in kernel.advance.signatures
                if "complex" not in str(_arg(sig, "st_")) and "UniTuple(int64 x 4)" in str(_arg(sig, "dim"))}

    for tab, proj, n, W in (("GLRK2", "symmetric", kernel.WIDE_POINTS, 16), ("GLRK4", "symmetric", 20, 8),
                            ("GLRK4", "symmetric", 5, 1)):
        eng = integrators.Engine(sy, integrators.tableau(tab), proj, 1.0)
        assert eng.lanes_for(n) == W
        eng.warm(q0[:n])
        assert W in widths(), (tab, proj, W, widths())
        st = eng.state(q0[:n])
        before = st.q.copy()
        eng.warm(st.q)
        assert np.array_equal(st.q, before) and st.steps.sum() == 0


def test_compile_kernels_names_the_children_that_failed():
    """engine.compile_kernels runs each specialisation in a child process and returns the ones that
    failed, for the caller to compile itself (an odd dimension has no stand-in system), and
    compile_kernel gives the specialisation it names."""
    from integrators import kernel
    from integrators.engine import compile_kernel, compile_kernels
    assert compile_kernels([(3, 8, "double")]) == [(3, 8, "double")]
    compile_kernel(2, 1)
    assert any(str(_arg(sig, "proto")) == "UniTuple(int64 x 1)" and str(_arg(sig, "dim")) == "UniTuple(int64 x 2)"
               and "complex" not in str(_arg(sig, "st_")) for sig in kernel.advance.signatures)


def test_one_specialisation_names_what_a_call_compiles():
    """Engine._specialise: a real state of 20 points takes double in 8 lanes, a complex one complex
    step in 1, a double-double one 8 lanes with Newton's tol, stall and floors scaled from eps to 2⁻¹⁰⁴ (the
    rest of the rule as is) and a prototype of double zeros; 16 lanes for double-double are refused."""
    import integrators
    from integrators.engine import Engine, Specialisation
    sy = integrators.system("lotka_volterra_2d")
    e = Engine(sy, integrators.tableau("GLRK2"), "symmetric", 0.1)
    q = np.array([[1.0, 1.0]]) + 0.01 * np.arange(20)[:, None]
    real = e._specialise(e.state(q))
    assert isinstance(real, Specialisation) and (real.number, real.lanes, real.proto) == ("double", 8, (0,) * 8)
    cs = e._specialise(e.state(q.astype(complex), dtype=np.complex128))
    assert (cs.number, cs.lanes) == ("complex step", 1)
    dd = Engine(sy, integrators.tableau("GLRK2"), "symmetric", 0.1, precision="double-double")
    spec = dd._specialise(dd.state(q))
    assert (spec.number, spec.lanes, spec.proto) == ("double-double", 8, (0.0,) * 8)
    scale = 2.0 ** -104 / np.finfo(float).eps
    from integrators.kernel import Newton
    scaled = [Newton._fields.index(n) for n in ("tol", "stall", "floor", "carry", "fine")]
    dither = Newton._fields.index("dither")        # the dithered approach: double unknowns only
    settle = Newton._fields.index("settle")        # the settled approach: the same
    same = [i for i in range(len(Newton._fields)) if i not in scaled and i not in (dither, settle)]
    assert np.array_equal(spec.newton[scaled], real.newton[scaled] * scale)
    assert np.array_equal(spec.newton[same], real.newton[same])
    assert real.newton[dither] == 0.0 and spec.newton[dither] == 0.0          # (opt-in)
    assert integrators.Tolerances(dither=True).array()[dither] == 2.0 ** -45
    assert integrators.Tolerances(dither=True).array(double_double=True)[dither] == 0.0
    assert real.newton[settle] == 2.0 ** -48 and spec.newton[settle] == 0.0  # (the default: 4 unknowns)
    assert integrators.Tolerances(settle=False).array(unknowns=4)[settle] == 0.0
    on = dict(settle=True)
    assert integrators.Tolerances(**on).array(unknowns=16)[settle] == 2.0 ** -48
    assert integrators.Tolerances(**on).array(double_double=True, unknowns=16)[settle] == 0.0
    for off in (dict(dither=True), dict(tol=FIXED_TOL), dict(predictor="extrapolate")):   # nor before the floor
        assert integrators.Tolerances(**on, **off).array(unknowns=16)[settle] == 0.0
    assert integrators.Tolerances(**on).array(unknowns=17)[settle] == 0.0     # carried factors: not settled
    with pytest.raises(ValueError, match="lanes must be 1 or 8"):
        dd._specialise(dd.state(q), lanes=16)


def test_point_functions_take_a_lane_width():
    """codegen.point_functions(lanes=W): 1 the scalar function, 8 and 16 the lane ones (one per W, the
    same object on a second call); double-double takes 1 or 8; a bool or another W is refused."""
    import integrators
    from integrators.codegen import point_functions
    sy = integrators.system("lotka_volterra_2d")
    scalar, lanes8 = point_functions(sy)[0], point_functions(sy, lanes=8)[0]
    assert scalar is not lanes8 and point_functions(sy, lanes=8)[0] is lanes8
    assert point_functions(sy, lanes=16)[0] not in (scalar, lanes8)
    for bad, kw in ((True, {}), (4, {}), (16, {"precision": "double-double"})):
        with pytest.raises(ValueError, match="lanes must be a lane width W"):
            point_functions(sy, lanes=bad, **kw)
