"""Degenerate Lagrangian systems L(q, v) = ϑ(q)·v − H(q), defined by ϑ and H alone.

A :class:`System` holds symbolic ϑ and H (sympy) and generates every derivative
exactly: ϑ_{k,i} = ∂ϑ_k/∂q^i, ϑ_{k,ij}, ∇H, ∇²H, the noncanonical symplectic
matrix Ω̄_ij = ∂_i ϑ_j − ∂_j ϑ_i (eq:euler_lagrange_equations_matrix), the explicit
vector field q̇ = Ω̄⁻¹ ∇H and, given a symmetry vector field V(q), the Noether
momentum P = ϑ·V (eq:noether_theorem).

Every numerical function takes q of shape (..., d) and returns arrays with the
same leading shape: ``theta`` (..., d), ``dtheta`` (..., d, d) indexed [k, i],
``ddtheta`` (..., d, d, d) indexed [k, i, j], ``H`` (...), ``dH`` (..., d),
``ddH`` (..., d, d).  The code is generated once per system (sympy common
subexpression elimination, numpy printer) and compiled lazily, so a scene that
never needs ϑ_{k,ij} never builds it.
"""
from __future__ import annotations

import functools
import itertools
import math

import numpy as np
import sympy
from .codegen import _Printer


def _numpy_field_call(s, *X):
    """The numpy functions' call of a spline field (1-, 2- or 3-D) on the system's data."""
    return f"{('_field1_np', '_field_np', '_field3_np')[len(X) - 1]}(_DATA, {s}, {', '.join(X)})"


def _compile(exprs, shape, qsyms, params, name, data=None):
    """Compile sympy expressions into ``f(q) -> array of shape q.shape[:-1] + shape``; ``data``:
    the system's spline fields (integrators/splines.py), which the expressions may use."""
    from .codegen import field_prelude
    flat, prelude, fnames = field_prelude(list(exprs), qsyms, params, 4,
                                          _numpy_field_call)
    subs, reduced = sympy.cse(flat, symbols=(sympy.Dummy(f"x{i}") for i in itertools.count()),
                              optimizations="basic")
    names = {s: f"_q{i}" for i, s in enumerate(qsyms)}
    names.update({k: f"_k{i}" for i, k in enumerate(params)})
    names.update(fnames)
    names.update({sym: f"_x{i}" for i, (sym, _) in enumerate(subs)})
    printer = _Printer(names)
    lines = [f"def {name}(_qin):"]
    lines.append("    _qin = numpy.asarray(_qin, dtype=numpy.result_type(_qin, numpy.float64))")
    # parameters in the input's real precision: a long-double call must not multiply them in double
    # first (for double the same IEEE products, bit for bit)
    for i, _ in enumerate(params):
        lines.append(f"    _k{i} = _qin.real.dtype.type(_K{i})")
    lines.append(f"    _out = numpy.zeros(_qin.shape[:-1] + {tuple(shape)!r}, dtype=_qin.dtype)")
    for i, s in enumerate(qsyms):
        lines.append(f"    {names[s]} = _qin[..., {i}]")
    lines += prelude
    for sym, e in subs:
        lines.append(f"    {names[sym]} = {printer.doprint(e)}")
    for idx, e in zip(itertools.product(*[range(n) for n in shape]), reduced):
        if e == 0:
            continue
        key = ", ".join(["..."] + [str(i) for i in idx])
        lines.append(f"    _out[{key}] = {printer.doprint(e)}")
    lines.append("    return _out")
    src = "\n".join(lines)
    namespace = {"numpy": np, **{f"_K{i}": float(v) for i, v in enumerate(params.values())}}
    if prelude:
        from .splines import field1_np, field_np
        from .splines3 import field3_np
        namespace.update(_field1_np=field1_np, _field_np=field_np, _field3_np=field3_np, _DATA=data)
    exec(compile(src, f"<generated {name}>", "exec"), namespace)
    fn = namespace[name]
    fn.source = src
    return fn


def _diff(e, x):
    """∂e/∂x with the distributions that abs() and sign() leave (DiracDelta) taken as 0."""
    d = sympy.diff(e, x)
    return d.replace(sympy.DiracDelta, lambda *args: sympy.Integer(0)) if d.has(sympy.DiracDelta) else d


def _not_finite(e) -> str | None:
    """What makes a sympy expression not finite (zoo, nan, ±oo), or None."""
    for bad, say in ((sympy.zoo, "complex infinity (zoo)"), (sympy.nan, "NaN"), (sympy.oo, "infinity"),
                     (-sympy.oo, "-infinity")):
        if e.has(bad):
            return say
    return None


def _expr(x, where, known):
    """A sympy expression from a sympy object or number, or from a string by the restricted parser
    (integrators.expressions: never ``sympify`` of text, which would run it)."""
    if isinstance(x, str):
        from .expressions import parse_expression
        return parse_expression(x, where, known)
    try:
        return sympy.sympify(x, strict=True)
    except sympy.SympifyError:
        raise ValueError(f"{where}: cannot use {x!r} as an expression") from None


class System:
    """A degenerate Lagrangian system from ϑ and H.

    Parameters
    ----------
    name : str
    q : list of d sympy Symbols (d even)
    theta : list of d sympy expressions ϑ_i(q)
    H : sympy expression H(q)
    params : dict {Symbol: float}, parameter values (every parameter overridable)
    symmetry : list of d expressions V(q) or None; momentum P = ϑ·V
    domain : list of expressions g(q) that must be > 0 (e.g. [q1, q2])
    defaults : dict with the paper's defaults (``q0``, ``h``, ...)
    """

    def __init__(self, name, q, theta, H, params=None, symmetry=None, domain=(), defaults=None,
                 momentum_name=None, flow=None, momentum=None, fields=(), source=None):
        self.name = name
        self.fields = tuple(fields)         # spline fields ϑ and H may use (integrators/splines.py)
        self.source = source                # where the fields came from (an equilibrium file), or None
        if self.fields:
            from .splines import pack
            self.data = pack(self.fields)
        else:
            self.data = np.zeros(0)
        self._flow = flow
        self.q = tuple(q)
        self.d = len(self.q)
        refuse_large(self.d, f"system {name}")
        if len(theta) != self.d:
            raise ValueError(f"system {name}: ϑ has {len(theta)} components for {self.d} coordinates")
        self.params = dict(params or {})
        known = {str(x): x for x in (*self.q, *self.params)}
        self.theta_expr = tuple(_expr(t, f"system {name}: theta[{i}]", known) for i, t in enumerate(theta))
        self.H_expr = _expr(H, f"system {name}: H", known)
        free = set().union(*(t.free_symbols for t in self.theta_expr), self.H_expr.free_symbols)
        unknown = free - set(self.q) - set(self.params)
        if unknown:
            raise ValueError(f"system {name}: no value for parameter(s) {', '.join(sorted(map(str, unknown)))}")
        for k, v in self.params.items():
            if not math.isfinite(float(v)):
                raise ValueError(f"system {name}: parameter {k} = {v} is not finite")
        self.symmetry = (None if symmetry is None else
                         tuple(_expr(v, f"system {name}: symmetry[{i}]", known) for i, v in enumerate(symmetry)))
        self.momentum_expr = (None if self.symmetry is None
                              else sympy.expand(sum(t * v for t, v in zip(self.theta_expr, self.symmetry))))
        if momentum is not None:            # a conserved quantity given directly (monitored like P)
            self.momentum_expr = _expr(momentum, f"system {name}: momentum", known)
            unknown = self.momentum_expr.free_symbols - set(self.q) - set(self.params)
            if unknown:
                raise ValueError(f"system {name}: momentum: no value for {', '.join(sorted(map(str, unknown)))}")
        self.momentum_name = momentum_name or ("P" if self.momentum_expr is not None else None)
        self.domain_expr = tuple(_expr(g, f"system {name}: domain[{i}]", known) for i, g in enumerate(domain))
        self.defaults = dict(defaults or {})

    # -- symbolic derivatives -------------------------------------------------
    # (taken away from kinks: the derivative of sign(x), which abs() brings, is 0, not DiracDelta(x),
    # a distribution no code can evaluate; where a function is C² it is the derivative everywhere)
    @functools.cached_property
    def dtheta_expr(self):
        return [[_diff(t, x) for x in self.q] for t in self.theta_expr]

    @functools.cached_property
    def ddtheta_expr(self):
        return [[[_diff(e, x) for x in self.q] for e in row] for row in self.dtheta_expr]

    @functools.cached_property
    def dH_expr(self):
        return [_diff(self.H_expr, x) for x in self.q]

    @functools.cached_property
    def ddH_expr(self):
        return [[_diff(e, x) for x in self.q] for e in self.dH_expr]

    def validate(self):
        """ValueError in one line naming the expression unless ϑ, H, their first and second
        derivatives (what the step engine evaluates), the momentum and the domain are finite
        expressions that the code generator can print: ``1/(x - x)``, ``log(0)*x`` or ``0/0`` are
        refused here, before any file is written, instead of failing inside the engine."""
        def where(key, i=None):
            return f"system {self.name}: {key}" + ("" if i is None else f"[{i}]")

        groups = [(where("theta", i), [e]) for i, e in enumerate(self.theta_expr)] + [(where("H"), [self.H_expr])]
        groups += [(where("momentum"), [self.momentum_expr])] if self.momentum_expr is not None else []
        groups += [(where("domain", i), [e]) for i, e in enumerate(self.domain_expr)]
        for i, e in enumerate(self.theta_expr):
            groups.append((f"{where('theta', i)}'s derivatives", [*self.dtheta_expr[i],
                                                                  *[x for row in self.ddtheta_expr[i] for x in row]]))
        groups.append((f"{where('H')}'s derivatives", [*self.dH_expr, *[x for row in self.ddH_expr for x in row]]))
        for key, exprs in groups:
            for e in exprs:
                bad = _not_finite(e)
                if bad:
                    raise ValueError(f"{key} is not finite: it contains {bad} (a division by zero, or log of 0?)")
        from .codegen import generate_source
        try:
            generate_source(self)
        except Exception as exc:           # a function the printer does not know: one line naming it
            raise ValueError(f"system {self.name}: cannot generate the engine's code for ϑ and H: "
                             f"{str(exc).splitlines()[0]}") from None
        return self

    def _fn(self, name, exprs, shape):
        return _compile(exprs, shape, self.q, self.params, name, self.data)

    def param_vector(self):
        """What every compiled point function receives as ``k``: the parameter values in order, then
        the fields' data (nothing for a system without fields); never empty."""
        v = np.concatenate([np.array([float(x) for x in self.params.values()], dtype=np.float64), self.data])
        return v if v.size else np.zeros(1)

    # -- compiled functions ---------------------------------------------------
    @functools.cached_property
    def theta(self):
        """ϑ(q): (..., d)."""
        return self._fn("theta", self.theta_expr, (self.d,))

    @functools.cached_property
    def dtheta(self):
        """ϑ_{k,i}(q) = ∂ϑ_k/∂q^i: (..., d, d)."""
        return self._fn("dtheta", [e for row in self.dtheta_expr for e in row], (self.d, self.d))

    @functools.cached_property
    def ddtheta(self):
        """ϑ_{k,ij}(q): (..., d, d, d)."""
        return self._fn("ddtheta", [e for m in self.ddtheta_expr for row in m for e in row],
                        (self.d, self.d, self.d))

    @functools.cached_property
    def H(self):
        """H(q): (...)."""
        return self._fn("hamiltonian", [self.H_expr], ())

    @functools.cached_property
    def dH(self):
        """∇H(q): (..., d)."""
        return self._fn("dH", self.dH_expr, (self.d,))

    @functools.cached_property
    def ddH(self):
        """∇²H(q): (..., d, d)."""
        return self._fn("ddH", [e for row in self.ddH_expr for e in row], (self.d, self.d))

    @property
    def has_momentum(self) -> bool:
        return self.momentum_expr is not None

    @functools.cached_property
    def momentum(self):
        """Noether momentum P(q) = ϑ(q)·V(q): (...); None when no symmetry is given."""
        if self.momentum_expr is None:
            return None
        return self._fn("momentum", [self.momentum_expr], ())

    def Omega(self, q):
        """Ω̄_ij = ∂_i ϑ_j − ∂_j ϑ_i (eq:euler_lagrange_equations_matrix): (..., d, d)."""
        T = self.dtheta(q)
        return np.swapaxes(T, -1, -2) - T

    def vector_field(self, q):
        """q̇ solving Ω̄(q) q̇ = ∇H(q): (..., d).

        This is eq:euler_lagrange_equations written out, Σ_j (∂_iϑ_j − ∂_jϑ_i) q̇^j = ∂_iH.
        The paper prints Ω̄ᵀ q̇ = ∇H in eq:euler_lagrange_equations_matrix with the same
        definition of Ω̄; that transpose flips the direction of time (for the guiding
        centre it would give ż = −u instead of b·ẋ = u), so we follow the Euler–Lagrange
        equations.  See docs/conventions.md.  Complex q is kept (complex-step derivatives).
        """
        q = np.asarray(q)
        q = q if np.iscomplexobj(q) else q.astype(float)
        return np.linalg.solve(self.Omega(q), self.dH(q)[..., None])[..., 0]

    def in_domain(self, q):
        """Boolean mask (...): finite and every domain expression > 0."""
        q = np.asarray(q, dtype=float)
        ok = np.all(np.isfinite(q), axis=-1)
        if self.domain_expr:
            g = self._domain_fn(q)
            ok &= np.all(g > 0, axis=-1)
        return ok

    @functools.cached_property
    def _domain_fn(self):
        return self._fn("domain", self.domain_expr, (len(self.domain_expr),))

    def with_params(self, **overrides):
        """A copy with some parameter values replaced (by parameter name)."""
        by_name = {k.name: k for k in self.params}
        new = dict(self.params)
        for key, val in overrides.items():
            if key not in by_name:
                raise ValueError(f"system {self.name}: unknown parameter '{key}' (has {', '.join(sorted(by_name))})")
            new[by_name[key]] = float(val)
        return System(self.name, self.q, self.theta_expr, self.H_expr, new, self.symmetry, self.domain_expr,
                      self.defaults, self.momentum_name, self._flow,
                      None if self.symmetry is not None else self.momentum_expr, self.fields, self.source)

    @property
    def has_exact_flow(self) -> bool:
        return self._flow is not None

    def exact_flow(self, q, t):
        """The exact time-t flow map applied to q (..., d), where a closed form is known."""
        if self._flow is None:
            raise ValueError(f"system {self.name} has no closed-form flow")
        return self._flow(np.asarray(q, dtype=float), float(t), self.param_values)

    @property
    def param_values(self) -> dict:
        return {k.name: float(v) for k, v in self.params.items()}

    def __repr__(self):
        p = ", ".join(f"{k}={v:g}" for k, v in self.param_values.items())
        return f"System({self.name}, d={self.d}{', ' if p else ''}{p})"


MAX_FORMULA_DIMENSION = 160     # the largest d the formula route takes (docs/audit.md, "Symbolic systems of moderate size")


def formula_seconds(d) -> float:
    """The measured cost of the formula route for d coordinates: sympy's derivatives (ϑ_q, ϑ_qq, H's
    first and second) 63 s at d = 128 growing as d³ (25 s at 96, 7.5 s at 64), and the engine's
    kernels compiled for that d (about 35 s each, real and complex step), on the 2-core machine."""
    return 63.0 * (d / 128.0) ** 3 + 70.0


def refuse_large(d, what="system"):
    """ValueError in one line, before sympy differentiates anything, for a system of more than
    MAX_FORMULA_DIMENSION coordinates: its derivatives alone would take minutes and gigabytes; such a
    system is audited by its step map (integrators.audit.audit_map, poincare audit --map)."""
    if d > MAX_FORMULA_DIMENSION:
        raise ValueError(f"{what}: d = {d} coordinates is too large for formulas (the derivatives and kernels "
                         f"would take about {formula_seconds(d) / 60:.0f} min; at most d = {MAX_FORMULA_DIMENSION}): "
                         "audit its step map instead (poincare audit --map, or a scene with "
                         "system.degrees_of_freedom; docs/audit.md)")


def system_from(theta, H, q, name="user", params=None, symmetry=None, domain=(), defaults=None, momentum=None):
    """A system from ϑ (list of sympy expressions), H and the coordinate symbols q.

    Example
    -------
    >>> x, y = sympy.symbols("x y")
    >>> sys = system_from([-y / 2, x / 2], (x**2 + y**2) / 2, [x, y])
    """
    if len(q) % 2:
        raise ValueError(f"system {name}: dimension {len(q)} is odd; Ω̄ must be invertible (even d)")
    return System(name, q, theta, H, params, symmetry, domain, defaults, momentum=momentum).validate()


# ----------------------------------------------------------------------------
# built-in systems (paper parameters as defaults)
# ----------------------------------------------------------------------------

def _lotka_volterra_2d():
    """sec:app_lotka_volterra_2d."""
    q1, q2 = sympy.symbols("q1 q2", positive=True)
    a1, a2, b1, b2 = sympy.symbols("a1 a2 b1 b2")
    theta = [sympy.log(q2) / q1 + q2, q1]
    H = a1 * q1 + a2 * q2 - b1 * sympy.log(q1) - b2 * sympy.log(q2)
    return System("lotka_volterra_2d", [q1, q2], theta, H, {a1: 1.0, a2: 1.0, b1: 1.0, b2: 2.0},
                  domain=[q1, q2], defaults={"q0": [1.0, 1.0], "h": 0.1})


def _point_vortices():
    """sec:app_planar_point_vortices, S(x, y) = 1 + x² + y², rotation symmetry."""
    x1, y1, x2, y2 = sympy.symbols("x1 y1 x2 y2", real=True)
    g1, g2 = sympy.symbols("gamma1 gamma2")
    S1, S2 = 1 + x1**2 + y1**2, 1 + x2**2 + y2**2
    theta = [-g1 * y1 * S1 / 2, g1 * x1 * S1 / 2, -g2 * y2 * S2 / 2, g2 * x2 * S2 / 2]
    H = g1 * g2 / (2 * sympy.pi) * S1 * S2 * sympy.log((x1 - x2) ** 2 + (y1 - y2) ** 2)
    # P = q¹ϑ₂ − q²ϑ₁ + q³ϑ₄ − q⁴ϑ₃ = ϑ·V for the rotation field V = (−y1, x1, −y2, x2)
    return System("point_vortices", [x1, y1, x2, y2], theta, H, {g1: 0.1, g2: 0.1},
                  symmetry=[-y1, x1, -y2, x2], momentum_name="angular momentum",
                  defaults={"q0": [1.0, 0.1, 1.0, -0.1], "h": 0.1})


def _guiding_centre_tokamak():
    """app:guiding_centre_dynamics: q = (R, Z, φ, u), field of Qin et al. (2009)."""
    R, Z, phi, u = sympy.symbols("R Z phi u", real=True)
    R0, B0, q0, mu = sympy.symbols("R0 B0 q0 mu")
    r2 = (R - R0) ** 2 + Z**2
    S = sympy.sqrt(r2 + q0**2 * R0**2)
    A_R = B0 * R0 * Z / (2 * R)
    A_Z = -sympy.log(R / R0) * B0 * R0 / 2
    A_phi = -B0 * r2 / (2 * q0 * R)
    b_R, b_Z, b_phi = -Z / S, (R - R0) / S, -q0 * R0 / S
    absB = B0 * S / (q0 * R)
    theta = [A_R + u * b_R, A_Z + u * b_Z, R * (A_phi + u * b_phi), 0]
    H = u**2 / 2 + mu * absB
    return System("guiding_centre_tokamak", [R, Z, phi, u], theta, H,
                  {R0: 2.0, B0: 5.0, q0: 2.0, mu: 0.01}, symmetry=[0, 0, 1, 0],
                  momentum_name="toroidal momentum", domain=[R],
                  defaults={"q0": [2.5, 0.0, 0.0, 0.5], "h": 2.5,
                            "orbits": {"deeply trapped": (0.1, 5.0), "barely trapped": (0.3375, 3.0),
                                       "barely passing": (0.3425, 2.5), "deeply passing": (0.5, 2.5)}})


def _guiding_centre_symmetric_flow(q, t, p):
    """Exact flow of guiding_centre_symmetric.

    Ω̄_xy = B₀(1 + r²), Ω̄_uz = 1 and ∇H = (2μB₀x, 2μB₀y, 0, u) give ẋ = −ωy, ẏ = ωx with
    ω = 2μ/(1 + r²), ż = u, u̇ = 0: a rotation about z by 2μt/(1 + r²) (r and u are constant)
    and a shift z += u t.  A reference for tests and benchmarks (a nonlinear shear flow).
    """
    r2 = q[..., 0] ** 2 + q[..., 1] ** 2
    ang = 2.0 * p["mu"] * t / (1.0 + r2)
    out = q.copy()
    out[..., 0] = np.cos(ang) * q[..., 0] - np.sin(ang) * q[..., 1]
    out[..., 1] = np.sin(ang) * q[..., 0] + np.cos(ang) * q[..., 1]
    out[..., 2] = q[..., 2] + q[..., 3] * t
    return out


def _guiding_centre_symmetric():
    """sec:app_integral_invariants: B = (0, 0, B₀(1 + x² + y²)), b = e_z."""
    x, y, z, u = sympy.symbols("x y z u", real=True)
    B0, mu = sympy.symbols("B0 mu")
    rho = 2 + x**2 + y**2
    theta = [-B0 * y * rho / 4, B0 * x * rho / 4, u, 0]
    H = u**2 / 2 + mu * B0 * (1 + x**2 + y**2)
    return System("guiding_centre_symmetric", [x, y, z, u], theta, H, {B0: 1.0, mu: 0.01},
                  symmetry=[-y, x, 0, 0], momentum_name="angular momentum",
                  defaults={"q0": [0.5, 0.0, 0.0, 0.5], "h": 10.0}, flow=_guiding_centre_symmetric_flow)


def _massless_charged_particle():
    """A massless charged particle in the plane (GeometricProblems.jl, MasslessChargedParticle):
    ϑ = A(x) = A₀/2 (1 + x₁² + x₂²)(−x₂, x₁), so B = ∇×A = A₀(1 + 2x₁² + 2x₂²), and H = φ(x) =
    E₀(cos x₁ + sin x₂).  No continuous symmetry: the energy is the conserved quantity."""
    x1, x2 = sympy.symbols("x1 x2", real=True)
    A0, E0 = sympy.symbols("A0 E0")
    S = 1 + x1**2 + x2**2
    return System("massless_charged_particle", [x1, x2], [-A0 * x2 * S / 2, A0 * x1 * S / 2],
                  E0 * (sympy.cos(x1) + sympy.sin(x2)), {A0: 1.0, E0: 1.0},
                  defaults={"q0": [1.0, 1.0], "h": 0.2})


def _lotka_volterra_4d():
    """Lotka–Volterra in 4-D as a degenerate Lagrangian system (GeometricProblems.jl, LotkaVolterra4d):
    ϑ = ((log q₂ + log q₄)/q₁, log q₃/q₂, (log q₁ + log q₄)/q₃, log q₂/q₄),
    H = Σᵢ aᵢqᵢ + bᵢ log qᵢ, every qᵢ > 0."""
    q = sympy.symbols("q1 q2 q3 q4", positive=True)
    a = sympy.symbols("a1 a2 a3 a4")
    b = sympy.symbols("b1 b2 b3 b4")
    lg = [sympy.log(x) for x in q]
    theta = [(lg[1] + lg[3]) / q[0], lg[2] / q[1], (lg[0] + lg[3]) / q[2], lg[1] / q[3]]
    H = sum(ai * qi + bi * li for ai, qi, bi, li in zip(a, q, b, lg))
    params = dict(zip(a, (1.0, 1.0, 1.0, 1.0))) | dict(zip(b, (-1.0, -2.0, -1.0, -1.0)))
    return System("lotka_volterra_4d", list(q), theta, H, params, domain=list(q),
                  defaults={"q0": [2.0, 1.0, 1.0, 1.0], "h": 0.1})


def _guiding_centre_solovev():
    """Guiding centre in a Solov'ev equilibrium (an exact Grad–Shafranov solution with constant
    p′(ψ) and F = B₀R₀), q = (R, Z, φ, u), the same Lagrangian as app:guiding_centre_dynamics:
    ϑ = A + u b, H = u²/2 + μ|B|, with covariant A = (B₀R₀Z/(2R), −B₀R₀ log(R/R₀)/2, −ψ) and

        ψ(R, Z) = B₀/(2q₀R₀²) ((R² − R₀²)²/4 + R²Z²/κ²),

    so Δ*ψ = B₀(1 + 1/κ²)R²/(q₀R₀²) and near the axis ψ ≈ B₀/(2q₀) ((R − R₀)² + Z²/κ²): the tokamak
    field of guiding_centre_tokamak with flux surfaces elongated by κ and Shafranov-shifted, as in the
    Solov'ev equilibria of ChargedParticleDynamics.jl / ElectromagneticFields.jl (McCarthy 1999,
    Cerfon & Freidberg 2010).  B^i = ε^{ijk}∂_jA_k/R in the (R, Z, φ) order used by the tokamak.
    Conserved: the energy and the toroidal momentum ϑ_φ."""
    R, Z, phi, u = sympy.symbols("R Z phi u", real=True)
    R0, B0, q0, kappa, mu = sympy.symbols("R0 B0 q0 kappa mu")
    psi = B0 / (2 * q0 * R0**2) * ((R**2 - R0**2) ** 2 / 4 + R**2 * Z**2 / kappa**2)
    A = [B0 * R0 * Z / (2 * R), -B0 * R0 * sympy.log(R / R0) / 2, -psi]
    B_cov = [sympy.diff(A[2], Z) / R, -sympy.diff(A[2], R) / R,
             R * (sympy.diff(A[1], R) - sympy.diff(A[0], Z))]          # B_R = B^R, B_Z = B^Z, B_φ = R² B^φ
    absB = sympy.sqrt(B_cov[0] ** 2 + B_cov[1] ** 2 + B_cov[2] ** 2 / R**2)
    theta = [A[i] + u * B_cov[i] / absB for i in range(3)] + [0]
    H = u**2 / 2 + mu * absB
    return System("guiding_centre_solovev", [R, Z, phi, u], theta, H,
                  {R0: 2.0, B0: 5.0, q0: 2.0, kappa: 1.6, mu: 0.01}, symmetry=[0, 0, 1, 0],
                  momentum_name="toroidal momentum", domain=[R],
                  defaults={"q0": [2.3, 0.0, 0.0, -0.3], "h": 2.5})


def _charged_particle_tokamak():
    """The full orbit of a charged particle (charge/mass 1) in the tokamak field of
    app:guiding_centre_dynamics, written as a degenerate Lagrangian in 6-D phase space q = (x, v):

        L = (A(x) + v)·ẋ − |v|²/2,   ϑ = (A(x) + v, 0, 0, 0),   H = |v|²/2,

    whose Euler–Lagrange equations are ẋ = v, v̇ = v × B (the Lorentz force), B = ∇×A.  A is the
    tokamak's vector potential in Cartesian components (A_R, A_Z and A_φ of guiding_centre_tokamak
    rotated by φ = atan2(y, x)).  Rotation about z (x and v together) is a symmetry, so the toroidal
    canonical momentum ϑ·V, V = (−y, x, 0, −v_y, v_x, 0), is conserved with the energy."""
    x, y, z, vx, vy, vz = sympy.symbols("x y z v_x v_y v_z", real=True)
    R0, B0, q0 = sympy.symbols("R0 B0 q0")
    R = sympy.sqrt(x**2 + y**2)
    r2 = (R - R0) ** 2 + z**2
    A_R, A_Z, A_phi = B0 * R0 * z / (2 * R), -sympy.log(R / R0) * B0 * R0 / 2, -B0 * r2 / (2 * q0 * R)
    A = [(A_R * x - A_phi * y) / R, (A_R * y + A_phi * x) / R, A_Z]
    theta = [A[0] + vx, A[1] + vy, A[2] + vz, 0, 0, 0]
    return System("charged_particle_tokamak", [x, y, z, vx, vy, vz], theta, (vx**2 + vy**2 + vz**2) / 2,
                  {R0: 2.0, B0: 5.0, q0: 2.0}, symmetry=[-y, x, 0, -vy, vx, 0],
                  momentum_name="toroidal momentum", domain=[x**2 + y**2],
                  defaults={"q0": [2.5, 0.0, 0.0, 0.2, 0.5, 0.0], "h": 0.05})


_SYSTEMS = {
    "lotka_volterra_2d": _lotka_volterra_2d,
    "point_vortices": _point_vortices,
    "guiding_centre_tokamak": _guiding_centre_tokamak,
    "guiding_centre_symmetric": _guiding_centre_symmetric,
    "massless_charged_particle": _massless_charged_particle,
    "lotka_volterra_4d": _lotka_volterra_4d,
    "guiding_centre_solovev": _guiding_centre_solovev,
    "charged_particle_tokamak": _charged_particle_tokamak,
}
SYSTEM_NAMES = tuple(_SYSTEMS)


@functools.lru_cache(maxsize=None)
def _builtin(name):
    return _SYSTEMS[name]()


_ALIASES = {"point_vortices": {"gamma": ("gamma1", "gamma2")},
            "lotka_volterra_2d": {"a": ("a1", "a2"), "b": ("b1", "b2")},
            "lotka_volterra_4d": {"a": ("a1", "a2", "a3", "a4"), "b": ("b1", "b2", "b3", "b4")}}


def system(name: str, **params) -> System:
    """A built-in system with the paper's parameters, any of which may be overridden.

    Vector parameters may be given whole: ``system("point_vortices", gamma=(0.1, 0.1))``.
    """
    if name not in _SYSTEMS:
        raise ValueError(f"unknown system '{name}'; choose one of {', '.join(SYSTEM_NAMES)}")
    base = _builtin(name)
    if not params:
        return base
    flat = {}
    aliases = _ALIASES.get(name, {})
    for key, val in params.items():
        if key in aliases and np.ndim(val) == 1:
            if len(val) != len(aliases[key]):
                raise ValueError(f"system {name}: parameter '{key}' needs {len(aliases[key])} values")
            flat.update(zip(aliases[key], val))
        else:
            flat[key] = val
    return base.with_params(**flat)
