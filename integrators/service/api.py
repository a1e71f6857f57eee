"""Run a scene from Python, as ``poincare run`` does from the shell.

    from integrators import service
    run = service.run("default", "default.h5", steps=200)      # a built-in name, a TOML path or a dict
    run                                                        # <Run ...>: the file, read (read_run)
    ds = run.to_xarray()                                       # labelled arrays (xarray)
    ds.I2.sel(pair="GLRK2-symmetric", form="corrected").plot()

The scene is validated like the CLI's (the same one-line messages, raised as exceptions: a
:class:`SceneError` or ``ValueError``), the file is the one ``poincare run`` writes, and the return
value is :func:`read_run` of it.  Keyword overrides set keys of the scene's ``[run]`` table
(``steps=2000``, ``h=5.0``, ``tableaus=["GLRK2"]``).  A script that calls :func:`run` under
``mpiexec -n K python script.py`` runs distributed, exactly as the CLI does; every rank gets the
Run.
"""
from __future__ import annotations

import copy
import json
import math
import os
from pathlib import Path

from .scene import RUN_KEYS, SceneError, parse_scene, scene_source


def _toml_value(v, key):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if v != v else ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)          # a TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x, key) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x, f'{key}.{k}')}" for k, x in v.items()) + " }"
    if hasattr(v, "tolist"):                                # numpy scalars and arrays
        return _toml_value(v.tolist(), key)
    raise SceneError(f"scene key '{key}': a {type(v).__name__} cannot be written to a scene file")


def _toml_key(k):
    k = str(k)
    return k if k and all(c.isalnum() or c in "_-" for c in k) else json.dumps(k, ensure_ascii=False)


def scene_text(data: dict) -> str:
    """A scene dict (the TOML's structure) as TOML text."""
    if not isinstance(data, dict):
        raise SceneError(f"a scene must be a dict with the TOML's tables, got {type(data).__name__}")
    lines = [f"{_toml_key(k)} = {_toml_value(v, k)}" for k, v in data.items() if not isinstance(v, dict)]
    for k, v in data.items():
        if isinstance(v, dict):
            lines += ["", f"[{_toml_key(k)}]"] + [f"{_toml_key(a)} = {_toml_value(b, f'{k}.{a}')}"
                                                  for a, b in v.items()]
    return "\n".join(lines) + "\n"


def _source(scene):
    """(scene dict or None, TOML text, origin) of a name, path, dict or Scene."""
    from .scene import Scene
    if isinstance(scene, Scene):
        return None, scene.text, None
    if isinstance(scene, dict):
        return copy.deepcopy(scene), None, "<scene>"
    text, path = scene_source(None if scene is None else str(scene))
    return None, text, str(path)


def run(scene="default", output=None, *, resume=False, force=False, threads=None, progress=None, **overrides):
    """Run ``scene`` (a built-in name, a TOML path, a dict with the TOML's tables, or a Scene) and
    return the file read back (:class:`integrators.service.Run`).

    output : the HDF5 path (default: the scene's ``output.path``)
    resume, force : as ``poincare run --resume`` / ``--force``
    threads : threads over points per rank (default: the node's cores shared among the ranks)
    progress : True/False for the progress bar (default: shown in a terminal or a notebook)
    overrides : keys of the scene's [run] table, e.g. ``steps=2000``, ``h=5.0``
    """
    if output is not None and not isinstance(output, (str, os.PathLike)):
        raise ValueError(f"output: a file path (str or Path) is needed, got {type(output).__name__} {output!r}")
    from ..engine import max_threads
    from .driver import run as run_driver
    from .reader import read_run
    from .ranks import communicator
    data, text, origin = _source(scene)
    unknown = sorted(set(overrides) - set(RUN_KEYS))
    if unknown:
        raise SceneError(f"unknown [run] key{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}: the keys are "
                         f"{', '.join(RUN_KEYS)}")
    if overrides:
        if data is None:
            from ..expressions import load_toml
            try:
                data = load_toml(text, origin or "<scene>")
            except ValueError as exc:
                raise SceneError(str(exc)) from None
        run_table = data.setdefault("run", {})
        if not isinstance(run_table, dict):
            raise SceneError("[run] must be a table")
        run_table.update(overrides)
    if data is not None:
        text = scene_text(data)
    sc = parse_scene(text, origin=origin or "<scene>")
    if threads is not None and not (isinstance(threads, int) and 1 <= threads <= max_threads()):
        raise ValueError(f"threads must be between 1 and {max_threads()} (the cores numba can use here), "
                         f"got {threads!r}")
    if output is not None and not str(output).strip():
        raise ValueError("output is empty: give a file name (or None for the scene's output.path)")
    out = Path(output or sc.output)
    comm = communicator()
    try:
        run_driver(sc, out, resume=resume, force=force, comm=comm, progress=progress, threads=threads,
                   version=_version())
    except (ValueError, OSError) as exc:
        raise _in_python_words(exc) from None
    comm.Barrier()                     # rank 0 has written the statuses: every rank reads the same file
    return read_run(out)


def _in_python_words(exc):
    """``exc`` (the same class) with the command line's advice in a Python caller's words:
    ``--resume`` is ``resume=True``, ``--force`` is ``force=True``, ``--steps N`` is ``steps=N``."""
    import re
    text = str(exc)
    said = re.sub(r"--steps (\d+)", r"steps=\1", text).replace("--resume", "resume=True").replace("--force",
                                                                                             "force=True")
    if said == text:
        return exc
    try:
        new = type(exc)(said)
    except Exception:
        return exc
    if hasattr(exc, "reason"):
        new.reason = exc.reason
    return new


def _version():
    from .. import __version__
    return __version__
