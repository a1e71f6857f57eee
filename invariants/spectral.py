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
    c = np.ascontiguousarray(fwd(np.ascontiguousarray(f, dtype=float)))
    # each part times 1/N: the numbers numpy's complex-by-real division gives (it multiplies by the
    # reciprocal), in a real loop (10 µs against 2 µs for 2,049 × 2 coefficients)
    return (c.view(np.float64) * (1.0 / f.shape[0])).view(np.complex128)


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


def loop_pairing(a, b, bh=None, ah=None):
    """∮ a·db/dτ dτ over [0, 1) for samples a, b (N, d) at τ_j = j/N, summed over the last axis.

    Computed in Fourier space (discrete Parseval): with â_k, b̂_k the rfft coefficients / N,

        ∮ a·b′ dτ = Σ_k conj(â_k)·(2πik) b̂_k = −4π Σ_{k=1}^{K} k Im(conj(â_k)·b̂_k),

    the Nyquist mode dropped as in :func:`loop_derivative`.  Mathematically the trapezoidal rule of
    a·(spectral b′); numerically it skips the inverse FFT of the derivative, whose round-off the
    high modes k ~ N/2 amplify: on PoincareInvariants.jl's 4-D Hénon map (two maps, I₁ = 2π,
    N = 1000) the error over 20 phases of the sampling is 4.7e-13 against 2.8e-12 in the median and
    1.6e-12 against 9.1e-12 in the worst; neither grows with N from 250 to 16,000 (docs/invariants.md)."""
    N = a.shape[0]
    ah = fourier_coefficients(a) if ah is None else ah
    bh = fourier_coefficients(b) if bh is None else bh      # (b's coefficients when already at hand)
    prod = (np.conj(ah) * bh).imag
    return -2.0 * np.pi * float(np.sum(_pairing_weights(ah.shape[0], N % 2 == 0, a.ndim) * prod))


@functools.lru_cache(maxsize=64)
def _pairing_weights(n, even, ndim):
    """2k for the modes k = 0 … n − 1 (twice: the ±k pair), 0 at the Nyquist mode of an even N, as a
    column (n, 1, …); read-only, shared between calls."""
    w = 2.0 * np.arange(n, dtype=float)
    if even:
        w[-1] = 0.0
    w = w.reshape((-1,) + (1,) * (ndim - 1))
    w.flags.writeable = False
    return w


def loop_integral(f):
    """∮ f dτ over [0, 1) by the trapezoidal rule: mean over axis 0."""
    return np.sum(f, axis=0) / f.shape[0]


def loop_tail(f, coefficients=None, absolute=None):
    """Relative size of the highest Fourier modes: max |f̂_k|, k ≥ 7/8·N/2, over max |f̂|
    (``coefficients``: f's, or ``absolute``: their absolute values, when already at hand)."""
    fh = absolute if absolute is not None else np.abs(fourier_coefficients(f) if coefficients is None else coefficients)
    K = fh.shape[0]
    top = max(1, K - max(K // 8, 2))
    peak = np.max(fh)
    return float(np.max(fh[top:]) / peak) if peak > 0 else 0.0


def top_mode(K):
    """The first mode of the top eighth of modes 0 … K (:func:`tail_model`'s)."""
    return max(1, K - max(K // 8, 2))


def decaying(c, axis=0):
    """Whether the absolute coefficients c (modes along ``axis``) fall towards the top: the top
    eighth's largest at round-off of the largest of all (ROUNDOFF_FLOOR), or the envelope (the
    largest coefficient from a mode on) falling by FLAT from the middle of the upper half's lower
    part to the top eighth (:func:`tail_model`'s reading of a floor).  A spectrum that does so has
    modes beyond it smaller still (the resolution monitor's assumption); a flat top (a jump, the
    points' own noise, the folded-back modes of a sampled product such as ϑ(q)) is no such spectrum."""
    c = np.moveaxis(np.asarray(c), axis, 0)
    return bool(np.max(c[top_mode(c.shape[0] - 1):]) <= ROUNDOFF_FLOOR * np.max(c) or falling(c))


def falling(c, axis=0):
    """Whether the envelope of the absolute coefficients c (modes along ``axis``) falls by FLAT from
    the middle of the upper half's lower part to the top eighth: a spectrum, not a floor."""
    c = np.moveaxis(np.asarray(c), axis, 0)
    K = c.shape[0] - 1
    top = top_mode(K)
    k1 = min(max(1, K // 2), top - 1) if top > 1 else 0
    k3 = min((k1 + top) // 2, top - 1) if top > 1 else 0
    return bool(np.max(c[k3:]) >= FLAT * np.max(c[top:]))


def top_at_roundoff(c, axes=(0,)):
    """Whether the absolute coefficients c have their top eighth of modes, along each of ``axes``,
    within ROUNDOFF_FLOOR of their largest: a sampled function whose modes beyond the samples, which
    fold onto the top first, are round-off (and stay there: the monitor's assumption)."""
    c = np.asarray(c)
    peak = np.max(c)
    for axis in axes:
        top = top_mode(c.shape[axis] - 1)
        if np.max(np.take(c, np.arange(top, c.shape[axis]), axis=axis)) > ROUNDOFF_FLOOR * peak:
            return False
    return True


ROUNDOFF_FLOOR = 64 * np.finfo(float).eps   # tails within 64 ulps of a column's largest coefficient are round-off
FLAT = 4.0               # a tail whose envelope falls by less than this over the eighth below the top is a floor


def tail_model(c, axis=0, medians=False, slow=0.5):
    """A model of a spectrum beyond the modes at hand, from its top: ``(top, tau, r)`` per column.

    c : absolute coefficients (K + 1, ...) along ``axis`` 0 (modes 0 … K).  ``top`` is the first mode
    of the top eighth (as :func:`loop_tail`), ``tau`` (...) the largest coefficient from ``top`` on,
    0 where the tail is no decaying spectrum: within ROUNDOFF_FLOOR of the column's largest
    coefficient (mode 0 included: the floor of the transform), or flat (the envelope falling by less
    than FLAT over the eighth of the modes below the top eighth; with ``medians``, the median of that
    eighth less than FLAT times the top eighth's, which one large coefficient of a floor cannot
    sway, or the envelope falling by less than FLAT over the whole upper half: the sampled points' own noise, Newton's tolerance and
    round-off carried along the orbits, which does not alias coherently; measured: a floor at
    1e-12 of the peak moved a stretched loop's I₁ by 4e-15 where a coherent reading says 4e-11).
    A flat tail well above round-off (a jump: an angle wrapped into [0, 2π)) is the other
    reading's to flag, the set's relative tail (:func:`loop_tail`); and ``r`` (...) ∈ [0, 1] the square root of the mean ratio
    of one mode to the next over the upper half of the modes, read from the envelope (the largest
    coefficient from each mode on): r = (tau / envelope[K/2])^(slow/(top − K/2)).  A coefficient
    m ≥ top is estimated as ``tau · r^(m − top)``: the far tail assumed to decay at half the rate
    the upper modes show (a product such as ϑ(q) of a band-limited q decays more slowly beyond the
    modes at hand than within them: tests/test_invariants.py), a flat floor (r = 1) where the
    spectrum does not decay (a spline's algebraic tail).  The estimate errs large against a
    spectrum that decays monotonically."""
    return tail_models([np.moveaxis(np.asarray(c), axis, 0)], medians, slow)[0][:3]


NARROW = 16          # columns below which the spectra's envelopes are read by a compiled loop


def tail_models(cs, medians=False, slow=0.5):
    """:func:`tail_model` of several spectra (modes on axis 0, the same number of modes), the same
    numbers as one call each, with each column's largest coefficient from ``top`` on and overall:
    [(top, tau, r, top's maximum, peak)].  A few columns in all (< NARROW) have their envelopes read
    by one compiled pass (:func:`_envelope_columns`): numpy's reductions along a long axis 0 of a
    narrow array run an element at a time (46 µs against 2 µs for the maximum of 2,049 × 2), and a
    dozen numpy calls on them cost more than the arithmetic."""
    K = cs[0].shape[0] - 1
    top = max(1, K - max(K // 8, 2))
    k1 = min(max(1, K // 2), top - 1) if top > 1 else 0
    k3 = min((k1 + top) // 2, top - 1) if top > 1 else 0
    cols = sum(c.shape[1] if c.ndim == 2 else NARROW for c in cs)
    if not medians and cols < NARROW:
        env = np.empty((4, cols))
        if len(cs) == 2:                             # (the aliasing estimate's two factors: one call)
            _envelope_pair(np.asarray(cs[0], dtype=float), np.asarray(cs[1], dtype=float), top, k1, k3, env)
        else:
            lo = 0
            for c in cs:
                _envelope_columns(np.asarray(c, dtype=float), top, k1, k3, env, lo)
                lo += c.shape[1]
        tau, ratio = _tau_ratio(env)                 # the model's comparisons and division, compiled
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.clip(ratio ** (slow / max(top - k1, 1)), 0.0, 1.0)
        out, lo = [], 0
        for c in cs:
            hi = lo + c.shape[1]
            out.append((top, tau[lo:hi], r[lo:hi], env[0, lo:hi], env[3, lo:hi]))
            lo = hi
        return out
    return [(top,) + _tail(c, K, top, k1, k3, medians, slow) for c in cs]


@njit(cache=True, error_model="numpy")
def _envelope_columns(c, top, k1, k3, env, lo):
    """env[:, lo + i] = the envelope max(c[m:, i]) of column i at m = top, k3, k1, 0 (rows 0 … 3);
    a NaN wins, as in numpy's maximum."""
    K1 = c.shape[0]
    for i in range(c.shape[1]):
        m = c[K1 - 1, i]
        for row, (a, b) in enumerate(((top, K1 - 1), (k3, top), (k1, k3), (0, k1))):
            for n in range(a, b):
                v = c[n, i]
                if v > m or v != v:
                    m = v
            env[row, lo + i] = m


@njit(cache=True, error_model="numpy")
def _envelope_pair(a, b, top, k1, k3, env):
    """:func:`_envelope_columns` of a, then of b beside it."""
    _envelope_columns(a, top, k1, k3, env, 0)
    _envelope_columns(b, top, k1, k3, env, a.shape[1])


@njit(cache=True, error_model="numpy")
def _tau_ratio(env):
    """(tau, ratio) of :func:`_model` from the envelope rows e_top, e3, e1, peak: the same
    comparisons and the same division, element by element."""
    n = env.shape[1]
    tau, ratio = np.empty(n), np.empty(n)
    for i in range(n):
        e_top, e3, e1, peak = env[0, i], env[1, i], env[2, i], env[3, i]
        noise = (e_top <= ROUNDOFF_FLOOR * peak) or (e3 < FLAT * e_top)
        tau[i] = 0.0 if noise else e_top
        ratio[i] = tau[i] / e1 if e1 > 0 else 0.0
    return tau, ratio


def _tail(c, K, top, k1, k3, medians, slow):
    """(tau, r) of :func:`tail_model`, the largest coefficient from ``top`` on and the largest of all,
    of the spectra c (modes on axis 0)."""
    # the envelope at the three modes the model reads, env[i] = max(c[i:]), from maxima of the
    # segments between them (the same numbers as the whole running maximum, at a fraction of its cost)
    def seg(a, b):
        return np.max(c[a:b], axis=0)
    e_top = seg(top, K + 1)
    e3 = np.maximum(seg(k3, top), e_top) if k3 < top else e_top
    e1 = np.maximum(seg(k1, k3), e3) if k1 < k3 else e3
    peak = np.maximum(seg(0, k1), e1) if k1 > 0 else e1
    flat = None
    if medians:                          # robust to one large coefficient of a noise floor
        flat = (np.median(c[k3:top], axis=0) < FLAT * np.median(c[top:], axis=0)) | (e1 < FLAT * e_top)
    return _model(e_top, e3, e1, peak, top, k1, flat, slow)


def _model(e_top, e3, e1, peak, top, k1, flat, slow):
    """(tau, r, e_top, peak) of :func:`tail_model` from the envelope at top, k3, k1 and 0 (``flat``:
    the medians' reading, or None for the envelope's)."""
    flat = e3 < FLAT * e_top if flat is None else flat
    noise = (e_top <= ROUNDOFF_FLOOR * peak) | flat
    tau = np.where(noise, 0.0, e_top)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(e1 > 0, tau / np.where(e1 > 0, e1, 1.0), 0.0)
        r = np.clip(ratio ** (slow / max(top - k1, 1)), 0.0, 1.0)
    return tau, r, e_top, peak


def loop_shifted(ch, N, phase):
    """Samples at τ_j = (j + phase)/N of the trigonometric interpolant whose coefficients (rfft / N)
    are ``ch`` (N//2 + 1, ...), the Nyquist mode of an even N dropped (as :func:`loop_derivative`
    drops it): the interpolant evaluated between the samples, and its coefficients there,
    (values (N, ...), coefficients).  ``phase`` in [0, 1): a fraction of the grid step."""
    k = np.arange(ch.shape[0], dtype=float)
    c = ch * np.exp(2j * np.pi * k * (phase / N)).reshape((-1,) + (1,) * (ch.ndim - 1))
    if N % 2 == 0:
        c[-1] = 0.0
    _, inv = _plans((N,) + ch.shape[1:])
    return inv(c * N).copy(), c


def loop_pairing_error(ah, bh, N, absolute=None, tails=False, model=(True, True)):
    """An estimate, erring large, of the error of :func:`loop_pairing` (∮ a·b′ dτ from N samples)
    from the two factors' Fourier coefficients ``ah``, ``bh`` (K + 1, d) (rfft / N).

    The sampled coefficients of a are aliased: â_k = a_k + a_{k−N} + a_{k+N} + …, so the discrete
    sum Σ 2πik conj(â_k) b̂_k carries the products k·b_k·a_{N−k} and k·a_k·b_{N−k} of each mode with
    the mode N − k of the other factor, and misses the modes beyond K.  The product ϑ(q)·q′ reaches
    modes several times further than q (a band-limited q, modes 1 … 20, gives I₁ wrong by
    1e-6 on 64 points while q's own top modes are zero), so this looks at both factors' spectra:
    with each factor's modes beyond K estimated by :func:`tail_model`,

        E = 4π Σ_i Σ_{k=1}^{K} k (|b̂_ik| α_a,i(N − k) + |â_ik| α_b,i(N − k)) + 4π Σ_i Σ_{m>K} m α_a,i(m) α_b,i(m),

    Returns ``(E, R)``: E, and the sum's own round-off R, 8 ulps of the size of its terms
    4π Σ k |â_k||b̂_k| (which can be 10⁴ times the value on a loop that shear has stretched: the terms
    cancel).  More points lower E, not R.  ``absolute``: (|â|, |b̂|) when already at hand.
    ``tails``: also each factor's :func:`loop_tail`, read off the same spectra: (E, R, tail_a, tail_b).
    ``model``: whether each factor's modes beyond K are modelled (a factor computed on the loop,
    such as ϑ(q), needs no model where its aliasing is measured by padding: (False, True)).
    """
    A, B = (np.abs(ah), np.abs(bh)) if absolute is None else absolute
    K = A.shape[0] - 1
    (ta, tau_a, r_a, top_a, peak_a), (tb, tau_b, r_b, top_b, peak_b) = tail_models([A, B])
    k = _modes(K, A.ndim)
    m = N - k                                                   # the alias partner, ≥ K ≥ top
    e = 0.0
    pos_a, pos_b = (tau_a > 0) & model[0], (tau_b > 0) & model[1]    # columns whose tail is a spectrum
    for tau, r, t0, other, pos in ((tau_a, r_a, ta, B, pos_a), (tau_b, r_b, tb, A, pos_b)):
        if pos.any():
            live = np.flatnonzero(np.ravel(pos))
            sel = (slice(1, None), live) if A.ndim == 2 else (slice(1, None),)
            tl, rl = (np.ravel(tau)[live], np.ravel(r)[live]) if A.ndim == 2 else (tau, r)
            e += float(np.sum(k * other[sel] * (tl * rl ** (m - t0))))
    ro = 8.0 * _EPS * np.sum(k * A[1:] * B[1:])                 # the sum's round-off: 8 ulps of its terms' size
    # modes beyond K: Σ_{m>K} m α_a(m) α_b(m), at most K + 1 terms of the geometric tail counted
    if (pos_a & pos_b).any():                # (else every term is 0: e + 0 is e)
        rr = r_a * r_b
        g = np.minimum(np.where(rr < 1, 1.0 / np.where(rr < 1, 1.0 - rr, 1.0), K + 1.0), K + 1.0)
        beyond = (K + 1) * tau_a * r_a ** (K + 1 - ta) * tau_b * r_b ** (K + 1 - tb) * g * 2.0
        e = e + np.sum(beyond)
    if tails:
        return (4.0 * np.pi * float(e), 4.0 * np.pi * float(ro), _reading(top_a, peak_a), _reading(top_b, peak_b))
    return 4.0 * np.pi * float(e), 4.0 * np.pi * float(ro)


def _reading(top, peak):
    """:func:`loop_tail` from the columns' largest top coefficients and peaks (maxima: exact)."""
    peak = peak.max()
    return float(top.max() / peak) if peak > 0 else 0.0


_EPS = float(np.finfo(float).eps)


@functools.lru_cache(maxsize=64)
def _modes(K, ndim):
    """The modes 1 … K as a column (K, 1, …) of floats (read-only: shared between calls)."""
    k = np.arange(1, K + 1, dtype=float).reshape((-1,) + (1,) * (ndim - 1))
    k.flags.writeable = False
    return k


def relative(error, value):
    """error / |value|, the monitor's scale-free reading: 0 where there is no error, inf where the
    value is 0 and the error is not."""
    if error == 0.0:
        return 0.0
    return error / abs(value) if value != 0.0 else float("inf")


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


def chebyshev_refined(v, shape):
    """Values at the ascending Chebyshev points of ``shape`` (m_σ, m_τ) of the tensor interpolant of
    v (n_σ, n_τ, ...) at its own points: its coefficients padded with zeros (m ≥ n)."""
    c = chebyshev_coefficients(chebyshev_coefficients(v, 0), 1)
    pad = np.zeros(tuple(shape) + v.shape[2:])
    pad[:v.shape[0], :v.shape[1]] = c
    return chebyshev_values(chebyshev_values(pad, 0), 1)


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


def _cc_moment(m):
    """∫_0^1 T_m(2x − 1) dx: 1/(1 − m²) for even m, 0 for odd (m an array)."""
    m = np.asarray(m, dtype=float)
    even = m % 2 == 0
    return np.where(even, 1.0 / (1.0 - np.where(even, m, 0.0) ** 2), 0.0)


def surface_roundoff(f):
    """The round-off of :func:`surface_integral` of f: 8 ulps of the integral of |f|."""
    return 8.0 * np.finfo(float).eps * float(surface_integral(np.abs(f)))


def surface_quadrature_error(f):
    """An estimate, erring large, of the error of :func:`surface_integral` of f (n_σ, n_τ) from f's
    own Chebyshev coefficients c_jl: along σ, the integrals over τ of the σ-modes, |Σ_l c_jl ∫T_l|
    (what each σ-mode adds to the value: a mode whose τ-profile integrates to zero, as
    cos 2πτ on the paper's surface, adds nothing whatever its size), and the same along τ, modelled beyond the n at hand by :func:`tail_model` (floors told by medians: a
    surface has too few coefficients a direction for one large one not to sway an envelope; the
    tail decaying at the rate its top shows, ``slow`` = 1: the integrand is sampled itself, not
    paired with another factor's alias as on a loop); a coefficient j ≥ n of T_j is
    integrated by Clenshaw–Curtis as its alias T_{2(n−1)−j} (j ≤ 2(n − 1)), an error of
    |∫T_{2(n−1)−j} − ∫T_j|; further modes count at most 2 each (n of them at most)."""
    c = chebyshev_coefficients(chebyshev_coefficients(f, 0), 1)
    ms, mt = _cc_moment(np.arange(c.shape[0])), _cc_moment(np.arange(c.shape[1]))
    e = 0.0
    for spec in (np.abs(c @ mt), np.abs(ms @ c)):
        n = spec.shape[0]
        top, tau, r = tail_model(spec, medians=True, slow=1.0)
        j = np.arange(n, 2 * n - 1, dtype=float)
        alpha = tau * r ** (j - top)
        e += float(np.sum(alpha * np.abs(_cc_moment(2 * (n - 1) - j) - _cc_moment(j))))
        rest = tau * r ** (2 * n - 1 - top)
        e += float(2.0 * rest * min(n, 1.0 / (1.0 - r) if r < 1 else n))
    return e
