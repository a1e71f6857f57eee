"""First and second Poincaré integral invariants (sec:app_integral_invariants).

Sign conventions (docs/conventions.md):

* Ω̄_ij = ∂_iϑ_j − ∂_jϑ_i, so dϑ = ½ Ω̄_ij dq^i ∧ dq^j.
* I₁[γ] = ∮ α(q) (dq/dτ) dτ with τ ∈ [0, 1) in the loop's sample order.  For the canonical form
  that is ∮ p·dq itself, not (1/2π)∮ p·dq as codes that report actions do: a loop of action J
  gives I₁ = 2πJ.
* Periodic coordinates (``period=``): q^i and q^i + P_i are the same point.  A set's samples may be
  wrapped (into [0, P) or anywhere); the differences between neighbours are unwrapped (each taken
  into (−P/2, P/2]) before the spectral derivative, and a loop that winds m times around the
  coordinate contributes m·P·mean(α_i) exactly.
* I₂[S] = ∫∫ Ω_ab x_σ^a x_τ^b dσ dτ for the two-form ½Ω_ab dx^a ∧ dx^b, σ the first
  and τ the second array axis; by Stokes I₂[S] = I₁[∂S] with ∂S traversed
  counter-clockwise in the (σ, τ) square (σ = 1 side run with τ increasing).

Forms (λ in the units of the paper; the corrected forms need h):

========== ===================================== ==============================================
form        one-form                               two-form
========== ===================================== ==============================================
noncanonical ϑ_i(q) dq^i                            ½ Ω̄_ij dq^i ∧ dq^j
canonical    p_i dq^i                               dp_i ∧ dq^i
corrected    ϑ_λ = (ϑ_i − hλ^kϑ_{k,i})(dq^i − h dλ^i)  dϑ_λ on (q, λ): see :func:`corrected_omega`
             (eq:symplectic_projection_one_form)
========== ===================================== ==============================================
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from integrators.simd import _at

from . import spectral

FORMS = ("canonical", "noncanonical", "corrected")
EPS = np.finfo(np.float64).eps
UNDER_RESOLVED = 1e-10   # documented threshold of the resolution monitor


@dataclasses.dataclass(frozen=True)
class InvariantValue:
    """An invariant with its resolution monitor.

    value : float
    resolution : the larger of two relative readings, each 0 for a set resolved to round-off:
        the value's own error estimate over |value| (``error``/|value|), and the relative size of
        the highest modes of the sampled set, as before (of q; of q and p, canonical; of (q, hλ)
        together, corrected: hλ enters ϑ_λ as a displacement of q)
    under_resolved : resolution > UNDER_RESOLVED (1e-10)
    error : the estimate, erring large, of |value − exact| from the spectra of what the value is
        made of (docs/invariants.md, "The resolution monitor"): on a loop the aliasing of the
        one-form's coefficients against q's modes (spectral.loop_pairing_error), on a surface the
        Clenshaw–Curtis error of the integrand (spectral.surface_quadrature_error); plus the
        round-off below
    roundoff : the value's round-off relative to |value|: 8 ulps of the size of the terms summed,
        which can be 10⁴ times the value where they cancel (a loop stretched by shear).  A floor of
        the value's precision that more points do not lower, so not part of ``resolution``
    reason : why a set is under-resolved where its spectrum cannot say (a coordinate that jumps by
        more than half its extent between neighbours: a wrapped angle given no ``period``); "" else
    """

    value: float
    resolution: float
    under_resolved: bool
    error: float = 0.0
    roundoff: float = 0.0
    reason: str = ""

    def __float__(self):
        return self.value


def _value(value, error, roundoff, tail, reason=""):
    """The InvariantValue of a value with its error estimate, its round-off and its set's relative tail
    (a ``reason`` makes it under-resolved whatever the spectra say: resolution 1)."""
    value = float(value)
    res = max(spectral.relative(error, value), tail, 1.0 if reason else 0.0)
    return InvariantValue(value, float(res), bool(res > UNDER_RESOLVED), float(error + roundoff),
                          float(spectral.relative(roundoff, value)), reason)


def _periods(period, d):
    """``period`` as (d,) floats, 0 where a coordinate is not periodic; None when none is."""
    if period is None:
        return None
    if np.ndim(period) > 1:
        raise ValueError(f"period must be a number or a 1-D list of one entry per coordinate ({d}), got an array of "
                         f"shape {np.shape(period)}")
    scalar = np.ndim(period) == 0
    entries = [period] if scalar else list(period)
    if not scalar and len(entries) != d:
        raise ValueError(f"period must be a number or one entry per coordinate ({d}), got {len(entries)} entries")
    P = np.zeros(len(entries))
    for i, x in enumerate(entries):
        x = 0.0 if x is None else x
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)) \
                or not np.isfinite(x) or x < 0:
            raise ValueError(f"period {'' if scalar else f'of coordinate {i} '}must be a positive number, or None or 0 "
                             f"where the coordinate is not periodic, got {x!r}")
        P[i] = float(x)
    if not P.any():
        return None
    return np.full(d, P[0]) if scalar else P


def _unwrap(q, P, axis):
    """q with each periodic coordinate's differences along ``axis`` taken into [−P/2, P/2)
    (the first sample stays where it is)."""
    out = q.copy()
    j = np.flatnonzero(P)
    x = np.take(q[..., j], np.arange(q.shape[axis]), axis=axis)
    dx = np.diff(x, axis=axis)
    Pj = P[j]
    dx = dx - Pj * np.floor(dx / Pj + 0.5)
    first = np.take(x, [0], axis=axis)
    out[..., j] = np.concatenate([first, first + np.cumsum(dx, axis=axis)], axis=axis)
    return out


def _jumps(q, P, axes, closed):
    """The reason a set whose coordinates jump by more than half their extent between neighbours
    (along ``axes``; a loop ``closed``: its last point is the first's neighbour) cannot be
    trusted, or "".  Periodic coordinates (P > 0) are unwrapped already and are left out."""
    extent = np.max(q, axis=tuple(range(q.ndim - 1))) - np.min(q, axis=tuple(range(q.ndim - 1)))
    for axis in axes:
        x = np.concatenate([q, np.take(q, [0], axis=axis)], axis=axis) if closed else q
        big = np.max(np.abs(np.diff(x, axis=axis)), axis=tuple(a for a in range(q.ndim - 1)))
        bad = np.flatnonzero((big > 0.5 * extent) & (extent > 0) & (P == 0 if P is not None else True))
        if bad.size:
            i = int(bad[0])
            return (f"coordinate {i} jumps by {big[i]:.3g} between neighbouring samples, more than half its extent "
                    f"{extent[i]:.3g}: a wrapped angle? give its period (period=…)")
    return ""


def _period_steps(diffs, P):
    """The reason a set's unwrapped samples cannot be trusted with the periods P, or "": a periodic
    coordinate that steps by a quarter period or more between neighbours (``diffs``: the
    differences between neighbours, one array per direction of the set), where a step cannot be
    told from a wrap (a period far smaller than the set, or a set far too coarse)."""
    for dx in diffs:
        step = np.max(np.abs(dx), axis=tuple(range(dx.ndim - 1)))
        bad = np.flatnonzero((P > 0) & (step >= P / 4))
        if bad.size:
            i = int(bad[0])
            return (f"coordinate {i} steps by {step[i]:.3g} between neighbouring samples, a quarter of its period "
                    f"{P[i]:.3g} or more: a wrap cannot be told from a step (is the period right?)")
    return ""


def _check_periodic(A_of, q, P, what):
    """Refuse a one-form (or two-form) that is not periodic where the coordinates are: its values
    at q and at q shifted by every period at once must agree to round-off."""
    A0, A1 = A_of(q), A_of(q + P)
    scale = np.max(np.abs(A0)) if A0.size else 0.0
    diff = np.max(np.abs(A1 - A0)) if A0.size else 0.0
    if diff > 1e-10 * max(scale, 1e-300):
        i = [int(x) for x in np.flatnonzero(P)]
        raise ValueError(f"the {what} is not periodic in coordinate{'s' if len(i) > 1 else ''} "
                         f"{', '.join(map(str, i))} (period {', '.join(f'{P[k]:g}' for k in i)}): its values change "
                         f"by {diff:.3g} (relative {diff / max(scale, 1e-300):.2g}) under a shift by the period")


MIN_POINTS = 8           # the fewest points along a direction of a sample set
SUBSET_BELOW = 1e-3 * UNDER_RESOLVED    # a loop's spectral estimate below this (relative) needs no subset


def _check(q, ndim, what):
    q = np.asarray(q, dtype=float)
    if q.ndim != ndim:
        raise ValueError(f"{what} must have {ndim} dimensions, got shape {q.shape}")
    layout = "(N, d): N points of d coordinates" if ndim == 2 else "(n_sigma, n_tau, d)"
    few = [n for n in q.shape[:-1] if n < MIN_POINTS]
    if few:
        hint = (f"; given transposed? the layout is {layout}" if q.shape[-1] >= MIN_POINTS else
                f" (the layout is {layout})")
        raise ValueError(f"{what} has shape {q.shape}: at least {MIN_POINTS} points along each direction are needed "
                         f"for a spectral value, got {min(few)}{hint}")
    if not np.isfinite(q).all():
        raise ValueError(f"{what} contains non-finite values")
    return q


def _need(x, name, form):
    if x is None:
        raise ValueError(f"form '{form}' needs {name}")
    return x


def _user_values(form, q, shape, what):
    """A user form's values at the samples, checked: finite, of the expected shape."""
    try:
        A = np.asarray(form(q), dtype=float)
    except Exception as exc:
        raise ValueError(f"the {what} {getattr(form, '__name__', form)!r} failed: {type(exc).__name__}: {exc}") \
            from None
    if A.shape != shape:
        raise ValueError(f"the {what} must return shape {shape} for points {q.shape}, got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError(f"the {what} returned non-finite values")
    return A


def one_form_coefficients(q, form, system=None, p=None, lam=None, h=None):
    """Coefficients (A_q, A_λ) of the one-form at the samples; A_λ is None unless corrected.
    ``form`` may be a callable ϑ(q): (..., d) -> (..., d), a one-form of the user's."""
    if callable(form):
        return _user_values(form, q, q.shape, "one-form"), None
    if form == "canonical":
        return _check(_need(p, "p", form), q.ndim, "p"), None
    if form not in FORMS:
        raise ValueError(f"unknown form '{form}'; choose one of {', '.join(FORMS)}")
    th = _need(system, "system", form).theta(q)
    if form == "noncanonical":
        return th, None
    lam = _check(_need(lam, "lam", form), q.ndim, "lam")
    h = float(_need(h, "h", form))
    # w_i = ϑ_i − h λ^k ϑ_{k,i}
    T = system.dtheta(q)
    w = th - h * np.sum(T * lam[..., :, None], axis=-2)
    return w, -h * w


def first_invariant(q, form="noncanonical", system=None, p=None, lam=None, h=None, period=None) -> InvariantValue:
    """I₁ = ∮ A(q) dq/dτ dτ over a loop q (N, d) sampled at τ_j = j/N: the trapezoidal rule of A·(spectral
    dq/dτ), evaluated in Fourier space by Parseval (spectral.loop_pairing).  Canonical: ∮ p·dq (not
    divided by 2π).

    form : 'noncanonical' (needs system), 'canonical' (needs p), 'corrected' (needs system, lam, h),
        or a callable ϑ(q) -> (N, d): the coefficients of a one-form of your own
    period : periodic coordinates: a number (every coordinate) or one entry per coordinate (None or 0
        where not periodic).  The loop's samples may be wrapped; neighbours' differences are unwrapped
        and a loop winding m times around coordinate i adds m·P_i·mean(A_i).  A one-form that is not
        periodic there is refused.  Without a period, a coordinate that jumps by more than half its
        extent between neighbours makes the value under-resolved, with ``reason`` saying so.
    """
    return first_invariants(q, [form], system, p, lam, h, period)[form]


def _winding(q, P):
    """(r, ramp): a loop's samples with periodic coordinates unwrapped, less the linear part m·P·τ of
    a coordinate that winds m times (r is periodic in τ), and the (d,) m·P."""
    n = q.shape[0]
    qu = _unwrap(q, P, 0)
    close = q[0] - qu[-1]
    close = np.where(P > 0, close - P * np.floor(close / np.where(P > 0, P, 1.0) + 0.5), 0.0)
    total = qu[-1] + close - qu[0]
    m = np.where(P > 0, np.round(total / np.where(P > 0, P, 1.0)), 0.0)
    ramp = m * P
    tau = np.arange(n) / n
    return qu - tau[:, None] * ramp, ramp


def first_invariants(q, forms, system=None, p=None, lam=None, h=None, period=None) -> dict:
    """{form: I₁} for several forms of one loop, sharing q's Fourier coefficients and resolution
    monitor; each value is bitwise what it is alone.  ``period``: as :func:`first_invariant`."""
    q = _check(q, 2, "loop q")
    P = _periods(period, q.shape[1])
    r, ramp = (q, None) if P is None else _winding(q, P)
    qh = spectral.fourier_coefficients(r)
    aq = np.abs(qh)                    # shared by the monitor's readings
    reason = None
    half = q.shape[0] % 2 == 0 and q.shape[0] // 2 >= MIN_POINTS    # the every-other-point subset
    qh2 = None
    out = {}
    for form in forms:
        A, Al = one_form_coefficients(q, form, system, p, lam, h)
        if P is not None and form != "canonical":
            _check_periodic(lambda x: one_form_coefficients(x, form, system, p, lam, h)[0], q, P, "one-form")
        ah = spectral.fourier_coefficients(A)
        aa = np.abs(ah)
        value = spectral.loop_pairing(A, r, bh=qh, ah=ah)        # in Fourier space (Parseval)
        error, roundoff, tail_a, tail_q = spectral.loop_pairing_error(ah, qh, q.shape[0], absolute=(aa, aq), tails=True)
        if reason is None:
            # a jump of a wrapped coordinate is a discontinuity, whose spectrum already flags the set:
            # the reason is sought only then (a third of the call's time at D = 2 otherwise); a
            # period the samples cannot tell from a step flags the set whatever its spectrum
            reason = (_period_steps([np.diff(r, axis=0, append=r[:1]) + ramp / q.shape[0]], P)
                      if P is not None else "")
            reason = reason or (_jumps(r, P, (0,), closed=True) if tail_q > UNDER_RESOLVED else "")
        if ramp is not None and ramp.any():                    # the winding: ∮ A_i m P_i dτ, A's mean
            wind = np.abs(ramp) * np.max(np.abs(A), axis=0)
            value += np.sum(ramp * np.mean(A, axis=0))
            error += tail_a * np.sum(wind)
            roundoff += 8 * EPS * np.sum(wind)
        check = half and error > SUBSET_BELOW * abs(float(value))     # the subset's value, where it can matter
        if check:
            qh2 = spectral.fourier_coefficients(r[::2]) if qh2 is None else qh2
            value2 = spectral.loop_pairing(A[::2], r[::2], bh=qh2)
            if ramp is not None and ramp.any():
                value2 += np.sum(ramp * np.mean(A[::2], axis=0))
        res = tail_q
        if Al is not None:
            alh, lh = spectral.fourier_coefficients(Al), spectral.fourier_coefficients(lam)
            value += spectral.loop_pairing(Al, lam, bh=lh, ah=alh)
            e2, r2 = spectral.loop_pairing_error(alh, lh, q.shape[0])
            error, roundoff = error + e2, roundoff + r2
            if check:
                value2 += spectral.loop_pairing(Al[::2], lam[::2])
            res = spectral.loop_tail(np.concatenate([r, h * lam], axis=-1))   # hλ has the units of q
        if check:             # two estimates that err large: the smaller is the sharper, and still errs large
            error = min(error, abs(float(value) - float(value2)))
        if form == "canonical":
            res = max(res, tail_a)
        out[form] = _value(value, error, roundoff, res, reason)
    return out


def corrected_omega(system, q, lam, h, paper_sign=False):
    """Ω_λ of dϑ_λ on (q, λ) at the points: (..., 2d, 2d).

    With w_i = ϑ_i − hλ^kϑ_{k,i} and ϑ_λ = w_i dq^i − h w_i dλ^i, the exterior derivative is

        Ω_λ = [[ Ω̄,            +h² λ·ϑ_qq ],
               [ −h² λ·ϑ_qq,   −h² Ω̄     ]],   (λ·ϑ_qq)_ij = λ^k ϑ_{k,ij}.

    eq:symplectic_projection_two_form prints the mixed blocks with the opposite sign;
    ``paper_sign=True`` evaluates that printed version (for the Stokes comparison in
    the tests and docs only).
    """
    T = system.dtheta(q)
    Om = np.swapaxes(T, -1, -2) - T
    Lq = np.sum(system.ddtheta(q) * lam[..., :, None, None], axis=-3)
    sgn = -1.0 if paper_sign else 1.0
    top = np.concatenate([Om, sgn * h * h * Lq], axis=-1)
    bottom = np.concatenate([-sgn * h * h * Lq, -h * h * Om], axis=-1)
    return np.concatenate([top, bottom], axis=-2)


@njit(cache=True, error_model="numpy")
def _omega_integrands(ev, k, q, lam, qs, qt, ls, lt, h2, sgn, corrected, nc, co, th, T, TT, dH, HH):
    """Per point, by the system's compiled point function: nc = q_σ·Ω̄·q_τ and, with ``corrected``,
    co = x_σ·Ω_λ·x_τ with Ω_λ the block matrix of :func:`corrected_omega` written out,
    q_σ·Ω̄·q_τ + sgn h² (q_σ·L·λ_τ − λ_σ·L·q_τ) − h² λ_σ·Ω̄·λ_τ, L_ij = λ^k ϑ_{k,ij}."""
    n, d = q.shape
    for i in range(n):
        ev(_at(q, i * d), _at(k, 0), corrected, _at(th, 0), _at(T, 0), _at(TT, 0), _at(dH, 0), _at(HH, 0))
        a = 0.0
        for m in range(d):
            for l in range(d):
                a += qs[i, m] * (T[l * d + m] - T[m * d + l]) * qt[i, l]
        nc[i] = a
        if corrected:
            b, c = 0.0, 0.0
            for m in range(d):
                for l in range(d):
                    L = 0.0
                    for j in range(d):
                        L += lam[i, j] * TT[(j * d + m) * d + l]
                    b += qs[i, m] * L * lt[i, l] - ls[i, m] * L * qt[i, l]
                    c += ls[i, m] * (T[l * d + m] - T[m * d + l]) * lt[i, l]
            co[i] = a + sgn * h2 * b - h2 * c


def _compiled_integrands(system, q, lam, qs, qt, ls, lt, h, paper_sign, corrected):
    """(noncanonical, corrected or None) integrands on the surface's points, or None where the
    system has no generated point functions (a duck-typed system: the numpy route is used)."""
    if not hasattr(system, "theta_expr"):
        return None
    from integrators.codegen import point_functions
    ev, _ = point_functions(system)
    d = q.shape[-1]
    flat = lambda x: np.ascontiguousarray(x.reshape(-1, d), dtype=float)
    n = q.shape[0] * q.shape[1]
    zero = np.zeros((n, d))
    nc, co = np.empty(n), np.empty(n)
    k = system.param_vector()
    _omega_integrands(ev, k, flat(q), flat(lam) if corrected else zero, flat(qs), flat(qt),
                      flat(ls) if corrected else zero, flat(lt) if corrected else zero, float(h or 0.0) ** 2,
                      -1.0 if paper_sign else 1.0, corrected, nc, co, np.empty(d), np.empty(d * d),
                      np.empty(d * d * d), np.empty(d), np.empty(d * d))
    shape = q.shape[:2]
    return nc.reshape(shape), (co.reshape(shape) if corrected else None)


def second_invariant(q, form="noncanonical", system=None, p=None, lam=None, h=None,
                     paper_sign=False, period=None) -> InvariantValue:
    """I₂ = ∫∫ Ω_ab x_σ^a x_τ^b dσ dτ over a surface q (n_σ, n_τ, d) at Chebyshev points.

    form : 'noncanonical' (Ω̄(q), needs system), 'canonical' (∫∫ p_σ·q_τ − p_τ·q_σ, needs p),
    'corrected' (dϑ_λ on (q, λ), needs system, lam, h), or a callable Ω(q) -> (n_σ, n_τ, d, d):
    the matrix of a two-form ½Ω_ab dq^a ∧ dq^b of your own.
    period : periodic coordinates, as for :func:`first_invariant`: the samples may be wrapped; the
        differences between neighbours along σ and τ are unwrapped before the derivatives, and a
        two-form that is not periodic there is refused.
    """
    return second_invariants(q, [form], system, p, lam, h, paper_sign, period)[form]


def second_invariants(q, forms, system=None, p=None, lam=None, h=None, paper_sign=False, period=None) -> dict:
    """{form: I₂} for several forms of one surface, sharing what they share: the transforms and
    derivatives of q, and ϑ_q, ϑ_qq from one compiled pass over the points for noncanonical and
    corrected together.  Each form's value is bitwise what it is alone (tests/test_invariants.py)."""
    q = _check(q, 3, "surface q")
    d = q.shape[-1]
    for form in forms:
        if not callable(form) and form not in FORMS:
            raise ValueError(f"unknown form '{form}'; choose one of {', '.join(FORMS)}")
    named = [f for f in forms if not callable(f)]
    P = _periods(period, d)
    qu = q if P is None else _unwrap(_unwrap(q, P, 1), P, 0)    # along τ, then σ: the patch in one sheet
    if P is not None:
        for form in forms:
            if callable(form):
                _check_periodic(lambda x: _user_values(form, x, x.shape + (d,), "two-form"), q, P, "two-form")
            elif form != "canonical":
                _check_periodic(_need(system, "system", form).Omega, q, P, "two-form Ω̄ of the system")
    cq0 = spectral.chebyshev_coefficients(qu, 0)
    qs, qt = spectral.chebyshev_derivative(qu, 0, cq0), spectral.chebyshev_derivative(qu, 1)
    cq2 = np.abs(spectral.chebyshev_coefficients(cq0, 1))
    tail_q = spectral.coefficient_tail(cq2)
    reason = _period_steps([np.diff(qu, axis=0), np.diff(qu, axis=1)], P) if P is not None else ""   # (as for loops)
    reason = reason or (_jumps(qu, P, (0, 1), closed=False) if tail_q > UNDER_RESOLVED else "")
    out, omega = {}, {}
    if "noncanonical" in named or "corrected" in named:
        sy = _need(system, "system", "noncanonical" if "noncanonical" in named else "corrected")
        want = "corrected" in named
        if want:
            lam = _check(_need(lam, "lam", "corrected"), 3, "lam")
            h = float(_need(h, "h", "corrected"))
            cl0 = spectral.chebyshev_coefficients(lam, 0)
            ls, lt = spectral.chebyshev_derivative(lam, 0, cl0), spectral.chebyshev_derivative(lam, 1)
        else:
            ls = lt = cl0 = None
        got = _compiled_integrands(sy, q, lam, qs, qt, ls, lt, h, paper_sign, want)
        if got is None:                     # a duck-typed system: the numpy route
            Om = sy.Omega(q)
            got = (np.einsum("...i,...ij,...j->...", qs, Om, qt),
                   np.einsum("...i,...ij,...j->...", np.concatenate([qs, ls], axis=-1),
                             corrected_omega(sy, q, lam, h, paper_sign), np.concatenate([qt, lt], axis=-1))
                   if want else None)
        omega = {"noncanonical": got[0], "corrected": got[1]}
    for form in forms:
        res = tail_q
        if callable(form):
            Om = _user_values(form, q, q.shape + (d,), "two-form")
            integrand = np.einsum("...i,...ij,...j->...", qs, Om, qt)
        elif form == "canonical":
            p = _check(_need(p, "p", form), 3, "p")
            cp0 = spectral.chebyshev_coefficients(p, 0)
            ps, pt = spectral.chebyshev_derivative(p, 0, cp0), spectral.chebyshev_derivative(p, 1)
            integrand = np.sum(ps * qt - pt * qs, axis=-1)
            res = max(tail_q, spectral.surface_tail(p, cp0))
        elif form == "noncanonical":
            integrand = omega["noncanonical"]
        else:
            integrand = omega["corrected"]
            hl2 = np.abs(h * spectral.chebyshev_coefficients(cl0, 1))      # λ's coefficients, scaled
            res = spectral.coefficient_tail(np.concatenate([cq2, hl2], axis=-1))   # hλ has the units of q
        out[form] = _value(spectral.surface_integral(integrand), spectral.surface_quadrature_error(integrand),
                           spectral.surface_roundoff(integrand), res, reason)
    return out


@dataclasses.dataclass(frozen=True)
class InvariantSeries:
    """An invariant along a solution: ``t``, ``value`` and ``resolution`` (nsave,), and
    ``relative_error`` = |I(t) − I(0)| / |I(0)|.  NaN where a point of the set had broken down."""

    t: np.ndarray
    value: np.ndarray
    resolution: np.ndarray

    @property
    def relative_error(self):
        return np.abs(self.value - self.value[0]) / abs(self.value[0])

    @property
    def under_resolved(self):
        return ~(self.resolution <= UNDER_RESOLVED)


def along(solution, form="noncanonical", system=None, period=None) -> InvariantSeries:
    """The invariant of a sample set at every saved time of an ``integrators.integrate`` solution.

    The set's shape travels with the points: integrate a loop (N, d) and get I₁, a surface
    (n_σ, n_τ, d) and get I₂ (``integrate`` keeps the leading shape of q0).  ``form`` as for
    :func:`first_invariant` / :func:`second_invariant`, a user callable included; p, λ and h come
    from the solution; ``period`` as for :func:`first_invariant`.
    """
    q = np.asarray(solution.q)
    if q.ndim == 3:
        fn = first_invariant
    elif q.ndim == 4:
        fn = second_invariant
    else:
        raise ValueError(f"along: the solution's q has shape {q.shape}; integrate a loop (N, d) or a surface "
                         "(n_sigma, n_tau, d)")
    vals, res = np.full(q.shape[0], np.nan), np.full(q.shape[0], np.nan)
    for k in range(q.shape[0]):
        if not np.all(np.isfinite(q[k])):
            continue
        broken = np.isfinite(solution.breakdown_time) & (solution.breakdown_time <= solution.t[k])
        if np.any(broken):
            continue
        v = fn(q[k], form, system=system, p=solution.p[k], lam=solution.lam[k], h=solution.h, period=period)
        vals[k], res[k] = v.value, v.resolution
    return InvariantSeries(np.asarray(solution.t), vals, res)
