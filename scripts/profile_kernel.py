"""Where a step's time goes inside the compiled kernel: cycle counters around its parts (issue 43).

    python scripts/profile_kernel.py [GLRK2-symmetric GLRK1-none …] [--orbit]

cProfile sees nothing inside the kernel and this machine's perf has no hardware counters, so this
script builds an instrumented copy of the package in a temporary folder: the same kernel source with
``llvm.readcyclecounter`` (rdtsc) read around its parts — the residual iterations with and without a
fresh Jacobian, the LU factorisation, the solve, the update and convergence test, the system's point functions
(inside the residual), a step's attempt, a whole step — and counters of iterations,
factorisations and second tries; caching off.  It
runs the benchmark's points (guiding_centre_symmetric, h = 10, 10⁴ points near the default loop
and spread over its bounding box; with ``--orbit`` one trajectory of 20,000 steps) one thread, and
prints cycles per group-step (W = 8 points; per step for an orbit).  The counters are calls of
non-inlined functions (about 30-40 cycles each, some 200 cycles an iteration in all), charged to
"the rest of the attempt": read the parts against each other, not as exact totals.  The patch is
made by text: if the kernel's lines it looks for have moved, the script says which and stops.
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

HEADER = '''
import ctypes as _ct
from numba.extending import intrinsic as _intrinsic
from llvmlite import ir as _ir
from numba.core import cgutils as _cg
from numba import types as _types
_PROF = (_ct.c_double * 32)()
_PROF_ADDR = _ct.addressof(_PROF)


@_intrinsic
def _rdtsc(typingctx):
    def codegen(context, builder, sig, args):
        fn = _cg.get_or_insert_function(builder.module, _ir.FunctionType(_ir.IntType(64), []), "llvm.readcyclecounter")
        return builder.call(fn, [])
    return _types.int64(), codegen


@_intrinsic
def _paddr(typingctx, a):
    def codegen(context, builder, sig, args):
        return builder.inttoptr(args[0], _ir.DoubleType().as_pointer())
    return _types.CPointer(_types.float64)(a), codegen


@njit(inline='never', error_model="numpy", nogil=True)     # (inlined, the counters were lost)
def _count(slot):
    _paddr(_PROF_ADDR)[slot] += 1.0


@njit(inline='never', error_model="numpy", nogil=True)
def _tick(slot, t0):
    t = _rdtsc()
    p = _paddr(_PROF_ADDR)
    p[slot] += float(t - t0)
    return _rdtsc()
'''

PATCHES = [
    ('_OPTS = dict(cache=True, error_model="numpy", nogil=True)',
     '_OPTS = dict(cache=False, error_model="numpy", nogil=True)\n' + HEADER),
    ("            _main(z, jac, r, Jx, ev, k, h, tb, plan, d, s, w, S)\n",
     "            t0 = _rdtsc()\n            _main(z, jac, r, Jx, ev, k, h, tb, plan, d, s, w, S)\n"
     "            t0 = _tick(0 if jac else 1, t0)\n            _count(10)\n"),
    ("            lu_factor(Jx, pivx, nz)\n",
     "            t0 = _rdtsc()\n            lu_factor(Jx, pivx, nz)\n            t0 = _tick(2, t0)\n            _count(14)\n"),
    ("        lu_solve(LU, piv, r, nz)                  # r is now −δ\n",
     "        t0 = _rdtsc()\n        lu_solve(LU, piv, r, nz)                  # r is now −δ\n        t0 = _tick(3, t0)\n"),
    ("        _judge(f, F, tol, cfg.stall_complex if is_complex(z) else cfg.stall, refresh)\n",
     "        _judge(f, F, tol, cfg.stall_complex if is_complex(z) else cfg.stall, refresh)\n"
     "        t0 = _tick(4, t0)\n"),
    ("        ev(raw(at(Q, i * d)), k, jac, raw(at(th, i * d)), raw(at(T, i * dd)), raw(at(TT, i * ddd)),\n"
     "           raw(at(dH, i * d)), raw(at(HH, i * dd)))\n",
     "        t9 = _rdtsc()\n        ev(raw(at(Q, i * d)), k, jac, raw(at(th, i * d)), raw(at(T, i * dd)), raw(at(TT, i * ddd)),\n"
     "           raw(at(dH, i * d)), raw(at(HH, i * dd)))\n        _tick(8, t9)\n"),
    ("    ev(raw(x), k, need, raw(at(w, S.pth + slot * d)), raw(at(w, S.pT + slot * dd)),\n"
     "       raw(at(w, S.pTT + slot * dd * d)), raw(at(w, S.pdH + slot * d)), raw(at(w, S.pHH + slot * dd)))\n",
     "    t9 = _rdtsc()\n    ev(raw(x), k, need, raw(at(w, S.pth + slot * d)), raw(at(w, S.pT + slot * dd)),\n"
     "       raw(at(w, S.pTT + slot * dd * d)), raw(at(w, S.pdH + slot * d)), raw(at(w, S.pHH + slot * dd)))\n"
     "    _tick(8, t9)\n"),
    ("    _attempt(mand(ld(f, F.have) != 0.0, mnot(again)), guess, mug, ev, inside, k, h, tb, plan, d, s, nz, w, S, f, F, ip,\n"
     "             IP, qr, cfg)\n",
     "    t0 = _rdtsc()\n    _attempt(mand(ld(f, F.have) != 0.0, mnot(again)), guess, mug, ev, inside, k, h, tb, plan, d, s, nz, w,"
     " S, f, F, ip,\n             IP, qr, cfg)\n    t0 = _tick(5, t0)\n    if anyl(again):\n        _count(12)\n"),
    ("        over = _step(t0 + (float(first) + ld(f, F.jn)) * h, ev, inside, kp, h, tb, plan, d, s, nz, w, S, f, F, ip, IP,\n"
     "                     qr, cfg)\n",
     "        tt = _rdtsc()\n        over = _step(t0 + (float(first) + ld(f, F.jn)) * h, ev, inside, kp, h, tb, plan, d, s, nz, w,"
     " S, f, F, ip, IP,\n                     qr, cfg)\n        tt = _tick(7, tt)\n        _count(13)\n"),
]

CHILD = r'''
import sys, time, numpy as np
import integrators, invariants
from integrators import kernel
from integrators.engine import set_threads
set_threads(1)
gc = integrators.system("guiding_centre_symmetric")
rng = np.random.default_rng(1)
q0 = invariants.loop("guiding_centre", 10000)
sets = {"loop": q0 + 1e-3 * rng.standard_normal(q0.shape)}
lo, hi = q0.min(0), q0.max(0)
sets["box"] = lo + (hi - lo) * rng.random(q0.shape)
names = ["jacobian it.", "residual it.", "factorise", "solve", "update+judge", "attempt", "", "step", "point fns"]
orbit = sys.argv[1] == "1"
for pair in sys.argv[2:]:
    tab, proj = pair.split("-")
    for nm, q in ((("orbit", sets["loop"][:1]),) if orbit else sets.items()):
        eng = integrators.Engine(gc, integrators.tableau(tab), proj, 10.0)
        st = eng.state(q); eng.advance(st, 1, 2)
        P = np.frombuffer(kernel._PROF, dtype=np.float64); P[:] = 0
        steps = 20000 if orbit else 10
        t = time.perf_counter(); eng.advance(st, 3, steps); w = time.perf_counter() - t
        g = P[13]
        print(f"{pair:16s} {nm:5s} {q.shape[0] * steps / w:11,.0f}/s | " + "  ".join(f"{n} {P[i] / g:6.0f}" for i, n in enumerate(names) if n)
              + f" | iterations {P[10] / g:.2f} factorisations {P[14] / g:.2f} retries {P[12] / g:.3f}", flush=True)
'''


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs", nargs="*", default=["GLRK2-symmetric", "GLRK1-none", "SRK3-symmetric", "GLRK4-symmetric"])
    ap.add_argument("--orbit", action="store_true", help="one trajectory (W = 1) instead of 10⁴ points in lanes")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    for sub in ("integrators", "invariants"):
        shutil.copytree(ROOT / sub, tmp / sub, ignore=shutil.ignore_patterns("__pycache__"))
    path = tmp / "integrators" / "kernel.py"
    text = path.read_text()
    for old, new in PATCHES:
        if old not in text:
            sys.exit(f"profile_kernel.py: integrators/kernel.py no longer has the line(s)\n{old}\nupdate PATCHES")
        text = text.replace(old, new)
    path.write_text(text)
    print("cycles (rdtsc) per group-step of 8 points" + (" (per step: one orbit)" if args.orbit else ""), flush=True)
    env = dict(os.environ, PYTHONPATH=str(tmp), POINCARE_CACHE=str(tmp / "cache"))
    subprocess.run([sys.executable, "-c", CHILD, "1" if args.orbit else "0", *args.pairs], env=env, check=True,
                   cwd=str(tmp))                  # (the copy first on sys.path, before an editable install)
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
