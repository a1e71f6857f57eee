"""G-EQDSK files written by other codes, read with no COCOS given and run from their own defaults
(docs/equilibria.md, "Files from other codes").

    python scripts/studies/equilibria_external.py                 # fetch the files, run every scene (~10 min)
    python scripts/studies/equilibria_external.py --steps 100     # a shorter run of each
    python scripts/studies/equilibria_external.py --json docs/figures/equilibria_external.json

The files come from packages on PyPI that ship them as test data (``pip download --no-deps``, into a
temporary folder; nothing is installed): a DIII-D EFIT file (omas), the STEP SCENE file, the same with
I_p and B_T reversed in its header, and a TRANSP file (pyrokinetics), beside this project's own FreeGS
file.  For each: the COCOS the reader identified and its notes, |q(ψ_N = 0.5)| against the file's,
the defaults (h, q0), and the statuses of the scene that integrators.service.scene.equilibrium_scene
builds from them (GLRK1 and GLRK2 with every projection, 1,000 steps), with its wall time.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import integrators
from integrators.equilibrium import system_from_geqdsk
from integrators.service import driver
from integrators.service.scene import equilibrium_scene, parse_scene

ROOT = Path(__file__).resolve().parents[2]
FILES = [  # (package, path in its wheel, the code that wrote it)
    ("omas==0.95.2", "omas/samples/g145419.02100", "EFIT (DIII-D shot 145419, 2.1 s)"),
    ("pyrokinetics==0.9.1", "pyrokinetics/templates/step.geqdsk", "SCENE (STEP)"),
    ("pyrokinetics==0.9.1", "pyrokinetics/templates/reverse_ipbt.geqdsk", "SCENE (STEP), I_p and B_T reversed in the header"),
    ("pyrokinetics==0.9.1", "pyrokinetics/templates/transp_eq.geqdsk", "TRANSP (TRXPL)"),
]


def fetch(folder: Path) -> list:
    """The files, extracted from their wheels into ``folder``: [(path, code)]."""
    out = []
    wheels = {}
    for pkg, member, code in FILES:
        if pkg not in wheels:
            subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", pkg, "-d", str(folder)],
                           check=True)
            name = pkg.split("==")[0]
            wheels[pkg] = next(folder.glob(f"{name}-*.whl"))
        with zipfile.ZipFile(wheels[pkg]) as z:
            target = folder / Path(member).name
            target.write_bytes(z.read(member))
        out.append((target, code))
    shipped = Path(integrators.__file__).parent / "service" / "scenes" / "freegs_dn.geqdsk"
    out.append((shipped, "FreeGS (this project's freegs_dn)"))
    return out


def study(path: Path, code: str, folder: Path, steps: int) -> dict:
    sy = system_from_geqdsk(path)
    name = path.name.replace(".", "_")
    text = equilibrium_scene(path, name=name, steps=steps)
    scene_path = folder / f"{name}.toml"
    if path.parent != folder:                   # the scene names the file beside it
        (folder / path.name).write_bytes(path.read_bytes())
    scene_path.write_text(text)
    t0 = time.perf_counter()
    summaries = driver.run(parse_scene(text, str(scene_path)), folder / f"{name}.h5", progress=False)
    wall = time.perf_counter() - t0
    return dict(file=path.name, code=code, cocos=sy.defaults["cocos"], notes=list(sy.defaults["notes"]),
                q_check=list(sy.defaults["q_check"]), h=sy.defaults["h"], q0=sy.defaults["q0"], steps=steps,
                wall_s=round(wall, 1), pairs={s.pair: dict(status=s.status, breakdowns=s.breakdowns) for s in summaries})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for path, code in fetch(folder):
            r = study(path, code, folder, args.steps)
            rows.append(r)
            statuses = sorted({p["status"] for p in r["pairs"].values()})
            print(f"{r['file']:22s} COCOS {r['cocos']:2d}  h = {r['h']:<6g} {', '.join(statuses):24s} "
                  f"{r['wall_s']:7.1f} s  ({code})", flush=True)
            for n in r["notes"]:
                print(f"    {n}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, ensure_ascii=False))
    return 0 if all(p["status"] == "ok" for r in rows for p in r["pairs"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
