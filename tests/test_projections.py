"""The projections as a layer (integrators.projections): a new projection is a row of the table (with
its own weights, if it likes) and, if it is solved after Ψ_h, one small compiled post term; the kernel
is not edited.  Shown with toys: the momentum reset, a post term that evaluates ϑ and puts the step's
end point on the constraint by moving p alone (q_{n+1} = q̂, p_{n+1} = ϑ(q̂), Λ = 0); and rows whose
weights are not the paper's."""
import numpy as np
import pytest
from numba import njit

import integrators
from integrators import projections
from integrators.kernel import END, evaluate
from integrators.projections import Projection, admission
from integrators.simd import at, ld, st


@njit(inline="always")
def reset_post(z, jac, r, J, ev, k, sig, d, w, S):
    """The post-term contract (integrators.kernel.project): p_{n+1} = ϑ(q̂), evaluated at the core's end
    point q̂ into the END slot; the residual r = Λ, so Newton's first iterate is Λ = 0 exactly and
    q_{n+1} = q̂."""
    evaluate(ev, k, at(w, S.qh), False, w, S, END, d)
    th, p1 = at(w, S.pth + END * d), at(w, S.p1)
    for m in range(d):
        st(p1, m, ld(th, m))
        st(r, m, ld(z, m))
    if jac:
        for m in range(d):
            for n in range(d):
                st(J, m * d + n, 1.0 if m == n else 0.0)


RESET = Projection("reset", "none", "start", True, "end", "one", (), post_term=reset_post)


@pytest.fixture
def with_reset(monkeypatch):
    """The table with the toy's row added, as a reader adding a sixth projection would."""
    monkeypatch.setitem(projections.RECORDS, "reset", RESET)


def _vortices(n=11):
    sy = integrators.system("point_vortices")
    q0 = np.array([1.0, 0.1, 1.0, -0.1]) + 1e-2 * np.random.default_rng(7).standard_normal((n, 4))
    return sy, q0


@pytest.mark.slow                               # a post term of one's own compiles its kernel (once per machine)
@pytest.mark.parametrize("n", [3, 11])          # the scalar path, and 8 lanes with one group part-filled
def test_a_toy_post_projection_runs_through_the_table_and_one_function(with_reset, n):
    """Every step of 'reset' starts on the constraint (q_n, ϑ(q_n)) as a projected step does, runs Ψ_h,
    and ends at Ψ_h's q with p on the constraint: Λ is exactly 0 at every step; q_{n+1} is one
    unprojected step's from (q_n, ϑ(q_n)) to Newton's tolerance (ϑ(q_n) compiled here, by numpy
    there); p_{n+1} = ϑ(q_{n+1}) to round-off (the post term's ϑ against numpy's), where that
    unprojected step leaves p off the constraint by the method's local error; and the standard
    projection (the same row with the paper's post term) moves q instead."""
    sy, q0 = _vortices(n)
    h, steps = 0.1, 12
    toy = integrators.integrate(sy, q0, tableau="GLRK2", projection="reset", h=h, steps=steps)
    assert toy.projection == "reset" and np.all(toy.steps_taken == steps)
    assert np.array_equal(toy.lam, np.zeros_like(toy.lam))
    off = 0.0
    for i in range(steps):
        one = integrators.integrate(sy, toy.q[i], tableau="GLRK2", projection="none", h=h, steps=1)
        assert np.max(np.abs(one.q[1] - toy.q[i + 1])) < 1e-12
        off = max(off, np.max(np.abs(one.p[1] - sy.theta(one.q[1]))))
    assert np.max(np.abs(toy.p[1:] - sy.theta(toy.q[1:]))) < 1e-14 < 1e-9 < off, off
    std = integrators.integrate(sy, q0, tableau="GLRK2", projection="standard", h=h, steps=steps)
    assert np.max(np.abs(std.q[1:] - toy.q[1:])) > 1e-11


_AGAIN = """
import sys, numpy as np
sys.path[:0] = [{root!r}, {tests!r}]
import integrators
from integrators import codegen
from test_projections import RESET, _vortices
sy, q0 = _vortices(3)
sol = integrators.integrate(sy, q0, tableau="GLRK2", projection=RESET, h=0.1, steps=12)
entry, = [m.advance for k, m in codegen._LOADED.items() if k in codegen._POSTS]
print(sum(entry.stats.cache_hits.values()), sum(entry.stats.cache_misses.values()), sol.q.tobytes().hex())
"""


@pytest.mark.slow                               # the first call compiles the toy's kernel (a few minutes)
def test_a_post_term_of_ones_own_is_compiled_once_per_machine(tmp_path):
    """The toy's kernel compiled here is cached: another process that runs the same post term loads it
    (one cache hit, no compilation) and gives the same bits.  The child imports the package this
    process runs (an installed copy and a checkout are different code: their keys differ) and starts
    in an empty folder, so that a checkout in the working folder does not shadow it."""
    import os
    import subprocess
    import sys
    sy, q0 = _vortices(3)
    sol = integrators.integrate(sy, q0, tableau="GLRK2", projection=RESET, h=0.1, steps=12)
    code = _AGAIN.format(root=os.path.dirname(os.path.dirname(os.path.abspath(integrators.__file__))),
                         tests=os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=tmp_path).stdout.split()
    assert out == ["1", "0", sol.q.tobytes().hex()]


@pytest.mark.slow                               # the toy's kernel for 16 lanes of d = 2 (a few minutes, once)
def test_the_toy_post_term_runs_through_a_scene_a_run_file_and_the_audit(monkeypatch, tmp_path):
    """'reset' added to RECORDS, as docs/engine.md says, and nothing else: a scene names it beside the
    standard projection and the driver runs both into a run file, where 'reset' reads back finished,
    with p on the constraint to round-off at every output (its post term put it there) and q away from
    the standard row's; the audit takes it by name, and its step map is integrate's step, bit for bit;
    it measures the toy's drift and one-step defects (finite numbers) without a breakdown, and those
    of the weighted row (HALF) beside it."""
    from helpers import LV_PAIRS
    from integrators import audit
    from integrators.service import driver, read_run
    from integrators.service.scene import parse_scene
    monkeypatch.setitem(projections.RECORDS, "reset", RESET)
    text = LV_PAIRS.replace('tableaus = ["GLRK1", "GLRK2"]', 'tableaus = ["GLRK2"]') \
        .replace('projections = ["none", "standard"]', 'projections = ["standard", "reset"]')
    scene = parse_scene(text)
    driver.run(scene, tmp_path / "a.h5", progress=False)
    run = read_run(tmp_path / "a.h5")
    toy, std = run["GLRK2-reset"], run["GLRK2-standard"]
    assert toy.status == std.status == "ok" and len(toy.t) == 5
    assert np.max(toy.errors["constraint"]) < 1e-13
    assert not np.array_equal(toy.errors["energy"], std.errors["energy"])
    cand, = audit.candidates_from("GLRK2", ["reset"])
    sy = scene.system()
    q = scene.loop_points()[:16]
    q1, p1, lam1 = cand.step(q, sy.theta(q), np.zeros_like(q), scene.h, sy)
    one = integrators.integrate(sy, q, tableau="GLRK2", projection="reset", h=scene.h, steps=1)
    assert np.array_equal(q1, one.q[1]) and np.array_equal(p1, one.p[1]) and not np.any(lam1)
    monkeypatch.setitem(projections.RECORDS, "half_symmetric", HALF)        # and the weighted row beside it
    cands = audit.candidates_from("GLRK2", ["reset", "half_symmetric"])
    rep = audit.audit(cands, scene, defect_points=2, levels=2, method="central differences")
    assert [e["name"] for e in rep["candidates"]] == ["GLRK2-reset", "GLRK2-half_symmetric"]
    for entry in rep["candidates"]:
        assert entry["breakdown_step"] is None and entry["drift"]
        defects = [x for f in entry["defect"].values() for x in (f["defect"] or [])]
        assert defects and all(np.isfinite(defects)), entry["defect"]


def test_a_record_is_taken_in_place_of_a_name():
    """integrate takes a Projection record as it takes a name: the standard projection's row written
    out is the built-in standard projection, bit for bit."""
    sy, q0 = _vortices(3)
    mine = Projection("my_standard", "none", "start", True, "end", "one", ())
    a = integrators.integrate(sy, q0, tableau="GLRK3", projection=mine, h=0.1, steps=5)
    b = integrators.integrate(sy, q0, tableau="GLRK3", projection="standard", h=0.1, steps=5)
    assert a.projection == "my_standard"
    assert np.array_equal(a.q, b.q) and np.array_equal(a.p, b.p) and np.array_equal(a.lam, b.lam)


def test_a_post_term_needs_a_projection_solved_after_the_step():
    """A post term on a row that is not solved after Ψ_h (no post, or coupled) is refused in one line,
    as an unknown name is."""
    T = integrators.tableau("GLRK2")
    coupled = Projection("mine", "unknown", "start", True, "end", "R_inf", (), post_term=reset_post)
    assert "not solved after" in admission(T, coupled)
    with pytest.raises(ValueError, match="not solved after"):
        integrators.Engine(integrators.system("point_vortices"), T, coupled, 0.1)
    assert "unknown projection 'sixth'" in admission(T, "sixth")


def test_one_list_of_projections_for_scenes_the_audit_and_run_files(with_reset):
    """A row added to RECORDS is named by a scene's run.projections and by the audit as by
    integrate (they read the one list, integrators.projections.names()); its pair's name in a run file
    splits back into the tableau and it.  A name that would not split (a '-') is refused in one line
    when the row is made; the reference engine and the oracle refuse a post term they would not apply."""
    from helpers import LV_PAIRS
    from integrators import audit
    from integrators.oracle import Oracle
    from integrators.reference import Stepper
    from integrators.service.output import split_pair_name
    from integrators.service.scene import parse_scene
    assert "reset" in projections.names()
    sc = parse_scene(LV_PAIRS.replace('projections = ["none", "standard"]', 'projections = ["none", "reset"]'))
    assert [(p.label, p.projection) for p in sc.pairs][:2] == [("GLRK1", "none"), ("GLRK1", "reset")]
    cand, = audit.candidates_from("GLRK2", ["reset"])
    assert cand.name == "GLRK2-reset" and split_pair_name(cand.name) == ("GLRK2", "reset")
    with pytest.raises(ValueError, match="letters, digits and '_'"):
        Projection("my-standard", "none", "start", True, "end", "one", ())
    sy, T = integrators.system("point_vortices"), integrators.tableau("GLRK2")
    for engine in (Stepper, Oracle):
        with pytest.raises(ValueError, match="own post term"):
            engine(sy, T, "reset", 0.1)


# Rows with their own weights (GeometricIntegrators.jl's projections are weights before and after the
# step): half the symmetric perturbation before Ψ_h; the symplectic row with other weights on both
# sides; the midpoint row with plain numbers.  Each is data: no kernel code, no compilation of its own.
HALF = Projection("half_symmetric", "unknown", "start", True, "end", "R_inf", (), pre_weight=0.5)
WEIGHTED = (HALF,
            Projection("light_symplectic", "previous", "start", True, "end", "R_inf", (), weight=0.5, pre_weight=0.25),
            Projection("plain_midpoint", "unknown", "midpoint", True, "midpoint", "one", (), weight=0.75,
                       pre_weight=0.5, pre_sign="R_inf"))


@pytest.mark.parametrize("row", WEIGHTED[::2], ids=lambda r: r.name)
@pytest.mark.parametrize("sysname,h,tab", [("point_vortices", 0.1, "GLRK2"), ("lotka_volterra_2d", 0.1, "LobIIIA3")])
def test_a_weighted_rows_jacobian_is_its_residuals_derivative(row, sysname, h, tab, rng):
    """The kernel's Jacobian of a coupled row with weights α, σ ≠ 1 (every column the weights enter:
    the stages' Λ columns, the constraint row, the midpoint's ∂p̃/∂Y) against complex-step differences
    of its residual, to 1e-12."""
    from helpers import assert_jacobian_is_complex_steps
    sy = integrators.system(sysname)
    eng = integrators.Engine(sy, integrators.tableau(tab), row, h)
    q = np.array(sy.defaults["q0"]) * (1 + 0.01 * rng.standard_normal(sy.d))
    z = 1e-2 * rng.standard_normal(eng.nz)
    z[: eng.tableau.s * sy.d] += np.tile(h * sy.vector_field(q), eng.tableau.s)
    assert_jacobian_is_complex_steps(sy, eng, h, q, sy.theta(q), 1e-3 * rng.standard_normal(sy.d), z)


@pytest.mark.parametrize("row", WEIGHTED, ids=lambda r: r.name)
def test_a_row_with_its_own_weights_is_the_same_step_in_all_three_engines(row):
    """Three steps of each weighted row: the compiled kernel, the numpy reference and the mpmath oracle
    (50 digits, each equation written plainly) agree to 1e-13 of the point's size; the weights move the
    step (against the paper's row of that kind, by more than 100 times that), and the constraint holds."""
    from integrators.oracle import Oracle
    from integrators.reference import State, Stepper, advance
    sy, q0 = _vortices(3)
    T, h, n = integrators.tableau("GLRK2"), 0.1, 3
    sol = integrators.integrate(sy, q0, tableau=T, projection=row, h=h, steps=n)
    st = Stepper(sy, T, row, h)
    S = State(q0, sy.theta(q0), np.zeros_like(q0), h, st.s)
    for k in range(1, n + 1):
        advance(st, S, k * h)
    assert np.max(np.abs(S.q - sol.q[-1])) < 1e-13 and np.max(np.abs(S.p - sol.p[-1])) < 1e-13
    orc = Oracle(sy, T, row, h)
    q, p, lam = q0[0], sy.theta(q0[0]), np.zeros(4)
    for k in range(n):
        q, p, lam = orc.step(q, p, lam)
    assert max(abs(float(x) - y) for x, y in zip(q, sol.q[-1, 0])) < 1e-13
    assert max(abs(float(x) - h * y) for x, y in zip(lam, sol.lam[-1, 0])) < 1e-13     # Solution.lam is λ = Λ/h
    paper = {"unknown": "midpoint" if row.pre_at == "midpoint" else "symmetric", "previous": "symplectic"}[row.pre]
    other = integrators.integrate(sy, q0, tableau=T, projection=paper, h=h, steps=n)
    assert np.max(np.abs(other.q[-1] - sol.q[-1])) > 1e-11        # 100 times the agreement
    assert np.max(np.abs(sol.p[1:] - sy.theta(sol.q[1:]))) < 1e-12


def test_the_papers_weights_written_out_are_the_built_in_row_bit_for_bit():
    """α = 1 and σ = R(∞) given as numbers are the symmetric and symplectic rows, bit for bit (a weight
    of 1 multiplies exactly)."""
    sy, q0 = _vortices(3)
    for name, pre in (("symmetric", "unknown"), ("symplectic", "previous")):
        mine = Projection("mine", pre, "start", True, "end", "R_inf", (), weight=1.0, pre_weight=1.0)
        a = integrators.integrate(sy, q0, tableau="GLRK2", projection=mine, h=0.1, steps=5)
        b = integrators.integrate(sy, q0, tableau="GLRK2", projection=name, h=0.1, steps=5)
        assert np.array_equal(a.q, b.q) and np.array_equal(a.lam, b.lam), name


def test_weights_are_numbers_and_a_row_without_a_perturbation_has_no_pre_weight():
    with pytest.raises(ValueError, match="pre_weight and pre_sign cannot be set"):
        Projection("mine", "none", "start", True, "end", "one", (), pre_weight=0.5)
    with pytest.raises(ValueError, match="weight must be a finite number"):
        Projection("mine", "unknown", "start", True, "end", "one", (), weight=float("nan"))
    with pytest.raises(ValueError, match="pre_sign must be 'one' or 'R_inf'"):
        Projection("mine", "unknown", "start", True, "end", "one", (), pre_sign="half")
    assert "needs |R(∞)| = 1" in admission(integrators.tableau("RadIIA2"), WEIGHTED[2])


def test_a_weighted_row_runs_through_a_scene_into_a_run_file(monkeypatch, tmp_path):
    """A row with its own weights added to RECORDS (data: it compiles nothing of its own) is a scene's
    pair: the driver runs it beside the paper's symmetric row into a run file, where it is read back by
    its name, finished, on the constraint to round-off at every output, and with its own energy error
    (the weights reached the run)."""
    from helpers import LV_PAIRS
    from integrators.service import driver, read_run
    from integrators.service.scene import parse_scene
    monkeypatch.setitem(projections.RECORDS, "half_symmetric", HALF)
    text = LV_PAIRS.replace('tableaus = ["GLRK1", "GLRK2"]', 'tableaus = ["GLRK2"]') \
        .replace('projections = ["none", "standard"]', 'projections = ["symmetric", "half_symmetric"]')
    driver.run(parse_scene(text), tmp_path / "a.h5", progress=False)
    run = read_run(tmp_path / "a.h5")
    half, full = run["GLRK2-half_symmetric"], run["GLRK2-symmetric"]
    assert half.status == full.status == "ok" and len(half.t) == 5
    assert np.max(half.errors["constraint"]) < 1e-13
    assert not np.array_equal(half.errors["energy"], full.errors["energy"])
