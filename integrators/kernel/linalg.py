"""Small dense linear algebra per lane and exact sums: LU with partial pivoting chosen per lane
(:func:`lu_factor`, :func:`lu_solve`), the products with ϑ_q and ϑ_qq the equations are made of
(:func:`transpose_apply`, :func:`apply`, :func:`contract`), the error-free transformations
(:func:`rounding`, :func:`product_rounding`) and the compensated weighted sum of the stages
(:func:`_weighted_sum`).  Every function is written against integrators.simd, so it serves one
lane (scalar, complex-step, double-double) and W real lanes alike."""
from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import overload

from ..simd import LanePtr, anyl, ld, ldi, lget, lset, mnot, nlanes, re, sel, st, sti
from .records import _OPTS


@njit(inline='always', **_OPTS)
def rounding(a, b, s):
    """(a + b) − s exactly, for s = fl(a + b) (Knuth's TwoSum)."""
    bb = s - a
    return (a - (s - bb)) + (b - bb)


@njit(**_OPTS)
def product_rounding(a, b, p):
    """a·b − p exactly, for p = fl(a·b) (Dekker's TwoProduct with Veltkamp's splitting: no fused
    multiply-add, so the same bits on every machine; exact while |a|, |b| < 2⁹⁹⁶)."""
    ca = 134217729.0 * a                    # 2²⁷ + 1
    ah = ca - (ca - a)
    al = a - ah
    cb = 134217729.0 * b
    bh = cb - (cb - b)
    bl = b - bh
    return ((ah * bh - p) + ah * bl + al * bh) + al * bl


@njit(**_OPTS)
def _weighted_sum(wt, wt_lo, o, v, s, d, m):
    """Σ_i (wt_{o+i} + wt_lo_{o+i}) v_{i,m} as (the sum rounded to double, what that rounding
    dropped): each product's and each addition's rounding error is kept (:func:`product_rounding`,
    :func:`rounding`) and summed apart, so the pair is the sum to O(ε²) of its size (Ogita, Rump
    and Oishi's Dot2).  Compiled apart, not inlined into numba's IR (LLVM still inlines it): the
    same bits and speed, and 10 s less compilation per kernel (docs/benchmarks-history.md)."""
    x = ld(v, m)
    acc = wt[o] * x
    err = product_rounding(wt[o], x, acc) + wt_lo[o] * x
    for i in range(1, s):
        x = ld(v, i * d + m)
        pr = wt[o + i] * x
        t = acc + pr
        err = err + ((rounding(acc, pr, t) + product_rounding(wt[o + i], x, pr)) + wt_lo[o + i] * x)
        acc = t
    out = acc + err
    return out, err - (out - acc)


# -- small dense linear algebra, per lane ---------------------------------------------------------

def pivot(A, piv, col, n):
    """Partial pivoting of column ``col``, each lane on its own: the first row at or below col whose
    |real part| is strictly the largest becomes the pivot (piv[col]), and rows col and that one swap
    (the whole row, as LAPACK does)."""


@overload(pivot, inline="always")
def _pivot(A, piv, col, n):
    if _real_lanes(A):
        def vector(A, piv, col, n):       # W real lanes: the search by compares and selects
            best = abs(ld(A, col * n + col))
            p = sel(best == best, float(col), float(col))
            for i in range(col + 1, n):
                v = abs(ld(A, i * n + col))
                larger = v > best
                best = sel(larger, v, best)
                p = sel(larger, float(i), p)
            sti(piv, col, p)
            for i in range(col + 1, n):
                swap = p == float(i)
                if anyl(swap):
                    for j in range(n):
                        a, b = ld(A, col * n + j), ld(A, i * n + j)
                        st(A, col * n + j, sel(swap, b, a))
                        st(A, i * n + j, sel(swap, a, b))
        return vector

    def lanewise(A, piv, col, n):         # one lane, complex-step or double-double values: lane by lane
        for l in range(nlanes(A)):
            p = col
            best = abs(re(lget(A, col * n + col, l)))
            for i in range(col + 1, n):
                v = abs(re(lget(A, i * n + col, l)))
                if v > best:
                    best, p = v, i
            lset(piv, col, l, p)
            if p != col:
                for j in range(n):
                    tmp = lget(A, col * n + j, l)
                    lset(A, col * n + j, l, lget(A, p * n + j, l))
                    lset(A, p * n + j, l, tmp)
    return lanewise


@njit(inline='always', **_OPTS)
def lu_factor(A, piv, n):
    """In-place LU of the n×n row-major A with partial pivoting, each lane its own pivots (chosen on
    the real part, so the complex-step specialisation pivots exactly as the real one).  A zero pivot
    is left in place: the solve then gives inf/NaN, which the Newton iteration reads as a failure."""
    for col in range(n):
        pivot(A, piv, col, n)
        inv = 1.0 / ld(A, col * n + col)
        for i in range(col + 1, n):
            f = ld(A, i * n + col) * inv
            st(A, i * n + col, f)
            nonzero = f != 0.0
            if not anyl(mnot(nonzero)):           # every lane eliminates: no selects needed
                for j in range(col + 1, n):
                    st(A, i * n + j, ld(A, i * n + j) - f * ld(A, col * n + j))
            elif anyl(nonzero):
                for j in range(col + 1, n):
                    x = ld(A, i * n + j)
                    st(A, i * n + j, sel(nonzero, x - f * ld(A, col * n + j), x))


def _real_lanes(A):
    """Whether A is a pointer to W > 1 lanes of doubles (the vector forms of the pivoting)."""
    return isinstance(A, LanePtr) and A.W > 1 and A.dtype == types.float64


def permute(piv, x, n):
    """x[i] ⇄ x[piv[i]] for i = 0 … n − 1, each lane with its own pivots (the row swaps of
    :func:`lu_factor` applied to a right-hand side)."""


@overload(permute, inline="always")
def _permute(piv, x, n):
    if _real_lanes(x):
        def vector(piv, x, n):            # W real lanes: compares and selects, nothing lane by lane
            for i in range(n):
                p = ldi(piv, i)
                if anyl(p != float(i)):
                    xi = ld(x, i)
                    new = xi
                    for r in range(i + 1, n):
                        here = p == float(r)
                        if anyl(here):
                            xr = ld(x, r)
                            st(x, r, sel(here, xi, xr))
                            new = sel(here, xr, new)
                    st(x, i, new)
        return vector

    def lanewise(piv, x, n):              # one lane, complex-step or double-double values
        for i in range(n):
            for l in range(nlanes(x)):
                p = lget(piv, i, l)
                if p != i:
                    tmp = lget(x, i, l)
                    lset(x, i, l, lget(x, p, l))
                    lset(x, p, l, tmp)
    return lanewise


@njit(inline='always', **_OPTS)
def lu_solve(A, piv, x, n):
    """Solve A x = b in place (x holds b on entry) with the factors of :func:`lu_factor`."""
    permute(piv, x, n)
    for i in range(n):
        acc = ld(x, i)
        for j in range(i):
            acc = acc - ld(A, i * n + j) * ld(x, j)
        st(x, i, acc)
    for i in range(n - 1, -1, -1):
        acc = ld(x, i)
        for j in range(i + 1, n):
            acc = acc - ld(A, i * n + j) * ld(x, j)
        st(x, i, acc / ld(A, i * n + i))


@njit(inline='always', **_OPTS)
def transpose_apply(T, v, out, d):
    """out_m = Σ_l T[l, m] v_l  (ϑ_qᵀ v)."""
    for m in range(d):
        acc = ld(T, m) * ld(v, 0)
        for l in range(1, d):
            acc = acc + ld(T, l * d + m) * ld(v, l)
        st(out, m, acc)


@njit(inline='always', **_OPTS)
def apply(T, v, out, d):
    """out_l = Σ_m T[l, m] v_m  (ϑ_q v)."""
    for l in range(d):
        acc = ld(T, l * d) * ld(v, 0)
        for m in range(1, d):
            acc = acc + ld(T, l * d + m) * ld(v, m)
        st(out, l, acc)


@njit(inline='always', **_OPTS)
def contract(TT, v, out, d):
    """out[m, n] = Σ_l TT[l, m, n] v_l  (∂(ϑ_qᵀ v)/∂q)."""
    dd = d * d
    for mn in range(dd):
        acc = ld(TT, mn) * ld(v, 0)
        for l in range(1, d):
            acc = acc + ld(TT, l * dd + mn) * ld(v, l)
        st(out, mn, acc)


@njit(inline='always', **_OPTS)
def _scale(x):
    """max(|x|, 1), or 1 where that is not finite: the size every unknown is measured against."""
    a = abs(x)
    sc = sel(a > 1.0, a, 1.0)
    return sel(np.isfinite(sc), sc, 1.0)


@njit(inline='always', **_OPTS)
def _own(x):
    """|x|, or 1 where that is not finite: a coordinate's own size, below 1 too (the settled
    approach's grid, :func:`integrators.kernel.newton._settle`: the floor's noise is in the ulps of
    the coordinate, not of :func:`_scale`)."""
    a = abs(x)
    return sel(np.isfinite(a), a, 1.0)
