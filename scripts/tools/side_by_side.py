"""The step engine at this commit against an earlier one, side by side on this machine (issue 43).

    python scripts/tools/side_by_side.py --base 083b6cf [--rounds 5] [--out docs/figures/side_by_side.json]

The earlier commit is checked out into a temporary git worktree with its own numba cache; each
round runs one child process per tree (this script with ``--measure``, ``integrators`` imported
from that tree), alternating which goes first, and the medians over the rounds are reported.
What a child measures, one thread, guiding_centre_symmetric at h = 10, scripts/studies/benchmarks_core.py's
protocol (10⁴ points, 2 warm-up steps, then 10 steps in one call; best of 3):

* ``loop``: the points near the default loop (Gaussian 1e-3), ``box``: the same number of points
  spread uniformly over the loop's bounding box; point-steps per second of GLRK2-symmetric,
  GLRK1-none, SRK3-symmetric and GLRK4-symmetric, in lanes (each tree's default width for the
  pair: kernel.LANES, or Engine.width where the tree has it; the rows record W);
* ``orbit``: one trajectory (W = 1, 20,000 steps, best of 3) of GLRK1-none and GLRK2/4/6-symmetric.

Both trees' states after the timed steps are written to .npz files and compared field by field:
the rows say whether every point's bits are the same.  Flop per cycle uses the flop count of one
Newton iteration as coded (scripts/studies/engine_lanes.py, Jacobian refreshes left out: a lower bound)
times the measured iterations per step, over the clock /proc/cpuinfo reports.
"""
import argparse
import contextlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
LANE_PAIRS = (("GLRK2", "symmetric"), ("GLRK1", "none"), ("SRK3", "symmetric"), ("GLRK4", "symmetric"))
ORBIT_PAIRS = (("GLRK1", "none"), ("GLRK2", "symmetric"), ("GLRK4", "symmetric"), ("GLRK6", "symmetric"))
FIELDS = ("q", "p", "Lam", "iterations", "breakdown_time")


def point_sets(n=10000):
    import invariants
    rng = np.random.default_rng(1)
    q0 = invariants.loop("guiding_centre", n)
    lo, hi = q0.min(0), q0.max(0)
    return {"loop": q0 + 1e-3 * rng.standard_normal(q0.shape), "box": lo + (hi - lo) * rng.random(q0.shape)}


def measure(dump):
    """Runs in a child, with integrators from the tree under test: rates as JSON on stdout."""
    import integrators
    from integrators import kernel
    from integrators.engine import set_threads
    set_threads(1)
    gc = integrators.system("guiding_centre_symmetric")
    sets = point_sets()
    out, states = {}, {}

    laned = hasattr(kernel, "LANES")        # a tree before lanes (0581e1c): one point at a time

    def rate(tab, proj, q, steps, lanes):
        eng = integrators.Engine(gc, integrators.tableau(tab), proj, 10.0)
        best, its, W = 0.0, 0.0, 1
        kw = {"lanes": lanes} if laned else {}
        for _ in range(3):
            st = eng.state(q)
            eng.advance(st, 1, 2, **kw)
            i0 = st.iterations.sum()
            t = time.perf_counter()
            use = eng.advance(st, 3, steps, **kw)
            best = max(best, q.shape[0] * steps / (time.perf_counter() - t))
            its = (st.iterations.sum() - i0) / (q.shape[0] * steps)
            W = getattr(use, "W", lanes or kernel.LANES) if laned else 1
        return best, float(its), st, W

    for tab, proj in LANE_PAIRS:
        for name, q in sets.items():
            r, its, st, W = rate(tab, proj, q, 10, None)
            out[f"{tab}-{proj} {name}"] = dict(rate=r, iterations=its, W=W)
            for f in FIELDS:
                states[f"{tab}-{proj} {name}/{f}"] = getattr(st, f)
    for tab, proj in ORBIT_PAIRS:
        r, its, st, W = rate(tab, proj, sets["loop"][:1], 20000, 1)
        out[f"{tab}-{proj} orbit"] = dict(rate=r, iterations=its, W=W)
        for f in FIELDS:
            states[f"{tab}-{proj} orbit/{f}"] = getattr(st, f)
    np.savez(dump, **states)
    print(json.dumps(out))


def flops(tab, proj):
    """Flop of one step as coded, per point, at the measured iterations (filled in by the caller)."""
    import integrators
    from integrators.costmodel import flops_per_iteration
    gc = integrators.system("guiding_centre_symmetric")
    t = integrators.tableau(tab)
    return flops_per_iteration(gc, t, integrators.Engine(gc, t, proj, 10.0))


def clock_hz():
    try:
        return 1e6 * max(float(ln.split(":")[1]) for ln in open("/proc/cpuinfo") if ln.startswith("cpu MHz"))
    except (OSError, ValueError):
        return float("nan")


@contextlib.contextmanager
def trees_of(base):
    """{"base": a temporary git worktree of commit ``base``, "this": this tree} and a scratch folder;
    the worktree is removed afterwards.  Both trees share the engine's cache of generated system
    code (its keys do not depend on the tree) and each has its own numba cache beside its sources."""
    tmp = Path(tempfile.mkdtemp())
    tree = tmp / "base"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), base], check=True,
                   capture_output=True)
    try:
        yield {"base": tree, "this": ROOT}, tmp
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], capture_output=True)


def alternate(trees, rounds):
    """(round, tree key) pairs, the trees' order alternating from round to round."""
    for r in range(rounds):
        for key in (list(trees) if r % 2 == 0 else list(trees)[::-1]):
            yield r, key


def child(tree, argv):
    """Run ``python argv…`` with ``integrators`` imported from ``tree`` (its own working directory and
    PYTHONPATH: the editable install would otherwise win); the JSON of its last line of output."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    env.pop("NUMBA_CACHE_DIR", None)
    p = subprocess.run([sys.executable, *map(str, argv)], env=env, capture_output=True, text=True, check=True,
                       cwd=str(tree))
    return json.loads(p.stdout.strip().splitlines()[-1])


def bits_equal(tmp):
    """{case: whether every array the two children dumped for it (base.npz, this.npz) is bitwise equal}."""
    a, b = np.load(tmp / "base.npz"), np.load(tmp / "this.npz")
    same = {k.split("/")[0]: True for k in a}
    for k in a:
        same[k.split("/")[0]] &= bool(np.array_equal(a[k], b[k], equal_nan=True))
    return same


def run_rounds(script, base, rounds):
    """``rounds`` rounds of ``script --measure`` in each tree (alternating): ({tree: [JSON, …]},
    {case: bits equal})."""
    runs = {}
    with trees_of(base) as (trees, tmp):
        for r, key in alternate(trees, rounds):
            argv = [script, "--base", base, "--measure", tmp / f"{key}.npz"]
            runs.setdefault(key, []).append(child(trees[key], argv))
            print(f"round {r + 1}: {key} done", flush=True)
        return runs, bits_equal(tmp)


def write(path, script, args, rows, **extra):
    """The rows, the machine, both commits and the command as JSON at ``path``."""
    out = dict(machine=platform.processor() or platform.machine(), **extra, base=args.base,
               this=subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                   text=True).stdout.strip(), rounds=args.rounds, date=time.strftime("%Y-%m-%d"),
               command=f"python scripts/tools/{script} --base {args.base} --rounds {args.rounds}", rows=rows)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(out, indent=1))
    print(f"wrote {path}")


def arguments(doc, out, base_help="the earlier commit"):
    """The command line both side-by-side scripts take: --base, --rounds, --out (default ``out``
    under docs/figures) and the children's hidden --measure."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--base", required=True, help=base_help)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", default=str(ROOT / "docs/figures" / out))
    ap.add_argument("--measure", help=argparse.SUPPRESS)
    return ap.parse_args()


def main():
    args = arguments(__doc__, "side_by_side.json")
    if args.measure:
        return measure(args.measure)
    runs, same = run_rounds(__file__, args.base, args.rounds)
    hz = clock_hz()
    rows = []
    for key in runs["this"][0]:
        before = float(np.median([r[key]["rate"] for r in runs["base"]]))
        after = float(np.median([r[key]["rate"] for r in runs["this"]]))
        its = runs["this"][0][key]["iterations"]
        tab, rest = key.split("-", 1)
        proj = rest.split()[0]
        fl = flops(tab, proj) * its
        rows.append(dict(case=key, W_before=runs["base"][0][key].get("W"), W_after=runs["this"][0][key].get("W"),
                         before=before, after=after, ratio=after / before, iterations=its,
                         flop_per_step=fl, flop_per_cycle_before=fl * before / hz, flop_per_cycle_after=fl * after / hz,
                         bits_equal=same[key], rounds_before=[r[key]["rate"] for r in runs["base"]],
                         rounds_after=[r[key]["rate"] for r in runs["this"]]))
        print(f"{key:28s} W {rows[-1]['W_before']}->{rows[-1]['W_after']} {before:12,.0f} -> {after:12,.0f}  "
              f"x{after / before:5.2f}  it {its:.2f}  "
              f"flop/cycle {fl * before / hz:.2f} -> {fl * after / hz:.2f}  bits {'equal' if same[key] else 'DIFFER'}")
    write(args.out, "side_by_side.py", args, rows, clock_hz=hz)


if __name__ == "__main__":
    main()
