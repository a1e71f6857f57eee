"""The energy order of SRK3 with the standard projection on point vortices, followed to round-off
(docs/convergence.md, "SRK3 + standard: energy order 3, not 4").

    python scripts/studies/convergence_srk3_standard.py

Setup of scripts/studies/convergence_orders.py (γ = (0.1, 0.1), q₀ = (1, 0.1, 1, −0.1), T = 2), h = 2⁻¹ … 2⁻¹³:
the energy error max_t |H − H₀| and the angular-momentum error max_t |P − P₀|, the local order
log₂(e(2h)/e(h)), and a least-squares fit e(h) = a h⁴ + b h³ (relative residuals) over the h whose
energy error is above 1e-14.  No reference solution is involved: both errors are against t = 0.
"""
import numpy as np

import integrators


def main():
    sy = integrators.system("point_vortices")
    q0, T = np.array([1.0, 0.1, 1.0, -0.1]), 2.0
    hs, eH, eP = [], [], []
    print("| h | energy error | local order | momentum error | local order |")
    print("|---|---|---|---|---|")
    for k in range(1, 14):
        h = 2.0 ** -k
        sol = integrators.integrate(sy, q0, tableau="SRK3", projection="standard",
                                    h=h, steps=int(round(T / h)), save_every=1)
        q = sol.q[:, 0]
        hs.append(h)
        eH.append(float(np.max(np.abs(sy.H(q) - sy.H(q[0])))))
        eP.append(float(np.max(np.abs(sy.momentum(q) - sy.momentum(q[0])))))
        oH = "" if k == 1 else f"{np.log2(eH[-2] / eH[-1]):.2f}"
        oP = "" if k == 1 else f"{np.log2(eP[-2] / eP[-1]):.2f}"
        print(f"| 2^-{k} | {eH[-1]:.3e} | {oH} | {eP[-1]:.3e} | {oP} |")
    h, e = np.array(hs), np.array(eH)
    use = e > 1e-14
    A = np.stack([h[use] ** 4, h[use] ** 3], axis=1) / e[use, None]      # relative least squares
    (a, b), *_ = np.linalg.lstsq(A, np.ones(use.sum()), rcond=None)
    resid = np.max(np.abs(A @ np.array([a, b]) - 1))
    print(f"\nfit over {use.sum()} h (energy error > 1e-14): e(h) = {a:.3e} h^4 + {b:.3e} h^3, "
          f"largest relative residual {resid:.1%}; the terms are equal at h = {b / a:.3g}")


if __name__ == "__main__":
    main()
