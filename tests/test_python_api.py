"""The Python side of the service: a scene run from Python (integrators.service.run), results as
xarray, the notebook's HTML, and the progress bar (tqdm)."""
import re
import tomllib

import numpy as np
import pytest

from integrators import service
from integrators.service.scene import SceneError, builtin_scenes


def _small(steps=20):
    data = tomllib.loads(builtin_scenes()["default"].read_text())
    data["run"].update(tableaus=["GLRK1", "GLRK2"], projections=["none", "symmetric"], steps=steps)
    return data


def test_run_a_builtin_scene_with_overrides_returns_the_file_read(tmp_path):
    out = tmp_path / "a.h5"
    run = service.run("default", out, steps=10, tableaus=["GLRK2"], projections=["symmetric"], progress=False)
    assert isinstance(run, service.Run) and run.steps == 10 and list(run.pairs) == ["GLRK2-symmetric"]
    again = service.read_run(out)
    p, q = run["GLRK2-symmetric"], again["GLRK2-symmetric"]
    assert p.status == "ok" and np.array_equal(p.I2["corrected"], q.I2["corrected"])
    assert p.t.shape == (3,)                               # outputs at 0, 5, 10


def test_a_dict_scene_gives_the_bits_of_its_toml_file(tmp_path):
    """A dict with the TOML's tables runs as the same scene written as a file: the invariants are
    bitwise equal, and the file keeps the scene as TOML text that parses back to the dict."""
    data = _small()
    path = tmp_path / "s.toml"
    path.write_text(service.scene_text(data))
    a = service.run(data, tmp_path / "a.h5", progress=False)
    b = service.run(str(path), tmp_path / "b.h5", progress=False)
    for name in a.pairs:
        assert np.array_equal(a[name].I1["noncanonical"], b[name].I1["noncanonical"]), name
    assert tomllib.loads(a.scene) == data


def test_bad_input_is_one_line_errors_not_tracebacks(tmp_path):
    with pytest.raises(SceneError, match="unknown \\[run\\] key stesp"):
        service.run("default", tmp_path / "x.h5", stesp=10)
    with pytest.raises(SceneError, match="neither a file nor a built-in scene"):
        service.run("no_such_scene", tmp_path / "x.h5")
    with pytest.raises(SceneError, match="'run.steps' must be int"):
        service.run("default", tmp_path / "x.h5", steps="many")
    with pytest.raises(ValueError, match="threads must be between"):
        service.run("default", tmp_path / "x.h5", steps=5, threads=0)
    with pytest.raises(SceneError, match="cannot be written"):
        service.run({"system": {"name": "point_vortices"}, "run": {"h": object()}}, tmp_path / "x.h5")
    assert not (tmp_path / "x.h5").exists()


def test_results_as_xarray(tmp_path):
    """Run.to_xarray(): one Dataset with pair, t and form; the values are the file's, the growth
    laws ride along, and ds.I2.sel(form=...) selects a series."""
    pytest.importorskip("xarray")
    run = service.run(_small(), tmp_path / "a.h5", progress=False)
    ds = run.to_xarray()
    assert list(ds.pair.values) == ["GLRK1-none", "GLRK1-symmetric", "GLRK2-none", "GLRK2-symmetric"]
    assert list(ds.form.values) == ["canonical", "noncanonical", "corrected"]
    for name, p in run.pairs.items():
        got = ds.I2.sel(pair=name, form="corrected").values
        assert np.array_equal(got, p.I2["corrected"])
        assert np.array_equal(ds.energy_error.sel(pair=name).values, p.errors["energy"])
        assert ds.status.sel(pair=name).item() == p.status
        assert ds.I1_growth_law.sel(pair=name, form="noncanonical").item() == p.growth["I1 noncanonical"][0]
    one = run["GLRK1-none"].to_xarray()
    assert one.attrs["pair"] == "GLRK1-none" and one.energy_error.attrs["growth_law"] == run["GLRK1-none"].growth["energy"][0]
    assert one.breakdown_time.shape == (run["GLRK1-none"].breakdown_time.size,)
    html = run._repr_html_()
    assert html.count("<tr>") == 1 + len(run.pairs) and "GLRK2-symmetric" in html
    assert len(repr(run).splitlines()) == 1


def test_the_progress_bar_is_tqdm_and_counts_every_step(capsys):
    from integrators.service.driver import Progress
    bar = Progress(40, enabled=True)
    for k in range(4):
        bar.update(10, f"pair {k}")
    err = capsys.readouterr().err
    assert re.search(r"40(\.0)?/40(\.0)?", err) and "100%" in err and "pair 3" in err
    quiet = Progress(40, enabled=False)
    quiet.update(40, "x")
    assert quiet.done == 40 and capsys.readouterr().err == ""


@pytest.mark.mpi
def test_a_script_that_calls_run_under_mpiexec_runs_distributed(tmp_path):
    """mpiexec -n 2 python script.py, the script calling service.run: every rank gets the Run, the
    file says 2 ranks ran it, and its invariants are bitwise the 1-rank file's."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path
    script = tmp_path / "go.py"
    script.write_text(
        "import sys\nfrom integrators import service\nfrom integrators.service.ranks import communicator\n"
        "r = service.run('default', sys.argv[1], steps=10, tableaus=['GLRK2'], progress=False)\n"
        "rank = communicator().rank\n"       # (a file per rank: mpiexec may interleave the ranks' stdout mid-line)
        "open(f'rank{rank}.txt', 'w').write(f'rank {rank} pairs {len(r.pairs)} {r[\"GLRK2-symmetric\"].status}')\n")
    mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).parent / "mpiexec")
    for cmd, out in (([sys.executable], "one.h5"), ([mpiexec, "-n", "2", sys.executable], "two.h5")):
        for old in tmp_path.glob("rank*.txt"):
            old.unlink()
        res = subprocess.run(cmd + [str(script), str(tmp_path / out)], capture_output=True, text=True, timeout=600,
                             cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    assert [(tmp_path / f"rank{r}.txt").read_text() for r in (0, 1)] == ["rank 0 pairs 5 ok", "rank 1 pairs 5 ok"]
    a, b = service.read_run(tmp_path / "one.h5"), service.read_run(tmp_path / "two.h5")
    for name in a.pairs:
        assert np.array_equal(a[name].I2["corrected"], b[name].I2["corrected"]), name
