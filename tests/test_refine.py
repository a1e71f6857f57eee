"""Sample sets that refine themselves (refine_to): nested levels, exact new points, the same bits
as a set that fine from the start, for any rank count and across a resume."""
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from integrators.service import driver
from integrators.service.reader import read_run
from integrators.service.scene import parse_scene, SceneError
from helpers import assert_same, dump
from invariants.samples import first_level, loop, refined_grid, surface

# the paper's guiding-centre loop of 64 points goes under-resolved near t = 2,000 (step 200); the
# surface of 17 × 17 later in the run (both measured here; the 16 × 16 surface of the paper's field
# reads 1.7e-8 from t = 0 since the monitor bounds the value: docs/invariants.md); h = 10, GLRK2-symmetric
SCENE = """
name = "refining"
[system]
name = "guiding_centre_symmetric"
[loop]
points = 64
refine_to = 256
[surface]
n_sigma = 17
n_tau = 17
refine_to = 1089
[run]
tableaus = ["GLRK2"]
projections = ["symmetric"]
h = 10.0
steps = 2000
output_every = 20
forms = ["canonical", "noncanonical", "corrected"]
[output]
checkpoint_seconds = 0.0
"""




def test_levels_nest_and_keep_every_old_point():
    assert refined_grid((64,), 2) == (256,) and refined_grid((16, 10), 1) == (31, 19)
    lv = first_level((4,), 2)
    assert lv.tolist() == [0, 2, 1, 2] * 4
    for level in (1, 2, 3):                  # the old points sit where level 0 says, bitwise
        assert np.array_equal(loop("guiding_centre", 64 << level)[first_level((64,), level) == 0],
                              loop("guiding_centre", 64))
        g = refined_grid((9, 5), level)
        fine = surface("guiding_centre", *g)
        assert np.array_equal(fine[first_level((9, 5), level) == 0], surface("guiding_centre", 9, 5).reshape(-1, 4))
        for lv in range(level + 1):          # each level's points are level lv's grid, less level lv − 1's
            mid = surface("guiding_centre", *refined_grid((9, 5), lv))
            new = first_level((9, 5), lv) == lv if lv else np.ones(mid.shape[:2], bool)
            assert np.array_equal(fine[first_level((9, 5), level) == lv], mid[new])


def test_refine_to_is_checked_in_one_line():
    with pytest.raises(SceneError, match=r"loop.refine_to = 100 allows no refinement: .* 128 points"):
        parse_scene(SCENE.replace("refine_to = 256", "refine_to = 100"))
    with pytest.raises(SceneError, match=r"surface.refine_to = 1,000 allows no refinement: .*33 × 33"):
        parse_scene(SCENE.replace("refine_to = 1089", "refine_to = 1000"))
    with pytest.raises(SceneError, match="'loop.refine_to' must be int"):
        parse_scene(SCENE.replace("refine_to = 256", "refine_to = 2.5"))
    assert parse_scene(SCENE).loop.levels == 2 and parse_scene(SCENE).surface.levels == 1
    # its finest level counts in the memory check, before a point of it is sampled
    with pytest.raises(SceneError, match=r"^loop.refine_to = 100,000,000,000 \(up to 68,719,476,736 points\) "
                                         r"needs about .* GiB of memory"):
        parse_scene(SCENE.replace("refine_to = 256", "refine_to = 100000000000"))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The refining scene, the same scene without refine_to, and the sets at 128 / 256 and 33 × 33
    points from the start."""
    d = tmp_path_factory.mktemp("refine")
    variants = {"refining": SCENE,
                "plain": SCENE.replace("refine_to = 256\n", "").replace("refine_to = 1089\n", ""),
                "fine1": SCENE.replace("points = 64\nrefine_to = 256", "points = 128")
                              .replace("n_sigma = 17\nn_tau = 17\nrefine_to = 1089", "n_sigma = 33\nn_tau = 33"),
                "fine2": SCENE.replace("points = 64\nrefine_to = 256", "points = 256")}
    out = {}
    for name, text in variants.items():
        out[name] = d / f"{name}.h5"
        driver.run(parse_scene(text), out[name], progress=False)
    return out


def test_a_refining_set_stays_resolved_where_the_plain_one_does_not(runs):
    plain = read_run(runs["plain"]).pairs["GLRK2-symmetric"]
    ref = read_run(runs["refining"]).pairs["GLRK2-symmetric"]
    assert plain.status == "under-resolved" and not plain.resolved["I1"].all() and not plain.resolved["I2"].all()
    assert ref.status == "ok" and ref.resolved["I1"].all() and ref.resolved["I2"].all()
    used = ref.points_used
    assert used["I1"][0] == 64 and set(used["I1"]) == {64, 128, 256} and set(used["I2"]) >= {289, 1089}
    # where the coarse set resolves the invariant, the refining run is the plain run's value
    for inv in ("I1", "I2"):
        coarse = used[inv] == (64 if inv == "I1" else 289)
        for form, v in getattr(ref, inv).items():
            assert np.array_equal(v[coarse], getattr(plain, inv)[form][coarse]), (inv, form)


def test_new_points_are_bitwise_the_set_that_fine_from_the_start(runs):
    """No interpolation: the new points are started at t = 0 and caught up, so at every output taken
    on 128 (256) loop points or 33 × 33 surface points the values and monitors are bitwise those of
    the run whose set had that many points from the start."""
    ref = read_run(runs["refining"]).pairs["GLRK2-symmetric"]
    checked = 0
    for name, inv, n in (("fine1", "I1", 128), ("fine2", "I1", 256), ("fine1", "I2", 1089)):
        other = read_run(runs[name]).pairs["GLRK2-symmetric"]
        at = ref.points_used[inv] == n
        checked += at.sum()
        assert at.any(), (inv, n)
        assert np.array_equal(ref.resolution[inv][at], other.resolution[inv][at])
        for form, v in getattr(ref, inv).items():
            assert np.array_equal(v[at], getattr(other, inv)[form][at]), (inv, n, form)
    assert checked > 50


def test_resume_after_a_refinement_gives_the_same_file(tmp_path, runs):
    """A run stopped after both sets refined (its catch-up states are not in the checkpoint) and
    resumed: the new points are started again at t = 0 and the file is the uninterrupted one's."""
    out = tmp_path / "stopped.h5"

    def stop(pair, step):
        if step == 1800:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        driver.run(parse_scene(SCENE), out, progress=False, after_output=stop)
    with h5py.File(out) as f:
        used = f["runs/GLRK2-symmetric/points_used/I1"][()]
        assert 128 in used and used.size < 101
    driver.run(parse_scene(SCENE), out, resume=True, progress=False)
    assert_same(dump(out), dump(runs["refining"]))


@pytest.mark.mpi
def test_a_refining_run_is_the_same_file_on_3_ranks_with_uneven_delays(tmp_path, runs):
    """The owners of a set's tasks turn over the batches, so each of the 3 ranks catches the new
    points up on its own; with random delays at every output and batches of 2 outputs, the file is
    the one-process run's, bit for bit."""
    scene = tmp_path / "refining.toml"
    scene.write_text(SCENE)
    child = tmp_path / "uneven.py"
    child.write_text(JITTER)
    out = tmp_path / "r3.h5"
    mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).parent / "mpiexec")
    r = subprocess.run([mpiexec, "-n", "3", sys.executable, str(child), str(scene), str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert_same(dump(out), dump(runs["refining"]))


JITTER = """
import random, sys, time
from integrators.service import driver
from integrators.service.ranks import communicator
from integrators.service.scene import load_scene
comm = communicator()
rng = random.Random(comm.rank)
march = driver.march

def uneven(engine, st, start, stop, every, hooks, *args, **kw):
    def late(step, *out):
        time.sleep(rng.uniform(0.0, 0.01 * comm.rank))
        hooks.on_output(step, *out)
    return march(engine, st, start, stop, every, hooks._replace(on_output=late), *args, **kw)

driver.march = uneven
driver._batch = lambda seconds_per_output, points: 2
driver.run(load_scene(sys.argv[1]), sys.argv[2], progress=False)
"""


def test_a_refining_sets_tasks_stay_on_one_rank_for_a_pair():
    """Its new points are advanced by whichever rank takes its tasks: that rank is the same for
    every batch of a pair (one catch-up, not one per rank) and turns from pair to pair; the other
    set's tasks go where the least task work is, so more than one rank takes them."""
    from integrators.service.tasks import Tasks
    scene = parse_scene(SCENE.replace("refine_to = 1089\n", ""))       # the loop refines, the surface not
    for size in (2, 3):
        st = Tasks(scene, size, 1e-10)
        firsts = []
        for k in range(size):
            owners = [st.assign(5, k) for _ in range(4 * size)]
            loop_owner = {own[("I1", "canonical")] for own in owners}
            surface_owner = {own[("I2", "canonical")] for own in owners}
            assert len(loop_owner) == 1 and len(surface_owner) >= 2
            firsts += loop_owner
        assert len(set(firsts)) == size


def test_plots_show_the_points_used(tmp_path, runs):
    from integrators.service.plots import plot_file
    written = plot_file(runs["refining"], tmp_path)
    assert tmp_path / "refining_refinement.png" in written
    assert not any(p.name.endswith("_refinement.png") for p in plot_file(runs["plain"], tmp_path / "plain"))
