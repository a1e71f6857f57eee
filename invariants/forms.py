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
import math

import numpy as np
from numba import njit

from integrators.simd import _at

from . import spectral

FORMS = ("canonical", "noncanonical", "corrected")
EPS = np.finfo(np.float64).eps
UNDER_RESOLVED = 1e-10   # documented threshold of the resolution monitor


@dataclasses.dataclass(frozen=True)
class InvariantValue:
    """An invariant with its resolution monitor (docs/invariants.md, "The resolution monitor bounds
    the value").

    value : float; for a form computed on the set (noncanonical, corrected, a callable), the sum on
        the set interpolated to ``padding`` times its points (loops: trigonometric interpolation;
        surfaces: Chebyshev, about ``padding`` times the points a side), the finest where the sum
        converged; the canonical form of a loop is summed on its samples (Parseval is exact there)
    resolution : the larger of two relative readings, each 0 for a set resolved to round-off:
        ``error``/|value| less round-off, and the relative size of the highest modes of the sampled
        set (of q; of q and p, canonical; of (q, hλ) together, corrected: hλ enters ϑ_λ as a
        displacement of q)
    under_resolved : resolution > UNDER_RESOLVED (1e-10)
    error : a bound on |value − exact| where the sampled set is resolved and each doubling of the
        points at least halves the sum's error: the value's change on the last doubling (or
        move·ρ/(1 − ρ) where the moves fell by ρ ≤ ½; 0 where the form's and the set's samples are
        at round-off already, and the N-point sum is exact), plus what the set's top eighth of modes
        adds, measured, and the round-off below (:func:`_padded`).  Where the set is not resolved
        (or its interpolant leaves the form's domain) it is not padded, and ``error`` is the model
        of the form's aliasing, an estimate
    roundoff : the value's round-off relative to |value|: 8 ulps of the size of the terms summed,
        which can be 10⁴ times the value where they cancel (a loop stretched by shear), and the
        rounding of the points themselves (8 ulps of their largest coordinate) carried through the
        derivative: on a loop as white noise paired with the form's modes, on a surface times n
        over the set's extent (a 1 mm patch at R = 2.5 is rounded at 1e-10 of its size); and what a
        floor of the set's top modes (at round-off, or flat: the orbits' noise) adds, measured.  A floor of
        the value's precision that more points do not lower, so not part of ``resolution``
    reason : why a set is under-resolved where its spectrum cannot say (a coordinate that jumps by
        more than half its extent between neighbours: a wrapped angle given no ``period``; padded
        values that do not converge); "" else
    padding : the factor of the points the value was summed on (1: the samples themselves)
    """

    value: float
    resolution: float
    under_resolved: bool
    error: float = 0.0
    roundoff: float = 0.0
    reason: str = ""
    padding: int = 1

    def __float__(self):
        return self.value


def _value(value, error, roundoff, tail, reason="", padding=1):
    """The InvariantValue of a value with its error estimate, its round-off and its set's relative tail
    (a ``reason`` makes it under-resolved whatever the spectra say: resolution 1)."""
    value = float(value)
    # an error within twice the round-off is round-off's (reported as ``roundoff``), not the set's: a
    # padded value that moved by its last bits, a value that is zero within round-off (a closed form)
    reading = spectral.relative(error, value) if error > 2.0 * roundoff else 0.0
    res = max(reading, tail, 1.0 if reason else 0.0)
    return InvariantValue(value, float(res), bool(res > UNDER_RESOLVED), float(error + roundoff),
                          float(spectral.relative(roundoff, value)), reason, int(padding))


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
    if q.ndim == 2 and axis == 0 and q.dtype == np.float64:
        return _unwrap_loop(np.ascontiguousarray(q), np.asarray(P, dtype=np.float64))
    out = q.copy()
    j = np.flatnonzero(P)
    x = np.take(q[..., j], np.arange(q.shape[axis]), axis=axis)
    dx = np.diff(x, axis=axis)
    Pj = P[j]
    dx = dx - Pj * np.floor(dx / Pj + 0.5)
    first = np.take(x, [0], axis=axis)
    out[..., j] = np.concatenate([first, first + np.cumsum(dx, axis=axis)], axis=axis)
    return out


@njit(cache=True, error_model="numpy")
def _unwrap_loop(q, P):
    """:func:`_unwrap` of a loop (N, d) along its points, in one pass: the same operations in the same
    order as the numpy version (each difference d − P⌊d/P + ½⌋, summed from the first sample in
    sequence, as cumsum does), so the same bits, without its five temporaries of the loop's size
    (they were 40 % of I₁'s time on 4,096 × 2,048)."""
    n, d = q.shape
    out = q.copy()
    total = np.zeros(d)
    for i in range(1, n):
        for c in range(d):
            if P[c] != 0.0:
                dx = q[i, c] - q[i - 1, c]
                dx = dx - P[c] * np.floor(dx / P[c] + 0.5)
                total[c] += dx
                out[i, c] = q[0, c] + total[c]
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


PADDING_MAX = 8         # a loop's one-form is evaluated on at most 8N interpolated points, a surface's
                        # two-form on at most (4n − 3)² (two doublings of its Chebyshev grid)
CONVERGED = 1e-3 * UNDER_RESOLVED   # a padded value that moves by less than this (relative) has converged


def _converged(move, value, roundoff):
    """Whether a padded value that moved by ``move`` on doubling the points needs no more: below
    CONVERGED of the value, or within twice its round-off."""
    return move <= max(CONVERGED * abs(value), 2.0 * roundoff)


def _points_precision(q, n):
    """The relative round-off a surface's own points carry into its derivatives: 8 ulps of their
    largest coordinate over the set's largest extent, times n (the points a direction; the
    derivative's amplification of noise).  A small set far from the origin (a 1 mm patch at R = 2.5)
    has its points rounded at 1e-10 of its size here, which no number of interpolated points changes."""
    axes = tuple(range(q.ndim - 1))
    extent = float(np.max(np.max(q, axis=axes) - np.min(q, axis=axes)))
    return 8.0 * EPS * float(np.max(np.abs(q))) / extent * n if extent > 0 else 0.0


def _padded(value_at, first, roundoff, cap):
    """The value of a sum on ever finer interpolated samples (the monitor's bound, docs/invariants.md,
    "The resolution monitor bounds the value"): ``first`` on the samples given, then
    ``value_at(level)`` on ``level`` times the points (level 2, 4, …; None where the interpolant left
    the form's domain) until the value moves by less than CONVERGED or the level reaches ``cap``.

    Returns (value, error, level, reason).  ``error`` is the last move, which bounds the last value's
    error where each doubling of the points at least halves it; from the third level on, where the
    moves fell by a ratio ρ ≤ ½, it is move·ρ/(1 − ρ), the bound where each doubling reduces the error
    by ρ or more (the assumption, checked by the moves themselves).  Where the moves do not halve (a
    set whose spectrum ends in a floor, the points' own noise), ``error`` is twice the largest move,
    an estimate rather than a bound, and above UNDER_RESOLVED of the value it comes with a reason.
    (first, None, 1, reason) where the interpolant left the domain."""
    previous, level, moves = first, 1, []
    while True:
        level *= 2
        value = value_at(level)
        if value is None:
            return first, None, 1, ("the set interpolated between its samples leaves the form's domain (values "
                                    f"not finite on {level}× its points)")
        moves.append(abs(value - previous))
        previous = value
        if _converged(moves[-1], value, roundoff) or level >= cap:
            break
    error, reason = moves[-1], ""
    if len(moves) > 1 and 0.0 < moves[-2] and moves[-1] <= 0.5 * moves[-2]:
        # the error falls by ρ = the last move's ratio to the one before, or faster (an aliasing error
        # falls exponentially, or algebraically with a constant ratio): |e_s| ≤ move · ρ/(1 − ρ)
        rho = moves[-1] / moves[-2]
        error = moves[-1] * rho / (1.0 - rho)
    elif not _converged(error, value, roundoff) and len(moves) > 1:
        error = 2.0 * max(moves)
        if error > UNDER_RESOLVED * abs(value):
            reason = (f"the value on the set interpolated to {level}× its points does not converge: it moved by "
                      f"{', then '.join(f'{m:.3g}' for m in moves)}")
    return value, error, level, reason


class _LoopLevels:
    """The loop interpolated between its samples (spectral.loop_shifted), shared by the forms of one
    call: the samples at τ_j = (j + phase)/N of q (its periodic part r and the winding's ramp) and λ."""

    def __init__(self, qh, lh, ramp, N):
        self.qh, self.lh, self.ramp, self.N = qh, lh, ramp, N
        self._points = {}
        self._truncated = {}

    def points(self, phase):
        """(q, r, r's coefficients, λ, λ's coefficients) at τ_j = (j + phase)/N."""
        if phase not in self._points:
            r, rh = spectral.loop_shifted(self.qh, self.N, phase)
            q = r if self.ramp is None else r + ((np.arange(self.N) + phase) / self.N)[:, None] * self.ramp
            lam, lh = spectral.loop_shifted(self.lh, self.N, phase) if self.lh is not None else (None, None)
            self._points[phase] = (q, r, rh, lam, lh)
        return self._points[phase]

    def truncated(self, eighths=1):
        """The same loop without its top ``eighths`` eighths of modes (of q and λ)."""
        if eighths not in self._truncated:
            top = _cut_mode(self.qh.shape[0] - 1, eighths)
            cut = lambda c: None if c is None else np.concatenate([c[:top], np.zeros_like(c[top:])])
            self._truncated[eighths] = _LoopLevels(cut(self.qh), cut(self.lh), self.ramp, self.N)
        return self._truncated[eighths]


def _loop_sum(coefficients, levels, phase, ramp):
    """The N-point sum of a form's I₁ on the loop's samples shifted by ``phase`` of a grid step; None
    where the form is not finite there."""
    q, r, rh, lam, lh = levels.points(phase)
    got = coefficients(q, lam)
    if got is None:
        return None
    A, Al = got
    v = spectral.loop_pairing(A, r, bh=rh)
    if Al is not None:
        v += spectral.loop_pairing(Al, lam, bh=lh)
    if ramp is not None and ramp.any():
        v += np.sum(ramp * np.mean(A, axis=0))
    return float(v)


def _loop_value(coefficients, levels, value, roundoff, ramp):
    """(value, error, level, reason) of one form on the padded loop (:func:`_padded`).  On s·N points
    the sum is the mean of the N-point sums at the s phases j/s of a grid step (the trapezoidal rule
    on the finer grid, split by phase): each doubling adds the odd phases.  ``coefficients``:
    (q, λ) → (A, Aλ) at shifted points, or None where not finite."""
    terms = [float(value)]

    def value_at(level):
        new = [_loop_sum(coefficients, levels, j / level, ramp) for j in range(1, level, 2)]
        if any(v is None for v in new):
            return None
        terms.extend(new)
        return math.fsum(terms) / level          # summed exactly: the order of the phases cannot matter
    return _padded(value_at, float(value), roundoff, PADDING_MAX)


def _cut_mode(K, eighths):
    """The first mode cut when the top ``eighths`` eighths of modes 0 … K are left out (1: the
    monitor's top eighth, spectral.top_mode; 2: the eighth below it too)."""
    top = spectral.top_mode(K)
    return max(1, top - (eighths - 1) * (K + 1 - top))


def _beyond(value, cut1, cut2):
    """What the modes beyond the samples add, from what the top eighth adds (E1 = |value − cut1|) and
    the eighth below it (E2 = |cut1 − cut2|): E1·r/(1 − r) with r = E1/E2 where the effects fall by
    r ≤ ½ an eighth (the next eighths, beyond the samples, falling as these did), E1 itself where
    they do not."""
    e1, e2 = abs(value - cut1), abs(cut1 - cut2)
    r = e1 / e2 if e2 > 0 else 1.0
    return e1 * r / (1.0 - r) if r <= 0.5 else e1


def _truncation_effect(coefficients, levels, level, value, ramp, floor=False):
    """What the modes beyond the samples add to the value (:func:`_beyond`), from the same sum on the
    loop without its top eighth of modes and without its top two: the effects of the modes at the
    edge of the samples' resolution, measured; for a ``floor`` (the points' own noise), what the top
    eighth itself adds.  None where a truncated loop leaves the form's domain."""
    cuts = []
    for eighths in ((1,) if floor else (1, 2)):
        cut = levels.truncated(eighths)
        terms = [_loop_sum(coefficients, cut, j / level, ramp) for j in range(level)]
        if any(v is None for v in terms):
            return None
        cuts.append(math.fsum(terms) / level)
    return abs(value - cuts[0]) if floor else _beyond(value, *cuts)


def first_invariants(q, forms, system=None, p=None, lam=None, h=None, period=None) -> dict:
    """{form: I₁} for several forms of one loop, sharing q's Fourier coefficients, its interpolated
    points and its resolution monitor; each value is bitwise what it is alone.  ``period``: as
    :func:`first_invariant`.

    A form computed on the loop (noncanonical, corrected, a callable) is summed on the loop
    interpolated to 2N, 4N, … points until the value converges (:func:`_padded`): the value is the
    sum on the finest, its error the last change, plus what the set's top eighth of modes adds to it
    where that is above round-off (:func:`_truncation_effect`).  The canonical form pairs two sets
    of samples, p and q: the N-point sum is exact for their interpolants (Parseval), so its error is
    what their top eighth adds, bounded term by term, and the model of their modes beyond
    (spectral.loop_pairing_error).  A set whose spectrum does not fall towards its top
    (spectral.decaying) is read by its top modes, as before."""
    q = _check(q, 2, "loop q")
    N = q.shape[0]
    P = _periods(period, q.shape[1])
    r, ramp = (q, None) if P is None else _winding(q, P)
    qh = spectral.fourier_coefficients(r)
    aq = np.abs(qh)                    # shared by the monitor's readings
    top = spectral.top_mode(aq.shape[0] - 1)
    reason = None
    levels = None
    out = {}
    for form in forms:
        A, Al = one_form_coefficients(q, form, system, p, lam, h)
        if P is not None and form != "canonical":
            _check_periodic(lambda x: one_form_coefficients(x, form, system, p, lam, h)[0], q, P, "one-form")
        ah = spectral.fourier_coefficients(A)
        aa = np.abs(ah)
        value = spectral.loop_pairing(A, r, bh=qh, ah=ah)        # in Fourier space (Parseval)
        padded = form != "canonical"
        error, roundoff, tail_a, tail_q = spectral.loop_pairing_error(ah, qh, N, absolute=(aa, aq), tails=True,
                                                                      model=(not padded, True))
        if reason is None:
            # a jump of a wrapped coordinate is a discontinuity, whose spectrum already flags the set:
            # the reason is sought only then (a third of the call's time at D = 2 otherwise); a
            # period the samples cannot tell from a step flags the set whatever its spectrum
            reason = (_period_steps([np.diff(r, axis=0, append=r[:1]) + ramp / N], P)
                      if P is not None else "")
            reason = reason or (_jumps(r, P, (0,), closed=True) if tail_q > UNDER_RESOLVED else "")
        if ramp is not None and ramp.any():                    # the winding: ∮ A_i m P_i dτ, A's mean
            wind = np.abs(ramp) * np.max(np.abs(A), axis=0)
            value += np.sum(ramp * np.mean(A, axis=0))
            error += (0.0 if padded else tail_a) * np.sum(wind)
            roundoff += 8 * EPS * np.sum(wind)
        # the points' own rounding (8 ulps of each coordinate's largest value, white noise of 1/√N a
        # mode) paired with the form's modes of that coordinate: 4π Σ_i ε_i Σ_k k|â_ik| / √N
        roundoff += 4.0 * np.pi * 8.0 * EPS / np.sqrt(N) * float(
            np.sum(np.max(np.abs(r), axis=0) * (spectral._modes(aa.shape[0] - 1, aa.ndim) * aa[1:])))
        tail, spectra = tail_q, [aq]
        if Al is not None:
            alh, lh = spectral.fourier_coefficients(Al), spectral.fourier_coefficients(lam)
            value += spectral.loop_pairing(Al, lam, bh=lh, ah=alh)
            e2, r2 = spectral.loop_pairing_error(alh, lh, N, model=(False, True))
            error, roundoff = error + e2, roundoff + r2
            scaled = np.abs(h * lh)
            tail = spectral.loop_tail(None, absolute=np.concatenate([aq, scaled], axis=-1))   # hλ: units of q
            spectra.append(scaled)
        if form == "canonical":
            tail, spectra = max(tail, tail_a), spectra + [aa]
            # what the top eighth adds to the sum, term by term: 4π Σ_{k ≥ top} k |p̂_k||q̂_k|
            error += 4.0 * np.pi * float(np.sum(np.arange(top, aa.shape[0])[:, None] * aa[top:] * aq[top:]))
        decays = all(spectral.decaying(c) for c in spectra)
        why, level, move = reason, 1, None
        if padded and spectral.top_at_roundoff(aa) and (Al is None or spectral.top_at_roundoff(np.abs(alh))) \
                and spectral.top_at_roundoff(aq):
            move = 0.0          # the form's and the set's samples resolved to round-off: the sum is exact
        elif padded and (decays or tail <= UNDER_RESOLVED) and not reason:
            # the set is resolved, or falls towards its top: its interpolant is the loop, and the sum
            # on it converges
            if levels is None:
                levels = _LoopLevels(qh, spectral.fourier_coefficients(lam) if lam is not None else None, ramp, N)
            floor = not any(spectral.falling(c) and not spectral.top_at_roundoff(c) for c in spectra)
            value, move, level, why, rounding = _padded_loop_form(_shifted_form(form, system, p, h), levels, value,
                                                                  roundoff, ramp, tail, floor)
            roundoff += rounding
        if padded and move is None:        # not padded: the samples' sum, the one-form's aliasing modelled
            error = error + _aliasing_model(ah, qh, aa, aq, N, Al, lam)
        out[form] = _value(value, error + (move or 0.0), roundoff, 0.0 if decays else tail, why, level)
    return out


def _padded_loop_form(coefficients, levels, value, roundoff, ramp, tail, floor):
    """(value, error, level, reason, rounding) of a form on the padded loop (:func:`_loop_value`),
    with what the set's top eighth adds where that could reach CONVERGED of the value (``tail``: the
    set's relative top modes; the sum's terms are roundoff / 8 ulps): in the error where the top is
    a falling spectrum above round-off, or in ``rounding`` where it is a ``floor`` (at round-off, or
    flat: the points' own rounding and noise, which more points do not lower); error None where the
    interpolant left the form's domain."""
    value, move, level, why = _loop_value(coefficients, levels, value, roundoff, ramp)
    rounding = 0.0
    if move is not None and tail * roundoff / (8 * EPS) > CONVERGED * abs(value):
        cut = _truncation_effect(coefficients, levels, level, value, ramp, floor)
        if cut is None:
            move, why = move + tail * abs(value), why or "the set without its top modes leaves the form's domain"
        elif floor:
            rounding = cut
        else:
            move += cut
    return value, move, level, why, rounding


def _aliasing_model(ah, qh, aa, aq, N, Al, lam):
    """The model of the one-form's aliasing (its modes beyond N/2 from its top eighth): the estimate
    where padding cannot measure it (a set not resolved, or interpolated out of the domain)."""
    e = spectral.loop_pairing_error(ah, qh, N, absolute=(aa, aq), model=(True, False))[0]
    if Al is not None:
        e += spectral.loop_pairing_error(spectral.fourier_coefficients(Al), spectral.fourier_coefficients(lam), N,
                                         model=(True, False))[0]
    return e


def _shifted_form(form, system, p, h):
    """(q, λ) → (A, Aλ) of ``form`` at interpolated points, or None where a value is not finite."""
    def coefficients(q, lam):
        try:
            A, Al = one_form_coefficients(q, form, system, p, lam, h)
        except ValueError:                  # a user one-form that failed or was not finite there
            return None
        if not np.all(np.isfinite(A)) or (Al is not None and not np.all(np.isfinite(Al))):
            return None
        return A, Al
    return coefficients


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
    derivatives of q, its interpolated grids, and ϑ_q, ϑ_qq from one compiled pass over the points for
    noncanonical and corrected together.  Each form's value is bitwise what it is alone
    (tests/test_invariants.py).

    Each form is integrated on the surface interpolated (Chebyshev) to about 2, 4 times the points a
    side (2n − 1, 4n − 3: grids that hold the given one) until the value converges (:func:`_padded`):
    the integrand is a product of the derivatives and Ω, of about twice q's degree, which
    Clenshaw–Curtis on the n points given does not integrate exactly."""
    q = _check(q, 3, "surface q")
    d = q.shape[-1]
    for form in forms:
        if not callable(form) and form not in FORMS:
            raise ValueError(f"unknown form '{form}'; choose one of {', '.join(FORMS)}")
    P = _periods(period, d)
    qu = q if P is None else _unwrap(_unwrap(q, P, 1), P, 0)    # along τ, then σ: the patch in one sheet
    if P is not None:
        for form in forms:
            if callable(form):
                _check_periodic(lambda x: _user_values(form, x, x.shape + (d,), "two-form"), q, P, "two-form")
            elif form != "canonical":
                _check_periodic(_need(system, "system", form).Omega, q, P, "two-form Ω̄ of the system")
    named = [f for f in forms if not callable(f)]
    if "noncanonical" in named or "corrected" in named:
        _need(system, "system", "noncanonical" if "noncanonical" in named else "corrected")
    if "corrected" in named:
        lam = _check(_need(lam, "lam", "corrected"), 3, "lam")
        h = float(_need(h, "h", "corrected"))
    if "canonical" in named:
        p = _check(_need(p, "p", "canonical"), 3, "p")
    grid = _SurfaceGrid(q, qu, p if "canonical" in named else None, lam if "corrected" in named else None)
    tail_q = spectral.coefficient_tail(grid.cq2)
    reason = _period_steps([np.diff(qu, axis=0), np.diff(qu, axis=1)], P) if P is not None else ""   # (as for loops)
    reason = reason or (_jumps(qu, P, (0, 1), closed=False) if tail_q > UNDER_RESOLVED else "")
    integrands = grid.integrands(forms, system, h, paper_sign)
    out = {}
    for form in forms:
        res, spectra = tail_q, [grid.cq2]
        if form == "canonical":
            cp2 = np.abs(spectral.chebyshev_coefficients(grid.cp0, 1))
            res, spectra = max(tail_q, spectral.coefficient_tail(cp2)), spectra + [cp2]
        elif form == "corrected":
            hl2 = np.abs(h * spectral.chebyshev_coefficients(grid.cl0, 1))      # λ's coefficients, scaled
            res = spectral.coefficient_tail(np.concatenate([grid.cq2, hl2], axis=-1))   # hλ has the units of q
            spectra.append(hl2)
        decays = all(spectral.decaying(c, axis) for c in spectra for axis in (0, 1))
        integrand = integrands[form]
        value, roundoff = spectral.surface_integral(integrand), spectral.surface_roundoff(integrand)
        roundoff *= 1.0 + _points_precision(qu, max(q.shape[:2])) / (8 * EPS)     # the points' own rounding
        why, level, error = reason, 1, None
        coefficients = np.abs(spectral.chebyshev_coefficients(spectral.chebyshev_coefficients(integrand, 0), 1))
        if spectral.top_at_roundoff(coefficients, (0, 1)) and spectral.top_at_roundoff(grid.cq2, (0, 1)):
            error = 0.0         # the integrand resolved to round-off on the points given: Clenshaw–Curtis is exact
        elif (decays or res <= UNDER_RESOLVED) and not reason:     # the interpolant is the surface

            def value_at(level, form=form, grid=grid):
                # every form's integrand on the level's grid in one pass (each form's numbers as alone)
                got = grid.refined(level).integrands(forms, system, h, paper_sign)[form]
                return spectral.surface_integral(got) if np.all(np.isfinite(got)) else None
            value, error, level, why = _padded(value_at, float(value), roundoff, PADDING_MAX // 2)
            if error is not None and res * roundoff / (8 * EPS) > CONVERGED * abs(value):   # (as for loops)
                cut = value_at(level, grid=grid.truncated(1)) if level > 1 else None
                cut2 = value_at(level, grid=grid.truncated(2)) if cut is not None else None
                if cut is None or cut2 is None:
                    error += res * abs(value)
                    why = why or "the set without its top modes leaves the form's domain"
                elif not any(spectral.falling(c, axis) and not spectral.top_at_roundoff(c, (axis,))
                             for c in spectra for axis in (0, 1)):   # a floor: the points' own (as for loops)
                    roundoff += abs(value - cut)
                elif form == "canonical":     # p is samples: its folded modes are not the interpolant's
                    error += abs(value - cut)
                else:
                    error += _beyond(value, cut, cut2)
        if error is None:              # not padded: the model of the integrand's Clenshaw–Curtis error
            error = spectral.surface_quadrature_error(integrand)
        out[form] = _value(value, error, roundoff, 0.0 if decays else res, why, level)
    return out


class _SurfaceGrid:
    """A surface's values on its Chebyshev grid with their derivatives (what the forms share), the
    forms' integrands there (computed together, cached), and the same surface interpolated to the
    finer grids of :func:`second_invariants` (cached by level: level s has s(n − 1) + 1 points a
    side; the values and the derivatives are each refined from the given grid, where the
    interpolant's derivative is exact)."""

    def __init__(self, q, qu, p, lam, derivatives=None):
        self.q, self.qu, self.p, self.lam = q, qu, p, lam
        if derivatives is None:
            cq0 = spectral.chebyshev_coefficients(qu, 0)
            self.cq2 = np.abs(spectral.chebyshev_coefficients(cq0, 1))
            self.cp0 = spectral.chebyshev_coefficients(p, 0) if p is not None else None
            self.cl0 = spectral.chebyshev_coefficients(lam, 0) if lam is not None else None
            d = lambda v, c0: (None, None) if v is None else (spectral.chebyshev_derivative(v, 0, c0),
                                                              spectral.chebyshev_derivative(v, 1))
            derivatives = d(qu, cq0) + d(p, self.cp0) + d(lam, self.cl0)
        self.qs, self.qt, self.ps, self.pt, self.ls, self.lt = derivatives
        self._levels, self._integrands = {}, {}

    def truncated(self, eighths=1):
        """The same surface without its top ``eighths`` eighths of Chebyshev modes in either direction
        (of q, p, λ)."""
        def cut(v):
            if v is None:
                return None
            c = spectral.chebyshev_coefficients(spectral.chebyshev_coefficients(v, 0), 1)
            ns, nt = c.shape[:2]
            c[_cut_mode(ns - 1, eighths):] = 0.0
            c[:, _cut_mode(nt - 1, eighths):] = 0.0
            return spectral.chebyshev_values(spectral.chebyshev_values(c, 0), 1)
        qu = cut(self.qu)
        return _SurfaceGrid(qu, qu, cut(self.p), cut(self.lam))

    def refined(self, level):
        """The grid interpolated to level × (n − 1) + 1 points a side."""
        if level not in self._levels:
            shape = tuple(level * (n - 1) + 1 for n in self.q.shape[:2])
            # what the integrands read (p's values are not read), refined in one transform of them all
            parts = (self.qu, self.qs, self.qt, self.ps, self.pt, self.lam, self.ls, self.lt)
            held = [v for v in parts if v is not None]
            fine = np.split(spectral.chebyshev_refined(np.concatenate(held, axis=-1), shape), len(held), axis=-1)
            it = iter(fine)
            qu, qs, qt, ps, pt, lam, ls, lt = (None if v is None else next(it) for v in parts)
            self._levels[level] = _SurfaceGrid(qu, qu, None, lam, (qs, qt, ps, pt, ls, lt))
        return self._levels[level]

    def integrands(self, forms, system, h, paper_sign):
        """{form: the integrand of I₂ at the grid's points} (each form's numbers the same whichever
        forms are asked with it; computed once a grid)."""
        missing = [f for f in forms if f not in self._integrands]
        named = [f for f in missing if not callable(f)]
        q, qs, qt, d = self.q, self.qs, self.qt, self.q.shape[-1]
        out = self._integrands
        if "noncanonical" in named or "corrected" in named:
            want = "corrected" in named
            lam, ls, lt = (self.lam, self.ls, self.lt) if want else (None, None, None)
            got = _compiled_integrands(system, q, lam, qs, qt, ls, lt, h, paper_sign, want)
            if got is None:                     # a duck-typed system: the numpy route
                Om = system.Omega(q)
                got = (np.einsum("...i,...ij,...j->...", qs, Om, qt),
                       np.einsum("...i,...ij,...j->...", np.concatenate([qs, ls], axis=-1),
                                 corrected_omega(system, q, lam, h, paper_sign), np.concatenate([qt, lt], axis=-1))
                       if want else None)
            out["noncanonical"] = got[0]
            if want:
                out["corrected"] = got[1]
        for form in missing:
            if callable(form):
                Om = _user_values(form, q, q.shape + (d,), "two-form")
                out[form] = np.einsum("...i,...ij,...j->...", qs, Om, qt)
            elif form == "canonical":
                out[form] = np.sum(self.ps * qt - self.pt * qs, axis=-1)
        return {f: out[f] for f in forms}


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
