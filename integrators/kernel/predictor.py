"""The stage predictor: the guess Newton starts each step from.  The base (:func:`_base`: the
Lagrange polynomial through the last step's stages, with h·q̇(q_n) where asked, :func:`_velocity`),
corrected by the extrapolated defects of the last DEPTH steps (:func:`_guess`) or by their fitted
linear recurrence (:func:`_recurrence`); after a step, :func:`_remember` enters its defect and
picks each block's order for the next guess."""
from __future__ import annotations

import numpy as np
from numba import njit

from ..projections import START
from ..simd import at, ld, mand, mnot, re, sel, st
from .records import AR, _coefficients, DEPTH, _OPTS
from .linalg import lu_factor, lu_solve, _scale
from .equations import evaluate


@njit(**_OPTS)
def _velocity(ev, P, q, v, where, d, g):
    """h·q̇(q) into v (lanes ``where``), q̇ solving Ω̄ q̇ = ∇H (eq:euler_lagrange_equations); zero
    where that is not finite."""
    w, S, ip, IP, h = g.w, g.S, g.ip, g.IP, P.h
    evaluate(ev, P.k, q, False, w, S, START, d)
    T, dH, PL = at(w, S.pT), at(w, S.pdH), at(w, S.PL)
    for i in range(d):
        for j in range(d):
            st(PL, i * d + j, ld(T, j * d + i) - ld(T, i * d + j))
        st(v, i, ld(dH, i))
    ipiv = at(ip, IP.ipiv)
    lu_factor(PL, ipiv, d)
    lu_solve(PL, ipiv, v, d)
    good = where
    for i in range(d):
        good = mand(good, np.isfinite(ld(v, i)))
    for m in range(d):
        st(v, m, sel(good, h * ld(v, m), 0.0))


@njit(**_OPTS)
def _first_guess(ev, P, q, Y, where, d, s, g):
    """Stage displacements h·q̇(q_n) at every stage (lanes ``where``)."""
    v = at(g.w, g.S.vf)
    _velocity(ev, P, q, v, where, d, g)
    for i in range(s):
        for m in range(d):
            st(Y, i * d + m, sel(where, ld(v, m), ld(Y, i * d + m)))


@njit(inline='always', **_OPTS)
def _base(ev, P, d, s, nl, fresh, g):
    """The guess every predictor starts from, into ``base`` (s·d stages, then Λ (``nl`` = d where
    the projection solves for it, else 0), then μ (Lobatto tableaus)): the
    Lagrange polynomial through the last step's stage values (Y_j at nodes c_j − 1) at the new
    nodes c_i, with h·q̇(q_n) as one more node under ``cfg.velocity``; Λ_n and μ_n as they are."""
    w, S, cfg = g.w, g.S, P.cfg
    c = _coefficients(P.tb, s)
    Ys, v, base, lam, mu = at(w, S.Y), at(w, S.vf), at(w, S.base), at(w, S.lam), at(w, S.mu)
    velocity = cfg.velocity != 0.0
    if velocity:
        _velocity(ev, P, at(w, S.q), v, mnot(fresh), d, g)
    for i in range(s):
        for m in range(d):
            acc = c.E[i * (s + 1)] * ld(Ys, m)
            for j in range(1, s):
                acc = acc + c.E[i * (s + 1) + j] * ld(Ys, j * d + m)
            if velocity:
                acc = acc + c.E[i * (s + 1) + s] * ld(v, m)
            st(base, i * d + m, acc)
    for m in range(nl):
        st(base, s * d + m, ld(lam, m))
    if P.plan.lobatto:
        for m in range(d):
            st(base, s * d + nl + m, ld(mu, m))


@njit(inline='always', **_OPTS)
def _recurrence(m, nb, d, w, S):
    """The defects' next value from a linear recurrence fitted to the last DEPTH of them, into ``ar``.

    δ_j ≈ c_0 δ_{j−1} + … + c_{m−1} δ_{j−m} is fitted by least squares to the first stage's d
    components of the DEPTH − m newest defects (normal equations with a ridge of 10⁻¹⁴ of their
    trace: the defects of a smooth motion are nearly dependent), and then predicts every component:
    δ_{n+1} = Σ_a c_a δ_{n−a} = Σ_k w_k T_k with w_k = (−1)^k Σ_{a ≥ k} c_a C(a, k), straight from
    the difference table.  A polynomial extrapolation is such a recurrence with fixed binomial
    coefficients; a fitted one also follows a uniform rotation (the symmetric guiding centre, to
    round-off) and the parasitic two-step wiggle of the unprojected midpoint rule (GLRK1-none: 2·10⁻⁸
    where the polynomial of order 8 gives 3·10⁻⁴ and the best order 2·10⁻⁶; docs/engine.md).  The first stage's defects come back from their
    differences in ``dh`` (newest first).  Lanes without a full table get a prediction too; the
    caller does not choose it."""
    D, dh, G, ar = at(w, S.D), at(w, S.dh), at(w, S.gram), at(w, S.ar)
    for k in range(DEPTH):
        for i in range(d):
            st(dh, k * d + i, ld(D, k * nb + i))
    for j in range(1, DEPTH):                    # after pass j, dh[j + t] = ∇^t δ_{n−j}: so dh[j] = δ_{n−j}
        for k in range(DEPTH - 1, j - 1, -1):
            for i in range(d):
                st(dh, k * d + i, ld(dh, (k - 1) * d + i) - ld(dh, k * d + i))
    rows = DEPTH - m
    mm = m + 1                                   # G: m rows of m coefficients and the right-hand side
    for a in range(m):
        for b in range(a, mm):
            x0, y0 = (a + 1) * d, (b + 1) * d if b < m else 0
            acc = ld(dh, x0) * ld(dh, y0)
            for j in range(rows):
                for i in range(1 if j == 0 else 0, d):
                    acc = acc + ld(dh, x0 + j * d + i) * ld(dh, y0 + j * d + i)
            st(G, a * mm + b, acc)
            if b < m:
                st(G, b * mm + a, acc)
    tr = ld(G, 0)
    for a in range(1, m):
        tr = tr + ld(G, a * mm + a)
    ridge = 1e-14 * tr / float(m)
    for a in range(m):
        st(G, a * mm + a, ld(G, a * mm + a) + ridge)
    for a in range(m):                           # Gaussian elimination (symmetric positive: no pivots;
        piv = ld(G, a * mm + a)                  # a zero one, where every defect is 0, divides by 1)
        st(G, a * mm + a, sel(piv != 0.0, piv, 1.0))
        inv = 1.0 / ld(G, a * mm + a)
        for b in range(a + 1, m):
            f = ld(G, b * mm + a) * inv
            for c in range(a, mm):
                st(G, b * mm + c, ld(G, b * mm + c) - f * ld(G, a * mm + c))
    for a in range(m - 1, -1, -1):               # the coefficients c_a, in G's last column
        acc = ld(G, a * mm + m)
        for b in range(a + 1, m):
            acc = acc - ld(G, a * mm + b) * ld(G, b * mm + m)
        st(G, a * mm + m, acc / ld(G, a * mm + a))
    for k in range(m):                           # the weights w_k of T_k, into G's first column
        acc = ld(G, k * mm + m)                  # (a = k: C(k, k) = 1)
        binom = 1.0
        for a in range(k + 1, m):
            binom = binom * a / (a - k)          # C(a, k)
            acc = acc + binom * ld(G, a * mm + m)
        st(G, k * mm, -acc if k % 2 else acc)
    for i in range(nb):
        acc = ld(G, 0) * ld(D, i)
        for k in range(1, m):
            acc = acc + ld(G, k * mm) * ld(D, k * nb + i)
        st(ar, i, acc)


@njit(inline='always', **_OPTS)
def _guess(ordy, ordl, depth, rec, nb, sd, w, S):
    """The guess (stages, Λ, μ): ``base`` plus the extrapolated error of the base.  The defects
    δ = solution − base of the last steps are kept as a table of backward differences, T_k = ∇^k δ
    (``D``, newest first); base + T_0 + … + T_{m−1} is the polynomial of degree m − 1 through the
    last m defects, one step on (Newton's backward-difference form), with m per lane: ``ordy`` for
    the stages, ``ordl`` for Λ and μ (0: the base itself; AR: base + the fitted recurrence's
    prediction ``ar``, where ``rec`` > 0).  A step's solution is a smooth function of its q_n, and
    so is the base's error, which this polynomial follows."""
    base, D, guess, ar = at(w, S.base), at(w, S.D), at(w, S.guess), at(w, S.ar)
    for i in range(nb):
        x = ld(base, i)
        acc = x
        order = ordy if i < sd else ordl
        for k in range(depth):
            acc = acc + ld(D, k * nb + i)
            x = sel(order == float(k + 1), acc, x)
        if rec > 0:
            y = ld(base, i) + ld(ar, i)
            x = sel(mand(order == AR, np.isfinite(y)), y, x)
        st(guess, i, x)


@njit(inline='always', **_OPTS)
def _remember(valid, depth, rec, trust, floor, nb, nl, s, d, g):
    """After a step taken from a base (lanes ``valid``): the new defect δ = (Y, Λ, μ)_{n+1} − base
    enters the difference table (T_0 = δ, T_k = T_{k−1} − T_{k−1}^old).  The new T_m is the error
    the guess of order m would have made on this step, so each block (stages; Λ and μ) takes for
    its next guess the order that did best here (among those its history allows), and the lane
    trusts its next stage guess (a Jacobian taken there) when that order's error was at most
    ``trust`` relative to max(|q|, 1), and above ``floor`` (the refresh floor: from a guess that
    close the carried factors converge in the two iterations any start takes, and a Jacobian there
    is waste).  With ``rec`` > 0 the fitted recurrence's prediction (``ar``,
    made before the step from the full table) competes too, as order AR."""
    w, S, f, F = g.w, g.S, g.f, g.F
    base, D, Ys, lam, mu, q = at(w, S.base), at(w, S.D), at(w, S.Y), at(w, S.lam), at(w, S.mu), at(w, S.q)
    cur, inv = at(w, S.guess), at(w, S.tl)       # (the guess is spent; tl is free after _prepare)
    sd = s * d
    held = ld(f, F.depth)
    for m in range(d):
        st(inv, m, 1.0 / _scale(re(ld(q, m))))
    for i in range(nb):
        new = ld(Ys, i) if i < sd else (ld(lam, i - sd) if i < sd + nl else ld(mu, i - sd - nl))
        st(cur, i, new - ld(base, i))
    zero = sel(valid, 0.0, 0.0)
    besty, bestl, ordy, ordl = zero, zero, zero, zero
    ary, arl, arok = zero, zero, held >= float(DEPTH)
    ar = at(w, S.ar)
    for k in range(depth + 1):
        ey, el = zero, zero
        for i in range(nb):
            c = ld(cur, i)
            a = abs(re(c)) * re(ld(inv, i % d))
            if i < sd:
                ey = sel(a > ey, a, ey)
            else:
                el = sel(a > el, a, el)
            if rec > 0 and k == 0:
                e = abs(re(c - ld(ar, i))) * re(ld(inv, i % d))
                arok = mand(arok, np.isfinite(e))
                if i < sd:
                    ary = sel(e > ary, e, ary)
                else:
                    arl = sel(e > arl, e, arl)
            if k < depth:
                old = ld(D, k * nb + i)
                st(D, k * nb + i, sel(valid, c, old))
                st(cur, i, c - old)
        if k == 0:
            besty, bestl = ey, el
        else:
            allowed = held >= float(k)
            better = mand(allowed, ey < besty)
            besty, ordy = sel(better, ey, besty), sel(better, float(k), ordy)
            better = mand(allowed, el < bestl)
            bestl, ordl = sel(better, el, bestl), sel(better, float(k), ordl)
    if rec > 0:
        better = mand(arok, ary < besty)
        besty, ordy = sel(better, ary, besty), sel(better, AR, ordy)
        better = mand(arok, arl < bestl)
        bestl, ordl = sel(better, arl, bestl), sel(better, AR, ordl)
    st(f, F.ordy, sel(valid, ordy, ld(f, F.ordy)))
    st(f, F.ordl, sel(valid, ordl, ld(f, F.ordl)))
    trusted = mand(besty <= trust, besty > floor)
    st(f, F.trust, sel(valid, sel(trusted, 1.0, 0.0), ld(f, F.trust)))
    st(f, F.depth, sel(valid, sel(held < float(depth), held + 1.0, float(depth)), held))
