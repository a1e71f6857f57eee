"""The edges a new user found, round two (issue 40): user code that never returns, tracebacks from
deep or huge inputs, truncated files called locked, a failed extension that damaged a finished
file, sys.exit in user code, NaN energy errors, names that pass for built-ins, code from outside
the scene's folder, and the smaller items."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from integrators.service import driver, files, output
from integrators.cli import main as cli_main
from integrators.service.scene import SceneError, parse_scene
from test_edges import BIN, LV, USER, one_line, poincare

MAPS = """
import os, sys, time
calls = [0]

def stuck(q, p, lam, h, system):
    calls[0] += 1
    if calls[0] > 30 and os.environ.get("STUCK_RANK", os.environ.get("PMI_RANK", "0")) == os.environ.get("PMI_RANK", "0"):
        if os.environ.get("SPIN"):
            while True:
                pass
        time.sleep(10**6)
    return q, p, lam

def bye(q, p, lam, h, system):
    sys.exit(0)

def shape_bye(tau):
    sys.exit(3)
"""

STUCK = USER.replace('tableaus = ["GLRK1"]\nprojections = ["none"]', 'step_maps = ["maps.py:stuck"]') \
    .replace("steps = 20", "steps = 100") + "[output]\ncheckpoint_seconds = 0.0\n"


def _rows(path, pair):
    with h5py.File(path, "r", locking=False) as f:
        return f[f"runs/{pair}/t"].shape[0]


def _wait_rows(path, pair, rows, proc, limit=120):
    deadline = time.time() + limit
    while time.time() < deadline and proc.poll() is None:
        time.sleep(0.1)
        try:
            if _rows(path, pair) >= rows:
                return True
        except (OSError, KeyError, RuntimeError):
            pass
    return False


# -- 1. user code that never returns ---------------------------------------------------------------

@pytest.mark.parametrize("how,signame,code", [("sleep", "SIGTERM", 143), ("spin", "SIGINT", 130)])
def test_a_step_map_that_never_returns_is_stopped_by_a_signal(tmp_path, how, signame, code):
    (tmp_path / "maps.py").write_text(MAPS)
    (tmp_path / "s.toml").write_text(STUCK)
    env = dict(os.environ, **({"SPIN": "1"} if how == "spin" else {}))
    proc = subprocess.Popen([str(BIN / "poincare"), "run", "s.toml", "-o", "s.h5", "-q"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert _wait_rows(tmp_path / "s.h5", "stuck-map", 3, proc)
    time.sleep(1.0)                       # now in the map for good (calls > 30: output rows at 10 steps)
    proc.send_signal(getattr(signal, signame))
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == code, err
    one_line(subprocess.CompletedProcess([], code, "", err), signame, "--resume")
    with h5py.File(tmp_path / "s.h5") as f:          # closed cleanly: every output flushed before is there
        g = f["runs/stuck-map"]
        assert g["t"].shape[0] >= 3 and g["I1/canonical"].shape[0] == g["t"].shape[0]
        assert g.attrs["status"] == "pending"


@pytest.mark.mpi
def test_a_rank_stuck_in_user_code_does_not_keep_mpiexec_from_stopping(tmp_path):
    """Rank 1 never returns from the map; rank 0 ends up waiting for its parts in an MPI receive,
    where no Python signal handler runs: the watchdog ends the run after POINCARE_STOP_GRACE."""
    (tmp_path / "maps.py").write_text(MAPS)
    (tmp_path / "s.toml").write_text(STUCK)
    env = dict(os.environ, STUCK_RANK="1", POINCARE_STOP_GRACE="1")
    proc = subprocess.Popen([str(BIN / "mpiexec"), "-n", "2", str(BIN / "poincare"), "run", "s.toml", "-o", "s.h5",
                             "-q"], cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert _wait_rows(tmp_path / "s.h5", "stuck-map", 2, proc)
    time.sleep(2.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    ours = [line for line in err.splitlines() if line.startswith("poincare:")]
    assert len(ours) == 1 and "SIGTERM" in ours[0] and "--resume" in ours[0] and "Traceback" not in err
    deadline = time.time() + 30           # the aborted ranks may still be exiting (and hold the file's lock)
    while True:
        try:
            with h5py.File(tmp_path / "s.h5", "r") as f:
                assert f["runs/stuck-map/t"].shape[0] >= 2
            break
        except BlockingIOError:
            assert time.time() < deadline
            time.sleep(0.2)


# -- 2. no traceback from a scene, tableau, option or file -----------------------------------------

OSC = USER.replace('H = "x^2 + y^2"', 'H = "x^2 + y^2"')


@pytest.mark.parametrize("change,words", [
    (lambda t: t + "\ndeep = " + "[" * 10000 + "]" * 10000 + "\n", ("nested 10000 deep", "at most 32")),
    (lambda t: t.replace('H = "x^2 + y^2"', 'H = "' + "-" * 1990 + 'x"'), ("system.H", "nested more than 100")),
    (lambda t: t.replace('H = "x^2 + y^2"', 'H = "x^2*1e308*1e308"'), ("system.H", "beyond the range of a double")),
    (lambda t: t.replace("h = 0.1", "h = 1e300"), ("run.h", "outside [1e-150, 1e+150]")),
    (lambda t: t.replace("h = 0.1", "h = 1e-320"), ("run.h", "outside [1e-150, 1e+150]")),
])
def test_hostile_scenes_are_one_line_before_any_file(tmp_path, change, words):
    (tmp_path / "s.toml").write_text(change(OSC))
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
    (tmp_path / "s.toml").write_text(OSC.replace('tableaus = ["GLRK1"]', 'tableaus = ["t.toml"]'))
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


def test_plot_of_a_run_stopped_before_any_row_with_points_stored(tmp_path):
    sc = parse_scene(LV.replace('diagnostics = ["energy", "constraint"]',
                                'diagnostics = ["energy", "constraint"]\nstore_points = true'))

    def stop():
        raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        driver.run(sc, tmp_path / "a.h5", progress=False, stop=stop)
    r = poincare("plot", str(tmp_path / "a.h5"), "-o", str(tmp_path / "png"))
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert not (tmp_path / "png" / "a_points.png").exists()     # no point was stored: no picture of them


# -- 3. a truncated file is damaged, not locked ----------------------------------------------------

@pytest.mark.slow
def test_a_truncated_file_is_called_damaged_not_locked(tmp_path):
    out = tmp_path / "lv.h5"
    driver.run(parse_scene(LV), out, progress=False)
    clean = out.read_bytes()
    (tmp_path / "lv.toml").write_text(LV)
    for size in (512, 1024, 2048, 4096, len(clean) // 2):
        out.write_bytes(clean[:size])
        for args in (("plot", str(out), "-o", str(tmp_path / "png")),
                     ("run", "lv.toml", "-o", str(out), "--resume", "-q")):
            r = poincare(*args, cwd=tmp_path)
            assert r.returncode == 2, (size, r.stderr)
            one_line(r, "damaged")
            assert "another process" not in r.stderr and "lock" not in r.stderr.replace("sblock", ""), r.stderr
        assert out.read_bytes() == clean[:size]


def test_lock_errors_are_told_from_damage():
    assert files.is_lock_error(BlockingIOError(11, "Resource temporarily unavailable"))
    assert files.is_lock_error(OSError("Unable to open file (unable to lock file, errno = 11, error message = "
                                        "'Resource temporarily unavailable')"))
    assert not files.is_lock_error(OSError("Unable to open file (bad object header version number)"))
    assert not files.is_lock_error(OSError("Unable to open file (truncated file: eof = 512, sblock->base_addr "
                                            "= 0, stored_eof = 96000)"))


def test_two_runs_creating_one_file_at_once(tmp_path):
    """The second of two runs that both found no file is refused as busy (exit 2), never writing
    over the first run's new file."""
    sc = parse_scene(LV)
    out = tmp_path / "a.h5"
    first = h5py.File(out, "w")                   # another run created it after our check
    try:
        with pytest.raises(files.BusyFile, match="another process"):
            output.create(out, sc, "0", 64, {}, 1e-10)
    finally:
        first.close()


# -- 4. a failed extension leaves a finished file as it was ------------------------------------------

def _limited(extra):
    import resource

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (extra, extra))
    return limit


def _finished_then_on_a_full_disk(tmp_path, room, *args):
    """A finished run of LV in tmp_path/lv.h5, then ``poincare run … args`` with ``room`` bytes to
    grow beyond the file's size; returns (the file's bytes before, the second command's result)."""
    (tmp_path / "lv.toml").write_text(LV)
    out = tmp_path / "lv.h5"
    assert poincare("run", "lv.toml", "-o", "lv.h5", "-q", cwd=tmp_path).returncode == 0
    before = out.read_bytes()
    r = subprocess.run([str(BIN / "poincare"), "run", "lv.toml", "-o", "lv.h5", *args, "--steps", "4000", "-q"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       preexec_fn=_limited(len(before) + room))
    return before, r


@pytest.mark.parametrize("room", [1000, 20000])      # no room for the copy / for the first new output
def test_a_failed_extension_leaves_the_finished_file_byte_for_byte(tmp_path, room):
    out = tmp_path / "lv.h5"
    before, r = _finished_then_on_a_full_disk(tmp_path, room, "--resume")
    assert r.returncode == 3, r.stderr
    one_line(r, "lv.h5", "as it was")
    assert ".new" not in r.stderr
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lv.h5", "lv.toml"]     # no working copy left
    r = poincare("run", "lv.toml", "-o", "lv.h5", "--resume", "--steps", "40", "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    with h5py.File(out) as f:
        assert f["runs/GLRK2-symmetric/t"].shape[0] == 5 and f.attrs["steps"] == 40


# -- 5. sys.exit in user code -------------------------------------------------------------------------

def test_sys_exit_in_a_step_map_stops_its_points_not_the_run(tmp_path):
    (tmp_path / "maps.py").write_text(MAPS)
    (tmp_path / "s.toml").write_text(STUCK.replace("maps.py:stuck", "maps.py:bye"))
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    assert "bye-map" in r.stdout and "failed" in r.stdout and "called sys.exit(0)" in r.stderr
    with h5py.File(tmp_path / "s.h5") as f:
        assert f["runs/bye-map"].attrs["status"] == "failed"


def test_sys_exit_in_a_shape_is_one_line_and_force_keeps_the_old_file(tmp_path):
    (tmp_path / "maps.py").write_text(MAPS)
    (tmp_path / "s.toml").write_text(OSC)
    assert poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path).returncode == 0
    before = (tmp_path / "s.h5").read_bytes()
    (tmp_path / "s.toml").write_text(OSC.replace('shape = "ellipse"', 'shape = "maps.py:shape_bye"')
                                     .replace("params = { d = 2, center = [0.5, 0.5], radii = [0.05, 0.05] }\n", ""))
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", "--force", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "loop.shape", "called sys.exit(3)")
    assert (tmp_path / "s.h5").read_bytes() == before


# -- 6. energy errors where H0 = 0 ---------------------------------------------------------------------

def test_an_energy_error_where_H0_is_zero_is_absolute_and_said(tmp_path):
    """H = y − 1/2 vanishes at two loop points (τ = 0, 1/2: y = 1/2 + 0.05 sin 2πτ is 1/2 exactly):
    there the error is |H − H0|, never NaN, and the file and the summary say so."""
    (tmp_path / "s.toml").write_text(OSC.replace('H = "x^2 + y^2"', 'H = "y - 1/2"')
                                     .replace('projections = ["none"]', 'projections = ["none"]\n'
                                              'diagnostics = ["energy", "constraint"]'))
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "absolute error |H − H0| at the 2 points where H0 = 0" in r.stdout
    with h5py.File(tmp_path / "s.h5") as f:
        e = f["runs/GLRK1-none/energy_error"][...]
        assert np.isfinite(e).all() and e[0] == 0.0
        assert f.attrs["energy_absolute_points"] == 2 and "absolute" in f.attrs["energy_error"]


def test_the_energy_scale_is_relative_where_H0_is_not_zero():
    from integrators.service.diagnostics import energy_scale
    assert np.array_equal(energy_scale([-2.0, 0.0, 3.0, -0.0]), [2.0, 1.0, 3.0, 1.0])


# -- 7, 8, 9: names and code ---------------------------------------------------------------------------

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


def test_relative_error_names_an_invariant_or_form_it_does_not_hold(tmp_path):
    driver.run(parse_scene(LV), tmp_path / "a.h5", progress=False)
    from integrators.service import read_run
    p = read_run(tmp_path / "a.h5")["GLRK2-symmetric"]
    assert p.relative_error("I1", "canonical").shape == p.t.shape
    for inv, form, msg in (("I3", "canonical", "choose 'I1'"), ("i1", "canonical", "choose 'I1'"),
                           ("I2", "canonical", "no surface"), ("I1", "corrected", "holds: canonical")):
        with pytest.raises(ValueError, match=msg):
            p.relative_error(inv, form)


# -- 10. the smaller items ---------------------------------------------------------------------------------

def test_a_failed_force_names_the_file_and_says_force(tmp_path):
    out = tmp_path / "lv.h5"
    before, r = _finished_then_on_a_full_disk(tmp_path, 30000, "--force")
    assert r.returncode == 3, r.stderr
    one_line(r, "'lv.h5' failed", "as it was", "--force")
    assert ".new" not in r.stderr and "--resume" not in r.stderr
    assert out.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["lv.h5", "lv.toml"]


def test_an_os_error_during_force_abandons_the_replacement(tmp_path, monkeypatch):
    out = tmp_path / "a.h5"
    driver.run(parse_scene(LV), out, progress=False)
    before = out.read_bytes()

    def broken(*a, **k):
        raise OSError(5, "Input/output error")
    monkeypatch.setattr(output, "write_rows", broken)
    with pytest.raises(files.OutputError, match="Input/output error.*as it was.*--force"):
        driver.run(parse_scene(LV), out, force=True, progress=False)
    assert out.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["a.h5"]


def test_an_unwritable_cache_is_named(tmp_path):
    (tmp_path / "file").write_text("")
    (tmp_path / "s.toml").write_text(OSC.replace("x^2 + y^2", "x^2 + y^2 + 0.125"))   # a system not yet cached
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path, env={"POINCARE_CACHE": str(tmp_path / "file/x")})
    assert r.returncode == 2 and not (tmp_path / "s.h5").exists()
    one_line(r, "$POINCARE_CACHE", str(tmp_path / "file/x"))


def test_plots_into_a_folder_that_cannot_be_written(tmp_path, monkeypatch, capsys):
    driver.run(parse_scene(LV), tmp_path / "a.h5", progress=False)
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if str(p).endswith("ro") else real(p, mode))
    (tmp_path / "ro").mkdir()
    assert cli_main(["plot", str(tmp_path / "a.h5"), "-o", str(tmp_path / "ro")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot write plots in" in err and "Errno" not in err


def test_an_empty_output_option_is_refused(tmp_path, capsys):
    (tmp_path / "lv.toml").write_text(LV)
    assert cli_main(["run", str(tmp_path / "lv.toml"), "-o", "", "-q"]) == 2
    assert "-o/--output is empty" in capsys.readouterr().err
    from integrators import service
    with pytest.raises(ValueError, match="output is empty"):
        service.run(str(tmp_path / "lv.toml"), "  ")


def test_a_python_caller_is_advised_in_python_words(tmp_path):
    from integrators import service
    (tmp_path / "lv.toml").write_text(LV)
    service.run(str(tmp_path / "lv.toml"), tmp_path / "a.h5", progress=False)
    with pytest.raises(ValueError) as info:
        service.run(str(tmp_path / "lv.toml"), tmp_path / "a.h5", progress=False)
    assert "resume=True" in str(info.value) and "force=True" in str(info.value) and "--" not in str(info.value)


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


def test_an_audit_verdict_near_the_round_off_floor_says_so():
    from integrators.audit.report import text_report
    from invariants.growth import ROUNDOFF

    def entry(emax):
        return {"max_error": emax, "drift_rate": 1e-13, "verdict": "growing", "resolution": 1e-14,
                "near_floor": ROUNDOFF < emax <= 10 * ROUNDOFF, "growth_exponent": 2.54}
    report = {"scene": "s", "system": "x", "h": 0.1, "steps": 10, "T": 1.0, "discrimination": None,
              "candidates": [{"name": "GLRK2-symmetric", "role": "candidate", "breakdown_step": None, "jacobian": "x",
                              "drift": {"I1/corrected": entry(1.7 * ROUNDOFF), "I2/corrected": entry(1e3 * ROUNDOFF)},
                              "defect": {}}]}
    lines = text_report(report).splitlines()
    near = [line for line in lines if "I1/corrected" in line][0]
    far = [line for line in lines if "I2/corrected" in line][0]
    assert "growing (α = 2.54); near the round-off floor" in near and "near" not in far
