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
    grid = 96                             # optional: the (x, y) grid of |B|, points a side
    field = "3d"                          # optional: |B| as one spline in (x, y, ζ), or "harmonics"
    grid_zeta = 56                        # optional: the 3-D field's ζ nodes a field period (default 8 a harmonic)
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
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..engine import PRECISIONS, Tolerances
from ..projections import admission, names as projection_names
from ..tableaus import tableau as builtin_tableau
from invariants.forms import MIN_POINTS
from .scene_checks import SceneError, _check_memory, _check_points
from .scene_files import boozer_scene, equilibrium_scene  # noqa: F401 (documented as integrators.service.scene.…)
from .scene_systems import _load, _make_system, _system_of, _tableau_file, _tableaus

FORMS = ("canonical", "noncanonical", "corrected")
DIAGNOSTICS = ("energy", "momentum", "constraint")
SCENE_DIR = Path(__file__).parent / "scenes"


CHECKPOINT_SECONDS = 60.0          # default of output.checkpoint_seconds
MAX_STEPS = 2**53                  # run.steps and --steps: every step number k, and so t = k·h, exact in double
H_RANGE = (1e-150, 1e150)          # run.h: h² a normal double, t = k·h finite for every k ≤ MAX_STEPS


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
               "boozer": str, "modes_tol": float, "grid": int, "field": str, "grid_zeta": int,
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

