"""The audit of black-box canonical step maps at scale (docs/audit.md, "Step maps in any dimension").

    python scripts/studies/audit_maps.py                       # every table (~15 min on 2 cores)
    python scripts/studies/audit_maps.py --only pendula pic     # some of them
    python scripts/studies/audit_maps.py --json docs/figures/audit_maps.json

* ``pendula``: `poincare audit --map pendula-strang` and `pendula-rk2` (each map its own process),
  k = 1,024 and 4,096 pendula, a 1,024-point loop, 100 steps, defects at 3 step sizes: wall time,
  peak resident memory (the process's ru_maxrss), verdicts, defect orders.
* ``pic``: the same for `pic-strang` and `pic-rk2` (cubic B-splines, 64 cells) with 10,000 particles.
* ``scaling``: the drift half alone (20 steps of Strang pendula, a 256-point loop) for d = 2k from 16
  to 16,384: seconds per loop point and step, split into the map's calls and the invariants.
* ``probes``: the matrix-free defect against the dense one where both run (RK2 pendula, k = 16):
  their ratio for 2, 4, 8, 16 and 32 probe pairs, over 20 seeds.
* ``loop``: the canonical I₁ with its monitor against a plain FFT loop integral, N = 4,096, D = 2, 100,
  1,000 coordinates.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
POINCARE = str(Path(sys.executable).parent / "poincare")


def whole(maps, k, extra=()):
    """One `poincare audit --map` per map in a child process: wall, peak RSS, verdicts."""
    rows = []
    for m in maps:
        out = Path(f"/tmp/audit_maps_{os.getpid()}_{m}.json")
        cmd = [POINCARE, "audit", "--map", m, "--k", str(k), "--steps", "100", "--loop-points", "1024",
               "--levels", "3", "--json", str(out), "-q", *extra]
        t0 = time.perf_counter()
        child = subprocess.run(["/usr/bin/time", "-f", "%M", *cmd], capture_output=True, text=True) \
            if Path("/usr/bin/time").exists() else None
        if child is None:
            child = subprocess.run(cmd, capture_output=True, text=True)
            rss = None
        else:
            rss = int(child.stderr.strip().splitlines()[-1]) * 1024
        wall = time.perf_counter() - t0
        if child.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed: {child.stderr}")
        rep = json.loads(out.read_text())
        out.unlink()
        c = rep["candidates"][0]
        d = c["drift"]["I1/canonical"]
        f = c["defect"]["canonical"]
        rows.append(dict(map=m, k=k, d=2 * k, wall_s=round(wall, 1), peak_rss_MiB=None if rss is None else round(rss / 2**20),
                         drift_verdict=d["verdict"], drift_max=d["max_error"], resolution=d["resolution"],
                         defect=f["defect"], order=f["order"], defect_verdict=f["verdict"], jacobian=c["jacobian"]))
        print(f"{m:16s} k = {k:6d}: {wall:6.1f} s, peak {rows[-1]['peak_rss_MiB']} MiB; drift {d['verdict']} "
              f"(max e {d['max_error']:.1e}, monitor {d['resolution']:.1e}); defect {f['verdict']}, order "
              f"{f['order'] if f['order'] is None else round(f['order'], 2)}", flush=True)
    return rows


def scaling():
    from integrators.audit import examples
    from integrators.audit.maps import _loop, _plane
    import invariants
    rows = []
    for k in (8, 32, 128, 512, 2048, 8192):
        step, info = examples.pendulum_array(k, method="strang")
        rng = np.random.default_rng(1)
        z0 = np.concatenate([rng.uniform(0, 2 * np.pi, k), 0.5 * rng.standard_normal(k)])
        z = _loop(z0, _plane(2 * k, None, None), 0.1, 256)
        t_map = t_inv = 0.0
        for _ in range(20):
            t = time.perf_counter()
            x, v = step(z[:, :k], z[:, k:], 0.1)
            t_map += time.perf_counter() - t
            z = np.concatenate([x, v], axis=1)
            t = time.perf_counter()
            invariants.first_invariant(x, "canonical", p=v, period=2 * np.pi)
            t_inv += time.perf_counter() - t
        per = lambda s: s / (20 * 256)
        rows.append(dict(d=2 * k, map_s_per_point_step=per(t_map), invariant_s_per_point_step=per(t_inv)))
        print(f"d = {2 * k:6d}: map {per(t_map) * 1e6:8.2f} µs, invariant {per(t_inv) * 1e6:8.2f} µs per loop point and "
              "step", flush=True)
    return rows


def time_one(fn):
    """Seconds of one call of fn (after one warm-up call)."""
    fn()
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def loop_cost():
    """The canonical I₁ of a 4,096-point loop with its monitor against the plain FFT loop integral (the
    numpy one-liner: FFT, multiply by 2πik, inverse FFT, sum p·q'), side by side: best of 7 samples of
    about 20 ms of back-to-back calls each (a single 0.1 ms call is timed with tens of % of jitter)."""
    import invariants
    rows = []
    N = 4096
    tau = np.arange(N) / N
    k = 2 * np.pi * np.fft.fftfreq(N, 1.0 / N)
    for D in (2, 100, 1000):
        rng = np.random.default_rng(D)
        modes = np.arange(1, 9)
        a = rng.standard_normal((2, len(modes), D)) * 0.5 ** modes[None, :, None]
        q = 1.0 + np.einsum("km,md->kd", np.cos(2 * np.pi * np.outer(tau, modes)), a[0])
        p = np.einsum("km,md->kd", np.sin(2 * np.pi * np.outer(tau, modes)), a[1])

        def plain():
            dq = np.fft.ifft(1j * k[:, None] * np.fft.fft(q, axis=0), axis=0).real
            return float(np.sum(p * dq) / N)

        def ours():
            return invariants.first_invariant(q, "canonical", p=p).value

        best, calls = {}, max(1, int(0.02 / max(time_one(plain), 1e-6)))   # about 20 ms a sample
        for name, fn in (("plain", plain), ("ours", ours)) * 2:
            for _ in range(7):
                t = time.perf_counter()
                for _ in range(calls):
                    fn()
                best[name] = min(best.get(name, np.inf), (time.perf_counter() - t) / calls)
        rows.append(dict(N=N, D=D, plain_ms=best["plain"] * 1e3, ours_ms=best["ours"] * 1e3,
                         ratio=best["ours"] / best["plain"], agree=abs(plain() - ours()) / abs(plain())))
        print(f"N = {N}, D = {D:5d}: ours {best['ours'] * 1e3:8.3f} ms, plain {best['plain'] * 1e3:8.3f} ms, "
              f"ratio {rows[-1]['ratio']:.2f}; values agree to {rows[-1]['agree']:.1e}", flush=True)
    return rows


def probes():
    from integrators.audit import examples
    from integrators.audit.maps import map_defect
    step, _ = examples.pendulum_array(16, method="rk2")
    rng = np.random.default_rng(2)
    z = np.concatenate([rng.uniform(0, 2 * np.pi, 16), 0.5 * rng.standard_normal(16)])[None]
    dense = map_defect(step, z, 0.1, dense=True)[0]
    rows = []
    for p in (2, 4, 8, 16, 32):
        r = np.array([map_defect(step, z, 0.1, probes=p, seed=s, dense=False)[0] / dense for s in range(20)])
        rows.append(dict(probes=p, dense=dense, ratio_min=float(r.min()), ratio_median=float(np.median(r)),
                         ratio_max=float(r.max())))
        print(f"{p:3d} probe pairs: probe / dense defect {r.min():.2f} … {r.max():.2f} (median {np.median(r):.2f}) over "
              f"20 seeds; dense {dense:.2e}", flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=("pendula", "pic", "scaling", "probes", "loop"))
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    todo = args.only or ("pendula", "pic", "scaling", "probes", "loop")
    out = dict(machine=f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
               date=time.strftime("%Y-%m-%d"))
    if "pendula" in todo:
        out["pendula"] = whole(["pendula-strang", "pendula-rk2"], 1024) + whole(["pendula-strang", "pendula-rk2"], 4096)
    if "pic" in todo:
        out["pic"] = whole(["pic-strang", "pic-rk2"], 10000)
    if "scaling" in todo:
        out["scaling"] = scaling()
    if "probes" in todo:
        out["probes"] = probes()
    if "loop" in todo:
        out["loop"] = loop_cost()
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
