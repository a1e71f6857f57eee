"""Brouwer's law under another Newton rule, on the cases tests/test_brouwer.py holds the default to
(issue 97): the same starts, steps and fits, each rule side by side, one process.

    python scripts/studies/brouwer_rules_quick.py [--rules default,predicted_plain] [--cases all]
        [--json docs/figures/brouwer_rules_quick.json]

The rows of docs/figures/brouwer_rules_quick.json named ``predicted_plain`` were run with a trial
rule not kept (the predicted floor, docs/figures/trials_predicted_floor.diff: remainder = 2⁻⁶⁰,
settle=False, plain_first=True; docs/brouwer.md).

Rules are scripts/tools/speed_parts.py's RULES by name.  Cases (the tests' own functions):
``kepler1``/``kepler2`` (GLRK1 h = 0.0005, GLRK2 h = 0.002, unprojected, 16 starts, 2·10⁴ steps),
``vortices`` (GLRK2-midpoint, h = 0.1, 16 starts, 2·10⁴ steps), ``gc4`` (GLRK4-symmetric on the
symmetric guiding centre, h = 10, 16 starts, 5·10⁴ steps), ``gc6`` (GLRK6-standard, 64 starts,
5·10⁴ steps, slope and mean/RMS), ``momentum`` (the point vortices' angular momentum under
GLRK3-symmetric, 64 starts, 5·10⁴ steps, slope and mean/RMS).  The tests' bounds: 0.72 on the first
four, ≤ 0.55 and |mean/RMS| ≤ 0.4 on gc6, the momentum slope ≤ 0.7 and |mean/RMS| ≤ 0.4 (tests/test_brouwer.py).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "scripts" / "tools"))
import integrators                                    # noqa: E402
import test_brouwer as tb                             # noqa: E402
from speed_parts import RULES                         # noqa: E402


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
    ks, kq = tb.kepler()
    return {
        "kepler1": lambda t: (tb.exponent(ks, kq, "GLRK1", "none", 0.0005, 20_000, t), None),
        "kepler2": lambda t: (tb.exponent(ks, kq, "GLRK2", "none", 0.002, 20_000, t), None),
        "vortices": lambda t: (tb.exponent(pv, qv, "GLRK2", "midpoint", 0.1, 20_000, t), None),
        "gc4": lambda t: (tb.exponent(gc, circle(16), "GLRK4", "symmetric", 10.0, 50_000, t, every=500,
                                      exact_energy=True), None),
        "gc6": lambda t: tb.exponent(gc, circle(64), "GLRK6", "standard", 10.0, 50_000, t, every=500,
                                     exact_energy=True, with_bias=True),
        "momentum": lambda t: tb.momentum_drift(t),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rules", default="default,plain,unsettled,unsettled_plain")
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
