"""The double-double type's accuracy against 50-digit mpmath: for each operation and function, the
largest and the median error over random samples of its domain, in units of 2⁻¹⁰⁴ relative
("dd-ulps": the last bit of a double-double).  Prints the table that docs/engine.md holds.

    python scripts/studies/engine_ddouble_accuracy.py [--samples 2000] [--seed 0]
"""
from __future__ import annotations

import argparse

import mpmath
import numpy as np

from integrators import ddouble as D
from integrators.ddouble_check import UNARY, _add, _atan2, _div, _mul, _sub, dd_of, samples, ulps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    mpmath.mp.dps = 50
    rows = []
    for name, (fn, ref, (lo, hi), _) in sorted(UNARY.items()):
        errs = []
        for x in samples(lo, hi, args.samples, args.seed):
            h, l_ = dd_of(x)
            errs.append(ulps(fn(h, l_), ref(D.value(h, l_))))
        rows.append((name, f"[{lo:g}, {hi:g}]", max(errs), float(np.median(errs))))
    for name, op, ref in (("+", _add, lambda a, b: a + b), ("−", _sub, lambda a, b: a - b),
                          ("×", _mul, lambda a, b: a * b), ("÷", _div, lambda a, b: a / b),
                          ("atan2", _atan2, mpmath.atan2)):
        errs = []
        for x, y in zip(samples(-1e6, 1e6, args.samples, args.seed + 1), samples(-1e3, 1e3, args.samples, args.seed + 2)):
            a, b = dd_of(x), dd_of(y)
            errs.append(ulps(op(*a, *b), ref(D.value(*a), D.value(*b))))
        rows.append((name, "x ∈ [−1e6, 1e6], y ∈ [−1e3, 1e3]", max(errs), float(np.median(errs))))
    print(f"{args.samples} samples each, seed {args.seed}; error in dd-ulps (2^-104 relative)")
    print("| operation | domain sampled | largest | median |")
    print("|---|---|---|---|")
    for name, dom, worst, med in rows:
        print(f"| {name} | {dom} | {worst:.2f} | {med:.2f} |")


if __name__ == "__main__":
    main()
