"""What the tests of scenes, files, resumes and the command line share: the `poincare` command run
as a process, small scenes, and readers of run files (moved here from the files that grew by issue)."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from integrators.service import driver
from integrators.service.scene import parse_scene


POINTS = Path(__file__).parent
SCENES = POINTS / "data" / "scenes"


def scene_text(name):
    """The shared test scene tests/data/scenes/<name>.toml, as text."""
    return (SCENES / f"{name}.toml").read_text()


BIN = Path(sys.executable).parent


LV_PAIRS = scene_text("lv_pairs")


GC = scene_text("gc")



def _flip_chunk(path, dataset):
    """Overwrite the first stored chunk of a dataset with garbage bytes (a damaged disk block)."""
    with h5py.File(path, "r") as f:
        info = f[dataset].id.get_chunk_info(0)
    with open(path, "r+b") as fh:
        fh.seek(info.byte_offset + 8)
        fh.write(b"\x13\x37" * 8)



SHAPES_CIRCLE = '''
import numpy as np

def circle(tau, r=0.3):
    return np.stack([r * np.cos(2 * np.pi * tau), r * np.sin(2 * np.pi * tau), 0 * tau, 0.5 + 0 * tau], axis=-1)

def boom(tau):
    raise RuntimeError("shape exploded")
'''


LV = scene_text("lv")


def scene(steps, every=10, text=LV):
    return parse_scene(text.replace("steps = 20", f"steps = {steps}").replace("output_every = 10",
                                                                              f"output_every = {every}"))


def dump(path, skip=("wall_clock",)):
    """Every dataset and status of a run file, checkpoints included, but for datasets whose names
    contain one of ``skip`` (the wall clocks by default)."""
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and not any(s in name for s in skip):
                out[name] = obj[()]
        f.visititems(visit)
        out["status"] = {k: str(f["runs"][k].attrs["status"]) for k in f["runs"]}
    return out


def differing(a, b):
    """The entries of two dumps that are not bitwise equal (NaN equal to NaN where both are)."""
    return sorted(set(a) ^ set(b)) + [
        k for k in set(a) & set(b) if not ((a[k] == b[k]) if k == "status" else np.array_equal(
            a[k], b[k], equal_nan=np.asarray(a[k]).dtype.kind in "fc"))]


def same(a, b):
    return not differing(a, b)


def assert_same(a, b):
    """Two run files (paths) or two dumps hold the same bits."""
    da, db = (x if isinstance(x, dict) else dump(x) for x in (a, b))
    assert not differing(da, db), differing(da, db)


def poincare(*args, cwd=None, n=None, env=None, **kw):
    cmd = [str(BIN / "poincare"), *args]
    if n:
        cmd = [str(BIN / "mpiexec"), "-n", str(n), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=cwd,
                          env=None if env is None else {**os.environ, **env}, **kw)


USER = scene_text("oscillator")


def one_line(r, *words):
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert all(w in r.stderr for w in words), r.stderr


SHAPES_TAU = '''
import numpy as np

def circle(tau, r=0.1, cx=0.5, cy=0.5):
    assert tau.shape == (32,) and tau[0] == 0.0 and tau[-1] == 31 / 32
    return np.stack([cx + r * np.cos(2 * np.pi * tau), cy + r * np.sin(2 * np.pi * tau)], axis=1)

def by_count(N):
    return np.zeros((N, 2))
'''


PARTIAL = LV.replace('projections = ["none", "symmetric"]', 'projections = ["none"]').replace(
    "h = 0.1", "h = 0.3").replace("center = [1.0, 1.0], radii = [0.1, 0.1]", "center = [0.35, 0.35], radii = [0.3, 0.3]")


def _claim_petabytes(path):
    """Set the first dimension of one series dataset's dataspace (5 rows, unlimited) to 2^50 + 5."""
    import struct
    data = bytearray(path.read_bytes())
    pattern = struct.pack("<Q", 5) + b"\xff" * 8
    k = data.index(pattern)
    data[k + 6] = 0x04
    path.write_bytes(bytes(data))


MAPS = """
import os, sys, time
calls = [0]

def stuck(q, p, lam, h, system):
    calls[0] += 1
    if calls[0] > 30 and os.environ.get("STUCK_RANK", os.environ.get("PMI_RANK", "0")) == os.environ.get("PMI_RANK", "0"):
        if os.environ.get("SPIN"):
            while True:
                pass
        time.sleep(10**6)
    return q, p, lam

def bye(q, p, lam, h, system):
    sys.exit(0)

def shape_bye(tau):
    sys.exit(3)
"""


STUCK = USER.replace('tableaus = ["GLRK1"]\nprojections = ["none"]', 'step_maps = ["maps.py:stuck"]') \
    .replace("steps = 20", "steps = 100") + "[output]\ncheckpoint_seconds = 0.0\n"


def _rows(path, pair):
    with h5py.File(path, "r", locking=False) as f:
        return f[f"runs/{pair}/t"].shape[0]


def wait_rows(path, pair, rows, proc, limit=120):
    deadline = time.time() + limit
    while time.time() < deadline and proc.poll() is None:
        time.sleep(0.1)
        try:
            if _rows(path, pair) >= rows:
                return True
        except (OSError, KeyError, RuntimeError):
            pass
    return False



def _limited(extra):
    import resource

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (extra, extra))
    return limit


def _finished_then_on_a_full_disk(tmp_path, room, *args):
    """A finished run of LV in tmp_path/lv.h5, then ``poincare run … args`` with ``room`` bytes to
    grow beyond the file's size; returns (the file's bytes before, the second command's result)."""
    (tmp_path / "lv.toml").write_text(LV)
    out = tmp_path / "lv.h5"
    assert poincare("run", "lv.toml", "-o", "lv.h5", "-q", cwd=tmp_path).returncode == 0
    before = out.read_bytes()
    r = subprocess.run([str(BIN / "poincare"), "run", "lv.toml", "-o", "lv.h5", *args, "--steps", "4000", "-q"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       preexec_fn=_limited(len(before) + room))
    return before, r



SMALL = scene_text("small")


def edit(text, old, new):
    assert old in text
    return text.replace(old, new)




def stop_at_output_8(scene, path, monkeypatch):
    """Run ``scene`` into ``path`` with a state every 3rd output and rows every 2nd, stopped (as by
    Ctrl-C) after output 8 of pair GLRK2-none: its rows end at 8, its newest state is at 6."""
    monkeypatch.setattr(driver, "_cadence", lambda seconds_per_output, checkpoint_seconds: 3)
    monkeypatch.setattr(driver, "_batch", lambda seconds_per_output, points: 2)

    def stop(pair, step):
        if pair == "GLRK2-none" and step == 32:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        driver.run(scene, path, progress=False, after_output=stop)


JITTER = """
import random, sys, time
from integrators.service import driver
from integrators.service.ranks import communicator
from integrators.service.scene import load_scene
comm = communicator()
rank_slowest = int(sys.argv[3])
slow = 0.0 if comm.size == 1 else 0.012 * (1 + (comm.rank - rank_slowest) % comm.size)
rng = random.Random(comm.rank)
march = driver.march

def uneven(engine, st, start, stop, every, hooks, *args, **kw):
    def late(step, *out):             # this rank reaches its outputs late by a random 0-slow s
        time.sleep(rng.uniform(0.0, slow))
        hooks.on_output(step, *out)
    return march(engine, st, start, stop, every, hooks._replace(on_output=late), *args, **kw)

driver.march = uneven
driver._batch = lambda seconds_per_output, points: 2
driver._cadence = lambda seconds_per_output, checkpoint_seconds: 3
driver.run(load_scene(sys.argv[1]), sys.argv[2], progress=False)
"""


def assert_jacobian_is_complex_steps(system, eng, h, q, p, lam, z, tol=1e-12):
    """The kernel's Newton Jacobian at (q, p, Λ, z) against complex-step differences of its residual,
    column by column, through the system's complex point function: within ``tol`` of each column's size."""
    from integrators import kernel
    from integrators.codegen import point_functions
    ev_r, _ = point_functions(system)
    ev_c, _ = point_functions(system, complex_step=True)
    assert h == eng.h
    _, J = kernel.probe(ev_r, eng.pair(), (q, p, lam), z, True, s=eng.tableau.s)
    for k in range(eng.nz):
        zc = z.astype(complex)
        zc[k] += 1e-30j
        col = kernel.probe(ev_c, eng.pair(), (q.astype(complex), p.astype(complex), lam.astype(complex)), zc, False,
                           s=eng.tableau.s)[0].imag / 1e-30
        assert np.max(np.abs(J[:, k] - col)) <= tol * max(1.0, np.max(np.abs(col))), k
