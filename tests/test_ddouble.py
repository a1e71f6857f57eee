"""The double-double number type (integrators/ddouble.py) against 50-digit mpmath: each operation
and function over its domain, its error in units of 2⁻¹⁰⁴ relative (dd-ulps; measured at most
1.91, scripts/studies/engine_ddouble_accuracy.py, docs/engine.md: the bounds here leave room for a libm whose
double starting values differ in the last bit); the operators running ordinary code on
double-doubles; the constants the nearest double-doubles."""
import math

import mpmath
import numpy as np
import pytest
from numba import njit

from integrators import ddouble as D
from integrators.ddouble import dd
from integrators.ddouble_check import UNARY, _add, _atan2, _div, _mul, _pow, _sub, dd_of, samples, ulps  # noqa: F401

mpmath.mp.dps = 50


@pytest.mark.parametrize("name", sorted(UNARY))
def test_each_function_is_within_a_few_dd_ulps_of_mpmath(name):
    fn, ref, (lo, hi), bound = UNARY[name]
    worst = 0.0
    for x in samples(lo, hi):
        h, l_ = dd_of(x)
        x = D.value(h, l_)                        # the double-double's own value
        worst = max(worst, ulps(fn(h, l_), ref(x)))
    assert worst <= bound, f"{name}: {worst:.1f} dd-ulps"


@pytest.mark.parametrize("op,ref,bound", [(_add, lambda a, b: a + b, 2), (_sub, lambda a, b: a - b, 2),
                                          (_mul, lambda a, b: a * b, 2), (_div, lambda a, b: a / b, 2),
                                          (_atan2, mpmath.atan2, 4)])
def test_arithmetic_is_within_a_few_dd_ulps_of_mpmath(op, ref, bound):
    worst = 0.0
    xs, ys = samples(-1e6, 1e6, seed=1), samples(-1e3, 1e3, seed=2)
    for x, y in zip(xs, ys):
        a, b = dd_of(x), dd_of(y)
        want = ref(D.value(*a), D.value(*b))
        if op in (_add, _sub) and abs(want) < 1e-20 * max(abs(x), abs(y)):
            continue                         # exact cancellation: relative error is not the measure
        worst = max(worst, ulps(op(*a, *b), want))
    assert worst <= bound, worst


def test_powers_integer_and_real():
    for x in samples(0.1, 10.0, n=50, seed=3):
        a = dd_of(x)
        xv = D.value(*a)
        for n in (0, 1, 2, 3, 7, -1, -4, 17):
            assert ulps(_pow(*a, float(n), 0.0), xv ** n) <= 4 * max(abs(n), 1)
        assert ulps(_pow(*a, 0.5, 0.0), mpmath.sqrt(xv)) <= 32
        assert ulps(_pow(*a, *dd_of(mpmath.mpf("1") / 3)), xv ** (D.value(*dd_of(mpmath.mpf(1) / 3)))) <= 64


def test_the_fma_two_product_is_exact():
    rng = np.random.default_rng(4)
    for a, b in rng.standard_normal((200, 2)) * 1e5:
        p, e = D.two_prod(a, b)
        assert mpmath.mpf(p) + mpmath.mpf(e) == mpmath.mpf(a) * mpmath.mpf(b)
        s, t = D.two_sum(a, b)
        assert mpmath.mpf(s) + mpmath.mpf(t) == mpmath.mpf(a) + mpmath.mpf(b)


def test_the_constants_are_the_nearest_double_doubles():
    for name, v in (("_LN2", mpmath.log(2)), ("_PI", mpmath.pi), ("_PI_2", mpmath.pi / 2)):
        assert getattr(D, name) == D.split(v), name
    for parts, v in ((D._PI_2_3, mpmath.pi / 2), (D._LN2_3, mpmath.log(2))):
        assert abs(mpmath.mpf(parts[0]) + parts[1] + parts[2] - v) < mpmath.mpf(10) ** -48
    assert all(tuple(D._INV_FACT[k]) == D.split(mpmath.mpf(1) / math.factorial(k)) for k in range(40))


@njit
def _horner(xh, xl, coefficients):
    """Ordinary code: a polynomial by Horner's rule, with doubles and integers mixed in."""
    x = dd(xh, xl)
    r = dd(0.0, 0.0)
    for c in coefficients:
        r = r * x + c
    r = 2 * r - 1 + (r / 2.0) * 2
    ok = (r > 0.0) or (r <= 0.0)
    return r.hi, r.lo, ok, -r < r, abs(-r) == r


def test_operators_run_ordinary_code_on_double_doubles():
    c = np.array([1.0, -3.0, 0.5, 7.0])
    x = dd_of(mpmath.mpf(1) / 3)
    h, l_, ok, less, same = _horner(*x, c)
    xv = D.value(*x)
    p = ((mpmath.mpf(1) * xv - 3) * xv + mpmath.mpf("0.5")) * xv + 7
    assert ulps((h, l_), 3 * p - 1) <= 8 and ok and less and same


def test_special_values():
    assert math.isnan(UNARY["sqrt"][0](-1.0, 0.0)[0]) and UNARY["sqrt"][0](0.0, 0.0) == (0.0, 0.0)
    assert UNARY["log"][0](0.0, 0.0)[0] == -np.inf and math.isnan(UNARY["log"][0](-1.0, 0.0)[0])
    assert UNARY["exp"][0](800.0, 0.0)[0] == np.inf and UNARY["exp"][0](-800.0, 0.0) == (0.0, 0.0)
    assert math.isnan(UNARY["asin"][0](1.5, 0.0)[0]) and UNARY["exp"][0](0.0, 0.0) == (1.0, 0.0)
    assert math.isnan(UNARY["sin"][0](np.inf, 0.0)[0])
