"""A projection's own post term: what a process pays to compile its kernel, and what the next one pays.

    export POINCARE_CACHE=$(mktemp -d)
    python scripts/studies/post_term_cache.py; python scripts/studies/post_term_cache.py

Each run is one process: it imports the package, adds docs/engine.md's toy (the momentum reset) and
integrates 3 point-vortex points 12 steps with GLRK2, printing the seconds of the import, of the
integrate call and of both.  The first run with an empty $POINCARE_CACHE compiles the kernel with the
post term and saves its entry (integrators.codegen.post_entry); a second run loads it
(docs/benchmarks-history.md).
"""
import time

t0 = time.perf_counter()
from numba import njit  # noqa: E402

import integrators  # noqa: E402
from integrators.kernel import END, evaluate  # noqa: E402
from integrators.projections import Projection  # noqa: E402
from integrators.simd import at, ld, st  # noqa: E402


@njit(inline="always")
def reset_post(z, jac, r, J, ev, k, sig, d, w, S):
    """p_{n+1} = ϑ(q̂), residual Λ (docs/engine.md, "Adding a projection")."""
    evaluate(ev, k, at(w, S.qh), False, w, S, END, d)
    th, p1 = at(w, S.pth + END * d), at(w, S.p1)
    for m in range(d):
        st(p1, m, ld(th, m))
        st(r, m, ld(z, m))
    if jac:
        for m in range(d):
            for n in range(d):
                st(J, m * d + n, 1.0 if m == n else 0.0)


if __name__ == "__main__":
    reset = Projection("reset", "none", "start", True, "end", "one", (), post_term=reset_post)
    t1 = time.perf_counter()
    integrators.integrate(integrators.system("point_vortices"), [[1, 0.1, 1, -0.1]] * 3, tableau="GLRK2",
                          projection=reset, h=0.1, steps=12)
    t2 = time.perf_counter()
    print(f"import {t1 - t0:.1f} s, integrate {t2 - t1:.1f} s, whole {t2 - t0:.1f} s")
