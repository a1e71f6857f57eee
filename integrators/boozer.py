"""Guiding centres in Boozer coordinates, read from ``boozmn`` files as booz_xform writes them.

:func:`read_boozmn` reads the NetCDF 3 file (``scipy.io.netcdf_file``: no netCDF4 dependency) into a
:class:`Boozer` record; :func:`system_from_boozer` turns it into a
:class:`~integrators.systems.System` with White's guiding centre in Boozer coordinates,

    ϑ = (ψ + ρ I) dθ + (ρ G − ψ_p) dζ,   H = ρ² B²/2 + μ B,

(ρ = ρ∥ = v∥/B, charge/mass 1, the file's units T and m; the covariant radial component K is not
kept, so the system is White's K = 0 form), written in the **axis chart**

    x = √(2|ψ|) cos θ,   y = σ √(2|ψ|) sin θ,   q = (x, y, ζ, ρ),   σ = sign Φ,

where dψ ∧ dθ = dx ∧ dy and ψ dθ = (x dy − y dx)/2 for either sign: one chart from the magnetic
axis to the boundary, smooth at the axis, so no clamp and no chart switch anywhere (SIMPLE #398).
ψ is the toroidal flux over 2π, ψ = s ψ₀ with ψ₀ = Φ_edge/2π (W7-X's files have Φ < 0: there
θ = −atan2(y, x), ρ I dθ = ρ Ĩ (x dy − y dx) with Ĩ = I/(2ψ) carrying ψ's sign, and ψ_p = ψ₀ ∫ι ds
too), and ψ_p the poloidal flux over 2π, dψ_p/dψ = ι.

**The field's data** are one set of interpolants from which ϑ and H are both built:

* ι, G (``bvco_b``) and I (``buco_b``) on VMEC's half grid, interpolated by cubic splines in s (I as
  I/s, which is finite at the axis); ψ_p = ψ₀ ∫₀ˢ ι ds' exactly (the spline's antiderivative).
  In the system G, Ĩ = I/(2ψ) and ψ_p are 1-D quintic splines in ψ (:class:`~integrators.splines.Spline1`)
  on a grid that holds every half-grid point and the axis (:data:`REFINE` nodes between half-grid
  points);
* |B| = Σ b_mn(s) cos(mθ − nζ) (+ b^s_mn sin(mθ − nζ) where not stellarator-symmetric), n including
  the field periods as booz_xform writes it.  Each mode's b_mn(s)/s^{p/2}, p = min(m, 2), is
  interpolated in s through the surfaces the transform kept (``jlist``): by the cubic spline (C²),
  or, for a mode whose spline strays past 1.5 times the mode's largest value on the surfaces, by a
  monotone cubic (PCHIP, C¹).  So b_mn ∝ √s for m = 1 and ∝ s for m ≥ 2 near the axis, and
  b_mn(s) cos mθ is a function of (x, y) continuous with its first derivatives there (the Cartesian
  spline below is C⁴ everywhere; near the axis it departs from the radial formula by about
  b̃_mn(0)·Δx², Δx its grid step).  Not p = m (the analytic axis behaviour) with cubic splines
  throughout: on simsopt's li383 file, whose transform kept 4 surfaces (s = 0.033, 0.1, 0.167,
  0.967), that overshoots the data by 10²–10⁴ between 0.167 and 0.967 (the circular tokamak's 16
  surfaces keep every mode's cubic spline within 1.37 of its data).
  Grouped by toroidal harmonic,

      B = C₀(x, y) + Σ_{n>0} C_n(x, y) cos nζ + S_n(x, y) sin nζ,

  each C_n, S_n evaluated on a Cartesian (x, y) grid covering the boundary circle.  By default
  (``field="3d"``) the sum at ``grid_zeta`` ζ nodes over a field period becomes one spline in
  (x, y, ζ), quintic and periodic in ζ (:mod:`integrators.splines3`, C⁴ as the harmonics' are): one cell
  lookup a point whatever the modes kept.  With ``field="harmonics"`` (and always for a file with
  only n = 0 kept) each C_n, S_n is a quintic tensor spline (:mod:`integrators.splines`) and the
  sum is taken in ζ exactly.  Either way |B| and all its derivatives are evaluated in the compiled
  engine, in lanes.  Modes whose largest |b_mn| over the kept surfaces is below ``modes_tol`` × |b₀₀| are
  left out (``defaults["notes"]`` says how many).  Beyond s = 1 the modes continue with s replaced
  by 1 + tanh(s − 1) (equal to s up to second order at the edge), so the grid's corners stay
  bounded; the domain is s < 1.

The numpy reference of the same |B| (the Fourier sum of the interpolated modes, no Cartesian grid)
is :meth:`Boozer.modB`; :meth:`Boozer.surface_modB` is the file's own Fourier sum on a kept surface.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import sympy

from .splines import Field, Field1, Spline1, Spline2
from .splines3 import Field3, Spline3

REQUIRED = ("nfp_b", "ns_b", "iota_b", "bvco_b", "buco_b", "phi_b", "ixm_b", "ixn_b", "bmnc_b", "jlist")
REFINE = 16                # nodes of the profiles' ψ grid per half-grid interval, over 2
GRID = 96                  # default Cartesian grid of the |B| harmonics, points a side
MARGIN = 0.08              # the Cartesian grid reaches (1 + MARGIN) r₁ past the boundary circle
AXIS_POWER = 2             # b_mn/s^{min(m, 2)/2} is what is interpolated in s (module docstring)
OVERSHOOT = 1.5            # a mode's cubic spline that strays past this × its data is replaced by PCHIP
H_PER_TRANSIT = 320        # default steps per poloidal transit of the default passing orbit
ZETA_PER_HARMONIC = 8      # default nodes of the 3-D field's ζ grid per period, per toroidal harmonic kept
FIELDS = ("3d", "harmonics")   # how |B| is interpolated (system_from_boozer's ``field``)


class BoozerError(ValueError):
    """A boozmn file that cannot be used, in one line naming the file and the problem."""


@dataclass(frozen=True)
class Boozer:
    """A boozmn file's content (read by :func:`read_boozmn`).

    nfp : field periods; ns : VMEC's radial points; asym : not stellarator-symmetric
    s_half : (ns − 1,) VMEC's half grid (j − ½)/(ns − 1), where iota, G, I are given
    iota, G, I : rotational transform, covariant B_ζ (``bvco_b``) and B_θ (``buco_b``) there
    phi_edge : the toroidal flux through the boundary, Φ(s = 1) (``phi_b``'s last value)
    s : (nsurf,) the surfaces the transform kept, (jlist − 1.5)/(ns − 1)
    xm, xn : (mn,) the modes (xn with the field periods); bmnc, bmns : (nsurf, mn), bmns None if
        stellarator-symmetric; rmnc, zmns : the surfaces' shape (R, Z), where the file has them
    minor_radius : (rmax_b − rmin_b)/2 where the file has them (and they differ), else R₀₀/``aspect_b``
        on the outermost kept surface, else NaN
    """

    path: str
    nfp: int
    ns: int
    asym: bool
    s_half: np.ndarray
    iota: np.ndarray
    G: np.ndarray
    I: np.ndarray
    phi_edge: float
    s: np.ndarray
    xm: np.ndarray
    xn: np.ndarray
    bmnc: np.ndarray
    bmns: np.ndarray | None
    rmnc: np.ndarray | None = None
    zmns: np.ndarray | None = None
    minor_radius: float = float("nan")
    _radial: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def psi0(self) -> float:
        """ψ at the boundary: the toroidal flux over 2π, with its sign."""
        return self.phi_edge / (2 * math.pi)

    @property
    def psi_abs(self) -> float:
        """|ψ₀|: the axis chart's (x² + y²)/2 at the boundary."""
        return abs(self.psi0)

    @property
    def sign(self) -> float:
        """The sign σ of Φ: the axis chart's angle atan2(y, x) is σθ."""
        return 1.0 if self.phi_edge > 0 else -1.0

    def surface_modB(self, j, theta, zeta):
        """The file's own Fourier sum Σ b_mn cos(mθ − nζ) (+ b^s sin) on kept surface number j."""
        theta, zeta = np.broadcast_arrays(np.asarray(theta, float), np.asarray(zeta, float))
        ang = self.xm * theta[..., None] - self.xn * zeta[..., None]
        out = np.cos(ang) @ self.bmnc[j]
        if self.bmns is not None:
            out = out + np.sin(ang) @ self.bmns[j]
        return out

    # -- the interpolants ----------------------------------------------------------------------
    def profiles(self):
        """(ι(s), G(s), I(s)/s, ψ_p(s)/ψ₀) as scipy splines in s (ψ_p's from ι's antiderivative,
        0 at the axis)."""
        if "profiles" not in self._radial:
            from scipy.interpolate import make_interp_spline
            k = min(3, self.s_half.size - 1)
            iota = make_interp_spline(self.s_half, self.iota, k=k)
            G = make_interp_spline(self.s_half, self.G, k=k)
            Is = make_interp_spline(self.s_half, self.I / self.s_half, k=k)
            anti = iota.antiderivative()
            at0 = float(anti(0.0))
            self._radial["profiles"] = (iota, G, Is, lambda s: anti(s) - at0)
        return self._radial["profiles"]

    def modes(self, modes_tol=1e-4):
        """The kept modes' indices (every mode whose largest |b_mn| over the kept surfaces is at least
        ``modes_tol`` × that of (0, 0); (0, 0) always), the power p = min(m, 2) of each, and the
        interpolant in s of every kept mode's b_mn(s)/s^{p/2} (:class:`_Radial`; and of the sine
        part, or None)."""
        key = ("modes", float(modes_tol))
        if key not in self._radial:
            size = np.abs(self.bmnc).max(0)
            if self.bmns is not None:
                size = np.maximum(size, np.abs(self.bmns).max(0))
            ref = float(np.abs(self.bmnc[:, (self.xm == 0) & (self.xn == 0)]).max())
            keep = np.flatnonzero((size >= modes_tol * ref) | ((self.xm == 0) & (self.xn == 0)))
            p = np.minimum(self.xm[keep], AXIS_POWER)
            cs = _Radial(self.s, self.bmnc[:, keep], p)
            ss = _Radial(self.s, self.bmns[:, keep], p) if self.bmns is not None else None
            self._radial[key] = (keep, p, cs, ss)
        return self._radial[key]

    def modB(self, s, theta, zeta, modes_tol=1e-4):
        """|B| at (s, θ, ζ) from the interpolated modes (the Fourier sum; the numpy reference of the
        system's Cartesian splines)."""
        keep, p, cs, ss = self.modes(modes_tol)
        s, theta, zeta = np.broadcast_arrays(*(np.asarray(a, float) for a in (s, theta, zeta)))
        m, n = self.xm[keep], self.xn[keep]
        se = _continued(s)
        amp = se[..., None] ** (p / 2.0)
        ang = m * theta[..., None] - n * zeta[..., None]
        out = np.sum(cs(se) * amp * np.cos(ang), -1)
        if ss is not None:
            out = out + np.sum(ss(se) * amp * np.sin(ang), -1)
        return out

    def harmonics(self, x, y, modes_tol=1e-4):
        """{n: (C_n, S_n)} at Cartesian points (x, y) of the axis chart (n ≥ 0 the toroidal harmonic,
        field periods included; S₀ is None): B = Σ_n C_n cos nζ + S_n sin nζ."""
        keep, p, cs, ss = self.modes(modes_tol)
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        s = (x * x + y * y) / (2 * self.psi_abs)
        se = _continued(s)
        th = self.sign * np.arctan2(y, x)
        m, n = self.xm[keep], self.xn[keep]
        amp = se[..., None] ** (p / 2.0)            # 0 on the axis for m > 0
        cm, sm = amp * np.cos(m * th[..., None]), amp * np.sin(m * th[..., None])
        c = cs(se)
        out = {}
        for nn in np.unique(np.abs(n)):
            sel = np.abs(n) == nn
            sgn = np.sign(n[sel])
            C = np.sum(c[..., sel] * cm[..., sel], -1)
            S = np.sum(sgn * c[..., sel] * sm[..., sel], -1)
            if ss is not None:
                d = ss(se)[..., sel]
                C = C + np.sum(d * sm[..., sel], -1)
                S = S - np.sum(sgn * d * cm[..., sel], -1)
            out[int(nn)] = (C, None if nn == 0 else S)
        return out


class _Radial:
    """b(s)/s^{p/2} of every mode (columns of ``b``, given on the kept surfaces ``s``) interpolated in
    s: the not-a-knot cubic spline (C²), or for a mode where that spline strays past OVERSHOOT times
    the mode's largest value on the surfaces (between 2,001 points of [0, 1]), the monotone cubic
    (PCHIP, C¹), which does not; ``__call__(s)`` gives (…, modes)."""

    def __init__(self, s, b, p):
        from scipy.interpolate import PchipInterpolator, make_interp_spline
        f = b / s[:, None] ** (p / 2.0)
        self.cubic = make_interp_spline(s, f, k=min(3, s.size - 1), axis=0)
        self.pchip = PchipInterpolator(s, f, axis=0, extrapolate=True)
        x = np.linspace(0.0, 1.0, 2001)
        stray = np.abs(self.cubic(x) * x[:, None] ** (p / 2.0)).max(0)
        self.monotone = stray > OVERSHOOT * np.maximum(np.abs(b).max(0), 1e-300)

    def __call__(self, s):
        c = self.cubic(s)
        if self.monotone.any():
            c = np.where(self.monotone, self.pchip(s), c)
        return c


def _continued(s):
    """s inside the boundary, 1 + tanh(s − 1) past it (equal to second order at s = 1)."""
    s = np.asarray(s, float)
    return np.where(s <= 1.0, s, 1.0 + np.tanh(s - 1.0))


def _fail(path, msg):
    raise BoozerError(f"{path}: {msg}")


def read_boozmn(path) -> Boozer:
    """A booz_xform ``boozmn`` NetCDF 3 file as a :class:`Boozer` record; a file that cannot be used
    raises :class:`BoozerError` in one line (missing variables, inconsistent sizes, values that are
    not finite, a non-symmetric file without ``bmns_b``)."""
    from scipy.io import netcdf_file
    path = str(path)
    if not Path(path).is_file():
        _fail(path, "no such file")
    try:
        with netcdf_file(path, "r", mmap=False) as nc:
            v = {k: np.array(x.data) for k, x in nc.variables.items()}
    except Exception as err:          # scipy raises TypeError/ValueError/OSError on a non-NetCDF-3 file
        _fail(path, f"not a NetCDF 3 boozmn file ({type(err).__name__}: {err}); NetCDF 4/HDF5 boozmn files "
                    "are not read: convert with `nccopy -k classic`")
    missing = [k for k in REQUIRED if k not in v]
    if missing:
        _fail(path, f"not a boozmn file: no {', '.join(missing)}")
    asym = bool(int(v["lasym__logical__"])) if "lasym__logical__" in v else "bmns_b" in v
    if asym and "bmns_b" not in v:
        _fail(path, "lasym is set but the file has no bmns_b")
    nfp, ns = int(v["nfp_b"]), int(v["ns_b"])
    if nfp < 1 or ns < 3:
        _fail(path, f"nfp_b = {nfp} and ns_b = {ns}: need nfp ≥ 1 and ns ≥ 3")
    prof = {}
    for key in ("iota_b", "bvco_b", "buco_b", "phi_b"):
        a = np.asarray(v[key], np.float64).ravel()
        if a.size != ns:
            _fail(path, f"{key} has {a.size} values for ns_b = {ns}")
        if not np.all(np.isfinite(a)):
            _fail(path, f"{key} has values that are not finite")
        prof[key] = a
    xm, xn = np.asarray(v["ixm_b"], np.int64).ravel(), np.asarray(v["ixn_b"], np.int64).ravel()
    jlist = np.asarray(v["jlist"], np.int64).ravel()
    if xm.size != xn.size or xm.size == 0 or np.any(xm < 0):
        _fail(path, f"ixm_b and ixn_b: {xm.size} and {xn.size} modes (need the same number, m ≥ 0)")
    if not np.any((xm == 0) & (xn == 0)):
        _fail(path, "no (m, n) = (0, 0) mode")
    if jlist.size < 2 or np.any(jlist < 2) or np.any(jlist > ns) or np.any(np.diff(jlist) <= 0):
        _fail(path, f"jlist {jlist.tolist()}: need at least 2 increasing surfaces within 2..ns_b = {ns}")
    arrays = {}
    for key in ("bmnc_b", "bmns_b", "rmnc_b", "zmns_b"):
        if key not in v or (key == "bmns_b" and not asym):
            arrays[key] = None
            continue
        a = np.asarray(v[key], np.float64)
        if a.shape != (jlist.size, xm.size):
            _fail(path, f"{key} has shape {a.shape}, expected ({jlist.size}, {xm.size}) (surfaces, modes)")
        if not np.all(np.isfinite(a)):
            _fail(path, f"{key} has values that are not finite")
        arrays[key] = a
    phi_edge = float(prof["phi_b"][-1])
    if not phi_edge != 0.0:
        _fail(path, f"the toroidal flux phi_b is {phi_edge:g} at the boundary: the axis chart needs Φ ≠ 0")
    s_half = (np.arange(1, ns) - 0.5) / (ns - 1)
    minor = float((v["rmax_b"] - v["rmin_b"]) / 2) if "rmax_b" in v and "rmin_b" in v else float("nan")
    if not minor > 0 and "aspect_b" in v and arrays["rmnc_b"] is not None:
        # booz_xform's Python writer leaves rmax_b = rmin_b = 0: the major radius (R₀₀ on the outermost
        # kept surface) over the aspect ratio instead
        aspect = float(np.asarray(v["aspect_b"]))
        r00 = arrays["rmnc_b"][-1, (xm == 0) & (xn == 0)]
        minor = float(r00[0] / aspect) if r00.size and aspect > 0 else float("nan")
    return Boozer(path=path, nfp=nfp, ns=ns, asym=asym, s_half=s_half, iota=prof["iota_b"][1:],
                  G=prof["bvco_b"][1:], I=prof["buco_b"][1:], phi_edge=phi_edge,
                  s=(jlist - 1.5) / (ns - 1), xm=xm, xn=xn, bmnc=arrays["bmnc_b"], bmns=arrays["bmns_b"],
                  rmnc=arrays["rmnc_b"], zmns=arrays["zmns_b"], minor_radius=minor)


# -- the system ------------------------------------------------------------------------------------

def _psi_grid(bz):
    """The profiles' regular ψ grid: the axis and every half-grid point are nodes; from 3 nodes
    below the axis to past s = 1 + MARGIN."""
    ds = 1.0 / (2 * (bz.ns - 1) * REFINE)
    lo, hi = -3, int(math.ceil((1 + MARGIN) ** 2 * 1.0 / ds)) + 3
    s = np.arange(lo, hi + 1) * ds
    return s


def profile_fields(bz):
    """Quintic splines in ψ (:class:`~integrators.splines.Spline1`) of G, Ĩ = I/(2ψ) and ψ_p."""
    iota, G, Is, psip = bz.profiles()
    s = _psi_grid(bz)
    psi = s * bz.psi_abs           # the chart's (x² + y²)/2 = |ψ|; Ĩ and ψ_p carry ψ's sign
    return [Spline1(psi, np.asarray(vals, float)) for vals in (G(s), Is(s) / (2 * bz.psi0), bz.psi0 * psip(s))]


def harmonic_fields(bz, modes_tol=1e-4, grid=GRID):
    """(the toroidal harmonics n, their Spline2 fields [C₀, C_n₁, S_n₁, …]) on the Cartesian grid."""
    r1 = math.sqrt(2 * bz.psi_abs)
    x = np.linspace(-(1 + MARGIN) * r1, (1 + MARGIN) * r1, grid)
    X, Y = np.meshgrid(x, x, indexing="ij")
    harm = bz.harmonics(X, Y, modes_tol)
    ns, fields = [], []
    for n in sorted(harm):
        C, S = harm[n]
        ns.append(n)
        fields.append(Spline2(x, x, C))
        if n:
            fields.append(Spline2(x, x, S))
    return ns, fields


def field_3d(bz, modes_tol=1e-4, grid=GRID, grid_zeta=None):
    """|B| as one :class:`~integrators.splines3.Spline3` in (x, y, ζ), ζ over one field period:
    the harmonics' sum (:meth:`Boozer.harmonics`) on the Cartesian grid of :func:`harmonic_fields`
    at ``grid_zeta`` ζ nodes (default ZETA_PER_HARMONIC × the largest harmonic per period, at least
    16).  Returns (the harmonics n, the spline, its ζ nodes)."""
    r1 = math.sqrt(2 * bz.psi_abs)
    x = np.linspace(-(1 + MARGIN) * r1, (1 + MARGIN) * r1, grid)
    X, Y = np.meshgrid(x, x, indexing="ij")
    harm = bz.harmonics(X, Y, modes_tol)
    ns = sorted(harm)
    if grid_zeta is None:
        grid_zeta = max(16, ZETA_PER_HARMONIC * (max(ns) // bz.nfp))
    grid_zeta = int(grid_zeta)
    if grid_zeta < 6:
        raise ValueError(f"grid_zeta = {grid_zeta}: the 3-D field needs at least 6 ζ nodes a period")
    zeta = np.arange(grid_zeta) * (2 * np.pi / bz.nfp) / grid_zeta
    values = np.zeros((grid, grid, grid_zeta))
    for n in ns:
        C, S = harm[n]
        values += C[:, :, None] * np.cos(n * zeta)
        if n:
            values += S[:, :, None] * np.sin(n * zeta)
    return ns, Spline3(x, x, 2 * np.pi / bz.nfp, values), grid_zeta


def _symbolic(harmonics, three_d=False):
    """ϑ, H, the domain, the symbols and the B expression; fields 0–2 the profiles (G, Ĩ, ψ_p in ψ),
    then either the 3-D field |B|(x, y, ζ) (``three_d``) or C₀ and (C_n, S_n) for the harmonics n > 0."""
    x, y, zeta, rho = sympy.symbols("x y zeta rho", real=True)
    mu, psi0 = sympy.symbols("mu psi_edge")
    psi = (x**2 + y**2) / 2
    G, It, psip = (Field1(psi, i, 0) for i in range(3))
    if three_d:
        B = Field3(x, y, zeta, 3, 0, 0, 0)
    else:
        B = Field(x, y, 3, 0, 0)
        f = 4
        for n in harmonics:
            if n:
                B = B + Field(x, y, f, 0, 0) * sympy.cos(n * zeta) + Field(x, y, f + 1, 0, 0) * sympy.sin(n * zeta)
                f += 2
    half = sympy.Rational(1, 2) + rho * It
    theta = [-y * half, x * half, rho * G - psip, sympy.Integer(0)]
    H = rho**2 * B**2 / 2 + mu * B
    domain = [1 - psi / psi0]
    return (x, y, zeta, rho), theta, H, domain, B, dict(mu=mu, psi_edge=psi0)


def system_from_boozer(path, mu=None, modes_tol=1e-4, grid=GRID, name=None, field="3d", grid_zeta=None):
    """The guiding centre in the Boozer field of a boozmn file (module docstring): a
    :class:`~integrators.systems.System` with q = (x, y, ζ, ρ) (the axis chart), parameters ``mu``
    and ``psi_edge`` (ψ₀), symmetry ∂/∂ζ where only n = 0 is kept (an axisymmetric file: P_ζ =
    ρG − ψ_p is conserved).

    mu : the magnetic moment (default v²/(4|B₀₀(axis)|), v = a|B|/100 the reference speed, a the
        file's minor radius: a Larmor radius of 1 % of it)
    modes_tol : modes below this fraction of |b₀₀| are left out (0 keeps all)
    grid : points a side of the Cartesian grid of |B|
    field : ``"3d"`` (default) |B| as one quintic spline in (x, y, ζ), periodic in ζ
        (:func:`field_3d`, :mod:`integrators.splines3`), whose cost
        does not grow with the modes kept; ``"harmonics"`` a quintic (x, y) spline per toroidal
        harmonic, summed with cos nζ, sin nζ (exact in ζ, C⁴; its cost grows with the harmonics).
        A file with only n = 0 kept (axisymmetric) always takes the harmonics' form: one (x, y)
        spline, so ∂H/∂ζ is exactly 0 and P_ζ is conserved to round-off.
    grid_zeta : ζ nodes a field period of the 3-D field (default :func:`field_3d`'s)

    ``defaults``: ``q0`` (a passing guiding centre at s = 0.3, θ = ζ = 0, v∥ = max(v/√2, 1.5 v_c)
    with v_c the trapped-passing boundary on that surface), ``trapped`` (v∥ = v_c/3), ``h`` (1/320
    of the passing orbit's poloidal transit 2π R₀/(ι |v∥|)), ``speed``, ``boozer`` (the path),
    ``notes``."""
    if field not in FIELDS:
        raise ValueError(f"field = {field!r}: one of {', '.join(map(repr, FIELDS))}")
    bz = read_boozmn(path)
    keep = bz.modes(modes_tol)[0]
    ns = sorted(int(n) for n in np.unique(np.abs(bz.xn[keep])))
    three_d = field == "3d" and ns != [0]
    if three_d:
        ns, f3, grid_zeta = field_3d(bz, modes_tol, grid, grid_zeta)
        hfields = [f3]
    else:
        ns, hfields = harmonic_fields(bz, modes_tol, grid)
    fields = profile_fields(bz) + hfields
    (x, y, zeta, rho), theta, H, domain, B, sym = _symbolic(ns, three_d)
    B00 = bz.modB(1e-12, 0.0, 0.0, modes_tol)
    Baxis = abs(float(B00))
    a = bz.minor_radius if math.isfinite(bz.minor_radius) else math.sqrt(2 * abs(bz.psi0) / max(Baxis, 1e-300))
    v = a * Baxis / 100
    if mu is None:
        mu = v**2 / (4 * Baxis)
    mu = float(mu)
    if not math.isfinite(mu):
        raise BoozerError(f"{path}: mu = {mu!r} is not finite")
    from .systems import System
    params = {sym["mu"]: mu, sym["psi_edge"]: bz.psi_abs}
    system = System(name or f"boozer:{Path(path).stem}", [x, y, zeta, rho], theta, H, params,
                    symmetry=[0, 0, 1, 0] if ns == [0] else None,
                    momentum_name="toroidal momentum P_ζ" if ns == [0] else None, domain=domain,
                    defaults={}, fields=fields, source=str(path))
    s0 = 0.3
    th = np.linspace(0, 2 * np.pi, 721)
    ze = np.linspace(0, 2 * np.pi / bz.nfp, 181)
    TT, ZZ = np.meshgrid(th, ze, indexing="ij")
    Bs = bz.modB(np.full(TT.shape, s0), TT, ZZ, modes_tol)
    B0 = float(bz.modB(s0, 0.0, 0.0, modes_tol))
    u_c = math.sqrt(max(2 * mu * (float(Bs.max()) - B0), 0.0))
    u_pass = max(v / math.sqrt(2), 1.5 * u_c)
    r = math.sqrt(2 * s0 * abs(bz.psi0))
    iota = float(bz.profiles()[0](s0))
    G0 = float(bz.profiles()[1](s0))
    R0 = abs(G0 / B0)                      # G ≈ R B: the major radius the transit takes
    h = 2 * math.pi * R0 / max(abs(iota), 1e-3) / u_pass / H_PER_TRANSIT
    grid_text = (f"one quintic spline in (x, y, ζ) on {grid} × {grid} × {grid_zeta} nodes a field period" if three_d
                 else f"a quintic spline a harmonic on a {grid} × {grid} grid")
    notes = (f"{bz.xm.size} modes in the file, {keep.size} kept (|b_mn| ≥ {modes_tol:g} |b_00|), "
             f"{len(ns)} toroidal harmonics; |B| as {grid_text}",
             "White's guiding centre with K = 0 (the covariant B_ψ is not kept)",
             f"ψ = s ψ₀, ψ₀ = Φ_edge/2π = {bz.psi0:.6g}; the file's sign of ι ({'+' if iota >= 0 else '−'}) and of G, I")
    system.defaults.update({"q0": [r, 0.0, 0.0, u_pass / B0], "trapped": [r, 0.0, 0.0, (u_c / 3 if u_c else 0.15 * v) / B0],
                            "h": float(f"{h:.2g}"), "speed": v, "u_boundary": u_c, "boozer": str(path),
                            "harmonics": tuple(ns), "field": "3d" if three_d else "harmonics",
                            "grid_zeta": grid_zeta if three_d else None, "notes": notes})
    system.boozer = bz
    return system


def field_line_system(path_or_boozer, name=None):
    """The field lines of a Boozer file as a 1-D Hamiltonian system in the axis chart: q = (x, y),
    ϑ = (−y/2, x/2) (ψ dθ), H = ψ_p(ψ), time ζ: θ advances at dθ/dζ = ι(ψ), so the winding of an
    orbit over ζ is the field's ι (the model's ψ_p, the same field as :func:`system_from_boozer`'s)."""
    from .systems import System
    bz = path_or_boozer if isinstance(path_or_boozer, Boozer) else read_boozmn(path_or_boozer)
    x, y = sympy.symbols("x y", real=True)
    psi0 = sympy.Symbol("psi_edge")
    psi = (x**2 + y**2) / 2
    fields = profile_fields(bz)
    H = Field1(psi, 2, 0)
    return System(name or f"field_lines:{Path(bz.path).stem}", [x, y], [-y / 2, x / 2], H, {psi0: bz.psi_abs},
                  domain=[1 - psi / psi0], defaults={}, fields=fields, source=bz.path)
