"""The edges a new user found (issue 29): run lengths that are not a multiple of the output cadence,
scenes refused before anything is written, damaged and busy files, code in scenes."""
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from integrators.service import driver
from integrators.cli import main as cli_main
from integrators.service.scene import SceneError, parse_scene

BIN = Path(sys.executable).parent

LV = """
name = "lv"
[system]
name = "lotka_volterra_2d"
[loop]
shape = "ellipse"
points = 64
params = { d = 2, center = [1.0, 1.0], radii = [0.1, 0.1] }
[run]
tableaus = ["GLRK2"]
projections = ["none", "symmetric"]
h = 0.1
steps = 20
output_every = 10
diagnostics = ["energy", "constraint"]
[output]
checkpoint_seconds = 0.0
"""


def scene(steps, every=10, text=LV):
    return parse_scene(text.replace("steps = 20", f"steps = {steps}").replace("output_every = 10",
                                                                              f"output_every = {every}"))


def dump(path):
    """Every dataset and status of a run file, checkpoints included (not the wall clocks)."""
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and "wall_clock" not in name:
                out[name] = obj[...]
        f.visititems(visit)
        out["status"] = {k: str(f["runs"][k].attrs["status"]) for k in f["runs"]}
    return out


def assert_same(a, b):
    da, db = dump(a), dump(b)
    assert da.keys() == db.keys()
    differ = [k for k in da if not (da[k] == db[k] if k == "status" else np.array_equal(da[k], db[k]))]
    assert not differ, differ


# -- run.steps not a multiple of run.output_every -----------------------------------------------------

@pytest.mark.parametrize("steps", [23, 27, 20])
def test_a_last_partial_interval_is_a_real_output(tmp_path, steps):
    out = tmp_path / "a.h5"
    summaries = driver.run(scene(steps), out, progress=False)
    assert [s.status for s in summaries] == ["ok", "ok"]
    with h5py.File(out) as f:
        g = f["runs/GLRK2-symmetric"]
        want = [0, 10, 20] + ([steps] if steps % 10 else [])
        assert np.array_equal(g["t"][...], np.array(want) * 0.1)
        # the state kept is at the last multiple of the cadence, from which a longer run goes on
        assert int(g["checkpoint/a/step"][()]) == 20 and int(g["checkpoint/b/step"][()]) == -1


@pytest.mark.parametrize("first,then", [(20, 23), (23, 27), (23, 30), (27, 45), (20, 45), (23, 24)])
def test_extending_a_run_gives_the_bits_of_the_straight_run(tmp_path, first, then):
    straight, grown = tmp_path / "straight.h5", tmp_path / "grown.h5"
    driver.run(scene(then), straight, progress=False)
    driver.run(scene(first), grown, progress=False)
    summaries = driver.run(scene(then), grown, resume=True, progress=False)
    assert [s.status for s in summaries] == ["ok", "ok"]
    assert_same(grown, straight)


def test_extending_twice_and_resuming_a_killed_partial_run(tmp_path):
    """20 -> 42 -> 45 steps (the issue's crash), and a run of 45 killed after its output at 40."""
    straight, grown, killed = tmp_path / "s.h5", tmp_path / "g.h5", tmp_path / "k.h5"
    driver.run(scene(45), straight, progress=False)
    driver.run(scene(20), grown, progress=False)
    driver.run(scene(42), grown, resume=True, progress=False)
    driver.run(scene(45), grown, resume=True, progress=False)
    assert_same(grown, straight)

    class Kill(Exception):
        pass

    def kill(pair, step):
        if pair == "GLRK2-symmetric" and step == 40:
            raise Kill

    with pytest.raises(Kill):
        driver.run(scene(45), killed, progress=False, after_output=kill)
    with h5py.File(killed) as f:
        assert f["runs/GLRK2-symmetric"].attrs["status"] == "pending"
    driver.run(scene(45), killed, resume=True, progress=False)
    assert_same(killed, straight)


@pytest.mark.parametrize("kill_at,first,then", [(10, 23, 45), (20, 23, 23), (20, 23, 27), (10, 20, 21)])
def test_a_killed_run_resumed_with_more_steps_gives_the_straight_bits(tmp_path, kill_at, first, then):
    straight, killed = tmp_path / "s.h5", tmp_path / "k.h5"
    driver.run(scene(then), straight, progress=False)

    class Kill(Exception):
        pass

    def kill(pair, step):
        if pair == "GLRK2-none" and step == kill_at:
            raise Kill

    with pytest.raises(Kill):
        driver.run(scene(first), killed, progress=False, after_output=kill)
    driver.run(scene(then), killed, resume=True, progress=False)
    assert_same(killed, straight)


def test_resuming_a_finished_run_with_the_same_steps_changes_no_number(tmp_path):
    out, straight = tmp_path / "a.h5", tmp_path / "s.h5"
    driver.run(scene(23), out, progress=False)
    driver.run(scene(23), straight, progress=False)
    summaries = driver.run(scene(23), out, resume=True, progress=False)
    assert [s.status for s in summaries] == ["ok", "ok"]
    assert_same(out, straight)
    with pytest.raises(SceneError, match="below run.output_every"):
        scene(23).with_steps(9)


def test_fewer_steps_are_refused_and_the_file_is_unchanged(tmp_path):
    out = tmp_path / "a.h5"
    driver.run(scene(23), out, progress=False)
    before = out.read_bytes()
    with pytest.raises(ValueError, match="fewer steps"):
        driver.run(scene(21), out, resume=True, progress=False)
    assert out.read_bytes() == before


def test_a_partial_interval_on_two_ranks_gives_the_one_rank_bits(tmp_path):
    (tmp_path / "lv.toml").write_text(LV.replace("steps = 20", "steps = 23"))
    for n, name in ((None, "one.h5"), (2, "two.h5")):
        r = poincare("run", "lv.toml", "-o", name, "-q", cwd=tmp_path, n=n)
        assert r.returncode == 0, r.stderr
    assert_same(tmp_path / "one.h5", tmp_path / "two.h5")


# -- scenes refused before anything is written ------------------------------------------------------

def poincare(*args, cwd=None, n=None, env=None):
    cmd = [str(BIN / "poincare"), *args]
    if n:
        cmd = [str(BIN / "mpiexec"), "-n", str(n), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=cwd,
                          env=None if env is None else {**os.environ, **env})


USER = """
name = "osc"
[system]
name = "oscillator"
coordinates = ["x", "y"]
theta = ["-y/2", "x/2"]
H = "x^2 + y^2"
[loop]
shape = "ellipse"
points = 32
params = { d = 2, center = [0.5, 0.5], radii = [0.05, 0.05] }
[run]
tableaus = ["GLRK1"]
projections = ["none"]
h = 0.1
steps = 20
output_every = 10
"""


def one_line(r, *words):
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert all(w in r.stderr for w in words), r.stderr


@pytest.mark.parametrize("H,what", [("1/(x - x)", "complex infinity"), ("x/0", "complex infinity"),
                                    ("log(0)*x", "complex infinity"), ("0/0 + x", "NaN"),
                                    ("1e400*x", "too large for a double")])
def test_a_non_finite_expression_is_refused_before_the_file_and_force_keeps_the_old_one(tmp_path, H, what):
    scene = tmp_path / "osc.toml"
    scene.write_text(USER)
    assert poincare("run", "osc.toml", "-o", "out.h5", "-q", cwd=tmp_path).returncode == 0
    before = (tmp_path / "out.h5").read_bytes()
    scene.write_text(USER.replace('H = "x^2 + y^2"', f'H = "{H}"'))
    for args in ((), ("--force",)):
        r = poincare("run", "osc.toml", "-o", "new.h5" if not args else "out.h5", "-q", *args, cwd=tmp_path)
        assert r.returncode == 2
        one_line(r, "system.H", what)
    assert not (tmp_path / "new.h5").exists() and (tmp_path / "out.h5").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["osc.toml", "out.h5"]


def test_force_replaces_the_old_file_only_once_the_new_run_has_started(tmp_path):
    old = tmp_path / "a.h5"
    driver.run(scene(20), old, progress=False)
    before = old.read_bytes()

    class Kill(Exception):
        pass

    def kill(pair, step):
        raise Kill

    with pytest.raises(Kill):          # killed at its first written rows: the new file has replaced the old
        driver.run(scene(30), old, force=True, progress=False, after_output=kill)
    with h5py.File(old) as f:
        assert int(f.attrs["steps"]) == 30
    old.write_bytes(before)
    stop = driver.StopRequest()
    stop.set(KeyboardInterrupt())                 # stopped before its first step: the old file stays
    with pytest.raises(KeyboardInterrupt):
        driver.run(scene(30), old, force=True, progress=False, stop=stop)
    assert old.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["a.h5"]


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


# -- shapes, code in scenes ------------------------------------------------------------------------

SHAPES = '''
import numpy as np

def circle(tau, r=0.1, cx=0.5, cy=0.5):
    assert tau.shape == (32,) and tau[0] == 0.0 and tau[-1] == 31 / 32
    return np.stack([cx + r * np.cos(2 * np.pi * tau), cy + r * np.sin(2 * np.pi * tau)], axis=1)

def by_count(N):
    return np.zeros((N, 2))
'''


def test_a_shape_function_gets_tau_in_0_1_and_its_params(tmp_path):
    (tmp_path / "shapes.py").write_text(SHAPES)
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


def test_the_summary_lists_the_code_a_scene_ran(tmp_path):
    (tmp_path / "shapes.py").write_text(SHAPES)
    (tmp_path / "osc.toml").write_text(USER.replace('shape = "ellipse"', 'shape = "shapes:circle"').replace(
        "params = { d = 2, center = [0.5, 0.5], radii = [0.05, 0.05] }", "params = { r = 0.02 }"))
    r = poincare("run", "osc.toml", "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert f"loop.shape = shapes:circle: {tmp_path.resolve() / 'shapes.py'}:circle" in r.stdout


# -- summaries, plots, damaged and busy files ----------------------------------------------------------

PARTIAL = LV.replace('projections = ["none", "symmetric"]', 'projections = ["none"]').replace(
    "h = 0.1", "h = 0.3").replace("center = [1.0, 1.0], radii = [0.1, 0.1]", "center = [0.35, 0.35], radii = [0.3, 0.3]")


def test_a_partial_pair_shows_no_error_it_cannot_vouch_for(tmp_path):
    (tmp_path / "p.toml").write_text(PARTIAL.replace("output_every = 10", "output_every = 5"))
    r = poincare("run", "p.toml", "-o", "p.h5", "-q", cwd=tmp_path)
    assert r.returncode == 1
    row = next(line for line in r.stdout.splitlines() if line.startswith("GLRK2-none"))
    assert row.split()[1] == "partial" and "0.000e+00" not in row
    import re                          # (how many break, and when, is the run's own business)
    assert re.search(r"GLRK2-none: \d+ of 64 points broke down \(the first at t = [0-9.]+\); a set's errors",
                     r.stdout), r.stdout
    from integrators.service.plots import _caption
    assert "broke down" in _caption(False, True) and "under-resolved" not in _caption(False, True)


def _claim_petabytes(path):
    """Set the first dimension of one series dataset's dataspace (5 rows, unlimited) to 2^50 + 5."""
    import struct
    data = bytearray(path.read_bytes())
    pattern = struct.pack("<Q", 5) + b"\xff" * 8
    k = data.index(pattern)
    data[k + 6] = 0x04
    path.write_bytes(bytes(data))


def test_a_dataset_that_claims_petabytes_is_one_line_and_resume_changes_no_byte(tmp_path):
    (tmp_path / "lv.toml").write_text(LV.replace("steps = 20", "steps = 40"))
    assert poincare("run", "lv.toml", "-o", "lv.h5", "-q", cwd=tmp_path).returncode == 0
    _claim_petabytes(tmp_path / "lv.h5")
    before = (tmp_path / "lv.h5").read_bytes()
    r = poincare("plot", "lv.h5", "-o", "png", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "damaged")
    (tmp_path / "lv.toml").write_text(LV.replace("steps = 20", "steps = 60"))
    r = poincare("run", "lv.toml", "-o", "lv.h5", "-q", "--resume", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "damaged", "--force")
    assert (tmp_path / "lv.h5").read_bytes() == before


@pytest.mark.slow
def test_a_few_flipped_bits_never_give_a_traceback_or_change_a_refused_file():
    script = Path(__file__).parents[1] / "scripts" / "damaged_files.py"
    r = subprocess.run([sys.executable, str(script), "--flips", "4", "--seed", "3", "--below", "40000",
                        "--offsets", "15062", "39781:5"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "6 flips in a" in r.stdout and ": 0 broke a rule" in r.stdout


def test_a_file_another_run_is_writing_is_called_busy_not_damaged(tmp_path):
    out = tmp_path / "lv.h5"
    driver.run(scene(20), out, progress=False)
    code = "import h5py, sys, time; f = h5py.File(sys.argv[1], 'r+'); print('open', flush=True); time.sleep(60)"
    holder = subprocess.Popen([sys.executable, "-c", code, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "open"
        r = poincare("plot", str(out), "-o", str(tmp_path / "png"))
        assert r.returncode == 2
        one_line(r, "open for writing by another process")
        (tmp_path / "lv.toml").write_text(LV.replace("steps = 20", "steps = 30"))
        r = poincare("run", "lv.toml", "-o", str(out), "--resume", "-q", cwd=tmp_path)
        assert r.returncode == 2
        one_line(r, "another process")
        before = out.read_bytes()
        r = poincare("run", "lv.toml", "-o", str(out), "--force", "-q", cwd=tmp_path)
        assert r.returncode == 2 and out.read_bytes() == before
        one_line(r, "another process")
    finally:
        holder.kill()
        holder.wait()


# -- the smaller items ----------------------------------------------------------------------------------

def test_control_characters_in_names_are_refused_and_never_printed_raw(tmp_path):
    with pytest.raises(SceneError, match="control characters"):
        parse_scene(USER.replace('name = "osc"', 'name = "a\\u001b[31mred"'))
    from integrators.cli import _printable
    assert _printable("a\x1b[31m\nb") == "a\\x1b[31m\\nb"


def test_threads_beyond_the_cores_are_refused(tmp_path, capsys):
    (tmp_path / "osc.toml").write_text(USER)
    assert cli_main(["run", str(tmp_path / "osc.toml"), "-o", str(tmp_path / "o.h5"), "--threads", "100000"]) == 2
    assert "--threads must be between 1 and" in capsys.readouterr().err
    assert not (tmp_path / "o.h5").exists()


def test_resume_on_a_read_only_file_system_exits_3_and_changes_nothing(tmp_path, monkeypatch, capsys):
    from integrators.service import output
    out = tmp_path / "lv.h5"
    (tmp_path / "lv.toml").write_text(LV)
    driver.run(scene(20), out, progress=False)
    before = out.read_bytes()
    real = output.h5py.File

    def read_only(name, mode="r", *a, **k):
        if mode != "r":
            raise OSError(30, "Read-only file system")
        return real(name, mode, *a, **k)

    monkeypatch.setattr(output.h5py, "File", read_only)
    assert cli_main(["run", str(tmp_path / "lv.toml"), "-o", str(out), "--resume", "--steps", "30", "-q"]) == 3
    assert "Read-only file system" in capsys.readouterr().err and out.read_bytes() == before


def test_audit_outputs_are_checked_before_the_audit(tmp_path, capsys):
    assert cli_main(["audit", "GLRK1", "--json", str(tmp_path / "no" / "a.json"), "-q"]) == 2
    assert "--json: directory" in capsys.readouterr().err
    (tmp_path / "f").write_text("")
    assert cli_main(["audit", "GLRK1", "--plots", str(tmp_path / "f"), "-q"]) == 2
    assert "--plots" in capsys.readouterr().err
    assert cli_main(["audit", "GLRK1", "--reference", "XYZ-none", "-q"]) == 2
    err = capsys.readouterr().err
    assert "reference 'XYZ-none'" in err and "candidate" not in err


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


def test_a_reordered_scene_with_more_steps_names_only_what_differs(tmp_path):
    out = tmp_path / "a.h5"
    driver.run(scene(20), out, progress=False)
    swapped = scene(30, text=LV.replace('["none", "symmetric"]', '["symmetric", "none"]'))
    with pytest.raises(ValueError) as exc:
        driver.run(swapped, out, resume=True, progress=False)
    assert "differs in run.projections (" in str(exc.value)


def test_a_full_disk_before_any_row_says_nothing_was_written(tmp_path, monkeypatch):
    from integrators.service import files
    monkeypatch.setattr(files, "available_bytes", lambda path: 0.0)
    with pytest.raises(files.OutputError, match="the file holds no output yet"):
        driver.run(scene(20), tmp_path / "a.h5", progress=False)


def test_a_run_and_its_pairs_have_a_short_repr(tmp_path):
    from integrators.service import read_run
    driver.run(scene(20), tmp_path / "a.h5", progress=False)
    run = read_run(tmp_path / "a.h5")
    assert "\n" not in repr(run) and len(repr(run)) < 200 and "2 ok" in repr(run)
    assert "\n" not in repr(run["GLRK2-none"]) and "3 outputs" in repr(run["GLRK2-none"])


def test_scene_keys_are_plain_text_and_name_the_default_forms(capsys):
    assert cli_main(["scenes", "--keys"]) == 0
    out = capsys.readouterr().out
    assert "``" not in out and ":class:" not in out and "default: canonical and noncanonical" in out


def test_the_audit_doc_counts_the_builtin_tableaus():
    import integrators
    doc = (Path(__file__).parents[1] / "docs" / "audit.md").read_text()
    assert f"all {len(integrators.TABLEAU_NAMES)} built-in tableaus" in doc


def test_an_expression_not_finite_at_the_sample_points_is_refused():
    with pytest.raises(SceneError, match=r"^loop: system.H is not finite at point 0 = \[0.55, 0.5\]"):
        parse_scene(USER.replace('H = "x^2 + y^2"', 'H = "sqrt(x - 10) + y^2"'))


def test_force_never_replaces_what_is_not_a_regular_file(tmp_path):
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="is not a regular file"):
        driver.run(scene(20), fifo, force=True, progress=False)
    assert not fifo.is_file() and fifo.exists()


def test_force_through_a_symlink_replaces_its_target(tmp_path):
    target, link = tmp_path / "data" / "a.h5", tmp_path / "a.h5"
    target.parent.mkdir()
    driver.run(scene(20), target, progress=False)
    link.symlink_to(target)
    driver.run(scene(30), link, force=True, progress=False)
    assert link.is_symlink()
    with h5py.File(target) as f:
        assert int(f.attrs["steps"]) == 30


def test_a_step_count_beyond_exact_step_times_is_refused(capsys, tmp_path):
    with pytest.raises(SceneError, match=r"run.steps must be between 1 and 2\^53"):
        parse_scene(USER.replace("steps = 20", "steps = 100000000000000000000"))
    (tmp_path / "osc.toml").write_text(USER)
    assert cli_main(["run", str(tmp_path / "osc.toml"), "-o", str(tmp_path / "o.h5"), "--steps", str(2**53 + 1)]) == 2
    assert "--steps must be at most 2^53" in capsys.readouterr().err and not (tmp_path / "o.h5").exists()
