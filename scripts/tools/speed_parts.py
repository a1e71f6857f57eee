"""What Brouwer's law costs, part by part: the step's speed and Newton's iterations at this commit,
under several stopping rules, side by side with earlier commits (issue 97).

    python scripts/tools/speed_parts.py --base 0985d75 [--also b0f07f8~1,b0f07f8,6dd5017] [--rounds 3] [--trees DIR]
    python scripts/tools/speed_parts.py --base 0985d75 --markdown docs/figures/speed_parts.json

Each commit is checked out into a temporary git worktree with its own numba cache
(scripts/tools/side_by_side.py's helpers); each round runs one child process per tree, in an order
that alternates from round to round, and the table reports the medians over the rounds.  What a
child measures, one thread, each tree's default lane width:

* ``loop``: 2,000 guiding-centre points near the default loop (``invariants.loop`` + Gaussian
  1e-3, seed 1), guiding_centre_symmetric, h = 10: 2 warm-up steps, then 50 steps in one call, best
  of 3; point-steps per second and Newton iterations a point-step, for GLRK2-symmetric, GLRK1-none,
  GLRK4-symmetric and GLRK2-standard;
* ``orbit``: one of those points alone (W = 1), 5,000 steps, GLRK4- and GLRK6-symmetric;
* ``kepler``: 16 Kepler orbits of eccentricity 0.5 (scripts/studies/brouwer_law.py's starts),
  h = 0.05, 1,000 steps, GLRK2-none and GLRK4-none;
* ``vortices``: 16 point-vortex points near the default start, h = 0.1, 1,000 steps,
  GLRK2-symmetric and GLRK3-symmetric.

Rules, each where the tree's ``Tolerances`` has the fields it names (a field the tree lacks is
dropped, so ``fixed`` at 0985d75 is that tree's default): ``default`` (the tree's own),
``unsettled`` (settle=False: Newton to the floor without the settled approach), ``fixed``
(tol = 4 eps, settle=False: the stopping rule of 0985d75).  Only this tree runs them all; the
others run ``default`` and ``fixed``.  The rows of docs/figures/speed_parts.json named ``plain``
and ``unsettled_plain`` were run with a trial not kept (plain_first: the first Newton iteration's
residual in plain arithmetic; docs/brouwer.md).
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from side_by_side import ROOT, alternate, clock_hz  # noqa: E402

FIXED = 4 * np.finfo(np.float64).eps
RULES = {"default": {}, "unsettled": {"settle": False}, "fixed": {"tol": FIXED, "settle": False}}
CASES = (("loop", "GLRK2", "symmetric"), ("loop", "GLRK1", "none"), ("loop", "GLRK4", "symmetric"),
         ("loop", "GLRK2", "standard"), ("orbit", "GLRK4", "symmetric"), ("orbit", "GLRK6", "symmetric"),
         ("kepler", "GLRK2", "none"), ("kepler", "GLRK4", "none"),
         ("vortices", "GLRK2", "symmetric"), ("vortices", "GLRK3", "symmetric"))


def kepler(n):
    """scripts/studies/brouwer_law.py's Kepler orbits (eccentricity 0.5, the starts spread over the
    phase and turned about the centre), written out so that an older tree's script is not needed."""
    import sympy
    from integrators.systems import system_from
    x, y, u, v = sympy.symbols("x y u v")
    system = system_from([u, v, 0, 0], (u**2 + v**2) / 2 - 1 / sympy.sqrt(x**2 + y**2), [x, y, u, v],
                         name="kepler", domain=[x**2 + y**2])
    e, p = 0.5, 0.75
    f = 2 * np.pi * np.arange(n) / n
    w = 2.4 * np.arange(n) + 0.1
    r = p / (1 + e * np.cos(f))
    vr, vt = np.sqrt(1 / p) * e * np.sin(f), np.sqrt(1 / p) * (1 + e * np.cos(f))
    c, s = np.cos(f + w), np.sin(f + w)
    return system, np.stack([r * c, r * s, vr * c - vt * s, vr * s + vt * c], 1)


def problems():
    """{protocol: (system, q0, h, steps)}."""
    import integrators
    import invariants
    rng = np.random.default_rng(1)
    gc = integrators.system("guiding_centre_symmetric")
    loop = invariants.loop("guiding_centre", 2000)
    loop = loop + 1e-3 * rng.standard_normal(loop.shape)
    ks, kq = kepler(16)
    pv = integrators.system("point_vortices")
    vq = np.asarray(pv.defaults["q0"]) + 1e-3 * rng.standard_normal((16, 4))
    return {"loop": (gc, loop, 10.0, 50), "orbit": (gc, loop[:1], 10.0, 5000),
            "kepler": (ks, kq, 0.05, 1000), "vortices": (pv, vq, 0.1, 1000)}


def tolerances(rule):
    """The tree's Tolerances with the fields of ``rule`` it has."""
    import dataclasses
    from integrators.engine import Tolerances
    have = {f.name for f in dataclasses.fields(Tolerances)}
    return Tolerances(**{k: v for k, v in RULES[rule].items() if k in have})


def measure(rules):
    """Runs in a child, with integrators from the tree under test: {case/rule: rate, iterations} as
    JSON on stdout."""
    import integrators
    from integrators.engine import set_threads
    set_threads(1)
    probs = problems()
    out = {}
    for prot, tab, proj in CASES:
        system, q, h, steps = probs[prot]
        for rule in rules:
            eng = integrators.Engine(system, integrators.tableau(tab), proj, h, tolerances=tolerances(rule))
            best, its = 0.0, 0.0
            for _ in range(3):
                st = eng.state(q)
                kw = {"lanes": 1} if prot == "orbit" else {}
                eng.advance(st, 1, 2, **kw)
                i0 = st.iterations.sum()
                t = time.perf_counter()
                eng.advance(st, 3, steps, **kw)
                best = max(best, q.shape[0] * steps / (time.perf_counter() - t))
                its = float((st.iterations.sum() - i0) / (q.shape[0] * steps))
            out[f"{tab}-{proj} {prot}/{rule}"] = dict(rate=best, iterations=its,
                                                     broken=int(np.sum(np.isfinite(st.breakdown_time))))
    print(json.dumps(out))


def child(tree, argv):
    """``python argv…`` with ``integrators`` imported from ``tree``; an earlier tree also keeps its
    generated system code apart (``POINCARE_CACHE`` in the tree: the files' keys do not name the
    engine, and a compiled one pickles the modules of the tree that made it).  The JSON of its last
    line of output."""
    import os
    import subprocess
    env = dict(os.environ, PYTHONPATH=str(tree))
    env.pop("NUMBA_CACHE_DIR", None)
    if Path(tree).resolve() != ROOT:
        env["POINCARE_CACHE"] = str(Path(tree) / ".poincare-cache")
    p = subprocess.run([sys.executable, *map(str, argv)], env=env, capture_output=True, text=True, check=True,
                       cwd=str(tree))
    return json.loads(p.stdout.strip().splitlines()[-1])


def markdown(path):
    """The table of a file this script wrote."""
    res = json.loads(Path(path).read_text())
    trees = res["trees"]
    print(f"*{res['date']}, {res['machine']}, {res['rounds']} rounds, one thread; `{res['command']}`*\n")
    head = " | ".join(f"{t} {r}" for t, rs in trees for r in rs)
    print(f"| case | {head} |")
    print("|---|" + "---:|" * sum(len(rs) for _, rs in trees))
    for case in res["cases"]:
        cells = []
        for t, rs in trees:
            for r in rs:
                v = res["rows"][t][f"{case}/{r}"]
                cells.append(f"{v['rate'] / 1e6:.3f} M, {v['iterations']:.2f} it")
        print(f"| {case} | " + " | ".join(cells) + " |")


def main():
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="the commit every figure is compared with")
    ap.add_argument("--also", default="", help="commits between, comma-separated")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "docs/figures/speed_parts.json"))
    ap.add_argument("--markdown", help="print the table of this file and stop")
    ap.add_argument("--trees", help="keep the worktrees (and their numba caches) in this folder for later runs")
    ap.add_argument("--measure", help=argparse.SUPPRESS)
    ap.add_argument("--rules", default="default,fixed", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.markdown:
        return markdown(args.markdown)
    if args.measure:
        return measure(args.rules.split(","))
    commits = [args.base] + [c for c in args.also.split(",") if c]
    import platform
    import subprocess
    import tempfile
    short = lambda c: subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", c], capture_output=True,
                                     text=True, check=True).stdout.strip()
    names = [short(c) for c in commits]
    trees = {}
    keep = Path(args.trees) if args.trees else Path(tempfile.mkdtemp())
    try:
        for c, n in zip(commits, names):
            tree = keep / n
            if not tree.exists():       # a worktree kept by --trees keeps its numba cache too
                subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), c], check=True,
                               capture_output=True)
            trees[n] = tree
        trees["this"] = ROOT
        rules = {n: "default,fixed" for n in names}
        rules["this"] = ",".join(RULES)
        runs = {}
        for r, key in alternate(trees, args.rounds):
            t0 = time.time()
            runs.setdefault(key, []).append(child(trees[key], [Path(__file__).resolve(), "--measure", "x",
                                                               "--rules", rules[key]]))
            print(f"round {r + 1}: {key} done in {time.time() - t0:.0f} s", flush=True)
    finally:
        if not args.trees:
            for n in names:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(keep / n)],
                               capture_output=True)
    rows = {k: {case: dict(rate=float(np.median([x[case]["rate"] for x in v])),
                           iterations=v[0][case]["iterations"], broken=v[0][case]["broken"],
                           rounds=[x[case]["rate"] for x in v]) for case in v[0]} for k, v in runs.items()}
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    out = dict(machine=platform.processor() or platform.machine(), clock_hz=clock_hz(), this=head,
               date=time.strftime("%Y-%m-%d"), rounds=args.rounds,
               command=f"python scripts/tools/speed_parts.py --base {args.base}"
                       + (f" --also {args.also}" if args.also else "") + f" --rounds {args.rounds}",
               trees=[[k, rules[k].split(",")] for k in trees], cases=[f"{t}-{p} {prot}" for prot, t, p in CASES],
               rows=rows)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(f"wrote {args.out}")
    markdown(args.out)


if __name__ == "__main__":
    main()
