"""The five projections of sec:projection as records: one row of the paper's table each, read by
the compiled kernel (:mod:`integrators.kernel`) and by the numpy reference.

With φ(q, p) = p − ϑ(q) the projection term h Ω⁻¹∇φᵀλ of eq:projector moves a
point by (q, p) ↦ (q + hλ, p + h ϑ_q(x)ᵀλ), where x is where ϑ_q is evaluated.
We write Λ = hλ.  The five choices differ only where the paper says they do
(table in sec:projection, σ = R(∞) of the tableau):

=============  ============================  ====================================  ==================
projection     perturbation (before Ψ_h)     projection (after Ψ_h)                solved
=============  ============================  ====================================  ==================
none           —                             —                                     Ψ_h alone
standard       —                             + Λ_{n+1}, ϑ_q at q_{n+1}             Ψ_h, then Λ
               (eq:orthogonal_projection)
symmetric      + Λ, ϑ_q at q_n               + σΛ, ϑ_q at q_{n+1}                  Ψ_h and Λ together
               (eq:symmetric_symplectic_projection)
symplectic     + Λ_n (known), ϑ_q at q_n      + σΛ_{n+1}, ϑ_q at q_{n+1}            Ψ_h, then Λ_{n+1}
               (eq:symplectic_projection)
midpoint       + Λ, ϑ_q at q̄_{n+1/2}          + σΛ, ϑ_q at q̄_{n+1/2}                Ψ_h and Λ together
               (eq:symplectic_midpoint_projection)
=============  ============================  ====================================  ==================

q̄_{n+1/2} = (q̄_n + q̄_{n+1})/2 is the midpoint of the unprojected step.  For the
midpoint projection the paper's eq:symplectic_midpoint_projection_post prints no
σ while its table has R(∞)λ_{n+1/2}; we follow the table (as GeometricIntegrators.jl
does): with σ = +1 and R(∞) = −1 (GLRK1, SRK3) the constraint cannot be enforced
at leading order.  Projected methods start every step on the constraint,
p_n = ϑ(q_n) (eq:fibre_derivative): p_0 = ϑ(q_0), then the p_n the last step's
projection left there (``kernel.equations._prepare``); ``none`` carries its own p_n.
"""
from __future__ import annotations

import dataclasses
import math
import re

PROJECTIONS = ("none", "standard", "symmetric", "symplectic", "midpoint")

# where ϑ_q of a projection term is taken, and the perturbation before Ψ_h: none; Λ of this step,
# solved with the stages (symmetric, midpoint); the last step's Λ (symplectic).  The codes the
# kernel reads (integrators.kernel imports them from here)
START, MIDPOINT, END = 0, 1, 2
PRE_NONE, PRE_UNKNOWN, PRE_PREVIOUS = 0, 1, 2


@dataclasses.dataclass(frozen=True)
class Projection:
    """One row of the table above, as data for the compiled kernel.

    pre : the perturbation before Ψ_h — 'none'; 'unknown' (Λ of this step, solved together with
          the stages: a coupled solve); 'previous' (Λ_n of the last step, known)
    pre_at : where ϑ_q of the perturbation is taken: 'start' (q_n) or 'midpoint' (q̄_{n+1/2})
    post : whether a projection follows Ψ_h (and the step starts on the constraint p_n = ϑ(q_n))
    post_at : where ϑ_q of the projection is taken: 'end' (q_{n+1}) or 'midpoint'
    sign : whether the post term's weight σ is multiplied by the tableau's R(∞) ('R_inf', which
          needs |R(∞)| = 1) or not ('one')
    labels : the paper's equations it implements
    weight : the post term's number: σ = weight (× R(∞) under 'R_inf')
    pre_weight, pre_sign : the same for the perturbation before Ψ_h, α = pre_weight (× R(∞) under
          'R_inf'): q̃ = q̄ + αΛ, p̃ = p̄ + α ϑ_q(x_pre)ᵀΛ.  The paper's rows all have α = 1;
          GeometricIntegrators.jl's projections are such weights before and after the step.  Only a
          row with a perturbation (``pre`` not 'none') may set them
    post_term : for a projection solved after Ψ_h (``post`` and not coupled), the compiled function
          whose root in Λ ends the step; None: the paper's, :func:`integrators.kernel.project`
          (ϑ(q̂ + σΛ) = p̂ + σ ϑ_q(q̂ + σΛ)ᵀΛ).  Its contract is in that function's docstring;
          docs/engine.md, "Adding a projection", shows one
    """

    name: str
    pre: str
    pre_at: str
    post: bool
    post_at: str
    sign: str
    labels: tuple
    post_term: object = None
    weight: float = 1.0
    pre_weight: float = 1.0
    pre_sign: str = "one"

    def __post_init__(self):
        # the name is a run file's group name after the tableau's and a '-' (output.split_pair_name):
        # letters, digits and '_' only, so that every pair's name splits back into its two parts
        if not isinstance(self.name, str) or not re.fullmatch(r"[A-Za-z0-9_]+", self.name):
            raise ValueError(f"a projection's name must be letters, digits and '_' (it follows the tableau's name "
                             f"and a '-' in run files), got {self.name!r}")
        for field in ("sign", "pre_sign"):
            if getattr(self, field) not in ("one", "R_inf"):
                raise ValueError(f"projection '{self.name}': {field} must be 'one' or 'R_inf', got {getattr(self, field)!r}")
        for field in ("weight", "pre_weight"):
            x = getattr(self, field)
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise ValueError(f"projection '{self.name}': {field} must be a finite number, got {x!r}")
        if self.pre == "none" and (self.pre_weight != 1.0 or self.pre_sign != "one"):
            raise ValueError(f"projection '{self.name}' has no perturbation before the step (pre 'none'): "
                             "its pre_weight and pre_sign cannot be set")

    @property
    def coupled(self) -> bool:
        return self.pre == "unknown"

    def sigma(self, tableau) -> float:
        """σ, the post term's weight for ``tableau``."""
        return float(self.weight) * (1.0 if self.sign == "one" else float(tableau.R_inf))

    def alpha(self, tableau) -> float:
        """α, the weight of the perturbation before Ψ_h for ``tableau``."""
        return float(self.pre_weight) * (1.0 if self.pre_sign == "one" else float(tableau.R_inf))

    def codes(self, tableau) -> tuple:
        """(pre, pre_at, post, post_at, σ, α) as the kernel reads them (:class:`integrators.kernel.Plan`)."""
        pre = {"none": PRE_NONE, "unknown": PRE_UNKNOWN, "previous": PRE_PREVIOUS}[self.pre]
        at = {"start": START, "midpoint": MIDPOINT, "end": END}
        return (pre, at[self.pre_at], bool(self.post), at[self.post_at], self.sigma(tableau), self.alpha(tableau))


RECORDS = {r.name: r for r in (
    Projection("none", "none", "start", False, "end", "one", ("eq:vprk",)),
    Projection("standard", "none", "start", True, "end", "one", ("eq:orthogonal_projection",)),
    Projection("symmetric", "unknown", "start", True, "end", "R_inf",
               ("eq:symmetric_projection_pre", "eq:symmetric_projection_post")),
    Projection("symplectic", "previous", "start", True, "end", "R_inf",
               ("eq:symplectic_projection_pre", "eq:symplectic_projection_post")),
    Projection("midpoint", "unknown", "midpoint", True, "midpoint", "R_inf",
               ("eq:symplectic_midpoint_projection_pre", "eq:symplectic_midpoint_projection_post")),
)}


def names() -> tuple:
    """The projections a pair may name, the rows of :data:`RECORDS` as they are now (a row added
    there is named by ``integrate``, scenes, the audit and run files alike)."""
    return tuple(RECORDS)


def projection_record(name) -> Projection:
    """The record of the projection ``name`` (a name in RECORDS), or ``name`` itself if it is a
    :class:`Projection`."""
    if isinstance(name, Projection):
        return name
    if name not in RECORDS:
        raise ValueError(f"unknown projection '{name}'; choose one of {', '.join(RECORDS)}")
    return RECORDS[name]


def admission(tableau, projection):
    """None if ``projection`` can be used with ``tableau``, else the one-line reason.

    The one place of this rule (the engine, scenes and the audit all ask here): the projections
    whose sign is σ = R(∞) need |R(∞)| = 1 (the table in sec:projection).
    """
    if not isinstance(projection, Projection) and projection not in RECORDS:
        return f"unknown projection '{projection}'; choose one of {', '.join(RECORDS)}"
    rec = projection_record(projection)
    if rec.post_term is not None and (not rec.post or rec.coupled):
        return f"projection '{rec.name}' has a post term but is not solved after Ψ_h (post, not coupled)"
    if "R_inf" in (rec.sign, rec.pre_sign) and abs(tableau.R_inf) != 1.0:
        return (f"projection '{rec.name}' needs |R(∞)| = 1 but {tableau.name} has R(∞) = {tableau.R_inf:.17g}; "
                "use 'none' or 'standard'")
    return None
