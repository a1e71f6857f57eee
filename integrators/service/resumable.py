"""What a run file allows a resume to continue: its scene, its tableaus, its pairs' rows and
checkpoints, checked before a byte is changed; and reopening it where each pair left off."""
from __future__ import annotations

import json
from typing import NamedTuple

import h5py
import numpy as np

from .files import BusyFile, DamagedFile, OutputError, check_size, is_lock_error, open_file, plain_error, size_limit
from .checkpoints import STATE_FIELDS, read_checkpoint, slot_files, state_dir, truncate
from .output import FINISHED, FORMAT, STATUSES

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


def read_input_digests(path) -> tuple:
    """What a run's input files were: ({label: Tableau.digest} of its tableau files ({} for none /
    older files), the sha256 of its equilibrium file or None)."""
    try:
        with open_file(path) as f:
            eq = f.attrs.get("equilibrium_sha256")
            return json.loads(f.attrs.get("tableau_digests", "{}")), (None if eq is None else str(eq))
    except (OSError, KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, (DamagedFile, BusyFile)):
            raise
        raise DamagedFile(f"'{path}' is damaged: cannot read its input files' digests ({plain_error(exc)})") from None


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

    for pair in scene.pairs:
        name = pair.name
        if name not in runs:
            raise damaged(f"the pair {name} is missing")
        g = runs[name]
        if str(g.attrs.get("status", "")) not in STATUSES:
            raise damaged(f"{g.name} has the status {g.attrs.get('status')!r}")
        older = [k for k in STATE_FIELDS if "checkpoint/a" in g and k not in g["checkpoint/a"]]
        if older and all(k in RESUME_BITS_FIELDS for k in older):
            raise DamagedFile(f"'{path}' was written by an earlier version, whose checkpoints do not note where "
                              f"Newton's factors were taken or what the predictor learnt ({', '.join(older)}): a resume "
                              "could not give the bits of "
                              "the run it continues. Its results read (poincare plot, read_run); to continue, start "
                              "again with --force")
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


# The checkpoint fields without which a resume cannot give the bits of the run it continues (where
# Newton's factors were taken, and what the stage predictor has learnt): a file that lacks only these
# was written by an earlier version, and is refused for resuming with that reason.
RESUME_BITS_FIELDS = ("have_lu", "jac_z", "jac_q", "jac_lam", "defects", "orders")


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


def reopen(path, scene):
    """The file of an interrupted or grown run (checked by :func:`check_resumable`), open for
    writing, with the scene now in force."""
    f = open_for_resume(path)
    f.attrs["scene"] = scene.text          # a grown run.steps is now the file's scene
    f.attrs["steps"] = scene.steps
    return f


class Job(NamedTuple):
    """What a pair has left to do: the step it starts at and the saved state it starts from (None:
    from the scene's points; on ranks other than 0, ``True`` where rank 0 holds a saved state)."""
    start: int
    state: object


def restart_pair(f, name, output_every, finished_too=False):
    """Where a pair starts: None (finished, and ``finished_too`` is False), Job(0, None) (from the
    start, rows cleared) or Job(step, state) of its checkpoint, with its row and the rows after it
    cleared (the driver takes the checkpoint's row again from the state: the same bits)."""
    g = f["runs"][name]
    step, state = read_checkpoint(g)
    if g.attrs["status"] in FINISHED and not finished_too:
        return None
    g.attrs["status"] = "pending"
    if step is None or step % output_every:      # (a state off the cadence, from an older version: start again)
        truncate(g, 0)
        g["breakdown_time"][...] = np.inf
        return Job(0, None)
    truncate(g, step // output_every)            # the checkpoint's own row is taken again from its state
    g["breakdown_time"][...] = state["breakdown_time"]   # as of the checkpoint: later rows are gone
    return Job(step, state)
