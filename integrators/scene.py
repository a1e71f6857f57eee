"""Scenes: what a batch run does, read from TOML and validated before anything runs.

A scene file::

    name = "my-run"                       # optional
    [system]
    name = "guiding_centre_symmetric"     # a built-in system
    params = { mu = 0.01 }                # optional overrides; a vector whole: { gamma = [0.1, 0.2] }

    [loop]                                # optional: a closed loop of sample points
    shape = "guiding_centre"              # built-in shape, or "module:function" / "file.py:function" returning (N, d)
    points = 2000
    params = { rx = 0.5 }                 # optional shape parameters

    [surface]                             # optional: a surface of n_sigma × n_tau Chebyshev points
    shape = "guiding_centre"              # or "module:function" / "file.py:function" taking (S, T), returning (nσ, nτ, d)
    n_sigma = 100
    n_tau = 100

    [run]
    tableaus = ["GLRK1", "GLRK2", "SRK3"]
    projections = ["none", "standard", "symmetric", "symplectic", "midpoint"]
    h = 10.0
    steps = 1000
    output_every = 10                     # steps between outputs
    forms = ["canonical", "noncanonical", "corrected"]
    diagnostics = ["energy", "momentum", "constraint"]
    store_points = false                  # also store every sample point at every output

    [output]
    path = "my-run.h5"

Every mistake is a :class:`SceneError` whose message names the key.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np

from .projections import PROJECTIONS, admission
from .systems import SYSTEM_NAMES, system as builtin_system
from .tableaus import tableau as builtin_tableau

FORMS = ("canonical", "noncanonical", "corrected")
DIAGNOSTICS = ("energy", "momentum", "constraint")
SCENE_DIR = Path(__file__).parent / "scenes"


class SceneError(ValueError):
    """A scene that cannot run; the message names the offending key."""


@dataclasses.dataclass(frozen=True)
class Scene:
    """A validated scene (immutable).  ``text`` is the TOML it came from."""

    name: str
    system_name: str
    system_params: dict
    loop: dict | None
    surface: dict | None
    tableaus: tuple
    projections: tuple
    h: float
    steps: int
    output_every: int
    forms: tuple
    diagnostics: tuple
    store_points: bool
    output: str
    text: str
    base: str | None = None          # directory of the scene file: where a relative file.py:function is looked up

    @property
    def pairs(self):
        """(tableau, projection) pairs in run order."""
        return [(t, p) for t in self.tableaus for p in self.projections]

    def with_steps(self, steps: int) -> "Scene":
        """The same scene run for ``steps`` steps (``poincare run --steps``)."""
        if steps < self.output_every:
            raise SceneError(f"--steps {steps} is below run.output_every = {self.output_every}")
        return dataclasses.replace(self, steps=int(steps))

    @property
    def n_outputs(self) -> int:
        return self.steps // self.output_every + 1

    def system(self):
        return builtin_system(self.system_name, **self.system_params)

    def loop_points(self):
        """(N, d) loop sample points or None."""
        if self.loop is None:
            return None
        from invariants import samples
        shape = _shape(self.loop["shape"], "loop.shape", self.base)
        return samples.loop(shape, self.loop["points"], **self.loop.get("params", {}))

    def surface_points(self):
        """(n_σ, n_τ, d) surface sample points or None."""
        if self.surface is None:
            return None
        from invariants import samples
        shape = _shape(self.surface["shape"], "surface.shape", self.base)
        return samples.surface(shape, self.surface["n_sigma"], self.surface["n_tau"], **self.surface.get("params", {}))


def _shape(spec, key, base=None):
    if ":" not in spec:
        return spec
    from .plugins import load_callable
    try:
        return load_callable(spec, key, base)
    except ValueError as exc:
        raise SceneError(str(exc)) from None


_SCHEMA = {
    "": {"name": str, "system": dict, "loop": dict, "surface": dict, "run": dict, "output": dict},
    "system": {"name": str, "params": dict},
    "loop": {"shape": str, "points": int, "params": dict},
    "surface": {"shape": str, "n_sigma": int, "n_tau": int, "params": dict},
    "run": {"tableaus": list, "projections": list, "h": float, "steps": int, "output_every": int,
            "forms": list, "diagnostics": list, "store_points": bool},
    "output": {"path": str},
}


def _check_table(data, section):
    schema = _SCHEMA[section]
    for key, val in data.items():
        where = f"{section}.{key}" if section else key
        if key not in schema:
            raise SceneError(f"unknown key '{where}' (allowed: {', '.join(sorted(schema))})")
        want = schema[key]
        ok = isinstance(val, want) and not (want is int and isinstance(val, bool))
        if want is float and isinstance(val, int) and not isinstance(val, bool):
            ok = True
        if not ok:
            raise SceneError(f"'{where}' must be {want.__name__}, got {type(val).__name__} {val!r}")


def _names(values, allowed, key, check=None):
    if not values:
        raise SceneError(f"'{key}' is empty")
    for v in values:
        if not isinstance(v, str):
            raise SceneError(f"'{key}' must be a list of strings, got {v!r}")
        if check is not None:
            try:
                check(v)
            except ValueError as exc:
                raise SceneError(f"{key}: {exc}") from None
        elif v not in allowed:
            raise SceneError(f"{key}: unknown value '{v}' (choose from {', '.join(allowed)})")
    if len(set(values)) != len(values):
        raise SceneError(f"'{key}' lists a value twice")
    return tuple(values)


def parse_scene(text: str, origin: str = "<scene>") -> Scene:
    """Validate TOML text into a Scene; raises SceneError naming the key."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: not valid TOML: {exc}") from None
    _check_table(data, "")
    for sec in ("system", "run"):
        if sec not in data:
            raise SceneError(f"missing table [{sec}]")
    for sec in ("system", "loop", "surface", "run", "output"):
        if sec in data:
            _check_table(data[sec], sec)
    sysd, run = data["system"], data["run"]
    if "name" not in sysd:
        raise SceneError("missing key 'system.name'")
    if sysd["name"] not in SYSTEM_NAMES:
        raise SceneError(f"system.name: unknown system '{sysd['name']}' (choose from {', '.join(SYSTEM_NAMES)})")
    params = dict(sysd.get("params", {}))
    def finite(v):
        return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)

    for k, v in params.items():
        if isinstance(v, list):          # a vector parameter given whole, as in Python: gamma = [0.1, 0.1]
            if not v or not all(finite(x) for x in v):
                raise SceneError(f"system.params.{k} must be a finite number or a list of them, got {v!r}")
            params[k] = tuple(float(x) for x in v)
        elif not finite(v):
            raise SceneError(f"system.params.{k} must be a finite number, got {v!r}")
    try:
        system = builtin_system(sysd["name"], **params)
    except ValueError as exc:
        raise SceneError(f"system.params: {exc}") from None
    if "loop" not in data and "surface" not in data:
        raise SceneError("the scene needs a [loop] or a [surface] of sample points")
    loop = dict(data["loop"]) if "loop" in data else None
    surface = dict(data["surface"]) if "surface" in data else None
    if loop is not None:
        loop.setdefault("shape", "guiding_centre")
        if "points" not in loop:
            raise SceneError("missing key 'loop.points'")
        if loop["points"] < 3:
            raise SceneError(f"loop.points must be at least 3, got {loop['points']}")
    if surface is not None:
        surface.setdefault("shape", "guiding_centre")
        for k in ("n_sigma", "n_tau"):
            if k not in surface:
                raise SceneError(f"missing key 'surface.{k}'")
            if surface[k] < 2:
                raise SceneError(f"surface.{k} must be at least 2, got {surface[k]}")
    for key in ("tableaus", "projections", "h", "steps"):
        if key not in run:
            raise SceneError(f"missing key 'run.{key}'")
    tabs = _names(run["tableaus"], None, "run.tableaus", check=builtin_tableau)
    projs = _names(run["projections"], PROJECTIONS, "run.projections")
    h = float(run["h"])
    if not math.isfinite(h) or h <= 0:
        raise SceneError(f"run.h must be a finite positive number, got {run['h']!r}")
    steps = run["steps"]
    if steps <= 0:
        raise SceneError(f"run.steps must be positive, got {steps}")
    every = run.get("output_every", max(1, steps // 100))
    if every <= 0 or every > steps:
        raise SceneError(f"run.output_every must be between 1 and run.steps = {steps}, got {every}")
    forms = _names(run.get("forms", ["canonical", "noncanonical"]), FORMS, "run.forms")
    diags = _names(run.get("diagnostics", list(DIAGNOSTICS)), DIAGNOSTICS, "run.diagnostics")
    if "momentum" in diags and not system.has_momentum:
        raise SceneError(f"run.diagnostics: system '{system.name}' has no Noether momentum")
    for t in tabs:
        tab = builtin_tableau(t)
        for p in projs:
            why = admission(tab, p)
            if why:
                raise SceneError(f"run: {why}")
    name = data.get("name", Path(origin).stem if origin != "<scene>" else "scene")
    out = data.get("output", {}).get("path", f"{name}.h5")
    scene = Scene(name=name, system_name=sysd["name"], system_params=params, loop=loop, surface=surface,
                  tableaus=tabs, projections=projs, h=h, steps=steps, output_every=every, forms=forms,
                  diagnostics=diags, store_points=bool(run.get("store_points", False)), output=out, text=text,
                  base=str(Path(origin).parent) if origin != "<scene>" else None)
    _check_points(scene, system)
    return scene


def _check_points(scene, system):
    for what, spec, pts in (("loop", scene.loop, scene.loop_points), ("surface", scene.surface, scene.surface_points)):
        if spec is None:
            continue
        try:
            q = np.asarray(pts(), dtype=float)
        except SceneError:
            raise
        except Exception as exc:      # a user shape function may raise anything: one line naming it
            who = f"{what}.shape '{spec['shape']}'" if ":" in spec["shape"] else what
            raise SceneError(f"{who} failed: {type(exc).__name__}: {exc}") from None
        want = (spec["points"], system.d) if what == "loop" else (spec["n_sigma"], spec["n_tau"], system.d)
        if q.shape[-1:] == (system.d,) and q.shape != want:
            raise SceneError(f"{what}: the shape gives points of shape {q.shape}, the scene needs {want}")
        q = q.reshape(-1, q.shape[-1])
        if q.shape[1] != system.d:
            raise SceneError(f"{what}: points have dimension {q.shape[1]}, system {system.name} needs {system.d}")
        bad = ~system.in_domain(q)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise SceneError(f"{what}: point {k} = {q[k].tolist()} is not finite or outside the domain of {system.name}")


_KEYS = {"system_name": "system.name", "system_params": "system.params", "loop": "loop", "surface": "surface",
         "tableaus": "run.tableaus", "projections": "run.projections", "h": "run.h", "steps": "run.steps",
         "output_every": "run.output_every", "forms": "run.forms", "diagnostics": "run.diagnostics",
         "store_points": "run.store_points"}


def scene_differences(a: Scene, b: Scene) -> list:
    """The scene keys whose parsed values differ between a and b and change the results (not the
    name, the output path, comments or formatting)."""
    return [key for field, key in _KEYS.items() if getattr(a, field) != getattr(b, field)]


def builtin_scenes() -> dict:
    """{name: path} of the scenes shipped with the package."""
    return {p.stem: p for p in sorted(SCENE_DIR.glob("*.toml"))}


def load_scene(spec: str | None) -> Scene:
    """A built-in scene by name, a TOML file by path, or the default scene (None)."""
    spec = spec or "default"
    scenes = builtin_scenes()
    if spec in scenes:
        path = scenes[spec]
    else:
        path = Path(spec)
        if not path.exists():
            raise SceneError(f"scene '{spec}' is neither a file nor a built-in scene ({', '.join(scenes)})")
    try:
        text = path.read_text()
    except OSError as exc:
        raise SceneError(f"cannot read scene '{spec}': {exc}") from None
    return parse_scene(text, origin=str(path))
