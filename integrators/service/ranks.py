"""Ranks and threads: the communicator, threads per rank, and the split of the points over the ranks.

A point's trajectory does not depend on its batch, so any split gives the same numbers; the split
only decides how long each rank takes to reach the next output.
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


def _split(n, size, offload=0.0, speed=None):
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


def _balance(stats):
    """(offload, speed) for the next pair's ``_split`` from this pair's per-rank (advance seconds,
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
