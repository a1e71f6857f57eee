"""PNG plots of a run file (``poincare plot run.h5``).

* ``<stem>_I1_<form>.png``, ``<stem>_I2_<form>.png``: the paper's figure grid — rows are
  projections, columns are tableaus — of the relative invariant error |I(t) − I(0)|/|I(0)|
  against time, log scale (errors span decades; exact zeros are drawn at 1e-17).  Outputs at
  which the set was under-resolved are shaded grey; a pair that is not ``ok`` is labelled
  with its status.  A damaged file (failed checksum, missing datasets) is one error line.
* ``<stem>_diagnostics.png``: energy, momentum and constraint errors, one panel each, every pair.
* ``<stem>_points.png``: the loop and the surface in the (q¹, q²) plane at five output times,
  when the run stored its points.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

FLOOR = 1e-17


def _pairs(f):
    """(tableaus, projections) in the scene's order (HDF5 lists groups alphabetically)."""
    try:
        from .scene import parse_scene
        sc = parse_scene(f.attrs["scene"])
        maps = [t for t, p in sc.pairs if p == "map"]
        return list(sc.tableaus) + maps, list(sc.projections) + (["map"] if maps else [])
    except (KeyError, ValueError):
        pass
    names = list(f["runs"])
    tabs, projs = [], []
    for n in names:
        t, p = n.rsplit("-", 1)
        if t not in tabs:
            tabs.append(t)
        if p not in projs:
            projs.append(p)
    return tabs, projs


def _read(g, name):
    """A dataset's values; a failed checksum or missing dataset is a DamagedFile naming it."""
    from .output import DamagedFile, plain_error
    try:
        return g[name][...]
    except (OSError, KeyError) as exc:
        raise DamagedFile(f"'{g.file.filename}' is damaged: cannot read {g.name}/{name} "
                          f"({plain_error(exc)})") from None


def _stretches(t, bad):
    """(start, end) time intervals covering the outputs flagged in ``bad`` (half an output beyond)."""
    out = []
    if t.size == 0 or not bad.any():
        return out
    dt = (t[1] - t[0]) if t.size > 1 else 1.0
    idx = np.flatnonzero(bad)
    start = prev = idx[0]
    for k in list(idx[1:]) + [None]:
        if k is None or k != prev + 1:
            out.append((t[start] - dt / 2, t[prev] + dt / 2))
            if k is not None:
                start = k
        if k is not None:
            prev = k
    return out


def _rel(v):
    v = np.asarray(v, dtype=float)
    if v.size == 0 or not np.isfinite(v[0]) or v[0] == 0:
        return np.full_like(v, np.nan)
    return np.maximum(np.abs(v - v[0]) / abs(v[0]), FLOOR)


def _grid(f, inv, form, out):
    tabs, projs = _pairs(f)
    shaded = False
    fig, axes = plt.subplots(len(projs), len(tabs), figsize=(max(3.4 * len(tabs), 6.0), 2.3 * len(projs) + 0.6),
                             sharex=True, sharey=True, squeeze=False)
    for i, p in enumerate(projs):
        for j, t in enumerate(tabs):
            ax = axes[i, j]
            name = f"{t}-{p}"
            if name in f["runs"] and f"{inv}/{form}" in f["runs"][name]:
                g = f["runs"][name]
                times = _read(g, "t")
                ax.semilogy(times, _rel(_read(g, f"{inv}/{form}")), lw=0.9)
                if f"resolved/{inv}" in g:          # grey where the set did not resolve its invariant
                    bad = _read(g, f"resolved/{inv}") == 0
                    for a, b in _stretches(times, bad):
                        ax.axvspan(a, b, color="0.6", alpha=0.35, lw=0, label="under-resolved")
                        shaded = True
                status = g.attrs.get("status", "")
                if status == "under-resolved" and f"under_resolved_from/{inv}" not in g.attrs:
                    status = ""                     # the other set is the under-resolved one
                if status not in ("ok", ""):
                    ax.text(0.02, 0.9, str(status), transform=ax.transAxes, fontsize=7, color="C3")
            ax.grid(True, which="major", lw=0.3)
            if i == 0:
                ax.set_title(t, fontsize=10)
            if j == 0:
                ax.set_ylabel(f"{p}\nrel. error", fontsize=8)
            if i == len(projs) - 1:
                ax.set_xlabel("t", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].set_ylim(FLOOR / 2, None)
    fig.suptitle(f"{'first' if inv == 'I1' else 'second'} Poincaré invariant {inv}, {form} form: "
                 f"|{inv}(t) − {inv}(0)| / |{inv}(0)|" + ("\n(grey: the set is under-resolved there)" if shaded else ""),
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)


def _diagnostics(f, out):
    diags = [d for d in ("energy_error", "momentum_error", "constraint_error")
             if any(d in f["runs"][n] for n in f["runs"])]
    if not diags:
        return False
    fig, axes = plt.subplots(1, len(diags), figsize=(5 * len(diags), 3.6), squeeze=False)
    for ax, d in zip(axes[0], diags):
        for k, name in enumerate(f["runs"]):
            g = f["runs"][name]
            if d in g and g[d].shape[0]:
                ax.semilogy(_read(g, "t"), np.maximum(_read(g, d), FLOOR), lw=0.8, label=name,
                            ls=("-", "--", ":", "-.")[k // 10 % 4])
        ax.set_title(d.replace("_", " ") + (" (relative)" if d == "energy_error" else ""), fontsize=10)
        ax.set_xlabel("t")
        ax.grid(True, lw=0.3)
    axes[0, -1].legend(fontsize=6, ncol=2, loc="lower right")
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return True


def _points(f, out):
    names = [n for n in f["runs"] if "points" in f["runs"][n]]
    if not names:
        return False
    g = f["runs"][names[0]]
    t = g["t"][...]
    picks = np.unique(np.linspace(0, len(t) - 1, 5).round().astype(int))
    fig, ax = plt.subplots(figsize=(6, 5))
    for k, idx in enumerate(picks):
        col = plt.cm.viridis(k / max(1, len(picks) - 1))
        if "points/loop" in g:
            q = g["points/loop"][idx]
            ax.plot(np.append(q[:, 0], q[0, 0]), np.append(q[:, 1], q[0, 1]), color=col, lw=1, label=f"t = {t[idx]:g}")
        if "points/surface" in g:
            s = g["points/surface"][idx]
            ax.plot(s[..., 0].ravel(), s[..., 1].ravel(), ".", ms=1, color=col)
    ax.set_xlabel("q¹")
    ax.set_ylabel("q²")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7)
    ax.set_title(f"advected sample points ({names[0]})", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return True


def plot_file(path, outdir=None):
    """Write every plot of a run file; returns the list of PNG paths."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"'{path}' does not exist")
    outdir = Path(outdir) if outdir else path.parent
    outdir.mkdir(parents=True, exist_ok=True)
    from .output import DamagedFile, plain_error
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ValueError(f"cannot read '{path}': {plain_error(exc)}") from None
    with f:
        try:
            return _plot_all(f, path, outdir)
        except (KeyError, OSError, TypeError, IndexError) as exc:
            raise DamagedFile(f"'{path}' is damaged or not a poincare run file ({type(exc).__name__}: "
                              f"{plain_error(exc)})") from None


def _plot_all(f, path, outdir):
    stem = path.stem
    written = []
    if "runs" not in f or not len(f["runs"]):
        raise ValueError(f"'{path}' holds no runs")
    first = f["runs"][list(f["runs"])[0]]
    for inv in ("I1", "I2"):
        if inv in first:
            for form in first[inv]:
                out = outdir / f"{stem}_{inv}_{form}.png"
                _grid(f, inv, form, out)
                written.append(out)
    out = outdir / f"{stem}_diagnostics.png"
    if _diagnostics(f, out):
        written.append(out)
    out = outdir / f"{stem}_points.png"
    if _points(f, out):
        written.append(out)
    return written
