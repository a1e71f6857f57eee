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

The modules, each importing only those above it: ``lanetypes`` (the types and their LLVM models),
``pointers`` (loads, stores, offsets, and the double-double values they load), ``values``
(arithmetic, comparisons and functions on :class:`Vec`; what the scalar and complex paths need),
``masks`` (selects and mask logic), ``dd`` (double-double lane arithmetic, registered on import).
What the kernel and the generated point functions use is re-exported here.
"""
from __future__ import annotations

from .lanetypes import DDLanePtr, DDVec, LanePtr, Mask, Vec
from .pointers import _at, at, ddv, elem, elem3, lanes, ld, ldi, lget, lset, nlanes, plain, put, put3, st, sti
from .values import dithers, is_complex, raw, re, step_measure, _vget, _vset
from .masks import anyl, lmask, mand, mnot, mor, sel
from . import dd  # noqa: F401  (registers the double-double lane arithmetic)

__all__ = ['anyl', '_at', 'at', 'DDLanePtr', 'ddv', 'DDVec', 'dithers', 'elem', 'elem3', 'is_complex', 'LanePtr',
           'lanes', 'ld', 'ldi', 'lget', 'lmask', 'lset', 'mand', 'Mask', 'mnot', 'mor', 'nlanes', 'plain',
           'put', 'put3', 'raw', 're', 'sel', 'st', 'step_measure', 'sti', 'Vec', '_vget', '_vset']
