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


def loop(shape="guiding_centre", n=2000, *, d=4, plane=(0, 1), center=None, radii=(1.0, 1.0), **params):
    """Points of a closed loop: (n, d).

    shape
        ``"guiding_centre"``: the paper's loop of sec:app_integral_invariants,
        q(τ) = (r_x cos 2πτ, r_y sin 2πτ, r_z sin 2πτ, u₀ + u₁ cos 2πτ), defaults
        r_x = 0.5, r_y = 0.3, r_z = 0.1, u₀ = 0.5, u₁ = 0.05 (the paper's ``s`` read as τ);
        ``"ellipse"``: center + radii[0] cos 2πτ e_{plane[0]} + radii[1] sin 2πτ e_{plane[1]};
        or a callable f(τ) → (n, d).
    """
    tau = loop_parameters(n)
    if callable(shape):
        q = np.asarray(shape(tau), dtype=float)
        if q.ndim != 2 or q.shape[0] != len(tau):
            raise ValueError(f"loop function must return shape (n, d), got {q.shape}")
        return q
    if shape == "guiding_centre":
        p = dict(rx=0.5, ry=0.3, rz=0.1, u0=0.5, u1=0.05)
        p.update(params)
        return np.stack([p["rx"] * np.cos(TWO_PI * tau), p["ry"] * np.sin(TWO_PI * tau),
                         p["rz"] * np.sin(TWO_PI * tau), p["u0"] + p["u1"] * np.cos(TWO_PI * tau)], axis=1)
    if shape in ("ellipse", "circle"):
        q = np.zeros((len(tau), d)) + (0.0 if center is None else np.asarray(center, dtype=float))
        i, j = plane
        q[:, i] += radii[0] * np.cos(TWO_PI * tau)
        q[:, j] += radii[1] * np.sin(TWO_PI * tau)
        return q
    raise ValueError(f"unknown loop shape '{shape}' (use 'guiding_centre', 'ellipse' or a callable)")


def surface_parameters(n_sigma: int, n_tau: int):
    """Chebyshev points (σ, τ) on [0, 1]²: two arrays (n_σ, n_τ), σ along axis 0."""
    s, t = chebyshev_points(int(n_sigma)), chebyshev_points(int(n_tau))
    return np.meshgrid(s, t, indexing="ij")


def surface(shape="guiding_centre", n_sigma=100, n_tau=100, *, d=4, plane=(0, 1), center=None,
            size=(1.0, 1.0), **params):
    """Points of a surface patch: (n_σ, n_τ, d).

    shape
        ``"guiding_centre"``: the paper's surface, q(σ, τ) = (r₀(σ − ½), r₀(τ − ½),
        r_z cos 2πσ cos 2πτ, u₀ + u₁ sin 2πσ sin 2πτ), defaults r₀ = 0.1, r_z = 0.1,
        u₀ = 0.5, u₁ = 0.01;
        ``"rectangle"``: center + size[0](σ − ½) e_{plane[0]} + size[1](τ − ½) e_{plane[1]};
        or a callable f(σ, τ) → (n_σ, n_τ, d).
    """
    S, T = surface_parameters(n_sigma, n_tau)
    if callable(shape):
        q = np.asarray(shape(S, T), dtype=float)
        if q.ndim != 3 or q.shape[:2] != S.shape:
            raise ValueError(f"surface function must return shape (n_sigma, n_tau, d), got {q.shape}")
        return q
    if shape == "guiding_centre":
        p = dict(r0=0.1, rz=0.1, u0=0.5, u1=0.01)
        p.update(params)
        return np.stack([p["r0"] * (S - 0.5), p["r0"] * (T - 0.5),
                         p["rz"] * np.cos(TWO_PI * S) * np.cos(TWO_PI * T),
                         p["u0"] + p["u1"] * np.sin(TWO_PI * S) * np.sin(TWO_PI * T)], axis=-1)
    if shape == "rectangle":
        q = np.zeros(S.shape + (d,)) + (0.0 if center is None else np.asarray(center, dtype=float))
        i, j = plane
        q[..., i] += size[0] * (S - 0.5)
        q[..., j] += size[1] * (T - 0.5)
        return q
    raise ValueError(f"unknown surface shape '{shape}' (use 'guiding_centre', 'rectangle' or a callable)")
