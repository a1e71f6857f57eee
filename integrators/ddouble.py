"""Double-double numbers for numba: a value is the unevaluated sum hi + lo of two doubles (|lo| ≤
½ ulp(hi)), about 32 significant digits with double's exponent range.

This is the number type of the double-double engine, written as a numba type so that
code written against ordinary operators runs on it unchanged: ``dd(hi, lo)`` makes one, ``.hi`` and
``.lo`` read it, and ``+ − × ÷``, unary ``−``, ``abs``, comparisons, ``np.sqrt`` and the functions
the restricted parser accepts (integrators/expressions.py: ``exp log sin cos tan asin acos atan
atan2 sinh cosh tanh``, and powers: :func:`dd_pow`, :func:`dd_powi`) take double-doubles, and
doubles or integers mixed with them.

Every operation is built from error-free transformations, so its result is a fixed function of
its inputs' bits on any x86-64 CPU (no fastmath, no contraction, no library call whose last bit
may differ between machines except where stated):

* TwoSum (Knuth): s + e = a + b exactly, six additions;
* TwoProduct: p + e = a × b exactly with e = fma(a, b, −p), LLVM's ``llvm.fma.f64`` intrinsic,
  which is exact by definition (an FMA instruction where the CPU has one, a correctly rounded
  software routine where it does not: the same bits either way).

The algorithms are those of Hida, Li and Bailey's QD library ("accurate" addition and division),
with the transcendental functions by argument reduction and Taylor series (exp, sin, cos), one
Newton step from the double value (log, atan2), and identities for the rest.  The double
``np.log``, ``np.arctan2`` and ``np.sin``/``np.cos`` calls that start the Newton steps come from
the platform's libm, whose last bit may differ between machines; the Newton step's result does
not depend on that bit beyond double-double round-off, but it is not bitwise independent of it.
Errors against 50-digit mpmath, in units of 2⁻¹⁰⁴ relative (a few "dd-ulps"), are measured by
tests/test_ddouble.py and tabulated in docs/engine.md.
"""
from __future__ import annotations

import math
import operator

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic, make_attribute_wrapper, models, overload, register_model

_OPTS = dict(cache=True, error_model="numpy")

EPS_DD = 2.0 ** -104          # the relative size of a double-double's last bit, about 4.9e-32


class DDType(types.Type):
    """A double-double value (hi, lo)."""

    def __init__(self):
        super().__init__(name="DD")


dd_t = DDType()


@register_model(DDType)
class _DDModel(models.StructModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, [("hi", types.float64), ("lo", types.float64)])


make_attribute_wrapper(DDType, "hi", "hi")
make_attribute_wrapper(DDType, "lo", "lo")


# Vector forms (integrators/simd/pointers.py registers them: W double-doubles in two <W x double>, hi and
# lo): ``dd`` and ``fma`` given vectors build and fuse them lane by lane, so every algorithm below,
# written with + − × and these two, runs unchanged on W double-doubles with each lane's bits those
# of the scalar code.
VECTOR_FORMS = {}


@intrinsic
def dd(typingctx, hi, lo):
    """The double-double hi + lo (the caller keeps |lo| ≤ ½ ulp(hi), or normalises with dd_add)."""
    if not (isinstance(hi, (types.Float, types.Integer)) and isinstance(lo, (types.Float, types.Integer))):
        return VECTOR_FORMS["dd"](hi, lo) if "dd" in VECTOR_FORMS else None

    def codegen(context, builder, sig, args):
        v = cgutils.create_struct_proxy(dd_t)(context, builder)
        v.hi = context.cast(builder, args[0], sig.args[0], types.float64)
        v.lo = context.cast(builder, args[1], sig.args[1], types.float64)
        return v._getvalue()
    return dd_t(hi, lo), codegen


@intrinsic
def fma(typingctx, a, b, c):
    """a × b + c rounded once (LLVM's llvm.fma.f64: exact by definition on every CPU)."""
    if not all(isinstance(x, types.Float) for x in (a, b, c)):
        return VECTOR_FORMS["fma"](a, b, c) if "fma" in VECTOR_FORMS else None

    def codegen(context, builder, sig, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.DoubleType(), [ir.DoubleType()] * 3),
                                            "llvm.fma.f64")
        return builder.call(fn, list(args))
    return types.float64(types.float64, types.float64, types.float64), codegen


# -- error-free transformations -------------------------------------------------------------------

@njit(**_OPTS)
def two_sum(a, b):
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


@njit(**_OPTS)
def quick_two_sum(a, b):          # |a| ≥ |b|
    s = a + b
    return s, b - (s - a)


@njit(**_OPTS)
def two_prod(a, b):
    p = a * b
    return p, fma(a, b, -p)


# -- arithmetic -----------------------------------------------------------------------------------

@njit(**_OPTS)
def to_dd(x):
    """A double (or integer) as a double-double; a double-double as itself."""
    return dd(x, 0.0)


@njit(**_OPTS)
def dd_add(a, b):
    s1, s2 = two_sum(a.hi, b.hi)
    t1, t2 = two_sum(a.lo, b.lo)
    s2 += t1
    s1, s2 = quick_two_sum(s1, s2)
    s2 += t2
    s1, s2 = quick_two_sum(s1, s2)
    return dd(s1, s2)


@njit(**_OPTS)
def dd_add_d(a, b):
    s1, s2 = two_sum(a.hi, b)
    s2 += a.lo
    s1, s2 = quick_two_sum(s1, s2)
    return dd(s1, s2)


@njit(**_OPTS)
def dd_neg(a):
    return dd(-a.hi, -a.lo)


@njit(**_OPTS)
def dd_sub(a, b):
    return dd_add(a, dd_neg(b))


@njit(**_OPTS)
def dd_mul(a, b):
    p1, p2 = two_prod(a.hi, b.hi)
    p2 += a.hi * b.lo + a.lo * b.hi
    p1, p2 = quick_two_sum(p1, p2)
    return dd(p1, p2)


@njit(**_OPTS)
def dd_mul_d(a, b):
    p1, p2 = two_prod(a.hi, b)
    p2 += a.lo * b
    p1, p2 = quick_two_sum(p1, p2)
    return dd(p1, p2)


@njit(**_OPTS)
def dd_sqr(a):
    p1, p2 = two_prod(a.hi, a.hi)
    p2 += 2.0 * a.hi * a.lo
    p2 += a.lo * a.lo
    p1, p2 = quick_two_sum(p1, p2)
    return dd(p1, p2)


@njit(**_OPTS)
def dd_div(a, b):
    q1 = a.hi / b.hi
    r = dd_sub(a, dd_mul_d(b, q1))
    q2 = r.hi / b.hi
    r = dd_sub(r, dd_mul_d(b, q2))
    q3 = r.hi / b.hi
    q1, q2 = quick_two_sum(q1, q2)
    return dd_add_d(dd(q1, q2), q3)


@njit(**_OPTS)
def dd_ldexp(a, k):
    """a × 2^k, exactly (no overflow check)."""
    f = 2.0 ** k
    return dd(a.hi * f, a.lo * f)


@njit(**_OPTS)
def dd_abs(a):
    return dd_neg(a) if a.hi < 0.0 or (a.hi == 0.0 and a.lo < 0.0) else a


@njit(**_OPTS)
def dd_sqrt(a):
    """√a by one Newton step from the double root (Karp's trick, as QD); NaN below 0."""
    if a.hi <= 0.0:
        return dd(np.sqrt(a.hi), 0.0)          # 0 → 0, negative → NaN
    x = 1.0 / np.sqrt(a.hi)
    ax = a.hi * x
    return dd_add_d(to_dd(ax), dd_sub(a, dd_sqr(to_dd(ax))).hi * (x * 0.5))


@njit(**_OPTS)
def dd_lt(a, b):
    return a.hi < b.hi or (a.hi == b.hi and a.lo < b.lo)


@njit(**_OPTS)
def dd_eq(a, b):
    return a.hi == b.hi and a.lo == b.lo


# -- constants (hi, lo), each the nearest double-double to the real number -------------------------

_LN2 = (6.931471805599452862e-01, 2.319046813846299558e-17)
_PI = (3.141592653589793116e+00, 1.224646799147353207e-16)
_PI_2 = (1.570796326794896558e+00, 6.123233995736766036e-17)

def _in_three(name):
    """A constant (mpmath's ``pi/2`` or ``ln2``) as p1 + p2 + p3 + O(1e-49), each part the
    nearest double to what is left (Cody and Waite's argument reduction)."""
    import mpmath
    with mpmath.workdps(80):
        x, parts = (mpmath.pi / 2 if name == "pi/2" else mpmath.log(2)), []
        for _ in range(3):
            parts.append(float(x))
            x -= parts[-1]
    return tuple(parts)


_PI_2_3 = _in_three("pi/2")
_LN2_3 = _in_three("ln2")
_PI_4_HI = 0.7853981633974483


def _exact_inverse_factorials(n=40):
    """1/k! as the nearest double-doubles (from exact rationals, through mpmath at 60 digits)."""
    import mpmath
    out = np.zeros((n, 2))
    with mpmath.workdps(60):
        for k in range(n):
            x = mpmath.mpf(1) / mpmath.factorial(k)
            hi = float(x)
            out[k] = hi, float(x - hi)
    return out


_INV_FACT = _exact_inverse_factorials()


@njit(**_OPTS)
def _inv_fact(k):
    return dd(_INV_FACT[k, 0], _INV_FACT[k, 1])


# -- exp, log ---------------------------------------------------------------------------------------

@njit(**_OPTS)
def dd_exp(a):
    """e^a: a = m ln2 + r, e^(r/512) by its Taylor series, squared nine times, times 2^m."""
    if a.hi > 709.78:
        return dd(np.inf, 0.0)
    if a.hi < -745.2:
        return dd(0.0, 0.0)
    if a.hi != a.hi:
        return a
    if a.hi == 0.0 and a.lo == 0.0:
        return dd(1.0, 0.0)
    m = np.floor(a.hi / _LN2[0] + 0.5)
    r = a
    for k in range(3):                 # a − m ln2 with ln2 in three parts, each m × part exact
        p, e = two_prod(m, _LN2_3[k])
        r = dd_sub(r, dd(p, e))
    r = dd(r.hi / 512.0, r.lo / 512.0)
    # e^r − 1 = r + r²/2! + …, |r| ≤ ln2/1024 ≈ 6.8e-4: 9 terms reach 1e-33
    p = dd_sqr(r)
    s = dd_add(r, dd(p.hi * 0.5, p.lo * 0.5))
    for k in range(3, 12):
        p = dd_mul(p, r)
        t = dd_mul(p, _inv_fact(k))
        s = dd_add(s, t)
        if abs(t.hi) <= 1e-34 * abs(s.hi):
            break
    for _ in range(9):            # e^(2x) − 1 = 2(e^x − 1) + (e^x − 1)²
        s = dd_add(dd(2.0 * s.hi, 2.0 * s.lo), dd_sqr(s))
    s = dd_add_d(s, 1.0)
    return dd_ldexp(s, int(m))


@njit(**_OPTS)
def dd_log(a):
    """ln a: near 1 (|a − 1| < 1/4) as 2 atanh((a − 1)/(a + 1)) by its series (a − 1 is exact,
    so ln a keeps its relative accuracy where it is small), elsewhere by one Newton step
    x ← x + a e^(−x) − 1 from the double log.  NaN below 0, −∞ at 0."""
    if a.hi <= 0.0 or a.hi != a.hi or a.hi == np.inf:
        return dd(np.log(a.hi), 0.0)
    if abs(a.hi - 1.0) < 0.25:
        u = dd_div(dd_add_d(a, -1.0), dd_add_d(a, 1.0))
        u2 = dd_sqr(u)
        s, t = u, u
        for k in range(3, 80, 2):
            t = dd_mul(t, u2)
            term = dd_div(t, dd(float(k), 0.0))
            s = dd_add(s, term)
            if abs(term.hi) <= 1e-34 * abs(s.hi):
                break
        return dd(2.0 * s.hi, 2.0 * s.lo)
    x = to_dd(np.log(a.hi))
    return dd_add_d(dd_add(x, dd_mul(a, dd_exp(dd_neg(x)))), -1.0)


# -- trigonometric ------------------------------------------------------------------------------------

@njit(**_OPTS)
def _taylor(t, x2, k0):
    """The series of sin, cos and sinh: its first term t (x, or 1), each next term the last times
    x2 (±x²) with 1/k! for k = k0, k0 + 2, … (the factorials of the odd or even powers), summed until
    a term is below 1e-34 of the sum."""
    s = t
    for k in range(k0, 40, 2):
        t = dd_mul(t, x2)
        term = dd_mul(t, _inv_fact(k))
        s = dd_add(s, term)
        if abs(term.hi) <= 1e-34 * abs(s.hi):
            break
    return s


@njit(**_OPTS)
def _sin_taylor(r):
    """sin r for |r| ≤ π/4."""
    return r if r.hi == 0.0 else _taylor(r, dd_neg(dd_sqr(r)), 3)


@njit(**_OPTS)
def _cos_taylor(r):
    """cos r for |r| ≤ π/4."""
    return _taylor(dd(1.0, 0.0), dd_neg(dd_sqr(r)), 2)


@njit(**_OPTS)
def _reduce(a):
    """(r, j): a = r + q π/2 with |r| ≤ π/4 and j = q mod 4.  π/2 in three doubles (Cody and
    Waite): each q × part is exact as a double-double (two_prod), so r keeps its own accuracy
    down to |r| ≈ 1e-16 |a| … for |q| < 2^53; beyond |a| ≈ 1e15 the reduction is not attempted."""
    if abs(a.hi) < _PI_4_HI:
        return a, 0
    q = np.floor(a.hi / _PI_2_3[0] + 0.5)
    r = a
    for k in range(3):
        p, e = two_prod(q, _PI_2_3[k])
        r = dd_sub(r, dd(p, e))
    return r, int(q) % 4


@njit(**_OPTS)
def dd_sin(a):
    if a.hi != a.hi or abs(a.hi) == np.inf:
        return dd(np.nan, 0.0)
    r, j = _reduce(a)
    if j == 0:
        return _sin_taylor(r)
    if j == 1:
        return _cos_taylor(r)
    if j == 2:
        return dd_neg(_sin_taylor(r))
    return dd_neg(_cos_taylor(r))


@njit(**_OPTS)
def dd_cos(a):
    if a.hi != a.hi or abs(a.hi) == np.inf:
        return dd(np.nan, 0.0)
    r, j = _reduce(a)
    if j == 0:
        return _cos_taylor(r)
    if j == 1:
        return dd_neg(_sin_taylor(r))
    if j == 2:
        return dd_neg(_cos_taylor(r))
    return _sin_taylor(r)


@njit(**_OPTS)
def dd_tan(a):
    return dd_div(dd_sin(a), dd_cos(a))


@njit(**_OPTS)
def dd_atan2(y, x):
    """The angle of (x, y) in (−π, π], by one Newton step from the double atan2 on the unit circle."""
    if x.hi == 0.0 and y.hi == 0.0:
        return to_dd(np.arctan2(y.hi, x.hi))
    if x.hi == 0.0:
        return dd(_PI_2[0], _PI_2[1]) if y.hi > 0.0 else dd(-_PI_2[0], -_PI_2[1])
    if y.hi == 0.0:
        return dd(_PI[0], _PI[1]) if x.hi < 0.0 else dd(0.0, 0.0)
    if x.hi != x.hi or y.hi != y.hi or abs(x.hi) == np.inf or abs(y.hi) == np.inf:
        return to_dd(np.arctan2(y.hi, x.hi))
    r = dd_sqrt(dd_add(dd_sqr(x), dd_sqr(y)))
    xx, yy = dd_div(x, r), dd_div(y, r)
    z = to_dd(np.arctan2(y.hi, x.hi))
    sz, cz = dd_sin(z), dd_cos(z)
    if abs(xx.hi) > abs(yy.hi):
        return dd_add(z, dd_div(dd_sub(yy, sz), cz))          # z + (sin θ − sin z)/cos z
    return dd_sub(z, dd_div(dd_sub(xx, cz), sz))              # z − (cos θ − cos z)/sin z


@njit(**_OPTS)
def dd_atan(a):
    return dd_atan2(a, dd(1.0, 0.0))


@njit(**_OPTS)
def _one_minus_sqr(a):
    """1 − a² as (1 − a)(1 + a): no cancellation near |a| = 1."""
    return dd_mul(dd_add_d(dd_neg(a), 1.0), dd_add_d(a, 1.0))


@njit(**_OPTS)
def dd_asin(a):
    if abs(a.hi) > 1.0 or (abs(a.hi) == 1.0 and a.lo * a.hi > 0.0):
        return dd(np.nan, 0.0)
    return dd_atan2(a, dd_sqrt(_one_minus_sqr(a)))


@njit(**_OPTS)
def dd_acos(a):
    if abs(a.hi) > 1.0 or (abs(a.hi) == 1.0 and a.lo * a.hi > 0.0):
        return dd(np.nan, 0.0)
    return dd_atan2(dd_sqrt(_one_minus_sqr(a)), a)


# -- hyperbolic -----------------------------------------------------------------------------------

@njit(**_OPTS)
def _sinh_taylor(a):
    """sinh a for |a| ≤ 0.05."""
    return _taylor(a, dd_sqr(a), 3)


@njit(**_OPTS)
def dd_sinh(a):
    if a.hi == 0.0:
        return a
    if abs(a.hi) > 0.05:
        ea = dd_exp(a)
        d = dd_sub(ea, dd_div(dd(1.0, 0.0), ea))
        return dd(d.hi * 0.5, d.lo * 0.5)
    return _sinh_taylor(a)


@njit(**_OPTS)
def dd_cosh(a):
    ea = dd_exp(a)
    s = dd_add(ea, dd_div(dd(1.0, 0.0), ea))
    return dd(s.hi * 0.5, s.lo * 0.5)


@njit(**_OPTS)
def dd_tanh(a):
    if a.hi == 0.0:
        return a
    if abs(a.hi) > 20.0:
        return dd(1.0, 0.0) if a.hi > 0 else dd(-1.0, 0.0)
    if abs(a.hi) > 0.05:
        ea = dd_exp(a)
        inv = dd_div(dd(1.0, 0.0), ea)
        return dd_div(dd_sub(ea, inv), dd_add(ea, inv))
    s = _sinh_taylor(a)
    return dd_div(s, dd_sqrt(dd_add_d(dd_sqr(s), 1.0)))


# -- powers ----------------------------------------------------------------------------------------

@njit(**_OPTS)
def dd_powi(a, n):
    """a^n for an integer n, by repeated squaring (1 for n = 0)."""
    m = abs(n)
    r = dd(1.0, 0.0)
    s = a
    while m > 0:
        if m & 1:
            r = dd_mul(r, s)
        m >>= 1
        if m:
            s = dd_sqr(s)
    return dd_div(dd(1.0, 0.0), r) if n < 0 else r


@njit(**_OPTS)
def dd_pow(a, b):
    """a^b: an integral b by :func:`dd_powi`, else e^(b ln a) (NaN for a < 0)."""
    if b.lo == 0.0 and b.hi == np.floor(b.hi) and abs(b.hi) < 2.0 ** 31:
        return dd_powi(a, int(b.hi))
    return dd_exp(dd_mul(b, dd_log(a)))


# -- operators: ordinary code runs on double-doubles -------------------------------------------------

def _is_dd(t):
    return isinstance(t, DDType)


def _is_num(t):
    return isinstance(t, (types.Float, types.Integer)) and not isinstance(t, types.Boolean)


def _lift(t):
    """How an operand of type ``t`` becomes a double-double, or None."""
    if _is_dd(t):
        return lambda x: x
    if _is_num(t):
        return lambda x: dd(x, 0.0)
    return None


def _lifted(a, b, fn):
    la, lb = _is_dd(a), _is_dd(b)
    if la and lb:
        return lambda a, b: fn(a, b)
    if la and _is_num(b):
        return lambda a, b: fn(a, dd(b, 0.0))
    if _is_num(a) and lb:
        return lambda a, b: fn(dd(a, 0.0), b)
    return None


def _operator(op, fn, fn_d=None):
    @overload(op, inline="never")
    def impl(a, b):
        if fn_d is not None and _is_dd(a) and _is_num(b):
            return lambda a, b: fn_d(a, float(b))
        if fn_d is not None and op in (operator.add, operator.mul) and _is_num(a) and _is_dd(b):
            return lambda a, b: fn_d(b, float(a))
        return _lifted(a, b, fn)
    return impl


@njit(**_OPTS)
def _sub_d(a, b):
    return dd_add_d(a, -b)


@njit(**_OPTS)
def _gt(a, b):
    return dd_lt(b, a)


@njit(**_OPTS)
def _le(a, b):
    return not dd_lt(b, a)


@njit(**_OPTS)
def _ge(a, b):
    return not dd_lt(a, b)


@njit(**_OPTS)
def _ne(a, b):
    return not dd_eq(a, b)


_operator(operator.add, dd_add, dd_add_d)
_operator(operator.sub, dd_sub, _sub_d)
_operator(operator.mul, dd_mul, dd_mul_d)
_operator(operator.truediv, dd_div)
_operator(operator.pow, dd_pow)
_operator(operator.lt, dd_lt)
_operator(operator.gt, _gt)
_operator(operator.le, _le)
_operator(operator.ge, _ge)
_operator(operator.eq, dd_eq)
_operator(operator.ne, _ne)


@overload(operator.neg, inline="never")
def _neg(a):
    if _is_dd(a):
        return lambda a: dd_neg(a)


@overload(abs, inline="never")
def _abs(a):
    if _is_dd(a):
        return lambda a: dd_abs(a)


def _unary(fn, *targets):
    for target in targets:
        @overload(target, inline="never")
        def impl(a):
            if _is_dd(a):
                return lambda a: fn(a)


_unary(dd_sqrt, np.sqrt, math.sqrt)
_unary(dd_exp, np.exp, math.exp)
_unary(dd_log, np.log, math.log)
_unary(dd_sin, np.sin, math.sin)
_unary(dd_cos, np.cos, math.cos)
_unary(dd_tan, np.tan, math.tan)
_unary(dd_asin, np.arcsin, math.asin)
_unary(dd_acos, np.arccos, math.acos)
_unary(dd_atan, np.arctan, math.atan)
_unary(dd_sinh, np.sinh, math.sinh)
_unary(dd_cosh, np.cosh, math.cosh)
_unary(dd_tanh, np.tanh, math.tanh)
_unary(dd_abs, np.abs)


def _atan2_overload(target):
    @overload(target, inline="never")
    def impl(a, b):
        return _lifted(a, b, dd_atan2)


_atan2_overload(np.arctan2)
_atan2_overload(math.atan2)


def as_dd(x):
    """``x`` as a double-double: itself, or a double (integer) with a zero low part."""


@overload(as_dd, inline="never")
def _as_dd(x):
    if _is_dd(x):
        return lambda x: x
    if _is_num(x):
        return lambda x: dd(float(x), 0.0)


@overload(np.isfinite, inline="never")
def _isfinite(a):
    if _is_dd(a):
        return lambda a: np.isfinite(a.hi) and np.isfinite(a.lo)


@overload(np.sign, inline="never")
def _sign(a):
    if _is_dd(a):
        return lambda a: dd(np.sign(a.hi) if a.hi != 0.0 else np.sign(a.lo), 0.0)


@njit(**_OPTS)
def scale_array(x, h):
    """h × x for a double-double array x (…, 2) and a double h, each value to a double-double."""
    out = np.empty_like(x)
    flat, res = x.reshape(-1, 2), out.reshape(-1, 2)
    for i in range(flat.shape[0]):
        r = dd_mul_d(dd(flat[i, 0], flat[i, 1]), h)
        res[i, 0], res[i, 1] = r.hi, r.lo
    return out


@njit(**_OPTS)
def divide_array(x, h):
    """x / h for a double-double array x (…, 2) and a double h, each value to a double-double."""
    out = np.empty_like(x)
    flat, res = x.reshape(-1, 2), out.reshape(-1, 2)
    hh = dd(h, 0.0)
    for i in range(flat.shape[0]):
        r = dd_div(dd(flat[i, 0], flat[i, 1]), hh)
        res[i, 0], res[i, 1] = r.hi, r.lo
    return out


# -- Python side -------------------------------------------------------------------------------------

def split(x, dps=50) -> tuple:
    """(hi, lo): the nearest double-double to the mpmath number (or exact string, int, Fraction) ``x``."""
    import mpmath
    with mpmath.workdps(dps + 10):
        v = mpmath.mpf(x) if not isinstance(x, mpmath.mpf) else x
        hi = float(v)
        return hi, float(v - hi)


def value(hi, lo, dps=50):
    """The exact value of hi + lo as an mpmath number (at ``dps`` digits, enough for any pair)."""
    import mpmath
    with mpmath.workdps(dps):
        return mpmath.mpf(hi) + mpmath.mpf(lo)


def squared_norm(x):
    """Σ_k x_k² over the last axis of the double array x as a double-double (hi, lo) of arrays:
    Dekker's TwoProduct by Veltkamp's splitting and Knuth's TwoSum in numpy, to about 2⁻¹⁰⁴ of the
    sum, the same bits on any machine (no fused multiply-add, no long double).  What a constant of
    the motion such as r² moved by in a double step can be read from it (scripts/studies/brouwer_step_bias.py)."""
    x = np.asarray(x, dtype=np.float64)
    c = 134217729.0 * x                     # 2²⁷ + 1
    xh = c - (c - x)
    xl = x - xh
    p = x * x
    e = ((xh * xh - p) + 2.0 * xh * xl) + xl * xl
    hi, lo = p[..., 0], e[..., 0]
    for k in range(1, x.shape[-1]):
        s = hi + p[..., k]
        t = s - hi
        lo = lo + (((hi - (s - t)) + (p[..., k] - t)) + e[..., k])
        hi = s
    s = hi + lo
    return s, lo - (s - hi)
