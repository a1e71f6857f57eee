"""Points in SIMD lanes for numba: a vector type, pointers that load and store it, and masks.

The step kernel is written once against a handful of functions — :func:`ld`, :func:`st`,
:func:`sel`, :func:`anyl`, :func:`lget`, :func:`lset`, :func:`nlanes` — and arithmetic operators.
Given plain pointers (``CPointer(float64)`` or ``complex128``) they are ordinary scalar loads,
stores and ``a if m else b``: that is the scalar path, one point at a time.  Given a
:class:`LanePtr` (W points interleaved, lane index innermost) the same source handles W points in
lockstep: a value is an LLVM ``<W x double>`` (:class:`Vec`), ``+ − × ÷``, ``sqrt`` and ``abs``
are packed instructions, comparisons give a per-lane :class:`Mask`, and every decision is a
select.  LLVM would not vectorise the scalar loops over lanes on its own (it cannot prove that
numba's pointers do not alias), so the vector type is explicit.

Bits: packed IEEE add, subtract, multiply, divide and square root round each lane exactly as the
scalar instruction does, and there is no fused multiply–add (no fastmath, no contraction).
Functions LLVM has no exact vector form for (``exp``, ``log``, ``sin``, ``pow`` …) are called lane
by lane through numba's own scalar implementation.  So a lane's value is bitwise the scalar path's
(tests/test_lanes.py checks it for every admissible pair).
"""
from __future__ import annotations

import operator

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import models
from numba.extending import intrinsic, make_attribute_wrapper, overload, register_model

from . import ddouble as _ddmod
from .ddouble import DDType, as_dd, dd, dd_t


def _is_dd_ptr(p):
    return isinstance(p, types.CPointer) and isinstance(p.dtype, DDType)


class Vec(types.Type):
    """W float64 values, one per lane."""

    def __init__(self, W):
        self.W = W
        super().__init__(name=f"Vec{W}")


class Mask(types.Type):
    """W booleans, one per lane."""

    def __init__(self, W):
        self.W = W
        super().__init__(name=f"Mask{W}")


class LanePtr(types.Type):
    """A pointer to W-lane interleaved data: logical element i of lane l lives at i·W + l."""

    def __init__(self, dtype, W):
        self.dtype, self.W = dtype, W
        super().__init__(name=f"LanePtr({dtype}, {W})")


@register_model(Vec)
class _VecModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, ir.VectorType(ir.DoubleType(), fe_type.W))


@register_model(Mask)
class _MaskModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, ir.VectorType(ir.IntType(1), fe_type.W))


@register_model(LanePtr)
class _LanePtrModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, dmm.lookup(fe_type.dtype).get_value_type().as_pointer())


def _splat(builder, value, W):
    vt = ir.VectorType(value.type, W)
    v = builder.insert_element(ir.Constant(vt, ir.Undefined), value, ir.Constant(ir.IntType(32), 0))
    zeros = ir.Constant(ir.VectorType(ir.IntType(32), W), [0] * W)
    return builder.shuffle_vector(v, ir.Constant(vt, ir.Undefined), zeros)


def _as_vec(context, builder, ty, val, W):
    """A Vec or a real number as a <W x double>."""
    if isinstance(ty, Vec):
        return val
    return _splat(builder, context.cast(builder, val, ty, types.float64), W)


def _intp(context, builder, ty, val):
    return context.cast(builder, val, ty, types.intp)


def _W(W):
    return ir.Constant(ir.IntType(64), W)


def _width(*tys):
    ws = {t.W for t in tys if isinstance(t, (Vec, Mask, LanePtr))}
    return ws.pop() if len(ws) == 1 else None


def _real(t):
    return isinstance(t, (types.Float, types.Integer, types.Boolean)) and not isinstance(t, types.Complex)


# -- pointers ----------------------------------------------------------------------------------


@intrinsic
def _at(typingctx, base, off):
    """Pointer to element ``off`` (flat, C order) of an array, or ``off`` elements past a pointer."""
    if isinstance(base, types.Array):
        def codegen(context, builder, sig, args):
            ary = context.make_array(sig.args[0])(context, builder, args[0])
            return builder.gep(ary.data, [args[1]])
        return types.CPointer(base.dtype)(base, off), codegen
    if isinstance(base, types.CPointer):
        def codegen(context, builder, sig, args):
            return builder.gep(args[0], [args[1]])
        return base(base, off), codegen

def _dd_proto(proto) -> bool:
    """Whether ``proto`` asks for double-double values: the marker ``(0.0,) * W`` (floats; W = 1 the
    scalar double-double path, W > 1 double-double lanes), where a lane count of doubles is
    ``(0,) * W`` (integers; a nested tuple would not pass numba's parallel loop)."""
    return isinstance(proto, types.BaseTuple) and len(proto) >= 1 and \
        all(isinstance(t, types.Float) for t in proto.types)


@intrinsic
def lanes(typingctx, base, off, proto):
    """A lane pointer to element ``off`` of ``base`` (array or pointer), W = len(proto), with
    offsets counted in logical elements (× W).  W = 1 gives a plain pointer: the scalar path.  With
    the double-double marker ``(0.0,)`` a float64 array or a double-double pointer gives a
    pointer to double-doubles (element i at doubles 2i, 2i + 1); other arrays (the pivots) stay plain."""
    W = len(proto) if isinstance(proto, types.BaseTuple) else None
    if W is None:
        return None
    dtype = base.dtype
    if W > 1 and _dd_proto(proto) and dtype == types.float64 and not isinstance(base, DDLanePtr):
        rt = DDLanePtr(W)

        def codegen_ddl(context, builder, sig, args):
            if isinstance(sig.args[0], types.Array):
                data = context.make_array(sig.args[0])(context, builder, args[0]).data
            else:
                data = args[0]
            return builder.gep(data, [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(2 * W))])
        return rt(base, off, proto), codegen_ddl
    if _dd_proto(proto) and (dtype == types.float64 or isinstance(dtype, DDType)):
        rt = types.CPointer(dd_t)

        def codegen_dd(context, builder, sig, args):
            if isinstance(sig.args[0], types.Array):
                data = context.make_array(sig.args[0])(context, builder, args[0]).data
                two = builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(2))
                return builder.bitcast(builder.gep(data, [two]), context.get_value_type(rt))
            return builder.gep(args[0], [_intp(context, builder, sig.args[1], args[1])])
        return rt(base, off, proto), codegen_dd
    if W > 1 and dtype not in (types.float64, types.int64):
        return None                             # lanes of doubles (values) and of int64 (pivots) only
    rt = types.CPointer(dtype) if W == 1 else LanePtr(dtype, W)

    def codegen(context, builder, sig, args):
        if isinstance(sig.args[0], types.Array):
            data = context.make_array(sig.args[0])(context, builder, args[0]).data
        else:
            data = args[0]
        return builder.gep(data, [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(W))])
    return rt(base, off, proto), codegen


@intrinsic
def _lp_at(typingctx, p, off):
    if not isinstance(p, LanePtr):
        return None

    def codegen(context, builder, sig, args):
        return builder.gep(args[0], [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(sig.args[0].W))])
    return p(p, off), codegen


@intrinsic
def _lp_load(typingctx, p, i):
    if not isinstance(p, LanePtr):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        ptr = builder.gep(args[0], [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(W))])
        vp = builder.bitcast(ptr, ir.VectorType(ir.DoubleType(), W).as_pointer())
        return builder.load(vp, align=8)
    return Vec(p.W)(p, i), codegen


@intrinsic
def _lp_store(typingctx, p, i, v):
    if not isinstance(p, LanePtr) or not (isinstance(v, Vec) or _real(v)):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        ptr = builder.gep(args[0], [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(W))])
        vp = builder.bitcast(ptr, ir.VectorType(ir.DoubleType(), W).as_pointer())
        builder.store(_as_vec(context, builder, sig.args[2], args[2], W), vp, align=8)
        return context.get_dummy_value()
    return types.void(p, i, v), codegen


@intrinsic
def _lp_elem(typingctx, p, i, lane):
    """Pointer to one lane's element (scalar access to lane data)."""
    if not isinstance(p, LanePtr):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        idx = builder.add(builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(W)),
                          _intp(context, builder, sig.args[2], args[2]))
        return builder.gep(args[0], [idx])
    return types.CPointer(p.dtype)(p, i, lane), codegen


def plain(proto):
    """The lane prototype of the real bookkeeping beside ``proto``'s values: ``proto`` itself, or
    (0,) for the double-double marker (flags stay doubles)."""


@overload(plain, inline="never")
def _plain(proto):
    if _dd_proto(proto):
        ints = (0,) * len(proto)
        return lambda proto: ints
    return lambda proto: proto


def elem(a, i, j):
    """a[i, j] of a state array: a number, or a double-double from an array with a last axis of 2."""


def elem3(a, i, j, k):
    """a[i, j, k] of a state array (as :func:`elem`)."""


def put(a, i, j, v):
    """a[i, j] = v of a state array (a double-double array keeps both parts)."""


def put3(a, i, j, k, v):
    """a[i, j, k] = v of a state array (as :func:`put`)."""


@overload(elem, inline="never")
def _elem(a, i, j):
    if a.ndim == 3:
        return lambda a, i, j: dd(a[i, j, 0], a[i, j, 1])
    return lambda a, i, j: a[i, j]


@overload(elem3, inline="never")
def _elem3(a, i, j, k):
    if a.ndim == 4:
        return lambda a, i, j, k: dd(a[i, j, k, 0], a[i, j, k, 1])
    return lambda a, i, j, k: a[i, j, k]


@overload(put, inline="never")
def _put(a, i, j, v):
    if a.ndim == 3:
        def impl_dd(a, i, j, v):
            x = as_dd(v)
            a[i, j, 0] = x.hi
            a[i, j, 1] = x.lo
        return impl_dd

    def impl(a, i, j, v):
        a[i, j] = v
    return impl


@overload(put3, inline="never")
def _put3(a, i, j, k, v):
    if a.ndim == 4:
        def impl_dd(a, i, j, k, v):
            x = as_dd(v)
            a[i, j, k, 0] = x.hi
            a[i, j, k, 1] = x.lo
        return impl_dd

    def impl(a, i, j, k, v):
        a[i, j, k] = v
    return impl


def ld(p, i):
    """Element i (all lanes) of p."""


def st(p, i, v):
    """Element i of p = v (a scalar goes to every lane)."""


def lget(p, i, lane):
    """Element i of one lane, as a scalar."""


def lset(p, i, lane, v):
    """Element i of one lane = v."""


def nlanes(p):
    """The lane count W of a pointer (1 for a plain pointer)."""


def at(p, off):
    """p advanced by ``off`` logical elements."""


@overload(ld, inline="never")
def _ld(p, i):
    if isinstance(p, DDLanePtr):
        return lambda p, i: _ddp_load(p, i)
    if isinstance(p, LanePtr):
        return lambda p, i: _lp_load(p, i)
    if isinstance(p, types.CPointer):
        return lambda p, i: p[i]


@overload(st, inline="never")
def _st(p, i, v):
    if isinstance(p, DDLanePtr):
        def impl_ddl(p, i, v):
            x = _ddv(v, p)
            _ddp_store(p, i, x.hi, x.lo)
        return impl_ddl
    if isinstance(p, LanePtr) and isinstance(v, DDVec):
        return lambda p, i, v: _lp_store(p, i, v.hi)       # a double-double into real bookkeeping: its double
    if isinstance(p, LanePtr):
        return lambda p, i, v: _lp_store(p, i, v)
    if _is_dd_ptr(p):
        def impl_dd(p, i, v):
            p[i] = as_dd(v)
        return impl_dd
    if isinstance(p, types.CPointer) and isinstance(v, DDType):
        def impl_round(p, i, v):       # a double-double into real bookkeeping: its double
            p[i] = v.hi
        return impl_round
    if isinstance(p, types.CPointer):
        def impl(p, i, v):
            p[i] = v
        return impl


@overload(lget, inline="never")
def _lget(p, i, lane):
    if isinstance(p, DDLanePtr):
        W = p.W
        return lambda p, i, lane: dd(_ddp_elem(p, i, lane)[0], _ddp_elem(p, i, lane)[W])
    if isinstance(p, LanePtr):
        return lambda p, i, lane: _lp_elem(p, i, lane)[0]
    if isinstance(p, types.CPointer):
        return lambda p, i, lane: p[i]


@overload(lset, inline="never")
def _lset(p, i, lane, v):
    if isinstance(p, DDLanePtr):
        W = p.W

        def impl_ddl(p, i, lane, v):
            x = as_dd(v)
            e = _ddp_elem(p, i, lane)
            e[0] = x.hi
            e[W] = x.lo
        return impl_ddl
    if isinstance(p, LanePtr) and isinstance(v, DDType):
        def impl_lround(p, i, lane, v):
            _lp_elem(p, i, lane)[0] = v.hi
        return impl_lround
    if isinstance(p, LanePtr):
        def impl(p, i, lane, v):
            _lp_elem(p, i, lane)[0] = v
        return impl
    if _is_dd_ptr(p):
        def impl_dd(p, i, lane, v):
            p[i] = as_dd(v)
        return impl_dd
    if isinstance(p, types.CPointer) and isinstance(v, DDType):
        def impl_round(p, i, lane, v):
            p[i] = v.hi
        return impl_round
    if isinstance(p, types.CPointer):
        def impl(p, i, lane, v):
            p[i] = v
        return impl


def ldi(p, i):
    """Element i (all lanes) of an int64 pointer, as doubles (a Vec at W > 1): row indices that
    compare and select like values."""


def sti(p, i, v):
    """Element i of an int64 pointer = v (doubles holding integers; a Vec goes lane by lane)."""


@intrinsic
def _lpi_load(typingctx, p, i):
    if not (isinstance(p, LanePtr) and p.dtype == types.int64):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        ptr = builder.gep(args[0], [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(W))])
        vp = builder.bitcast(ptr, ir.VectorType(ir.IntType(64), W).as_pointer())
        return builder.sitofp(builder.load(vp, align=8), ir.VectorType(ir.DoubleType(), W))
    return Vec(p.W)(p, i), codegen


@intrinsic
def _lpi_store(typingctx, p, i, v):
    if not (isinstance(p, LanePtr) and p.dtype == types.int64 and (isinstance(v, Vec) or _real(v))):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        ptr = builder.gep(args[0], [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(W))])
        vp = builder.bitcast(ptr, ir.VectorType(ir.IntType(64), W).as_pointer())
        vec = _as_vec(context, builder, sig.args[2], args[2], W)
        builder.store(builder.fptosi(vec, ir.VectorType(ir.IntType(64), W)), vp, align=8)
        return context.get_dummy_value()
    return types.void(p, i, v), codegen


@overload(ldi, inline="never")
def _ldi(p, i):
    if isinstance(p, LanePtr) and p.dtype == types.int64:
        return lambda p, i: _lpi_load(p, i)
    if isinstance(p, types.CPointer) and p.dtype == types.int64:
        return lambda p, i: float(p[i])


@overload(sti, inline="never")
def _sti(p, i, v):
    if isinstance(p, LanePtr) and p.dtype == types.int64:
        return lambda p, i, v: _lpi_store(p, i, v)
    if isinstance(p, types.CPointer) and p.dtype == types.int64:
        def impl(p, i, v):
            p[i] = int(v)
        return impl


@overload(nlanes, inline="never")
def _nlanes(p):
    if isinstance(p, (LanePtr, DDLanePtr)):
        W = p.W
        return lambda p: W
    if isinstance(p, types.CPointer):
        return lambda p: 1


# -- values ------------------------------------------------------------------------------------

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


# -- masks ---------------------------------------------------------------------------------------

def sel(m, a, b):
    """a where m, else b (per lane)."""


def mand(a, b):
    """a and b (per lane)."""


def mor(a, b):
    """a or b (per lane)."""


def mnot(a):
    """not a (per lane)."""


def anyl(m):
    """Whether any lane of m is true."""


def lmask(m, lane):
    """One lane of a mask, as a bool."""


@intrinsic
def _vsel(typingctx, m, a, b):
    W = _width(m, a, b)
    if W is None or not isinstance(m, (Mask, types.Boolean)):
        return None
    if not all(isinstance(t, Vec) or _real(t) for t in (a, b)):
        return None

    def codegen(context, builder, sig, args):
        mm = args[0] if isinstance(sig.args[0], Mask) else \
            _splat(builder, context.cast(builder, args[0], sig.args[0], types.boolean), W)
        return builder.select(mm, _as_vec(context, builder, sig.args[1], args[1], W),
                              _as_vec(context, builder, sig.args[2], args[2], W))
    return Vec(W)(m, a, b), codegen


@overload(sel, inline="never")
def _sel(m, a, b):
    if isinstance(a, DDVec) or isinstance(b, DDVec) or (isinstance(m, Mask) and (_is_dd_scalar(a) or _is_dd_scalar(b))):
        if isinstance(a, DDVec):
            def impl_ddv(m, a, b):
                x, y = a, _ddv(b, a)
                return ddv(_vsel(m, x.hi, y.hi), _vsel(m, x.lo, y.lo))
            return impl_ddv
        if isinstance(b, DDVec):
            def impl_ddv2(m, a, b):
                x, y = _ddv(a, b), b
                return ddv(_vsel(m, x.hi, y.hi), _vsel(m, x.lo, y.lo))
            return impl_ddv2
        if isinstance(m, Mask):
            def impl_ddv3(m, a, b):
                x, y = _ddv(a, m), _ddv(b, m)
                return ddv(_vsel(m, x.hi, y.hi), _vsel(m, x.lo, y.lo))
            return impl_ddv3
    if isinstance(m, Mask) or isinstance(a, Vec) or isinstance(b, Vec):
        return lambda m, a, b: _vsel(m, a, b)
    if isinstance(m, types.Boolean) and (isinstance(a, DDType) or isinstance(b, DDType)):
        return lambda m, a, b: as_dd(a) if m else as_dd(b)
    if isinstance(m, types.Boolean):
        return lambda m, a, b: a if m else b


def _mask_binary(fn, op):
    @intrinsic
    def mop(typingctx, a, b):
        W = _width(a, b)
        if W is None:
            return None

        def codegen(context, builder, sig, args):
            xs = [v if isinstance(t, Mask) else _splat(builder, context.cast(builder, v, t, types.boolean), W)
                  for t, v in zip(sig.args, args)]
            return getattr(builder, op)(*xs)
        return Mask(W)(a, b), codegen

    @overload(fn, inline="never")
    def ov(a, b):
        if isinstance(a, Mask) or isinstance(b, Mask):
            return lambda a, b: mop(a, b)
        if op == "and_":
            return lambda a, b: a and b
        return lambda a, b: a or b


_mask_binary(mand, "and_")
_mask_binary(mor, "or_")


@intrinsic
def _mnot(typingctx, a):
    if not isinstance(a, Mask):
        return None

    def codegen(context, builder, sig, args):
        return builder.not_(args[0])
    return a(a), codegen


@overload(mnot, inline="never")
def _mnot_ov(a):
    if isinstance(a, Mask):
        return lambda a: _mnot(a)
    if isinstance(a, types.Boolean):
        return lambda a: not a


@intrinsic
def _many(typingctx, m):
    if not isinstance(m, Mask):
        return None

    def codegen(context, builder, sig, args):
        bits = builder.bitcast(args[0], ir.IntType(sig.args[0].W))
        return builder.icmp_unsigned("!=", bits, ir.Constant(ir.IntType(sig.args[0].W), 0))
    return types.boolean(m), codegen


@overload(anyl, inline="never")
def _anyl(m):
    if isinstance(m, Mask):
        return lambda m: _many(m)
    if isinstance(m, types.Boolean):
        return lambda m: m


@intrinsic
def _mget(typingctx, m, lane):
    if not isinstance(m, Mask):
        return None

    def codegen(context, builder, sig, args):
        return builder.extract_element(args[0], args[1])
    return types.boolean(m, lane), codegen


@overload(lmask, inline="never")
def _lmask(m, lane):
    if isinstance(m, Mask):
        return lambda m, lane: _mget(m, lane)
    if isinstance(m, types.Boolean):
        return lambda m, lane: m


@overload(at, inline="never")
def _at_ov(p, off):
    if isinstance(p, DDLanePtr):
        return lambda p, off: _ddp_at(p, off)
    if isinstance(p, LanePtr):
        return lambda p, off: _lp_at(p, off)
    if isinstance(p, types.CPointer):
        return lambda p, off: _at(p, off)


# -- what the scalar and complex paths need as well ---------------------------------------------

def raw(p):
    """The plain pointer under a lane pointer (what a compiled point function takes)."""


def re(x):
    """The real part (x itself for a real value or a Vec)."""


def is_complex(p):
    """Whether a pointer's data are complex (a compile-time constant)."""


def step_measure(r, scale, cs):
    """|r|/scale; for a complex-step value also |Im r|/(cs·scale), the derivative's own measure."""


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


@overload(step_measure, inline="never")
def _step_measure(r, scale, cs):
    if isinstance(r, (DDType, DDVec)):
        return lambda r, scale, cs: abs(r.hi) / scale
    if isinstance(r, types.Complex):
        return lambda r, scale, cs: max(abs(r.real) / scale, abs(r.imag) / (cs * scale))
    return lambda r, scale, cs: abs(r) / scale


# -- double-double lanes ---------------------------------------------------------------------------
#
# W double-doubles are two <W x double> vectors, hi and lo (:class:`DDVec`); in memory an element of
# a :class:`DDLanePtr` is 2W doubles, its W high parts then its W low parts.  The arithmetic is
# integrators/ddouble.py's own (dd_add, dd_mul, dd_div … written with + − × and ``fma``): given
# vectors, those operations are the packed instructions above and ``llvm.fma.vWf64``, so a lane's
# bits are the scalar double-double path's.  What branches (√, |x|, comparisons) is written here with
# selects; the transcendental functions and powers run lane by lane through the scalar code.


class DDVec(types.Type):
    """W double-doubles, one per lane."""

    def __init__(self, W):
        self.W = W
        super().__init__(name=f"DDVec{W}")


class DDLanePtr(types.Type):
    """A pointer to W-lane double-double data: element i is doubles [2iW, 2iW + W) (the high
    parts of lanes 0 … W − 1) and [2iW + W, 2iW + 2W) (their low parts)."""

    def __init__(self, W):
        self.W = W
        self.dtype = types.float64
        super().__init__(name=f"DDLanePtr({W})")


@register_model(DDVec)
class _DDVecModel(models.StructModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, [("hi", Vec(fe_type.W)), ("lo", Vec(fe_type.W))])


@register_model(DDLanePtr)
class _DDLanePtrModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, ir.DoubleType().as_pointer())


make_attribute_wrapper(DDVec, "hi", "hi")
make_attribute_wrapper(DDVec, "lo", "lo")


def _is_dd_scalar(t):
    return isinstance(t, DDType)


def _pair(context, builder, W, hi, lo):
    v = cgutils.create_struct_proxy(DDVec(W))(context, builder)
    v.hi, v.lo = hi, lo
    return v._getvalue()


def _dd_vector_form(hi, lo):
    """ddouble.dd(hi, lo) for vectors (a real number goes to every lane)."""
    W = _width(hi, lo)
    if W is None or not all(isinstance(t, Vec) or _real(t) for t in (hi, lo)):
        return None

    def codegen(context, builder, sig, args):
        return _pair(context, builder, W, _as_vec(context, builder, sig.args[0], args[0], W),
                     _as_vec(context, builder, sig.args[1], args[1], W))
    return DDVec(W)(hi, lo), codegen


def _fma_vector_form(a, b, c):
    """ddouble.fma for vectors: llvm.fma.vWf64, each lane a × b + c rounded once."""
    W = _width(a, b, c)
    if W is None or not all(isinstance(t, Vec) or _real(t) for t in (a, b, c)):
        return None

    def codegen(context, builder, sig, args):
        vt = ir.VectorType(ir.DoubleType(), W)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vt, [vt] * 3), f"llvm.fma.v{W}f64")
        return builder.call(fn, [_as_vec(context, builder, t, x, W) for t, x in zip(sig.args, args)])
    return Vec(W)(a, b, c), codegen


_ddmod.VECTOR_FORMS.update(dd=_dd_vector_form, fma=_fma_vector_form)


@intrinsic
def ddv(typingctx, hi, lo):
    """W double-doubles from two Vecs (or reals, to every lane)."""
    return _dd_vector_form(hi, lo)


def _lane_width(t):
    return t.W if isinstance(t, (DDVec, Vec, Mask, DDLanePtr, LanePtr)) else None


@intrinsic
def _splat_dd(typingctx, x, like):
    """A double-double or a real number (low part 0) in every lane of ``like``'s width."""
    W = _lane_width(like)
    if W is None or not (isinstance(x, DDType) or _real(x)):
        return None

    def codegen(context, builder, sig, args):
        if isinstance(sig.args[0], DDType):
            v = cgutils.create_struct_proxy(dd_t)(context, builder, value=args[0])
            return _pair(context, builder, W, _splat(builder, v.hi, W), _splat(builder, v.lo, W))
        hi = _as_vec(context, builder, sig.args[0], args[0], W)
        return _pair(context, builder, W, hi, _splat(builder, ir.Constant(ir.DoubleType(), 0.0), W))
    return DDVec(W)(x, like), codegen


def _ddv(x, like):
    """x as W double-doubles, W the width of ``like``: itself, a double-double or a number in every
    lane, a Vec with zero low parts."""


@overload(_ddv, inline="never")
def _ddv_ov(x, like):
    if isinstance(x, DDVec):
        return lambda x, like: x
    if isinstance(x, Vec):
        return lambda x, like: ddv(x, 0.0)
    if isinstance(x, DDType) or _real(x):
        return lambda x, like: _splat_dd(x, like)


@intrinsic
def _ddp_at(typingctx, p, off):
    if not isinstance(p, DDLanePtr):
        return None

    def codegen(context, builder, sig, args):
        return builder.gep(args[0], [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(2 * sig.args[0].W))])
    return p(p, off), codegen


@intrinsic
def _ddp_raw(typingctx, p):
    if not isinstance(p, DDLanePtr):
        return None

    def codegen(context, builder, sig, args):
        return args[0]
    return types.CPointer(types.float64)(p), codegen


@intrinsic
def _ddp_load(typingctx, p, i):
    if not isinstance(p, DDLanePtr):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        ptr = builder.gep(args[0], [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(2 * W))])
        vt = ir.VectorType(ir.DoubleType(), W).as_pointer()
        hi = builder.load(builder.bitcast(ptr, vt), align=8)
        lo = builder.load(builder.bitcast(builder.gep(ptr, [_W(W)]), vt), align=8)
        return _pair(context, builder, W, hi, lo)
    return DDVec(p.W)(p, i), codegen


@intrinsic
def _ddp_store(typingctx, p, i, hi, lo):
    if not (isinstance(p, DDLanePtr) and isinstance(hi, Vec) and isinstance(lo, Vec)):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        ptr = builder.gep(args[0], [builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(2 * W))])
        vt = ir.VectorType(ir.DoubleType(), W).as_pointer()
        builder.store(args[2], builder.bitcast(ptr, vt), align=8)
        builder.store(args[3], builder.bitcast(builder.gep(ptr, [_W(W)]), vt), align=8)
        return context.get_dummy_value()
    return types.void(p, i, hi, lo), codegen


@intrinsic
def _ddp_elem(typingctx, p, i, lane):
    """Pointer to one lane's high part of element i (its low part is W doubles further)."""
    if not isinstance(p, DDLanePtr):
        return None

    def codegen(context, builder, sig, args):
        W = sig.args[0].W
        idx = builder.add(builder.mul(_intp(context, builder, sig.args[1], args[1]), _W(2 * W)),
                          _intp(context, builder, sig.args[2], args[2]))
        return builder.gep(args[0], [idx])
    return types.CPointer(types.float64)(p, i, lane), codegen


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
