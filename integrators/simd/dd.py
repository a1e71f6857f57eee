"""Double-double lanes: W double-doubles are two <W x double> vectors, hi and lo (:class:`DDVec`); in
memory an element of a :class:`DDLanePtr` is 2W doubles, its W high parts then its W low parts.  The
arithmetic is integrators/ddouble.py's own (dd_add, dd_mul, dd_div … written with + − × and
``fma``): given vectors, those operations are the packed instructions of integrators.simd's values
and ``llvm.fma.vWf64``, so a lane's bits are the scalar double-double path's.  What branches (√,
|x|, comparisons) is written here with selects; the transcendental functions and powers run lane by
lane through the scalar code."""
from __future__ import annotations

import operator

import numpy as np
from numba import njit, types
from numba.extending import overload

from .. import ddouble as _ddmod
from ..ddouble import DDType, dd
from .lanetypes import DDVec, _real, Vec
from .pointers import _ddv, ddv
from .values import _vget, _vset
from .masks import mand, mnot, mor, _vsel


def _ddv_operands(a, b):
    """The width when (a, b) is a double-double lane operation: one of them W double-doubles, or a
    double-double scalar beside a Vec; the other a number, Vec, double-double or DDVec."""
    kinds = (DDVec, DDType, Vec)
    if not all(isinstance(t, kinds) or (_real(t) and not isinstance(t, types.Boolean)) for t in (a, b)):
        return None
    if not (isinstance(a, DDVec) or isinstance(b, DDVec) or
            (isinstance(a, DDType) and isinstance(b, Vec)) or (isinstance(a, Vec) and isinstance(b, DDType))):
        return None
    ws = {t.W for t in (a, b) if isinstance(t, (DDVec, Vec))}
    return ws.pop() if len(ws) == 1 else None


def _dd_like(t):
    return isinstance(t, (DDVec, DDType))


def _ddv_operator(op, fn, fn_d=None):
    """``op`` on double-double lanes with the scalar path's choice of algorithm: where the scalar code
    takes a double (fn_d: dd_add_d, dd_mul_d) a lane takes the same (a number or a Vec); elsewhere
    both operands as double-doubles (fn)."""
    @overload(op, inline="never")
    def impl(a, b):
        W = _ddv_operands(a, b)
        if W is None:
            return None
        like = 0 if isinstance(a, (DDVec, Vec)) else 1          # the operand that gives the width
        if fn_d is not None and _dd_like(a) and not _dd_like(b):
            if like == 0:
                return lambda a, b: fn_d(_ddv(a, a), b)
            return lambda a, b: fn_d(_ddv(a, b), b)
        if fn_d is not None and op in (operator.add, operator.mul) and not _dd_like(a) and _dd_like(b):
            if like == 0:
                return lambda a, b: fn_d(_ddv(b, a), a)
            return lambda a, b: fn_d(_ddv(b, b), a)
        if like == 0:
            return lambda a, b: fn(_ddv(a, a), _ddv(b, a))
        return lambda a, b: fn(_ddv(a, b), _ddv(b, b))
    return impl


def _v_lt(a, b):
    return mor(a.hi < b.hi, mand(a.hi == b.hi, a.lo < b.lo))


def _v_eq(a, b):
    return mand(a.hi == b.hi, a.lo == b.lo)


def _v_sub_d(a, b):
    return _ddmod.dd_add_d(a, -b)


def _v_gt(a, b):
    return _v_lt(b, a)


def _v_le(a, b):
    return mnot(_v_lt(b, a))


def _v_ge(a, b):
    return mnot(_v_lt(a, b))


def _v_ne(a, b):
    return mnot(_v_eq(a, b))


def _register_ddv_operators():
    from numba import njit
    jit = dict(cache=True, error_model="numpy")
    fns = {f.__name__: njit(**jit)(f) for f in (_v_lt, _v_eq, _v_gt, _v_le, _v_ge, _v_ne, _v_sub_d)}
    globals().update(fns)
    D = _ddmod
    _ddv_operator(operator.add, D.dd_add, D.dd_add_d)
    _ddv_operator(operator.sub, D.dd_sub, fns["_v_sub_d"])
    _ddv_operator(operator.mul, D.dd_mul, D.dd_mul_d)
    _ddv_operator(operator.truediv, D.dd_div)
    for op, name in ((operator.lt, "_v_lt"), (operator.gt, "_v_gt"), (operator.le, "_v_le"),
                     (operator.ge, "_v_ge"), (operator.eq, "_v_eq"), (operator.ne, "_v_ne")):
        _ddv_operator(op, fns[name])


_register_ddv_operators()


@overload(operator.neg, inline="never")
def _ddv_neg(a):
    if isinstance(a, DDVec):
        return lambda a: ddv(-a.hi, -a.lo)


@njit(cache=True, error_model="numpy")
def _ddv_abs_impl(a):
    neg = mor(a.hi < 0.0, mand(a.hi == 0.0, a.lo < 0.0))
    return ddv(_vsel(neg, -a.hi, a.hi), _vsel(neg, -a.lo, a.lo))


@njit(cache=True, error_model="numpy")
def _ddv_sqrt_impl(a):
    """dd_sqrt's two branches in every lane, then each lane's own (its bits the scalar path's)."""
    x = 1.0 / np.sqrt(a.hi)
    ax = a.hi * x
    r = _ddmod.dd_add_d(ddv(ax, 0.0), _ddmod.dd_sub(a, _ddmod.dd_sqr(ddv(ax, 0.0))).hi * (x * 0.5))
    small = a.hi <= 0.0
    return ddv(_vsel(small, np.sqrt(a.hi), r.hi), _vsel(small, 0.0, r.lo))


for _target in (abs, np.abs):
    @overload(_target, inline="never")
    def _ddv_abs_ov(a):
        if isinstance(a, DDVec):
            return lambda a: _ddv_abs_impl(a)


@overload(np.sqrt, inline="never")
def _ddv_sqrt_ov(a):
    if isinstance(a, DDVec):
        return lambda a: _ddv_sqrt_impl(a)


@overload(np.isfinite, inline="never")
def _ddv_isfinite(a):
    if isinstance(a, DDVec):
        return lambda a: mand(np.isfinite(a.hi), np.isfinite(a.lo))


def _ddv_per_lane_unary(fn):
    """fn on W double-doubles, lane by lane through the scalar double-double code."""
    @overload(fn)
    def ov(a):
        if isinstance(a, DDVec):
            W = a.W

            def impl(a):
                hi, lo = a.hi, a.lo
                for l in range(W):
                    r = fn(dd(_vget(a.hi, l), _vget(a.lo, l)))
                    hi = _vset(hi, l, r.hi)
                    lo = _vset(lo, l, r.lo)
                return ddv(hi, lo)
            return impl


for _fn in (np.exp, np.log, np.sin, np.cos, np.tan, np.arcsin, np.arccos, np.arctan, np.sinh, np.cosh, np.tanh,
            np.sign):
    _ddv_per_lane_unary(_fn)


def _ddv_per_lane_binary(fn):
    @overload(fn)
    def ov(a, b):
        W = _ddv_operands(a, b)
        if W is None:
            return None

        def lanewise(x, y):
            hi, lo = x.hi, x.lo
            for l in range(W):
                r = fn(dd(_vget(x.hi, l), _vget(x.lo, l)), dd(_vget(y.hi, l), _vget(y.lo, l)))
                hi = _vset(hi, l, r.hi)
                lo = _vset(lo, l, r.lo)
            return ddv(hi, lo)
        lanewise = njit(cache=False, error_model="numpy")(lanewise)
        if isinstance(a, (DDVec, Vec)):
            return lambda a, b: lanewise(_ddv(a, a), _ddv(b, a))
        return lambda a, b: lanewise(_ddv(a, b), _ddv(b, b))


for _fn in (np.arctan2, np.power, operator.pow):
    _ddv_per_lane_binary(_fn)
