"""A user's own system and tableau, written only in a scene file, run like a built-in one."""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from integrators.service import read_run
from integrators.cli import main as cli_main
from integrators.service.files import DamagedFile
from integrators.service.scene import SceneError, parse_scene

TABLEAU = '''name = "MyGL2"
a = [["1/4", "1/4 - sqrt(3)/6"], ["1/4 + sqrt(3)/6", "1/4"]]
b = ["1/2", "1/2"]
c = ["1/2 - sqrt(3)/6", "1/2 + sqrt(3)/6"]
'''

SCENE = '''name = "anharmonic"
[system]
name = "anharmonic"
coordinates = ["x", "y"]
theta = ["-y*(1 + x^2 + y^2)/2", "x*(1 + x^2 + y^2)/2"]
H = "omega*(x^2 + y^2)/2 + eps*(x^2 + y^2)^2"
params = { omega = 1.0, eps = 0.1 }
symmetry = ["-y", "x"]

[loop]
shape = "ellipse"
points = 64
params = { d = 2, center = [0.5, 0.0], radii = [0.01, 0.01] }

[surface]
shape = "rectangle"
n_sigma = 12
n_tau = 12
params = { d = 2, center = [0.5, 0.0], size = [0.01, 0.01] }

[run]
tableaus = ["GLRK2", "my_gl2.toml"]
projections = ["symmetric", "none"]
h = 0.1
steps = 200
output_every = 10
forms = ["canonical", "noncanonical"]
'''


def _poincare(*args, n=None, cwd=None):
    exe = shutil.which("poincare") or str(Path(sys.executable).parent / "poincare")
    cmd = [exe, *args]
    if n:
        cmd = [shutil.which("mpiexec") or str(Path(sys.executable).parent / "mpiexec"), "-n", str(n), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=cwd)


def _write(tmp_path, scene=SCENE):
    (tmp_path / "my_gl2.toml").write_text(TABLEAU)
    path = tmp_path / "user.toml"
    path.write_text(scene)
    return path


@pytest.mark.mpi
def test_a_system_and_a_tableau_from_the_scene_file_run_under_mpiexec(tmp_path):
    """ϑ, H and a tableau written only as text: 2 ranks give the 1-rank file's bits, the TOML tableau
    (strings parsed exactly, in extended precision) gives the built-in GLRK2's bits, the energy and
    the Noether momentum are conserved to round-off, and the plots are drawn."""
    scene = _write(tmp_path)
    for n, out in ((None, "one.h5"), (2, "two.h5")):
        r = _poincare("run", str(scene), "-o", str(tmp_path / out), "-q", n=n, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    with h5py.File(tmp_path / "one.h5") as a, h5py.File(tmp_path / "two.h5") as b:
        assert sorted(a["runs"]) == ["GLRK2-none", "GLRK2-symmetric", "MyGL2-none", "MyGL2-symmetric"]
        for pair in a["runs"]:
            assert a["runs"][pair].attrs["status"] == "ok"
            for key in ("I1/canonical", "I2/noncanonical", "energy_error", "checkpoint/a/q"):
                assert np.array_equal(a["runs"][pair][key][()], b["runs"][pair][key][()]), (pair, key)
        for key in ("I1/noncanonical", "energy_error", "checkpoint/a/q", "checkpoint/b/Y"):
            assert np.array_equal(a[f"runs/GLRK2-symmetric/{key}"][()], a[f"runs/MyGL2-symmetric/{key}"][()])
        g = a["runs/MyGL2-symmetric"]
        assert np.max(g["energy_error"][()]) < 1e-12 and np.max(g["momentum_error"][()]) < 1e-12
        assert g["t"].shape == (21,)
    run = read_run(tmp_path / "two.h5")        # the documented reader gives the file's arrays
    with h5py.File(tmp_path / "two.h5") as b:
        g = b["runs/MyGL2-none"]
        p = run["MyGL2-none"]
        assert p.status == "ok" and run.system == "anharmonic" and run.steps == 200
        assert np.array_equal(p.t, g["t"][()]) and np.array_equal(p.I2["noncanonical"], g["I2/noncanonical"][()])
        assert np.array_equal(p.errors["momentum"], g["momentum_error"][()])
        assert p.relative_error("I1", "noncanonical").max() > 1e-9      # unprojected GLRK2 is not exact here
    r = _poincare("plot", str(tmp_path / "two.h5"), "-o", str(tmp_path / "figs"))
    assert r.returncode == 0, r.stderr
    assert {p.name for p in (tmp_path / "figs").iterdir()} >= {"two_I1_canonical.png", "two_I2_noncanonical.png",
                                                              "two_diagnostics.png"}


def test_a_system_from_a_python_function(tmp_path, monkeypatch):
    (tmp_path / "mysys.py").write_text(
        "import sympy, integrators\n"
        "def oscillator(omega=1.0):\n"
        "    x, y = sympy.symbols('x y')\n"
        "    return integrators.system_from([-y / 2, x / 2], omega * (x**2 + y**2) / 2, [x, y], name='osc')\n")
    text = SCENE.replace(SCENE[SCENE.index("[system]"):SCENE.index("[loop]")],
                         "[system]\nfunction = \"mysys.py:oscillator\"\nparams = { omega = 2.0 }\n\n")
    text = text.replace('tableaus = ["GLRK2", "my_gl2.toml"]', 'tableaus = ["GLRK1"]')
    text = text.replace('forms = ["canonical", "noncanonical"]', 'forms = ["canonical"]\ndiagnostics = ["energy"]')
    path = tmp_path / "f.toml"
    path.write_text(text)
    monkeypatch.chdir(tmp_path)
    from integrators.service.scene import load_scene
    sc = load_scene(str(path))
    sy = sc.system()
    assert sy.name == "osc" and sy.H(np.array([1.0, 0.0])) == 1.0      # omega = 2 reached the function


@pytest.mark.parametrize("change,msg", [
    (('H = "omega*(x^2 + y^2)/2 + eps*(x^2 + y^2)^2"', 'H = "omega*(x^2 + z^2)"'), r"system\.H.*z"),
    (('H = "omega*(x^2 + y^2)/2 + eps*(x^2 + y^2)^2"', 'H = "__import__(\'os\')"'), r"system\.H"),
    (('H = "omega*(x^2 + y^2)/2 + eps*(x^2 + y^2)^2"', 'H = "x^^2"'), r"system\.H"),
    (('coordinates = ["x", "y"]', 'coordinates = ["x", "y", "z"]'), r"theta has 2 entries for 3 coordinates"),
    (('theta = ["-y*(1 + x^2 + y^2)/2", "x*(1 + x^2 + y^2)/2"]', 'theta = ["y", "x"]'), r"Ω̄ = dϑ is singular"),
    (('params = { omega = 1.0, eps = 0.1 }', 'params = { omega = 1.0, eps = 0.1, x = 1.0 }'), r"system\.params\.x"),
    (('H = "omega*(x^2 + y^2)/2 + eps*(x^2 + y^2)^2"\n', ''), r"system\.H"),
    (('tableaus = ["GLRK2", "my_gl2.toml"]', 'tableaus = ["GLRK2", "nope.toml"]'), r"run\.tableaus.*nope\.toml"),
    (('tableaus = ["GLRK2", "my_gl2.toml"]', 'tableaus = ["GLRK2", "my_gl2.toml", "my_gl2.toml"]'), r"twice"),
])
def test_bad_user_systems_and_tableaus_are_one_line_errors(tmp_path, change, msg):
    path = _write(tmp_path, SCENE.replace(*change))
    with pytest.raises(SceneError, match=msg):
        parse_scene(path.read_text(), origin=str(path))


def test_odd_dimension_is_refused(tmp_path):
    text = SCENE.replace('coordinates = ["x", "y"]', 'coordinates = ["x", "y", "z"]')
    text = text.replace('theta = ["-y*(1 + x^2 + y^2)/2", "x*(1 + x^2 + y^2)/2"]', 'theta = ["-y", "x", "0"]')
    text = text.replace('symmetry = ["-y", "x"]', 'symmetry = ["-y", "x", "0"]')
    path = _write(tmp_path, text)
    with pytest.raises(SceneError, match="dimension 3 is odd"):
        parse_scene(path.read_text(), origin=str(path))


def test_cli_exit_2_for_a_bad_expression(tmp_path, capsys, monkeypatch):
    path = _write(tmp_path, SCENE.replace('H = "omega*(x^2 + y^2)/2 + eps*(x^2 + y^2)^2"', 'H = "open(1)"'))
    monkeypatch.chdir(tmp_path)
    assert cli_main(["run", str(path), "-o", str(tmp_path / "x.h5"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "system.H" in err[0]
    assert not (tmp_path / "x.h5").exists()


def test_a_user_scene_resumes_to_the_same_bits(tmp_path):
    """Extending a finished run of the user scene (run.steps raised) gives the bits of one longer run:
    the stored scene, system expressions and tableau file included, is recognised as the same."""
    scene = _write(tmp_path)
    r = _poincare("run", str(scene), "-o", str(tmp_path / "part.h5"), "-q", "--steps", "100", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = _poincare("run", str(scene), "-o", str(tmp_path / "part.h5"), "-q", "--resume", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = _poincare("run", str(scene), "-o", str(tmp_path / "full.h5"), "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    with h5py.File(tmp_path / "part.h5") as a, h5py.File(tmp_path / "full.h5") as b:
        for pair in b["runs"]:
            for key in ("t", "I1/noncanonical", "I2/canonical", "energy_error", "checkpoint/a/q", "checkpoint/b/q"):
                assert np.array_equal(a["runs"][pair][key][()], b["runs"][pair][key][()]), (pair, key)


def test_a_changed_tableau_file_is_not_resumed(tmp_path, capsys):
    """The run file keeps the digest of each tableau file's coefficients: a resume after the file was
    edited (same name, one coefficient's last bits changed) is a one-line error, not a silent mix of
    two methods; the unchanged file resumes."""
    scene = _write(tmp_path, SCENE.replace('projections = ["symmetric", "none"]', 'projections = ["none"]'))
    out = tmp_path / "r.h5"
    assert cli_main(["run", str(scene), "-o", str(out), "-q", "--steps", "20"]) == 0
    with h5py.File(out) as f:
        assert "MyGL2" in f.attrs["tableau_digests"]
    (tmp_path / "my_gl2.toml").write_text(TABLEAU.replace('b = ["1/2", "1/2"]', 'b = ["0.5000000000000001", "1/2"]'))
    capsys.readouterr()
    assert cli_main(["run", str(scene), "-o", str(out), "-q", "--resume"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "my_gl2.toml" in err[0] and "other coefficients" in err[0], err
    (tmp_path / "my_gl2.toml").write_text("# reformatted\n" + TABLEAU)
    assert cli_main(["run", str(scene), "-o", str(out), "-q", "--resume"]) == 0


def test_an_almost_symmetric_tableau_is_refused_with_its_digits(tmp_path):
    """A b perturbed in its last bit moves R(∞) to 0.9999999999999997: the σ = R(∞) projections refuse it, and
    the message prints R(∞) to 17 digits (it read 'needs |R(∞)| = 1 but MyGL2 has R(∞) = 1')."""
    (tmp_path / "my_gl2.toml").write_text(TABLEAU.replace('b = ["1/2", "1/2"]', 'b = ["0.5000000000000001", "1/2"]'))
    with pytest.raises(SceneError, match=r"MyGL2 has R\(∞\) = 0\.99999999999999\d+; use"):
        parse_scene(SCENE, origin=str(tmp_path / "user.toml"))


def test_read_run_refuses_a_file_that_is_not_a_run(tmp_path):
    (tmp_path / "x.h5").write_bytes(b"not hdf5 at all")
    with pytest.raises(DamagedFile, match="x.h5"):
        read_run(tmp_path / "x.h5")
    with h5py.File(tmp_path / "y.h5", "w") as f:
        f["a"] = 1
    with pytest.raises(DamagedFile, match="not a poincare run file"):
        read_run(tmp_path / "y.h5")


MAPS = '''import numpy as np

def rk4(q, p, lam, h, system):
    """Classical RK4 on q' = v(q): a batched step map, not symplectic."""
    f = system.vector_field
    k1 = f(q); k2 = f(q + h / 2 * k1); k3 = f(q + h / 2 * k2); k4 = f(q + h * k3)
    q1 = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return q1, system.theta(q1), np.zeros_like(q1)

def broken(q, p, lam, h, system):
    raise RuntimeError("no")
'''


@pytest.mark.mpi
def test_a_step_map_runs_as_a_pair_of_the_scene(tmp_path):
    """run.step_maps: the user's map goes through the same driver, MPI, HDF5 and plots; RK4's invariant
    error grows (it is not symplectic) while GLRK2-symmetric stays at round-off."""
    (tmp_path / "mymaps.py").write_text(MAPS)
    scene = _write(tmp_path, SCENE.replace('projections = ["symmetric", "none"]',
                                           'projections = ["symmetric"]\nstep_maps = ["mymaps.py:rk4"]'))
    for n, out in ((None, "one.h5"), (2, "two.h5")):
        r = _poincare("run", str(scene), "-o", str(tmp_path / out), "-q", n=n, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    a, b = read_run(tmp_path / "one.h5"), read_run(tmp_path / "two.h5")
    assert sorted(a.pairs) == ["GLRK2-symmetric", "MyGL2-symmetric", "rk4-map"]
    for k in a.pairs:
        assert a[k].status == "ok" and np.array_equal(a[k].I2["canonical"], b[k].I2["canonical"])
    e_rk4 = a["rk4-map"].relative_error("I1", "canonical")
    assert e_rk4[-1] > 1e-8 and e_rk4[-1] > e_rk4[2]
    assert a["GLRK2-symmetric"].relative_error("I1", "canonical").max() < 1e-12
    r = _poincare("plot", str(tmp_path / "two.h5"), "-o", str(tmp_path / "figs"))
    assert r.returncode == 0, r.stderr


def test_a_step_map_that_raises_stops_its_points_not_the_run(tmp_path):
    (tmp_path / "mymaps.py").write_text(MAPS)
    scene = _write(tmp_path, SCENE.replace('projections = ["symmetric", "none"]',
                                           'projections = ["symmetric"]\nstep_maps = ["mymaps.py:broken"]'))
    r = _poincare("run", str(scene), "-o", str(tmp_path / "x.h5"), "-q", cwd=tmp_path)
    assert r.returncode == 1, r.stderr                 # a pair failed: not ok
    assert r.stderr.count("step map broken raised RuntimeError: no at step 1") == 1
    run = read_run(tmp_path / "x.h5")
    assert run["broken-map"].status == "failed" and np.all(run["broken-map"].breakdown_time == 0.1)
    assert run["GLRK2-symmetric"].status == "ok"


def test_a_missing_step_map_is_a_one_line_error(tmp_path):
    scene = _write(tmp_path, SCENE.replace('projections = ["symmetric", "none"]',
                                           'projections = ["symmetric"]\nstep_maps = ["nothere.py:rk4"]'))
    with pytest.raises(SceneError, match=r"run\.step_maps.*nothere\.py"):
        parse_scene(scene.read_text(), origin=str(scene))


def test_a_scene_of_step_maps_only(tmp_path):
    """run.tableaus = [] (and projections = []) beside run.step_maps is a scene of maps only, not
    'run.tableaus must be a non-empty list' (issue 53); without step maps the empty list is refused."""
    (tmp_path / "mymaps.py").write_text(MAPS)
    text = re.sub(r'(?m)^tableaus = .*$', 'tableaus = []', SCENE)
    text = re.sub(r'(?m)^projections = .*$', 'projections = []\nstep_maps = ["mymaps.py:rk4"]', text)
    scene = parse_scene(text, str(tmp_path / "s.toml"))
    assert [p.label for p in scene.pairs] == ["rk4"]
    with pytest.raises(SceneError, match="non-empty list"):
        parse_scene(re.sub(r'(?m)^tableaus = .*$', 'tableaus = []', SCENE), str(tmp_path / "s.toml"))


RING = '''import numpy as np
from integrators.audit.examples import pendulum_array

K = 6
strang, info = pendulum_array(K, method="strang")
rk2 = pendulum_array(K, method="rk2")[0]
energy = info["energy"]


def start():
    """Every pendulum near the bottom, x = 0.02: the loop (radius 0.05 in pendulum 0's plane)
    straddles the angle 0, and the maps wrap it into [0, 2π)."""
    return np.full(K, 0.02), np.linspace(0.0, 0.05, K)
'''

RING_SCENE = '''name = "ring"
[system]
name = "ring"
degrees_of_freedom = 6
period = 6.283185307179586
energy = "ring.py:energy"

[loop]
shape = "ellipse"
points = 64
params = { d = 12, center = "ring.py:start", radii = [0.05, 0.05], plane = [0, 6] }

[run]
tableaus = []
step_maps = ["ring.py:strang", "ring.py:rk2"]
h = 0.1
steps = 60
output_every = 10
store_points = true
'''


@pytest.mark.mpi
def test_a_canonical_map_scene_gives_one_file_on_1_2_3_ranks_and_resumes_to_it(tmp_path):
    """system.degrees_of_freedom: step(x, v, h) maps with no formula through the driver (issue 53):
    1, 2 and 3 ranks write the same file bit for bit; a run extended by --resume is the straight
    run's file; Strang keeps the canonical I₁ of a loop whose angles are wrapped at round-off and
    the energy error small, RK2 does not keep I₁."""
    from helpers import dump
    (tmp_path / "ring.py").write_text(RING)
    scene = tmp_path / "ring.toml"
    scene.write_text(RING_SCENE)
    for n, out in ((None, "one.h5"), (2, "two.h5"), (3, "three.h5")):
        r = _poincare("run", str(scene), "-o", str(tmp_path / out), "-q", n=n, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    one = dump(tmp_path / "one.h5", skip=("wall_clock", "checkpoint"))
    for out in ("two.h5", "three.h5"):
        other = dump(tmp_path / out, skip=("wall_clock", "checkpoint"))
        assert one.keys() == other.keys() and all(
            np.array_equal(one[k], other[k], equal_nan=True) if k != "status" else one[k] == other[k] for k in one)
    run = read_run(tmp_path / "one.h5")
    pts = run["strang-map"].points["loop"][1:]
    assert np.all((pts[..., :6] >= 0) & (pts[..., :6] < 2 * np.pi)) and np.sum(np.ptp(pts[..., 0], axis=1) > 6) >= 3
    assert run["strang-map"].relative_error("I1", "canonical").max() < 1e-12
    assert 0 < run["strang-map"].errors["energy"].max() < 1e-2
    assert run["rk2-map"].relative_error("I1", "canonical").max() > 1e-6
    short = tmp_path / "short.toml"
    short.write_text(RING_SCENE.replace("steps = 60", "steps = 30"))
    assert _poincare("run", str(short), "-o", str(tmp_path / "ext.h5"), "-q", cwd=tmp_path).returncode == 0
    r = _poincare("run", str(scene), "-o", str(tmp_path / "ext.h5"), "-q", "--resume", n=2, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    ext = dump(tmp_path / "ext.h5", skip=("wall_clock", "checkpoint"))
    assert ext.keys() == one.keys() and all(
        np.array_equal(one[k], ext[k], equal_nan=True) if k != "status" else one[k] == ext[k] for k in one)


def test_a_canonical_map_scene_without_the_period_is_under_resolved_not_wrong(tmp_path):
    """The same loop with system.period left out: its wrapped angles jump by 2π between neighbours,
    and the run says under-resolved rather than reporting a value."""
    (tmp_path / "ring.py").write_text(RING)
    scene = tmp_path / "ring.toml"
    scene.write_text(RING_SCENE.replace("period = 6.283185307179586\n", ""))
    r = _poincare("run", str(scene), "-o", str(tmp_path / "x.h5"), "-q", cwd=tmp_path)
    assert r.returncode == 1
    run = read_run(tmp_path / "x.h5")
    assert run["strang-map"].status == "under-resolved" and not run["strang-map"].resolved["I1"][1:].any()


@pytest.mark.parametrize("change, match", [
    (('tableaus = []', 'tableaus = ["GLRK2"]\nprojections = ["none"]'), "has no formula for the engine"),
    (("h = 0.1", "h = 0.1\nforms = [\"canonical\", \"noncanonical\"]"), "the canonical form only .v·dx."),
    (('h = 0.1', 'h = 0.1\ndiagnostics = ["constraint"]'), "energy error only"),
    (('period = 6.283185307179586', 'period = [1.0, 2.0]'), "2 entries for 6 positions"),
    (('period = 6.283185307179586', 'period = -1.0'), "system.period must be a positive number"),
    (('energy = "ring.py:energy"', 'energy = "ring.py:nothere"'), "system.energy.*no function 'nothere'"),
    (('degrees_of_freedom = 6', 'degrees_of_freedom = 6\ntheta = ["x"]'), "system.theta cannot go with"),
    (('center = "ring.py:start"', 'center = "ring.py:energy"'), "loop.params.center.*failed"),
    (('d = 12', 'd = 10'), "center must be a list of d = 10 numbers, got 12"),
])
def test_canonical_map_scene_mistakes_are_one_line_errors(tmp_path, change, match):
    (tmp_path / "ring.py").write_text(RING)
    with pytest.raises(SceneError, match=match):
        parse_scene(RING_SCENE.replace(*change), str(tmp_path / "ring.toml"))


def test_the_builtin_canonical_map_scene_tells_strang_from_rk2(tmp_path):
    """poincare run pendula_map (256 pendula, maps only): Strang keeps I₁ at round-off, RK2 does not."""
    r = _poincare("run", "pendula_map", "-o", str(tmp_path / "p.h5"), "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    run = read_run(tmp_path / "p.h5")
    assert run["strang-map"].relative_error("I1", "canonical").max() < 1e-11
    assert run["rk2-map"].relative_error("I1", "canonical").max() > 1e-3
    assert all(run[k].resolved["I1"].all() for k in run.pairs)



def test_the_builtin_map_scenes_code_is_the_audit_examples_arithmetic():
    """pendula_map.py is written as a user writes a scene's maps (plain numpy, importing nothing of the
    package); its maps, energy and start are bitwise those of integrators.audit.examples."""
    import importlib.util
    from pathlib import Path

    import integrators
    from integrators.audit import examples
    path = Path(integrators.__file__).parent / "service" / "scenes" / "pendula_map.py"
    assert "integrators" not in "".join(ln for ln in path.read_text().splitlines(True) if "import" in ln)
    spec = importlib.util.spec_from_file_location("pendula_map_scene", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    x0, v0 = mod.start()
    _, info = examples.example("pendula-strang", k=mod.K)
    assert np.array_equal(x0, info["point"][0]) and np.array_equal(v0, info["point"][1])
    rng = np.random.default_rng(5)
    x, v = x0 + 0.3 * rng.standard_normal((4, mod.K)), v0 + 0.3 * rng.standard_normal((4, mod.K))
    for method in ("strang", "rk2"):
        ours, ref = getattr(mod, method)(x, v, 0.1), examples.pendulum_array(mod.K, method=method)[0](x, v, 0.1)
        assert np.array_equal(ours[0], ref[0]) and np.array_equal(ours[1], ref[1])
    assert np.array_equal(mod.energy(x, v), info["energy"](x, v))

ONE_FORM = '''import numpy as np

def theta(q):                      # ϑ = (0, x + x³/3): dϑ = (1 + x²) dx ∧ dy
    return np.stack([np.zeros_like(q[:, 0]), q[:, 0] + q[:, 0] ** 3 / 3], axis=1)

def energy(q):
    return 0.5 * q[:, 1] ** 2 - np.cos(q[:, 0])

def kick(q, h):                    # y += h ∂V/(1 + x²), V = cos x: the exact flow of a potential
    return np.stack([q[:, 0], q[:, 1] - h * np.sin(q[:, 0]) / (1 + q[:, 0] ** 2)], axis=1)

def euler_drift(q, h):             # x += h y/(1 + x²): explicit Euler, not symplectic for dϑ
    return np.stack([q[:, 0] + h * q[:, 1] / (1 + q[:, 0] ** 2), q[:, 1]], axis=1)
'''

ONE_FORM_SCENE = '''name = "one_form"
[system]
name = "cubic"
dimension = 2
one_form = "of.py:theta"
energy = "of.py:energy"

[loop]
shape = "ellipse"
points = 64
params = { d = 2, center = [0.3, 0.2], radii = [0.05, 0.05] }

[surface]
shape = "rectangle"
n_sigma = 12
n_tau = 12
params = { d = 2, center = [0.3, 0.2], size = [0.1, 0.1] }

[run]
step_maps = ["of.py:kick", "of.py:euler_drift"]
h = 0.05
steps = 40
output_every = 10
store_points = true
'''


@pytest.mark.mpi
def test_a_scene_of_maps_with_a_one_form_of_code(tmp_path):
    """system.dimension + system.one_form: maps step(q, h) -> q with ϑ(q) of code (issue 53): the
    noncanonical I₁ and I₂ at t = 0 are the formula route's (invariants.first/second_invariant with the
    same ϑ written as formulas) to 1e-15; the kick keeps both at round-off, the Euler drift does not;
    1 and 2 ranks write the same file; the form is ϑ·dq only."""
    import sympy
    import integrators
    import invariants
    from helpers import dump
    (tmp_path / "of.py").write_text(ONE_FORM)
    scene = tmp_path / "of.toml"
    scene.write_text(ONE_FORM_SCENE)
    for n, out in ((None, "one.h5"), (2, "two.h5")):
        r = _poincare("run", str(scene), "-o", str(tmp_path / out), "-q", n=n, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    one, two = (dump(tmp_path / f, skip=("wall_clock", "checkpoint")) for f in ("one.h5", "two.h5"))
    assert one.keys() == two.keys() and all(
        np.array_equal(one[k], two[k], equal_nan=True) if k != "status" else one[k] == two[k] for k in one)
    run = read_run(tmp_path / "one.h5")
    x, y = sympy.symbols("x y", real=True)
    sy = integrators.system_from(["0", "x + x^3/3"], "y^2/2 - cos(x)", [x, y])
    sc = parse_scene(ONE_FORM_SCENE, str(scene))
    i1 = invariants.first_invariant(sc.loop_points(), "noncanonical", system=sy).value
    i2 = invariants.second_invariant(sc.surface_points(), "noncanonical", system=sy).value
    kick, euler = run["kick-map"], run["euler_drift-map"]
    assert abs(kick.I1["noncanonical"][0] - i1) < 1e-15 and abs(kick.I2["noncanonical"][0] - i2) < 1e-15
    assert kick.relative_error("I1", "noncanonical").max() < 1e-13
    assert kick.relative_error("I2", "noncanonical").max() < 1e-13
    assert euler.relative_error("I1", "noncanonical").max() > 1e-5
    ns = {}
    exec(ONE_FORM, ns)
    q0, qT = (np.concatenate([kick.points["loop"][i], kick.points["surface"][i].reshape(-1, 2)])
              for i in (0, -1))                                       # the energy error: of.py's energy
    H0 = ns["energy"](q0)
    want = np.max(np.abs(ns["energy"](qT) - H0) / np.abs(H0))
    assert kick.errors["energy"][0] == 0 and abs(kick.errors["energy"][-1] - want) <= 1e-15 * want
    with pytest.raises(SceneError, match="noncanonical form only"):
        parse_scene(ONE_FORM_SCENE.replace("h = 0.05", 'h = 0.05\nforms = ["canonical"]'), str(scene))
    with pytest.raises(SceneError, match="system.dimension and system.one_form go together"):
        parse_scene(ONE_FORM_SCENE.replace('one_form = "of.py:theta"\n', ""), str(scene))
