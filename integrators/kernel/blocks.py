"""The kernel's entry points: :func:`advance` (every live point of a state through n steps, blocks
over threads, W lanes at a time, lanes refilled as points finish: :func:`_block`), the points in and
out of their lanes (:func:`_gather`, :func:`_scatter`), the outputs inside a call (:func:`_record`),
:func:`refactor` (a resumed run's Newton factors) and :func:`probe` (the residual and Jacobian of one
point, for tests)."""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..simd import _at, anyl, at, elem, elem3, ld, lget, lanes, lmask, lset, mand, mor, plain, put, put3, sel, st
from .records import DEPTH, ORDERS, ROUNDS, Group, layout, _newton_rule, _OPTS, Outputs, Pair, Plan, _records, Shape, Span, \
    StateArrays, Step
from .linalg import lu_factor
from .equations import _main, _prepare
from .projection import PAPER
from .step import _step


@njit(**_OPTS)
def _gather(st_, pt, l, valid, d, s, nz, g):
    """The state of point ``pt`` into lane ``l``; ``valid`` False leaves the lane empty (it holds
    the point's values, so that its arithmetic stays on ordinary numbers, but it is not live and
    has no factors)."""
    w, S, f, F, ip, IP = g.w, g.S, g.f, g.F, g.ip, g.IP
    q, p, Lam, qc, pc, Y, mu = st_.q, st_.p, st_.Lam, st_.q_comp, st_.p_comp, st_.Y, st_.mu
    hist, live, tbrk, lu, piv, have = st_.have_history, st_.live, st_.breakdown_time, st_.lu, st_.piv, st_.have_lu
    jz, jq, jl = st_.jac_z, st_.jac_q, st_.jac_lam
    for m in range(d):
        lset(w, S.jq + m, l, elem(jq, pt, m))
        lset(w, S.jl + m, l, elem(jl, pt, m))
    for i in range(nz):
        lset(w, S.jz + i, l, elem3(jz, pt, i // d, i % d))
    for m in range(d):
        lset(w, S.q + m, l, elem(q, pt, m))
        lset(w, S.p + m, l, elem(p, pt, m))
        lset(w, S.lam + m, l, elem(Lam, pt, m))
        lset(w, S.qc + m, l, elem(qc, pt, m))
        lset(w, S.pc + m, l, elem(pc, pt, m))
        lset(w, S.mu + m, l, elem(mu, pt, m))
    for i in range(s):
        for m in range(d):
            lset(w, S.Y + i * d + m, l, elem3(Y, pt, i, m))
    for i in range(DEPTH * (s + 2)):
        for m in range(d):
            lset(w, S.D + i * d + m, l, elem3(st_.defects, pt, i, m))
    pr_, O = st_.orders, ORDERS
    lset(f, F.depth, l, float(pr_[pt, O.depth]))
    lset(f, F.ordy, l, float(pr_[pt, O.ordy]))
    lset(f, F.ordl, l, float(pr_[pt, O.ordl]))
    lset(f, F.trust, l, float(pr_[pt, O.trust]))
    lset(f, F.age, l, float(pr_[pt, O.age]))
    known = have[pt] != 0 and valid           # factors kept from the last step
    for i in range(nz):
        for j in range(nz):
            lset(w, S.lu + i * nz + j, l, sel(known, elem3(lu, pt, i, j), 0.0))
        # (a lane's solve runs whether or not its factors are used: its pivots must be rows)
        lset(ip, IP.piv + i, l, piv[pt, i] if known else i)
    lset(f, F.have, l, float(have[pt]))
    lset(f, F.hist, l, float(hist[pt]))
    lset(f, F.live, l, float(live[pt]) if valid else 0.0)
    lset(f, F.tbrk, l, tbrk[pt])
    lset(f, F.itn, l, 0.0)
    lset(f, F.stp, l, 0.0)
    lset(f, F.jn, l, 0.0)
    lset(f, F.held, l, 1.0 if valid else 0.0)
    lset(f, F.retry, l, 0.0)
    lset(ip, IP.pt, l, pt)


@njit(**_OPTS)
def _scatter(st_, pt, l, d, s, nz, g):
    """Lane ``l``'s state back into point ``pt``."""
    w, S, f, F, ip, IP = g.w, g.S, g.f, g.F, g.ip, g.IP
    q, p, Lam, qc, pc, Y, mu = st_.q, st_.p, st_.Lam, st_.q_comp, st_.p_comp, st_.Y, st_.mu
    hist, live, tbrk, lu, piv, have = st_.have_history, st_.live, st_.breakdown_time, st_.lu, st_.piv, st_.have_lu
    itn, stp = st_.iterations, st_.steps
    jz, jq, jl = st_.jac_z, st_.jac_q, st_.jac_lam
    for m in range(d):
        put(jq, pt, m, lget(w, S.jq + m, l))
        put(jl, pt, m, lget(w, S.jl + m, l))
    for i in range(nz):
        put3(jz, pt, i // d, i % d, lget(w, S.jz + i, l))
    for m in range(d):
        put(q, pt, m, lget(w, S.q + m, l))
        put(p, pt, m, lget(w, S.p + m, l))
        put(Lam, pt, m, lget(w, S.lam + m, l))
        put(qc, pt, m, lget(w, S.qc + m, l))
        put(pc, pt, m, lget(w, S.pc + m, l))
        put(mu, pt, m, lget(w, S.mu + m, l))
    for i in range(s):
        for m in range(d):
            put3(Y, pt, i, m, lget(w, S.Y + i * d + m, l))
    for i in range(DEPTH * (s + 2)):
        for m in range(d):
            put3(st_.defects, pt, i, m, lget(w, S.D + i * d + m, l))
    pr_ = st_.orders
    O = ORDERS
    pr_[pt, O.depth] = int(lget(f, F.depth, l))
    pr_[pt, O.ordy] = int(lget(f, F.ordy, l))
    pr_[pt, O.ordl] = int(lget(f, F.ordl, l))
    pr_[pt, O.trust] = int(lget(f, F.trust, l))
    pr_[pt, O.age] = int(lget(f, F.age, l))
    for i in range(nz):
        for j in range(nz):
            put3(lu, pt, i, j, lget(w, S.lu + i * nz + j, l))
        piv[pt, i] = lget(ip, IP.piv + i, l)
    have[pt] = 1 if lget(f, F.have, l) != 0.0 else 0
    hist[pt] = 1 if lget(f, F.hist, l) != 0.0 else 0
    live[pt] = 1 if lget(f, F.live, l) != 0.0 else 0
    tbrk[pt] = lget(f, F.tbrk, l)
    itn[pt] += int(lget(f, F.itn, l))
    stp[pt] += int(lget(f, F.stp, l))


@njit(inline='always', **_OPTS)
def _next_live(live, order, nxt, hi):
    """The first position at or after ``nxt`` in ``order`` whose point is live (``hi`` when none)."""
    while nxt < hi and live[order[nxt]] == 0:
        nxt += 1
    return nxt


@njit(**_OPTS)
def _record(snap, every, first, l, d, g):
    """Lane ``l``'s point at the end of its step into ``snap`` (:func:`advance`'s outputs) when the step's
    number is an output's (a multiple of ``every`` before the call's last step)."""
    w, S, f, F, ip, IP = g.w, g.S, g.f, g.F, g.ip, g.IP
    n = first - 1 + int(lget(f, F.jn, l))
    if n % every != 0:
        return
    k = n // every - (first - 1) // every - 1
    sq, sp, sl, mark = snap
    if k < 0 or k >= mark.shape[0]:
        return
    pt = lget(ip, IP.pt, l)
    for m in range(d):
        put3(sq, k, pt, m, lget(w, S.q + m, l))
        put3(sp, k, pt, m, lget(w, S.p + m, l))
        put3(sl, k, pt, m, lget(w, S.lam + m, l))
    mark[k, pt] = 1


@njit(**_OPTS)
def _block(scratch, span, ev, inside, post, pair, steps, st_, sizes, out):
    """The live points among order[lo … hi − 1] through ``nsteps`` steps each, W (= len(proto))
    lanes at a time, with the thread's scratch arrays; returns the group steps taken, the Newton
    iterations they ran and the Jacobians they took (the columns :data:`ROUNDS`).

    Plain tuples, as :func:`advance`'s parallel loop makes them (it takes no named tuples):
    ``scratch`` = (WS, FS, IS, QR), the thread's value, flag and integer buffers and one lane's q for
    the domain test; ``span`` = (order, lo, hi); ``pair`` = (k, tab, plan, h, newton) as pointers and
    the plan's tuple (the :class:`Pair` record's fields); ``steps`` = (t0, first, nsteps) (:class:`Span`);
    ``st_`` the :class:`StateArrays`; ``sizes`` = (d, s, nz, proto, lay); ``out`` = (snap, every).

    **Lanes are refilled.**  Each lane holds one point and counts its steps (``F.jn``); after every
    step, a lane whose point has taken its ``nsteps`` steps or has broken down hands the point back
    (:func:`_scatter`) and takes up the next live point of the block (:func:`_gather`), which starts
    at its own first step: the lanes of one group may be at different steps, each step aiming at
    its own lane's time.  Points that are not live are never taken up (:func:`advance` leaves them
    out of the blocks), so dead points cost nothing and live ones are packed into full groups.  A
    lane with nothing left to take is empty (not live) until the last lane's point is done.  Nothing
    in a point's arithmetic reads another lane, so its bits are those it gets alone (W = 1 takes the
    points one after another).

    The scratch arrays are arguments (not locals) on purpose: the caller holds them for the whole
    call, while numba would free a local array after its last use as an array, i.e. while the raw
    pointers taken from it are still in use.
    """
    WS, FS, IS, QR = scratch
    order, lo, hi = span
    kp, tb, plan, h, cfg = pair
    t0, first, nsteps = steps
    d, s, nz, proto, lay = sizes
    snap, every = out
    # the records by name, made here (numba's parallel loop takes no named tuples)
    S, F, IP = _records(lay)
    st_ = StateArrays(*st_)
    P = Step(post, kp, h, tb, Plan(*plan), _newton_rule(cfg))
    W = len(proto)
    g = Group(lanes(WS, 0, proto), S, lanes(FS, 0, plain(proto)), F, lanes(IS, 0, plain(proto)), IP, _at(QR, 0))
    f, ip = g.f, g.ip
    live = st_.live
    nxt = _next_live(live, order, lo, hi)
    if nxt == hi or nsteps <= 0:
        return 0, 0, 0
    pad = order[nxt]                              # empty lanes hold this point's values, not live
    held = 0
    for l in range(W):
        if nxt < hi:
            _gather(st_, order[nxt], l, True, d, s, nz, g)
            nxt = _next_live(live, order, nxt + 1, hi)
            held += 1
        else:
            _gather(st_, pad, l, False, d, s, nz, g)
    rounds = 0
    last = float(nsteps)
    while held > 0:
        rounds += 1
        over = _step(t0 + (float(first) + ld(f, F.jn)) * h, float(first), ev, inside, P, d, s, nz, g)
        jn = ld(f, F.jn) + sel(over, 1.0, 0.0)
        st(f, F.jn, jn)
        if every > 0:                             # outputs inside the call: the points that took their step
            taken = mand(over, mand(ld(f, F.held) != 0.0, ld(f, F.live) != 0.0))
            if anyl(taken):
                for l in range(W):
                    if lmask(taken, l):
                        _record(snap, every, first, l, d, g)
        ends = mand(ld(f, F.held) != 0.0, mor(ld(f, F.live) == 0.0, jn >= last))
        if anyl(ends):                            # lanes whose point is done: hand it back, take the next
            for l in range(W):
                if lmask(ends, l):
                    _scatter(st_, lget(ip, IP.pt, l), l, d, s, nz, g)
                    if nxt < hi:
                        _gather(st_, order[nxt], l, True, d, s, nz, g)
                        nxt = _next_live(live, order, nxt + 1, hi)
                    else:
                        lset(f, F.held, l, 0.0)
                        lset(f, F.live, l, 0.0)
                        held -= 1
    return rounds, int(lget(f, F.gits, 0)), int(lget(f, F.gjac, 0))


@njit(**_OPTS)
def _aligned(raw, n):
    """The n elements of ``raw`` from its first 64-byte boundary on (``raw`` holds 16 more).  A lane
    value (W doubles) then never straddles two cache lines: numba aligns arrays to 32 bytes, and a
    scratch array at 32 modulo 64 made every lane load and store a split one.  Which of the two a run
    got was a matter of where its allocations fell, one way for the whole process: the same pair
    measured 0.21 or 0.27 µs a point-step (SRK3-symmetric at W = 16) from one process to the next
    (docs/benchmarks.md, "Aligned lanes")."""
    off = (64 - raw.ctypes.data % 64) % 64 // raw.itemsize
    return raw[off:off + n]


@njit(parallel=True, **_OPTS)
def advance(ev, inside, post, pair, span, st_, shape, outputs):
    """Advance every live point of the state tuple ``st_`` by ``span.nsteps`` steps, the step numbered
    ``span.first`` aiming at t0 + first·h (:class:`Span`), with the pair's data ``pair`` (:class:`Pair`),
    laid out as ``shape`` says (:class:`Shape`), writing ``outputs`` (:class:`Outputs`).  The live
    points, in their order, are taken ``block`` at a
    time (dead points are left out before blocks are made, so every block but the last is full),
    blocks spread over the threads, and W = len(proto) at a time within a block (``ev`` must be the
    W-lane point function); a point's steps never depend on its block, its lanes, its thread or its
    neighbours.  ``post``: the projection's post term, PAPER for :func:`project` (read only by
    projections solved after Ψ_h); a projection's own post term arrives as a type
    (:class:`~integrators.kernel.projection.PostTerm`, from the cached entry
    :func:`integrators.codegen.post_entry` generates) or, where its source cannot be read, as the
    compiled function itself (a kernel of its own in every process).

    ``st_``: the :class:`StateArrays` as a plain tuple; ``pair.newton``: the float64 array of a
    :class:`Newton` record (:class:`integrators.engine.Tolerances`); ``shape.lay``: :func:`layout` as
    three int64 arrays (Engine._layout); ``outputs.rounds`` (int64, a row per block): the steps, the
    Newton iterations and the Jacobians (evaluated and factorised, the projection's solve's
    included) each block's group of lanes ran (:func:`_block`), so point-steps / (W · Σ steps) is
    the share of lane steps that did work, and the points' iterations / (W · Σ iterations) that of
    lane iterations.

    ``outputs.snap`` = (q, p, Λ, mark), K outputs of every point, and ``every`` (0: none): after a point's
    step numbered a multiple of ``every`` (the k-th such step after ``first`` − 1, k < K), its q, p,
    Λ go to row k and mark[k, point] = 1; a point that is not live after that step is not recorded
    (:meth:`integrators.engine.Engine.advance_outputs` fills those from its frozen state).  A point
    keeps its lane for the whole call, so a run's outputs cost no trip of its Newton factors and
    predictor table through memory (docs/benchmarks.md, "What a call costs").
    """
    k, tab, plan, h, tolerances = pair.k, pair.tab, pair.plan, pair.h, pair.newton
    t0, first, nsteps = span.t0, span.first, span.nsteps
    proto, lay, block = shape.proto, shape.lay, shape.block
    rounds, snap, every = outputs.rounds, outputs.snap, outputs.every
    arrays = StateArrays(*st_)
    q, Y, lu = arrays.q, arrays.Y, arrays.lu
    n = q.shape[0]
    d = len(shape.dim)     # ``dim`` is a tuple of d zeros: d is a compile-time constant, one compilation
    #                        per dimension, and the compiler unrolls the loops over coordinates
    s = Y.shape[1]
    nz = lu.shape[1]
    W = len(proto)
    S, F, IP = _records(lay)
    nw, nf, ni = S.size * W, F.size * W, IP.size * W
    kp, tb = _at(k, 0), _at(tab, 0)
    R = ROUNDS
    live = arrays.live
    order = np.empty(n, np.int64)               # the live points, in order
    m = 0
    for i in range(n):
        if live[i] != 0:
            order[m] = i
            m += 1
    nblocks = (m + block - 1) // block
    for bi in prange(nblocks):
        WS = _aligned(np.zeros(nw * (q.ndim - 1) + 16, q.dtype), nw * (q.ndim - 1))   # (a double-double state,
        FS = _aligned(np.zeros(nf + 16), nf)                                            # (n, d, 2): two doubles
        IS = _aligned(np.zeros(ni + 16, np.int64), ni)                                  # a value)
        QR = np.zeros(d)
        rounds[bi, R.steps], rounds[bi, R.iterations], rounds[bi, R.jacobians] = _block(
            (WS, FS, IS, QR), (order, bi * block, min(m, (bi + 1) * block)), ev, inside, post,
            (kp, tb, plan, h, tolerances), (t0, first, nsteps), st_, (d, s, nz, proto, lay), (snap, every))


def advance_argument(sig, name):
    """The numba type of :func:`advance`'s argument ``name`` in its compiled signature ``sig`` (one of
    ``advance.signatures``), or of the field ``name`` of one of its records (``dim``, ``proto``: of
    :class:`Shape`): which specialisations exist, read by name."""
    import inspect
    params = list(inspect.signature(advance.py_func).parameters)
    if name in params:
        return sig[params.index(name)]
    for record, arg in ((Pair, "pair"), (Span, "span"), (Shape, "shape"), (Outputs, "outputs")):
        if name in record._fields:
            return sig[params.index(arg)][record._fields.index(name)]
    raise KeyError(f"advance has no argument or record field {name!r}")


@njit(**_OPTS)
def theta_dd_points(ev, k, q2, out, T, TT, dH, HH):
    """ϑ at each double-double point of q2 (n, d, 2) into out (n, d, 2), by the system's
    double-double point function (integrators.engine.theta_dd)."""
    n, d = q2.shape[0], q2.shape[1]
    P = (0.0,)
    for i in range(n):
        ev(lanes(q2, i * d, P), _at(k, 0), False, lanes(out, i * d, P), lanes(T, 0, P), lanes(TT, 0, P),
           lanes(dH, 0, P), lanes(HH, 0, P))


@njit(**_OPTS)
def scalars_dd_points(sc, k, q2, out):
    """H and the momentum at each double-double point of q2 (n, d, 2) into out (n, 2, 2), by the
    system's double-double ``scalars_dd`` (integrators.engine.scalars_dd)."""
    n, d = q2.shape[0], q2.shape[1]
    P = (0.0,)
    for i in range(n):
        sc(lanes(q2, i * d, P), _at(k, 0), lanes(out, i * 2, P))


@njit(**_OPTS)
def refactor(ev, pair, st_, shape):
    """Rebuild the Newton factors ``lu, piv`` of every point that has them (``have_lu``) from where
    they were taken (``jac_z``, ``jac_q``, ``jac_lam``): the step's equations' Jacobian at that
    iterate, factorised, as :func:`_newton` did (one lane: W = 1, ``ev`` the scalar point function;
    a lane's factors are the scalar path's bits).  What a state read from a checkpoint needs before
    it is advanced, so that the resumed run is bitwise the run it continues.  (One thread: once per
    resume, one Jacobian a point.)  ``pair``: :class:`Pair`; ``shape``: :class:`Shape` (its dim, proto
    and lay)."""
    arrays = StateArrays(*st_)
    n = arrays.q.shape[0]
    d = len(shape.dim)
    s = arrays.Y.shape[1]
    nz = arrays.lu.shape[1]
    proto = shape.proto
    S, F, IP = _records(shape.lay)
    kp = _at(pair.k, 0)
    pl = Plan(*pair.plan)
    P = Step(PAPER, kp, pair.h, _at(pair.tab, 0), pl, _newton_rule(pair.newton))
    have, lu, piv = arrays.have_lu, arrays.lu, arrays.piv
    WS = np.zeros(S.size * (arrays.q.ndim - 1), arrays.q.dtype)
    IS = np.zeros(IP.size, np.int64)
    w, ip = lanes(WS, 0, proto), lanes(IS, 0, plain(proto))
    for pt in range(n):
        if have[pt] == 0:
            continue
        for m in range(d):
            lset(w, S.q + m, 0, elem(arrays.jac_q, pt, m))
            lset(w, S.lam + m, 0, elem(arrays.jac_lam, pt, m))
        for i in range(nz):
            lset(w, S.z + i, 0, elem3(arrays.jac_z, pt, i // d, i % d))
        _prepare(ev, kp, pl, d, w, S)
        LU, pv = at(w, S.lu), at(ip, IP.piv)
        _main(at(w, S.z), True, at(w, S.r), LU, ev, P, d, s, w, S)
        lu_factor(LU, pv, nz)
        for i in range(nz):
            for j in range(nz):
                put3(lu, pt, i, j, lget(w, S.lu + i * nz + j, 0))
            piv[pt, i] = lget(ip, IP.piv + i, 0)


@njit(**_OPTS)
def _probe(WS, unknowns, ev, pair, point, jac, s, S):
    zz, r, J = unknowns
    q, p, lam = point
    d = q.shape[0]
    w = lanes(WS, 0, (0,))
    for m in range(d):
        st(w, S.q + m, q[m])
        st(w, S.p + m, p[m])
        st(w, S.lam + m, lam[m])
    P = Step(PAPER, _at(pair.k, 0), pair.h, _at(pair.tab, 0), Plan(*pair.plan), _newton_rule(pair.newton))
    _prepare(ev, P.k, P.plan, d, w, S)
    _main(_at(zz, 0), jac, _at(r, 0), _at(J, 0), ev, P, d, s, w, S)


def probe(ev, pair, point, z, jac, *, s):
    """The step's residual at z (and its Jacobian when ``jac``) for one point ``point`` = (q, p, Λ) of
    a pair with ``s`` stages and data ``pair`` (:class:`Pair`, Engine.pair()): the equations Newton
    solves, for tests (the Jacobian against complex-step differences of the residual)."""
    q = point[0]
    d = q.shape[0]
    nz = z.shape[0]
    S, F, _ = layout(s, d, nz)
    WS = np.zeros(S.size, z.dtype)
    r = np.zeros(nz, z.dtype)
    J = np.zeros(nz * nz, z.dtype)
    _probe(WS, (z.copy(), r, J), ev, pair, tuple(point), jac, s, S)
    return r, J.reshape((nz, nz))
