"""The command line (integrators/cli.py): statuses and exit codes, signals and mpiexec, the summary's notes,
plots, the audit's options, and advice in the caller's words."""
import os
import signal
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import integrators
from integrators.cli import main as cli_main
from integrators.service import driver
from integrators.service.scene import load_scene, parse_scene
from integrators.tableaus import tableau
from helpers import BIN, edit, GC, LV, LV_PAIRS, MAPS, one_line, PARTIAL, poincare, POINTS, SHAPES_TAU, SMALL, STUCK, USER, wait_rows



def test_the_audit_cli_refuses_a_code_tableau_in_one_line(tmp_path, monkeypatch, capsys):
    from integrators.cli import main
    monkeypatch.chdir(tmp_path)
    f = tmp_path / "evil.toml"
    f.write_text('a = [["__import__(\'os\').system(\'touch PWNED\')"]]\nb = [1]\nc = [0.5]\n')
    assert main(["audit", str(f), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a[0][0]" in err and "not allowed" in err
    assert not (tmp_path / "PWNED").exists()


def test_a_scene_where_every_point_breaks_down_fails(tmp_path):
    scene = tmp_path / "lv.toml"
    # h = 1.4: every point of every pair breaks down from 1.2 to 1.6 (measured); at 1.8-3.0 a few of
    # GLRK1-none's 64 points survive the 20 steps
    scene.write_text(LV_PAIRS.replace("h = 0.1", "h = 1.4"))
    r = poincare("run", str(scene), "-o", str(tmp_path / "lv.h5"), "-q")
    assert r.returncode == 1, r.stderr
    rows = [line for line in r.stdout.splitlines() if line.startswith("GLRK")]
    assert len(rows) == 4 and all(line.split()[1] == "failed" and "failed" in line.split()[3:] for line in rows)
    assert "0.000e+00" not in r.stdout and "4 failed of 4 pairs" in r.stdout
    with h5py.File(tmp_path / "lv.h5") as f:
        assert {f["runs"][k].attrs["status"] for k in f["runs"]} == {"failed"}


def test_an_under_resolved_set_is_reported_in_file_summary_exit_code_and_plot(tmp_path):
    scene = tmp_path / "gc.toml"
    scene.write_text(GC.replace("n_sigma = 20\nn_tau = 20", "n_sigma = 8\nn_tau = 8"))   # (12 x 12 is exact, issue 69)
    out = tmp_path / "gc.h5"
    r = poincare("run", str(scene), "-o", str(out), "-q")
    assert r.returncode == 1
    assert "under-resolved" in r.stdout and "the surface was under-resolved at" in r.stdout
    with h5py.File(out) as f:
        g = f["runs/GLRK2-symmetric"]
        assert g.attrs["status"] == "under-resolved" and g.attrs["under_resolved_from/I2"] == 0.0
        assert f.attrs["resolution_threshold"] == 1e-10
        assert g["resolved/I2"][0] == 0 and g["resolution/I2"][0] > 1e-10
        assert np.all(g["resolved/I1"][...] == 1)
    assert cli_main(["plot", str(out), "-o", str(tmp_path / "png")]) == 0


def test_a_resolved_scene_is_ok_and_exits_0(tmp_path):
    out = tmp_path / "gc.h5"
    summaries = driver.run(parse_scene(GC), out, progress=False)
    assert [s.status for s in summaries] == ["ok", "ok"]
    with h5py.File(out) as f:
        assert all(np.all(f["runs"][k]["resolved/I2"][...] == 1) for k in f["runs"])


def test_each_pairs_status_is_written_when_it_finishes(tmp_path):
    out = tmp_path / "gc.h5"

    def stop(pair, step):
        if pair == "GLRK2-symplectic" and step == 8:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        driver.run(parse_scene(GC), out, progress=False, after_output=stop)
    with h5py.File(out) as f:
        assert f["runs/GLRK2-symmetric"].attrs["status"] == "ok"
        assert f["runs/GLRK2-symplectic"].attrs["status"] == "pending"


@pytest.mark.slow
@pytest.mark.parametrize("signame,code", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_signal_flushes_says_how_to_resume_and_resume_finishes(tmp_path, signame, code):
    import signal
    scene = tmp_path / "gc.toml"
    # about 5 s of stepping (2 pairs of 464 points, 20,000 steps): a signal sent after the fifth row
    # lands mid-run even on a loaded machine (at 400 steps the run could finish first and exit 1)
    scene.write_text(GC.replace("steps = 40", "steps = 20000").replace("output_every = 4", "output_every = 200"))
    out = tmp_path / "gc.h5"
    proc = subprocess.Popen([str(BIN / "poincare"), "run", str(scene), "-o", str(out), "-q"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert wait_rows(out, "GLRK2-symmetric", 5, proc)
    proc.send_signal(getattr(signal, signame))
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert err.count("\n") == 1 and signame in err and "--resume" in err and "Traceback" not in err
    with h5py.File(out) as f:
        n = f["runs/GLRK2-symmetric/t"].shape[0]
        assert n >= 5 and f["runs/GLRK2-symmetric/I1/noncanonical"].shape[0] == n
    r = poincare("run", str(scene), "-o", str(out), "-q", "--resume")
    assert r.returncode in (0, 1) and "GLRK2-symplectic" in r.stdout


@pytest.mark.mpi
def test_sigterm_under_mpiexec_stops_every_rank(tmp_path):
    import signal
    scene = tmp_path / "gc.toml"
    scene.write_text(GC.replace("steps = 40", "steps = 40000"))
    out = tmp_path / "gc.h5"
    proc = subprocess.Popen([str(BIN / "mpiexec"), "-n", "2", str(BIN / "poincare"), "run", str(scene), "-o", str(out),
                             "-q"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert wait_rows(out, "GLRK2-symmetric", 5, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)          # no rank is left waiting in a collective
    assert proc.returncode == 143
    ours = [line for line in err.splitlines() if line.startswith("poincare:")]
    assert len(ours) == 1 and "SIGTERM" in ours[0] and "--resume" in ours[0] and "Traceback" not in err
    with h5py.File(out, "r", locking=False) as f:      # a rank's lock can outlive it by a moment under load
        assert f["runs/GLRK2-symmetric/t"].shape[0] >= 5


@pytest.mark.mpi
def test_an_error_is_printed_once_under_mpiexec(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(GC.replace("h = 10.0", "h = -1.0"))
    r = poincare("run", str(bad), "-o", str(tmp_path / "x.h5"), n=2)
    assert r.returncode != 0
    assert r.stderr.strip() == "poincare: error: run.h must be a finite positive number, got -1.0"


def test_audit_module_function_from_the_current_directory(tmp_path):
    (tmp_path / "mystep.py").write_text((POINTS / "audit_maps.py").read_text())
    r = poincare("audit", "mystep:rk4", "--steps", "5", "--reference", "none", "--points", "2", "--levels", "3",
                 "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "not symplectic" in r.stdout


def test_a_step_map_that_raises_in_the_defect_study_is_a_verdict(capsys):
    from integrators import audit
    import audit_maps
    scene = load_scene("point_vortices").with_steps(5)
    rep = audit.audit([audit.Candidate("broken", audit_maps.broken, "function")], scene, levels=3, defect_points=2)
    c = rep["candidates"][0]
    assert c["breakdown_step"] == 1 and all(r["verdict"] == "broke down" for r in c["drift"].values())
    assert all(r["verdict"].startswith("step failed (broken raised RuntimeError") for r in c["defect"].values())
    assert "step failed" in audit.text_report(rep)


@pytest.mark.parametrize("args,msg", [(["--points", "0"], "--points must be a positive integer"),
                                      (["--levels", "0"], "--levels must be a positive integer")])
def test_audit_options_are_validated(args, msg, capsys):
    assert cli_main(["audit", "GLRK1", *args, "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and msg in err


def test_default_audit_scene_tells_non_symplectic_maps_apart():
    """On the audit's default scene (point vortices) the implicit midpoint rule, GLRK1-standard and RK4
    are not symplectic, with the defect orders docs/audit.md states (measured 3.21, 4.00, 5.16)."""
    from integrators import audit
    import audit_maps
    args = cli_main.__globals__["build_parser"]().parse_args(["audit", "GLRK1"])
    scene = load_scene(args.scene)
    assert scene.system_name == "point_vortices"
    q = scene.loop_points()[::64][:4]
    cands = [("implicit_midpoint", audit_maps.implicit_midpoint, None, (2.9, 3.5)),
             ("GLRK1-standard", audit.stepper_map(tableau("GLRK1"), "standard"), set(), (3.8, 4.2)),
             ("rk4", audit_maps.rk4, None, (4.8, 5.5))]
    for name, step, reads, (lo, hi) in cands:
        r, used = audit.defect_study(step, scene.system(), q, scene.h, 5, reads=reads)
        nc = r["noncanonical"]
        assert used == "complex step" and nc["verdict"] == "not symplectic", name
        assert lo < nc["order"] < hi, (name, nc["order"])


def test_version_license_citation_and_scene_keys(capsys):
    with pytest.raises(SystemExit) as e:
        cli_main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"poincare {integrators.__version__}"
    assert cli_main(["scenes", "--keys"]) == 0
    keys = capsys.readouterr().out
    assert all(k in keys for k in ("[system]", "n_sigma", "output_every", "store_points", "file.py:function"))
    root = Path(__file__).parent.parent
    assert "MIT License" in (root / "LICENSE").read_text()
    import tomllib
    assert tomllib.loads((root / "pyproject.toml").read_text())["project"]["license"] == "MIT"
    cff = (root / "CITATION.cff").read_text()
    assert "cff-version" in cff and "Projected Variational Integrators" in cff


def test_plot_shades_exactly_the_under_resolved_outputs():
    from integrators.service.plots import _stretches
    t = np.array([0.0, 10.0, 20.0, 30.0, 40.0])
    assert _stretches(t, np.array([0, 1, 1, 0, 1], bool)) == [(5.0, 25.0), (35.0, 45.0)]
    assert _stretches(t, np.zeros(5, bool)) == []
    assert _stretches(t, np.ones(5, bool)) == [(-5.0, 45.0)]


def test_the_summary_lists_the_code_a_scene_ran(tmp_path):
    (tmp_path / "shapes.py").write_text(SHAPES_TAU)
    (tmp_path / "osc.toml").write_text(USER.replace('shape = "ellipse"', 'shape = "shapes:circle"').replace(
        "params = { d = 2, center = [0.5, 0.5], radii = [0.05, 0.05] }", "params = { r = 0.02 }"))
    r = poincare("run", "osc.toml", "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert f"loop.shape = shapes:circle: {tmp_path.resolve() / 'shapes.py'}:circle" in r.stdout


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


def test_threads_beyond_the_cores_are_refused(tmp_path, scene_file, capsys):
    scene_file("oscillator", to="osc.toml")
    assert cli_main(["run", str(tmp_path / "osc.toml"), "-o", str(tmp_path / "o.h5"), "--threads", "100000"]) == 2
    assert "--threads must be between 1 and" in capsys.readouterr().err
    assert not (tmp_path / "o.h5").exists()


def test_audit_outputs_are_checked_before_the_audit(tmp_path, capsys):
    assert cli_main(["audit", "GLRK1", "--json", str(tmp_path / "no" / "a.json"), "-q"]) == 2
    assert "--json: directory" in capsys.readouterr().err
    (tmp_path / "f").write_text("")
    assert cli_main(["audit", "GLRK1", "--plots", str(tmp_path / "f"), "-q"]) == 2
    assert "--plots" in capsys.readouterr().err
    assert cli_main(["audit", "GLRK1", "--reference", "XYZ-none", "-q"]) == 2
    err = capsys.readouterr().err
    assert "reference 'XYZ-none'" in err and "candidate" not in err


def test_the_audit_doc_counts_the_builtin_tableaus():
    import integrators
    doc = (Path(__file__).parents[1] / "docs" / "audit.md").read_text()
    assert f"all {len(integrators.TABLEAU_NAMES)} built-in tableaus" in doc


@pytest.mark.parametrize("how,signame,code", [("sleep", "SIGTERM", 143), ("spin", "SIGINT", 130)])
def test_a_step_map_that_never_returns_is_stopped_by_a_signal(tmp_path, how, signame, code):
    (tmp_path / "maps.py").write_text(MAPS)
    (tmp_path / "s.toml").write_text(STUCK)
    env = dict(os.environ, **({"SPIN": "1"} if how == "spin" else {}))
    proc = subprocess.Popen([str(BIN / "poincare"), "run", "s.toml", "-o", "s.h5", "-q"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert wait_rows(tmp_path / "s.h5", "stuck-map", 3, proc)
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
    assert wait_rows(tmp_path / "s.h5", "stuck-map", 2, proc)
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


def test_sys_exit_in_a_step_map_stops_its_points_not_the_run(tmp_path):
    (tmp_path / "maps.py").write_text(MAPS)
    (tmp_path / "s.toml").write_text(STUCK.replace("maps.py:stuck", "maps.py:bye"))
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    assert "bye-map" in r.stdout and "failed" in r.stdout and "called sys.exit(0)" in r.stderr
    with h5py.File(tmp_path / "s.h5") as f:
        assert f["runs/bye-map"].attrs["status"] == "failed"


def test_sys_exit_in_a_shape_is_one_line_and_force_keeps_the_old_file(tmp_path, scene_file):
    (tmp_path / "maps.py").write_text(MAPS)
    scene_file("oscillator", to="s.toml")
    assert poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path).returncode == 0
    before = (tmp_path / "s.h5").read_bytes()
    (tmp_path / "s.toml").write_text(USER.replace('shape = "ellipse"', 'shape = "maps.py:shape_bye"')
                                     .replace("params = { d = 2, center = [0.5, 0.5], radii = [0.05, 0.05] }\n", ""))
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", "--force", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "loop.shape", "called sys.exit(3)")
    assert (tmp_path / "s.h5").read_bytes() == before


def test_an_energy_error_where_H0_is_zero_is_absolute_and_said(tmp_path):
    """H = y − 1/2 vanishes at two loop points (τ = 0, 1/2: y = 1/2 + 0.05 sin 2πτ is 1/2 exactly):
    there the error is |H − H0|, never NaN, and the file and the summary say so."""
    (tmp_path / "s.toml").write_text(USER.replace('H = "x^2 + y^2"', 'H = "y - 1/2"')
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


def test_relative_error_names_an_invariant_or_form_it_does_not_hold(tmp_path):
    driver.run(parse_scene(LV), tmp_path / "a.h5", progress=False)
    from integrators.service import read_run
    p = read_run(tmp_path / "a.h5")["GLRK2-symmetric"]
    assert p.relative_error("I1", "canonical").shape == p.t.shape
    for inv, form, msg in (("I3", "canonical", "choose 'I1'"), ("i1", "canonical", "choose 'I1'"),
                           ("I2", "canonical", "no surface"), ("I1", "corrected", "holds: canonical")):
        with pytest.raises(ValueError, match=msg):
            p.relative_error(inv, form)


def test_plots_into_a_folder_that_cannot_be_written(tmp_path, monkeypatch, capsys):
    driver.run(parse_scene(LV), tmp_path / "a.h5", progress=False)
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if str(p).endswith("ro") else real(p, mode))
    (tmp_path / "ro").mkdir()
    assert cli_main(["plot", str(tmp_path / "a.h5"), "-o", str(tmp_path / "ro")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot write plots in" in err and "Errno" not in err


def test_an_empty_output_option_is_refused(tmp_path, scene_file, capsys):
    scene_file("lv")
    assert cli_main(["run", str(tmp_path / "lv.toml"), "-o", "", "-q"]) == 2
    assert "-o/--output is empty" in capsys.readouterr().err
    from integrators import service
    with pytest.raises(ValueError, match="output is empty"):
        service.run(str(tmp_path / "lv.toml"), "  ")


def test_a_python_caller_is_advised_in_python_words(tmp_path, scene_file):
    from integrators import service
    scene_file("lv")
    service.run(str(tmp_path / "lv.toml"), tmp_path / "a.h5", progress=False)
    with pytest.raises(ValueError) as info:
        service.run(str(tmp_path / "lv.toml"), tmp_path / "a.h5", progress=False)
    assert "resume=True" in str(info.value) and "force=True" in str(info.value) and "--" not in str(info.value)


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


@pytest.mark.parametrize("argv,msg", [
    (["run", "no-such-scene"], "neither a file nor a built-in scene"),
    (["plot", "missing.h5"], "does not exist"),
    (["run", "--resume", "-o", "nothing.h5"], "cannot resume"),
])
def test_cli_errors_are_one_line(argv, msg, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli_main(argv) == 2
    err = capsys.readouterr().err
    assert msg in err and err.count("\n") == 1 and "Traceback" not in err


def test_bad_scene_file_through_the_cli(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(edit(SMALL, "h = 10.0", "h = -10.0"))
    r = poincare("run", str(bad), "-o", str(tmp_path / "x.h5"))
    assert r.returncode == 2 and r.stderr.strip() == "poincare: error: run.h must be a finite positive number, got -10.0"
    assert not (tmp_path / "x.h5").exists()


def test_plots_are_written(tmp_path):
    scene = parse_scene(edit(SMALL, "forms = [", "store_points = true\nforms = ["))
    out = tmp_path / "p.h5"
    driver.run(scene, out, progress=False)
    assert cli_main(["plot", str(out), "-o", str(tmp_path / "png")]) == 0
    names = sorted(p.name for p in (tmp_path / "png").iterdir())
    assert names == sorted([f"p_I{k}_{f}.png" for k in (1, 2) for f in ("canonical", "corrected", "noncanonical")]
                           + ["p_diagnostics.png", "p_points.png"])
    assert all((tmp_path / "png" / n).stat().st_size > 10_000 for n in names)


ODD_MAPS = '''import numpy as np

def interrupts(q, p, lam, h, system):
    raise KeyboardInterrupt

def complex_map(q, p, lam, h, system):
    return q + 0j, p + 1e-3j, lam

def complex_shape(tau):
    return np.stack([0.5 + 0.05 * np.cos(2 * np.pi * tau), 0.5 + 0.05j * np.sin(2 * np.pi * tau)], axis=1)
'''


def test_a_step_map_that_raises_keyboardinterrupt_or_returns_complex_values_fails_as_code(tmp_path):
    """A KeyboardInterrupt raised by a step map itself is that map's failure, not 'interrupted by
    SIGINT' (no signal was sent); complex values from a step map or a loop shape are refused, not cut
    to their real part (issue 56)."""
    (tmp_path / "maps.py").write_text(ODD_MAPS)
    for name, say in (("interrupts", "raised KeyboardInterrupt itself (no signal was sent)"),
                      ("complex_map", "values of types complex128")):
        (tmp_path / "s.toml").write_text(STUCK.replace("maps.py:stuck", f"maps.py:{name}").replace("steps = 100", "steps = 10"))
        r = poincare("run", "s.toml", "-o", f"{name}.h5", "-q", cwd=tmp_path)
        assert r.returncode == 1 and "SIGINT" not in r.stderr + r.stdout, r.stderr
        assert say in r.stderr and f"{name}-map" in r.stdout and "failed" in r.stdout, r.stderr
    (tmp_path / "s.toml").write_text(USER.replace('shape = "ellipse"', 'shape = "maps.py:complex_shape"')
                                     .replace("params = { d = 2, center = [0.5, 0.5], radii = [0.05, 0.05] }\n", ""))
    r = poincare("run", "s.toml", "-o", "c.h5", "-q", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "loop function returned complex values")


def test_plain_errors_for_plain_mistakes(tmp_path):
    """read_run(None), an output path of 123 and an unknown pair are one-line errors, not a raw
    TypeError or a bare KeyError (issue 56)."""
    from integrators import service
    from integrators.service.reader import read_run
    with pytest.raises(ValueError, match="read_run: a run file's path .* got NoneType None"):
        read_run(None)
    with pytest.raises(ValueError, match="output: a file path .* got int 123"):
        service.run("point_vortices", 123)
    out = tmp_path / "pv.h5"
    (tmp_path / "s.toml").write_text(USER)
    assert poincare("run", "s.toml", "-o", str(out), "-q", cwd=tmp_path).returncode == 0
    with pytest.raises(KeyError, match=r"no pair 'GLRK9-none' in this run; its pairs: GLRK1-none"):
        read_run(out).pairs["GLRK9-none"]

