"""sec:app_energy_drift: the energy error of GLRK3–6 with the symmetric projection on the barely
passing tokamak orbit, by the paper's 10-interval rule, with three coefficient sets and against an
extended-precision run.

    python scripts/studies/results_energy_drift.py double [--steps 1000000] [--json docs/figures/energy_drift.json]
    python scripts/studies/results_energy_drift.py extended GLRK5 [--steps 200000] [--json docs/figures/energy_drift_extended.json]
    python scripts/studies/results_energy_drift.py double-double GLRK3 GLRK4 GLRK5 GLRK6 [--steps 1250000] [--json docs/figures/energy_drift_double_double.json]

(R, Z, φ, u) = (2.5, 0, 0, 0.3425), h = 2.5 (app:guiding_centre_dynamics).  The run is split into 10
intervals of equal length; each interval's value is max |H − H₀|/|H₀| over it (sampled every
steps/4000 steps).  "growth" is the law and exponent α of e ∝ t^α that invariants.growth finds in the
sampled series (the project's one classifier; α: 0 for a bounded error, 1/2 for a random walk, as
Brouwer's law has round-off do, 1 for linear growth).

``double``: the compiled engine with the double + correction coefficients (what the engine uses,
the compensated technique of Hairer et al. 2008 that the section describes), the same rounded to
double, and a and b rounded with ā their exact symplectic conjugate (Antoñana et al. 2017:
eq:vprk_coefficients holds in floating point; ``Tableau.conjugated``).  The table gives each set's
floating-point symplecticity residual max |b_i ā_ij + b_j a_ji − b_i b_j|.

``extended``: the same orbit in x87 long double (64-bit significand, eps 1.1e-19, 2,000 times
smaller than double's) on the numpy engine of integrators/reference.py (the compiled engine's oracle,
the same equations; Newton to 4 eps of long double), beside the compiled double run of the same
steps.  Both energies are evaluated in long double.  "round-off part" is max |H(q_double) −
H(q_long double)|/|H₀| over each interval: the double run's energy error minus the reference's.  The
long-double run costs about 5–10 ms a step (Python overhead; the compiled engine 20–30 µs).
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import integrators
from integrators.integrate import integrate
from invariants.growth import growth_law

Q0 = (2.5, 0.0, 0.0, 0.3425)
H_STEP = 2.5


def intervals(e, every):
    """The paper's rule: the maximum of e over each tenth of the run; and how e grows, by the
    project's one classifier (invariants.growth on the whole sampled series): (maxima, exponent,
    law)."""
    e = np.asarray(e, dtype=float)
    chunks = np.array_split(e[1:], 10)
    maxima = np.array([c.max() for c in chunks])
    g = growth_law(np.arange(e.size) * float(every), e)
    return [float(f"{m:.3g}") for m in maxima], round(g.exponent, 2), g.law


def double_run(tab, steps, every):
    """The compiled engine in double: the states every ``every`` steps, wall time, broke down."""
    sy = integrators.system("guiding_centre_tokamak")
    t0 = time.perf_counter()
    sol = integrate(sy, np.array(Q0), tableau=tab, projection="symmetric", h=H_STEP, steps=steps, save_every=every)
    return sol.q[:, 0], time.perf_counter() - t0, bool(np.isfinite(sol.breakdown_time[0]))


def energy_error(q):
    sy = integrators.system("guiding_centre_tokamak")
    H = sy.H(np.asarray(q, dtype=np.longdouble))
    return np.abs(H - H[0]) / abs(H[0]), H


def double(args):
    every = max(1, args.steps // 4000)
    rows = []
    print("| tableau | coefficients | residual | max energy error in each tenth of the run | growth |")
    print("|---|---|---:|---|---|")
    for name in args.tableaus:
        tab = integrators.tableau(name)
        for label, t in (("double + correction", tab), ("double", tab.rounded()),
                         ("ā conjugate of the rounded a (Antoñana)", tab.conjugated())):
            q, wall, broke = double_run(t, args.steps, every)
            maxima, growth, law = intervals(energy_error(q)[0], every)
            r = dict(tableau=name, coefficients=label, residual=float(f"{t.float_symplectic_residual:.2g}"),
                     steps=args.steps, broke=broke, intervals=maxima, growth=growth, growth_law=law,
                     wall_s=round(wall, 1))
            rows.append(r)
            print(f"| {name} | {label} | {r['residual']:.1e} | {', '.join(f'{m:.1e}' for m in maxima)} "
                  f"| {law}, α = {growth:+.2f} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")


def beside_double(args):
    """For each tableau of ``args``: (name, tableau, sampling cadence, the --json results so far, the
    compiled double run of the orbit), the run a reference is compared with."""
    every = max(1, args.steps // 4000)
    out = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).exists() else {}
    for name in args.tableaus:
        tab = integrators.tableau(name)
        yield name, tab, every, out, double_run(tab, args.steps, every)


def extended(args):
    from integrators import reference
    sy = integrators.system("guiding_centre_tokamak")
    for name, tab, every, out, (qd, wall_d, broke_d) in beside_double(args):
        q = np.array([Q0], dtype=np.longdouble)
        st = reference.Stepper(sy, tab, "symmetric", H_STEP)
        S = reference.State(q, sy.theta(q), np.zeros_like(q), H_STEP, st.s)
        saved = [S.q[0].copy()]
        t0 = time.perf_counter()
        for k in range(1, args.steps + 1):
            reference.advance(st, S, k * H_STEP)
            if not S.live[0]:
                break
            if k % every == 0:
                saved.append(S.q[0].copy())
            if k % (args.steps // 20) == 0:
                print(f"{name} long double: step {k:,} of {args.steps:,}, {time.perf_counter() - t0:.0f} s",
                      flush=True)
        wall_x = time.perf_counter() - t0
        qx = np.array(saved)
        ex, Hx = energy_error(qx)
        ed, Hd = energy_error(qd[:len(qx)])
        part = np.abs(Hd - Hx) / abs(Hx[0])
        row = dict(tableau=name, steps=args.steps, completed=bool(S.live[0]), every=every,
                   newton_iterations_per_step=round(float(S.iterations[0]) / max(1, int(S.steps[0])), 2),
                   wall_long_double_s=round(wall_x, 1), wall_double_s=round(wall_d, 1))
        row["position_difference_at_end"] = float(f"{np.max(np.abs(qd[len(qx) - 1] - qx[-1].astype(float))):.3g}")
        record(args, out, name, row, every, (("double", ed), ("long_double", ex), ("round_off_part", part)))


def record(args, out, name, row, every, series):
    """The row's interval maxima and growth of each (key, series), printed, and merged into --json."""
    for key, e in series:
        row[key], row[key + "_growth"], row[key + "_growth_law"] = intervals(e, every)
        print(f"| {name} | {key} | {', '.join(f'{m:.1e}' for m in row[key])} | {row[key + '_growth_law']}, "
              f"α = {row[key + '_growth']:+.2f} |", flush=True)
    out[name] = row
    if args.json:     # re-read: another process may have added its tableau meanwhile
        merged = json.loads(Path(args.json).read_text()) if Path(args.json).exists() else {}
        merged[name] = row
        Path(args.json).write_text(json.dumps(merged, indent=1) + "\n")


def dd_energy(q2):
    """H in double-double at the points q2 (n, d, 2): (n, 2) pairs (hi, lo)."""
    from integrators.engine import scalars_dd
    return scalars_dd(integrators.system("guiding_centre_tokamak"), q2)[:, 0]


def dd_difference(a, b, scale):
    """|a − b|/|scale| of double-double arrays (n, 2): hi − hi (exact where they are close) plus lo − lo."""
    return np.abs((a[:, 0] - b[:, 0]) + (a[:, 1] - b[:, 1])) / abs(scale)


def double_double(args):
    """The orbit in double-double (the compiled kernel's third specialisation, ~32 digits) beside
    the compiled double run of the same steps; both energies evaluated in double-double.  'round-off
    part': |H(q_double) − H(q_dd)|/|H₀|, the double run's energy error less the reference's."""
    sy = integrators.system("guiding_centre_tokamak")
    for name, tab, every, out, (qd, wall_d, broke_d) in beside_double(args):
        t0 = time.perf_counter()
        sol = integrate(sy, np.array(Q0), tableau=tab, projection="symmetric",
                        h=H_STEP, steps=args.steps, save_every=every,
                        precision="double-double")
        wall_x = time.perf_counter() - t0
        q2 = np.stack([sol.q[:, 0], sol.q_lo[:, 0]], axis=-1)
        Hx = dd_energy(q2)
        Hd = dd_energy(np.stack([qd, np.zeros_like(qd)], axis=-1))
        H0 = Hx[0, 0]
        ex, ed, part = dd_difference(Hx, Hx[:1], H0), dd_difference(Hd, Hx[:1], H0), dd_difference(Hd, Hx, H0)
        row = dict(tableau=name, steps=args.steps, completed=not bool(np.isfinite(sol.breakdown_time[0])),
                   double_completed=not broke_d, every=every,
                   newton_iterations_per_step=round(float(sol.newton_iterations[0]) / max(1, int(sol.steps_taken[0])), 2),
                   wall_double_double_s=round(wall_x, 1), wall_double_s=round(wall_d, 1))
        row["position_difference_at_end"] = float(f"{np.max(np.abs(qd[-1] - (sol.q[-1, 0] + sol.q_lo[-1, 0]))):.3g}")
        record(args, out, name, row, every, (("double", ed), ("double_double", ex), ("round_off_part", part)))
        print(f"  {name}: double-double {wall_x:.0f} s, double {wall_d:.0f} s, "
              f"{row['newton_iterations_per_step']} Newton iterations a step", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("double", help="the compiled engine with three coefficient sets")
    d.add_argument("--tableaus", nargs="+", default=["GLRK3", "GLRK4", "GLRK5", "GLRK6"])
    d.add_argument("--steps", type=int, default=1_000_000)
    d.add_argument("--json")
    x = sub.add_parser("extended", help="a long-double run beside the double one")
    x.add_argument("tableaus", nargs="+")
    x.add_argument("--steps", type=int, default=200_000)
    x.add_argument("--json")
    dd = sub.add_parser("double-double", help="a double-double run beside the double one")
    dd.add_argument("tableaus", nargs="+")
    dd.add_argument("--steps", type=int, default=1_250_000)
    dd.add_argument("--json")
    args = ap.parse_args()
    {"double": double, "extended": extended, "double-double": double_double}[args.cmd](args)


if __name__ == "__main__":
    main()
