"""What a self-refining sample set costs, measured side by side on one rank.

For each pair asked for, three runs of the same scene (default: the shipped
``guiding_centre_tokamak_refining``):

* ``plain``: the scene's own sets without ``refine_to`` (what a user had before: under-resolved);
* ``refining``: the scene as shipped (new points started at t = 0 and caught up when needed);
* ``finest``: the sets as fine from the start as the refining run ever made them (the other way
  to get every output resolved, had one known the size in advance).

It reports each run's wall time, its seconds advancing the scene's points, the seconds the new
points took (the catch-up and after), the outputs resolved and the status, and checks that the
refining run's values at the outputs taken on the finest level are bitwise the ``finest`` run's.

    python scripts/studies/scenes_refinement.py                       # GLRK2-symmetric and SRK3-standard
    python scripts/studies/scenes_refinement.py --pairs GLRK2-symplectic --json docs/figures/refinement.json
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from integrators.service import driver  # noqa: E402
from integrators.service.api import scene_text  # noqa: E402
from integrators.service.reader import read_run  # noqa: E402
from integrators.service.scene import parse_scene, scene_source  # noqa: E402


def run(data, path, pair):
    tab, proj = pair.rsplit("-", 1)
    data = dict(data, run=dict(data["run"], tableaus=[tab], projections=[proj]))
    scene = parse_scene(scene_text(data))
    t0 = time.perf_counter()
    summaries = driver.run(scene, path, progress=False, force=True)
    wall = time.perf_counter() - t0
    s = summaries[0]
    pr = read_run(path).pairs[pair]
    return {"wall_s": wall, "advance_s": s.timings.get("advance", np.nan), "new_points_s": s.timings.get("refine", 0.0),
            "new_point_steps": s.timings.get("refine_point_steps", 0), "status": s.status,
            "resolved": {inv: f"{int(v.sum())}/{v.size}" for inv, v in pr.resolved.items()},
            "points": {spec.invariant: spec.count for spec, _ in scene.sample_sets},
            "most_used": {inv: int(v.max()) for inv, v in pr.points_used.items()}}, pr


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="guiding_centre_tokamak_refining")
    ap.add_argument("--pairs", nargs="+", default=["GLRK2-symmetric", "SRK3-standard"])
    ap.add_argument("--json", help="write the measurements as JSON")
    args = ap.parse_args()
    text, _ = scene_source(args.scene)
    data = tomllib.loads(text)
    out = {"scene": args.scene, "machine": os.uname().machine, "cpus": os.cpu_count(), "pairs": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for pair in args.pairs:
            plain = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
            for key in ("loop", "surface"):
                plain[key] = {k: v for k, v in data[key].items() if k != "refine_to"}
            res = {"plain": run(plain, Path(tmp) / "plain.h5", pair)[0]}
            res["refining"], ref = run(data, Path(tmp) / "refining.h5", pair)
            finest = {k: (dict(v) if isinstance(v, dict) else v) for k, v in plain.items()}
            spec = parse_scene(text)
            for s, _ in spec.sample_sets:
                most = res["refining"]["most_used"][s.invariant]
                level = next(lv for lv in range(s.levels + 1) if s.at_level(lv).count == most)
                fine = s.at_level(level)
                if s.name == "loop":
                    finest["loop"]["points"] = fine.points
                else:
                    finest["surface"]["n_sigma"], finest["surface"]["n_tau"] = fine.n_sigma, fine.n_tau
            res["finest"], fin = run(finest, Path(tmp) / "finest.h5", pair)
            same = {}
            for inv in ref.points_used:
                at = ref.points_used[inv] == res["refining"]["most_used"][inv]
                same[inv] = bool(all(np.array_equal(v[at], getattr(fin, inv)[f][at]) for f, v in getattr(ref, inv).items()))
            res["refining_equals_finest_where_used"] = same
            out["pairs"][pair] = res
            print(f"\n{pair}")
            print(f"{'run':9s} {'points (I1, I2)':>18s} {'wall [s]':>9s} {'advance':>8s} {'new pts':>8s} "
                  f"{'resolved I1':>12s} {'resolved I2':>12s}  status")
            for name, r in res.items():
                if name.startswith("refining_equals"):
                    continue
                pts = r["points"] if name != "refining" else {k: f"{r['points'][k]}→{r['most_used'][k]}"
                                                             for k in r["points"]}
                print(f"{name:9s} {str(pts.get('I1')) + ', ' + str(pts.get('I2')):>18s} {r['wall_s']:9.1f} "
                      f"{r['advance_s']:8.1f} {r['new_points_s']:8.1f} {r['resolved'].get('I1', '-'):>12s} "
                      f"{r['resolved'].get('I2', '-'):>12s}  {r['status']}")
            print(f"refining run bitwise the finest run at the outputs on the finest level: {same}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
