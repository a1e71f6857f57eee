"""Scenes written from a field file's defaults (:func:`boozer_scene`, :func:`equilibrium_scene`, both
also reached as ``integrators.service.scene.…``): the TOML text of a scene whose sets sit where the
file's field is defined, for the user to read, edit and run (docs/stellarators.md, docs/equilibria.md).
"""
from __future__ import annotations

import math
from pathlib import Path


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


def boozer_scene(path, *, name=None, steps=1000, output=None, modes_tol=1e-4, grid=96, field="3d") -> str:
    """The TOML text of a scene built from a boozmn file's own defaults (docs/stellarators.md), as
    :func:`equilibrium_scene` does for G-EQDSK files: the loop (2,048 points, refining to 8,192) a
    circle in the axis chart's (x, y) of radius r₁/5000 (r₁ = √(2ψ₀), the boundary's radius there)
    around the passing guiding centre ``defaults["q0"]``, the surface (24 × 24, refining to 47 × 47) a
    square of side r₁/2500 around the trapped one, h = ``defaults["h"]``, GLRK1 and GLRK2 with every
    projection, every form.  Save it, edit it, run it: ``poincare run file.toml``."""
    from ..boozer import system_from_boozer
    sy = system_from_boozer(path, modes_tol=modes_tol, grid=grid, field=field)
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
field = "{sy.defaults['field']}"
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
