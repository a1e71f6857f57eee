"""Results do not depend on how often a run is looked at (docs/engine.md, "What it promises").

    python scripts/studies/engine_cadence.py                      # three built-in systems, then the STEP file (~3 min)
    python scripts/studies/engine_cadence.py --json docs/figures/cadence.json

1. Three built-in scenes' loops (guiding_centre_tokamak GLRK2-none, point_vortices GLRK2-symmetric,
   lotka_volterra SRK3-symplectic), 40 steps through ``integrate`` with ``save_every`` 1, 8 and 40:
   are q, p, λ, the Newton iterations and the breakdown times bitwise the same?
2. The STEP G-EQDSK file of pyrokinetics 0.9.1 (``pip download``, nothing installed; or ``--geqdsk``)
   at h = 140 (the default h this project gave it before the transit-time rule), GLRK2-none, the
   2,048 loop points of its ``equilibrium_scene``, 50 steps: through ``integrate`` with
   ``save_every`` 1 and 10, and through the driver with ``output_every`` 1 and 10: the points that
   break down and when.

Run on any version of the code (it uses public calls only), so before/after tables come from one
script.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

import integrators
from integrators.equilibrium import system_from_geqdsk
from integrators.service import driver
from integrators.service.reader import read_run
from integrators.service.scene import equilibrium_scene, load_scene, parse_scene

BUILTIN = [("guiding_centre_tokamak", "GLRK2", "none"), ("point_vortices", "GLRK2", "symmetric"),
           ("lotka_volterra", "SRK3", "symplectic")]
STEP_WHEEL, STEP_MEMBER = "pyrokinetics==0.9.1", "pyrokinetics/templates/step.geqdsk"


def same(a, b) -> bool:
    return all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
               for f in ("q", "p", "lam", "newton_iterations", "breakdown_time"))


def builtin_rows(steps=40, cadences=(1, 8, 40)) -> list:
    rows = []
    for name, tab, proj in BUILTIN:
        sc = load_scene(name)
        sols = [integrators.integrate(sc.system(), sc.loop_points(), tableau=tab, projection=proj,
                                      h=sc.h, steps=steps, save_every=k)
                for k in cadences]
        last = [dict(q=s.q[-1], p=s.p[-1], lam=s.lam[-1], newton_iterations=s.newton_iterations,
                     breakdown_time=s.breakdown_time) for s in sols]
        equal = all(all(np.array_equal(last[0][f], x[f], equal_nan=True) for f in last[0]) for x in last[1:])
        rows.append(dict(scene=name, pair=f"{tab}-{proj}", steps=steps, cadences=list(cadences), bitwise=equal,
                         iterations=[int(s.newton_iterations.sum()) for s in sols],
                         breakdowns=[int(np.isfinite(s.breakdown_time).sum()) for s in sols]))
    return rows


def step_file(folder: Path) -> Path:
    subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", STEP_WHEEL, "-d", str(folder)],
                   check=True)
    wheel = next(folder.glob("pyrokinetics-*.whl"))
    target = folder / "step.geqdsk"
    with zipfile.ZipFile(wheel) as z:
        target.write_bytes(z.read(STEP_MEMBER))
    return target


def broken(times) -> dict:
    """{breakdown time: number of points} of the points that broke down."""
    t = np.asarray(times).ravel()
    vals, counts = np.unique(t[np.isfinite(t)], return_counts=True)
    return {f"{v:g}": int(c) for v, c in zip(vals, counts)}


def step_rows(path: Path, folder: Path, h=140.0, steps=50) -> list:
    sy = system_from_geqdsk(path)
    text = equilibrium_scene(path, name="step_cadence", steps=steps)
    text = re.sub(r"(?ms)^\[surface\].*?(?=^\[)", "", text)            # the loop only
    text = re.sub(r"(?m)^h = .*$", f"h = {h!r}", text)
    text = re.sub(r"(?m)^tableaus = .*$", 'tableaus = ["GLRK2"]', text)
    text = re.sub(r"(?m)^projections = .*$", 'projections = ["none"]', text)
    text = re.sub(r"(?m)^forms = .*$", 'forms = ["canonical"]', text)
    rows = []
    q0 = parse_scene(text, str(folder / "x.toml")).loop_points()
    sols = []
    for k in (1, 10):
        t0 = time.perf_counter()
        sol = integrators.integrate(sy, q0, tableau="GLRK2", projection="none", h=h, steps=steps, save_every=k)
        sols.append(sol)
        rows.append(dict(path="integrate", cadence=k, points=len(q0), h=h, steps=steps,
                         breakdowns=broken(sol.breakdown_time), iterations=int(sol.newton_iterations.sum()),
                         wall_s=round(time.perf_counter() - t0, 1)))
    rows[-1]["bitwise_with_cadence_1"] = bool(np.array_equal(sols[0].q[-1], sols[1].q[-1], equal_nan=True)
                                              and np.array_equal(sols[0].breakdown_time, sols[1].breakdown_time))
    finals = []
    for k in (1, 10):
        scene_text = re.sub(r"(?m)^output_every = .*$", f"output_every = {k}", text)
        scene_path = folder / f"step_every{k}.toml"
        scene_path.write_text(scene_text)
        out = folder / f"step_every{k}.h5"
        t0 = time.perf_counter()
        driver.run(parse_scene(scene_text, str(scene_path)), out, progress=False)
        pair = next(iter(read_run(out).pairs.values()))
        bt = pair.breakdown_time
        finals.append((pair.t, pair.I1["canonical"], bt))
        rows.append(dict(path="driver", cadence=k, points=len(q0), h=h, steps=steps, breakdowns=broken(bt),
                         wall_s=round(time.perf_counter() - t0, 1)))
    (t1, I1, b1), (t10, I10, b10) = finals          # I₁ at the outputs both wrote, and the breakdown times
    common = np.isin(t1, t10)
    rows[-1]["bitwise_with_cadence_1"] = bool(np.array_equal(I1[common], I10, equal_nan=True)
                                              and np.array_equal(b1, b10))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--geqdsk", help="the STEP file (default: fetched from the pyrokinetics 0.9.1 wheel)")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)
    out = dict(builtin=builtin_rows())
    for r in out["builtin"]:
        print(f"{r['scene']:24s} {r['pair']:18s} save_every {r['cadences']}: bitwise {r['bitwise']}, "
              f"iterations {r['iterations']}, breakdowns {r['breakdowns']}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = Path(args.geqdsk) if args.geqdsk else step_file(folder)
        if path.parent != folder:
            (folder / path.name).write_bytes(path.read_bytes())
            path = folder / path.name
        out["step"] = step_rows(path, folder)
    for r in out["step"]:
        extra = f", bitwise with cadence 1: {r['bitwise_with_cadence_1']}" if "bitwise_with_cadence_1" in r else ""
        print(f"STEP h = {r['h']:g} GLRK2-none {r['points']} points, {r['path']:9s} every {r['cadence']:2d}: "
              f"breakdowns {r['breakdowns'] or 'none'}{extra} ({r['wall_s']} s)", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    ok = all(r["bitwise"] for r in out["builtin"]) and all(r.get("bitwise_with_cadence_1", True) for r in out["step"])
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
