"""The batch-run service on top of the numerical core (SPEC Part 3).

    from integrators import service
    scene = service.load_scene("default")           # a built-in scene, or a path to a TOML file
    summaries = service.run(scene, "run.h5")        # every (tableau, projection) pair; MPI-aware
    r = service.read_run("run.h5")                  # the HDF5 file, as arrays

Modules: ``scene`` (scene files and their typed loop/surface specs), ``ranks`` (the communicator,
threads per rank and the load balance), ``driver`` (the run), ``output`` (the one owner of the
HDF5 format, reading and writing), ``plots``, ``plugins`` (a user's Python callables), ``cli``.
"""
from .driver import PairSummary, run
from .output import PairRun, Run, read_run
from .scene import Scene, SceneError, builtin_scenes, load_scene, parse_scene

__all__ = ["run", "PairSummary", "read_run", "Run", "PairRun", "load_scene", "parse_scene", "Scene", "SceneError",
           "builtin_scenes"]
