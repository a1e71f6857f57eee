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
from integrators.service.cli import main as cli_main
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


def test_fewer_steps_are_refused_and_the_file_is_unchanged(tmp_path):
    out = tmp_path / "a.h5"
    driver.run(scene(23), out, progress=False)
    before = out.read_bytes()
    with pytest.raises(ValueError, match="fewer steps"):
        driver.run(scene(21), out, resume=True, progress=False)
    assert out.read_bytes() == before
