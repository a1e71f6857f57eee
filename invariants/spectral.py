"""Spectral calculus on loops (Fourier) and surfaces (Chebyshev), batched over trailing axes.

Loops: N equispaced τ_j = j/N on [0, 1); dq/dτ by FFT (pyfftw plans built once per
array shape and reused); ∮ f dτ by the trapezoidal rule (spectrally accurate for
smooth periodic f).

Surfaces: Chebyshev points of the second kind mapped to [0, 1], ascending,
x_k = (1 + chebpts2_k)/2; values → Chebyshev coefficients by a DCT-I along each
axis (the transform chebpy's ``vals2coeffs2`` applies in 1-D); derivatives by the
coefficient recurrence; tensor Clenshaw–Curtis quadrature.
"""
from __future__ import annotations

import functools

import numpy as np
import pyfftw
from numba import njit
import scipy.fft
from numpy.polynomial import chebyshev as C


def chebpts2(n: int) -> np.ndarray:
    """n Chebyshev points of the second kind on [−1, 1], ascending: chebpy's ``chebpts2``, bit for bit
    (tests/test_invariants.py compares them).  Written here because importing chebpy loads
    matplotlib.pyplot: 0.43 s of every process's start, on every rank (docs/benchmarks.md)."""
    if n == 1:
        return np.array([0.0])
    return np.cos(np.arange(n)[::-1] * np.pi / (n - 1))

# ----------------------------------------------------------------------------- loops

_PLANS: dict = {}


def _plans(shape):
    """Forward and inverse real FFT plans along axis 0 for arrays of ``shape`` (cached)."""
    key = tuple(shape)
    if key not in _PLANS:
        a = pyfftw.empty_aligned(shape, dtype="float64")
        fwd = pyfftw.builders.rfft(a, axis=0, planner_effort="FFTW_ESTIMATE", threads=1)
        spec = pyfftw.empty_aligned(fwd.output_shape, dtype="complex128")
        inv = pyfftw.builders.irfft(spec, n=shape[0], axis=0, planner_effort="FFTW_ESTIMATE", threads=1)
        _PLANS[key] = (fwd, inv)
    return _PLANS[key]


def fourier_coefficients(f):
    """rfft of f along axis 0 divided by N: (N//2 + 1, ...)."""
    fwd, _ = _plans(f.shape)
    return fwd(np.ascontiguousarray(f, dtype=float)) / f.shape[0]


def loop_derivative(f):
    """df/dτ of samples f (N, ...) at τ_j = j/N, τ ∈ [0, 1): spectral, Nyquist mode dropped."""
    N = f.shape[0]
    fwd, inv = _plans(f.shape)
    fh = fwd(np.ascontiguousarray(f, dtype=float)).copy()
    k = np.arange(fh.shape[0], dtype=float)
    if N % 2 == 0:
        k[-1] = 0.0
    fh *= (2j * np.pi * k).reshape((-1,) + (1,) * (f.ndim - 1))
    return inv(fh).copy()


def loop_pairing(a, b, bh=None):
    """∮ a·db/dτ dτ over [0, 1) for samples a, b (N, d) at τ_j = j/N, summed over the last axis.

    Computed in Fourier space (discrete Parseval): with â_k, b̂_k the rfft coefficients / N,

        ∮ a·b′ dτ = Σ_k conj(â_k)·(2πik) b̂_k = −4π Σ_{k=1}^{K} k Im(conj(â_k)·b̂_k),

    the Nyquist mode dropped as in :func:`loop_derivative`.  Mathematically the trapezoidal rule of
    a·(spectral b′); numerically it skips the inverse FFT of the derivative, whose round-off the
    high modes k ~ N/2 amplify: on PoincareInvariants.jl's 4-D Hénon map (two maps, I₁ = 2π,
    N = 1000) the error over 20 phases of the sampling is 4.7e-13 against 2.8e-12 in the median and
    1.6e-12 against 9.1e-12 in the worst; neither grows with N from 250 to 16,000 (docs/invariants.md)."""
    N = a.shape[0]
    ah = fourier_coefficients(a)
    bh = fourier_coefficients(b) if bh is None else bh      # (b's coefficients when already at hand)
    w = 2.0 * np.arange(ah.shape[0], dtype=float)           # k, twice for the ±k pair
    if N % 2 == 0:
        w[-1] = 0.0
    prod = (np.conj(ah) * bh).imag
    return -2.0 * np.pi * float(np.sum(w.reshape((-1,) + (1,) * (a.ndim - 1)) * prod))


def loop_integral(f):
    """∮ f dτ over [0, 1) by the trapezoidal rule: mean over axis 0."""
    return np.sum(f, axis=0) / f.shape[0]


def loop_tail(f, coefficients=None):
    """Relative size of the highest Fourier modes: max |f̂_k|, k ≥ 7/8·N/2, over max |f̂|
    (``coefficients``: f's, when already at hand)."""
    fh = np.abs(fourier_coefficients(f) if coefficients is None else coefficients)
    K = fh.shape[0]
    top = max(1, K - max(K // 8, 2))
    peak = np.max(fh)
    return float(np.max(fh[top:]) / peak) if peak > 0 else 0.0


# ----------------------------------------------------------------------------- surfaces

@functools.lru_cache(maxsize=None)
def chebyshev_points(n: int) -> np.ndarray:
    """n Chebyshev points of the second kind on [0, 1], ascending."""
    if n < 2:
        raise ValueError("a surface needs at least 2 Chebyshev points per direction")
    x = (1.0 + chebpts2(n)) / 2.0
    x[0], x[-1] = 0.0, 1.0
    return x


def chebyshev_coefficients(v, axis):
    """Values at ascending Chebyshev points → coefficients of Σ c_j T_j(2x − 1) along ``axis`` (DCT-I)."""
    n = v.shape[axis]
    c = scipy.fft.dct(np.flip(v, axis=axis), type=1, axis=axis)
    c /= n - 1
    sl = [slice(None)] * v.ndim
    for end in (0, n - 1):
        sl[axis] = end
        c[tuple(sl)] /= 2
    return c


def chebyshev_values(c, axis):
    """Coefficients → values at the ascending Chebyshev points (inverse of the above)."""
    n = c.shape[axis]
    c = c.copy()
    sl = [slice(None)] * c.ndim
    sl[axis] = slice(1, n - 1)
    c[tuple(sl)] /= 2
    return np.flip(scipy.fft.dct(c, type=1, axis=axis, overwrite_x=True), axis=axis)


@njit(cache=True, error_model="numpy")
def _chebder(c, scl):
    """numpy.polynomial.chebyshev.chebder(c, scl=scl) along axis 0 of a 2-D c, the same operations in
    the same order (the same bits), compiled: numpy's version loops over the n coefficients in
    Python, which made it a third of the surface invariant's time."""
    n0, m = c.shape
    c = c * scl
    n = n0 - 1
    der = np.empty((n0, m))
    der[n, :] = 0.0                            # the padding row chebyshev_derivative adds
    for j in range(n, 2, -1):                  # (row by row: each column sees numpy's sequence)
        for k in range(m):
            der[j - 1, k] = (2 * j) * c[j, k]
            c[j - 2, k] += (j * c[j, k]) / (j - 2)
    for k in range(m):
        if n > 1:
            der[1, k] = 4 * c[2, k]
        der[0, k] = c[1, k]
    return der


def chebyshev_derivative(v, axis, coefficients=None):
    """∂v/∂x along ``axis`` for values at Chebyshev points on [0, 1] (``coefficients``: those of v
    along ``axis`` when already at hand)."""
    c = chebyshev_coefficients(v, axis) if coefficients is None else coefficients
    c0 = np.moveaxis(c, axis, 0)
    dc = _chebder(np.ascontiguousarray(c0).reshape(c0.shape[0], -1), 2.0).reshape(c0.shape)  # d/dx = 2 d/dξ
    return chebyshev_values(np.moveaxis(dc, 0, axis), axis)


@functools.lru_cache(maxsize=None)
def clenshaw_curtis_weights(n: int) -> np.ndarray:
    """Weights w with Σ w_k f(x_k) = ∫_0^1 f for the interpolant at the n Chebyshev points."""
    moments = np.zeros(n)
    j = np.arange(0, n, 2)
    moments[::2] = 2.0 / (1.0 - j.astype(float) ** 2)
    # w = Tᵀ m, T the values → coefficients map
    T = chebyshev_coefficients(np.eye(n), axis=0)
    return 0.5 * (T.T @ moments)


def surface_integral(f):
    """∫_0^1 ∫_0^1 f dσ dτ for f (nσ, nτ, ...) at Chebyshev points: tensor Clenshaw–Curtis."""
    ws, wt = clenshaw_curtis_weights(f.shape[0]), clenshaw_curtis_weights(f.shape[1])
    return np.tensordot(ws, np.tensordot(wt, f, axes=([0], [1])), axes=([0], [0]))


def surface_tail(v, coefficients0=None):
    """Relative size of the Chebyshev coefficients with index ≥ 7/8 n in either direction
    (``coefficients0``: those of v along axis 0 when already at hand)."""
    c0 = chebyshev_coefficients(v, 0) if coefficients0 is None else coefficients0
    return coefficient_tail(np.abs(chebyshev_coefficients(c0, 1)))


def coefficient_tail(c):
    """:func:`surface_tail` from the absolute 2-D Chebyshev coefficients (n_σ, n_τ, ...)."""
    ns, nt = c.shape[:2]
    ks, kt = max(1, ns - max(ns // 8, 2)), max(1, nt - max(nt // 8, 2))
    peak = np.max(c)
    tail = max(np.max(c[ks:]), np.max(c[:, kt:]))
    return float(tail / peak) if peak > 0 else 0.0
