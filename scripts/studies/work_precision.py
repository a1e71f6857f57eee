"""Work–precision: wall time against error, VPRK pairs against scipy (docs/work_precision.md).

    python scripts/studies/work_precision.py trajectory [--systems ...] [--points 16]
                                         # docs/figures/work_precision/<system>.json (<system>_1.json: 1 point)
    python scripts/studies/work_precision.py invariants [--steps 10000]   # docs/figures/work_precision/invariants.json
    python scripts/studies/work_precision.py plot                         # docs/figures/work_precision*.png
    python scripts/studies/work_precision.py table                        # the markdown tables of docs/work_precision.md

trajectory
    For each system, 16 points near the paper's initial condition, advanced to T = 64 h₀ (h₀ the
    paper's step) by every tableau × projection pair at h₀, h₀/2 and h₀/4, and by scipy's
    ``solve_ivp`` (DOP853 and Radau, rtol = atol from 1e-3 to 1e-13) on the explicit ODE
    q̇ = Ω̄(q)⁻¹∇H(q) (eq:euler_lagrange_equations; ``System.vector_field``), all 16 points as
    one vectorised ODE, Radau with the block-diagonal Jacobian sparsity.  Error: the largest
    component of |q(T) − q_ref(T)| / max(1, |q_ref(T)|) over the points.  Reference: the exact
    flow for guiding_centre_symmetric, otherwise DOP853 at rtol = atol = 1e-13; its own error is
    estimated by DOP853 at 3e-14 and recorded as ``reference_check``.  Time: wall time of the
    call (``integrate`` including its set-up; ``solve_ivp``), one run each.
invariants
    guiding_centre_symmetric, the paper's loop with 1,000 points and surface with 32 × 32
    Chebyshev points (both resolved to round-off by the exact flow at T = 10⁵), h = 10 for
    ``--steps`` steps (T = 10⁵), and with h = 20, 40, 80 (``--h``) to the same T: the relative error |I(T) − I(0)|/|I(0)| of the noncanonical I₁ and I₂
    for a set of VPRK pairs and for DOP853/Radau over tolerances.
"""
import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.sparse import block_diag

import integrators
from integrators.integrate import integrate
from invariants import forms, samples
from stability import all_pairs as admissible_pairs    # scripts/studies/stability_campaign.py: every pair a tableau admits

ROOT = Path(__file__).resolve().parents[2]
FIG = ROOT / "docs" / "figures"
DATA = FIG / "work_precision"
NPOINTS = 16
T_STEPS = 64
SYSTEMS = {   # name: (system, centre, spread, h0)
    "lotka_volterra_2d": ([1.0, 1.0], 0.05, 0.1),
    "point_vortices": ([1.0, 0.1, 1.0, -0.1], 0.01, 0.1),
    "guiding_centre_tokamak": ([2.5, 0.0, 0.0, 0.5], 0.01, 2.5),
    "guiding_centre_symmetric": ([0.5, 0.0, 0.0, 0.5], 0.05, 10.0),
}
DOP_TOLS = [1e-3, 1e-5, 1e-7, 1e-9, 1e-11, 1e-12]    # 1e-13 is the reference
RADAU_TOLS = [1e-3, 1e-5, 1e-7, 1e-9, 1e-11]


def scipy_solve(system, q0, T, method, tol):
    """All points as one ODE; returns (q(T) (n, d) or None, wall seconds, function evaluations)."""
    n, d = q0.shape

    def f(t, y):
        return system.vector_field(y.reshape(n, d)).ravel()

    kw = {}
    if method == "Radau":
        kw["jac_sparsity"] = block_diag([np.ones((d, d))] * n).tocsc()
    t0 = time.perf_counter()
    with np.errstate(all="ignore"):
        sol = solve_ivp(f, (0.0, T), q0.ravel(), method=method, rtol=tol, atol=tol, **kw)
    wall = time.perf_counter() - t0
    if not sol.success:
        return None, wall, int(sol.nfev)
    return sol.y[:, -1].reshape(n, d), wall, int(sol.nfev)


def error(q, ref):
    if q is None or not np.all(np.isfinite(q)):
        return None
    return float(np.max(np.abs(q - ref) / np.maximum(1.0, np.abs(ref))))


def start_points(system, centre, spread, rng):
    q0 = np.asarray(centre) + spread * rng.uniform(-1.0, 1.0, (NPOINTS, len(centre)))
    assert system.in_domain(q0).all()
    return q0


def trajectory(args):
    DATA.mkdir(parents=True, exist_ok=True)
    for name in args.systems:
        if name not in SYSTEMS:
            raise SystemExit(f"error: unknown system '{name}'; choose from {', '.join(SYSTEMS)}")
        rng = np.random.default_rng(6)
        out = {"meta": dict(machine=platform.platform(), python=platform.python_version(), points=args.points,
                            T="64 h0", numpy=np.__version__)}
        centre, spread, h0 = SYSTEMS[name]
        system = integrators.system(name)
        q0 = start_points(system, centre, spread, rng)[:args.points]
        T = T_STEPS * h0
        system.vector_field(q0); system.ddtheta(q0); system.ddH(q0)       # generate code outside timings
        if name == "guiding_centre_symmetric":
            ref = system.exact_flow(q0, T)
            check = 0.0
        else:
            ref = scipy_solve(system, q0, T, "DOP853", 1e-13)[0]
            check = error(scipy_solve(system, q0, T, "DOP853", 3e-14)[0], ref)
        rows = []
        for method, tols in (("DOP853", DOP_TOLS), ("Radau", RADAU_TOLS)):
            for tol in tols:
                q, wall, nfev = scipy_solve(system, q0, T, method, tol)
                rows.append(dict(method=method, tol=tol, wall=wall, error=error(q, ref), nfev=nfev))
                print(f"{name:26s} {method:8s} tol {tol:7.0e} {wall:8.3f} s  error {rows[-1]['error']}", flush=True)
        for tab, proj in admissible_pairs():
            for k in range(3):
                h = h0 / 2 ** k
                t0 = time.perf_counter()
                sol = integrate(system, q0, tableau=tab, projection=proj,
                                h=h, steps=T_STEPS * 2 ** k, save_every=T_STEPS * 2 ** k)
                wall = time.perf_counter() - t0
                broke = int(np.isfinite(sol.breakdown_time).sum())
                err = None if broke else error(sol.q[-1], ref)
                rows.append(dict(method=f"{tab}-{proj}", tableau=tab, projection=proj, h=h, wall=wall,
                                 error=err, broke=broke, newton=sol.mean_newton_iterations))
            print(f"{name:26s} {tab:9s} {proj:10s} errors {[r['error'] for r in rows[-3:]]}", flush=True)
        out.update(system=name, T=T, h0=h0, reference_check=check, runs=rows)
        (DATA / data_name(name, args.points)).write_text(json.dumps(out, indent=0))


def data_name(system, points):
    return f"{system}.json" if points == NPOINTS else f"{system}_{points}.json"


def invariant_errors(system, loop_q, surf_q, I1_0, I2_0):
    i1 = forms.first_invariant(loop_q, "noncanonical", system)
    i2 = forms.second_invariant(surf_q, "noncanonical", system)
    return (abs(i1.value - I1_0) / abs(I1_0), abs(i2.value - I2_0) / abs(I2_0), bool(i1.under_resolved or i2.under_resolved))


INV_PAIRS = [("GLRK1", "none"), ("GLRK1", "symmetric"), ("GLRK1", "midpoint"), ("GLRK2", "none"),
             ("GLRK2", "standard"), ("GLRK2", "symmetric"), ("GLRK2", "symplectic"), ("SRK3", "symmetric"),
             ("GLRK4", "symmetric")]


def invariants(args):
    """Runs each pair at each step size of ``--h`` to T = h·steps of the first (10⁵), and the scipy
    methods; new runs replace the file's runs of the same method and step (or tolerance)."""
    DATA.mkdir(parents=True, exist_ok=True)
    system = integrators.system("guiding_centre_symmetric")
    loop_q = samples.loop(n=1000)
    surf_q = samples.surface(n_sigma=32, n_tau=32)
    ns = surf_q.shape[:2]
    q0 = np.concatenate([loop_q, surf_q.reshape(-1, 4)])
    I1_0 = forms.first_invariant(loop_q, "noncanonical", system).value
    I2_0 = forms.second_invariant(surf_q, "noncanonical", system).value
    T = 10.0 * args.steps
    split = lambda q: (q[:1000], q[1000:].reshape(ns + (4,)))      # noqa: E731
    exact = invariant_errors(system, *split(system.exact_flow(q0, T)), I1_0, I2_0)
    path = DATA / "invariants.json"
    out = json.loads(path.read_text()) if path.exists() else {"runs": []}
    if out.get("meta", {}).get("T", T) != T:
        raise SystemExit(f"{path} holds runs to T = {out['meta']['T']:g}, not {T:g}: move it away first")
    out["meta"] = dict(machine=platform.platform(), python=platform.python_version(), loop=1000,
                       surface=list(ns), h=10.0, steps=args.steps, T=T, exact_flow=exact)
    print("exact flow", exact, flush=True)

    def record(run):
        key = (run["method"], run.get("h"), run.get("tol"))
        out["runs"] = [r for r in out["runs"] if (r["method"], r.get("h", 10.0 if "tol" not in r else None),
                                                  r.get("tol")) != key] + [run]
        print(run, flush=True)
        path.write_text(json.dumps(out, indent=0))
    pairs = [tuple(p.split(":")) for p in args.pairs] if args.pairs else INV_PAIRS
    for tab, proj in pairs:
        for h in args.h:
            steps = int(round(T / h))
            t0 = time.perf_counter()
            sol = integrate(system, q0, tableau=tab, projection=proj, h=h, steps=steps, save_every=steps)
            wall = time.perf_counter() - t0
            broke = int(np.isfinite(sol.breakdown_time).sum())
            e1, e2, under = invariant_errors(system, *split(sol.q[-1]), I1_0, I2_0)
            record(dict(method=f"{tab}-{proj}", h=h, wall=wall, I1=e1, I2=e2, under_resolved=under, broke=broke))
    for method, tols in (("DOP853", [1e-6, 1e-8, 1e-10, 1e-12]), ("Radau", [1e-6, 1e-8, 1e-10])):
        if method not in args.scipy:
            continue
        for tol in tols:
            q, wall, nfev = scipy_solve(system, q0, T, method, tol)
            e1, e2, under = (None, None, None) if q is None else invariant_errors(system, *split(q), I1_0, I2_0)
            record(dict(method=method, tol=tol, wall=wall, I1=e1, I2=e2, under_resolved=under, nfev=nfev))


FAMILY = {"GLRK": "tab:blue", "SRK3": "tab:green", "LobIIID": "tab:purple", "LobIIIE": "tab:pink",
          "LobIII": "tab:gray", "RadIIA": "tab:brown"}
MARK = {"none": "o", "standard": "s", "symmetric": "^", "symplectic": "D", "midpoint": "v"}


def colour(tab):
    for k, c in FAMILY.items():
        if tab.startswith(k):
            return c
    return "k"


def plot(args):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    data = {n: json.loads((DATA / f"{n}.json").read_text()) for n in SYSTEMS if (DATA / f"{n}.json").exists()}
    names = list(data)
    fig, axes = plt.subplots(2, 2, figsize=(11, 8.5))
    for ax, name in zip(axes.ravel(), names):
        runs = data[name]["runs"]
        by = {}
        for r in runs:
            by.setdefault(r["method"], []).append(r)
        for m, rs in by.items():
            rs = [r for r in rs if r["error"] is not None and r["error"] < 10.0]   # > 10: not a solution
            if not rs:
                continue
            x, y = [r["wall"] for r in rs], [max(r["error"], 1e-17) for r in rs]
            if m in ("DOP853", "Radau"):
                ax.loglog(x, y, "-", color="red" if m == "DOP853" else "orange", lw=2.2, marker="*", ms=7, label=m, zorder=5)
            else:
                tab, proj = rs[0]["tableau"], rs[0]["projection"]
                ax.loglog(x, y, "-", color=colour(tab), lw=0.6, marker=MARK[proj], ms=3, alpha=0.6)
        ax.axhline(max(data[name]["reference_check"], 1e-17), color="k", ls=":", lw=1)
        ax.set_title(f"{name}, T = {data[name]['T']:g}")
        ax.set_xlabel("wall time [s] (16 points)")
        ax.set_ylim(top=10.0)
        ax.set_ylabel("max relative error at T")
        ax.grid(True, which="major", alpha=0.3)
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color=c, label=k) for k, c in FAMILY.items()]
    handles += [Line2D([], [], color="k", ls="", marker=mk, label=p) for p, mk in MARK.items()]
    handles += [Line2D([], [], color="red", lw=2.2, marker="*", label="scipy DOP853"),
                Line2D([], [], color="orange", lw=2.2, marker="*", label="scipy Radau")]
    fig.legend(handles=handles, loc="lower center", ncol=7, fontsize=8)
    fig.suptitle("Work–precision: every tableau × projection at h₀, h₀/2, h₀/4 (lower left is better; "
                 "dotted: the reference's own error)")
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    fig.savefig(FIG / "work_precision.png", dpi=80)
    plt.close(fig)
    p = DATA / "invariants.json"
    if p.exists():
        inv = json.loads(p.read_text())
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
        for ax, key in zip(axes, ("I1", "I2")):
            for r in inv["runs"]:
                if r[key] is None:
                    continue
                sc = r["method"] in ("DOP853", "Radau")
                c = ("red" if r["method"] == "DOP853" else "orange") if sc else colour(r["method"].split("-")[0])
                mk = "*" if sc else MARK[r["method"].split("-")[1]]
                ax.loglog(r["wall"], max(r[key], 1e-17), mk, color=c, ms=8 if sc else 6)
                label = f"{r['tol']:.0e}" if sc else r["method"]
                ax.annotate(label, (r["wall"], max(r[key], 1e-17)), fontsize=6, xytext=(3, 2), textcoords="offset points")
            ax.set_xlabel("wall time [s]")
            ax.set_ylabel(f"|{key}(T) − {key}(0)| / |{key}(0)|, noncanonical")
            ax.grid(True, alpha=0.3)
        m = inv["meta"]
        fig.suptitle(f"guiding_centre_symmetric, {m['steps']} steps of h = {m['h']:g} (T = {m['T']:g}), "
                     f"loop {m['loop']} points, surface {m['surface'][0]}×{m['surface'][1]}")
        fig.tight_layout()
        fig.savefig(FIG / "work_precision_invariants.png", dpi=80)
        plt.close(fig)


THRESHOLDS = (1e-3, 1e-6, 1e-9, 1e-11)


def fastest(runs, ok):
    """The fastest run of ``runs`` for which ok(run) holds, or None."""
    good = [r for r in runs if ok(r)]
    return min(good, key=lambda r: r["wall"]) if good else None


def _cell(r, label):
    return ("—", "—") if r is None else (label(r), f"{1e3 * r['wall']:.0f} ms" if r["wall"] < 10 else f"{r['wall']:.0f} s")


def table(args):
    """The fastest VPRK pair, DOP853 and Radau run that reach each error, from the JSON files."""
    for points in (NPOINTS, 1):
        files = {n: DATA / data_name(n, points) for n in SYSTEMS}
        if not any(f.exists() for f in files.values()):
            continue
        print(f"\n{points} point{'s' if points > 1 else ''}, trajectory error at T = 64 h₀:\n")
        print("| system | error ≤ | fastest VPRK pair (h) | time | DOP853 (tol) | time | Radau (tol) | time | VPRK / best scipy |")
        print("|---|---|---|---:|---|---:|---|---:|---:|")
        for name, f in files.items():
            if not f.exists():
                continue
            runs = json.loads(f.read_text())["runs"]
            for e in THRESHOLDS:
                reach = lambda r: r["error"] is not None and r["error"] <= e      # noqa: E731
                v = fastest([r for r in runs if "tableau" in r], reach)
                d = fastest([r for r in runs if r["method"] == "DOP853"], reach)
                rd = fastest([r for r in runs if r["method"] == "Radau"], reach)
                best = min([r["wall"] for r in (d, rd) if r is not None], default=None)
                ratio = "—" if v is None or best is None else f"{v['wall'] / best:.2g}"
                cells = (_cell(v, lambda r: f"{r['method']} ({r['h']:g})") + _cell(d, lambda r: f"DOP853 ({r['tol']:g})")
                         + _cell(rd, lambda r: f"Radau ({r['tol']:g})"))
                print(f"| {name} | {e:.0e} | " + " | ".join(cells) + f" | {ratio} |")
    p = DATA / "invariants.json"
    if p.exists():
        inv = json.loads(p.read_text())
        runs = [dict(r, error=None if r["I1"] is None else max(r["I1"], r["I2"])) for r in inv["runs"]]
        m = inv["meta"]
        hs = sorted({r.get("h", 10.0) for r in inv["runs"] if "tol" not in r})
        print(f"\nInvariants, guiding_centre_symmetric, T = {m['T']:g}, h = {', '.join(f'{h:g}' for h in hs)}; "
              "error: the larger of the noncanonical I₁ and I₂ relative errors at T:\n")
        print("| error ≤ | fastest VPRK pair (h) | time | DOP853 (tol) | time | Radau (tol) | time | best scipy / VPRK |")
        print("|---|---|---:|---|---:|---|---:|---:|")
        for e in (1e-6, 1e-9, 1e-11):
            reach = lambda r: r["error"] is not None and r["error"] <= e and not r.get("broke")  # noqa: E731
            v = fastest([r for r in runs if "tol" not in r], reach)
            d = fastest([r for r in runs if r["method"] == "DOP853"], reach)
            rd = fastest([r for r in runs if r["method"] == "Radau"], reach)
            cells = (_cell(v, lambda r: f"{r['method']} ({r.get('h', 10.0):g})") + _cell(d, lambda r: f"DOP853 ({r['tol']:g})")
                     + _cell(rd, lambda r: f"Radau ({r['tol']:g})"))
            best = min([r["wall"] for r in (d, rd) if r is not None], default=None)
            ratio = "—" if v is None or best is None else f"{best / v['wall']:.1f}×"
            print(f"| {e:.0e} | " + " | ".join(cells) + f" | {ratio} |")
        print("\nEvery run (relative errors of I₁ / I₂ at T, wall time):\n")
        print("| run | h or tol | I₁ | I₂ | time |")
        print("|---|---:|---:|---:|---:|")
        for r in sorted(inv["runs"], key=lambda r: ("tol" in r, r["method"], r.get("h", 0), -r.get("tol", 0))):
            f = lambda x: "—" if x is None else f"{x:.1e}"     # noqa: E731
            note = f" ({r['broke']} points broke down)" if r.get("broke") else ""
            print(f"| {r['method']}{note} | {r.get('h', r.get('tol', 10.0)):g} | {f(r['I1'])} | {f(r['I2'])} | {r['wall']:.0f} s |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("trajectory")
    t.add_argument("--systems", nargs="+", default=list(SYSTEMS))
    t.add_argument("--points", type=int, default=NPOINTS, help="points per run (16; 1 for single trajectories)")
    i = sub.add_parser("invariants")
    i.add_argument("--steps", type=int, default=10000, help="steps of h = 10: T = 10 steps")
    i.add_argument("--h", nargs="+", type=float, default=[10.0, 20.0, 40.0, 80.0], help="step sizes of the VPRK runs")
    i.add_argument("--pairs", nargs="+")
    i.add_argument("--scipy", nargs="*", default=["DOP853", "Radau"],
                   help="scipy methods to compare (Radau at 1e-10 alone takes about 18 minutes)")
    sub.add_parser("plot")
    sub.add_parser("table")
    args = ap.parse_args()
    {"trajectory": trajectory, "invariants": invariants, "plot": plot, "table": table}[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
