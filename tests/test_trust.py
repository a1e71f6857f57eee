"""Results you can trust (issue 15): no code from data files, names never matter, failures are
failures, under-resolved sets are reported, batch-safe output, validated extension points."""
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import sympy

import integrators
from integrators.expressions import ExpressionError, parse_expression, parse_number
from integrators.tableaus import tableau, tableau_from_file


# -- no code from data ------------------------------------------------------------------------------

@pytest.mark.parametrize("text", [
    '__import__("os").system("touch PWNED")',
    'open("PWNED", "w").write("x")',
    "(lambda: 1)()",
    "[c for c in ().__class__.__base__.__subclasses__()]",
    "().__class__",
    "exec('1')",
    "sqrt.__globals__",
    "'1' + '2'",
    "1 if 1 else 2",
])
def test_a_tableau_file_holding_code_runs_nothing(tmp_path, monkeypatch, text):
    monkeypatch.chdir(tmp_path)
    f = tmp_path / "evil.toml"
    f.write_text(f"a = [[{text!r}]]\nb = [1]\nc = [0.5]\n".replace("'", "'''", 0))
    with pytest.raises(ValueError, match=r"evil.toml.*a\[0\]\[0\]"):
        tableau_from_file(f)
    assert not (tmp_path / "PWNED").exists()


def test_the_audit_cli_refuses_a_code_tableau_in_one_line(tmp_path, monkeypatch, capsys):
    from integrators.cli import main
    monkeypatch.chdir(tmp_path)
    f = tmp_path / "evil.toml"
    f.write_text('a = [["__import__(\'os\').system(\'touch PWNED\')"]]\nb = [1]\nc = [0.5]\n')
    assert main(["audit", str(f), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a[0][0]" in err and "not allowed" in err
    assert not (tmp_path / "PWNED").exists()


def test_parser_reads_exact_numbers():
    assert parse_expression("1/3", "k") == sympy.Rational(1, 3)
    assert parse_expression("2^3 - 3**2", "k") == -1
    assert parse_expression("(1/2 - sqrt(15)/10)", "k") == sympy.Rational(1, 2) - sympy.sqrt(15) / 10
    assert parse_expression(0.1, "k") == sympy.Rational("0.1")
    x = sympy.Symbol("x")
    assert parse_expression("exp(-x^2) * pi", "k", {"x": x}) == sympy.exp(-x ** 2) * sympy.pi
    # a caller's own name shadows a constant: a parameter called pi is that parameter
    pi = sympy.Symbol("pi")
    assert parse_expression("2*pi", "k", {"pi": pi}) == 2 * pi


@pytest.mark.parametrize("text,msg", [
    ("1/0", "not a finite number"),
    ("x + 1", "unknown name 'x'"),
    ("9**9**9", "exponent"),
    ("((2**64)**64)**64", "power larger"),
    ("1 +", "cannot read"),
    ("sqrt", "without a call"),
    ("log(-1)", "not a finite real"),
])
def test_parser_errors_name_the_key(text, msg):
    with pytest.raises(ExpressionError, match=msg) as e:
        parse_number(text, "my.toml: b[1]", 30)
    assert str(e.value).startswith("my.toml: b[1]: ")


def test_a_tableau_entry_1_over_0_names_the_key(tmp_path):
    f = tmp_path / "t.toml"
    f.write_text('a = [["1/0"]]\nb = [1]\nc = ["1/2"]\n')
    with pytest.raises(ValueError, match=r"a\[0\]\[0\]: '1/0' is not a finite number"):
        tableau_from_file(f)


def test_a_lobatto_IIIA_tableau_without_d_is_refused_naming_d(tmp_path):
    ref = tableau("LobIIIA3")
    rows = [[str(sympy.nsimplify(float(x))) for x in row] for row in ref.a]
    f = tmp_path / "lob.toml"
    f.write_text(f"a = {rows}\nb = ['1/6', '2/3', '1/6']\nc = ['0', '1/2', '1']\n")
    with pytest.raises(ValueError, match=r"singular.*give d"):
        tableau_from_file(f)
    d = [str(sympy.nsimplify(float(x))) for x in ref.d]
    f.write_text(f"a = {rows}\nb = ['1/6', '2/3', '1/6']\nc = ['0', '1/2', '1']\nd = {d}\n")
    t = tableau_from_file(f)
    assert np.max(np.abs(t.a - ref.a)) < 1e-16 and np.max(np.abs(t.d - ref.d)) < 1e-15


# -- names never matter ------------------------------------------------------------------------------

def test_system_from_with_hostile_names_gives_hand_values():
    q, p, out, np_ = sympy.symbols("q p out np")
    e, pi, sq, lg, ex, lam = sympy.symbols("e pi sqrt log exp lambda")
    theta = [-p * e / 2, q * pi / 2, -np_ * sq, out * lg]
    H = (q ** 2 + p ** 2) * ex / 2 + lam * (out ** 2 + np_ ** 2)
    s = integrators.system_from(theta, H, [q, p, out, np_],
                                params={e: 2.0, pi: 3.0, sq: 5.0, lg: 7.0, ex: 0.5, lam: 0.25})
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert s.theta(x).tolist() == [-2.0, 1.5, -20.0, 21.0]
    assert s.H(x) == 7.5
    assert s.dH(x).tolist() == [0.5, 1.0, 1.5, 2.0]
    assert s.Omega(x)[0, 1] == 2.5              # ∂_q ϑ_p − ∂_p ϑ_q = π/2 + e/2 = 1.5 + 1


def test_system_from_coordinate_named_q_and_x0():
    # the old generator called its argument q and its subexpressions _x0, _x1, ...
    q, x0, y, z = sympy.symbols("q _x0 y z")
    s = integrators.system_from([2 * q, 4 * q, 6 * q, x0], q * x0 + y * z, [q, x0, y, z])
    pt = np.array([1.0, 5.0, 2.0, 3.0])
    assert s.theta(pt).tolist() == [2.0, 4.0, 6.0, 5.0] and s.H(pt) == 11.0


def test_system_from_reads_strings_with_the_restricted_parser(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    x, y = sympy.symbols("x y")
    s = integrators.system_from(["-y/2", "x/2"], "(x^2 + y^2)/2", [x, y])
    assert s.H(np.array([3.0, 4.0])) == 12.5
    with pytest.raises(ValueError, match=r"theta\[0\].*not allowed"):
        integrators.system_from(['__import__("os").system("touch PWNED")', "x"], "x", [x, y])
    assert not (tmp_path / "PWNED").exists()
