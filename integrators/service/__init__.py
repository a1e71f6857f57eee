"""The batch-run service on top of the numerical core (SPEC Part 3).

    from integrators import service
    r = service.run("default", "run.h5", steps=200)  # a built-in name, a TOML path or a dict; MPI-aware
    r = service.read_run("run.h5")                   # the HDF5 file, as arrays (what run returns)
    ds = r.to_xarray()                               # labelled: ds.I2.sel(form="corrected")

Modules: ``api`` (:func:`run` from Python), ``scene`` (scene files and their typed loop/surface
specs), ``phase_space`` (systems given by step maps only), ``ranks`` (the communicator, threads per
rank and the load balance), ``driver`` (the run) with ``diagnostics``, ``tasks``, ``refine`` and
``checkpoints``, ``output`` and ``writer`` (the HDF5 format, written), ``reader`` (read back),
``resumable`` (what a resume may continue), ``statuses``, ``plots``, ``plugins`` (a user's Python
callables), ``stop`` (signals and user code).  The command line is :mod:`integrators.cli`.
"""
from .api import run, scene_text
from .driver import PairSummary
from .reader import PairRun, Run, read_run
from .scene import Scene, SceneError, builtin_scenes, load_scene, parse_scene

__all__ = ["run", "scene_text", "PairSummary", "read_run", "Run", "PairRun", "load_scene", "parse_scene", "Scene", "SceneError",
           "builtin_scenes"]
