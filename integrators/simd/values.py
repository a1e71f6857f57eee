"""Values: arithmetic, comparisons and the functions LLVM has no exact vector form for (lane by lane
through numba's scalar code) on :class:`Vec`; and what the scalar and complex paths need as well
(:func:`raw`, :func:`re`, :func:`is_complex`, :func:`step_measure`) (integrators.simd)."""
from __future__ import annotations

import operator

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from ..ddouble import DDType
from .lanetypes import _as_vec, DDLanePtr, DDVec, LanePtr, Mask, _real, _splat, Vec, _width
from .pointers import _ddp_raw


def _binary(op, fop):
    @intrinsic
    def vop(typingctx, a, b):
        W = _width(a, b)
        if W is None or not all(isinstance(t, Vec) or _real(t) for t in (a, b)):
            return None

        def codegen(context, builder, sig, args):
            x = _as_vec(context, builder, sig.args[0], args[0], W)
            y = _as_vec(context, builder, sig.args[1], args[1], W)
            return getattr(builder, fop)(x, y)
        return Vec(W)(a, b), codegen

    @overload(op, inline="never")
    def ov(a, b):
        if (isinstance(a, Vec) or isinstance(b, Vec)) and all(isinstance(t, Vec) or _real(t) for t in (a, b)):
            return lambda a, b: vop(a, b)
    return vop


_binary(operator.add, "fadd")
_binary(operator.sub, "fsub")
_binary(operator.mul, "fmul")
_binary(operator.truediv, "fdiv")
_binary(operator.iadd, "fadd")          # (x += y on Vecs: the double-double algorithms use it)
_binary(operator.isub, "fsub")
_binary(operator.imul, "fmul")


def _compare(op, code):
    @intrinsic
    def vcmp(typingctx, a, b):
        W = _width(a, b)
        if W is None or not all(isinstance(t, Vec) or _real(t) for t in (a, b)):
            return None

        def codegen(context, builder, sig, args):
            x = _as_vec(context, builder, sig.args[0], args[0], W)
            y = _as_vec(context, builder, sig.args[1], args[1], W)
            return builder.fcmp_ordered(code, x, y) if code != "!=" else builder.fcmp_unordered(code, x, y)
        return Mask(W)(a, b), codegen

    @overload(op, inline="never")
    def ov(a, b):
        if (isinstance(a, Vec) or isinstance(b, Vec)) and all(isinstance(t, Vec) or _real(t) for t in (a, b)):
            return lambda a, b: vcmp(a, b)


# Python's float comparisons: ordered (false on NaN) except !=, which is true on NaN
_compare(operator.lt, "<")
_compare(operator.le, "<=")
_compare(operator.gt, ">")
_compare(operator.ge, ">=")
_compare(operator.eq, "==")
_compare(operator.ne, "!=")


@intrinsic
def _vneg(typingctx, a):
    if not isinstance(a, Vec):
        return None

    def codegen(context, builder, sig, args):
        return builder.fneg(args[0])
    return a(a), codegen


@overload(operator.neg, inline="never")
def _neg(a):
    if isinstance(a, Vec):
        return lambda a: _vneg(a)


def _unary_intrinsic(name):
    @intrinsic
    def vf(typingctx, a):
        if not isinstance(a, Vec):
            return None

        def codegen(context, builder, sig, args):
            fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(args[0].type, [args[0].type]),
                                                f"llvm.{name}.v{sig.args[0].W}f64")
            return builder.call(fn, [args[0]])
        return a(a), codegen
    return vf


_vsqrt = _unary_intrinsic("sqrt")
_vfabs = _unary_intrinsic("fabs")


@overload(np.sqrt, inline="never")
def _sqrt(a):
    if isinstance(a, Vec):
        return lambda a: _vsqrt(a)


@overload(abs, inline="never")
def _abs(a):
    if isinstance(a, Vec):
        return lambda a: _vfabs(a)


@overload(np.abs, inline="never")
def _npabs(a):
    if isinstance(a, Vec):
        return lambda a: _vfabs(a)


@intrinsic
def _vget(typingctx, v, lane):
    if not isinstance(v, Vec):
        return None

    def codegen(context, builder, sig, args):
        return builder.extract_element(args[0], args[1])
    return types.float64(v, lane), codegen


@intrinsic
def _vset(typingctx, v, lane, x):
    if not isinstance(v, Vec):
        return None

    def codegen(context, builder, sig, args):
        return builder.insert_element(args[0], context.cast(builder, args[2], sig.args[2], types.float64), args[1])
    return v(v, lane, x), codegen


def _per_lane_unary(fn):
    """fn on a Vec, lane by lane, through numba's scalar implementation (the scalar path's bits)."""
    @overload(fn)
    def ov(a):
        if isinstance(a, Vec):
            W = a.W

            def impl(a):
                out = a
                for l in range(W):
                    out = _vset(out, l, fn(_vget(a, l)))
                return out
            return impl


for _fn in (np.exp, np.log, np.sin, np.cos, np.tan, np.arcsin, np.arccos, np.arctan, np.sinh, np.cosh, np.tanh,
            np.sign, np.log1p, np.expm1):
    _per_lane_unary(_fn)


@intrinsic
def _vec_like(typingctx, x, v):
    """x as a Vec of v's width (a real number goes to every lane)."""
    W = _width(x, v)
    if W is None or not (isinstance(x, Vec) or _real(x)):
        return None

    def codegen(context, builder, sig, args):
        return _as_vec(context, builder, sig.args[0], args[0], W)
    return Vec(W)(x, v), codegen


def _per_lane_binary(fn):
    @overload(fn)
    def ov(a, b):
        if (isinstance(a, Vec) or isinstance(b, Vec)) and all(isinstance(t, Vec) or _real(t) for t in (a, b)):
            W = _width(a, b)
            if _real(b):                # a scalar exponent stays what it is (int or float), as on the scalar path
                def impl(a, b):
                    out = a
                    for l in range(W):
                        out = _vset(out, l, fn(_vget(a, l), b))
                    return out
                return impl

            def impl(a, b):
                x, y = _vec_like(a, b), _vec_like(b, a)
                out = x
                for l in range(W):
                    out = _vset(out, l, fn(_vget(x, l), _vget(y, l)))
                return out
            return impl


for _fn in (np.arctan2, np.power, operator.pow):
    _per_lane_binary(_fn)


@intrinsic
def _misfinite(typingctx, a):
    if not isinstance(a, Vec):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        fabs = cgutils.get_or_insert_function(builder.module, ir.FunctionType(args[0].type, [args[0].type]),
                                              f"llvm.fabs.v{W}f64")
        inf = _splat(builder, ir.Constant(ir.DoubleType(), float("inf")), W)
        return builder.fcmp_ordered("!=", builder.call(fabs, [args[0]]), inf)
    return Mask(a.W)(a), codegen


@overload(np.isfinite, inline="never")
def _isfinite(a):
    if isinstance(a, Vec):
        return lambda a: _misfinite(a)


# -- what the scalar and complex paths need as well ---------------------------------------------

def raw(p):
    """The plain pointer under a lane pointer (what a compiled point function takes)."""


def re(x):
    """The real part (x itself for a real value or a Vec)."""


def is_complex(p):
    """Whether a pointer's data are complex (a compile-time constant)."""


def step_measure(r, scale, cs):
    """|r|/scale; for a complex-step value also |Im r|/(cs·scale), the derivative's own measure."""


def dithers(p):
    """Whether a pointer's data are plain doubles (a compile-time constant): the unknowns whose Newton
    iterates are rounded to a grid (:func:`integrators.kernel.newton._update`); not complex-step
    values, not double-doubles."""


@intrinsic
def _lp_raw(typingctx, p):
    if not isinstance(p, LanePtr):
        return None

    def codegen(context, builder, sig, args):
        return args[0]
    return types.CPointer(p.dtype)(p), codegen


@overload(raw, inline="never")
def _raw(p):
    if isinstance(p, DDLanePtr):
        return lambda p: _ddp_raw(p)
    if isinstance(p, LanePtr):
        return lambda p: _lp_raw(p)
    if isinstance(p, types.CPointer):
        return lambda p: p


@overload(re, inline="never")
def _re(x):
    if isinstance(x, types.Complex):
        return lambda x: x.real
    if isinstance(x, (DDType, DDVec)):
        return lambda x: x.hi            # (where a double is wanted: pivot choice, the domain test)
    return lambda x: x


@overload(is_complex, inline="never")
def _is_complex(p):
    c = isinstance(p.dtype, types.Complex)
    return lambda p: c


@overload(dithers, inline="never")
def _dithers(p):
    c = isinstance(p, (LanePtr, types.CPointer)) and p.dtype == types.float64
    return lambda p: c


@overload(step_measure, inline="never")
def _step_measure(r, scale, cs):
    if isinstance(r, (DDType, DDVec)):
        return lambda r, scale, cs: abs(r.hi) / scale
    if isinstance(r, types.Complex):
        return lambda r, scale, cs: max(abs(r.real) / scale, abs(r.imag) / (cs * scale))
    return lambda r, scale, cs: abs(r) / scale
