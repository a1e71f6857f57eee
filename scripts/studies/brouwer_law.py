"""Brouwer's law: how the round-off part of the energy error grows (docs/brouwer.md).

With a symplectic method the truncation part of the energy error stays bounded; what round-off
adds should grow like a random walk, √t (Brouwer's law), not like t.  The round-off part is
measured as issue 70 defines it: the energy error of the double run minus that of the
double-double run of the same method, step and starts (whose own round-off is 2⁻¹⁰⁴), both
energies evaluated in double-double by the engine's own H (so H's rounding is not counted).  Per
pair: the RMS over the starts against the step number, the exponent of a power law fitted to it
from step 10³ on (log-spaced samples; ± the spread of 200 bootstrap resamples of the starts), the
mean over the starts at the end (a bias shows here), Newton iterations per step, and the growth
law (invariants.growth) of the RMS series in the audit's words.

Cases:
* canonical, written as degenerate systems: the pendulum (ϑ = (p, 0), H = p²/2 − cos x, x₀ from
  0.5 to 1.5, p₀ = 0) and a Kepler orbit of eccentricity 0.5 (ϑ = (u, v, 0, 0), perihelion 0.5,
  the starts rotated about the centre), GLRK1-6 with projection none, 10⁶ steps;
* degenerate, the paper's systems with their projected pairs (``--degenerate``), 10⁵ steps;
  a pair counts only where its double-double energy error is bounded over the run (its growth
  law ``bounded`` or ``round-off``).

Rules compared: the default (``now``: Newton until its update stops halving), the rule before
issue 70 (``fixed``: the same predictor stopped at 4 ulps, Tolerances(tol=FIXED_TOL)), and the rule
before issue 55 (``extrapolate``: Tolerances(predictor="extrapolate", tol=FIXED_TOL)); the two
older rules over the first ``--before-steps`` (2·10⁵) steps, the issue's measurement.

    python scripts/studies/brouwer_law.py --json docs/figures/brouwer_law.json        # about 1.5 h
    python scripts/studies/brouwer_law.py --cases pendulum --tableaus GLRK4 --steps 200000
    python scripts/studies/brouwer_law.py --markdown docs/figures/brouwer_law.json   # the table
    python scripts/studies/brouwer_law.py --markdown OLD.json NEW.json --json ALL.json   # NEW's rows replace
                                                      # OLD's (their exponents shown beside), into ALL
    python scripts/studies/brouwer_law.py --speed          # what it costs: point-steps/s, one thread
    python scripts/studies/brouwer_law.py --cases kepler --tableaus GLRK6 --starts 32 \
        --rule 'fresh={"trust_max_unknowns": 64, "trust_floor": 0, "refresh_floor": 0}'   # another rule beside

The double-double runs do not depend on the rule: they are cached (``--cache``, default
$POINCARE_CACHE/brouwer or ~/.cache/poincare/brouwer) and reused by later runs of the script.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import sympy

import integrators
from integrators.engine import FIXED_TOL, scalars_dd
from integrators.systems import system_from
from invariants.growth import growth_law

ROOT = Path(__file__).resolve().parents[2]
FIT_FROM = 1000           # the exponent is fitted from this step on (the measurement)
BOOTSTRAP = 200
SAMPLES = 40              # log-spaced samples of the RMS series the fit uses
EXPONENT_BOUND = 0.55     # issue 70: every pair at most this
# the engine a rows file was measured with (written into the file); a file without it is older
SUMS = "2026-11-29: the increments summed exactly (kernel._weighted_sum)"
RESIDUAL = "2026-11-30: the residual's sums and G_i to O(eps^2) (kernel.equations._force)"
STATE = "2026-11-30: the step sees the state's compensation terms (kernel.equations._prepare)"
SETTLED = "2026-11-30: the settled approach the default (Tolerances.settle, its grid in the coordinates' own ulps)"
PROJECTED_P = ("2026-12-01: projected steps start from the p_n their solve left, with its compensation term, "
               "and G_i is taken at the exact stage point (kernel.equations._prepare, _stages)")
ENGINE = PROJECTED_P      # the engine since (before it SETTLED; then STATE, Tolerances(settle=False); then RESIDUAL, then SUMS)
DITHER_OPTION = "2026-11-30: the dithered approach (Tolerances.dither)"   # its first version, the default for a day:
                          # its floor test stopped early (docs/brouwer.md); the § rows of the table
EXACT_POINTS = "2026-11-29: the equations see their points exactly (kernel.exact_points)"
OLDER = "2026-11-28: before the exact points"
MARKS = {ENGINE: "", SETTLED: " ♮", STATE: " ¤", RESIDUAL: " ¶", SUMS: " ∥", DITHER_OPTION: " §", EXACT_POINTS: " †", OLDER: " ‡"}    # the table's mark of a row of each engine
NEGLIGIBLE = 1e-19        # a truncation part below this: the reference is H(q₀) (no double-double run)
COUPLING_MAX = 0.01       # the round-off part δE moves the phase by ~δE·T (frequencies ~ 1 here), which
                          # moves a truncation error of size e by ~e·δE·T: e·T at most this, so that
                          # this cross term stays below 1 % of the round-off part itself
# (tableau, h) per case: steps short enough that the double-double run's energy error (truncation)
# times the phase the round-off walks stays far below the round-off (the table shows both)
CANONICAL_H = {
    "pendulum": {"GLRK1": 0.002, "GLRK2": 0.01, "GLRK3": 0.02, "GLRK4": 0.02, "GLRK5": 0.05, "GLRK6": 0.1},
    "kepler": {"GLRK1": 0.0002, "GLRK2": 0.002, "GLRK3": 0.005, "GLRK4": 0.005, "GLRK5": 0.01, "GLRK6": 0.02},
}
DEGENERATE = ("lotka_volterra_2d", "point_vortices", "guiding_centre_symmetric")
DEGENERATE_TABLEAUS = ("GLRK1", "GLRK2", "GLRK3", "GLRK4", "GLRK5", "GLRK6", "SRK3")
DEGENERATE_PROJECTIONS = ("standard", "symmetric", "symplectic", "midpoint")


EXTRA_RULES = {}          # --rule NAME=JSON: more Tolerances, run over the whole run as "now" is


def rules():
    return {**{name: integrators.Tolerances(**kw) for name, kw in EXTRA_RULES.items()},
            "now": integrators.Tolerances(),
            "fixed": integrators.Tolerances(tol=FIXED_TOL, dither=False),
            "extrapolate": integrators.Tolerances(predictor="extrapolate", tol=FIXED_TOL, dither=False)}


def pendulum(n):
    x, p = sympy.symbols("x p")
    system = system_from([p, 0], p**2 / 2 - sympy.cos(x), [x, p], name="pendulum")
    q0 = np.stack([np.linspace(0.5, 1.5, n), np.zeros(n)], 1)
    return system, q0


def kepler(n):
    """Kepler orbits of eccentricity 0.5 and semi-major axis 1 (period 2π, energy −½), the starts
    spread over the orbit's phase (true anomaly 2πk/n) and turned about the centre (by k·2.4 rad),
    so that the RMS over the starts averages over the orbit rather than following one phase."""
    x, y, u, v = sympy.symbols("x y u v")
    system = system_from([u, v, 0, 0], (u**2 + v**2) / 2 - 1 / sympy.sqrt(x**2 + y**2), [x, y, u, v],
                         name="kepler", domain=[x**2 + y**2])
    e, p = 0.5, 0.75                                  # p = a(1 − e²)
    f = 2 * np.pi * np.arange(n) / n                  # true anomaly
    w = 2.4 * np.arange(n) + 0.1                      # the orbit's turn
    r = p / (1 + e * np.cos(f))
    vr, vt = np.sqrt(1 / p) * e * np.sin(f), np.sqrt(1 / p) * (1 + e * np.cos(f))
    c, s = np.cos(f + w), np.sin(f + w)
    q0 = np.stack([r * c, r * s, vr * c - vt * s, vr * s + vt * c], 1)
    return system, q0


def degenerate(name, n):
    """The system's default start and n − 1 more on a small circle about it (radius 1 % of |q₀|)."""
    system = integrators.system(name)
    c = np.asarray(system.defaults["q0"], dtype=float)
    rng = np.random.default_rng(70)
    off = rng.standard_normal((n, c.size))
    off[0] = 0
    q0 = c + 0.01 * max(np.abs(c).max(), 1e-3) * off / np.maximum(np.linalg.norm(off, axis=1, keepdims=True), 1e-300)
    return system, q0


def energy_dd(system, q, q_lo=None):
    """H at the points q (+ q_lo) in double-double: (hi, lo), each of q's leading shape."""
    lead = q.shape[:-1]
    q2 = np.stack([q.reshape(-1, q.shape[-1]), (np.zeros_like(q) if q_lo is None else q_lo).reshape(-1, q.shape[-1])], -1)
    e = scalars_dd(system, q2)[:, 0, :]
    return e[:, 0].reshape(lead), e[:, 1].reshape(lead)


def cache_dir(arg):
    if arg:
        return Path(arg)
    root = os.environ.get("POINCARE_CACHE")
    return (Path(root) if root else Path.home() / ".cache" / "poincare") / "brouwer"


def reference(system, q0, tableau, projection, h, steps, every, cache, probe):
    """The reference energies (hi, lo), (steps/every + 1, n): the double-double run's, cached by
    what determines them; or H(q₀) in double-double at every output where a double-double run of
    ``probe`` steps keeps the energy within NEGLIGIBLE (the truncation part is then below what
    the table can show).  Returns (hi, lo, truncation over the probe or run, what was used, seconds)."""
    key = hashlib.sha256(json.dumps([system.name, str(system.param_values), q0.tobytes().hex(), tableau,
                                     projection, h, steps, every, probe]).encode()).hexdigest()[:16]
    path = cache / f"{system.name}_{tableau}_{projection}_{steps}_{key}.npz"
    if path.exists():
        z = np.load(path)
        return z["hi"], z["lo"], float(z["truncation"]), str(z["kind"]), float(z["seconds"])
    t = time.perf_counter()

    def run(n):
        sol = integrators.integrate(system, q0, tableau=tableau, projection=projection, h=h, steps=n,
                                    save_every=min(every, n), precision="double-double")
        hi, lo = energy_dd(system, sol.q, sol.q_lo)
        broke = np.isfinite(sol.breakdown_time)
        hi[:, broke], lo[:, broke] = np.nan, np.nan
        return hi, lo

    hi, lo = run(min(probe, steps))
    good = np.all(np.isfinite(hi), axis=0)
    trunc = float(np.max(np.abs((hi - hi[0]) + (lo - lo[0]))[:, good])) if good.any() else float("nan")
    k = steps // every + 1
    if trunc <= NEGLIGIBLE:
        kind = f"H(q0): truncation over {min(probe, steps):,} steps ≤ {NEGLIGIBLE:g}"
        hi, lo = np.broadcast_to(hi[0], (k, hi.shape[1])).copy(), np.broadcast_to(lo[0], (k, lo.shape[1])).copy()
        hi[:, ~good] = np.nan
    else:
        kind = "double-double run"
        if steps > probe:
            hi, lo = run(steps)
            good = np.all(np.isfinite(hi), axis=0)
        trunc = float(np.max(np.abs((hi - hi[0]) + (lo - lo[0]))[:, good])) if good.any() else float("nan")
    seconds = time.perf_counter() - t
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, hi=hi, lo=lo, truncation=trunc, kind=kind, seconds=seconds)
    return hi, lo, trunc, kind, seconds


def fit(steps, r):
    """(exponent, its bootstrap spread) of the RMS over the starts (columns of r) against steps ≥ FIT_FROM."""
    use = np.flatnonzero(steps >= FIT_FROM)
    if use.size < 3:
        return float("nan"), float("nan")
    pick = np.unique(np.clip(np.searchsorted(steps[use], np.geomspace(steps[use][0], steps[use][-1], SAMPLES)),
                             0, use.size - 1))
    use = use[pick]
    x = np.log(steps[use])

    def exponent(cols):
        rms = np.sqrt(np.mean(r[use][:, cols] ** 2, axis=1))
        return float(np.polyfit(x, np.log(np.maximum(rms, 1e-300)), 1)[0])

    n = r.shape[1]
    rng = np.random.default_rng(0)
    boot = [exponent(rng.integers(0, n, n)) for _ in range(BOOTSTRAP)]
    return exponent(np.arange(n)), float(np.std(boot))


def measure(system, q0, tableau, projection, h, steps, before_steps, every, cache, probe, now_only=False):
    """One pair: the reference, then each rule's double run; a dict of what was measured."""
    hi, lo, trunc, kind, dd_seconds = reference(system, q0, tableau, projection, h, steps, every, cache, probe)
    good = np.all(np.isfinite(hi), axis=0)
    e_dd = (hi - hi[0]) + (lo - lo[0])                 # the double-double run's energy error (truncation)
    ddlaw = growth_law(np.arange(hi.shape[0]) * every, np.max(np.abs(e_dd[:, good]), axis=1)) if good.any() else None
    out = dict(system=system.name, tableau=tableau, projection=projection, h=h, steps=steps, starts=int(q0.shape[0]),
               starts_used=int(good.sum()), every=every, reference=kind, dd_seconds=round(dd_seconds, 1),
               truncation=trunc, dd_law="broke down" if ddlaw is None else ddlaw.law, rules={})
    if ddlaw is None or ddlaw.law in ("linear", "faster"):
        out["left_out"] = f"the double-double run's energy error is {out['dd_law']}, not bounded"
        return out
    if trunc * abs(h) * steps > COUPLING_MAX:
        out["left_out"] = (f"the double-double run's energy error reaches {trunc:.1e} over T = {abs(h) * steps:g}: "
                           f"the phase the round-off walks would move it by more than 1 % of the round-off")
        return out
    for name, tol in rules().items():
        if now_only and name in ("fixed", "extrapolate"):
            continue
        n_steps = min(before_steps, steps) if name in ("fixed", "extrapolate") else steps
        t = time.perf_counter()
        sol = integrators.integrate(system, q0, tableau=tableau, projection=projection, h=h, steps=n_steps,
                                    save_every=every, tolerances=tol)
        seconds = time.perf_counter() - t
        ehi, elo = energy_dd(system, sol.q)
        k = ehi.shape[0]
        ok = good & ~np.isfinite(sol.breakdown_time)
        r = ((ehi - hi[:k]) + (elo - lo[:k]))[:, ok]    # double's energy minus double-double's, per start
        at = np.arange(k) * every
        rms = np.sqrt(np.mean(r ** 2, axis=1))
        exponent, spread = fit(at, r)
        law = growth_law(at[1:], rms[1:])
        keep = np.unique(np.searchsorted(at, np.geomspace(every, at[-1], SAMPLES)).clip(1, k - 1))
        out["rules"][name] = dict(steps=n_steps, seconds=round(seconds, 2), starts_used=int(ok.sum()),
                                  iterations=float(sol.newton_iterations[ok].sum() / max(n_steps * ok.sum(), 1)),
                                  exponent=round(exponent, 3), exponent_spread=round(spread, 3),
                                  rms_end=float(rms[-1]), mean_end=float(np.mean(r[-1])),
                                  growth_law=law.law, growth_exponent=float(law.exponent),
                                  rms=[float(f"{v:.4g}") for v in rms[keep]], steps_at=[int(v) for v in at[keep]])
    return out


def cases(args):
    for case in args.cases:
        if case in CANONICAL_H:
            system, q0 = (pendulum if case == "pendulum" else kepler)(args.starts)
            for tab in args.tableaus:
                if tab in CANONICAL_H[case]:
                    yield system, q0, tab, "none", CANONICAL_H[case][tab], args.steps
        elif case == "degenerate":
            for name in args.degenerate_systems:
                system, q0 = degenerate(name, args.degenerate_starts)
                h = float(system.defaults["h"])
                for tab in DEGENERATE_TABLEAUS:
                    for proj in DEGENERATE_PROJECTIONS:
                        if args.degenerate_pairs is None or f"{name}:{tab}:{proj}" in args.degenerate_pairs:
                            yield system, q0, tab, proj, h, args.degenerate_steps
        else:
            raise SystemExit(f"error: unknown case '{case}'; choose pendulum, kepler or degenerate")


def rms_at(rule, step):
    """The stored RMS series of a rule at ``step`` (log-log interpolation between its samples)."""
    at, rms = np.asarray(rule["steps_at"], float), np.asarray(rule["rms"], float)
    return float(np.exp(np.interp(np.log(step), np.log(at), np.log(rms))))


def laws(rule):
    """(the growth law of the RMS series with no round-off floor, the audit's verdict on it)."""
    from integrators.audit.drift import VERDICTS
    at, rms = np.asarray(rule["steps_at"], float), np.asarray(rule["rms"], float)
    return growth_law(at, rms, roundoff=0.0).law, VERDICTS[growth_law(at, rms).law]


def merged(docs):
    """The rows of several rows files, a later file's row replacing an earlier one of the same pair;
    each row keeps its file's ``engine`` and, where it replaced a row of an older engine, that row's
    exponent (now) as ``before``."""
    out = {}
    for doc in docs:
        engine = doc.get("engine", OLDER)
        for row in doc["rows"]:
            key = (row["system"], row["tableau"], row["projection"])
            row = dict(row, engine=row.get("engine", engine))     # a merged file's rows keep theirs
            old = out.get(key)
            if old is not None and old["engine"] != engine and not old.get("left_out"):
                row["before"] = dict(exponent=old["rules"]["now"]["exponent"],
                                     spread=old["rules"]["now"]["exponent_spread"],
                                     iterations=old["rules"]["now"]["iterations"], engine=old["engine"])
                if old["engine"] == DITHER_OPTION and old.get("before"):
                    row["before"] = old["before"]       # the default before, not the opt-in's first version
            if old is not None and not old.get("left_out") and not row.get("left_out"):
                for k in ("fixed", "extrapolate"):      # a --now-only row keeps the older rules' runs
                    row["rules"].setdefault(k, old["rules"][k])
            out[key] = row
    return list(out.values())


def markdown(rows):
    """The table of docs/brouwer.md: one line per pair, the three rules side by side; a pair measured
    with another engine than ENGINE is marked (MARKS: ♮ the engine before projected steps kept their
    p_n (SETTLED), ¤ the engine before the settled approach was the default (STATE), ¶ the engine before the state's compensation
    terms (RESIDUAL), ∥ the one before the residual's own sums (SUMS), § the first version of the
    dithered approach,
    whose floor test stopped early, † the exact points' engine, ‡ the engine before those),
    and a pair re-measured shows the older engine's exponent and iterations (now) beside."""
    lines = ["| system | pair | h | steps | reference (truncation) | it./step: now · fixed · extrapolate | "
             "exponent now | fixed | extrapolate | now, the engine before (it./step) | "
             "RMS at 2·10⁵: now · fixed · extrapolate | mean / RMS at end (now) | law (no floor) · audit |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    left = []
    for row in rows:
        if row.get("left_out"):
            left.append(f"{row['system']} {row['tableau']}-{row['projection']}: {row['left_out']}")
            continue
        now, fixed, extra = (row["rules"][k] for k in ("now", "fixed", "extrapolate"))
        ref = "H(q₀)" if row["reference"].startswith("H(q0)") else "dd run"
        b = fixed["steps"]
        bold = "**" if now["exponent"] <= EXPONENT_BOUND else ""
        law, verdict = laws(now)
        mark = MARKS.get(row.get("engine", ENGINE), " ‡")
        bef = row.get("before")
        before = f"{bef['exponent']:.2f} ± {bef['spread']:.2f} ({bef['iterations']:.2f})" if bef else "—"
        lines.append(
            f"| {row['system']} | {row['tableau']}-{row['projection']}{mark} | {row['h']:g} | {now['steps']:,} | "
            f"{ref} ({row['truncation']:.0e}) | {now['iterations']:.2f} · {fixed['iterations']:.2f} · "
            f"{extra['iterations']:.2f} | {bold}{now['exponent']:.2f} ± {now['exponent_spread']:.2f}{bold} | "
            f"{fixed['exponent']:.2f} ± {fixed['exponent_spread']:.2f} | {extra['exponent']:.2f} ± "
            f"{extra['exponent_spread']:.2f} | {before} | {rms_at(now, b):.1e} · {fixed['rms_end']:.1e} · "
            f"{extra['rms_end']:.1e} | {now['mean_end'] / now['rms_end']:+.2f} | {law} · {verdict} |")
    out = "\n".join(lines)
    if left:
        out += "\n\nLeft out:\n" + "\n".join(f"- {x}" for x in left)
    return out


def dither_table(rows):
    """The dithered approach against the default, pair by pair, from rows whose rules are
    ``dither`` (Tolerances(dither=True)) and ``undithered`` or ``now`` (the default; where a row
    holds only its exponent and iterations, those): exponents, iterations a step, mean/RMS at the
    end, and the averages over the pairs (docs/brouwer.md, "The dithered approach")."""
    lines = ["| system | pair | exponent dithered | undithered | it./step dithered · undithered | "
             "mean / RMS dithered · undithered |", "|---|---|---|---|---|---|"]
    got = []
    for row in rows:
        if row.get("left_out"):
            continue
        a, b = row["rules"]["dither"], row["rules"].get("undithered", row["rules"].get("now"))
        ratio = (lambda r: f"{r['mean_end'] / r['rms_end']:+.2f}" if "rms_end" in r else "—")
        lines.append(f"| {row['system']} | {row['tableau']}-{row['projection']} | {a['exponent']:.2f} ± "
                     f"{a['exponent_spread']:.2f} | {b['exponent']:.2f} ± {b['exponent_spread']:.2f} | "
                     f"{a['iterations']:.2f} · {b['iterations']:.2f} | {ratio(a)} · {ratio(b)} |")
        got.append((row["system"], a["exponent"], b["exponent"], a["exponent_spread"], b["exponent_spread"],
                    a["iterations"], b["iterations"]))
    out = "\n".join(lines)
    for system in sorted({g[0] for g in got}) + [None]:
        g = np.array([x[1:] for x in got if system is None or x[0] == system])
        out += (f"\n\n{system or 'all'} ({len(g)} pairs): exponents average {g[:, 0].mean():.3f} dithered, "
                f"{g[:, 1].mean():.3f} undithered; at most {EXPONENT_BOUND}: {int((g[:, 0] <= EXPONENT_BOUND).sum())}, "
                f"{int((g[:, 1] <= EXPONENT_BOUND).sum())}; within twice their spread: "
                f"{int((g[:, 0] - 2 * g[:, 2] <= EXPONENT_BOUND).sum())}, {int((g[:, 1] - 2 * g[:, 3] <= EXPONENT_BOUND).sum())}; "
                f"iterations a step {np.min(g[:, 4] - g[:, 5]):+.2f} to {np.max(g[:, 4] - g[:, 5]):+.2f} "
                f"({np.min(g[:, 4] / g[:, 5] - 1):+.0%} to {np.max(g[:, 4] / g[:, 5] - 1):+.0%})")
    return out


SPEED_PAIRS = (("GLRK1", "none"), ("GLRK2", "symmetric"), ("GLRK2", "symplectic"), ("SRK3", "symmetric"),
               ("GLRK4", "symmetric"), ("GLRK6", "symmetric"))


def speed(points=10_000, steps=20, rounds=3):
    """Point-steps per second of the default against the fixed 4 ulps: guiding_centre_symmetric,
    h = 10, ``points`` near the default loop, ``steps`` steps after 2 (the history filled), one
    thread, the two rules alternating, best of ``rounds``; iterations a point-step beside."""
    import invariants
    integrators.set_threads(1)
    sy = integrators.system("guiding_centre_symmetric")
    q0 = invariants.loop("guiding_centre", points)
    out = []
    for tab, proj in SPEED_PAIRS:
        best, its = {}, {}
        for _ in range(rounds):
            for name in ("now", "fixed"):
                e = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0, tolerances=rules()[name])
                st = e.state(q0)
                e.advance(st, 1, 2)
                before = st.iterations.sum()
                t = time.perf_counter()
                e.advance(st, 3, steps)
                best[name] = min(best.get(name, np.inf), time.perf_counter() - t)
                its[name] = (st.iterations.sum() - before) / (points * steps)
        row = dict(pair=f"{tab}-{proj}", **{f"{k}_per_s": points * steps / v for k, v in best.items()},
                   **{f"{k}_iterations": v for k, v in its.items()})
        out.append(row)
        print(f"| {row['pair']} | {row['fixed_per_s']:,.0f} | {row['now_per_s']:,.0f} | "
              f"{row['now_per_s'] / row['fixed_per_s']:.2f} | {its['fixed']:.2f} → {its['now']:.2f} |", flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=lambda s: s.split(","), default=["pendulum", "kepler", "degenerate"])
    ap.add_argument("--tableaus", type=lambda s: s.split(","), default=[f"GLRK{s}" for s in range(1, 7)])
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--starts", type=int, default=64)
    ap.add_argument("--before-steps", type=int, default=200_000)
    ap.add_argument("--degenerate-steps", type=int, default=100_000)
    ap.add_argument("--degenerate-starts", type=int, default=32)
    ap.add_argument("--degenerate-systems", type=lambda s: s.split(","), default=list(DEGENERATE),
                    help="which of the degenerate systems (comma-separated; default all three)")
    ap.add_argument("--degenerate-pairs", type=lambda s: s.split(","), default=None,
                    help="only these degenerate pairs, SYSTEM:TABLEAU:PROJECTION,... (default: every pair)")
    ap.add_argument("--probe", type=int, default=20_000, help="steps of the double-double run that decides "
                    "whether the truncation part is negligible")
    ap.add_argument("--every", type=int, default=1000, help="output cadence in steps")
    ap.add_argument("--cache", default=None)
    ap.add_argument("--json", default=None, help="write the rows here (appending to what is there)")
    ap.add_argument("--markdown", default=None, nargs="+", metavar="JSON", help="print the table of rows files and stop")
    ap.add_argument("--rule", action="append", default=[], metavar="NAME=JSON",
                    help='another rule beside the three, e.g. fresh=\'{"trust_max_unknowns": 64, "trust_floor": 0}\'')
    ap.add_argument("--dither-table", default=None, nargs="+", metavar="JSON", help="print the dithered approach "
                    "against the default from rows files with the rules dither and undithered (or now), and stop")
    ap.add_argument("--now-only", action="store_true", help="run the default rule alone (the fixed and "
                    "extrapolate rules do not depend on the dither: --markdown takes them from the rows replaced)")
    ap.add_argument("--speed", action="store_true", help="point-steps per second of the default against the fixed "
                    "4 ulps (one thread) and stop")
    args = ap.parse_args(argv)
    for text in args.rule:
        name, _, kw = text.partition("=")
        EXTRA_RULES[name] = json.loads(kw)
        integrators.Tolerances(**EXTRA_RULES[name])          # a bad field fails here, before any run
    if args.speed:
        print("| pair | fixed 4 ulps | default | default / fixed | it./step |\n|---|---:|---:|---:|---|")
        speed()
        return 0
    if args.dither_table:
        print(dither_table([row for f in args.dither_table for row in json.loads(Path(f).read_text())["rows"]]))
        return 0
    if args.markdown:
        docs = [json.loads(Path(f).read_text()) for f in args.markdown]
        rows = merged(docs)
        print(markdown(rows))
        if args.json:                  # the merged rows, each with its engine, as one file
            Path(args.json).write_text(json.dumps(dict(
                rows=rows, engine=ENGINE, merged_from=[dict(command=d.get("command", d.get("commands")),
                note=d.get("note"), engine=d.get("engine", OLDER)) for d in docs]), indent=1) + "\n")
        return 0
    cache = cache_dir(args.cache)
    doc = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).exists() else dict(rows=[])
    doc.update(command="python scripts/studies/brouwer_law.py " + " ".join(argv if argv is not None else sys.argv[1:]),
               machine=os.uname().machine, numpy=np.__version__, engine=ENGINE)
    for system, q0, tab, proj, h, steps in cases(args):
        every = min(args.every, steps // 100)
        t = time.perf_counter()
        row = measure(system, q0, tab, proj, h, steps, args.before_steps, every, cache, args.probe, args.now_only)
        doc["rows"] = [r for r in doc["rows"] if (r["system"], r["tableau"], r["projection"]) != (system.name, tab, proj)]
        doc["rows"].append(row)
        now = row["rules"].get("now")
        print(f"{system.name} {tab}-{proj} h={h:g}: " + (row.get("left_out") or
              f"exponent {now['exponent']:.3f} ± {now['exponent_spread']:.3f}, it./step {now['iterations']:.2f}, "
              f"RMS {now['rms_end']:.1e}" + "".join(f"; {k} {row['rules'][k]['exponent']:.3f}"
                                                    for k in ("fixed", "extrapolate") if k in row["rules"]) +
              "".join(f"; {k} {row['rules'][k]['exponent']:.3f} ± {row['rules'][k]['exponent_spread']:.3f}, it./step "
                      f"{row['rules'][k]['iterations']:.2f}, mean/RMS {row['rules'][k]['mean_end'] / row['rules'][k]['rms_end']:+.2f}"
                      for k in EXTRA_RULES)) + f" ({time.perf_counter() - t:.0f} s)",
              flush=True)
        if args.json:
            Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
