"""Regenerate the shipped test equilibrium: a free-boundary Grad–Shafranov solution by FreeGS, as
G-EQDSK (integrators/service/scenes/freegs_dn.geqdsk; issue 44).

FreeGS 0.8.2 runs only with numpy < 2 and scipy < 1.14, which the project's runtime does not use,
so this script runs in an environment of its own (two commands, Python 3.11):

    python3 -m venv /tmp/fgs && /tmp/fgs/bin/pip install "freegs==0.8.2" "numpy<2" "scipy<1.14" "matplotlib<3.10"
    /tmp/fgs/bin/python scripts/tools/make_equilibrium.py [--out integrators/service/scenes/freegs_dn.geqdsk]

The equilibrium is FreeGS's own free-boundary example (its README and examples/01-freeboundary.py):
the test tokamak (freegs.machine.TestTokamak, four pairs of poloidal field coils around R ≈ 1 m),
X-points asked for at (1.1, −0.6) and (1.1, 0.8) m with an isoflux constraint between (1.1, −0.6)
and (1.1, 0.6), 200 kA of plasma current, 1 kPa on axis, F = R·B_φ = 2 T·m in vacuum, FreeGS's
profile shape (α_m = 1, α_n = 2), on a 65 × 65 grid over R ∈ [0.1, 2] m, Z ∈ [−1, 1] m, solved to
FreeGS's default tolerance.  FreeGS writes ψ per radian, (R, φ, Z) right-handed, and ψ falling from
the axis to the boundary with positive current: COCOS 3 by Sauter & Medvedev's table, the
project's default (integrators/equilibrium.py).  Its q is positive, which COCOS 3 would make
negative; the system does not use q's sign (only |q|, to check ψ's normalisation).
"""
import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "integrators/service/scenes/freegs_dn.geqdsk"))
    ap.add_argument("--n", type=int, default=65, help="grid points a side")
    args = ap.parse_args()
    import freegs
    from freegs import geqdsk

    tokamak = freegs.machine.TestTokamak()
    eq = freegs.Equilibrium(tokamak=tokamak, Rmin=0.1, Rmax=2.0, Zmin=-1.0, Zmax=1.0, nx=args.n, ny=args.n,
                            boundary=freegs.boundary.freeBoundaryHagenow)
    profiles = freegs.jtor.ConstrainPaxisIp(eq, 1e3, 2e5, 2.0)
    constrain = freegs.control.constrain(xpoints=[(1.1, -0.6), (1.1, 0.8)], isoflux=[(1.1, -0.6, 1.1, 0.6)])
    freegs.solve(eq, profiles, constrain, show=False)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w") as fh:
        geqdsk.write(eq, fh, label="freegs_dn")
    print(f"wrote {args.out}: {args.n} x {args.n}, Ip = {eq.plasmaCurrent():.4g} A, "
          f"psi axis {eq.psi_axis:.6g}, boundary {eq.psi_bndry:.6g}")


if __name__ == "__main__":
    main()
