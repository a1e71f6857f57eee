"""Jumps in a map's image of a loop, and I₁ over the loop's continuous pieces (docs/audit.md, "Maps
with jumps").

The defect of :mod:`integrators.audit.maps` is taken point by point, so a map with a jump (a kick by
−h·sign(q), a linear-spline PIC force) reads ``symplectic`` wherever it is smooth, and the loop
integral over its broken image is not its invariant.  Here the image of the loop after one step is
looked at coordinate by coordinate: a gap between neighbouring points that stands out of its
neighbours' (:func:`candidates`) is a candidate; up to ``CANDIDATES`` of them (the most prominent)
are bisected ``BISECTIONS`` times in the loop's parameter,
the map evaluated at each midpoint.  A continuous map's gap falls with the interval (by 2⁻³⁰ after
30 halvings where it is Lipschitz); a gap that keeps more than ``KEEP`` = 2⁻¹⁵ of itself, and more
than round-off, is a jump.  Two jumps closer together than the loop's spacing can hide each other
(opposite jumps in one gap); the piecewise I₁ below then does not settle, and says so.  A kink (a jump in
the derivative only) is continuous and is not reported.

With the jumps located (to 2⁻³⁰ of the loop's step), :func:`piecewise_first_invariant` sums ∫ ϑ·dz
over the images of the pieces between them (Chebyshev points on each piece, doubled until the sum
settles), and over the same pieces of the loop itself, so that the two are compared with the same
quadrature: the one-step change of I₁ over the continuous pieces, as Barham & Burby's diagnostic
defines it for maps with jumps.  Where the map's generating function is continuous across the
jumps (a kick v → v − h·sign(x), the exact flow of |x|: Φ*(v dx) − v dx = d(−h|x|)) the pieces'
terms telescope and this change is at round-off, while the closed loop's I₁ is not an invariant;
a composition (kick, drift, kick) composes the drift's generating function with the jump and the
pieces' I₁ moves too.
"""
from __future__ import annotations

import math

import numpy as np

JUMP_RATIO = 4.0        # a candidate gap stands out of its coordinate's second differences by this squared
CANDIDATES = 16         # candidate gaps bisected, at most (the largest against their coordinate's steps)
BISECTIONS = 30         # halvings of a candidate's interval in the loop's parameter
KEEP = 2.0 ** -15       # a gap keeping more than this of itself over BISECTIONS halvings is a jump (Lipschitz: 2⁻³⁰)
COLUMNS = 512           # coordinates looked at at once (the gaps of a block are one block of the state)
PIECES_UP_TO = 64       # the piecewise I₁ is offered up to this many pieces
PIECE_POINTS = (33, 65, 129, 257, 513, 1025)   # Chebyshev points per piece, doubled until the sum settles
SETTLED = 1e-13         # ... to this fraction of |I₁|


def _unwrap(d, P):
    """Differences d (..., n) with the periodic coordinates' (P > 0) whole periods taken out."""
    if P is None:
        return d
    per = P > 0
    if per.any():
        d = d.copy()
        d[..., per] -= P[per] * np.round(d[..., per] / P[per])
    return d


def candidates(image, P, limit=CANDIDATES):
    """Candidate jumps of a loop's image (N, n) (rows at τ = i/N, cyclic): a list of (i, j, gap) for the
    gap between rows i and i + 1 in coordinate j, the ``limit`` most prominent, and how many candidates
    there were in all.

    A jump J in the gap d_i stands out of the gaps' second differences: a_i = d_i − (d_{i−1} + d_{i+1})/2
    is J there (and −J/2 beside it), against O(Δτ²) for a smooth image; a candidate is a local maximum
    of |a| that is ``JUMP_RATIO``² times its coordinate's median |a| (and above round-off)."""
    N, n = image.shape
    found = []                                   # (score, i, j, gap)
    total = 0
    for c0 in range(0, n, COLUMNS):
        block = image[:, c0:c0 + COLUMNS]
        d = _unwrap(np.roll(block, -1, axis=0) - block, None if P is None else P[c0:c0 + COLUMNS])
        a = np.abs(d - 0.5 * (np.roll(d, 1, axis=0) + np.roll(d, -1, axis=0)))
        noise = 1e3 * np.finfo(float).eps * (np.max(np.abs(block), axis=0) + np.max(np.abs(d), axis=0))
        typical = np.median(a, axis=0) + noise + np.finfo(float).tiny
        hit = (a >= np.roll(a, 1, axis=0)) & (a >= np.roll(a, -1, axis=0)) & (a > JUMP_RATIO ** 2 * typical)
        if not hit.any():
            continue
        i, j = np.nonzero(hit)
        total += i.size
        score = a[i, j] / typical[j]
        keep = np.argsort(score)[::-1][:limit]
        found += [(float(score[m]), int(i[m]), int(c0 + j[m]), float(abs(d[i[m], j[m]]))) for m in keep]
    found.sort(reverse=True)
    return [(i, j, g) for _, i, j, g in found[:limit]], total


def find_jumps(advance, at, image, P, limit=CANDIDATES):
    """The jumps of a map's image of a loop: ``advance(rows) -> rows`` the map at its step, ``at(τ)``
    the loop's rows at parameters τ (m,), ``image`` = advance(at(i/N)); ``P`` (n,) periods or None.

    Returns {"jumps": [{"tau", "coordinate", "size", "interval"}], "candidates": candidates found,
    "bisected": how many were bisected, "verdict": "jumps" | "continuous" | "cannot tell", "reason"}."""
    N = image.shape[0]
    cand, total = candidates(image, P, limit)
    out = {"jumps": [], "candidates": int(total), "bisected": len(cand), "verdict": "continuous", "reason": ""}
    if not cand:
        return out
    lo = np.array([i / N for i, _, _ in cand])
    hi = np.array([(i + 1) / N for i, _, _ in cand])
    cols = np.array([j for _, j, _ in cand])
    g0 = np.array([g for _, _, g in cand])
    a = image[[i for i, _, _ in cand]][np.arange(len(cand)), cols]
    b = image[[(i + 1) % N for i, _, _ in cand]][np.arange(len(cand)), cols]
    Pc = None if P is None else P[cols]

    def gap(u, w):
        d = w - u
        if Pc is not None:
            d = np.where(Pc > 0, d - Pc * np.round(d / np.where(Pc > 0, Pc, 1.0)), d)
        return np.abs(d)

    try:
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            with np.errstate(all="ignore"):
                zm = np.asarray(advance(at(mid)), dtype=float)[np.arange(len(cand)), cols]
            if not np.all(np.isfinite(zm)):
                out.update(verdict="cannot tell", reason="the map is not finite inside a candidate gap")
                return out
            left = gap(a, zm) >= gap(zm, b)
            hi, b = np.where(left, mid, hi), np.where(left, zm, b)
            lo, a = np.where(left, lo, mid), np.where(left, a, zm)
    except Exception as exc:            # the map raised on the bisection's rows: no verdict on jumps
        out.update(verdict="cannot tell", reason=f"the map raised while a gap was bisected ({type(exc).__name__}: {exc})")
        return out
    g = gap(a, b)
    jump = (g > KEEP * g0) & (g > 1e3 * np.finfo(float).eps * (np.abs(a) + np.abs(b)))
    merged = []                          # one jump seen in several coordinates is one jump (the largest kept)
    for m in sorted(np.flatnonzero(jump), key=lambda m: lo[m]):
        here = {"tau": float(0.5 * (lo[m] + hi[m])), "coordinate": int(cols[m]), "size": float(g[m]),
                "interval": [float(lo[m]), float(hi[m])], "coordinates": [int(cols[m])]}
        last = merged[-1] if merged else None
        if last is not None and lo[m] <= last["interval"][1] + 4 * (hi[m] - lo[m]):
            last["coordinates"].append(int(cols[m]))
            last["interval"] = [min(last["interval"][0], float(lo[m])), max(last["interval"][1], float(hi[m]))]
            if g[m] > last["size"]:
                last.update(tau=here["tau"], coordinate=here["coordinate"], size=here["size"])
        else:
            merged.append(here)
    out["jumps"] = merged
    if out["jumps"]:
        big = max(out["jumps"], key=lambda r: r["size"])
        out["verdict"] = "jumps"
        out["reason"] = (f"the loop's image jumps at {len(out['jumps'])} place{'s' if len(out['jumps']) != 1 else ''} ({int(jump.sum())} of {len(cand)} candidate "
                         f"gaps bisected {BISECTIONS} times keep more than 2⁻¹⁵ of themselves; {total} candidates in "
                         f"all); the largest, {big['size']:.3g} in coordinate {big['coordinate']} at τ = {big['tau']:.9f}")
    return out


def piecewise_first_invariant(advance, at, jumps, one_form, P, scale):
    """I₁ = Σ ∫ ϑ·dz over the continuous pieces of the loop between its image's jumps, after the map
    and before it, by the same Chebyshev quadrature on each piece: {"before", "after", "change"
    (|after − before|/|before|), "pieces", "points", "settled"}, or None where there are more than
    ``PIECES_UP_TO`` pieces.  ``jumps``: :func:`find_jumps`' list (all of the image's jumps: a piece
    hiding another one does not settle, and says so); ``one_form(rows) -> (m, n)``; ``scale`` the
    loop's |I₁| (what "settled" is relative to)."""
    from invariants.spectral import chebyshev_derivative, chebyshev_points, clenshaw_curtis_weights
    if not jumps or len(jumps) > PIECES_UP_TO:
        return None
    cuts = sorted((j["interval"] for j in jumps), key=lambda iv: iv[0])
    starts = [iv[1] for iv in cuts]
    ends = [iv[0] for iv in cuts[1:]] + [cuts[0][0] + 1.0]

    def arc(rows):
        z = np.asarray(rows, dtype=float)
        z = z[0] + np.cumsum(np.concatenate([np.zeros((1, z.shape[1])), _unwrap(np.diff(z, axis=0), P)]), axis=0)
        dz = chebyshev_derivative(z, 0)
        return float(clenshaw_curtis_weights(z.shape[0]) @ np.sum(np.asarray(one_form(z)) * dz, axis=1))

    def total(m, mapped):
        s = 0.0
        for t0, t1 in zip(starts, ends):
            tau = t0 + (t1 - t0) * chebyshev_points(m)
            rows = at(tau)                     # the loop is 1-periodic in τ
            s += arc(advance(rows) if mapped else rows)
        return s

    prev, settled, m = None, False, PIECE_POINTS[0]
    with np.errstate(all="ignore"):
        for m in PIECE_POINTS:
            now = (total(m, False), total(m, True))
            if prev is not None and max(abs(now[0] - prev[0]), abs(now[1] - prev[1])) <= SETTLED * scale:
                settled = True
                break
            prev = now
    before, after = now
    return {"before": before, "after": after, "change": abs(after - before) / abs(before) if before else math.nan,
            "pieces": len(starts), "points": m, "settled": settled}
