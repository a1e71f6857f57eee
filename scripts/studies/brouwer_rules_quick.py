"""Brouwer's law under another Newton rule, on the cases tests/test_brouwer.py holds the default to
(issue 97): the same starts, steps and fits, each rule side by side, one process.

    python scripts/studies/brouwer_rules_quick.py [--rules default,unsettled] [--cases all]
        [--json docs/figures/brouwer_rules_quick.json]

The rows of docs/figures/brouwer_rules_quick.json named ``plain``, ``unsettled_plain`` and
``predicted_plain`` were run with trial rules not kept (plain_first, the first Newton iteration's
residual in plain arithmetic, and the predicted floor: docs/figures/trials_predicted_floor.diff,
remainder = 2⁻⁶⁰, settle=False, plain_first=True; docs/brouwer.md); today's engine runs
``default`` and ``unsettled``.

Rules are scripts/tools/speed_parts.py's RULES by name.  Cases (the tests' measurements):
``kepler1``/``kepler2`` (GLRK1 h = 0.0005, GLRK2 h = 0.002, unprojected, 16 starts, 2·10⁴ steps),
``vortices`` (GLRK2-midpoint, h = 0.1, 16 starts, 2·10⁴ steps), ``gc4`` (GLRK4-symmetric on the
symmetric guiding centre, h = 10, 16 starts, 5·10⁴ steps), ``gc6`` (GLRK6-standard, 64 starts,
5·10⁴ steps, slope and mean/RMS), ``momentum`` (the point vortices' angular momentum under
GLRK3-symmetric, 64 starts, 5·10⁴ steps, slope and mean/RMS).  The tests' bounds: 0.72 on the first
four, ≤ 0.55 and |mean/RMS| ≤ 0.4 on gc6, the momentum slope ≤ 0.7 and |mean/RMS| ≤ 0.4 (tests/test_brouwer.py, whose measurements are
written out here: a script imports nothing of the tests).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts" / "tools"))
import integrators                                    # noqa: E402
from integrators.engine import scalars_dd             # noqa: E402
from speed_parts import RULES                         # noqa: E402

sys.path.insert(0, str(ROOT / "scripts" / "studies"))
import brouwer_law                                    # noqa: E402
from brouwer_law import energy_dd                     # noqa: E402


def broken(run):
    """No exponent from a run where points broke down."""
    n = int(np.isfinite(run.breakdown_time).sum())
    if n:
        raise SystemExit(f"brouwer_rules_quick: {n} points broke down; no exponent reported")


def roundoff(system, q0, pair, h, steps, tolerances, every, exact_energy):
    """(steps at the outputs, the round-off part of H there, one column a start): the run's H minus
    the double-double run's (brouwer_law.py's energy_dd), or minus H(q₀) with ``exact_energy`` (the
    pair keeps H exactly in exact arithmetic)."""
    tableau, projection = pair
    kw = dict(tableau=tableau, projection=projection, h=h, steps=steps, save_every=every)
    run = integrators.integrate(system, q0, tolerances=tolerances, **kw)
    broken(run)
    if exact_energy:
        ref = energy_dd(system, q0)
    else:
        dd = integrators.integrate(system, q0, precision="double-double", **kw)
        broken(dd)
        ref = energy_dd(system, dd.q, dd.q_lo)
    hi, lo = energy_dd(system, run.q)
    return np.arange(hi.shape[0]) * every, (hi - ref[0]) + (lo - ref[1])


def exponent(system, q0, tableau, projection, h, steps, tolerances, every=100, exact_energy=False,
             with_bias=False):
    """tests/test_brouwer.py's measurement: the log-slope of the RMS over the starts of the round-off
    part from step 10³ on, 30 log-spaced samples; with ``with_bias`` also its mean over the starts
    at the end / the RMS there."""
    at, r = roundoff(system, q0, (tableau, projection), h, steps, tolerances, every, exact_energy)
    rms = np.sqrt(np.mean(r ** 2, axis=1))
    use = np.unique(np.searchsorted(at, np.geomspace(1000, at[-1], 30)).clip(0, at.size - 1))
    slope = np.polyfit(np.log(at[use]), np.log(rms[use]), 1)[0]
    return (slope, r[-1].mean() / rms[-1]) if with_bias else slope


def kepler(n=16):
    """brouwer_law.py's Kepler system from the tests' starts (eccentricity 0.5, turned about the
    centre, all at the same phase of the orbit)."""
    system, _ = brouwer_law.kepler(n)
    phi = 2 * np.pi * np.arange(n) / n + 0.1
    c, s = np.cos(phi), np.sin(phi)
    return system, np.stack([0.5 * c, 0.5 * s, -np.sqrt(3) * s, np.sqrt(3) * c], 1)


def momentum_drift(tolerances, starts=64, steps=50_000, outputs=16):
    """Point vortices, GLRK3-symmetric, h = 0.1: the log-slope of the RMS over the starts of
    P(q_n) − P(q₀) against n (outputs 4 … 16) and its mean over the starts at the end / that RMS."""
    system, q0 = brouwer_law.degenerate("point_vortices", starts)   # the tests' starts
    sol = integrators.integrate(system, q0, tableau="GLRK3", projection="symmetric", h=0.1, steps=steps,
                                save_every=steps // outputs, tolerances=tolerances)
    broken(sol)
    n, m = sol.q.shape[:2]
    pair = scalars_dd(system, np.stack([sol.q.reshape(n * m, 4), np.zeros((n * m, 4))], -1))[:, 1, :]
    momentum = pair.reshape(n, m, 2)                  # P (hi, lo) at each output and start
    r = (momentum[..., 0] - momentum[0, :, 0]) + (momentum[..., 1] - momentum[0, :, 1])
    rms = np.sqrt(np.mean(r[1:] ** 2, axis=1))        # outputs 1 … outputs
    slope = np.polyfit(np.log(np.arange(4, outputs + 1)), np.log(rms[3:]), 1)[0]
    return slope, r[-1].mean() / rms[-1]


def cases():
    gc = integrators.system("guiding_centre_symmetric")
    c = np.asarray(gc.defaults["q0"], dtype=float)

    def circle(n):
        off = np.random.default_rng(70).standard_normal((n, 4))
        return c + 0.01 * np.abs(c).max() * off / np.linalg.norm(off, axis=1, keepdims=True)

    pv = integrators.system("point_vortices")
    cv = np.asarray(pv.defaults["q0"], dtype=float)
    off = np.random.default_rng(70).standard_normal((16, 4))
    qv = cv + 0.01 * off / np.linalg.norm(off, axis=1, keepdims=True)
    ks, kq = kepler()
    return {
        "kepler1": lambda t: (exponent(ks, kq, "GLRK1", "none", 0.0005, 20_000, t), None),
        "kepler2": lambda t: (exponent(ks, kq, "GLRK2", "none", 0.002, 20_000, t), None),
        "vortices": lambda t: (exponent(pv, qv, "GLRK2", "midpoint", 0.1, 20_000, t), None),
        "gc4": lambda t: (exponent(gc, circle(16), "GLRK4", "symmetric", 10.0, 50_000, t, every=500,
                                      exact_energy=True), None),
        "gc6": lambda t: exponent(gc, circle(64), "GLRK6", "standard", 10.0, 50_000, t, every=500,
                                     exact_energy=True, with_bias=True),
        "momentum": lambda t: momentum_drift(t),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rules", default="default,unsettled")
    ap.add_argument("--cases", default="all")
    ap.add_argument("--json")
    args = ap.parse_args()
    table = cases()
    names = list(table) if args.cases == "all" else args.cases.split(",")
    out = []
    for case in names:
        for rule in args.rules.split(","):
            t0 = time.time()
            slope, bias = table[case](integrators.Tolerances(**RULES[rule]))
            out.append(dict(case=case, rule=rule, slope=float(slope), bias=None if bias is None else float(bias),
                            seconds=time.time() - t0))
            print(f"{case:10s} {rule:22s} slope {slope:.3f}" + ("" if bias is None else f"  mean/RMS {bias:+.2f}")
                  + f"  ({time.time() - t0:.0f} s)", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(dict(date=time.strftime("%Y-%m-%d"), rows=out,
                                                   command="python scripts/studies/brouwer_rules_quick.py "
                                                           f"--rules {args.rules} --cases {args.cases}"), indent=1))


if __name__ == "__main__":
    main()
