"""Real stellarator equilibria through the engine: W7-X, Landreman–Paul QA and QH (docs/stellarators.md).

The three VMEC input files ship in simsopt's source distribution (MIT): ``input.W7-X_standard_configuration``,
``input.LandremanPaul2021_QA_reactorScale_lowres``, ``input.LandremanPaul2021_QH_reactorScale_lowres``.
This script fetches that distribution from the package index once, runs each input through ``vmecpp``
(fixed boundary) and ``booz_xform`` (Boozer transform), and caches what it makes (``--cache``); then, for
each ``boozmn`` file:

* the system from the file's defaults (``system_from_boozer``): modes kept, harmonics, the 3-D field's
  accuracy against the Fourier sum of the kept modes;
* the default passing and trapped guiding centres, ``--steps`` steps of GLRK2-symmetric: energy error,
  breakdowns;
* in QA and QH, the quasi-symmetry check (:func:`_symmetry_check`): the momentum of the symmetry,
  P_ζ in QA, n₁P_θ + P_ζ in QH, along the default orbits with the symmetric modes only (conserved
  to the interpolation's accuracy), with every mode (it moves), and with the breaking modes doubled
  (it moves twice as far);
* a scene from the defaults (``boozer_scene``, every pair, ``--scene-steps`` steps; its sets a quarter of
  the defaults' size unless ``--full``) run with ``poincare run`` on 1 and on 2 ranks: the statuses and
  whether the two files hold the same bits.

Needs the optional extra: ``pip install -e ".[stellarators]"`` (vmecpp, booz_xform; about 3 s of VMEC for
the low-resolution QA/QH inputs, longer for W7-X, on 2 cores).

    python scripts/studies/stellarator_equilibria.py --json docs/figures/stellarator_equilibria.json
    python scripts/studies/stellarator_equilibria.py --full --scene-steps 1000 --steps 200 \
        --json docs/figures/stellarator_equilibria_full.json       # the scenes exactly from the defaults
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tarfile
import time
import urllib.request
from pathlib import Path

import numpy as np

CASES = {"W7-X": "input.W7-X_standard_configuration",
         "QA": "input.LandremanPaul2021_QA_reactorScale_lowres",
         "QH": "input.LandremanPaul2021_QH_reactorScale_lowres"}
SIMSOPT = "simsopt"


def fetch_inputs(cache: Path) -> dict:
    """The three VMEC inputs (and simsopt's licence) from simsopt's sdist on the package index, cached."""
    out = {name: cache / fname for name, fname in CASES.items()}
    if all(p.exists() for p in out.values()):
        return out
    with urllib.request.urlopen(f"https://pypi.org/pypi/{SIMSOPT}/json", timeout=120) as r:
        meta = json.load(r)
    sdist = next(u for u in meta["urls"] if u["packagetype"] == "sdist")
    tgz = cache / sdist["filename"]
    if not tgz.exists():
        print(f"fetching {sdist['url']} ({sdist['size'] / 1e6:.0f} MB)", flush=True)
        urllib.request.urlretrieve(sdist["url"], tgz)
    with tarfile.open(tgz) as tf:
        for m in tf.getmembers():
            base = Path(m.name).name
            if base in CASES.values() or (base == "LICENSE" and m.name.count("/") == 1):
                m.name = base if base != "LICENSE" else "LICENSE-simsopt.txt"
                tf.extract(m, cache)
    return out


def boozmn(name: str, vmec_input: Path, cache: Path) -> Path:
    """vmecpp then booz_xform on one input; the boozmn file (cached)."""
    out = cache / f"boozmn_{name}.nc"
    if out.exists():
        return out
    import booz_xform
    import vmecpp
    t0 = time.perf_counter()
    inp = vmecpp.VmecInput.from_file(vmec_input)
    res = vmecpp.run(inp, verbose=False)
    wout = cache / f"wout_{name}.nc"
    res.wout.save(str(wout))
    t1 = time.perf_counter()
    b = booz_xform.Booz_xform()
    b.verbose = 0
    b.read_wout(str(wout), True)            # True: read the fluxes too (phi_b; without it they are written as 0)
    b.mboz, b.nboz = max(2 * inp.mpol, 16), max(2 * inp.ntor, 16)
    b.run()
    b.write_boozmn(str(out))
    print(f"{name}: vmecpp {t1 - t0:.1f} s (mpol {inp.mpol}, ntor {inp.ntor}, ns {list(inp.ns_array)}), "
          f"booz_xform {time.perf_counter() - t1:.1f} s (mboz {b.mboz}, nboz {b.nboz})", flush=True)
    return out


def study(name: str, path: Path, steps: int, scene_steps: int, work: Path, full: bool = False) -> dict:
    import integrators
    from integrators.boozer import read_boozmn, system_from_boozer
    from integrators.service.scene import boozer_scene
    row = {"case": name, "file": path.name}
    bz = read_boozmn(path)
    t0 = time.perf_counter()
    sy = system_from_boozer(path)
    row.update(build_s=time.perf_counter() - t0, nfp=bz.nfp, modes=int(bz.xm.size), kept=int(bz.modes()[0].size),
               harmonics=list(sy.defaults["harmonics"]), field=sy.defaults["field"], grid_zeta=sy.defaults["grid_zeta"],
               phi_sign=int(bz.sign), h=sy.defaults["h"], notes=list(sy.defaults["notes"]))
    rng = np.random.default_rng(71)
    s, th, ze = rng.uniform(0, 0.98, 2000), rng.uniform(0, 2 * np.pi, 2000), rng.uniform(0, 2 * np.pi, 2000)
    r = np.sqrt(2 * bz.psi_abs * s)
    q = np.stack([r * np.cos(th), bz.sign * r * np.sin(th), ze, 0 * s], 1)
    e = np.abs(sy.H(q) / sy.param_values["mu"] / bz.modB(s, th, ze) - 1)
    row.update(field_err_max=float(e.max()), field_err_median=float(np.median(e)))
    d = sy.defaults
    q0 = np.array([d["q0"], d["trapped"]])
    t0 = time.perf_counter()
    sol = integrators.integrate(sy, q0, tableau="GLRK2", projection="symmetric", h=d["h"], steps=steps,
                                save_every=max(1, steps // 100))
    row["orbits_s"] = time.perf_counter() - t0
    E = np.stack([sy.H(sol.q[:, i]) for i in range(2)])
    ok = np.isfinite(E)
    row.update(energy_err=[float(np.nanmax(np.abs(E[i][ok[i]] / E[i, 0] - 1))) for i in range(2)],
               broke=[bool(np.isfinite(t)) for t in sol.breakdown_time])
    if name in ("QA", "QH") and not full:
        row["symmetry"] = _symmetry_check(path, bz, steps)
    scene = path.parent / f"{name}.toml"           # beside the boozmn file, which it names
    text = boozer_scene(path, name=f"boozer_{name.replace('-', '_')}", steps=scene_steps)
    scene.write_text(text if full else text.replace("points = 2048", "points = 512").replace("refine_to = 8192", "refine_to = 2048")
                     .replace("n_sigma = 24", "n_sigma = 12").replace("n_tau = 24", "n_tau = 12")
                     .replace("refine_to = 2209", "refine_to = 529"))
    runs = {}
    for ranks in (1, 2):
        out = work / f"{name}_{ranks}.h5"
        cmd = ([sys.executable, "-m", "integrators.cli"] if ranks == 1 else
               [str(Path(sys.executable).with_name("mpiexec")), "-n", "2", sys.executable, "-m", "integrators.cli"])
        t0 = time.perf_counter()
        p = subprocess.run(cmd + ["run", str(scene), "-o", str(out), "--force"], capture_output=True, text=True,
                           cwd=work)
        if p.returncode:
            print(p.stderr[-2000:], file=sys.stderr)
        runs[ranks] = {"rc": p.returncode, "wall_s": time.perf_counter() - t0, "out": p.stdout[-6000:],
                       "err": p.stderr[-2000:]}
    row["scene"] = {str(k): {"rc": v["rc"], "wall_s": v["wall_s"]} for k, v in runs.items()}
    row["scene_table"] = runs[1]["out"]
    row["scene_statuses"] = [ln.split()[1] for ln in runs[1]["out"].splitlines()
                             if ln[:5] in ("GLRK1", "GLRK2") and len(ln.split()) > 2]
    row["scene_same_bits"] = (_same_bits(work / f"{name}_1.h5", work / f"{name}_2.h5")
                              if all(v["rc"] == 0 for v in runs.values()) else None)
    return row


def _symmetry_check(path: Path, bz, steps: int) -> dict:
    """The quasi-symmetry check.  The helicity is the largest m = 1 mode's: symmetric modes have
    n = m·n₁ (QA n₁ = 0, QH n₁ = −nfp here), |B| is then a function of ψ and θ − n₁ζ, and the momentum
    P_h = n₁ P_θ + P_ζ (P_θ = ψ + ρI, P_ζ = ρG − ψ_p) is conserved.  P_h's largest relative move
    along the default orbits with the symmetric modes only, with every mode of the file, with the
    breaking modes doubled, and with the default modes_tol; the symmetric-only case also on a 192²
    grid (what is left there is the Cartesian grid's interpolation, which is not symmetric)."""
    import integrators
    from integrators.boozer import system_from_boozer
    m1 = np.flatnonzero(bz.xm == 1)
    n1 = int(bz.xn[m1[np.argmax(np.abs(bz.bmnc[:, m1]).max(0))]])
    breaking = bz.xn != n1 * bz.xm
    big = np.abs(bz.bmnc).max(0) / abs(bz.bmnc[:, (bz.xm == 0) & (bz.xn == 0)]).max()
    out = {"n1": n1, "breaking_max": float(big[breaking].max())}
    cases = [("symmetric only", 0.0, 0.0, {}), ("symmetric only, 192² grid", 0.0, 0.0, {"grid": 192}),
             ("every mode", 1.0, 0.0, {}), ("breaking modes doubled", 2.0, 0.0, {}),
             ("default modes_tol", 1.0, 1e-4, {})]
    for label, factor, tol, kw in cases:
        src = path
        if factor != 1.0:
            src = path.parent / f"{path.stem}_breaking_x{factor:g}.nc"
            _scaled_copy(path, src, bz, factor, breaking)
        sy = system_from_boozer(src, modes_tol=tol, **kw)
        d = sy.defaults
        q0 = np.array([d["q0"], d["trapped"]])
        sl = integrators.integrate(sy, q0, tableau="GLRK2", projection="symmetric", h=d["h"], steps=steps,
                                   save_every=max(1, steps // 100))
        P = np.stack([_p_helical(sy, sl.q[:, i], n1) for i in range(2)])
        out[label] = {"P_rel": [float(np.max(np.abs(P[i] - P[i, 0])) / abs(P[i, 0])) for i in range(2)],
                      "harmonics": len(d["harmonics"]), "field": d["field"]}
    return out


def _p_helical(system, q, n1):
    """n₁ P_θ + P_ζ along an orbit, from the system's own profile splines (fields 0–2: G, Ĩ, ψ_p)."""
    from integrators.splines import field1_np
    r2 = (q[:, 0] ** 2 + q[:, 1] ** 2) / 2
    psi = system.boozer.sign * r2
    P = len(system.params)
    k = system.param_vector()
    G, It, psip = (field1_np(k, i, r2, P)[0] for i in range(3))
    return n1 * (psi + q[:, 3] * 2 * psi * It) + q[:, 3] * G - psip


def _scaled_copy(src: Path, dst: Path, bz, factor: float, which):
    """A copy of a boozmn file with the modes ``which`` (a mask) of |B| multiplied by ``factor``."""
    from scipy.io import netcdf_file
    with netcdf_file(src, "r", mmap=False) as f, netcdf_file(dst, "w") as g:
        for dname, size in f.dimensions.items():
            g.createDimension(dname, size)
        for vname, var in f.variables.items():
            data = np.array(var[()])
            if vname == "bmnc_b":
                data[:, which] *= factor
            out = g.createVariable(vname, var.typecode(), var.dimensions)
            if var.dimensions:
                out[:] = data
            else:
                out.data[()] = data         # (assignValue indexes a 0-d array with [:] in this scipy)


def _same_bits(a: Path, b: Path):
    """Every dataset of the two run files equal bit for bit (wall-clock times aside)."""
    import h5py
    if not (a.exists() and b.exists()):
        return None
    with h5py.File(a, "r", locking=False) as fa, h5py.File(b, "r", locking=False) as fb:
        names = []
        fa.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) else None)
        for n in names:
            if "wall" in n or n not in fb:
                continue
            x, y = fa[n][()], fb[n][()]
            if isinstance(x, np.ndarray) and x.dtype.kind == "f":
                if x.shape != y.shape or not np.array_equal(x.view(np.uint8), y.view(np.uint8)):
                    return False
    return True


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
                    / "poincare" / "stellarators")
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--scene-steps", type=int, default=100)
    ap.add_argument("--full", action="store_true",
                    help="the scene exactly as boozer_scene writes it (2,048-point loop, 24 × 24 surface); "
                         "without it the sets are a quarter of that; the quasi-symmetry check is left to the "
                         "reduced run")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    if not all(importlib.util.find_spec(m) for m in ("vmecpp", "booz_xform")):
        sys.exit('this study needs the optional extra: pip install -e ".[stellarators]"')
    inputs = fetch_inputs(args.cache)
    rows = []
    for name in args.cases.split(","):
        path = boozmn(name, inputs[name], args.cache)
        work = args.cache / "runs"
        work.mkdir(exist_ok=True)
        row = study(name, path, args.steps, args.scene_steps, work, args.full)
        row["scene_size"] = "full" if args.full else "reduced"
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items() if k not in ("scene_table", "notes")}, default=str), flush=True)
        print(row["scene_table"], flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
