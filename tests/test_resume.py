"""Resuming and extending runs (integrators/service/resumable.py, driver.py): the last partial interval is
an output, a killed or extended run has the straight run's bits on any number of ranks, and a resume
names what differs."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import sympy

import integrators
from integrators.cli import main as cli_main
from integrators.expressions import ExpressionError, parse_expression, parse_number
from integrators.service import driver
from integrators.service import driver, files, output
from integrators.service.checkpoints import slot_files
from integrators.service.scene import SceneError, load_scene, parse_scene
from integrators.service.scene import SceneError, parse_scene
from integrators.tableaus import tableau, tableau_from_file

from helpers import BIN, GC, LV, _dump, _wait_for_rows, assert_same, poincare, scene


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


def test_a_reordered_scene_with_more_steps_names_only_what_differs(tmp_path):
    out = tmp_path / "a.h5"
    driver.run(scene(20), out, progress=False)
    swapped = scene(30, text=LV.replace('["none", "symmetric"]', '["symmetric", "none"]'))
    with pytest.raises(ValueError) as exc:
        driver.run(swapped, out, resume=True, progress=False)
    assert "differs in run.projections (" in str(exc.value)
