"""Writer: rank 0's side of the file during a run.

Rank 0 appends each batch's rows once every rank's pieces of it are here, in order, one flush a
batch; the breakdown times when they changed, the integrator state at a checkpoint (with
``output.checkpoints = "per-rank"``, the links to the slabs every rank wrote); and a pair's
status, growth laws and clocks once its last rows are written (integrators.service.output holds
the layout and the crash-safe checkpoint).  ``--force`` over an existing file writes beside it and
replaces it only once the first rows are written (:class:`Replacement`).
"""
from __future__ import annotations

import os
import time
from typing import NamedTuple

import numpy as np

from . import checkpoints, output, statuses


class Piece(NamedTuple):
    """One rank's part of one output: the maxima of its points' errors, its tasks' invariant values
    ({(invariant, form): …}), and its state piece (points, breakdown times, a checkpoint's state or
    ``slab``)."""
    errors: dict
    values: dict
    state: dict


class Pieces(NamedTuple):
    """What a rank sends rank 0 for a batch of outputs: a :class:`Piece` per output, its rates (pair
    name, point-steps a second) and, with a pair's last batch, its clocks."""
    rows: list
    rates: tuple
    clock: dict | None


def concat(parts):
    return {name: np.concatenate([p[name] for p in parts]) for name in parts[0] if name != "slab"}


class Writer:
    """Rank 0's writes of a run into the open file ``f``."""

    def __init__(self, f, scene, spent, after_output, timings, threshold, slabs=None):
        self.f, self.scene, self.spent, self.slabs = f, scene, spent, slabs
        self.after_output, self.timings, self.threshold = after_output, timings, threshold
        self.started = None                # --force: called once the first rows are written

    def write(self, b, batches):
        """The batch's rows from every rank's :class:`Piece` s at each output (``batches``: a list
        per rank), written together and flushed; the breakdown times when they changed, the state at
        a checkpoint."""
        scene, pair, t0 = self.scene, b.pair, time.perf_counter()
        rows = []
        for i, x in enumerate(b.held):
            parts = [r[i] for r in batches]
            values = {k: v for p in parts for k, v in p.values.items()}
            rows.append(pair.diagnostics.combine(x.step * scene.h, [p.errors for p in parts], values))
            for key, why in values.items():       # the first reason a set was under-resolved, kept
                if key[1] == "reason" and f"under_resolved_reason/{key[0]}" not in pair.g.attrs:
                    pair.g.attrs[f"under_resolved_reason/{key[0]}"] = why
            if scene.store_points:
                q = np.concatenate([p.state["q"] for p in parts])
                for spec, sl in scene.sample_sets:
                    rows[-1][f"points/{spec.name}"] = q[sl].reshape(spec.grid + (q.shape[1],))
        last = b.held[-1]
        full = concat([r[-1].state for r in batches])
        bt = full["breakdown_time"]
        changed = pair.breakdown_written is None or not np.array_equal(bt, pair.breakdown_written)
        t1 = time.perf_counter()
        output.wall_clock(pair.g, pair.wall())
        if self.slabs is None:
            output.write_rows(self.f, pair.g, last.step, rows, bt if changed else None,
                              full if last.checkpoint else None)
        else:                    # per-rank checkpoints: every rank has written its slab; link them
            output.write_rows(self.f, pair.g, last.step, rows, bt if changed else None)
            if last.checkpoint:
                checkpoints.link_checkpoint(self.f, pair.g, last.step,
                                       [x for r in batches for x in r[-1].state["slab"]], self.slabs)
        pair.breakdown_written = bt
        if self.started is not None:
            self.started()
            self.started = None
        self.spent.charge(pair.clock, "invariants", t1 - t0)
        self.spent.charge(pair.clock, "hdf5", time.perf_counter() - t1)
        if self.after_output is not None:
            for x in b.held:
                self.after_output(pair.name, x.step)

    def finish_pair(self, pair, clocks):
        """Once a pair's last rows are written: its status and growth laws, and its clocks (every
        rank's, for the cost model, scripts/studies/scaling_model.py); returns every rank's clock."""
        clock = pair.clock
        clocks = [dict(clock, points=pair.block[1] - pair.block[0])] + clocks
        clock["per_rank"] = clocks
        self.timings[pair.name] = clock
        output.wall_clock(pair.g, pair.wall())
        statuses.close_pair(pair.g, self.scene.n_outputs, self.threshold, self.slabs)
        self.f.flush()
        return clocks


class Replacement:
    """``--force`` over an existing file: the new run writes ``.NAME.PID.new`` beside it, which
    replaces the old file (an atomic rename) once its first rows are written; a run that stops
    before that removes its new file and leaves the old one as it was."""

    def __init__(self, path):
        self.path, self.new, self.done = path, path.with_name(f".{path.name}.{os.getpid()}.new"), False

    def commit(self):
        if not self.done:
            os.replace(self.new, self.path)
            self.done = True

    def abandon(self):
        if not self.done:
            try:
                os.remove(self.new)
            except OSError:
                pass


def close_quietly(f):
    """Flush and close ``f``, whatever fails (on the way out of a failed run)."""
    from .stop import critical
    with critical():
        try:
            f.flush()
        except Exception:
            pass
        try:
            f.close()
        except Exception:
            pass
