"""How an error grows with time: one classifier for every series the project reports.

The paper's argument is about how an error behaves over a long run: bounded (an oscillation), a
random walk of round-off (Brouwer's law, ∝ t^½), a secular drift (∝ t) or worse.  The paper judges
the energy error by "splitting the time interval of the simulation in 10 sub-intervals and computing
the maximum of the absolute value of the energy error in each interval" (sec:app_energy_drift).
This module makes that judgement a number::

    from invariants.growth import growth_law
    g = growth_law(t, e)            # e(t) ≥ 0, e.g. |I(t) − I(0)|/|I(0)|
    g.law, g.exponent, g.exponent_error, g.onset

**The rule.**

1. *Windows.*  The run (0, T] is split into ``WINDOWS`` windows whose ends grow geometrically from
   the first sample time to T, and the largest e of each window is taken (the paper's maxima per
   sub-interval, on a logarithmic grid because the laws are power laws: each window then weighs
   the same in log t).  Empty windows are merged into the next.
2. *The late law.*  The slope α of log(window maximum) against log(window end), least squares over
   the windows of the last ``LATE_DECADES`` decades of the run (at least ``MIN_WINDOWS`` windows),
   with its standard error.  α ≈ 0 bounded, ½ random walk, 1 linear.
3. *The law* from α: ``bounded`` below ``BOUNDED_BELOW``; ``random walk`` below ``LINEAR_FROM``;
   ``linear`` up to ``FASTER_FROM``; ``faster`` above it (exponential growth lands here: its local
   exponent λt grows without bound).  A series whose every value is at most ``roundoff`` is
   ``round-off`` whatever its exponent (the exponent is still reported: a round-off random walk,
   Brouwer's law, gives about ½, a drift in the last bits about 1).
4. *The onset*, for a growing error: the break of the broken stick that fits the window maxima
   best (flat before the break, a power law after): the time from which the law holds.  The
   exponent reported is the stick's slope after the break; for a bounded error the late fit's.

A series with non-finite values (a broken-down set) gets the law of its finite prefix; one with
fewer than ``MIN_WINDOWS`` usable windows gets ``undetermined`` (``round-off`` where every value is
at most ``roundoff``).  A window whose maximum is exactly 0 has no scale and is not usable: an error
that alternates 2, 0, 2, 0, … (an anti-symplectic map) is not a growth from 0.  The thresholds are validated on
5,000 synthetic series and on the project's known results (scripts/studies/growth_laws.py,
docs/growth.md).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

ROUNDOFF = 1e-11        # largest relative error still called round-off (the audit's threshold)
WINDOWS = 16            # log-spaced windows over the run
MIN_WINDOWS = 5         # fewest windows a fit uses
LATE_DECADES = 1.5      # the late law: the windows of the last 1.5 decades of the run
BOUNDED_BELOW = 0.25    # α below this: bounded
LINEAR_FROM = 0.7       # α from here: linear (between: random walk)
FASTER_FROM = 1.5       # α above this: faster than linear
LAWS = ("round-off", "bounded", "random walk", "linear", "faster", "undetermined")


@dataclasses.dataclass(frozen=True)
class GrowthLaw:
    """The verdict on one error series: ``law`` (one of LAWS), the fitted ``exponent`` α of
    e ∝ t^α with its standard error, the time ``onset`` from which the law holds, the largest
    error ``max_error`` and the window ends and maxima the fit used (``windows``, ``maxima``)."""

    law: str
    exponent: float
    exponent_error: float
    onset: float
    max_error: float
    windows: tuple = ()
    maxima: tuple = ()
    log_prefactor: float = math.nan

    def fitted(self, t):
        """The fitted law C·t^α of the window maxima at times t from the onset on (NaN before): what
        plots draw."""
        t = np.asarray(t, dtype=float)
        if not self.windows or not math.isfinite(self.exponent):
            return np.full(t.shape, np.nan)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            out = np.exp(self.log_prefactor + self.exponent * np.log(t))
        return np.where(t >= self.onset, out, np.nan)

    def __str__(self):
        if not math.isfinite(self.exponent):
            return self.law
        return f"{self.law} (α = {self.exponent:.2f} ± {self.exponent_error:.2f} from t = {self.onset:.4g})"


def window_maxima(t, e, windows=WINDOWS):
    """(window ends, largest e in each window) over log-spaced windows of (0, t_end]; t > 0 only."""
    t, e = np.asarray(t, dtype=float), np.asarray(e, dtype=float)
    keep = t > 0
    t, e = t[keep], e[keep]
    if t.size == 0:
        return np.zeros(0), np.zeros(0)
    edges = np.geomspace(t[0], t[-1], windows + 1) if t[-1] > t[0] else np.array([t[0], t[0]])
    edges[0] = 0.0
    edges[-1] = t[-1]
    idx = np.searchsorted(edges, t, side="left") - 1          # window i holds (edges[i], edges[i+1]]
    idx = np.clip(idx, 0, windows - 1)
    ends, maxima = [], []
    for i in np.unique(idx):
        sel = idx == i
        ends.append(float(t[sel][-1]))
        maxima.append(float(np.max(e[sel])))
    return np.array(ends), np.array(maxima)


def _fit(x, y):
    """Least-squares slope of y on x and its standard error."""
    n = x.size
    xm = x - x.mean()
    sxx = float(np.dot(xm, xm))
    if n < 2 or sxx == 0.0:
        return math.nan, math.nan
    slope = float(np.dot(xm, y - y.mean()) / sxx)
    if n < 3:
        return slope, math.inf
    res = y - y.mean() - slope * xm
    return slope, math.sqrt(float(np.dot(res, res)) / (n - 2) / sxx)


def _law(alpha, peak, roundoff):
    if peak <= roundoff:
        return "round-off"
    if alpha > FASTER_FROM:
        return "faster"
    if alpha >= LINEAR_FROM:
        return "linear"
    return "random walk" if alpha >= BOUNDED_BELOW else "bounded"


def _hinge(x, y, last):
    """The broken stick y = c + α·max(x − x_j, 0) with the least residual over j ≤ ``last``:
    (j, α, its standard error, c)."""
    best = None
    for j in range(last + 1):
        z = np.maximum(x - x[j], 0.0)
        A = np.stack([np.ones_like(z), z], axis=1)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ coef
        rss = float(r @ r)
        if best is None or rss < best[0] - 1e-12 * abs(best[0]):
            zm = z - z.mean()
            sxx = float(zm @ zm)
            err = math.sqrt(rss / max(x.size - 2, 1) / sxx) if sxx > 0 else math.inf
            best = (rss, j, float(coef[1]), err, float(coef[0]))
    return best[1:]


def growth_law_of_maxima(ends, maxima, roundoff=ROUNDOFF, peak=None):
    """The verdict from window maxima already taken (e.g. scripts/studies/stability_campaign.py's envelopes):
    ``ends`` increasing window end times, ``maxima`` the largest error in each window."""
    w, m = np.asarray(ends, dtype=float), np.asarray(maxima, dtype=float)
    good = np.isfinite(w) & np.isfinite(m) & (w > 0)
    w, m = w[good], m[good]
    peak = float(np.max(m)) if peak is None and m.size else (math.nan if peak is None else float(peak))
    if np.any(m > 0):                       # a window that met only e = 0 exactly has no scale: not usable
        w, m = w[m > 0], m[m > 0]
    if w.size < MIN_WINDOWS or not np.any(m > 0):
        law = "round-off" if m.size and np.all(m <= roundoff) else "undetermined"
        return GrowthLaw(law, math.nan, math.nan, float(w[0]) if w.size else math.nan, peak, tuple(w), tuple(m))
    y = np.log(m)
    x = np.log(w)
    # the late law: the windows of the last LATE_DECADES (at least MIN_WINDOWS of them)
    late = max(0, min(int(np.searchsorted(x, x[-1] - LATE_DECADES * math.log(10.0))), w.size - MIN_WINDOWS))
    a_late, e_late = _fit(x[late:], y[late:])
    law = _law(a_late, peak, roundoff)
    if law in ("random walk", "linear", "faster") or (law == "round-off" and a_late >= BOUNDED_BELOW):
        # growth: from where?  The broken stick, flat before its onset (an error that sat at a
        # level and then grew), a power law after; the exponent is the stick's
        j, alpha, err, c = _hinge(x, y, w.size - MIN_WINDOWS)
        logc = c - alpha * x[j]
        if _law(alpha, math.inf, roundoff) != _law(a_late, math.inf, roundoff):   # no clear break
            j, alpha, err = late, a_late, e_late
            logc = float(np.mean(y[late:] - alpha * x[late:]))
    else:
        j, alpha, err = 0, a_late, e_late
        logc = float(np.mean(y[late:] - alpha * x[late:]))
    return GrowthLaw(law, alpha, err, float(w[j]), peak, tuple(w), tuple(m), logc)


def growth_law(t, e, roundoff=ROUNDOFF, windows=None):
    """The growth law of an error series e(t) ≥ 0 (see the module doc); NaN/inf values end the
    series (a set that broke down: the law of what came before)."""
    t, e = np.asarray(t, dtype=float).ravel(), np.abs(np.asarray(e, dtype=float).ravel())
    if t.shape != e.shape:
        raise ValueError(f"growth_law: t and e differ in length ({t.size} and {e.size})")
    bad = ~np.isfinite(e)
    if bad.any():
        stop = int(np.argmax(bad))
        t, e = t[:stop], e[:stop]
    peak = float(np.max(e)) if e.size else math.nan
    if windows is None:                     # a short series: about 3 samples a window
        windows = max(MIN_WINDOWS, min(WINDOWS, int(np.sum(t > 0)) // 3))
    w, m = window_maxima(t, e, windows)
    return growth_law_of_maxima(w, m, roundoff, peak)


# -- the classifier's validation set ----------------------------------------------------------------

OSCILLATION = 0.1       # synthetic linear series: an oscillation up to this share of the final drift
DRAWN = ("round-off", "bounded", "random walk", "linear", "faster")     # the laws synthetic series are drawn from


def synthetic_series(law, rng, n=None):
    """A synthetic error series (t, e) of a known law (one of :data:`DRAWN`), drawn from numpy's
    generator ``rng`` with random parameters and 0–30 % multiplicative noise, n samples (default 200
    to 4,000): the classifier's validation set (docs/growth.md; scripts/studies/growth_laws.py)."""
    n = int(rng.integers(200, 4001)) if n is None else n
    t = np.arange(1, n + 1, dtype=float)
    T = t[-1]
    noise = 1 + rng.uniform(0, 0.3) * rng.standard_normal(n) if law not in ("round-off", "random walk") else 1.0
    if law == "round-off":
        if rng.random() < 0.5:
            return t, np.abs(np.cumsum(10 ** rng.uniform(-16, -15) * rng.standard_normal(n)))
        per = 10 ** rng.uniform(np.log10(2), np.log10(T / 3))
        return t, 10 ** rng.uniform(-15, -12) * np.abs(np.sin(2 * np.pi * t / per + rng.uniform(0, 6.3)))
    if law == "bounded":
        per = 10 ** rng.uniform(np.log10(2), np.log10(T / 3))
        A = 10 ** rng.uniform(-10, -2)
        e = np.abs(np.sin(2 * np.pi * t / per + rng.uniform(0, 6.3)))
        if rng.random() < 0.5:
            e = np.abs(e + 0.5 * np.sin(2 * np.pi * t / (per * np.sqrt(2)) + rng.uniform(0, 6.3)))
        return t, A * e * np.abs(noise)
    if law == "random walk":
        return t, np.abs(np.cumsum(10 ** rng.uniform(-10, -5) * rng.standard_normal(n)))
    if law == "linear":
        a = 10 ** rng.uniform(-12, -4)
        per = 10 ** rng.uniform(np.log10(2), np.log10(T / 3))
        b = rng.uniform(0, OSCILLATION) * a * T
        return t, np.abs((a * t + b * np.sin(2 * np.pi * t / per)) * noise)
    # faster
    if rng.random() < 0.5:
        lam = rng.uniform(4, 20) / T
        return t, np.abs(10 ** rng.uniform(-14, -8) * np.expm1(lam * t) * noise)
    a = 10 ** rng.uniform(-16, -8)
    return t, np.abs(a * t ** 3 * (1 + 0.1 * np.sin(t)) * noise)


def confusion(count, seed=0, samples=None):
    """{drawn law: {classified law: count}} of ``count`` synthetic series of each law (numpy's
    generator of ``seed``; ``samples`` points each, default 200 to 4,000): how often
    :func:`growth_law` names each law."""
    rng = np.random.default_rng(seed)
    M = {d: {f: 0 for f in LAWS} for d in DRAWN}
    for law in DRAWN:
        for _ in range(count):
            t, e = synthetic_series(law, rng, samples)
            M[law][growth_law(t, e).law] += 1
    return M
