"""Run built-in scenes and report, per pair, the status and the largest resolution monitor of each set.

    python scripts/tools/check_scenes.py                      # every built-in scene (paper_poincare: ~17 min)
    python scripts/tools/check_scenes.py default lotka_volterra
    python scripts/tools/check_scenes.py --json docs/figures/scenes_resolution.json
    python scripts/tools/check_scenes.py --keep runs/       # keep the run files (then: poincare plot runs/NAME.h5)

The evidence behind "the shipped scenes' summaries show no under-resolved set" (docs/scenes.md):
the monitor is invariants.forms' relative size of the top eighth of the modes, largest over the forms
and over every output of the run; a set is resolved while it is at most invariants.UNDER_RESOLVED.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from integrators.service.driver import run
from integrators.service.scene import builtin_scenes, load_scene
from invariants import UNDER_RESOLVED


def check(name, workdir):
    scene = load_scene(name)
    out = Path(workdir) / f"{name}.h5"
    t0 = time.perf_counter()
    summaries = run(scene, out, progress=False)
    wall = time.perf_counter() - t0
    rows = []
    with h5py.File(out, "r") as f:
        for s in summaries:
            g = f["runs"][s.pair]
            mon = {inv: float(np.nanmax(g[f"resolution/{inv}"][...])) for inv in ("I1", "I2") if inv in g}
            rows.append(dict(pair=s.pair, status=s.status, breakdowns=s.breakdowns, monitor=mon))
    return dict(scene=name, wall_s=round(wall, 1), threshold=UNDER_RESOLVED, pairs=rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", help="built-in scene names (default: all)")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--keep", help="write the run files into this folder (default: a temporary one)")
    args = ap.parse_args(argv)
    names = args.scenes or list(builtin_scenes())
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        if args.keep:
            Path(args.keep).mkdir(parents=True, exist_ok=True)
        for name in names:
            r = check(name, args.keep or tmp)
            results.append(r)
            statuses = sorted({p["status"] for p in r["pairs"]})
            worst = {inv: max(p["monitor"].get(inv, 0.0) for p in r["pairs"]) for inv in ("I1", "I2")}
            print(f"{name:24s} {r['wall_s']:8.1f} s  statuses {', '.join(statuses):20s} largest monitor "
                  f"loop {worst['I1']:.1e}  surface {worst['I2']:.1e}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0 if all(p["status"] == "ok" for r in results for p in r["pairs"]) else 1


if __name__ == "__main__":
    sys.exit(main())
