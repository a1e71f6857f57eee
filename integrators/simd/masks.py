"""Masks: per-lane selects (:func:`sel`), their logic (:func:`mand`, :func:`mor`, :func:`mnot`) and
what reads them (:func:`anyl`, :func:`lmask`) (integrators.simd)."""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic, overload

from ..ddouble import DDType, as_dd
from .lanetypes import _as_vec, DDVec, _is_dd_scalar, Mask, _real, _splat, Vec, _width
from .pointers import _ddv, ddv


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
