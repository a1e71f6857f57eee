"""The symplecticity audit (integrators.audit, `poincare audit`): verdicts that can fail."""
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import integrators
from integrators import audit, cli
from integrators.service.scene import load_scene, parse_scene

import audit_maps  # noqa: E402  (tests/ is on sys.path under pytest)

DATA = Path(__file__).parent / "data"
TESTS = Path(__file__).parent

SMALL = """
name = "audit-small"
[system]
name = "guiding_centre_symmetric"
[loop]
shape = "guiding_centre"
points = 64
[surface]
shape = "guiding_centre"
n_sigma = 12
n_tau = 12
[run]
tableaus = ["GLRK2"]
projections = ["symmetric"]
h = 10.0
steps = 40
output_every = 2
forms = ["canonical", "noncanonical", "corrected"]
"""


@pytest.fixture(scope="module")
def vortices():
    sc = load_scene("point_vortices")
    return sc.system(), sc.loop_points()[::64][:3], sc.h


def study(step, sys_q_h, reads=None, levels=4):
    sy, q, h = sys_q_h
    return audit.defect_study(step, sy, q, h, levels, reads=reads)


def test_complex_step_jacobian_matches_central_differences(vortices):
    sy, q, h = vortices
    step = audit.stepper_map(integrators.tableau("GLRK2"), "symmetric")
    p, lam = sy.theta(q), np.zeros_like(q)
    Dc, used_c, _ = audit.jacobian(step, q, p, lam, h, sy)
    Df, used_f, _ = audit.jacobian(step, q, p, lam, h, sy, method="central differences")
    assert used_c == "complex step" and used_f == "central differences"
    assert np.max(np.abs(Dc - Df)) < 1e-10 * np.max(np.abs(Dc))


def test_unprojected_vprk_is_canonically_symplectic_to_roundoff(vortices):
    for tab in ("GLRK1", "GLRK2", "SRK3", "LobIIIA3"):
        cand, = audit.candidates_from(tab, ["none"])
        r, used = study(cand.step, vortices, cand.reads)
        assert used == "complex step"
        assert r["canonical"]["verdict"] == "symplectic", (tab, r["canonical"])
        assert max(r["canonical"]["defect"]) < 1e-14
        # ... but not noncanonically: the solution leaves the constraint (sec:app_integral_invariants)
        assert r["noncanonical"]["verdict"] == "not symplectic"


def test_symplectic_projection_preserves_the_modified_form_only(vortices):
    cand, = audit.candidates_from("SRK3", ["symplectic"])
    r, _ = study(cand.step, vortices, cand.reads)
    assert r["corrected"]["verdict"] == "symplectic" and max(r["corrected"]["defect"]) < 1e-14
    assert r["noncanonical"]["verdict"] == "not symplectic"
    assert 3.5 < r["noncanonical"]["order"] < 4.5        # measured 3.95 on this scene


def test_standard_projection_defect_and_its_order(vortices):
    cand, = audit.candidates_from("GLRK1", ["standard"])
    r, _ = study(cand.step, vortices, cand.reads)
    assert r["noncanonical"]["verdict"] == "not symplectic"
    assert r["noncanonical"]["order"] > 2.5
    assert r["canonical"]["verdict"].startswith("n/a") and r["corrected"]["verdict"].startswith("n/a")


def test_user_rk4_is_not_symplectic_with_defect_order_5(vortices):
    r, used = study(audit_maps.rk4, vortices, levels=4)
    assert used == "complex step"                       # plain arithmetic: complex step goes through
    nc = r["noncanonical"]
    assert nc["verdict"] == "not symplectic" and 4.5 < nc["order"] < 5.5
    assert r["canonical"]["verdict"].startswith("n/a")   # detected: rk4 ignores p and λ
    assert r["corrected"]["verdict"].startswith("n/a")


def test_user_non_symplectic_projection(vortices):
    r, _ = study(audit_maps.glrk2_reset, vortices)
    assert r["noncanonical"]["verdict"] == "not symplectic"
    assert 2.5 < r["noncanonical"]["order"] < 3.5       # the GLRK2 unprojected step's O(h³)


def test_exact_flow_by_central_differences_is_symplectic():
    sc = load_scene("default")
    sy, q = sc.system(), sc.loop_points()[::32][:4]
    r, used = audit.defect_study(audit_maps.exact_flow, sy, q, 10.0, 3)
    assert used == "central differences"                # the exact flow is real-only
    assert r["noncanonical"]["verdict"] == "symplectic"
    assert max(r["noncanonical"]["defect"]) < audit.DEFECT_FLOOR["central differences"]


def test_user_tableau_files(vortices):
    good = audit.candidates_from(str(DATA / "srk3_user.toml"), ["none", "symplectic"])
    ref = audit.candidates_from("SRK3", ["none", "symplectic"])
    for c, cr in zip(good, ref):
        r, _ = study(c.step, vortices, c.reads, levels=3)
        rr, _ = study(cr.step, vortices, cr.reads, levels=3)
        assert r["noncanonical"]["defect"] == pytest.approx(rr["noncanonical"]["defect"], rel=1e-6)
    bad, = audit.candidates_from(str(DATA / "radau2_abar_a.toml"), ["none"])
    r, _ = study(bad.step, vortices, bad.reads)
    assert r["canonical"]["verdict"] == "not symplectic"
    assert min(r["canonical"]["defect"]) > 1e-10


def test_tableau_file_is_offered_only_the_projections_it_admits():
    names = [c.name for c in audit.candidates_from(str(DATA / "radau2_abar_a.toml"))]
    assert names == ["RadIIA2-user-none", "RadIIA2-user-standard"]


def test_drift_verdicts_of_synthetic_series():
    t = np.linspace(0.0, 100.0, 41)
    assert audit.drift_verdict(t, 1e-6 * t, False)[2] == "drifting"
    assert audit.drift_verdict(t, 1e-6 * np.abs(np.sin(t)), False)[2] == "bounded"
    assert audit.drift_verdict(t, 1e-13 * np.abs(np.sin(t)), False)[2] == "round-off"
    assert audit.drift_verdict(t, 1e-6 * t, True)[2] == "broke down"
    assert audit.drift_verdict(t, 1e-6 * t, False, resolution=1e-5)[2] == "under-resolved"
    emax, rate, _ = audit.drift_verdict(t, 3e-7 * t, False)
    assert rate == pytest.approx(3e-7) and emax == pytest.approx(3e-5)


@pytest.fixture(scope="module")
def small_report():
    scene = parse_scene(SMALL)
    cands = audit.candidates_from("GLRK1", ["none", "symmetric", "symplectic"])
    user = audit.Candidate("rk4", audit_maps.rk4, "function")
    return audit.audit(cands + [user], scene, defect_points=2, levels=3)


def test_audit_drift_verdicts_on_the_guiding_centre(small_report):
    v = {c["name"]: {k: r["verdict"] for k, r in c["drift"].items()} for c in small_report["candidates"]}
    assert v["GLRK1-none"]["I1/canonical"] == "round-off"
    assert v["GLRK1-none"]["I1/noncanonical"] in ("bounded", "drifting")
    assert v["GLRK1-symmetric"]["I1/noncanonical"] == "round-off"
    assert v["GLRK1-symmetric"]["I2/noncanonical"] == "round-off"
    assert v["GLRK1-symplectic"]["I1/corrected"] == "round-off"
    assert v["GLRK1-symplectic"]["I1/noncanonical"] != "round-off"
    assert v["rk4"]["I1/noncanonical"] == "drifting"          # h = 10 RK4 loses area steadily


def test_user_map_that_raises_is_reported_not_fatal():
    scene = parse_scene(SMALL.replace("steps = 40", "steps = 4"))
    rep = audit.audit([audit.Candidate("broken", audit_maps.broken, "function")], scene, defect=False)
    c = rep["candidates"][0]
    assert c["breakdown_step"] == 1
    assert all(r["verdict"] == "broke down" for r in c["drift"].values())


def test_report_text_json_and_plots(small_report, tmp_path):
    text = audit.text_report(small_report)
    assert "GLRK1-symplectic" in text and "order" in text and "round-off" in text
    json.dumps(small_report)                                   # serialisable as is
    paths = audit.plot_report(small_report, tmp_path)
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_cli_audit_user_function(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(SMALL.replace("steps = 40", "steps = 6"))
    out = tmp_path / "r.json"
    rc = cli.main(["audit", f"{TESTS / 'audit_maps.py'}:rk4", "--scene", str(scene), "--reference", "none",
                   "--json", str(out), "--levels", "3", "--points", "2", "-q"])
    assert rc == 0
    rep = json.loads(out.read_text())
    assert rep["candidates"][0]["name"] == "rk4"
    assert rep["candidates"][0]["defect"]["noncanonical"]["verdict"] == "not symplectic"


@pytest.mark.parametrize("args, msg", [
    (["audit", "NOPE"], "is not a built-in tableau"),
    (["audit", f"{TESTS / 'audit_maps.py'}:nothing"], "has no function 'nothing'"),
    (["audit", "no_such_module_xyz:f"], "is not a .py file or package in"),
    (["audit", "GLRK2", "--projection", "sideways"], "unknown projection"),
    (["audit", "RadIIA2", "--projection", "symmetric"], "none of symmetric applies"),
    (["audit", "GLRK2", "--reference", "GLRK2"], "must be TABLEAU-projection"),
    (["audit", "GLRK2", "--steps", "0"], "--steps must be a positive integer"),
])
def test_cli_audit_errors(args, msg, capsys):
    assert cli.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err


def test_a_scene_that_cannot_tell_methods_apart_says_so(tmp_path, capsys):
    """The paper's Lotka–Volterra model: even the standard projection is exactly symplectic there
    (SPEC Part 4), so the audit's report opens with a one-line warning and a comparison run says it once; on the
    point vortices, whose defects show, there is none."""
    from integrators.service.scene import load_scene
    lv, pv = load_scene("lotka_volterra"), load_scene("point_vortices")
    msg = audit.discrimination(lv.system(), lv.points(lv.system()), lv.h)
    assert msg is not None and "cannot tell" in msg and "GLRK2-standard" in msg
    assert audit.discrimination(pv.system(), pv.points(pv.system()), pv.h) is None
    report = audit.audit(audit.candidates_from("GLRK2", ["standard"]), dataclasses.replace(lv, steps=4),
                         drift=False, defect=False)           # the check comes first, whatever is measured
    assert audit.text_report(report).splitlines()[1].startswith("warning: this scene cannot tell")
    capsys.readouterr()
    assert cli.main(["run", "lotka_volterra", "--steps", "20", "-q", "-o", str(tmp_path / "lv.h5")]) in (0, 1)
    notes = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("note: this scene cannot tell")]
    assert len(notes) == 1                   # once, under its summary (issue 56: it was said twice)
