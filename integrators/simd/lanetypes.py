"""The lane types: W doubles (:class:`Vec`), W booleans (:class:`Mask`), a pointer to W-lane data
(:class:`LanePtr`), and their double-double forms (:class:`DDVec`, :class:`DDLanePtr`), with their
LLVM models and the helpers that make their values (integrators.simd)."""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import make_attribute_wrapper, models, register_model

from ..ddouble import DDType


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


# -- the double-double lane types (their arithmetic: integrators/simd/dd.py) ----------------------


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


def _lane_width(t):
    return t.W if isinstance(t, (DDVec, Vec, Mask, DDLanePtr, LanePtr)) else None
