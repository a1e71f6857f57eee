"""Poincaré integral invariants on loops and surfaces (sec:app_integral_invariants).

    import invariants
    q = invariants.loop("guiding_centre", 2000)                 # (N, d)
    I1 = invariants.first_invariant(q, "noncanonical", system=sys)
    S = invariants.surface("guiding_centre", 100, 100)          # (nσ, nτ, d)
    I2 = invariants.second_invariant(S, "noncanonical", system=sys)
    I1.value, I1.resolution, I1.under_resolved
    sol = integrators.integrate(sys, S, tableau="GLRK2", projection="symmetric", h=10, steps=100, save_every=10)
    series = invariants.along(sol, "noncanonical", system=sys)  # I₂ at every saved time
"""
from .forms import (FORMS, UNDER_RESOLVED, InvariantSeries, InvariantValue, along, corrected_omega, first_invariant,
                    second_invariant)
from .samples import loop, loop_parameters, surface, surface_parameters

__all__ = ["first_invariant", "second_invariant", "loop", "surface", "loop_parameters", "surface_parameters",
           "FORMS", "UNDER_RESOLVED", "InvariantValue", "corrected_omega", "along", "InvariantSeries"]
