"""Tableaus: order conditions, symplecticity, R(∞), Lobatto d, extended precision, TOML loading."""
import mpmath
import numpy as np
import pytest

import integrators
from integrators.order_conditions import order_residuals, trees
from integrators.tableaus import TABLEAU_NAMES, tableau, tableau_from_file


def test_tree_counts_match_oeis_A000081():
    assert [len(trees(n)) for n in range(1, 9)] == [1, 1, 2, 4, 9, 20, 48, 115]


@pytest.mark.parametrize("name", TABLEAU_NAMES)
def test_order_conditions_hold_to_nominal_order(name):
    tab = tableau(name)
    for p in range(1, tab.order + 1):
        assert order_residuals(tab.a + tab.a_lo, tab.b + tab.b_lo, p) < 1e-14, (name, p)
        if not name.startswith("Rad"):
            assert order_residuals(tab.abar + tab.abar_lo, tab.b + tab.b_lo, p) < 1e-14, (name, p)


@pytest.mark.parametrize("s", range(1, 7))
def test_gauss_order_is_exactly_2s(s):
    tab = tableau(f"GLRK{s}")
    assert tab.order == 2 * s
    assert order_residuals(tab.a, tab.b, 2 * s + 1) > 1e-8  # the next order fails


@pytest.mark.parametrize("name", [n for n in TABLEAU_NAMES if not n.startswith("Rad")])
def test_symplecticity_condition_in_extended_precision(name):
    assert tableau(name).symplectic_defect < 1e-45


@pytest.mark.parametrize("name", ["RadIIA2", "RadIIA3"])
def test_radau_is_not_symplectic(name):
    assert tableau(name).symplectic_defect > 1e-3


def _R_numeric(tab, z):
    s = tab.s
    return 1 + z * tab.b @ np.linalg.solve(np.eye(s) - z * tab.a, np.ones(s))


@pytest.mark.parametrize("s", range(1, 7))
def test_R_inf_gauss_is_minus_one_to_the_s(s):
    tab = tableau(f"GLRK{s}")
    assert tab.R_inf == (-1) ** s
    assert abs(_R_numeric(tab, 1e7) - tab.R_inf) < 1e-5


@pytest.mark.parametrize("fam", ["A", "B"])
@pytest.mark.parametrize("s", [2, 3, 4])
def test_R_inf_lobatto_AB_is_minus_one_to_the_s_minus_one(fam, s):
    assert tableau(f"LobIII{fam}{s}").R_inf == (-1) ** (s - 1)


def test_R_inf_radau_and_srk3():
    assert tableau("RadIIA2").R_inf == 0.0
    assert tableau("SRK3").R_inf == -1.0


@pytest.mark.parametrize("s,paper", [(2, [1, -1]), (3, [0.5, -1, 0.5]),
                                     (4, [1, -5 ** 0.5, 5 ** 0.5, -1])])
def test_lobatto_d_matches_paper_up_to_scale(s, paper):
    d = tableau(f"LobIIIA{s}").d
    paper = np.array(paper)
    assert np.allclose(d / d[0], paper / paper[0], rtol=0, atol=1e-15)
    # d/b spans the null space of a (the dependent velocity stages)
    tab = tableau(f"LobIIIA{s}")
    assert np.max(np.abs(tab.a @ (tab.d / tab.b))) < 1e-14


def test_double_plus_correction_is_accurate_to_extended_precision():
    tab = tableau("GLRK3")
    mp = mpmath.mp.clone()
    mp.dps = 50
    A = tab.exact["a"]
    for i in range(3):
        for j in range(3):
            err = abs(mp.mpf(tab.a[i, j]) + mp.mpf(tab.a_lo[i, j]) - A[i, j])
            assert err < mp.mpf(10) ** -30
    assert np.any(tab.a_lo != 0)


def test_srk3_midpoint_stage():
    tab = tableau("SRK3")
    assert tab.c[1] == 0.5
    assert np.max(np.abs(tab.a[1] - tab.b / 2)) < 1e-16


def test_tableau_from_toml_reproduces_builtin_bitwise(tmp_path):
    f = tmp_path / "srk3.toml"
    f.write_text('''
name = "mySRK3"
a = [["5/36", "2/9", "5/36 - sqrt(15)/10"],
     ["5/36", "2/9", "5/36"],
     ["5/36 + sqrt(15)/10", "2/9", "5/36"]]
b = ["5/18", "4/9", "5/18"]
c = ["1/2 - sqrt(15)/10", "1/2", "1/2 + sqrt(15)/10"]
''')
    user, ref = tableau_from_file(f), tableau("SRK3")
    assert user.order == 4 and user.R_inf == -1.0
    for key in ("a", "a_lo", "abar", "abar_lo", "b", "b_lo", "c"):
        assert np.array_equal(getattr(user, key), getattr(ref, key)), key


@pytest.mark.parametrize("text,msg", [("a=[[1]]\nb=[1]\nc=[0]\nfoo=1", "unknown key 'foo'"),
                                      ("a=[[1]]\nb=[1]", "missing key 'c'"),
                                      ("a=[[1]]\nb=[0.5]\nc=[1]", "sum to 0.5"),
                                      ("a=[['x']]\nb=[1]\nc=[1]", "a\\[0\\]\\[0\\]: unknown name 'x'")])
def test_bad_tableau_files(tmp_path, text, msg):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ValueError, match=msg):
        tableau_from_file(f)


def test_unknown_tableau_name():
    with pytest.raises(ValueError, match="unknown tableau 'GLRK7'"):
        integrators.tableau("GLRK7")


def test_rounded_drops_only_the_corrections():
    """Tableau.rounded(): the same doubles without their corrections (sec:app_energy_drift's plain
    variant); GLRK4's corrections are nonzero, so the digest changes; the runs agree bit for bit over
    10 steps of Lotka–Volterra and part by 9.5e-15 after 100 (measured)."""
    import numpy as np
    import integrators
    tab = integrators.tableau("GLRK4")
    r = tab.rounded()
    assert np.array_equal(r.a, tab.a) and np.array_equal(r.b, tab.b) and np.array_equal(r.abar, tab.abar)
    assert not (r.a_lo.any() or r.abar_lo.any() or r.b_lo.any()) and tab.a_lo.any()
    assert r.digest != tab.digest
    sy = integrators.system("lotka_volterra_2d")
    q1 = integrators.integrate(sy, [1.0, 1.0], tableau=tab, projection="symmetric", h=0.1, steps=100).q[-1]
    q2 = integrators.integrate(sy, [1.0, 1.0], tableau=r, projection="symmetric", h=0.1, steps=100).q[-1]
    assert 0 < np.max(np.abs(q1 - q2)) < 1e-13


@pytest.mark.parametrize("name", ["GLRK3", "GLRK4", "GLRK5", "GLRK6"])
def test_the_symplecticity_condition_in_floating_point(name):
    """eq:vprk_coefficients for the coefficients the step uses, evaluated exactly: the double +
    correction tableau and Tableau.conjugated() (ā the exact conjugate of the rounded a, Antoñana et
    al.) satisfy it to 1e-30; rounded to double, or with GeometricIntegrators.jl's ā computed in
    double, it is off by 1e-18 … 1e-16."""
    tab = tableau(name)
    assert tab.float_symplectic_residual < 1e-30
    assert tab.conjugated().float_symplectic_residual < 1e-30
    assert 1e-18 < tab.rounded().float_symplectic_residual < 1e-16
    assert 1e-18 < tab.conjugated(compensated=False).float_symplectic_residual < 1e-16
    c = tab.conjugated()
    assert not (c.a_lo.any() or c.b_lo.any()) and np.array_equal(c.a, tab.a)
    assert 0 < np.max(np.abs(c.abar - tab.abar)) < 1e-16       # a different ā in its last bits
