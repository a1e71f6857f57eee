"""Scenes, tableau files and expressions: data never runs code, every mistake is one line naming the key
before any file is written, and code a scene names runs only from its folder (integrators/service/scene.py,
expressions.py, tableaus.py, plugins.py)."""
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
import sympy

import integrators
from integrators.cli import main as cli_main
from integrators.expressions import ExpressionError, parse_expression, parse_number
from integrators.service import driver
from integrators.service.scene import builtin_scenes, load_scene, parse_scene, SceneError
from integrators.tableaus import tableau, tableau_from_file
from helpers import BIN, edit, GC, LV, MAPS, one_line, poincare, SHAPES_CIRCLE, SHAPES_TAU, SMALL, STUCK, USER



@pytest.mark.parametrize("text", [
    '__import__("os").system("touch PWNED")',
    'open("PWNED", "w").write("x")',
    "(lambda: 1)()",
    "[c for c in ().__class__.__base__.__subclasses__()]",
    "().__class__",
    "exec('1')",
    "sqrt.__globals__",
    "'1' + '2'",
    "1 if 1 else 2",
])
def test_a_tableau_file_holding_code_runs_nothing(tmp_path, monkeypatch, text):
    monkeypatch.chdir(tmp_path)
    f = tmp_path / "evil.toml"
    f.write_text(f"a = [[{text!r}]]\nb = [1]\nc = [0.5]\n".replace("'", "'''", 0))
    with pytest.raises(ValueError, match=r"evil.toml.*a\[0\]\[0\]"):
        tableau_from_file(f)
    assert not (tmp_path / "PWNED").exists()


def test_parser_reads_exact_numbers():
    assert parse_expression("1/3", "k") == sympy.Rational(1, 3)
    assert parse_expression("2^3 - 3**2", "k") == -1
    assert parse_expression("(1/2 - sqrt(15)/10)", "k") == sympy.Rational(1, 2) - sympy.sqrt(15) / 10
    assert parse_expression(0.1, "k") == sympy.Rational("0.1")
    x = sympy.Symbol("x")
    assert parse_expression("exp(-x^2) * pi", "k", {"x": x}) == sympy.exp(-x ** 2) * sympy.pi
    # a caller's own name shadows a constant: a parameter called pi is that parameter
    pi = sympy.Symbol("pi")
    assert parse_expression("2*pi", "k", {"pi": pi}) == 2 * pi


@pytest.mark.parametrize("text,msg", [
    ("1/0", "not a finite number"),
    ("x + 1", "unknown name 'x'"),
    ("9**9**9", "exponent"),
    ("((2**64)**64)**64", "power larger"),
    ("1 +", "cannot read"),
    ("sqrt", "without a call"),
    ("log(-1)", "not a finite real"),
])
def test_parser_errors_name_the_key(text, msg):
    with pytest.raises(ExpressionError, match=msg) as e:
        parse_number(text, "my.toml: b[1]", 30)
    assert str(e.value).startswith("my.toml: b[1]: ")


def test_a_tableau_entry_1_over_0_names_the_key(tmp_path):
    f = tmp_path / "t.toml"
    f.write_text('a = [["1/0"]]\nb = [1]\nc = ["1/2"]\n')
    with pytest.raises(ValueError, match=r"a\[0\]\[0\]: '1/0' is not a finite number"):
        tableau_from_file(f)


def test_a_lobatto_IIIA_tableau_without_d_is_refused_naming_d(tmp_path):
    ref = tableau("LobIIIA3")
    rows = [[str(sympy.nsimplify(float(x))) for x in row] for row in ref.a]
    f = tmp_path / "lob.toml"
    f.write_text(f"a = {rows}\nb = ['1/6', '2/3', '1/6']\nc = ['0', '1/2', '1']\n")
    with pytest.raises(ValueError, match=r"singular.*give d"):
        tableau_from_file(f)
    d = [str(sympy.nsimplify(float(x))) for x in ref.d]
    f.write_text(f"a = {rows}\nb = ['1/6', '2/3', '1/6']\nc = ['0', '1/2', '1']\nd = {d}\n")
    t = tableau_from_file(f)
    assert np.max(np.abs(t.a - ref.a)) < 1e-16 and np.max(np.abs(t.d - ref.d)) < 1e-15


def test_system_from_with_hostile_names_gives_hand_values():
    q, p, out, np_ = sympy.symbols("q p out np")
    e, pi, sq, lg, ex, lam = sympy.symbols("e pi sqrt log exp lambda")
    theta = [-p * e / 2, q * pi / 2, -np_ * sq, out * lg]
    H = (q ** 2 + p ** 2) * ex / 2 + lam * (out ** 2 + np_ ** 2)
    s = integrators.system_from(theta, H, [q, p, out, np_],
                                params={e: 2.0, pi: 3.0, sq: 5.0, lg: 7.0, ex: 0.5, lam: 0.25})
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert s.theta(x).tolist() == [-2.0, 1.5, -20.0, 21.0]
    assert s.H(x) == 7.5
    assert s.dH(x).tolist() == [0.5, 1.0, 1.5, 2.0]
    assert s.Omega(x)[0, 1] == 2.5              # ∂_q ϑ_p − ∂_p ϑ_q = π/2 + e/2 = 1.5 + 1


def test_system_from_coordinate_named_q_and_x0():
    # the old generator called its argument q and its subexpressions _x0, _x1, ...
    q, x0, y, z = sympy.symbols("q _x0 y z")
    s = integrators.system_from([2 * q, 4 * q, 6 * q, x0], q * x0 + y * z, [q, x0, y, z])
    pt = np.array([1.0, 5.0, 2.0, 3.0])
    assert s.theta(pt).tolist() == [2.0, 4.0, 6.0, 5.0] and s.H(pt) == 11.0


def test_system_from_reads_strings_with_the_restricted_parser(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    x, y = sympy.symbols("x y")
    s = integrators.system_from(["-y/2", "x/2"], "(x^2 + y^2)/2", [x, y])
    assert s.H(np.array([3.0, 4.0])) == 12.5
    with pytest.raises(ValueError, match=r"theta\[0\].*not allowed"):
        integrators.system_from(['__import__("os").system("touch PWNED")', "x"], "x", [x, y])
    assert not (tmp_path / "PWNED").exists()


@pytest.mark.parametrize("name", ["default", "point_vortices", "lotka_volterra", "guiding_centre_tokamak",
                                  "paper_poincare", "massless_charged_particle", "lotka_volterra_4d",
                                  "guiding_centre_solovev", "charged_particle_tokamak"])
def test_builtin_scenes_start_resolved(name):
    """Every shipped scene's sets resolve their invariants at t = 0 (the whole run: docs/scenes.md)."""
    from invariants import UNDER_RESOLVED
    from invariants.spectral import loop_tail, surface_tail
    sc = load_scene(name)
    sy = sc.system()
    if sc.loop is not None:
        q = sc.loop_points()
        assert max(loop_tail(q), loop_tail(sy.theta(q))) < UNDER_RESOLVED / 10
    if sc.surface is not None:
        q = sc.surface_points()
        assert max(surface_tail(q), surface_tail(sy.theta(q))) < UNDER_RESOLVED / 10


@pytest.mark.parametrize("name", ["massless_charged_particle", "lotka_volterra_4d", "guiding_centre_solovev",
                                  "charged_particle_tokamak"])
def test_the_new_systems_scenes_run_ok_through_the_driver(name, tmp_path):
    """The first 40 steps of each new system's scene (2-, 4- and 6-dimensional) through the driver and
    HDF5: every pair ok, and the pairs docs/scenes.md names as keeping a form keep it to round-off."""
    import dataclasses
    sc = load_scene(name)
    sc = dataclasses.replace(sc, steps=40, output_every=20)
    summaries = driver.run(sc, tmp_path / "x.h5", progress=False)
    assert {s.status for s in summaries} == {"ok"}
    run = integrators.service.read_run(tmp_path / "x.h5")
    for pair in run.pairs:
        kept = ("canonical" if pair.endswith("-none") else "corrected" if pair.endswith("-symplectic") else None)
        if kept:
            for inv in ("I1", "I2"):
                assert np.max(np.abs(run[pair].relative_error(inv, kept))) < 1e-11, (pair, inv)


def test_file_py_and_module_shapes_in_scenes_and_a_raising_shape(tmp_path, monkeypatch):
    (tmp_path / "myshapes.py").write_text(SHAPES_CIRCLE)
    sub = tmp_path / "scenes"
    sub.mkdir()
    text = GC.replace("[loop]\npoints = 64", '[loop]\nshape = "myshapes.py:circle"\npoints = 64').replace(
        "[surface]\nn_sigma = 20\nn_tau = 20\n", "")
    (tmp_path / "a.toml").write_text(text)
    sc = load_scene(str(tmp_path / "a.toml"))          # file.py next to the scene file
    tau = np.arange(64) / 64
    assert np.allclose(sc.loop_points()[:, 0], 0.3 * np.cos(2 * np.pi * tau))
    monkeypatch.chdir(tmp_path)                        # module:function from the current directory
    (sub / "b.toml").write_text(text.replace("myshapes.py:circle", "myshapes:circle"))
    assert load_scene(str(sub / "b.toml")).loop_points().shape == (64, 4)
    (sub / "c.toml").write_text(text.replace("myshapes.py:circle", "myshapes:boom"))
    with pytest.raises(SceneError, match=r"^loop.shape 'myshapes:boom' failed: RuntimeError: shape exploded \(a loop shape is called as f\(tau"):
        load_scene(str(sub / "c.toml"))


def test_one_admission_rule_for_integrate_scenes_and_audit(tmp_path):
    """θ-method with θ = 3/4 has R(∞) = −1/3: the σ = R(∞) projections need ±1, everywhere alike."""
    from integrators import audit
    from integrators.projections import admission
    tab = integrators.tableau_from_arrays("theta34", [["3/4"]], ["1"], ["3/4"])
    assert abs(tab.R_inf + 1 / 3) < 1e-15
    sy = integrators.system("guiding_centre_symmetric")
    for proj in ("symmetric", "symplectic", "midpoint"):
        assert "needs |R(∞)| = 1" in admission(tab, proj)
        with pytest.raises(ValueError, match=r"needs \|R\(∞\)\| = 1"):
            integrators.integrate(sy, [0.5, 0.0, 0.0, 0.5], tableau=tab, projection=proj, h=1.0, steps=1)
    assert admission(tab, "none") is None and admission(tab, "standard") is None
    f = tmp_path / "theta34.toml"
    f.write_text('a = [["3/4"]]\nb = ["1"]\nc = ["3/4"]\n')
    assert [c.projection for c in audit.candidates_from(str(f))] == ["none", "standard"]
    with pytest.raises(SceneError, match=r"needs \|R\(∞\)\| = 1 but RadIIA2"):
        parse_scene(GC.replace('tableaus = ["GLRK2"]', 'tableaus = ["RadIIA2"]').replace(
            '"symmetric", "symplectic"', '"standard", "symplectic"'))


def test_vector_parameters_in_scenes_as_in_python():
    text = """
[system]
name = "point_vortices"
params = { gamma = [0.2, 0.1] }
[loop]
shape = "ellipse"
points = 16
params = { d = 4, center = [1.0, 0.1, 1.0, -0.1], radii = [0.002, 0.002], plane = [0, 1] }
[run]
tableaus = ["GLRK2"]
projections = ["symmetric"]
h = 0.1
steps = 2
"""
    sy = parse_scene(text).system()
    assert sy.param_values == {"gamma1": 0.2, "gamma2": 0.1}
    assert sy.param_values == integrators.system("point_vortices", gamma=(0.2, 0.1)).param_values
    with pytest.raises(SceneError, match=r"system.params: .*'gamma' needs 2 values"):
        parse_scene(text.replace("[0.2, 0.1]", "[0.2, 0.1, 0.3]"))
    with pytest.raises(SceneError, match=r"system.params.gamma must be a finite number or a list"):
        parse_scene(text.replace("[0.2, 0.1]", '[0.2, "x"]'))


@pytest.fixture(scope="module")
def finished_oscillator(tmp_path_factory):
    """The bytes of a finished run of the oscillator scene (made once for the tests below)."""
    where = tmp_path_factory.mktemp("finished")
    (where / "osc.toml").write_text(USER)
    assert poincare("run", "osc.toml", "-o", "out.h5", "-q", cwd=where).returncode == 0
    return (where / "out.h5").read_bytes()


@pytest.mark.parametrize("H,what", [("1/(x - x)", "complex infinity"), ("x/0", "complex infinity"),
                                    ("log(0)*x", "complex infinity"), ("0/0 + x", "NaN"),
                                    ("1e400*x", "too large for a double")])
def test_a_non_finite_expression_is_refused_before_the_file_and_force_keeps_the_old_one(
        tmp_path, finished_oscillator, H, what):
    scene = tmp_path / "osc.toml"
    before = finished_oscillator
    (tmp_path / "out.h5").write_bytes(before)
    scene.write_text(USER.replace('H = "x^2 + y^2"', f'H = "{H}"'))
    for args in ((), ("--force",)):
        r = poincare("run", "osc.toml", "-o", "new.h5" if not args else "out.h5", "-q", *args, cwd=tmp_path)
        assert r.returncode == 2
        one_line(r, "system.H", what)
    assert not (tmp_path / "new.h5").exists() and (tmp_path / "out.h5").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["osc.toml", "out.h5"]


def test_abs_is_differentiated_away_from_its_kink():
    import sympy
    import integrators
    x, y = sympy.symbols("x y", real=True)
    sy = integrators.system_from(["-y/2", "x/2"], "abs(x)^3 + y^2", [x, y])
    q = np.array([[0.3, 0.2], [-0.3, 0.2], [0.0, 0.2]])
    assert np.allclose(sy.dH(q)[:, 0], [3 * 0.09, -3 * 0.09, 0.0], rtol=1e-15, atol=0)
    assert np.allclose(sy.ddH(q)[:, 0, 0], [1.8, 1.8, 0.0], rtol=1e-15, atol=0)


def test_abs_in_a_scene_runs(tmp_path):
    (tmp_path / "osc.toml").write_text(USER.replace('H = "x^2 + y^2"', 'H = "abs(x)^3 + y^2"'))
    r = poincare("run", "osc.toml", "-q", cwd=tmp_path)
    assert r.returncode in (0, 1) and "GLRK1-none" in r.stdout and r.stderr == "", r.stderr


@pytest.mark.parametrize("change,key", [('points = 32', 'points = 100000000000'),
                                        ('[loop]', '[surface]\nn_sigma = 1000000\nn_tau = 1000000\n[loop]')])
def test_a_scene_too_large_for_memory_is_one_line_before_any_file(tmp_path, change, key):
    (tmp_path / "osc.toml").write_text(USER.replace(*((change, key) if change != "[loop]" else (change, key))))
    r = poincare("run", "osc.toml", "-q", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "loop.points" if "points" in key else "surface.n_sigma × surface.n_tau", "GiB of memory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["osc.toml"]


def test_a_shape_function_gets_tau_in_0_1_and_its_params(tmp_path):
    (tmp_path / "shapes.py").write_text(SHAPES_TAU)
    text = USER.replace('shape = "ellipse"', 'shape = "shapes.py:circle"').replace(
        "params = { d = 2, center = [0.5, 0.5], radii = [0.05, 0.05] }", "params = { r = 0.02 }")
    q = parse_scene(text, origin=str(tmp_path / "osc.toml")).loop_points()
    assert np.allclose(np.hypot(q[:, 0] - 0.5, q[:, 1] - 0.5), 0.02, rtol=1e-14)
    with pytest.raises(SceneError, match=r"loop.shape 'shapes.py:by_count' failed: .*called as f\(tau, \*\*params\)"):
        parse_scene(text.replace("circle", "by_count").replace("params = { r = 0.02 }", ""),
                    origin=str(tmp_path / "osc.toml"))


@pytest.mark.parametrize("params,msg", [
    ("{ d = 2, center = [0.5], radii = [0.05, 0.05] }", "loop.params.center must be a list of d = 2 numbers"),
    ("{ d = 2, center = [0.5, 0.5], radii = [0.05] }", "loop.params.radii must be a list of 2 numbers"),
    ("{ d = 2, center = [0.5, 0.5], plane = [0, 5] }", "loop.params.plane must be two different coordinate"),
    ("{ d = 2, centre = [0.5, 0.5] }", "loop.params: the shape 'ellipse' takes no parameter 'centre'"),
])
def test_bad_shape_params_name_the_key(params, msg):
    with pytest.raises(SceneError) as exc:
        parse_scene(USER.replace("{ d = 2, center = [0.5, 0.5], radii = [0.05, 0.05] }", params))
    assert str(exc.value).startswith(msg), str(exc.value)


@pytest.mark.parametrize("spec", ["builtins:print", "os:system", "integrators:system"])
def test_a_scene_cannot_name_an_installed_module(tmp_path, spec):
    (tmp_path / "osc.toml").write_text(USER.replace('shape = "ellipse"', f'shape = "{spec}"'))
    r = poincare("run", "osc.toml", "-q", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, f"module '{spec.split(':')[0]}' is not a .py file or package in", "never an installed module")


def test_control_characters_in_names_are_refused_and_never_printed_raw(tmp_path):
    with pytest.raises(SceneError, match="control characters"):
        parse_scene(USER.replace('name = "osc"', 'name = "a\\u001b[31mred"'))
    from integrators.cli import _printable
    assert _printable("a\x1b[31m\nb") == "a\\x1b[31m\\nb"


def test_a_non_utf8_scene_names_the_file(tmp_path, capsys):
    (tmp_path / "bad.toml").write_bytes(b"name = \"\xff\"\n")
    assert cli_main(["run", str(tmp_path / "bad.toml"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "UTF-8" in err


def test_a_step_map_of_the_wrong_shape_is_named():
    from integrators.audit.candidates import _call
    q = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"returned arrays of shapes \(3, 1\), \(3, 2\), \(3, 2\) for inputs"):
        _call(lambda q, p, lam, h, s: (q[:, :1], p, lam), q, q, q, 0.1, None)


def test_scene_keys_are_plain_text_and_name_the_default_forms(capsys):
    assert cli_main(["scenes", "--keys"]) == 0
    out = capsys.readouterr().out
    assert "``" not in out and ":class:" not in out and "default: canonical and noncanonical" in out


def test_an_expression_not_finite_at_the_sample_points_is_refused():
    with pytest.raises(SceneError, match=r"^loop: system.H is not finite at point 0 = \[0.55, 0.5\]"):
        parse_scene(USER.replace('H = "x^2 + y^2"', 'H = "sqrt(x - 10) + y^2"'))


def test_a_step_count_beyond_exact_step_times_is_refused(capsys, tmp_path, scene_file):
    with pytest.raises(SceneError, match=r"run.steps must be between 1 and 2\^53"):
        parse_scene(USER.replace("steps = 20", "steps = 100000000000000000000"))
    scene_file("oscillator", to="osc.toml")
    assert cli_main(["run", str(tmp_path / "osc.toml"), "-o", str(tmp_path / "o.h5"), "--steps", str(2**53 + 1)]) == 2
    assert "--steps must be at most 2^53" in capsys.readouterr().err and not (tmp_path / "o.h5").exists()


@pytest.mark.parametrize("change,words", [
    (lambda t: t + "\ndeep = " + "[" * 10000 + "]" * 10000 + "\n", ("nested 10000 deep", "at most 32")),
    (lambda t: t.replace('H = "x^2 + y^2"', 'H = "' + "-" * 1990 + 'x"'), ("system.H", "nested more than 100")),
    (lambda t: t.replace('H = "x^2 + y^2"', 'H = "x^2*1e308*1e308"'), ("system.H", "beyond the range of a double")),
    (lambda t: t.replace("h = 0.1", "h = 1e300"), ("run.h", "outside [1e-150, 1e+150]")),
    (lambda t: t.replace("h = 0.1", "h = 1e-320"), ("run.h", "outside [1e-150, 1e+150]")),
])
def test_hostile_scenes_are_one_line_before_any_file(tmp_path, change, words):
    (tmp_path / "s.toml").write_text(change(USER))
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, *words)
    assert "Warning" not in r.stderr and not (tmp_path / "s.h5").exists()


@pytest.mark.parametrize("text,words", [
    ("a = []\nb = []\nc = []\n", ("non-empty",)),
    ("a = " + "[" * 5000 + "]" * 5000 + "\nb = [1]\nc = [1]\n", ("nested 5000 deep",)),
])
def test_hostile_tableau_files_are_one_line(tmp_path, text, words):
    (tmp_path / "t.toml").write_text(text)
    (tmp_path / "s.toml").write_text(USER.replace('tableaus = ["GLRK1"]', 'tableaus = ["t.toml"]'))
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path)
    assert r.returncode == 2 and not (tmp_path / "s.h5").exists()
    one_line(r, "t.toml", *words)
    r = poincare("audit", "t.toml", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "t.toml", *words)


def test_a_fifo_as_scene_or_tableau_is_refused_not_read_for_ever(tmp_path):
    os.mkfifo(tmp_path / "f.toml")
    r = subprocess.run([str(BIN / "poincare"), "run", "f.toml", "-q"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2
    one_line(r, "f.toml", "not a regular file")
    r = subprocess.run([str(BIN / "poincare"), "audit", "f.toml"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2
    one_line(r, "f.toml", "not a regular file")


def test_the_first_output_is_tried_before_the_file_is_opened(tmp_path, monkeypatch):
    """A computation that fails on the scene's values (here the invariants, made to overflow as h²
    once did) is refused before the output file exists, not after a file with every pair pending."""
    import invariants.forms

    def overflow(*a, **k):
        raise OverflowError("(34, 'Numerical result out of range')")
    monkeypatch.setattr(invariants.forms, "first_invariants", overflow)
    sc = parse_scene(LV)
    with pytest.raises(ValueError, match="first output cannot be computed.*OverflowError.*nothing was written"):
        driver.run(sc, tmp_path / "a.h5", progress=False)
    assert not (tmp_path / "a.h5").exists()


@pytest.mark.parametrize("name,file", [(None, "GLRK2.toml"), ('"glrk2"', "mine.toml"), ('"SRK3"', "mine.toml")])
def test_a_tableau_file_cannot_take_a_builtin_name(tmp_path, name, file):
    from integrators.tableaus import tableau_from_file
    (tmp_path / file).write_text((f"name = {name}\n" if name else "") + "a = [[0.5]]\nb = [1]\nc = [0.5]\n")
    with pytest.raises(ValueError, match="the name of the built-in tableau"):
        tableau_from_file(tmp_path / file)


@pytest.mark.parametrize("spec", ["../maps.py:bye", "{abs}/maps.py:bye", "link.py:bye"])
def test_code_outside_the_scene_folder_is_refused(tmp_path, spec):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "maps.py").write_text(MAPS + "\nopen(__file__ + '.ran', 'w').close()\n")
    (tmp_path / "maps.py").write_text(MAPS + "\nopen(__file__ + '.ran', 'w').close()\n")
    work = tmp_path / "scene"
    work.mkdir()
    (work / "link.py").symlink_to(elsewhere / "maps.py")
    (work / "s.toml").write_text(STUCK.replace("maps.py:stuck", spec.format(abs=elsewhere)))
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=work)
    assert r.returncode == 2
    one_line(r, "run.step_maps", "outside")
    assert not list(tmp_path.rglob("*.ran"))              # nothing of it ran


@pytest.mark.parametrize("text,words", [
    ('a = [[0,0,0,0],["1/2",0,0,0],[0,"1/2",0,0],[0,0,1,0]]\nb = ["1/6","1/3","1/3","1/6"]\nc = [0,"1/2","1/2",1]\n',
     ("explicit Runge–Kutta", "not variational PRK", "run.step_maps")),
    ('a = [[0,0,0],["5/24","1/3","-1/24"],["1/6","2/3","1/6"]]\nb = ["1/6","2/3","1/6"]\nc = [0,"1/2",1]\n',
     ("singular", "give d", "[1/2, -1, 1/2]")),
])
def test_a_singular_a_says_what_is_accepted(tmp_path, text, words):
    from integrators.tableaus import tableau_from_file
    (tmp_path / "m.toml").write_text(text)
    with pytest.raises(ValueError) as info:
        tableau_from_file(tmp_path / "m.toml")
    assert all(w in str(info.value) for w in words), str(info.value)


@pytest.mark.parametrize("change,msg", [
    (("h = 10.0", "h = 10.0\nspeed = 3"), "unknown key 'run.speed'"),
    (("h = 10.0", "h = '10'"), "'run.h' must be float"),
    (("h = 10.0", "h = 0.0"), "run.h must be a finite positive"),
    (("h = 10.0", "h = -1.0"), "run.h must be a finite positive"),
    (("h = 10.0", "h = nan"), "run.h must be a finite positive"),
    (("steps = 40", "steps = 0"), "run.steps must be between 1 and"),
    (("steps = 40", "steps = -5"), "run.steps must be between 1 and"),
    (('"GLRK1", "GLRK2"', '"GLRK1", "GLRK9"'), "unknown tableau 'GLRK9'"),
    (('"none", "symmetric"', '"none", "orthogonal"'), "unknown value 'orthogonal'"),
    (('name = "guiding_centre_symmetric"', 'name = "pendulum"'), "unknown system 'pendulum'"),
    (('name = "guiding_centre_symmetric"', 'name = "guiding_centre_symmetric"\nparams = { nu = 1.0 }'), "unknown parameter 'nu'"),
    (("points = 64", "points = 64\nparams = { u0 = nan }"), "not finite or outside the domain"),
    (("points = 64", "points = 2"), "loop.points must be at least 8"),
    (("output_every = 4", "output_every = 0"), "run.output_every"),
    (("forms = [", "forms = ['magic', "), "unknown value 'magic'"),
    (("[run]", "[run]\ntableaus = 3\n"), "not valid TOML"),
    (('"corrected"]\n', '"corrected"]\n[output]\ncheckpoint_seconds = -1.0\n'), "output.checkpoint_seconds"),
    (('"corrected"]\n', '"corrected"]\n[output]\ncheckpoint_seconds = inf\n'), "output.checkpoint_seconds"),
    (('"corrected"]\n', '"corrected"]\n[output]\ncheckpoints = "per-node"\n'), "output.checkpoints must be"),
])
def test_bad_scenes_name_the_key(change, msg):
    with pytest.raises(SceneError, match=msg):
        parse_scene(edit(SMALL, *change))


def test_out_of_domain_points_and_missing_sections():
    lv = """
[system]
name = "lotka_volterra_2d"
[loop]
shape = "ellipse"
points = 16
params = { d = 2, center = [0.05, 1.0], radii = [0.1, 0.1] }
[run]
tableaus = ["GLRK2"]
projections = ["none"]
h = 0.1
steps = 10
diagnostics = ["energy"]
"""
    with pytest.raises(SceneError, match="outside the domain of lotka_volterra_2d"):
        parse_scene(lv)
    with pytest.raises(SceneError, match="needs a \\[loop\\] or a \\[surface\\]"):
        parse_scene("[system]\nname='point_vortices'\n[run]\ntableaus=['GLRK1']\nprojections=['none']\nh=0.1\nsteps=1")
    with pytest.raises(SceneError, match="has no Noether momentum"):
        parse_scene(edit(lv, 'diagnostics = ["energy"]', 'diagnostics = ["momentum"]').replace("0.05", "1.0"))


def test_every_builtin_scene_validates():
    names = set(builtin_scenes())
    assert {"default", "paper_poincare", "lotka_volterra", "point_vortices", "guiding_centre_tokamak",
            "massless_charged_particle", "lotka_volterra_4d", "guiding_centre_solovev",
            "charged_particle_tokamak"} <= names
    for name in names:
        load_scene(name)


def test_the_jacobian_refresh_reaches_newton_and_is_part_of_the_scene(tmp_path):
    """run.jacobian_refresh = 0.1: the stored points after 20 steps are bitwise those of the engine
    with Tolerances(refresh=0.1) on the scene's points in the driver's calls, and differ from the default run's (0.01) in
    their last bits only; a value outside (0, 1) is a one-line scene error, and a run file is not
    resumed with another value."""
    from integrators.engine import Engine, Tolerances
    from integrators.service import reader
    from integrators.service.scene import scene_differences
    text = LV.replace("[run]\n", "[run]\nstore_points = true\n")
    fast, plain = parse_scene(text.replace("[run]\n", "[run]\njacobian_refresh = 0.1\n")), parse_scene(text)
    assert (fast.jacobian_refresh, plain.jacobian_refresh) == (0.1, Tolerances.refresh)
    assert scene_differences(fast, plain) == ["run.jacobian_refresh"]
    driver.run(fast, tmp_path / "fast.h5", progress=False)
    driver.run(plain, tmp_path / "plain.h5", progress=False)
    sy = fast.system()
    for name in ("GLRK2-none", "GLRK2-symmetric"):
        eng = Engine(sy, tableau("GLRK2"), name.split("-")[1], fast.h, tolerances=Tolerances(refresh=0.1))
        st = eng.state(fast.loop_points())
        eng.advance(st, 1, fast.steps)                           # in one call: the driver's calls give the same bits
        a = reader.read_run(tmp_path / "fast.h5")[name].points["loop"][-1]
        b = reader.read_run(tmp_path / "plain.h5")[name].points["loop"][-1]
        assert np.array_equal(a, st.q), name
        assert not np.array_equal(a, b) and np.max(np.abs(a - b)) < 1e-12, name
    for bad in ("0.0", "1.0", "-0.1", "1e400", '"often"'):
        with pytest.raises(SceneError, match=r"run\.jacobian_refresh'? must be"):
            parse_scene(text.replace("[run]\n", f"[run]\njacobian_refresh = {bad}\n"))


def test_numbers_a_double_cannot_hold_nesting_and_stage_matrices_are_judged_fairly(tmp_path):
    """H = "1e-420*x^2" (a literal that reads as 0) is refused as 1e999 is; 999 nested parentheses
    say 'nested more than 100 deep' without echoing the expression; a 50-stage a = I/100 (det 1e-100,
    condition 1) is not called singular, Lobatto IIIA's a still is; a FIFO named as a scene's data
    file is 'not a regular file' (issue 56)."""
    from integrators.expressions import ExpressionError, parse_expression
    from integrators.tableaus import tableau_from_file
    x = sympy.Symbol("x")
    with pytest.raises(ExpressionError, match=r"the number 1e-420 .* below the range of a double"):
        parse_expression("1e-420*x^2", "system.H", {"x": x})
    deep = "(" * 999 + "x" + ")" * 999
    with pytest.raises(ExpressionError) as e:
        parse_expression(deep, "system.H", {"x": x})
    assert str(e.value) == "system.H: the expression is nested more than 100 deep"
    assert parse_expression("1e-300*x", "system.H", {"x": x}) != 0
    s = 50
    rows = "\n".join("  [" + ", ".join("0.01" if i == j else "0" for j in range(s)) + "]," for i in range(s))
    (tmp_path / "diag.toml").write_text(f'name = "diag"\nb = [{", ".join(["0.02"] * s)}]\n'
                                        f'c = [{", ".join(["0.01"] * s)}]\na = [\n{rows}\n]\n')
    assert tableau_from_file(tmp_path / "diag.toml").name == "diag"
    (tmp_path / "lob.toml").write_text('b = [0.5, 0.5]\nc = [0, 1]\na = [[0, 0], [0.5, 0.5]]\n')
    with pytest.raises(ValueError, match="a is singular"):
        tableau_from_file(tmp_path / "lob.toml")
    os.mkfifo(tmp_path / "pipe.toml")
    text = (Path(integrators.__file__).parent / "service" / "scenes" / "point_vortices.toml").read_text().replace('tableaus = ["GLRK2", "SRK3"]',
                                                                     'tableaus = ["pipe.toml"]')
    with pytest.raises(SceneError, match=r"'pipe.toml' is not a regular file"):
        parse_scene(text, str(tmp_path / "s.toml"))


def test_a_set_of_zero_extent_is_refused():
    """A loop whose points all coincide has I₁ = 0 and no relative error: one line, not an 'ok' run
    with '—' (issue 56)."""
    text = (Path(integrators.__file__).parent / "service" / "scenes" / "point_vortices.toml").read_text()
    text = text.replace("radii = [0.002, 0.002]", "radii = [0.0, 0.0]")
    with pytest.raises(SceneError, match=r"^loop: all 256 points are the same point .* zero extent"):
        parse_scene(text)
