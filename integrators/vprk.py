"""The VPRK core: internal-stage equations of eq:vprk / eq:vprk_lobatto and their Jacobian.

For L = ϑ(q)·v − H(q) the stage relations of eq:vprk_1 read P_i = ϑ(Q_i) and
F_i = ϑ_q(Q_i)ᵀ V_i − ∇H(Q_i).  We solve for the stage displacements
Y_i = h V_i (same units as q, so one tolerance fits all unknowns):

    Q_i = q̄ + Σ_j a_ij Y_j                                   (eq:vprk_2, left)
    R_i = ϑ(Q_i) − p̄ − Σ_j ā_ij G_j + μ d_i / b_i = 0,      G_j = h F_j   (eq:vprk_2 right, eq:vprk_lobatto)
    D   = Σ_i d_i Y_i = 0                                    (Lobatto IIIA/IIIB only)
    q̄' = q̄ + Σ_i b_i Y_i,   p̄' = p̄ + Σ_i b_i G_i              (eq:vprk_3)

Sums over stages use the double + correction coefficients of the tableau.  All
arrays carry a leading points axis; contractions over the (small) stage index are
explicit loops with elementwise numpy operations and contractions over coordinates
are stacked matmuls, one small product per point, so a point's arithmetic never
depends on which other points share its batch.
"""
from __future__ import annotations

import numpy as np


def combine(coef, coef_lo, X):
    """Σ_j coef_ij X_j with a double + correction coefficient matrix.

    coef, coef_lo : (s, s) ; X : (n, s, d) -> (n, s, d)
    """
    s = coef.shape[0]
    out = np.empty_like(X)
    for i in range(s):
        acc = coef[i, 0] * X[:, 0]
        for j in range(1, s):
            acc = acc + coef[i, j] * X[:, j]
        cor = coef_lo[i, 0] * X[:, 0]
        for j in range(1, s):
            cor = cor + coef_lo[i, j] * X[:, j]
        out[:, i] = acc + cor
    return out


def weigh(w, w_lo, X):
    """Σ_i w_i X_i with double + correction weights: w (s,), X (n, s, ...) -> (n, ...)."""
    acc = w[0] * X[:, 0]
    cor = w_lo[0] * X[:, 0]
    for i in range(1, len(w)):
        acc = acc + w[i] * X[:, i]
        cor = cor + w_lo[i] * X[:, i]
    return acc + cor


def transpose_apply(T, v):
    """(Tᵀ v)_m = Σ_l T[..., l, m] v[..., l]: T (..., d, d), v (..., d).

    Stacked matmul treats every point's matrix on its own, so the bits of a point never
    depend on its batch (checked bitwise in tests/test_integrate.py).
    """
    return np.matmul(v[..., None, :], T)[..., 0, :]


def contract_first(T3, v):
    """Σ_l T3[..., l, :, :] v[..., l]: T3 (..., d, d, d), v (..., d) -> (..., d, d)."""
    d = v.shape[-1]
    flat = T3.reshape(T3.shape[:-2] + (d * d,))
    return np.matmul(v[..., None, :], flat)[..., 0, :].reshape(T3.shape[:-3] + (d, d))


class Stages:
    """Stage quantities of one VPRK solve for n points.

    Parameters
    ----------
    system, tableau, h
    qbar : (n, d) start of the unprojected step
    Y : (n, s, d) stage displacements h V_i
    jacobian : also evaluate ϑ_q, ϑ_qq, ∇²H terms needed by the Jacobian
    """

    def __init__(self, system, tableau, h, qbar, Y, jacobian=True):
        tab = tableau
        self.Q = qbar[:, None, :] + combine(tab.a, tab.a_lo, Y)        # (n, s, d)
        self.theta = system.theta(self.Q)                                # (n, s, d)
        self.Theta = system.dtheta(self.Q)                               # (n, s, d, d) [k, i]
        self.G = transpose_apply(self.Theta, Y) - h * system.dH(self.Q)  # (n, s, d)
        if jacobian:
            # K_i[m, n] = ∂G_i[m]/∂Q_i[n] = Σ_l ϑ_{l,mn}(Q_i) Y_i^l − h H_mn(Q_i)
            self.K = contract_first(system.ddtheta(self.Q), Y) - h * system.ddH(self.Q)


def stage_residual(tab, st, pbar, mu):
    """R_i = ϑ(Q_i) − p̄ − Σ_j ā_ij G_j (+ μ d_i/b_i): (n, s, d)."""
    R = st.theta - pbar[:, None, :] - combine(tab.abar, tab.abar_lo, st.G)
    if mu is not None:
        R = R + mu[:, None, :] * (tab.d / tab.b)[None, :, None]
    return R


def stage_jacobian_blocks(tab, st):
    """∂R_i/∂Y_j = a_ij Θ_i − ā_ij Θ_jᵀ − Σ_l ā_il a_lj K_l, as a list of lists of (n, d, d)."""
    s = tab.s
    a, ab = tab.a, tab.abar
    ThetaT = np.swapaxes(st.Theta, -1, -2)
    blocks = []
    for i in range(s):
        row = []
        for j in range(s):
            B = a[i, j] * st.Theta[:, i] - ab[i, j] * ThetaT[:, j]
            for l in range(s):
                c = ab[i, l] * a[l, j]
                if c != 0.0:
                    B = B - c * st.K[:, l]
            row.append(B)
        blocks.append(row)
    return blocks


def stage_jacobian_shift(tab, st):
    """∂R_i/∂q̄ (a shift of all stage positions) = Θ_i − Σ_l ā_il K_l: list of (n, d, d)."""
    out = []
    for i in range(tab.s):
        B = st.Theta[:, i].copy()
        for l in range(tab.s):
            if tab.abar[i, l] != 0.0:
                B = B - tab.abar[i, l] * st.K[:, l]
        out.append(B)
    return out
