"""Spectral convergence of I₁ and I₂ against closed-form values (docs/invariants.md).

    python scripts/studies/invariants_convergence.py

Loop: the paper's guiding-centre loop and the same loop advected by the exact flow
to t = 500 (rotation by 2μt/(1 + r²), strongly sheared).  Surface: the paper's
surface, and advected to t = 500.  The reference is the value at t = 0 computed
in closed form with sympy (the exact flow preserves it).
"""
from pathlib import Path

import numpy as np
import sympy

import integrators
import invariants
from invariants.samples import band_limited_loop

ROOT = Path(__file__).resolve().parents[2]
GC = integrators.system("guiding_centre_symmetric")


def exact_values():
    t, s = sympy.symbols("tau sigma", real=True)
    R, pi = sympy.Rational, sympy.pi
    c, sn = sympy.cos(2 * pi * t), sympy.sin(2 * pi * t)
    q = [R(1, 2) * c, R(3, 10) * sn, R(1, 10) * sn, R(1, 2) + R(1, 20) * c]
    th = [e.subs(GC.params).subs(dict(zip(GC.q, q))) for e in GC.theta_expr]
    I1 = sympy.integrate(sympy.expand(sum(a * sympy.diff(b, t) for a, b in zip(th, q))), (t, 0, 1))
    x, y = R(1, 10) * (s - R(1, 2)), R(1, 10) * (t - R(1, 2))
    z = R(1, 10) * sympy.cos(2 * pi * s) * sympy.cos(2 * pi * t)
    u = R(1, 2) + R(1, 100) * sympy.sin(2 * pi * s) * sympy.sin(2 * pi * t)
    dens = (1 + x**2 + y**2) * (sympy.diff(x, s) * sympy.diff(y, t) - sympy.diff(y, s) * sympy.diff(x, t)) \
        + (sympy.diff(u, s) * sympy.diff(z, t) - sympy.diff(z, s) * sympy.diff(u, t))
    I2 = sympy.integrate(sympy.expand(dens), (s, 0, 1), (t, 0, 1))
    return sympy.N(I1, 30), sympy.N(I2, 30), I1, I2


def flow(q, t):
    return GC.exact_flow(q, t)


def issue_loop(N, issue):
    """The band-limited loops of issues 57 and 69 (invariants.samples.band_limited_loop): q with Fourier
    modes 1 … 20 only around the paper's loop's centre, ϑ(q)·q′ reaching mode 80."""
    scale, decay = ([0.05, 0.05, 0.05, 0.01], 0.7) if issue == 57 else ([0.02] * 4, 1.0)
    return band_limited_loop(N, [0.0, 0.0, 0.0, 0.5], 20, decay, scale)


def plain_loop(q):
    """The plain N-point sum: Parseval of ϑ at the samples against q (no padding, no monitor)."""
    from invariants import spectral
    return spectral.loop_pairing(GC.theta(q), q)


MONITOR_TEXT = (
    "The integrand ϑ(q)·q′ of I₁ is a product: its modes reach several times further than q's, so a loop "
    "whose q is resolved can give an aliased I₁ (issue 57), and a model of the aliasing from the sampled "
    "spectra cannot see modes the sampling has already folded back (issue 69: 64 points wrong by 1e-6 read "
    "resolved). The monitor therefore measures the aliasing instead of modelling it. Where the one-form's "
    "samples and the set's both have their top eighth of modes at round-off (64 ulps of their peak: the "
    "modes beyond the samples fold onto the top first), the N-point sum is exact and is the value. Else, "
    "where the set is resolved (its spectrum falls towards its top, `spectral.decaying`, or its top eighth "
    "is within 1e-10 of its peak), its trigonometric interpolant is the loop, so ϑ evaluated on the "
    "interpolant at 2N, 4N, … points (`spectral.loop_shifted`: the samples shifted by a fraction of a step; "
    "the 2N-point sum is the mean of the N-point sums at phases 0 and ½) converges to the exact value. The "
    "value reported is the sum on the finest level, reached when it moves by less than 1e-13 of itself or "
    "within twice its round-off, at most 8N (`InvariantValue.padding`); its `error` is the last move. "
    "**The assumption**: each doubling of the points at least halves the sum's error, so the last move "
    "bounds the last value's error; from the third level on, where the moves fell by a ratio ρ ≤ ½, the "
    "error is move·ρ/(1 − ρ), the bound where every further doubling falls by ρ or more (exponentially "
    "converging aliasing does; an algebraic tail keeps a constant ratio). Where the moves do not halve "
    "(the points' own noise, a form that is not a function of the points) the error is twice the largest "
    "move, an estimate, and above 1e-10 of the value the set is flagged with that `reason`. What the set's "
    "top eighth of modes adds to the value is measured too, by the same sum on the set without them, "
    "where it could reach 1e-13 of the value: in the error where that top is a falling spectrum above "
    "round-off, in `roundoff` where it is a floor (at round-off, or flat: the points' own rounding and "
    "Newton's tolerance carried along the orbits, which more points do not lower). A set whose spectrum does "
    "not decay towards its top is read by its top modes, as before; one whose interpolant leaves the "
    "form's domain is summed on its samples, flagged with that reason. Surfaces are the same with "
    "Chebyshev interpolation to (2n − 1)² and (4n − 3)² points (grids that hold the given one): the "
    "integrand is a product of the derivatives and Ω(q), about twice q's degree, which Clenshaw–Curtis on "
    "n points does not integrate exactly, the canonical form included. The canonical form of a loop pairs "
    "two sets of samples, p and q: Parseval is exact for their interpolants, so it needs no padding; its "
    "error is what their top eighth adds (4π Σ k|p̂_k||q̂_k| over it) and the model of their modes beyond, "
    "and a p whose spectrum is flat at its top (a sampled ϑ(q) whose modes folded back) is flagged by its "
    "top modes. `resolution` is the error over |I| (0 where it is within twice the round-off), or the "
    "set's top modes where its spectrum does not decay. `roundoff` is 8 ulps of the size of the sum's "
    "terms plus the points' own rounding carried through the derivative (on a loop, 8 ulps of each "
    "coordinate as white noise paired with the form's modes; on a surface, 8 ulps of the largest "
    "coordinate over the set's extent, times n: a 1 mm patch at R = 2.5 is rounded at 1e-10 of its size).")


ADVECTED_NOTE = (
    "No value was called resolved and wrong. The values whose error exceeds their `error` unflagged are all "
    "advected loops of GLRK4 and GLRK5 (t ≥ 10,000, 128 and 256 points): errors 1.1e-12 to 2.2e-12, at most "
    "1.7 times the value's own `roundoff`. Their coordinate z has grown to 1.1e4 (z += u t) while I₁ is "
    "0.53, so the points are rounded at 1e-12 of I₁: the 256-point set's interpolant misses the other 256 "
    "points by 5.5e-12, 5e-16 of the coordinate, and the even and odd halves of the 512 differ from it "
    "by ±6e-13 at t = 10,000 (±1.7e-12 at t = 20,000). Flagged values that were right are mostly the "
    "canonical form, whose p samples a ϑ(q) with modes folded back (its flat top is read as such), and "
    "sets just short of their band, where the last move bounds the last value's error only by the "
    "error of the level before. Where a surface's top eighth is a falling spectrum, what the modes beyond "
    "the samples add is taken from the top two eighths' measured effects, E1·r/(1 − r) with r = E1/E2 ≤ ½; "
    "the canonical surface keeps E1 itself, since its p is samples whose folded modes the ratio does not "
    "see (with the ratio it missed one surface of the study, wrong by 9.4e-10; without it, it over-flags "
    "point_vortices' canonical I₂ at two outputs, docs/scenes.md).")


def monitor_section():
    """The monitor against the value's real error where q alone looks resolved (issues 57 and 69)."""
    from invariants import spectral
    out = ["", "## The resolution monitor bounds the value", "", MONITOR_TEXT, "",
           "**Band-limited loops** (q with Fourier modes 1 … 20, guiding_centre_symmetric, noncanonical; "
           "against the plain sum on 8,192 points; tests/test_monitor_bound.py). 'plain' is the N-point sum "
           "of the samples, the value before issue 69:", "",
           "| loop | N | plain sum's error | value's error | monitor | padding | q's top modes |",
           "|---|---|---|---|---|---|---|"]
    for issue in (57, 69):
        ref = plain_loop(issue_loop(8192, issue))
        for N in (44, 48, 56, 64, 72, 80, 96, 128, 160, 1024):
            q = issue_loop(N, issue)
            v = invariants.first_invariant(q, "noncanonical", system=GC)
            out.append(f"| issue {issue} | {N} | {abs(plain_loop(q) - ref) / abs(ref):.1e} | "
                       f"{abs(v.value - ref) / abs(ref):.1e} | {v.resolution:.1e}"
                       f"{' (flagged)' if v.under_resolved else ''} | {v.padding} | {spectral.loop_tail(q):.1e} |")
    lv = integrators.system("lotka_volterra_2d")

    def patch(S, T):
        s, t = S - 0.5, T - 0.5
        return np.stack([0.6 + 0.8 * s + 0.2 * t * t, 0.6 + 0.8 * t + 0.3 * s * t], axis=-1)

    def plain_surface(S):
        qs, qt = spectral.chebyshev_derivative(S, 0), spectral.chebyshev_derivative(S, 1)
        return float(spectral.surface_integral(np.einsum("...i,...ij,...j->...", qs, lv.Omega(S), qt)))
    out += ["", "**A polynomial surface** (degree 2 in σ and τ) in Lotka–Volterra's Ω = 1/(xy), against the plain "
            "sum on 257²:", "",
            "| n_σ = n_τ | plain sum's error | value's error | monitor | padding | the set's top coefficients |",
            "|---|---|---|---|---|---|"]
    ref = plain_surface(invariants.surface(patch, 257, 257))
    for n in (8, 10, 12, 16, 20, 24, 32):
        S = invariants.surface(patch, n, n)
        v = invariants.second_invariant(S, "noncanonical", system=lv)
        out.append(f"| {n} | {abs(plain_surface(S) - ref) / abs(ref):.1e} | {abs(v.value - ref) / abs(ref):.1e} | "
                   f"{v.resolution:.1e}{' (flagged)' if v.under_resolved else ''} | {v.padding} | "
                   f"{spectral.surface_tail(S):.1e} |")
    out += monitor_study()
    out += ["", "Not covered: the points' own noise (Newton's tolerance carried along the orbits). On a 1 mm "
            "surface of guiding_centre_tokamak after 710 GLRK2-standard steps, I₂ on 24², 47² and 93² "
            "Chebyshev points differs by 1.8e-9 and 8e-10 of its value, halving with n (the noise averages "
            "out like 1/n, it is no spectrum): the spread of a value between sample sets of a non-symplectic "
            "run, at that level, is the orbits', not the quadrature's, and no monitor of one set sees it."]
    return out


def monitor_study():
    """The study's table and the cost, from the files scripts/studies/invariants_monitor.py wrote."""
    import json
    out = []
    path = ROOT / "docs" / "figures" / "invariants_monitor.json"
    if path.exists():
        sys_path = str(ROOT / "scripts" / "studies")
        import sys
        sys.path.insert(0, sys_path)
        from invariants_monitor import markdown
        got = json.loads(path.read_text())
        out += ["", "### The monitor on thousands of sets", "",
                f"`{got['command']}` ({got['wall_s'] / 60:.0f} min on the 2-core development machine): random "
                "band-limited loops (modes 2 … 24, decay 0.6 … 1, amplitude 0.1 … 1 of the scale, N from about "
                "2× to 16× the band) and polynomial surfaces (degree 1 … 8, n from about the degree to 6×) on "
                "four systems, every form, and the paper's loop (512 points) advected 2,000 steps of h = 10 by "
                "every GLRK1–6 and SRK3 pair with every projection, its sets of every 2nd … 16th point against "
                "the 512. 'called resolved, wrong': not flagged and wrong by more than 1e-10 (the goal: 0); "
                "'error > estimate': the error above the value's own `error` (not flagged and above 1e-12; "
                "flagged, where the assumption failed; at round-off, below 1e-12, where the reference's own "
                "round-off is of the same size); 'flagged, right': flagged though within 1e-10; 'reading > "
                "100× error': the monitor's reading (`resolution`) more than 100 times the error, the error "
                "floored at the value's `roundoff` (and 1e-15): how far the monitor errs large.", "",
                markdown(got["table"], got["skipped"]), "", ADVECTED_NOTE]
    cost = ROOT / "docs" / "figures" / "invariants_monitor_cost.json"
    if cost.exists():
        got = json.loads(cost.read_text())
        out += ["", "**Cost** (`python scripts/studies/invariants_monitor.py --cost --json FILE`, run with each "
                "version's package on the path, the same machine one after the other; the best of 20 calls; "
                f"{got['note']}):", "",
                "| set | plain sum | monitor before (" + got["before"] + ") | monitor now | now / plain | "
                "now / before |",
                "|---|---|---|---|---|---|"]
        for b, a in zip(got["rows_before"], got["rows_now"]):
            out.append(f"| {a['set']} | {a['plain'] * 1e3:.3f} ms | {b['monitor'] * 1e3:.3f} ms | "
                       f"{a['monitor'] * 1e3:.3f} ms | {a['monitor'] / a['plain']:.1f} | "
                       f"{a['monitor'] / b['monitor']:.1f} |")
    return out


PERIODS = """
## Periodic coordinates: `period=`

`first_invariant(q, form, …, period=P)` and `second_invariant(…, period=P)` take coordinates that are angles or lie on a periodic domain: P is one number (every coordinate) or a 1-D list of one entry per coordinate, 0 or None where a coordinate is not periodic; anything else (a negative, a NaN, an array of two dimensions) is refused in one line. The samples may be wrapped (into [0, P) or anywhere): the differences between neighbours are taken into [−P/2, P/2) before the spectral derivative, and a loop that winds m times around coordinate i adds m·P_i·mean(A_i) exactly (docs/conventions.md, "Periodic coordinates"). A one-form (two-form) that is not periodic there is refused.

A period is trusted only where the samples can tell a wrap from a step: a periodic coordinate that steps by a quarter of its period or more between neighbouring samples (a period far smaller than the set, such as `period=1e-12` on a unit circle, or a set far too coarse) makes the value under-resolved (resolution 1), with `reason` naming the coordinate, its step and its period. Before, the unit circle with `period=1e-12` gave I₁ = −6e-12 marked resolved where the value is −π (tests/test_audit_edges.py). `audit_map` refuses such a period before it runs, against the loop it builds; without a period, a coordinate that jumps by more than half its extent between neighbours is under-resolved with that reason (a wrapped angle).

An invariant whose value is zero within its own error (|I| ≤ `error`, round-off included: I₁ of a closed one-form, dϑ = 0) has no relative error. A run records such an I(0) in the file's root attribute `absolute_invariants` (e.g. `"I1/noncanonical"`), and its error is then |I(t) − I(0)| in the summary (which says so), the plots, the growth laws and `PairRun.relative_error`.
"""   # the conventions of period= and of exact zeros (no measurement: the tests hold them)


def main():
    I1x, I2x, I1s, I2s = exact_values()
    I1x, I2x = float(I1x), float(I2x)
    lines = ["# Invariants: spectral convergence", "",
             "Produced by `python scripts/studies/invariants_convergence.py`. Exact values (sympy): "
             f"I₁ = `{sympy.simplify(I1s)}` = {I1x:.17g} for the paper's loop, "
             f"I₂ = `{sympy.simplify(I2s)}` = {I2x:.17g} for the paper's surface "
             "(guiding_centre_symmetric, B₀ = 1, μ = 0.01). 'advected' = the same set moved by the exact flow "
             "to t = 500 (differential rotation by 2μt/(1 + r²) about z, z += u t), which leaves both values "
             "unchanged. Columns: relative error |I − I_exact|/|I_exact| and the resolution monitor "
             "(the value's error bound over |I|: below, 'The resolution monitor bounds the value'; flagged above "
             "1e-10).", "",
             "## I₁ on the loop (Fourier coefficients, Parseval)", "",
             "| N | error t=0 | monitor t=0 | error advected | monitor advected |", "|---|---|---|---|---|"]
    for N in (8, 16, 32, 64, 128, 256, 512, 1000, 2000):
        q = invariants.loop("guiding_centre", N)
        a = invariants.first_invariant(q, "noncanonical", system=GC)
        b = invariants.first_invariant(flow(q, 500.0), "noncanonical", system=GC)
        lines.append(f"| {N} | {abs(a.value - I1x) / abs(I1x):.1e} | {a.resolution:.1e} | "
                     f"{abs(b.value - I1x) / abs(I1x):.1e} | {b.resolution:.1e}{' (flagged)' if b.under_resolved else ''} |")
    lines += ["", "## I₂ on the surface (Chebyshev, Clenshaw–Curtis)", "",
              "| n_σ = n_τ | error t=0 | monitor t=0 | error advected | monitor advected |", "|---|---|---|---|---|"]
    for n in (8, 12, 16, 20, 24, 32, 48, 64, 100):
        S = invariants.surface("guiding_centre", n, n)
        a = invariants.second_invariant(S, "noncanonical", system=GC)
        b = invariants.second_invariant(flow(S, 500.0), "noncanonical", system=GC)
        lines.append(f"| {n} | {abs(a.value - I2x) / abs(I2x):.1e} | {a.resolution:.1e}{' (flagged)' if a.under_resolved else ''} | "
                     f"{abs(b.value - I2x) / abs(I2x):.1e} | {b.resolution:.1e}{' (flagged)' if b.under_resolved else ''} |")
    lines += monitor_section()
    lines += ["", "## Round-off of I₁: Parseval against the trapezoidal rule of the FFT derivative", "",
              "first_invariant sums conj(Â_k)·2πik q̂_k over the Fourier coefficients (spectral.loop_pairing) "
              "instead of applying the trapezoidal rule to A·(inverse FFT of 2πik q̂_k); the two are the same "
              "number in exact arithmetic. With the trapezoid, the advected loop above read 2.5e-15 to 5.9e-15 "
              "for N = 64 to 2000; with Parseval it reads 0 to 8.4e-16. On PoincareInvariants.jl's 4-D Hénon "
              "map (the unit circle in both (qᵢ, pᵢ) planes, two maps, I₁ = 2π exactly, a trigonometric "
              "polynomial of degree 16), |I₁ − 2π| over 20 phases of the sampling "
              "(`python scripts/studies/invariants_roundoff.py`):", ""]
    from invariants_roundoff import errors
    lines += ["| N | Parseval: median | worst | trapezoid of FFT derivative: median | worst |", "|---|---|---|---|---|"]
    for N in (250, 500, 1000, 2000, 4000, 8000, 16000):
        new, old = errors(N, np.random.default_rng(0).random(20))
        lines.append(f"| {N:,} | {np.median(new):.1e} | {new.max():.1e} | {np.median(old):.1e} | {old.max():.1e} |")
    lines += ["", "Parseval is 1.8× to 6× better in the median and grows with N in neither form: the rest is "
              "the round-off of the points themselves (their coordinates reach 184 after two maps, while I₁ "
              "is 2π). PoincareInvariants.jl's own Hénon test, on I₂ with finite differences, allows 5e-13 "
              "after one map and 5e-12 after two."]
    text = "\n".join(lines) + "\n" + PERIODS
    print(text)
    (ROOT / "docs" / "invariants.md").write_text(text)


if __name__ == "__main__":
    main()
