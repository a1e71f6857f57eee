"""Round-off of I₁: Parseval's sum in Fourier space against the trapezoidal rule of the inverse-FFT
derivative, on PoincareInvariants.jl's 4-D Hénon map (docs/invariants.md, "Round-off of I₁"; the table
there is printed by scripts/studies/invariants_convergence.py, which calls errors() below).

    python scripts/studies/invariants_roundoff.py

The unit circle in both (qᵢ, pᵢ) planes, mapped twice: I₁ = ∮ p·dq = 2π exactly, and the loop is a
trigonometric polynomial of degree 16, so every N here resolves it and the error is round-off only.
For each N, 20 phases of the sampling τ_j = (j + φ)/N; the median and the largest |I₁ − 2π|.
"""
import numpy as np

import invariants
from invariants import samples, spectral


def errors(N, phases):
    canonical = lambda z: np.concatenate([z[:, 2:], np.zeros((len(z), 2))], axis=1)  # noqa: E731
    new, old = [], []
    for phase in phases:
        z = samples.henon_loop(N, phase)
        new.append(abs(invariants.first_invariant(z, form=canonical).value - 2 * np.pi))
        trapezoid = spectral.loop_integral(np.sum(z[:, 2:] * spectral.loop_derivative(z)[:, :2], axis=1))
        old.append(abs(trapezoid - 2 * np.pi))
    return np.array(new), np.array(old)


def main():
    print("| N | Parseval: median | worst | trapezoid of FFT derivative: median | worst |")
    print("|---|---|---|---|---|")
    for N in (250, 500, 1000, 2000, 4000, 8000, 16000):
        new, old = errors(N, np.random.default_rng(0).random(20))
        print(f"| {N:,} | {np.median(new):.1e} | {new.max():.1e} | {np.median(old):.1e} | {old.max():.1e} |")


if __name__ == "__main__":
    main()
