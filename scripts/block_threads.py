"""The block loop's threads: what a first run spends compiling, and what a call over threads costs.

    python scripts/block_threads.py [--base TREE] [--rounds N] [--out FILE.json]

Each measurement is a fresh process with empty numba and POINCARE_CACHE folders (as on a machine
that never ran the engine) that advances 16 points of guiding_centre_symmetric with GLRK2-symmetric
by two steps, once with W = 8 lanes and once with W = 1 (the pair of kernels a first run compiles),
and records the wall time of each call and numba's compile events per function (exclusive of the
functions it compiled inside); then, the caches filled, the seconds per call of 300 calls that
advance 1,024 points by one step on the default threads (16 blocks: the calls where spreading
the blocks over threads costs most against the work).  ``--base TREE`` measures another checkout the same way, its rounds
alternating with this tree's, so both see the same machine.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent


def measure(W):
    """In a fresh process: compile and run one pair with W lanes; the seconds and the per-function split."""
    from numba.core import event

    stack, exclusive = [], {}

    class Compiles(event.Listener):
        def on_start(self, e):
            stack.append([e.data["dispatcher"].py_func.__qualname__, time.perf_counter(), 0.0])

        def on_end(self, e):
            name, t0, inner = stack.pop()
            dt = time.perf_counter() - t0
            exclusive[name] = exclusive.get(name, 0.0) + dt - inner
            if stack:
                stack[-1][2] += dt

    event.register("numba:compile", Compiles())
    import numpy as np

    import integrators
    system = integrators.system("guiding_centre_symmetric")
    engine = integrators.Engine(system, integrators.tableau("GLRK2"), "symmetric", 10.0)
    q = np.array([0.05, 0.0, 0.0, 0.0]) + 1e-3 * np.random.default_rng(1).standard_normal((16, 4))
    t = time.perf_counter()
    engine.advance(engine.state(q), 0, 2, lanes=W)
    seconds = time.perf_counter() - t
    top = dict(sorted(exclusive.items(), key=lambda kv: -kv[1])[:8])
    out = {"W": W, "seconds": round(seconds, 2), "exclusive": {k: round(v, 2) for k, v in top.items()}}
    if W > 1:
        import invariants
        state = engine.state(invariants.loop("guiding_centre", 1024))
        engine.advance(state, 0, 1)
        best = []
        for _ in range(3):
            t = time.perf_counter()
            for k in range(300):
                engine.advance(state, 1 + k, 1)
            best.append((time.perf_counter() - t) / 300)
        out["call_seconds"] = min(best)
        out["threads"] = integrators.engine.get_threads()
    return out


def child(tree, W):
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=f"{tmp}/numba", POINCARE_CACHE=f"{tmp}/poincare",
                   PYTHONPATH=str(tree))
        out = subprocess.run([sys.executable, str(HERE / "scripts" / "block_threads.py"), "--child", str(W)],
                             cwd=tree, env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="another checkout, measured alternately")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", help="write the measurements here (JSON)")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(measure(args.child)))
        return
    trees = {"this": HERE} | ({"base": Path(args.base).resolve()} if args.base else {})
    runs = []
    for r in range(args.rounds):
        for label, tree in (trees.items() if r % 2 == 0 else reversed(trees.items())):
            for W in (8, 1):
                m = child(tree, W) | {"tree": label, "round": r}
                runs.append(m)
                call = f"  call {m['call_seconds'] * 1e3:.2f} ms ({m['threads']} threads)" if "call_seconds" in m else ""
                print(f"{label:5s} round {r} W={W}: {m['seconds']:6.1f} s  "
                      + ", ".join(f"{k} {v}" for k, v in list(m["exclusive"].items())[:4]) + call, flush=True)
    for label in trees:
        pairs = [sum(m["seconds"] for m in runs if m["tree"] == label and m["round"] == r) for r in range(args.rounds)]
        print(f"{label}: W = 8 and W = 1 together {', '.join(f'{p:.1f}' for p in pairs)} s")
    if args.out:
        Path(args.out).write_text(json.dumps({"command": " ".join(sys.argv), "date": time.strftime("%Y-%m-%d"),
                                              "runs": runs}, indent=1) + "\n")


if __name__ == "__main__":
    main()
