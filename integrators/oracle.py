"""One (projected) VPRK step in mpmath at 50 digits: the oracle of the double-double engine.

The equations of integrators/projections.py's table written plainly (eq:vprk_1–eq:vprk_3 and each
projection's eq:…_pre / eq:…_post, as integrators/kernel/ solves them), on mpmath numbers, with
ϑ, ϑ_q and ∇H from the system's sympy expressions (our own built-in systems' expressions, turned
into mpmath functions by sympy.lambdify) and the tableau's 50-digit coefficients
(``Tableau.exact``).  Each solve is mpmath's multidimensional Newton to 1e-45.
"""
from __future__ import annotations

import mpmath
import sympy

from integrators.projections import projection_record


class Oracle:
    def __init__(self, system, tableau, projection, h, dps=50):
        self.dps = dps
        mpmath.mp.dps = dps
        self.s, self.d = tableau.s, system.d
        rec = projection_record(projection)
        if rec.post_term is not None:
            raise ValueError(f"projection '{rec.name}' has its own post term, which the oracle does not apply (it "
                             "solves the paper's projection)")
        self.rec, self.sigma, self.alpha = rec, mpmath.mpf(rec.sigma(tableau)), mpmath.mpf(rec.alpha(tableau))
        ex = tableau.exact
        self.a = [[mpmath.mpf(ex["a"][i, j]) for j in range(self.s)] for i in range(self.s)]
        self.abar = [[mpmath.mpf(ex["abar"][i, j]) for j in range(self.s)] for i in range(self.s)]
        self.b = [mpmath.mpf(x) for x in ex["b"]]
        self.dvec = None if ex.get("d") is None else [mpmath.mpf(x) for x in ex["d"]]   # Lobatto (eq:vprk_lobatto)
        self.h = mpmath.mpf(h)
        q = list(system.q)
        subs = {k: sympy.Float(v, 60) if not isinstance(v, int) else v for k, v in system.params.items()}
        mk = lambda exprs: sympy.lambdify(q, [sympy.sympify(e).subs(subs) for e in exprs], "mpmath")
        self._th = mk(system.theta_expr)
        self._T = mk([e for row in system.dtheta_expr for e in row])      # T[k][i] = ∂ϑ_k/∂q_i
        self._dH = mk(system.dH_expr)
        self._vf = system

    def th(self, x):
        return [mpmath.mpf(v) for v in self._th(*x)]

    def T(self, x):
        v = self._T(*x)
        d = self.d
        return [[mpmath.mpf(v[k * d + i]) for i in range(d)] for k in range(d)]

    def dH(self, x):
        return [mpmath.mpf(v) for v in self._dH(*x)]

    def tapply(self, T, v):
        """ϑ_qᵀ v: out_m = Σ_l T[l][m] v_l."""
        d = self.d
        return [mpmath.fsum(T[l][m] * v[l] for l in range(d)) for m in range(d)]

    def velocity(self, x):
        """q̇ solving Ω̄ q̇ = ∇H, Ω̄_ij = ∂_i ϑ_j − ∂_j ϑ_i: the first guess."""
        T, dH, d = self.T(x), self.dH(x), self.d
        M = mpmath.matrix([[T[j][i] - T[i][j] for j in range(d)] for i in range(d)])
        return list(mpmath.lu_solve(M, mpmath.matrix(dH)))

    def _project(self, qh, ph, lam):
        """The consecutive projection after Ψ_h: Λ solving ϑ(q̂ + σΛ) = p̂ + σ ϑ_q(q̂ + σΛ)ᵀΛ from the
        guess ``lam``; (q₁, p₁, Λ)."""
        d, sig = self.d, self.sigma

        def post(*Lz):
            x = [qh[m] + sig * Lz[m] for m in range(d)]
            tl, th1 = self.tapply(self.T(x), list(Lz)), self.th(x)
            return [ph[m] + sig * tl[m] - th1[m] for m in range(d)]
        L = mpmath.findroot(post, list(lam), tol=mpmath.mpf(10) ** (-2 * self.dps + 10), maxsteps=100)
        L = [L[m] for m in range(d)]
        x = [qh[m] + sig * L[m] for m in range(d)]
        tl = self.tapply(self.T(x), L)
        return x, [ph[m] + sig * tl[m] for m in range(d)], L

    def step(self, q, p, lam):
        """(q₁, p₁, Λ₁) from (q, p, Λ = hλ of the last step), mpmath lists of d numbers."""
        s, d, h, sig, al, rec = self.s, self.d, self.h, self.sigma, self.alpha, self.rec
        q = [mpmath.mpf(x) for x in q]
        p = [mpmath.mpf(x) for x in p]
        lam = [mpmath.mpf(x) for x in lam]
        pre = rec.pre
        qbar = [q[m] + al * lam[m] for m in range(d)] if pre == "previous" else list(q)
        pbar = self.th(q) if rec.post else list(p)
        Tq = self.T(q)
        if pre == "previous":
            tl = self.tapply(Tq, lam)
            pbar = [pbar[m] + al * tl[m] for m in range(d)]
        coupled = pre == "unknown"

        lob = self.dvec is not None
        iM = s * d + (d if coupled else 0)

        def parts(z):
            Y = [z[i * d:(i + 1) * d] for i in range(s)]
            L = z[s * d:s * d + d] if coupled else [mpmath.mpf(0)] * d
            q0 = [qbar[m] + al * L[m] for m in range(d)]
            Q = [[q0[m] + mpmath.fsum(self.a[i][j] * Y[j][m] for j in range(s)) for m in range(d)] for i in range(s)]
            G = []
            for i in range(s):
                tY, g = self.tapply(self.T(Q[i]), Y[i]), self.dH(Q[i])
                G.append([tY[m] - h * g[m] for m in range(d)])
            sY = [mpmath.fsum(self.b[i] * Y[i][m] for i in range(s)) for m in range(d)]
            sG = [mpmath.fsum(self.b[i] * G[i][m] for i in range(s)) for m in range(d)]
            return Y, L, q0, Q, G, sY, sG

        def pre_T(q0, sY):
            if rec.pre_at == "midpoint":
                return self.T([q0[m] + sY[m] / 2 for m in range(d)])
            return Tq

        def residual(*z):
            Y, L, q0, Q, G, sY, sG = parts(list(z))
            pb = list(pbar)
            if coupled:
                Tp = pre_T(q0, sY)
                tl = self.tapply(Tp, L)
                pb = [pbar[m] + al * tl[m] for m in range(d)]
            r = []
            mu = list(z[iM:iM + d]) if lob else None
            for i in range(s):
                thQ = self.th(Q[i])
                for m in range(d):
                    rr = thQ[m] - pb[m] - mpmath.fsum(self.abar[i][j] * G[j][m] for j in range(s))
                    if lob:
                        rr += mu[m] * self.dvec[i] / self.b[i]
                    r.append(rr)
            if coupled:
                q1 = [q0[m] + sY[m] + sig * L[m] for m in range(d)]
                Tpost = self.T(q1) if rec.post_at == "end" else Tp
                tl = self.tapply(Tpost, L)
                th1 = self.th(q1)
                r += [pb[m] + sG[m] + sig * tl[m] - th1[m] for m in range(d)]
            if lob:
                r += [mpmath.fsum(self.dvec[i] * Y[i][m] for i in range(s)) for m in range(d)]
            return r

        v = self.velocity(q)
        z0 = [h * v[m] for _ in range(s) for m in range(d)] + (list(lam) if coupled else []) + \
            ([mpmath.mpf(0)] * d if lob else [])
        z = mpmath.findroot(residual, z0, tol=mpmath.mpf(10) ** (-2 * self.dps + 10), maxsteps=100)
        z = [z[i] for i in range(len(z0))]
        Y, L, q0, Q, G, sY, sG = parts(z)
        if coupled:
            q1 = [q0[m] + sY[m] + sig * L[m] for m in range(d)]
            Tp = pre_T(q0, sY)
            pb = [pbar[m] + al * x for m, x in enumerate(self.tapply(Tp, L))]
            Tpost = self.T(q1) if rec.post_at == "end" else Tp
            tl = self.tapply(Tpost, L)
            return q1, [pb[m] + sG[m] + sig * tl[m] for m in range(d)], L
        if rec.post:                       # Ψ_h, then the projection
            return self._project([qbar[m] + sY[m] for m in range(d)], [pbar[m] + sG[m] for m in range(d)], lam)
        return [q[m] + sY[m] for m in range(d)], [p[m] + sG[m] for m in range(d)], [mpmath.mpf(0)] * d
