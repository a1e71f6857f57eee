"""The step's equations (eq:vprk_1 - eq:vprk_3, eq:vprk_lobatto) with the coupled projections'
pre and post rows, their exact Jacobian, and where Ψ_h starts (:func:`_prepare`).  :func:`_main` is
what Newton solves in MODE_MAIN; :func:`_residual` also serves the tests through
:func:`integrators.kernel.probe`."""
from __future__ import annotations

from numba import njit, types
from numba.extending import overload

from ..ddouble import DDType, dd
from ..projections import END, MIDPOINT, PRE_PREVIOUS, PRE_UNKNOWN, START
from ..simd import DDVec, Vec, at, ld, raw, st
from .records import _coefficients, _OPTS, unknowns
from .linalg import apply, contract, product_rounding, rounding, transpose_apply, _weighted_sum


def lobatto_d(c, i, like):
    """The Lobatto weight d_i (eq:vprk_lobatto) in the precision of ``like``: the double d_i, or for
    a double-double ``like`` the double-double d_i + d_lo_i."""


def lobatto_ratio(c, i, like):
    """d_i / b_i in the precision of ``like`` (double: d_i / b_i of the doubles, as always)."""


@overload(lobatto_d, inline="always")
def _lobatto_d(c, i, like):
    if isinstance(like, (DDType, DDVec)):
        return lambda c, i, like: dd(c.d[i], c.d_lo[i])
    return lambda c, i, like: c.d[i]


@overload(lobatto_ratio, inline="always")
def _lobatto_ratio(c, i, like):
    if isinstance(like, (DDType, DDVec)):
        return lambda c, i, like: dd(c.d[i], c.d_lo[i]) / dd(c.b[i], c.b_lo[i])
    return lambda c, i, like: c.d[i] / c.b[i]


def exact_points(like):
    """Whether the equations see the points they are evaluated at exactly (a compile-time constant):
    in plain doubles a point q̄ + x is rounded to double, and what the rounding drops, e (:func:`rounding`),
    enters the residual as ϑ_q e, so that the residual resolves every increment to its own size
    (:func:`_residual`); double-double values carry their own low part and complex-step values a
    derivative, so there the points are taken as they are."""


@overload(exact_points, inline="always")
def _exact_points(like):
    yes = isinstance(like, (Vec, types.Float))
    return lambda like: yes


@njit(inline='always', **_OPTS)
def evaluate(ev, k, x, need, w, S, slot, d):
    """ϑ and its derivatives at the point x (d values) into the point slot ``slot`` (START, MIDPOINT or
    END) of the scratch ``w``: ϑ at ``S.pth + slot·d``, ϑ_q at ``S.pT + slot·d²`` (row-major,
    [k, i] = ∂ϑ_k/∂q_i), ∇H at ``S.pdH + slot·d`` and, when ``need``, ϑ_qq at ``S.pTT + slot·d³`` and
    ∇²H at ``S.pHH + slot·d²``.  Part of the post-term contract (:func:`project`): a post term reads
    them with :func:`integrators.simd.at`/``ld``; any lane width."""
    dd = d * d
    ev(raw(x), k, need, raw(at(w, S.pth + slot * d)), raw(at(w, S.pT + slot * dd)),
       raw(at(w, S.pTT + slot * dd * d)), raw(at(w, S.pdH + slot * d)), raw(at(w, S.pHH + slot * dd)))


# -- the step's equations ---------------------------------------------------------------------

@njit(inline='always', **_OPTS)
def _force(T, y, h, dH, G, Ge, d):
    """G_m = Σ_l T[l, m] y_l − h ∇H_m in doubles, and into Ge what its products and sums dropped
    (:func:`product_rounding`, :func:`rounding`): G + Ge is G to O(ε²) of its terms."""
    for m in range(d):
        acc = ld(T, m) * ld(y, 0)
        err = product_rounding(ld(T, m), ld(y, 0), acc)
        for l in range(1, d):
            t = ld(T, l * d + m)
            pr = t * ld(y, l)
            sm = acc + pr
            err = err + (rounding(acc, pr, sm) + product_rounding(t, ld(y, l), pr))
            acc = sm
        hg = h * ld(dH, m)
        g = acc - hg
        err = (err - product_rounding(h, ld(dH, m), hg)) + rounding(acc, -hg, g)
        st(G, m, g)
        st(Ge, m, err)


@njit(inline='always', **_OPTS)
def _plain_sum(wt, o, v, s, d, m):
    """Σ_i wt_{o+i} v_{i,m} in plain arithmetic (for error terms)."""
    acc = wt[o] * ld(v, m)
    for i in range(1, s):
        acc = acc + wt[o + i] * ld(v, i * d + m)
    return acc


@njit(inline='always', **_OPTS)
def _stages(z, jac, ev, P, c, q0, s, d, w, S):
    """Q_i = q̃ + Σ_j a_ij Y_j, their ϑ, ϑ_q, ∇H, and G_i = ϑ_q(Q_i)ᵀY_i − h∇H(Q_i) (eq:vprk_1,
    eq:vprk_3); with ``jac`` (and in plain doubles) also K_i = ∂G_i/∂Q_i.  Then Σ b_i Y_i and Σ b_i
    G_i (sY, sG), double + correction weights.  In plain doubles every sum is formed to O(ε²)
    (:func:`_weighted_sum`): ϑ_q(Q_i) e_i goes to tE, e_i what forming Q_i in doubles dropped
    (Σ_j a_ij Y_j's rounding, q̃ + that sum's, q̃'s own ``S.eQ``: :func:`exact_points`); to ``S.Ge``
    what forming G_i from the values ϑ_q(Q_i), Y_i and ∇H(Q_i) dropped (:func:`_force`) and K_i e_i,
    so that G_i too is taken at the stage point Q_i + e_i, as ϑ(Q_i) is (without it, one step of the
    guiding centre's GLRK6-symmetric pair erred in r² by −0.0101 ± 0.0016 ulp on average over 4·10⁵
    points with ϑ correctly rounded, −0.0012 with it: docs/brouwer.md); and what rounding the two
    sums to double dropped (with Σ b_i Ge_i) to ``S.sYe``, ``S.sGe``."""
    k, h = P.k, P.h
    dd = d * d
    ddd = dd * d
    Q, th, T, TT, dH, HH = at(w, S.Q), at(w, S.th), at(w, S.T), at(w, S.TT), at(w, S.dH), at(w, S.HH)
    G, K, sY, sG = at(w, S.G), at(w, S.K), at(w, S.sY), at(w, S.sG)
    exact = exact_points(ld(q0, 0))
    e0, e, tE = at(w, S.eQ), at(w, S.tl), at(w, S.tE)
    for i in range(s):
        for m in range(d):
            if exact:                           # Σ_j a_ij Y_j to O(ε²), its error into e_i
                x, xe = _weighted_sum(c.a, c.a_lo, i * s, z, s, d, m)
                Qm = ld(q0, m) + x
                st(Q, i * d + m, Qm)
                st(e, m, (rounding(ld(q0, m), x, Qm) + xe) + ld(e0, m))
                continue
            acc = c.a[i * s] * ld(z, m)
            for j in range(1, s):
                acc = acc + c.a[i * s + j] * ld(z, j * d + m)
            cor = c.a_lo[i * s] * ld(z, m)
            for j in range(1, s):
                cor = cor + c.a_lo[i * s + j] * ld(z, j * d + m)
            x = acc + cor
            Qm = ld(q0, m) + x
            st(Q, i * d + m, Qm)
        ev(raw(at(Q, i * d)), k, jac or exact, raw(at(th, i * d)), raw(at(T, i * dd)), raw(at(TT, i * ddd)),
           raw(at(dH, i * d)), raw(at(HH, i * dd)))
        if exact:
            apply(at(T, i * dd), e, at(tE, i * d), d)
        Gi, Ki = at(G, i * d), at(K, i * dd)
        if jac or exact:
            contract(at(TT, i * ddd), at(z, i * d), Ki, d)
            for mn in range(dd):
                st(Ki, mn, ld(Ki, mn) - h * ld(HH, i * dd + mn))
        if exact:                               # G_i and what forming it dropped (Ge), at Q_i + e_i
            Gei = at(w, S.Ge + i * d)
            _force(at(T, i * dd), at(z, i * d), h, at(dH, i * d), Gi, Gei, d)
            for m in range(d):                  # K_i e_i: G_i's first-order change from Q_i to Q_i + e_i
                acc = ld(Ki, m * d) * ld(e, 0)
                for n in range(1, d):
                    acc = acc + ld(Ki, m * d + n) * ld(e, n)
                st(Gei, m, ld(Gei, m) + acc)
        else:
            transpose_apply(at(T, i * dd), at(z, i * d), Gi, d)
            for m in range(d):
                st(Gi, m, ld(Gi, m) - h * ld(dH, i * d + m))
    for m in range(d):
        if exact:                               # the increments to O(ε²): what rounding them drops
            y, ye = _weighted_sum(c.b, c.b_lo, 0, z, s, d, m)       # goes to sYe, sGe
            g, ge = _weighted_sum(c.b, c.b_lo, 0, G, s, d, m)
            ge = ge + _plain_sum(c.b, 0, at(w, S.Ge), s, d, m)
            st(sY, m, y)
            st(sG, m, g)
            st(w, S.sYe + m, ye)
            st(w, S.sGe + m, ge)
            continue
        acc = c.b[0] * ld(z, m)
        cor = c.b_lo[0] * ld(z, m)
        accg = c.b[0] * ld(G, m)
        corg = c.b_lo[0] * ld(G, m)
        for i in range(1, s):
            acc = acc + c.b[i] * ld(z, i * d + m)
            cor = cor + c.b_lo[i] * ld(z, i * d + m)
            accg = accg + c.b[i] * ld(G, i * d + m)
            corg = corg + c.b_lo[i] * ld(G, i * d + m)
        st(sY, m, acc + cor)
        st(sG, m, accg + corg)


@njit(inline='always', **_OPTS)
def _residual(z, jac, r, ev, P, c, d, s, w, S):
    """The residual of the step's equations; returns the slot of ϑ_q in the pre term.

    R_i = ϑ(Q_i) − p̃ − Σ_j ā_ij G_j (+ μ d_i/b_i)  (eq:vprk_2, eq:vprk_lobatto).  With a coupled
    projection q̃ = q̄ + Λ, p̃ = p̄ + ϑ_q(x_pre)ᵀΛ (eq:symmetric_projection_pre,
    eq:symplectic_midpoint_projection_pre) and the constraint row R_Λ = p_{n+1} − ϑ(q_{n+1}) with
    q_{n+1} = q̃ + Σ b_i Y_i + σΛ, p_{n+1} = p̃ + Σ b_i G_i + σ ϑ_q(x_post)ᵀΛ (the matching _post).

    In plain doubles ϑ at a point is taken as ϑ(x) + ϑ_q(x) e, e what rounding x = q̄ + … to double
    dropped (:func:`exact_points`): ϑ(Q_i) − p̃ is then the increment's own, to its own relative
    precision, not to an ulp of q.  Without it the part of Y below an ulp of q is left where the
    guess put it, and the compensated sum of q_{n+1} accumulates it (a constant of the motion kept
    exactly in exact arithmetic then walks off by whole ulps, one sign: docs/brouwer.md).  And the
    stage rows are formed to O(ε²) of their terms from the values the system returns: Σ_j ā_ij G_j
    by :func:`_weighted_sum`, each G_j with what forming it dropped (``S.Ge``, :func:`_force`).
    Rounded instead, the residual's own rounding left every step's result off by a part of one
    sign: one GLRK2-symmetric step of a rotation whose ϑ and H evaluate exactly moved r² outwards by
    +0.021 of its round-off's spread (10⁶ points), and the symmetric guiding centre's r² drifted
    at large steps (docs/brouwer.md, "The residual's own rounding").  What the system's own
    evaluations round is not the engine's to undo.
    """
    k, plan = P.k, P.plan
    dd = d * d
    coupled = plan.pre == PRE_UNKNOWN
    u = unknowns(plan, s, d)
    iL, iM = u.L, u.M
    qbar, pbar, q0, pb = at(w, S.qbar), at(w, S.pbar), at(w, S.q0), at(w, S.pb)
    sY, sG, q1, p1, mid, tl = at(w, S.sY), at(w, S.sG), at(w, S.q1), at(w, S.p1), at(w, S.mid), at(w, S.tl)
    th, G, pth, pT, tE, pwe = at(w, S.th), at(w, S.G), at(w, S.pth), at(w, S.pT), at(w, S.tE), at(w, S.pwe)
    Lz = at(z, iL)
    exact = exact_points(ld(qbar, 0))
    qbe, e0 = at(w, S.qbe), at(w, S.eQ)
    for m in range(d):
        if coupled:
            aL = plan.alpha * ld(Lz, m)
            q0m = ld(qbar, m) + aL
            st(q0, m, q0m)
            if exact:
                st(e0, m, ld(qbe, m) + rounding(ld(qbar, m), aL, q0m))
        else:
            st(q0, m, ld(qbar, m))
            if exact:
                st(e0, m, ld(qbe, m))
    _stages(z, jac, ev, P, c, q0, s, d, w, S)
    px = START
    if coupled:
        if plan.pre_at == MIDPOINT:        # ϑ_q at the unprojected midpoint q̄_{n+1/2}
            for m in range(d):
                st(mid, m, ld(q0, m) + 0.5 * ld(sY, m))
            evaluate(ev, k, mid, jac, w, S, MIDPOINT, d)
            px = MIDPOINT
        transpose_apply(at(pT, px * dd), Lz, pb, d)
        for m in range(d):
            aT = plan.alpha * ld(pb, m)
            pbm = ld(pbar, m) + aT
            if exact:
                st(pwe, m, ld(w, S.pbe + m) + rounding(ld(pbar, m), aT, pbm))
            st(pb, m, pbm)
    else:
        for m in range(d):
            st(pb, m, ld(pbar, m))
            if exact:
                st(pwe, m, ld(w, S.pbe + m))
    for i in range(s):
        for m in range(d):
            if exact:                           # ϑ(Q_i) − p̃ − Σ_j ā_ij G_j, every sum and G_j to O(ε²)
                x, xe = _weighted_sum(c.abar, c.abar_lo, i * s, G, s, d, m)
                xe = xe + _plain_sum(c.abar, i * s, at(w, S.Ge), s, d, m)
                rr = ld(th, i * d + m) - ld(pb, m)
                rr = (((rr + ld(tE, i * d + m)) - ld(pwe, m)) - x) - xe
                if plan.lobatto:
                    rr = rr + ld(z, iM + m) * lobatto_ratio(c, i, rr)
                st(r, i * d + m, rr)
                continue
            acc = c.abar[i * s] * ld(G, m)
            for j in range(1, s):
                acc = acc + c.abar[i * s + j] * ld(G, j * d + m)
            cor = c.abar_lo[i * s] * ld(G, m)
            for j in range(1, s):
                cor = cor + c.abar_lo[i * s + j] * ld(G, j * d + m)
            rr = ld(th, i * d + m) - ld(pb, m)
            if exact:
                rr = (rr + ld(tE, i * d + m)) - ld(pwe, m)
            rr = rr - (acc + cor)
            if plan.lobatto:
                rr = rr + ld(z, iM + m) * lobatto_ratio(c, i, rr)
            st(r, i * d + m, rr)
    if coupled:
        e1 = at(w, S.qhe)
        for m in range(d):
            a = ld(q0, m) + ld(sY, m)
            q1m = a + plan.sigma * ld(Lz, m)
            st(q1, m, q1m)
            if exact:
                st(e1, m, (ld(e0, m) + ld(w, S.sYe + m)) + rounding(ld(q0, m), ld(sY, m), a)
                   + rounding(a, plan.sigma * ld(Lz, m), q1m))
        evaluate(ev, k, q1, jac, w, S, END, d)
        pp = END if plan.post_at == END else px
        transpose_apply(at(pT, pp * dd), Lz, tl, d)
        if exact:
            apply(at(pT, END * dd), e1, at(w, S.eQ), d)        # ϑ_q(q_{n+1}) e_{n+1} (q̃'s e0 is used)
        for m in range(d):
            a = ld(pb, m) + ld(sG, m)
            p1m = a + plan.sigma * ld(tl, m)
            st(p1, m, p1m)
            rl = p1m - ld(pth, END * d + m)
            if exact:
                pe = ((ld(pwe, m) + ld(w, S.sGe + m)) + rounding(ld(pb, m), ld(sG, m), a)
                      + rounding(a, plan.sigma * ld(tl, m), p1m))
                st(w, S.pcn + m, pe)           # p_{n+1}'s compensation term (:func:`_sum_increments`)
                rl = (rl + pe) - ld(w, S.eQ + m)
            st(r, iL + m, rl)
    if plan.lobatto:
        for m in range(d):
            z0 = ld(z, m)
            acc = lobatto_d(c, 0, z0) * z0
            for i in range(1, s):
                acc = acc + lobatto_d(c, i, z0) * ld(z, i * d + m)
            st(r, iM + m, acc)
    return px


@njit(inline='always', **_OPTS)
def _stage_jacobian(J, nz, c, plan, d, s, w, S):
    """∂R_i/∂Y_j: a_ij ϑ_q(Q_i) − ā_ij ϑ_q(Q_j)ᵀ − Σ_l ā_il a_lj K_l (− b_j S_x/2 at the midpoint)."""
    dd = d * d
    T, K, Sx = at(w, S.T), at(w, S.K), at(w, S.S)
    mid = plan.pre == PRE_UNKNOWN and plan.pre_at == MIDPOINT
    for i in range(s):
        for j in range(s):
            aij, abij = c.a[i * s + j], c.abar[i * s + j]
            for m in range(d):
                for n in range(d):
                    B = aij * ld(T, i * dd + m * d + n) - abij * ld(T, j * dd + n * d + m)
                    for l in range(s):
                        cc = c.abar[i * s + l] * c.a[l * s + j]
                        if cc != 0.0:
                            B = B - cc * ld(K, l * dd + m * d + n)
                    if mid:
                        B = B - (0.5 * c.b[j] * plan.alpha) * ld(Sx, m * d + n)
                    st(J, (i * d + m) * nz + j * d + n, B)


@njit(inline='always', **_OPTS)
def _projection_jacobian(J, nz, px, c, plan, d, s, w, S):
    """The coupled projection's rows and columns: ∂R_i/∂Λ, ∂R_Λ/∂Λ and ∂R_Λ/∂Y_j (the derivatives of
    the pre and post terms of eq:symmetric_projection_pre/_post and the midpoint's)."""
    dd = d * d
    iL = unknowns(plan, s, d).L
    T, K, pT = at(w, S.T), at(w, S.K), at(w, S.pT)
    Sx, S1 = at(w, S.S), at(w, S.S + dd)
    sig, al = plan.sigma, plan.alpha
    Tx = at(pT, px * dd)
    T1 = at(pT, END * dd)
    Tp = T1 if plan.post_at == END else Tx
    spost = S1 if plan.post_at == END else Sx
    upost = (al + sig) if plan.post_at == END else al        # ∂x_post/∂Λ
    cpost = 1.0 if plan.post_at == END else 0.5              # ∂x_post/∂Y_j = cpost b_j
    mid = plan.pre_at == MIDPOINT
    for m in range(d):
        for n in range(d):
            dpb = al * ld(Tx, n * d + m)                     # ∂p̃/∂Λ = α ϑ_q(x_pre)ᵀ (+ α² S_x at the midpoint)
            if mid:
                dpb = dpb + (al * al) * ld(Sx, m * d + n)
            for i in range(s):
                B = ld(T, i * dd + m * d + n)
                for l in range(s):
                    if c.abar[i * s + l] != 0.0:
                        B = B - c.abar[i * s + l] * ld(K, l * dd + m * d + n)
                st(J, (i * d + m) * nz + iL + n, al * B - dpb)
            KS = c.b[0] * ld(K, m * d + n)
            for l in range(1, s):
                KS = KS + c.b[l] * ld(K, l * dd + m * d + n)
            st(J, (iL + m) * nz + iL + n, (dpb + sig * ld(Tp, n * d + m) + (sig * upost) * ld(spost, m * d + n)) + al * KS
               - (al + sig) * ld(T1, m * d + n))
            for j in range(s):
                KB = c.b[0] * c.a[j] * ld(K, m * d + n)
                for l in range(1, s):
                    KB = KB + c.b[l] * c.a[l * s + j] * ld(K, l * dd + m * d + n)
                ey = sig * cpost * ld(spost, m * d + n)
                if mid:
                    ey = ey + (0.5 * al) * ld(Sx, m * d + n)
                st(J, (iL + m) * nz + j * d + n, KB + c.b[j] * ld(T, j * dd + n * d + m) + c.b[j] * ey
                   - c.b[j] * ld(T1, m * d + n))


@njit(inline='always', **_OPTS)
def _main(z, jac, r, J, ev, P, d, s, w, S):
    """Residual of the step's equations (:func:`_residual`) and, when ``jac``, their exact Jacobian
    into J (:func:`_stage_jacobian`, :func:`_projection_jacobian`, the Lobatto rows)."""
    plan = P.plan
    c = _coefficients(P.tb, s)
    px = _residual(z, jac, r, ev, P, c, d, s, w, S)
    if not jac:
        return
    dd = d * d
    ddd = dd * d
    coupled = plan.pre == PRE_UNKNOWN
    u = unknowns(plan, s, d)
    iL, iM, nz = u.L, u.M, u.nz
    for i in range(nz * nz):
        st(J, i, 0.0)
    Lz, pTT = at(z, iL), at(w, S.pTT)
    if coupled and plan.pre_at == MIDPOINT:
        contract(at(pTT, MIDPOINT * ddd), Lz, at(w, S.S), d)        # ∂(ϑ_q(M)ᵀΛ)/∂M
    if coupled and plan.post_at == END:
        contract(at(pTT, END * ddd), Lz, at(w, S.S + dd), d)       # ∂(ϑ_q(q1)ᵀΛ)/∂q1
    _stage_jacobian(J, nz, c, plan, d, s, w, S)
    if coupled:
        _projection_jacobian(J, nz, px, c, plan, d, s, w, S)
    if plan.lobatto:
        for i in range(s):
            for m in range(d):
                st(J, (i * d + m) * nz + iM + m, c.d[i] / c.b[i])
                st(J, (iM + m) * nz + i * d + m, c.d[i])


@njit(inline='always', **_OPTS)
def _prepare(ev, k, plan, d, w, S):
    """q̄, p̄ where Ψ_h starts: the state (q_n, p_n); the symplectic projection first adds the last
    step's Λ_n (eq:symplectic_projection_pre); ϑ_q(q_n) goes to the START slot where a pre term takes
    it there.  A projected step starts from the p_n its solve left on the constraint p = ϑ(q) (to
    Newton's tolerance), not from ϑ(q_n) evaluated afresh: every fresh evaluation is a new rounding
    of ϑ at q_n that the projection turns into a shift of q, and on the guiding centre's
    GLRK6-standard pair those shifts added up with one sign (energy round-off exponent 0.58 ± 0.02
    at 256 starts; docs/brouwer.md, "The projected steps' p_n").  In plain doubles what rounding q̄
    and p̄ to double dropped goes to ``S.qbe`` and ``S.pbe`` (:func:`exact_points`), and so do the
    state's compensation terms q_c and p_c, so that the step advances the state it was given, not
    its doubles.  Seeing only the doubles, an unprojected step fed what q_c and p_c held back into
    the method's parasitic mode every step: on the pendulum written with ϑ = (q₂, 0), GLRK1 keeps
    p₁ = q₂ in exact arithmetic (the error's sign flips a step); p₁ − q₂ broke from 0 after 10³-10⁴
    steps and walked by an ulp a step, and the energy's round-off with it (10⁶ steps: exponent 0.72,
    RMS 4.1·10⁻¹⁴; now 0.11, 7.8·10⁻¹⁷; docs/brouwer.md, "The state's compensation terms")."""
    q, p, lam, qc, pc = at(w, S.q), at(w, S.p), at(w, S.lam), at(w, S.qc), at(w, S.pc)
    qbar, pbar, tl, qbe = at(w, S.qbar), at(w, S.pbar), at(w, S.tl), at(w, S.qbe)
    pT = at(w, S.pT)
    exact = exact_points(ld(q, 0))
    if plan.pre == PRE_PREVIOUS or (plan.pre == PRE_UNKNOWN and plan.pre_at == START):
        evaluate(ev, k, q, False, w, S, START, d)
    for m in range(d):
        if plan.pre == PRE_PREVIOUS:
            aL = plan.alpha * ld(lam, m)
            qb = ld(q, m) + aL
            st(qbar, m, qb)
            if exact:
                st(qbe, m, rounding(ld(q, m), aL, qb) + ld(qc, m))
        else:
            st(qbar, m, ld(q, m))
            if exact:
                st(qbe, m, ld(qc, m))
        st(pbar, m, ld(p, m))
    pbe = at(w, S.pbe)
    if exact:
        for m in range(d):
            st(pbe, m, ld(pc, m))
    if plan.pre == PRE_PREVIOUS:
        transpose_apply(pT, lam, tl, d)
        for m in range(d):
            aT = plan.alpha * ld(tl, m)
            pb = ld(pbar, m) + aT
            if exact:
                st(pbe, m, ld(pbe, m) + rounding(ld(pbar, m), aT, pb))
            st(pbar, m, pb)
