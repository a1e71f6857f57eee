"""The resolution monitor as a bound (docs/invariants.md, "The monitor on thousands of sets").

Random band-limited loops and surfaces on four systems, every form (canonical, noncanonical,
corrected; I₁ and I₂), and loops advected by every GLRK1–6 and SRK3 pair with every projection: each
reported value against a reference on many more points, and its monitor.  Counted per system and
form: values called resolved whose error exceeds UNDER_RESOLVED (the goal: none), values whose
error exceeds their own ``error`` estimate, flagged values that were right, and readings
(``resolution``) more than 100 times the error (floored at the value's own ``roundoff``).

    python scripts/studies/invariants_monitor.py                       # the study (about 15 minutes)
    python scripts/studies/invariants_monitor.py --sets 20 --no-advected   # a quick look
    python scripts/studies/invariants_monitor.py --json docs/figures/invariants_monitor.json --markdown
    python scripts/studies/invariants_monitor.py --cost                # the monitor's cost (any version)
    PYTHONPATH=OLD_TREE python scripts/studies/invariants_monitor.py --cost --json old.json --version HASH
    python scripts/studies/invariants_monitor.py --cost --json docs/figures/invariants_monitor_cost.json \
        --before old.json --note "…"                                  # side by side

References: the plain sum (no padding, no monitor) on 8,192 points for loops and Clenshaw–Curtis on
129² points for surfaces, each checked against 16,384 points / 193² (a set whose reference moves by
more than 1e-14 of its value between the two is left out and counted).  For an advected loop the
reference is the same run's set of 512 points; its N-point sets are every 2nd … 16th point.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

import integrators
import invariants
from invariants import spectral
from invariants.forms import corrected_omega, one_form_coefficients

FORMS = ("canonical", "noncanonical", "corrected")
THRESHOLD = invariants.UNDER_RESOLVED
ROUNDOFF = 1e-12        # errors below this are the sums' and the references' round-off (the table says how many)
# system: (centre, the perturbation's scale per coordinate, h for the corrected form)
SYSTEMS = {
    "guiding_centre_symmetric": ([0.0, 0.0, 0.0, 0.5], [0.15, 0.15, 0.1, 0.03], 10.0),
    "lotka_volterra_2d": ([1.0, 1.0], [0.15, 0.15], 0.1),
    "point_vortices": ([1.0, 0.1, 1.0, -0.1], [0.03, 0.03, 0.03, 0.03], 0.1),
    "massless_charged_particle": ([1.0, 1.0], [0.1, 0.1], 0.2),
}
REF_LOOP, REF_SURFACE = 8192, 129


def _plain_loop(system, q, form, lam, h):
    """I₁ of a loop by the plain N-point sum (Parseval of the form's samples against q's)."""
    A, Al = one_form_coefficients(q, form, system, None, lam, h)
    v = spectral.loop_pairing(A, q)
    return v + spectral.loop_pairing(Al, lam) if Al is not None else v


def _plain_surface(system, S, form, lam, h):
    """I₂ by Clenshaw–Curtis on the surface's own points, the numpy route (Ω̄ or Ω_λ contracted)."""
    qs, qt = spectral.chebyshev_derivative(S, 0), spectral.chebyshev_derivative(S, 1)
    if form == "noncanonical":
        f = np.einsum("...i,...ij,...j->...", qs, system.Omega(S), qt)
    else:
        ls, lt = spectral.chebyshev_derivative(lam, 0), spectral.chebyshev_derivative(lam, 1)
        f = np.einsum("...i,...ij,...j->...", np.concatenate([qs, ls], -1), corrected_omega(system, S, lam, h),
                      np.concatenate([qt, lt], -1))
    return float(spectral.surface_integral(f))


def _record(kind, system, form, got, ref, plain, **extra):
    err = abs(got.value - ref) / abs(ref)
    return dict(kind=kind, system=system, form=form, error=err, alias=abs(plain - ref) / abs(ref),
                estimate=got.error / abs(got.value) if got.value else float("inf"), resolution=got.resolution,
                flagged=bool(got.under_resolved), padding=int(getattr(got, "padding", 1)), reason=got.reason,
                roundoff=got.roundoff, **extra)


def random_loops(name, count, rng, skipped):
    """Records of ``count`` random band-limited loops of one system, three forms each."""
    from invariants.samples import band_limited_loop
    system = integrators.system(name)
    centre, scale, h = SYSTEMS[name]
    out = []
    while len(out) < 3 * count:
        modes = int(rng.integers(2, 25))
        decay = float(rng.uniform(0.6, 1.0))
        amp = float(10 ** rng.uniform(-1.0, 0.0))
        N = int(np.round(2 ** rng.uniform(np.log2(max(2 * modes + 4, 8)), np.log2(16 * modes + 64))))
        seed = int(rng.integers(1 << 30))
        make = lambda n, s=seed: band_limited_loop(n, centre, modes, decay, amp * np.asarray(scale), s)
        lam_of = lambda n, s=seed: band_limited_loop(n, np.zeros(len(centre)), modes, decay,
                                                     0.01 * np.asarray(scale), s + 1)
        refs = {}
        with np.errstate(all="ignore"):
            for form in ("noncanonical", "corrected"):
                a = _plain_loop(system, make(REF_LOOP), form, lam_of(REF_LOOP), h)
                b = _plain_loop(system, make(2 * REF_LOOP), form, lam_of(2 * REF_LOOP), h)
                refs[form] = (a, abs(a - b))
        if not all(np.isfinite(r) and np.isfinite(e) and e <= 1e-14 * abs(r) for r, e in refs.values()):
            skipped[f"loop {name}"] = skipped.get(f"loop {name}", 0) + 1
            continue
        q, lam = make(N), lam_of(N)
        with np.errstate(all="ignore"):
            got = invariants.forms.first_invariants(q, list(FORMS), system, p=system.theta(q), lam=lam, h=h)
        for form in FORMS:
            ref = refs["corrected" if form == "corrected" else "noncanonical"][0]
            plain = _plain_loop(system, q, form if form != "canonical" else "noncanonical", lam, h)
            out.append(_record("loop", name, form, got[form], ref, plain, N=N, modes=modes))
    return out


def random_surfaces(name, count, rng, skipped):
    """Records of ``count`` random polynomial surfaces of one system, three forms each."""
    from invariants.samples import band_limited_surface
    system = integrators.system(name)
    centre, scale, h = SYSTEMS[name]
    out = []
    while len(out) < 3 * count:
        degree = int(rng.integers(1, 9))
        decay = float(rng.uniform(0.5, 1.0))
        amp = float(10 ** rng.uniform(-1.0, 0.0))
        n = int(np.round(2 ** rng.uniform(np.log2(max(degree + 2, 8)), np.log2(6 * degree + 12))))
        seed = int(rng.integers(1 << 30))
        make = lambda k, s=seed: band_limited_surface(k, k, centre, degree, decay, amp * np.asarray(scale), s)
        lam_of = lambda k, s=seed: band_limited_surface(k, k, np.zeros(len(centre)), degree, decay,
                                                        0.01 * np.asarray(scale), s + 1)
        refs = {}
        with np.errstate(all="ignore"):
            for form in ("noncanonical", "corrected"):
                a = _plain_surface(system, make(REF_SURFACE), form, lam_of(REF_SURFACE), h)
                b = _plain_surface(system, make(193), form, lam_of(193), h)
                refs[form] = (a, abs(a - b))
        if not all(np.isfinite(r) and np.isfinite(e) and e <= 1e-14 * abs(r) for r, e in refs.values()):
            skipped[f"surface {name}"] = skipped.get(f"surface {name}", 0) + 1
            continue
        S, lam = make(n), lam_of(n)
        with np.errstate(all="ignore"):
            got = invariants.forms.second_invariants(S, list(FORMS), system, p=system.theta(S), lam=lam, h=h)
        for form in FORMS:
            ref = refs["corrected" if form == "corrected" else "noncanonical"][0]
            plain = _plain_surface(system, S, form if form != "canonical" else "noncanonical", lam, h)
            out.append(_record("surface", name, form, got[form], ref, plain, n=n, degree=degree))
    return out


def advected_loops(steps=2000, save=250):
    """Records of the paper's loop (512 points) advected by every GLRK1–6 and SRK3 pair with every
    projection (guiding_centre_symmetric, h = 10): at each saved time, the sets of every 2nd … 16th
    point against the 512-point set."""
    system = integrators.system("guiding_centre_symmetric")
    q0 = invariants.loop("guiding_centre", 512)
    out = []
    for tab in ("GLRK1", "GLRK2", "GLRK3", "GLRK4", "GLRK5", "GLRK6", "SRK3"):
        for proj in ("none", "standard", "symmetric", "symplectic", "midpoint"):
            sol = integrators.integrate(system, q0, tableau=tab, projection=proj, h=10.0, steps=steps, save_every=save)
            for k in range(1, sol.q.shape[0]):
                q, p, lam = sol.q[k], sol.p[k], sol.lam[k]
                if not np.all(np.isfinite(q)):
                    continue
                full = invariants.forms.first_invariants(q, list(FORMS), system, p=p, lam=lam, h=10.0)
                if max(v.resolution for v in full.values()) > 1e-12:
                    continue                                 # the reference itself is not resolved
                for step in (2, 4, 8, 16):
                    sub = invariants.forms.first_invariants(q[::step], list(FORMS), system, p=p[::step],
                                                            lam=lam[::step], h=10.0)
                    for form in FORMS:
                        plain = (spectral.loop_pairing(p[::step], q[::step]) if form == "canonical" else
                                 _plain_loop(system, q[::step], form, lam[::step], 10.0))
                        out.append(_record("advected", f"{tab}-{proj}", form, sub[form], full[form].value, plain,
                                           N=512 // step, t=float(sol.t[k])))
    return out


def summary(records):
    """Rows per (kind, system, form)."""
    rows = {}
    for r in records:
        key = (r["kind"], r["system"] if r["kind"] != "advected" else "35 pairs", r["form"])
        rows.setdefault(key, []).append(r)
    table = []
    for (kind, system, form), rs in sorted(rows.items()):
        err = np.array([r["error"] for r in rs])
        est = np.array([r["estimate"] for r in rs])
        flagged = np.array([r["flagged"] for r in rs])
        alias = np.array([r["alias"] for r in rs])
        roundoff = np.array([r["roundoff"] for r in rs])
        table.append(dict(kind=kind, system=system, form=form, sets=len(rs),
                          alias_min=float(np.min(alias)), alias_max=float(np.max(alias)),
                          wrong_called_resolved=int(np.sum(~flagged & (err > THRESHOLD))),
                          error_above_estimate=int(np.sum((err > est) & ~flagged & (err > ROUNDOFF))),
                          error_above_estimate_flagged=int(np.sum((err > est) & flagged)),
                          error_above_estimate_roundoff=int(np.sum((err > est) & ~flagged & (err <= ROUNDOFF))),
                          flagged=int(np.sum(flagged)), flagged_right=int(np.sum(flagged & (err <= THRESHOLD))),
                          # the monitor's reading (the error less round-off's share, relative) against the error,
                          # floored at the value's round-off: how far the reading errs large
                          estimate_over_100x=int(np.sum(np.array([r["resolution"] for r in rs]) >
                                                        100 * np.maximum(err, np.maximum(roundoff, 1e-15)))),
                          padded=int(np.sum([r["padding"] > 1 for r in rs]))))
    return table


def markdown(table, skipped):
    lines = ["| sets | system | form | n | plain sum's error (aliasing) | called resolved, wrong | error > estimate: "
             "not flagged, above 1e-12 | …: flagged | …: at round-off | flagged (all) | flagged, right | "
             "reading > 100× error | "
             "padded |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    keys = ("sets", "wrong_called_resolved", "error_above_estimate", "error_above_estimate_flagged",
            "error_above_estimate_roundoff", "flagged", "flagged_right", "estimate_over_100x", "padded")
    for r in table:
        lines.append(f"| {r['kind']} | {r['system']} | {r['form']} | {r['sets']} | {r['alias_min']:.0e} … "
                     f"{r['alias_max']:.0e} | **{r['wrong_called_resolved']}** | **{r['error_above_estimate']}** | "
                     + " | ".join(str(r[k]) for k in keys[3:]) + " |")
    tot = {k: sum(r[k] for r in table) for k in keys}
    lines.append(f"| all | | | {tot['sets']} | | **{tot['wrong_called_resolved']}** | "
                 f"**{tot['error_above_estimate']}** | "
                 + " | ".join(str(tot[k]) for k in keys[3:]) + " |")
    if skipped:
        lines.append("")
        lines.append("Left out (reference not converged to 1e-14 between its two sizes, or not finite): "
                     + ", ".join(f"{k} {v}" for k, v in sorted(skipped.items())) + ".")
    return "\n".join(lines)


def cost(repeat=20):
    """Seconds per call: the plain FFT loop integral (ϑ at the samples, one Parseval sum), this
    version's first_invariant, and the surface's plain Clenshaw–Curtis against second_invariant."""
    from invariants.samples import band_limited_loop
    system = integrators.system("guiding_centre_symmetric")
    rows = []

    def best(f):
        f()
        ts = []
        for _ in range(repeat):
            t = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t)
        return min(ts)
    for N in (128, 2000, 16384):
        q = band_limited_loop(N, [0.0, 0.0, 0.0, 0.5], 20, 0.8, [0.15, 0.15, 0.1, 0.03], 3)
        rows.append(dict(set=f"loop {N}", plain=best(lambda: _plain_loop(system, q, "noncanonical", None, None)),
                         monitor=best(lambda: invariants.first_invariant(q, "noncanonical", system=system))))
    for n in (20, 47, 100):
        S = invariants.surface("guiding_centre", n, n)
        rows.append(dict(set=f"surface {n}²",
                         plain=best(lambda: _plain_surface(system, S, "noncanonical", None, None)),
                         monitor=best(lambda: invariants.second_invariant(S, "noncanonical", system=system))))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=150,
                    help="random loops per system, half as many surfaces (default 150)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-advected", action="store_true", help="leave out the advected loops")
    ap.add_argument("--json", help="write the records' summary here")
    ap.add_argument("--markdown", action="store_true", help="print the table as markdown")
    ap.add_argument("--cost", action="store_true", help="time the monitor against the plain sum and stop")
    ap.add_argument("--before", help="with --cost --json: an earlier version's --cost file, written side by side")
    ap.add_argument("--version", default="", help="with --cost --json: the version measured (a commit)")
    ap.add_argument("--note", default="", help="with --cost --before: what the machine was doing")
    args = ap.parse_args(argv)
    if args.cost:
        rows = cost()
        for r in rows:
            print(f"{r['set']:16s} plain {r['plain'] * 1e3:9.3f} ms   first/second_invariant "
                  f"{r['monitor'] * 1e3:9.3f} ms   ratio {r['monitor'] / r['plain']:6.1f}")
        if args.json:
            out = dict(rows=rows, version=args.version)
            if args.before:        # side by side with an earlier version's file of this mode
                before = json.load(open(args.before))
                out = dict(rows_now=rows, rows_before=before["rows"], before=before["version"], note=args.note)
            with open(args.json, "w") as f:
                json.dump(out, f, indent=1)
        return 0
    rng = np.random.default_rng(args.seed)
    records, skipped = [], {}
    t0 = time.perf_counter()
    for name in SYSTEMS:
        records += random_loops(name, args.sets, rng, skipped)
        records += random_surfaces(name, max(args.sets // 2, 1), rng, skipped)
        print(f"{name}: {len(records)} values so far, {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if not args.no_advected:
        records += advected_loops()
    table = summary(records)
    text = markdown(table, skipped)
    print(text if args.markdown else json.dumps(table, indent=1))
    bad = [r for r in records if not r["flagged"] and (r["error"] > THRESHOLD or
                                                       r["error"] > max(r["estimate"], ROUNDOFF))]
    for r in bad[:20]:
        print("called resolved, wrong, or above its estimate:", r, file=sys.stderr)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(command="python scripts/studies/invariants_monitor.py " + " ".join(argv or sys.argv[1:]),
                           table=table, skipped=skipped, wall_s=round(time.perf_counter() - t0, 1),
                           worst_missed=bad[:20]), f, indent=1)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
