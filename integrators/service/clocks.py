"""Clocks: the seconds a rank spends in each phase of a pair, and its running totals.

A pair's clock (:func:`pair_clock`) is what ``poincare run`` records per pair and rank
(``PairSummary.timings``, and every rank's under ``per_rank``) and what the cost model of
scripts/studies/scaling_model.py reads.  :class:`Spent` keeps the rank's seconds outside the advance over the
whole run, any pair's, so that the rates a rank reports for the balance of the next pair
(:meth:`Spent.rates`) count the other pairs' lagged work as work, not as slow advancing.
"""
from __future__ import annotations

import time

PHASES = ("advance", "gather", "invariants", "hdf5", "wait_plan", "wait_gather", "wait_recv", "refine")


def pair_clock() -> dict:
    """A pair's phases at zero: advance (the engine), gather (sending and receiving, waits included),
    invariants (a batch's tasks and rows), hdf5 (rank 0's writes), the waits by kind, refine (new
    points of refining sets), and counters."""
    return dict.fromkeys(PHASES, 0.0) | {"refine_point_steps": 0, "batches": 0}


class Spent:
    """A rank's seconds outside the advance, over the whole run."""

    def __init__(self):
        self.total = {"invariants": 0.0, "hdf5": 0.0, "gather": 0.0}

    def charge(self, clock, phase, seconds):
        """Book seconds of output work or exchange to a pair's clock and to the running total."""
        clock[phase] += seconds
        self.total[phase] += seconds

    def snapshot(self) -> dict:
        return dict(self.total)

    def rates(self, since, t_start, steps, points):
        """(seconds advancing, points, seconds of output work), each a step, since the running
        totals were ``since`` and the wall clock ``t_start``, over ``steps`` steps of ``points``
        points (what ranks.balance takes)."""
        d = {k: v - since[k] for k, v in self.total.items()}
        work, steps = d["invariants"] + d["hdf5"], max(steps, 1)
        return (time.perf_counter() - t_start - work - d["gather"]) / steps, points, work / steps
