"""One-step Ω̄ defects and their orders in double-double, where double's audit hits its floor
(docs/audit.md, "Defect orders below double's floor").

    python scripts/studies/audit_defect_dd.py [--scenes point_vortices massless_charged_particle]
                                [--tableaus GLRK1 … SRK3] [--levels 5] [--json docs/figures/defect_dd.json]
    python scripts/studies/audit_defect_dd.py --floor      # the floor: GLRK3-standard on the charged particle at small h,
                                             # with three central-difference steps

Each scene's audit points (4 points of its loop, as `poincare audit` takes them) and h, h/2, …,
h/2^(levels−1): the defect of every admissible pair of the tableaus (integrators.audit.defect_dd),
the study's floor (the defects again with a 4× smaller difference step: their largest
disagreement), the order fitted over the defects above 10 × that floor, and double's audit beside
it (its defect at h and its order, or its floor).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import integrators
from integrators import audit
from integrators.audit import defect_dd
from integrators.projections import PROJECTIONS, admission
from integrators.service.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]


def audit_points(scene):
    system = scene.system()
    pts = scene.loop_points()
    return pts[np.linspace(0, pts.shape[0], 4, endpoint=False).astype(int)]


def floor():
    sy = integrators.system("massless_charged_particle")
    q = audit_points(load_scene("massless_charged_particle"))
    print("| h | δ = 2⁻¹¹ | δ = 2⁻¹² | δ = 2⁻¹³ |\n|---|---|---|---|")
    for k in range(3, 9):
        h = 0.2 * 2.0 ** -k
        row = []
        for e in (-11, -12, -13):
            defect_dd.FD_STEP_DD = 2.0 ** e
            row.append(defect_dd.defects_dd(sy, integrators.tableau("GLRK3"), "standard", q, h))
        print(f"| 0.2·2⁻{k} | " + " | ".join(f"{v:.2e}" for v in row) + " |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["point_vortices", "massless_charged_particle"])
    ap.add_argument("--tableaus", nargs="+", default=["GLRK1", "GLRK2", "GLRK3", "GLRK4", "GLRK5", "GLRK6", "SRK3"])
    ap.add_argument("--levels", type=int, default=5)
    ap.add_argument("--json", default=None)
    ap.add_argument("--floor", action="store_true")
    args = ap.parse_args(argv)
    if args.floor:
        return floor()
    out = {"command": "python scripts/studies/audit_defect_dd.py " + " ".join(argv or __import__("sys").argv[1:]),
           "floor_dd": defect_dd.DEFECT_FLOOR_DD, "scenes": {}}
    for name in args.scenes:
        scene = load_scene(name)
        sy, q, h = scene.system(), audit_points(scene), scene.h
        print(f"\n{name} (h = {h:g}, {len(q)} points)\n")
        print("| pair | double: defect at h, order | double-double: defect at h … h/16 | floor | order |")
        print("|---|---|---|---|---|")
        rows = {}
        for tab in args.tableaus:
            tableau = integrators.tableau(tab)
            for proj in PROJECTIONS:
                if admission(tableau, proj):
                    continue
                t0 = time.perf_counter()
                dd = defect_dd.defect_study_dd(sy, tableau, proj, q, h, args.levels)
                cand = audit.pair_candidate(tableau, proj)
                dbl, used = audit.defect_study(cand.step, sy, q, h, args.levels, "auto", cand.reads)
                nc = dbl["noncanonical"]
                rows[f"{tab}-{proj}"] = {"double": nc["defect"], "double_order": nc["order"], "jacobian": used,
                                         "double_double": dd["defect"], "order": dd["order"],
                                         "seconds": time.perf_counter() - t0}
                dorder = f"h^{nc['order']:.1f}" if nc["order"] is not None else "no order (floor)"
                order = f"h^{dd['order']:.2f}" if dd["order"] is not None else "none above 10 × floor"
                rows[f"{tab}-{proj}"]["floor"] = dd["floor"]
                print(f"| {tab}-{proj} | {nc['defect'][0]:.1e}, {dorder} | "
                      + ", ".join(f"{v:.1e}" for v in dd["defect"]) + f" | {dd['floor']:.0e} | {order} |", flush=True)
        out["scenes"][name] = {"h": h, "points": q.tolist(), "rows": rows}
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
