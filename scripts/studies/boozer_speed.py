"""What a Boozer field costs in the compiled engine (docs/stellarators.md, docs/benchmarks.md; issue 71).

Three measurements on simsopt's li383 file (114 of its 1,040 modes at the default modes_tol 1e-4,
8 toroidal harmonics, the 96 × 96 Cartesian grid), one thread, best of ``--repeat``:

* **the field per point**: the system's compiled point function at 10⁴ random points over the
  plasma (each in another cell: the data's caches are cold), with every derivative the engine
  takes at a stage (ϑ, ϑ_q, ϑ_qq, ∇H, ∇²H: |B| with its first and second derivatives and the 3
  profile splines with theirs), for |B| as one 3-D spline (``field="3d"``, 96 × 96 × 56) and as
  15 harmonic splines (``field="harmonics"``); the 3-D field's own evaluation alone; against a direct
  Fourier sum of |B| and its first and second derivatives in (s, θ, ζ) over the same modes and over
  all 1,040 (each mode's radial factor a cubic in s; one cos and one sin a mode), compiled by numba
  the same way;
* **a loop's run**: GLRK2-symmetric on 4,096 points about the default passing guiding centre, the
  default h, ``--steps`` steps, in point-steps per second and the time 10⁴ steps would take.

    python scripts/studies/boozer_speed.py                 # about 2 minutes after compilation
"""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
from numba import njit

import integrators
from integrators.boozer import read_boozmn, system_from_boozer
from integrators.codegen import point_functions
from integrators.simd import _at, lanes
from integrators.splines3 import field3

LI383 = Path(integrators.__file__).parent / "service" / "scenes" / "boozmn_li383_low_res.nc"


@njit(cache=True)
def _engine_points(ev, k, q, th, T, TT, dH, HH):
    n, d = q.shape
    P = (0,)                 # one lane of doubles (kernel.lanes)
    acc = 0.0
    for i in range(n):
        ev(lanes(q, i * d, P), _at(k, 0), True, lanes(th, 0, P), lanes(T, 0, P), lanes(TT, 0, P),
           lanes(dH, 0, P), lanes(HH, 0, P))
        acc += dH[0] + HH[0]
    return acc


@njit(cache=True)
def _field_alone(k, P, s, x, y, z):
    """|B| with its first and second derivatives from the 3-D field alone (splines3.field3)."""
    acc = 0.0
    for i in range(x.size):
        o = field3(k, P, s, x[i], y[i], z[i])
        acc += o[0] + o[9]
    return acc


@njit(cache=True)
def _fourier(s, th, ze, m, n, c):
    """|B|, its gradient and Hessian in (s, θ, ζ) by the direct sum over the modes (m, n) with radial
    cubics c[mode, 0..3] (b = c0 + c1 s + c2 s² + c3 s³); returns a checksum."""
    acc = 0.0
    out = np.zeros(10)
    for i in range(s.size):
        out[:] = 0.0
        x = s[i]
        for j in range(m.size):
            b = c[j, 0] + x * (c[j, 1] + x * (c[j, 2] + x * c[j, 3]))
            db = c[j, 1] + x * (2 * c[j, 2] + 3 * x * c[j, 3])
            ddb = 2 * c[j, 2] + 6 * x * c[j, 3]
            a = m[j] * th[i] - n[j] * ze[i]
            co, si = math.cos(a), math.sin(a)
            out[0] += b * co                      # B
            out[1] += db * co                     # ∂s
            out[2] -= b * m[j] * si               # ∂θ
            out[3] += b * n[j] * si               # ∂ζ
            out[4] += ddb * co                    # ∂ss
            out[5] -= db * m[j] * si              # ∂sθ
            out[6] += db * n[j] * si              # ∂sζ
            out[7] -= b * m[j] * m[j] * co        # ∂θθ
            out[8] += b * m[j] * n[j] * co        # ∂θζ
            out[9] -= b * n[j] * n[j] * co        # ∂ζζ
        acc += out[0] + out[9]
    return acc


def best(fn, repeat):
    fn()
    t = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return min(t)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--field", choices=("3d", "harmonics"), default="3d",
                    help="the |B| interpolation of the loop's run (both are timed per point)")
    args = ap.parse_args(argv)
    integrators.set_threads(1)
    sy = system_from_boozer(LI383, field=args.field)
    other = system_from_boozer(LI383, field="harmonics" if args.field == "3d" else "3d")
    bz = read_boozmn(LI383)
    rng = np.random.default_rng(71)
    N = args.points
    s, th, ze = rng.uniform(0.01, 0.95, N), rng.uniform(0, 2 * np.pi, N), rng.uniform(0, 2 * np.pi, N)
    r = np.sqrt(2 * bz.psi0 * s)
    q = np.ascontiguousarray(np.stack([r * np.cos(th), r * np.sin(th), ze, np.full(N, 1e-3)], 1))
    d = 4
    bufs = [np.zeros(d), np.zeros(d * d), np.zeros(d * d * d), np.zeros(d), np.zeros(d * d)]
    rows = []
    for system in (sy, other):
        ev, _ = point_functions(system)
        k = system.param_vector()
        t_engine = best(lambda: _engine_points(ev, k, q, *bufs), args.repeat) / N
        kind = ("one spline in (x, y, ζ), " + f"{system.defaults['grid_zeta']} ζ nodes"
                if system.defaults["field"] == "3d" else "a quintic (x, y) spline a harmonic")
        rows.append((f"engine point function (ϑ…ϑ_qq, ∇H, ∇²H), |B| as {kind}", bz.modes()[0].size, t_engine))
    if sy.defaults["field"] == "3d":
        k = sy.param_vector()
        t_b = best(lambda: _field_alone(k, len(sy.params), 3, q[:, 0].copy(), q[:, 1].copy(), q[:, 2].copy()),
                   args.repeat) / N
        rows.append(("|B| with ∇, ∇² alone: the 3-D field's evaluation", bz.modes()[0].size, t_b))
    for label, keep in (("Fourier sum, kept modes", bz.modes()[0]), ("Fourier sum, all modes", np.arange(bz.xm.size))):
        c = np.ascontiguousarray(rng.standard_normal((keep.size, 4)))
        m, n = bz.xm[keep].astype(np.float64), bz.xn[keep].astype(np.float64)
        rows.append((f"{label} (|B|, ∇, ∇²)", keep.size, best(lambda: _fourier(s, th, ze, m, n, c), args.repeat) / N))
    print("| evaluation | modes | ns a point | ns a mode a point |")
    print("|---|---:|---:|---:|")
    for label, modes, t in rows:
        print(f"| {label} | {modes} | {t * 1e9:,.0f} | {t * 1e9 / modes:.1f} |")

    # a loop's run
    d0 = sy.defaults
    r1 = math.sqrt(2 * bz.psi0)
    tau = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    q0 = np.tile(np.asarray(d0["q0"], float), (4096, 1))
    q0[:, 0] += r1 / 5000 * np.cos(tau)
    q0[:, 1] += r1 / 5000 * np.sin(tau)
    integrators.integrate(sy, q0, tableau="GLRK2", projection="symmetric", h=d0["h"], steps=2)   # compile every variant
    t0 = time.perf_counter()
    sol = integrators.integrate(sy, q0, tableau="GLRK2", projection="symmetric", h=d0["h"], steps=args.steps,
                                save_every=args.steps)
    dt = time.perf_counter() - t0
    rate = 4096 * args.steps / dt
    print(f"\n|B| as {sy.defaults['notes'][0].split('; |B| as ')[1]}")
    print(f"GLRK2-symmetric, 4,096 points, h = {d0['h']}, {args.steps} steps: {dt:.1f} s, {rate:,.0f} point-steps/s, "
          f"{sol.newton_iterations.sum() / (4096 * args.steps):.2f} Newton iterations a step; 10⁴ steps would take "
          f"{4096 * 1e4 / rate / 60:.1f} min (one thread)")


if __name__ == "__main__":
    main()
