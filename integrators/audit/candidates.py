"""Candidates of the audit: built-in or file tableaus with a projection, or a user's step map
(the contract is in :mod:`integrators.audit`)."""
from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np


@dataclasses.dataclass
class Candidate:
    """A step map to audit.  ``reads`` says which inputs besides q it uses (None: detect)."""

    name: str
    step: Callable
    kind: str                       # 'pair' (built-in tableau/file + projection) or 'function'
    tableau: object = None
    projection: str | None = None
    reads: set | None = None        # inputs besides q the map uses; None: detect from the Jacobian


def stepper_map(tableau, projection) -> Callable:
    """The step map of a (tableau, projection) pair as a pure batched function.

    One call is one step of the compiled engine from the vector-field guess (no history): the
    Newton solution does not depend on the guess beyond its tolerance.  Accepts complex arrays:
    the engine's complex128 specialisation carries the derivatives (complex step) through the
    Newton solve.  A point whose step fails is NaN.  Real points take the engine's vector path
    even when there are fewer than its W = kernel.LANES lanes (a point's bits do not depend on W):
    an audit on a few points, such as the check :func:`integrators.audit.discrimination` makes
    before every run, then compiles no scalar kernel beside the one the run compiles.
    """
    from ..engine import Engine
    from ..kernel import LANES
    cache = {}

    def step(q, p, lam, h, system):
        key = (id(system), float(h))
        if key not in cache:
            cache[key] = Engine(system, tableau, projection, h)
        engine = cache[key]
        q, p, lam = (np.asarray(x) for x in (q, p, lam))
        dtype = np.complex128 if any(np.iscomplexobj(x) for x in (q, p, lam)) else np.float64
        st = engine.state(q, p, lam, dtype=dtype)
        engine.advance(st, 1, 1, lanes=engine.lanes_for(max(q.shape[0], LANES)))
        q1, p1, lam1 = st.q, st.p, st.Lam / h
        bad = ~st.live
        for x in (q1, p1, lam1):
            x[bad] = np.nan
        return q1, p1, lam1

    return step


def load_function(spec: str) -> Callable:
    """``module:function`` or ``path/to/file.py:function`` -> the callable (ValueError if not found)."""
    from ..service.plugins import load_callable
    return load_callable(spec, "step map", confined=False)   # typed on the command line


def candidates_from(spec: str, projections=None, what="candidate") -> list[Candidate]:
    """Candidates named by a CLI argument: a built-in tableau, a tableau TOML file, or module:function.

    A tableau is audited with every projection in ``projections`` that it admits (default: all
    five; the symmetric, symplectic and midpoint projections need |R(∞)| = 1).
    """
    from ..projections import PROJECTIONS, admission, names
    from ..tableaus import TABLEAU_NAMES, tableau, tableau_from_file
    if spec in TABLEAU_NAMES:
        tab = tableau(spec)
    elif spec.endswith(".toml"):
        tab = tableau_from_file(spec)
    elif ":" in spec:
        fn = load_function(spec)
        if projections:
            raise ValueError("--projection applies to tableaus only, not to a step function")
        return [Candidate(spec.rsplit(":", 1)[1], fn, "function")]
    else:
        raise ValueError(f"{what} '{spec}' is not a built-in tableau ({', '.join(TABLEAU_NAMES)}), "
                         "a .toml tableau file, or module:function")
    wanted = list(projections) if projections else list(PROJECTIONS)
    for p in wanted:
        if p not in names():
            raise ValueError(f"unknown projection '{p}'; choose from {', '.join(names())}")
    ok = [p for p in wanted if admission(tab, p) is None]
    if not ok:
        raise ValueError(f"{tab.name} has R(∞) = {tab.R_inf:g}: none of {', '.join(wanted)} applies")
    return [pair_candidate(tab, p) for p in ok]


def pair_candidate(tab, projection) -> Candidate:
    """A built-in or file tableau with a projection.  Only an unprojected map reads p_n (the projected
    maps start from p_n = ϑ(q_n)) and only one whose perturbation is the last step's Λ_n (the
    symplectic projection) reads λ_n (the others take it as a guess): read off the projection's record."""
    from ..projections import projection_record
    rec = projection_record(projection)
    reads = ({"p"} if not rec.post else set()) | ({"lam"} if rec.pre == "previous" else set())
    from ..service.output import pair_name
    return Candidate(pair_name(tab.name, projection), stepper_map(tab, projection), "pair", tab, projection, reads)


def _call(step, q, p, lam, h, system):
    out = step(q, p, lam, h, system)
    if not (isinstance(out, tuple) and len(out) == 3):
        raise ValueError("the step map must return a tuple (q, p, lam)")
    out = tuple(np.asarray(x) for x in out)
    if any(x.shape != np.shape(q) for x in out):
        raise ValueError(f"the step map returned arrays of shapes {', '.join(str(x.shape) for x in out)} for "
                         f"inputs of shape {np.shape(q)} (it must return q, p, lam of the inputs' shape)")
    return out
