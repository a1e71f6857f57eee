"""The resolution monitor as a bound (issue 69; docs/invariants.md, "The resolution monitor bounds the
value"): forms computed on the set are summed on its interpolant at 2N, 4N, … points until the value
converges; the value is the finest sum, its ``error`` the last change (a bound where each doubling at
least halves the error), and no value is called resolved whose error exceeds UNDER_RESOLVED.

References are plain sums (no padding, no monitor) on many more points of the same band-limited set:
Parseval on 8,192 points for loops, Clenshaw–Curtis on 129² for surfaces."""
import numpy as np
import pytest

import integrators
import invariants
from invariants import spectral
from invariants.forms import corrected_omega, first_invariants, one_form_coefficients, second_invariants
from invariants.samples import band_limited_loop, band_limited_surface

GC = integrators.system("guiding_centre_symmetric")
LV = integrators.system("lotka_volterra_2d")
T = invariants.UNDER_RESOLVED
ROUNDOFF = 1e-12      # below this an error is the sums' and the reference's round-off (its size is the CPU's)


def plain_loop(system, q, form="noncanonical", lam=None, h=None):
    A, Al = one_form_coefficients(q, form, system, None, lam, h)
    v = spectral.loop_pairing(A, q)
    return v + spectral.loop_pairing(Al, lam) if Al is not None else v


def plain_surface(system, S, form="noncanonical", lam=None, h=None):
    qs, qt = spectral.chebyshev_derivative(S, 0), spectral.chebyshev_derivative(S, 1)
    if form == "noncanonical":
        f = np.einsum("...i,...ij,...j->...", qs, system.Omega(S), qt)
    else:
        ls, lt = spectral.chebyshev_derivative(lam, 0), spectral.chebyshev_derivative(lam, 1)
        f = np.einsum("...i,...ij,...j->...", np.concatenate([qs, ls], -1), corrected_omega(system, S, lam, h),
                      np.concatenate([qt, lt], -1))
    return float(spectral.surface_integral(f))


CENTRE = [0.0, 0.0, 0.0, 0.5]


@pytest.mark.parametrize("scale,decay", [([0.05, 0.05, 0.05, 0.01], 0.7),    # issue 57's loop
                                         ([0.02] * 4, 1.0)])                   # issue 69's: modes 1-20 of 0.02
def test_the_issues_band_limited_loops_are_right_where_called_resolved(scale, decay):
    """Issue 69's table: at 64 and 72 points I₁ was wrong by 1e-6 and 6e-6 and read resolved (2.4e-15),
    at 96 and 128 points exact and flagged.  Now every value called resolved is right to 1e-12, its
    error within its estimate, and from twice the integrand's band on (ϑ(q)·q′ reaches mode 80: 160
    points) none is flagged."""
    ref = plain_loop(GC, band_limited_loop(8192, CENTRE, 20, decay, scale))
    for N in (44, 48, 56, 64, 72, 80, 96, 128, 160, 256, 1024):
        v = invariants.first_invariant(band_limited_loop(N, CENTRE, 20, decay, scale), "noncanonical", system=GC)
        err = abs(v.value - ref) / abs(ref)
        assert v.under_resolved or err <= T, (N, err, v)
        assert v.under_resolved or err <= max(v.error / abs(v.value), ROUNDOFF), (N, err, v)
        if N >= 160:
            assert not v.under_resolved and err < ROUNDOFF, (N, err, v)
    # the plain sum on 64 points is the issue's wrong value; the padded one is not
    q = band_limited_loop(64, CENTRE, 20, decay, scale)
    assert abs(plain_loop(GC, q) - ref) > 1e3 * T * abs(ref) or decay == 0.7


def test_the_paper_surface_of_16_points_a_side_is_not_flagged_at_t0():
    """The paper's surface: I₂ = 601/60000 exactly.  On 16 × 16 points q's top Chebyshev modes are
    1.7e-8 of its peak (cos 2πσ cos 2πτ), which flagged it; the value does not depend on them."""
    S = invariants.surface("guiding_centre", 16, 16)
    got = second_invariants(S, ["canonical", "noncanonical", "corrected"], GC, p=GC.theta(S), lam=np.zeros_like(S),
                            h=10.0)
    for form, v in got.items():
        assert not v.under_resolved and abs(v.value - 601 / 60000) <= 1e-14 * 601 / 60000, (form, v)
    assert spectral.surface_tail(S) > 1e-9                # the set's own top modes, as before


def test_a_polynomial_surface_in_lotka_volterra_is_never_called_resolved_wrongly():
    """Degree 2 in σ and τ in Ω = 1/(xy) (issue 57's surface): the plain Clenshaw–Curtis sum is wrong by
    5e-5 on 8² points; the padded value is right where called resolved, within its estimate."""
    def shape(S, T):
        s, t = S - 0.5, T - 0.5
        return np.stack([0.6 + 0.8 * s + 0.2 * t * t, 0.6 + 0.8 * t + 0.3 * s * t], axis=-1)
    ref = plain_surface(LV, invariants.surface(shape, 129, 129))
    assert abs(plain_surface(LV, invariants.surface(shape, 8, 8)) - ref) > 1e-5 * abs(ref)
    for n in (8, 10, 12, 16, 20, 24, 32, 48):
        v = invariants.second_invariant(invariants.surface(shape, n, n), "noncanonical", system=LV)
        err = abs(v.value - ref) / abs(ref)
        assert err <= max(v.error / abs(v.value), ROUNDOFF), (n, err, v)
        assert v.under_resolved or err <= T, (n, err, v)
        if n >= 16:
            assert not v.under_resolved, (n, v)


SYSTEMS = {"guiding_centre_symmetric": (CENTRE, [0.15, 0.15, 0.1, 0.03], 10.0),
           "lotka_volterra_2d": ([1.0, 1.0], [0.1, 0.1], 0.1),
           "point_vortices": ([1.0, 0.1, 1.0, -0.1], [0.03] * 4, 0.1)}


@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_a_sample_of_the_study_none_called_resolved_wrongly(name):
    """scripts/studies/invariants_monitor.py in small: random band-limited loops (6) and surfaces (3) of
    random band, amplitude and size, every form.  No value is called resolved whose error exceeds the
    threshold, and none not flagged has an error above both its estimate and round-off."""
    system = integrators.system(name)
    centre, scale, h = SYSTEMS[name]
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(6):
        modes, decay, amp = int(rng.integers(2, 25)), rng.uniform(0.6, 1.0), 10 ** rng.uniform(-1, 0)
        N, seed = int(2 ** rng.uniform(np.log2(max(2 * modes + 4, 8)), np.log2(16 * modes + 64))), int(rng.integers(99))
        make = lambda n: band_limited_loop(n, centre, modes, decay, amp * np.asarray(scale), seed)
        lam = lambda n: band_limited_loop(n, np.zeros(len(centre)), modes, decay, 0.01 * np.asarray(scale), seed + 1)
        with np.errstate(all="ignore"):
            ref = {f: plain_loop(system, make(8192), f, lam(8192), h) for f in ("noncanonical", "corrected")}
        if not np.all(np.isfinite(list(ref.values()))):
            continue                        # the loop left the system's domain (Lotka–Volterra: x, y > 0)
        q = make(N)
        with np.errstate(all="ignore"):
            got = first_invariants(q, ["canonical", "noncanonical", "corrected"], system, p=system.theta(q),
                                   lam=lam(N), h=h)
        for form, v in got.items():
            r = ref["corrected" if form == "corrected" else "noncanonical"]
            err = abs(v.value - r) / abs(r)
            assert v.under_resolved or err <= T, (form, N, modes, err, v)
            assert v.under_resolved or err <= max(v.error / abs(v.value), ROUNDOFF), (form, N, modes, err, v)
            checked += 1
    for _ in range(3):
        degree, decay, amp = int(rng.integers(1, 9)), rng.uniform(0.5, 1.0), 10 ** rng.uniform(-1, 0)
        n, seed = int(2 ** rng.uniform(np.log2(max(degree + 2, 8)), np.log2(6 * degree + 12))), int(rng.integers(99))
        make = lambda k: band_limited_surface(k, k, centre, degree, decay, amp * np.asarray(scale), seed)
        lam = lambda k: band_limited_surface(k, k, np.zeros(len(centre)), degree, decay, 0.01 * np.asarray(scale),
                                             seed + 1)
        with np.errstate(all="ignore"):
            ref = {f: plain_surface(system, make(129), f, lam(129), h) for f in ("noncanonical", "corrected")}
        if not np.all(np.isfinite(list(ref.values()))):
            continue
        S = make(n)
        with np.errstate(all="ignore"):
            got = second_invariants(S, ["canonical", "noncanonical", "corrected"], system, p=system.theta(S),
                                    lam=lam(n), h=h)
        for form, v in got.items():
            r = ref["corrected" if form == "corrected" else "noncanonical"]
            err = abs(v.value - r) / abs(r)
            assert v.under_resolved or err <= T, (form, n, degree, err, v)
            assert v.under_resolved or err <= max(v.error / abs(v.value), ROUNDOFF), (form, n, degree, err, v)
            checked += 1
    assert checked >= 18


def test_the_interpolant_between_samples_is_the_band_limited_loop():
    """spectral.loop_shifted: the samples at τ_j = (j + φ)/N of a loop with modes up to 20 are its exact
    values there (the padding's points)."""
    tau = np.arange(64) / 64
    f = lambda t: np.stack([np.cos(2 * np.pi * 3 * t) + 0.3 * np.sin(2 * np.pi * 20 * t), np.sin(2 * np.pi * t)], -1)
    values, coefficients = spectral.loop_shifted(spectral.fourier_coefficients(f(tau)), 64, 0.37)
    assert np.max(np.abs(values - f(tau + 0.37 / 64))) < 1e-14
    assert np.allclose(spectral.fourier_coefficients(values), coefficients, atol=1e-15)


def test_a_form_that_leaves_its_domain_between_the_samples_is_flagged_with_its_reason():
    """A user one-form defined at the samples only (NaN elsewhere): the value is the samples' sum, flagged,
    and the reason says why."""
    q = band_limited_loop(24, [0.0, 0.0], 5, 0.8, [0.5, 0.5], 1)
    cubic = lambda x: np.stack([-x[:, 1] * (1 + x[:, 0] ** 2), x[:, 0] * (1 + x[:, 1] ** 2)], -1) / 2
    form = lambda x: np.where(np.isin(x, q), cubic(x), np.nan)
    v = invariants.first_invariant(q, form)
    assert v.under_resolved and "leaves the form's domain" in v.reason and v.padding == 1
    assert v.value == plain_loop(None, q, cubic)                  # the samples' own sum


def test_a_form_whose_padded_values_do_not_converge_is_flagged():
    """A one-form that changes with every evaluation (a cubic form times 1 + 1e-6·k at its k-th call) on
    a resolved loop whose form is aliased: the padded values keep moving; the error is twice the
    largest move (an estimate, not a bound), and the reason says they do not converge."""
    cubic = lambda x: np.stack([-x[:, 1] * (1 + x[:, 0] ** 2), x[:, 0] * (1 + x[:, 1] ** 2)], -1) / 2
    make = lambda n: band_limited_loop(n, [0.0, 0.0], 5, 0.8, [0.5, 0.5], 1)
    calls = []

    def form(x):
        calls.append(1)
        return cubic(x) * (1 + 1e-6 * len(calls))
    v = invariants.first_invariant(make(24), form)
    exact = plain_loop(None, make(4096), cubic)
    assert v.under_resolved and "does not converge" in v.reason and v.padding == 8 and len(calls) == 8
    # the moves double (6.1e-8, 1.2e-7, 2.4e-7: the form drifts by 1e-6 of itself a call), so no bound
    # holds; the set is flagged whatever its estimate, and the value is within the drift of 8 calls
    assert v.resolution == 1.0 and 0 < v.error and abs(v.value - exact) <= 8e-6 * abs(exact)


def test_a_closed_one_form_is_zero_within_round_off_and_not_flagged():
    """dϑ = 0: I₁ = 0 exactly.  Padded values that move by their last bits are round-off, not a set that
    is not resolved (a relative error of a zero would be infinite)."""
    q = band_limited_loop(64, [0.5, 0.2, 0.1, 0.3], 8, 0.7, [0.1] * 4, 2)
    closed = lambda x: np.stack([x[:, 0], x[:, 3], 2 * x[:, 2], x[:, 1]], -1)     # ∇(q0²/2 + q1 q3 + q2²)
    v = invariants.first_invariant(q, closed)
    assert abs(v.value) <= v.error < 1e-14 and not v.under_resolved
