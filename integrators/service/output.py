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
                                       (an invariant whose I(0) is zero within its error, a closed
                                       one-form's I₁: its error is |I − I(0)|, the root attribute
                                       absolute_invariants lists it, e.g. "I1/noncanonical")
        momentum_error      (n,)       max over points of |P − P₀|
        constraint_error    (n,)       max over points of |p − ϑ(q)|
        breakdown_time      (npoints,) per point, inf = never (loop points first, then the surface row by row)
        points/loop, points/surface    (n, N, d), (n, nσ, nτ, d) only with run.store_points
        checkpoint/a, checkpoint/b     two alternating copies of the integrator state (see below; with
                                       per-rank checkpoints, virtual datasets over slab files beside the file)
        attrs: status, wall_time [s], under_resolved_reason/I1, …/I2 (why a set was under-resolved where its
               spectrum cannot say: a wrapped coordinate without its period; absent otherwise),
               under_resolved_from/I1, under_resolved_from/I2 (first output time at
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

The other jobs of the file live beside this one, along the data path: the file and its errors
(:mod:`.files`), the integrator state (:mod:`.checkpoints`), what a resume may continue
(:mod:`.resumable`), a finished pair's status and growth laws (:mod:`.statuses`) and reading a run
back (:mod:`.reader`).
"""
from __future__ import annotations

import datetime
import json
import os

import h5py
import numpy as np

from .files import BusyFile, OutputError, ensure_space, is_lock_error, plain_error
from .checkpoints import STATE_FIELDS, _pad_stages, write_checkpoint

FORMAT = "poincare/2"


STATUSES = ("pending", "ok", "under-resolved", "partial", "failed")


FINISHED = ("ok", "under-resolved", "partial", "failed")


def pair_name(tableau, projection) -> str:
    """The group name of a (tableau, projection) pair: 'GLRK2-symmetric' (a step map: 'rk4-map')."""
    return f"{tableau}-{projection}"


def split_pair_name(name) -> tuple:
    """(tableau, projection) of a pair's group name (a tableau name may itself contain '-')."""
    tab, proj = name.rsplit("-", 1)
    return tab, proj


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
    if scene.system_spec.get("sha256"):     # ... and the same equilibrium file (docs/equilibria.md)
        f.attrs["equilibrium_sha256"] = scene.system_spec["sha256"]
    runs = f.create_group("runs")
    for pair in scene.pairs:
        g = runs.create_group(pair.name)
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


def note_energy_scale(f, absolute, points):
    """Root attributes saying what ``energy_error`` measures: relative |H − H₀|/|H₀|, and absolute
    |H − H₀| at the ``absolute`` points where H₀ = 0 (diagnostics.energy_scale)."""
    f.attrs["energy_absolute_points"] = absolute
    f.attrs["energy_error"] = "max over live points of |H - H0|/|H0|" + (
        f"; |H - H0| (absolute) at the {absolute} of {points} points where H0 = 0" if absolute else "")


def note_absolute_invariants(f, keys):
    """The root attribute ``absolute_invariants``: the invariants ('I1/form' …) whose I(0) is zero
    within its error, whose error is then |I(t) − I(0)| (statuses.relative_error)."""
    f.attrs["absolute_invariants"] = " ".join(sorted(keys))


def pair_group(f, name):
    return f["runs"][name]


def wall_clock(g, value=None) -> float:
    """The pair's accumulated wall time [s] (over resumes); with ``value``, set it."""
    if value is not None:
        g["wall_clock"][0] = value
    return float(g["wall_clock"][0])


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
