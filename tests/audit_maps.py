"""User step maps for tests/test_audit.py (the contract of integrators.audit)."""
import numpy as np

import integrators
from integrators.audit import stepper_map


def rk4(q, p, lam, h, system):
    """Classical explicit RK4 on q̇ = Ω̄⁻¹∇H; p_{n+1} = ϑ(q_{n+1}).  Not symplectic."""
    f = system.vector_field
    k1 = f(q)
    k2 = f(q + 0.5 * h * k1)
    k3 = f(q + 0.5 * h * k2)
    k4 = f(q + h * k3)
    q1 = q + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return q1, system.theta(q1), np.zeros_like(q1)


def implicit_midpoint(q, p, lam, h, system):
    """The implicit midpoint rule q₁ = q + h f((q + q₁)/2) on q̇ = f(q) = Ω̄⁻¹∇H, by 40 fixed-point
    sweeps (a contraction for h·Lip f < 1; plain arithmetic, so complex step applies).  Symplectic
    for a constant Ω̄ only: not symplectic for the noncanonical forms of the point vortices."""
    f = system.vector_field
    q1 = q + h * f(q)
    for _ in range(40):
        q1 = q + h * f(0.5 * (q + q1))
    return q1, system.theta(q1), np.zeros_like(q1)


_glrk2 = stepper_map(integrators.tableau("GLRK2"), "none")


def glrk2_reset(q, p, lam, h, system):
    """Unprojected GLRK2 followed by the naive, non-symplectic 'projection' p ← ϑ(q)."""
    q1, _, lam1 = _glrk2(q, p, lam, h, system)
    return q1, system.theta(q1), lam1


def exact_flow(q, p, lam, h, system):
    """The exact flow of guiding_centre_symmetric (real arithmetic only: central differences)."""
    q1 = system.exact_flow(q, h)
    return q1, system.theta(q1), np.zeros_like(q1)


def broken(q, p, lam, h, system):
    raise RuntimeError("this map always fails")
