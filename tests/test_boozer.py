"""Guiding centres in Boozer coordinates from boozmn files (integrators/boozer.py, issue 71).

* the two shipped simsopt files are read: the interpolated modes give back the file's own Fourier
  sum on every kept surface, ι, G, I their half-grid values, the Cartesian harmonics the Fourier
  sum; the radial interpolant does not overshoot li383's four surfaces;
* a file that is not a usable boozmn file is refused in one line;
* (slow) the compiled engine: the field-line map's winding is the file's ι to 1e-9; the system's
  |B| is the Fourier sum's to the grid's accuracy; in the axisymmetric file P_ζ and the energy are
  kept to round-off by projected pairs, also by orbits through the axis region and one started on
  the axis; li383's default orbits run.
"""
from pathlib import Path

import numpy as np
import pytest
from scipy.io import netcdf_file

import integrators
from integrators.boozer import BoozerError, field_line_system, read_boozmn, system_from_boozer

SCENES = Path(integrators.__file__).parent / "service" / "scenes"
CIRCULAR = SCENES / "boozmn_circular_tokamak.nc"
LI383 = SCENES / "boozmn_li383_low_res.nc"


@pytest.fixture(scope="module")
def files():
    return {"circular": read_boozmn(CIRCULAR), "li383": read_boozmn(LI383)}


def test_reads_the_shipped_files(files):
    c, li = files["circular"], files["li383"]
    assert (c.nfp, c.ns, c.xm.size, c.s.size, c.asym) == (1, 17, 48, 16, False)
    assert (li.nfp, li.ns, li.xm.size, li.s.size, li.asym) == (3, 16, 1040, 4, False)
    np.testing.assert_allclose(li.s, (np.array([2, 3, 4, 16]) - 1.5) / 15, rtol=0, atol=1e-15)
    assert np.all(li.xn % 3 == 0)                                # n carries the field periods
    assert c.psi0 == pytest.approx(67.8603 / (2 * np.pi), rel=1e-5)   # phi_b's last value over 2π


@pytest.mark.parametrize("name", ["circular", "li383"])
def test_modes_give_back_the_files_fourier_sum(files, name):
    """With every mode kept, the interpolated |B| on each kept surface is the file's own sum."""
    bz = files[name]
    th, ze = np.meshgrid(np.linspace(0, 2 * np.pi, 41), np.linspace(0, 2 * np.pi / bz.nfp, 17))
    b00 = abs(bz.bmnc[0, 0])
    for j, s in enumerate(bz.s):
        err = np.abs(bz.modB(np.full(th.shape, s), th, ze, modes_tol=0) - bz.surface_modB(j, th, ze))
        assert err.max() <= 1e-13 * b00, (j, err.max())


@pytest.mark.parametrize("name", ["circular", "li383"])
def test_profiles_interpolate_the_half_grid(files, name):
    bz = files[name]
    iota, G, Is, psip = bz.profiles()
    np.testing.assert_allclose(iota(bz.s_half), bz.iota, rtol=1e-14, atol=0)
    np.testing.assert_allclose(G(bz.s_half), bz.G, rtol=1e-14, atol=0)
    np.testing.assert_allclose(Is(bz.s_half) * bz.s_half, bz.I, rtol=1e-12, atol=1e-15)
    assert psip(0.0) == 0.0
    s = np.linspace(0.05, 0.95, 7)     # ψ_p is ι's antiderivative: a centred difference of it is ι
    e = 1e-5
    np.testing.assert_allclose((psip(s + e) - psip(s - e)) / (2 * e), iota(s), rtol=1e-8)


@pytest.mark.parametrize("name", ["circular", "li383"])
def test_harmonics_sum_to_the_fourier_sum(files, name):
    bz = files[name]
    rng = np.random.default_rng(71)
    s, th, ze = rng.uniform(0, 1, 300), rng.uniform(-np.pi, np.pi, 300), rng.uniform(0, 2 * np.pi, 300)
    r = np.sqrt(2 * bz.psi0 * s)
    harm = bz.harmonics(r * np.cos(th), r * np.sin(th))
    B = sum(C * np.cos(n * ze) + (S * np.sin(n * ze) if S is not None else 0.0) for n, (C, S) in harm.items())
    ref = bz.modB(s, th, ze)
    assert np.max(np.abs(B / ref - 1)) < 1e-12
    assert sorted(harm) == sorted(set(np.abs(bz.xn[bz.modes()[0]]).tolist()))


def test_radial_interpolation_stays_within_the_data(files):
    """li383's transform kept 4 surfaces (s = 0.033 … 0.967): between them no mode exceeds 3.5 times
    its largest value on the surfaces (measured 3.18 over all 1,040 modes; a cubic spline of b/s^{m/2}
    overshoots by 10²–10⁴ there)."""
    bz = files["li383"]
    keep, p, cs, _ = bz.modes(0)
    s = np.linspace(0, 1, 2001)
    b = cs(s) * s[:, None] ** (p / 2)
    ratio = np.abs(b).max(0) / np.maximum(np.abs(bz.bmnc[:, keep]).max(0), 1e-300)
    assert ratio.max() < 3.5


def _copy(src, dst, drop=(), change=None):
    """A copy of the NetCDF file src at dst without the variables ``drop``, with ``change[name] = array``."""
    change = change or {}
    with netcdf_file(str(src), "r", mmap=False) as a, netcdf_file(str(dst), "w") as b:
        for name, var in a.variables.items():
            if name in drop:
                continue
            data = np.asarray(change.get(name, var.data), dtype=var.data.dtype)
            dims = tuple(f"{name}_{i}" for i in range(data.ndim))
            for dim, n in zip(dims, data.shape):
                b.createDimension(dim, n)
            out = b.createVariable(name, data.dtype, dims)
            if data.ndim:
                out[:] = data
            else:
                out.data[()] = data         # (assignValue indexes a 0-d array with [:] in this scipy)
    return dst


def test_refuses_what_it_cannot_use(tmp_path, files):
    bad = tmp_path / "text.nc"
    bad.write_text("not a netcdf file\n")
    cases = {
        "not a NetCDF 3 boozmn file": bad,
        "no bmnc_b": _copy(CIRCULAR, tmp_path / "nobmn.nc", drop=("bmnc_b",)),
        "bmnc_b has shape": _copy(CIRCULAR, tmp_path / "shape.nc", change={"bmnc_b": files["circular"].bmnc[:, :40]}),
        "the axis chart needs Φ ≠ 0": _copy(CIRCULAR, tmp_path / "zero.nc", change={"phi_b": np.zeros(17)}),
        "no such file": tmp_path / "missing.nc",
    }
    for what, path in cases.items():
        with pytest.raises(BoozerError) as err:
            read_boozmn(path)
        msg = str(err.value)
        assert "\n" not in msg and msg.startswith(str(path)) and what in msg, msg


# -- the compiled engine --------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("path", [CIRCULAR, LI383])
def test_field_line_winding_is_the_files_iota(path):
    """θ(ζ) of the field-line system over 20 toroidal turns (GLRK4, 200 steps a turn): its winding
    is the file's iota_b on the half grid to 1e-9 (measured 5e-10 on li383, 1e-13 on the circular
    file, whose ι is linear in s)."""
    bz = read_boozmn(path)
    js = np.arange(1, bz.s_half.size, 2)
    r = np.sqrt(2 * bz.psi0 * bz.s_half[js])
    turns, per = 20, 200
    sol = integrators.integrate(field_line_system(bz), np.stack([r, 0 * r], 1), tableau="GLRK4", projection="none",
                                h=2 * np.pi / per, steps=per * turns, save_every=1)
    ang = np.unwrap(np.arctan2(sol.q[..., 1], sol.q[..., 0]), axis=0)
    winding = (ang[-1] - ang[0]) / (2 * np.pi * turns)
    assert np.max(np.abs(winding - bz.iota[js])) < 1e-9


@pytest.mark.slow
def test_a_file_with_negative_flux_is_the_mirror_image(tmp_path, files):
    """li383 with Φ → −Φ (W7-X's files have Φ < 0): the chart turns the other way, θ = −atan2(y, x).
    Its field lines wind at −ι in atan2 (to 1e-9), its |B| at (x, y) is the original's at (x, −y)
    (to 1e-12), and its default orbits run with the original's energy error bound."""
    bz = files["li383"]
    flipped = _copy(LI383, tmp_path / "flipped.nc",
                    change={"phi_b": -np.asarray(netcdf_file(LI383, "r", mmap=False).variables["phi_b"][:])})
    fz = read_boozmn(flipped)
    assert fz.sign == -1.0 and fz.psi0 == -bz.psi0 and fz.psi_abs == bz.psi0
    js = np.array([3, 9])
    r = np.sqrt(2 * fz.psi_abs * fz.s_half[js])
    sol = integrators.integrate(field_line_system(fz), np.stack([r, 0 * r], 1), tableau="GLRK4", projection="none",
                                h=2 * np.pi / 200, steps=200 * 10, save_every=1)
    ang = np.unwrap(np.arctan2(sol.q[..., 1], sol.q[..., 0]), axis=0)
    assert np.max(np.abs((ang[-1] - ang[0]) / (2 * np.pi * 10) + fz.iota[js])) < 1e-9
    a, b = system_from_boozer(LI383), system_from_boozer(flipped)
    rng = np.random.default_rng(5)
    s, th, ze = rng.uniform(0, 0.95, 200), rng.uniform(0, 2 * np.pi, 200), rng.uniform(0, 2 * np.pi, 200)
    rr = np.sqrt(2 * bz.psi0 * s)
    q = np.stack([rr * np.cos(th), rr * np.sin(th), ze, 0 * s], 1)
    qm = q * [1, -1, 1, 1]
    assert np.max(np.abs(b.H(q) / a.H(qm) - 1)) < 1e-12
    d = b.defaults
    sol = integrators.integrate(b, np.array([d["q0"], d["trapped"]]), tableau="GLRK2", projection="symmetric",
                                h=d["h"], steps=1000, save_every=100)
    assert np.isinf(sol.breakdown_time).all()
    E = np.stack([b.H(sol.q[:, i]) for i in range(2)])
    assert np.max(np.abs(E / E[:, :1] - 1)) < 1e-6


@pytest.fixture(scope="module")
def circular_system():
    return system_from_boozer(CIRCULAR, grid=64)


@pytest.mark.slow
def test_system_field_is_the_fourier_sum(circular_system):
    """The compiled |B| (quintic splines on a 64² grid) against the Fourier sum of the same modes at
    300 points with s < 0.98: within 1e-5 relative (measured 3.3e-6, 7 modes)."""
    sy, bz = circular_system, circular_system.boozer
    rng = np.random.default_rng(3)
    s, th, ze = rng.uniform(0, 0.98, 300), rng.uniform(0, 2 * np.pi, 300), rng.uniform(0, 2 * np.pi, 300)
    r = np.sqrt(2 * bz.psi0 * s)
    q = np.stack([r * np.cos(th), r * np.sin(th), ze, 0 * s], 1)
    B = sy.H(q) / sy.param_values["mu"]
    assert np.max(np.abs(B / bz.modB(s, th, ze) - 1)) < 1e-5


def near_axis(sy):
    """Eight trapped guiding centres on a circle of radius 0.02 r₁ about the axis of the circular
    tokamak and one on the axis itself (the default trapped orbit's ρ), and r₁."""
    r1 = np.sqrt(2 * sy.boozer.psi0)
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    rho = sy.defaults["trapped"][3]
    return np.vstack([np.stack([0.02 * r1 * np.cos(ang), 0.02 * r1 * np.sin(ang), 0 * ang, rho + 0 * ang], 1),
                      [0.0, 0.0, 0.0, rho]]), r1


@pytest.mark.slow
@pytest.mark.parametrize("tableau,projection", [("GLRK2", "standard"), ("GLRK2", "symmetric"), ("GLRK4", "symmetric")])
def test_axisymmetric_file_keeps_momentum_and_energy_through_the_axis(circular_system, tableau, projection):
    """The circular tokamak (n = 0 only: ∂/∂ζ is a symmetry, P_ζ = ρG − ψ_p): eight trapped guiding
    centres started on a circle of radius 0.02 r₁ about the axis (their orbits come to 0.0033 r₁ of
    it), one started on the axis itself, and the default passing and trapped ones; 4,000 steps of
    the default h.  No point breaks down; P_ζ is kept to round-off by every orbit under every pair
    (the default orbits: measured ≤ 3.4e-14 relative; 4.0e-13 and 1.6e-12 under GLRK2- and
    GLRK4-symmetric were steps whose Newton stopped short of the floor, test below); the axis
    family's energy too (measured ≤ 5.4e-14; the passing orbit's energy error is the method's
    truncation, 1.1e-9 for GLRK2)."""
    sy, d = circular_system, circular_system.defaults
    q0, r1 = near_axis(sy)
    q0 = np.vstack([q0, d["q0"], d["trapped"]])
    sol = integrators.integrate(sy, q0, tableau=tableau, projection=projection, h=d["h"], steps=4000, save_every=20)
    assert np.isinf(sol.breakdown_time).all()
    E = np.stack([sy.H(sol.q[:, i]) for i in range(len(q0))])
    P = np.stack([sy.momentum(sol.q[:, i]) for i in range(len(q0))])
    dP = np.abs(P - P[:, :1]).max(1) / np.abs(P[:, 0])
    assert dP.max() < 1e-13
    assert np.max(np.abs(E[:9] / E[:9, :1] - 1)) < 5e-13
    r = np.hypot(sol.q[..., 0], sol.q[..., 1])
    assert r[:, :8].min() < 0.005 * r1                      # the family does come close to the axis


@pytest.mark.slow
def test_dithered_newton_stops_at_the_floor_near_the_axis(circular_system):
    """The dithered approach (Tolerances(dither=True)) rounds Newton's guess and iterates to 64 ulps
    of their scale, 1 for x, y ≈ 0.004 near the axis: thousands of their own ulps.  Its first
    version's floor test took updates within 64 ulps on carried factors that contracted by 0.5-0.8
    for the floor and stopped there, and single steps moved P_ζ by 70-90 ulps: 1.3e-12 over the
    4,000 steps of the test above (GLRK2-symmetric, its eight near-axis orbits and the one on the
    axis).  The strict floor test keeps it to round-off (measured 5.7e-15; 5.8e-15 undithered)."""
    sy, d = circular_system, circular_system.defaults
    q0, _ = near_axis(sy)
    sol = integrators.integrate(sy, q0, tableau="GLRK2", projection="symmetric", h=d["h"], steps=4000, save_every=20,
                                tolerances=integrators.Tolerances(dither=True))
    assert np.isinf(sol.breakdown_time).all()
    P = np.stack([sy.momentum(sol.q[:, i]) for i in range(len(q0))])
    assert (np.abs(P - P[:, :1]).max(1) / np.abs(P[:, 0])).max() < 1e-13


@pytest.mark.slow
def test_li383_default_orbits_run():
    """li383 (nfp 3, 114 modes of 1,040 at 1e-4, 8 toroidal harmonics, |B| as the 3-D spline): the
    default passing and trapped guiding centres, 2,000 steps of GLRK2-symmetric at the default h,
    stay in the plasma with a bounded energy error (measured 2.5e-7 passing, 1.7e-11 trapped; with
    the harmonics' form 1.5e-7 and 1.7e-11)."""
    sy = system_from_boozer(LI383)
    d = sy.defaults
    assert d["harmonics"] == (0, 3, 6, 9, 12, 15, 18, 21)
    sol = integrators.integrate(sy, np.array([d["q0"], d["trapped"]]), tableau="GLRK2", projection="symmetric",
                                h=d["h"], steps=2000, save_every=100)
    assert np.isinf(sol.breakdown_time).all()
    E = np.stack([sy.H(sol.q[:, i]) for i in range(2)])
    assert np.max(np.abs(E / E[:, :1] - 1)) < 1e-6


# -- scenes -----------------------------------------------------------------------------------------

def _li383_scene(tmp_path, steps):
    import shutil
    shutil.copy(LI383, tmp_path / "boozmn_li383_low_res.nc")
    scene = tmp_path / "li383.toml"
    scene.write_text((SCENES / "boozer_li383.toml").read_text().replace("steps = 400", f"steps = {steps}")
                     .replace("points = 2048", "points = 256").replace("refine_to = 8192", "refine_to = 512")
                     .replace("n_sigma = 24", "n_sigma = 8").replace("n_tau = 24", "n_tau = 8")
                     .replace("refine_to = 2209", "refine_to = 225"))
    return scene


def test_a_boozer_scene_is_checked_in_one_line(tmp_path):
    import shutil
    from integrators.service.scene import SceneError, load_scene
    shutil.copy(LI383, tmp_path / "boozmn_li383_low_res.nc")
    base = (SCENES / "boozer_li383.toml").read_text()
    for change, words in [(("grid = 96", "grid = 4"), "system.grid"),
                          (("modes_tol = 0.0001", "modes_tol = 2.0"), "system.modes_tol"),
                          (('boozer = "boozmn_li383_low_res.nc"', 'boozer = "nowhere.nc"'), "system.boozer: file"),
                          (("grid = 96", 'grid = 96\ncocos = 3'), "system.cocos cannot go with system.boozer"),
                          (('field = "3d"', 'field = "fourier"'), "system.field must be one of"),
                          (('field = "3d"', 'grid_zeta = 5'), "system.grid_zeta must be between 6")]:
        (tmp_path / "s.toml").write_text(base.replace(*change))
        with pytest.raises(SceneError) as err:
            load_scene(str(tmp_path / "s.toml")).system()
        assert words in str(err.value) and "\n" not in str(err.value), str(err.value)


@pytest.mark.slow
def test_the_li383_scene_runs_every_pair_ok_and_names_the_file(tmp_path, capsys):
    """The built-in scene (smaller sets, 8 steps): every pair ok, the summary names the file, its
    digest and the modes kept."""
    from integrators.cli import main as cli_main
    scene = _li383_scene(tmp_path, 8)
    assert cli_main(["run", str(scene), "-o", str(tmp_path / "a.h5")]) == 0
    said = capsys.readouterr().out
    assert said.count(" ok ") == 10, said
    assert "read from boozmn_li383_low_res.nc (sha256 593f78a5469b" in said and "114 kept" in said


@pytest.mark.slow
@pytest.mark.mpi
def test_the_li383_scene_gives_the_same_bits_on_2_ranks(tmp_path):
    from helpers import dump, poincare, same
    scene = _li383_scene(tmp_path, 6)
    files = []
    for n in (None, 2):
        out = tmp_path / f"r{n or 1}.h5"
        r = poincare("run", str(scene), "-o", str(out), "-q", n=n)
        assert r.returncode == 0, r.stderr[-2000:]
        files.append(dump(out))
    assert same(*files)


@pytest.mark.slow
def test_no_step_stops_short_of_the_round_off_floor():
    """Newton's stall test stops a lane whose update no longer halves, taking that for round-off; with
    factors carried from an earlier step or iterate an update can stop halving far above it. On the
    circular tokamak's scene loop (64 of its points, the default grid and h, 400 steps),
    GLRK1-symmetric moved P_ζ, a constant of the discrete motion, by up to 1.7e-11 (relative) in
    single steps, 10⁴ ulps of one sign (GLRK2: 2.0e-12), and in the QA equilibrium the scene's I₁
    by jumps of 10⁻⁹ (docs/stellarators.md); with the stall test taken only under a Jacobian at the
    iterate (or below the refresh floor) no step moves it by more than 1.0e-14 (measured)."""
    import tomllib
    from integrators.service.scene import boozer_scene
    sy = system_from_boozer(CIRCULAR)
    lp = tomllib.loads(boozer_scene(CIRCULAR))["loop"]["params"]
    a = 2 * np.pi * np.arange(0, 512, 8) / 512
    q0 = np.tile(lp["center"], (a.size, 1))
    q0[:, 0] += lp["radii"][0] * np.cos(a)
    q0[:, 1] += lp["radii"][1] * np.sin(a)
    sol = integrators.integrate(sy, q0, tableau="GLRK1", projection="symmetric", h=sy.defaults["h"], steps=400,
                                save_every=1)
    assert np.isinf(sol.breakdown_time).all()
    P = np.stack([sy.momentum(sol.q[:, i]) for i in range(a.size)])
    assert np.max(np.abs(np.diff(P, axis=1)) / np.abs(P[:, :1])) < 1e-13
