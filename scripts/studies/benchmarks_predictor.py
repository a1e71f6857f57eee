"""The stage predictor with defects against the engine's rule before it, side by side in one run
(docs/benchmarks.md, "The stage predictor").

    python scripts/studies/benchmarks_predictor.py [--points 10000] [--out docs/figures/benchmark_predictor.json]
    python scripts/studies/benchmarks_predictor.py --flops   # only the flop counts of an iteration and a Jacobian
    python scripts/studies/benchmarks_predictor.py --paper   # only the engine on paper_poincare's points
    python scripts/studies/benchmarks_predictor.py --floor   # only Jacobians of one orbit against the refresh floor
    python scripts/studies/benchmarks_predictor.py --trust-floor   # only the default (trust_floor=1e-7) against 0
    python scripts/studies/benchmarks_predictor.py --calls   # only calls of 10 steps, outputs recorded, one call
    python scripts/studies/benchmarks_predictor.py --four-stages   # only a looser tol for four stages (not kept)
    python scripts/studies/benchmarks_predictor.py --roundoff   # only the round-off against double-double

The rules run in this process on the same points, one thread, alternating which goes first:
``Tolerances(predictor="extrapolate")`` ("before": the last step's stages extrapolated, the factors
carried from the last step, refreshed after an iteration that contracted by less than 0.01: the
engine's bits before issue 55), the default ``Tolerances()`` ("defects": that guess corrected by
the extrapolated defects of the last steps, by a polynomial or a fitted linear recurrence; a
Jacobian at the guess, where the last guess was good to 10⁻³ but not to 10⁻⁷ (the trust floor), in
pairs of at most 16 Newton unknowns, the carried factors in larger pairs; refreshed only above the
refresh floor; at least two iterations a step), the Jacobian schedule ("schedule":
``jacobian_every=2``, those Jacobians at every second step by number only) and the other choice
of Jacobian ("other": ``Tolerances(trust_max_unknowns=0)``, the carried factors alone, for the
pairs of at most 16 unknowns; ``Tolerances(trust_max_unknowns=64)``, a Jacobian at the trusted
guess, above, where the default carries the factors).
guiding_centre_symmetric, h = 10:

* iterations: mean Newton iterations (residual evaluations) and Jacobians per point-step, 32 points
  near the default loop, 50 steps from the start (the first steps, with a shorter history,
  included), and one orbit, one point per lane, and the Newton work: iterations + Jacobians × the
  pair's Jacobian in iterations (the flop counts below);
* speed: point-steps per second of 10⁴ points near the loop and 10⁴ spread over its bounding box,
  50 steps from the start in one call, best of 2 in each of 2 rounds; one orbit, 2,000 steps;
* robustness: iterations and breakdowns at larger steps and on two other systems;
* drift: how far 64 loop points end from the old rule's after 300 steps (round-off, not speed);
* flops per point-step as coded: Newton iterations × the residual-and-solve count of
  scripts/studies/engine_lanes.py, plus Jacobians × a count of the Jacobian's extra work (second
  derivatives, contractions, assembly, LU), both read off the generated point function and the
  kernel's loops (a lower bound: selects, loads and bookkeeping are not counted).
"""
import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

import integrators
import invariants
from integrators.engine import set_threads

from integrators.costmodel import flops_per_iteration, jacobian_flops, newton_per_step, protocol_points

ROOT = Path(__file__).resolve().parents[2]
LOOP32 = invariants.loop("guiding_centre", 32)            # the protocol's 32 points, before their offsets
RULES = {"before": integrators.Tolerances(predictor="extrapolate"), "defects": integrators.Tolerances(),
         "schedule": integrators.Tolerances(jacobian_every=2), "other": None}
PAIRS = (("GLRK1", "none"), ("GLRK2", "symmetric"), ("GLRK2", "standard"), ("SRK3", "symmetric"),
         ("SRK3", "none"), ("SRK3", "symplectic"), ("GLRK4", "symmetric"), ("GLRK6", "symmetric"))


def point_sets(n):
    rng = np.random.default_rng(1)
    q0 = invariants.loop("guiding_centre", n)
    lo, hi = q0.min(0), q0.max(0)
    return {"loop": q0 + 1e-3 * rng.standard_normal(q0.shape), "box": lo + (hi - lo) * rng.random(q0.shape)}


def engine(sy, tab, proj, h, rule):
    tol = RULES[rule]
    if rule == "other":                   # the choice of Jacobian the default does not make for this pair
        nz = integrators.Engine(sy, integrators.tableau(tab), proj, h).nz
        fresh = nz <= integrators.Tolerances().trust_max_unknowns
        tol = integrators.Tolerances(trust_max_unknowns=0 if fresh else 64)
    return integrators.Engine(sy, integrators.tableau(tab), proj, h, tolerances=tol)


def iterations(sy):
    q0 = point_sets(32)["loop"]
    rows = []
    for tab, proj in PAIRS:
        row = dict(pair=f"{tab}-{proj}")
        for rule in RULES:
            e = engine(sy, tab, proj, 10.0, rule)
            cost = jacobian_flops(sy, e.tableau, e) / flops_per_iteration(sy, e.tableau, e)
            for key, pts in (("", q0), ("_orbit", q0[:1])):
                st = e.state(pts)
                use = e.advance(st, 1, 50, lanes=1)
                its, jac = st.iterations.sum() / st.steps.sum(), use.jacobians / st.steps.sum()
                row[rule + key] = its
                row[rule + key + "_jacobians"] = jac
                row[rule + key + "_work"] = its + cost * jac
        rows.append(row)
        print(row, flush=True)
    return rows


def rate(e, q0, steps, lanes=None):
    best = np.inf
    for _ in range(2):
        st = e.state(q0)
        t = time.perf_counter()
        use = e.advance(st, 1, steps, lanes=lanes)
        best = min(best, time.perf_counter() - t)
    return q0.shape[0] * steps / best, st.iterations.sum() / st.steps.sum(), use.jacobians / max(use.rounds, 1)


def speed(sy, n):
    sets = point_sets(n)
    rows = []
    cases = [(tab, proj, name) for tab, proj in PAIRS for name in sets]
    cases += [(tab, "symmetric", "orbit") for tab in ("GLRK2", "GLRK4", "GLRK6")] + [("GLRK1", "none", "orbit")]
    for tab, proj, name in cases:
        res = {rule: [] for rule in RULES}
        for rnd in range(2):
            for rule in (list(RULES) if rnd == 0 else list(RULES)[::-1]):
                e = engine(sy, tab, proj, 10.0, rule)
                if name == "orbit":
                    res[rule].append(rate(e, sets["loop"][:1], 2000, lanes=1))
                else:
                    e.warm(sets[name])
                    res[rule].append(rate(e, sets[name], 50))
        row = dict(pair=f"{tab}-{proj}", points=name)
        for rule in RULES:
            row[rule] = max(r[0] for r in res[rule])
            row[rule + "_iterations"] = res[rule][0][1]
            row[rule + "_jacobians"] = res[rule][0][2]
            e = engine(sy, tab, proj, 10.0, rule)
            row[rule + "_flops"] = (flops_per_iteration(sy, e.tableau, e) * row[rule + "_iterations"]
                                    + jacobian_flops(sy, e.tableau, e) * row[rule + "_jacobians"])
        row["ratio"] = row["defects"] / row["before"]
        row["ratio_schedule"] = row["schedule"] / row["before"]
        row["ratio_other"] = row["other"] / row["before"]
        rows.append(row)
        print(f"{row['pair']:18s} {name:5s} before {row['before']:11,.0f}  defects {row['defects']:11,.0f} "
              f"{row['ratio']:.2f}x  schedule {row['ratio_schedule']:.2f}x  other {row['ratio_other']:.2f}x  it. {row['before_iterations']:.2f} -> "
              f"{row['defects_iterations']:.2f} / {row['other_iterations']:.2f}  J/step {row['before_jacobians']:.2f} -> "
              f"{row['defects_jacobians']:.2f} / {row['other_jacobians']:.2f}  flop/step {row['before_flops']:.0f} -> "
              f"{row['defects_flops']:.0f} / {row['other_flops']:.0f}", flush=True)
    return rows


def drift():
    """Round-off, not speed: 64 points on the default loop, 300 steps, max |q − q_before| for the
    default, with a Jacobian at every trusted guess, and with the refresh horizon
    (``refresh_horizon=-1``, the carried factors everywhere: the rule measured and not kept)."""
    q0 = invariants.loop("guiding_centre", 64)
    sy = integrators.system("guiding_centre_symmetric")
    rules = {"before": RULES["before"], "defects": RULES["defects"],
             "fresh": integrators.Tolerances(trust_max_unknowns=64),
             "horizon": integrators.Tolerances(trust_max_unknowns=0, refresh_horizon=-1)}
    rows = []
    for tab, proj in (("GLRK1", "symmetric"), ("GLRK2", "symmetric"), ("GLRK2", "standard"), ("SRK3", "midpoint")):
        q = {}
        for rule, tol in rules.items():
            e = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0, tolerances=tol)
            st = e.state(q0)
            e.advance(st, 1, 300)
            q[rule] = st.q
        row = dict(pair=f"{tab}-{proj}", **{r: float(np.max(np.abs(q[r] - q["before"]))) for r in rules if r != "before"})
        rows.append(row)
        print(row, flush=True)
    return rows


def paper_points():
    """The engine alone on half the points of paper_poincare (every other point of the 2,000-point
    loop and the 100 × 100 surface), its 15 pairs, 200 steps as the driver runs them between
    checkpoints (one call recording the outputs every 10 steps), one thread, best of 2: µs and
    iterations per point-step under the old rule, the default, the Jacobian schedule
    (``jacobian_every=2``) and the carried factors (``trust_max_unknowns=0``)."""
    sy = integrators.system("guiding_centre_symmetric")
    pts = np.concatenate([invariants.loop("guiding_centre", 2000),
                          invariants.surface("guiding_centre", 100, 100).reshape(-1, 4)])[::2]
    rules = {"before": RULES["before"], "defects": RULES["defects"], "schedule": RULES["schedule"],
             "carried": integrators.Tolerances(trust_max_unknowns=0)}
    total = dict.fromkeys(rules, 0.0)
    rows = []
    for tab in ("GLRK1", "GLRK2", "SRK3"):
        for proj in ("none", "standard", "symmetric", "symplectic", "midpoint"):
            row = dict(pair=f"{tab}-{proj}")
            for rule, tol in rules.items():
                e = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0, tolerances=tol)
                e.warm(pts)
                best = np.inf
                for _ in range(2):
                    st = e.state(pts)
                    t = time.perf_counter()
                    e.advance_outputs(st, 1, 200, 10)
                    best = min(best, time.perf_counter() - t)
                total[rule] += best
                row[rule] = best / (len(pts) * 200) * 1e6
                row[rule + "_iterations"] = st.iterations.sum() / st.steps.sum()
            rows.append(row)
            print(f"{row['pair']}: " + ", ".join(f"{r} {row[r]:.3f} us {row[r + '_iterations']:.2f} it." for r in rules)
                  + f"; defects / before {row['before'] / row['defects']:.2f}x", flush=True)
    print("seconds, all 15 pairs: " + ", ".join(f"{r} {v:.2f}" for r, v in total.items()))
    return rows


def trust_floor():
    """The default (trust_floor=1e-7) against Tolerances(trust_floor=0) (the refresh floor alone), one thread,
    best of 2: µs a point-step on half of paper_poincare's points (200 steps as the driver runs
    them) and on 10⁴ points near the loop and spread over its box (50 steps from the start), and
    the protocol's iterations and Newton work (32 points, one a lane); the rule before issue 55
    (``predictor="extrapolate"``) beside them for scale."""
    sy = integrators.system("guiding_centre_symmetric")
    paper = np.concatenate([invariants.loop("guiding_centre", 2000),
                            invariants.surface("guiding_centre", 100, 100).reshape(-1, 4)])[::2]
    sets = dict(paper=(paper, 200), **{k: (v, 50) for k, v in point_sets(10000).items()})
    for tab, proj in (("GLRK1", "none"), ("GLRK2", "none"), ("SRK3", "none"), ("GLRK2", "symplectic"),
                      ("SRK3", "symplectic"), ("GLRK2", "standard"), ("GLRK2", "symmetric"), ("SRK3", "symmetric")):
        row = []
        rules = {f"trust_floor {fl:g}": integrators.Tolerances(trust_floor=fl)
                 for fl in (0.0, integrators.Tolerances().trust_floor)}
        rules["before issue 55"] = RULES["before"]
        for label, tol in rules.items():
            its, _, work = newton_per_step(tab, proj, protocol_points(LOOP32), tol, lanes=1)
            e = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0, tolerances=tol)
            speed = {}
            for name, (pts, steps) in sets.items():
                best = np.inf
                for _ in range(2):
                    st = e.state(pts)
                    t = time.perf_counter()
                    e.advance_outputs(st, 1, steps, 10)
                    best = min(best, time.perf_counter() - t)
                speed[name] = best / (len(pts) * steps) * 1e6
            row.append(f"{label}: protocol {its:.2f} it. work {work:.2f}; "
                       + ", ".join(f"{k} {v:.3f} us" for k, v in speed.items()))
        print(f"{tab}-{proj}: " + " | ".join(row), flush=True)


def double_double_q(sy, tab, proj, h, q0, steps):
    """q after ``steps`` steps of a double-double run of the pair (hi + lo rounded to double): the
    reference for the round-off of a double run of the same method."""
    e = integrators.Engine(sy, integrators.tableau(tab), proj, h, precision="double-double")
    st = e.state(q0)
    e.advance(st, 1, steps)
    q = np.asarray(st.q)
    return q[..., 0] + q[..., 1]


def four_stages():
    """A looser Newton tolerance for tableaus of four stages or more, measured and not kept
    (docs/benchmarks-history.md): ``Tolerances(tol=k·eps)`` for k = 4 (the default), 8 and 16.
    GLRK4- and GLRK6-symmetric on the guiding centre: mean iterations a point-step (32 protocol
    points and one orbit, one point a lane, 50 steps) and the error after 300 steps of 64 loop
    points against a double-double run of the same method (max and median over the points); then
    point vortices (32 points near the convergence study's q₀, T = 2, h = 2⁻⁷ and 2⁻⁹), the error at
    T against double-double (median and max over the points) for 4 and 8 eps."""
    eps = np.finfo(np.float64).eps
    truth = double_double_q
    sy = integrators.system("guiding_centre_symmetric")
    q0 = invariants.loop("guiding_centre", 64)
    for tab in ("GLRK4", "GLRK6"):
        ref = truth(sy, tab, "symmetric", 10.0, q0, 300)
        rules = {"before": integrators.Tolerances(predictor="extrapolate"),
                 **{f"{k} eps": integrators.Tolerances(tol=k * eps) for k in (4, 8, 16)}}
        for name, tol in rules.items():
            its = newton_per_step(tab, "symmetric", protocol_points(LOOP32), tol, lanes=1)[0]
            orbit = newton_per_step(tab, "symmetric", protocol_points(invariants.loop("guiding_centre", 3))[:1], tol, lanes=1)[0]
            e = integrators.Engine(sy, integrators.tableau(tab), "symmetric", 10.0, tolerances=tol)
            st = e.state(q0)
            e.advance(st, 1, 300)
            err = np.abs(st.q - ref)
            print(f"{tab}-symmetric {name:7s}: iterations {its:.2f}, one orbit {orbit:.2f}; error against "
                  f"double-double after 300 steps: max {err.max():.2e}, median {np.median(err):.2e}", flush=True)
    sy = integrators.system("point_vortices")
    q0 = np.array([1.0, 0.1, 1.0, -0.1]) + 1e-3 * np.random.default_rng(3).standard_normal((32, 4))
    for tab, proj in (("GLRK4", "midpoint"), ("LobIIIB4", "midpoint"), ("GLRK5", "midpoint"), ("GLRK4", "symmetric"),
                      ("GLRK6", "symmetric"), ("GLRK4", "standard")):
        for h in (2.0 ** -7, 2.0 ** -9):
            steps = int(round(2 / h))
            ref = truth(sy, tab, proj, h, q0, steps)
            row = []
            for k in (4, 8):
                e = integrators.Engine(sy, integrators.tableau(tab), proj, h, tolerances=integrators.Tolerances(tol=k * eps))
                st = e.state(q0)
                e.advance(st, 1, steps)
                err = np.abs(st.q - ref).max(axis=1)
                row.append(f"{k} eps: median {np.median(err):.1e}, max {err.max():.1e}, "
                           f"{st.iterations.sum() / st.steps.sum():.2f} it.")
            print(f"point vortices {tab}-{proj} h = 2^{int(np.log2(h))}: " + " | ".join(row), flush=True)


def roundoff():
    """Round-off against double-double: point vortices, 32 points near the convergence study's q₀,
    T = 2, h = 2⁻⁷ and 2⁻⁹; max over each point's coordinates of |q − q_dd| at T (q_dd a
    double-double run of the same method), median and max over the points, for the rule before
    issue 55, the default with trust_floor = 0 and the default."""
    sy = integrators.system("point_vortices")
    q0 = np.array([1.0, 0.1, 1.0, -0.1]) + 1e-3 * np.random.default_rng(3).standard_normal((32, 4))
    rules = {"before": integrators.Tolerances(predictor="extrapolate"),
             "trust_floor 0": integrators.Tolerances(trust_floor=0.0), "default": integrators.Tolerances()}
    for tab, proj in (("GLRK1", "symmetric"), ("GLRK2", "none"), ("GLRK2", "symmetric"), ("GLRK2", "midpoint"),
                      ("GLRK3", "midpoint"), ("SRK3", "standard"), ("SRK3", "symplectic")):
        for h in (2.0 ** -7, 2.0 ** -9):
            steps = int(round(2 / h))
            ref = double_double_q(sy, tab, proj, h, q0, steps)
            row = []
            for name, tol in rules.items():
                e = integrators.Engine(sy, integrators.tableau(tab), proj, h, tolerances=tol)
                st = e.state(q0)
                e.advance(st, 1, steps)
                err = np.abs(st.q - ref).max(axis=1)
                row.append(f"{name}: median {np.median(err):.1e}, max {err.max():.1e}")
            print(f"{tab}-{proj} h = 2^{int(np.log2(h))}: " + " | ".join(row), flush=True)


def calls():
    """What a call costs: half of paper_poincare's points, 200 steps in 20 calls of 10 (its output
    cadence), in one call that records the 19 outputs inside it (Engine.advance_outputs, what the
    driver's march does between checkpoints) and in one plain call, one thread, µs a point-step, the
    default and the old rule, best of 2 rounds: a call moves every point's LU factors and predictor
    table into the lanes and back; recorded outputs move q, p, Λ out only.  The outputs of the
    recording call are checked bitwise against the 20 calls'."""
    sy = integrators.system("guiding_centre_symmetric")
    pts = np.concatenate([invariants.loop("guiding_centre", 2000),
                          invariants.surface("guiding_centre", 100, 100).reshape(-1, 4)])[::2]
    for tab in ("GLRK1", "GLRK2", "SRK3"):
        row = []
        for rule in ("defects", "before"):
            e = integrators.Engine(sy, integrators.tableau(tab), "symmetric", 10.0, tolerances=RULES[rule])
            e.warm(pts)
            best, seen = {}, {}
            for _ in range(2):
                for how in ("20 calls", "outputs", "1 call"):
                    st = e.state(pts)
                    t = time.perf_counter()
                    if how == "20 calls":
                        got = []
                        for k in range(20):
                            e.advance(st, 1 + 10 * k, 10)
                            got.append(st.q.copy())
                    elif how == "outputs":
                        _, inside = e.advance_outputs(st, 1, 200, 10)
                        got = [o.q for _, o in inside] + [st.q]
                    else:
                        e.advance(st, 1, 200)
                        got = [st.q]
                    dt = time.perf_counter() - t
                    best[how] = min(best.get(how, np.inf), dt / (len(pts) * 200) * 1e6)
                    seen[how] = got
            same = all(np.array_equal(a, b) for a, b in zip(seen["20 calls"], seen["outputs"]))
            assert same and np.array_equal(seen["1 call"][0], seen["outputs"][-1]), "outputs differ"
            row.append(f"{rule}: " + ", ".join(f"{how} {v:.3f} us" for how, v in best.items()))
        print(f"{tab}-symmetric: " + "; ".join(row) + " (outputs bitwise the 20 calls')", flush=True)


def floor_orbit():
    """One orbit of GLRK4- and GLRK6-symmetric near the loop, 300 steps: Jacobians and iterations per step
    with the refresh floor at 0 (the old refresh rule), 1e-14, 1e-13 and 1e-12 (the default)."""
    sy = integrators.system("guiding_centre_symmetric")
    q0 = point_sets(3)["loop"][:1]
    for floor in (0.0, 1e-14, 1e-13, 1e-12):
        row = []
        for tab in ("GLRK4", "GLRK6"):
            e = integrators.Engine(sy, integrators.tableau(tab), "symmetric", 10.0,
                                   tolerances=integrators.Tolerances(refresh_floor=floor))
            st = e.state(q0)
            use = e.advance(st, 1, 300, lanes=1)
            row.append(f"{tab}-symmetric {st.iterations.sum() / st.steps.sum():.2f} it., "
                       f"{use.jacobians / st.steps.sum():.2f} Jacobians a step")
        print(f"refresh_floor {floor:g}: " + "; ".join(row), flush=True)


def robustness():
    rng = np.random.default_rng(1)
    cases = [("guiding_centre_symmetric", h, invariants.loop("guiding_centre", 128)
              + 1e-3 * rng.standard_normal((128, 4)), 200) for h in (10.0, 40.0, 100.0)]
    cases += [("lotka_volterra_2d", h, np.array([[1.0, 1.0]]) + 0.5 * rng.random((64, 2)), 2000) for h in (0.1, 0.5)]
    cases += [("point_vortices", 0.1, np.array([[1, 0.1, 1, -0.1]]) + 1e-3 * rng.standard_normal((64, 4)), 500)]
    rows = []
    for name, h, q0, steps in cases:
        sy = integrators.system(name)
        for tab, proj in (("GLRK2", "symmetric"), ("GLRK1", "none"), ("GLRK2", "none"), ("SRK3", "symplectic")):
            row = dict(system=name, h=h, steps=steps, pair=f"{tab}-{proj}")
            for rule in RULES:
                e = engine(sy, tab, proj, h, rule)
                st = e.state(q0)
                e.advance(st, 1, steps)
                row[rule] = st.iterations.sum() / max(st.steps.sum(), 1)
                row[rule + "_broke"] = int((~st.live).sum())
            rows.append(row)
            print(row, flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10000)
    ap.add_argument("--out", default=str(ROOT / "docs/figures/benchmark_predictor.json"))
    ap.add_argument("--flops", action="store_true", help="print the flop counts as coded and stop")
    ap.add_argument("--paper", action="store_true", help="the engine alone on paper_poincare's points, and stop")
    ap.add_argument("--floor", action="store_true", help="Jacobians of one orbit against the refresh floor, and stop")
    ap.add_argument("--trust-floor", action="store_true", help="the default trust_floor against 0, and stop")
    ap.add_argument("--four-stages", action="store_true",
                    help="tol at 4, 8 and 16 eps for four stages or more: iterations and the error against "
                         "double-double (measured, not kept), and stop")
    ap.add_argument("--roundoff", action="store_true",
                    help="round-off against double-double on point vortices, the rules side by side, and stop")
    ap.add_argument("--calls", action="store_true",
                    help="a point-step in calls of 10 steps, in one call recording outputs and in one call, and stop")
    a = ap.parse_args()
    set_threads(1)
    sy = integrators.system("guiding_centre_symmetric")
    if a.paper:
        paper_points()
        return
    if a.floor:
        floor_orbit()
        return
    if a.four_stages:
        four_stages()
        return
    if a.roundoff:
        roundoff()
        return
    if a.calls:
        calls()
        return
    if a.trust_floor:
        trust_floor()
        return
    if a.flops:
        for tab, proj in PAIRS:
            e = engine(sy, tab, proj, 10.0, "defects")
            it, jac = flops_per_iteration(sy, e.tableau, e), jacobian_flops(sy, e.tableau, e)
            print(f"{tab}-{proj}: iteration {it} flop, Jacobian {jac} flop more: {jac / it:.1f} iterations")
        return
    t0 = time.perf_counter()
    out = dict(date=time.strftime("%Y-%m-%d"), machine=platform.processor() or platform.machine(),
               iterations=iterations(sy), speed=speed(sy, a.points), robustness=robustness(), drift=drift())
    out["seconds"] = time.perf_counter() - t0
    Path(a.out).write_text(json.dumps(out, indent=1, default=float))
    print(f"wrote {a.out} ({out['seconds']:.0f} s)")


if __name__ == "__main__":
    main()
