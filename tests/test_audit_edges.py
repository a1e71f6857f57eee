"""The map audit's and the one-form scenes' edges (issue 68): one validation of a map audit's
arguments and sizes (the Python call, the command line, scenes), periods judged against the set,
an exact zero's error absolute, growth laws that need windows with a scale, no numpy warnings.
Each test failed before the change it names."""
import json
import math
import warnings

import numpy as np
import pytest

from invariants import first_invariant
from invariants.growth import growth_law
from integrators.audit import examples
from integrators.audit.maps import audit_map, check_arguments

from helpers import one_line, poincare


def _strang(x, v, h):
    v = v - 0.5 * h * np.sin(x)
    x = x + h * v
    return x, v - 0.5 * h * np.sin(x)


POINT = (np.array([0.3, 0.5, 0.7, 0.9]), np.array([0.1, -0.2, 0.3, 0.0]))


@pytest.mark.parametrize("kw, words", [
    (dict(loop_points=0), "loop_points must be a whole number of at least 8"),
    (dict(levels=0), "levels must be"),
    (dict(defect_points=0), "defect_points must be"),
    (dict(defect_points=100, loop_points=64), "more than the loop's 64 points"),
    (dict(h=1e-320), "below the smallest normal double"),
    (dict(point=np.zeros(8)), "got one array of shape (8,)"),
    (dict(period=np.array([[2 * np.pi]])), "1-D list"),
    (dict(method="bogus"), "method must be one of"),
    (dict(step={}), "no step map given"),
    (dict(radius=0), "radius must be a positive number"),
    (dict(plane=(0, 1)), "carries no area of the form"),
    (dict(plane=(0, 5)), "carries no area of the form"),       # x_0 against v_1: ω = 0 too
    (dict(period=1e-12), "is not a period of this loop"),
    (dict(loop_points=10 ** 12), "GiB of memory"),           # 512 TB: more than any machine has
    (dict(surface=(10 ** 6, 10 ** 6)), "a smaller surface"),
])
def test_a_bad_argument_is_one_line_before_anything_is_allocated(kw, words):
    args = {"step": _strang, "point": POINT, "h": 0.1, "steps": 10, "loop_points": 64, **kw}
    with pytest.raises(ValueError) as exc:
        audit_map(args.pop("step"), args.pop("point"), args.pop("h"), **args)
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_sizes_are_judged_from_the_dimension_alone():
    """check_arguments needs no array: a dimension of 2·10⁹ is refused without allocating one."""
    with pytest.raises(ValueError, match="GiB of memory for the sets"):
        check_arguments(2 * 10 ** 9, 0.1)
    with pytest.raises(ValueError, match="odd"):
        check_arguments(3, 0.1, noncanonical=True)
    assert check_arguments(8, 0.1)[:3] == (0.1, 100, 2)


def test_a_period_the_samples_cannot_tell_from_a_step_flags_the_value():
    """A unit circle given period 1e-12: before, I₁ ≈ −6e-12 marked resolved where the value is −π;
    now under-resolved, with the reason.  The right period (2π on a loop winding once) still gives
    the exact value."""
    tau = np.arange(64) / 64
    q = np.stack([np.cos(2 * np.pi * tau), np.sin(2 * np.pi * tau)], 1)
    theta = lambda x: np.stack([-x[:, 1], x[:, 0]], 1) / 2
    v = first_invariant(q, theta, period=1e-12)
    assert v.under_resolved and "quarter of its period" in v.reason
    ok = first_invariant(q, theta)
    assert not ok.under_resolved and abs(ok.value - math.pi) < 1e-13
    wind = np.stack([2 * np.pi * tau, 1 + 0.1 * np.sin(2 * np.pi * tau)], 1)     # (angle, action): winds once
    w = first_invariant(wind, lambda x: np.stack([x[:, 1], 0 * x[:, 1]], 1), period=[2 * np.pi, 0])
    assert not w.under_resolved and abs(w.value - 2 * np.pi) < 1e-13


def test_an_alternating_error_is_not_growth():
    """An anti-symplectic map (x, v) -> (v, x) flips I₁: its error reads 2, 0, 2, 0, …  Before, 10
    outputs read 'growing'; now too few windows with a scale say 'undetermined', and 30 say 'bounded'."""
    anti = lambda x, v, h: (v, x)
    for steps, verdict in ((10, "undetermined"), (30, "bounded")):
        c = audit_map(anti, POINT, 0.1, steps=steps, output_every=1, loop_points=64)["candidates"][0]
        assert c["drift"]["I1/canonical"]["verdict"] == verdict, steps
    t = np.arange(1.0, 11.0)
    assert growth_law(t, np.where(np.arange(10) % 2 == 0, 2.0, 0.0)).law == "undetermined"
    assert growth_law(t, 1e-6 * t).law == "linear"                       # a short series still has its law


def test_a_wrapped_loop_without_its_period_says_why():
    wrapped = lambda x, v, h: (lambda x1, v1: (x1 - 2 * np.pi * np.floor(x1 / (2 * np.pi)), v1))(*_strang(x, v, h))
    rep = audit_map(wrapped, (np.full(4, 6.2), np.ones(4)), 0.1, steps=20, loop_points=64, radius=0.5)
    d = rep["candidates"][0]["drift"]["I1/canonical"]
    assert d["verdict"] == "under-resolved" and "give its period" in d["under_resolved_reason"]
    from integrators.audit import text_report
    assert "why: from t = " in text_report(rep)


def test_maps_that_overflow_warn_nothing():
    """inf and 1e300 maps: broken down and 'step failed', with no numpy warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for bad in (lambda x, v, h: (x * np.inf, v), lambda x, v, h: (x * 1e300, v * 1e300)):
            c = audit_map(bad, POINT, 0.1, steps=10, loop_points=64)["candidates"][0]
            assert c["drift"]["I1/canonical"]["verdict"] == "broke down"
            assert c["defect"]["canonical"]["verdict"] == "step failed"


def test_a_noncanonical_map_needs_an_even_dimension_and_a_plane_with_area():
    theta = lambda q: np.concatenate([q[:, 2:], 0 * q[:, 2:]], axis=1)
    ident = lambda q, h: q + 0.0
    with pytest.raises(ValueError, match="odd"):
        audit_map(ident, np.zeros(3), 0.1, theta=lambda q: q, loop_points=64)
    with pytest.raises(ValueError, match="dϑ"):
        audit_map(ident, np.zeros(4), 0.1, theta=theta, loop_points=64, plane=(0, 1))
    c = audit_map(ident, np.zeros(4), 0.1, theta=theta, loop_points=64, plane=(0, 2), steps=10)["candidates"][0]
    assert c["drift"]["I1/noncanonical"]["verdict"] == "round-off"


def test_the_command_line_judges_sizes_before_building_an_example(tmp_path):
    """--k 10⁹ was a 17.9 GB kill; --loop-points 0 an IndexError; --levels 0 numpy's message."""
    for args, words in ((["--k", "1000000000"], ("GiB of memory", "--k")),
                        (["--loop-points", "0"], ("--loop-points must be",)),
                        (["--levels", "0"], ("--levels must be",)),
                        (["--points", "0"], ("--points must be",)),
                        (["--period", "1e-12"], ("not a period of this loop",))):
        r = poincare("audit", "--map", "pendula-strang", *args, "-q", cwd=tmp_path)
        assert r.returncode == 2, (args, r.stderr)
        one_line(r, *words)


def test_a_map_file_imports_a_module_beside_it(tmp_path):
    (tmp_path / "helper_68.py").write_text("def go(x, v, h):\n    return x + h * v, v\n")
    (tmp_path / "m.py").write_text("import helper_68\ndef step(x, v, h):\n    return helper_68.go(x, v, h)\n")
    np.savez(tmp_path / "p.npz", x0=np.zeros(2), v0=np.ones(2))
    r = poincare("audit", "--map", f"{tmp_path}/m.py:step", "--point", f"{tmp_path}/p.npz", "--h", "0.1",
                 "--steps", "20", "--loop-points", "64", "--json", "r.json", "-q", cwd=tmp_path.parent)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path.parent / "r.json").read_text())["candidates"][0]["defect"]["canonical"]["verdict"] \
        == "symplectic"


ONE_FORM = '''[system]
{system}
[loop]
points = 64
shape = "ellipse"
params = {{ d = 4, center = [0.5, 0.2, 0.1, 0.3], radii = [0.1, 0.1], plane = [0, 2] }}
[run]
step_maps = ["of.py:rot", "of.py:shear"]
h = 0.1
steps = 20
'''
OF = '''import numpy as np
def closed(q):          # the gradient of q0²/2 + q1 q3 + q2²: dϑ = 0
    t = np.zeros_like(q); t[:, 0] = q[:, 0]; t[:, 1] = q[:, 3]; t[:, 3] = q[:, 1]; t[:, 2] = 2 * q[:, 2]
    return t
def nan(q):
    return np.full_like(q, np.nan)
def rot(q, h):
    c, s = np.cos(h), np.sin(h)
    out = q.copy(); out[:, 0] = c * q[:, 0] - s * q[:, 2]; out[:, 2] = s * q[:, 0] + c * q[:, 2]
    return out
def shear(q, h):
    out = q.copy(); out[:, 1] = q[:, 1] + h * q[:, 3]
    return out
'''


def test_a_closed_one_form_has_absolute_errors_not_relative_ones(tmp_path):
    """dϑ = 0: I₁ = 0 exactly, so I(0) is round-off.  Before, both pairs 'ok' with relative I₁ errors of
    5.8e16; now the file lists I1/noncanonical as absolute and the errors are round-off's."""
    (tmp_path / "of.py").write_text(OF)
    (tmp_path / "c.toml").write_text(ONE_FORM.format(system='dimension = 4\none_form = "of.py:closed"'))
    r = poincare("run", "c.toml", "-q", "-o", "c.h5", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "absolute |I(t) − I(0)|" in r.stdout
    from integrators.service.reader import read_run
    run = read_run(str(tmp_path / "c.h5"))
    for pair in run.pairs.values():
        assert pair.absolute == {"I1/noncanonical"}
        assert np.nanmax(pair.relative_error("I1", "noncanonical")) < 1e-14


def test_a_one_form_that_is_not_finite_or_odd_is_named_in_one_line(tmp_path):
    (tmp_path / "of.py").write_text(OF)
    (tmp_path / "n.toml").write_text(ONE_FORM.format(system='dimension = 4\none_form = "of.py:nan"'))
    one_line(poincare("run", "n.toml", "-q", cwd=tmp_path), "system.one_form is not finite at 64 of 64 points")
    (tmp_path / "o.toml").write_text(ONE_FORM.format(system='dimension = 3\none_form = "of.py:closed"'))
    one_line(poincare("run", "o.toml", "-q", cwd=tmp_path), "system.dimension = 3 is odd")


def test_a_scene_of_a_billion_degrees_of_freedom_is_refused_before_it_is_built(tmp_path):
    """It hung and ended in a MemoryError traceback (a period of 10⁹ entries, a state of d = 2·10⁹)."""
    (tmp_path / "of.py").write_text(OF)
    (tmp_path / "b.toml").write_text(ONE_FORM.format(system="degrees_of_freedom = 1000000000\nperiod = 6.28")
                                     .replace("d = 4", "d = 8"))
    one_line(poincare("run", "b.toml", "-q", cwd=tmp_path), "system.degrees_of_freedom = 1,000,000,000", "GiB")


def test_a_scene_says_why_a_wrapped_loop_is_under_resolved(tmp_path):
    """A map that wraps its angles, in a scene without system.period: the footnote said 'refine the
    set'; now it gives the reason the invariants found, and the pair group keeps it."""
    (tmp_path / "wrapmap.py").write_text(
        "import numpy as np\n"
        "def step(x, v, h):\n"
        "    v = v - 0.5 * h * np.sin(x); x = x + h * v; v = v - 0.5 * h * np.sin(x)\n"
        "    return x - 2 * np.pi * np.floor(x / (2 * np.pi)), v\n")
    (tmp_path / "w.toml").write_text(
        '[system]\ndegrees_of_freedom = 2\n[loop]\npoints = 64\nshape = "ellipse"\n'
        'params = { d = 4, center = [6.2, 6.2, 1.0, 1.0], radii = [0.3, 0.3], plane = [0, 2] }\n'
        '[run]\nstep_maps = ["wrapmap.py:step"]\nh = 0.1\nsteps = 20\n')
    r = poincare("run", "w.toml", "-q", "-o", "w.h5", cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    assert "(why: coordinate 0 jumps by" in r.stdout and "refine the set" not in r.stdout
    import h5py
    with h5py.File(tmp_path / "w.h5", "r") as f:
        assert "a wrapped angle" in f["runs/step-map"].attrs["under_resolved_reason/I1"]


def test_a_missing_one_form_is_named_once(tmp_path):
    """The error named 'system.system.one_form'."""
    (tmp_path / "of.py").write_text(OF)
    (tmp_path / "m.toml").write_text(ONE_FORM.format(system='dimension = 4\none_form = "of.py:nope"'))
    r = poincare("run", "m.toml", "-q", cwd=tmp_path)
    one_line(r, "system.one_form: 'of.py' has no function 'nope'")
    assert "system.system" not in r.stderr
