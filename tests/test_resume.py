"""Resuming and extending runs (integrators/service/resumable.py, driver.py): the last partial interval is
an output, a killed or extended run has the straight run's bits on any number of ranks, and a resume
names what differs."""
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import integrators
from integrators.cli import main as cli_main
from integrators.service import driver
from integrators.service.checkpoints import slot_files
from integrators.service.scene import parse_scene, SceneError
from helpers import BIN, GC, LV, SMALL, wait_rows, assert_same, dump, edit, poincare, same, scene, stop_at_output_8



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
    assert wait_rows(part, "GLRK2-symmetric", 5, proc)
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
    da, db = dump(a, skip=("wall_clock", "checkpoint")), dump(b, skip=("wall_clock", "checkpoint"))
    assert da.keys() == db.keys() and all(
        np.array_equal(da[k], db[k]) if k != "status" else da[k] == db[k] for k in da)
    # the same through --steps on the command line, and fewer steps are refused
    c = tmp_path / "c.h5"
    assert poincare("run", str(short), "-o", str(c), "-q").returncode == 0
    assert poincare("run", str(short), "-o", str(c), "-q", "--resume", "--steps", "80").returncode == 0
    dc = dump(c, skip=("wall_clock", "checkpoint"))
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


def test_the_state_is_written_every_few_outputs_and_a_resume_recomputes_the_rows_after_it(tmp_path, monkeypatch):
    """The state goes to the file about every output.checkpoint_seconds, not at every output: with
    the default (60 s) this small run writes it once a pair, at the end.  Forced to every 3rd output,
    with rows written every 2nd, a run stopped after output 8 of a pair has 9 rows but its state at
    output 6; the resume drops rows 7 and 8, computes them again, and the file is the uninterrupted
    run's, bit for bit, its settled checkpoints too."""
    scene = parse_scene(SMALL)
    full, part = tmp_path / "full.h5", tmp_path / "part.h5"
    driver.run(scene, full, progress=False)
    with h5py.File(full) as f:
        for name in f["runs"]:
            assert sorted(int(f["runs"][name][f"checkpoint/{s}/step"][()]) for s in "ab") == [-1, 40], name
    stop_at_output_8(scene, part, monkeypatch)
    with h5py.File(part) as f:
        g = f["runs/GLRK2-none"]
        assert g["t"].shape[0] == 9 and g["I2/corrected"].shape[0] == 9
        assert sorted(int(g[f"checkpoint/{s}/step"][()]) for s in "ab") == [12, 24]
    driver.run(scene, part, progress=False, resume=True)
    # checkpoints included: a finished pair keeps its final state in slot a, whenever states were written
    assert same(dump(full, skip=("wall_clock",)), dump(part, skip=("wall_clock",)))


@pytest.mark.parametrize("first,then", [("per-rank", "per-rank"), ("per-rank", "in-file"), ("in-file", "per-rank")])
def test_per_rank_checkpoints_resume_to_the_in_file_bits(tmp_path, monkeypatch, first, then):
    """output.checkpoints = "per-rank": each rank's state is a slab file beside the run file, linked
    into the checkpoint slots as virtual datasets.  A run stopped after output 8 (states every 3rd
    output), with a stray slab of another run planted beside it, resumed with either setting: every
    value of the file, the settled checkpoints read through the links too, is the uninterrupted
    in-file run's; the folder then holds exactly the slabs the slots link."""
    from integrators.service import checkpoints
    scene = lambda mode: parse_scene(SMALL.replace('"symmetric", "symplectic"', '"symplectic"')
                                     + f'[output]\ncheckpoints = "{mode}"\n')
    full, part = tmp_path / "full.h5", tmp_path / "part.h5"
    driver.run(scene("in-file"), full, progress=False)
    stop_at_output_8(scene(first), part, monkeypatch)
    folder = tmp_path / "part.h5.checkpoints"
    if first == "per-rank":
        with h5py.File(part) as f:
            c = f["runs/GLRK2-none/checkpoint/b"]          # the newest state (step 24), linked
            assert c["q"].is_virtual and int(c["step"][()]) == 24 and checkpoints.slot_files(c)[0][1:] == (0, 464)
        (folder / "GLRK2-none.27.0badf00d.0-464.h5").write_bytes(b"a stopped run's slab, never linked")
    driver.run(scene(then), part, progress=False, resume=True)
    assert same(dump(full), dump(part))
    with h5py.File(part) as f:
        linked = {n for g in f["runs"].values() for s_ in "ab" for n, _, _ in checkpoints.slot_files(g[f"checkpoint/{s_}"])}
        virtual = {k for k, g in f["runs"].items() if g["checkpoint/a/q"].is_virtual}
    assert {p.name for p in folder.iterdir()} == linked
    assert virtual == ({"GLRK1-none", "GLRK1-symplectic"} if first == "per-rank" else set()) \
        | ({"GLRK2-none", "GLRK2-symplectic"} if then == "per-rank" else set())   # finished before / after the stop


def test_kill_and_resume_gives_the_same_bits(tmp_path):
    scene = tmp_path / "small.toml"
    scene.write_text(edit(SMALL, "steps = 40", "steps = 500"))
    full, part = tmp_path / "full.h5", tmp_path / "part.h5"
    rc_full = poincare("run", str(scene), "-o", str(full), "-q").returncode
    assert rc_full in (0, 1)              # 1 if the 64-point loop is sheared out of resolution
    proc = subprocess.Popen([shutil.which("poincare") or str(Path(sys.executable).parent / "poincare"),
                             "run", str(scene), "-o", str(part), "-q"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    # wait until the third pair's first rows are on disk (a batch of about 2 s of advancing, here
    # maybe the whole pair), then kill without warning
    deadline = time.time() + 120
    while time.time() < deadline:
        time.sleep(0.2)
        try:
            with h5py.File(part, "r", locking=False) as f:   # the writer holds HDF5's file lock
                if f["runs/GLRK1-symplectic/t"].shape[0] >= 1:
                    break
        except (OSError, KeyError, RuntimeError):
            pass
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    with h5py.File(part, "r") as f:                     # readable, complete up to its last output
        done = f["runs/GLRK1-none"]
        assert done["t"].shape[0] == 126 and done["I1/canonical"].shape[0] == 126
        g = f["runs/GLRK1-symplectic"]
        n = g["t"].shape[0]
        assert 1 <= n <= 126 and all(g[k].shape[0] == n for k in ("I1/noncanonical", "I2/corrected", "energy_error"))
        assert np.array_equal(g["t"][...], 10.0 * 4 * np.arange(n))
    r = poincare("run", str(scene), "-o", str(part), "-q")
    assert r.returncode == 2 and "--resume" in r.stderr
    r = poincare("run", str(scene), "-o", str(part), "-q", "--resume")
    assert r.returncode == rc_full, r.stderr
    assert same(dump(full, skip=("wall_clock", "checkpoint")), dump(part, skip=("wall_clock", "checkpoint")))


def test_a_file_from_before_checkpoints_noted_newtons_factors_is_refused_in_one_line(tmp_path):
    """A run file whose checkpoints lack have_lu, jac_z, jac_q, jac_lam (written before issue 56) is not
    resumed (a resume could not give the bits of the run it continues) and is not called damaged: one
    line, exit 2, and its results still read."""
    scene = tmp_path / "lv.toml"
    scene.write_text(LV)
    out = tmp_path / "lv.h5"
    assert poincare("run", str(scene), "-o", str(out), "-q").returncode in (0, 1)
    with h5py.File(out, "r+") as f:
        for g in f["runs"].values():
            for slot in ("a", "b"):
                for k in ("have_lu", "jac_z", "jac_q", "jac_lam"):
                    del g[f"checkpoint/{slot}/{k}"]
    r = poincare("run", str(scene), "-o", str(out), "-q", "--resume")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "earlier version" in r.stderr and "damaged" not in r.stderr and "--force" in r.stderr
    assert integrators.service.read_run(out).pairs
