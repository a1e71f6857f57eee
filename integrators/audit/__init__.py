"""Symplecticity audit of a one-step map (SPEC Part 4): which forms does it preserve?

A *candidate* is a batched one-step map

    step(q, p, lam, h, system) -> (q_new, p_new, lam_new)

on arrays of shape (n, d) (n points, d = system.d), with ``h`` a float and ``system`` an
:class:`integrators.System`.  It must be a pure function of its arguments (no state kept
between calls: the audit calls it on perturbed copies of the same points), advance every
row independently, and return new arrays.  ``lam`` is the Lagrange multiplier λ of the
projections (Λ = hλ); a map without one returns it unchanged or as zeros.  A map may mark a
failed point by returning non-finite values in its row.  If the map also accepts complex
arrays (written with plain arithmetic, no ``float()``/``abs`` on inputs), the audit
differentiates it by complex step; otherwise by 8th-order central differences.

Built-in (tableau, projection) pairs and tableau files are wrapped into such maps by
:func:`stepper_map`.

Two measurements (docs/audit.md has the thresholds and the table for the built-ins):

* **Invariant drift.**  The candidate advances the loop and surface of a scene; I₁ and I₂ in
  the scene's forms give e(t) = |I(t) − I(0)|/|I(0)|.  Reported: max e, the drift rate (slope
  of a least-squares line through e(t)), the growth law of e (invariants.growth: its law, exponent
  α of e ∝ t^α and the time from which it holds) and a verdict:

  - ``broke down``: a sample point failed before the end;
  - ``under-resolved``: the set's resolution monitor (invariants.forms) exceeded ``RESOLVED`` at
    some output and max e is above round-off, so e may be sampling error: refine the loop or surface;
  - otherwise the growth law in the audit's words: ``round-off`` (max e ≤ ``ROUNDOFF``),
    ``bounded``, ``random walk``, ``drifting`` (linear), ``growing`` (faster than linear), or
    ``undetermined`` (fewer than 5 outputs).  A verdict whose max e lies within ``NEAR_FLOOR``
    (10×) above ``ROUNDOFF`` says so (``near_floor`` in the JSON): there a drifting or growing law
    may be round-off's rather than the method's.

* **One-step symplecticity defect.**  At sample points x = (q, ϑ(q), λ) the Jacobian DΦ of
  x ↦ Φ(x) gives, per form, the pull-back defect (relative to the size of the terms summed,
  so that round-off reads ~1e-16 whatever the scale):

  - noncanonical: DΦ_qᵀ Ω̄(q') DΦ_q − Ω̄(q), DΦ_q = dq'/dq along the constraint p = ϑ(q);
  - canonical: Bᵀ J B − J on (q, p), B = ∂(q', p')/∂(q, p), J the matrix of dp∧dq (only for maps
    that read p_n: a projected map starts from p_n = ϑ(q_n), on which the canonical and the
    noncanonical form agree);
  - corrected: Cᵀ Ω_λ(q', λ') C − Ω_λ(q, λ) on (q, λ), C = ∂(q', λ')/∂(q, λ), Ω_λ of
    eq:symplectic_projection_two_form (our sign, docs/conventions.md) (only for maps that
    read λ_n: the symplectic projection).

  for h, h/2, h/4, …; the order p of defect ∝ h^p is fitted over the values above the floor.

* **Canonical maps in any dimension** (:func:`audit_map`, :mod:`.maps`): ``step(x, v, h) -> (x, v)``
  with nothing symbolic, the defect matrix-free (random probe pairs, two Jacobian–vector products
  each) and periodic positions; shipped examples in :mod:`.examples` (pendulum arrays, 1-D PIC).

* **Whether the scene can tell at all** (:func:`discrimination`): where even maps that are not
  symplectic in general (the standard projection of GLRK1, GLRK2) keep Ω̄ to the defect floor, the
  report opens with a one-line warning instead of letting "symplectic" read as a finding.
"""
from __future__ import annotations

from .candidates import Candidate, candidates_from, load_function, pair_candidate, stepper_map
from .defect import DEFECT_FLOOR, FD_ORDER8, FD_STEP, READ_THRESHOLD, defect_study, defects, fit_order, jacobian
from .discrimination import discrimination
from .drift import RESOLVED, ROUNDOFF, VERDICTS, drift_verdict, run_drift
from .report import audit, plot_report, text_report
from .maps import audit_map, jvp, map_defect

__all__ = ["Candidate", "candidates_from", "load_function", "pair_candidate", "stepper_map", "DEFECT_FLOOR",
           "FD_ORDER8", "FD_STEP", "READ_THRESHOLD", "defect_study", "defects", "fit_order", "jacobian",
           "VERDICTS", "RESOLVED", "ROUNDOFF", "discrimination", "drift_verdict", "run_drift", "audit", "plot_report",
           "text_report", "audit_map", "jvp", "map_defect"]
