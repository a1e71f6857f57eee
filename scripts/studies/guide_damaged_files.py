"""Flip single bits of a finished 4-pair run file, or cut it short, and check what `poincare plot` and
`poincare run --resume` make of each damaged copy: one line and exit 0-3, never a traceback or a
crash, and a refused or failed resume leaves the file byte for byte as it was.  A truncated file
must be called damaged, never locked or busy (HDF5's message for a bad superblock names the
'sblock').

    python scripts/studies/guide_damaged_files.py [--flips 30] [--seed 1] [--offsets 15062 39781:5 ...] [--below BYTES]
    python scripts/studies/guide_damaged_files.py --flips 0 --truncate     # every 512 bytes up to the first dataset, and a few beyond

Prints one line per flip or cut and a summary; exits 1 if any broke a rule.  (The test suite runs a
few of the same checks: tests/test_files.py.)"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SCENE = """
name = "lv"
[system]
name = "lotka_volterra_2d"
[loop]
shape = "ellipse"
points = 64
params = { d = 2, center = [1.0, 1.0], radii = [0.1, 0.1] }
[run]
tableaus = ["GLRK1", "GLRK2"]
projections = ["none", "symmetric"]
h = 0.1
steps = 20
output_every = 5
diagnostics = ["energy", "constraint"]
"""

BIN = Path(sys.executable).parent


def poincare(*args, cwd):
    r = subprocess.run([str(BIN / "poincare"), *args], capture_output=True, text=True, cwd=cwd, timeout=300)
    return r.returncode, r.stderr


def check_flip(work, clean, offset, bit):
    """[] or the rules one flipped bit broke."""
    path = work / "lv.h5"
    data = bytearray(clean)
    data[offset] ^= 1 << bit
    path.write_bytes(bytes(data))
    broken = []
    code, err = poincare("plot", "lv.h5", "-o", "png", cwd=work)
    if code not in (0, 2) or "Traceback" in err or err.count("\n") > 1:
        broken.append(f"plot exit {code}: {err.strip().splitlines()[-1] if err.strip() else ''}")
    before = path.read_bytes()
    code, err = poincare("run", "lv.toml", "-o", "lv.h5", "--resume", "-q", cwd=work)
    if code not in (0, 1, 2, 3) or "Traceback" in err or err.count("\n") > 1:
        broken.append(f"resume exit {code}: {err.strip().splitlines()[-1] if err.strip() else ''}")
    if code not in (0, 1) and path.read_bytes() != before:
        broken.append(f"resume exit {code} changed the file")
    return broken, code


def check_truncation(work, clean, size):
    """[] or the rules a file cut to ``size`` bytes broke: plot and resume call it damaged (exit 2),
    never locked or busy, and the refused resume leaves it as it was."""
    path = work / "lv.h5"
    path.write_bytes(clean[:size])
    broken = []
    for args in (("plot", "lv.h5", "-o", "png"), ("run", "lv.toml", "-o", "lv.h5", "--resume", "-q")):
        code, err = poincare(*args, cwd=work)
        if code != 2 or "Traceback" in err or err.count("\n") != 1:
            broken.append(f"{args[0]} exit {code}: {err.strip().splitlines()[-1] if err.strip() else ''}")
        elif "damaged" not in err or "lock" in err.replace("sblock", "") or "another process" in err:
            broken.append(f"{args[0]} says: {err.strip()}")
    if path.read_bytes() != clean[:size]:
        broken.append("resume changed the file")
    return broken


def first_dataset_offset(path) -> int:
    """The file offset of the first dataset's data: the metadata lies before it."""
    import h5py
    offsets = []
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                try:
                    offsets.append(obj.id.get_offset())
                except Exception:
                    pass
        f.visititems(visit)
    offsets = [o for o in offsets if o]           # (a chunked dataset has no one offset: None)
    return min(offsets) if offsets else os.path.getsize(path) // 2


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flips", type=int, default=30)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--offsets", nargs="*", default=[], help="byte offsets to flip, each OFFSET or OFFSET:BIT")
    ap.add_argument("--below", type=int, default=None, help="flip only bytes before this offset (the metadata)")
    ap.add_argument("--truncate", action="store_true",
                    help="also cut the file every 512 bytes up to its first dataset, and at a few sizes beyond")
    args = ap.parse_args(argv)
    import numpy as np
    work = Path(tempfile.mkdtemp(prefix="damaged_"))
    try:
        (work / "lv.toml").write_text(SCENE)
        code, err = poincare("run", "lv.toml", "-o", "lv.h5", "-q", cwd=work)
        assert code == 0, err
        clean = (work / "lv.h5").read_bytes()
        rng = np.random.default_rng(args.seed)
        flips = [(int(o.split(":")[0]), int(o.split(":")[1]) if ":" in o else int(rng.integers(8))) for o in args.offsets]
        flips += [(int(o), int(b)) for o, b in zip(rng.integers(min(len(clean), args.below or len(clean)), size=args.flips),
                                                   rng.integers(8, size=args.flips))]
        bad = 0
        for offset, bit in flips:
            broken, code = check_flip(work, clean, offset, bit)
            bad += bool(broken)
            print(f"offset {offset:6d} bit {bit}: resume exit {code}  " + ("; ".join(broken) or "ok"), flush=True)
        print(f"{len(flips)} flips in a {len(clean):,}-byte file: {bad} broke a rule")
        if args.truncate:
            first = first_dataset_offset(work / "lv.h5")
            sizes = list(range(0, first + 1, 512)) + [first + 1, len(clean) // 4, len(clean) // 2,
                                                       3 * len(clean) // 4, len(clean) - 1]
            cut_bad = 0
            for size in sizes:
                broken = check_truncation(work, clean, size)
                cut_bad += bool(broken)
                print(f"cut to {size:6d} bytes: " + ("; ".join(broken) or "ok"), flush=True)
            print(f"{len(sizes)} truncations (first dataset at byte {first:,}): {cut_bad} broke a rule")
            bad += cut_bad
        return 1 if bad else 0
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
