"""The G-EQDSK equilibrium systems measured (issue 44; docs/equilibria.md, docs/benchmarks.md).

    python scripts/studies/equilibria_systems.py [--out docs/figures/equilibria.json] [--figures docs/figures]

* **Convergence**: the Solov'ev equilibrium written to G-EQDSK files (17 digits) on 17² … 257² grids
  against ``guiding_centre_solovev`` at 200 random points inside the plasma: the largest differences
  of ψ̃, ϑ, H, ϑ_q, ∇H, ϑ_qq, ∇²H and the fitted orders (figure ``equilibria_convergence.png``).
* **Orbit**: 10⁴ GLRK2-symmetric steps of the default Solov'ev orbit in each file's field against the
  analytic one: the largest deviation in (R, Z, u), and the round-off floor (one ulp moved).
* **Cost**: GLRK2-symmetric point-steps per second in lanes, one thread, 10⁴ points, in the shipped
  FreeGS field and in the analytic ``guiding_centre_tokamak`` field, measured alternately (5 rounds,
  best of each; both fields' points near a passing orbit, every point alive to the end).
* **Orbits in the shipped equilibrium**: the flux surfaces with a passing and two trapped guiding
  centres (figure ``equilibria_orbits.png``).
"""
import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

import integrators
from integrators.engine import set_threads
from integrators.equilibrium import read_geqdsk, system_from_geqdsk, write_solovev

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "integrators/service/scenes/freegs_dn.geqdsk"
NAMES = ("theta", "H", "dtheta", "dH", "ddtheta", "ddH")


def convergence(ns=(17, 33, 65, 129, 257)):
    sol = integrators.system("guiding_centre_solovev")
    rng = np.random.default_rng(0)
    P = np.column_stack([2.0 + 0.35 * (2 * rng.random(200) - 1), 0.45 * (2 * rng.random(200) - 1),
                         rng.random(200), 0.3 * (2 * rng.random(200) - 1)])
    folder = Path(tempfile.mkdtemp())
    rows = []
    for n in ns:
        sy = system_from_geqdsk(write_solovev(folder / f"s{n}.geqdsk", n), mu=0.01)
        row = {nm: float(np.max(np.abs(getattr(sy, nm)(P) - getattr(sol, nm)(P)))) for nm in NAMES}
        row["n"] = n
        rows.append(row)
        print(f"n = {n:4d}: " + "  ".join(f"{nm} {row[nm]:.2e}" for nm in NAMES), flush=True)
    orders = {}
    for nm in NAMES:
        use = [r for r in rows if r["n"] >= 33 and r[nm] > 1e-14]     # past the coarsest grid, above round-off
        if len(use) >= 2:
            orders[nm] = float(-np.polyfit(np.log([r["n"] for r in use[:3]]), np.log([r[nm] for r in use[:3]]), 1)[0])
    print("fitted orders (33² to 129², or the grids above 1e-14): " + "  ".join(f"{k} {v:.2f}" for k, v in orders.items()))
    return rows, orders


def orbit(ns=(33, 65, 129)):
    sol = integrators.system("guiding_centre_solovev")
    q0 = np.array([sol.defaults["q0"]])
    kw = dict(h=2.5, steps=10_000, save_every=50)
    ref = integrators.integrate(sol, q0, tableau="GLRK2", projection="symmetric", **kw)
    nudged = integrators.integrate(sol, q0 * (1 + np.finfo(float).eps), tableau="GLRK2", projection="symmetric", **kw)
    floor = float(np.max(np.abs(nudged.q[..., [0, 1, 3]] - ref.q[..., [0, 1, 3]])))
    folder = Path(tempfile.mkdtemp())
    out = {"floor": floor, "rows": []}
    path = ref.q.reshape(-1, 4)
    for n in ns:
        sy = system_from_geqdsk(write_solovev(folder / f"s{n}.geqdsk", n), mu=0.01)
        got = integrators.integrate(sy, q0, tableau="GLRK2", projection="symmetric", **kw)
        dev = float(np.max(np.abs(got.q[..., [0, 1, 3]] - ref.q[..., [0, 1, 3]])))
        field = float(max(np.max(np.abs(sy.theta(path) - sol.theta(path))), np.max(np.abs(sy.dH(path) - sol.dH(path)))))
        out["rows"].append(dict(n=n, deviation=dev, field_error=field))
        print(f"orbit, n = {n}: deviation {dev:.2e} (field error on the orbit {field:.2e}); round-off floor {floor:.1e}")
    return out


def cost(rounds=5, n=10000):
    set_threads(1)
    rng = np.random.default_rng(1)
    sy = system_from_geqdsk(SHIPPED, mu=7.082196e-06)
    c = np.array([1.4505169, 0.0379210, 0.0, 4.728073e-03])
    q_eq = c + rng.standard_normal((n, 4)) * [1e-3, 1e-3, 0.0, 1e-4]
    tok = integrators.system("guiding_centre_tokamak")
    q_tok = np.array(tok.defaults["q0"]) + rng.standard_normal((n, 4)) * [1e-3, 1e-3, 0.0, 1e-3]
    cases = {"spline (FreeGS)": (sy, q_eq, 120.0), "analytic tokamak": (tok, q_tok, 2.5)}
    best = {k: 0.0 for k in cases}
    its = {}
    for _ in range(rounds):
        for k, (s_, q, h) in cases.items():
            eng = integrators.Engine(s_, integrators.tableau("GLRK2"), "symmetric", h)
            st = eng.state(q)
            eng.advance(st, 1, 2)
            i0 = st.iterations.sum()
            t = time.perf_counter()
            eng.advance(st, 3, 10)
            best[k] = max(best[k], n * 10 / (time.perf_counter() - t))
            its[k] = float((st.iterations.sum() - i0) / (n * 10))
            assert st.live.all()
    set_threads(None)
    ratio = best["analytic tokamak"] / best["spline (FreeGS)"]
    for k in cases:
        print(f"{k:18s}: {best[k]:10,.0f} point-steps/s, {its[k]:.2f} Newton iterations a step")
    print(f"a step in the spline field costs {ratio:.2f}× one in the analytic field")
    return dict(rates=best, iterations=its, ratio=ratio, rounds=rounds, points=n)


def orbits_figure(path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sy = system_from_geqdsk(SHIPPED, mu=7.082196e-06)
    eq = read_geqdsk(SHIPPED)
    v = sy.defaults["speed"]
    c = np.array([1.4505169, 0.0379210, 0.0, 0.0])
    starts = np.array([c + [0, 0, 0, v / np.sqrt(2)], c + [0, 0, 0, 0.15 * v], c + [0.1, 0, 0, 0.1 * v]])
    res = integrators.integrate(sy, starts, tableau="GLRK2", projection="symmetric", h=120.0, steps=4000, save_every=2)
    fig, ax = plt.subplots(figsize=(4.6, 6.2))
    ax.contour(eq.R, eq.Z, eq.psi.T / eq.psi_span, np.linspace(0.1, 0.9, 9), colors="0.8", linewidths=0.6)
    ax.contour(eq.R, eq.Z, eq.psi.T / eq.psi_span, [1.0], colors="0.3", linewidths=1.0)
    labels = ["passing, u = v/√2", "trapped, u = 0.15 v", "trapped, u = 0.1 v, R + 0.1 m"]
    for i, lab in enumerate(labels):
        ax.plot(res.q[:, i, 0], res.q[:, i, 1], ".", ms=0.8, label=lab)
    ax.set_aspect("equal")
    ax.set_xlim(0.6, 2.0)
    ax.set_ylim(-1.0, 1.0)
    ax.set_xlabel("R [m]")
    ax.set_ylabel("Z [m]")
    ax.set_title("FreeGS double null: ψ_N = 0.1 … 1, GLRK2-symmetric", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def convergence_figure(rows, orders, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.4, 4.0))
    n = [r["n"] for r in rows]
    for nm, lab in zip(NAMES, ("ϑ", "H", "ϑ_q", "∇H", "ϑ_qq", "∇²H")):
        ax.loglog(n, [max(r[nm], 1e-17) for r in rows], "o-", label=f"{lab} (order {orders.get(nm, float('nan')):.1f})")
    ax.set_xticks(n)
    ax.set_xticklabels([str(x) for x in n])
    ax.minorticks_off()
    ax.set_xlabel("grid points a side")
    ax.set_ylabel("max |file − analytic|")
    ax.set_title("Solov'ev through G-EQDSK (17 digits) against the analytic system", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs/figures/equilibria.json"))
    ap.add_argument("--figures", default=str(ROOT / "docs/figures"))
    args = ap.parse_args()
    rows, orders = convergence()
    res = dict(machine=platform.processor() or platform.machine(), date=time.strftime("%Y-%m-%d"),
               command="python scripts/studies/equilibria_systems.py", convergence=rows, orders=orders, orbit=orbit(), cost=cost())
    fig = Path(args.figures)
    fig.mkdir(parents=True, exist_ok=True)
    convergence_figure(rows, orders, fig / "equilibria_convergence.png")
    orbits_figure(fig / "equilibria_orbits.png")
    Path(args.out).write_text(json.dumps(res, indent=1))
    print(f"wrote {args.out} and the figures in {fig}")


if __name__ == "__main__":
    main()
