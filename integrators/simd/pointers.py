"""Pointers: loads, stores and offsets (:func:`ld`, :func:`st`, :func:`at`, :func:`lanes`, one lane's
element, integer data), the same source for plain pointers (the scalar path), :class:`LanePtr` and
:class:`DDLanePtr` (integrators.simd), and the double-double lane values they load (:func:`ddv`)."""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from .. import ddouble as _ddmod
from ..ddouble import DDType, as_dd, dd, dd_t
from .lanetypes import (_as_vec, DDLanePtr, DDVec, _intp, _is_dd_ptr, _lane_width, LanePtr, _pair, _real, _splat, Vec,
                        _W, _width)


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


@overload(at, inline="never")
def _at_ov(p, off):
    if isinstance(p, DDLanePtr):
        return lambda p, off: _ddp_at(p, off)
    if isinstance(p, LanePtr):
        return lambda p, off: _lp_at(p, off)
    if isinstance(p, types.CPointer):
        return lambda p, off: _at(p, off)


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
