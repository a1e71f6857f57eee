"""HDF5 output of a batch run, written incrementally and crash-safe.

Layout (format ``poincare/2``)::

    /                       attrs: format, scene (TOML text), version, system, created,
                                   resolution_threshold (the monitor value above which a set is under-resolved),
                                   precision ("double", or "double-double": run.precision; the
                                   checkpoint's value arrays then have a last axis of 2, hi and lo,
                                   and the errors below are differences taken in double-double)
    /runs/<TABLEAU>-<projection>/
        t                   (n,)       output times
        I1/<form>, I2/<form> (n,)      invariants (only the forms asked for; I2 only with a surface)
        resolution/I1, resolution/I2 (n,)  resolution monitor of the loop / surface (largest over the forms)
        resolved/I1, resolved/I2     (n,)  1 where the set resolved its invariant (monitor ≤ threshold), else 0
        points_used/I1, points_used/I2 (n,) a set with refine_to: the points of the level its invariant
                                           was taken on (the coarsest that resolved it; integrators.service.refine);
                                           attrs: points (the scene's own), refine_to
        energy_error        (n,)       max over points of |H − H₀|/|H₀| (|H − H₀| where H₀ = 0: the
                                       root attributes energy_error, energy_absolute_points say so)
        momentum_error      (n,)       max over points of |P − P₀|
        constraint_error    (n,)       max over points of |p − ϑ(q)|
        breakdown_time      (npoints,) per point, inf = never (loop points first, then the surface row by row)
        points/loop, points/surface    (n, N, d), (n, nσ, nτ, d) only with run.store_points
        checkpoint/a, checkpoint/b     two alternating copies of the integrator state (see below; with
                                       per-rank checkpoints, virtual datasets over slab files beside the file)
        attrs: status, wall_time [s], under_resolved_from/I1, under_resolved_from/I2 (first output time at
               which the set was under-resolved; absent while it is resolved)

``status`` is written when a pair finishes and is one of (see :data:`STATUSES`)

    pending          not finished (still running, or killed: ``--resume`` continues it)
    ok               every point completed and every set stayed resolved
    under-resolved   every point completed, but a set stopped resolving its invariant at some output
    partial          some points broke down (their sets' invariants are NaN from then on)
    failed           every point broke down

Every dataset grows by one row per output; the driver appends the rows of about two seconds
of advancing together and flushes, so a run killed at any moment leaves a readable file with
every output up to the last flush.  Every chunked dataset carries HDF5's fletcher32 checksum, so damaged bytes
are reported on reading (:class:`DamagedFile`) instead of being plotted.  The file uses
HDF5's default (earliest) format: the newer superblock keeps "open for writing" flags that
a killed writer leaves set, after which plain readers refuse the file.

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

import dataclasses
import datetime
import errno
import json
import os
import re

import h5py
import numpy as np

from ..engine import CHECKPOINT_FIELDS

FORMAT = "poincare/2"
STATUSES = ("pending", "ok", "under-resolved", "partial", "failed")
FINISHED = ("ok", "under-resolved", "partial", "failed")
STATE_FIELDS = CHECKPOINT_FIELDS         # the engine's State defines the checkpoint schema


def pair_name(tableau, projection) -> str:
    """The group name of a (tableau, projection) pair: 'GLRK2-symmetric' (a step map: 'rk4-map')."""
    return f"{tableau}-{projection}"


def split_pair_name(name) -> tuple:
    """(tableau, projection) of a pair's group name (a tableau name may itself contain '-')."""
    tab, proj = name.rsplit("-", 1)
    return tab, proj


def relative_error(v) -> np.ndarray:
    """|I(t) − I(0)| / |I(0)| of a series of invariant values; NaN throughout when I(0) is not a
    finite non-zero number (the one definition of the invariant error: summaries, plots, audit)."""
    v = np.asarray(v, dtype=float)
    if v.size == 0 or not np.isfinite(v[0]) or v[0] == 0:
        return np.full_like(v, np.nan)
    with np.errstate(all="ignore"):
        return np.abs(v - v[0]) / abs(v[0])


class OutputError(OSError):
    """The output file could not be created or written (disk full, no permission, ...): one line."""


class DamagedFile(ValueError):
    """A run file whose metadata or data is damaged (failed checksum, missing groups)."""


class BusyFile(ValueError):
    """A run file that another process holds open for writing (HDF5's file lock)."""


def open_file(path, mode="r"):
    """h5py.File(path, mode) with one-line errors: a file locked by a run that is still writing it
    is :class:`BusyFile`, anything else that cannot be opened as HDF5 :class:`DamagedFile`."""
    if not os.path.exists(path):
        raise FileNotFoundError(f"'{path}' does not exist")
    try:
        return h5py.File(path, mode)
    except OSError as exc:
        if is_lock_error(exc):
            raise BusyFile(f"'{path}' is open for writing by another process (a run still going?): wait for it "
                           "to finish or stop it first") from None
        raise DamagedFile(f"cannot read '{path}': damaged or not an HDF5 run file ({plain_error(exc)})") from None


def is_lock_error(exc) -> bool:
    """Whether an error from opening an HDF5 file is its lock, held by another process (EAGAIN from
    HDF5's flock), and not a damaged file: HDF5's message for a bad superblock names the 'sblock'
    (a substring test for 'lock' once took a truncated file for a locked one)."""
    if isinstance(exc, BlockingIOError) or getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
        return True
    text = str(exc)
    return bool(re.search(r"unable to lock file|errno = (11|35)\b|Resource temporarily unavailable", text))


def check_size(ds, limit):
    """DamagedFile unless dataset ``ds`` claims at most ``limit`` bytes: damaged metadata can claim
    petabytes, and reading it would try to allocate them."""
    nbytes = ds.size * ds.dtype.itemsize if ds.shape is not None else 0
    if nbytes > limit:
        raise DamagedFile(f"'{ds.file.filename}' is damaged: {ds.name} claims {nbytes / 2**20:,.0f} MiB, more "
                          "than the file can hold")


def size_limit(path) -> int:
    """The most bytes a dataset of the run file ``path`` can hold: twice the file (a slot never written
    reads as zeros without taking space), and at least 16 MiB."""
    import os
    return max(2 * os.path.getsize(path), 1 << 24)


def plain_error(exc) -> str:
    """The useful part of an h5py/OS error: 'Permission denied', 'No space left on device', ..."""
    text = str(exc)
    m = re.search(r"error message = '([^']*)'", text)
    if m:
        return m.group(1)
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    m = re.search(r"\(([^()]*)\)\s*$", text)
    return m.group(1) if m else text


SPACE_MARGIN = 1 << 18      # bytes kept free beyond an output's own size (HDF5 metadata, chunk slack)


def available_bytes(path) -> float:
    """Bytes the run may still add to ``path``: the free space of its file system, and no more than
    the process's file-size limit (``ulimit -f``, which batch systems set) allows."""
    import os
    import resource
    import shutil
    from pathlib import Path
    path = Path(path)
    free = float(shutil.disk_usage(path.parent if str(path.parent) else ".").free)
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY:
        size = os.path.getsize(path) if path.exists() else 0
        free = min(free, float(soft - size))
    return free


def ensure_space(path, nbytes, where):
    """OutputError before writing when fewer than ``nbytes`` + SPACE_MARGIN bytes are available: HDF5
    reports a failed write only from object destructors (and may then crash), so the driver checks
    first and stops with the file intact up to its last output."""
    free = available_bytes(path)
    if free < nbytes + SPACE_MARGIN:
        held = f"the file holds every output up to {where}" if where else "the file holds no output yet"
        reason = (f"no space left ({free / 2**20:.2f} MiB available, the next output needs about "
                  f"{(nbytes + SPACE_MARGIN) / 2**20:.2f} MiB)")
        err = OutputError(f"{reason.replace('no space left', f'no space left for {str(path)!r}', 1)}; {held}: "
                          "free space, then run again with --resume")
        err.reason = reason
        raise err


def _series(g, name, dtype="f8"):
    return g.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(256,), fletcher32=True)


def create(path, scene, version, npoints, state_shapes, threshold):
    """Create the file with every group and dataset of the scene (OutputError in one line if it cannot)."""
    try:
        f = h5py.File(path, "x")          # never over a file another run made since it was checked
    except OSError as exc:
        if is_lock_error(exc) or isinstance(exc, FileExistsError) or os.path.exists(path):
            raise BusyFile(f"output '{path}' was just created by another process (two runs started at once?): "
                           "give each run its own -o") from None
        raise OutputError(f"cannot create output '{path}': {plain_error(exc)}") from None
    try:
        _layout(f, scene, version, npoints, state_shapes, threshold)
        f.flush()
    except OSError as exc:
        f.close()
        raise OutputError(f"cannot write output '{path}': {plain_error(exc)}") from None
    return f


def _layout(f, scene, version, npoints, state_shapes, threshold):
    f.attrs["format"] = FORMAT
    f.attrs["scene"] = scene.text
    f.attrs["steps"] = scene.steps          # run.steps in force (the command line may override the text)
    f.attrs["version"] = version
    f.attrs["system"] = scene.system_name
    f.attrs["precision"] = scene.precision        # the engine's numbers: "double" or "double-double"
    f.attrs["resolution_threshold"] = threshold
    f.attrs["created"] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    if scene.tableau_files:                 # a resume must find the same coefficients, not only the name
        f.attrs["tableau_digests"] = json.dumps({t: scene.tableau(t).digest for t in scene.tableau_files})
    runs = f.create_group("runs")
    for tab, proj in scene.pairs:
        g = runs.create_group(pair_name(tab, proj))
        g.attrs["status"] = "pending"
        g.attrs["wall_time"] = 0.0
        _series(g, "t")
        for spec, _ in scene.sample_sets:
            for form in scene.forms:
                _series(g, f"{spec.invariant}/{form}")
            _series(g, f"resolution/{spec.invariant}")
            _series(g, f"resolved/{spec.invariant}", "u1")
            if spec.levels:
                ds = _series(g, f"points_used/{spec.invariant}", "i8")
                ds.attrs["points"], ds.attrs["refine_to"] = spec.count, spec.refine_to
        for diag in scene.diagnostics:
            _series(g, f"{diag}_error")
        g.create_dataset("breakdown_time", data=np.full(npoints, np.inf), chunks=True, fletcher32=True)
        g.create_dataset("wall_clock", data=np.zeros(1))
        if scene.store_points:
            d = state_shapes["q"][0][1]
            for spec, _ in scene.sample_sets:
                shape = spec.grid + (d,)
                g.create_dataset(f"points/{spec.name}", shape=(0,) + shape, maxshape=(None,) + shape, dtype="f8",
                                 chunks=(1,) + shape, fletcher32=True)
        for slot in ("a", "b"):
            c = g.create_group(f"checkpoint/{slot}")
            c.create_dataset("step", data=np.array(-1, dtype=np.int64))
            for name in STATE_FIELDS:
                shape, dtype = state_shapes[name]
                c.create_dataset(name, shape=shape, dtype=dtype, chunks=True, fletcher32=True)


def append(g, rows: list):
    """Append output rows [{dataset path: value}, ...] (the same keys) to the pair group g."""
    for name in rows[0]:
        ds = g[name]
        n = ds.shape[0]
        ds.resize(n + len(rows), axis=0)
        ds[n:] = np.stack([np.asarray(r[name]) for r in rows]).astype(ds.dtype, copy=False)


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


def _pad_stages(state, s_max):
    Y = state["Y"]
    if Y.shape[1] < s_max:
        state = dict(state, Y=np.concatenate([Y, np.zeros((Y.shape[0], s_max - Y.shape[1], Y.shape[2]))], axis=1))
    return state


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


def read_scene_text(path):
    """(scene TOML, steps in force) stored in a run file (DamagedFile / BusyFile / ValueError in one line)."""
    try:
        with open_file(path) as f:
            if f.attrs.get("format") not in (FORMAT, "poincare/1"):
                raise ValueError(f"'{path}' is not a poincare run file")
            steps = f.attrs.get("steps")
            return str(f.attrs["scene"]), (None if steps is None else int(steps))
    except (FileNotFoundError, DamagedFile, BusyFile):
        raise
    except (OSError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise DamagedFile(f"cannot read '{path}': damaged or not an HDF5 run file ({plain_error(exc)})") from None


def read_tableau_digests(path) -> dict:
    """{label: Tableau.digest} of the tableau files a run was started with ({} for none / older files)."""
    try:
        with open_file(path) as f:
            return json.loads(f.attrs.get("tableau_digests", "{}"))
    except (OSError, KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, (DamagedFile, BusyFile)):
            raise
        raise DamagedFile(f"'{path}' is damaged: cannot read its tableau digests ({plain_error(exc)})") from None


def check_resumable(path, scene):
    """Read-only, before a resume opens ``path`` for writing: every pair of ``scene`` is there with
    its datasets of the shapes the scene gives, no dataset claims more than the file can hold,
    every checksum holds and the checkpoint slots are readable.  DamagedFile in one line, naming
    what is wrong; the file is not changed."""
    from ..engine import State
    limit = size_limit(path)
    with open_file(path) as f:
        try:
            runs = f["runs"]
            _check_pairs(f, runs, scene, limit, State)
        except DamagedFile:
            raise
        except Exception as exc:     # h5py raises KeyError, OSError, RuntimeError, ValueError on damaged metadata
            raise DamagedFile(f"'{path}' is damaged ({type(exc).__name__}: {plain_error(exc)}); it cannot be "
                              "resumed (start again with --force)") from None


def _check_pairs(f, runs, scene, limit, State):
    path = f.filename
    n, rows = scene.n_points, scene.n_outputs

    def damaged(what):
        return DamagedFile(f"'{path}' is damaged: {what}; it cannot be resumed (start again with --force)")

    for tab, proj in scene.pairs:
        name = pair_name(tab, proj)
        if name not in runs:
            raise damaged(f"the pair {name} is missing")
        g = runs[name]
        if str(g.attrs.get("status", "")) not in STATUSES:
            raise damaged(f"{g.name} has the status {g.attrs.get('status')!r}")
        lengths = set()

        def visit(key, obj):
            if not isinstance(obj, h5py.Dataset):
                return
            try:
                check_size(obj, limit)
            except DamagedFile as exc:
                raise DamagedFile(f"{exc}; it cannot be resumed (start again with --force)") from None
            try:
                obj[...]
            except (OSError, ValueError, RuntimeError, MemoryError) as exc:
                raise damaged(f"cannot read {obj.name} ({plain_error(exc)})") from None
            if obj.maxshape and obj.maxshape[0] is None:
                lengths.add(obj.shape[0])
        g.visititems(visit)
        if len(lengths) > 1 or (lengths and max(lengths) > rows):
            raise damaged(f"the series of {g.name} have {sorted(lengths)} rows (at most {rows})")
        if g["breakdown_time"].shape != (n,):
            raise damaged(f"{g.name}/breakdown_time has shape {g['breakdown_time'].shape}, not ({n},)")
        for slot in ("a", "b"):
            c = g[f"checkpoint/{slot}"]
            if c["step"].shape != ():
                raise damaged(f"{c.name}/step is not a number")
            if int(c["step"][()]) >= 0 and slot_files(c):
                folder = state_dir(path)
                gone = [name for name, _, _ in slot_files(c) if not (folder / name).is_file()]
                if gone:
                    raise DamagedFile(f"cannot resume '{path}': the checkpoint of {name} is in '{folder}', which "
                                      f"lacks {len(gone)} of its {len(slot_files(c))} slab files ({gone[0]}, …): "
                                      "a run file with per-rank checkpoints resumes only beside that folder "
                                      "(its results read without it)")
                for slab, lo, hi in slot_files(c):
                    try:
                        with h5py.File(folder / slab, "r") as sf:
                            if any(sf[field].shape[0] != hi - lo for field in STATE_FIELDS):
                                raise ValueError("its rows do not match the link")
                            for field in STATE_FIELDS:
                                sf[field][...]
                    except (OSError, KeyError, ValueError, RuntimeError) as exc:
                        raise damaged(f"the checkpoint slab '{folder.name}/{slab}' cannot be read "
                                      f"({plain_error(exc)})") from None
            for field, (shape, dtype) in State.schema(n, 1, 1).items():
                ds = c[field]
                if ds.shape[0] != n or ds.dtype != dtype:
                    raise damaged(f"{ds.name} has shape {ds.shape} and type {ds.dtype}")


def open_for_resume(path):
    """Reopen an interrupted run for writing; the caller has checked its scene."""
    try:
        f = h5py.File(path, "r+")
    except OSError as exc:
        if is_lock_error(exc):
            raise BusyFile(f"cannot resume '{path}': it is open for writing by another process (a run still "
                           "going?)") from None
        raise OutputError(f"cannot resume '{path}': {plain_error(exc)}") from None
    if f.attrs.get("format") != FORMAT:
        found = f.attrs.get("format")
        f.close()
        raise ValueError(f"cannot resume '{path}': format {found!r}, this version writes {FORMAT}")
    return f


def pair_summary(g, n_outputs, threshold):
    """(status, breakdowns, {'I1 form': max error over the resolved outputs}, unresolved) of one pair
    group, unresolved = {set: (first under-resolved t, under-resolved outputs, outputs)}; reading a
    damaged dataset raises DamagedFile naming it."""
    try:
        bt = g["breakdown_time"][...]
        t = g["t"][...]
        broke = int(np.isfinite(bt).sum())
        unresolved_from, errs = {}, {}
        for inv in ("I1", "I2"):
            if inv not in g:
                continue
            res = g[f"resolution/{inv}"][...]
            ok = (res <= threshold)           # NaN (a set with a broken point) is not resolved either
            if not broke and (~ok).any():
                unresolved_from[inv] = (float(t[np.flatnonzero(~ok)[0]]), int((~ok).sum()), int(ok.size))
            for form in g[inv]:
                v = g[inv][form][...]
                use = ok & np.isfinite(v)       # resolved, and not yet broken down (NaN from a breakdown on)
                use[:1] = False                 # the error at t = 0 is 0 by definition: it vouches for nothing
                e = relative_error(v)
                errs[f"{inv} {form}"] = float(np.max(e[use])) if use.any() and np.isfinite(e[use]).all() else np.nan
    except OSError as exc:
        raise DamagedFile(f"dataset in '{g.name}' is damaged ({plain_error(exc)})") from None
    complete = t.shape[0] == n_outputs
    if not complete:
        status = "pending"
    elif broke == bt.size:
        status = "failed"
    elif broke:
        status = "partial"
    elif unresolved_from:
        status = "under-resolved"
    else:
        status = "ok"
    return status, broke, errs, unresolved_from


def growth_laws(g, threshold):
    """{'I1 form' | 'I2 form' | 'energy' | …: GrowthLaw} of a pair's series (invariants.growth): each
    invariant's relative error over the outputs where its set was resolved and no point had broken
    down (the law of that prefix), each diagnostic's error as stored."""
    from invariants.growth import growth_law
    t = _read(g, "t")
    laws = {}
    for inv in ("I1", "I2"):
        if inv not in g:
            continue
        ok = _read(g, f"resolution/{inv}") <= threshold
        for form in g[inv]:
            e = relative_error(_read(g, f"{inv}/{form}"))
            laws[f"{inv} {form}"] = growth_law(t, np.where(ok, e, np.nan))
    for key in g:
        if key.endswith("_error"):
            laws[key[:-len("_error")]] = growth_law(t, _read(g, key))
    return laws


def write_laws(g, laws):
    """Each series dataset's attributes growth_law, growth_exponent (± growth_exponent_error) and
    growth_onset (the time from which the law holds)."""
    for key, law in laws.items():
        ds = g["/".join(key.split(" ")) if key.startswith("I") else f"{key}_error"]
        ds.attrs["growth_law"] = law.law
        ds.attrs["growth_exponent"] = law.exponent
        ds.attrs["growth_exponent_error"] = law.exponent_error
        ds.attrs["growth_onset"] = law.onset
        ds.attrs["growth_log_prefactor"] = law.log_prefactor    # log C of the fitted C·t^α (plots)


def set_status(g, status, unresolved_from):
    g.attrs["status"] = status
    for inv in ("I1", "I2"):
        key = f"under_resolved_from/{inv}"
        if inv in unresolved_from:
            g.attrs[key] = unresolved_from[inv][0]
        elif key in g.attrs:
            del g.attrs[key]


def reopen(path, scene):
    """The file of an interrupted or grown run (checked by :func:`check_resumable`), open for
    writing, with the scene now in force."""
    f = open_for_resume(path)
    f.attrs["scene"] = scene.text          # a grown run.steps is now the file's scene
    f.attrs["steps"] = scene.steps
    return f


def note_energy_scale(f, absolute, points):
    """Root attributes saying what ``energy_error`` measures: relative |H − H₀|/|H₀|, and absolute
    |H − H₀| at the ``absolute`` points where H₀ = 0 (diagnostics.energy_scale)."""
    f.attrs["energy_absolute_points"] = absolute
    f.attrs["energy_error"] = "max over live points of |H - H0|/|H0|" + (
        f"; |H - H0| (absolute) at the {absolute} of {points} points where H0 = 0" if absolute else "")


def pair_group(f, name):
    return f["runs"][name]


def wall_clock(g, value=None) -> float:
    """The pair's accumulated wall time [s] (over resumes); with ``value``, set it."""
    if value is not None:
        g["wall_clock"][0] = value
    return float(g["wall_clock"][0])


def restart_pair(f, name, output_every, finished_too=False):
    """Where a pair starts: None (finished, and ``finished_too`` is False), (0, None) (from the start,
    rows cleared) or (step, state) of its checkpoint, with its row and the rows after it cleared
    (the driver takes the checkpoint's row again from the state: the same bits)."""
    g = f["runs"][name]
    step, state = read_checkpoint(g)
    if g.attrs["status"] in FINISHED and not finished_too:
        return None
    g.attrs["status"] = "pending"
    if step is None or step % output_every:      # (a state off the cadence, from an older version: start again)
        truncate(g, 0)
        g["breakdown_time"][...] = np.inf
        return 0, None
    truncate(g, step // output_every)            # the checkpoint's own row is taken again from its state
    g["breakdown_time"][...] = state["breakdown_time"]   # as of the checkpoint: later rows are gone
    return step, state


def write_rows(f, g, step, rows, breakdown_time=None, state=None):
    """Append output rows (the last at ``step``) and flush; with ``breakdown_time`` (when it changed)
    the points' breakdown times, and with ``state`` the checkpoint of the full integrator state at
    ``step`` (stage arrays padded to the file's largest s).  Refuses, naming the last output
    written, when the disk cannot hold it."""
    need = sum(np.asarray(v).nbytes for row in rows for v in row.values())
    need += (0 if breakdown_time is None else breakdown_time.nbytes) + \
        (0 if state is None else sum(v.nbytes for v in state.values()))
    last = f"{g.name.rsplit('/', 1)[-1]} t = {g['t'][-1]:g}" if g["t"].shape[0] else None
    if last is None:                      # this pair has no rows yet: name the last pair that has
        names = list(f["runs"])
        done = [k for k in names if f["runs"][k]["t"].shape[0]]
        last = f"{done[-1]} t = {f['runs'][done[-1]]['t'][-1]:g}" if done else None
    ensure_space(f.filename, need, last)
    append(g, rows)
    if breakdown_time is not None:
        g["breakdown_time"][...] = breakdown_time
    if state is None:
        f.flush()
        return
    write_checkpoint(f, g, step, _pad_stages(state, g["checkpoint/a/Y"].shape[1]))


def close_pair(g, n_outputs, threshold, folder=None):
    """The pair's status from its rows (see :func:`pair_summary`), written; a finished pair's
    checkpoint slots settled (:func:`settle_checkpoint`)."""
    status, _, _, unresolved = pair_summary(g, n_outputs, threshold)
    set_status(g, status, unresolved)
    if status in FINISHED:
        write_laws(g, growth_laws(g, threshold))
        settle_checkpoint(g, folder)


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


def finish(path, names, n_outputs) -> list:
    """Write each pair's final status, wall_time and growth laws; [(name, status, breakdowns, errors,
    wall time, unresolved, (first breakdown time or None, points), laws, refined)] as :func:`pair_summary`,
    :func:`growth_laws` and :func:`refined` give them."""
    out = []
    with h5py.File(path, "r+") as f:
        threshold = float(f.attrs.get("resolution_threshold", np.inf))
        for name in names:
            g = f["runs"][name]
            status, broke, errs, unresolved = pair_summary(g, n_outputs, threshold)
            set_status(g, status, unresolved)
            laws = growth_laws(g, threshold)
            if status in FINISHED:
                write_laws(g, laws)
            wall = float(g["wall_clock"][0])
            g.attrs["wall_time"] = wall
            bt = g["breakdown_time"][...]
            first = float(bt[np.isfinite(bt)].min()) if broke else None
            out.append((name, status, broke, errs, wall, unresolved, (first, int(bt.size)), laws, refined(g)))
    return out


def refined(g) -> dict:
    """{'I1'|'I2': (first t on more points than the scene's, the scene's points, the most used)} of
    a pair's sets that refined themselves (``points_used``; its attribute ``points``: the scene's)."""
    out = {}
    for inv in g.get("points_used", {}):
        ds = g[f"points_used/{inv}"]
        used, t, base = ds[...], g["t"][...], int(ds.attrs["points"])
        n = min(used.size, t.size)
        more = np.flatnonzero(used[:n] > base)
        if more.size:
            out[inv] = (float(t[more[0]]), base, int(used[:n].max()))
    return out


@dataclasses.dataclass
class PairRun:
    """One (tableau, projection) pair of a run file, read into arrays (see :func:`read_run`).

    t : (n,) output times; ``I1``/``I2`` : {form: (n,) values} (empty without a loop / surface);
    ``resolution``/``resolved`` : {'I1'|'I2': (n,)} the sets' monitors and 0/1 flags;
    ``errors`` : {'energy'|'momentum'|'constraint': (n,)} max over live points; ``breakdown_time`` :
    (npoints,) inf where a point never broke down; ``points`` : {'loop'|'surface': array} when the scene
    stored them; ``status``, ``wall_time``; ``under_resolved_from`` : {'I1'|'I2': first t} of a set
    that was under-resolved; ``growth`` : {'I1 form'|'I2 form'|'energy'|…: (law, exponent, its error,
    onset, log prefactor)} of a finished pair (invariants.growth: the fitted law C·t^α holds from the
    onset; the datasets' growth_* attributes); ``points_used`` : {'I1'|'I2': (n,)} of a set with
    ``refine_to``, the points of the level each output's invariant was taken on.
    """

    name: str
    status: str
    wall_time: float
    t: np.ndarray
    I1: dict
    I2: dict
    resolution: dict
    resolved: dict
    errors: dict
    breakdown_time: np.ndarray
    points: dict
    under_resolved_from: dict = dataclasses.field(default_factory=dict)
    growth: dict = dataclasses.field(default_factory=dict)
    points_used: dict = dataclasses.field(default_factory=dict)

    def __repr__(self):
        t = f"t = {self.t[0]:g} … {self.t[-1]:g}" if self.t.size else "no outputs"
        forms = [f"{inv}: {', '.join(d)}" for inv, d in (("I1", self.I1), ("I2", self.I2)) if d]
        return (f"<PairRun {self.name}: {self.status}, {self.t.size} outputs ({t}), "
                f"{'; '.join(forms) or 'no invariants'}, {int(np.isfinite(self.breakdown_time).sum())} of "
                f"{self.breakdown_time.size} points broke down>")

    def relative_error(self, inv="I1", form="noncanonical"):
        """|I(t) − I(0)| / |I(0)| of one invariant ("I1" or "I2") and form (:func:`relative_error`);
        a ValueError names an invariant or form the run does not hold."""
        if inv not in ("I1", "I2"):
            raise ValueError(f"invariant {inv!r}: choose 'I1' (the loop's) or 'I2' (the surface's)")
        values = self.I1 if inv == "I1" else self.I2
        if form not in values:
            held = ", ".join(sorted(values)) or "none: the scene has no " + ("loop" if inv == "I1" else "surface")
            raise ValueError(f"{inv} form {form!r} is not in this run (it holds: {held})")
        return relative_error(values[form])

    def to_xarray(self, forms=None):
        """The pair as an ``xarray.Dataset`` over time ``t`` (and ``form``, ``point``): ``I1``, ``I2``
        (t, form); ``resolution_I1``, ``resolved_I1``, ``points_used_I1`` (a refining set), … (t);
        the diagnostics' ``energy_error``, …
        (t), each with its growth law in ``.attrs``; ``I1_growth_law``, ``I1_growth_exponent``, …
        (form); ``breakdown_time`` (point).  Attributes: pair, status, wall_time, under-resolved
        times.  ``ds.I2.sel(form="corrected").plot()`` draws a series."""
        import xarray as xr
        from invariants import FORMS
        forms = list(forms) if forms is not None else \
            [f for f in FORMS if f in self.I1 or f in self.I2] + \
            sorted({f for d in (self.I1, self.I2) for f in d} - set(FORMS))
        n = self.t.shape[0]
        data = {}
        for inv in ("I1", "I2"):
            d = getattr(self, inv)
            if not d:
                continue
            data[inv] = (("t", "form"), np.stack([np.asarray(d[f], float) if f in d else np.full(n, np.nan)
                                                  for f in forms], axis=1) if forms else np.zeros((n, 0)),
                         {"long_name": f"{inv} ({'loop' if inv == 'I1' else 'surface'})"})
            g = [self.growth.get(f"{inv} {f}") for f in forms]
            data[f"{inv}_growth_law"] = ("form", np.array([x[0] if x else "" for x in g], dtype=object))
            data[f"{inv}_growth_exponent"] = ("form", np.array([x[1] if x else np.nan for x in g]))
            data[f"{inv}_growth_onset"] = ("form", np.array([x[3] if x else np.nan for x in g]))
            if inv in self.resolution:
                data[f"resolution_{inv}"] = ("t", np.asarray(self.resolution[inv], float))
            if inv in self.resolved:
                data[f"resolved_{inv}"] = ("t", np.asarray(self.resolved[inv]))
            if inv in self.points_used:
                data[f"points_used_{inv}"] = ("t", np.asarray(self.points_used[inv]))
        for key, v in self.errors.items():
            attrs = {}
            if key in self.growth:
                law, a, da, onset, _ = self.growth[key]
                attrs = {"growth_law": law, "growth_exponent": a, "growth_exponent_error": da, "growth_onset": onset}
            data[f"{key}_error"] = ("t", np.asarray(v, float), attrs)
        data["breakdown_time"] = ("point", np.asarray(self.breakdown_time, float))
        attrs = {"pair": self.name, "status": self.status, "wall_time": self.wall_time}
        attrs.update({f"under_resolved_from_{k}": v for k, v in self.under_resolved_from.items()})
        return xr.Dataset(data, coords={"t": ("t", np.asarray(self.t, float)), "form": ("form", forms)},
                          attrs=attrs)

    def _repr_html_(self):
        return _html_table([self])


@dataclasses.dataclass
class Run:
    """A run file read whole: ``scene`` (the TOML text it ran), ``system`` (its name), ``format``,
    ``pairs`` {name: PairRun} by name; ``run['GLRK2-symmetric']`` is ``run.pairs[...]``."""

    path: str
    format: str
    system: str
    scene: str
    steps: int
    pairs: dict
    precision: str = "double"        # the engine's numbers (root attribute; files before it: double)

    def __getitem__(self, name):
        return self.pairs[name]

    def __repr__(self):
        counts = {}
        for p in self.pairs.values():
            counts[p.status] = counts.get(p.status, 0) + 1
        prec = "" if self.precision == "double" else f" in {self.precision}"
        return (f"<Run '{self.path}': {self.system}{prec}, {len(self.pairs)} pairs "
                f"({', '.join(f'{v} {k}' for k, v in counts.items())}), {self.steps} steps; "
                "run.pairs by name, run[name] one pair>")

    def to_xarray(self):
        """Every pair as one ``xarray.Dataset`` with a ``pair`` dimension (see
        :meth:`PairRun.to_xarray`; a pair still pending is NaN past its last output), plus
        ``status`` and ``wall_time`` per pair: ``ds.I2.sel(pair="GLRK2-symmetric", form="corrected")``."""
        import xarray as xr
        from invariants import FORMS
        forms = [f for f in FORMS if any(f in p.I1 or f in p.I2 for p in self.pairs.values())]
        forms += sorted({f for p in self.pairs.values() for d in (p.I1, p.I2) for f in d} - set(forms))
        tabs, projs = self.grid()
        order = [pair_name(t, q) for t in tabs for q in projs]
        names = [n for n in order if n in self.pairs] + [n for n in self.pairs if n not in order]
        parts = []
        for name, p in ((n, self.pairs[n]) for n in names):
            ds = p.to_xarray(forms)
            parts.append(ds.assign(status=((), p.status), wall_time=((), p.wall_time)).expand_dims(pair=[name]))
        if not parts:
            return xr.Dataset(attrs={"path": self.path, "system": self.system, "steps": self.steps,
                                     "precision": self.precision})
        ds = xr.concat(parts, dim="pair", join="outer", combine_attrs="drop_conflicts", data_vars="all",
                       coords="different", compat="equals")
        ds.attrs.update(path=self.path, system=self.system, steps=self.steps, format=self.format,
                        precision=self.precision)
        for key in ("pair", "status", "wall_time"):
            ds.attrs.pop(key, None)
        return ds

    def _repr_html_(self):
        prec = "" if self.precision == "double" else f" in {_esc(self.precision)}"
        return (f"<p><b>poincare run</b> <code>{_esc(self.path)}</code>: {_esc(self.system)}{prec}, {self.steps} steps, "
                f"{len(self.pairs)} pairs</p>" + _html_table(list(self.pairs.values())))

    def grid(self) -> tuple:
        """(tableaus, projections) in the scene's order (HDF5 lists the groups alphabetically); a
        user's step maps come last, under the projection 'map'."""
        try:
            from .scene import parse_scene
            sc = parse_scene(self.scene)
            maps = [t for t, p in sc.pairs if p == "map"]
            return list(sc.tableaus) + maps, list(sc.projections) + (["map"] if maps else [])
        except ValueError:                 # the scene no longer parses here (a user file moved): by name
            tabs, projs = [], []
            for name in self.pairs:
                t, p = split_pair_name(name)
                tabs += [t] if t not in tabs else []
                projs += [p] if p not in projs else []
            return tabs, projs


def _esc(text):
    import html
    return html.escape(str(text))


def _html_table(pairs):
    """An HTML table of pairs: status, points broken down, and each series' largest error and law."""
    keys = []
    for p in pairs:
        for k in [f"{inv} {f}" for inv in ("I1", "I2") for f in getattr(p, inv)] + list(p.errors):
            if k not in keys:
                keys.append(k)
    head = "".join(f"<th>{_esc(k)}</th>" for k in keys)
    rows = []
    for p in pairs:
        cells = []
        for k in keys:
            if k.startswith("I"):
                inv, form = k.split(" ", 1)
                v = getattr(p, inv).get(form)
                e = relative_error(v) if v is not None and len(v) else None
            else:
                e = p.errors.get(k)
            big = float(np.nanmax(e)) if e is not None and len(e) and np.isfinite(e).any() else None
            law = p.growth.get(k, ("",))[0]
            cells.append(f"<td>{'—' if big is None else f'{big:.2e}'}<br><small>{_esc(law)}</small></td>")
        broke = int(np.isfinite(p.breakdown_time).sum())
        rows.append(f"<tr><td><b>{_esc(p.name)}</b></td><td>{_esc(p.status)}</td><td>{broke}</td>"
                    + "".join(cells) + "</tr>")
    return ("<table><tr><th>pair</th><th>status</th><th>broke</th>" + head + "</tr>" + "".join(rows) + "</table>"
            "<p><small>largest |I(t) − I(0)|/|I(0)| (all outputs) and diagnostic errors, with their growth laws"
            "</small></p>")


def _read(g, name, limit=None):
    """A dataset's values; a failed checksum, a missing dataset or one that claims more bytes than
    ``limit`` is a DamagedFile naming it."""
    try:
        ds = g[name]
        if limit is not None:
            check_size(ds, limit)
        return ds[...]
    except DamagedFile:
        raise
    except (OSError, KeyError, ValueError, RuntimeError, MemoryError) as exc:
        raise DamagedFile(f"'{g.file.filename}' is damaged: cannot read {g.name}/{name} "
                          f"({plain_error(exc)})") from None


def _growth_attrs(g):
    out = {}
    for key in [f"{inv}/{form}" for inv in ("I1", "I2") if inv in g for form in g[inv]] + \
            [k for k in g if k.endswith("_error")]:
        a = g[key].attrs
        if "growth_law" in a:
            name = key.replace("/", " ") if key.startswith("I") else key[:-len("_error")]
            out[name] = (str(a["growth_law"]), float(a["growth_exponent"]), float(a["growth_exponent_error"]),
                         float(a["growth_onset"]), float(a.get("growth_log_prefactor", np.nan)))
    return out


def read_run(path) -> Run:
    """Read a ``poincare run`` file into arrays (the layout above; h5py underneath).

    A damaged dataset (failed checksum) or a file that is not a run file is one :class:`DamagedFile`
    naming it.  Pairs still ``pending`` are read as far as they got.
    """
    limit = size_limit(path) if os.path.exists(path) else 0
    try:
        with open_file(path) as f:
            fmt = f.attrs.get("format")
            if fmt not in (FORMAT, "poincare/1"):
                raise DamagedFile(f"'{path}' is not a poincare run file")
            pairs = {}
            for name, g in f["runs"].items():
                def sets(key):
                    return {k: _read(g, f"{key}/{k}", limit) for k in g[key]} if key in g else {}
                pairs[name] = PairRun(
                    name=name, status=str(g.attrs.get("status", "pending")),
                    wall_time=float(_read(g, "wall_clock", limit)[0]), t=_read(g, "t", limit), I1=sets("I1"), I2=sets("I2"),
                    resolution=sets("resolution"), resolved=sets("resolved"),
                    errors={k[:-len("_error")]: _read(g, k, limit) for k in g if k.endswith("_error")},
                    breakdown_time=_read(g, "breakdown_time", limit), points=sets("points"),
                    under_resolved_from={k.split("/")[1]: float(v) for k, v in g.attrs.items()
                                         if k.startswith("under_resolved_from/")},
                    growth=_growth_attrs(g), points_used=sets("points_used"))
            return Run(path=str(path), format=str(fmt), system=str(f.attrs.get("system", "")),
                       scene=str(f.attrs.get("scene", "")), steps=int(f.attrs.get("steps", 0)), pairs=pairs,
                       precision=str(f.attrs.get("precision", "double")))
    except (DamagedFile, BusyFile, FileNotFoundError):
        raise
    except (OSError, KeyError, ValueError, RuntimeError, TypeError, MemoryError, AttributeError) as exc:
        # (damaged metadata: h5py may hand back None for a group whose header it cannot read)
        raise DamagedFile(f"cannot read '{path}': damaged or not a poincare run file "
                          f"({type(exc).__name__}: {plain_error(exc)})") from None
