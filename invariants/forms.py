"""First and second Poincaré integral invariants (sec:app_integral_invariants).

Sign conventions (docs/conventions.md):

* Ω̄_ij = ∂_iϑ_j − ∂_jϑ_i, so dϑ = ½ Ω̄_ij dq^i ∧ dq^j.
* I₁[γ] = ∮ α(q) (dq/dτ) dτ with τ ∈ [0, 1) in the loop's sample order.
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
    """

    value: float
    resolution: float
    under_resolved: bool
    error: float = 0.0
    roundoff: float = 0.0

    def __float__(self):
        return self.value


def _value(value, error, roundoff, tail):
    """The InvariantValue of a value with its error estimate, its round-off and its set's relative tail."""
    value = float(value)
    res = max(spectral.relative(error, value), tail)
    return InvariantValue(value, float(res), bool(res > UNDER_RESOLVED), float(error + roundoff),
                          float(spectral.relative(roundoff, value)))


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
    if not np.all(np.isfinite(q)):
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


def first_invariant(q, form="noncanonical", system=None, p=None, lam=None, h=None) -> InvariantValue:
    """I₁ = ∮ A(q) dq/dτ dτ over a loop q (N, d) sampled at τ_j = j/N: the trapezoidal rule of A·(spectral
    dq/dτ), evaluated in Fourier space by Parseval (spectral.loop_pairing).

    form : 'noncanonical' (needs system), 'canonical' (needs p), 'corrected' (needs system, lam, h),
        or a callable ϑ(q) -> (N, d): the coefficients of a one-form of your own
    """
    return first_invariants(q, [form], system, p, lam, h)[form]


def first_invariants(q, forms, system=None, p=None, lam=None, h=None) -> dict:
    """{form: I₁} for several forms of one loop, sharing q's Fourier coefficients and resolution
    monitor; each value is bitwise what it is alone."""
    q = _check(q, 2, "loop q")
    qh = spectral.fourier_coefficients(q)
    tail_q = spectral.loop_tail(q, qh)
    half = q.shape[0] % 2 == 0 and q.shape[0] // 2 >= MIN_POINTS    # the every-other-point subset
    qh2 = None
    out = {}
    for form in forms:
        A, Al = one_form_coefficients(q, form, system, p, lam, h)
        ah = spectral.fourier_coefficients(A)
        value = spectral.loop_pairing(A, q, bh=qh, ah=ah)        # in Fourier space (Parseval)
        error, roundoff = spectral.loop_pairing_error(ah, qh, q.shape[0])
        check = half and error > SUBSET_BELOW * abs(float(value))     # the subset's value, where it can matter
        if check:
            qh2 = spectral.fourier_coefficients(q[::2]) if qh2 is None else qh2
            value2 = spectral.loop_pairing(A[::2], q[::2], bh=qh2)
        res = tail_q
        if Al is not None:
            alh, lh = spectral.fourier_coefficients(Al), spectral.fourier_coefficients(lam)
            value += spectral.loop_pairing(Al, lam, bh=lh, ah=alh)
            e2, r2 = spectral.loop_pairing_error(alh, lh, q.shape[0])
            error, roundoff = error + e2, roundoff + r2
            if check:
                value2 += spectral.loop_pairing(Al[::2], lam[::2])
            res = spectral.loop_tail(np.concatenate([q, h * lam], axis=-1))   # hλ has the units of q
        if check:             # two estimates that err large: the smaller is the sharper, and still errs large
            error = min(error, abs(float(value) - float(value2)))
        if form == "canonical":
            res = max(res, spectral.loop_tail(p, ah))
        out[form] = _value(value, error, roundoff, res)
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
                     paper_sign=False) -> InvariantValue:
    """I₂ = ∫∫ Ω_ab x_σ^a x_τ^b dσ dτ over a surface q (n_σ, n_τ, d) at Chebyshev points.

    form : 'noncanonical' (Ω̄(q), needs system), 'canonical' (∫∫ p_σ·q_τ − p_τ·q_σ, needs p),
    'corrected' (dϑ_λ on (q, λ), needs system, lam, h), or a callable Ω(q) -> (n_σ, n_τ, d, d):
    the matrix of a two-form ½Ω_ab dq^a ∧ dq^b of your own.
    """
    return second_invariants(q, [form], system, p, lam, h, paper_sign)[form]


def second_invariants(q, forms, system=None, p=None, lam=None, h=None, paper_sign=False) -> dict:
    """{form: I₂} for several forms of one surface, sharing what they share: the transforms and
    derivatives of q, and ϑ_q, ϑ_qq from one compiled pass over the points for noncanonical and
    corrected together.  Each form's value is bitwise what it is alone (tests/test_invariants.py)."""
    q = _check(q, 3, "surface q")
    d = q.shape[-1]
    for form in forms:
        if not callable(form) and form not in FORMS:
            raise ValueError(f"unknown form '{form}'; choose one of {', '.join(FORMS)}")
    named = [f for f in forms if not callable(f)]
    cq0 = spectral.chebyshev_coefficients(q, 0)
    qs, qt = spectral.chebyshev_derivative(q, 0, cq0), spectral.chebyshev_derivative(q, 1)
    cq2 = np.abs(spectral.chebyshev_coefficients(cq0, 1))
    tail_q = spectral.coefficient_tail(cq2)
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
                           spectral.surface_roundoff(integrand), res)
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


def along(solution, form="noncanonical", system=None) -> InvariantSeries:
    """The invariant of a sample set at every saved time of an ``integrators.integrate`` solution.

    The set's shape travels with the points: integrate a loop (N, d) and get I₁, a surface
    (n_σ, n_τ, d) and get I₂ (``integrate`` keeps the leading shape of q0).  ``form`` as for
    :func:`first_invariant` / :func:`second_invariant`, a user callable included; p, λ and h come
    from the solution.
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
        v = fn(q[k], form, system=system, p=solution.p[k], lam=solution.lam[k], h=solution.h)
        vals[k], res[k] = v.value, v.resolution
    return InvariantSeries(np.asarray(solution.t), vals, res)
