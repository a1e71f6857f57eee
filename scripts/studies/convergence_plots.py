"""Convergence plots of every pair whose measured order differs from the paper by more than 0.5.

    python scripts/studies/convergence_plots.py     # reads docs/figures/convergence.json, writes docs/figures/convergence_disagreements.png
"""
import json
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def main():
    data = json.loads((ROOT / "docs" / "figures" / "convergence.json").read_text())
    rows = data["runs"] if isinstance(data, dict) else data
    bad = [r for r in rows
           if any(np.isfinite(r[k]) and abs(r[k] - r[p]) > 0.5
                  for k, p in (("order_solution", "paper_energy"), ("order_energy", "paper_energy"),
                               ("order_momentum", "paper_momentum")))]
    ncol = 4
    nrow = int(np.ceil(len(bad) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4 * ncol, 3.2 * nrow), squeeze=False)
    for ax, r in zip(axes.flat, bad):
        h = np.array(r["h"])
        for key, lab, m in (("solution_error", "solution", "o-"), ("energy_error", "energy", "s-"),
                            ("momentum_error", "momentum", "^-")):
            ax.loglog(h, r[key], m, ms=4, label=lab)
        for p, ls in ((r["paper_energy"], ":"), (r["paper_momentum"], "--")):
            ax.loglog(h, 1e-3 * (h / h[0]) ** p, "k" + ls, lw=0.8)
        for floor in sorted(set((data.get("floors") or {"reference": 1e-12}).values())):
            ax.axhline(floor, color="grey", lw=0.5)           # round-off floors below which no order is fitted
        ax.set_title(f"{r['tableau']}-{r['projection']}  paper: {r['paper_energy']}/{r['paper_momentum']}", fontsize=9)
        ax.set_xlabel("h")
        ax.set_ylabel("error")
        ax.grid(True, which="both", lw=0.3)
    for ax in list(axes.flat)[len(bad):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("Point vortices: pairs whose measured order differs from the paper by > 0.5 "
                 "(black: paper's energy (dotted) and momentum (dashed) slopes; grey: 1e-12 fit floor)", fontsize=10)
    fig.tight_layout()
    out = ROOT / "docs" / "figures" / "convergence_disagreements.png"
    fig.savefig(out, dpi=80)
    print(out)


if __name__ == "__main__":
    main()
