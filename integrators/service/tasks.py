"""Tasks: what is computed for an output, and which rank computes it.

Each rank keeps, at every output, its points' errors (:meth:`Diagnostics.point_errors`) and its
part of each sample set (q, p, λ, live): an :class:`Output`.  The outputs of a batch go together
(:class:`Batch`).  A set's invariants in every form are one rank's task for a batch, given when the
batch closes (:meth:`Tasks.assign`) to the rank that has been given the least task work so far,
the costliest set first, by the cost estimates of :data:`diagnostics.COST_PER_POINT` × the set's
points × the batch's outputs.  Every rank closes the same batches in the same order with the same
sizes, so every rank makes the same assignment without a message.  The owner gathers the set's
parts from every rank and computes its values (:meth:`Tasks.run`); a set that refines itself
stays on one rank for a pair and takes the coarsest level that resolves it
(integrators.service.refine).  A task is the same function of the same points on any rank, so no
bit depends on who computes it.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .diagnostics import COST_PER_POINT, assign_sets
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
    index: int = 0                  # its place among the run's batches
    owners: dict = dataclasses.field(default_factory=dict)   # {(invariant, form): rank} (Tasks.assign)


class Tasks:
    """The scene's invariant tasks on ``size`` ranks: who takes which set in which batch, and the
    computation itself."""

    def __init__(self, scene, size, threshold):
        self.scene, self.size, self.threshold = scene, size, threshold
        self.first = assign_sets(scene, size)          # a refining set's rank in the run's first pair
        self.refining = {spec.invariant for spec, _ in scene.sample_sets if spec.levels}
        self.order = {p.name: k for k, p in enumerate(scene.pairs)}
        self.cost = {spec.invariant: sum(COST_PER_POINT[(spec.invariant, f)] for f in scene.forms) * spec.count
                     for spec, _ in scene.sample_sets}  # one output's task, in the estimates' units
        self.load = np.zeros(size)                       # task work given to each rank so far

    def assign(self, outputs, pair=0) -> dict:
        """{(invariant, form): rank} of the next batch, of ``outputs`` outputs of the run's
        ``pair``-th pair: each set, the costliest first, to the rank given the least task work so
        far (the lowest on a tie), its work added.  So the largest task bounds how late a batch's
        values come, not how many outputs a second the ranks get through, and batches of unequal
        size do not pile the large set on some ranks (turning the owners by batch index did: with
        two batches a pair, a big and a small one, the big ones' surface tasks went to every other
        rank; docs/scaling.md, "Distributed output").  A set that refines itself stays on one
        rank for the whole pair, turning by one rank a pair: its new points are advanced by the
        rank that takes its tasks (integrators.service.refine), once a pair rather than once per
        rank.  Called once per batch, in the same order on every rank."""
        own = {}
        for inv in sorted(self.cost, key=lambda i: (-self.cost[i], i)):
            r = (self.first[(inv, self.scene.forms[0])] + pair) % self.size if inv in self.refining \
                else int(np.argmin(self.load))
            self.load[r] += self.cost[inv] * outputs
            own.update({(inv, f): r for f in self.scene.forms})
        return own

    def needs(self, owners):
        """{owner: [set index]} of a batch with ``owners``: which ranks need which sets' parts."""
        sets = list(enumerate(s for s, _ in self.scene.sample_sets))
        return {o: [i for i, spec in sets if any(owners[(spec.invariant, fm)] == o for fm in self.scene.forms)]
                for o in sorted(set(owners.values()))}

    def others(self, rank, owners):
        """The ranks whose parts of a batch with ``owners`` ``rank`` waits for (none unless it owns a task)."""
        return [r for r in range(self.size) if r != rank] if rank in self.needs(owners) else []

    def pair_index(self, pair):
        """The place of a pair (the driver's _Pair, or its name) in the scene's run order."""
        return self.order[getattr(pair, "name", pair)]

    def parts(self, block, st):
        """This rank's part of each sample set (copies of q, p, λ, live: the state moves on);
        ``block`` = (lo, hi), the rows it advances."""
        lo, hi = block
        q, p, Lam = st.nearest()             # (a double-double run's invariants: from its states rounded to double)
        mine = (q, p, Lam / self.scene.h, st.live)
        out = []
        for _, rows in self.scene.sample_sets:
            a, b = max(lo, rows.start), min(hi, rows.stop)
            out.append(tuple(np.array(x[max(a - lo, 0):max(b - lo, 0)]) for x in mine))
        return out

    @staticmethod
    def stack(held, s):
        """This rank's parts of set ``s`` over a batch's outputs ``held``, as the four arrays (q, p, λ,
        live) each with the outputs along a first axis: what goes to the set's owner.  A few large
        arrays travel 3-5× faster than four small ones an output (transport: mpi4py pkl5 sends
        large arrays as their own buffers; docs/scaling.md); the owner takes output i as
        ``a[i]`` of each, the same values."""
        return tuple(np.stack([x.parts[s][c] for x in held]) for c in range(4))

    def run(self, rank, batch, got):
        """The values of ``rank``'s tasks at each output of ``batch``: [{(invariant, form): (value,
        resolution, computed, all live)}], from ``got`` = {rank: {set: (q, p, λ, live) stacked over
        the batch's outputs}} of the other ranks (:meth:`stack`)."""
        scene, pair = self.scene, batch.pair
        values = [{} for _ in batch.held]
        own = batch.owners
        for s in self.needs(own).get(rank, []):
            spec = scene.sample_sets[s][0]
            forms = [fm for fm in scene.forms if own[(spec.invariant, fm)] == rank]
            for i, v in enumerate(values):
                parts = [tuple(a[i] for a in got[r][s]) if r != rank else batch.held[i].parts[s]
                         for r in range(self.size)]
                q, p, lam, live = (np.concatenate([x[c] for x in parts]) for c in range(4))
                shp = spec.grid + (q.shape[1],)
                args = (spec, forms, q.reshape(shp), p.reshape(shp), lam.reshape(shp))
                if spec.levels:       # a set that refines itself: the coarsest level that resolves it
                    v.update(refined_values(pair.diagnostics, pair.refiners[spec.name], *args,
                                            live.reshape(spec.grid), batch.held[i].step, self.threshold))
                else:
                    v.update(pair.diagnostics.set_values(*args, live))
        return values
