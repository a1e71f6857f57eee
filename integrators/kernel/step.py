"""One step of W points: where it starts, Newton on the step's equations and, for a projection
solved after Ψ_h, on its post term (:func:`_attempt`); the compensated sums of q_{n+1} and p_{n+1}
(:func:`_sum_increments`); the commit of the lanes whose step succeeded inside the domain
(:func:`_commit`); the guess, the retry from h·q̇ and the breakdown (:func:`_step`)."""
from __future__ import annotations

import numpy as np
from numba import njit

from ..projections import PRE_PREVIOUS, PRE_UNKNOWN
from ..simd import anyl, at, ld, lget, lset, mand, mnot, mor, nlanes, re, sel, st
from .records import DEPTH, MODE_MAIN, MODE_POST, _OPTS, RECURRENCE, _runtime, unknowns
from .linalg import rounding, _own, _scale
from .equations import exact_points, _prepare
from .newton import _newton
from .predictor import _base, _first_guess, _guess, _recurrence, _remember

# -- one step of W points ---------------------------------------------------------------------

@njit(inline='always', **_OPTS)
def _none(f, F):
    """A mask with no lane set (of the same type as any other: one compilation of its users)."""
    x = ld(f, F.done)
    return mand(x != x, x == x)



@njit(**_OPTS)
def _attempt(known, start, ev, inside, P, d, s, nz, g):
    """One step of the lanes ``f.active`` from ``start`` = (the stage guess, the guesses of Λ_{n+1}
    and of μ), starting from the kept Newton factors in the lanes ``known``; commits the new state of
    each lane that succeeds.  Per lane: ``f.okstep`` whether it did, ``f.itn`` += iterations."""
    guess, lam0, mu0 = start
    w, S, f, F, ip, IP, plan = g.w, g.S, g.f, g.F, g.ip, g.IP, P.plan
    sd = s * d
    coupled = plan.pre == PRE_UNKNOWN
    u = unknowns(plan, s, d)
    iL, iM = u.L, u.M
    q, lam = at(w, S.q), at(w, S.lam)
    qbar, pbar, sY, sG, p1 = at(w, S.qbar), at(w, S.pbar), at(w, S.sY), at(w, S.sG), at(w, S.p1)
    z, zev, r = at(w, S.z), at(w, S.zev), at(w, S.r)
    _prepare(ev, P.k, plan, d, w, S)
    for i in range(sd):
        st(z, i, ld(guess, i))
    for m in range(d):
        sc = _scale(ld(q, m))                   # every unknown relative to its coordinate's size
        ow = _own(ld(q, m))
        for i in range(nz // d):
            st(f, F.scale + i * d + m, sc)
            st(f, F.own + i * d + m, ow)
        if coupled:
            st(z, iL + m, ld(lam0, m))
        if plan.lobatto:
            st(z, iM + m, ld(mu0, m))
            st(f, F.scale + iM + m, _scale(ld(pbar, m)))
            st(f, F.own + iM + m, _own(ld(pbar, m)))
    _newton(_runtime(MODE_MAIN, nz), (z, zev, r), nz, (at(w, S.lu), at(ip, IP.piv), known), ev, P, d, s, g)
    ok = ld(f, F.ok) != 0.0
    its = ld(f, F.its)
    inc, pn, ln = at(w, S.inc), at(w, S.pn), at(w, S.ln)
    if coupled:                                 # Ψ_h and Λ solved together
        for m in range(d):
            Lm = ld(zev, iL + m)
            aL = plan.alpha * Lm
            a = aL + ld(sY, m)
            b = plan.sigma * Lm
            im = a + b
            st(inc, m, im)
            if exact_points(Lm):
                st(w, S.ince + m, (ld(w, S.sYe + m) + rounding(aL, ld(sY, m), a)) + rounding(a, b, im))
            st(pn, m, ld(p1, m))
            st(ln, m, Lm)
    elif plan.post:                             # Ψ_h, then the projection
        qh, ph, sYs = at(w, S.qh), at(w, S.ph), at(w, S.sYs)
        pz, pzev, pr = at(w, S.pz), at(w, S.pzev), at(w, S.pr)
        qhe, qbe, phe, pbe = at(w, S.qhe), at(w, S.qbe), at(w, S.phe), at(w, S.pbe)
        exact = exact_points(ld(qbar, 0))
        for m in range(d):
            st(sYs, m, ld(sY, m))
            qhm = ld(qbar, m) + ld(sY, m)
            st(qh, m, qhm)
            phm = ld(pbar, m) + ld(sG, m)
            st(ph, m, phm)
            if exact:
                st(qhe, m, (ld(qbe, m) + ld(w, S.sYe + m)) + rounding(ld(qbar, m), ld(sY, m), qhm))
                st(phe, m, (ld(pbe, m) + ld(w, S.sGe + m)) + rounding(ld(pbar, m), ld(sG, m), phm))
                st(w, S.pcn + m, 0.0)           # p_{n+1}'s term: a post term of one's own may leave it
            st(pz, m, ld(lam0, m))
            st(f, F.pscale + m, _scale(ld(qh, m)))
            st(f, F.pown + m, _own(ld(qh, m)))
        _newton(_runtime(MODE_POST, nz), (pz, pzev, pr), _runtime(d, nz), (at(w, S.PL), at(ip, IP.ipiv), _none(f, F)), ev,
                P, d, s, g)
        ok = mand(ok, ld(f, F.ok) != 0.0)
        its = its + ld(f, F.its)
        for m in range(d):
            aL = plan.alpha * ld(lam, m)
            shift = aL + ld(sYs, m) if plan.pre == PRE_PREVIOUS else ld(sYs, m)
            b = plan.sigma * ld(pzev, m)
            im = shift + b
            st(inc, m, im)
            if exact:
                e = rounding(aL, ld(sYs, m), shift) if plan.pre == PRE_PREVIOUS else 0.0 * shift
                st(w, S.ince + m, (ld(w, S.sYe + m) + e) + rounding(shift, b, im))
            st(pn, m, ld(p1, m))
            st(ln, m, ld(pzev, m))
    else:
        for m in range(d):
            st(inc, m, ld(sY, m))
            st(ln, m, 0.0)
            if exact_points(ld(sY, m)):
                st(w, S.ince + m, ld(w, S.sYe + m))
    active = ld(f, F.active) != 0.0
    st(f, F.itn, ld(f, F.itn) + sel(active, its, 0.0))
    _sum_increments(plan, d, w, S)
    for m in range(d):
        ok = mand(ok, mand(np.isfinite(ld(pn, m)), np.isfinite(ld(ln, m))))
    st(f, F.okstep, sel(mand(active, ok), 1.0, 0.0))
    _commit(inside, P, d, s, iM, g)


@njit(inline='always', **_OPTS)
def _sum_increments(plan, d, w, S):
    """q_{n+1} = q_n + inc (and, unprojected, p_{n+1} = p_n + Σ b_i G_i) by compensated summation into
    qn, qcn (pn, pcn); a projected step's pn is already p_{n+1}, and in plain doubles its solve left
    what forming it dropped in pcn: the two are renormalised (a double and a term below its half
    ulp).  In plain doubles what rounding the increment to double dropped (``S.ince``, ``S.sGe``)
    joins the compensation term, so q_{n+1} is the step's own to O(ε²) of the increment (rounded,
    the increment's errors of an ulp of itself added up with one sign on the guiding centre's GLRK4
    pairs: docs/brouwer.md)."""
    q, p, qc, pc, sG = at(w, S.q), at(w, S.p), at(w, S.qc), at(w, S.pc), at(w, S.sG)
    inc, pn, qn, qcn, pcn = at(w, S.inc), at(w, S.pn), at(w, S.qn), at(w, S.qcn), at(w, S.pcn)
    exact = exact_points(ld(q, 0))
    for m in range(d):
        y = ld(inc, m) + (ld(qc, m) + ld(w, S.ince + m)) if exact else ld(inc, m) + ld(qc, m)
        t = ld(q, m) + y
        st(qcn, m, y - (t - ld(q, m)))
        st(qn, m, t)
        if plan.post:
            if exact:
                y = ld(pcn, m)
                t = ld(pn, m) + y
                st(pcn, m, y - (t - ld(pn, m)))
                st(pn, m, t)
            else:
                st(pcn, m, ld(pc, m))
        else:
            y = ld(sG, m) + (ld(pc, m) + ld(w, S.sGe + m)) if exact else ld(sG, m) + ld(pc, m)
            t = ld(p, m) + y
            st(pcn, m, y - (t - ld(p, m)))
            st(pn, m, t)


@njit(inline='always', **_OPTS)
def _commit(inside, P, d, s, iM, g):
    """The lanes whose step succeeded (``f.okstep``) and whose q_{n+1} lies in the domain take the new
    state (q, p, Λ, compensation terms, the stages and μ for the next guess); the others keep theirs."""
    w, S, f, F, qr = g.w, g.S, g.f, g.F, g.qr
    q, p, lam, qc, pc = at(w, S.q), at(w, S.p), at(w, S.lam), at(w, S.qc), at(w, S.pc)
    qn, qcn, pn, pcn, ln, zev = at(w, S.qn), at(w, S.qcn), at(w, S.pn), at(w, S.pcn), at(w, S.ln), at(w, S.zev)
    for l in range(nlanes(w)):
        if lget(f, F.okstep, l) != 0.0:
            for m in range(d):
                qr[m] = re(lget(qn, m, l))
            if not inside(qr, P.k):
                lset(f, F.okstep, l, 0.0)
    commit = ld(f, F.okstep) != 0.0
    if anyl(commit):
        Ys, mus = at(w, S.Y), at(w, S.mu)
        for m in range(d):
            st(q, m, sel(commit, ld(qn, m), ld(q, m)))
            st(qc, m, sel(commit, ld(qcn, m), ld(qc, m)))
            st(p, m, sel(commit, ld(pn, m), ld(p, m)))
            st(pc, m, sel(commit, ld(pcn, m), ld(pc, m)))
            st(lam, m, sel(commit, ld(ln, m), ld(lam, m)))
            if P.plan.lobatto:
                st(mus, m, sel(commit, ld(zev, iM + m), ld(mus, m)))
        for i in range(s * d):
            st(Ys, i, sel(commit, ld(zev, i), ld(Ys, i)))


@njit(**_OPTS)
def _step(t_next, n0, ev, inside, P, d, s, nz, g):
    """Advance the live lanes by one step; returns the lanes whose step is over (taken, or broken down).

    The guess (:func:`_guess`): the last step's stages extrapolated, corrected by the last steps'
    defects (``cfg.depth`` of them; none under ``predictor="extrapolate"``).  A step is tried from
    up to three starts before a lane breaks down: (0) the guess, with a Jacobian taken there where
    the lane trusts it (``F.trust``; never where ``cfg.trust`` < 0: ``predictor="extrapolate"``, and pairs above
    ``Tolerances.trust_max_unknowns``) and the step is due (its number, ``n0`` + ``F.jn``, a
    multiple of ``cfg.every``: a schedule by step number, not by the lane's own history, so the
    lanes of a group take their Jacobians at the same steps wherever their points lie), else with
    the factors carried from the last step; if that
    fails, (1) the uncorrected base guess with the other choice (a Jacobian there when none are
    carried; under ``predictor="extrapolate"`` the base is the guess, so this is the same guess
    with a fresh Jacobian); then (2) h·q̇(q_n) at every stage, μ = 0, with a Jacobian taken there.  A first
    step starts at (2).  A lane whose last try fails (Newton does not converge, a value is not
    finite, q leaves the domain) is frozen at its last good state with its breakdown time set to
    ``t_next``.  Each further try is the lane's next call of this
    function (``F.retry``: the next try's number, its step not over), made beside its neighbours'
    next steps instead of in a pass of its own in which they would wait; it computes what a pass of
    its own would."""
    w, S, f, F, cfg = g.w, g.S, g.f, g.F, P.cfg
    live = ld(f, F.live) != 0.0
    fresh = ld(f, F.hist) == 0.0
    tries = ld(f, F.retry)
    last = tries == 2.0
    depth = int(cfg.depth)
    plan = P.plan
    nl = d if (plan.pre == PRE_UNKNOWN or plan.post) else 0     # Λ solved for: predicted too
    sd = s * d
    nb = sd + nl + (d if plan.lobatto else 0)
    _base(ev, P, d, s, nl, fresh, g)
    first_try = tries == 0.0
    rec = int(cfg.rec)
    if rec > 0 and anyl(ld(f, F.depth) >= float(DEPTH)):     # (only a full table chooses it)
        if rec == RECURRENCE:                   # the default as a constant: the fit's loops unroll, and
            _recurrence(RECURRENCE, nb, d, w, S)    # its m × m solve stays in registers (the same arithmetic,
        else:                                   # 0.016-0.018 µs a point-step less: docs/benchmarks.md)
            _recurrence(rec, nb, d, w, S)
    _guess(sel(first_try, ld(f, F.ordy), 0.0), sel(first_try, ld(f, F.ordl), 0.0), depth, rec, nb, sd, w, S)
    guess = at(w, S.guess)
    first = mand(live, mor(fresh, last))        # a first step, or the last try: from h·q̇(q_n)
    if anyl(first):
        _first_guess(ev, P, at(w, S.q), guess, first, d, s, g)
    if plan.lobatto:                            # μ's guess: zero on the last try
        for m in range(d):
            st(guess, sd + nl + m, sel(last, 0.0, ld(guess, sd + nl + m)))
    st(f, F.active, sel(live, 1.0, 0.0))
    have = ld(f, F.have) != 0.0
    every = cfg.every                           # this step's number (n0 + F.jn) a multiple of ``every``
    if every > 1.0:
        for l in range(nlanes(w)):
            n = n0 + lget(f, F.jn, l)
            lset(f, F.okstep, l, 1.0 if n - every * np.floor(n / every) == 0.0 else 0.0)
    else:
        st(f, F.okstep, 1.0)
    due = ld(f, F.okstep) != 0.0                # (okstep is free until _attempt sets it)
    trusted = mand(mand(ld(f, F.trust) != 0.0, due), ld(f, F.age) >= cfg.age)   # carried: try 0 untrusted, try 1 trusted
    known = mand(have, mor(mand(first_try, mnot(trusted)), mand(tries == 1.0, trusted)))
    _attempt(known, (guess, at(w, S.guess + sd), at(w, S.guess + sd + nl)), ev, inside, P, d, s, nz, g)
    ok = ld(f, F.okstep) != 0.0
    nxt = sel(mor(fresh, last), 3.0, sel(mand(first_try, have), 1.0, 2.0))   # the next try (3: none left)
    retry = mand(live, mand(mnot(ok), nxt < 3.0))
    st(f, F.retry, sel(live, sel(retry, nxt, 0.0), ld(f, F.retry)))
    st(f, F.have, sel(live, sel(ok, 1.0, 0.0), ld(f, F.have)))
    good = mand(live, ok)
    if depth > 0:
        _remember(mand(good, mnot(fresh)), depth, rec, cfg.trust, cfg.carry, nb, nl, s, d, g)
    st(f, F.stp, ld(f, F.stp) + sel(good, 1.0, 0.0))
    age = ld(f, F.age)
    st(f, F.age, sel(good, sel(age < 255.0, age + 1.0, age), age))
    st(f, F.hist, sel(good, 1.0, ld(f, F.hist)))
    broke = mand(live, mand(mnot(ok), mnot(retry)))
    st(f, F.tbrk, sel(broke, t_next, ld(f, F.tbrk)))
    st(f, F.live, sel(broke, 0.0, ld(f, F.live)))
    return mand(live, mnot(retry))
