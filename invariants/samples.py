"""Sample sets: loops (N equispaced τ ∈ [0, 1)) and surfaces (n_σ × n_τ Chebyshev points on [0, 1]²)."""
from __future__ import annotations

import numpy as np

from .spectral import chebyshev_points

TWO_PI = 2.0 * np.pi


def loop_parameters(n: int) -> np.ndarray:
    """τ_j = j/n, j = 0 … n − 1."""
    if int(n) != n or n < 3:
        raise ValueError(f"a loop needs at least 3 points, got {n}")
    return np.arange(int(n)) / int(n)


def loop(shape="guiding_centre", n=2000, **params):
    """Points of a closed loop: (n, d).

    shape
        ``"guiding_centre"``: the paper's loop of sec:app_integral_invariants,
        q(τ) = (r_x cos 2πτ, r_y sin 2πτ, r_z sin 2πτ, u₀ + u₁ cos 2πτ), defaults
        r_x = 0.5, r_y = 0.3, r_z = 0.1, u₀ = 0.5, u₁ = 0.05 (the paper's ``s`` read as τ);
        ``"ellipse"``: center + radii[0] cos 2πτ e_{plane[0]} + radii[1] sin 2πτ e_{plane[1]};
        or a callable f(τ, **params) → (n, d), called with τ the (n,) array j/n, j = 0 … n − 1: one
        period in [0, 1), the endpoint excluded (the loop closes on itself).
    """
    tau = loop_parameters(n)
    if callable(shape):
        q = _real(shape(tau, **params), "loop")
        if q.ndim != 2 or q.shape[0] != len(tau):
            raise ValueError(f"loop function must return shape (n, d), got {q.shape}")
        return q
    if shape == "guiding_centre":
        p = dict(rx=0.5, ry=0.3, rz=0.1, u0=0.5, u1=0.05)
        _unknown(params, shape, p)
        p.update(params)
        return np.stack([p["rx"] * np.cos(TWO_PI * tau), p["ry"] * np.sin(TWO_PI * tau),
                         p["rz"] * np.sin(TWO_PI * tau), p["u0"] + p["u1"] * np.cos(TWO_PI * tau)], axis=1)
    if shape in ("ellipse", "circle"):
        p = dict(d=4, plane=(0, 1), center=None, radii=(1.0, 1.0))
        _unknown(params, shape, p)
        p.update(params)
        d = p["d"]
        i, j = _plane(p["plane"], d)
        q = np.zeros((len(tau), d)) + _center(p["center"], d)
        radii = _pair(p["radii"], "radii")
        q[:, i] += radii[0] * np.cos(TWO_PI * tau)
        q[:, j] += radii[1] * np.sin(TWO_PI * tau)
        return q
    raise ValueError(f"unknown loop shape '{shape}' (use 'guiding_centre', 'ellipse' or a callable)")


def band_limited_loop(n, center, modes=20, decay=0.7, scale=None, seed=1):
    """A loop whose coordinates have Fourier modes 1 … ``modes`` only, exactly: (n, d).

    q(τ) = center + Σ_k (a_k cos 2πkτ + b_k sin 2πkτ), a_k, b_k normal with standard deviations
    ``scale``·decay^k (``scale``: one number per coordinate, default 0.05 each) from
    numpy's generator of ``seed``.  Smooth and band-limited: q's own top modes are zero for any n >
    2·modes, while a one-form of q reaches further; the resolution monitor's test set."""
    center = np.asarray(center, dtype=float)
    d = center.size
    scale = np.full(d, 0.05) if scale is None else np.asarray(scale, dtype=float)
    tau = loop_parameters(n)
    q = np.zeros((int(n), d)) + center
    rng = np.random.default_rng(seed)
    for k in range(1, modes + 1):
        a = rng.normal(size=(2, d)) * scale * decay**k
        q += a[0] * np.cos(TWO_PI * k * tau)[:, None] + a[1] * np.sin(TWO_PI * k * tau)[:, None]
    return q


def band_limited_surface(n_sigma, n_tau, center, degree=6, decay=0.7, scale=None, seed=1):
    """A surface whose coordinates are polynomials of ``degree`` in σ and in τ, exactly: (n_σ, n_τ, d).

    q(σ, τ) = center + Σ_{j, l ≤ degree, (j, l) ≠ (0, 0)} c_jl T_j(2σ − 1) T_l(2τ − 1), c_jl normal
    with standard deviations ``scale``·decay^(j + l) (``scale``: one number per coordinate, default
    0.05 each) from numpy's generator of ``seed``.  Its own Chebyshev coefficients end at ``degree``
    (resolved on more than about 8/7 · degree points a side), while the integrand of I₂, a product
    of its derivatives with Ω(q), reaches further: the surface counterpart of
    :func:`band_limited_loop`."""
    center = np.asarray(center, dtype=float)
    d = center.size
    scale = np.full(d, 0.05) if scale is None else np.asarray(scale, dtype=float)
    S, T = surface_parameters(n_sigma, n_tau)
    x, y = 2.0 * S - 1.0, 2.0 * T - 1.0
    q = np.zeros(S.shape + (d,)) + center
    rng = np.random.default_rng(seed)
    Tx = np.polynomial.chebyshev.chebvander(x, degree)       # (n_σ, n_τ, degree + 1)
    Ty = np.polynomial.chebyshev.chebvander(y, degree)
    for j in range(degree + 1):
        for l in range(degree + 1):
            if j == l == 0:
                continue
            c = rng.normal(size=d) * scale * decay ** (j + l)
            q += (Tx[..., j] * Ty[..., l])[..., None] * c
    return q


def henon_loop(n, phase=0.0, a=1.4, b=0.3):
    """PoincareInvariants.jl's test loop (n, 4): the unit circle in both (qᵢ, pᵢ) planes, sampled at
    τ_j = (j + phase)/n, mapped twice by the 4-D Hénon map (two planar Hénon maps coupled through
    the momenta).  The maps are symplectic, so ∮ p·dq = 2π exactly; the loop is a trigonometric
    polynomial of degree 16 (resolved at any n > 32): an error of I₁ on it is round-off only."""
    def henon(q, p):
        p = 1 + p - a * q * q
        q, p = b * q, p / b
        return -p, q

    def henon_4d(z):
        q1, q2, p1, p2 = z.T
        q1, p1 = henon(q1, p1)
        q2, p2 = henon(q2, p2)
        return np.stack([q1, q2, p1 - q2, p2 - q1], axis=-1)
    tau = -2 * np.pi * (np.arange(int(n)) + phase) / int(n)
    return henon_4d(henon_4d(np.stack([np.cos(tau), np.cos(tau), np.sin(tau), np.sin(tau)], axis=1)))


def surface_parameters(n_sigma: int, n_tau: int):
    """Chebyshev points (σ, τ) on [0, 1]²: two arrays (n_σ, n_τ), σ along axis 0."""
    s, t = chebyshev_points(int(n_sigma)), chebyshev_points(int(n_tau))
    return np.meshgrid(s, t, indexing="ij")


def surface(shape="guiding_centre", n_sigma=100, n_tau=100, **params):
    """Points of a surface patch: (n_σ, n_τ, d).

    shape
        ``"guiding_centre"``: the paper's surface, q(σ, τ) = (r₀(σ − ½), r₀(τ − ½),
        r_z cos 2πσ cos 2πτ, u₀ + u₁ sin 2πσ sin 2πτ), defaults r₀ = 0.1, r_z = 0.1,
        u₀ = 0.5, u₁ = 0.01;
        ``"rectangle"``: center + size[0](σ − ½) e_{plane[0]} + size[1](τ − ½) e_{plane[1]};
        or a callable f(σ, τ, **params) → (n_σ, n_τ, d), called with σ, τ two (n_σ, n_τ) arrays of
        Chebyshev points on [0, 1] (endpoints included, σ along axis 0).
    """
    S, T = surface_parameters(n_sigma, n_tau)
    if callable(shape):
        q = _real(shape(S, T, **params), "surface")
        if q.ndim != 3 or q.shape[:2] != S.shape:
            raise ValueError(f"surface function must return shape (n_sigma, n_tau, d), got {q.shape}")
        return q
    if shape == "guiding_centre":
        p = dict(r0=0.1, rz=0.1, u0=0.5, u1=0.01)
        _unknown(params, shape, p)
        p.update(params)
        return np.stack([p["r0"] * (S - 0.5), p["r0"] * (T - 0.5),
                         p["rz"] * np.cos(TWO_PI * S) * np.cos(TWO_PI * T),
                         p["u0"] + p["u1"] * np.sin(TWO_PI * S) * np.sin(TWO_PI * T)], axis=-1)
    if shape == "rectangle":
        p = dict(d=4, plane=(0, 1), center=None, size=(1.0, 1.0))
        _unknown(params, shape, p)
        p.update(params)
        d = p["d"]
        i, j = _plane(p["plane"], d)
        q = np.zeros(S.shape + (d,)) + _center(p["center"], d)
        size = _pair(p["size"], "size")
        q[..., i] += size[0] * (S - 0.5)
        q[..., j] += size[1] * (T - 0.5)
        return q
    raise ValueError(f"unknown surface shape '{shape}' (use 'guiding_centre', 'rectangle' or a callable)")


def _real(values, what):
    """A shape function's values as a float array: real numbers only (a complex value is refused,
    not cut to its real part; strings and objects are refused as numpy refuses them)."""
    a = np.asarray(values)
    if a.dtype.kind == "c":
        raise ValueError(f"{what} function returned complex values ({a.dtype}); return real coordinates")
    return np.asarray(a, dtype=float)


def _unknown(params, shape, allowed=()):
    extra = sorted(set(params) - set(allowed))
    if extra:
        raise ValueError(f"params: the shape '{shape}' takes no parameter '{extra[0]}'"
                         + (f" (it takes {', '.join(sorted(allowed))})" if allowed else ""))


def _plane(plane, d):
    if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 2:
        raise ValueError(f"params.d must be an integer ≥ 2, got {d!r}")
    ok = (isinstance(plane, (list, tuple)) and len(plane) == 2 and
          all(isinstance(k, (int, np.integer)) and not isinstance(k, bool) and 0 <= k < d for k in plane))
    if not ok or plane[0] == plane[1]:
        raise ValueError(f"params.plane must be two different coordinate indices in 0 … {d - 1}, got {plane!r}")
    return int(plane[0]), int(plane[1])


def _center(center, d):
    if center is None:
        return np.zeros(d)
    c = np.asarray(center, dtype=float) if isinstance(center, (list, tuple, np.ndarray)) else None
    if c is None or c.shape != (d,):
        raise ValueError(f"params.center must be a list of d = {d} numbers, got "
                         + (f"{c.size} numbers" if c is not None else repr(center)))
    return c


def _pair(v, key):
    ok = isinstance(v, (list, tuple, np.ndarray)) and len(v) == 2
    if not ok:
        raise ValueError(f"params.{key} must be a list of 2 numbers, got {v!r}")
    return float(v[0]), float(v[1])


# -- nested refinement (a set's levels: the driver's refine_to) ------------------------------------
def refined_grid(grid: tuple, level: int) -> tuple:
    """The grid of a set ``level`` refinements on: a loop of N points has N·2^level (τ = j/(N·2^level)
    keeps every old τ), a Chebyshev surface (n_σ, n_τ) has (2^level(n_σ − 1) + 1, 2^level(n_τ − 1) + 1)
    (the extrema cos(πj/(n − 1)) nest: n → 2n − 1 keeps every old point)."""
    if len(grid) == 1:
        return (grid[0] << level,)
    return tuple(((n - 1) << level) + 1 for n in grid)


def first_level(grid: tuple, level: int) -> np.ndarray:
    """For each point of the grid ``level`` refinements on (:func:`refined_grid`), the level at which
    it first appears (0: a point of the original set).  Along one axis, index j of the refined grid
    is a point of level ℓ's grid when 2^(level − ℓ) divides j; a surface point appears when both its
    indices have.  Row-major order within one level is row-major order in the refined grid, so
    ``x[first_level(g, L) == l]`` lists level l's new points in the order of level l's own grid."""
    def axis(m):
        j = np.arange(m)
        v = np.zeros(m, dtype=np.int64)            # 2-adic valuation of j, capped at level (j = 0: level)
        for k in range(1, level + 1):
            v[(j % (1 << k)) == 0] = k
        return level - v
    axes = [axis(m) for m in refined_grid(grid, level)]
    if len(axes) == 1:
        return axes[0]
    return np.maximum(axes[0][:, None], axes[1][None, :])
