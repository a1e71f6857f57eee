"""The lane kernel against the scalar kernel it replaced, side by side in one run (docs/benchmarks.md).

    python scripts/studies/engine_lanes.py [--points 10000] [--previous 0581e1c] [--out docs/figures/engine_lanes.json]

* The previous kernel (integrators/kernel.py at ``--previous``, one point at a time) is read from
  git history into a temporary module and driven with the same generated point functions, so both
  kernels run in this process on the same points.
* For each pair: point-steps per second of the previous kernel, of the new kernel's scalar path
  (W = 1) and of its lanes (W = kernel.LANES), one thread, guiding_centre_symmetric at h = 10 with
  the benchmark's 10⁴ points near the default loop (2 warm-up steps, then 10 steps in one call);
  W = 8 on 2 threads; Newton iterations per step; and whether every field of the three states is
  bitwise equal.
* The instructions of the compiled kernel (its non-inlined functions for W = 8 and W = 1): packed
  double-precision arithmetic (``v…pd``) against scalar (``v…sd``).
* A flop count per Newton iteration *as coded* (the generated point functions' operators and the
  kernel's loops, Jacobian refreshes left out, so a lower bound), times the measured iterations per
  step, over the clock: flop per cycle before and after.
"""
import argparse
import functools
import importlib.util
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import integrators
import invariants
from integrators import kernel
from integrators.codegen import point_functions
from integrators.costmodel import flops_per_iteration
from integrators.engine import _lagrange_matrix, set_threads

ROOT = Path(__file__).resolve().parents[2]
PAIRS = [("GLRK2", "symmetric"), ("GLRK1", "none"), ("SRK3", "symmetric"), ("GLRK4", "symmetric"),
         ("LobIIIA3", "standard"), ("GLRK2", "symplectic"), ("GLRK3", "midpoint")]
FIELDS = ("q", "p", "Lam", "q_comp", "p_comp", "Y", "mu", "live", "iterations", "steps")


def previous_kernel(rev):
    """The scalar kernel at ``rev`` as a module.  It was one file, integrators/kernel.py, up to the
    kernel's split into integrators/kernel/ (the study compares with the kernel the lanes replaced,
    0581e1c, which drives its own argument list): a revision without that file is refused in one line."""
    got = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:integrators/kernel.py"], capture_output=True,
                         text=True)
    if got.returncode != 0:
        raise SystemExit(f"--previous {rev}: no integrators/kernel.py there (the study reads the one-file scalar "
                         "kernel the lanes replaced, such as 0581e1c)")
    src = got.stdout
    folder = Path(tempfile.mkdtemp())
    (folder / "previous_kernel.py").write_text(src)
    spec = importlib.util.spec_from_file_location("previous_kernel", folder / "previous_kernel.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def rate(eng, q0, run):
    st = eng.state(q0)
    run(st, 1, 2)
    its0, steps0 = st.iterations.sum(), st.steps.sum()
    t = time.perf_counter()
    run(st, 3, 10)
    wall = time.perf_counter() - t
    return st, q0.shape[0] * 10 / wall, (st.iterations.sum() - its0) / max(1, st.steps.sum() - steps0)


def asm_counts():
    """Packed vs scalar double arithmetic in the compiled kernel (``advance`` with everything it
    calls linked in) for d = 4, W = 1 and W = LANES.  numba shows no assembly of cached code, so this
    compiles afresh in a child process with an empty numba cache (about two minutes)."""
    code = ("import json, numpy as np, integrators, sys; sys.path.insert(0, %r); import engine_lanes; "
            "sy = integrators.system('guiding_centre_symmetric'); "
            "eng = integrators.Engine(sy, integrators.tableau('GLRK2'), 'symmetric', 10.0); "
            "[eng.advance(eng.state(np.tile(sy.defaults['q0'], (8, 1))), 1, 1, lanes=W) for W in (1, %d)]; "
            "print(json.dumps(engine_lanes._asm_here()))") % (str(Path(__file__).parent), kernel.LANES)
    env = dict(os.environ, NUMBA_CACHE_DIR=tempfile.mkdtemp())
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return {int(k): v for k, v in json.loads(r.stdout.strip().splitlines()[-1]).items()}


def _asm_here():
    out = {}
    pat_p = re.compile(r"\bv(add|sub|mul|div|sqrt|min|max)pd\b")
    pat_s = re.compile(r"\bv(add|sub|mul|div|sqrt|min|max)sd\b")
    for sig in kernel.advance.signatures:
        arg = functools.partial(kernel.advance_argument, sig)
        if "complex" in str(arg("st_")) or "UniTuple(int64 x 4)" not in str(arg("dim")):
            continue
        asm = kernel.advance.inspect_asm(sig)
        packed, scalar = len(pat_p.findall(asm)), len(pat_s.findall(asm))
        out[len(arg("proto"))] = {"packed": packed, "scalar": scalar, "packed_share": packed / max(1, packed + scalar)}
    return out


def output_vs_step(h=10.0, reps=30):
    """One output of the paper's sets (I₁ of the 2,000-point loop and I₂ of the 100 × 100 surface in
    all three forms, each set's forms together as the driver computes them, and the energy,
    momentum and constraint errors of all 12,000 points, Diagnostics.point_errors) against one GLRK2-symmetric step of the
    same 12,000 points in lanes, one thread.  Outputs timed back to back, then interleaved with
    5-step calls of the engine as in a run (the steps' 14 MB of Newton factors leave the caches
    cold for the output); the minimum of ``reps`` each."""
    from invariants.forms import first_invariants, second_invariants
    gc = integrators.system("guiding_centre_symmetric")
    loop, surf = invariants.loop("guiding_centre", 2000), invariants.surface("guiding_centre", 100, 100)
    pts = np.concatenate([loop, surf.reshape(-1, 4)])
    set_threads(1)
    eng = integrators.Engine(gc, integrators.tableau("GLRK2"), "symmetric", h)
    st = eng.state(pts)
    eng.advance(st, 1, 2)
    q, p, lam = st.q, st.p, st.Lam / h
    from types import SimpleNamespace
    from integrators.service.diagnostics import Diagnostics
    diag = Diagnostics(SimpleNamespace(diagnostics=("energy", "momentum", "constraint")), gc, pts)

    def output():
        first_invariants(q[:2000], list(invariants.FORMS), system=gc, p=p[:2000], lam=lam[:2000], h=h)
        second_invariants(q[2000:].reshape(surf.shape), list(invariants.FORMS), system=gc,
                          p=p[2000:].reshape(surf.shape), lam=lam[2000:].reshape(surf.shape), h=h)
        diag.point_errors(q, p, st.live)

    output()
    alone = []
    for _ in range(reps):                       # outputs back to back: their own data stay in cache
        t = time.perf_counter()
        output()
        alone.append(time.perf_counter() - t)
    outs, steps = [], []
    for k in range(reps):                       # interleaved, so that both see the same machine
        t = time.perf_counter()
        output()
        outs.append(time.perf_counter() - t)
        t = time.perf_counter()
        eng.advance(st, 3 + 5 * k, 5)           # steps as a run takes them: several a call
        steps.append((time.perf_counter() - t) / 5)
    set_threads(None)
    t_out, t_step = min(outs), min(steps)       # the least disturbed of each (a shared, noisy machine)
    return dict(output_s=t_out, step_s=t_step, output_in_steps=t_out / t_step,
                output_back_to_back_s=min(alone), output_back_to_back_in_steps=min(alone) / t_step,
                output_median_s=float(np.median(outs)), step_median_s=float(np.median(steps)),
                output_in_steps_median=float(np.median(outs) / np.median(steps)), reps=reps)


def clock_hz():
    try:
        mhz = [float(ln.split(":")[1]) for ln in open("/proc/cpuinfo") if ln.startswith("cpu MHz")]
        return 1e6 * max(mhz)
    except (OSError, ValueError):
        return float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=10000)
    ap.add_argument("--previous", default="0581e1c")
    ap.add_argument("--out", default=str(ROOT / "docs/figures/engine_lanes.json"))
    args = ap.parse_args()
    old = previous_kernel(args.previous)
    sy = integrators.system("guiding_centre_symmetric")
    rng = np.random.default_rng(0)
    q0 = invariants.loop("guiding_centre", args.points)
    q0 = q0 + 1e-3 * rng.standard_normal(q0.shape)
    ev, inside = point_functions(sy)
    hz = clock_hz()
    rows = []
    for tab, proj in PAIRS:
        tableau = integrators.tableau(tab)
        eng = integrators.Engine(sy, tableau, proj, 10.0)
        set_threads(1)

        # the previous kernel's layouts (its engine's flat tableau: no d_lo, E s × s), six tolerances
        parts = (tableau.a, tableau.a_lo, tableau.abar, tableau.abar_lo, tableau.b, tableau.b_lo,
                 tableau.d if tableau.d is not None else np.zeros(tableau.s),
                 _lagrange_matrix(tableau.c - 1.0, tableau.c))
        tab_old = np.concatenate([np.asarray(x, dtype=np.float64).ravel() for x in parts])

        def run_old(st, first, n):
            old.advance(ev, inside, eng.k, tab_old, tuple(eng.plan), eng.h, 0.0, first, n, False, 64,
                        st._tuple(eng.nz), (0,) * sy.d, eng._cfg[:6])
        s_old, r_old, its = rate(eng, q0, run_old)
        s_1, r_1, _ = rate(eng, q0, lambda st, f, n: eng.advance(st, f, n, lanes=1))
        s_w, r_w, _ = rate(eng, q0, lambda st, f, n: eng.advance(st, f, n, lanes=kernel.LANES))
        set_threads(2)
        _, r_w2, _ = rate(eng, q0, lambda st, f, n: eng.advance(st, f, n, lanes=kernel.LANES))
        set_threads(None)
        same = all(np.array_equal(getattr(s_old, f), getattr(x, f)) for x in (s_1, s_w) for f in FIELDS)
        flops = flops_per_iteration(sy, tableau, eng) * its
        row = dict(pair=f"{tab}-{proj}", previous=r_old, scalar_path=r_1, lanes=r_w, lanes_2_threads=r_w2,
                   speedup=r_w / r_old, threads_2_over_1=r_w2 / r_w, iterations_per_step=its, bitwise_equal=same,
                   flops_per_step=flops, flop_per_cycle_previous=flops * r_old / hz,
                   flop_per_cycle_lanes=flops * r_w / hz)
        rows.append(row)
        print(f"{row['pair']:>20}: previous {r_old:>10,.0f}  W=1 {r_1:>10,.0f}  W={kernel.LANES} {r_w:>10,.0f} "
              f"({row['speedup']:.2f}×)  2 threads {r_w2:>10,.0f} ({row['threads_2_over_1']:.2f}×)  "
              f"{its:.2f} it/step  ≥{flops:.0f} flop/step  flop/cycle {row['flop_per_cycle_previous']:.2f} → "
              f"{row['flop_per_cycle_lanes']:.2f}  bits equal {same}", flush=True)
    asm = asm_counts()
    for W, c in asm.items():
        print(f"W={W}: {c['packed']} packed and {c['scalar']} scalar double instructions "
              f"({100 * c['packed_share']:.0f} % packed)")
    ovs = output_vs_step()
    print(f"one output of the paper's sets {1e3 * ovs['output_s']:.1f} ms after steps "
          f"({1e3 * ovs['output_back_to_back_s']:.1f} ms back to back), one step of their 12,000 points "
          f"{1e3 * ovs['step_s']:.1f} ms: {ovs['output_in_steps']:.2f} steps "
          f"({ovs['output_back_to_back_in_steps']:.2f} back to back)")
    out = dict(machine=platform.processor() or platform.machine(), clock_hz=hz, points=args.points,
               previous=args.previous, lanes=kernel.LANES, rows=rows, asm=asm, output_vs_step=ovs,
               command="python scripts/studies/engine_lanes.py --points %d" % args.points)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
