"""Runge–Kutta tableaus for variational partitioned Runge–Kutta (VPRK) methods.

A VPRK method (eq:vprk) is given by the coefficients ``a`` (positions), ``abar``
(momenta), weights ``b = bbar`` and nodes ``c``.  Unless a family defines it,
``abar`` is the symplectic conjugate of ``a`` from eq:vprk_coefficients,

    b_i abar_ij + b_j a_ji = b_i b_j   =>   abar_ij = b_j (1 - a_ji / b_i).

Every coefficient is computed in extended precision (mpmath, 50 digits) and
carried as a double plus a double correction (``a = a_hi + a_lo``), following
Hairer, McLachlan & Razakarivony (2008) as described in sec:app_energy_drift.
``R(∞)`` is the limit of the stability function R(z) = 1 + z bᵀ(I − zA)⁻¹e,
evaluated in extended precision, never typed in (see :func:`stability_at_infinity`).

The Lobatto families use the constraint vector ``d`` of eq:vprk_lobatto for the
IIIA–IIIB and IIIB–IIIA pairs, whose velocity stages are linearly dependent.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
from pathlib import Path

import mpmath
import numpy as np

_DPS = 50


@dataclasses.dataclass(frozen=True, eq=False)
class Tableau:
    """An immutable VPRK tableau.

    Attributes
    ----------
    name : str
    s : int, number of stages
    order : int, classical order of the (a, b, c) method
    a, a_lo, abar, abar_lo : (s, s) float arrays, coefficient and its correction
    b, b_lo, c : (s,) float arrays
    d : (s,) float array or None, Lobatto constraint vector (eq:vprk_lobatto)
    R_inf : float, R(∞) of the stability function (±1, 0 or inf)
    exact : dict of mpmath matrices (a, abar, b, c, d) for checks in tests
    """

    name: str
    s: int
    order: int
    a: np.ndarray
    a_lo: np.ndarray
    abar: np.ndarray
    abar_lo: np.ndarray
    b: np.ndarray
    b_lo: np.ndarray
    c: np.ndarray
    d: np.ndarray | None
    R_inf: float
    exact: dict = dataclasses.field(repr=False)

    @property
    def symplectic_defect(self) -> float:
        """max |b_i abar_ij + b_j a_ji − b_i b_j| in extended precision."""
        a, ab, b = self.exact["a"], self.exact["abar"], self.exact["b"]
        s = self.s
        return float(max(abs(b[i] * ab[i, j] + b[j] * a[j, i] - b[i] * b[j])
                         for i in range(s) for j in range(s)))

    def rounded(self) -> "Tableau":
        """The same tableau with its coefficients rounded to double: the corrections a_lo, ā_lo, b_lo
        dropped (the plain-double variant of sec:app_energy_drift's comparison)."""
        return dataclasses.replace(self, a_lo=np.zeros_like(self.a_lo), abar_lo=np.zeros_like(self.abar_lo),
                                   b_lo=np.zeros_like(self.b_lo))

    def conjugated(self, compensated: bool = True) -> "Tableau":
        """a and b rounded to double, and ā chosen from those doubles so that eq:vprk_coefficients
        holds in floating point (the technique of Antoñana et al. 2017 that sec:app_energy_drift
        cites): ā is no longer the rounded exact ā, it is the symplectic conjugate of the rounded a.

        compensated=True: ā_ij = b_j (b_i − a_ji) / b_i evaluated in exact rational arithmetic from
        the doubles a, b and carried as double + correction, so the condition holds to about 1e-33
        for the coefficients the step uses (see :attr:`float_symplectic_residual`), while the order
        conditions hold to the 1e-17 of a and b.  compensated=False: GeometricIntegrators.jl's
        ``b[j] * (1 - a[j,i] / b[i])`` in double, no correction.
        """
        from fractions import Fraction
        s, a, b = self.s, self.a, self.b
        hi, lo = np.zeros((s, s)), np.zeros((s, s))
        for i in range(s):
            for j in range(s):
                if compensated:
                    x = Fraction(b[j]) * (Fraction(b[i]) - Fraction(a[j, i])) / Fraction(b[i])
                    hi[i, j] = float(x)
                    lo[i, j] = float(x - Fraction(hi[i, j]))
                else:
                    hi[i, j] = b[j] * (1.0 - a[j, i] / b[i])
        return dataclasses.replace(self, a_lo=np.zeros_like(self.a_lo), abar=hi, abar_lo=lo,
                                   b_lo=np.zeros_like(self.b_lo))

    @property
    def float_symplectic_residual(self) -> float:
        """max |b_i ā_ij + b_j a_ji − b_i b_j| for the coefficients the step uses (each one its double
        plus its correction), evaluated exactly: how far the floating-point tableau is from
        eq:vprk_coefficients.  (:attr:`symplectic_defect` is the same for the exact coefficients.)"""
        from fractions import Fraction

        def eff(hi, lo):
            return [[Fraction(x) + Fraction(y) for x, y in zip(rh, rl)] for rh, rl in zip(hi, lo)]
        a, ab = eff(self.a, self.a_lo), eff(self.abar, self.abar_lo)
        b = [Fraction(x) + Fraction(y) for x, y in zip(self.b, self.b_lo)]
        s = self.s
        return float(max(abs(b[i] * ab[i][j] + b[j] * a[j][i] - b[i] * b[j]) for i in range(s) for j in range(s)))

    @property
    def digest(self) -> str:
        """SHA-256 of every coefficient the step uses (a, ā, b with their corrections, c, d), bit for
        bit: two tableaus with the same digest step identically whatever their files look like."""
        h = hashlib.sha256()
        for x in (self.a, self.a_lo, self.abar, self.abar_lo, self.b, self.b_lo, self.c,
                  np.zeros(0) if self.d is None else self.d):
            h.update(np.ascontiguousarray(x, dtype="<f8").tobytes() + b"|")
        return h.hexdigest()

    def __repr__(self) -> str:
        return f"Tableau({self.name}, s={self.s}, order={self.order}, R(∞)={self.R_inf:g})"


# ----------------------------------------------------------------------------
# extended-precision building blocks
# ----------------------------------------------------------------------------

def _mp():
    ctx = mpmath.mp.clone()
    ctx.dps = _DPS
    return ctx


def _shifted_legendre(mp, n):
    """Coefficients (ascending) of P_n(2x − 1) = Σ_k (−1)^(n+k) C(n,k) C(n+k,k) x^k."""
    return [(-1) ** (n + k) * mp.binomial(n, k) * mp.binomial(n + k, k) for k in range(n + 1)]


def _real_roots(mp, coeffs_ascending):
    roots = mp.polyroots(list(reversed(coeffs_ascending)), maxsteps=500, extraprec=4 * _DPS)
    return sorted(mp.re(r) for r in roots)


def _gauss_nodes(mp, s):
    """Roots of the shifted Legendre polynomial P_s(2x − 1)."""
    return _real_roots(mp, _shifted_legendre(mp, s))


def _lobatto_nodes(mp, s):
    """0, 1 and the roots of d/dx P_{s−1}(2x − 1)."""
    p = _shifted_legendre(mp, s - 1)
    dp = [k * p[k] for k in range(1, len(p))]
    inner = _real_roots(mp, dp) if len(dp) > 1 else []
    return [mp.mpf(0)] + inner + [mp.mpf(1)]


def _radau_right_nodes(mp, s):
    """Radau IIA nodes: roots of P_s(2x − 1) − P_{s−1}(2x − 1) (c_s = 1)."""
    p, q = _shifted_legendre(mp, s), _shifted_legendre(mp, s - 1) + [0]
    roots = _real_roots(mp, [x - y for x, y in zip(p, q)])
    roots[-1] = mp.mpf(1)
    return roots


def _quadrature_weights(mp, c):
    s = len(c)
    V = mp.matrix(s, s)
    rhs = mp.matrix(s, 1)
    for k in range(s):
        for j in range(s):
            V[k, j] = c[j] ** k
        rhs[k] = mp.mpf(1) / (k + 1)
    return mp.lu_solve(V, rhs)


def _collocation(mp, c):
    """a_ij = ∫_0^{c_i} ℓ_j: the simplifying assumption C(s)."""
    s = len(c)
    W = mp.matrix(s, s)
    for k in range(s):
        for j in range(s):
            W[k, j] = c[j] ** k
    A = mp.matrix(s, s)
    for i in range(s):
        rhs = mp.matrix(s, 1)
        for k in range(s):
            rhs[k] = c[i] ** (k + 1) / (k + 1)
        row = mp.lu_solve(W, rhs)
        for j in range(s):
            A[i, j] = row[j]
    return A


def _lobatto_IIIC(mp, c, b):
    """a_i1 = b_1 and C(s − 1)."""
    s = len(c)
    A = mp.matrix(s, s)
    W = mp.matrix(s - 1, s - 1)
    for k in range(s - 1):
        for j in range(1, s):
            W[k, j - 1] = c[j] ** k
    for i in range(s):
        rhs = mp.matrix(s - 1, 1)
        for k in range(s - 1):
            rhs[k] = c[i] ** (k + 1) / (k + 1) - b[0] * c[0] ** k
        row = mp.lu_solve(W, rhs)
        A[i, 0] = b[0]
        for j in range(1, s):
            A[i, j] = row[j - 1]
    return A


def symplectic_conjugate(mp, A, b):
    """abar_ij = b_j (1 − a_ji / b_i), the solution of eq:vprk_coefficients."""
    s = len(b)
    Ab = mp.matrix(s, s)
    for i in range(s):
        for j in range(s):
            Ab[i, j] = b[j] * (1 - A[j, i] / b[i])
    return Ab


def _lobatto_nullvector(mp, c):
    """Null vector of Dᵀ, D_ij = ℓ_j'(c_i): the d of eq:vprk_lobatto, scaled so d_1 = 1.

    The paper's s = 3 choice (1/2, −1, 1/2) differs by a factor 2; the scale of d
    is absorbed by the multiplier μ and does not change the solution.
    """
    s = len(c)
    # ℓ_j'(c_i) via the barycentric differentiation matrix
    w = [mp.mpf(1) / mp.fprod([c[j] - c[k] for k in range(s) if k != j]) for j in range(s)]
    D = mp.matrix(s, s)
    for i in range(s):
        for j in range(s):
            if i != j:
                D[i, j] = (w[j] / w[i]) / (c[i] - c[j])
        D[i, i] = -mp.fsum(D[i, j] for j in range(s) if j != i)
    # solve Dᵀ x = 0 with x_1 = 1: drop one equation (rank s − 1)
    M = mp.matrix(s - 1, s - 1)
    rhs = mp.matrix(s - 1, 1)
    for r in range(s - 1):
        for k in range(1, s):
            M[r, k - 1] = D[k, r]
        rhs[r] = -D[0, r]
    x = mp.lu_solve(M, rhs)
    return [mp.mpf(1)] + [x[k] for k in range(s - 1)]


def stability_at_infinity(mp, A, b) -> float:
    """R(∞) for R(z) = det(I − zA + z e bᵀ) / det(I − zA).

    Evaluated at z = 10⁴⁰ in 50-digit arithmetic; values within 10⁻²⁰ of 0 or
    above 10²⁰ are reported as 0 and inf, anything else is rounded to a double.
    """
    s = len(b)
    z = mp.mpf(10) ** 40
    I = mp.eye(s)
    E = mp.matrix(s, s)
    for i in range(s):
        for j in range(s):
            E[i, j] = b[j]
    num = mp.det(I - z * A + z * E)
    den = mp.det(I - z * A)
    if den == 0:
        return float("inf")
    r = num / den
    if abs(r) < mp.mpf(10) ** -20:
        return 0.0
    if abs(r) > mp.mpf(10) ** 20:
        return float("inf")
    return float(r)


def _split(mp, M):
    """mp matrix/vector → (double, double correction)."""
    if isinstance(M, list):
        hi = np.array([float(x) for x in M])
        lo = np.array([float(x - mp.mpf(h)) for x, h in zip(M, hi)])
        return hi, lo
    rows, cols = M.rows, M.cols
    hi = np.array([[float(M[i, j]) for j in range(cols)] for i in range(rows)])
    lo = np.array([[float(M[i, j] - mp.mpf(hi[i, j])) for j in range(cols)] for i in range(rows)])
    return hi, lo


def _pair_R_inf(mp, A, Abar, b) -> float:
    """R(∞) governing the projection signs (table in sec:projection).

    It is R(∞) of the position tableau ``a``.  Where that is 0 or ∞ (Lobatto
    IIIC: R = 0; IIIC*: R = ∞; neither symmetric), the value of the symmetric
    average (a + abar)/2 is used: for the IIIC–IIIC* pair that is Lobatto IIIE.
    A tableau whose R(∞) is still 0 (Radau IIA) can only be used unprojected or
    with the standard projection.
    """
    r = stability_at_infinity(mp, A, b)
    if r not in (0.0, float("inf")):
        return r
    return stability_at_infinity(mp, (A + Abar) / 2, b)


def make_tableau(name, a, b, c, *, abar=None, d=None, order=None, mp=None) -> Tableau:
    """Build and validate a tableau from extended-precision or float data.

    Parameters
    ----------
    a : (s, s) array-like of numbers / mpmath numbers
    b, c : (s,) array-like
    abar : (s, s), optional; default: the symplectic conjugate of ``a``
    d : (s,), optional Lobatto constraint vector
    order : int, optional; default: computed from the order conditions
    """
    mp = mp or _mp()
    A = a if hasattr(a, 'rows') else mp.matrix([[mp.mpf(x) for x in row] for row in a])
    s = A.rows
    bb = [mp.mpf(b[i]) for i in range(len(b))]
    cc = [mp.mpf(c[i]) for i in range(len(c))]
    if A.cols != s or len(bb) != s or len(cc) != s:
        raise ValueError(f"tableau {name}: a must be (s, s) with s = len(b) = len(c)")
    if any(x == 0 for x in bb):
        raise ValueError(f"tableau {name}: zero weight b_i (the symplectic conjugate divides by b_i)")
    if abs(mp.fsum(bb) - 1) > mp.mpf(10) ** -14:
        raise ValueError(f"tableau {name}: weights sum to {float(mp.fsum(bb))}, not 1")
    if abar is None:
        Ab = symplectic_conjugate(mp, A, bb)
    else:
        Ab = abar if hasattr(abar, 'rows') else mp.matrix([[mp.mpf(x) for x in row] for row in abar])
    dd = None if d is None else [mp.mpf(x) for x in d]
    if dd is None and _singular(A, s):
        if all(A[i, j] == 0 for i in range(s) for j in range(i, s)):
            raise ValueError(f"tableau {name}: a is strictly lower triangular, an explicit Runge–Kutta method "
                             "(RK4, Euler, Heun): explicit methods are not variational PRK tableaus. A tableau "
                             "here needs a invertible (Gauss–Legendre, Radau IIA, SRK3) or, where a is singular "
                             "as in Lobatto IIIA, the constraint weights d of eq:vprk_lobatto; an explicit "
                             "method runs as your own step map (run.step_maps)")
        raise ValueError(f"tableau {name}: a is singular (its velocity stages are linearly dependent, as in "
                         "Lobatto IIIA, whose first row is zero), so the stage equations need the constraint "
                         "0 = Σ d_i V_i of eq:vprk_lobatto: give d, s numbers (Lobatto IIIA with 2, 3, 4 "
                         "stages: d = [1, -1], [1/2, -1, 1/2], [1, -sqrt(5), sqrt(5), -1]); abar, when "
                         "given (a IIIA/IIIB pair), is the momentum stages' matrix")
    if dd is not None and len(dd) != s:
        raise ValueError(f"tableau {name}: d must have s = {s} entries, got {len(dd)}")
    a_hi, a_lo = _split(mp, A)
    ab_hi, ab_lo = _split(mp, Ab)
    b_hi, b_lo = _split(mp, bb)
    c_hi, _ = _split(mp, cc)
    if order is None:
        from .order_conditions import order_of
        order = order_of(a_hi + a_lo, b_hi + b_lo, c_hi, max_order=2 * s)
    return Tableau(
        name=name, s=s, order=int(order),
        a=a_hi, a_lo=a_lo, abar=ab_hi, abar_lo=ab_lo, b=b_hi, b_lo=b_lo, c=c_hi,
        d=None if dd is None else np.array([float(x) for x in dd]),
        R_inf=_pair_R_inf(mp, A, Ab, bb),
        exact={"a": A, "abar": Ab, "b": bb, "c": cc, "d": dd},
    )


# ----------------------------------------------------------------------------
# families
# ----------------------------------------------------------------------------

def _glrk(s):
    mp = _mp()
    c = _gauss_nodes(mp, s)
    return make_tableau(f"GLRK{s}", _collocation(mp, c), _quadrature_weights(mp, c), c, order=2 * s, mp=mp)


def _srk3():
    """tab:srk3 (Zhao 2014): symplectic, symmetric, Z_2 is the midpoint."""
    mp = _mp()
    r = mp.sqrt(15) / 10
    a = mp.matrix([[mp.mpf(5) / 36, mp.mpf(2) / 9, mp.mpf(5) / 36 - r],
                   [mp.mpf(5) / 36, mp.mpf(2) / 9, mp.mpf(5) / 36],
                   [mp.mpf(5) / 36 + r, mp.mpf(2) / 9, mp.mpf(5) / 36]])
    b = [mp.mpf(5) / 18, mp.mpf(4) / 9, mp.mpf(5) / 18]
    c = [mp.mpf(1) / 2 - r, mp.mpf(1) / 2, mp.mpf(1) / 2 + r]
    return make_tableau("SRK3", a, b, c, order=4, mp=mp)


def _lobatto(family, s):
    mp = _mp()
    c = _lobatto_nodes(mp, s)
    b = _quadrature_weights(mp, c)
    bl = [b[i] for i in range(s)]
    A_ = _collocation(mp, c)                    # IIIA
    B_ = symplectic_conjugate(mp, A_, bl)       # IIIB
    C_ = _lobatto_IIIC(mp, c, bl)               # IIIC
    Cs = symplectic_conjugate(mp, C_, bl)       # IIIC*
    a = {"A": A_, "B": B_, "C": C_, "D": (A_ + B_) / 2, "E": (C_ + Cs) / 2}[family]
    d = _lobatto_nullvector(mp, c) if family in ("A", "B") else None
    return make_tableau(f"LobIII{family}{s}", a, bl, c, d=d, order=2 * s - 2, mp=mp)


def _radau_IIA(s):
    """Radau IIA for both q and p (abar = a): not symplectic, keeps the constraint."""
    mp = _mp()
    c = _radau_right_nodes(mp, s)
    A = _collocation(mp, c)
    b = _quadrature_weights(mp, c)
    return make_tableau(f"RadIIA{s}", A, [b[i] for i in range(s)], c, abar=A, order=2 * s - 1, mp=mp)


def _builders():
    reg = {f"GLRK{s}": functools.partial(_glrk, s) for s in range(1, 7)}
    reg["SRK3"] = _srk3
    for fam in "ABCDE":
        for s in (2, 3, 4):
            reg[f"LobIII{fam}{s}"] = functools.partial(_lobatto, fam, s)
    for s in (2, 3):
        reg[f"RadIIA{s}"] = functools.partial(_radau_IIA, s)
    return reg


_BUILDERS = _builders()
TABLEAU_NAMES = tuple(_BUILDERS)


@functools.lru_cache(maxsize=None)
def tableau(name: str) -> Tableau:
    """A built-in tableau by name (see ``TABLEAU_NAMES``)."""
    if isinstance(name, Tableau):
        return name
    if name not in _BUILDERS:
        raise ValueError(f"unknown tableau '{name}'; choose one of {', '.join(TABLEAU_NAMES)}")
    return _BUILDERS[name]()


def _parse_number(mp, x, where):
    """An entry of a user tableau: a number, or a string read by the restricted parser
    (:mod:`integrators.expressions`: numbers, + − × ÷, powers, sqrt and a few functions; no code runs)."""
    from .expressions import parse_number
    if isinstance(x, bool) or not isinstance(x, (int, float, str)):
        raise ValueError(f"{where}: expected a number or a string like '1/2 - sqrt(15)/10', got {x!r}")
    return mp.mpf(parse_number(x, where, _DPS + 5))


def tableau_from_arrays(name, a, b, c, abar=None, d=None, order=None) -> Tableau:
    """A user tableau from arrays (numbers or exact strings such as ``"sqrt(3)/6"``)."""
    mp = _mp()
    s = len(b)
    A = [[_parse_number(mp, x, f"{name}: a[{i}][{j}]") for j, x in enumerate(row)] for i, row in enumerate(a)]
    if len(A) != s or any(len(r) != s for r in A):
        raise ValueError(f"{name}: a must be {s}×{s} to match b")
    Ab = None if abar is None else [[_parse_number(mp, x, f"{name}: abar[{i}][{j}]") for j, x in enumerate(row)]
                                    for i, row in enumerate(abar)]
    return make_tableau(
        name, A, [_parse_number(mp, x, f"{name}: b[{i}]") for i, x in enumerate(b)],
        [_parse_number(mp, x, f"{name}: c[{i}]") for i, x in enumerate(c)],
        abar=Ab, d=None if d is None else [_parse_number(mp, x, f"{name}: d[{i}]") for i, x in enumerate(d)],
        order=order, mp=mp)


def _singular(A, s) -> bool:
    """Whether the stage matrix a is singular for the solve: its condition number above 1e12 (a
    determinant test would call a = I/100 with 50 stages singular: det 1e-100)."""
    import numpy as np
    with np.errstate(all="ignore"):
        cond = np.linalg.cond(np.array([[float(A[i, j]) for j in range(s)] for i in range(s)]))
    return not np.isfinite(cond) or cond > 1e12


def tableau_from_file(path) -> Tableau:
    """Load a tableau from TOML: keys ``a``, ``b``, ``c``; optional ``name``, ``abar``, ``d``, ``order``.

    Numbers may be TOML floats or strings evaluated exactly, e.g. ``"1/2 - sqrt(15)/10"``.
    """
    from .expressions import load_toml
    path = Path(path)
    if path.exists() and not path.is_file():      # a FIFO would be read for ever
        raise ValueError(f"tableau file '{path}' is not a regular file")
    try:
        data = load_toml(path.read_text(encoding="utf-8"), f"tableau file '{path}'")
    except FileNotFoundError:
        raise ValueError(f"tableau file '{path}' not found") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"tableau file '{path}' is not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    except OSError as exc:
        raise ValueError(f"cannot read tableau file '{path}': {exc.strerror or exc}") from None
    allowed = {"name", "a", "b", "c", "abar", "d", "order"}
    extra = set(data) - allowed
    if extra:
        raise ValueError(f"tableau file '{path}': unknown key '{sorted(extra)[0]}' (allowed: {', '.join(sorted(allowed))})")
    for key in ("a", "b", "c"):
        if key not in data:
            raise ValueError(f"tableau file '{path}': missing key '{key}'")
    name = data.get("name", path.stem)
    if not isinstance(name, str):
        raise ValueError(f"tableau file '{path}': 'name' must be a string, got {name!r}")
    clash = next((t for t in TABLEAU_NAMES if t.casefold() == name.strip().casefold()), None)
    if clash is not None:                 # it would run, and be written and plotted, as the built-in
        raise ValueError(f"tableau file '{path}' is named '{name}', the name of the built-in tableau {clash}: "
                         "give it a name of its own (name = \"...\")"
                         + ("" if "name" in data else ", or rename the file"))
    for key, depth in (("a", 2), ("abar", 2), ("b", 1), ("c", 1), ("d", 1)):
        v = data.get(key)
        if v is not None and not (isinstance(v, list) and (depth == 1 or all(isinstance(r, list) for r in v))):
            raise ValueError(f"tableau file '{path}': '{key}' must be a {'list of lists' if depth == 2 else 'list'}")
    if not data["a"] or not data["b"] or not data["c"]:
        raise ValueError(f"tableau file '{path}': 'a', 'b' and 'c' must be non-empty (a tableau has at least one stage)")
    order = data.get("order")
    if order is not None and (isinstance(order, bool) or not isinstance(order, int) or order < 1):
        raise ValueError(f"tableau file '{path}': 'order' must be a positive integer, got {order!r}")
    try:
        return tableau_from_arrays(name, data["a"], data["b"], data["c"], abar=data.get("abar"), d=data.get("d"),
                                   order=order)
    except ValueError as exc:
        raise ValueError(f"tableau file '{path}': {exc}") from None
