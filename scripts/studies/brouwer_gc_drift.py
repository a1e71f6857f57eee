"""Where the symmetric guiding centre's GLRK3/SRK3 round-off grows faster than t (docs/brouwer.md).

On guiding_centre_symmetric the pairs GLRK3-symmetric/-midpoint and SRK3-symmetric/-midpoint have
round-off exponents 0.8–1.5 although their double-double energy error is 1e-32.  This script
measures the parallel velocity u (a constant of the motion: u̇ = 0, kept exactly by these pairs in
exact arithmetic) in the double run, for one start, against what could drive its drift:

* the size of the cyclic coordinate z (its ulp grows ∝ t): the same run with z₀ shifted by 2.5·10⁵;
* the time t₀ (the systems are autonomous): t₀ = 5·10⁵;
* the Newton rule: the default, the fixed 4 ulps, fresh factors at every iteration;
* the double-double run of the same pair (its u, to 1e-32).

    python scripts/studies/brouwer_gc_drift.py                  # GLRK3-symmetric, about 1 min
    python scripts/studies/brouwer_gc_drift.py --pair SRK3-midpoint
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import integrators
from integrators.engine import FIXED_TOL

sys.path.insert(0, str(Path(__file__).resolve().parent))
from brouwer_law import degenerate   # noqa: E402  (the study's starts)

STEPS, EVERY, H = 50_000, 10_000, 10.0


def u_drift(system, q0, tableau, projection, t0=0.0, tolerances=None, precision="double"):
    sol = integrators.integrate(system, q0, tableau=tableau, projection=projection, h=H, steps=STEPS,
                                save_every=EVERY, t0=t0, tolerances=tolerances, precision=precision)
    du = sol.q[:, 0, 3] - q0[0, 3]
    if precision == "double-double":
        du = du + sol.q_lo[:, 0, 3]
    return du


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pair", default="GLRK3-symmetric")
    ap.add_argument("--start", type=int, default=1, help="which of the study's 16 starts")
    args = ap.parse_args(argv)
    tableau, projection = args.pair.split("-")
    system, starts = degenerate("guiding_centre_symmetric", 16)
    q0 = starts[args.start:args.start + 1]
    shifted = q0.copy()
    shifted[:, 2] += 2.5e5
    still = q0.copy()
    still[:, 3] = 0.0
    rows = [("default", u_drift(system, q0, tableau, projection)),
            ("z₀ + 2.5e5", u_drift(system, shifted, tableau, projection)),
            ("t₀ = 5e5", u_drift(system, q0, tableau, projection, t0=5e5)),
            ("fixed 4 ulps", u_drift(system, q0, tableau, projection, tolerances=integrators.Tolerances(tol=FIXED_TOL))),
            ("fresh factors", u_drift(system, q0, tableau, projection, tolerances=integrators.Tolerances(
                trust_max_unknowns=64, trust_floor=0, refresh_floor=0))),
            ("u₀ = 0 (z still)", u_drift(system, still, tableau, projection)),
            ("double-double", u_drift(system, q0, tableau, projection, precision="double-double"))]
    print(f"guiding_centre_symmetric {args.pair}, h = {H:g}, start {args.start}: u(t) − u₀ at steps "
          + ", ".join(f"{k:,}" for k in range(0, STEPS + 1, EVERY)))
    print(f"| run | " + " | ".join(f"{k:,}" for k in range(EVERY, STEPS + 1, EVERY)) + " |")
    print("|---|" + "---:|" * (STEPS // EVERY))
    for name, du in rows:
        print(f"| {name} | " + " | ".join(f"{v:.2e}" for v in du[1:]) + " |")


if __name__ == "__main__":
    main()
