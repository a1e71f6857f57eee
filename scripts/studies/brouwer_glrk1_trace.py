"""One pendulum start under GLRK1-none, double against double-double: where the round-off leaves the
reference (docs/brouwer.md, "Where the bound is not met", the canonical GLRK1 rows).

For the pendulum written as a degenerate system (ϑ(q) = (q₂, 0), H = q₂²/2 − cos q₁), the state's
momentum p equals ϑ(q) = (q₂, 0) on the solution.  Printed every ``--every`` steps: the energy's
round-off part (double minus double-double, both in double-double), q's difference from the
reference, and p₁ − q₂ of the double run (the relation the unprojected method keeps in exact
arithmetic) beside the reference's.

    python scripts/studies/brouwer_glrk1_trace.py --start 51 --steps 32000 --every 1600   # about a minute

Since the step sees the state's compensation terms, p₁ − q₂ stays 0 and q within half an ulp of the
reference (docs/brouwer.md, "The state's compensation terms"); before, it broke from 0 after a few
thousand steps.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import integrators

sys.path.insert(0, str(Path(__file__).resolve().parent))
from brouwer_law import energy_dd, pendulum  # noqa: E402  (the study's system and starts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--start", type=int, default=51, help="which of the study's 64 starts")
    ap.add_argument("--steps", type=int, default=16_000)
    ap.add_argument("--every", type=int, default=800)
    ap.add_argument("--h", type=float, default=0.002)
    ap.add_argument("--dithered", action="store_true", help="Tolerances(dither=True) (default: the engine's default)")
    args = ap.parse_args(argv)
    system, q0 = pendulum(64)
    q0 = q0[args.start:args.start + 1]
    kw = dict(tableau="GLRK1", projection="none", h=args.h, steps=args.steps, save_every=args.every)
    dd = integrators.integrate(system, q0, precision="double-double", **kw)
    sol = integrators.integrate(system, q0, tolerances=integrators.Tolerances(dither=args.dithered), **kw)
    hi, lo = energy_dd(system, dd.q, dd.q_lo)
    eh, el = energy_dd(system, sol.q)
    de = (eh - hi) + (el - lo)
    dq = (sol.q - dd.q) - dd.q_lo
    gap = sol.p[..., 0] - sol.q[..., 1]
    gap_dd = (dd.p[..., 0] - dd.q[..., 1]) + (dd.p_lo[..., 0] - dd.q_lo[..., 1])
    print(f"start {args.start}: q0 = {q0[0].tolist()}, GLRK1-none, h = {args.h}")
    print("   step   E − E_dd     q₁ − q₁_dd   q₂ − q₂_dd   p₁ − q₂ (double)  (double-double)")
    for k in range(dq.shape[0]):
        print(f"{k * args.every:7d}  {de[k, 0]:+.2e}  {dq[k, 0, 0]:+.2e}  {dq[k, 0, 1]:+.2e}  {gap[k, 0]:+.2e}"
              f"         {gap_dd[k, 0]:+.1e}")


if __name__ == "__main__":
    main()
