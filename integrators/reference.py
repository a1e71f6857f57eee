"""The reference engine: the batched-numpy VPRK step, in any numpy dtype (long double included).

The same equations as the compiled engine (integrators/projections.py, eq:vprk_1–eq:vprk_3,
eq:vprk_lobatto and each projection's eq:…_pre / eq:…_post), written plainly with batched numpy
arrays: Newton with a per-point convergence mask and inverse Jacobians carried across steps, the
projections read from the same records as the kernel's (:func:`integrators.projections.projection_record`:
where ϑ_q is taken, σ, what is solved together; no branch on a projection's name).  It is

* **the tests' independent oracle** of the compiled engine (tests/test_engine.py: 16 ulps after
  one step on every admissible pair of three systems, the same breakdowns, long runs that track
  each other) — a second statement of the equations in another language of arrays;
* the engine of the long-double studies kept in the docs (scripts/studies/convergence_orders.py --extended,
  scripts/studies/results_energy_drift.py): on long double arrays it converges Newton to 4 eps of long double.
  New studies below double use the compiled engine in double-double (docs/engine.md: the
  long-double path is retired as a precision);
* the stopping-rule experiment's engine (``Stepper(accept_unconverged=True)``,
  scripts/studies/stability_breakdown.py) and the "before" column of scripts/studies/benchmarks_core.py.

Use::

    from integrators import reference
    st = reference.Stepper(system, integrators.tableau("GLRK2"), "symmetric", h)
    S = reference.State(q, system.theta(q), np.zeros_like(q), h, st.s)     # q of any float dtype
    for k in range(1, n + 1):
        reference.advance(st, S, k * h)

It is slow (many numpy passes a step): runs use :mod:`integrators.engine`.
"""
from __future__ import annotations

import numpy as np

from integrators.engine import _lagrange_matrix
from integrators.kernel import COMPLEX_STEP
from integrators.projections import admission, projection_record





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


# --- batched Newton ---



EPS = np.finfo(float).eps


def invert_batched(J):
    """Inverses of a stack of matrices; a singular matrix gives a NaN inverse instead of raising.

    J : (n, m, m) -> (n, m, m).  Each matrix is inverted on its own (LAPACK per matrix), so the
    result for one point does not depend on the others.
    """
    if J.dtype == np.longdouble:
        # LAPACK has no long double.  Newton only needs an approximate inverse: with the
        # residual in long double it converges to the long-double solution all the same (the
        # inverse's 1e-16 error slows each iteration's contraction by that factor, no more)
        return invert_batched(J.astype(np.float64)).astype(np.longdouble)
    try:
        return np.linalg.inv(J)
    except np.linalg.LinAlgError:
        out = np.full_like(J, np.nan)
        for k in range(J.shape[0]):  # rare path: isolate the singular points
            try:
                out[k] = np.linalg.inv(J[k])
            except np.linalg.LinAlgError:
                pass
        return out


def apply_batched(M, r):
    """M r for stacks (n, m, m) and (n, m).

    numpy's stacked matmul multiplies each matrix by its vector on its own, so a point's
    bits do not depend on the batch (tests/test_integrate.py checks this bitwise).
    """
    return np.matmul(M, r[..., None])[..., 0]


def newton(fun, z0, scale, *, tol=None, stall=None, maxiter=40, refresh=None, jinv=None, known=None):
    """Solve fun(idx, z)[0] = 0 for every row of z.

    Newton's method with the exact Jacobian, kept while it works: the Jacobian is evaluated
    and inverted at the first iteration (unless the caller hands in an inverse from the last
    step, ``jinv``/``known``) and again for any point whose update shrank by less than the
    factor ``refresh`` in its last iteration (default: ``Tolerances.refresh``, 0.01, the compiled kernel's,
    so that the oracle takes the kernel's path).  Between refreshes an iteration costs one
    residual evaluation and a matrix–vector product.  Every decision is per point, so a
    point's iterates never depend on the rest of the batch.

    Parameters
    ----------
    fun : callable(idx, z, jacobian) -> (r, J, extras); idx (m,) indices of active rows,
          z (m, nz), r (m, nz) residuals, J (m, nz, nz) Jacobians (None when ``jacobian`` is
          False), extras a dict of (m, ...) arrays computed along with the residual
    z0 : (n, nz) initial guess (not modified)
    scale : (n, nz) positive scale of each unknown
    jinv : optional (n, nz, nz) inverse Jacobians to start from (e.g. the last step's); it is
           updated in place with every refresh, so the caller can carry it to the next solve
    known : (n,) bool, rows of ``jinv`` that hold a usable inverse (the others start fresh)
    tol : converged when max |δ|/scale ≤ tol (default 4 eps of z's precision: 8.9e-16 in double,
          4.3e-19 in long double).  For complex z (complex-step derivatives, used by
          the audit, perturbations i·COMPLEX_STEP) the imaginary part, read as a derivative, must
          meet the same test.
    stall : also converged when max |δ|/scale ≤ stall and the update no longer
            halves (the iteration has reached its round-off floor); default 1e-10 in double and
          the same number of ulps, 2.4e-14, in long double

    Returns
    -------
    z : (n, nz) solution: the last iterate at which the residual was evaluated, whose
        Newton update was below tolerance
    converged : (n,) bool, iterations : (n,) int
    extras : dict of (n, ...) arrays, ``fun``'s extras at that iterate
    """
    eps = np.finfo(z0.real.dtype).eps
    tol = 4 * eps if tol is None else tol
    stall = 1e-10 * (eps / EPS) if stall is None else stall
    if refresh is None:                      # the compiled kernel's policy, so the oracle takes its path
        from integrators.engine import Tolerances
        refresh = Tolerances.refresh
    z = z0.copy()
    n, nz = z.shape
    complex_step = np.iscomplexobj(z)
    if complex_step:      # derivatives: accept a round-off floor only when it is a tight one
        stall = min(stall, 1e-13)
    converged = np.zeros(n, dtype=bool)
    iterations = np.zeros(n, dtype=np.int64)
    previous = np.full(n, np.inf)
    Jinv = np.empty((n, nz, nz), dtype=z.dtype) if jinv is None else jinv
    stale = np.ones(n, dtype=bool) if jinv is None or known is None else ~known   # needs a fresh Jacobian
    z_eval = z.copy()
    extras = {}
    active = np.arange(n)
    for _ in range(maxiter):
        if active.size == 0:
            break
        everyone = active.size == n          # plain views instead of gathers while all iterate
        sel = slice(None) if everyone else active
        za = z[sel]
        z_eval[sel] = za
        r = _residual_and_inverse(fun, active, sel, za, stale[sel], Jinv, extras, n)
        delta = -apply_batched(Jinv[sel], r)
        za = za + delta
        z[sel] = za
        iterations[sel] += 1
        size, theta, done, bad = _progress(delta, za, scale[sel], previous[sel], tol, stall, complex_step)
        stale[sel] = np.isfinite(theta) & (theta > refresh)
        previous[sel] = size
        converged[active[done]] = True
        active = active[~(done | bad)]
    return z_eval, converged, iterations, extras


def _progress(delta, za, scale, prev, tol, stall, complex_step):
    """(size of the update relative to scale, contraction θ against the last, converged, failed)
    per row.  Converged: the update is below tol, or a round-off floor is reached (below stall and
    no longer halving).  Not on the error predicted from the contraction, θ/(1 − θ)·|δ|: that
    stops early enough to leave constraint errors of 1e-12."""
    size = np.max(np.abs(delta.real) / scale, axis=1)
    if complex_step:       # the derivative (imaginary part) must converge too, to its own scale
        size = np.maximum(size, np.max(np.abs(delta.imag) / (COMPLEX_STEP * scale), axis=1))
    bad = ~np.isfinite(size) | ~np.all(np.isfinite(za), axis=1)
    with np.errstate(invalid="ignore"):
        theta = np.where(np.isfinite(prev), size / prev, np.inf)   # contraction; unknown at first
    done = ((size <= tol) | ((size <= stall) & np.isfinite(theta) & (theta > 0.5))) & ~bad
    return size, theta, done, bad


def _keep(extras, n, rows, ex):
    """Store ``fun``'s extras of the rows evaluated (NaN rows until a row is)."""
    for key, val in ex.items():
        if key not in extras:
            extras[key] = np.full((n,) + val.shape[1:], np.nan, dtype=val.dtype)
        extras[key][rows] = val


def _residual_and_inverse(fun, active, sel, za, fresh, Jinv, extras, n):
    """One Newton iteration's residual of the rows ``active`` (``sel``: their index, or all), with a
    fresh Jacobian, inverted into Jinv, for the rows that need one (``fresh``)."""
    if fresh.all():
        r, J, ex = fun(active, za, True)
        _keep(extras, n, sel, ex)
        if isinstance(sel, slice):
            Jinv[...] = invert_batched(J)
        else:
            Jinv[active] = invert_batched(J)
        return r
    r = np.empty_like(za)
    if fresh.any():
        r[fresh], J, ex = fun(active[fresh], za[fresh], True)
        _keep(extras, n, active[fresh], ex)
        Jinv[active[fresh]] = invert_batched(J)
    r[~fresh], _, ex = fun(active[~fresh], za[~fresh], False)
    _keep(extras, n, active[~fresh], ex)
    return r


# --- the step ---

def _apply_rows(E, Y):
    """Σ_j E_ij Y[:, j]: E (s, m), Y (n, m, d) -> (n, s, d); explicit loop (batch-independent bits)."""
    out = np.empty((Y.shape[0], E.shape[0], Y.shape[2]), dtype=Y.dtype)
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

    def __init__(self, system, tableau, projection, h, accept_unconverged=False):
        """``accept_unconverged``: a step whose Newton iteration has not converged after its last
        iteration is taken anyway when the iterate is finite (GeometricIntegrators.jl's stopping
        rule: only a non-finite value ends a run); ``self.unconverged`` counts such steps."""
        why = admission(tableau, projection)
        if why:
            raise ValueError(why)
        self.system, self.tableau, self.projection, self.h = system, tableau, projection, float(h)
        self.accept_unconverged, self.unconverged = accept_unconverged, 0
        self.record = rec = projection_record(projection)      # the paper's table row, as the kernel reads it
        if rec.post_term is not None:
            raise ValueError(f"projection '{rec.name}' has its own post term, which the reference engine does not "
                             "apply (it solves the paper's projection): compare it with the compiled engine only")
        self.sigma, self.alpha = rec.sigma(tableau), rec.alpha(tableau)
        self.coupled = rec.coupled
        self.lobatto = tableau.d is not None
        s, d = tableau.s, system.d
        self.s, self.d = s, d
        self.nz = (s + (1 if self.coupled else 0) + (1 if self.lobatto else 0)) * d
        # Lagrange extrapolation of the last step's stage values (nodes c_j − 1) to the next
        # step's nodes c_i, from one step only: two steps (degree 2s − 1) gain nothing for s ≥ 2,
        # whose stage values carry an O(h^{s+1}) error of their own, and their amplification
        # spoils the guess for SRK3.
        self.extrapolation = _lagrange_matrix(tableau.c - 1.0, tableau.c)

    # -- initial guesses --------------------------------------------------------
    def first_guess(self, q):
        """Stage displacements h·q̇(q_n) at every stage: (n, s, d)."""
        with np.errstate(all="ignore"):
            try:                             # a guess: double precision is enough
                v = self.system.vector_field(q.astype(float) if q.dtype == np.longdouble else q).astype(q.dtype)
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
        rec = self.record
        if not rec.post:                         # unprojected: the method's own p_n
            qbar, pbar = q, p
        elif rec.pre == "previous":              # the last step's Λ_n first (eq:symplectic_projection_pre)
            qbar = q + self.alpha * Lam
            pbar = sysm.theta(q) + self.alpha * transpose_apply(sysm.dtheta(q), Lam)
        else:                                    # on the constraint p_n = ϑ(q_n)
            qbar, pbar = q, sysm.theta(q)
        Theta_q = sysm.dtheta(q) if rec.coupled and rec.pre_at == "start" else None

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
                q0 = q0 + self.alpha * L
                sumbY = weigh(tab.b, tab.b_lo, Y)
                if rec.pre_at == "start":
                    Tx = Theta_q[idx]
                else:  # ϑ_q at the unprojected midpoint
                    M = q0 + 0.5 * sumbY
                    Tx = sysm.dtheta(M)
                pb = pb + self.alpha * transpose_apply(Tx, L)
            st = Stages(sysm, tab, h, q0, Y, jacobian=jacobian)
            res = [stage_residual(tab, st, pb, mu).reshape(m, sd)]
            sumbG = weigh(tab.b, tab.b_lo, st.G)
            if self.coupled:
                q1 = q0 + sumbY + sig * L
                T1 = sysm.dtheta(q1)
                Tp = T1 if rec.post_at == "end" else Tx
                p1 = pb + sumbG + sig * transpose_apply(Tp, L)
                res.append(p1 - sysm.theta(q1))
                # what the step needs at this iterate: q increment (perturbation, Ψ_h, projection), p_{n+1}
                extras = {"inc_q": (self.alpha * L + sumbY) + sig * L, "p": p1}
            else:
                extras = {"sumbY": weigh(tab.b, tab.b_lo, Y), "sumbG": sumbG}
            if self.lobatto:
                res.append(weigh(tab.d, np.zeros_like(tab.d), Y))
            r = np.concatenate(res, axis=1)
            if not jacobian:
                return r, None, extras

            J = self._jacobian(z, st, L, Tx if self.coupled else None, T1 if self.coupled else None,
                               q1 if self.coupled else None, M if self.coupled and rec.pre_at == "midpoint" else None)
            return r, J, extras

        return fun, unpack, qbar, pbar, Theta_q

    def _jacobian(self, z, st, L, Tx, T1, q1, M):
        """The exact Jacobian (m, nz, nz) of the step's equations at the stage values ``st``: the
        stage blocks, the coupled projection's rows and columns (ϑ_q of the pre term Tx, of the
        end T1, the end point q1, the midpoint M where ϑ_q is taken there), the Lobatto rows."""
        sysm, tab, sig, al, rec = self.system, self.tableau, self.sigma, self.alpha, self.record
        s, d, m = self.s, self.d, z.shape[0]
        sd = s * d
        iL = sd if self.coupled else None
        iM = sd + (d if self.coupled else 0) if self.lobatto else None
        J = np.zeros((m, self.nz, self.nz), dtype=z.dtype)
        Sx = contract_first(sysm.ddtheta(M), L) if self.coupled and rec.pre_at == "midpoint" else None
        blocks = stage_jacobian_blocks(tab, st)
        for i in range(s):
            for j in range(s):
                B = blocks[i][j]
                if Sx is not None:
                    B = B - (0.5 * tab.b[j] * al) * Sx
                J[:, i * d:(i + 1) * d, j * d:(j + 1) * d] = B
        if self.coupled:
            TxT = np.swapaxes(Tx, -1, -2)
            dpb_dL = al * TxT if Sx is None else al * TxT + (al * al) * Sx     # ∂p̃/∂Λ, p̃ = p̄ + α ϑ_q(x)ᵀΛ
            shift = stage_jacobian_shift(tab, st)
            for i in range(s):
                J[:, i * d:(i + 1) * d, iL:iL + d] = al * shift[i] - dpb_dL
            if rec.post_at == "end":
                S1 = contract_first(sysm.ddtheta(q1), L)
                dp1_dL = dpb_dL + sig * np.swapaxes(T1, -1, -2) + sig * (al + sig) * S1
                extra_Y = sig * S1
            else:                                # ϑ_q of the post term at the midpoint too
                dp1_dL = dpb_dL + sig * TxT + (sig * al) * Sx
                extra_Y = (0.5 * (al + sig)) * Sx
            ThetaT = np.swapaxes(st.Theta, -1, -2)
            KS = weigh(tab.b, np.zeros_like(tab.b), st.K)
            rows = slice(iL, iL + d)
            for j in range(s):
                KB = tab.b[0] * tab.a[0, j] * st.K[:, 0]
                for l in range(1, s):
                    KB = KB + tab.b[l] * tab.a[l, j] * st.K[:, l]
                dp1 = KB + tab.b[j] * ThetaT[:, j] + tab.b[j] * extra_Y
                J[:, rows, j * d:(j + 1) * d] = dp1 - tab.b[j] * T1
            J[:, rows, iL:iL + d] = dp1_dL + al * KS - (al + sig) * T1
        if self.lobatto:
            for i in range(s):
                J[:, i * d:(i + 1) * d, iM:iM + d] = (tab.d[i] / tab.b[i]) * np.eye(d)
                J[:, iM:iM + d, i * d:(i + 1) * d] = tab.d[i] * np.eye(d)
        return J

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
        sig = self.sigma
        s, d = self.s, self.d
        rec = self.record
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
        if not rec.post:
            out.inc_q, out.inc_p, out.p, out.Lam = ex["sumbY"], ex["sumbG"], None, np.zeros_like(q)
        elif self.coupled:
            out.inc_q, out.p, out.inc_p, out.Lam = ex["inc_q"], ex["p"], None, L
        else:  # standard / symplectic: the projection is a separate solve (eq:vprk_3, then the projection)
            sumbY = ex["sumbY"]
            L1, ok1, its1, ex1 = self._post_projection(qbar + sumbY, pbar + ex["sumbG"], Lam)
            ok &= ok1
            out.iterations = its + its1
            out.p = ex1["p"]
            out.inc_q = (sumbY + sig * L1) if rec.pre == "none" else ((self.alpha * Lam + sumbY) + sig * L1)
            out.inc_p, out.Lam = None, L1
        if self.accept_unconverged:
            finite = np.all(np.isfinite(z), axis=1)
            self.unconverged += int(np.count_nonzero(finite & ~ok))
            ok = finite
        out.ok = ok
        return out

    def _post_projection(self, qb, pb, guess):
        """Solve ϑ(q̄ + σΛ) = p̄ + σ ϑ_q(q̄ + σΛ)ᵀΛ for Λ (eq:orthogonal_projection, eq:symplectic_projection_post)."""
        sysm, sig = self.system, self.sigma

        def fun(idx, L, jacobian=True):
            q1 = qb[idx] + sig * L
            T1 = sysm.dtheta(q1)
            p1 = pb[idx] + sig * transpose_apply(T1, L)
            r = p1 - sysm.theta(q1)
            if not jacobian:
                return r, None, {"p": p1}
            S1 = contract_first(sysm.ddtheta(q1), L)
            return r, sig * (np.swapaxes(T1, -1, -2) - T1) + sig * sig * S1, {"p": p1}

        scale = np.maximum(np.abs(qb), 1.0)
        scale = np.where(np.isfinite(scale), scale, 1.0)
        return newton(fun, guess, scale)


# --- the state and the time step ---
class State:
    """Mutable per-point state of a run (all arrays have a leading points axis)."""

    def __init__(self, q, p, lam, h, s):
        n, d = q.shape
        self.q = q.copy()
        self.p = p.copy()
        self.Lam = h * lam
        self.q_comp = np.zeros_like(q)
        self.p_comp = np.zeros_like(q)
        self.Y = np.zeros((n, s, d), dtype=q.dtype)   # stage displacements of the last step
        self.mu = np.zeros_like(q)
        self.have_history = np.zeros(n, dtype=bool)
        self.live = np.ones(n, dtype=bool)
        self.breakdown_time = np.full(n, np.inf)
        self.iterations = np.zeros(n, dtype=np.int64)
        self.steps = np.zeros(n, dtype=np.int64)
        # inverse Jacobians of the last step's solve, reused by the next one (allocated at the
        # first step, when the size of the step's system is known); not part of a checkpoint:
        # call forget_jacobians() wherever a run may be resumed from, so that a resumed run is
        # bitwise the run it continues
        self.jinv = None
        self.have_jinv = np.zeros(n, dtype=bool)

    def forget_jacobians(self):
        """Start every point's next solve from a fresh Jacobian."""
        self.have_jinv[:] = False


def _kahan(x, comp, inc):
    """Compensated x + inc; returns (new x, new compensation)."""
    y = inc + comp
    t = x + y
    return t, y - (t - x)


def _attempt(stepper, state, idx, guess, mu0, reuse=True):
    """One step for the points idx from the given guesses; returns (ok, new values)."""
    sysm = stepper.system
    q = state.q[idx]
    if state.jinv is None or state.jinv.shape[1] != stepper.nz:
        state.jinv = np.empty((state.q.shape[0], stepper.nz, stepper.nz), dtype=q.dtype)
        state.have_jinv[:] = False
    known = state.have_jinv[idx] if reuse else np.zeros(idx.size, dtype=bool)
    # while every point is live, Newton refreshes the inverses in place (no gather, no copy back)
    jinv = state.jinv if idx.size == state.q.shape[0] else state.jinv[idx]
    with np.errstate(all="ignore"):
        res = stepper.step(q, state.p[idx], state.Lam[idx], guess, mu0, jinv, known)
        q_new, qc_new = _kahan(q, state.q_comp[idx], res.inc_q)
        if res.inc_p is None:
            p_new, pc_new = res.p, state.p_comp[idx]
        else:
            p_new, pc_new = _kahan(state.p[idx], state.p_comp[idx], res.inc_p)
        ok = res.ok & sysm.in_domain(q_new) & np.all(np.isfinite(p_new), axis=1)
        ok &= np.all(np.isfinite(res.Lam), axis=1)
    return ok, (q_new, qc_new, p_new, pc_new, res)


def _commit(state, idx, ok, new):
    q_new, qc_new, p_new, pc_new, res = new
    good = idx[ok]
    state.q[good], state.q_comp[good] = q_new[ok], qc_new[ok]
    state.p[good], state.p_comp[good] = p_new[ok], pc_new[ok]
    state.Lam[good] = res.Lam[ok]
    state.Y[good] = res.Y[ok]
    if res.mu is not None:
        state.mu[good] = res.mu[ok]
    state.have_history[good] = True
    if res.jinv is not state.jinv:
        state.jinv[good] = res.jinv[ok]
    state.have_jinv[idx] = ok
    state.iterations[idx] += res.iterations
    state.steps[good] += 1


CHUNK = 20000    # points advanced together; larger batches spill out of the cache (docs/scaling.md, "Throughput at scale")


def advance(stepper: Stepper, state: State, t_next: float, chunk: int = CHUNK):
    """Advance every live point of ``state`` by one step (in place), ``chunk`` points at a time.

    A point whose step fails from the extrapolated guess and the last step's Jacobian is tried
    again from that guess with a fresh Jacobian, then from the vector-field guess h·q̇(q_n) (μ = 0)
    with a fresh Jacobian, before it is declared broken down (the compiled engine's ladder).  The chunking changes no bits (a point's step does not depend on its
    batch); it keeps the working arrays small: at 200,000 points one batch runs at 99k
    point-steps/s, chunks of 20,000 at 136k.
    """
    live = np.flatnonzero(state.live)
    for k in range(0, live.size, chunk):
        _advance(stepper, state, live[k:k + chunk], t_next)


def _advance(stepper, state, idx, t_next):
    if idx.size == 0:
        return
    fresh = ~state.have_history[idx]
    guess = stepper.extrapolate(state.Y[idx])
    if fresh.any():
        guess[fresh] = stepper.first_guess(state.q[idx[fresh]])
    known = state.have_jinv[idx].copy() if state.jinv is not None else np.zeros(idx.size, dtype=bool)
    ok, new = _attempt(stepper, state, idx, guess, state.mu[idx])
    _commit(state, idx, ok, new)
    again = ~ok & known           # carried factors failed: the same guess with a Jacobian taken there
    if again.any():
        aidx = idx[again]
        ok_a, new_a = _attempt(stepper, state, aidx, guess[again], state.mu[aidx], reuse=False)
        _commit(state, aidx, ok_a, new_a)
        ok[again] = ok_a
    retry = ~ok & ~fresh
    if retry.any():
        ridx = idx[retry]
        ok_r, new_r = _attempt(stepper, state, ridx, stepper.first_guess(state.q[ridx]), np.zeros_like(state.q[ridx]),
                              reuse=False)
        _commit(state, ridx, ok_r, new_r)
        ok[retry] = ok_r
    bad = idx[~ok]
    state.live[bad] = False
    state.breakdown_time[bad] = t_next


