"""The bias of one step's round-off on rotations, and the drift it makes (docs/brouwer.md, "The
residual's own rounding").

The symmetric guiding centre's x-y motion is a rotation that every projected pair below keeps r²
of exactly in exact arithmetic (their double-double runs: r² to 1e-30), so the change of r² in a
double step is round-off alone and needs no reference run.  Two measurements:

* ``step`` (the default): one double step from each of ``--points`` random points (r in [0.3, 0.7],
  any phase) of a 2-D rotation (``--after K``: the step after K steps, its guess from the
  predictor's history; the first step's is h·q̇ and its Newton takes more iterations), the relative change of r² per point: its mean over the points
  against its spread.  A step whose round-off has no bias gives |mean/spread| within 1/√n (±0.001
  for 10⁶ points).  Systems: ``exact`` (ϑ = (−y, x)/2, H = r²/64: every evaluation exact, only the
  engine's own arithmetic rounds), ``linear`` (ϑ = 5/8·(−y, x), H = (1 + r²)/100) and ``gc``
  (the guiding centre's x-y part, ϑ = (2 + r²)/4·(−y, x), H = (1 + r²)/100).
* ``long``: the built-in guiding_centre_symmetric (``--systems gc``, the default), ``--starts``
  starts spread over r in [0.3, 0.7], phase, z and u, 5·10⁴ steps: the exponent of the RMS over the
  starts of r²(t)/r²(0) − 1 (fitted from step 10³, ± the bootstrap spread over the starts) and its
  mean/RMS at the end (±1/√n for independent walks).  ``exact`` and ``linear`` are its 4-D
  counterparts whose ϑ is linear (ϑ = (−y/2, x/2, u, 0), H = r²/128 + u²/2: every evaluation exact;
  ϑ = (−5y/8, 5x/8, u, 0), H = (1 + r²)/100 + u²/2): a rotation of x, y (without the guiding
  centre's shear) and the same drift of z, with a Jacobian that does not change, so Newton's
  factors are exact.

The last column of both tables is the pair's double-double run's largest |r²/r²(0) − 1| (1,000 of
the points one step, or 4 of the starts 2,000 steps), in exact rationals: about 1e-30 where the pair
keeps r² in exact arithmetic; a larger value means the row measures the method, not round-off.

    python scripts/studies/brouwer_step_bias.py                        # about 1 minute (compiled)
    python scripts/studies/brouwer_step_bias.py --mode long --h 10,20  # about 10 minutes
    python scripts/studies/brouwer_step_bias.py --mode long --systems gc,exact,linear \
        --pairs GLRK6-standard,GLRK6-symmetric --h 10                  # about 4 minutes
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import sympy

import integrators
from integrators.ddouble import squared_norm
from integrators.systems import System

sys.path.insert(0, str(Path(__file__).resolve().parent))
from brouwer_law import fit   # noqa: E402

STEP_PAIRS = "GLRK1-symmetric,GLRK2-symmetric,GLRK2-standard,GLRK4-symmetric,SRK3-symmetric"
DD_POINTS = 1_000      # points (step) or starts (long) of the double-double check
DD_STEPS = 2_000
LONG_PAIRS = "GLRK1-midpoint,GLRK2-symmetric,GLRK3-midpoint,GLRK4-symmetric,GLRK4-standard"


def rotation(kind):
    """A 2-D rotation written as a degenerate system (module docstring)."""
    x, y = sympy.symbols("x y", real=True)
    if kind == "exact":
        return System("rotation_exact", [x, y], [-y / 2, x / 2], (x**2 + y**2) / 64)
    if kind == "linear":
        c = sympy.Rational(5, 8)
        return System("rotation_linear", [x, y], [-c * y, c * x], (1 + x**2 + y**2) / 100)
    if kind == "gc":
        rho = (2 + x**2 + y**2) / 4
        return System("rotation_gc", [x, y], [-y * rho, x * rho], (1 + x**2 + y**2) / 100)
    raise SystemExit(f"--systems: unknown {kind!r} (exact, linear, gc)")


def relative_change_of_r2(q0, q1):
    """r²(q1)/r²(q0) − 1 per point, r² = x² + y² of the first two coordinates, to about 10⁻³⁰."""
    (h0, l0), (h1, l1) = squared_norm(q0[..., :2]), squared_norm(q1[..., :2])
    return ((h1 - h0) + (l1 - l0)) / h0


def step_bias(kind, pair, h, n, tolerances=None, after=0):
    """One double step from n random points (``after`` > 0: the step after that many, taken with
    the predictor's history): mean and spread of the relative change of r²."""
    system = rotation(kind)
    rng = np.random.default_rng(11)
    r, ph = rng.uniform(0.3, 0.7, n), rng.uniform(0.0, 2 * np.pi, n)
    q0 = np.stack([r * np.cos(ph), r * np.sin(ph)], 1)
    tableau, projection = pair.split("-")
    sol = integrators.integrate(system, q0, tableau=tableau, projection=projection, h=h, steps=after + 1,
                                save_every=1, tolerances=tolerances)
    bad = int(np.isfinite(sol.breakdown_time).sum())
    v = relative_change_of_r2(sol.q[-2], sol.q[-1])
    return dict(system=kind, pair=pair, h=h, after=after, points=n, broke=bad, mean=float(v.mean()), spread=float(v.std()),
                bias=float(v.mean() / v.std()), iterations=float(sol.newton_iterations.sum() / (n * (after + 1))),
                exact=exactness(system, q0[:DD_POINTS], tableau, projection, h, 1))


def exactness(system, q0, tableau, projection, h, steps):
    """max |r²(q_n)/r²(q₀) − 1| of the pair's double-double run, in exact rationals: whether the pair
    keeps r² in exact arithmetic (double-double round-off: about 1e-30)."""
    sol = integrators.integrate(system, q0, tableau=tableau, projection=projection, h=h, steps=steps,
                                save_every=steps, precision="double-double")
    out = 0.0
    for k in range(q0.shape[0]):
        x, y = (Fraction(sol.q[-1, k, i]) + Fraction(sol.q_lo[-1, k, i]) for i in (0, 1))
        r0 = Fraction(q0[k, 0]) ** 2 + Fraction(q0[k, 1]) ** 2
        out = max(out, abs(float((x * x + y * y) / r0 - 1)))
    return out


def rotation4(kind):
    """guiding_centre_symmetric (``gc``) or a 4-D counterpart with a linear ϑ (module docstring)."""
    if kind == "gc":
        return integrators.system("guiding_centre_symmetric")
    x, y, z, u = sympy.symbols("x y z u", real=True)
    if kind == "exact":
        return System("rotation4_exact", [x, y, z, u], [-y / 2, x / 2, u, 0], (x**2 + y**2) / 128 + u**2 / 2)
    if kind == "linear":
        c = sympy.Rational(5, 8)
        return System("rotation4_linear", [x, y, z, u], [-c * y, c * x, u, 0],
                      (1 + x**2 + y**2) / 100 + u**2 / 2)
    raise SystemExit(f"--systems: unknown {kind!r} in long mode (gc, exact, linear)")


def long_drift(pair, h, n, steps, tolerances=None, kind="gc"):
    """guiding_centre_symmetric (or a 4-D counterpart, :func:`rotation4`) from n spread starts: the
    r² drift's exponent and mean/RMS."""
    system = rotation4(kind)
    rng = np.random.default_rng(7)
    r, ph = rng.uniform(0.3, 0.7, n), rng.uniform(0, 2 * np.pi, n)
    q0 = np.stack([r * np.cos(ph), r * np.sin(ph), rng.uniform(-1, 1, n), rng.uniform(0.3, 0.7, n)], 1)
    every = steps // 50
    tableau, projection = pair.split("-")
    sol = integrators.integrate(system, q0, tableau=tableau, projection=projection, h=h, steps=steps,
                                save_every=every, tolerances=tolerances)
    ok = ~np.isfinite(sol.breakdown_time)
    d = relative_change_of_r2(sol.q[0], sol.q)[:, ok]
    exponent, spread = fit(np.arange(d.shape[0]) * every, d)
    rms = float(np.sqrt(np.mean(d[-1] ** 2)))
    return dict(system=kind, pair=pair, h=h, starts=int(ok.sum()), steps=steps, exponent=round(exponent, 3),
                exact=exactness(system, q0[:4], tableau, projection, h, DD_STEPS),
                exponent_spread=round(spread, 3), mean_over_rms=float(d[-1].mean() / rms), rms_end=rms,
                iterations=float(sol.newton_iterations[ok].sum() / (steps * ok.sum())))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", choices=("step", "long"), default="step")
    ap.add_argument("--systems", default=None,
                    help="step mode: exact, linear, gc (default all three); long mode: gc (default), exact, linear")
    ap.add_argument("--pairs", default=None, help=f"default: {STEP_PAIRS} (step), {LONG_PAIRS} (long)")
    ap.add_argument("--h", default=None, help="comma-separated steps (default 10 (step), 10,20 (long))")
    ap.add_argument("--points", type=int, default=1_000_000, help="step mode")
    ap.add_argument("--after", type=int, default=0, help="step mode: measure the step after this many (0: the first)")
    ap.add_argument("--starts", type=int, default=256, help="long mode")
    ap.add_argument("--steps", type=int, default=50_000, help="long mode")
    ap.add_argument("--rule", default="{}", help="Tolerances fields as JSON, e.g. '{\"dither\": true}'")
    ap.add_argument("--json", default=None, help="write the rows here")
    args = ap.parse_args(argv)
    try:
        tolerances = integrators.Tolerances(**json.loads(args.rule))
    except (ValueError, TypeError) as e:
        raise SystemExit(f"--rule: {e}")
    rows = []
    if args.mode == "step":
        hs = [float(v) for v in (args.h or "10").split(",")]
        print("| system | pair | h | it./step | mean of Δ(r²)/r² | its spread | mean/spread (±1/√n) | double-double |")
        print("|---|---|---:|---:|---:|---:|---:|---:|")
        for kind in (args.systems or "exact,linear,gc").split(","):
            for h in hs:
                for pair in (args.pairs or STEP_PAIRS).split(","):
                    row = step_bias(kind, pair, h, args.points, tolerances, args.after)
                    rows.append(row)
                    note = f" ({row['broke']} broke down)" if row["broke"] else ""
                    print(f"| {kind} | {pair} | {h:g} | {row['iterations']:.2f} | {row['mean']:+.2e} | "
                          f"{row['spread']:.2e} | {row['bias']:+.4f} (±{1 / np.sqrt(args.points):.4f}){note} | {row['exact']:.0e} |",
                          flush=True)
    else:
        hs = [float(v) for v in (args.h or "10,20").split(",")]
        print("| system | pair | h | it./step | exponent | mean/RMS at the end (±1/√n) | RMS at the end | double-double |")
        print("|---|---|---:|---:|---|---:|---:|---:|")
        for kind, h, pair in itertools.product((args.systems or "gc").split(","), hs,
                                               (args.pairs or LONG_PAIRS).split(",")):
            t = time.perf_counter()
            row = long_drift(pair, h, args.starts, args.steps, tolerances, kind)
            row["seconds"] = round(time.perf_counter() - t, 1)
            rows.append(row)
            print(f"| {kind} | {pair} | {h:g} | {row['iterations']:.2f} | {row['exponent']:.2f} ± {row['exponent_spread']:.2f} | "
                  f"{row['mean_over_rms']:+.2f} (±{1 / np.sqrt(row['starts']):.2f}) | {row['rms_end']:.2e} | "
                  f"{row['exact']:.0e} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(dict(mode=args.mode, rule=json.loads(args.rule), rows=rows), indent=1))


if __name__ == "__main__":
    main()
