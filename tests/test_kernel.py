"""The kernel's Python-side contracts (integrators.kernel): the flat tableau it reads by offset, the
scratch layout it carves into buffers, the lane-width rule, and the projection codes it shares with
integrators.projections.  (Its numbers are tested through the engine: test_engine.py, test_lanes.py,
test_vprk.py.)"""
import numpy as np
import pytest

import integrators
from integrators import kernel, projections
from integrators.engine import predictor


@pytest.mark.parametrize("name", integrators.TABLEAU_NAMES)
def test_the_flat_tableau_holds_each_coefficient_where_the_kernel_reads_it(name):
    """flat_tableau writes [a, a_lo, ā, ā_lo, b, b_lo, d, d_lo, E]; _coefficients reads them at
    0, s², 2s², 3s², 4s², 4s² + s, …, 4s² + 4s: every field of every built-in tableau is found at the
    kernel's offset, and a + a_lo (the double-double split) is the double a plus a correction below
    half an ulp of it."""
    t = integrators.tableau(name)
    s, ss = t.s, t.s * t.s
    E = predictor(t.c)
    flat = kernel.flat_tableau(t, E)
    assert flat.size == 4 * ss + 4 * s + s * (s + 1)
    at = dict(a=0, a_lo=ss, abar=2 * ss, abar_lo=3 * ss, b=4 * ss, b_lo=4 * ss + s, d=4 * ss + 2 * s,
              d_lo=4 * ss + 3 * s, E=4 * ss + 4 * s)
    assert tuple(at) == kernel.Coefficients._fields
    for field, want in (("a", t.a), ("a_lo", t.a_lo), ("abar", t.abar), ("abar_lo", t.abar_lo), ("b", t.b),
                        ("b_lo", t.b_lo), ("E", E)):
        want = np.asarray(want, dtype=float).ravel()
        assert np.array_equal(flat[at[field]:at[field] + want.size], want), field
    d = flat[at["d"]:at["d"] + s]
    assert np.array_equal(d, np.zeros(s) if t.d is None else np.asarray(t.d, dtype=float))
    lo = flat[at["a_lo"]:at["a_lo"] + ss]
    assert np.all(np.abs(lo) <= 0.5 * np.spacing(np.abs(flat[:ss])) + 1e-300)


@pytest.mark.parametrize("s,d,nz", [(1, 4, 4), (2, 4, 12), (3, 6, 30), (6, 4, 32)])
def test_the_scratch_layout_lays_every_buffer_end_to_end(s, d, nz):
    """layout(s, d, nz): each record's offsets start at 0 and increase by the named buffer's size, the
    last field is the total, and the sizes are the ones the kernel indexes (Q: s·d, T: s·d², lu:
    nz², piv: nz …)."""
    S, F, IP = kernel.layout(s, d, nz)
    for rec in (S, F, IP):
        offsets = list(rec)
        assert offsets[0] == 0 and all(b >= a for a, b in zip(offsets, offsets[1:]))
    size = dict(zip(S._fields[:-1], np.diff(list(S))))
    assert (size["Q"], size["T"], size["TT"], size["lu"], size["Jt"], size["z"], size["guess"]) == \
        (s * d, s * d * d, s * d ** 3, nz * nz, nz * nz, nz, (s + 2) * d)       # guess: stages, Λ, μ
    assert (size["base"], size["D"]) == ((s + 2) * d, kernel.DEPTH * (s + 2) * d)
    assert dict(zip(IP._fields[:-1], np.diff(list(IP)))) == {"piv": nz, "pivt": nz, "ipiv": d, "pt": 1}
    assert F.size == 2 * (nz + d) + (len(F._fields) - 5)     # scale, pscale, own, pown, then one flag each
    assert (F.own - F.scale, F.pown - F.pscale) == (nz + d, nz + d)


def test_the_lane_width_rule():
    """W = 16 for Newton systems of up to 28 unknowns on calls of at least 1,024 points, else 8."""
    assert kernel.lane_width(28, 1024) == kernel.WIDE == 16
    assert kernel.lane_width(29, 1024) == kernel.lane_width(28, 1023) == kernel.LANES == 8


def test_the_projection_codes_are_the_kernels():
    """Each projection record's codes are the kernel's constants (one owner: integrators.projections)."""
    assert (kernel.START, kernel.MIDPOINT, kernel.END) == (projections.START, projections.MIDPOINT, projections.END)
    t = integrators.tableau("GLRK2")
    got = {name: projections.projection_record(name).codes(t)[:4] for name in projections.PROJECTIONS}
    assert got == {"none": (kernel.PRE_NONE, kernel.START, False, kernel.END),
                   "standard": (kernel.PRE_NONE, kernel.START, True, kernel.END),
                   "symmetric": (kernel.PRE_UNKNOWN, kernel.START, True, kernel.END),
                   "symplectic": (kernel.PRE_PREVIOUS, kernel.START, True, kernel.END),
                   "midpoint": (kernel.PRE_UNKNOWN, kernel.MIDPOINT, True, kernel.MIDPOINT)}
