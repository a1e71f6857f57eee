"""HDF5 output of a batch run, written incrementally and crash-safe.

Layout (format ``poincare/1``)::

    /                       attrs: format, scene (TOML text), version, system, created
    /runs/<TABLEAU>-<projection>/
        t                   (n,)       output times
        I1/<form>, I2/<form> (n,)      invariants (only the forms asked for; I2 only with a surface)
        resolution/I1, resolution/I2 (n,)  resolution monitor of the loop / surface
        energy_error        (n,)       max over points of |H − H₀|/|H₀|
        momentum_error      (n,)       max over points of |P − P₀|
        constraint_error    (n,)       max over points of |p − ϑ(q)|
        breakdown_time      (npoints,) per point, inf = never (loop points first, then the surface row by row)
        points/loop, points/surface    (n, N, d), (n, nσ, nτ, d) only with run.store_points
        checkpoint/a, checkpoint/b     two alternating copies of the integrator state
        attrs: status (pending | ok | partial | failed), wall_time [s]

Every dataset grows by one row per output and the file is flushed after each output,
so a run killed at any moment leaves a readable file with every output up to the
last flush.  The file uses HDF5's default (earliest) format: the newer superblock
keeps "open for writing" flags that a killed writer leaves set, after which plain
readers refuse the file.  A checkpoint slot is first marked invalid (step = −1),
then written, then given its step; resume uses the newest valid slot and drops any
rows written after it.
"""
from __future__ import annotations

import datetime

import h5py
import numpy as np

FORMAT = "poincare/1"
STATE_FIELDS = ("q", "p", "Lam", "q_comp", "p_comp", "Y", "mu", "have_history", "live", "breakdown_time",
                "iterations", "steps")


def pair_name(tableau, projection):
    return f"{tableau}-{projection}"


def _series(g, name):
    return g.create_dataset(name, shape=(0,), maxshape=(None,), dtype="f8", chunks=(256,))


def create(path, scene, version, npoints, state_shapes):
    """Create the file with every group and dataset of the scene."""
    f = h5py.File(path, "w")
    f.attrs["format"] = FORMAT
    f.attrs["scene"] = scene.text
    f.attrs["version"] = version
    f.attrs["system"] = scene.system_name
    f.attrs["created"] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    runs = f.create_group("runs")
    for tab, proj in scene.pairs:
        g = runs.create_group(pair_name(tab, proj))
        g.attrs["status"] = "pending"
        g.attrs["wall_time"] = 0.0
        _series(g, "t")
        for inv, present in (("I1", scene.loop is not None), ("I2", scene.surface is not None)):
            if present:
                for form in scene.forms:
                    _series(g, f"{inv}/{form}")
                _series(g, f"resolution/{inv}")
        for diag in scene.diagnostics:
            _series(g, f"{diag}_error")
        g.create_dataset("breakdown_time", data=np.full(npoints, np.inf))
        g.create_dataset("wall_clock", data=np.zeros(1))
        if scene.store_points:
            if scene.loop is not None:
                n, d = scene.loop["points"], state_shapes["q"][0][1]
                g.create_dataset("points/loop", shape=(0, n, d), maxshape=(None, n, d), dtype="f8", chunks=(1, n, d))
            if scene.surface is not None:
                ns, nt, d = scene.surface["n_sigma"], scene.surface["n_tau"], state_shapes["q"][0][1]
                g.create_dataset("points/surface", shape=(0, ns, nt, d), maxshape=(None, ns, nt, d), dtype="f8",
                                 chunks=(1, ns, nt, d))
        for slot in ("a", "b"):
            c = g.create_group(f"checkpoint/{slot}")
            c.create_dataset("step", data=np.array(-1, dtype=np.int64))
            for name in STATE_FIELDS:
                shape, dtype = state_shapes[name]
                c.create_dataset(name, shape=shape, dtype=dtype)
    f.flush()
    return f


def append(g, row: dict):
    """Append one output row {dataset path: value} to the pair group g."""
    for name, val in row.items():
        ds = g[name]
        n = ds.shape[0]
        ds.resize(n + 1, axis=0)
        ds[n] = val


def write_checkpoint(f, g, step, state: dict):
    """Write the state into the older slot: invalidate, write, flush, validate, flush."""
    slots = [g["checkpoint/a"], g["checkpoint/b"]]
    steps = [int(s["step"][()]) for s in slots]
    c = slots[0] if steps[0] <= steps[1] else slots[1]
    c["step"][()] = -1
    f.flush()
    for name in STATE_FIELDS:
        c[name][...] = state[name]
    f.flush()
    c["step"][()] = step
    f.flush()


def read_checkpoint(g):
    """(step, state) of the newest valid slot, or (None, None)."""
    best = None
    for slot in ("a", "b"):
        c = g[f"checkpoint/{slot}"]
        step = int(c["step"][()])
        if step >= 0 and (best is None or step > best[0]):
            best = (step, {name: c[name][...] for name in STATE_FIELDS})
    return best if best is not None else (None, None)


def truncate(g, n_rows):
    """Drop output rows beyond n_rows (written after the checkpoint being resumed from)."""
    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.maxshape and obj.maxshape[0] is None and obj.shape[0] > n_rows:
            obj.resize(n_rows, axis=0)
    g.visititems(visit)


def open_for_resume(path, scene):
    """Reopen an interrupted run; the scene must be the one it was started with."""
    try:
        f = h5py.File(path, "r+")
    except OSError as exc:
        raise ValueError(f"cannot resume '{path}': {exc}") from None
    if f.attrs.get("format") != FORMAT:
        f.close()
        raise ValueError(f"cannot resume '{path}': not a {FORMAT} file")
    if f.attrs.get("scene") != scene.text:
        f.close()
        raise ValueError(f"cannot resume '{path}': it was written by a different scene")
    return f
