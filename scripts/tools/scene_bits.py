"""The shipped scenes' run files, for comparing two versions of the code bit for bit.

    python scripts/tools/scene_bits.py run OUTDIR [--ranks 2] [--scenes default lotka_volterra ...]
    python scripts/tools/scene_bits.py compare DIR_A DIR_B

``run`` runs every built-in scene (or those named) with this checkout's command line into OUTDIR
(``mpiexec -n RANKS``; the files are the same for any rank count) and writes OUTDIR/digests.json: a
SHA-256 of every dataset's bytes and every attribute of every file, leaving out what a run may
differ in by design — wall clocks (``wall_clock``, ``wall_time``), the creation time and the
version, and attributes a newer format added (``precision``).  ``compare`` says which scenes and
which entries differ.  Run ``run`` in a checkout of each version (its own numba cache), then
``compare``: how issue 42's restructuring was shown to change no shipped scene's file.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np

SKIP_ATTRS = {"created", "version", "wall_time", "precision"}
SKIP_DATA = ("wall_clock",)


def digests(path) -> dict:
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            for key, value in obj.attrs.items():
                if key not in SKIP_ATTRS:
                    out[f"{name}@{key}"] = hashlib.sha256(repr(np.asarray(value).tolist()).encode()).hexdigest()
            if isinstance(obj, h5py.Dataset) and not any(s in name for s in SKIP_DATA):
                data = obj[()]
                out[name] = hashlib.sha256(np.ascontiguousarray(data).tobytes() if isinstance(data, np.ndarray)
                                           else repr(data).encode()).hexdigest()
        for key, value in f.attrs.items():
            if key not in SKIP_ATTRS:
                out[f"/@{key}"] = hashlib.sha256(repr(np.asarray(value).tolist()).encode()).hexdigest()
        f.visititems(visit)
    return out


def run(outdir, ranks, scenes):
    from integrators.service.scene import builtin_scenes
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    bin_ = Path(sys.executable).parent
    names = scenes or list(builtin_scenes())
    # (the command line moved from integrators.service.cli to integrators.cli in issue 42)
    cli = ("import os, sys, integrators\n"
           "if os.path.exists(os.path.join(os.path.dirname(integrators.__file__), 'cli.py')):\n"
           "    from integrators.cli import main\n"
           "else:\n    from integrators.service.cli import main\nsys.exit(main())")
    result = {}
    for name in names:
        path = outdir / f"{name}.h5"
        path.unlink(missing_ok=True)
        t0 = time.perf_counter()
        cmd = [str(bin_ / "mpiexec"), "-n", str(ranks), sys.executable, "-c", cli, "run", name, "-o", str(path), "-q"]
        rc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ)).returncode
        result[name] = {"exit": rc, "digests": digests(path) if path.exists() else {}}
        print(f"{name}: exit {rc}, {len(result[name]['digests'])} entries, {time.perf_counter() - t0:.0f} s", flush=True)
    (outdir / "digests.json").write_text(json.dumps(result, indent=0))


def compare(a, b) -> int:
    A = json.loads((Path(a) / "digests.json").read_text())
    B = json.loads((Path(b) / "digests.json").read_text())
    bad = 0
    for name in sorted(set(A) | set(B)):
        if name not in A or name not in B:
            print(f"{name}: only in {'B' if name not in A else 'A'}")
            bad += 1
            continue
        da, db = A[name]["digests"], B[name]["digests"]
        differ = sorted(k for k in set(da) | set(db) if da.get(k) != db.get(k))
        same_exit = A[name]["exit"] == B[name]["exit"]
        print(f"{name}: exit {A[name]['exit']}/{B[name]['exit']}, {len(da)} entries, "
              + ("identical" if not differ and same_exit else f"{len(differ)} differ: {differ[:5]}"))
        bad += bool(differ) or not same_exit
    return 1 if bad else 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("outdir")
    r.add_argument("--ranks", type=int, default=2)
    r.add_argument("--scenes", nargs="*", default=None)
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args(argv)
    if args.cmd == "run":
        return run(args.outdir, args.ranks, args.scenes)
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
