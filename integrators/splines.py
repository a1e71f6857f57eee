"""Quintic tensor splines on a regular (R, Z) grid, as symbols a system's ϑ and H can use.

A field given on a grid (the poloidal flux ψ(R, Z) of an equilibrium file, or a potential built
from it) becomes the quintic interpolating tensor spline of its values (scipy's not-a-knot
B-spline interpolation along each axis, :class:`Spline2`): C⁴ across cells, so ϑ_qq and ∇²H, which
need third derivatives, are continuous, and every derivative the engine takes is the exact
derivative of the interpolant, not an approximation of it.  On each cell the spline is a
polynomial, stored as its 36 Taylor coefficients about the cell's midpoint.

In a system the spline is the sympy function :class:`Field` — ``Field(R, Z, s, a, b)`` is
∂ᵃ/∂Rᵃ ∂ᵇ/∂Zᵇ of the system's field number ``s`` — so sympy differentiates ϑ and H through it
exactly as through any function.  The fields' data are runtime data beside the parameters: the
vector ``k`` that every point function receives is the parameters followed by
:meth:`System.data <integrators.systems.System>` (a table of each field's offset, then the
fields' blocks, :func:`pack`), so one generated and compiled module serves every grid and every
equilibrium of the same form.  Generated code evaluates a field with all its derivatives up to
order three at once (:func:`field`, one cell lookup), on every number type the engine uses:
doubles, complex steps (the cell from the real part), double-doubles, and W lanes (lane by lane,
each lane the scalar path's bits).  :func:`field_np` is the same evaluation on numpy arrays (the
systems' numpy functions, the reference engine, the invariants).

Outside the grid a field continues the polynomial of its edge cell (finite, smooth, meaningless):
the systems that use fields put the grid into their domain, so a point that leaves it breaks down
instead of using those values.
"""
from __future__ import annotations

import numpy as np
import sympy
from numba import njit
from numba.extending import overload

from .ddouble import DDType, dd
from .simd import DDVec, Vec, _vget, _vset, ddv, re

#: the derivatives (a, b) = ∂ᵃ_R ∂ᵇ_Z a field evaluation returns, in this order: total order ≤ 3
DERIVATIVES = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (3, 0), (2, 1), (1, 2), (0, 3))
ORDER = 5                  # quintic
HEADER = 6                 # a field's block: nR, nZ, R0, dR, Z0, dZ, then (nR−1)(nZ−1) cells × 36


class Field(sympy.Function):
    """∂ᵃ_R ∂ᵇ_Z of the system's spline field number ``s`` at (R, Z): ``Field(R, Z, s, a, b)``.

    sympy differentiates it by raising a or b; derivatives past the third are refused where code
    is generated (the evaluation returns orders ≤ 3, which is what ϑ_qq and ∇²H need from a ϑ
    and H that use a field and its first derivatives)."""

    nargs = 5
    is_real = True

    def fdiff(self, argindex=1):
        x, y, s, a, b = self.args
        if argindex == 1:
            return Field(x, y, s, a + 1, b)
        if argindex == 2:
            return Field(x, y, s, a, b + 1)
        raise sympy.ArgumentIndexError(self, argindex)

    def _eval_is_real(self):
        return True


# -- building a spline from grid values ------------------------------------------------------------

class Spline2:
    """The quintic interpolating tensor spline of ``values[i, j]`` = f(R[i], Z[j]) on a regular grid.

    ``coefficients[i, j, a, b]`` is the coefficient of (R − Rm_i)ᵃ (Z − Zm_j)ᵇ on cell (i, j),
    Rm_i, Zm_j the cell's midpoint (computed in double as R0 + (i + ½)dR, as the evaluation does)."""

    def __init__(self, R, Z, values):
        from scipy.interpolate import make_interp_spline
        R, Z, values = (np.asarray(x, dtype=np.float64) for x in (R, Z, values))
        if R.ndim != 1 or Z.ndim != 1 or values.shape != (R.size, Z.size):
            raise ValueError(f"a spline needs values of shape (len(R), len(Z)), got {values.shape}")
        if min(R.size, Z.size) < ORDER + 1:
            raise ValueError(f"a quintic spline needs at least {ORDER + 1} grid points a side, got {R.size} × {Z.size}")
        for name, x in (("R", R), ("Z", Z)):
            step = np.diff(x)
            if not (np.all(step > 0) and np.allclose(step, step[0], rtol=1e-9, atol=0)):
                raise ValueError(f"the {name} grid must be regular and increasing")
        if not np.all(np.isfinite(values)):
            raise ValueError("the field's grid values are not all finite")
        self.R0, self.dR, self.nR = float(R[0]), float((R[-1] - R[0]) / (R.size - 1)), R.size
        self.Z0, self.dZ, self.nZ = float(Z[0]), float((Z[-1] - Z[0]) / (Z.size - 1)), Z.size
        along_R = make_interp_spline(R, values, k=ORDER, axis=0)           # coefficients (nR, nZ)
        Rm = self.R0 + (np.arange(self.nR - 1) + 0.5) * self.dR
        Zm = self.Z0 + (np.arange(self.nZ - 1) + 0.5) * self.dZ
        coef = np.empty((self.nR - 1, self.nZ - 1, ORDER + 1, ORDER + 1))
        fact = [1.0, 1.0, 2.0, 6.0, 24.0, 120.0]
        for a in range(ORDER + 1):
            # ∂ᵃ_R at the cells' midpoints, for every Z node, then a spline in Z of those
            dR_a = along_R.derivative(a)(Rm) if a else along_R(Rm)                # (nR − 1, nZ)
            along_Z = make_interp_spline(Z, dR_a, k=ORDER, axis=1)
            for b in range(ORDER + 1):
                d = along_Z.derivative(b)(Zm) if b else along_Z(Zm)               # (nR − 1, nZ − 1)
                coef[:, :, a, b] = d / (fact[a] * fact[b])
        self.coefficients = coef

    def pack(self):
        """The field's block of a system's data: [nR, nZ, R0, dR, Z0, dZ, coefficients…]."""
        return np.concatenate([[self.nR, self.nZ, self.R0, self.dR, self.Z0, self.dZ], self.coefficients.ravel()])

    def __call__(self, R, Z, a=0, b=0):
        """∂ᵃ_R ∂ᵇ_Z at points (numpy arrays; any real or complex dtype)."""
        if getattr(self, "_alone", None) is None:
            self._alone = pack([self])
        return field_np(self._alone, 0, np.asarray(R), np.asarray(Z))[DERIVATIVES.index((a, b))]


def pack(fields):
    """A system's data from its fields: the offset of each field's block (counted from the data's
    start), then the blocks."""
    blocks = [f.pack() for f in fields]
    offsets, at = [], len(blocks)
    for blk in blocks:
        offsets.append(at)
        at += blk.size
    return np.concatenate([np.array(offsets, dtype=np.float64)] + blocks)


# -- evaluation: numpy -------------------------------------------------------------------------------

def _cells_np(k, base, x, y):
    nR, nZ = int(k[base]), int(k[base + 1])
    R0, dR, Z0, dZ = k[base + 2], k[base + 3], k[base + 4], k[base + 5]
    xr, yr = np.real(x).astype(np.float64), np.real(y).astype(np.float64)
    i = np.clip(np.floor((xr - R0) / dR), 0, nR - 2).astype(np.int64)
    j = np.clip(np.floor((yr - Z0) / dZ), 0, nZ - 2).astype(np.int64)
    i = np.where(np.isfinite(xr), i, 0)
    j = np.where(np.isfinite(yr), j, 0)
    xm = x - (R0 + (i + 0.5) * dR)
    ym = y - (Z0 + (j + 0.5) * dZ)
    start = base + HEADER + (i * (nZ - 1) + j) * 36
    return start, xm, ym


def field_np(k, s, x, y, P=0):
    """The ten derivatives (:data:`DERIVATIVES`) of field ``s`` of the data at ``k[P:]`` at points
    (x, y), numpy arrays of any real or complex dtype: the same polynomial evaluation as
    :func:`field`, term by term."""
    k = np.asarray(k, dtype=np.float64)
    base = P + int(k[P + s])
    x, y = np.broadcast_arrays(x, y)
    start, xm, ym = _cells_np(k, base, x, y)
    c = k[start[..., None] + np.arange(36)]                        # (..., 36): c[a * 6 + b]
    py = [[None] * 4 for _ in range(6)]
    for a in range(6):
        row = [c[..., a * 6 + b] for b in range(6)]
        for m in range(4):
            py[a][m] = _horner_deriv(row, ym, m)
    out = []
    for (da, db) in DERIVATIVES:
        out.append(_horner_deriv([py[a][db] for a in range(6)], xm, da))
    return tuple(out)


def _horner_deriv(c, x, m):
    """Σ_b c_b ∂ᵐ(xᵇ) by Horner: the m-th derivative of the polynomial with coefficients c."""
    n = len(c)
    acc = _falling(n - 1, m) * c[n - 1]
    for b in range(n - 2, m - 1, -1):
        acc = acc * x + _falling(b, m) * c[b]
    return acc


def _falling(b, m):
    """b (b − 1) … (b − m + 1) as a double (1.0 for m = 0)."""
    f = 1.0
    for i in range(m):
        f *= b - i
    return f


# -- evaluation: compiled (scalars, complex steps, double-doubles, lanes) ------------------------------

_FALL = np.array([[_falling(b, m) for m in range(4)] for b in range(6)])


@njit(cache=True, error_model="numpy")
def _poly(c0, c1, c2, c3, c4, c5, y, m):
    """∂ᵐ/∂yᵐ of Σ_b c_b yᵇ (b = 0 … 5) by Horner, the operations of :func:`_horner_deriv` (m ≤ 3:
    y enters at once, so the result has y's type).  The same for a cell's rows (in Z) and for the
    combination of the rows (in R)."""
    acc = (_FALL[5, m] * c5) * y + _FALL[4, m] * c4
    if m <= 3:
        acc = acc * y + _FALL[3, m] * c3
    if m <= 2:
        acc = acc * y + _FALL[2, m] * c2
    if m <= 1:
        acc = acc * y + _FALL[1, m] * c1
    if m == 0:
        acc = acc * y + c0
    return acc


@njit(cache=True, error_model="numpy")
def _rows(c0, c1, c2, c3, c4, c5, y):
    """A cell row's polynomial in y and its first three derivatives."""
    return (_poly(c0, c1, c2, c3, c4, c5, y, 0), _poly(c0, c1, c2, c3, c4, c5, y, 1),
            _poly(c0, c1, c2, c3, c4, c5, y, 2), _poly(c0, c1, c2, c3, c4, c5, y, 3))


@njit(cache=True, error_model="numpy")
def _combine(r0, r1, r2, r3, r4, r5, xm):
    """The ten derivatives from the six rows' (value, ∂_y, ∂²_y, ∂³_y) at the local x."""
    return (_poly(r0[0], r1[0], r2[0], r3[0], r4[0], r5[0], xm, 0),
            _poly(r0[0], r1[0], r2[0], r3[0], r4[0], r5[0], xm, 1),
            _poly(r0[1], r1[1], r2[1], r3[1], r4[1], r5[1], xm, 0),
            _poly(r0[0], r1[0], r2[0], r3[0], r4[0], r5[0], xm, 2),
            _poly(r0[1], r1[1], r2[1], r3[1], r4[1], r5[1], xm, 1),
            _poly(r0[2], r1[2], r2[2], r3[2], r4[2], r5[2], xm, 0),
            _poly(r0[0], r1[0], r2[0], r3[0], r4[0], r5[0], xm, 3),
            _poly(r0[1], r1[1], r2[1], r3[1], r4[1], r5[1], xm, 2),
            _poly(r0[2], r1[2], r2[2], r3[2], r4[2], r5[2], xm, 1),
            _poly(r0[3], r1[3], r2[3], r3[3], r4[3], r5[3], xm, 0))


@njit(cache=True, error_model="numpy")
def _locate(k, base, xr, yr):
    """The cell of the real point (xr, yr) in the field at ``base`` (the edge cell outside the grid):
    the index of its first coefficient and its midpoint (R, Z)."""
    nR, nZ = int(k[base]), int(k[base + 1])
    R0, dR, Z0, dZ = k[base + 2], k[base + 3], k[base + 4], k[base + 5]
    i = 0
    j = 0
    if np.isfinite(xr):
        i = int(min(max(np.floor((xr - R0) / dR), 0.0), nR - 2.0))
    if np.isfinite(yr):
        j = int(min(max(np.floor((yr - Z0) / dZ), 0.0), nZ - 2.0))
    return base + HEADER + (i * (nZ - 1) + j) * 36, R0 + (i + 0.5) * dR, Z0 + (j + 0.5) * dZ


def _coef(k, p, off):
    """Coefficient ``off`` of the cell starting at p: a number, or with p a Vec of each lane's start,
    the Vec of each lane's coefficient."""


@overload(_coef)
def _coef_ov(k, p, off):
    if isinstance(p, Vec):
        return lambda k, p, off: _gather(k, p, off)
    return lambda k, p, off: k[p + off]


@njit(cache=True, error_model="numpy")
def _evaluate(k, p, xm, ym):
    """The ten derivatives from the cell at p (an index, or a Vec of them) at the local (xm, ym)."""
    rw0 = _rows(_coef(k, p, 0), _coef(k, p, 1), _coef(k, p, 2), _coef(k, p, 3), _coef(k, p, 4), _coef(k, p, 5), ym)
    rw1 = _rows(_coef(k, p, 6), _coef(k, p, 7), _coef(k, p, 8), _coef(k, p, 9), _coef(k, p, 10), _coef(k, p, 11), ym)
    rw2 = _rows(_coef(k, p, 12), _coef(k, p, 13), _coef(k, p, 14), _coef(k, p, 15), _coef(k, p, 16), _coef(k, p, 17),
                ym)
    rw3 = _rows(_coef(k, p, 18), _coef(k, p, 19), _coef(k, p, 20), _coef(k, p, 21), _coef(k, p, 22), _coef(k, p, 23),
                ym)
    rw4 = _rows(_coef(k, p, 24), _coef(k, p, 25), _coef(k, p, 26), _coef(k, p, 27), _coef(k, p, 28), _coef(k, p, 29),
                ym)
    rw5 = _rows(_coef(k, p, 30), _coef(k, p, 31), _coef(k, p, 32), _coef(k, p, 33), _coef(k, p, 34), _coef(k, p, 35),
                ym)
    return _combine(rw0, rw1, rw2, rw3, rw4, rw5, xm)


@njit(cache=True, error_model="numpy")
def _field_scalar(k, P, s, x, y):
    """The ten derivatives of field ``s`` at one point (double, complex or double-double x, y)."""
    p, mR, mZ = _locate(k, P + int(k[P + s]), re(x), re(y))
    return _evaluate(k, p, x - mR, y - mZ)


def _width_of(v):
    """The lane count of a Vec."""


@overload(_width_of)
def _width_of_ov(v):
    W = v.W
    return lambda v: W


@njit(cache=True, error_model="numpy")
def _gather(k, starts, off):
    """The Vec of k[starts[l] + off] over the lanes (``starts`` a Vec of whole numbers)."""
    v = starts
    for l in range(_width_of(starts)):
        v = _vset(v, l, k[int(_vget(starts, l)) + off])
    return v


@njit(cache=True, error_model="numpy")
def _dd_put10(hi, lo, l, o):
    """Lane l of ten double-double lane vectors (their hi and lo parts) set from ten double-doubles."""
    return ((_vset(hi[0], l, o[0].hi), _vset(hi[1], l, o[1].hi), _vset(hi[2], l, o[2].hi), _vset(hi[3], l, o[3].hi),
             _vset(hi[4], l, o[4].hi), _vset(hi[5], l, o[5].hi), _vset(hi[6], l, o[6].hi), _vset(hi[7], l, o[7].hi),
             _vset(hi[8], l, o[8].hi), _vset(hi[9], l, o[9].hi)),
            (_vset(lo[0], l, o[0].lo), _vset(lo[1], l, o[1].lo), _vset(lo[2], l, o[2].lo), _vset(lo[3], l, o[3].lo),
             _vset(lo[4], l, o[4].lo), _vset(lo[5], l, o[5].lo), _vset(lo[6], l, o[6].lo), _vset(lo[7], l, o[7].lo),
             _vset(lo[8], l, o[8].lo), _vset(lo[9], l, o[9].lo)))


@njit(cache=True, error_model="numpy")
def _ddv10(hi, lo):
    """Ten DDVecs from their hi and lo parts."""
    return (ddv(hi[0], lo[0]), ddv(hi[1], lo[1]), ddv(hi[2], lo[2]), ddv(hi[3], lo[3]), ddv(hi[4], lo[4]),
            ddv(hi[5], lo[5]), ddv(hi[6], lo[6]), ddv(hi[7], lo[7]), ddv(hi[8], lo[8]), ddv(hi[9], lo[9]))


def field(k, P, s, x, y):
    """The ten derivatives (:data:`DERIVATIVES`) of the system's field ``s`` at (x, y): ``k`` the
    point function's parameter pointer, ``P`` the number of parameters before the data."""


@overload(field, inline="never")
def _field_ov(k, P, s, x, y):
    if isinstance(x, Vec) and isinstance(y, Vec):
        W = x.W

        def lanes(k, P, s, x, y):           # each lane's cell, then the polynomial in vector form:
            base = P + int(k[P + s])        # every lane does the scalar path's operations
            starts, xm, ym = x, x, y
            for l in range(W):
                xr, yr = _vget(x, l), _vget(y, l)
                p, mR, mZ = _locate(k, base, xr, yr)
                starts = _vset(starts, l, float(p))
                xm = _vset(xm, l, xr - mR)
                ym = _vset(ym, l, yr - mZ)
            return _evaluate(k, starts, xm, ym)
        return lanes
    if isinstance(x, DDVec) and isinstance(y, DDVec):
        W = x.W

        def lanes_dd(k, P, s, x, y):
            hi = (x.hi, x.hi, x.hi, x.hi, x.hi, x.hi, x.hi, x.hi, x.hi, x.hi)
            lo = hi
            for l in range(W):
                o = _field_scalar(k, P, s, dd(_vget(x.hi, l), _vget(x.lo, l)), dd(_vget(y.hi, l), _vget(y.lo, l)))
                hi, lo = _dd_put10(hi, lo, l, o)
            return _ddv10(hi, lo)
        return lanes_dd
    return lambda k, P, s, x, y: _field_scalar(k, P, s, x, y)


# -- one coordinate: profiles ------------------------------------------------------------------------

#: the derivatives a 1-D field's evaluation returns, in this order
DERIVATIVES1 = (0, 1, 2, 3)
HEADER1 = 3                # a 1-D field's block: n, X0, dX, then (n − 1) cells × 6


class Field1(sympy.Function):
    """∂ᵃ_X of the system's 1-D spline field number ``s`` at X: ``Field1(X, s, a)`` (a profile such
    as G(ψ), ι(ψ)); derivatives past the third are refused where code is generated."""

    nargs = 3
    is_real = True

    def fdiff(self, argindex=1):
        x, s, a = self.args
        if argindex == 1:
            return Field1(x, s, a + 1)
        raise sympy.ArgumentIndexError(self, argindex)

    def _eval_is_real(self):
        return True


class Spline1:
    """The quintic not-a-knot interpolating spline of ``values[i]`` = f(X[i]) on a regular grid, as
    :class:`Spline2` along one axis: ``coefficients[i, a]`` the coefficient of (X − Xm_i)ᵃ on cell i."""

    def __init__(self, X, values):
        from scipy.interpolate import make_interp_spline
        X, values = (np.asarray(v, dtype=np.float64) for v in (X, values))
        if X.ndim != 1 or values.shape != X.shape:
            raise ValueError(f"a 1-D spline needs values of the grid's shape {X.shape}, got {values.shape}")
        if X.size < ORDER + 1:
            raise ValueError(f"a quintic spline needs at least {ORDER + 1} grid points, got {X.size}")
        step = np.diff(X)
        if not (np.all(step > 0) and np.allclose(step, step[0], rtol=1e-9, atol=0)):
            raise ValueError("the grid must be regular and increasing")
        if not np.all(np.isfinite(values)):
            raise ValueError("the field's grid values are not all finite")
        self.X0, self.dX, self.n = float(X[0]), float((X[-1] - X[0]) / (X.size - 1)), X.size
        sp = make_interp_spline(X, values, k=ORDER)
        Xm = self.X0 + (np.arange(self.n - 1) + 0.5) * self.dX
        fact = [1.0, 1.0, 2.0, 6.0, 24.0, 120.0]
        self.coefficients = np.stack([(sp.derivative(a)(Xm) if a else sp(Xm)) / fact[a] for a in range(ORDER + 1)], 1)

    def pack(self):
        """The field's block of a system's data: [n, X0, dX, coefficients…]."""
        return np.concatenate([[self.n, self.X0, self.dX], self.coefficients.ravel()])

    def __call__(self, X, a=0):
        """∂ᵃ_X at points (numpy arrays; any real or complex dtype)."""
        if getattr(self, "_alone", None) is None:
            self._alone = pack([self])
        return field1_np(self._alone, 0, np.asarray(X))[a]


def field1_np(k, s, x, P=0):
    """The four derivatives of 1-D field ``s`` of the data at ``k[P:]`` at points x (numpy arrays of any
    real or complex dtype): :func:`field1`'s operations, elementwise."""
    k = np.asarray(k, dtype=np.float64)
    base = P + int(k[P + s])
    n, X0, dX = int(k[base]), k[base + 1], k[base + 2]
    xr = np.real(x).astype(np.float64)
    with np.errstate(invalid="ignore"):
        i = np.where(np.isfinite(xr), np.clip(np.floor((xr - X0) / dX), 0, n - 2), 0).astype(np.int64)
    xm = x - (X0 + (i + 0.5) * dX)
    c = k[(base + HEADER1 + i * 6)[..., None] + np.arange(6)]
    row = [c[..., b] for b in range(6)]
    return tuple(_horner_deriv(row, xm, m) for m in range(4))


@njit(cache=True, error_model="numpy")
def _locate1(k, base, xr):
    """The cell of the real point xr in the 1-D field at ``base``: its first coefficient's index, its midpoint."""
    n, X0, dX = int(k[base]), k[base + 1], k[base + 2]
    i = 0
    if np.isfinite(xr):
        i = int(min(max(np.floor((xr - X0) / dX), 0.0), n - 2.0))
    return base + HEADER1 + i * 6, X0 + (i + 0.5) * dX


@njit(cache=True, error_model="numpy")
def _evaluate1(k, p, xm):
    return _rows(_coef(k, p, 0), _coef(k, p, 1), _coef(k, p, 2), _coef(k, p, 3), _coef(k, p, 4), _coef(k, p, 5), xm)


@njit(cache=True, error_model="numpy")
def _field1_scalar(k, P, s, x):
    p, m = _locate1(k, P + int(k[P + s]), re(x))
    return _evaluate1(k, p, x - m)


def field1(k, P, s, x):
    """The value and first three derivatives of the system's 1-D field ``s`` at x."""


@overload(field1, inline="never")
def _field1_ov(k, P, s, x):
    if isinstance(x, Vec):
        W = x.W

        def lanes(k, P, s, x):
            base = P + int(k[P + s])
            starts, xm = x, x
            for l in range(W):
                xr = _vget(x, l)
                p, m = _locate1(k, base, xr)
                starts = _vset(starts, l, float(p))
                xm = _vset(xm, l, xr - m)
            return _evaluate1(k, starts, xm)
        return lanes
    if isinstance(x, DDVec):
        W = x.W

        def lanes_dd(k, P, s, x):
            hi = (x.hi, x.hi, x.hi, x.hi)
            lo = hi
            for l in range(W):
                o = _field1_scalar(k, P, s, dd(_vget(x.hi, l), _vget(x.lo, l)))
                hi = (_vset(hi[0], l, o[0].hi), _vset(hi[1], l, o[1].hi), _vset(hi[2], l, o[2].hi),
                      _vset(hi[3], l, o[3].hi))
                lo = (_vset(lo[0], l, o[0].lo), _vset(lo[1], l, o[1].lo), _vset(lo[2], l, o[2].lo),
                      _vset(lo[3], l, o[3].lo))
            return (ddv(hi[0], lo[0]), ddv(hi[1], lo[1]), ddv(hi[2], lo[2]), ddv(hi[3], lo[3]))
        return lanes_dd
    return lambda k, P, s, x: _field1_scalar(k, P, s, x)
