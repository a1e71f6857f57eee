"""Which details move the step at which an unprojected even-stage Gauss–Legendre run breaks down on
Lotka–Volterra (docs/stability.md, "Why GLRK2 breaks down at step 74,564 and not 250,000").

    python scripts/studies/stability_breakdown.py [--pairs GLRK2 GLRK4] [--steps 1000000] [--json out.json]

The paper's case: lotka_volterra_2d, q₀ = (1, 1), h = 0.1, no projection.  Variants, each a batch of
points advanced together (points are independent; the engine is bitwise the same for any batch):
  baseline        p₀ = ϑ(q₀), the double + correction coefficients
  p0 ± ulps       p₀ = ϑ(q₀) with each component moved by −2 … +2 ulps (24 random patterns)
  q0 ± ulps       q₀ moved by −2 … +2 ulps per component, p₀ = ϑ(q₀) (24 patterns)
  plain double    the same baseline with the coefficients rounded to double (corrections dropped)
For each: the breakdown step (or "completed") of every point, and the spread over the batch.

    python scripts/studies/stability_breakdown.py --newton-tol 8.9e-16 1e-12 1e-10 [--steps 150000]

runs GLRK2 instead on the numpy engine of integrators/reference.py (the compiled engine's oracle, same
rules) with Newton's convergence tolerance set to each value: max |δ|/scale ≤ tol (4 eps = 8.9e-16
in both engines).  With --engine compiled, this study and --stopping-rule run on the compiled
engine instead (its tolerances are runtime data, integrators.Tolerances; --pairs applies), in
seconds rather than hours.

    python scripts/studies/stability_breakdown.py --stopping-rule [--pairs GLRK2] [--steps 400000] [--json out.json]

the stopping rule, on the numpy engine: ours declares a point broken down when its Newton iteration
has not converged after 40 iterations, from the extrapolated guess and once more from a fresh one;
GeometricIntegrators.jl takes the step with whatever the iteration reached and stops only at a
non-finite value.  The run with the second rule reports the first step taken unconverged, how many
were, the step at which it stopped (a non-finite value, or a point outside the domain q > 0, where
GeometricIntegrators.jl would take the log of a negative number) and the energy error |ΔH|/|H₀|
in each tenth of the run.
"""
import argparse
import json
import time

import numpy as np

import integrators
from integrators.integrate import integrate


def ulps(x, k):
    """x moved by k ulps (k an integer array of x's shape)."""
    out = x.copy()
    for _ in range(int(np.max(np.abs(k))) if k.size else 0):
        step = np.abs(k) > 0
        out = np.where(step, np.nextafter(out, np.where(k > 0, np.inf, -np.inf)), out)
        k = k - np.sign(k)
    return out


def breakdown_steps(system, q0, p0, tab, h, steps):
    sol = integrate(system, q0, tableau=tab, projection="none", h=h, steps=steps, save_every=steps, p0=p0)
    return [int(n) + 1 if np.isfinite(t) else None for n, t in zip(sol.steps_taken, sol.breakdown_time)]


def summary(name, steps_list, total):
    done = [s for s in steps_list if s is not None]
    text = f"{len(steps_list) - len(done)} of {len(steps_list)} completed {total:,} steps"
    if done:
        text = (f"broke down at {min(done):,} … {max(done):,} (median {int(np.median(done)):,}); " + text)
    return dict(variant=name, steps=steps_list, summary=text)


def compiled_breakdown(system, name, q, h, steps, tolerances, every=1000):
    """(breakdown step or None, max |ΔH|/|H₀| over the outputs) of unprojected ``name`` on the compiled
    engine with Newton's ``tolerances`` (outputs every ``every`` steps)."""
    from integrators.engine import Engine, Hooks, march
    engine = Engine(system, integrators.tableau(name), "none", h, tolerances=tolerances)
    st = engine.state(q)
    H0, worst = system.H(q)[0], [0.0]

    def on_output(k):
        if st.live[0]:
            worst[0] = max(worst[0], float(abs(system.H(st.q)[0] - H0) / abs(H0)))

    def check():
        if not st.live[0]:
            raise StopIteration

    try:
        march(engine, st, 0, steps, every, Hooks(on_output, check=check))
    except StopIteration:
        pass
    broke = None if st.live[0] else int(round(st.breakdown_time[0] / h))
    return broke, worst[0]


def compiled_studies(args):
    """The Newton-tolerance and stopping-rule studies on the compiled engine (integrators.Tolerances)."""
    system = integrators.system("lotka_volterra_2d")
    h, q = 0.1, np.array([[1.0, 1.0]])
    out = []
    cases = [(f"Newton tol {tol:.1e}", integrators.Tolerances(tol=tol)) for tol in (args.newton_tol or [])]
    if args.stopping_rule:
        cases.append(("GeometricIntegrators.jl's rule", integrators.Tolerances(accept_unconverged=True)))
    for name in args.pairs:
        for label, tol in cases:
            t0 = time.perf_counter()
            broke, worst = compiled_breakdown(system, name, q, h, args.steps, tol)
            print(f"{name}-none compiled engine, {label}: "
                  + (f"broke down at step {broke:,}" if broke else f"completed {args.steps:,} steps")
                  + f", max |ΔH|/|H0| {worst:.2e}", flush=True)
            out.append(dict(tableau=name, case=label, tol=tol.tol, accept_unconverged=tol.accept_unconverged,
                            breakdown_step=broke, steps=args.steps, max_energy_error=worst,
                            wall_s=round(time.perf_counter() - t0, 1)))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


def newton_tolerance(args):
    """GLRK2 unprojected on the numpy engine with each Newton tolerance: the breakdown step."""
    from integrators import reference
    system = integrators.system("lotka_volterra_2d")
    h, q = 0.1, np.array([[1.0, 1.0]])
    out = []
    for tol in args.newton_tol:
        reference.newton.__kwdefaults__["tol"] = tol
        st = reference.Stepper(system, integrators.tableau("GLRK2"), "none", h)
        S = reference.State(q, system.theta(q), np.zeros_like(q), h, st.s)
        t0 = time.perf_counter()
        k = 0
        while S.live[0] and k < args.steps:
            k += 1
            reference.advance(st, S, k * h)
        row = dict(tol=tol, breakdown_step=None if S.live[0] else k, steps=args.steps,
                   wall_s=round(time.perf_counter() - t0, 1))
        print(f"GLRK2-none numpy engine, Newton tol {tol:.1e}: "
              + (f"broke down at step {k:,}" if not S.live[0] else f"completed {args.steps:,} steps"), flush=True)
        out.append(row)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


def stopping_rule(args):
    """Unprojected pairs on the numpy engine taking unconverged steps instead of stopping."""
    from integrators import reference
    system = integrators.system("lotka_volterra_2d")
    h, q = 0.1, np.array([[1.0, 1.0]])
    H0 = system.H(q)[0]
    out = []
    for name in args.pairs:
        st = reference.Stepper(system, integrators.tableau(name), "none", h, accept_unconverged=True)
        S = reference.State(q, system.theta(q), np.zeros_like(q), h, st.s)
        t0 = time.perf_counter()
        first, k, tenth = None, 0, max(1, args.steps // 10)
        worst, maxima = 0.0, []
        while S.live[0] and k < args.steps:
            k += 1
            reference.advance(st, S, k * h)
            if first is None and st.unconverged:
                first = k
            if k % 10 == 0 and S.live[0]:
                worst = max(worst, float(abs(system.H(S.q)[0] - H0) / abs(H0)))
            if k % tenth == 0:
                maxima.append(float(f"{worst:.3g}"))
                worst = 0.0
                print(f"{name}-none, GeometricIntegrators.jl's rule: step {k:,}, {st.unconverged} unconverged steps, "
                      f"max |ΔH|/|H0| {maxima[-1]:.2e}", flush=True)
        row = dict(tableau=name, h=h, q0=q[0].tolist(), steps=args.steps, first_unconverged_step=first,
                   unconverged_steps=st.unconverged, stopped_at_step=None if S.live[0] else k,
                   energy_error_per_tenth=maxima, wall_s=round(time.perf_counter() - t0, 1))
        print(row, flush=True)
        out.append(row)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", nargs="+", default=["GLRK2", "GLRK4"])
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--json")
    ap.add_argument("--newton-tol", nargs="+", type=float)
    ap.add_argument("--stopping-rule", action="store_true",
                    help="take unconverged steps (GeometricIntegrators.jl's rule) on the numpy engine")
    ap.add_argument("--engine", choices=["compiled", "numpy"], default="numpy",
                    help="engine of the --newton-tol and --stopping-rule studies (compiled: integrators.Tolerances)")
    args = ap.parse_args()
    if args.engine == "compiled" and (args.stopping_rule or args.newton_tol):
        return compiled_studies(args)
    if args.stopping_rule:
        return stopping_rule(args)
    if args.newton_tol:
        return newton_tolerance(args)
    system = integrators.system("lotka_volterra_2d")
    h, q = 0.1, np.array([1.0, 1.0])
    rng = np.random.default_rng(0)
    kp = rng.integers(-2, 3, (24, 2))
    kq = rng.integers(-2, 3, (24, 2))
    out = []
    for name in args.pairs:
        tab = integrators.tableau(name)
        plain = tab.rounded()
        p = system.theta(q)
        t0 = time.perf_counter()
        rows = [summary("baseline", breakdown_steps(system, q[None], p[None], tab, h, args.steps), args.steps),
                summary("p0 ± ulps", breakdown_steps(system, np.repeat(q[None], 24, 0), ulps(np.repeat(p[None], 24, 0), kp),
                                                     tab, h, args.steps), args.steps),
                summary("q0 ± ulps", breakdown_steps(system, ulps(np.repeat(q[None], 24, 0), kq), None, tab, h, args.steps),
                        args.steps),
                summary("plain double", breakdown_steps(system, q[None], p[None], plain, h, args.steps), args.steps)]
        for r in rows:
            print(f"{name}-none  {r['variant']:14s} {r['summary']}", flush=True)
        out.append(dict(tableau=name, h=h, q0=q.tolist(), wall_s=round(time.perf_counter() - t0, 1), rows=rows))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
