"""Newton's method on W lanes at once: the exact Jacobian factorised per lane and kept while it
contracts (:func:`_newton`), the update and its size (:func:`_update`) and the stopping rule
(:func:`_judge`), all with masks and selects, every decision per lane."""
from __future__ import annotations

import numpy as np
from numba import njit

from ..simd import anyl, at, dithers, is_complex, ld, ldi, lget, lset, mand, mnot, mor, nlanes, sel, st, sti, step_measure
from .records import COMPLEX_STEP, MODE_MAIN, _OPTS
from .linalg import lu_factor, lu_solve
from .equations import _main
from .projection import post_term


@njit(inline='always', **_OPTS)
def _keep_factors(LU, piv, Jt, pivt, stale, nz):
    """The fresh factors Jt, pivt (every lane's) into LU, piv for the lanes that asked (``stale``)."""
    for i in range(nz * nz):
        st(LU, i, sel(stale, ld(Jt, i), ld(LU, i)))
    for i in range(nz):
        sti(piv, i, sel(stale, ldi(pivt, i), ldi(piv, i)))


@njit(inline='always', **_OPTS)
def _note_jacobian(z, stale, nz, d, w, S):
    """The point a fresh Jacobian was taken at (the iterate z, and the step's q_n and Λ_n) into jz,
    jq, jl for the lanes ``stale``."""
    jz, jq, jl, q, lam = at(w, S.jz), at(w, S.jq), at(w, S.jl), at(w, S.q), at(w, S.lam)
    for i in range(nz):
        st(jz, i, sel(stale, ld(z, i), ld(jz, i)))
    for m in range(d):
        st(jq, m, sel(stale, ld(q, m), ld(jq, m)))
        st(jl, m, sel(stale, ld(lam, m), ld(jl, m)))


ROUNDS = 2       # the dithered approach: at most this many of a solve's updates are rounded (_update)
CRAWL = 0.8      # ... and within 64 ulps its carried factors are refreshed only above this contraction (_judge)


@njit(inline='always', **_OPTS)
def _to_grid(z, scale, nz, mask, dither):
    """The lanes ``mask`` of z rounded to a grid of ulp(c), c = dither·2⁵¹·scale per unknown:
    (z + c) − c, exact, a move of at most half that grid (32 ulps of scale for 2⁻⁴⁵)."""
    k = dither * 2.0 ** 51
    for i in range(nz):
        zi = ld(z, i)
        c = ld(scale, i) * k
        st(z, i, sel(mask, (zi + c) - c, zi))


@njit(inline='always', **_OPTS)
def _update(z, r, done, scale, nz, f, F, dither):
    """z −= δ (r holds −δ) in the lanes not done; per lane the update's size max |δ|/scale
    (``F.norm``), whether it was NaN and whether the new z is finite.

    Dithered approach (``dither`` > 0, double unknowns only): where the update was larger than
    ``dither`` (relative, like the size), the new iterate is rounded (and so is the guess, by
    :func:`_newton`) to a grid of ulp(c) with c = dither·2⁵¹·scale, (z + c) − c (exact; for the
    default 2⁻⁴⁵ a grid of 64 ulps of scale, so the iterate moves by at most 32), so Newton's last
    iterations start from a point whose error is set by where the solution falls in the grid, not
    by the guess.  At the floor the computed residual is not smooth (a stage
    point's rounding flips as an unknown moves by less than its ulp), and where Newton stops
    depended on the side it came from; a guess whose error is smooth in time came from the same
    side step after step, and the round-off drifted (point vortices GLRK3-symplectic over 64
    starts, the energy exponent 0.72 ± 0.03 with mean/RMS +0.85; docs/brouwer.md).  The grid's
    offset from the solution changes from step to step like a random number, so the side does
    too.  At most ROUNDS updates a solve are rounded; ``F.rounded`` marks a lane whose iterate was
    (:func:`_judge` does not take the update that follows for the floor).  Bitwise the same in every
    lane and on the scalar path (one add and one subtract a value)."""
    size = sel(done, 0.0, 0.0)
    nan = done
    finite = mnot(done)
    for i in range(nz):
        ri = ld(r, i)
        zi = ld(z, i) - ri
        st(z, i, sel(done, ld(z, i), zi))
        v = step_measure(ri, ld(scale, i), COMPLEX_STEP)
        nan = mor(nan, v != v)
        size = sel(v > size, v, size)
        finite = mand(finite, np.isfinite(zi))
    if dithers(z) and dither > 0.0:
        big = mand(mand(mnot(done), size > dither), ld(f, F.rounds) < ROUNDS)
        _to_grid(z, scale, nz, big, dither)
        st(f, F.rounded, sel(big, 1.0, 0.0))
        st(f, F.rounds, ld(f, F.rounds) + sel(big, 1.0, 0.0))
    st(f, F.norm, size)
    st(f, F.nan, sel(nan, 1.0, 0.0))
    st(f, F.finite, sel(finite, 1.0, 0.0))


@njit(inline='always', **_OPTS)
def _settle(z, done, own, nz, f, F, grid):
    """The settled approach (``grid`` > 0, double unknowns only; the default): the first iterate of a
    solve reached by an update of at most ``grid`` (relative, like the size: 2⁻⁴⁸, 16 ulps of scale)
    is rounded to a grid of ulp(c), c = grid·2⁵¹·own per unknown, ``own`` its coordinate's own |value|
    (8 ulps of the coordinate; a move of at most 4), and Newton goes on from there.  At the floor the
    computed residual is not smooth (a stage point's rounding flips as an unknown moves by less than
    its ulp), so where Newton stops depends on the side it comes from; a guess whose error is smooth
    in time came from the same side step after step, and the round-off drifted (point vortices
    GLRK3-symmetric: the angular momentum over 64 starts and 2·10⁵ steps grew like n^0.98 with
    mean/RMS −0.47; docs/brouwer.md).  The rounded iterate's offset from the solution is set by
    where the solution falls in the grid, not by the guess.  Once a solve; returns the lanes rounded
    now (their update is not the floor: ``off``); ``F.rounds`` counts the updates since
    (:func:`_settling`, :func:`_settled`).  The grid must be coarser than the floor's noise, which
    is in the coordinate's own ulps: 2 ulps of max(|q|, 1) (2⁻⁵⁰) left the point vortices'
    SRK3-symmetric at 0.67 over 64 starts, and finer, in the increments' own ulps, their
    GLRK3-symmetric momentum drifted again; but 8 ulps of max(|q|, 1), hundreds of ulps of a
    near-axis x, y ≈ 0.004, left P_ζ of near-axis Boozer orbits at 1.14e-13 (docs/brouwer.md, "The
    settled approach, the default")."""
    first = mand(mand(mnot(done), ld(f, F.norm) <= grid), ld(f, F.rounds) == 0.0)
    _to_grid(z, own, nz, first, grid)
    st(f, F.rounded, sel(first, 1.0, 0.0))
    st(f, F.rounds, sel(first, 1.0, ld(f, F.rounds)))
    return first


@njit(inline='always', **_OPTS)
def _settling(done, f, F, accept):
    """Before :func:`_judge`, the settled approach's two updates after a rounding (``F.rounds`` 2: the
    update taken at the rounded iterate; 3: the one after it).  Returns the lanes whose solve ends
    now (the update at 3 is at most ``accept``, relative: the iterate it was computed at came from
    the grid, not from the guess's side, and lies within about that of the solution; 2⁻⁶⁰ by
    default: with 2⁻⁵¹ the iterates taken were up to 2 ulps off, Kepler's unprojected GLRK1 lost its
    exact p = v by 4 ulps over 10⁵ steps and Kepler's energy round-off grew 3-7.5×) and the lanes
    whose update is not the floor (the one at 2: its size is the rounding's, and its ratio to the
    update before it says nothing of the factors).  Where the update at 3 is larger, the floor test
    goes on as usual."""
    cnt = ld(f, F.rounds)
    sz = ld(f, F.norm)
    ends = mand(mand(mnot(done), cnt == 3.0), mand(sz <= accept,
                                                   mand(ld(f, F.finite) != 0.0, ld(f, F.nan) == 0.0)))
    return ends, cnt == 2.0


@njit(inline='always', **_OPTS)
def _settled(done, ends, f, F):
    """After :func:`_judge`: the lanes ``ends`` have converged; the update taken at the rounded iterate
    asks for no fresh Jacobian (the judge reads its growth as factors that stopped contracting: a
    Jacobian there took GLRK2-symmetric's Newton work on the predictor's protocol from 4.56 to 7.34,
    tests/test_predictor.py's ``newton_per_step``); the count of updates since the rounding goes on.
    Without that Jacobian, carried factors that contract by more than half an iteration come back
    from the grid slowly and their next update "stops halving" a few ulps from the solution, where
    the floor test stops (the guiding centre's GLRK6-symmetric drifted so, 0.96 over 5·10⁴ steps):
    hence the settled approach only in the pairs whose guesses take Jacobians
    (:class:`integrators.engine.Tolerances`, ``settle``)."""
    cnt = ld(f, F.rounds)
    st(f, F.done, sel(ends, 1.0, ld(f, F.done)))
    st(f, F.ok, sel(ends, 1.0, ld(f, F.ok)))
    st(f, F.stale, sel(mand(mnot(done), cnt == 2.0), 0.0, ld(f, F.stale)))
    st(f, F.rounds, sel(cnt > 0.0, cnt + 1.0, 0.0))


@njit(inline='always', **_OPTS)
def _judge(f, F, cfg, stall, off, strict):
    """Each lane still iterating after an update: failed (NaN, not finite), converged (size ≤ tol, or
    ≤ fine² (an update of 10⁻²⁸ of its coordinate, far below what even the compensation term of q
    holds: there is nothing left to halve), or ≤ stall once the update stops halving: within ``fine`` (64 ulps), or wherever the
    iteration before was a Newton step with a Jacobian at its own iterate, after which the update
    falls quadratically unless round-off stops it; factors carried from an earlier step or iterate
    can stop halving far above the floor, or even grow, when the guess was poor: stopping there
    left errors of 10⁴ ulps of one sign in single steps (tests/test_boozer.py), so such a lane
    takes a fresh Jacobian and goes on; from its ``least``-th iteration on: with the defects'
    guess 2, because at small steps that guess is often within tol already, and taking it, not the
    iterate after it, left its extrapolation error, a few ulps of the same sign, in every step:
    SRK3-standard on point vortices at h = 2⁻¹³, 16,384 steps, momentum off by 1.0·10⁻¹³ against
    4.6·10⁻¹⁵ from the extrapolation alone) or on, with a fresh Jacobian next time if this
    iteration contracted by θ > ``refresh``, its update was larger than ``floor`` (an update a few
    thousand ulps small measures round-off, not the factors: a Jacobian there was the engine's
    largest waste on high-order pairs, docs/benchmarks.md) and θ^horizon·|δ| > tol: the factors
    would not converge within ``horizon`` more iterations, about what a Jacobian costs in
    iterations plus the two it takes after (``horizon`` 0: the first two tests alone).  Written
    with masks and selects, so W lanes are judged at once (the same comparisons and the one division of the scalar path, lane by lane).

    ``strict`` (the dithered approach, whose roundings put an iterate up to 32 ulps of its scale
    off on purpose): an update within ``fine`` is the floor only after a fresh Jacobian or once it
    no longer shrinks at all (θ ≥ 1), never the update taken at a rounded iterate (``off``), and
    within ``fine`` the carried factors are refreshed only where θ > 0.8.  Without it a lane on
    carried factors contracting by 0.5-0.8 stopped 32 ulps of its scale from the solution: P_ζ of
    near-axis Boozer orbits moved by 70-90 ulps in single steps (tests/test_boozer.py)."""
    tol, fine, refresh, floor, horizon, least = cfg.tol, cfg.fine, cfg.refresh, cfg.floor, cfg.horizon, cfg.least
    on = ld(f, F.done) == 0.0
    st(f, F.its, ld(f, F.its) + sel(on, 1.0, 0.0))
    sz, prev = ld(f, F.norm), ld(f, F.prev)
    failed = mor(mor(ld(f, F.nan) != 0.0, ld(f, F.finite) == 0.0), mnot(np.isfinite(sz)))
    theta = sel(np.isfinite(prev), sz / prev, np.inf)
    slow = mand(np.isfinite(theta), theta > 0.5)
    near = mand(sz <= fine, theta >= 1.0) if strict else sz <= fine
    floored = mor(mand(mand(mand(sz <= stall, slow), mor(ld(f, F.exact) != 0.0, near)), mnot(off)),
                  sz <= fine * fine)
    converged = mand(mand(mnot(failed), mor(sz <= tol, floored)), ld(f, F.its) >= least)
    ends = mand(on, mor(failed, converged))
    goes = mand(on, mnot(ends))
    st(f, F.done, sel(ends, 1.0, ld(f, F.done)))
    st(f, F.ok, sel(mand(on, converged), 1.0, ld(f, F.ok)))
    left = sel(goes, np.inf, np.inf)             # |δ| after ``horizon`` more iterations at rate θ
    if horizon > 0.0:
        left = sz
        for _ in range(int(horizon)):
            left = left * theta
    tired = mand(mand(np.isfinite(theta), theta > refresh), mand(mor(sz > floor, slow), left > tol))   # slow: not floored
    if strict:                                   # within the fine band the carried factors go on unless they crawl
        tired = mand(tired, mor(sz > fine, theta > CRAWL))
    st(f, F.exact, sel(goes, ld(f, F.stale), ld(f, F.exact)))     # this iteration's: the next one's judge
    st(f, F.stale, sel(goes, sel(tired, 1.0, 0.0), ld(f, F.stale)))
    st(f, F.prev, sel(goes, sz, prev))


@njit(**_OPTS)
def _newton(mode, iterate, nz, factors, ev, P, d, s, g):
    """Newton's method with the exact Jacobian, kept while it contracts, for every active lane.

    ``mode`` MODE_MAIN solves the step's equations (:func:`_main`), MODE_POST the consecutive projection
    (its post term ``P.post``: :func:`project` for the paper's).  A lane's Jacobian is evaluated and factorised at its first iteration (unless
    ``known``: LU and piv hold its last step's factors) and again after an iteration that shrank
    its update by less than REFRESH.  A lane has converged when max |δ|/scale ≤ STALL once the
    update stops halving within 64 ulps or after an exact Newton step (older factors that stop
    halving above that are refreshed, not taken for the floor: :func:`_judge`), or ≤ TOL (0 by default: every step ends at its round-off floor, so what
    it leaves is round-off and not a remainder of one sign: Brouwer's law, docs/brouwer.md); for complex z the imaginary part, read as a derivative, must pass the
    same test.  A lane that is done is held at its solution ``zev`` (the last iterate at which its
    residual was evaluated; every buffer the equations fill holds that evaluation) while the others
    go on.  Lanes to solve: ``f.active``; the outcome per lane in ``f.ok`` and ``f.its``.  The
    tolerances are runtime data, ``P.cfg`` a :class:`Newton` record (:class:`integrators.engine.Tolerances`);
    with ``cfg.accept`` a finite iterate that has not converged after ``cfg.maxiter`` iterations is
    taken (GeometricIntegrators.jl's stopping rule).

    ``iterate`` = (z, zev, r): the ``nz`` unknowns (the guess on entry), the solution, the residual;
    ``factors`` = (LU, piv, known): the kept factors and the lanes whose factors they are; ``P`` the
    :class:`Step`, ``g`` the :class:`Group`.
    """
    z, zev, r = iterate
    LU, piv, known = factors
    W = nlanes(z)           # (mode and nz arrive as runtime ints: a literal would compile this twice)
    w, S, f, F, ip, IP, cfg = g.w, g.S, g.f, g.F, g.ip, g.IP, P.cfg
    active = ld(f, F.active) != 0.0
    st(f, F.done, sel(active, 0.0, 1.0))
    st(f, F.ok, 0.0)
    st(f, F.its, 0.0)
    st(f, F.prev, np.inf)
    st(f, F.stale, sel(mand(active, mnot(known)), 1.0, 0.0))
    st(f, F.exact, 0.0)
    scale = at(f, F.scale if mode == MODE_MAIN else F.pscale)
    own = at(f, F.own if mode == MODE_MAIN else F.pown)
    Jt = at(w, S.Jt if mode == MODE_MAIN else S.pJ)
    pivt = at(ip, IP.pivt)
    st(f, F.rounded, 0.0)
    st(f, F.rounds, 0.0)
    if dithers(z) and cfg.dither > 0.0:          # the guess too: with the defects' recurrence it is often
        _to_grid(z, scale, nz, active, cfg.dither)   # within the floor already, and its side is the history's
    settles = dithers(z) and cfg.settle > 0.0
    for _ in range(int(cfg.maxiter)):
        done = ld(f, F.done) != 0.0
        if not anyl(mnot(done)):
            break
        stale = ld(f, F.stale) != 0.0
        for i in range(nz):
            zi = sel(done, ld(zev, i), ld(z, i))
            st(z, i, zi)
            st(zev, i, zi)
        jac = anyl(stale)
        Jx, pivx = (LU, piv) if W == 1 else (Jt, pivt)   # one lane: factorise in place
        if mode == MODE_MAIN:
            _main(z, jac, r, Jx, ev, P, d, s, w, S)
        else:
            post_term(P, z, jac, r, Jx, ev, d, w, S)
        if jac:
            lset(f, F.gjac, 0, lget(f, F.gjac, 0) + 1.0)
            lu_factor(Jx, pivx, nz)
            if W > 1:                             # every lane factorised, the lanes that asked keep theirs
                _keep_factors(LU, piv, Jt, pivt, stale, nz)
            if mode == MODE_MAIN:                 # where they were taken: what refactor() rebuilds them from
                _note_jacobian(z, stale, nz, d, w, S)
                st(f, F.age, sel(stale, 0.0, ld(f, F.age)))
        lu_solve(LU, piv, r, nz)                  # r is now −δ
        lset(f, F.gits, 0, lget(f, F.gits, 0) + 1.0)
        off = ld(f, F.rounded) != 0.0             # this update was taken at a rounded iterate
        _update(z, r, done, scale, nz, f, F, cfg.dither)
        ends = done
        if settles:
            off = mor(off, _settle(z, done, own, nz, f, F, cfg.settle))
            ends, after = _settling(done, f, F, cfg.settle_accept)
            off = mor(off, after)
        _judge(f, F, cfg, cfg.stall_complex if is_complex(z) else cfg.stall, off, dithers(z) and cfg.dither > 0.0)
        if settles:
            _settled(done, ends, f, F)
    for l in range(W):                            # lanes out of iterations
        if lget(f, F.done, l) == 0.0 and cfg.accept != 0 and lget(f, F.its, l) > 0:
            lset(f, F.ok, l, 1.0)
