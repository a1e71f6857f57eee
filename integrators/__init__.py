"""The numerical core: variational partitioned Runge–Kutta integrators with the projections of
"Projected Variational Integrators for Degenerate Lagrangian Systems".

Public API::

    import integrators
    sys = integrators.system("point_vortices", gamma=(0.1, 0.1))
    tab = integrators.tableau("GLRK2")
    sol = integrators.integrate(sys, q0, tableau=tab, projection="symmetric", h=0.1, steps=1000)

The batch-run service (scenes, the MPI driver, HDF5 output, plots, the CLI) is the subpackage
:mod:`integrators.service` and the symplecticity audit is :mod:`integrators.audit`; no module of
the core imports either.
"""
from . import numba_cache

numba_cache.install()       # before anything is compiled or loaded: processes share the cache safely

from .integrate import Solution, integrate
from .engine import Engine, State, Tolerances, march, set_threads
from .projections import PROJECTIONS
from .systems import SYSTEM_NAMES, System, system, system_from
from .tableaus import TABLEAU_NAMES, Tableau, tableau, tableau_from_arrays, tableau_from_file
from .equilibrium import EquilibriumError, system_from_geqdsk
from .boozer import BoozerError, read_boozmn, system_from_boozer

__all__ = ["integrate", "Solution", "system", "system_from", "System", "SYSTEM_NAMES", "tableau",
           "tableau_from_file", "tableau_from_arrays", "Tableau", "TABLEAU_NAMES", "PROJECTIONS", "Engine", "State", "Tolerances", "march",
           "set_threads", "system_from_geqdsk", "EquilibriumError", "system_from_boozer", "read_boozmn", "BoozerError"]
__version__ = "0.1.0"
