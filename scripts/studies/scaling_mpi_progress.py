"""Does MPI deliver a large message while its sender is busy outside MPI?

    .venv/bin/mpiexec -n 2 .venv/bin/python scripts/studies/scaling_mpi_progress.py

Rank 1 posts a non-blocking send of a pickled 20 MB array and then computes for 2 s without calling
MPI; rank 0 starts receiving after 0.5 s.  If the receive ends near 0.5 s, the MPI library moves the
message without the sender's help, and the driver's non-blocking hand-offs (integrators/service/driver.py,
_Stream) need no progress calls inside the advance; if it ends near 2 s, they would.
"""
import time

import numpy as np
from mpi4py import MPI


def busy(seconds):
    t = time.perf_counter()
    while time.perf_counter() - t < seconds:
        np.sum(np.ones(1000))


def main():
    comm = MPI.COMM_WORLD
    if comm.size != 2:
        raise SystemExit("run it on 2 ranks: mpiexec -n 2 python scripts/studies/scaling_mpi_progress.py")
    comm.Barrier()
    t0 = time.perf_counter()
    if comm.rank == 1:
        req = comm.isend(np.random.rand(2_500_000), dest=0, tag=3)
        busy(2.0)
        req.wait()
    else:
        busy(0.5)
        t1 = time.perf_counter()
        x = comm.recv(source=1, tag=3)
        library = " ".join(MPI.Get_library_version().splitlines()[0].split())
        print(f"{library}: {x.nbytes / 1e6:.0f} MB received "
              f"{time.perf_counter() - t0:.3f} s after the send was posted (the receive took "
              f"{time.perf_counter() - t1:.3f} s; the sender was busy outside MPI until 2 s)")


if __name__ == "__main__":
    main()
