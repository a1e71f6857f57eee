"""The audit of a list of candidates on a scene: both measurements, the text report and the plots."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .defect import DEFECT_FLOOR, defect_study
from .discrimination import discrimination
from invariants.growth import BOUNDED_BELOW, FASTER_FROM, LINEAR_FROM, growth_law

from .drift import RESOLVED, ROUNDOFF, drift_verdict, run_drift

NEAR_FLOOR = 10.0      # a drift verdict with max e within this factor above ROUNDOFF is said to be near the floor


def audit(candidates, scene, *, references=(), defect_points=4, levels=5, method="auto", progress=None,
          drift=True, defect=True):
    """Run both measurements (or the one asked for) for every candidate and reference.

    Returns the JSON-able report (see :func:`text_report` for its reading).
    """
    system = scene.system()
    pts = scene.loop_points() if scene.loop is not None else scene.surface_points().reshape(-1, system.d)
    sel = np.linspace(0, pts.shape[0], defect_points, endpoint=False).astype(int)
    qd = pts[sel]
    report = {"scene": scene.name, "system": scene.system_name, "h": scene.h, "steps": scene.steps,
              "T": scene.h * scene.steps, "thresholds": {"roundoff": ROUNDOFF, "growth_exponents": [BOUNDED_BELOW, LINEAR_FROM, FASTER_FROM],
                                                         "resolved": RESOLVED,
                                                         "defect_floor": DEFECT_FLOOR},
              "defect_points": qd.tolist(), "candidates": [],
              "discrimination": discrimination(system, pts, scene.h)       # a warning about projected methods:
              if any(c.kind == "pair" for c in list(candidates) + list(references)) else None}   # only with one
    for cand, role in [(c, "candidate") for c in candidates] + [(c, "reference") for c in references]:
        entry = {"name": cand.name, "role": role, "kind": cand.kind, "breakdown_step": None, "drift": {},
                 "t": [], "errors": {}, "defect": {}, "jacobian": None}
        if drift:
            if progress:
                progress(f"{cand.name}: invariant drift over {scene.steps} steps")
            t, series, broke, resolution = run_drift(cand, scene)
            for key, err in series.items():
                res = resolution.get(key.split("/")[0], 0.0)
                g = growth_law(t, err)
                emax, rate, verdict = drift_verdict(t, err, broke is not None, res, law=g)
                entry["drift"][key] = {"max_error": emax, "drift_rate": rate, "verdict": verdict, "resolution": res,
                                       "near_floor": bool(ROUNDOFF < emax <= NEAR_FLOOR * ROUNDOFF),
                                       "growth_law": g.law, "growth_exponent": g.exponent,
                                       "growth_exponent_error": g.exponent_error, "growth_onset": g.onset}
            entry.update(breakdown_step=broke, t=t.tolist(), errors={k: v.tolist() for k, v in series.items()})
        if defect:
            if progress:
                progress(f"{cand.name}: one-step defects at {len(qd)} points, {levels} step sizes")
            try:
                entry["defect"], entry["jacobian"] = defect_study(cand.step, system, qd, scene.h, levels, method,
                                                                  cand.reads)
            except Exception as exc:      # the user's map raised: a verdict, not a traceback
                why = f"step failed ({cand.name} raised {type(exc).__name__}: {exc})"
                entry["defect"] = {form: {"h": [scene.h * 2.0 ** -k for k in range(levels)], "defect": None,
                                          "order": None, "verdict": why}
                                   for form in ("canonical", "noncanonical", "corrected")}
                entry["jacobian"] = "none (the map raised)"
        report["candidates"].append(entry)
    return report


def _fmt(x, spec=".1e"):
    if x is None:
        return "—"
    if isinstance(x, float) and not math.isfinite(x):
        return "nan"
    return format(x, spec)


def text_report(report) -> str:
    """The human-readable report (of a sweep over step sizes: :func:`sweep_text`)."""
    if report.get("sweep"):
        return sweep_text(report)
    lines = [f"Symplecticity audit on scene '{report['scene']}' ({report['system']}, h = {report['h']:g}, "
             f"{report['steps']} steps, T = {report['T']:g})",
             f"thresholds: round-off ≤ {ROUNDOFF:g}; growth e ∝ t^α of the window maxima (invariants.growth): "
             f"bounded α < {BOUNDED_BELOW:g}, random walk < {LINEAR_FROM:g}, drifting ≤ {FASTER_FROM:g}, growing above; "
             f"defect floor {DEFECT_FLOOR['complex step']:g} (complex step), "
             f"{DEFECT_FLOOR['central differences']:g} (central differences)", "",
             "Invariant drift: max |I(t) − I(0)|/|I(0)|, drift rate [1/time], resolution monitor, verdict"]
    if report.get("discrimination"):
        lines[1:1] = [f"warning: {report['discrimination']}"]
    for c in report["candidates"]:
        head = f"  {c['name']} ({c['role']})" + (f" — a point broke down at step {c['breakdown_step']}"
                                                  if c["breakdown_step"] else "")
        lines.append(head)
        for key, r in c["drift"].items():
            alpha = r.get("growth_exponent")
            grow = f" (α = {alpha:.2f})" if alpha is not None and math.isfinite(alpha) else ""
            near = (f"; near the round-off floor ({ROUNDOFF:.0e}): max e within {NEAR_FLOOR:g}x of it, so this "
                    "law may be round-off's, not the method's" if r.get("near_floor") else "")
            lines.append(f"    {key:18s} {_fmt(r['max_error']):>9s} {_fmt(r['drift_rate'], '+.1e'):>9s} "
                         f"{_fmt(r['resolution']):>9s}  {r['verdict']}{grow}{near}")
            if r["verdict"] == "under-resolved" and r.get("under_resolved_reason"):
                lines.append(f"      why: {r['under_resolved_reason']}")
        if c.get("energy_error"):          # a step map's audit given an energy function
            law = f"; {c['energy_growth_law']}" if c.get("energy_growth_law") else ""
            lines.append(f"    {'energy':18s} {_fmt(max(c['energy_error'])):>9s}  (max |H − H(0)|/|H(0)| over the "
                         f"points and outputs{law})")
    lines += ["", "One-step symplecticity defect (relative) for h, h/2, …, fitted order in h, verdict"]
    for c in report["candidates"]:
        lines.append(f"  {c['name']} ({c['role']}, Jacobian by {c['jacobian']})")
        for form, r in c["defect"].items():
            vals = " ".join(f"{_fmt(v):>8s}" for v in r["defect"]) if r["defect"] else ""
            order = f"order {r['order']:.2f}" if r["order"] is not None else ""
            lines.append(f"    {form:13s} {vals:45s} {order:11s} {r['verdict']}")
            if r.get("reason"):
                lines.append(f"    {'':13s} ({r['reason']})")
    return "\n".join(lines)


def sweep_text(report) -> str:
    """The human-readable report of a map audit over a list of step sizes: one line per h and map
    (the defect, the loop's error after one step or the run's largest, the jumps, the verdict), and
    each map's orders."""
    mode = report["sweep"]["mode"]
    lines = [f"Symplecticity audit over {len(report['h'])} step sizes on '{report['scene']}' ({report['system']}, "
             f"{mode} each; the sets and I(0) built once)",
             f"thresholds: round-off ≤ {ROUNDOFF:g} (I₁); defect floor {DEFECT_FLOOR['complex step']:g} (complex step), "
             f"{DEFECT_FLOOR['central differences']:g} (central differences)", "",
             f"  {'h':>12s} {'defect':>9s} {'I₁ error':>9s} {'jumps':>6s}  verdict"]
    for c in report["candidates"]:
        form = next(iter(c["defect"]))
        d = c["defect"][form]
        one = c.get("one_step")
        lines.append(f"  {c['name']} (Jacobian by {c['jacobian']})")
        for i, (r, v) in enumerate(zip(c["runs"], c["verdicts"])):
            key = f"I1/{form}"
            at = d["h"].index(v["h"]) if v["h"] in d["h"] else None
            dv = d["defect"][at] if at is not None and d["defect"] else None
            e = one["error"][i] if one else r["drift"].get(key, {}).get("max_error")
            j = r.get("discontinuity") or {}
            nj = len(j.get("jumps", [])) if j.get("verdict") == "jumps" else 0
            lines.append(f"  {v['h']:12.6g} {_fmt(dv):>9s} {_fmt(e):>9s} {nj:6d}  {v['verdict']}")
            if v["verdict"] != "symplectic" and v.get("reason") and (i == 0 or v["verdict"] != c["verdicts"][i - 1]["verdict"]):
                lines.append(f"  {'':12s} ({v['reason']})")
        orders = []
        if d.get("order") is not None:
            orders.append(f"defect order {d['order']:.2f}")
        if one and one.get("order") is not None:
            orders.append(f"one-step I₁ error order {one['order']:.2f}")
        if orders:
            lines.append(f"  {'':12s} " + "; ".join(orders) + " (fitted over the levels above their floors)")
    return "\n".join(lines)


def plot_report(report, directory) -> list[Path]:
    """Two PNGs: invariant errors against time, defects against h (a sweep: one, both against h)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    if report.get("sweep"):
        return [_plot_sweep(report, directory, plt)]
    cands = report["candidates"]
    colour = {c["name"]: f"C{k % 10}" for k, c in enumerate(cands)}     # one colour per candidate throughout
    style = {c["name"]: "-" if c["role"] == "candidate" else "--" for c in cands}
    forms = ("canonical", "noncanonical", "corrected")
    invs = sorted({k.split("/")[0] for c in cands for k in c["errors"]})
    fig, axes = plt.subplots(max(len(invs), 1), 3, figsize=(12, 3.2 * max(len(invs), 1)), squeeze=False)
    for row, inv in zip(axes, invs):
        for ax, form in zip(row, forms):
            key = f"{inv}/{form}"
            for c in cands:
                if key in c["errors"]:
                    e = np.maximum(np.array(c["errors"][key], float), 1e-17)
                    ax.semilogy(c["t"], e, style[c["name"]], color=colour[c["name"]], label=c["name"])
            ax.axhline(ROUNDOFF, color="grey", lw=0.5)
            ax.set_title(key, fontsize=9)
            ax.set_xlabel("t")
        row[0].set_ylabel("|I(t) − I(0)| / |I(0)|")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8)
    fig.suptitle(f"invariant errors, scene {report['scene']} (grey: round-off threshold)", fontsize=10)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    p1 = directory / "audit_invariants.png"
    fig.savefig(p1, dpi=80)
    plt.close(fig)
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), squeeze=False)
    for ax, form in zip(axes[0], forms):
        for c in cands:
            r = c["defect"].get(form)
            if r and r["defect"]:
                ax.loglog(np.abs(r["h"]), np.maximum(r["defect"], 1e-18), "o" + style[c["name"]],
                          color=colour[c["name"]], label=c["name"], ms=3)
        ax.axhline(DEFECT_FLOOR["complex step"], color="grey", lw=0.5)
        ax.set_title(f"{form} defect", fontsize=9)
        ax.set_xlabel("h")
    axes[0][0].set_ylabel("relative defect")
    handles = [plt.Line2D([], [], color=colour[c["name"]], ls=style[c["name"]], marker="o", ms=3) for c in cands]
    fig.legend(handles, [c["name"] for c in cands], loc="lower center", ncol=min(len(cands), 4), fontsize=8)
    fig.suptitle("one-step symplecticity defect (grey: complex-step floor; absent: the map does not read "
                 "the form's inputs)", fontsize=9)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    p2 = directory / "audit_defects.png"
    fig.savefig(p2, dpi=80)
    plt.close(fig)
    return [p1, p2]


def _plot_sweep(report, directory, plt):
    """A sweep's PNG: each map's defect and I₁ error (one step, or the run's largest) against h, jumps
    and verdicts marked (× where the map's image jumps)."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), squeeze=False)
    for n, c in enumerate(report["candidates"]):
        form = next(iter(c["defect"]))
        d, one, col = c["defect"][form], c.get("one_step"), f"C{n % 10}"
        if d["defect"]:
            axes[0][0].loglog(np.abs(d["h"]), np.maximum(d["defect"], 1e-18), "o-", color=col, ms=3, label=c["name"])
        hs = [v["h"] for v in c["verdicts"]]
        e = one["error"] if one else [r["drift"].get(f"I1/{form}", {}).get("max_error", math.nan) for r in c["runs"]]
        axes[0][1].loglog(np.abs(hs), np.maximum(np.array(e, float), 1e-18), "o-", color=col, ms=3, label=c["name"])
        jumpy = [i for i, v in enumerate(c["verdicts"]) if v["verdict"] == "discontinuous"]
        if jumpy:
            axes[0][1].loglog(np.abs(np.array(hs))[jumpy], np.maximum(np.array(e, float)[jumpy], 1e-18), "x",
                              color=col, ms=8)
    axes[0][0].axhline(DEFECT_FLOOR["complex step"], color="grey", lw=0.5)
    axes[0][1].axhline(ROUNDOFF, color="grey", lw=0.5)
    axes[0][0].set_title("one-step defect", fontsize=9)
    axes[0][1].set_title("|I₁(h) − I₁(0)|/|I₁(0)| after " + report["sweep"]["mode"] + " (×: the image jumps)", fontsize=9)
    for ax in axes[0]:
        ax.set_xlabel("h")
    axes[0][1].legend(fontsize=8)
    fig.suptitle(f"audit over step sizes, {report['scene']} (grey: the floors)", fontsize=10)
    fig.tight_layout()
    path = directory / "audit_sweep.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
