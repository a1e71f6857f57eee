"""The projections as a layer (integrators.projections): a new projection is a row of the table and,
if it is solved after Ψ_h, one small compiled post term; the kernel is not edited.  Shown with a toy:
the identity post projection, which ends every step where Ψ_h did (Λ = 0)."""
import numpy as np
import pytest
from numba import njit

import integrators
from integrators import projections
from integrators.projections import Projection, admission
from integrators.simd import at, ld, st


@njit(inline="always")
def identity_post(z, jac, r, J, ev, k, sig, d, w, S):
    """The post-term contract (integrators.kernel.project) with residual r = Λ: Newton's first
    iterate is Λ = 0 exactly, and p_{n+1} = p̂."""
    ph, p1 = at(w, S.ph), at(w, S.p1)
    for m in range(d):
        st(p1, m, ld(ph, m))
        st(r, m, ld(z, m))
    if jac:
        for m in range(d):
            for n in range(d):
                st(J, m * d + n, 1.0 if m == n else 0.0)


IDENTITY = Projection("identity", "none", "start", True, "end", "one", (), post_term=identity_post)


@pytest.fixture
def with_identity(monkeypatch):
    """The table with the toy's row added, as a reader adding a sixth projection would."""
    monkeypatch.setitem(projections.RECORDS, "identity", IDENTITY)


def _vortices(n=11):
    sy = integrators.system("point_vortices")
    q0 = np.array([1.0, 0.1, 1.0, -0.1]) + 1e-2 * np.random.default_rng(7).standard_normal((n, 4))
    return sy, q0


@pytest.mark.parametrize("n", [3, 11])          # the scalar path, and 8 lanes with one group part-filled
def test_a_toy_post_projection_runs_through_the_table_and_one_function(with_identity, n):
    """Every step of 'identity' starts on the constraint (q_n, ϑ(q_n)) as a projected step does, runs
    Ψ_h, and ends at Ψ_h's point: Λ is exactly 0 at every step; every step is one unprojected step
    from (q_n, ϑ(q_n)) to Newton's tolerance (ϑ(q_n) compiled here, by numpy there); and p_{n+1} is left off the constraint by the method's
    local error, where the standard projection (the same row with the paper's post term) puts it on."""
    sy, q0 = _vortices(n)
    h, steps = 0.1, 12
    toy = integrators.integrate(sy, q0, tableau="GLRK2", projection="identity", h=h, steps=steps)
    assert toy.projection == "identity" and np.all(toy.steps_taken == steps)
    assert np.array_equal(toy.lam, np.zeros_like(toy.lam))
    for i in range(steps):
        one = integrators.integrate(sy, toy.q[i], tableau="GLRK2", projection="none", h=h, steps=1)
        assert np.max(np.abs(one.q[1] - toy.q[i + 1])) < 1e-12
        assert np.max(np.abs(one.p[1] - toy.p[i + 1])) < 1e-12
    off = np.max(np.abs(toy.p[1:] - sy.theta(toy.q[1:])))
    std = integrators.integrate(sy, q0, tableau="GLRK2", projection="standard", h=h, steps=steps)
    assert off > 1e-9 and np.max(np.abs(std.p[1:] - sy.theta(std.q[1:]))) < 1e-12, off


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
    coupled = Projection("mine", "unknown", "start", True, "end", "R_inf", (), post_term=identity_post)
    assert "not solved after" in admission(T, coupled)
    with pytest.raises(ValueError, match="not solved after"):
        integrators.Engine(integrators.system("point_vortices"), T, coupled, 0.1)
    assert "unknown projection 'sixth'" in admission(T, "sixth")


def test_one_list_of_projections_for_scenes_the_audit_and_run_files(with_identity):
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
    assert "identity" in projections.names()
    sc = parse_scene(LV_PAIRS.replace('projections = ["none", "standard"]', 'projections = ["none", "identity"]'))
    assert [(p.label, p.projection) for p in sc.pairs][:2] == [("GLRK1", "none"), ("GLRK1", "identity")]
    cand, = audit.candidates_from("GLRK2", ["identity"])
    assert cand.name == "GLRK2-identity" and split_pair_name(cand.name) == ("GLRK2", "identity")
    with pytest.raises(ValueError, match="letters, digits and '_'"):
        Projection("my-standard", "none", "start", True, "end", "one", ())
    sy, T = integrators.system("point_vortices"), integrators.tableau("GLRK2")
    for engine in (Stepper, Oracle):
        with pytest.raises(ValueError, match="own post term"):
            engine(sy, T, "identity", 0.1)
