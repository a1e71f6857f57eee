"""Results you can trust (issue 15): no code from data files, names never matter, failures are
failures, under-resolved sets are reported, batch-safe output, validated extension points."""
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import sympy

import integrators
from integrators.expressions import ExpressionError, parse_expression, parse_number
from integrators.tableaus import tableau, tableau_from_file


# -- no code from data ------------------------------------------------------------------------------

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


def test_the_audit_cli_refuses_a_code_tableau_in_one_line(tmp_path, monkeypatch, capsys):
    from integrators.cli import main
    monkeypatch.chdir(tmp_path)
    f = tmp_path / "evil.toml"
    f.write_text('a = [["__import__(\'os\').system(\'touch PWNED\')"]]\nb = [1]\nc = [0.5]\n')
    assert main(["audit", str(f), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a[0][0]" in err and "not allowed" in err
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


# -- names never matter ------------------------------------------------------------------------------

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


# -- the service: statuses, exit codes, batch safety ---------------------------------------------------

from integrators.service import driver  # noqa: E402
from integrators.service.checkpoints import slot_files  # noqa: E402
from integrators.cli import main as cli_main  # noqa: E402
from integrators.service.scene import SceneError, load_scene, parse_scene  # noqa: E402

POINTS = Path(__file__).parent
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
tableaus = ["GLRK1", "GLRK2"]
projections = ["none", "standard"]
h = 0.1
steps = 20
output_every = 5
diagnostics = ["energy", "constraint"]
"""

GC = """
name = "gc"
[system]
name = "guiding_centre_symmetric"
[loop]
points = 64
[surface]
n_sigma = 20
n_tau = 20
[run]
tableaus = ["GLRK2"]
projections = ["symmetric", "symplectic"]
h = 10.0
steps = 40
output_every = 4
forms = ["canonical", "noncanonical", "corrected"]
"""


def poincare(*args, cwd=None, n=None, **kw):
    cmd = [str(BIN / "poincare"), *args]
    if n:
        cmd = [str(BIN / "mpiexec"), "-n", str(n), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=cwd, **kw)


def test_a_scene_where_every_point_breaks_down_fails(tmp_path):
    scene = tmp_path / "lv.toml"
    scene.write_text(LV.replace("h = 0.1", "h = 2.0"))
    r = poincare("run", str(scene), "-o", str(tmp_path / "lv.h5"), "-q")
    assert r.returncode == 1, r.stderr
    rows = [line for line in r.stdout.splitlines() if line.startswith("GLRK")]
    assert len(rows) == 4 and all(line.split()[1] == "failed" and "failed" in line.split()[3:] for line in rows)
    assert "0.000e+00" not in r.stdout and "4 failed of 4 pairs" in r.stdout
    with h5py.File(tmp_path / "lv.h5") as f:
        assert {f["runs"][k].attrs["status"] for k in f["runs"]} == {"failed"}


def test_an_under_resolved_set_is_reported_in_file_summary_exit_code_and_plot(tmp_path):
    scene = tmp_path / "gc.toml"
    scene.write_text(GC.replace("n_sigma = 20\nn_tau = 20", "n_sigma = 12\nn_tau = 12"))
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


def _wait_for_rows(path, pair, rows, proc, limit=120):
    import time
    deadline = time.time() + limit
    while time.time() < deadline and proc.poll() is None:
        time.sleep(0.1)
        try:
            with h5py.File(path, "r", locking=False) as f:
                if f[f"runs/{pair}/t"].shape[0] >= rows:
                    return True
        except (OSError, KeyError, RuntimeError):
            pass
    return False


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
    assert _wait_for_rows(out, "GLRK2-symmetric", 5, proc)
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
    assert _wait_for_rows(out, "GLRK2-symmetric", 5, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)          # no rank is left waiting in a collective
    assert proc.returncode == 143
    ours = [line for line in err.splitlines() if line.startswith("poincare:")]
    assert len(ours) == 1 and "SIGTERM" in ours[0] and "--resume" in ours[0] and "Traceback" not in err
    with h5py.File(out) as f:
        assert f["runs/GLRK2-symmetric/t"].shape[0] >= 5


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.parametrize("checkpoints", ["in-file", "per-rank"])
def test_a_run_stopped_on_2_ranks_resumes_on_3_to_the_one_rank_bits(tmp_path, checkpoints):
    """Kill and resume on a different rank count: the checkpoint holds every point's state whatever
    split wrote it, and the resumed file's rows are the uninterrupted 1-rank run's, bit for bit.
    Per-rank checkpoints (each rank's slab in its own file beside the run file, linked into it):
    the same, the final state read through the links is the in-file run's, the folder keeps only the
    slabs linked (a killed run's unlinked ones are removed), and without the folder the resume is
    refused in one line naming it while the results still read."""
    import signal
    text = GC.replace("steps = 40", "steps = 20000").replace("output_every = 4", "output_every = 200") \
        + "[output]\ncheckpoint_seconds = 0.0\n"
    (tmp_path / "full.toml").write_text(text)
    scene = tmp_path / "gc.toml"
    scene.write_text(text + f'checkpoints = "{checkpoints}"\n')
    full, part = tmp_path / "full.h5", tmp_path / "part.h5"
    rc = poincare("run", str(tmp_path / "full.toml"), "-o", str(full), "-q").returncode
    proc = subprocess.Popen([str(BIN / "mpiexec"), "-n", "2", str(BIN / "poincare"), "run", str(scene), "-o",
                             str(part), "-q"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert _wait_for_rows(part, "GLRK2-symmetric", 5, proc)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=60)
    assert proc.returncode == 143
    with h5py.File(part) as f:
        assert f["runs/GLRK2-symplectic"].attrs["status"] == "pending"
    folder = tmp_path / "part.h5.checkpoints"
    if checkpoints == "per-rank":
        folder.rename(tmp_path / "elsewhere")
        r = poincare("run", str(scene), "-o", str(part), "-q", "--resume")
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and str(folder) in r.stderr, r.stderr
        assert integrators.service.read_run(part)["GLRK2-symmetric"].t.size > 0
        (tmp_path / "elsewhere").rename(folder)
    r = poincare("run", str(scene), "-o", str(part), "-q", "--resume", n=3)
    assert r.returncode == rc, r.stderr
    skip = ("wall_clock",) if checkpoints == "per-rank" else ("wall_clock", "checkpoint")
    if checkpoints == "per-rank":
        with h5py.File(part) as f:
            slabs = {k: sorted(slot_files(g["checkpoint/a"]), key=lambda x: x[1]) for k, g in f["runs"].items()}
            assert all(f["runs"][k]["checkpoint/a/q"].is_virtual for k in f["runs"])
        for k, links in slabs.items():              # every point's state, once: the split of the last run
            assert [lo for _, lo, _ in links] == [0] + [hi for _, _, hi in links[:-1]] and links[-1][2] == 464, k
            assert len(links) in (2, 3) and all(name.startswith(k + ".20000.") for name, _, _ in links), k
        assert {p.name for p in folder.iterdir()} == {name for links in slabs.values() for name, _, _ in links}
    with h5py.File(full) as a, h5py.File(part) as b:
        names = []
        a.visit(lambda k: names.append(k) if isinstance(a[k], h5py.Dataset) and not any(x in k for x in skip)
                else None)
        assert names and all(np.array_equal(a[k][()], b[k][()], equal_nan=a[k].dtype.kind == "f") for k in names)
        assert [a["runs"][k].attrs["status"] for k in a["runs"]] == [b["runs"][k].attrs["status"] for k in b["runs"]]


def test_a_full_disk_is_one_line_and_leaves_a_readable_file(tmp_path):
    import resource
    import signal
    scene = tmp_path / "gc.toml"
    scene.write_text(GC)
    out = tmp_path / "gc.h5"

    def limit():                              # ulimit -f: writes past 600 kB fail as on a full disk
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (600_000, 600_000))

    r = subprocess.run([str(BIN / "poincare"), "run", str(scene), "-o", str(out), "-q"], preexec_fn=limit,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 3, r.stderr[-2000:]
    assert r.stderr.count("\n") == 1 and "no space left" in r.stderr and "--resume" in r.stderr
    with h5py.File(out) as f:                 # every flushed output is there
        rows = [f["runs"][k]["t"].shape[0] for k in ("GLRK2-symmetric", "GLRK2-symplectic")]
        assert rows[0] >= 1 and all(f["runs"][k]["I1/canonical"].shape[0] == n
                                    for k, n in zip(("GLRK2-symmetric", "GLRK2-symplectic"), rows))


@pytest.mark.parametrize("make,args,msg", [
    (lambda d: None, ["-o", "{d}/missing/x.h5"], "output directory '{d}/missing' does not exist"),
    (lambda d: (d / "adir").mkdir(), ["-o", "{d}/adir", "--force"], "is a directory"),
    (lambda d: None, ["-o", "/proc/poincare-test.h5"], "cannot create output '/proc/poincare-test.h5'"),
    (lambda d: (d / "x.h5").write_text(""), ["-o", "{d}/x.h5", "--resume", "--force"], "contradict"),
])
def test_unusable_outputs_are_one_plain_line(tmp_path, capsys, make, args, msg):
    make(tmp_path)
    scene = tmp_path / "gc.toml"
    scene.write_text(GC)
    rc = cli_main(["run", str(scene), "-q", *[a.format(d=tmp_path) for a in args]])
    err = capsys.readouterr().err
    assert rc in (2, 3) and err.count("\n") == 1 and msg.format(d=tmp_path) in err, err
    assert "flags =" not in err and "errno" not in err.lower()


@pytest.mark.mpi
def test_an_error_is_printed_once_under_mpiexec(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(GC.replace("h = 10.0", "h = -1.0"))
    r = poincare("run", str(bad), "-o", str(tmp_path / "x.h5"), n=2)
    assert r.returncode != 0
    assert r.stderr.strip() == "poincare: error: run.h must be a finite positive number, got -1.0"


def _flip_chunk(path, dataset):
    """Overwrite the first stored chunk of a dataset with garbage bytes (a damaged disk block)."""
    with h5py.File(path, "r") as f:
        info = f[dataset].id.get_chunk_info(0)
    with open(path, "r+b") as fh:
        fh.seek(info.byte_offset + 8)
        fh.write(b"\x13\x37" * 8)


def test_damaged_data_and_metadata_are_reported_not_plotted(tmp_path, capsys):
    out = tmp_path / "gc.h5"
    driver.run(parse_scene(GC), out, progress=False)
    _flip_chunk(out, "runs/GLRK2-symplectic/I1/noncanonical")
    assert cli_main(["plot", str(out), "-o", str(tmp_path / "png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and "I1/noncanonical" in err
    # a resume of the damaged file is one line too
    (tmp_path / "gc.toml").write_text(GC)
    assert cli_main(["run", str(tmp_path / "gc.toml"), "-o", str(out), "--resume", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and "--force" in err
    # missing metadata (a group gone) is one line, not a KeyError traceback
    out2 = tmp_path / "gc2.h5"
    driver.run(parse_scene(GC), out2, progress=False)
    with h5py.File(out2, "r+") as f:
        del f["runs/GLRK2-symmetric/t"]
    assert cli_main(["plot", str(out2), "-o", str(tmp_path / "png2")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and "Traceback" not in err


# -- resume ---------------------------------------------------------------------------------------------

def _dump(path, skip=("wall_clock", "checkpoint")):
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and not any(s in name for s in skip):
                out[name] = obj[...]
        f.visititems(visit)
        out["status"] = {k: f["runs"][k].attrs["status"] for k in f["runs"]}
    return out


def test_resume_compares_parsed_scenes_and_lists_the_keys_that_differ(tmp_path, capsys):
    scene = tmp_path / "gc.toml"
    scene.write_text(GC)
    out = tmp_path / "gc.h5"
    driver.run(parse_scene(GC), out, progress=False)
    scene.write_text("# a comment and different spacing\n" + GC.replace("h = 10.0", "h =   10.0"))
    assert cli_main(["run", str(scene), "-o", str(out), "--resume", "-q"]) == 0
    capsys.readouterr()
    scene.write_text(GC.replace("h = 10.0", "h = 5.0").replace('"symplectic"]', '"midpoint"]'))
    assert cli_main(["run", str(scene), "-o", str(out), "--resume", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "run.projections, run.h" in err


@pytest.mark.slow
def test_a_finished_run_extended_to_more_steps_equals_one_longer_run(tmp_path):
    short, longer = tmp_path / "short.toml", tmp_path / "long.toml"
    short.write_text(GC)
    longer.write_text(GC.replace("steps = 40", "steps = 80"))
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    assert poincare("run", str(longer), "-o", str(b), "-q").returncode == 0
    assert poincare("run", str(short), "-o", str(a), "-q").returncode == 0
    r = poincare("run", str(longer), "-o", str(a), "-q", "--resume")
    assert r.returncode == 0, r.stderr
    da, db = _dump(a), _dump(b)
    assert da.keys() == db.keys() and all(
        np.array_equal(da[k], db[k]) if k != "status" else da[k] == db[k] for k in da)
    # the same through --steps on the command line, and fewer steps are refused
    c = tmp_path / "c.h5"
    assert poincare("run", str(short), "-o", str(c), "-q").returncode == 0
    assert poincare("run", str(short), "-o", str(c), "-q", "--resume", "--steps", "80").returncode == 0
    dc = _dump(c)
    assert all(np.array_equal(dc[k], db[k]) if k != "status" else dc[k] == db[k] for k in db)
    r = poincare("run", str(short), "-o", str(c), "-q", "--resume")
    assert r.returncode == 2 and "fewer steps" in r.stderr


# -- extension points ------------------------------------------------------------------------------------

SHAPES = '''
import numpy as np

def circle(tau, r=0.3):
    return np.stack([r * np.cos(2 * np.pi * tau), r * np.sin(2 * np.pi * tau), 0 * tau, 0.5 + 0 * tau], axis=-1)

def boom(tau):
    raise RuntimeError("shape exploded")
'''


def test_file_py_and_module_shapes_in_scenes_and_a_raising_shape(tmp_path, monkeypatch):
    (tmp_path / "myshapes.py").write_text(SHAPES)
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


# -- small things ------------------------------------------------------------------------------------------

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
