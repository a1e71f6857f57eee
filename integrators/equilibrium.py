"""Guiding centres in a tokamak equilibrium read from a G-EQDSK file.

:func:`system_from_geqdsk` turns a G-EQDSK file (EFIT, CHEASE, FreeGS, TokaMaker … write them: the
poloidal flux ψ(R, Z) on a grid, F(ψ) = R B_φ on a grid in ψ, the boundary) into a
:class:`~integrators.systems.System` with the guiding-centre Lagrangian of app:guiding_centre_dynamics,

    q = (R, Z, φ, u),   ϑ = A + u b,   H = u²/2 + μ|B|,   B = ∇ × A,

in the coordinates of the project's other tokamak systems ((R, Z, φ) right-handed, metric
diag(1, 1, R²), covariant components).  The file is read by ``freeqdsk`` (PyPI); its sign
conventions are those of the COCOS index given (Sauter & Medvedev, Comput. Phys. Commun. 184
(2013) 293), COCOS 3 by default, and a file that contradicts them is refused in one line.

**The field.**  In COCOS form B = F(ψ)∇φ + σ_Bp ∇φ × ∇ψ/(2π)^e_Bp.  With ψ̃ = (ψ − ψ_axis)/(2π)^e_Bp and
s = −σ_RφZ (the COCOS toroidal direction against ours), a vector potential is

    A_R = −s G_Z(R, Z)/(2R),   A_Z = s G_R(R, Z)/2,   A_φ = −σ_Bp s ψ̃(R, Z),
    G_Z = ∫_{Z_axis}^{Z} F(ψ(R, Z')) dZ',   G_R = ∫_{R_axis}^{R} F(ψ(R', Z))/R' dR',

a gauge smooth on the whole grid, for any F(ψ), which for constant F and a Solov'ev ψ is the gauge of
``guiding_centre_solovev`` exactly.  ψ̃, G_Z and G_R are quintic tensor splines on the file's grid
(:mod:`integrators.splines`; G_Z and G_R from 8-point Gauss–Legendre quadrature of F∘ψ cell by cell,
F the quintic interpolating spline of the file's F(ψ), continued past the axis and boundary values
by its cubic Taylor polynomial there), and B is the exact curl of that A: divergence-free, and every
derivative the engine takes is exact for the interpolant.

**The domain.**  The box of the last closed flux surface (the file's boundary points, within the
grid) and ψ_N < 1: a guiding centre that leaves the plasma breaks down cleanly (kernel's domain test)
instead of using extrapolated field.

**Checks** (each a one-line :class:`EquilibriumError`): the file parses and has a grid of at least
6 × 6 points with finite ψ and F; ψ rises or falls from the axis to the boundary as COCOS's σ_Bp
says it does for the file's plasma current; F has the sign of the file's B₀; and the safety factor
q computed from this field on the ψ_N = 0.5 surface agrees with the file's |q(0.5)| to 5 % (a wrong
2π normalisation of ψ, COCOS 1–8 against 11–18, is off by a factor 6.3).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sympy

from .splines import Field, Spline2

DEFAULT_COCOS = 3


class EquilibriumError(ValueError):
    """An equilibrium file that cannot be used: one line naming the file and the problem."""


def cocos_signs(cocos: int):
    """(e_Bp, σ_Bp, σ_RφZ, σ_ρθφ) of a COCOS index (1–8, 11–18), Sauter & Medvedev (2013), Table I."""
    if cocos not in (*range(1, 9), *range(11, 19)):
        raise EquilibriumError(f"cocos = {cocos!r}: COCOS indices are 1-8 and 11-18")
    base = cocos % 10
    e_bp = 1 if cocos >= 11 else 0
    sigma_bp = 1 if base in (1, 2, 5, 6) else -1
    sigma_rphiz = 1 if base % 2 else -1
    sigma_rhothetaphi = 1 if base in (1, 2, 7, 8) else -1
    return e_bp, sigma_bp, sigma_rphiz, sigma_rhothetaphi


@dataclass
class Equilibrium:
    """What the system needs from a G-EQDSK file, checked: the grid, ψ̃ = (ψ − ψ_axis)/(2π)^e_Bp on it
    (per radian, zero on the axis), F on the uniform ψ_N grid, the axis, the boundary box."""
    path: str
    cocos: int
    R: np.ndarray
    Z: np.ndarray
    psi: np.ndarray          # ψ̃ on the grid, [i, j] at (R[i], Z[j])
    psi_span: float          # ψ̃ at the boundary (ψ̃ is 0 on the axis)
    F: np.ndarray            # F(ψ_N) at ψ_N = linspace(0, 1, len(F))
    axis: tuple
    box: tuple               # (R_min, R_max, Z_min, Z_max) of the boundary, within the grid
    q: np.ndarray            # the file's q(ψ_N) (may be empty)
    current: float
    B0: float
    R0: float
    notes: tuple = ()        # what the reader identified or trusted, and why (one sentence each)
    given: bool = False      # the COCOS was given (cocos=...), not identified

    def where(self):
        return Path(self.path).name


def _fail(path, msg):
    raise EquilibriumError(f"{Path(path).name}: {msg}")


def identify_cocos(dpsi, current, field, q):
    """The COCOS a G-EQDSK file's own signs say, as Sauter & Medvedev (2013) sec. 5 identify it, but
    for the 2π of ψ (e_Bp), which the q check decides (:func:`system_from_geqdsk`): ``(base, reasons)``,
    base ∈ {1, 3, 5, 7}, reasons one clause per sign.

    σ_Bp = sign(ψ_boundary − ψ_axis)·sign(I_p);  σ_ρθφ = sign(q)·sign(I_p)·sign(B₀) with B₀'s sign
    that of F (where the file has no q, σ_ρθφ = σ_Bp is assumed: it does not enter the field);
    σ_RφZ = +1 ((R, φ, Z) right-handed) is assumed: no G-EQDSK quantity shows it."""
    s_bp = 1 if (dpsi > 0) == (current > 0) else -1
    why = [f"σ_Bp = {s_bp:+d}: ψ {'rises' if dpsi > 0 else 'falls'} from the axis to the boundary with I_p "
           f"{'> 0' if current > 0 else '< 0'}"]
    qs = q[np.isfinite(q) & (q != 0)] if q.size else q
    if qs.size and (np.all(qs > 0) or np.all(qs < 0)):
        s_rtp = int(np.sign(qs[0]) * np.sign(current) * np.sign(field))
        why.append(f"σ_ρθφ = {s_rtp:+d}: q {'> 0' if qs[0] > 0 else '< 0'} with I_p·B₀ "
                   f"{'> 0' if current * field > 0 else '< 0'}")
    else:
        s_rtp = s_bp
        why.append(f"σ_ρθφ = {s_rtp:+d} assumed (no q of one sign; it does not enter the field)")
    why.append("σ_RφZ = +1 assumed ((R, φ, Z) right-handed: no G-EQDSK quantity shows it; "
               "say cocos = N + 1 for the even index)")
    base = {(1, 1): 1, (-1, -1): 3, (1, -1): 5, (-1, 1): 7}[(s_bp, s_rtp)]
    return base, why


def read_geqdsk(path, cocos: int | None = None, e_bp: int | None = None) -> Equilibrium:
    """The checked contents of a G-EQDSK file (see the module's docstring for the checks).

    cocos : the file's COCOS index, or None to identify it from the file (:func:`identify_cocos`;
        ψ per radian, e_Bp = 0, unless ``e_bp`` = 1 says ψ is the total flux)."""
    from freeqdsk import geqdsk
    if cocos is not None:
        cocos_signs(cocos)
    path = str(path)
    p = Path(path)
    if not p.is_file():
        _fail(path, "no such file" if not p.exists() else "not a regular file")
    try:
        with open(path) as fh:
            import warnings
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                g = geqdsk.read(fh, data_fmt=_data_format(path))
    except UnicodeDecodeError:
        _fail(path, "not a G-EQDSK file (not text)")
    except Exception as exc:           # freeqdsk's own parse errors: one line
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        _fail(path, f"not a readable G-EQDSK file ({type(exc).__name__}: {msg[:160]})")
    nx, ny = int(g.nx), int(g.ny)
    psi = np.asarray(g.psi, dtype=float)
    fpol = np.asarray(g.fpol, dtype=float)
    if nx < 6 or ny < 6:
        _fail(path, f"a {nx} x {ny} grid: quintic splines need at least 6 x 6 points")
    if psi.shape != (nx, ny) or fpol.shape != (nx,):
        _fail(path, f"ψ has shape {psi.shape} and F {fpol.shape} for a {nx} x {ny} grid")
    for name, x in (("ψ(R, Z)", psi), ("F(ψ)", fpol)):
        if not np.all(np.isfinite(x)):
            _fail(path, f"{name} has values that are not finite")
    scalars = dict(rdim=g.rdim, zdim=g.zdim, rleft=g.rleft, zmid=g.zmid, rmagx=g.rmagx, zmagx=g.zmagx,
                   simagx=g.simagx, sibdry=g.sibdry, bcentr=g.bcentr, cpasma=g.cpasma, rcentr=g.rcentr)
    for k, v in scalars.items():
        if not math.isfinite(float(v)):
            _fail(path, f"{k} = {v} is not finite")
    if g.rdim <= 0 or g.zdim <= 0 or g.rleft <= 0:
        _fail(path, f"the grid R ∈ [{g.rleft}, {g.rleft + g.rdim}] m, height {g.zdim} m is not a grid at R > 0")
    R = g.rleft + np.linspace(0.0, g.rdim, nx)
    Z = g.zmid - g.zdim / 2 + np.linspace(0.0, g.zdim, ny)
    if not (R[0] < g.rmagx < R[-1] and Z[0] < g.zmagx < Z[-1]):
        _fail(path, f"the magnetic axis ({g.rmagx:g}, {g.zmagx:g}) m is outside the grid")
    dpsi = float(g.sibdry - g.simagx)
    if dpsi == 0.0:
        _fail(path, "ψ on the boundary equals ψ on the axis")
    if np.any(fpol == 0) or not (np.all(fpol > 0) or np.all(fpol < 0)):
        _fail(path, "F(ψ) = R B_φ changes sign or is zero: a toroidal field through zero is not a tokamak's")
    field = float(np.sign(fpol[0]))
    notes = []
    if np.sign(g.bcentr) != field:         # the profiles make the field; the header's scalar is a summary
        notes.append(f"the header's B₀ = {g.bcentr:+.4g} T {'is zero' if g.bcentr == 0 else 'has the opposite sign'}"
                     f" to F(ψ) ({'> 0' if field > 0 else '< 0'}), which sets the field: F is trusted, the header's "
                     "B₀ is not used")
    q = np.asarray(g.qpsi, dtype=float) if g.qpsi is not None else np.zeros(0)
    if not np.any(q) or not np.all(np.isfinite(q)):
        q = np.zeros(0)                  # a file without q (all zeros): nothing to check it against
    cocos, first = _conventions(path, cocos, e_bp, dpsi, float(g.cpasma), field, q)
    given = not first.startswith("COCOS")
    notes = ([first] if first else []) + notes
    e, sigma_bp, _, _ = cocos_signs(cocos)
    scale = (2 * math.pi) ** e
    box = (float(R[0]), float(R[-1]), float(Z[0]), float(Z[-1]))
    rb, zb = np.asarray(g.rbdry if g.rbdry is not None else []), np.asarray(g.zbdry if g.zbdry is not None else [])
    if rb.size >= 3 and zb.size == rb.size and np.all(np.isfinite(rb)) and np.all(np.isfinite(zb)):
        box = (max(box[0], float(rb.min())), min(box[1], float(rb.max())),
               max(box[2], float(zb.min())), min(box[3], float(zb.max())))
    return Equilibrium(path=path, cocos=cocos, R=R, Z=Z, psi=(psi - g.simagx) / scale, psi_span=dpsi / scale,
                       F=fpol, axis=(float(g.rmagx), float(g.zmagx)), box=box, q=q, current=float(g.cpasma),
                       B0=float(g.bcentr), R0=float(g.rcentr), notes=tuple(notes), given=given)


def _conventions(path, cocos, e_bp, dpsi, current, field, q):
    """(the COCOS to use, the note that says why: '' where a given index agrees with the file)."""
    if cocos is None:
        if current == 0.0:
            _fail(path, "I_p = 0 in the header: the COCOS cannot be identified without the current's sign; "
                        "give system.cocos (cocos=...)")
        base, why = identify_cocos(dpsi, current, field, q)
        cocos = base + 10 * int(e_bp or 0)
        return cocos, f"COCOS {cocos} identified from the file: " + "; ".join(why)
    if current == 0.0:
        return cocos, ""
    base, why = identify_cocos(dpsi, current, field, q)
    if cocos_signs(cocos)[1] != cocos_signs(base)[1]:
        return cocos, (f"cocos = {cocos} was given and is used, though the file's own signs say COCOS {base} or "
                       f"{base + 10} ({why[0]}): the poloidal field is the reverse of what the file's current implies")
    return cocos, ""


def _data_format(path):
    """The Fortran format of the file's numbers: G-EQDSK's (5e16.9), or as wide as the first data
    line says (5 numbers a line: a file written with more digits, as :func:`write_solovev` does,
    is read with all of them)."""
    with open(path) as fh:
        fh.readline()
        line = fh.readline().rstrip("\r\n")
    w = len(line) // 5
    if len(line) % 5 or w == 16 or not 10 <= w <= 40:
        return None
    return f"(5e{w}.{w - 7})"


# -- F(ψ) and the toroidal-field potentials ---------------------------------------------------------

class _Fpsi:
    """F as a function of ψ_N: the quintic interpolating spline of the file's values, continued past
    0 and 1 by its cubic Taylor polynomial there (C³, so the potentials stay smooth off the plasma)."""

    def __init__(self, F):
        from scipy.interpolate import make_interp_spline
        x = np.linspace(0.0, 1.0, F.size)
        self.spline = make_interp_spline(x, F, k=5) if F.size >= 6 else make_interp_spline(x, F, k=min(3, F.size - 1))
        self.ends = [(e, [float(self.spline(e, nu=m)) for m in range(4)]) for e in (0.0, 1.0)]

    def __call__(self, x):
        x = np.asarray(x, dtype=float)
        out = self.spline(np.clip(x, 0.0, 1.0))
        for e, d in self.ends:
            far = (x < 0.0) if e == 0.0 else (x > 1.0)
            t = x[far] - e
            out[far] = d[0] + t * (d[1] + t * (d[2] / 2 + t * d[3] / 6))
        return out


_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)


def _integrals(grid, start, f_at):
    """∫_start^{grid[j]} f dx for every node j: f_at(points) evaluates the integrand at an array of
    abscissae (shape (..., m) → (..., m)); 8-point Gauss–Legendre on each cell, the cell holding
    ``start`` split there."""
    n = grid.size
    ja = int(np.clip(np.searchsorted(grid, start) - 1, 0, n - 2))

    def gl(a, b):                        # ∫_a^b over intervals (arrays a, b)
        a, b = np.asarray(a, float), np.asarray(b, float)
        x = (a + b)[..., None] / 2 + (b - a)[..., None] / 2 * _GL_X
        return (f_at(x) * _GL_W).sum(-1) * (b - a) / 2

    cells = gl(grid[:-1], grid[1:])                      # (..., n − 1)
    out = np.zeros(cells.shape[:-1] + (n,))
    right = gl(np.full(1, start), np.full(1, grid[ja + 1]))[..., 0]
    left = gl(np.full(1, grid[ja]), np.full(1, start))[..., 0]
    out[..., ja + 1] = right
    for j in range(ja + 2, n):
        out[..., j] = out[..., j - 1] + cells[..., j - 1]
    out[..., ja] = -left
    for j in range(ja - 1, -1, -1):
        out[..., j] = out[..., j + 1] - cells[..., j]
    return out


def fields_of(eq: Equilibrium):
    """The three splines of the system: ψ̃, G_Z, G_R (see the module's docstring)."""
    psi = Spline2(eq.R, eq.Z, eq.psi)
    F = _Fpsi(eq.F)
    Ra, Za = eq.axis
    R, Z = eq.R, eq.Z

    def along_Z(zs):                     # zs: (nZcells, m) → F(ψ_N(R_i, zs)) for every R_i: (nR, nZcells, m)
        Rb = np.broadcast_to(R[:, None, None], (R.size,) + zs.shape)
        Zb = np.broadcast_to(zs[None], (R.size,) + zs.shape)
        return F(psi(Rb, Zb) / eq.psi_span)

    def along_R(rs):
        Rb = np.broadcast_to(rs[None], (Z.size,) + rs.shape)
        Zb = np.broadcast_to(Z[:, None, None], (Z.size,) + rs.shape)
        return F(psi(Rb, Zb) / eq.psi_span) / Rb

    GZ = _integrals(Z, Za, along_Z)                      # (nR, nZ)
    GR = _integrals(R, Ra, along_R).T                    # (nZ, nR) → (nR, nZ)
    return psi, Spline2(R, Z, GZ), Spline2(R, Z, GR)


# -- the system ---------------------------------------------------------------------------------------

def _symbolic():
    """ϑ, H, the domain and the symbols of the guiding centre in a spline equilibrium (fields 0, 1, 2:
    ψ̃, G_Z, G_R); every equilibrium shares these expressions, so one compiled module serves all."""
    R, Z, phi, u = sympy.symbols("R Z phi u", real=True)
    mu, s_phi, s_bp, span, Rlo, Rhi, Zlo, Zhi = sympy.symbols("mu sign_phi sign_Bp psi_span R_min R_max Z_min Z_max")
    psi, GZ, GR = (Field(R, Z, i, 0, 0) for i in range(3))
    A = [-s_phi * GZ / (2 * R), s_phi * GR / 2, -s_bp * s_phi * psi]
    B_cov = [sympy.diff(A[2], Z) / R, -sympy.diff(A[2], R) / R,
             R * (sympy.diff(A[1], R) - sympy.diff(A[0], Z))]     # B_R = B^R, B_Z = B^Z, B_φ = R² B^φ
    absB = sympy.sqrt(B_cov[0] ** 2 + B_cov[1] ** 2 + B_cov[2] ** 2 / R**2)
    theta = [A[i] + u * B_cov[i] / absB for i in range(3)] + [sympy.Integer(0)]
    H = u**2 / 2 + mu * absB
    domain = [R - Rlo, Rhi - R, Z - Zlo, Zhi - Z, 1 - psi / span]
    return (R, Z, phi, u), theta, H, domain, dict(mu=mu, sign_phi=s_phi, sign_Bp=s_bp, psi_span=span, R_min=Rlo,
                                                  R_max=Rhi, Z_min=Zlo, Z_max=Zhi)


def safety_factor(system, psi_n=0.5, points=4000):
    """|q| on the flux surface ψ_N = ``psi_n`` of a G-EQDSK system, from its own field: the surface
    through the outboard midplane, followed by its poloidal field, q = (1/2π) ∮ |B_φ|/(R B_p) dl."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq
    from .splines import field_np
    k = system.param_vector()
    P = len(system.params)
    par = system.param_values
    Ra, Za = system.defaults["axis"]

    def derivs(R, Z):
        f = [field_np(k, s, np.asarray(R, float), np.asarray(Z, float), P) for s in range(3)]
        return f

    def psin(R):
        return float(derivs(R, Za)[0][0]) / par["psi_span"] - psi_n

    Rout = brentq(psin, Ra + 1e-6 * (par["R_max"] - Ra), par["R_max"])

    def field(R, Z):
        f0, f1, f2 = derivs(R, Z)
        s, sb = par["sign_phi"], par["sign_Bp"]
        BR = -sb * s * f0[2] / R
        BZ = sb * s * f0[1] / R
        Bphi = s * f2[1] / 2 + s * f1[2] / (2 * R)      # physical B_φ = ∂_R A_Z − ∂_Z A_R
        return BR, BZ, Bphi

    def rhs(t, y):
        BR, BZ, Bphi = field(y[0], y[1])
        Bp = math.hypot(BR, BZ)
        return [BR / Bp, BZ / Bp, abs(Bphi) / (y[0] * Bp)]

    BR, BZ, _ = field(Rout, Za)
    sgn = float(np.sign(BZ))
    tmin = 0.1 * (Rout - Ra)

    def back(t, y):                      # crossing the midplane again, on the outboard side (the
        d = y[1] - Za                    # inboard crossing goes the other way; near the start the
        return d if t > tmin else sgn * (abs(d) + 1e-12)    # guard keeps the start's sign)
    back.terminal = True
    back.direction = sgn
    sol = solve_ivp(rhs, (0.0, 100.0), [Rout, Za, 0.0], events=back, rtol=1e-10, atol=1e-12, max_step=0.01)
    if not sol.t_events[0].size:
        return float("nan")
    return float(sol.y_events[0][0][2] / (2 * math.pi))


def system_from_geqdsk(path, mu=None, cocos: int | None = None, check_q=True, name=None):
    """The guiding centre in the equilibrium of a G-EQDSK file (module docstring): a
    :class:`~integrators.systems.System` with q = (R, Z, φ, u), parameter ``mu`` (and the file's
    derived constants as parameters: sign_phi, sign_Bp, psi_span and the domain's box), symmetry
    ∂/∂φ (the toroidal momentum ϑ_φ is conserved).

    cocos : the file's COCOS index, or None (the default) to identify it from the file: the signs
        of ψ's rise, I_p, F and q (:func:`identify_cocos`), and the 2π of ψ (e_Bp) from the q check
        (this field's |q(ψ_N = 0.5)| against the file's: a ratio 1 means ψ per radian, 1/2π total
        flux).  A given index overrules the signs (with a note where the file's own signs differ);
        a q check that fails under a given index is refused.  ``defaults["cocos"]`` is the index
        used and ``defaults["notes"]`` says how it was found and what the reader trusted.

    Units are the file's (m, T) with charge/mass 1, so speeds set the orbits' width: a speed v has
    Larmor radius v/|B|.  The defaults are scaled to the plasma: the reference speed
    v = a|B_axis|/100 (a the boundary's half-width; a Larmor radius of 1 % of a), ``mu`` =
    v²/(4|B_axis|) when not given, and ``defaults`` holds ``q0`` (a passing guiding centre on the
    outboard midplane at ψ_N ≈ 0.3, u = max(v/√2, 1.5u_c) with u_c the trapped-passing boundary there,
    ``u_boundary``), ``trapped`` (the same place, u = u_c/3), ``h`` (:func:`_default_h`), ``axis``,
    ``speed`` (v) and ``equilibrium`` (the path)."""
    eq = read_geqdsk(path, cocos)
    system = _system_of(eq, path, mu, name)
    notes = list(eq.notes)
    if check_q and eq.q.size:
        qfile = float(np.interp(0.5, np.linspace(0, 1, eq.q.size), np.abs(eq.q)))
        qhere = safety_factor(system, 0.5)
        ratio = qhere / qfile
        if not eq.given and math.isfinite(ratio) and abs(ratio * 2 * math.pi - 1) < 0.05:
            eq = read_geqdsk(path, None, e_bp=1)             # ψ is the total flux: COCOS 11-18
            notes = list(eq.notes)
            system = _system_of(eq, path, mu, name)
            qhere = safety_factor(system, 0.5)
            ratio = qhere / qfile
        if not (math.isfinite(ratio) and abs(ratio - 1) < 0.05):
            how = "as given (cocos = ...)" if eq.given else "as identified"
            _fail(path, f"q at ψ_N = 0.5 is {qhere:.4g} from the field with COCOS {eq.cocos} {how} and {qfile:.4g} "
                        f"in the file (ratio {ratio:.3g}; 2π or 1/2π means ψ's normalisation, COCOS 1-8 against "
                        "11-18): give system.cocos, or check the file")
        system.defaults["q_check"] = (qhere, qfile)
        if not eq.given:
            notes[0] += (f"; e_Bp = {eq.cocos // 10}: this field's |q(ψ_N = 0.5)| {qhere:.4g} matches the file's "
                         f"{qfile:.4g} with ψ {'per radian' if eq.cocos < 10 else 'the total flux'}")
    elif not eq.given:
        notes[0] += "; e_Bp = 0 assumed (ψ per radian): the file has no q to check the 2π against"
    system.defaults["cocos"] = eq.cocos
    system.defaults["notes"] = tuple(notes)
    return system


def _system_of(eq, path, mu, name):
    """The System of a read equilibrium (:func:`system_from_geqdsk` without the q check)."""
    from .systems import System
    _, sigma_bp, sigma_rphiz, _ = cocos_signs(eq.cocos)
    fields = fields_of(eq)
    (R, Z, phi, u), theta, H, domain, sym = _symbolic()
    Ra, Za = eq.axis
    Baxis = abs(float(fields[2](Ra, Za, 1, 0)) / 2 + float(fields[1](Ra, Za, 0, 1)) / (2 * Ra))   # |B_φ| on axis
    v = (eq.box[1] - eq.box[0]) / 2 * Baxis / 100
    if mu is None:
        mu = v**2 / (4 * Baxis)
    values = dict(mu=float(mu), sign_phi=float(-sigma_rphiz), sign_Bp=float(sigma_bp), psi_span=eq.psi_span,
                  R_min=eq.box[0], R_max=eq.box[1], Z_min=eq.box[2], Z_max=eq.box[3])
    if not math.isfinite(values["mu"]):
        raise EquilibriumError(f"{eq.where()}: mu = {mu!r} is not finite")
    params = {sym[k]: v for k, v in values.items()}
    R03 = _midplane(fields[0], eq, 0.3)
    system = System(name or f"equilibrium:{Path(path).stem}", [R, Z, phi, u], theta, H, params,
                    symmetry=[0, 0, 1, 0], momentum_name="toroidal momentum", domain=domain, defaults={},
                    fields=fields, source=str(path))
    # the trapped-passing boundary where the orbits start: u_c² = 2μ(B_max − B), B_max on the inboard
    # midplane of the same flux surface; the default orbits keep well away from it on either side
    # (near it the orbits' periods differ strongly and shear any set out of resolution)
    B = lambda RR: float(system.H(np.array([RR, Za, 0.0, 0.0]))) / values["mu"] if values["mu"] else 0.0
    Bmax = B(_midplane(fields[0], eq, 0.3, outboard=False))
    u_c = math.sqrt(max(2 * values["mu"] * (Bmax - B(R03)), 0.0))
    u_pass = max(v / math.sqrt(2), 1.5 * u_c)
    system.defaults.update({"q0": [R03, Za, 0.0, u_pass], "trapped": [R03, Za, 0.0, u_c / 3 if u_c else 0.15 * v],
                            "h": _default_h(eq, R03, u_pass), "axis": (Ra, Za), "speed": v, "u_boundary": u_c,
                            "equilibrium": str(path)})
    return system


def _midplane(psi, eq, psi_n, outboard=True):
    """R on the outboard (or inboard) midplane, at the axis's Z, where ψ_N = psi_n (the grid's
    first point of 400 from the axis to the box's edge past it)."""
    Ra, Za = eq.axis
    Rs = np.linspace(Ra, eq.box[1] if outboard else eq.box[0], 400)
    pn = psi(Rs, np.full_like(Rs, Za)) / eq.psi_span
    i = int(np.argmax(pn >= psi_n)) if np.any(pn >= psi_n) else Rs.size - 1
    return float(Rs[i])


H_PER_TRANSIT = 320         # default steps per poloidal transit of the default passing orbit


def _default_h(eq, R, u, psi_n=0.3):
    """A step of 1/H_PER_TRANSIT (1/320) of the default passing orbit's poloidal transit time
    2π q R/|u|, its fastest time scale (a trapped orbit's bounce is slower, the drifts slower
    still), with q the file's |q| where the orbit starts (ψ_N = ``psi_n``; 1 without a q profile),
    rounded to two significant digits: 1,000 steps are three transits.  1/40 at q(0.5) broke points
    down within 3 steps in STEP's file (h = 140); at 1/80 its sample sets, even of a/5000, mixed out of
    resolution by the fourth transit whatever their size (a spread of transit frequencies across
    them, partly the method's phase error: a quarter of the step spread them a fifth as far).  With
    1/320 the default scenes of the five files in docs/equilibria.md run ok."""
    q = float(np.interp(psi_n, np.linspace(0, 1, eq.q.size), np.abs(eq.q))) if eq.q.size else 1.0
    h = 2 * math.pi * q * R / abs(u) / H_PER_TRANSIT
    return float(f"{h:.2g}")


def write_solovev(path, n=65, R0=2.0, B0=5.0, q0=2.0, kappa=1.6, a=0.5, cocos: int = DEFAULT_COCOS, nbdry=128,
                  digits=17, q=None, current=1, field=1, header_B0=None):
    """Write the Solov'ev equilibrium of ``guiding_centre_solovev`` (the same R0, B0, q0, κ) as a
    G-EQDSK file on an n × n grid: the box R ∈ [R0 − 1.3a, R0 + 1.3a], |Z| ≤ 1.3κa, the boundary the flux
    surface through (R0 + a, 0), F = B₀R₀ (constant), written in the signs of COCOS ``cocos`` so that
    :func:`system_from_geqdsk` with that COCOS gives the analytic system's field (and its gauge: the axis
    is (R0, 0)).  ``digits``: significant digits of every number (G-EQDSK's own format has 9, which is
    the field's precision then; 17, the default, keeps every double, in a wider format that
    :func:`read_geqdsk` recognises).  Used by the tests and docs/equilibria.md.

    For the COCOS tests: ``current`` and ``field`` (±1) reverse the plasma current (ψ's rise, so
    B_p) and the toroidal field (F, B₀) of the physical equilibrium; ``q`` (a number) writes a flat
    q profile of that magnitude with the sign COCOS gives it, σ_Ip σ_B0 σ_ρθφ (None: zeros, not
    checked); ``header_B0`` writes that B₀ in the header whatever F says (an inconsistent header)."""
    from freeqdsk import geqdsk
    e_bp, sigma_bp, sigma_rphiz, _ = cocos_signs(cocos)
    s = -sigma_rphiz
    # the analytic system has A_φ = −ψ_sol and physical B_φ = −B₀R₀/R in our coordinates; here
    # A_φ = −σ_Bp s ψ̃ and B_φ = s F/R: so ψ̃ = σ_Bp s ψ_sol and F = −s B₀R₀
    c = B0 / (2 * q0 * R0**2)

    def psi_sol(R, Z):
        return c * ((R**2 - R0**2) ** 2 / 4 + R**2 * Z**2 / kappa**2)

    R = np.linspace(R0 - 1.3 * a, R0 + 1.3 * a, n)
    Z = np.linspace(-1.3 * kappa * a, 1.3 * kappa * a, n)
    psib = psi_sol(R0 + a, 0.0)
    theta = np.linspace(0, 2 * np.pi, nbdry, endpoint=False)
    from scipy.optimize import brentq
    rb = np.empty(nbdry)
    for i, t in enumerate(theta):          # the boundary along rays from the axis
        ray = lambda r: psi_sol(R0 + r * np.cos(t), r * np.sin(t)) - psib
        rb[i] = brentq(ray, 1e-9, 2.5 * kappa * a)
    sign_psi = sigma_bp * s * (2 * np.pi) ** e_bp * current
    F = -s * B0 * R0 * field
    psi_axis, psi_bdry = 0.0, sign_psi * psib
    ip = np.sign(psi_bdry - psi_axis) * sigma_bp * 1e6     # the current whose sign COCOS asks for
    _, _, _, sigma_rtp = cocos_signs(cocos)
    qpsi = np.zeros(n) if q is None else np.full(n, abs(q) * np.sign(ip) * np.sign(F) * sigma_rtp)
    data = dict(nx=n, ny=n, rdim=R[-1] - R[0], zdim=Z[-1] - Z[0], rcentr=R0, rleft=R[0], zmid=0.0, rmagx=R0,
                zmagx=0.0, simagx=psi_axis, sibdry=psi_bdry, bcentr=F / R0 if header_B0 is None else header_B0,
                cpasma=ip, fpol=np.full(n, F), pres=np.zeros(n), ffprime=np.zeros(n), pprime=np.zeros(n),
                psi=sign_psi * psi_sol(R[:, None], Z[None, :]), qpsi=qpsi,
                rbdry=R0 + rb * np.cos(theta), zbdry=rb * np.sin(theta),
                rlim=np.array([R[0], R[-1], R[-1], R[0]]), zlim=np.array([Z[0], Z[0], Z[-1], Z[-1]]))
    with open(path, "w") as fh:
        geqdsk.write(data, fh, label="solovev", data_fmt=f"(5e{digits + 7}.{digits})")
    return path
