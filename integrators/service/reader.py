"""A run file read back: :func:`read_run` gives a :class:`Run` of :class:`PairRun` (xarray,
HTML in notebooks); a damaged dataset is one :class:`~.files.DamagedFile` naming it."""
from __future__ import annotations

import dataclasses
import os

import numpy as np

from .files import BusyFile, DamagedFile, _read, open_file, plain_error, size_limit
from .output import FORMAT, pair_name, split_pair_name
from .statuses import absolute_invariants, relative_error

@dataclasses.dataclass
class PairRun:
    """One (tableau, projection) pair of a run file, read into arrays (see :func:`read_run`).

    t : (n,) output times; ``I1``/``I2`` : {form: (n,) values} (empty without a loop / surface);
    ``resolution``/``resolved`` : {'I1'|'I2': (n,)} the sets' monitors and 0/1 flags;
    ``errors`` : {'energy'|'momentum'|'constraint': (n,)} max over live points; ``breakdown_time`` :
    (npoints,) inf where a point never broke down; ``points`` : {'loop'|'surface': array} when the scene
    stored them; ``status``, ``wall_time``; ``under_resolved_from`` : {'I1'|'I2': first t} of a set
    that was under-resolved; ``growth`` : {'I1 form'|'I2 form'|'energy'|…: (law, exponent, its error,
    onset, log prefactor)} of a finished pair (invariants.growth: the fitted law C·t^α holds from the
    onset; the datasets' growth_* attributes); ``points_used`` : {'I1'|'I2': (n,)} of a set with
    ``refine_to``, the points of the level each output's invariant was taken on.
    """

    name: str
    status: str
    wall_time: float
    t: np.ndarray
    I1: dict
    I2: dict
    resolution: dict
    resolved: dict
    errors: dict
    breakdown_time: np.ndarray
    points: dict
    under_resolved_from: dict = dataclasses.field(default_factory=dict)
    growth: dict = dataclasses.field(default_factory=dict)
    points_used: dict = dataclasses.field(default_factory=dict)
    absolute: frozenset = frozenset()     # 'I1/form' … whose I(0) is zero within its error: absolute errors

    def __repr__(self):
        t = f"t = {self.t[0]:g} … {self.t[-1]:g}" if self.t.size else "no outputs"
        forms = [f"{inv}: {', '.join(d)}" for inv, d in (("I1", self.I1), ("I2", self.I2)) if d]
        return (f"<PairRun {self.name}: {self.status}, {self.t.size} outputs ({t}), "
                f"{'; '.join(forms) or 'no invariants'}, {int(np.isfinite(self.breakdown_time).sum())} of "
                f"{self.breakdown_time.size} points broke down>")

    def relative_error(self, inv="I1", form="noncanonical"):
        """|I(t) − I(0)| / |I(0)| of one invariant ("I1" or "I2") and form (:func:`relative_error`;
        |I(t) − I(0)| where I(0) is zero within its error: ``absolute``);
        a ValueError names an invariant or form the run does not hold."""
        if inv not in ("I1", "I2"):
            raise ValueError(f"invariant {inv!r}: choose 'I1' (the loop's) or 'I2' (the surface's)")
        values = self.I1 if inv == "I1" else self.I2
        if form not in values:
            held = ", ".join(sorted(values)) or "none: the scene has no " + ("loop" if inv == "I1" else "surface")
            raise ValueError(f"{inv} form {form!r} is not in this run (it holds: {held})")
        return relative_error(values[form], f"{inv}/{form}" in self.absolute)

    def to_xarray(self, forms=None):
        """The pair as an ``xarray.Dataset`` over time ``t`` (and ``form``, ``point``): ``I1``, ``I2``
        (t, form); ``resolution_I1``, ``resolved_I1``, ``points_used_I1`` (a refining set), … (t);
        the diagnostics' ``energy_error``, …
        (t), each with its growth law in ``.attrs``; ``I1_growth_law``, ``I1_growth_exponent``, …
        (form); ``breakdown_time`` (point).  Attributes: pair, status, wall_time, under-resolved
        times.  ``ds.I2.sel(form="corrected").plot()`` draws a series."""
        import xarray as xr
        from invariants import FORMS
        forms = list(forms) if forms is not None else \
            [f for f in FORMS if f in self.I1 or f in self.I2] + \
            sorted({f for d in (self.I1, self.I2) for f in d} - set(FORMS))
        n = self.t.shape[0]
        data = {}
        for inv in ("I1", "I2"):
            d = getattr(self, inv)
            if not d:
                continue
            data[inv] = (("t", "form"), np.stack([np.asarray(d[f], float) if f in d else np.full(n, np.nan)
                                                  for f in forms], axis=1) if forms else np.zeros((n, 0)),
                         {"long_name": f"{inv} ({'loop' if inv == 'I1' else 'surface'})"})
            g = [self.growth.get(f"{inv} {f}") for f in forms]
            data[f"{inv}_growth_law"] = ("form", np.array([x[0] if x else "" for x in g], dtype=object))
            data[f"{inv}_growth_exponent"] = ("form", np.array([x[1] if x else np.nan for x in g]))
            data[f"{inv}_growth_onset"] = ("form", np.array([x[3] if x else np.nan for x in g]))
            if inv in self.resolution:
                data[f"resolution_{inv}"] = ("t", np.asarray(self.resolution[inv], float))
            if inv in self.resolved:
                data[f"resolved_{inv}"] = ("t", np.asarray(self.resolved[inv]))
            if inv in self.points_used:
                data[f"points_used_{inv}"] = ("t", np.asarray(self.points_used[inv]))
        for key, v in self.errors.items():
            attrs = {}
            if key in self.growth:
                law, a, da, onset, _ = self.growth[key]
                attrs = {"growth_law": law, "growth_exponent": a, "growth_exponent_error": da, "growth_onset": onset}
            data[f"{key}_error"] = ("t", np.asarray(v, float), attrs)
        data["breakdown_time"] = ("point", np.asarray(self.breakdown_time, float))
        attrs = {"pair": self.name, "status": self.status, "wall_time": self.wall_time}
        attrs.update({f"under_resolved_from_{k}": v for k, v in self.under_resolved_from.items()})
        return xr.Dataset(data, coords={"t": ("t", np.asarray(self.t, float)), "form": ("form", forms)},
                          attrs=attrs)

    def _repr_html_(self):
        return _html_table([self])


@dataclasses.dataclass
class Run:
    """A run file read whole: ``scene`` (the TOML text it ran), ``system`` (its name), ``format``,
    ``pairs`` {name: PairRun} by name; ``run['GLRK2-symmetric']`` is ``run.pairs[...]``."""

    path: str
    format: str
    system: str
    scene: str
    steps: int
    pairs: dict
    precision: str = "double"        # the engine's numbers (root attribute; files before it: double)

    def __getitem__(self, name):
        return self.pairs[name]

    def __repr__(self):
        counts = {}
        for p in self.pairs.values():
            counts[p.status] = counts.get(p.status, 0) + 1
        prec = "" if self.precision == "double" else f" in {self.precision}"
        return (f"<Run '{self.path}': {self.system}{prec}, {len(self.pairs)} pairs "
                f"({', '.join(f'{v} {k}' for k, v in counts.items())}), {self.steps} steps; "
                "run.pairs by name, run[name] one pair>")

    def to_xarray(self):
        """Every pair as one ``xarray.Dataset`` with a ``pair`` dimension (see
        :meth:`PairRun.to_xarray`; a pair still pending is NaN past its last output), plus
        ``status`` and ``wall_time`` per pair: ``ds.I2.sel(pair="GLRK2-symmetric", form="corrected")``."""
        import xarray as xr
        from invariants import FORMS
        forms = [f for f in FORMS if any(f in p.I1 or f in p.I2 for p in self.pairs.values())]
        forms += sorted({f for p in self.pairs.values() for d in (p.I1, p.I2) for f in d} - set(forms))
        tabs, projs = self.grid()
        order = [pair_name(t, q) for t in tabs for q in projs]
        names = [n for n in order if n in self.pairs] + [n for n in self.pairs if n not in order]
        parts = []
        for name, p in ((n, self.pairs[n]) for n in names):
            ds = p.to_xarray(forms)
            parts.append(ds.assign(status=((), p.status), wall_time=((), p.wall_time)).expand_dims(pair=[name]))
        if not parts:
            return xr.Dataset(attrs={"path": self.path, "system": self.system, "steps": self.steps,
                                     "precision": self.precision})
        ds = xr.concat(parts, dim="pair", join="outer", combine_attrs="drop_conflicts", data_vars="all",
                       coords="different", compat="equals")
        ds.attrs.update(path=self.path, system=self.system, steps=self.steps, format=self.format,
                        precision=self.precision)
        for key in ("pair", "status", "wall_time"):
            ds.attrs.pop(key, None)
        return ds

    def _repr_html_(self):
        prec = "" if self.precision == "double" else f" in {_esc(self.precision)}"
        return (f"<p><b>poincare run</b> <code>{_esc(self.path)}</code>: {_esc(self.system)}{prec}, {self.steps} steps, "
                f"{len(self.pairs)} pairs</p>" + _html_table(list(self.pairs.values())))

    def grid(self) -> tuple:
        """(tableaus, projections) in the scene's order (HDF5 lists the groups alphabetically); a
        user's step maps come last, under the projection 'map'."""
        try:
            from .scene import parse_scene
            sc = parse_scene(self.scene)
            maps = [p.label for p in sc.pairs if p.step_map]
            return list(sc.tableaus) + maps, list(sc.projections) + (["map"] if maps else [])
        except ValueError:                 # the scene no longer parses here (a user file moved): by name
            tabs, projs = [], []
            for name in self.pairs:
                t, p = split_pair_name(name)
                tabs += [t] if t not in tabs else []
                projs += [p] if p not in projs else []
            return tabs, projs


def _esc(text):
    import html
    return html.escape(str(text))


def _html_table(pairs):
    """An HTML table of pairs: status, points broken down, and each series' largest error and law."""
    keys = []
    for p in pairs:
        for k in [f"{inv} {f}" for inv in ("I1", "I2") for f in getattr(p, inv)] + list(p.errors):
            if k not in keys:
                keys.append(k)
    head = "".join(f"<th>{_esc(k)}</th>" for k in keys)
    rows = []
    for p in pairs:
        cells = []
        for k in keys:
            if k.startswith("I"):
                inv, form = k.split(" ", 1)
                v = getattr(p, inv).get(form)
                e = relative_error(v, f"{inv}/{form}" in p.absolute) if v is not None and len(v) else None
            else:
                e = p.errors.get(k)
            big = float(np.nanmax(e)) if e is not None and len(e) and np.isfinite(e).any() else None
            law = p.growth.get(k, ("",))[0]
            cells.append(f"<td>{'—' if big is None else f'{big:.2e}'}<br><small>{_esc(law)}</small></td>")
        broke = int(np.isfinite(p.breakdown_time).sum())
        rows.append(f"<tr><td><b>{_esc(p.name)}</b></td><td>{_esc(p.status)}</td><td>{broke}</td>"
                    + "".join(cells) + "</tr>")
    return ("<table><tr><th>pair</th><th>status</th><th>broke</th>" + head + "</tr>" + "".join(rows) + "</table>"
            "<p><small>largest |I(t) − I(0)|/|I(0)| (all outputs) and diagnostic errors, with their growth laws"
            "</small></p>")


def _growth_attrs(g):
    out = {}
    for key in [f"{inv}/{form}" for inv in ("I1", "I2") if inv in g for form in g[inv]] + \
            [k for k in g if k.endswith("_error")]:
        a = g[key].attrs
        if "growth_law" in a:
            name = key.replace("/", " ") if key.startswith("I") else key[:-len("_error")]
            out[name] = (str(a["growth_law"]), float(a["growth_exponent"]), float(a["growth_exponent_error"]),
                         float(a["growth_onset"]), float(a.get("growth_log_prefactor", np.nan)))
    return out


class Pairs(dict):
    """{pair name: PairRun}; an unknown name is a KeyError that lists the pairs there are."""

    def __missing__(self, key):
        raise KeyError(f"no pair {key!r} in this run; its pairs: {', '.join(self) or 'none'}")


def read_run(path) -> Run:
    """Read a ``poincare run`` file into arrays (the layout above; h5py underneath).

    A damaged dataset (failed checksum) or a file that is not a run file is one :class:`DamagedFile`
    naming it.  Pairs still ``pending`` are read as far as they got.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"read_run: a run file's path (str or Path) is needed, got {type(path).__name__} {path!r}")
    limit = size_limit(path) if os.path.exists(path) else 0
    try:
        with open_file(path) as f:
            fmt = f.attrs.get("format")
            if fmt not in (FORMAT, "poincare/1"):
                raise DamagedFile(f"'{path}' is not a poincare run file")
            pairs = Pairs()
            for name, g in f["runs"].items():
                def sets(key):
                    return {k: _read(g, f"{key}/{k}", limit) for k in g[key]} if key in g else {}
                pairs[name] = PairRun(
                    name=name, status=str(g.attrs.get("status", "pending")),
                    wall_time=float(_read(g, "wall_clock", limit)[0]), t=_read(g, "t", limit), I1=sets("I1"), I2=sets("I2"),
                    resolution=sets("resolution"), resolved=sets("resolved"),
                    errors={k[:-len("_error")]: _read(g, k, limit) for k in g if k.endswith("_error")},
                    breakdown_time=_read(g, "breakdown_time", limit), points=sets("points"),
                    under_resolved_from={k.split("/")[1]: float(v) for k, v in g.attrs.items()
                                         if k.startswith("under_resolved_from/")},
                    growth=_growth_attrs(g), points_used=sets("points_used"), absolute=frozenset(absolute_invariants(f)))
            return Run(path=str(path), format=str(fmt), system=str(f.attrs.get("system", "")),
                       scene=str(f.attrs.get("scene", "")), steps=int(f.attrs.get("steps", 0)), pairs=pairs,
                       precision=str(f.attrs.get("precision", "double")))
    except (DamagedFile, BusyFile, FileNotFoundError):
        raise
    except (OSError, KeyError, ValueError, RuntimeError, TypeError, MemoryError, AttributeError) as exc:
        # (damaged metadata: h5py may hand back None for a group whose header it cannot read)
        raise DamagedFile(f"cannot read '{path}': damaged or not a poincare run file "
                          f"({type(exc).__name__}: {plain_error(exc)})") from None
