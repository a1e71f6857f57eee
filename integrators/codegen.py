"""The system's compiled point functions: generated Python source from its symbolic ϑ and H, kept in
an on-disk cache and compiled by numba once per machine.

:func:`point_functions` gives the engine (integrators/engine.py) and the kernel
(integrators/kernel/) what they call for a system: ϑ, ϑ_q, ∇H and, for Jacobians, ϑ_qq and ∇²H
at one point (or W points in lanes, or a complex-step point, or in double-double), with common
subexpressions shared, and the domain test.  The source (:func:`generate_source`,
:func:`generate_dd_source`) is written to ``$POINCARE_CACHE/kernels`` (or
``$XDG_CACHE_HOME/poincare``, ``~/.cache/poincare``) under a key of the expressions
(:func:`_key`), so MPI ranks and later runs share it; parameter values are runtime data.  Deleting
the cache is always safe.  :class:`_Printer` is the one printer of generated code: the systems'
numpy functions (integrators/systems.py) and the compiled ones print through it.
"""
from __future__ import annotations

import hashlib
import importlib.util
import itertools
import os
import sys
from pathlib import Path

from sympy.printing.numpy import NumPyPrinter

CODEGEN_VERSION = "7"          # bump when the generated source changes shape (7: codegen._variant)
DD_CODEGEN_VERSION = "4"       # ... and this when the double-double source does


def cache_dir() -> Path:
    """Where generated kernels and numba's compiled code are kept."""
    root = os.environ.get("POINCARE_CACHE")
    if root:
        return Path(root)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "poincare"



class _Printer(NumPyPrinter):
    """numpy printer that prints every symbol by the safe name it was given.

    The generated code never sees a user's names: coordinates become ``_q0, _q1, …``, parameters
    ``_k0, _k1, …`` and common subexpressions ``_x0, …`` (sympy Dummies, so a user symbol
    spelled ``_x0`` cannot be mistaken for one), and numpy is reached as ``numpy.…`` only.  So a
    coordinate called ``q``, ``out`` or ``np``, or a parameter called ``e``, ``pi``, ``sqrt`` or
    ``lambda``, means exactly that symbol.
    """

    def __init__(self, names):
        super().__init__({"fully_qualified_modules": True, "allow_unknown_functions": False})
        self.names = names

    def _print_Symbol(self, expr):
        try:
            return self.names[expr]
        except KeyError:
            raise ValueError(f"no value for symbol '{expr}'") from None

    _print_Dummy = _print_Symbol


def _key(system) -> str:
    """Hash of what the generated source depends on: coordinates, parameter order, ϑ, H, domain, the
    lane width."""
    import numba
    import sympy
    from .kernel import LANES, WIDE
    parts = [CODEGEN_VERSION, numba.__version__, sys.version.split()[0],
             sympy.srepr(tuple(system.q)), sympy.srepr(tuple(system.params)),
             sympy.srepr(tuple(system.theta_expr)), sympy.srepr(system.H_expr), sympy.srepr(tuple(system.domain_expr))]
    if LANES != 8:
        # the lane functions are compiled for W = LANES: another width is another module (8, the
        # width every cached module was made for, adds nothing, so those keys stay as they were)
        parts.append(f"lanes {LANES}")
    if WIDE != 16:
        parts.append(f"wide {WIDE}")
    if getattr(system, "fields", ()):
        # the generated module compiles integrators/splines.py's evaluation into its own functions,
        # and numba's cache checks only the module's file: a changed splines.py is a new key
        parts.append(Path(__file__).with_name("splines.py").read_text())
        parts.append(Path(__file__).with_name("splines3.py").read_text())
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:20]


class _EnginePrinter:
    """The generated code's printer: :class:`integrators.systems._Printer` with integer powers written
    as products (x**3 → x*x*x, x**-2 → 1.0/(x*x)), so the scalar and the W-lane functions do the same
    IEEE operations (a lane's pow would be a per-lane library call)."""

    _cls = None

    @classmethod
    def make(cls, names):
        if cls._cls is None:
            class Printer(_Printer):
                def _print_Pow(self, expr, rational=False):
                    b, e = expr.as_base_exp()
                    if e.is_Integer and 0 < abs(int(e)) <= 64:
                        base = f"({self._print(b)})"
                        prod = "*".join([base] * abs(int(e)))
                        return f"({prod})" if e > 0 else f"(1.0/({prod}))"
                    return super()._print_Pow(expr, rational)
            cls._cls = Printer
        return cls._cls(names)


class _DDPrinter:
    """The double-double point functions' printer: :class:`_EnginePrinter` with every number that
    is not a small integer written as the nearest double-double, ``_dd(hi, lo)``, from its exact
    value at 50 digits (1/3, π, √2 and 1e-1 as the reals they are, not as doubles)."""

    _cls = None

    @classmethod
    def make(cls, names):
        if cls._cls is None:
            import sympy

            from .ddouble import split

            class Printer(_EnginePrinter.make({}).__class__):
                def _print(self, expr, **kwargs):
                    if isinstance(expr, sympy.Basic) and expr.is_number and expr.is_real is not False:
                        if expr.is_Integer and abs(int(expr)) < 2 ** 53:
                            return f"{int(expr)}.0" if int(expr) >= 0 else f"({int(expr)}.0)"
                        hi, lo = split(str(sympy.N(expr, 60)))
                        return f"_dd({hi!r}, {lo!r})"
                    return super()._print(expr, **kwargs)
            cls._cls = Printer
        return cls._cls(names)


def _field_call(data, P):
    """The generated code's call of a spline field's evaluation: ``field1``, ``field`` or ``field3`` (1-, 2-, 3-D)
    on the data ``data`` after ``P`` parameters."""
    def call(s, *X):
        return f"{('field1', 'field', 'field3')[len(X) - 1]}({data}, {P}, {s}, {', '.join(X)})"
    return call


def field_prelude(exprs, qsyms, params, indent, call):
    """The spline fields (:class:`integrators.splines.Field1`, :class:`~integrators.splines.Field`,
    :class:`integrators.splines3.Field3`) in
    ``exprs`` as plain symbols: returns (the expressions with each derivative of a field at its
    point replaced by a symbol, the lines that evaluate each field at each point once with all the
    derivatives its evaluation returns, {symbol: name}).  ``call`` formats the evaluation:
    ``call(s, X)``, ``call(s, X, Y)`` or ``call(s, X, Y, Z)`` with the coordinates printed.  No fields: the
    expressions unchanged and no lines."""
    import sympy
    from .splines import DERIVATIVES, DERIVATIVES1, Field, Field1
    from .splines3 import DERIVATIVES3, Field3
    exprs = list(exprs)
    atoms = set().union(*(e.atoms(Field1, Field, Field3) for e in exprs)) if exprs else set()
    if not atoms:
        return exprs, [], {}
    names = {s: f"_q{i}" for i, s in enumerate(qsyms)}
    names.update({k: f"_k{i}" for i, k in enumerate(params)})
    pr = _EnginePrinter.make(names)
    groups, subst, fnames, lines = {}, {}, {}, []
    pad = " " * indent
    for atom in sorted(atoms, key=sympy.default_sort_key):
        dim = 3 if isinstance(atom, Field3) else 1 if isinstance(atom, Field1) else 2
        coords, s_, orders = atom.args[:dim], int(atom.args[dim]), tuple(int(o) for o in atom.args[dim + 1:])
        table = {1: tuple((a,) for a in DERIVATIVES1), 2: DERIVATIVES, 3: DERIVATIVES3}[dim]
        if orders not in table:
            top = max(sum(o) for o in table)
            raise ValueError(f"field {s_}: a derivative of order {sum(orders)} (at most {top} are evaluated "
                             f"for a {dim}-D field)")
        key = (coords, s_, dim)
        if key not in groups:
            g = len(groups)
            groups[key] = g
            lines.append(f"{pad}_fv{g} = {call(s_, *(pr.doprint(c) for c in coords))}")
        g = groups[key]
        tag = "".join(str(o) for o in orders)
        sym = sympy.Dummy(f"f{g}_{tag}")
        subst[atom] = sym
        fnames[sym] = f"_f{g}_{tag}"
        lines.append(f"{pad}{fnames[sym]} = _fv{g}[{table.index(orders)}]")
    return [e.xreplace(subst) for e in exprs], lines, fnames


def _body(exprs, targets, qsyms, params, indent, known=(), printer=None, fields=None):
    """Lines ``st(array, index, exprs[i])`` for ``targets[i] = (array, index)``, with common
    subexpressions shared; ``known``: (symbol, expression) pairs already assigned, reused here;
    ``fields``: the names of the symbols :func:`field_prelude` put for the spline fields.
    Returns the lines and the new (symbol, expression) pairs."""
    import sympy
    exprs = list(exprs)
    for sym, e in known:
        exprs = [x.xreplace({e: sym}) for x in exprs]
    subs, reduced = sympy.cse(exprs, symbols=(sympy.Dummy(f"x{i}") for i in itertools.count()),
                              optimizations="basic")
    names = {s: f"_q{i}" for i, s in enumerate(qsyms)}
    names.update({k: f"_k{i}" for i, k in enumerate(params)})
    names.update(fields or {})
    names.update({sym: f"_x{i}" for i, (sym, _) in enumerate(known)})
    names.update({sym: f"_x{len(known) + i}" for i, (sym, _) in enumerate(subs)})
    pr = (printer or _EnginePrinter).make(names)
    pad = " " * indent
    filled = _zero_filled(targets, reduced)
    zero = pr.doprint(sympy.Integer(0))
    lines = [x for a, n in filled.items() for x in (f"{pad}for _i in range({n}):", f"{pad}    st({a}, _i, {zero})")]
    lines += [f"{pad}{names[sym]} = {pr.doprint(e)}" for sym, e in subs]
    lines += [f"{pad}st({a}, {i}, {pr.doprint(e)})" for (a, i), e in zip(targets, reduced)
              if not (a in filled and e.is_zero is True)]
    return lines, list(known) + subs


ZERO_LOOP = 16     # an array with at least this many zero entries is zeroed by a loop, not entry by entry


def _zero_filled(targets, exprs) -> dict:
    """{array: size} of the target arrays written whole (indices 0 … size − 1) with at least ZERO_LOOP
    zero entries: a loop stores their zeros and only the others are written one by one.  The values
    are the same; the code of a system of d coordinates no longer grows as d³ where ϑ_qq is sparse
    (a ring of 32 pendula: 262,144 entries of ϑ_qq, all zero)."""
    by = {}
    for (a, i), e in zip(targets, exprs):
        idx, zeros = by.setdefault(a, ([], [0]))
        idx.append(i)
        zeros[0] += e.is_zero is True
    return {a: len(idx) for a, (idx, zeros) in by.items()
            if zeros[0] >= ZERO_LOOP and sorted(idx) == list(range(len(idx)))}


def generate_source(system) -> str:
    """The Python source of a system's compiled point functions: ``evaluate_real``,
    ``evaluate_complex`` (the same body, for the audit's complex-step derivatives),
    ``evaluate_lanes`` (the same body on W = kernel.LANES interleaved points; None where a function
    has no lane form), ``lanes_wide()`` (which compiles it on W = kernel.WIDE points when first
    called) and ``inside``.  Made once per System object (a scene's validation and the
    engine share it)."""
    cached = getattr(system, "_generated_source", None)
    if cached is None:
        cached = _generate_source(system)
        system._generated_source = cached
    return cached


def _point_body(system, printer=None):
    """The lines of a point function's body: ϑ, ϑ_q, ∇H (``first``), then ϑ_qq, ∇²H (``second``,
    under ``if _need:``).  ϑ, ϑ_q and ∇H come from the same lines whether or not the second
    derivatives are asked for, so their bits never depend on it (a W-lane call computes them for
    every lane when any lane asks)."""
    d = system.d
    q, params = system.q, list(system.params)
    th = [(("_th", i), system.theta_expr[i]) for i in range(d)]
    T = [(("_T", i * d + j), system.dtheta_expr[i][j]) for i in range(d) for j in range(d)]
    dH = [(("_dH", i), system.dH_expr[i]) for i in range(d)]
    TT = [(("_TT", (i * d + j) * d + l), system.ddtheta_expr[i][j][l])
          for i in range(d) for j in range(d) for l in range(d)]
    HH = [(("_HH", i * d + j), system.ddH_expr[i][j]) for i in range(d) for j in range(d)]
    light, extra = th + T + dH, TT + HH
    P = len(params)
    exprs, prelude, fnames = field_prelude([e for _, e in light + extra], q, params, 4,
                                           _field_call("_k", P))
    el, ex = exprs[:len(light)], exprs[len(light):]
    first, known = _body(el, [t for t, _ in light], q, params, 4, printer=printer, fields=fnames)
    second, _ = _body(ex, [t for t, _ in extra], q, params, 8, known, printer=printer, fields=fnames)
    return prelude + first, second


_SIGNATURE = "types.void({p}, _F, types.boolean, {p}, {p}, {p}, {p}, {p})"
_ARGS = "(_qin, _k, _need, _th, _T, _TT, _dH, _HH)"


def _variant(name, body, *, pointer, proto, optional=False, lazy=None):
    """The lines that compile a point function's ``body`` (its lines under the def) as one
    specialisation: values of the numba type ``pointer`` points to, lanes as many as ``proto`` has
    zeros (integers: double or complex; floats: double-double; the lane prototype of integrators.simd).

    Eager (``lazy`` None): the cfunc ``name``, made when the module is imported; ``optional``: None
    where the body has no form for this specialisation (a function without a lane form: the engine
    runs W = 1).  Lazy: a function ``name()`` (``lazy`` its docstring) that compiles it when first
    called, so that a specialisation nobody asks for is never compiled.  Every specialisation has a
    name of its own: numba's cache tells functions apart by name, not by ``proto``."""
    if lazy is None:
        out = ["", f"_A = {pointer}", f"_P = {proto!r}", f"def _{name}{_ARGS}:", *body, ""]
        make = f"cfunc({_SIGNATURE.format(p='_A')}, cache=True, error_model='numpy')(_{name})"
        if not optional:
            return out + [f"{name} = {make}"]
        return out + ["try:", f"    {name} = {make}",
                      "except Exception:     # a function without a lane form: the engine runs W = 1",
                      f"    {name} = None"]
    return ["", f"def {name}():", f'    """{lazy}"""', f"    _P = {proto!r}", "",
            f"    def _{name}_{len(proto)}{_ARGS}:", *["    " + x for x in body], "",
            f"    return cfunc({_SIGNATURE.format(p='_F')}, cache=True, error_model='numpy')(_{name}_{len(proto)})", ""]


def _generate_source(system) -> str:
    from .kernel import LANES, WIDE
    d = system.d
    q, params = system.q, list(system.params)
    first, second = _point_body(system)
    head = [f"    {a} = lanes({a}, 0, _P)" for a in ("_qin", "_th", "_T", "_TT", "_dH", "_HH")]
    head += [f"    _q{i} = ld(_qin, {i})" for i in range(d)] + [f"    _k{i} = _k[{i}]" for i in range(len(params))]
    body = head + first + ["    if _need:", *second, "        pass"]
    lines = [f'"""Generated by integrators.codegen for the system {system.name!r}; do not edit."""',
             "import numpy", "from numba import cfunc, njit, types",
             "from integrators.simd import lanes, ld, st", *_field_import(system), "",
             "_F = types.CPointer(types.float64)"]
    lines += _variant("evaluate_real", body, pointer="types.CPointer(types.float64)", proto=(0,))
    lines += _variant("evaluate_complex", body, pointer="types.CPointer(types.complex128)", proto=(0,))
    lines += _variant("evaluate_lanes", body, pointer="types.CPointer(types.float64)", proto=(0,) * LANES,
                      optional=True)
    # W = kernel.WIDE, compiled when a pair with a small Newton system first asks for it: a system
    # used only with larger ones never pays its compilation
    lines += _variant("lanes_wide", body, pointer="_F", proto=(0,) * WIDE,
                      lazy=f"The W = {WIDE} point function (compiled on first call).")
    scal = [system.H_expr, system.momentum_expr if system.momentum_expr is not None else sympy_zero()]
    lines += ["", "", "@cfunc(types.void(_F, _F, _F), cache=True, error_model='numpy')",
              "def scalars(_qin, _k, _out):",
              "    \"\"\"H and the Noether momentum (0 when the system has none) at one point.\"\"\""]
    lines += [f"    _q{i} = _qin[{i}]" for i in range(d)] + [f"    _k{i} = _k[{i}]" for i in range(len(params))]
    lines += _body_plain(scal, ["_out[0]", "_out[1]"], q, params, 4)
    lines += ["", "", "@cfunc(types.boolean(_F, _F), cache=True, error_model='numpy')",
              "def inside(_qin, _k):",
              f"    for _i in range({d}):",
              "        if not numpy.isfinite(_qin[_i]):",
              "            return False"]
    if system.domain_expr:
        g = [(f"_g{i}", e) for i, e in enumerate(system.domain_expr)]
        gl = _body_plain([e for _, e in g], [t for t, _ in g], q, params, 4)
        lines += [f"    _q{i} = _qin[{i}]" for i in range(d)] + [f"    _k{i} = _k[{i}]" for i in range(len(params))]
        lines += gl
        lines += [f"    if not ({t} > 0):\n        return False" for t, _ in g]
    lines += ["    return True", ""]
    return "\n".join(lines)


def generate_dd_source(system) -> str:
    """The Python source of a system's double-double point function ``evaluate_dd`` (the
    signature of ``evaluate_real`` on pointers to double-doubles; integrators/ddouble.py), its
    constants exact to a double-double (:class:`_DDPrinter`), and ``lanes_dd()``, which compiles the
    same body on W lanes of double-doubles.  A module of its own, made only when a double-double run
    asks for it."""
    from .kernel import LANES
    d = system.d
    q, params = system.q, list(system.params)
    first, second = _point_body(system, _DDPrinter)
    head = [f"    {a} = lanes({a}, 0, _P)" for a in ("_qin", "_th", "_T", "_TT", "_dH", "_HH")]
    # the parameters as double-doubles (their doubles exactly): a product of two parameters must not
    # round to double first
    kdd = [f"    _k{i} = _dd(_k[{i}], 0.0)" for i in range(len(params))]
    head += [f"    _q{i} = ld(_qin, {i})" for i in range(d)] + kdd
    scal = [system.H_expr, system.momentum_expr if system.momentum_expr is not None else sympy_zero()]
    P = len(params)
    scal, sprelude, sfields = field_prelude(scal, q, params, 4, _field_call("_k", P))
    sbody, _ = _body(scal, [("_out", 0), ("_out", 1)], q, params, 4, printer=_DDPrinter, fields=sfields)
    sbody = sprelude + sbody
    lines = [f'"""Generated by integrators.codegen for the system {system.name!r} (double-double); do not edit."""',
             "import numpy", "from numba import cfunc, types",
             "from integrators.ddouble import dd as _dd, dd_t", "from integrators.simd import lanes, ld, st",
             *_field_import(system), "",
             "_F = types.CPointer(types.float64)"]
    body = [*head, *first, "    if _need:", *second, "        pass"]
    lines += _variant("evaluate_dd", body, pointer="types.CPointer(dd_t)", proto=(0.0,))
    lines += ["", "", "def _scalars_dd(_qin, _k, _out):",
             "    \"\"\"H and the Noether momentum (0 when the system has none) at one point, in double-double.\"\"\"",
             "    _qin = lanes(_qin, 0, _P)", "    _out = lanes(_out, 0, _P)",
             *[f"    _q{i} = ld(_qin, {i})" for i in range(d)], *kdd,
             *sbody, "",
             "scalars_dd = cfunc(types.void(_A, _F, _A), cache=True, error_model='numpy')(_scalars_dd)", ""]
    # W = kernel.LANES double-doubles (integrators.simd's DDVec), compiled when a double-double
    # run of at least W points asks for it
    lines += _variant("lanes_dd", body, pointer="_F", proto=(0.0,) * LANES,
                      lazy="The W-lane double-double point function (compiled on first call).")
    return "\n".join(lines)


def _field_import(system):
    """The generated module's import of the spline evaluation, for a system that uses fields."""
    return (["from integrators.splines import field, field1", "from integrators.splines3 import field3"]
            if getattr(system, "fields", ()) else [])


def sympy_zero():
    import sympy
    return sympy.Float(0.0)


def _body_plain(exprs, targets, qsyms, params, indent):
    """Lines ``targets[i] = exprs[i]`` (scalar names), with common subexpressions shared."""
    import sympy
    P = len(params)
    exprs, prelude, fnames = field_prelude(list(exprs), qsyms, params, indent,
                                           _field_call("_k", P))
    subs, reduced = sympy.cse(list(exprs), symbols=(sympy.Dummy(f"x{i}") for i in itertools.count()),
                              optimizations="basic")
    names = {s: f"_q{i}" for i, s in enumerate(qsyms)}
    names.update({k: f"_k{i}" for i, k in enumerate(params)})
    names.update(fnames)
    names.update({sym: f"_x{i}" for i, (sym, _) in enumerate(subs)})
    pr = _Printer(names)
    pad = " " * indent
    return prelude + [f"{pad}{names[sym]} = {pr.doprint(e)}" for sym, e in subs] + \
        [f"{pad}{t} = {pr.doprint(e)}" for t, e in zip(targets, reduced)]


_LOADED = {}


class CacheError(ValueError):
    """The engine's code cache ($POINCARE_CACHE) cannot be written: one line naming it."""


def _write_and_import(path: Path, source, module_name: str):
    """The module ``module_name`` from ``path``, first written there from ``source()`` when it is not
    (atomically, so MPI ranks generating together never see half a file)."""
    folder = path.parent
    if not path.exists():
        tmp = folder / f".{path.stem}.{os.getpid()}.tmp"
        try:
            folder.mkdir(parents=True, exist_ok=True)
            tmp.write_text(source())
            os.replace(tmp, path)
        except OSError as exc:
            where = "$POINCARE_CACHE" if os.environ.get("POINCARE_CACHE") else "the engine's cache"
            raise CacheError(f"cannot write {where} '{folder}' ({exc.strerror or exc}): the generated code of "
                             "each system is kept there; set POINCARE_CACHE to a folder you can write") from None
    spec = importlib.util.spec_from_file_location(module_name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod         # numba's cache finds a function's module by name
    spec.loader.exec_module(mod)
    return mod


def load_module(system, precision="double"):
    """The generated module of ``system`` (``precision`` 'double' or 'double-double'): written to the
    cache once, imported once per process.  Its ``__file__`` is the generated source (the cost model
    reads its operations)."""
    key = getattr(system, "_engine_key", None)
    if key is None:
        key = system._engine_key = _key(system)       # (sympy's srepr of every expression: once)
    if precision != "double":
        key = f"{key}_dd{DD_CODEGEN_VERSION}"
    if key not in _LOADED:
        generate = generate_source if precision == "double" else generate_dd_source
        _LOADED[key] = _write_and_import(cache_dir() / "kernels" / f"system_{key}.py", lambda: generate(system),
                                         f"poincare_system_{key}")
    return _LOADED[key]


# -- a projection's own post term ------------------------------------------------------------------

POST_VERSION = "1"             # bump when the generated entry changes shape
_POSTS = {}                    # key -> the compiled post term, read by the generated module on import

_POST_SOURCE = '''"""Generated by integrators.codegen: the step kernel's entry for the post term {name};
do not edit.  Its key covers the source of {module}, the compiled modules of integrators and the
numba and Python versions."""
from numba import njit

from integrators.codegen import _POSTS
from integrators.kernel import blocks
from integrators.kernel.projection import token

_post = token(_POSTS[{key!r}])
_advance = blocks.advance


def _entry(ev, inside, pair, span, st_, shape, outputs):
    _advance(ev, inside, _post(), pair, span, st_, shape, outputs)


advance = njit(cache=True)(_entry)
'''


def _post_key(fn):
    """Hash of what a post term's compiled kernel depends on: the source of the module that defines it
    (its whole file, so helpers beside it count; its own source where it has no file), its name, the
    compiled modules of this package (their time stamps and sizes, as for the package's own cache) and
    the numba and Python versions.  None where no source can be read (a function made by ``exec``)."""
    import inspect
    import numba
    from .numba_cache import package_stamp
    f = getattr(fn, "py_func", None)
    if f is None:
        return None
    try:
        mod = inspect.getmodule(f)
        src = inspect.getsource(mod) if mod is not None and getattr(mod, "__file__", None) else inspect.getsource(f)
    except (OSError, TypeError):
        return None
    parts = [POST_VERSION, numba.__version__, sys.version.split()[0], f.__module__, f.__qualname__, src,
             repr(package_stamp())]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:20]


def post_entry(fn):
    """The cached kernel entry of a projection's own compiled post term ``fn``:
    ``advance(ev, inside, pair, span, st_, shape, outputs)``, :func:`integrators.kernel.advance` with
    ``fn`` as its post term, compiled once per machine and signature like the paper's (a generated
    module in ``$POINCARE_CACHE/kernels`` hands ``fn`` to the kernel as a type,
    :class:`integrators.kernel.projection.PostTerm`, so the compiled code holds no address of this
    process).  None where ``fn``'s source cannot be read: the engine then compiles it in every process.
    A post term that calls functions of another module of one's own is keyed on its own module's
    source only (numba's own cache has the same reach): after changing those, delete the cache."""
    key = _post_key(fn)
    if key is None:
        return None
    if key not in _LOADED:
        _POSTS[key] = fn
        name = f"{fn.py_func.__module__}.{fn.py_func.__qualname__}"
        _LOADED[key] = _write_and_import(
            cache_dir() / "kernels" / f"post_{key}.py",
            lambda: _POST_SOURCE.format(name=name, module=fn.py_func.__module__, key=key), f"poincare_post_{key}")
    return _LOADED[key].advance


def scalar_function(system):
    """The compiled ``scalars(q, k, out)`` of ``system``: out = [H(q), momentum(q) or 0]."""
    return load_module(system).scalars


def point_functions(system, complex_step=False, lanes=1, precision="double"):
    """The compiled (evaluate, inside) pair of ``system`` (generated and compiled once per machine)
    for ``lanes`` = W: 1, the scalar real or complex-step evaluation; kernel.LANES or kernel.WIDE,
    the W-lane one (real only; None where the system has a function without a lane form).  With
    ``precision="double-double"`` the scalar double-double one (its own module,
    :func:`generate_dd_source`), or its LANES-lane one."""
    from .kernel import LANES, WIDE
    if isinstance(lanes, bool) or lanes not in ((1, LANES) if precision == "double-double" else (1, LANES, WIDE)):
        raise ValueError(f"lanes must be a lane width W (1, {LANES}{'' if precision == 'double-double' else f' or {WIDE}'}), "
                         f"got {lanes!r}")
    if precision == "double-double":
        mod = load_module(system, "double-double")
        if lanes == 1:
            return mod.evaluate_dd, load_module(system).inside
        if not hasattr(mod, "_lanes_dd"):
            try:
                mod._lanes_dd = mod.lanes_dd()
            except Exception:       # a function without a lane form: the engine runs W = 1
                mod._lanes_dd = None
        return mod._lanes_dd, load_module(system).inside
    mod = load_module(system)
    if lanes == WIDE:
        if not hasattr(mod, "_lanes_wide"):
            try:
                mod._lanes_wide = mod.lanes_wide()
            except Exception:       # a function without a lane form: the engine runs W = 1
                mod._lanes_wide = None
        return mod._lanes_wide, mod.inside
    ev = mod.evaluate_lanes if lanes == LANES else (mod.evaluate_complex if complex_step else mod.evaluate_real)
    return ev, mod.inside


# -- the state and the engine --------------------------------------------------------------------
