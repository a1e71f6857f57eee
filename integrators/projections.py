"""One step of a (projected) VPRK method, batched over points (sec:projection).

With φ(q, p) = p − ϑ(q) the projection term h Ω⁻¹∇φᵀλ of eq:projector moves a
point by (q, p) ↦ (q + hλ, p + h ϑ_q(x)ᵀλ), where x is where ϑ_q is evaluated.
We write Λ = hλ.  The five choices differ only where the paper says they do
(table in sec:projection, σ = R(∞) of the tableau):

=============  ============================  ====================================  ==================
projection     perturbation (before Ψ_h)     projection (after Ψ_h)                solved
=============  ============================  ====================================  ==================
none           —                             —                                     Ψ_h alone
standard       —                             + Λ_{n+1}, ϑ_q at q_{n+1}             Ψ_h, then Λ
               (eq:orthogonal_projection)
symmetric      + Λ, ϑ_q at q_n               + σΛ, ϑ_q at q_{n+1}                  Ψ_h and Λ together
               (eq:symmetric_symplectic_projection)
symplectic     + Λ_n (known), ϑ_q at q_n      + σΛ_{n+1}, ϑ_q at q_{n+1}            Ψ_h, then Λ_{n+1}
               (eq:symplectic_projection)
midpoint       + Λ, ϑ_q at q̄_{n+1/2}          + σΛ, ϑ_q at q̄_{n+1/2}                Ψ_h and Λ together
               (eq:symplectic_midpoint_projection)
=============  ============================  ====================================  ==================

q̄_{n+1/2} = (q̄_n + q̄_{n+1})/2 is the midpoint of the unprojected step.  For the
midpoint projection the paper's eq:symplectic_midpoint_projection_post prints no
σ while its table has R(∞)λ_{n+1/2}; we follow the table (as GeometricIntegrators.jl
does): with σ = +1 and R(∞) = −1 (GLRK1, SRK3) the constraint cannot be enforced
at leading order.  Projected methods start every step on the constraint,
p_n = ϑ(q_n) (eq:fibre_derivative); ``none`` carries its own p_n.
"""
from __future__ import annotations

import numpy as np

from . import vprk
from .newton import EPS, newton

PROJECTIONS = ("none", "standard", "symmetric", "symplectic", "midpoint")
NEEDS_UNIT_R_INF = ("symmetric", "symplectic", "midpoint")   # σ = R(∞) must be ±1 (table in sec:projection)


def admission(tableau, projection):
    """None if ``projection`` can be used with ``tableau``, else the one-line reason.

    The one place of this rule (the Stepper, scenes and the audit all ask here): the symmetric,
    symplectic and midpoint projections multiply their post-projection by σ = R(∞), which the
    paper's construction needs to be ±1.
    """
    if projection not in PROJECTIONS:
        return f"unknown projection '{projection}'; choose one of {', '.join(PROJECTIONS)}"
    if projection in NEEDS_UNIT_R_INF and abs(tableau.R_inf) != 1.0:
        return (f"projection '{projection}' needs |R(∞)| = 1 but {tableau.name} has R(∞) = {tableau.R_inf:g}; "
                "use 'none' or 'standard'")
    return None


def _lagrange_matrix(nodes, targets):
    """E with E_ij = ℓ_j(targets_i) for the Lagrange basis on ``nodes``."""
    E = np.ones((len(targets), len(nodes)))
    for i, x in enumerate(targets):
        for j, xj in enumerate(nodes):
            for k, xk in enumerate(nodes):
                if k != j:
                    E[i, j] *= (x - xk) / (xj - xk)
    return E


def _apply_rows(E, Y):
    """Σ_j E_ij Y[:, j]: E (s, m), Y (n, m, d) -> (n, s, d); explicit loop (batch-independent bits)."""
    out = np.empty((Y.shape[0], E.shape[0], Y.shape[2]))
    for i in range(E.shape[0]):
        acc = E[i, 0] * Y[:, 0]
        for j in range(1, E.shape[1]):
            acc = acc + E[i, j] * Y[:, j]
        out[:, i] = acc
    return out


class StepResult:
    """Outcome of one step for n points (all arrays have a leading points axis)."""

    __slots__ = ("q", "p", "Lam", "Y", "mu", "ok", "iterations", "inc_q", "inc_p", "jinv")


class Stepper:
    """The step map Φ_h of one (tableau, projection) pair for a system.

    ``step(q, p, Lam, guess)`` advances n points; see :meth:`step`.
    """

    def __init__(self, system, tableau, projection, h):
        why = admission(tableau, projection)
        if why:
            raise ValueError(why)
        self.system, self.tableau, self.projection, self.h = system, tableau, projection, float(h)
        self.sigma = 1.0 if projection == "standard" else float(np.sign(tableau.R_inf))
        self.coupled = projection in ("symmetric", "midpoint")
        self.lobatto = tableau.d is not None
        s, d = tableau.s, system.d
        self.s, self.d = s, d
        self.nz = (s + (1 if self.coupled else 0) + (1 if self.lobatto else 0)) * d
        # Lagrange extrapolation of the last step's stage values (nodes c_j − 1) to the next
        # step's nodes c_i.  (Extrapolating from two steps, degree 2s − 1, was tried: it gains
        # nothing for s ≥ 2, whose stage values carry an O(h^{s+1}) error of their own, and
        # its amplification wrecks the guess for SRK3.)
        self.extrapolation = _lagrange_matrix(tableau.c - 1.0, tableau.c)

    # -- initial guesses --------------------------------------------------------
    def first_guess(self, q):
        """Stage displacements h·q̇(q_n) at every stage: (n, s, d)."""
        with np.errstate(all="ignore"):
            try:
                v = self.system.vector_field(q)
            except np.linalg.LinAlgError:
                v = np.zeros_like(q)
        v = np.where(np.isfinite(v), v, 0.0)
        return np.repeat((self.h * v)[:, None, :], self.s, axis=1)

    def extrapolate(self, Y):
        """Next step's stage guess from the last step's stage displacements Y (n, s, d)."""
        return _apply_rows(self.extrapolation, Y)

    # -- the step -------------------------------------------------------------
    def equations(self, q, p, Lam):
        """The nonlinear system of one step for n points.

        Returns ``(fun, unpack, qbar, pbar, Theta_q)`` where ``fun(idx, z) -> (r, J)``
        evaluates the residual (m, nz) and its exact Jacobian (m, nz, nz) for the rows
        ``idx`` with unknowns z = [Y_1 … Y_s, Λ (coupled projections), μ (Lobatto)].
        """
        sysm, tab, h, sig = self.system, self.tableau, self.h, self.sigma
        s, d = self.s, self.d
        proj = self.projection
        if proj == "none":
            qbar, pbar = q, p
        elif proj == "symplectic":
            qbar = q + Lam
            pbar = sysm.theta(q) + vprk.transpose_apply(sysm.dtheta(q), Lam)
        else:
            qbar, pbar = q, sysm.theta(q)
        Theta_q = sysm.dtheta(q) if proj == "symmetric" else None

        sd = s * d
        iL = sd if self.coupled else None
        iM = sd + (d if self.coupled else 0) if self.lobatto else None

        def unpack(z):
            m = z.shape[0]
            Y = z[:, :sd].reshape(m, s, d)
            L = z[:, iL:iL + d] if self.coupled else None
            mu = z[:, iM:iM + d] if self.lobatto else None
            return Y, L, mu

        def fun(idx, z, jacobian=True):
            Y, L, mu = unpack(z)
            m = z.shape[0]
            q0, pb = qbar[idx], pbar[idx]
            if self.coupled:
                q0 = q0 + L
                sumbY = vprk.weigh(tab.b, tab.b_lo, Y)
                if proj == "symmetric":
                    Tx = Theta_q[idx]
                else:  # midpoint: ϑ_q at the unprojected midpoint
                    M = q0 + 0.5 * sumbY
                    Tx = sysm.dtheta(M)
                pb = pb + vprk.transpose_apply(Tx, L)
            st = vprk.Stages(sysm, tab, h, q0, Y, jacobian=jacobian)
            res = [vprk.stage_residual(tab, st, pb, mu).reshape(m, sd)]
            sumbG = vprk.weigh(tab.b, tab.b_lo, st.G)
            if self.coupled:
                q1 = q0 + sumbY + sig * L
                T1 = sysm.dtheta(q1)
                Tp = T1 if proj == "symmetric" else Tx
                p1 = pb + sumbG + sig * vprk.transpose_apply(Tp, L)
                res.append(p1 - sysm.theta(q1))
                # what the step needs at this iterate: q increment (perturbation, Ψ_h, projection), p_{n+1}
                extras = {"inc_q": (L + sumbY) + sig * L, "p": p1}
            else:
                extras = {"sumbY": vprk.weigh(tab.b, tab.b_lo, Y), "sumbG": sumbG}
            if self.lobatto:
                res.append(vprk.weigh(tab.d, np.zeros_like(tab.d), Y))
            r = np.concatenate(res, axis=1)
            if not jacobian:
                return r, None, extras

            J = np.zeros((m, self.nz, self.nz), dtype=z.dtype)
            Sx = vprk.contract_first(sysm.ddtheta(M), L) if proj == "midpoint" else None
            blocks = vprk.stage_jacobian_blocks(tab, st)
            for i in range(s):
                for j in range(s):
                    B = blocks[i][j]
                    if Sx is not None:
                        B = B - (0.5 * tab.b[j]) * Sx
                    J[:, i * d:(i + 1) * d, j * d:(j + 1) * d] = B
            if self.coupled:
                TxT = np.swapaxes(Tx, -1, -2)
                dpb_dL = TxT if Sx is None else TxT + Sx
                shift = vprk.stage_jacobian_shift(tab, st)
                for i in range(s):
                    J[:, i * d:(i + 1) * d, iL:iL + d] = shift[i] - dpb_dL
                if proj == "symmetric":
                    S1 = vprk.contract_first(sysm.ddtheta(q1), L)
                    dp1_dL = dpb_dL + sig * np.swapaxes(T1, -1, -2) + sig * (1.0 + sig) * S1
                    extra_Y = sig * S1
                else:
                    dp1_dL = (1.0 + sig) * dpb_dL
                    extra_Y = (0.5 * (1.0 + sig)) * Sx
                ThetaT = np.swapaxes(st.Theta, -1, -2)
                KS = vprk.weigh(tab.b, np.zeros_like(tab.b), st.K)
                rows = slice(iL, iL + d)
                for j in range(s):
                    KB = tab.b[0] * tab.a[0, j] * st.K[:, 0]
                    for l in range(1, s):
                        KB = KB + tab.b[l] * tab.a[l, j] * st.K[:, l]
                    dp1 = KB + tab.b[j] * ThetaT[:, j] + tab.b[j] * extra_Y
                    J[:, rows, j * d:(j + 1) * d] = dp1 - tab.b[j] * T1
                J[:, rows, iL:iL + d] = dp1_dL + KS - (1.0 + sig) * T1
            if self.lobatto:
                for i in range(s):
                    J[:, i * d:(i + 1) * d, iM:iM + d] = (tab.d[i] / tab.b[i]) * np.eye(d)
                    J[:, iM:iM + d, i * d:(i + 1) * d] = tab.d[i] * np.eye(d)
            return r, J, extras

        return fun, unpack, qbar, pbar, Theta_q

    def step(self, q, p, Lam, Y0, mu0, jinv=None, known=None):
        """Advance n points by one step.

        Parameters
        ----------
        q, p : (n, d) current state (p is ignored by projected methods: p_n = ϑ(q_n))
        Lam : (n, d) last Λ = hλ (guess for standard/symmetric/midpoint; Λ_n for symplectic)
        Y0 : (n, s, d) guess of the stage displacements
        mu0 : (n, d) guess of the Lobatto multiplier
        jinv, known : optional (n, nz, nz) inverse Jacobians of the step's system from the last
            step and the (n,) mask of rows that hold one; Newton starts from them (and refreshes
            a point's inverse when its iteration stops contracting).  Updated in place.

        Returns
        -------
        StepResult with increments ``inc_q`` (to be added to q with compensated
        summation), ``p`` (p_{n+1} as the method computes it), ``Lam`` (Λ of this
        step), ``Y``/``mu`` (for the next guess), ``ok`` (n,), ``iterations`` (n,) and
        ``jinv`` (the inverse Jacobians at the end of the solve, for the next step).
        """
        sysm, tab, h, sig = self.system, self.tableau, self.h, self.sigma
        s, d = self.s, self.d
        proj = self.projection
        n = q.shape[0]
        sd = s * d
        iL = sd if self.coupled else None
        iM = sd + (d if self.coupled else 0) if self.lobatto else None
        fun, unpack, qbar, pbar, Theta_q = self.equations(q, p, Lam)
        z0 = np.empty((n, self.nz), dtype=np.result_type(q, Lam, Y0))   # complex for complex-step derivatives
        z0[:, :sd] = Y0.reshape(n, sd)
        if self.coupled:
            z0[:, iL:iL + d] = Lam
        if self.lobatto:
            z0[:, iM:iM + d] = mu0
        # every unknown is measured relative to its own coordinate's size (at least 1)
        qscale = np.maximum(np.abs(q), 1.0)
        scale = np.tile(qscale, self.nz // d)
        if self.lobatto:
            scale[:, iM:iM + d] = np.maximum(np.abs(pbar), 1.0)
        scale = np.where(np.isfinite(scale), scale, 1.0)
        # the solution is the last iterate at which the residual was evaluated (its update was
        # below tolerance), so the step's outputs come from that evaluation, not a new one
        if jinv is None:
            jinv, known = np.empty((n, self.nz, self.nz), dtype=z0.dtype), np.zeros(n, dtype=bool)
        z, ok, its, ex = newton(fun, z0, scale, jinv=jinv, known=known)
        Y, L, mu = unpack(z)
        out = StepResult()
        out.Y, out.mu, out.iterations, out.jinv = Y, mu, its, jinv
        if proj == "none":
            out.inc_q, out.inc_p, out.p, out.Lam = ex["sumbY"], ex["sumbG"], None, np.zeros_like(q)
        elif self.coupled:
            out.inc_q, out.p, out.inc_p, out.Lam = ex["inc_q"], ex["p"], None, L
        else:  # standard / symplectic: the projection is a separate solve (eq:vprk_3, then the projection)
            sumbY = ex["sumbY"]
            L1, ok1, its1, ex1 = self._post_projection(qbar + sumbY, pbar + ex["sumbG"], Lam)
            ok &= ok1
            out.iterations = its + its1
            out.p = ex1["p"]
            out.inc_q = (sumbY + sig * L1) if proj == "standard" else ((Lam + sumbY) + sig * L1)
            out.inc_p, out.Lam = None, L1
        out.ok = ok
        return out

    def _post_projection(self, qb, pb, guess):
        """Solve ϑ(q̄ + σΛ) = p̄ + σ ϑ_q(q̄ + σΛ)ᵀΛ for Λ (eq:orthogonal_projection, eq:symplectic_projection_post)."""
        sysm, sig = self.system, self.sigma

        def fun(idx, L, jacobian=True):
            q1 = qb[idx] + sig * L
            T1 = sysm.dtheta(q1)
            p1 = pb[idx] + sig * vprk.transpose_apply(T1, L)
            r = p1 - sysm.theta(q1)
            if not jacobian:
                return r, None, {"p": p1}
            S1 = vprk.contract_first(sysm.ddtheta(q1), L)
            return r, sig * (np.swapaxes(T1, -1, -2) - T1) + sig * sig * S1, {"p": p1}

        scale = np.maximum(np.abs(qb), 1.0)
        scale = np.where(np.isfinite(scale), scale, 1.0)
        return newton(fun, guess, scale)
