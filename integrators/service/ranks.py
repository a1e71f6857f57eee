"""Ranks and threads: the communicator, threads per rank, and the split of the points over the ranks.

A point's trajectory does not depend on its batch, so any split gives the same numbers; the split
only decides how long each rank takes to reach the next output.  The points are dealt to the ranks
in a fixed shuffled order (:func:`deal`), so that every rank holds a fair sample of the run's points
(loop and surface, easy and hard), and a rank's cost per point measured on one pair predicts its
share of the next.
"""
from __future__ import annotations

import os

import numpy as np

from ..engine import State


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


def deal(n, size) -> np.ndarray:
    """The order in which the n points are dealt out: rank r takes ``order[lo:hi]`` for its block
    (lo, hi) of :func:`_split` (sorted: :func:`owned`).  A fixed shuffle: contiguous blocks of the
    scene's points would give one rank the loop and the other only surface rows, and their costs per
    point differ from pair to pair by up to 40 % (measured on the paper scene), so a split sized on
    one pair's rates was off on the next.  The identity on one rank.  Made on rank 0 and broadcast,
    so that the ranks agree whatever their numpy."""
    if size == 1:
        return np.arange(n)
    return np.random.default_rng(20261123).permutation(n)


def owned(order, blocks) -> list:
    """[rank r's points, as increasing indices into the run's points] for the blocks of ``_split``."""
    return [np.sort(order[lo:hi]) for lo, hi in blocks]


def _split(n, size, offload=0.0, speed=None):
    """Blocks of n points, one per rank: [(lo, hi), ...], contiguous in the order of :func:`deal`.

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


def _resized(blocks, stats, outputs):
    """Rank 0 at a meeting of the ranks: the blocks for the next batch of ``outputs`` outputs, from
    each rank's (advance seconds per output, points, output-work seconds per output, seconds its
    last move of points took per point) since the last meeting, or ``blocks`` unchanged when the
    batch would gain less than twice what moving the points costs."""
    offload, speed = _balance([s[:3] for s in stats])
    if speed is None:
        return blocks
    new = _split(blocks[-1][1], len(blocks), offload, speed)
    c = np.array([adv / pts for adv, pts, *_ in stats])
    work = np.array([s[2] for s in stats])

    def finish(bl):
        return np.max(c * np.array([hi - lo for lo, hi in bl]) + work)

    moved = sum(abs(a[1] - b[1]) for a, b in zip(blocks[:-1], new[:-1]))     # points that change rank, at most
    cost = max(s[3] for s in stats) * (max(hi - lo for lo, hi in new) + moved)
    return new if (finish(blocks) - finish(new)) * outputs > 2 * cost else blocks


def move(comm, st, order, old, new, h):
    """Hand each point whose block changes from ``old`` to ``new`` (shares of the dealt ``order``) to
    its new rank, with its state; ``st`` takes this rank's new points, in increasing index order,
    which it returns.  Done only at an output, where the Newton factors were dropped: a point goes on
    from its state exactly as a resume from a checkpoint does, so no bit changes."""
    r = comm.rank
    mine = np.sort(order[old[r][0]:old[r][1]])
    fields = st.checkpoint()
    out = []
    for s, (lo, hi) in enumerate(new):
        a, b = max(lo, old[r][0]), min(hi, old[r][1])
        idx = np.sort(order[a:b]) if a < b else np.empty(0, np.int64)
        rows = np.searchsorted(mine, idx)
        out.append((idx, {k: v[rows] for k, v in fields.items()}) if s != r else None)
    got = comm.alltoall(out)
    a, b = max(new[r][0], old[r][0]), min(new[r][1], old[r][1])
    kept = np.sort(order[a:b]) if a < b else np.empty(0, np.int64)
    got[r] = (kept, {k: v[np.searchsorted(mine, kept)] for k, v in fields.items()})
    idx = np.concatenate([g[0] for g in got])
    at = np.argsort(idx, kind="stable")
    vars(st).update(vars(State.from_checkpoint({k: np.concatenate([g[1][k] for g in got])[at] for k in fields}, h)))
    return idx[at]


def default_threads(comm) -> int:
    """Threads per rank: the cores of this node shared among its ranks (MPICH's MPI_LOCALNRANKS, else
    every rank counts as local)."""
    local = int(os.environ.get("MPI_LOCALNRANKS", comm.size) or comm.size)
    return max(1, (os.cpu_count() or 1) // max(1, local))
