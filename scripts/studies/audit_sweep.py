"""Barham & Burby's sweeps in one audit_map call each (docs/audit.md, "Sweeps over step sizes").

    python scripts/studies/audit_sweep.py --json pic.json                 # the PIC at full size (~35 min on 2 cores)
    python scripts/studies/audit_sweep.py --poisson fem --rk2 heun --peer-start DIR --degrees 2 --json pic2.json
                                             # the study's discretisation and start (DIR: the peer's checkout)
    python scripts/studies/audit_sweep.py --particles 1024 --loop-points 4096 --json small.json
    python scripts/studies/audit_sweep.py --pendula 4096 --loop-points 4096 --json pendula.json
    python scripts/studies/audit_sweep.py --invariant 2048 4096 [--peer DIR]  # I₁ alone, best of 3
    python scripts/studies/audit_sweep.py --peer-map DIR    # our PIC step against the peer's, same points

``--invariant D N``: the canonical I₁ with its monitor (whole, and as the audit sums it over blocks)
on one loop of D periodic coordinates and N points; with ``--peer DIR`` (a checkout of
github.com/wbarham/symplectic_diagnostic, run from its own environment's Python) its
``LoopIntegral(N, period=L).compute`` on the same loop instead.

A 1-D electrostatic PIC (integrators.audit.examples.pic: B-splines of degree 1, 2, 3, the field
energy's exact gradient, a Landau start α = 0.01; ``--poisson fem`` the study's finite-element
Laplacian GᵀMG/Δ² instead of the spectral one), Strang and RK2 (``--rk2 heun``: Heun's, the study's), ten step sizes dt = 2⁻¹ … 2⁻¹⁰,
audited by one ``audit_map`` call per degree in one-step mode (``steps=1``) on a loop of radius 1 in
every coordinate (``plane="every"``, the study's loop).  Each degree runs in its own process: its
wall and CPU time, peak resident memory (ru_maxrss), and every verdict, defect, one-step error and
jump count go to the JSON; the table is printed as markdown.  ``--pendula K``: the pendulum array
instead (integrators.audit.examples.pendulum_array, K pendula, Strang and RK2, the same sweep and loop).
"""
from __future__ import annotations

import argparse
import json
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HS = [2.0 ** -j for j in range(1, 11)]


def peer_start(peer, particles):
    """The study's Landau start from the peer's own ``landau_IC`` (its checkout, run, not copied):
    boxsize 50, thermal speed 1, A = 0.5, mode 1, seed 42, as its ``simulate.py`` defaults."""
    sys.path.insert(0, str(Path(peer) / "pic_1d"))
    from pic_1d import landau_IC
    return landau_IC(particles, 50.0, 1.0, 0.5, 1, seed=42)


def one(degree, particles, cells, loop_points, radius, pendula=None, poisson="spectral", rk2="rk2", peer=None):
    """One degree's audit (or with ``pendula``, the pendulum array's) in this process: a JSON-able row."""
    from integrators.audit import examples
    from integrators.audit.maps import audit_map
    maps, info = {}, None
    for method in ("strang", rk2):
        if pendula:
            maps[method], info = examples.pendulum_array(pendula, method=method)
        else:
            maps[method], info = examples.pic(particles=particles, cells=cells, length=50.0 if peer else 4 * np.pi,
                                              degree=degree, method=method, poisson=poisson)
    if pendula:
        rng = np.random.default_rng(1)
        point, particles, degree = (rng.uniform(0, 2 * np.pi, pendula), 0.5 * rng.standard_normal(pendula)), pendula, "pendula"
    else:
        point = peer_start(peer, particles) if peer else info["landau"]()
    t0, c0 = time.perf_counter(), time.process_time()
    rep = audit_map(maps, point, HS, steps=1, loop_points=loop_points, radius=radius, plane="every",
                    period=info["period"], defect_points=2)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    out = {"degree": degree, "poisson": None if pendula else poisson, "start": "peer" if peer else "ours",
           "length": info["period"], "particles": particles, "cells": cells,
           "loop_points": loop_points, "radius": radius,
           "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
           "peak_rss_MiB": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
           "state_MiB": round(loop_points * 2 * particles * 8 / 2**20), "maps": {}}
    for c in rep["candidates"]:
        d = c["defect"]["canonical"]
        out["maps"][c["name"]] = {
            "h": HS, "verdict": [v["verdict"] for v in c["verdicts"]],
            "defect": [d["defect"][d["h"].index(h)] for h in HS], "defect_order": d["order"],
            "one_step_error": c["one_step"]["error"], "one_step_order": c["one_step"]["order"],
            "one_step_floor": c["one_step"]["floor"],
            "jumps": [len(r["discontinuity"]["jumps"]) if r["discontinuity"] else None for r in c["runs"]]}
    return out


def invariant_timing(D, N, peer=None):
    """Wall and CPU seconds (best of 3 by wall) of I₁ on one loop: ours whole and blocked, or the peer's."""
    L = 4 * np.pi
    rng = np.random.default_rng(1)
    pos, vel = rng.uniform(0, L, D), rng.standard_normal(D)
    th = 2 * np.pi * np.arange(N) / N

    def best(f):
        out = []
        for _ in range(3):
            w, c = time.perf_counter(), time.process_time()
            f()
            out.append((time.perf_counter() - w, time.process_time() - c))
        return min(out)
    if peer:
        sys.path.insert(0, str(peer))
        from loop_integrals_par import LoopIntegral          # the peer's code, run, not copied
        q, p = np.mod(pos[:, None] + np.sin(th)[None], L), vel[:, None] + np.cos(th)[None]
        li = LoopIntegral(N, period=L)
        return {"peer": best(lambda: li.compute(q, p))}
    import invariants
    from integrators.audit.maps import _blocked_first_invariant
    x, v = np.mod(pos[None] + np.cos(th)[:, None], L), vel[None] + np.sin(th)[:, None]
    P = np.full(D, L)
    whole = lambda: invariants.first_invariant(x, "canonical", p=v, period=P)
    whole()                                                   # compiled once before timing
    return {"whole": best(whole), "blocked": best(lambda: _blocked_first_invariant(x, v, P))}


def peer_map_check(peer, particles=4096, cells=128, points=8):
    """The peer's PIC step (its ``PICSimulation``, run, not copied: boxsize 50, n0 1, a Landau start
    A = 0.5 from its ``landau_IC`` of seed 42, points of its radius-1 loop) beside ours with the study's
    discretisation (``poisson="fem"``, Heun for its RK2; degree 2 translated by Δ/2, our shape being
    centred on its node): the largest |Δx|, |Δv| over ``points`` loop points and every dt, per degree
    and method."""
    sys.path.insert(0, str(Path(peer) / "pic_1d"))
    from pic_1d import PICSimulation, landau_IC
    from integrators.audit import examples
    L = 50.0
    pos, vel = landau_IC(particles, L, 1.0, 0.5, 1, seed=42)
    th = 2 * np.pi * np.arange(points) / points
    xs, vs = np.mod(pos[None] + np.sin(th)[:, None], L), vel[None] + np.cos(th)[:, None]
    out = {}
    for degree in (1, 2, 3):
        shift = 0.5 * L / cells if degree == 2 else 0.0
        for method, symplectic in (("strang", True), ("heun", False)):
            ours, _ = examples.pic(particles, cells, L, degree, method, poisson="fem")
            dx = dv = scale = 0.0
            for h in HS:
                sim = PICSimulation(particles, cells, h, L, 1.0, None, None, order_space=degree,
                                    symplectic=symplectic)
                theirs = []
                for x, v in zip(xs, vs):
                    sim.initialize(x, v)
                    sim.step()
                    theirs.append((sim.pos.copy(), sim.vel.copy()))
                x1, v1 = ours(np.mod(xs - shift, L), vs, h)
                x1 = np.mod(x1 + shift, L)
                for i, (xp, vp) in enumerate(theirs):
                    d = np.abs(x1[i] - xp)
                    dx = max(dx, float(np.max(np.minimum(d, L - d))))
                    dv = max(dv, float(np.max(np.abs(v1[i] - vp))))
                    scale = max(scale, float(np.max(np.abs(vp))))
            out[f"degree {degree} {method}"] = (dx, dv, scale)
    return out


def markdown(rows):
    lines = ["| degree | map | verdicts dt = 2⁻¹ … 2⁻¹⁰ | defect at 2⁻¹, 2⁻¹⁰ (order) | one-step e at 2⁻¹, 2⁻¹⁰ "
             "(order) | jumps found | wall · CPU | peak memory (state) |", "|---|---|---|---|---|---|---|---|"]
    short = {"symplectic": "S", "not symplectic": "N", "discontinuous": "D", "cannot tell at this h": "?",
             "broke down": "B"}
    for r in rows:
        for name, m in r["maps"].items():
            o = "—" if m["defect_order"] is None else f"{m['defect_order']:.2f}"
            o1 = "—" if m["one_step_order"] is None else f"{m['one_step_order']:.2f}"
            lines.append(f"| {r['degree']} | {name} | {''.join(short.get(v, '?') for v in m['verdict'])} | "
                         f"{m['defect'][0]:.1e}, {m['defect'][-1]:.1e} ({o}) | {m['one_step_error'][0]:.1e}, "
                         f"{m['one_step_error'][-1]:.1e} ({o1}) | {max(m['jumps'])} | {r['wall_s']:.0f} s · "
                         f"{r['cpu_s']:.0f} s | {r['peak_rss_MiB']:,} MiB ({r['state_MiB']:,} MiB) |")
    return "\n".join(lines) + "\n\nS symplectic, N not symplectic, D discontinuous (the loop's image jumps)."


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=4096)
    ap.add_argument("--cells", type=int, default=128)
    ap.add_argument("--loop-points", type=int, default=16384)
    ap.add_argument("--radius", type=float, default=1.0)
    ap.add_argument("--degrees", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--poisson", choices=("spectral", "fem"), default="spectral",
                    help="the PIC's Poisson solve: spectral (1/k²) or the study's finite elements (GᵀMG/Δ²)")
    ap.add_argument("--rk2", choices=("rk2", "heun"), default="rk2",
                    help="the non-symplectic method: the explicit midpoint rule, or Heun's (the study's)")
    ap.add_argument("--pendula", type=int, default=None, help="the pendulum array of this many pendula instead")
    ap.add_argument("--invariant", type=int, nargs=2, default=None, metavar=("D", "N"))
    ap.add_argument("--peer", default=None, help="with --invariant: the peer's checkout instead of ours")
    ap.add_argument("--peer-start", default=None, metavar="DIR",
                    help="the PIC on [0, 50) from the peer's Landau start (A = 0.5, seed 42; its checkout)")
    ap.add_argument("--peer-map", default=None, metavar="DIR",
                    help="our PIC step beside the peer's PICSimulation on the same points (its checkout)")
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)   # a child: one degree, JSON on stdout
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    if a.peer_map:
        for name, (dx, dv, scale) in peer_map_check(a.peer_map, a.particles, a.cells).items():
            print(f"{name}: max |Δx| {dx:.1e}, max |Δv| {dv:.1e} (|v| up to {scale:.1f}; {a.particles} particles, "
                  f"{a.cells} cells, 8 loop points, dt 2⁻¹ … 2⁻¹⁰)")
        return
    if a.invariant:
        for name, (w, c) in invariant_timing(*a.invariant, a.peer).items():
            print(f"{name}: wall {w:.3f} s, CPU {c:.3f} s (D = {a.invariant[0]}, N = {a.invariant[1]})")
        return
    if a.one is not None:
        print(json.dumps(one(a.one, a.particles, a.cells, a.loop_points, a.radius, a.pendula, a.poisson, a.rk2,
                             a.peer_start)))
        return
    rows = []
    for deg in ([0] if a.pendula else a.degrees):
        child = subprocess.run([sys.executable, __file__, "--one", str(deg), "--particles", str(a.particles),
                                "--cells", str(a.cells), "--loop-points", str(a.loop_points), "--radius",
                                str(a.radius), "--poisson", a.poisson, "--rk2", a.rk2]
                               + (["--peer-start", a.peer_start] if a.peer_start else []) + (["--pendula", str(a.pendula)] if a.pendula else []),
                               capture_output=True, text=True)
        if child.returncode != 0:
            raise SystemExit(child.stderr)
        rows.append(json.loads(child.stdout.strip().splitlines()[-1]))
        print(f"degree {deg}: {rows[-1]['wall_s']} s", file=sys.stderr, flush=True)
    print(markdown(rows))
    if a.json:
        Path(a.json).write_text(json.dumps({"machine": platform.platform(), "date": time.strftime("%Y-%m-%d"),
                                            "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
