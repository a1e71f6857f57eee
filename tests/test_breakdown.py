"""Breakdowns and degenerate inputs (integrators/engine.py, kernel/): adversarial inputs break nothing and bad points break down alone (docs/stability.md)."""
import re

import h5py
import numpy as np
import pytest

import integrators
import invariants
from integrators.service import driver
from integrators.service.scene import parse_scene

SCENE = """
name = "stress"
[system]
name = "guiding_centre_symmetric"
[loop]
points = 16
[surface]
n_sigma = 8
n_tau = 8
[run]
tableaus = ["GLRK2"]
projections = ["symmetric", "none"]
h = 10.0
steps = 6
output_every = 2
"""


def test_huge_step_breaks_points_down_without_an_exception():
    gc = integrators.system("guiding_centre_symmetric")
    q0 = invariants.loop("guiding_centre", 16)
    for proj in integrators.PROJECTIONS:
        sol = integrators.integrate(gc, q0, tableau="GLRK2", projection=proj, h=1e6, steps=3)
        done = ~np.isfinite(sol.breakdown_time)
        # every point either finished or is frozen at its last good, finite state
        assert np.all(np.isfinite(sol.q[-1])), proj
        assert np.all(sol.steps_taken[done] == 3)


def test_non_finite_momentum_of_one_point_does_not_touch_the_others():
    gc = integrators.system("guiding_centre_symmetric")
    q0 = invariants.loop("guiding_centre", 8)
    p0 = gc.theta(q0)
    good = integrators.integrate(gc, q0, tableau="GLRK2", projection="none", h=10.0, steps=5, p0=p0)
    p0[3, 1] = np.nan
    bad = integrators.integrate(gc, q0, tableau="GLRK2", projection="none", h=10.0, steps=5, p0=p0)
    assert bad.breakdown_time[3] == 10.0 and np.isinf(np.delete(bad.breakdown_time, 3)).all()
    keep = np.arange(8) != 3
    assert np.array_equal(bad.q[:, keep], good.q[:, keep])          # bitwise: points are independent


@pytest.mark.parametrize("q, msg", [
    ([0.0, 1.0], "outside the domain"),
    ([np.inf, 1.0], "not finite"),
    ([np.nan, 1.0], "not finite"),
])
def test_initial_points_on_the_boundary_or_not_finite_are_refused(q, msg):
    lv = integrators.system("lotka_volterra_2d")
    with pytest.raises(ValueError, match=msg):
        integrators.integrate(lv, q, tableau="GLRK2", projection="symmetric", h=0.1, steps=2)


def test_point_next_to_the_domain_boundary_is_handled():
    lv = integrators.system("lotka_volterra_2d")
    sol = integrators.integrate(lv, [[1e-300, 1.0], [1.0, 1.0]], tableau="GLRK2", projection="symmetric",
                                h=0.1, steps=5)
    assert np.isinf(sol.breakdown_time[1])                           # the ordinary point goes on
    assert np.all(np.isfinite(sol.q[-1]))


def test_single_point():
    pv = integrators.system("point_vortices")
    sol = integrators.integrate(pv, [1.0, 0.1, 1.0, -0.1], tableau="GLRK2", projection="symmetric", h=0.1, steps=10)
    assert sol.q.shape == (11, 1, 4) and np.isinf(sol.breakdown_time[0])


def test_zero_area_surface_has_zero_invariant_not_an_error():
    gc = integrators.system("guiding_centre_symmetric")
    S = np.broadcast_to(invariants.loop("guiding_centre", 3)[0], (8, 8, 4)).copy()
    for form in ("noncanonical", "canonical"):
        v = invariants.second_invariant(S, form, system=gc, p=gc.theta(S))
        assert v.value == 0.0


def test_service_with_a_huge_step_finishes_with_a_readable_file(tmp_path):
    text = SCENE.replace("h = 10.0", "h = 1.0e6")
    out = tmp_path / "huge.h5"
    summaries = driver.run(parse_scene(text), out, progress=False)
    assert {s.status for s in summaries} <= {"ok", "under-resolved", "partial", "failed"}
    with h5py.File(out) as f:                                         # the file is complete and readable
        for name in ("GLRK2-symmetric", "GLRK2-none"):
            g = f["runs"][name]
            assert g["t"].shape == (4,) and g.attrs["status"] in ("ok", "under-resolved", "partial", "failed")


CADENCE_CASES = [  # (scene, pair, h: large enough that points break down at steps spread over the run)
    ("guiding_centre_tokamak", ("GLRK2", "none"), 20.0),
    ("point_vortices", ("GLRK2", "symmetric"), 1.0),
    ("lotka_volterra", ("SRK3", "symplectic"), 0.5),
]


@pytest.mark.parametrize("scene,pair,h", CADENCE_CASES)
def test_results_and_breakdowns_do_not_depend_on_the_output_cadence(scene, pair, h):
    """q, p, λ, the Newton iterations and the breakdown times after 40 steps are bitwise the same for
    save_every 1, 8 and 40, on points of which some break down at steps spread over the run
    (issue 56: the last step's Newton factors used to be dropped at every output)."""
    from integrators.service.scene import load_scene
    sc = load_scene(scene)
    q0 = sc.loop_points()[::8]
    sols = [integrators.integrate(sc.system(), q0, tableau=pair[0], projection=pair[1], h=h, steps=40,
                                  save_every=k) for k in (1, 8, 40)]
    steps = sols[0].breakdown_time[np.isfinite(sols[0].breakdown_time)] / h
    assert 0 < steps.size < len(q0) or len(np.unique(steps)) > 1, "the case must break points down at several steps"
    for s in sols[1:]:
        for f in ("newton_iterations", "breakdown_time", "steps_taken"):
            assert np.array_equal(getattr(sols[0], f), getattr(s, f)), f
        for f in ("q", "p", "lam"):
            assert np.array_equal(getattr(sols[0], f)[-1], getattr(s, f)[-1]), f
            every = s.t.size - 1
            assert np.array_equal(getattr(sols[0], f)[::40 // every], getattr(s, f)), f


@pytest.mark.parametrize("scene,pair,h", CADENCE_CASES[:2])
def test_outputs_inside_a_call_are_the_state_a_call_ending_there_leaves(scene, pair, h):
    """march with ``light`` (Engine.advance_outputs: calls that run past outputs and record them)
    against a call per output: q, p, Λ, live and the breakdown times at each of 40 outputs bitwise
    equal, on points that break down at steps spread over the run; the final states equal too."""
    from integrators.engine import Engine, Hooks, march
    from integrators.service.scene import load_scene
    sc = load_scene(scene)
    q0 = sc.loop_points()[::8]
    got = {}
    for light in (None, lambda step: True):
        eng = Engine(sc.system(), integrators.tableau(pair[0]), pair[1], h)
        st = eng.state(q0)
        rows = []

        def on_output(step, out=None):
            at = st if out is None else out
            rows.append((step,) + tuple(np.array(getattr(at, f)) for f in ("q", "p", "Lam", "live", "breakdown_time")))

        march(eng, st, 0, 40, 1, Hooks(on_output, light=light), target=1e-9 if light is None else 10.0)
        got[light is None] = rows, st
    (per_call, a), (inside, b) = got[True], got[False]
    assert [r[0] for r in per_call] == [r[0] for r in inside] == list(range(1, 41))
    lives = [int(r[4].sum()) for r in per_call]
    assert lives[0] > lives[-1] and len(set(lives)) > 2, "the case must break points down at several steps"
    for x, y in zip(per_call, inside):
        for u, v in zip(x[1:], y[1:]):
            assert u.dtype == v.dtype and np.array_equal(u, v, equal_nan=True), x[0]
    for f in ("q", "p", "Lam", "live", "breakdown_time", "iterations", "steps"):
        assert np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True), f


def test_the_driver_gives_the_same_file_values_for_output_every_1_and_10(tmp_path):
    """A scene run with output_every = 1 and 10: the same breakdown times, and the same points and
    invariants at every output both wrote (issue 56)."""
    from integrators.service.reader import read_run
    from integrators.service.scene import load_scene
    text = load_scene("lotka_volterra").text
    text = text[:text.index("[surface]")] + text[text.index("[run]"):]
    for key, value in (("tableaus", '["SRK3"]'), ("projections", '["symplectic", "none"]'), ("h", "0.5"),
                       ("steps", "40"), ("forms", '["canonical"]')):
        text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", text)
    text = text.replace("[run]\n", "[run]\nstore_points = true\n")
    runs = []
    for every in (1, 10):
        path = tmp_path / f"every{every}.h5"
        driver.run(parse_scene(re.sub(r"(?m)^output_every = .*$", f"output_every = {every}", text)), path,
                   progress=False)
        runs.append(read_run(path))
    one, ten = runs
    for name in ("SRK3-symplectic", "SRK3-none"):
        a, b = one[name], ten[name]
        assert np.isfinite(a.breakdown_time).any(), name
        assert np.array_equal(a.breakdown_time, b.breakdown_time), name
        keep = np.isin(a.t, b.t)
        assert keep.sum() == b.t.size == 5
        assert np.array_equal(a.points["loop"][keep], b.points["loop"], equal_nan=True), name
        assert np.array_equal(a.I1["canonical"][keep], b.I1["canonical"], equal_nan=True), name
