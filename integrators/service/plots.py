"""PNG plots of a run file (``poincare plot run.h5``).

* ``<stem>_I1_<form>.png``, ``<stem>_I2_<form>.png``: the paper's figure grid — rows are
  projections, columns are tableaus — of the relative invariant error |I(t) − I(0)|/|I(0)|
  against time, log scale (errors span decades; exact zeros, as at t = 0, are not drawn).  Outputs at
  which the set was under-resolved are shaded grey, outputs from its first broken-down point on
  red; a pair that is not ``ok`` is labelled with its status.  A damaged file (failed checksum, missing datasets) is one error line.
* ``<stem>_diagnostics.png``: energy, momentum and constraint errors, one panel each, every pair.
* ``<stem>_points.png``: the loop and the surface in the (q¹, q²) plane at five output times,
  when the run stored its points.
* ``<stem>_refinement.png``: for sets with ``refine_to``, the points each output's invariant was
  taken on, against time, every pair.
"""
from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .output import pair_name  # noqa: E402
from .reader import read_run  # noqa: E402
from .statuses import relative_error  # noqa: E402

FLOOR = 1e-17


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


def _grid(run, inv, form, out):
    tabs, projs = run.grid()
    shaded = shaded_broke = False
    fig, axes = plt.subplots(len(projs), len(tabs), figsize=(max(3.4 * len(tabs), 6.0), 2.3 * len(projs) + 0.6),
                             sharex=True, sharey=True, squeeze=False)
    for i, p in enumerate(projs):
        for j, t in enumerate(tabs):
            ax = axes[i, j]
            pr = run.pairs.get(pair_name(t, p))
            values = None if pr is None else (pr.I1 if inv == "I1" else pr.I2).get(form)
            if values is not None:
                rel = np.asarray(relative_error(values, f"{inv}/{form}" in pr.absolute), dtype=float)
                ax.semilogy(pr.t, np.where(rel > 0, rel, np.nan), lw=0.9, ms=3,   # zeros (t = 0) not drawn
                            marker="." if np.count_nonzero(rel > 0) < 30 else None)
                if rel.size > 1 and not np.any(rel[1:] > 0) and np.all(np.isfinite(rel)):
                    ax.text(0.5, 0.5, "0 at every output", transform=ax.transAxes, fontsize=7, ha="center")
                _law_line(ax, pr, f"{inv} {form}")
                broke = ~np.isfinite(values)        # red from the set's first broken point on (no invariant)
                for a, b in _stretches(pr.t, broke):
                    ax.axvspan(a, b, color="C3", alpha=0.18, lw=0, label="broken down")
                    shaded_broke = True
                if inv in pr.resolved:              # grey where the set did not resolve its invariant
                    for a, b in _stretches(pr.t, (pr.resolved[inv] == 0) & ~broke):
                        ax.axvspan(a, b, color="0.6", alpha=0.35, lw=0, label="under-resolved")
                        shaded = True
                status = pr.status
                if status == "under-resolved" and inv not in pr.under_resolved_from:
                    status = ""                     # the other set is the under-resolved one
                if status not in ("ok", ""):
                    ax.text(0.02, 0.9, status, transform=ax.transAxes, fontsize=7, color="C3")
            ax.grid(True, which="major", lw=0.3)
            if i == 0:
                ax.set_title(t, fontsize=10)
            if j == 0:
                ax.set_ylabel(f"{p}\nrel. error", fontsize=8)
            if i == len(projs) - 1:
                ax.set_xlabel("t", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].set_ylim(FLOOR / 2, None)
    _time_axis(axes[0, 0], run)
    fig.suptitle(f"{'first' if inv == 'I1' else 'second'} Poincaré invariant {inv}, {form} form: "
                 f"|{inv}(t) − {inv}(0)| / |{inv}(0)|\n(dashed: the fitted growth law C·t^α of its window "
                 "maxima, from where it holds)" + _caption(shaded, shaded_broke),
                 fontsize=10)
    fig.tight_layout()
    _save(fig, out)
    plt.close(fig)


def _time_axis(ax, run):
    """The run's time span on ``ax`` (not only the drawn points': zeros are not drawn)."""
    ts = [pr.t for pr in run.pairs.values() if pr.t.size]
    if ts:
        lo, hi = min(float(t.min()) for t in ts), max(float(t.max()) for t in ts)
        if hi > lo:
            ax.set_xlim(lo - 0.03 * (hi - lo), hi + 0.03 * (hi - lo))


def _law_line(ax, pr, key, colour="k"):
    """The fitted growth law C·t^α from its onset (dashed) and its name, where the file has one."""
    if key not in pr.growth:
        return
    law, alpha, err, onset, logc = pr.growth[key]
    t = pr.t[(pr.t >= onset) & (pr.t > 0)]
    if t.size > 1 and np.isfinite(logc) and np.isfinite(alpha):
        ax.semilogy(t, np.maximum(np.exp(logc + alpha * np.log(t)), FLOOR), "--", color=colour, lw=0.7)
    label = law if not np.isfinite(alpha) else f"{law}, α = {alpha:.2f}"
    ax.text(0.98, 0.04, label, transform=ax.transAxes, fontsize=6.5, ha="right", color="0.25")


def _caption(under, broke):
    parts = (["grey: the set is under-resolved there"] if under else []) + \
        (["red: points of the set broke down, no invariant"] if broke else [])
    return "".join(f"\n({p})" for p in parts)


def _absolute_energy(run) -> bool:
    """Whether the file records some points' energy error as absolute (H0 = 0: its root attribute)."""
    import h5py
    try:
        with h5py.File(run.path, "r") as f:
            return int(f.attrs.get("energy_absolute_points", 0)) > 0
    except (OSError, ValueError):
        return False


DIAGNOSTIC_AXES = {"energy": "max |H − H₀|/|H₀|  (relative)", "momentum": "max |P − P₀|  (absolute)",
                   "constraint": "max |p − ϑ(q)|  (absolute)"}


def _diagnostics(run, out):
    """Energy, momentum and constraint errors, one panel each, every pair: each axis says what it
    measures, values of exactly 0 (t = 0) are not drawn (no floor that reads as data), and each
    panel's legend (the pairs with that error's growth law) sits below it, off the curves."""
    diags = [d for d in ("energy", "momentum", "constraint") if any(d in pr.errors for pr in run.pairs.values())]
    if not diags:
        return False
    n = len(run.pairs)
    rows = (n + 1) // 2
    fig, axes = plt.subplots(1, len(diags), figsize=(5 * len(diags), 3.4 + 0.16 * rows), squeeze=False)
    for ax, d in zip(axes[0], diags):
        for k, (name, pr) in enumerate(run.pairs.items()):
            if d in pr.errors and pr.errors[d].shape[0]:
                law = pr.growth.get(d, ("",))[0]
                e = np.asarray(pr.errors[d], dtype=float)
                ax.semilogy(pr.t, np.where(e > 0, e, np.nan), lw=0.8, label=f"{name}: {law}" if law else name,
                            ls=("-", "--", ":", "-.")[k // 10 % 4], ms=3,
                            marker="." if np.count_nonzero(e > 0) < 30 else None)   # (a few outputs: points)
        label = DIAGNOSTIC_AXES[d]
        if d == "energy" and _absolute_energy(run):
            label += "; absolute where H₀ = 0"
        ax.set_ylabel(label, fontsize=8)
        ax.set_title(f"{d} error", fontsize=10)
        _time_axis(ax, run)
        ax.set_xlabel("t")
        ax.grid(True, lw=0.3)
    for ax in axes[0]:                      # each panel's own legend, below it
        if ax.get_legend_handles_labels()[0]:      # (none before any pair wrote a row)
            ax.legend(fontsize=6, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.2), frameon=False)
    fig.tight_layout()
    _save(fig, out)
    plt.close(fig)
    return True


def _points(run, out):
    rows = {n: min([pr.t.size] + [len(v) for v in pr.points.values()]) for n, pr in run.pairs.items() if pr.points}
    names = [n for n, k in rows.items() if k > 0]      # (a run stopped before a pair's first row: none)
    if not names:
        return False
    pr = run.pairs[names[0]]
    t = pr.t[:rows[names[0]]]
    picks = np.unique(np.linspace(0, len(t) - 1, 5).round().astype(int))
    fig, ax = plt.subplots(figsize=(6, 5))
    for k, idx in enumerate(picks):
        col = plt.cm.viridis(k / max(1, len(picks) - 1))
        if "loop" in pr.points:
            q = pr.points["loop"][idx]
            ax.plot(np.append(q[:, 0], q[0, 0]), np.append(q[:, 1], q[0, 1]), color=col, lw=1, label=f"t = {t[idx]:g}")
        if "surface" in pr.points:
            s = pr.points["surface"][idx]
            ax.plot(s[..., 0].ravel(), s[..., 1].ravel(), ".", ms=1, color=col)
    ax.set_xlabel("q¹")
    ax.set_ylabel("q²")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7)
    ax.set_title(f"advected sample points ({names[0]})", fontsize=10)
    fig.tight_layout()
    _save(fig, out)
    plt.close(fig)
    return True


def _save(fig, out):
    """fig as the PNG ``out``, written beside it and renamed over it: a symbolic link (or anything)
    at ``out`` is replaced as an entry of the folder, never written through."""
    import tempfile
    out = Path(out)
    fd, tmp = tempfile.mkstemp(prefix=".plot-", suffix=".png", dir=out.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    try:
        os.chmod(tmp, 0o666 & ~umask)          # a plain file's mode, not mkstemp's 0600
        fig.savefig(tmp, dpi=90)
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def plot_file(path, outdir=None):
    """Write every plot of a run file; returns the list of PNG paths.  The file is read by
    :func:`integrators.service.output.read_run`: a damaged dataset is one DamagedFile naming it."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"'{path}' does not exist")
    outdir = Path(outdir) if outdir else path.parent
    try:
        outdir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"cannot make the plot folder '{outdir}': {exc.strerror or exc}") from None
    if not os.access(outdir, os.W_OK | os.X_OK):
        raise ValueError(f"cannot write plots in '{outdir}' (permission denied): give another folder with -o")
    run = read_run(path)
    if not run.pairs:
        raise ValueError(f"'{path}' holds no runs")
    stem = path.stem
    written = []
    first = next(iter(run.pairs.values()))
    for inv, forms in (("I1", first.I1), ("I2", first.I2)):
        for form in forms:
            out = outdir / f"{stem}_{inv}_{form}.png"
            _grid(run, inv, form, out)
            written.append(out)
    out = outdir / f"{stem}_diagnostics.png"
    if _diagnostics(run, out):
        written.append(out)
    out = outdir / f"{stem}_points.png"
    if _points(run, out):
        written.append(out)
    out = outdir / f"{stem}_refinement.png"
    if _refinement(run, out):
        written.append(out)
    return written


def _level_label(n, inv):
    """A refinement level by its size: "256" points of a loop, "47 × 47" of a square surface."""
    r = int(round(n ** 0.5))
    return f"{r} × {r}" if inv == "I2" and r * r == n else f"{n:,}"


def _refinement(run, out):
    """The points each refining set's invariant was taken on, against time (a step line): pairs
    whose series are the same are one line, labelled with all of them; the legend below the panel."""
    sets = [inv for inv in ("I1", "I2") if any(inv in pr.points_used for pr in run.pairs.values())]
    if not sets:
        return False
    fig, axes = plt.subplots(1, len(sets), figsize=(5.2 * len(sets), 3.8), squeeze=False)
    for ax, inv in zip(axes[0], sets):
        groups = {}                                     # the same (t, points) series: one line
        for name, pr in run.pairs.items():
            if inv in pr.points_used and pr.t.size:
                n = min(pr.t.size, pr.points_used[inv].size)
                key = (pr.t[:n].tobytes(), np.asarray(pr.points_used[inv][:n]).tobytes())
                groups.setdefault(key, (pr.t[:n], pr.points_used[inv][:n], []))[2].append(name)
        for k, (t, used, names) in enumerate(groups.values()):
            label = names[0] if len(names) == 1 else (f"{len(names)} pairs, the same: " + ", ".join(names)
                                                      if len(names) <= 3 else f"all {len(names)} pairs, the same"
                                                      if len(names) == len(run.pairs) else
                                                      f"{len(names)} pairs, the same: {names[0]} … {names[-1]}")
            ax.step(t, used, where="post", lw=1.0, label=label, ls=("-", "--", ":", "-.")[k // 10 % 4])
        ax.set_yscale("log", base=2)
        levels = sorted({int(x) for _, used, _ in groups.values() for x in np.asarray(used) if x > 0})
        ax.set_yticks(levels, [_level_label(x, inv) for x in levels])    # the levels used, by their sizes
        ax.minorticks_off()
        ax.set_title(f"{'loop' if inv == 'I1' else 'surface'} ({inv})", fontsize=10)
        ax.set_ylabel("points the invariant was taken on", fontsize=8)
        ax.set_xlabel("t", fontsize=8)
        ax.grid(True, which="major", lw=0.3)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.18), frameon=False)
    fig.suptitle("refining sample sets: the coarsest nested level\nwhose invariant the monitor vouches for",
                 fontsize=10)
    fig.tight_layout()
    _save(fig, out)
    plt.close(fig)
    return True
