"""Quintic tensor splines in (x, y, z), periodic in z, as symbols a system's ϑ and H can use.

The 3-D companion of :mod:`integrators.splines` for a field that depends on an angle as well as on
two Cartesian coordinates: a stellarator's |B|(x, y, ζ) in the Boozer axis chart
(:mod:`integrators.boozer`).  One evaluation costs the same whatever the field's Fourier content,
where a sum over toroidal harmonics costs one 2-D spline per harmonic.

**The interpolant.**  The quintic tensor B-spline on uniform knots at the grid nodes
(:class:`Spline3`): not-a-knot in x and y (the fifth derivative continuous at the second, third,
last but two and last but one nodes), periodic in z with the period ``period``.  It is C⁴ across
cells, as the 2-D fields of :mod:`integrators.splines` are, so ∇²H of an H that uses the field is
continuous and the images of a smooth surface under the step stay smooth to the fourth derivative,
and every derivative the engine takes is the exact derivative of the interpolant.  Quintic in
every direction because lower degrees were tried and measured worse (docs/stellarators.md): cubic
in ζ left the energy error of GLRK2-symmetric without the method's order (a step spans several ζ
cells); cubic in x and y (C²) left kinks in the third derivative of the step's images, which the
spectral I₂ of a 12 × 12 surface read as a drift of 1e-11 its resolution monitor did not see.
What is stored is each B-spline coefficient over 120³, so that the basis is evaluated with
whole-number coefficients (120× the uniform quintic basis and its derivatives in the cell's local
t ∈ [0, 1), :data:`QUINTIC`): the derivatives are exact derivatives of the evaluated polynomials,
with no rounded 1/120 between them.  Its error for a smooth field is O(Δ⁶).

In a system the spline is the sympy function :class:`Field3` — ``Field3(X, Y, Z, s, a, b, c)`` is
∂ᵃ_X ∂ᵇ_Y ∂ᶜ_Z of the system's field number ``s`` — beside :class:`~integrators.splines.Field` in
the same field list and data vector (:func:`integrators.splines.pack`).  Generated code evaluates it
with all its derivatives up to order **two** at once (:func:`field3`, one cell lookup): what ∇²H needs
from an H that uses the field itself; a third derivative is refused where code is generated.  On
doubles, complex steps (the cell from the real part), double-doubles and W lanes (lane by lane, each
lane the scalar path's bits); :func:`field3_np` is the same evaluation on numpy arrays, operation for
operation.

Outside the grid in x or y the field continues the polynomial of its edge cell (finite, smooth,
meaningless): the systems that use it put the grid into their domain.  In z there is no outside.
"""
from __future__ import annotations

import numpy as np
import sympy
from numba import njit
from numba.extending import overload

from .ddouble import dd
from .simd import DDVec, Vec, _vget, _vset, re
from .splines import _dd_put10, _ddv10, _gather

#: the derivatives (a, b, c) = ∂ᵃ_x ∂ᵇ_y ∂ᶜ_z a field evaluation returns, in this order: total order ≤ 2
DERIVATIVES3 = ((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (2, 0, 0), (1, 1, 0), (1, 0, 1), (0, 2, 0),
                (0, 1, 1), (0, 0, 2))
HEADER3 = 12   # a field's block: nx, ny, nz, x0, dx, y0, dy, z0, dz, 1/dx, 1/dy, 1/dz, then the coefficients


class Field3(sympy.Function):
    """∂ᵃ_X ∂ᵇ_Y ∂ᶜ_Z of the system's 3-D spline field number ``s``: ``Field3(X, Y, Z, s, a, b, c)``."""

    nargs = 7
    is_real = True

    def fdiff(self, argindex=1):
        x, y, z, s, a, b, c = self.args
        if argindex == 1:
            return Field3(x, y, z, s, a + 1, b, c)
        if argindex == 2:
            return Field3(x, y, z, s, a, b + 1, c)
        if argindex == 3:
            return Field3(x, y, z, s, a, b, c + 1)
        raise sympy.ArgumentIndexError(self, argindex)

    def _eval_is_real(self):
        return True


# -- building the spline from grid values ----------------------------------------------------------

#: 120 × the uniform quintic B-spline basis on a cell, in its local t: coefficients of t⁰ … t⁵ of the
#: six basis functions centred on the nodes k − 2 … k + 3 (z-stencil of a cell starting at node k)
QUINTIC = ((1, -5, 10, -10, 5, -1), (26, -50, 20, 20, -20, 5), (66, 0, -60, 0, 30, -10),
           (26, 50, 20, -20, -20, 10), (1, 5, 10, 10, 5, -5), (0, 0, 0, 0, 0, 1))


def _not_a_knot(n):
    """The (n + 4)² matrix whose solution is the uniform quintic B-spline coefficients c₋₂ … c_{n+1}
    over 120 interpolating n node values: c_{i−2} + 26c_{i−1} + 66c_i + 26c_{i+1} + c_{i+2} = 120 f_i,
    and the jump of the fifth derivative (∝ Σ_k (−1)ᵏ C(6, k + 3) c_{j+k}, k = −3 … 3) zero at nodes
    1, 2, n − 3 and n − 2."""
    A = np.zeros((n + 4, n + 4))
    for i in range(n):
        A[i, i:i + 5] = (1.0, 26.0, 66.0, 26.0, 1.0)
    jump = (1.0, -6.0, 15.0, -20.0, 15.0, -6.0, 1.0)
    for row, j in enumerate((1, 2, n - 3, n - 2)):
        A[n + row, j - 1:j + 6] = jump
    return A


class Spline3:
    """The quintic interpolating tensor spline of ``values[i, j, k]`` = f(x[i], y[j], k·period/nz):
    not-a-knot in x and y (regular grids of at least 8 points), periodic in z (nz ≥ 6 points over
    one period, starting at z = 0).

    ``coefficients[i + 2, j + 2, k + 2]`` is the B-spline coefficient over 120³ of the basis function
    centred on node (i, j, k), i = −2 … nx + 1, j = −2 … ny + 1, k = −2 … nz + 2 (k taken modulo nz:
    the periodic coefficients are stored with two before and three after, so a cell's 6 × 6 × 6
    block is read without a wrap)."""

    def __init__(self, x, y, period, values):
        x, y, values = (np.asarray(v, dtype=np.float64) for v in (x, y, values))
        period = float(period)
        if x.ndim != 1 or y.ndim != 1 or values.ndim != 3 or values.shape[:2] != (x.size, y.size):
            raise ValueError(f"a 3-D spline needs values of shape (len(x), len(y), nz), got {values.shape}")
        if min(x.size, y.size) < 8 or values.shape[2] < 6:
            raise ValueError(f"a 3-D spline needs at least 8 × 8 × 6 grid points, got {values.shape}")
        for name, v in (("x", x), ("y", y)):
            step = np.diff(v)
            if not (np.all(step > 0) and np.allclose(step, step[0], rtol=1e-9, atol=0)):
                raise ValueError(f"the {name} grid must be regular and increasing")
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"the period must be positive and finite, got {period!r}")
        if not np.all(np.isfinite(values)):
            raise ValueError("the field's grid values are not all finite")
        self.nx, self.ny, self.nz = x.size, y.size, values.shape[2]
        self.x0, self.dx = float(x[0]), float((x[-1] - x[0]) / (x.size - 1))
        self.y0, self.dy = float(y[0]), float((y[-1] - y[0]) / (y.size - 1))
        self.z0, self.dz, self.period = 0.0, period / self.nz, period
        nx, ny, nz = self.nx, self.ny, self.nz
        c = np.linalg.solve(_not_a_knot(nx), np.concatenate([values, np.zeros((4, ny, nz))]).reshape(nx + 4, -1))
        c = c.reshape(nx + 4, ny, nz).transpose(1, 0, 2)
        c = np.linalg.solve(_not_a_knot(ny), np.concatenate([c, np.zeros((4, nx + 4, nz))]).reshape(ny + 4, -1))
        c = c.reshape(ny + 4, nx + 4, nz).transpose(1, 0, 2)
        w = 2 * np.pi * np.arange(nz) / nz      # the periodic quintic's circulant: (1, 26, 66, 26, 1)/120
        c = np.fft.ifft(np.fft.fft(c, axis=2) / (66.0 + 52.0 * np.cos(w) + 2.0 * np.cos(2 * w)), axis=2).real
        self.coefficients = np.ascontiguousarray(c[:, :, (np.arange(-2, nz + 3)) % nz])

    def pack(self):
        """The field's block of a system's data (:func:`integrators.splines.pack`)."""
        head = [self.nx, self.ny, self.nz, self.x0, self.dx, self.y0, self.dy, self.z0, self.dz,
                1.0 / self.dx, 1.0 / self.dy, 1.0 / self.dz]
        return np.concatenate([np.asarray(head, dtype=np.float64), self.coefficients.ravel()])

    def __call__(self, x, y, z, a=0, b=0, c=0):
        """∂ᵃ_x ∂ᵇ_y ∂ᶜ_z at points (numpy arrays; any real or complex dtype)."""
        if getattr(self, "_alone", None) is None:
            from .splines import pack
            self._alone = pack([self])
        return field3_np(self._alone, 0, np.asarray(x), np.asarray(y), np.asarray(z))[DERIVATIVES3.index((a, b, c))]


# -- the evaluation's arithmetic: the same functions on numbers, lanes and numpy arrays ---------------

def _weights5_py(t, inv, inv2):
    """120× the uniform quintic B-spline basis on a cell at its local t (:data:`QUINTIC`), and its
    first and second derivatives in the coordinate (× 1/Δ, 1/Δ²)."""
    w = (((((5.0 - t) * t - 10.0) * t + 10.0) * t - 5.0) * t + 1.0,
         ((((5.0 * t - 20.0) * t + 20.0) * t + 20.0) * t - 50.0) * t + 26.0,
         ((30.0 - 10.0 * t) * t * t - 60.0) * t * t + 66.0,
         ((((10.0 * t - 20.0) * t - 20.0) * t + 20.0) * t + 50.0) * t + 26.0,
         ((((5.0 - 5.0 * t) * t + 10.0) * t + 10.0) * t + 5.0) * t + 1.0,
         t * t * t * t * t)
    d = (((((20.0 - 5.0 * t) * t - 30.0) * t + 20.0) * t - 5.0) * inv,
         ((((25.0 * t - 80.0) * t + 60.0) * t + 40.0) * t - 50.0) * inv,
         (((120.0 - 50.0 * t) * t * t - 120.0) * t) * inv,
         ((((50.0 * t - 80.0) * t - 60.0) * t + 40.0) * t + 50.0) * inv,
         ((((20.0 - 25.0 * t) * t + 30.0) * t + 20.0) * t + 5.0) * inv,
         (5.0 * t * t * t * t) * inv)
    s = ((((60.0 - 20.0 * t) * t - 60.0) * t + 20.0) * inv2,
         (((100.0 * t - 240.0) * t + 120.0) * t + 40.0) * inv2,
         ((360.0 - 200.0 * t) * t * t - 120.0) * inv2,
         (((200.0 * t - 240.0) * t - 120.0) * t + 40.0) * inv2,
         (((60.0 - 100.0 * t) * t + 60.0) * t + 20.0) * inv2,
         (20.0 * t * t * t) * inv2)
    return w, d, s


def _zrow_py(c0, c1, c2, c3, c4, c5, wz):
    """A row of six coefficients along z: the value, ∂_z and ∂²_z."""
    w, d, s = wz
    return (c0 * w[0] + c1 * w[1] + c2 * w[2] + c3 * w[3] + c4 * w[4] + c5 * w[5],
            c0 * d[0] + c1 * d[1] + c2 * d[2] + c3 * d[3] + c4 * d[4] + c5 * d[5],
            c0 * s[0] + c1 * s[1] + c2 * s[2] + c3 * s[3] + c4 * s[4] + c5 * s[5])


def _yslab_py(r0, r1, r2, r3, r4, r5, wy):
    """Six z-rows along y combined: the derivatives (b, c) = (0,0), (1,0), (2,0), (0,1), (1,1), (0,2)."""
    w, d, s = wy
    return (r0[0] * w[0] + r1[0] * w[1] + r2[0] * w[2] + r3[0] * w[3] + r4[0] * w[4] + r5[0] * w[5],
            r0[0] * d[0] + r1[0] * d[1] + r2[0] * d[2] + r3[0] * d[3] + r4[0] * d[4] + r5[0] * d[5],
            r0[0] * s[0] + r1[0] * s[1] + r2[0] * s[2] + r3[0] * s[3] + r4[0] * s[4] + r5[0] * s[5],
            r0[1] * w[0] + r1[1] * w[1] + r2[1] * w[2] + r3[1] * w[3] + r4[1] * w[4] + r5[1] * w[5],
            r0[1] * d[0] + r1[1] * d[1] + r2[1] * d[2] + r3[1] * d[3] + r4[1] * d[4] + r5[1] * d[5],
            r0[2] * w[0] + r1[2] * w[1] + r2[2] * w[2] + r3[2] * w[3] + r4[2] * w[4] + r5[2] * w[5])


def _xcomb_py(u0, u1, u2, u3, u4, u5, wx):
    """Six y-slabs along x combined: the ten derivatives of :data:`DERIVATIVES3`."""
    w, d, s = wx
    return (u0[0] * w[0] + u1[0] * w[1] + u2[0] * w[2] + u3[0] * w[3] + u4[0] * w[4] + u5[0] * w[5],
            u0[0] * d[0] + u1[0] * d[1] + u2[0] * d[2] + u3[0] * d[3] + u4[0] * d[4] + u5[0] * d[5],
            u0[1] * w[0] + u1[1] * w[1] + u2[1] * w[2] + u3[1] * w[3] + u4[1] * w[4] + u5[1] * w[5],
            u0[3] * w[0] + u1[3] * w[1] + u2[3] * w[2] + u3[3] * w[3] + u4[3] * w[4] + u5[3] * w[5],
            u0[0] * s[0] + u1[0] * s[1] + u2[0] * s[2] + u3[0] * s[3] + u4[0] * s[4] + u5[0] * s[5],
            u0[1] * d[0] + u1[1] * d[1] + u2[1] * d[2] + u3[1] * d[3] + u4[1] * d[4] + u5[1] * d[5],
            u0[3] * d[0] + u1[3] * d[1] + u2[3] * d[2] + u3[3] * d[3] + u4[3] * d[4] + u5[3] * d[5],
            u0[2] * w[0] + u1[2] * w[1] + u2[2] * w[2] + u3[2] * w[3] + u4[2] * w[4] + u5[2] * w[5],
            u0[4] * w[0] + u1[4] * w[1] + u2[4] * w[2] + u3[4] * w[3] + u4[4] * w[4] + u5[4] * w[5],
            u0[5] * w[0] + u1[5] * w[1] + u2[5] * w[2] + u3[5] * w[3] + u4[5] * w[4] + u5[5] * w[5])


_weights5 = njit(cache=True, error_model="numpy")(_weights5_py)
_zrow = njit(cache=True, error_model="numpy")(_zrow_py)
_yslab = njit(cache=True, error_model="numpy")(_yslab_py)


_xcomb = njit(cache=True, error_model="numpy")(_xcomb_py)


# -- evaluation: numpy -------------------------------------------------------------------------------

def _header(k, base):
    nx, ny, nz = int(k[base]), int(k[base + 1]), int(k[base + 2])
    return nx, ny, nz, k[base + 3:base + HEADER3]


def field3_np(k, s, x, y, z, P=0):
    """The ten derivatives (:data:`DERIVATIVES3`) of 3-D field ``s`` of the data at ``k[P:]`` at points
    (x, y, z), numpy arrays of any real or complex dtype: :func:`field3`'s operations, elementwise."""
    k = np.asarray(k, dtype=np.float64)
    base = P + int(k[P + s])
    nx, ny, nz, (x0, dx, y0, dy, z0, dz, ix, iy, iz) = _header(k, base)
    x, y, z = np.broadcast_arrays(x, y, z)
    xr, yr, zr = (np.real(v).astype(np.float64) for v in (x, y, z))
    with np.errstate(invalid="ignore"):
        i = np.where(np.isfinite(xr), np.clip(np.floor((xr - x0) / dx), 0, nx - 2), 0).astype(np.int64)
        j = np.where(np.isfinite(yr), np.clip(np.floor((yr - y0) / dy), 0, ny - 2), 0).astype(np.int64)
        kf = np.where(np.isfinite(zr), np.floor((zr - z0) / dz), 0.0)
    kz = (kf - nz * np.floor(kf / nz)).astype(np.int64)
    SY, SX = nz + 5, (ny + 4) * (nz + 5)
    start = base + HEADER3 + i * SX + j * SY + kz
    wx = _weights5_py((x - (x0 + i * dx)) * ix, ix, ix * ix)
    wy = _weights5_py((y - (y0 + j * dy)) * iy, iy, iy * iy)
    wz = _weights5_py((z - (z0 + kf * dz)) * iz, iz, iz * iz)
    u = []
    for a in range(6):
        rows = [_zrow_py(*(k[start + a * SX + b * SY + c] for c in range(6)), wz) for b in range(6)]
        u.append(_yslab_py(*rows, wy))
    return _xcomb_py(*u, wx)


# -- evaluation: compiled --------------------------------------------------------------------------

def _coef3(k, p, off):
    """Coefficient ``off`` past p: a number, or with p a Vec of each lane's start, the Vec of each
    lane's coefficient."""


@overload(_coef3)
def _coef3_ov(k, p, off):
    if isinstance(p, Vec):
        return lambda k, p, off: _gather(k, p, off)
    return lambda k, p, off: k[p + off]


@njit(cache=True, error_model="numpy")
def _locate3(k, base, xr, yr, zr):
    """The cell of the real point (xr, yr, zr): the index of its block's first coefficient, the
    node (x_i, y_j, z_k) it starts at (z_k unreduced, so z − z_k is the local offset), the strides."""
    nx, ny, nz = int(k[base]), int(k[base + 1]), int(k[base + 2])
    x0, dx, y0, dy, z0, dz = k[base + 3], k[base + 4], k[base + 5], k[base + 6], k[base + 7], k[base + 8]
    i = 0
    j = 0
    kf = 0.0
    if np.isfinite(xr):
        i = int(min(max(np.floor((xr - x0) / dx), 0.0), nx - 2.0))
    if np.isfinite(yr):
        j = int(min(max(np.floor((yr - y0) / dy), 0.0), ny - 2.0))
    if np.isfinite(zr):
        kf = np.floor((zr - z0) / dz)
    kz = int(kf - nz * np.floor(kf / nz))
    SY = nz + 5
    SX = (ny + 4) * SY
    return base + HEADER3 + i * SX + j * SY + kz, x0 + i * dx, y0 + j * dy, z0 + kf * dz, SX, SY


@njit(cache=True, error_model="numpy")
def _row(k, p, o, wz):
    return _zrow(_coef3(k, p, o), _coef3(k, p, o + 1), _coef3(k, p, o + 2), _coef3(k, p, o + 3),
                 _coef3(k, p, o + 4), _coef3(k, p, o + 5), wz)


@njit(cache=True, error_model="numpy")
def _slab(k, p, off, SY, wy, wz):
    return _yslab(_row(k, p, off, wz), _row(k, p, off + SY, wz), _row(k, p, off + 2 * SY, wz),
                  _row(k, p, off + 3 * SY, wz), _row(k, p, off + 4 * SY, wz), _row(k, p, off + 5 * SY, wz), wy)


@njit(cache=True, error_model="numpy")
def _evaluate3(k, p, SX, SY, wx, wy, wz):
    """The ten derivatives from the block at p (an index, or a Vec of them) with the three axes' weights."""
    return _xcomb(_slab(k, p, 0, SY, wy, wz), _slab(k, p, SX, SY, wy, wz), _slab(k, p, 2 * SX, SY, wy, wz),
                  _slab(k, p, 3 * SX, SY, wy, wz), _slab(k, p, 4 * SX, SY, wy, wz), _slab(k, p, 5 * SX, SY, wy, wz),
                  wx)


@njit(cache=True, error_model="numpy")
def _field3_scalar(k, P, s, x, y, z):
    """The ten derivatives of 3-D field ``s`` at one point (double, complex or double-double x, y, z)."""
    base = P + int(k[P + s])
    p, xi, yj, zk, SX, SY = _locate3(k, base, re(x), re(y), re(z))
    ix, iy, iz = k[base + 9], k[base + 10], k[base + 11]
    return _evaluate3(k, p, SX, SY, _weights5((x - xi) * ix, ix, ix * ix), _weights5((y - yj) * iy, iy, iy * iy),
                      _weights5((z - zk) * iz, iz, iz * iz))


def field3(k, P, s, x, y, z):
    """The ten derivatives (:data:`DERIVATIVES3`) of the system's 3-D field ``s`` at (x, y, z): ``k``
    the point function's parameter pointer, ``P`` the number of parameters before the data."""


@overload(field3, inline="never")
def _field3_ov(k, P, s, x, y, z):
    if isinstance(x, Vec) and isinstance(y, Vec) and isinstance(z, Vec):
        W = x.W

        def lanes(k, P, s, x, y, z):          # each lane's cell and local offsets, then the sums in vector form
            base = P + int(k[P + s])
            ix, iy, iz = k[base + 9], k[base + 10], k[base + 11]
            starts, tx, ty, tz = x, x, y, z
            SX, SY = 0, 0
            for l in range(W):
                xr, yr, zr = _vget(x, l), _vget(y, l), _vget(z, l)
                p, xi, yj, zk, SX, SY = _locate3(k, base, xr, yr, zr)
                starts = _vset(starts, l, float(p))
                tx = _vset(tx, l, (xr - xi) * ix)
                ty = _vset(ty, l, (yr - yj) * iy)
                tz = _vset(tz, l, (zr - zk) * iz)
            return _evaluate3(k, starts, SX, SY, _weights5(tx, ix, ix * ix), _weights5(ty, iy, iy * iy),
                              _weights5(tz, iz, iz * iz))
        return lanes
    if isinstance(x, DDVec) and isinstance(y, DDVec) and isinstance(z, DDVec):
        W = x.W

        def lanes_dd(k, P, s, x, y, z):
            hi = (x.hi, x.hi, x.hi, x.hi, x.hi, x.hi, x.hi, x.hi, x.hi, x.hi)
            lo = hi
            for l in range(W):
                o = _field3_scalar(k, P, s, dd(_vget(x.hi, l), _vget(x.lo, l)), dd(_vget(y.hi, l), _vget(y.lo, l)),
                                   dd(_vget(z.hi, l), _vget(z.lo, l)))
                hi, lo = _dd_put10(hi, lo, l, o)
            return _ddv10(hi, lo)
        return lanes_dd
    return lambda k, P, s, x, y, z: _field3_scalar(k, P, s, x, y, z)

