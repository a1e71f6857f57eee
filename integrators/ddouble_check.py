"""The double-double number type (integrators/ddouble.py) measured against mpmath: each operation
on plain (hi, lo) pairs, the functions with the domains they are measured on, samples with random low
parts, and the error in units of 2⁻¹⁰⁴ relative (dd-ulps).  Shared by tests/test_ddouble.py and
scripts/studies/engine_ddouble_accuracy.py (docs/engine.md).  The caller sets mpmath's precision (50 digits there)."""
import mpmath
import numpy as np
from numba import njit

from . import ddouble as D
from .ddouble import dd


def dd_of(x):
    return D.split(x)


def ulps(got, want):
    """|got − want| / |want| in units of 2⁻¹⁰⁴ (absolute below |want| = 1e-300)."""
    g = D.value(*got)
    return float(abs(g - want) / max(abs(want), mpmath.mpf("1e-300")) / mpmath.mpf(2) ** -104)


@njit
def _add(ah, al, bh, bl):
    r = dd(ah, al) + dd(bh, bl)
    return r.hi, r.lo


@njit
def _sub(ah, al, bh, bl):
    r = dd(ah, al) - dd(bh, bl)
    return r.hi, r.lo


@njit
def _mul(ah, al, bh, bl):
    r = dd(ah, al) * dd(bh, bl)
    return r.hi, r.lo


@njit
def _div(ah, al, bh, bl):
    r = dd(ah, al) / dd(bh, bl)
    return r.hi, r.lo


@njit
def _atan2(ah, al, bh, bl):
    r = np.arctan2(dd(ah, al), dd(bh, bl))
    return r.hi, r.lo


@njit
def _pow(ah, al, bh, bl):
    r = dd(ah, al) ** dd(bh, bl)
    return r.hi, r.lo


def _unary(fn):
    fn = njit(fn)

    @njit
    def f(ah, al):
        r = fn(dd(ah, al))
        return r.hi, r.lo
    return f


UNARY = {
    "sqrt": (_unary(lambda a: np.sqrt(a)), mpmath.sqrt, (1e-200, 1e200), 4),
    "exp": (_unary(lambda a: np.exp(a)), mpmath.exp, (-600.0, 700.0), 4),     # (below e^-600 ≈ 1e-261 the low part nears the subnormals)
    "log": (_unary(lambda a: np.log(a)), mpmath.log, (1e-200, 1e200), 4),
    "log near 1": (_unary(lambda a: np.log(a)), mpmath.log, (0.5, 2.0), 4),
    "sin": (_unary(lambda a: np.sin(a)), mpmath.sin, (-100.0, 100.0), 4),
    "cos": (_unary(lambda a: np.cos(a)), mpmath.cos, (-100.0, 100.0), 4),
    "tan": (_unary(lambda a: np.tan(a)), mpmath.tan, (-1.5, 1.5), 4),
    "asin": (_unary(lambda a: np.arcsin(a)), mpmath.asin, (-1.0, 1.0), 4),
    "acos": (_unary(lambda a: np.arccos(a)), mpmath.acos, (-1.0, 1.0), 4),
    "atan": (_unary(lambda a: np.arctan(a)), mpmath.atan, (-1e3, 1e3), 4),
    "sinh": (_unary(lambda a: np.sinh(a)), mpmath.sinh, (-20.0, 20.0), 4),
    "cosh": (_unary(lambda a: np.cosh(a)), mpmath.cosh, (-20.0, 20.0), 4),
    "tanh": (_unary(lambda a: np.tanh(a)), mpmath.tanh, (-20.0, 20.0), 4),
    "abs": (_unary(lambda a: abs(a)), abs, (-1e10, 1e10), 0),
}


def samples(lo, hi, n=300, seed=0):
    """``n`` double-double samples in [lo, hi] (log-spaced for a positive range spanning decades),
    with random low parts, as mpmath numbers."""
    rng = np.random.default_rng(seed)
    if lo > 0 and hi / lo > 1e3:
        x = np.exp(rng.uniform(np.log(lo), np.log(hi), n))
    else:
        x = rng.uniform(lo, hi, n)
    out = []
    for v in x:
        lo_part = float(np.spacing(v)) * rng.uniform(-0.5, 0.5)
        out.append(mpmath.mpf(float(v)) + mpmath.mpf(lo_part))
    return out
