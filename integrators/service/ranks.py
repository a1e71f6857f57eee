"""Ranks and balance: the communicator, threads per rank, and who advances which points.

A point's trajectory does not depend on its batch, so any split gives the same numbers; the split
only decides how long each rank takes to reach the next output.  The first pair is split evenly;
each later one by the ranks' measured rates on the pair before it (:func:`balance`,
:func:`split`), planned by rank 0 from about the middle of that pair and sent without a meeting
(:class:`Planner`).
"""
from __future__ import annotations

import os

import numpy as np


class _Serial:
    """The part of an MPI communicator the driver uses, for one process."""

    rank, size = 0, 1

    def gather(self, obj, root=0):
        return [obj]

    def bcast(self, obj, root=0):
        return obj

    def scatter(self, objs, root=0):
        return objs[0]

    def Barrier(self):
        pass


def communicator():
    """MPI.COMM_WORLD when running under mpiexec with more than one rank, else a serial stand-in."""
    if not any(k in os.environ for k in ("PMI_RANK", "PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "HYDRA_CONTROL_FD",
                                         "PMI_FD", "MPI_LOCALNRANKS")):
        return _Serial()
    try:
        from mpi4py import MPI
    except ImportError:
        return _Serial()
    comm = MPI.COMM_WORLD
    return comm if comm.Get_size() > 1 else _Serial()


def split(n, size, offload=0.0, speed=None):
    """Contiguous blocks of n points, one per rank: [(lo, hi), ...].

    Besides advancing its points, each rank has output work at every output: its share of the
    invariant tasks and of the per-point diagnostics, and on rank 0 the HDF5 write.  With
    ``speed[r]`` rank r's points per second (measured on the previous pair; equal if None) and
    ``offload[r]`` its output work in its own points' worth (S_r/c_r; a scalar is rank 0's alone),
    every rank reaches the next output at the same time T: c_r·n_r + S_r = T with Σ n_r = n, i.e.
    n_r = (n + Σ offload)·speed[r]/Σ speed − offload[r].  No block drops below a quarter of an even
    share, and no rank's speed counts as more than twice or less than half the median (a noisy
    pair must not starve a rank).  Any split gives the same numbers: a point's trajectory does not
    depend on its batch.
    """
    if size == 1:
        return [(0, n)]
    w = np.ones(size) if speed is None else np.asarray(speed, dtype=float)
    if w.shape != (size,) or not np.all(np.isfinite(w) & (w > 0)):
        w = np.ones(size)
    w = np.clip(w, np.median(w) / 2, np.median(w) * 2)     # one noisy measurement must not starve a rank
    w = w / w.sum()
    off = np.zeros(size)
    if np.ndim(offload) == 0:
        off[0] = float(offload)
    elif np.shape(offload) == (size,):
        off = np.asarray(offload, dtype=float)
    off = np.where(np.isfinite(off) & (off > 0), off, 0.0)
    x = (n + off.sum()) * w - off
    floor = n / (4 * size)
    fixed = np.zeros(size, dtype=bool)
    while True:                               # ranks pushed below the floor get the floor; the rest share what is left
        low = ~fixed & (x < floor)
        if not low.any():
            break
        fixed |= low
        x[fixed] = floor
        free = ~fixed
        x[free] = (x[free] / x[free].sum() * (n - floor * fixed.sum())) if free.any() else x[free]
    bounds = np.concatenate([[0.0], np.cumsum(x)]).round().astype(int)
    bounds[-1] = n
    return [(int(bounds[k]), int(bounds[k + 1])) for k in range(size)]


def balance(stats):
    """(offload, speed) for the next pair's :func:`split` from this pair's per-rank (advance seconds,
    points, output-work seconds)."""
    speed = np.array([pts / adv if adv > 0 and pts > 0 else np.nan for adv, pts, _ in stats])
    if not np.all(np.isfinite(speed)):
        return 0.0, None
    offload = np.array([work * v for (_, _, work), v in zip(stats, speed)])
    return offload, speed.tolist()


def default_threads(comm) -> int:
    """Threads per rank: the cores of this node shared among its ranks (MPICH's MPI_LOCALNRANKS, else
    every rank counts as local)."""
    local = int(os.environ.get("MPI_LOCALNRANKS", comm.size) or comm.size)
    return max(1, (os.cpu_count() or 1) // max(1, local))


class Planner:
    """Rank 0's plan of the next pair, (blocks, batch, cadence), sent to every rank without waiting
    once past the running pair's middle with every rank's rates on it (at its last batch in any
    case).  The blocks follow those rates (:func:`split`), else the latest finished pair's."""

    def __init__(self, size):
        self.size = size
        self.balance = (0.0, None)     # (offload, speed) of the latest pair with every rank's clocks
        self.plan = None
        self.next_pair = None          # (points, batch, cadence) of the next pair, until its plan is sent
        self.rates = {}                # {rank: (pair name, rates)}: the latest each rank sent

    def maybe_send(self, pair, middle, step, last, own_rates, transport):
        """Send the next pair's plan if it is due (``own_rates``: a callable giving rank 0's rates)."""
        from .transport import PLAN
        if self.next_pair is None or step < middle:
            return
        sent = (self.rates.get(r, (None, None)) for r in range(1, self.size))
        rates = [own_rates()] + [x for name, x in sent if name == pair]
        if len(rates) < self.size and not last:
            return
        n, batch, cadence = self.next_pair
        bal = balance(rates) if len(rates) == self.size else (0.0, None)
        bal = bal if bal[1] is not None else self.balance
        self.plan, self.next_pair = (split(n, self.size, *bal), batch, cadence), None
        for r in range(1, self.size):
            transport.send(self.plan, r, PLAN)

    def after_pair(self, clocks):
        """A finished pair's clocks (every rank's): the balance to fall back on."""
        self.balance = balance([(c["advance"], c["points"], c["invariants"] + c["hdf5"]) for c in clocks])

    def receive(self, rank, transport):
        """This rank's copy of the plan for the pair it begins (waits only if rank 0 has not sent it)."""
        from .transport import PLAN
        return self.plan if rank == 0 else transport.receive(0, PLAN)
