"""A restricted parser for the expressions that data files carry (tableau entries, scene strings).

Nothing read from a file is ever handed to ``eval``, ``exec`` or ``sympy.sympify``: the text is
parsed by Python's :mod:`ast` (which builds a tree and runs nothing) and the tree is walked
here, accepting only

* numbers (integers are kept exact, so ``1/3`` is the rational 1/3, not a rounded float),
* the operators ``+ − × ÷`` and powers (``**`` or ``^``), unary ``±``, parentheses,
* the names the caller allows (coordinates and parameters of a system; none for a tableau),
* the constants ``pi`` and ``E`` and the functions in :data:`FUNCTIONS`, unless a caller's
  own name shadows them (a parameter called ``pi`` is that parameter).

Anything else — attribute access, subscripts, calls of other names, lambdas, comprehensions,
strings, keyword arguments — is an :class:`ExpressionError` that names the key it came from.
Powers with a numeric exponent are limited to |exponent| ≤ :data:`MAX_EXPONENT` (and numeric powers
to 2^:data:`MAX_BITS` in size) and the text
to :data:`MAX_LENGTH` characters, so no file can make the parser compute for ever.
"""
from __future__ import annotations

import ast
import math
import tomllib

import sympy

MAX_LENGTH = 2000
MAX_EXPONENT = 64
MAX_BITS = 4096
MAX_DEPTH = 100          # operators and calls nested in one expression
MAX_TOML_DEPTH = 32      # arrays and inline tables nested in a data file

FUNCTIONS = {
    "sqrt": sympy.sqrt, "exp": sympy.exp, "log": sympy.log, "sin": sympy.sin, "cos": sympy.cos,
    "tan": sympy.tan, "asin": sympy.asin, "acos": sympy.acos, "atan": sympy.atan, "atan2": sympy.atan2,
    "sinh": sympy.sinh, "cosh": sympy.cosh, "tanh": sympy.tanh, "abs": sympy.Abs, "Abs": sympy.Abs,
    "Rational": sympy.Rational,
}
CONSTANTS = {"pi": sympy.pi, "E": sympy.E}


class ExpressionError(ValueError):
    """An expression that is not allowed or not well formed; the message names its key."""


_BINARY = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
           ast.Div: lambda a, b: a / b, ast.Pow: None}


def parse_expression(text, where: str, names: dict | None = None):
    """The sympy expression of ``text``; ``names`` maps the allowed identifiers to sympy objects.

    ``where`` is the key the text came from (e.g. ``"tableau.toml: a[0][2]"``); every error
    message starts with it.
    """
    names = dict(names or {})
    if isinstance(text, bool):
        raise ExpressionError(f"{where}: expected a number or an expression, got {text!r}")
    if isinstance(text, int):
        return sympy.Integer(text)
    if isinstance(text, float):
        return sympy.Rational(repr(text)) if text == text and abs(text) != float("inf") else _bad(where, text)
    if not isinstance(text, str):
        raise ExpressionError(f"{where}: expected a number or an expression string, got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"{where}: expression longer than {MAX_LENGTH} characters")
    src = text.strip().replace("^", "**")                                  # x^2 is a power, as in sympy
    try:
        tree = ast.parse(src, mode="eval")
    except SyntaxError as exc:
        if "nested" in str(exc):             # Python's own limit on parentheses (200)
            raise ExpressionError(f"{where}: the expression is nested more than {MAX_DEPTH} deep") from None
        shown = text if len(text) <= 80 else text[:60] + f"… ({len(text)} characters)"
        raise ExpressionError(f"{where}: cannot read '{shown}' as an expression") from None
    except (RecursionError, MemoryError):
        raise ExpressionError(f"{where}: the expression is nested more than {MAX_DEPTH} deep") from None
    try:
        walker = _Walker(where, text, names)
        walker.src = src
        e = walker.visit(tree.body)
    except RecursionError:
        raise ExpressionError(f"{where}: the expression is nested more than {MAX_DEPTH} deep") from None
    for a in e.atoms(sympy.Number):          # 1e308*1e308 is one exact number: it must be a double
        try:
            if math.isinf(float(a)):
                raise OverflowError
        except OverflowError:
            raise ExpressionError(f"{where}: '{text}' holds a number beyond the range of a double "
                                  f"(|x| > {1.7976931348623157e308:.4g})") from None
        except TypeError:
            continue
        if a != 0 and abs(float(a)) < 2.2250738585072014e-308:    # 10^-420 would be 0 (or lose digits)
            raise ExpressionError(f"{where}: '{text}' holds a number below the range of a double's normal "
                                  f"numbers (0 < |x| < 2.225e-308): it would round to {float(a):g}") from None
    return e


def load_toml(text: str, where: str) -> dict:
    """``tomllib.loads(text)`` with arrays and inline tables nested at most :data:`MAX_TOML_DEPTH`
    deep (deeper ones would exhaust the reader's recursion): a ValueError starting with ``where``
    for that and for TOML that does not read."""
    depth = _toml_depth(text)
    if depth > MAX_TOML_DEPTH:
        raise ValueError(f"{where}: not valid here: arrays or inline tables nested {depth} deep "
                         f"(at most {MAX_TOML_DEPTH})")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{where}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ValueError(f"{where}: not valid here: arrays or inline tables nested too deep "
                         f"(at most {MAX_TOML_DEPTH})") from None


def _toml_depth(text: str) -> int:
    """The deepest nesting of brackets and braces in TOML ``text`` outside strings and comments."""
    depth = most = 0
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif c in "\"'":
            quote = text[i:i + 3] if text[i:i + 3] in ('"""', "'''") else c
            i += len(quote)
            while i < n and not text.startswith(quote, i):
                i += 2 if (text[i] == "\\" and quote[0] == '"') else 1
            i += len(quote)
            continue
        elif c in "[{":
            depth += 1
            most = max(most, depth)
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    return most


def _bad(where, text):
    raise ExpressionError(f"{where}: '{text}' is not a finite number")


class _Walker:
    def __init__(self, where, text, names):
        self.where, self.text, self.names = where, text, names

    def fail(self, what):
        raise ExpressionError(f"{self.where}: {what} is not allowed in '{self.text}' "
                              "(numbers, + - * / **, parentheses and the documented functions only)")

    def visit(self, node, depth=0):
        if depth > MAX_DEPTH:
            raise ExpressionError(f"{self.where}: the expression is nested more than {MAX_DEPTH} deep")
        depth += 1
        if isinstance(node, ast.Constant):
            v = node.value
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                self.fail(f"the literal {v!r}")
            if isinstance(v, float) and not math.isfinite(v):
                raise ExpressionError(f"{self.where}: the number in '{self.text}' is too large for a double "
                                      "(it reads as infinity)")
            if isinstance(v, float) and abs(v) < 2.2250738585072014e-308:    # 1e-420 reads as 0.0
                literal = (ast.get_source_segment(getattr(self, "src", ""), node) or "").lower()
                if any(c in "123456789" for c in literal.split("e")[0]):
                    raise ExpressionError(f"{self.where}: the number {literal} in '{self.text}' is below the range "
                                          f"of a double's normal numbers (0 < |x| < 2.225e-308): it reads as {v:g}")
            return sympy.Integer(v) if isinstance(v, int) else sympy.Rational(repr(v))
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return self.names[node.id]
            if node.id in CONSTANTS:
                return CONSTANTS[node.id]
            if node.id in FUNCTIONS:
                self.fail(f"the function name '{node.id}' without a call")
            allowed = sorted(self.names)
            raise ExpressionError(f"{self.where}: unknown name '{node.id}' in '{self.text}'"
                                  + (f" (known: {', '.join(allowed)})" if allowed else ""))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            v = self.visit(node.operand, depth)
            return -v if isinstance(node.op, ast.USub) else v
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            left, right = self.visit(node.left, depth), self.visit(node.right, depth)
            if isinstance(node.op, ast.Pow):
                if right.is_number and not (abs(right) <= MAX_EXPONENT):
                    self.fail(f"the exponent {right}")
                if left.is_number and right.is_number and left != 0 and \
                        abs(float(sympy.N(sympy.log(abs(left), 2)))) * abs(float(sympy.N(right))) > MAX_BITS:
                    self.fail(f"a numeric power larger than 2^{MAX_BITS}")
                return left ** right
            return _BINARY[type(node.op)](left, right)
        if isinstance(node, ast.Call):
            fn = node.func
            if not isinstance(fn, ast.Name) or fn.id in self.names or fn.id not in FUNCTIONS:
                self.fail(f"the call '{ast.unparse(fn)}(…)'")
            if node.keywords:
                self.fail("a keyword argument")
            args = [self.visit(a, depth) for a in node.args]
            try:
                return FUNCTIONS[fn.id](*args)
            except (TypeError, ValueError) as exc:
                raise ExpressionError(f"{self.where}: {fn.id}() in '{self.text}': {exc}") from None
        self.fail(f"'{ast.unparse(node)}'")


def parse_number(text, where: str, digits: int):
    """A finite real number from ``text`` as an mpmath-ready decimal string of ``digits`` digits."""
    e = parse_expression(text, where)
    if not e.is_number:
        raise ExpressionError(f"{where}: '{text}' is not a number")
    if e.has(sympy.zoo, sympy.nan, sympy.oo, -sympy.oo) or e.is_finite is False:
        raise ExpressionError(f"{where}: '{text}' is not a finite number (division by zero?)")
    v = sympy.N(e, digits)
    if not v.is_real or not v.is_finite:
        raise ExpressionError(f"{where}: '{text}' is not a finite real number")
    return str(v)
