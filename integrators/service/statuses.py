"""A pair's end: its status, the growth laws of its invariant errors, its summary; the one
definition of an invariant's error (:func:`relative_error`)."""
from __future__ import annotations

import h5py
import numpy as np

from .files import DamagedFile, _read, plain_error
from .checkpoints import settle_checkpoint
from .output import FINISHED

def relative_error(v, absolute=False) -> np.ndarray:
    """|I(t) − I(0)| / |I(0)| of a series of invariant values; NaN throughout when I(0) is not a
    finite non-zero number (the one definition of the invariant error: summaries, plots, audit).
    ``absolute``: |I(t) − I(0)|, for an invariant whose I(0) is zero within its own error (an exact
    zero, such as a closed one-form's I₁: a relative error has no scale there; see
    :func:`absolute_invariants`)."""
    v = np.asarray(v, dtype=float)
    if absolute:
        with np.errstate(all="ignore"):
            return np.abs(v - v[0]) if v.size and np.isfinite(v[0]) else np.full_like(v, np.nan)
    if v.size == 0 or not np.isfinite(v[0]) or v[0] == 0:
        return np.full_like(v, np.nan)
    with np.errstate(all="ignore"):
        return np.abs(v - v[0]) / abs(v[0])


def absolute_invariants(f) -> set:
    """{'I1/form', …}: the invariants of a run file whose I(0) is zero within its error (the root
    attribute ``absolute_invariants``, written at the start of a run): their error is |I(t) − I(0)|."""
    text = f.attrs.get("absolute_invariants", "")
    return set((text.decode() if isinstance(text, bytes) else str(text)).split())


def invariant_error(g, inv, form, values=None) -> np.ndarray:
    """The error series of one invariant of a pair group: relative, or absolute where the file says
    I(0) is zero (:func:`absolute_invariants`)."""
    v = _read(g, f"{inv}/{form}") if values is None else values
    return relative_error(v, f"{inv}/{form}" in absolute_invariants(g.file))


def pair_summary(g, n_outputs, threshold):
    """(status, breakdowns, {'I1 form': max error over the resolved outputs}, unresolved) of one pair
    group, unresolved = {set: (first under-resolved t, under-resolved outputs, outputs, the reason
    the run recorded or "")}; reading a
    damaged dataset raises DamagedFile naming it."""
    try:
        bt = g["breakdown_time"][...]
        t = g["t"][...]
        broke = int(np.isfinite(bt).sum())
        unresolved_from, errs = {}, {}
        for inv in ("I1", "I2"):
            if inv not in g:
                continue
            res = g[f"resolution/{inv}"][...]
            ok = (res <= threshold)           # NaN (a set with a broken point) is not resolved either
            if not broke and (~ok).any():
                unresolved_from[inv] = (float(t[np.flatnonzero(~ok)[0]]), int((~ok).sum()), int(ok.size),
                                        str(g.attrs.get(f"under_resolved_reason/{inv}", "")))
            for form in g[inv]:
                v = g[inv][form][...]
                use = ok & np.isfinite(v)       # resolved, and not yet broken down (NaN from a breakdown on)
                use[:1] = False                 # the error at t = 0 is 0 by definition: it vouches for nothing
                e = invariant_error(g, inv, form, v)
                errs[f"{inv} {form}"] = float(np.max(e[use])) if use.any() and np.isfinite(e[use]).all() else np.nan
    except OSError as exc:
        raise DamagedFile(f"dataset in '{g.name}' is damaged ({plain_error(exc)})") from None
    complete = t.shape[0] == n_outputs
    if not complete:
        status = "pending"
    elif broke == bt.size:
        status = "failed"
    elif broke:
        status = "partial"
    elif unresolved_from:
        status = "under-resolved"
    else:
        status = "ok"
    return status, broke, errs, unresolved_from


def growth_laws(g, threshold):
    """{'I1 form' | 'I2 form' | 'energy' | …: GrowthLaw} of a pair's series (invariants.growth): each
    invariant's relative error over the outputs where its set was resolved and no point had broken
    down (the law of that prefix), each diagnostic's error as stored."""
    from invariants.growth import growth_law
    t = _read(g, "t")
    laws = {}
    for inv in ("I1", "I2"):
        if inv not in g:
            continue
        ok = _read(g, f"resolution/{inv}") <= threshold
        for form in g[inv]:
            e = invariant_error(g, inv, form)
            laws[f"{inv} {form}"] = growth_law(t, np.where(ok, e, np.nan))
    for key in g:
        if key.endswith("_error"):
            laws[key[:-len("_error")]] = growth_law(t, _read(g, key))
    return laws


def write_laws(g, laws):
    """Each series dataset's attributes growth_law, growth_exponent (± growth_exponent_error) and
    growth_onset (the time from which the law holds)."""
    for key, law in laws.items():
        ds = g["/".join(key.split(" ")) if key.startswith("I") else f"{key}_error"]
        ds.attrs["growth_law"] = law.law
        ds.attrs["growth_exponent"] = law.exponent
        ds.attrs["growth_exponent_error"] = law.exponent_error
        ds.attrs["growth_onset"] = law.onset
        ds.attrs["growth_log_prefactor"] = law.log_prefactor    # log C of the fitted C·t^α (plots)


def set_status(g, status, unresolved_from):
    g.attrs["status"] = status
    for inv in ("I1", "I2"):
        key = f"under_resolved_from/{inv}"
        if inv in unresolved_from:
            g.attrs[key] = unresolved_from[inv][0]
        elif key in g.attrs:
            del g.attrs[key]


def close_pair(g, n_outputs, threshold, folder=None):
    """The pair's status from its rows (see :func:`pair_summary`), written; a finished pair's
    checkpoint slots settled (:func:`settle_checkpoint`)."""
    status, _, _, unresolved = pair_summary(g, n_outputs, threshold)
    set_status(g, status, unresolved)
    if status in FINISHED:
        write_laws(g, growth_laws(g, threshold))
        settle_checkpoint(g, folder)


def finish(path, names, n_outputs, write=True) -> list:
    """Write each pair's final status, wall_time and growth laws; [(name, status, breakdowns, errors,
    wall time, unresolved, (first breakdown time or None, points), laws, refined)] as :func:`pair_summary`,
    :func:`growth_laws` and :func:`refined` give them.  ``write=False`` (a resume with nothing left to
    do) reads them and writes nothing: the file stays byte for byte."""
    out = []
    with h5py.File(path, "r+" if write else "r") as f:
        threshold = float(f.attrs.get("resolution_threshold", np.inf))
        for name in names:
            g = f["runs"][name]
            status, broke, errs, unresolved = pair_summary(g, n_outputs, threshold)
            laws = growth_laws(g, threshold)
            wall = float(g["wall_clock"][0])
            if write:
                set_status(g, status, unresolved)
                if status in FINISHED:
                    write_laws(g, laws)
                g.attrs["wall_time"] = wall
            bt = g["breakdown_time"][...]
            first = float(bt[np.isfinite(bt)].min()) if broke else None
            out.append((name, status, broke, errs, wall, unresolved, (first, int(bt.size)), laws, refined(g)))
    return out


def refined(g) -> dict:
    """{'I1'|'I2': (first t on more points than the scene's, the scene's points, the most used)} of
    a pair's sets that refined themselves (``points_used``; its attribute ``points``: the scene's)."""
    out = {}
    for inv in g.get("points_used", {}):
        ds = g[f"points_used/{inv}"]
        used, t, base = ds[...], g["t"][...], int(ds.attrs["points"])
        n = min(used.size, t.size)
        more = np.flatnonzero(used[:n] > base)
        if more.size:
            out[inv] = (float(t[more[0]]), base, int(used[:n].max()))
    return out
