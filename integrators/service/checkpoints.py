"""The integrator state in the run file: checkpoint slots, written in file or as per-rank slabs.

The integrator state is written about every ``output.checkpoint_seconds`` of wall time (default
60 s; 0: at every output) and at each pair's last output, not at every output: a row is a few
dozen numbers, a state about 300 bytes a point.  A checkpoint slot is first marked invalid
(step = −1), then written, then given its step; resume uses the newest valid slot, drops the rows
written after it and computes them again.  Every output starts the next step from fresh Newton
Jacobians, so a run resumed from any output is bitwise the uninterrupted one, and how often the
state is written changes no result.  A finished pair keeps its final state in slot a, slot b empty;
when ``run.steps`` is not a multiple of ``run.output_every`` the state kept is the one at the last
multiple (the driver's ``last_checkpoint_step``): the last, shorter interval is recomputed by a
resume, and a longer run goes on from there with the straight run's bits.

With ``output.checkpoints = "per-rank"`` no rank sends its state to rank 0: at a checkpoint each
rank writes its points' rows as a file of its own, ``<file>.checkpoints/<pair>.<step>.<run>.<lo>-<hi>.h5``
(:func:`write_slab`: every field, fletcher32, closed), and rank 0, once every rank's slab of that
output has come, links them into the older slot as virtual datasets (:func:`link_checkpoint`; the
slot's ``slabs`` attribute lists them) with the same invalidate–link–validate protocol, then removes
the slabs that slot linked before.  Reading ``checkpoint/a/q`` with h5py gives the whole state as
before; resume reads the slab files themselves (:func:`read_checkpoint`) and refuses, naming the
folder, when one is missing (HDF5 would read a missing source as zeros).  Slabs that no slot links
(a stopped run's, a replaced file's) are removed by the next run (:func:`prune_slabs`).  Either
setting resumes a file written with the other; the values are the same, only the links name the
ranks that wrote them.
"""
from __future__ import annotations

import json

import h5py
import numpy as np

from ..engine import CHECKPOINT_FIELDS
from .files import DamagedFile, OutputError, SPACE_MARGIN, available_bytes, plain_error

STATE_FIELDS = CHECKPOINT_FIELDS         # the engine's State defines the checkpoint schema


def write_checkpoint(f, g, step, state: dict):
    """Write the state into the older slot: invalidate, write, flush, validate, flush."""
    slots = [g["checkpoint/a"], g["checkpoint/b"]]
    steps = [int(s["step"][()]) for s in slots]
    c = slots[0] if steps[0] <= steps[1] else slots[1]
    c["step"][()] = -1
    f.flush()
    old = slot_files(c)
    if old:                               # the slot linked per-rank slabs (a run resumed in-file)
        _slot_fields(c, _shapes(c))
    for name in STATE_FIELDS:
        c[name][...] = state[name]
    f.flush()
    c["step"][()] = step
    f.flush()
    _remove_slabs(state_dir(f.filename), old)


CHECKPOINT_MODES = ("in-file", "per-rank")     # output.checkpoints: who writes the state


STATE_DIR_SUFFIX = ".checkpoints"


def state_dir(path):
    """The folder beside run file ``path`` that holds its per-rank checkpoint slabs ('run.h5' →
    'run.h5.checkpoints')."""
    from pathlib import Path
    path = Path(path).resolve()            # (through a symlink: beside its target, where the links resolve)
    return path.with_name(path.name + STATE_DIR_SUFFIX)


def slab_name(pair, step, token, lo, hi) -> str:
    """The file name of one rank's slab of a pair's state at ``step``; ``token`` is the run's own,
    so a slab of a run that was stopped before its checkpoint was linked never meets a new one."""
    return f"{pair}.{step}.{token}.{lo}-{hi}.h5"


def write_slab(folder, name, state: dict, s_max):
    """Write one rank's slab of the integrator state (rows of its points; stage arrays padded to the
    file's largest s) as its own HDF5 file ``folder/name``, checksummed and closed: the per-rank
    checkpoint (``output.checkpoints = "per-rank"``), linked into the run file by rank 0 once every
    rank's slab of that output is written (:func:`link_checkpoint`).  OutputError in one line."""
    state = _pad_stages(state, s_max)
    path = folder / name
    need = sum(v.nbytes for v in state.values()) + SPACE_MARGIN
    if available_bytes(path) < need:
        raise OutputError(f"no space left for the checkpoint slab '{path}' (it needs about {need / 2**20:.2f} MiB); "
                          "the run file holds every output written before it: free space, then run again with --resume")
    try:
        with h5py.File(path, "w") as s:
            for field in STATE_FIELDS:
                v = np.asarray(state[field])
                s.create_dataset(field, data=v, chunks=True if v.size else None, fletcher32=bool(v.size))
    except OSError as exc:
        raise OutputError(f"cannot write the checkpoint slab '{path}': {plain_error(exc)}") from None


def _stage_rows(s):
    """The rows (axis 1) of the state's stage-shaped fields for a pair of s stages: Y (s), jac_z
    (s + 2: the stages, Λ, μ) and the predictor's defects (DEPTH (s + 2)).  The one place that knows
    which fields grow with s (:func:`_pad_stages`, :func:`unpad_stages`)."""
    from ..kernel import DEPTH
    return {"Y": s, "jac_z": s + 2, "defects": DEPTH * (s + 2)}


def _pad_stages(state, s_max):
    """The stage-shaped fields (:func:`_stage_rows`) padded with zeros at their ends to the scene's
    largest s (the file's schema); :func:`unpad_stages` cuts them back."""
    s = state["Y"].shape[1]
    if s_max <= s:
        return state
    pad = lambda a, k: np.concatenate([a, np.zeros((a.shape[0], k) + a.shape[2:], a.dtype)], axis=1)
    have, want = _stage_rows(s), _stage_rows(s_max)
    return dict(state, **{f: pad(state[f], want[f] - have[f]) for f in have})


def unpad_stages(state, s):
    """A state read from a checkpoint cut back to its pair's s stages (:func:`_pad_stages` undone)."""
    return dict(state, **{f: state[f][:, :rows] for f, rows in _stage_rows(s).items()})


def slot_files(c) -> list:
    """[(file name, lo, hi)] of the slabs a checkpoint slot links to ([] for a slot held in the file)."""
    return [tuple(x) for x in json.loads(c.attrs.get("slabs", "[]"))]


def _slot_fields(c, shapes, slabs=None, prefix=""):
    """Recreate a slot's state datasets: in the file (``slabs`` None: chunked, never written, so
    they read as zeros and take no space) or as virtual datasets over the per-rank slab files
    ``prefix/<name>`` [(name, lo, hi)]; the slot's step is −1 throughout (the caller's protocol)."""
    for field, (shape, dtype) in shapes.items():
        if field in c:
            del c[field]
        if slabs is None:
            c.create_dataset(field, shape=shape, dtype=dtype, chunks=True, fletcher32=True)
            continue
        _virtual(c, field, shape, dtype, [(f"{prefix}/{name}", lo, hi) for name, lo, hi in slabs])
    if slabs is None:
        if "slabs" in c.attrs:
            del c.attrs["slabs"]
    else:
        c.attrs["slabs"] = json.dumps([list(x) for x in slabs])


def _virtual(c, field, shape, dtype, sources):
    """A virtual dataset ``c/field`` whose rows lo:hi are dataset ``field`` of file ``path`` for each
    (path, lo, hi) of ``sources``, zeros elsewhere.  HDF5's own calls: h5py's VirtualLayout costs
    about 2.6× as much in Python (0.54 against 0.21 s for 1,024 slabs × 12 fields)."""
    from h5py import h5d, h5p, h5s, h5t
    dtype = np.dtype(dtype)
    dcpl = h5p.create(h5p.DATASET_CREATE)
    dcpl.set_fill_value(np.zeros((), dtype))
    vspace, rest = h5s.create_simple(shape), tuple(shape[1:])
    for path, lo, hi in sources:
        vspace.select_hyperslab((lo,) + (0,) * len(rest), (hi - lo,) + rest)
        dcpl.set_virtual(vspace, path.encode(), field.encode(), h5s.create_simple((hi - lo,) + rest))
    h5d.create(c.id, field.encode(), h5t.py_create(dtype), h5s.create_simple(shape), dcpl=dcpl).close()


def _shapes(c):
    return {field: (c[field].shape, c[field].dtype) for field in STATE_FIELDS}


def _remove_slabs(folder, slabs):
    for name, _, _ in slabs:
        try:
            (folder / name).unlink()
        except OSError:
            pass


def link_checkpoint(f, g, step, slabs, folder):
    """The per-rank checkpoint at ``step``: the older slot becomes virtual datasets over every rank's
    slab file (already written and closed), with the same protocol as :func:`write_checkpoint`:
    invalidate, link, flush, validate, flush.  The slabs the slot linked before are then removed."""
    slots = [g["checkpoint/a"], g["checkpoint/b"]]
    steps = [int(s["step"][()]) for s in slots]
    c = slots[0] if steps[0] <= steps[1] else slots[1]
    old = slot_files(c)
    c["step"][()] = -1
    f.flush()
    _slot_fields(c, _shapes(c), sorted(slabs, key=lambda x: x[1]), folder.name)
    f.flush()
    c["step"][()] = step
    f.flush()
    _remove_slabs(folder, old)


def prune_slabs(f, path, token):
    """Remove the slab files beside ``path`` that no checkpoint slot of ``f`` links to, except this
    run's own (``token``: written, perhaps not linked yet): what a stopped run or a replaced file left."""
    folder = state_dir(path)
    if not folder.is_dir():
        return
    linked = {name for g in f["runs"].values() for slot in ("a", "b") for name, _, _ in slot_files(g[f"checkpoint/{slot}"])}
    for p in folder.glob("*.h5"):
        parts = p.name.split(".")
        if p.name not in linked and not (len(parts) > 3 and parts[-3] == token):
            try:
                p.unlink()
            except OSError:
                pass


def read_checkpoint(g):
    """(step, state) of the newest valid slot, or (None, None).  A slot of per-rank slabs is read
    from the slab files themselves (beside the file), not through its virtual datasets, which
    would read a missing slab as zeros."""
    best = None
    for slot in ("a", "b"):
        c = g[f"checkpoint/{slot}"]
        step = int(c["step"][()])
        if step >= 0 and (best is None or step > best[0]):
            best = (step, c)
    if best is None:
        return None, None
    step, c = best
    slabs = slot_files(c)
    if not slabs:
        return step, {name: c[name][...] for name in STATE_FIELDS}
    folder = state_dir(g.file.filename)
    state = {name: np.empty(c[name].shape, c[name].dtype) for name in STATE_FIELDS}
    for name, lo, hi in slabs:
        try:
            with h5py.File(folder / name, "r") as s:
                for field in STATE_FIELDS:
                    state[field][lo:hi] = s[field][...]
        except (OSError, KeyError, ValueError) as exc:
            raise DamagedFile(f"cannot read the checkpoint slab '{folder.name}/{name}' of {g.name} "
                              f"({plain_error(exc)}); it cannot be resumed (start again with --force)") from None
    return step, state


def truncate(g, n_rows):
    """Drop output rows beyond n_rows (written after the checkpoint being resumed from)."""
    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.maxshape and obj.maxshape[0] is None and obj.shape[0] > n_rows:
            obj.resize(n_rows, axis=0)
    g.visititems(visit)


def settle_checkpoint(g, folder=None):
    """Put a finished pair's final state in slot a and empty slot b (step −1, zeros), whichever slot
    was written last.  Which states were written on the way depends on wall time (how fast the
    outputs came); the finished file does not, so it is bitwise the same for any rank count (with
    per-rank checkpoints its values are; the links name the ranks' slabs).  At every moment one
    valid slot holds the final state."""
    a, b, f = g["checkpoint/a"], g["checkpoint/b"], g.file
    folder = folder or state_dir(f.filename)
    shapes, before = _shapes(a), slot_files(a) + slot_files(b)
    if int(b["step"][()]) > int(a["step"][()]):
        a["step"][()] = -1
        f.flush()
        if slot_files(b):                 # per-rank slabs: the links move, not the bytes
            _slot_fields(a, shapes, slot_files(b), folder.name)
        else:
            if slot_files(a):             # (a resumed in-file: slot a in the file again)
                _slot_fields(a, shapes)
            for name in STATE_FIELDS:
                a[name][...] = b[name][...]
        f.flush()
        a["step"][()] = int(b["step"][()])
        f.flush()
    b["step"][()] = -1
    f.flush()
    if slot_files(b) or any(b[name].id.get_storage_size() > 0 for name in STATE_FIELDS):
        _slot_fields(b, shapes)          # made anew, never written (zeros, no bytes written): assigning
        f.flush()                        # 0 would broadcast row by row (16 s for 10⁵ points)
    kept = set(slot_files(a))             # the slabs no slot links any more go
    _remove_slabs(folder, [x for x in before if x not in kept])
