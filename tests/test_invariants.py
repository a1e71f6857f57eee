"""Invariants: closed-form values, Stokes, canonical = noncanonical on Δ, invariance under an exact flow."""
import numpy as np
import pytest
import sympy

import integrators
import invariants
from invariants import spectral

GC = integrators.system("guiding_centre_symmetric")
t_, s_ = sympy.symbols("tau sigma", real=True)


def exact_loop_integral(system, qexpr):
    """∮ ϑ(q(τ))·q'(τ) dτ in closed form (sympy)."""
    subs = dict(zip(system.q, qexpr))
    th = [sympy.sympify(e).subs(system.params).subs(subs) for e in system.theta_expr]
    f = sum(a * sympy.diff(b, t_) for a, b in zip(th, qexpr))
    return sympy.integrate(sympy.expand(sympy.simplify(f)), (t_, 0, 1))


def rel(a, b):
    return abs(a - b) / abs(b)


def test_ellipse_area():
    x, y = sympy.symbols("x y")
    area_form = integrators.system_from([-y / 2, x / 2], (x**2 + y**2) / 2, [x, y])
    q = invariants.loop("ellipse", 64, d=2, radii=(1.3, 0.4), center=(0.2, -0.7))
    I1 = invariants.first_invariant(q, "noncanonical", system=area_form)
    assert rel(I1.value, np.pi * 1.3 * 0.4) <= 1e-14 and not I1.under_resolved
    S = invariants.surface("rectangle", 8, 8, d=2, size=(1.3, 0.4))
    assert rel(invariants.second_invariant(S, "noncanonical", system=area_form).value, 1.3 * 0.4) <= 1e-14


def test_paper_loop_and_surface_at_t0_closed_form():
    c, s = sympy.cos(2 * sympy.pi * t_), sympy.sin(2 * sympy.pi * t_)
    R = sympy.Rational
    loop_expr = [R(1, 2) * c, R(3, 10) * s, R(1, 10) * s, R(1, 2) + R(1, 20) * c]
    exact1 = float(exact_loop_integral(GC, loop_expr))
    I1 = invariants.first_invariant(invariants.loop("guiding_centre", 2000), "noncanonical", system=GC)
    assert rel(I1.value, exact1) <= 1e-13
    # surface: Ω̄ has only Ω̄_xy = B0(1 + x² + y²) and Ω̄_uz = 1; x = r0(σ−½), y = r0(τ−½)
    r0, rz, u1 = R(1, 10), R(1, 10), R(1, 100)
    x, y = r0 * (s_ - R(1, 2)), r0 * (t_ - R(1, 2))
    z = rz * sympy.cos(2 * sympy.pi * s_) * sympy.cos(2 * sympy.pi * t_)
    u = R(1, 2) + u1 * sympy.sin(2 * sympy.pi * s_) * sympy.sin(2 * sympy.pi * t_)
    dens = (1 + x**2 + y**2) * (sympy.diff(x, s_) * sympy.diff(y, t_) - sympy.diff(y, s_) * sympy.diff(x, t_)) \
        + (sympy.diff(u, s_) * sympy.diff(z, t_) - sympy.diff(z, s_) * sympy.diff(u, t_))
    exact2 = float(sympy.integrate(sympy.expand(dens), (s_, 0, 1), (t_, 0, 1)))
    I2 = invariants.second_invariant(invariants.surface("guiding_centre", 100, 100), "noncanonical", system=GC)
    assert rel(I2.value, exact2) <= 1e-13


@pytest.mark.slow
def test_nonplanar_loop_on_point_vortices_closed_form():
    pv = integrators.system("point_vortices")
    c, s = sympy.cos(2 * sympy.pi * t_), sympy.sin(2 * sympy.pi * t_)
    R = sympy.Rational
    expr = [1 + R(1, 5) * c, R(1, 10) + R(1, 5) * s * c, 1 + R(1, 10) * sympy.sin(4 * sympy.pi * t_), -R(1, 10) + R(1, 5) * s]
    exact = float(exact_loop_integral(pv, expr))
    f = sympy.lambdify(t_, expr, "numpy")
    q = invariants.loop(lambda tau: np.stack([np.broadcast_to(v, tau.shape) for v in f(tau)], axis=1), 256)
    assert rel(invariants.first_invariant(q, "noncanonical", system=pv).value, exact) <= 1e-13


def disk_surface(n_sigma, n_tau, deform=0.25):
    """A strongly deformed disk in (x, y, z, u): its σ = 1 edge is a smooth closed loop."""
    def f(S, T):
        a = 2 * np.pi * T
        x = 0.4 * S * np.cos(a) + deform * (S * np.sin(a)) ** 2
        y = 0.3 * S * np.sin(a) + deform * S**3 * np.cos(a) * np.sin(a)
        z = 0.2 * S * np.sin(a + 0.3) + 0.1 * S**2 * np.cos(2 * a)
        u = 0.5 + 0.1 * S * np.cos(a) + 0.05 * S**2 * np.sin(3 * a)
        return np.stack([x, y, z, u], axis=-1)
    return f


def lam_field(S, T):
    a = 2 * np.pi * T
    return np.stack([0.3 * S * np.cos(a), 0.2 * S * np.sin(2 * a), 0.1 + 0.2 * S * np.sin(a), 0.3 * S**2 * np.cos(a)], axis=-1)


@pytest.mark.parametrize("system", ["guiding_centre_symmetric", "guiding_centre_tokamak"])
def test_stokes_noncanonical_and_corrected(system):
    sy = integrators.system(system)
    shift = np.array([2.5, 0.0, 0.0, 0.0]) if system == "guiding_centre_tokamak" else 0.0
    f = disk_surface(64, 128)
    S = f(*invariants.surface_parameters(64, 128)) + shift
    tau = invariants.loop_parameters(512)
    edge = f(np.ones_like(tau), tau) + shift
    lamS = lam_field(*invariants.surface_parameters(64, 128))
    lamE = lam_field(np.ones_like(tau), tau)
    I2 = invariants.second_invariant(S, "noncanonical", system=sy)
    I1 = invariants.first_invariant(edge, "noncanonical", system=sy)
    assert abs(I2.value - I1.value) <= 1e-12 * abs(I1.value)
    h = 2.0
    I2c = invariants.second_invariant(S, "corrected", system=sy, lam=lamS, h=h)
    I1c = invariants.first_invariant(edge, "corrected", system=sy, lam=lamE, h=h)
    assert abs(I2c.value - I1c.value) <= 1e-12 * abs(I1c.value)
    # the mixed-term sign printed in eq:symplectic_projection_two_form breaks Stokes
    I2p = invariants.second_invariant(S, "corrected", system=sy, lam=lamS, h=h, paper_sign=True)
    assert abs(I2p.value - I1c.value) > 1e-6 * abs(I1c.value)


def test_canonical_equals_noncanonical_on_the_constraint():
    q = invariants.loop("guiding_centre", 500)
    a = invariants.first_invariant(q, "noncanonical", system=GC).value
    b = invariants.first_invariant(q, "canonical", p=GC.theta(q)).value
    assert abs(a - b) <= 1e-15 * abs(a)
    S = invariants.surface("guiding_centre", 40, 40)
    a = invariants.second_invariant(S, "noncanonical", system=GC).value
    b = invariants.second_invariant(S, "canonical", p=GC.theta(S)).value
    assert abs(a - b) <= 1e-13 * abs(a)


def exact_gc_flow(q, t):
    return GC.exact_flow(q, t)


def test_exact_flow_is_the_vector_field(rng):
    q = np.array([0.4, -0.2, 0.1, 0.5]) + 0.1 * rng.standard_normal((5, 4))
    dt = 1e-6
    v = (exact_gc_flow(q, dt) - exact_gc_flow(q, -dt)) / (2 * dt)
    assert np.allclose(v, GC.vector_field(q), rtol=1e-8, atol=1e-9)


@pytest.mark.parametrize("t", [0.0, 100.0, 500.0])
def test_invariants_constant_under_the_exact_flow(t):
    q = invariants.loop("guiding_centre", 2000)
    S = invariants.surface("guiding_centre", 100, 100)
    I1_0 = invariants.first_invariant(q, "noncanonical", system=GC).value
    I2_0 = invariants.second_invariant(S, "noncanonical", system=GC).value
    I1 = invariants.first_invariant(exact_gc_flow(q, t), "noncanonical", system=GC)
    I2 = invariants.second_invariant(exact_gc_flow(S, t), "noncanonical", system=GC)
    assert abs(I1.value - I1_0) <= 1e-13 * abs(I1_0)
    assert abs(I2.value - I2_0) <= 1e-13 * abs(I2_0)


def test_resolution_monitor_flags_an_under_resolved_loop():
    q = exact_gc_flow(invariants.loop("guiding_centre", 64), 20000.0)  # strongly wound
    assert invariants.first_invariant(q, "noncanonical", system=GC).under_resolved
    assert not invariants.first_invariant(invariants.loop("guiding_centre", 64), "noncanonical", system=GC).under_resolved


@pytest.mark.parametrize("shape,say", [((2, 64), "got 2; given transposed"), ((4, 2), "got 4 (the layout is (N, d)"),
                                       ((7, 3), "at least 8 points")])
def test_a_loop_of_too_few_points_or_transposed_is_refused(shape, say):
    q = np.ones(shape)
    with pytest.raises(ValueError, match=r"loop q has shape .*" + say.replace("(", r"\(").replace(")", r"\)")):
        invariants.first_invariant(q, "canonical", p=q)
    S = np.ones((8, 5, 2))
    with pytest.raises(ValueError, match=r"surface q has shape \(8, 5, 2\): at least 8 points"):
        invariants.second_invariant(S, "canonical", p=S)


def test_chebyshev_points_are_chebpys_bit_for_bit():
    from chebpy.algorithms import chebpts2
    for n in list(range(1, 40)) + [100, 185, 913]:
        assert np.array_equal(spectral.chebpts2(n), chebpts2(n)), n


def test_dct_matches_chebpy_and_weights_integrate_polynomials(rng):
    from chebpy.algorithms import vals2coeffs2
    v = rng.standard_normal(17)
    assert np.allclose(spectral.chebyshev_coefficients(v, 0), vals2coeffs2(v), atol=1e-15)
    x = spectral.chebyshev_points(17)
    w = spectral.clenshaw_curtis_weights(17)
    for k in range(17):
        assert abs(w @ x**k - 1 / (k + 1)) < 1e-15
    assert np.allclose(spectral.chebyshev_derivative(x**5, 0), 5 * x**4, atol=1e-13)


def test_fft_derivative_and_plan_reuse():
    tau = invariants.loop_parameters(33)
    f = np.stack([np.sin(2 * np.pi * 3 * tau), np.cos(2 * np.pi * tau)], axis=1)
    df = spectral.loop_derivative(f)
    assert np.allclose(df[:, 0], 6 * np.pi * np.cos(6 * np.pi * tau), atol=1e-12)
    n_plans = len(spectral._PLANS)
    spectral.loop_derivative(f)
    assert len(spectral._PLANS) == n_plans


def test_first_invariant_in_fourier_space_has_less_round_off():
    """The unit circle in both (qᵢ, pᵢ) planes after two Hénon maps: I₁ = ∮ p·dq = 2π exactly (the
    loop is a trigonometric polynomial of degree 16, resolved at N = 1000).  Over 20 phases of the
    sampling, Parseval's sum (spectral.loop_pairing, what first_invariant computes) against the
    trapezoidal rule of p·(inverse-FFT dq/dτ), measured: median 4.7e-13 against 2.8e-12, worst
    1.6e-12 against 9.1e-12."""
    from invariants.samples import henon_loop      # the loop of the docs' table (scripts/studies/invariants_roundoff.py)
    new, old = [], []
    for phase in np.random.default_rng(0).random(20):
        z = henon_loop(1000, phase)
        new.append(abs(invariants.first_invariant(z[:, :2], "canonical", p=z[:, 2:]).value - 2 * np.pi))
        trapezoid = spectral.loop_integral(np.sum(z[:, 2:] * spectral.loop_derivative(z)[:, :2], axis=1))
        old.append(abs(trapezoid - 2 * np.pi))
    assert np.median(new) < np.median(old) / 3 and max(new) < max(old) / 3
    assert np.median(new) < 7e-13 and max(new) < 2.5e-12


def test_loop_pairing_is_the_trapezoidal_rule_of_the_spectral_derivative(rng):
    """Same number up to round-off, for odd and even N."""
    for N in (33, 64):
        tau = invariants.loop_parameters(N)
        a = np.stack([np.cos(2 * np.pi * tau) + 0.3 * np.sin(6 * np.pi * tau), np.sin(4 * np.pi * tau)], axis=1)
        b = np.stack([np.sin(2 * np.pi * tau), np.cos(2 * np.pi * tau) ** 3], axis=1)
        ref = spectral.loop_integral(np.sum(a * spectral.loop_derivative(b), axis=1))
        assert abs(spectral.loop_pairing(a, b) - ref) < 1e-14 * 10


@pytest.mark.parametrize("bad,msg", [(dict(form="magic"), "unknown form"), (dict(form="canonical"), "needs p"),
                                     (dict(form="corrected"), "needs lam")])
def test_bad_arguments(bad, msg):
    with pytest.raises(ValueError, match=msg):
        invariants.first_invariant(invariants.loop("guiding_centre", 16), system=GC, **bad)


# -- forms of the user's, and invariants along a solution ------------------------------------------

def test_a_user_one_form_gives_the_enclosed_area():
    """∮ (−y/2 dx + x/2 dy) over a circle of radius r is π r² (to 1e-14), and ϑ of a system given as
    a callable reproduces the noncanonical form bit for bit."""
    r = 0.3
    q = invariants.loop("ellipse", 64, d=2, radii=(r, r))
    v = invariants.first_invariant(q, lambda x: np.stack([-x[:, 1] / 2, x[:, 0] / 2], axis=1))
    assert abs(v.value - np.pi * r * r) <= 1e-14 * np.pi * r * r and not v.under_resolved
    gc = integrators.system("guiding_centre_symmetric")
    loop = invariants.loop("guiding_centre", 200)
    assert invariants.first_invariant(loop, gc.theta).value == invariants.first_invariant(loop, "noncanonical",
                                                                                          system=gc).value


def test_a_user_two_form_and_its_checks():
    gc = integrators.system("guiding_centre_symmetric")
    S = invariants.surface("guiding_centre", 16, 16)
    # the same integrand by numpy's contraction and by the compiled pass: the same value to round-off
    mine, compiled = invariants.second_invariant(S, gc.Omega), invariants.second_invariant(S, "noncanonical", system=gc)
    assert abs(mine.value - compiled.value) <= 1e-14 * abs(compiled.value)
    assert mine.padding == compiled.padding and mine.under_resolved == compiled.under_resolved
    with pytest.raises(ValueError, match="two-form must return shape"):
        invariants.second_invariant(S, gc.theta)
    with pytest.raises(ValueError, match="one-form .* failed: ZeroDivisionError"):
        invariants.first_invariant(invariants.loop("guiding_centre", 16), lambda x: 1 / 0)


def test_invariants_along_a_solution_keep_the_sets_shape():
    """integrate a surface (nσ, nτ, d) and a loop: the solution keeps their shapes, and
    invariants.along gives I₂ / I₁ at every saved time, equal to the one-by-one values; GLRK2 with the
    symmetric projection keeps the noncanonical I₂ to round-off on guiding_centre_symmetric."""
    gc = integrators.system("guiding_centre_symmetric")
    S = invariants.surface("guiding_centre", 20, 20)           # (the default scene's surface: resolved)
    sol = integrators.integrate(gc, S, tableau="GLRK2", projection="symmetric", h=10.0, steps=30, save_every=10)
    assert sol.q.shape == (4, 20, 20, 4) and sol.breakdown_time.shape == (20, 20)
    series = invariants.along(sol, "noncanonical", system=gc)
    assert series.t.tolist() == [0.0, 100.0, 200.0, 300.0]
    assert series.value[2] == invariants.second_invariant(sol.q[2], "noncanonical", system=gc).value
    assert np.max(series.relative_error) < 1e-12 and not series.under_resolved.any()
    loop = invariants.loop("guiding_centre", 64)
    sol1 = integrators.integrate(gc, loop, tableau="GLRK1", projection="none", h=10.0, steps=20, save_every=10)
    s1 = invariants.along(sol1, "canonical")
    assert s1.value.shape == (3,) and np.max(s1.relative_error) < 1e-12


@pytest.mark.parametrize("sysname", ["guiding_centre_symmetric", "point_vortices"])
def test_forms_computed_together_are_bitwise_the_forms_alone_and_match_the_numpy_route(sysname, rng):
    """second_invariants shares transforms and one compiled pass of ϑ_q, ϑ_qq between the forms:
    each value and resolution is bitwise the form computed alone; the compiled integrands agree with
    the numpy route (Ω̄ and corrected_omega contracted by einsum) to round-off."""
    from invariants.forms import second_invariants

    class Duck:                       # no generated point functions: the numpy route
        def __init__(self, sy):
            self.sy = sy

        def Omega(self, q):
            return self.sy.Omega(q)

        def dtheta(self, q):
            return self.sy.dtheta(q)

        def ddtheta(self, q):
            return self.sy.ddtheta(q)

    sy = integrators.system(sysname)
    S = invariants.surface("rectangle", 24, 20, center=sy.defaults["q0"], size=(0.2, 0.1), plane=(0, 2))
    S = S * (1 + 1e-3 * rng.standard_normal(S.shape))
    p, lam, h = sy.theta(S) + 1e-3 * rng.standard_normal(S.shape), 1e-2 * rng.standard_normal(S.shape), 0.3
    together = second_invariants(S, list(invariants.FORMS), system=sy, p=p, lam=lam, h=h)
    numpy_route = second_invariants(S, ["noncanonical", "corrected"], system=Duck(sy), lam=lam, h=h)
    for form in invariants.FORMS:
        alone = invariants.second_invariant(S, form, system=sy, p=p, lam=lam, h=h)
        assert together[form].value == alone.value and together[form].resolution == alone.resolution, form
    for form in ("noncanonical", "corrected"):
        assert abs(together[form].value - numpy_route[form].value) <= 1e-13 * max(1.0, abs(together[form].value))
    loop = S[:, 0]
    ones = invariants.forms.first_invariants(loop, list(invariants.FORMS), system=sy, p=p[:, 0], lam=lam[:, 0], h=h)
    for form in invariants.FORMS:
        alone = invariants.first_invariant(loop, form, system=sy, p=p[:, 0], lam=lam[:, 0], h=h)
        assert ones[form].value == alone.value and ones[form].resolution == alone.resolution, form


# -- periodic coordinates (issue 53) ----------------------------------------------------------------

def _rotating_loop(n, shift=1.0):
    """A pendulum loop that winds once around the angle x (wrapped into [0, 2π)) with
    p = 0.5 + 0.2 cos 2πτ: I₁ = ∮ p dx = 2π·0.5 + 0.06π exactly."""
    tau = np.arange(n) / n
    x = (2 * np.pi * tau + 0.3 * np.sin(2 * np.pi * tau) + shift) % (2 * np.pi)
    return x[:, None], (0.5 + 0.2 * np.cos(2 * np.pi * tau))[:, None], np.pi + 0.06 * np.pi


@pytest.mark.parametrize("n", [64, 256])
def test_a_wrapped_angle_gives_the_closed_form_with_its_period_and_is_flagged_without(n):
    """∮ p dx on a loop that winds once around a wrapped angle: with period=2π the closed form within
    1e-13 (measured: exact), not flagged; without, the value is wrong (the study's −0.539·2π kind) and the set is
    under-resolved with a reason naming the jump; a librating loop across the cut likewise."""
    x, p, exact = _rotating_loop(n)
    for period in (2 * np.pi, [2 * np.pi]):
        v = invariants.first_invariant(x, "canonical", p=p, period=period)
        assert abs(v.value - exact) <= 1e-13 * exact and not v.under_resolved and v.reason == ""
    bad = invariants.first_invariant(x, "canonical", p=p)
    assert abs(bad.value - exact) > 0.1 and bad.under_resolved and "coordinate 0 jumps" in bad.reason
    tau = np.arange(n) / n
    xl, pl = ((0.5 * np.cos(2 * np.pi * tau)) % (2 * np.pi))[:, None], (0.5 * np.sin(2 * np.pi * tau))[:, None]
    v = invariants.first_invariant(xl, "canonical", p=pl, period=2 * np.pi)
    assert abs(v.value + 0.25 * np.pi) <= 1e-13 and not v.under_resolved
    assert invariants.first_invariant(xl, "canonical", p=pl).under_resolved


def test_periods_per_coordinate_forms_and_refusals():
    """One entry per coordinate (None where not periodic); a user one-form periodic in x gives the
    same value as canonical; one that is not periodic is refused in one line naming the coordinate;
    bad periods are refused; a loop that does not jump needs no period and is not flagged."""
    x, p, exact = _rotating_loop(128)
    q = np.concatenate([x, p], axis=1)
    periodic = lambda q: np.stack([q[..., 1], np.zeros_like(q[..., 0])], axis=-1)
    v = invariants.first_invariant(q, periodic, period=[2 * np.pi, None])
    assert abs(v.value - exact) <= 1e-13 * exact
    assert invariants.first_invariant(q, periodic, period=[2 * np.pi, 0]).value == v.value
    with pytest.raises(ValueError, match=r"not periodic in coordinate 0 \(period 6\.28"):
        invariants.first_invariant(q, lambda q: periodic(q) + q * [1.0, 0.0], period=[2 * np.pi, None])
    for bad in ([2 * np.pi], [-1.0, None], [np.inf, None], ["2pi", None]):
        with pytest.raises(ValueError, match="period"):
            invariants.first_invariant(q, periodic, period=bad)
    gc = integrators.system("guiding_centre_symmetric")
    loop = invariants.loop("guiding_centre", 128)
    v = invariants.first_invariant(loop, "noncanonical", system=gc)
    assert not v.under_resolved and v.reason == ""


def test_a_surface_across_the_cut_of_a_periodic_coordinate():
    """The canonical I₂ of the unit square x ∈ [2π − ½, 2π + ½) (wrapped), v ∈ [0, 1] (sheared):
    −1 (dp ∧ dq in the (σ, τ) orientation) with period=2π; flagged with a reason without."""
    S, T = invariants.surface_parameters(16, 16)
    x, v = ((2 * np.pi - 0.5 + S) % (2 * np.pi))[..., None], (T + 0.1 * S ** 2)[..., None]
    r = invariants.second_invariant(x, "canonical", p=v, period=2 * np.pi)
    assert abs(r.value + 1.0) <= 1e-13 and not r.under_resolved
    bad = invariants.second_invariant(x, "canonical", p=v)
    assert bad.under_resolved and "jumps" in bad.reason


def test_the_tail_models_of_narrow_spectra_are_the_numpy_paths_numbers():
    """spectral.tail_models reads a few columns' envelopes by a compiled loop: the same numbers, bit
    for bit, as the numpy path (segment maxima) for every K from 2 modes up, decaying and flat
    spectra, one and several columns, and a NaN where numpy's maximum keeps it."""
    from invariants import spectral
    rng = np.random.default_rng(0)
    for K1 in (3, 4, 5, 9, 33, 2049):
        for D in (1, 2, 5):
            A = np.abs(rng.standard_normal((K1, D))) * np.exp(-np.arange(K1))[:, None]
            B = np.abs(rng.standard_normal((K1, D)))
            if K1 > 5:
                A[K1 // 3, 0] = np.nan
            K = K1 - 1
            top = max(1, K - max(K // 8, 2))
            k1 = min(max(1, K // 2), top - 1) if top > 1 else 0
            k3 = min((k1 + top) // 2, top - 1) if top > 1 else 0
            for got, c in zip(spectral.tail_models([A, B]), (A, B)):
                want = spectral._tail(c, K, top, k1, k3, False, 0.5)
                assert got[0] == top and all(np.array_equal(x, y, equal_nan=True) for x, y in zip(got[1:], want))


def test_the_compiled_unwrap_of_a_loop_gives_the_numpy_formulas_bits():
    """invariants.forms._unwrap of a loop runs compiled in one pass; it must give the bits of the
    numpy formula it replaces (each difference d − P⌊d/P + ½⌋, summed in sequence from the first
    sample by cumsum), on loops with wraps, non-periodic coordinates and periods of any size."""
    from invariants import forms

    def reference(q, P):
        out = q.copy()
        j = np.flatnonzero(P)
        dx = np.diff(q[:, j], axis=0)
        dx = dx - P[j] * np.floor(dx / P[j] + 0.5)
        out[:, j] = np.concatenate([q[:1, j], q[:1, j] + np.cumsum(dx, axis=0)], axis=0)
        return out

    rng = np.random.default_rng(0)
    for _ in range(30):
        N, d = int(rng.integers(4, 2000)), int(rng.integers(1, 30))
        P = np.where(rng.random(d) < 0.6, rng.uniform(0.1, 10, d), 0.0)
        P[0] = P[0] or 1.0
        q = np.cumsum(rng.standard_normal((N, d)) * rng.uniform(0.01, 3), axis=0)
        q = np.where(P > 0, np.mod(q, np.where(P > 0, P, 1.0)), q)
        assert forms._unwrap(q, P, 0).tobytes() == reference(q, P).tobytes()
