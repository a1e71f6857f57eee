"""Scenes: what a batch run does, read from TOML and validated before anything runs.

A scene file::

    name = "my-run"                       # optional
    [system]
    name = "guiding_centre_symmetric"     # a built-in system
    params = { mu = 0.01 }                # optional overrides; a vector whole: { gamma = [0.1, 0.2] }

    [system]                              # ... or your own, from ϑ and H alone (restricted parser)
    name = "oscillator"                   # a label
    coordinates = ["x", "y"]              # an even number of names
    theta = ["-y/2", "x/2"]
    H = "omega*(x^2 + y^2)/2"
    params = { omega = 1.0 }              # every other name in the expressions
    symmetry = ["-y", "x"]                # optional: Noether momentum P = ϑ·V; or momentum = "..."
    domain = ["x + 2"]                    # optional: expressions that must stay > 0

    [system]                              # ... or a function returning an integrators.System
    function = "mysys.py:make"            # (or module:function; top-level system = "..." says the same)
    params = { omega = 2.0 }              # passed to it as keyword arguments

    [system]                              # ... or guiding centres in a tokamak equilibrium (docs/equilibria.md)
    equilibrium = "eq.geqdsk"             # a G-EQDSK file, next to the scene or in the current directory
    cocos = 3                             # its sign conventions (COCOS index; default: identified from the file)
    params = { mu = 1e-5 }                # the magnetic moment (default from the plasma's size and field)

    [system]                              # ... or guiding centres in a stellarator's Boozer field (docs/stellarators.md)
    boozer = "boozmn_x.nc"                # a booz_xform boozmn file (NetCDF 3), found as an equilibrium file is
    modes_tol = 1e-4                      # optional: modes below this fraction of |b_00| are left out
    grid = 96                             # optional: the (x, y) grid of |B|'s harmonics, points a side
    params = { mu = 1e-5 }                # optional: the magnetic moment (default from the plasma's size and field)

    [system]                              # ... or a canonical phase space with no formula (docs/systems.md)
    name = "pendula"                      # a label
    degrees_of_freedom = 1024             # k: q = (x_0 … x_{k−1}, v_0 … v_{k−1}), the form v·dx; run.step_maps
                                          # are then canonical maps step(x, v, h) -> (x, v) on (n, k) arrays
    period = 6.283185307179586            # optional: the positions' period (one number or one per x; 0: none)
    energy = "maps.py:energy"             # optional: batched energy(x, v) -> (n,), for the energy error

    [system]                              # ... or d coordinates with a one-form of code (docs/systems.md)
    dimension = 4                         # d; run.step_maps are then maps step(q, h) -> q on (n, d) arrays
    one_form = "maps.py:theta"            # batched theta(q) -> (n, d): the Lagrangian ϑ(q)·q̇ − H(q)'s ϑ
    period = [0.0, 6.283185307179586, 0.0, 0.0]   # optional, per coordinate; energy = "maps.py:H" (H(q) -> (n,))

    [loop]                                # optional: a closed loop of sample points
    shape = "guiding_centre"              # built-in shape, or "module:function" / "file.py:function": called as
                                          # f(tau, **params), tau the (N,) array j/N in [0, 1), returning (N, d)
    points = 2000
    params = { rx = 0.5 }                 # optional shape parameters; any system: shape = "ellipse" with
                                          # params = { d = 2, center = [1.0, 1.0], radii = [0.04, 0.04], plane = [0, 1] };
                                          # center = "maps.py:start" takes what start() returns (an array of d,
                                          # or a tuple joined: (x0, v0)), for centres too long to write
    refine_to = 16000                     # optional: the loop may refine itself up to this many points
                                          # (N → 2N, every old τ kept; the surface: n → 2n − 1 per direction)

    [surface]                             # optional: a surface of n_sigma × n_tau Chebyshev points
    shape = "guiding_centre"              # or "rectangle" (params d, center, size, plane), or "module:function" /
                                          # "file.py:function": f(S, T, **params), two (nσ, nτ) arrays of
                                          # Chebyshev points in [0, 1], returning (nσ, nτ, d)
    n_sigma = 100
    n_tau = 100
    refine_to = 40000                     # optional: the surface may refine itself up to n_sigma·n_tau this large

    [run]
    tableaus = ["GLRK1", "GLRK2", "SRK3"]  # built-in names or tableau TOML files (as `poincare audit` reads)
    projections = ["none", "standard", "symmetric", "symplectic", "midpoint"]
    step_maps = ["mymaps.py:leapfrog"]    # optional: your batched step(q, p, lam, h, system) -> (q, p, lam)
                                          # (the audit's contract), run as the pair "leapfrog-map"
    h = 10.0                              # in [1e-150, 1e150]: h² a normal double
    steps = 1000
    output_every = 10                     # steps between outputs (default steps/100); when steps is not a
                                          # multiple, the last interval is shorter and ends at run.steps
    forms = ["canonical", "noncanonical", "corrected"]   # default: canonical and noncanonical only
                                          # ("corrected" costs ϑ_qq at every output: ask for it)
    diagnostics = ["energy", "momentum", "constraint"]   # default: all three ("momentum" only where the
                                          # system has one: a symmetry or a momentum expression)
    store_points = false                  # also store every sample point at every output
    precision = "double"                  # or "double-double" (~32 digits, the compiled engine's third
                                          # specialisation): states, checkpoints and the energy, momentum
                                          # and constraint errors in double-double; the invariants from
                                          # the states rounded to double.  Not with step_maps.
    jacobian_refresh = 0.01               # Newton takes a fresh Jacobian after an iteration that contracted
                                          # by less than this (Tolerances.refresh; in (0, 1)).  Another
                                          # value changes every result's last bits and the run's speed
                                          # (docs/benchmarks-history.md, "the levers that change bits")

    [output]
    path = "my-run.h5"
    checkpoint_seconds = 60.0             # write the integrator state about this often (and at each pair's
                                          # end); 0: at every output.  A kill loses at most this much work.
    checkpoints = "in-file"               # or "per-rank": every rank writes its own points' state beside the
                                          # file (my-run.h5.checkpoints/), linked into it; for hundreds of ranks

Files named in a scene (tableaus, file.py:function) are looked up next to the scene file, then in
the current directory.  A scene that names Python code (file.py:function, module:function) runs
it, like a script: only code found there (never an installed module), and the run's summary
lists it.  Strings (expressions, tableau entries) are data: a restricted parser reads them.  Every mistake is a :class:`SceneError` whose message names the key; an
expression that does not parse, an unknown name, an odd dimension or an Ω̄ that is singular at a
sample point are refused before anything runs.
"""
from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..engine import PRECISIONS, Tolerances
from ..projections import admission, names as projection_names
from ..systems import SYSTEM_NAMES, system as builtin_system
from ..tableaus import tableau as builtin_tableau
from invariants.forms import MIN_POINTS

FORMS = ("canonical", "noncanonical", "corrected")
DIAGNOSTICS = ("energy", "momentum", "constraint")
SCENE_DIR = Path(__file__).parent / "scenes"


CHECKPOINT_SECONDS = 60.0          # default of output.checkpoint_seconds
MAX_STEPS = 2**53                  # run.steps and --steps: every step number k, and so t = k·h, exact in double
H_RANGE = (1e-150, 1e150)          # run.h: h² a normal double, t = k·h finite for every k ≤ MAX_STEPS


class SceneError(ValueError):
    """A scene that cannot run; the message names the offending key."""


@dataclasses.dataclass(frozen=True)
class LoopSpec:
    """The [loop] of a scene: ``points`` samples of a closed loop, for I₁."""

    points: int
    shape: str = "guiding_centre"            # a built-in shape (invariants.samples) or module:function
    params: dict = dataclasses.field(default_factory=dict)
    refine_to: int | None = None             # the most points refinement may grow the loop to
    name = "loop"
    invariant = "I1"

    @property
    def grid(self) -> tuple:
        """The set's own shape (without the dimension d)."""
        return (self.points,)

    @property
    def count(self) -> int:
        return self.points

    def sample(self, base=None):
        """(N, d) sample points."""
        from invariants import samples
        return samples.loop(_shape(self.shape, "loop.shape", base), self.points, **_set_params(self.params, "loop", base))

    def at_level(self, level):
        """The loop ``level`` refinements on (N·2^level points, every old τ kept); level 0 is this one."""
        from invariants.samples import refined_grid
        return self if level == 0 else dataclasses.replace(self, points=refined_grid(self.grid, level)[0],
                                                           refine_to=None)

    @property
    def levels(self) -> int:
        """How many refinements ``refine_to`` allows (0 without it)."""
        return _levels(self)


@dataclasses.dataclass(frozen=True)
class SurfaceSpec:
    """The [surface] of a scene: an n_σ × n_τ Chebyshev grid on a surface, for I₂."""

    n_sigma: int
    n_tau: int
    shape: str = "guiding_centre"
    params: dict = dataclasses.field(default_factory=dict)
    refine_to: int | None = None             # the most points (n_σ·n_τ) refinement may grow the surface to
    name = "surface"
    invariant = "I2"

    @property
    def grid(self) -> tuple:
        return (self.n_sigma, self.n_tau)

    @property
    def count(self) -> int:
        return self.n_sigma * self.n_tau

    def sample(self, base=None):
        """(n_σ, n_τ, d) sample points."""
        from invariants import samples
        return samples.surface(_shape(self.shape, "surface.shape", base), self.n_sigma, self.n_tau,
                               **_set_params(self.params, "surface", base))

    def at_level(self, level):
        """The surface ``level`` refinements on (n → 2n − 1 Chebyshev points per direction, nested)."""
        from invariants.samples import refined_grid
        if level == 0:
            return self
        n_sigma, n_tau = refined_grid(self.grid, level)
        return dataclasses.replace(self, n_sigma=n_sigma, n_tau=n_tau, refine_to=None)

    @property
    def levels(self) -> int:
        """How many refinements ``refine_to`` allows (0 without it)."""
        return _levels(self)


def _levels(spec) -> int:
    if spec.refine_to is None:
        return 0
    level = 0
    while spec.at_level(level + 1).count <= spec.refine_to:
        level += 1
    return level


class Pair(NamedTuple):
    """One run of a scene: a tableau (by its label) with a projection, or a user's step map
    (run.step_maps; ``projection`` None, ``label`` the function's name)."""

    label: str
    projection: str | None

    @property
    def step_map(self) -> bool:
        return self.projection is None

    @property
    def name(self) -> str:
        """Its group in the run file: 'GLRK2-symmetric', a step map 'rk4-map' (output.pair_name)."""
        from .output import pair_name
        return pair_name(self.label, "map" if self.projection is None else self.projection)


@dataclasses.dataclass(frozen=True)
class Scene:
    """A validated scene (immutable).  ``text`` is the TOML it came from."""

    name: str
    system_name: str
    system_params: dict
    loop: LoopSpec | None
    surface: SurfaceSpec | None
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
    checkpoint_seconds: float = CHECKPOINT_SECONDS  # wall time between checkpoints (0: every output); results do not depend on it
    checkpoints: str = "in-file"     # who writes the state: rank 0 into the file, or every rank its slab beside it
    base: str | None = None          # directory of the scene file: where a relative file.py:function is looked up
    system_spec: dict = dataclasses.field(default_factory=dict)   # the [system] table (user systems)
    tableau_files: dict = dataclasses.field(default_factory=dict)  # {label: path} of tableau TOML files
    step_maps: tuple = ()            # run.step_maps specs, in order
    precision: str = "double"        # run.precision: the engine's numbers ("double" or "double-double")
    jacobian_refresh: float = Tolerances.refresh   # run.jacobian_refresh: Newton's refresh threshold
    _built: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)   # system, tableaus: made once

    @property
    def max_stages(self) -> int:
        """The most stages s of the scene's tableaus (1 without any): the checkpoint's stage arrays
        are this wide, whichever pair wrote them."""
        return max([self.tableau(t).s for t in self.tableaus] + [1])

    @property
    def pairs(self) -> list:
        """The scene's :class:`Pair` s in run order: every (tableau, projection), then the step maps."""
        return [Pair(t, p) for t in self.tableaus for p in self.projections] + \
            [Pair(step_map_label(m), None) for m in self.step_maps]

    def step_map(self, label):
        """The callable of the step map whose pair label is ``label``."""
        spec = next(m for m in self.step_maps if step_map_label(m) == label)
        return _load(spec, "run.step_maps", self.base)

    def with_steps(self, steps: int) -> "Scene":
        """The same scene run for ``steps`` steps (``poincare run --steps``)."""
        if steps < self.output_every:
            raise SceneError(f"--steps {steps} is below run.output_every = {self.output_every}")
        if steps > MAX_STEPS:
            raise SceneError(f"--steps must be at most 2^53 = {MAX_STEPS:,}, got {steps}")
        return dataclasses.replace(self, steps=int(steps))

    @property
    def n_outputs(self) -> int:
        """Outputs of a finished pair: at step 0, every run.output_every steps, and at run.steps
        (the last interval may be shorter)."""
        return -(-self.steps // self.output_every) + 1

    def system(self):
        """The scene's System: a built-in one, one from ϑ and H in the scene, or a user function's;
        made once (a scene copied with other steps shares it; one with another system does not)."""
        key = ("system", repr(self.system_spec), repr(self.system_params), self.system_name, self.base)
        if key not in self._built:
            self._built[key] = _make_system(self.system_spec or {"name": self.system_name}, self.system_params,
                                            self.base)
        return self._built[key]

    def tableau(self, label):
        """The Tableau of a run.tableaus entry (by its pair label), made once."""
        key = ("tableau", label, self.tableau_files.get(label))
        if key not in self._built:
            if label in self.tableau_files:
                from ..tableaus import tableau_from_file
                self._built[key] = tableau_from_file(self.tableau_files[label])
            else:
                self._built[key] = builtin_tableau(label)
        return self._built[key]

    def loop_points(self):
        """(N, d) loop sample points or None."""
        return None if self.loop is None else self.loop.sample(self.base)

    def surface_points(self):
        """(n_σ, n_τ, d) surface sample points or None."""
        return None if self.surface is None else self.surface.sample(self.base)

    @property
    def sample_sets(self) -> list:
        """[(spec, slice)]: the loop, then the surface, with the rows they occupy in every points array
        of a run (the surface row by row)."""
        out, lo = [], 0
        for spec in (self.loop, self.surface):
            if spec is not None:
                out.append((spec, slice(lo, lo + spec.count)))
                lo += spec.count
        return out

    @property
    def n_points(self) -> int:
        return sum(spec.count for spec, _ in self.sample_sets)

    def points(self, system=None):
        """(n, d) every sample point of the scene, in the order of :attr:`sample_sets`."""
        system = system or self.system()
        return np.concatenate([spec.sample(self.base).reshape(-1, system.d) for spec, _ in self.sample_sets])


def _grid_text(spec):
    return f"{spec.points} τ" if spec.name == "loop" else f"{spec.n_sigma} × {spec.n_tau} Chebyshev points"


def _shape(spec, key, base=None):
    return spec if ":" not in spec else _load(spec, key, base)


def _load(spec, key, base=None):
    """The user's callable ``spec`` (file.py:function, module:function) named by scene key ``key``;
    a SceneError in one line where it cannot be loaded (plugins.load_callable)."""
    from .plugins import load_callable
    try:
        return load_callable(spec, key, base)
    except ValueError as exc:
        raise SceneError(str(exc)) from None


def _set_params(params, key, base=None):
    """A set's shape parameters, ``center = "file.py:function"`` replaced by what the function returns
    when called with no arguments: one array of d numbers, or a tuple of arrays joined in order
    ((x0, v0) of a canonical phase space).  For centres too long to write in TOML."""
    c = params.get("center")
    if not isinstance(c, str):
        return params
    fn = _load(c, f"{key}.params.center", base)
    try:
        got = fn()
    except Exception as exc:          # the user's function may raise anything: one line naming it
        raise SceneError(f"{key}.params.center '{c}' failed: {type(exc).__name__}: {exc}") from None
    parts = got if isinstance(got, (tuple, list)) else (got,)
    return {**params, "center": np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in parts])}


_SCHEMA = {
    "": {"name": str, "system": dict, "loop": dict, "surface": dict, "run": dict, "output": dict},
    "system": {"name": str, "params": dict, "coordinates": list, "theta": list, "H": str, "symmetry": list,
               "momentum": str, "domain": list, "function": str, "equilibrium": str, "cocos": int,
               "boozer": str, "modes_tol": float, "grid": int,
               "degrees_of_freedom": int, "dimension": int, "one_form": str, "period": object, "energy": str},
    "loop": {"shape": str, "points": int, "params": dict, "refine_to": int},
    "surface": {"shape": str, "n_sigma": int, "n_tau": int, "params": dict, "refine_to": int},
    "run": {"tableaus": list, "projections": list, "step_maps": list, "h": float, "steps": int, "output_every": int,
            "forms": list, "diagnostics": list, "store_points": bool, "precision": str,
            "jacobian_refresh": float},
    "output": {"path": str, "checkpoint_seconds": float, "checkpoints": str},
}
RUN_KEYS = tuple(_SCHEMA["run"])      # what integrators.service.run(..., **overrides) may set


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
    """Validate TOML text into a Scene; raises SceneError naming the key.

    The tables in the order a reader meets them — the TOML and its tables' keys, [system], the
    sample sets, [run]'s pairs, steps and records, [output] — each checked by its own function, the
    first mistake reported; then what needs the whole scene (memory, the points, user code)."""
    data = _tables(text, origin)
    sysd, run = data["system"], data["run"]
    base = str(Path(origin).parent) if origin != "<scene>" else None
    system, params, spec = _system_of(sysd, base, _points_asked(data))
    loop, surface = _sets_of(data)
    maps, tabs, tableau_files, projs = _pairs_of(run, base)
    h, steps, every = _steps_of(run)
    if getattr(system, "black_box", False):
        forms, diags = _phase_space_records(system, run, maps, tabs)
    else:
        forms = _names(run.get("forms", ["canonical", "noncanonical"]), FORMS, "run.forms")
        default_diags = [x for x in DIAGNOSTICS if x != "momentum" or system.has_momentum]
        diags = _names(run.get("diagnostics", default_diags), DIAGNOSTICS, "run.diagnostics")
    if "momentum" in diags and not system.has_momentum:
        raise SceneError(f"run.diagnostics: system '{system.name}' has no Noether momentum")
    for t in tabs:
        tab = builtin_tableau(t) if t not in tableau_files else _tableau_file(tableau_files[t])
        for p in projs:
            why = admission(tab, p)
            if why:
                raise SceneError(f"run: {why}")
    precision = run.get("precision", "double")
    if precision not in PRECISIONS:
        raise SceneError(f"run.precision must be one of {', '.join(map(repr, PRECISIONS))}, got {precision!r}")
    if precision != "double" and maps:
        raise SceneError("run.precision = \"double-double\" is the compiled engine's: a step map (run.step_maps) "
                         "runs in double; give it a scene of its own")
    refresh = run.get("jacobian_refresh", Tolerances.refresh)
    if not (math.isfinite(refresh) and 0 < refresh < 1):
        raise SceneError(f"run.jacobian_refresh must be in (0, 1), got {refresh!r}")
    name = data.get("name", Path(origin).stem if origin != "<scene>" else "scene")
    for key, value in (("name", name), ("system.name", sysd.get("name", ""))):
        if not value.isprintable():
            raise SceneError(f"'{key}' holds control characters (a newline or a terminal escape): {value!r}")
    out, ck_seconds, ck_mode = _output_of(data.get("output", {}), name)
    scene = Scene(name=name, system_name=system.name, system_params=params, loop=loop, surface=surface,
                  tableaus=tabs, projections=projs, h=h, steps=steps, output_every=every, forms=forms,
                  diagnostics=diags, store_points=bool(run.get("store_points", False)), output=out, text=text,
                  checkpoint_seconds=ck_seconds, checkpoints=ck_mode,
                  base=base, system_spec=spec, tableau_files=tableau_files, step_maps=maps, precision=precision,
                  jacobian_refresh=float(refresh))
    _check_memory(scene, system)
    _check_points(scene, system)
    for label in {step_map_label(m) for m in maps}:
        scene.step_map(label)             # import now: a missing file or function is a one-line error
    return scene


def _phase_space_records(system, run, maps, tabs):
    """(forms, diagnostics) of a scene of black-box maps: its maps only, its one form (canonical v·dx,
    or the noncanonical ϑ·dq of system.one_form), the energy error where system.energy is given."""
    what = ("a canonical phase space (system.degrees_of_freedom)" if system.form == "canonical" else
            "a system of step maps with a one-form of code (system.one_form)")
    if tabs or not maps:
        contract = "step(x, v, h) -> (x, v)" if system.form == "canonical" else "step(q, h) -> q"
        raise SceneError(f"{what} has no formula for the engine: give run.step_maps (maps {contract}) and "
                         "run.tableaus = [] or none")
    forms = _names(run.get("forms", [system.form]), FORMS, "run.forms")
    if forms != (system.form,):
        raise SceneError(f"run.forms: {what} has the {system.form} form only "
                         f"({'v·dx' if system.form == 'canonical' else 'ϑ·dq'}), got {list(forms)}")
    energy = () if system.energy is None else ("energy",)
    diags = run.get("diagnostics", list(energy))
    if not isinstance(diags, list) or any(x not in energy for x in diags):
        raise SceneError(f"run.diagnostics: {what} records {'the energy error only' if energy else 'none'}"
                         f" ({'system.energy is given' if energy else 'give system.energy for the energy error'}),"
                         f" got {diags!r}")
    return forms, tuple(dict.fromkeys(diags))


def _tables(text, origin) -> dict:
    """The TOML (restricted reader) with its tables present and their keys known and typed."""
    from ..expressions import load_toml
    try:
        data = load_toml(text, origin)
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    if isinstance(data.get("system"), str):       # system = "module:function"
        data["system"] = {"function": data["system"]}
    _check_table(data, "")
    for sec in ("system", "run"):
        if sec not in data:
            raise SceneError(f"missing table [{sec}]")
    for sec in ("system", "loop", "surface", "run", "output"):
        if sec in data:
            _check_table(data[sec], sec)
    return data


def _points_asked(data) -> int:
    """The sample points [loop] and [surface] ask for where they give whole numbers (at least
    MIN_POINTS): a first measure of a scene's size, before the sets are checked."""
    whole = lambda v: v if isinstance(v, int) and not isinstance(v, bool) and v > 0 else MIN_POINTS
    loop, surface = data.get("loop", {}), data.get("surface", {})
    count = whole(loop.get("points")) if isinstance(loop, dict) and loop else 0
    if isinstance(surface, dict) and surface:
        count += whole(surface.get("n_sigma")) * whole(surface.get("n_tau"))
    return max(count, MIN_POINTS)


def _finite(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


def _system_of(sysd, base, points=MIN_POINTS):
    """[system]: (the System, its parameters, the user system's spec or {}); ``points``: the sample
    points the scene asks for, as far as its tables say before they are checked (a phase space of
    step maps judges its memory by them before it is built)."""
    if "equilibrium" in sysd:
        return _equilibrium_of(sysd, base)
    if "boozer" in sysd:
        return _boozer_of(sysd, base)
    for k in ("modes_tol", "grid"):
        if k in sysd:
            raise SceneError(f"system.{k} belongs to system.boozer (a boozmn file)")
    if "degrees_of_freedom" in sysd or "dimension" in sysd or "one_form" in sysd:
        return _phase_space_of(sysd, base, points)
    for k in ("period", "energy"):
        if k in sysd:
            raise SceneError(f"system.{k} belongs to a system given by step maps (system.degrees_of_freedom, or "
                             "system.dimension with system.one_form)")
    if "cocos" in sysd:
        raise SceneError("system.cocos belongs to system.equilibrium (a G-EQDSK file)")
    user = any(k in sysd for k in ("coordinates", "function"))
    if not user:
        if "name" not in sysd:
            raise SceneError("missing key 'system.name' (or give system.coordinates, theta and H, or system = "
                             "\"module:function\")")
        if sysd["name"] not in SYSTEM_NAMES:
            raise SceneError(f"system.name: unknown system '{sysd['name']}' (choose from {', '.join(SYSTEM_NAMES)}; "
                             "or give system.coordinates, theta and H)")
        for k in ("theta", "H", "symmetry", "momentum", "domain"):
            if k in sysd:
                raise SceneError(f"system.{k} needs system.coordinates (a built-in system brings its own)")
    params = dict(sysd.get("params", {}))
    for k, v in params.items():
        if isinstance(v, list):          # a vector parameter given whole, as in Python: gamma = [0.1, 0.1]
            if not v or not all(_finite(x) for x in v):
                raise SceneError(f"system.params.{k} must be a finite number or a list of them, got {v!r}")
            params[k] = tuple(float(x) for x in v)
        elif not _finite(v):
            raise SceneError(f"system.params.{k} must be a finite number, got {v!r}")
    spec = {k: v for k, v in sysd.items() if k != "params"} if user else {}
    return _make_system(spec or {"name": sysd["name"]}, params, base), params, spec


def _equilibrium_of(sysd, base):
    """[system] equilibrium = "file.geqdsk" (looked up next to the scene, then in the current
    directory), cocos = N, params = {mu = …}: the guiding centre in that equilibrium
    (integrators.equilibrium).  The file is data: it is read, never run."""
    e, digest, params = _field_file(sysd, base, "equilibrium", ())
    spec = {"equilibrium": e, "cocos": sysd.get("cocos"), "sha256": digest}
    return _make_system(spec, params, base), params, spec


def _field_file(sysd, base, key, others):
    """A [system] that a field file brings (``key`` = "equilibrium" or "boozer"): refuses the keys of
    other kinds of system (and ``others``), finds the file, checks the parameters; returns (the name
    as given, the file's sha256, the parameters).  The digest belongs to the scene: a resume compares
    it (a changed file is another field), not where the file lies, which may differ between a run
    and its resume."""
    for k in ("name", "coordinates", "theta", "H", "symmetry", "momentum", "domain", "function") + others:
        if k in sysd:
            raise SceneError(f"system.{k} cannot go with system.{key} (the file brings the system)")
    import hashlib
    e = sysd[key]
    found = _data_file(e, base, f"system.{key}: file")
    params = dict(sysd.get("params", {}))
    for k, v in params.items():
        if not _finite(v):
            raise SceneError(f"system.params.{k} must be a finite number, got {v!r}")
    return e, hashlib.sha256(found.read_bytes()).hexdigest(), params


def _boozer_of(sysd, base):
    """[system] boozer = "boozmn_x.nc" (looked up as an equilibrium file is), modes_tol, grid,
    params = {mu = …}: the guiding centre in that Boozer field (integrators.boozer).  The file is
    data: it is read, never run."""
    e, digest, params = _field_file(sysd, base, "boozer", ("equilibrium", "cocos"))
    tol = sysd.get("modes_tol", 1e-4)
    if not (_finite(tol) and 0 <= tol < 1):
        raise SceneError(f"system.modes_tol must be a number in [0, 1), got {tol!r}")
    grid = sysd.get("grid", 96)
    if not 16 <= grid <= 1024:
        raise SceneError(f"system.grid must be between 16 and 1024 points a side, got {grid}")
    spec = {"boozer": e, "modes_tol": float(tol), "grid": int(grid), "sha256": digest}
    return _make_system(spec, params, base), params, spec


def _phase_space_of(sysd, base, points=MIN_POINTS):
    """[system] of black-box maps (integrators.service.phase_space): degrees_of_freedom = k, the
    canonical phase space (x, v) of dimension 2k, run.step_maps canonical maps step(x, v, h) -> (x, v);
    or dimension = d with one_form = "file.py:theta", run.step_maps maps step(q, h) -> q.  Both take
    period = P and energy = "file.py:function"."""
    canonical = "degrees_of_freedom" in sysd
    key = "system.degrees_of_freedom" if canonical else "system.dimension"
    for k in ("coordinates", "theta", "H", "symmetry", "momentum", "domain", "function", "cocos", "params") + \
            (("dimension", "one_form") if canonical else ()):
        if k in sysd:
            raise SceneError(f"system.{k} cannot go with {key} (a system of step maps has no formula: its maps "
                             "are code, run.step_maps)")
    if not canonical and not ("dimension" in sysd and "one_form" in sysd):
        raise SceneError("system.dimension and system.one_form go together (d coordinates and the batched "
                         "theta(q) -> (n, d) of maps step(q, h) -> q)")
    k = sysd["degrees_of_freedom" if canonical else "dimension"]
    if k < (1 if canonical else 2):
        raise SceneError(f"{key} must be a positive number{'' if canonical else ' ≥ 2'}, got {k}")
    if not canonical and k % 2:
        raise SceneError(f"system.dimension = {k} is odd: a one-form on an odd number of coordinates is degenerate "
                         "(dϑ has a kernel, no map can be symplectic for it); a degenerate Lagrangian needs an even d")
    _check_dimension_memory(key, k, 2 * k if canonical else k, points)
    period = sysd.get("period")
    if period is not None:
        if isinstance(period, list):
            if len(period) != k:
                raise SceneError(f"system.period has {len(period)} entries for {k} "
                                 f"{'positions' if canonical else 'coordinates'} (give one number, or one per "
                                 f"{'position' if canonical else 'coordinate'}, 0 where not periodic)")
        elif isinstance(period, bool) or not isinstance(period, (int, float)):
            raise SceneError(f"system.period must be a number or a list of them, got {period!r}")
    spec = {key: sysd[key] for key in ("name", "degrees_of_freedom", "dimension", "one_form", "period", "energy")
            if key in sysd}
    return _make_system(spec, {}, base), {}, spec


def _data_file(e, base, what):
    """A data file a scene names (a tableau, an equilibrium): the path as given if absolute, else next
    to the scene, then in the current directory; a one-line error, "``what`` 'e' not found", if none exists."""
    p = Path(e)
    cands = [p] if p.is_absolute() else [*([Path(base) / p] if base else []), Path.cwd() / p]
    odd = next((c for c in cands if c.exists() and not c.is_file()), None)
    found = next((c for c in cands if c.is_file()), None)
    if found is None and odd is not None:              # a FIFO (read for ever), a directory, a device
        raise SceneError(f"{what} '{e}' is not a regular file ({odd})")
    if found is None:
        raise SceneError(f"{what} '{e}' not found (looked in {', '.join(str(c.parent) for c in cands)})")
    return found


def _sets_of(data):
    """[loop] and [surface]: (LoopSpec or None, SurfaceSpec or None), at least one."""
    if "loop" not in data and "surface" not in data:
        raise SceneError("the scene needs a [loop] or a [surface] of sample points")
    loop = surface = None
    if "loop" in data:
        if "points" not in data["loop"]:
            raise SceneError("missing key 'loop.points'")
        loop = LoopSpec(**data["loop"])
        if loop.points < MIN_POINTS:
            raise SceneError(f"loop.points must be at least {MIN_POINTS} (a spectral value needs them), got {loop.points}")
    if "surface" in data:
        for k in ("n_sigma", "n_tau"):
            if k not in data["surface"]:
                raise SceneError(f"missing key 'surface.{k}'")
        surface = SurfaceSpec(**data["surface"])
        for k in ("n_sigma", "n_tau"):
            if getattr(surface, k) < MIN_POINTS:
                raise SceneError(f"surface.{k} must be at least {MIN_POINTS} (a spectral value needs them), got "
                                 f"{getattr(surface, k)}")
    for set_ in (loop, surface):
        if set_ is not None and set_.refine_to is not None and set_.levels == 0:
            raise SceneError(f"{set_.name}.refine_to = {set_.refine_to:,} allows no refinement: the {set_.name}'s "
                             f"first refinement has {set_.at_level(1).count:,} points "
                             f"({_grid_text(set_.at_level(1))}); give at least that, or leave refine_to out")
    return loop, surface


def _pairs_of(run, base):
    """[run]'s pairs: (step maps, tableau labels, {label: tableau file}, projections)."""
    maps = tuple(run.get("step_maps", ()))
    for key in ("h", "steps") + (() if maps else ("tableaus", "projections")):
        if key not in run:
            raise SceneError(f"missing key 'run.{key}'")
    if maps:
        from .plugins import is_spec
        for m in maps:
            if not is_spec(m):
                raise SceneError(f"run.step_maps: '{m}' must be module:function or file.py:function")
        if len({step_map_label(m) for m in maps}) != len(maps):
            raise SceneError("'run.step_maps' lists two functions of the same name")
    if maps and run.get("tableaus") == [] and run.get("projections", []) == []:
        run = {k: v for k, v in run.items() if k not in ("tableaus", "projections")}   # step maps only
    tabs, tableau_files = _tableaus(run["tableaus"], base) if "tableaus" in run else ((), {})
    projs = _names(run["projections"], projection_names(), "run.projections") if "projections" in run else ()
    if bool(tabs) != bool(projs):
        raise SceneError("run.tableaus and run.projections go together: give both or neither")
    return maps, tabs, tableau_files, projs


def _steps_of(run):
    """[run]'s (h, steps, output_every)."""
    h = float(run["h"])
    if not math.isfinite(h) or h <= 0:
        raise SceneError(f"run.h must be a finite positive number, got {run['h']!r}")
    if not H_RANGE[0] <= h <= H_RANGE[1]:
        raise SceneError(f"run.h = {run['h']!r} is outside [{H_RANGE[0]:g}, {H_RANGE[1]:g}] (the corrected forms "
                         "and the projections take h², which must be a normal double)")
    steps = run["steps"]
    if not 0 < steps <= MAX_STEPS:
        raise SceneError(f"run.steps must be between 1 and 2^53 = {MAX_STEPS:,} (step times exact in double), "
                         f"got {steps}")
    every = run.get("output_every", max(1, steps // 100))
    if every <= 0 or every > steps:
        raise SceneError(f"run.output_every must be between 1 and run.steps = {steps}, got {every}")
    return h, steps, every


def _output_of(out, name):
    """[output]: (path, checkpoint_seconds, checkpoints)."""
    path = out.get("path", f"{safe_name(name)}.h5")
    ck_seconds = float(out.get("checkpoint_seconds", CHECKPOINT_SECONDS))
    if not (math.isfinite(ck_seconds) and ck_seconds >= 0):
        raise SceneError(f"output.checkpoint_seconds must be a finite number ≥ 0, got {ck_seconds!r}")
    ck_mode = out.get("checkpoints", "in-file")
    if ck_mode not in ("in-file", "per-rank"):
        raise SceneError(f"output.checkpoints must be \"in-file\" or \"per-rank\", got {ck_mode!r}")
    return path, ck_seconds, ck_mode


def safe_name(name: str) -> str:
    """A scene name as a file name (the default output, name.h5): letters, digits, '-', '_' and '.'
    kept, anything else (a '/', a '..' path, a control character) as '_', no leading dot."""
    import re
    return re.sub(r"[^A-Za-z0-9._-]", "_", str(name)).lstrip(".") or "scene"


def step_map_label(spec):
    """A step map's pair label: its function's name."""
    return spec.rsplit(":", 1)[1]


def _make_system(spec, params, base):
    """A System from a scene's [system] table: built-in by name, from ϑ and H, a user function, or
    an equilibrium file."""
    if "equilibrium" in spec:
        from ..equilibrium import EquilibriumError, system_from_geqdsk
        rest = {k: v for k, v in params.items() if k != "mu"}
        try:
            made = system_from_geqdsk(_data_file(spec["equilibrium"], base, "system.equilibrium: file"),
                                      mu=params.get("mu", None), cocos=spec.get("cocos"))
            return made.with_params(**rest) if rest else made
        except EquilibriumError as exc:
            raise SceneError(f"system.equilibrium: {exc}") from None
        except ValueError as exc:
            raise SceneError(f"system.params: {exc}") from None
    if "boozer" in spec:
        from ..boozer import BoozerError, system_from_boozer
        rest = {k: v for k, v in params.items() if k != "mu"}
        try:
            made = system_from_boozer(_data_file(spec["boozer"], base, "system.boozer: file"), mu=params.get("mu", None),
                                      modes_tol=spec.get("modes_tol", 1e-4), grid=spec.get("grid", 96))
            return made.with_params(**rest) if rest else made
        except BoozerError as exc:
            raise SceneError(f"system.boozer: {exc}") from None
        except ValueError as exc:
            raise SceneError(f"system.params: {exc}") from None
    if "degrees_of_freedom" in spec or "one_form" in spec:
        from .phase_space import OneFormSpace, PhaseSpace
        energy = _load(spec["energy"], "system.energy", base) if "energy" in spec else None
        one_form = _load(spec["one_form"], "system.one_form", base) if "one_form" in spec else None
        try:                              # (the loads above name their key already)
            if "one_form" in spec:
                return OneFormSpace(spec["dimension"], one_form, spec.get("name", "one-form"), spec.get("period"), energy)
            return PhaseSpace(spec["degrees_of_freedom"], spec.get("name", "canonical"), spec.get("period"), energy)
        except ValueError as exc:
            raise SceneError(f"system.{exc}") from None
    if "function" in spec:
        from ..systems import System
        fn = _load(spec["function"], "system", base)
        try:
            made = fn(**params)
        except Exception as exc:          # the user's function may raise anything: one line naming it
            raise SceneError(f"system '{spec['function']}' failed: {type(exc).__name__}: {exc}") from None
        if not isinstance(made, System):
            raise SceneError(f"system '{spec['function']}' must return an integrators.System, got {type(made).__name__}")
        try:
            return made.validate()
        except ValueError as exc:
            raise SceneError(f"system '{spec['function']}': {exc}") from None
    if "coordinates" in spec:
        return _system_from_table(spec, params)
    try:
        return builtin_system(spec["name"], **params)
    except ValueError as exc:
        raise SceneError(f"system.params: {exc}") from None


def _system_from_table(spec, params):
    """ϑ and H (and optionally a symmetry or momentum, and a domain) from the scene, through the
    restricted parser (integrators.expressions): nothing in the file is ever executed."""
    import sympy
    from ..systems import system_from
    from ..systems import refuse_large
    coords = spec["coordinates"]
    if not coords or not all(isinstance(c, str) and c.isidentifier() for c in coords):
        raise SceneError(f"system.coordinates must be a list of names, got {coords!r}")
    try:
        refuse_large(len(coords), "system.coordinates")
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    if len(set(coords)) != len(coords):
        raise SceneError("system.coordinates lists a name twice")
    clash = sorted(set(coords) & set(params))
    if clash:
        raise SceneError(f"system.params.{clash[0]}: '{clash[0]}' is also a coordinate")
    for key in ("theta", "H"):
        if key not in spec:
            raise SceneError(f"missing key 'system.{key}' (a system from system.coordinates needs theta and H)")
    for key in ("theta", "symmetry", "domain"):
        if key in spec and not all(isinstance(e, str) for e in spec[key]):
            raise SceneError(f"system.{key} must be a list of expression strings, got {spec[key]!r}")
    for key in ("theta", "symmetry"):
        if key in spec and len(spec[key]) != len(coords):
            raise SceneError(f"system.{key} has {len(spec[key])} entries for {len(coords)} coordinates")
    if "symmetry" in spec and "momentum" in spec:
        raise SceneError("give system.symmetry or system.momentum, not both")
    for k, v in params.items():
        if isinstance(v, tuple):
            raise SceneError(f"system.params.{k}: a system from expressions takes numbers, got a list")
    q = [sympy.Symbol(c, real=True) for c in coords]
    pars = {sympy.Symbol(k, real=True): float(v) for k, v in params.items()}
    try:
        return system_from(spec["theta"], spec["H"], q, name=spec.get("name", "user"), params=pars,
                           symmetry=spec.get("symmetry"), domain=spec.get("domain", ()),
                           momentum=spec.get("momentum"))
    except ValueError as exc:
        raise SceneError(str(exc).replace(f"system {spec.get('name', 'user')}: ", "system.")) from None


def _tableau_file(path):
    from ..tableaus import tableau_from_file
    try:
        return tableau_from_file(path)
    except ValueError as exc:
        raise SceneError(f"run.tableaus: {exc}") from None


def _tableaus(entries, base):
    """run.tableaus: built-in names and tableau TOML files (looked up next to the scene, then in the
    current directory).  Returns the pair labels (a file's tableau is labelled by its name) and
    {label: path} of the files."""
    if not isinstance(entries, list) or not entries:
        raise SceneError("'run.tableaus' must be a non-empty list")
    labels, files = [], {}
    for e in entries:
        if not isinstance(e, str):
            raise SceneError(f"'run.tableaus' must be a list of strings, got {e!r}")
        if e.endswith(".toml"):
            found = _data_file(e, base, "run.tableaus: tableau file")
            label = _tableau_file(found).name
            if not label or "/" in label or label in SYSTEM_NAMES or not label.isprintable():
                raise SceneError(f"run.tableaus: '{e}' has the unusable name {label!r}")
            files[label] = str(found.resolve())
        else:
            try:
                builtin_tableau(e)
            except ValueError as exc:
                raise SceneError(f"run.tableaus: {exc}") from None
            label = e
        if label in labels:
            raise SceneError(f"'run.tableaus' lists the tableau '{label}' twice")
        labels.append(label)
    return tuple(labels), files


MEMORY_BASE = 400 * 2**20        # the interpreter, numpy, numba, MPI and HDF5 of one rank (measured ~300 MiB)


def memory_per_point(d, s, precision="double", factors=True) -> tuple:
    """(bytes one sample point costs the rank that advances it, bytes of its state).  The cost: its
    state (:class:`integrators.engine.State`), Newton factors of a pair with s stages (assuming the
    largest system a projection solves, (s + 2)·d unknowns) and its part of the invariants'
    transforms (about 20 arrays of d doubles).  For GLRK2 on a 4-dimensional system this gives
    3.0 KiB; measured 1.8-2.3 KiB (docs/benchmarks.md).  ``factors`` False: a scene of step maps
    only, which hold no Newton factors (O(d) a point)."""
    from ..engine import State
    nz = (s + 2) * d
    def size(dd):
        return sum(int(np.prod(shape)) * np.dtype(dt).itemsize for shape, dt in State.schema(1, dd, s, precision).values())
    # every field is linear in d: read off d = 1 and 2, never a state of the (perhaps huge) d itself
    one, two = size(1), size(2)
    state = one + (two - one) * (d - 1)
    factors = 8 * (nz * nz + nz) * (2 if precision == "double-double" else 1) if factors else 0
    return state + factors + 8 * 20 * d, state


def available_memory() -> float | None:
    """Bytes of memory available to new work on this node (MemAvailable), or None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def _local_ranks() -> int:
    """Ranks that share this node under mpiexec (MPICH and Open MPI say so in the environment), else 1."""
    for key in ("MPI_LOCALNRANKS", "OMPI_COMM_WORLD_LOCAL_SIZE"):
        try:
            return max(1, int(os.environ[key]))
        except (KeyError, ValueError):
            pass
    return 1


def _check_dimension_memory(key, value, d, points):
    """Refuse, naming ``key``, a dimension d whose ``points`` sample points (the scene's sets, or the
    fewest a set may have) cannot fit in this node's memory, before the system or any point is
    built (a period of d entries, the points themselves); :func:`_check_memory` judges the whole
    scene once it is built."""
    free = available_memory()
    per_point, state = memory_per_point(d, 1, "double", factors=False)
    need = (8 * 16 * d + per_point + state) * points
    if free is not None and need > free:
        raise SceneError(f"{key} = {value:,} ({d:,} coordinates) needs about {need / 2**30:,.1f} GiB of memory for "
                         f"{points:,} sample points; this node has {free / 2**30:,.1f} GiB available: a smaller "
                         "system, or audit its map on a loop of fewer points (poincare audit --map)")


def _check_memory(scene, system):
    """Refuse, naming the key, a scene whose points cannot fit in this node's memory: every rank
    holds all sample points (q₀, the sets' values) and its share of the states, rank 0 the whole
    checkpoint as well.  Checked before any point is sampled or any file is written."""
    free = available_memory()
    if free is None:
        return
    n, d = scene.n_points, system.d
    s = scene.max_stages
    local = _local_ranks()
    per_point, state = memory_per_point(d, s, scene.precision, factors=bool(scene.tableaus))
    # every local rank holds all points' samples and set values (~16 arrays of d doubles) and
    # advances its share; rank 0 also gathers every point's state for a checkpoint
    need = local * (MEMORY_BASE + 8 * 16 * d * n) + (per_point + state) * n
    # a refining set's new points (up to refine_to) are advanced by one rank, its whole finest grid
    # held while its invariants are taken
    new = {spec.name: spec.at_level(spec.levels).count - spec.count for spec, _ in scene.sample_sets}
    need += sum((per_point + 8 * 16 * d) * m for m in new.values())
    if need <= free:
        return
    big = max((sp for sp, _ in scene.sample_sets), key=lambda sp: sp.count + new[sp.name])
    if new[big.name]:
        key = f"{big.name}.refine_to = {big.refine_to:,} (up to {big.at_level(big.levels).count:,} points)"
        raise SceneError(f"{key} needs about {need / 2**30:,.1f} GiB of memory; this node has "
                         f"{free / 2**30:,.1f} GiB available: give a smaller refine_to")
    key = ("loop.points = " if big.name == "loop" else
           f"surface.n_sigma × surface.n_tau = {big.n_sigma} × {big.n_tau} = ") + f"{big.count:,}"
    raise SceneError(f"{key} needs about {need / 2**30:,.1f} GiB of memory for {n:,} points "
                     f"({per_point / 1024:.1f} KiB a point{f' on {local} ranks' if local > 1 else ''}); "
                     f"this node has {free / 2**30:,.1f} GiB available: use fewer points")


def _check_points(scene, system):
    specs = [(spec, spec.name) for spec, _ in scene.sample_sets]
    specs += [(spec.at_level(spec.levels), f"{spec.name} refined to {spec.at_level(spec.levels).count:,} points")
              for spec, _ in scene.sample_sets if spec.levels]        # the finest level a refinement may reach
    for spec, what in specs:
        try:
            q = np.asarray(spec.sample(scene.base), dtype=float)
        except SceneError:
            raise
        except Exception as exc:      # a user shape function may raise anything: one line naming it
            if ":" not in spec.shape:
                msg = str(exc)
                raise SceneError(f"{what}.{msg}" if msg.startswith("params") else f"{what}: {msg}") from None
            contract = ("f(tau, **params) with tau the (N,) array j/N in [0, 1), returning (N, d)"
                        if spec.name == "loop" else "f(sigma, tau, **params) with two (n_sigma, n_tau) arrays of "
                        "Chebyshev points in [0, 1], returning (n_sigma, n_tau, d)")
            raise SceneError(f"{what}.shape '{spec.shape}' failed: {type(exc).__name__}: {exc} (a {what} shape "
                             f"is called as {contract})") from None
        want = spec.grid + (system.d,)
        if q.shape[-1:] == (system.d,) and q.shape != want:
            raise SceneError(f"{what}: the shape gives points of shape {q.shape}, the scene needs {want}")
        q = q.reshape(-1, q.shape[-1])
        if q.shape[1] != system.d:
            raise SceneError(f"{what}: points have dimension {q.shape[1]}, system {system.name} needs {system.d}")
        bad = ~system.in_domain(q)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise SceneError(f"{what}: point {k} = {q[k].tolist()} is not finite or outside the domain of {system.name}")
        if np.all(q == q[0]):             # every point the same: the invariant is 0, no relative error exists
            raise SceneError(f"{what}: all {q.shape[0]:,} points are the same point {q[0].tolist()} (a set of zero "
                             "extent: its invariant is 0 and no relative error of it can be measured); give the "
                             "shape radii or a size > 0")
        if getattr(system, "black_box", False):
            _check_energy(system, q, what)
            _check_one_form(system, q, what)
            continue
        with np.errstate(all="ignore"):
            for key, values in (("H", system.H(q)), ("theta", system.theta(q)), ("H's gradient", system.dH(q))):
                bad = ~np.isfinite(values).reshape(q.shape[0], -1).all(axis=1)
                if bad.any():
                    k = int(np.flatnonzero(bad)[0])
                    raise SceneError(f"{what}: system.{key} is not finite at point {k} = {q[k].tolist()} "
                                     f"(outside where the expression is defined?)")
            cond = np.linalg.cond(system.Omega(q))
        bad = ~(cond < 1e12)
        if bad.any():                     # the equations of motion need Ω̄ invertible (eq:euler_lagrange_equations_matrix)
            k = int(np.flatnonzero(bad)[0])
            raise SceneError(f"{what}: Ω̄ = dϑ is singular at point {k} = {q[k].tolist()} (condition number "
                             f"{cond[k]:.1e}); check system.theta")


def _check_one_form(system, q, what):
    """A system of step maps with a one-form of code: system.one_form at a set's points, (n, d) finite
    values, or a one-line error naming it (the maps' runs would all fail with no word of why)."""
    if getattr(system, "one_form", None) is None:
        return
    try:
        with np.errstate(all="ignore"):
            t = system.theta(q)
    except ValueError as exc:         # OneFormSpace.theta's own check names system.one_form
        raise SceneError(f"{what}: {exc}") from None
    except Exception as exc:          # the user's function may raise anything: one line naming it
        raise SceneError(f"{what}: system.one_form failed: {type(exc).__name__}: {exc}") from None
    bad = ~np.isfinite(t).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise SceneError(f"{what}: system.one_form is not finite at {int(bad.sum())} of {q.shape[0]} points (the first, "
                         f"point {k} = {q[k].tolist()})")


def _check_energy(system, q, what):
    """A canonical phase space's system.energy at a set's points: (n,) finite values, or a one-line error."""
    if system.energy is None:
        return
    try:
        with np.errstate(all="ignore"):
            e = system.H(q)
    except Exception as exc:          # the user's function may raise anything: one line naming it
        raise SceneError(f"{what}: system.energy failed: {type(exc).__name__}: {exc}") from None
    bad = ~np.isfinite(e)
    if bad.any():
        raise SceneError(f"{what}: system.energy is not finite at point {int(np.flatnonzero(bad)[0])}")


# (a tableau file is compared here by its label, the tableau's name: where the file lies may differ
# between a run and its resume, which finds it next to the output or in the current directory; its
# coefficients are compared by the driver against the digests stored in the run file)
_KEYS = {"system_name": "system.name", "system_params": "system.params", "system_spec": "system",
         "loop": "loop", "surface": "surface", "step_maps": "run.step_maps",
         "tableaus": "run.tableaus", "projections": "run.projections", "h": "run.h", "steps": "run.steps",
         "output_every": "run.output_every", "forms": "run.forms", "diagnostics": "run.diagnostics",
         "store_points": "run.store_points", "precision": "run.precision",
         "jacobian_refresh": "run.jacobian_refresh"}


def scene_differences(a: Scene, b: Scene) -> list:
    """The scene keys whose parsed values differ between a and b and change the results (not the
    name, the output path, comments or formatting)."""
    return [key for field, key in _KEYS.items() if getattr(a, field) != getattr(b, field)]


def builtin_scenes() -> dict:
    """{name: path} of the scenes shipped with the package."""
    return {p.stem: p for p in sorted(SCENE_DIR.glob("*.toml"))}


def load_scene(spec: str | None) -> Scene:
    """A built-in scene by name, a TOML file by path, or the default scene (None)."""
    text, path = scene_source(spec)
    return parse_scene(text, origin=str(path))


def scene_source(spec: str | None) -> tuple:
    """(TOML text, path) of a built-in scene by name, a TOML file by path, or the default (None)."""
    spec = spec or "default"
    scenes = builtin_scenes()
    if spec in scenes:
        path = scenes[spec]
    else:
        path = Path(spec)
        if not path.exists():
            raise SceneError(f"scene '{spec}' is neither a file nor a built-in scene ({', '.join(scenes)})")
        if not path.is_file():            # a directory, a FIFO (reading it would wait for ever), a device
            raise SceneError(f"scene '{spec}' is not a regular file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(f"scene '{spec}' is not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    except OSError as exc:
        raise SceneError(f"cannot read scene '{spec}': {exc.strerror or exc}") from None
    return text, path


def _file_scene_sets(loop_center, loop_radius, surface_center, surface_side, h, steps, name, output) -> str:
    """The [loop] … [output] tables of a scene written from a file's defaults (:func:`boozer_scene`,
    :func:`equilibrium_scene`): a 2,048-point circle refining to 8,192, a 24 × 24 square refining to
    47 × 47, both in the plane (0, 1), GLRK1 and GLRK2 with every projection, every form."""
    def vec(*x):
        return ", ".join(repr(float(c)) for c in x)
    return f'''[loop]
shape = "ellipse"
points = 2048
refine_to = 8192
params = {{ d = 4, center = [{vec(*loop_center)}], radii = [{vec(loop_radius, loop_radius)}], plane = [0, 1] }}

[surface]
shape = "rectangle"
n_sigma = 24
n_tau = 24
refine_to = 2209
params = {{ d = 4, center = [{vec(*surface_center)}], size = [{vec(surface_side, surface_side)}], plane = [0, 1] }}

[run]
tableaus = ["GLRK1", "GLRK2"]
projections = ["none", "standard", "symmetric", "symplectic", "midpoint"]
h = {h!r}
steps = {int(steps)}
output_every = {max(1, int(steps) // 100)}
forms = ["canonical", "noncanonical", "corrected"]

[output]
path = "{output or name + '.h5'}"
'''


def boozer_scene(path, *, name=None, steps=1000, output=None, modes_tol=1e-4, grid=96) -> str:
    """The TOML text of a scene built from a boozmn file's own defaults (docs/stellarators.md), as
    :func:`equilibrium_scene` does for G-EQDSK files: the loop (2,048 points, refining to 8,192) a
    circle in the axis chart's (x, y) of radius r₁/5000 (r₁ = √(2ψ₀), the boundary's radius there)
    around the passing guiding centre ``defaults["q0"]``, the surface (24 × 24, refining to 47 × 47) a
    square of side r₁/2500 around the trapped one, h = ``defaults["h"]``, GLRK1 and GLRK2 with every
    projection, every form.  Save it, edit it, run it: ``poincare run file.toml``."""
    from ..boozer import system_from_boozer
    sy = system_from_boozer(path, modes_tol=modes_tol, grid=grid)
    r1 = math.sqrt(2 * sy.param_values["psi_edge"])
    x0, y0, z0, rho0 = sy.defaults["q0"]
    rt = sy.defaults["trapped"][3]
    stem = Path(str(path)).name
    name = name or "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in Path(stem).stem) or "boozer"
    return f'''# Guiding centres in {stem}, from the system's own defaults (integrators.service.scene.boozer_scene).
# {'; '.join(sy.defaults['notes'])}
name = "{name}"

[system]
boozer = "{stem}"
modes_tol = {float(modes_tol)!r}
grid = {int(grid)}
params = {{ mu = {sy.param_values['mu']:.17g} }}

{_file_scene_sets((x0, y0, z0, rho0), r1 / 5000, (x0, y0, z0, rt), r1 / 2500, sy.defaults['h'], steps, name, output)}'''


def equilibrium_scene(path, cocos=None, *, name=None, steps=1000, output=None) -> str:
    """The TOML text of a scene built from a G-EQDSK file's own defaults (docs/equilibria.md), as
    the built-in ``freegs_dn`` is built from its file: the loop (2,048 points, refining to 8,192) a
    circle in (R, Z) of radius a/5000 (a the boundary's half-width) around the passing guiding centre
    ``defaults["q0"]``, the surface (24 × 24, refining to 47 × 47) a square of side a/2500 around the
    trapped one ``defaults["trapped"]`` at the same place, h = ``defaults["h"]``, GLRK1 and GLRK2 with every
    projection, every form.  Save it, edit it, run it: ``poincare run file.toml``."""
    from ..equilibrium import system_from_geqdsk
    sy = system_from_geqdsk(path, cocos=cocos)
    p = sy.param_values
    a = (p["R_max"] - p["R_min"]) / 2
    R0, Z0, _, u0 = sy.defaults["q0"]
    ut = sy.defaults["trapped"][3]
    stem = Path(str(path)).name
    name = name or "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in Path(stem).stem) or "equilibrium"
    cocos_line = (f"cocos = {cocos}" if cocos is not None else
                  f"# cocos = {sy.defaults['cocos']}          # identified from the file at each run: uncomment to fix it")
    return f'''# Guiding centres in {stem}, from the system's own defaults (integrators.service.scene.equilibrium_scene).
# {'; '.join(sy.defaults['notes'])}
name = "{name}"

[system]
equilibrium = "{stem}"
{cocos_line}
params = {{ mu = {p['mu']:.17g} }}

{_file_scene_sets((R0, Z0, 0.0, u0), a / 5000, (R0, Z0, 0.0, ut), a / 2500, sy.defaults['h'], steps, name, output)}'''
