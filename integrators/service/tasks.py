"""Tasks: what is computed for an output, and which rank computes it.

Each rank keeps, at every output, its points' errors (:meth:`Diagnostics.point_errors`) and its
part of each sample set (q, p, λ, live): an :class:`Output`.  The outputs of a batch go together
(:class:`Batch`).  A set's invariants in every form are one rank's task for a batch: the
assignment (:func:`integrators.service.diagnostics.assign_sets`) turned by one rank a batch
(:meth:`Tasks.owners`), so over any R consecutive batches every rank takes every set once.  The
owner gathers the set's parts from every rank and computes its values (:meth:`Tasks.run`); a set
that refines itself takes the coarsest level that resolves it (integrators.service.refine).  A task
is the same function of the same points on any rank, so no bit depends on who computes it.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from . import output
from .diagnostics import assign_sets
from .refine import refined_values


@dataclasses.dataclass
class Output:
    """What a rank keeps of one output until its batch's tasks have run: its points' errors, its
    part of each sample set (q, p, λ, live), and what rank 0 writes of its points."""

    step: int
    checkpoint: bool
    errors: dict
    parts: list
    piece: dict


@dataclasses.dataclass
class Batch:
    pair: object                    # the driver's _Pair
    held: list                      # an Output per output
    last: bool                      # the pair's last batch
    index: int = 0                  # its place among the run's batches (whose turn each task is)


class Tasks:
    """The scene's invariant tasks on ``size`` ranks: who takes which set in which batch, and the
    computation itself."""

    def __init__(self, scene, size, threshold):
        self.scene, self.size, self.threshold = scene, size, threshold
        self.assignment = assign_sets(scene, size)
        self.refining = {spec.invariant for spec, _ in scene.sample_sets if spec.levels}
        self.order = {output.pair_name(t, p): k for k, (t, p) in enumerate(scene.pairs)}

    def owners(self, j, k=0):
        """{(invariant, form): rank} of batch ``j`` of the run's ``k``-th pair: the assignment
        (:func:`assign_sets`: a set's forms on one rank, longest set first to the least loaded)
        turned by j ranks, so that over any R consecutive batches every rank runs every task once:
        the largest task bounds how late a batch's values come, not how many outputs a second the
        ranks get through (docs/benchmarks.md, "Distributed output").  A set that refines itself
        turns by pair instead (k ranks): its new points are advanced by the rank that takes its
        tasks (integrators.service.refine), once a pair rather than once per rank."""
        return {key: (r + (k if key[0] in self.refining else j)) % self.size for key, r in self.assignment.items()}

    def needs(self, j, k=0):
        """{owner: [set index]} of batch ``j`` of the ``k``-th pair: which ranks need which sets' parts."""
        own = self.owners(j, k)
        sets = list(enumerate(s for s, _ in self.scene.sample_sets))
        return {o: [i for i, spec in sets if any(own[(spec.invariant, fm)] == o for fm in self.scene.forms)]
                for o in sorted(set(own.values()))}

    def others(self, rank, j, k=0):
        """The ranks whose parts of batch ``j`` (of the ``k``-th pair) ``rank`` waits for (none
        unless it owns a task)."""
        return [r for r in range(self.size) if r != rank] if rank in self.needs(j, k) else []

    def of(self, batch):
        """(batch index, pair index) of a :class:`Batch`: what the rotation turns by."""
        return batch.index, self.order[batch.pair.name]

    def parts(self, block, st):
        """This rank's part of each sample set (copies of q, p, λ, live: the state moves on);
        ``block`` = (lo, hi), the rows it advances."""
        lo, hi = block
        mine = (st.q, st.p, st.Lam / self.scene.h, st.live)
        out = []
        for _, rows in self.scene.sample_sets:
            a, b = max(lo, rows.start), min(hi, rows.stop)
            out.append(tuple(np.array(x[max(a - lo, 0):max(b - lo, 0)]) for x in mine))
        return out

    def run(self, rank, batch, got):
        """The values of ``rank``'s tasks at each output of ``batch``: [{(invariant, form): (value,
        resolution, computed, all live)}], from ``got`` = {rank: parts[set][output]} of the other ranks."""
        scene, pair = self.scene, batch.pair
        j, k = self.of(batch)
        values = [{} for _ in batch.held]
        own = self.owners(j, k)
        for s in self.needs(j, k).get(rank, []):
            spec = scene.sample_sets[s][0]
            forms = [fm for fm in scene.forms if own[(spec.invariant, fm)] == rank]
            for i, v in enumerate(values):
                parts = [got[r][s][i] if r != rank else batch.held[i].parts[s] for r in range(self.size)]
                q, p, lam, live = (np.concatenate([x[c] for x in parts]) for c in range(4))
                shp = spec.grid + (q.shape[1],)
                args = (spec, forms, q.reshape(shp), p.reshape(shp), lam.reshape(shp))
                if spec.levels:       # a set that refines itself: the coarsest level that resolves it
                    v.update(refined_values(pair.diagnostics, pair.refiners[spec.name], *args,
                                            live.reshape(spec.grid), batch.held[i].step, self.threshold))
                else:
                    v.update(pair.diagnostics.set_values(*args, live))
        return values
