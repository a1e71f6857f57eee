"""Run a scene under mpiexec with the ranks' blocks re-sized to random sizes at every re-split point,
so that points move between ranks in the middle of every pair (tests/test_service.py compares the
file with a one-rank run, bit for bit).  Prints how many times points moved.

    mpiexec -n 3 python tests/mpi_resplit.py scene.toml out.h5
"""
import sys

import numpy as np

from integrators.service import driver
from integrators.service.scene import load_scene

rng = np.random.default_rng(7)
driver.RESPLIT_MIN = -1.0                                       # move whatever the proposal
driver._balance = lambda stats: (0.0, list(rng.uniform(0.5, 2.0, len(stats))))   # a random proposal
moved = [0]
resplit = driver._resplit


def counting(*args):
    new = resplit(*args)
    moved[0] += new is not None
    return new


driver._resplit = counting
driver.run(load_scene(sys.argv[1]), sys.argv[2], progress=False)
if driver.communicator().rank == 0:
    print(f"moved {moved[0]}")
