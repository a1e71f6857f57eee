"""Breakdowns and degenerate inputs (integrators/engine.py, kernel.py): adversarial inputs break nothing and bad points break down alone (docs/stability.md)."""
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
        sol = integrators.integrate(gc, q0, "GLRK2", proj, h=1e6, steps=3)
        done = ~np.isfinite(sol.breakdown_time)
        # every point either finished or is frozen at its last good, finite state
        assert np.all(np.isfinite(sol.q[-1])), proj
        assert np.all(sol.steps_taken[done] == 3)


def test_non_finite_momentum_of_one_point_does_not_touch_the_others():
    gc = integrators.system("guiding_centre_symmetric")
    q0 = invariants.loop("guiding_centre", 8)
    p0 = gc.theta(q0)
    good = integrators.integrate(gc, q0, "GLRK2", "none", h=10.0, steps=5, p0=p0)
    p0[3, 1] = np.nan
    bad = integrators.integrate(gc, q0, "GLRK2", "none", h=10.0, steps=5, p0=p0)
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
        integrators.integrate(lv, q, "GLRK2", "symmetric", h=0.1, steps=2)


def test_point_next_to_the_domain_boundary_is_handled():
    lv = integrators.system("lotka_volterra_2d")
    sol = integrators.integrate(lv, [[1e-300, 1.0], [1.0, 1.0]], "GLRK2", "symmetric", h=0.1, steps=5)
    assert np.isinf(sol.breakdown_time[1])                           # the ordinary point goes on
    assert np.all(np.isfinite(sol.q[-1]))


def test_single_point():
    pv = integrators.system("point_vortices")
    sol = integrators.integrate(pv, [1.0, 0.1, 1.0, -0.1], "GLRK2", "symmetric", h=0.1, steps=10)
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
