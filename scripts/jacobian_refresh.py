"""A shipped scene with Newton's default Jacobian refresh (0.01) against run.jacobian_refresh = R.

    python scripts/jacobian_refresh.py [--scene paper_poincare] [--refresh 0.1] [--ranks 2] [--rounds 2]
                                       [--out docs/figures/jacobian_refresh.json]

Each round runs the scene as shipped and the same scene with ``jacobian_refresh = R`` added to its
[run] table (``mpiexec -n RANKS poincare run``, one thread a rank), alternating which goes first,
and records each run's wall time (the whole command) and each pair's wall time from its file.  The
two files are then compared: every invariant series and energy, momentum and constraint error, as
the largest difference relative to the series' own scale (invariants: last bits of values of order
one; the errors are themselves round-off and differ as much), and the breakdown times.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def _run(scene: Path, out: Path, ranks: int) -> float:
    cmd = [str(BIN / "poincare"), "run", str(scene), "-o", str(out), "-q", "--force", "--threads", "1"]
    if ranks > 1:
        cmd = [str(BIN / "mpiexec"), "-n", str(ranks)] + cmd
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def _compare(a: Path, b: Path) -> dict:
    from integrators.service.reader import read_run
    ra, rb = read_run(a), read_run(b)
    worst = {}
    for name, pa in ra.pairs.items():
        pb = rb[name]
        series = {f"{inv} {f}": (getattr(pa, inv)[f], getattr(pb, inv)[f]) for inv in ("I1", "I2")
                  for f in getattr(pa, inv)}
        series.update({k: (pa.errors[k], pb.errors[k]) for k in pa.errors})
        for key, (x, y) in series.items():
            scale = max(np.nanmax(np.abs(x)), 1e-300)
            worst[f"{name} {key}"] = float(np.nanmax(np.abs(x - y)) / scale)
        if not np.array_equal(pa.breakdown_time, pb.breakdown_time):
            worst[f"{name} breakdown_time"] = "differ"
    return worst


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="paper_poincare")
    ap.add_argument("--refresh", type=float, default=0.1)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "docs/figures/jacobian_refresh.json"))
    args = ap.parse_args()
    from integrators.service.scene import builtin_scenes
    text = builtin_scenes()[args.scene].read_text()
    assert "\n[run]\n" in text, "the scene has no [run] table line"
    tmp = Path(tempfile.mkdtemp(prefix="refresh-"))
    scenes = {"0.01": tmp / "default.toml", str(args.refresh): tmp / "fast.toml"}
    scenes["0.01"].write_text(text)
    scenes[str(args.refresh)].write_text(text.replace("\n[run]\n", f"\n[run]\njacobian_refresh = {args.refresh!r}\n"))
    walls = {k: [] for k in scenes}
    from integrators.service.reader import read_run
    for r in range(args.rounds):
        order = list(scenes) if r % 2 == 0 else list(scenes)[::-1]
        for key in order:
            walls[key].append(_run(scenes[key], tmp / f"{key}.h5", args.ranks))
            print(f"round {r + 1}: refresh {key}: {walls[key][-1]:.1f} s", flush=True)
    pairs = {k: {n: p.wall_time for n, p in read_run(tmp / f"{k}.h5").pairs.items()} for k in scenes}
    diff = _compare(tmp / "0.01.h5", tmp / f"{args.refresh}.h5")
    inv = [v for k, v in diff.items() if isinstance(v, float) and (" I1 " in k or " I2 " in k)]
    err = [v for k, v in diff.items() if isinstance(v, float) and not (" I1 " in k or " I2 " in k)]
    result = {"command": "python scripts/jacobian_refresh.py " + " ".join(sys.argv[1:]),
              "machine": platform.processor() or platform.machine(), "date": time.strftime("%Y-%m-%d"),
              "scene": args.scene, "ranks": args.ranks, "walls_s": walls, "pair_walls_s": pairs,
              "largest_relative_difference": {"invariants": max(inv, default=0.0), "errors": max(err, default=0.0)},
              "differences": diff}
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    for k in scenes:
        print(f"refresh {k}: walls {', '.join(f'{w:.1f}' for w in walls[k])} s")
    print("pair walls [s]:")
    for n in pairs["0.01"]:
        print(f"  {n:20s} {pairs['0.01'][n]:6.1f} -> {pairs[str(args.refresh)][n]:6.1f}")
    print(f"largest difference relative to the series' scale: invariants {max(inv, default=0.0):.3g}, "
          f"energy/momentum/constraint errors {max(err, default=0.0):.3g}; "
          f"breakdown times differ in {sum(1 for v in diff.values() if v == 'differ')} pairs")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
