"""The one-step Ω̄ defect below double's floor: a built-in pair stepped by the double-double engine.

Double's audit (:mod:`integrators.audit.defect`) reads a defect down to about 1e-13 (complex step):
where a pair's defect falls below that as h shrinks, its order cannot be fitted.  Here the same
noncanonical defect

    max |Aᵀ Ω̄(q') A − Ω̄(q)| / max (|A|ᵀ |Ω̄(q')| |A| + |Ω̄(q)|),   A = ∂q'/∂q along p = ϑ(q)

is taken with every ingredient far below double: the step Φ_h by the compiled engine in
double-double (``Engine(..., precision="double-double")``, all perturbed points of all sample
points advanced together in lanes); A by 8th-order central differences with relative step 2⁻¹²
on double-double inputs (truncation ~δ⁸ ≈ 1e-29, noise ~2⁻¹⁰⁴/δ ≈ 2e-28); ϑ_q and Ω̄ from the
system's sympy expressions in mpmath at 40 digits, with the parameters' doubles taken exactly;
the pull-back in mpmath.  Each study measures its own floor (:func:`defect_study_dd`: the same
defects with a four times smaller step); :data:`DEFECT_FLOOR_DD` is the least it may be
(scripts/studies/audit_defect_dd.py --floor).  Only built-in pairs (the engine's); a user's step map runs in
double.
"""
from __future__ import annotations

import numpy as np

from .defect import fit_order

# the 8th-order central difference weights as exact fractions (the doubles of 4/5 … would set a
# floor of ~1e-17 on the Jacobian)
FD_ORDER8_EXACT = ((1, (4, 5)), (2, (-1, 5)), (3, (4, 105)), (4, (-1, 280)))

FD_STEP_DD = 2.0 ** -12     # relative step of the double-double central differences
DEFECT_FLOOR_DD = 1e-27     # the least floor of a study: ~50× the charged particle's measured one (docs/audit.md)
DPS = 40                    # mpmath digits of the pull-back


def _omega_mp(system):
    """q (mpf list) ↦ (Ω̄ (d × d mpmath matrix), ϑ_q) from the system's expressions, its parameters'
    doubles taken exactly."""
    import mpmath
    import sympy
    exact = {k: sympy.Rational(float(v)) for k, v in system.params.items()}
    T = sympy.lambdify(system.q, [[e.subs(exact) for e in row] for row in system.dtheta_expr], "mpmath")
    d = system.d

    def omega(q):
        t = T(*q)                        # t[k][i] = ∂ϑ_k/∂q^i
        Tm = mpmath.matrix(d, d)
        Om = mpmath.matrix(d, d)
        for i in range(d):
            for j in range(d):
                Tm[i, j] = t[i][j]
                Om[i, j] = t[j][i] - t[i][j]      # Ω̄_ij = ∂_iϑ_j − ∂_jϑ_i
        return Om, Tm
    return omega


def _mp(x2):
    """mpmath values of a double-double array (..., 2)."""
    import mpmath
    flat = x2.reshape(-1, 2)
    return [mpmath.mpf(float(a)) + mpmath.mpf(float(b)) for a, b in flat]


def _split(values, shape):
    from ..ddouble import split
    return np.array([split(v) for v in values]).reshape(shape + (2,))


def defects_dd(system, tableau, projection, q, h):
    """The relative one-step Ω̄ defect of the pair at points q (m, d) with step h, its largest over
    the points (a float), computed as the module says."""
    import mpmath
    from ..ddouble import divide_array
    from ..engine import Engine, State, theta_dd
    m, d = q.shape
    n = 3 * d
    eng = Engine(system, tableau, projection, h, precision="double-double")
    q2 = np.ascontiguousarray(np.stack([q, np.zeros_like(q)], axis=-1))
    p2 = theta_dd(system, q2)
    st = eng.state(q2, p2)
    eng.advance(st, 1, 1)                                  # λ_n: what the map returns from (q, ϑ(q), 0)
    lam2 = divide_array(np.ascontiguousarray(st.Lam), float(h))
    lam2[~np.isfinite(lam2)] = 0.0
    with mpmath.workdps(DPS):
        x0 = [_mp(q2[i]) + _mp(p2[i]) + _mp(lam2[i]) for i in range(m)]
        e = int(round(np.log2(FD_STEP_DD)))
        deltas = [[mpmath.ldexp(1, int(mpmath.floor(mpmath.log(max(abs(v), 1), 2))) + e) for v in x] for x in x0]
        inputs = []
        for i in range(m):
            inputs.append(x0[i])
            for k, _ in FD_ORDER8_EXACT:
                for sgn in (1, -1):
                    for j in range(n):
                        x = list(x0[i])
                        x[j] = x[j] + sgn * k * deltas[i][j]
                        inputs.append(x)
        X = _split([v for x in inputs for v in x], (len(inputs), n))
        S = State.double_double(np.ascontiguousarray(X[:, :d]), np.ascontiguousarray(X[:, d:2 * d]),
                                np.ascontiguousarray(X[:, 2 * d:]), h, tableau.s)
        eng.advance(S, 1, 1)
        if not S.live.all():
            return float("nan")
        out_q = S.q
        omega = _omega_mp(system)
        worst = mpmath.mpf(0)
        per = 1 + 2 * len(FD_ORDER8_EXACT) * n
        for i in range(m):
            base = i * per
            Fq = [_mp(out_q[base + r]) for r in range(per)]
            # A = ∂q'/∂q + ∂q'/∂p ϑ_q: columns j < d (q) and d ≤ j < 2d (p) of the Jacobian of q'
            D = mpmath.matrix(d, 2 * d)
            r = 1
            for k, (num, den) in FD_ORDER8_EXACT:
                w = mpmath.mpf(num) / den
                for sgn in (1, -1):
                    for j in range(n):
                        if j < 2 * d:
                            for a in range(d):
                                D[a, j] += sgn * w * Fq[r][a] / deltas[i][j]
                        r += 1
            Om0, T0 = omega(x0[i][:d])
            Om1, _ = omega(Fq[0])
            A = mpmath.matrix(d, d)
            for a in range(d):
                for b in range(d):
                    A[a, b] = D[a, b] + mpmath.fsum(D[a, d + c] * T0[c, b] for c in range(d))
            pull = A.T * Om1 * A - Om0
            absA = mpmath.matrix([[abs(A[a, b]) for b in range(d)] for a in range(d)])
            absO = mpmath.matrix([[abs(Om1[a, b]) for b in range(d)] for a in range(d)])
            size = absA.T * absO * absA
            top = max(abs(pull[a, b]) for a in range(d) for b in range(d))
            bottom = max(size[a, b] + abs(Om0[a, b]) for a in range(d) for b in range(d))
            worst = max(worst, top / bottom)
        return float(worst)


def defect_study_dd(system, tableau, projection, q, h, levels=5):
    """The Ω̄ defect for h·2^-k, k < levels, in double-double: {'h', 'defect', 'floor', 'order'}.

    Each defect is taken twice, with central-difference steps δ = FD_STEP_DD and δ/4: their largest
    disagreement (or DEFECT_FLOOR_DD, whichever is larger) is the study's ``floor`` — the
    differences' truncation error grows with the map's ninth derivatives, which differ between
    systems (point vortices 0.2 apart: ~5e-24; the charged particle: ~2e-29).  The order is fitted
    over the defects above 10 × floor (None with fewer than three)."""
    global FD_STEP_DD
    hs = [h * 2.0 ** -k for k in range(levels)]
    vals, other = [], []
    step = FD_STEP_DD
    try:
        for hk in hs:
            vals.append(defects_dd(system, tableau, projection, q, hk))
            FD_STEP_DD = step / 4
            other.append(defects_dd(system, tableau, projection, q, hk))
            FD_STEP_DD = step
    finally:
        FD_STEP_DD = step
    floor = max([DEFECT_FLOOR_DD] + [abs(a - b) for a, b in zip(vals, other) if np.isfinite(a - b)])
    return {"h": hs, "defect": vals, "floor": floor, "order": fit_order(hs, vals, floor)}
