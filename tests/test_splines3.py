"""The 3-D field (integrators/splines3.py), the 1-D profiles (splines.Spline1) and li383's |B|
through them in the compiled engine.

* the spline interpolates its nodes, reproduces a quintic in (x, y) constant in z to round-off
  (not-a-knot), converges as Δ⁶ on a smooth periodic field, and its derivatives are the exact
  derivatives of the interpolant (complex steps);
* the compiled scalar evaluation is the numpy one, bit for bit; in the engine, W lanes give the
  scalar path's bits, double-double lanes too, and the Newton Jacobian is the complex-step one;
* li383's |B| from the 3-D field is the Fourier sum of the kept modes to the stated accuracy;
* the 1-D quintic profile spline reproduces quintics and is evaluated with the same bits compiled
  and in numpy.
"""
from pathlib import Path

import numpy as np
import pytest
from numba import njit

import integrators
from integrators import kernel
from integrators.boozer import system_from_boozer
from integrators.splines import Spline1, field1, field1_np, pack
from integrators.splines3 import DERIVATIVES3, Spline3, field3, field3_np

LI383 = Path(integrators.__file__).parent / "service" / "scenes" / "boozmn_li383_low_res.nc"
PERIOD = 2 * np.pi / 3


def _smooth(x, y, z):
    return np.sin(1.3 * x + 0.4) * np.cos(y) + x * y * y * np.cos(3 * z) + 0.2 * np.sin(6 * z + x)


def _spline(f, n, nz):
    x, y = np.linspace(-1, 1, n), np.linspace(-1.2, 0.9, n + 3)
    X, Y, Z = np.meshgrid(x, y, np.arange(nz) * PERIOD / nz, indexing="ij")
    return Spline3(x, y, PERIOD, f(X, Y, Z)), (X, Y, Z)


def _points(rng, n=500):
    return rng.uniform(-1, 1, n), rng.uniform(-1.2, 0.9, n), rng.uniform(-20, 20, n)


def test_interpolates_its_nodes_and_reproduces_quintics(rng):
    sp, (X, Y, Z) = _spline(_smooth, 20, 12)
    assert np.max(np.abs(sp(X, Y, Z) - _smooth(X, Y, Z))) < 1e-14
    quintic = lambda x, y, z: 0.3 + x - 2 * y + x * x * y - 0.7 * y ** 5 + 0.25 * x ** 5 * y ** 3 + 0 * z
    sp, _ = _spline(quintic, 11, 6)
    x, y, z = _points(rng)
    assert np.max(np.abs(sp(x, y, z) - quintic(x, y, z))) < 1e-12
    assert np.max(np.abs(sp(x, y, z, 1, 0, 0) - (1 + 2 * x * y + 1.25 * x ** 4 * y ** 3))) < 1e-11
    assert np.max(np.abs(sp(x, y, z, 0, 0, 1))) < 1e-13


def test_converges_as_the_sixth_power_of_the_step(rng):
    """Halving every step divides the error of a smooth periodic field by about 64."""
    x, y, z = _points(rng, 2000)
    err = []
    for n, nz in ((16, 16), (32, 32)):
        sp, _ = _spline(_smooth, n, nz)
        err.append(np.max(np.abs(sp(x, y, z) - _smooth(x, y, z))))
    assert 40 < err[0] / err[1] < 100, err


def test_derivatives_are_the_interpolants(rng):
    """First derivatives against complex steps of the value; second ones against complex steps of
    the first: to 1e-12 of their size."""
    sp, _ = _spline(_smooth, 16, 12)
    x, y, z = _points(rng)
    h = 1e-30
    unit = {0: (1, 0, 0), 1: (0, 1, 0), 2: (0, 0, 1)}
    for order in DERIVATIVES3[1:]:
        axis = next(i for i in range(3) if order[i])
        step = unit[axis]
        rest = tuple(o - s for o, s in zip(order, step))
        cs = sp(x + 1j * h * step[0], y + 1j * h * step[1], z + 1j * h * step[2], *rest).imag / h
        assert np.max(np.abs(cs - sp(x, y, z, *order))) <= 1e-12 * np.max(np.abs(cs)), order


@njit
def _compiled(k, x, y, z):
    out = np.empty((x.size, 10))
    for i in range(x.size):
        o = field3(k, 0, 0, x[i], y[i], z[i])
        for j in range(10):
            out[i, j] = o[j]
    return out


def test_compiled_evaluation_is_numpys_bit_for_bit(rng):
    sp, _ = _spline(_smooth, 16, 12)
    k = pack([sp])
    x, y, z = _points(rng)
    x[:3] = (-5.0, 4.0, np.nan)                 # outside the grid: the edge cell; not finite: cell 0
    assert np.array_equal(_compiled(k, x, y, z), np.stack(field3_np(k, 0, x, y, z), 1), equal_nan=True)


def test_a_spline_refuses_what_it_cannot_use():
    x = np.linspace(0, 1, 8)
    for args, words in [((x, x[:7], 1.0, np.zeros((8, 7, 6))), "at least 8"),
                        ((x, x, 1.0, np.zeros((8, 8, 5))), "at least 8 × 8 × 6"),
                        ((x ** 2, x, 1.0, np.zeros((8, 8, 6))), "regular"),
                        ((x, x, 0.0, np.zeros((8, 8, 6))), "period"),
                        ((x, x, 1.0, np.full((8, 8, 6), np.nan)), "finite")]:
        with pytest.raises(ValueError, match=words):
            Spline3(*args)


@njit
def _compiled1(k, x):
    out = np.empty((x.size, 4))
    for i in range(x.size):
        o = field1(k, 0, 0, x[i])
        for j in range(4):
            out[i, j] = o[j]
    return out


def test_the_profile_spline_reproduces_quintics_with_numpys_bits(rng):
    X = np.linspace(-0.1, 2.0, 23)
    f = lambda x: 0.5 - x + 0.3 * x ** 3 - 0.25 * x ** 5
    sp = Spline1(X, f(X))
    x = rng.uniform(-0.1, 2.0, 400)
    assert np.max(np.abs(sp(x) - f(x))) < 1e-13
    assert np.max(np.abs(sp(x, 1) - (-1 + 0.9 * x ** 2 - 1.25 * x ** 4))) < 1e-12
    assert np.max(np.abs(sp(x, 3) - (1.8 - 15 * x ** 2))) < 1e-9
    k = pack([sp])
    x[:2] = (-3.0, np.nan)
    assert np.array_equal(_compiled1(k, x), np.stack(field1_np(k, 0, x), 1), equal_nan=True)
    with pytest.raises(ValueError, match="regular"):
        Spline1(X ** 2, X)


@pytest.fixture(scope="module")
def li383():
    return system_from_boozer(LI383)


def _near_default(sy, rng, n):
    return np.asarray(sy.defaults["q0"]) + np.outer(rng.standard_normal(n), [3e-3, 3e-3, 0.2, 1e-4])


def test_li383_takes_the_3d_field_and_its_b_is_the_fourier_sum(li383, rng):
    """|B| from the 3-D field (96² × 56) against the Fourier sum of the 114 kept modes at 2,000 points
    with s < 0.98: within 1e-4 everywhere (measured 4.4e-5, at the axis, as the harmonics' form: the
    radial interpolant's s^{1/2} there) and 1e-6 in the median (measured 4.7e-9)."""
    sy, bz = li383, li383.boozer
    assert sy.defaults["field"] == "3d" and sy.defaults["grid_zeta"] == 56
    s, th, ze = rng.uniform(0, 0.98, 2000), rng.uniform(0, 2 * np.pi, 2000), rng.uniform(0, 2 * np.pi, 2000)
    r = np.sqrt(2 * bz.psi0 * s)
    q = np.stack([r * np.cos(th), r * np.sin(th), ze, 0 * s], 1)
    e = np.abs(sy.H(q) / sy.param_values["mu"] / bz.modB(s, th, ze) - 1)
    assert e.max() < 1e-4 and np.median(e) < 1e-6, (e.max(), np.median(e))


@pytest.mark.slow
def test_lanes_give_the_scalar_paths_bits_in_the_3d_field(li383, rng):
    """11 points (8 lanes and 3), 3 steps, W = 8 against W = 1, every field of the state bitwise equal."""
    q0 = _near_default(li383, rng, 11)
    fields = ("q", "p", "Lam", "q_comp", "p_comp", "Y", "live", "breakdown_time", "iterations", "steps")
    for tab, proj in (("GLRK2", "symmetric"), ("GLRK1", "none"), ("GLRK2", "symplectic"), ("SRK3", "midpoint")):
        eng = integrators.Engine(li383, integrators.tableau(tab), proj, li383.defaults["h"])
        a, b = eng.state(q0), eng.state(q0)
        eng.advance(a, 1, 3, lanes=1)
        eng.advance(b, 1, 3, lanes=kernel.LANES)
        assert a.live.all()
        assert all(np.array_equal(getattr(a, f), getattr(b, f)) for f in fields), (tab, proj)


@pytest.mark.slow
def test_the_jacobian_is_exact_in_the_3d_field(li383, rng):
    """The kernel's Jacobian against complex-step differences of its residual: to 1e-12."""
    from helpers import assert_jacobian_is_complex_steps
    h = li383.defaults["h"]
    eng = integrators.Engine(li383, integrators.tableau("GLRK2"), "symmetric", h)
    q = _near_default(li383, rng, 1)[0]
    p = li383.theta(q) + 1e-9 * rng.standard_normal(4)
    lam = 1e-9 * rng.standard_normal(4)
    z = 1e-7 * rng.standard_normal(eng.nz)
    z[:8] += np.tile(h * li383.vector_field(q), 2)
    assert_jacobian_is_complex_steps(li383, eng, h, q, p, lam, z)


@pytest.mark.slow
def test_double_double_runs_in_the_3d_field(li383):
    """precision="double-double": the lanes' bits are W = 1's, and after 20 steps the double run is
    within its own round-off of the double-double one."""
    from integrators.engine import Engine
    q0 = np.asarray(li383.defaults["q0"]) + np.outer(np.linspace(-1, 1, 9), [2e-3, 1e-3, 0.0, 0.0])
    h = li383.defaults["h"]
    eng = Engine(li383, integrators.tableau("GLRK2"), "symmetric", h, precision="double-double")
    a, b = eng.state(q0), eng.state(q0)
    eng.advance(a, 1, 20, lanes=1)
    eng.advance(b, 1, 20)
    assert a.live.all() and np.array_equal(a.q, b.q)
    d = integrators.integrate(li383, q0, tableau="GLRK2", projection="symmetric", h=h, steps=20, save_every=20)
    assert np.max(np.abs(d.q[-1] - a.q[..., 0]) / np.abs(a.q[..., 0]).clip(1e-3)) < 1e-12
