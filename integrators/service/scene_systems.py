"""The system and tableaus a scene names, built: a built-in system with its parameters, a table of
expressions (restricted parser), an equilibrium or Boozer file, a phase space of step maps, or a
file.py:function; tableaus by name or from a TOML file beside the scene.  Files and code named in a
scene are looked up next to the scene file, then in the current directory (:func:`_load`).
"""
from __future__ import annotations

from pathlib import Path

from ..systems import SYSTEM_NAMES, system as builtin_system
from ..tableaus import tableau as builtin_tableau
from invariants.forms import MIN_POINTS
from .scene_checks import SceneError, _check_dimension_memory, _finite


def _load(spec, key, base=None):
    """The user's callable ``spec`` (file.py:function, module:function) named by scene key ``key``;
    a SceneError in one line where it cannot be loaded (plugins.load_callable)."""
    from .plugins import load_callable
    try:
        return load_callable(spec, key, base)
    except ValueError as exc:
        raise SceneError(str(exc)) from None


def _system_of(sysd, base, points=MIN_POINTS):
    """[system]: (the System, its parameters, the user system's spec or {}); ``points``: the sample
    points the scene asks for, as far as its tables say before they are checked (a phase space of
    step maps judges its memory by them before it is built)."""
    if "equilibrium" in sysd:
        return _equilibrium_of(sysd, base)
    if "boozer" in sysd:
        return _boozer_of(sysd, base)
    for k in ("modes_tol", "grid", "field", "grid_zeta"):
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
    """[system] boozer = "boozmn_x.nc" (looked up as an equilibrium file is), modes_tol, grid, field,
    grid_zeta, params = {mu = …}: the guiding centre in that Boozer field (integrators.boozer).  The file is
    data: it is read, never run."""
    e, digest, params = _field_file(sysd, base, "boozer", ("equilibrium", "cocos"))
    tol = sysd.get("modes_tol", 1e-4)
    if not (_finite(tol) and 0 <= tol < 1):
        raise SceneError(f"system.modes_tol must be a number in [0, 1), got {tol!r}")
    grid = sysd.get("grid", 96)
    if not 16 <= grid <= 1024:
        raise SceneError(f"system.grid must be between 16 and 1024 points a side, got {grid}")
    from ..boozer import FIELDS
    field = sysd.get("field", "3d")
    if field not in FIELDS:
        raise SceneError(f"system.field must be one of {', '.join(map(repr, FIELDS))}, got {field!r}")
    grid_zeta = sysd.get("grid_zeta", None)
    if grid_zeta is not None and not 6 <= grid_zeta <= 4096:
        raise SceneError(f"system.grid_zeta must be between 6 and 4096 points a field period, got {grid_zeta}")
    spec = {"boozer": e, "modes_tol": float(tol), "grid": int(grid), "field": field, "sha256": digest}
    if grid_zeta is not None:
        spec["grid_zeta"] = int(grid_zeta)
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
                                      modes_tol=spec.get("modes_tol", 1e-4), grid=spec.get("grid", 96),
                                      field=spec.get("field", "3d"), grid_zeta=spec.get("grid_zeta", None))
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
