"""Lanes that take up the next point, against fixed groups of lanes, where points break down (issue 43).

    python scripts/lane_refill.py --base 03aa7b5 [--rounds 5] [--out docs/figures/lane_refill.json]

The earlier commit (fixed groups: a group of W consecutive points runs until its last live point
is done, and a point that broke down keeps its lane) is checked out beside this tree as in
scripts/side_by_side.py, and each round runs one child per tree, alternating which goes first.
What a child measures, one thread: guiding_centre_tokamak, GLRK2-symmetric, 4,000 points
q0·(1 + σξ) with ξ standard normal (seed 1), at the system's h = 2.5 and at 4× and 16× it, 200 steps
in 10 calls of 20 (as the driver advances between outputs), after one warm-up step of a copy.
Larger h and σ make more points break down (leave the domain or stop converging); the others go on.

Reported per case: the points still live at the end, successful point-steps per second (median
over the rounds of each tree) and whether the two trees' final states are bitwise equal.  Timings on
a shared machine move by ±15 % from run to run, so this tree also counts the work, which does not
move: the group steps and group Newton iterations the kernel reports
(:class:`integrators.engine.LaneUse`; the earlier commit reports none), with lanes refilled from
blocks of 64 and with fixed groups (blocks of W = 8: nothing to refill from within a call), and
the occupancies point-steps / (W · group steps) and point iterations / (W · group iterations).
"""
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from side_by_side import arguments, run_rounds, write  # noqa: E402

CASES = [(sigma, factor) for sigma in (0.1, 0.3) for factor in (1, 4, 16)]
BLOCK = 64          # integrators.engine.BLOCK
FIELDS = ("q", "p", "Lam", "iterations", "steps", "live", "breakdown_time")


def measure(dump):
    """Runs in a child, with integrators from the tree under test: JSON on stdout, states to ``dump``."""
    import integrators
    from integrators.engine import set_threads
    set_threads(1)
    counts = hasattr(integrators.engine, "LaneUse")        # the earlier commit reports no work
    sy = integrators.system("guiding_centre_tokamak")
    q0 = np.array(sy.defaults["q0"])
    out, states = {}, {}
    for sigma, factor in CASES:
        q = q0 * (1 + sigma * np.random.default_rng(1).standard_normal((4000, sy.d)))
        eng = integrators.Engine(sy, integrators.tableau("GLRK2"), "symmetric", sy.defaults["h"] * factor)
        eng.advance(eng.state(q[:64]), 1, 1)                   # compile outside the clock
        key = f"sigma {sigma} h x{factor}"
        for block in ((BLOCK, "W") if counts else (BLOCK,)):
            st = eng.state(q)
            work = np.zeros(2, dtype=np.int64)
            t = time.perf_counter()
            for c in range(10):
                use = eng.advance(st, 1 + 20 * c, 20, block=8 if block == "W" else block)
                if counts:
                    work += use[1:]
            dt = time.perf_counter() - t
            done, its = int(st.steps.sum()), int(st.iterations.sum())
            row = out.setdefault(key, dict(live=int(st.live.sum()), point_steps=done, point_iterations=its))
            if block == BLOCK:
                row["rate"] = done / dt
                for f in FIELDS:
                    states[f"{key}/{f}"] = getattr(st, f)
            if counts:
                row[f"block {block}"] = dict(group_steps=int(work[0]), group_iterations=int(work[1]),
                                             step_occupancy=done / (8 * work[0]),
                                             iteration_occupancy=its / (8 * work[1]))
    np.savez(dump, **states)
    print(json.dumps(out))


def main():
    args = arguments(__doc__, "lane_refill.json", "the earlier commit (fixed groups of lanes)")
    if args.measure:
        return measure(args.measure)
    runs, same = run_rounds(__file__, args.base, args.rounds)
    rows = []
    for key in runs["this"][0]:
        before = float(np.median([r[key]["rate"] for r in runs["base"]]))
        after = float(np.median([r[key]["rate"] for r in runs["this"]]))
        first = runs["this"][0][key]
        refill, fixed = first[f"block {BLOCK}"], first["block W"]
        rows.append(dict(case=key, live=first["live"], point_steps=first["point_steps"], before=before, after=after,
                         ratio=after / before, refill=refill, fixed_groups=fixed, bits_equal=same[key],
                         rounds_before=[r[key]["rate"] for r in runs["base"]],
                         rounds_after=[r[key]["rate"] for r in runs["this"]]))
        print(f"{key:18s} live {first['live']:5d}/4000  {before:10,.0f} -> {after:10,.0f} point-steps/s  "
              f"x{after / before:5.2f}  group steps {fixed['group_steps']:6d} -> {refill['group_steps']:6d}, "
              f"iterations {fixed['group_iterations']:8d} -> {refill['group_iterations']:8d} "
              f"(occupancy {refill['step_occupancy']:.3f}, {refill['iteration_occupancy']:.3f})  "
              f"bits {'equal' if same[key] else 'DIFFER'}")
    write(args.out, "lane_refill.py", args, rows)


if __name__ == "__main__":
    main()
