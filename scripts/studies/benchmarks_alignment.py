"""Lane widths and the scratch's alignment, measured in fresh processes (benchmarks.md, "Aligned lanes").

    python scripts/studies/benchmarks_alignment.py [--processes 3] [--out docs/figures/benchmark_alignment.json]
    python scripts/studies/benchmarks_alignment.py --tree /path/to/another/checkout   # that version's code

Each process (one thread) advances half of paper_poincare's points (the 2,000-point loop and the
100 × 100 surface, every second point, guiding_centre_symmetric, h = 10) by 60 steps after 20, in
W = 8 and W = 16 lanes alternately, best of 3 each, and prints µs a point-step.  Where the kernel's
scratch lands in memory is decided once per process, so a version whose scratch is not aligned
shows two speeds from one process to the next; the spread over processes is the measurement.
``--tree`` runs the processes on another checkout's code (``git worktree add /tmp/old <commit>``),
for the before/after table; run it from a directory that is not a checkout (the current directory
comes first on Python's path).
"""
import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAIRS = (("GLRK1", "none"), ("GLRK2", "symmetric"), ("SRK3", "symmetric"), ("GLRK4", "symmetric"),
         ("GLRK6", "symmetric"))


def child():
    import numpy as np

    import integrators
    import invariants
    from integrators.engine import set_threads
    set_threads(1)
    sy = integrators.system("guiding_centre_symmetric")
    pts = np.concatenate([invariants.loop("guiding_centre", 2000),
                          invariants.surface("guiding_centre", 100, 100).reshape(-1, 4)])[::2]
    out = {}
    for tab, proj in PAIRS:
        e = integrators.Engine(sy, integrators.tableau(tab), proj, 10.0)
        best = {8: np.inf, 16: np.inf}
        for _ in range(3):
            for W in best:
                st = e.state(pts)
                e.advance(st, 1, 20, lanes=W)
                t = time.perf_counter()
                e.advance(st, 21, 60, lanes=W)
                best[W] = min(best[W], time.perf_counter() - t)
        out[f"{tab}-{proj}"] = {"nz": e.nz, "default_W": e.lanes_for(len(pts)),
                                **{f"W{W}_us": v / (len(pts) * 60) * 1e6 for W, v in best.items()}}
    print(json.dumps(out))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--processes", type=int, default=3)
    ap.add_argument("--tree", default=str(ROOT), help="the checkout whose code the processes run")
    ap.add_argument("--out", default=None, help="JSON file (default: print only)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        child()
        return
    env = dict(os.environ, PYTHONPATH=str(Path(a.tree).resolve()), NUMBA_NUM_THREADS="1")
    runs = []
    for k in range(a.processes):
        got = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child"], env=env, cwd="/",
                             capture_output=True, text=True, check=True)
        runs.append(json.loads(got.stdout.strip().splitlines()[-1]))
        print(f"process {k + 1}: " + "; ".join(f"{p} (nz {r['nz']}, default W {r['default_W']}) "
                                              f"W=8 {r['W8_us']:.3f}, W=16 {r['W16_us']:.3f} us"
                                              for p, r in runs[-1].items()), flush=True)
    if a.out:
        Path(a.out).write_text(json.dumps(dict(date=time.strftime("%Y-%m-%d"), tree=str(a.tree),
                                               machine=platform.processor() or platform.machine(),
                                               processes=runs), indent=1))


if __name__ == "__main__":
    main()
