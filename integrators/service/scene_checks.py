"""What a scene is checked against before anything runs: its error type, the memory its points will
take on this machine (per rank, per point, from the state's and Newton's sizes), its sample points
(finite, inside the domain) and the functions it names (a one-form and an energy that evaluate).

Every mistake is a :class:`SceneError` whose message names the key (docs/scenes.md).
"""
from __future__ import annotations

import math
import os

import numpy as np


class SceneError(ValueError):
    """A scene that cannot run; the message names the offending key."""


def _finite(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


MEMORY_BASE = 400 * 2**20        # the interpreter, numpy, numba, MPI and HDF5 of one rank (measured ~300 MiB)


def memory_per_point(d, s, precision="double", factors=True) -> tuple:
    """(bytes one sample point costs the rank that advances it, bytes of its state).  The cost: its
    state (:class:`integrators.engine.State`), Newton factors of a pair with s stages (assuming the
    largest system a projection solves, (s + 2)·d unknowns) and its part of the invariants'
    transforms (about 20 arrays of d doubles).  For GLRK2 on a 4-dimensional system this gives
    3.0 KiB; measured 1.8-2.3 KiB (docs/benchmarks.md).  ``factors`` False: a scene of step maps
    only, which hold no Newton factors (O(d) a point)."""
    from ..engine import State
    nz = (s + 2) * d
    def size(dd):
        return sum(int(np.prod(shape)) * np.dtype(dt).itemsize for shape, dt in State.schema(1, dd, s, precision).values())
    # every field is linear in d: read off d = 1 and 2, never a state of the (perhaps huge) d itself
    one, two = size(1), size(2)
    state = one + (two - one) * (d - 1)
    factors = 8 * (nz * nz + nz) * (2 if precision == "double-double" else 1) if factors else 0
    return state + factors + 8 * 20 * d, state


def available_memory() -> float | None:
    """Bytes of memory available to new work on this node (MemAvailable), or None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def _local_ranks() -> int:
    """Ranks that share this node under mpiexec (MPICH and Open MPI say so in the environment), else 1."""
    for key in ("MPI_LOCALNRANKS", "OMPI_COMM_WORLD_LOCAL_SIZE"):
        try:
            return max(1, int(os.environ[key]))
        except (KeyError, ValueError):
            pass
    return 1


def _check_dimension_memory(key, value, d, points):
    """Refuse, naming ``key``, a dimension d whose ``points`` sample points (the scene's sets, or the
    fewest a set may have) cannot fit in this node's memory, before the system or any point is
    built (a period of d entries, the points themselves); :func:`_check_memory` judges the whole
    scene once it is built."""
    free = available_memory()
    per_point, state = memory_per_point(d, 1, "double", factors=False)
    need = (8 * 16 * d + per_point + state) * points
    if free is not None and need > free:
        raise SceneError(f"{key} = {value:,} ({d:,} coordinates) needs about {need / 2**30:,.1f} GiB of memory for "
                         f"{points:,} sample points; this node has {free / 2**30:,.1f} GiB available: a smaller "
                         "system, or audit its map on a loop of fewer points (poincare audit --map)")


def _check_memory(scene, system):
    """Refuse, naming the key, a scene whose points cannot fit in this node's memory: every rank
    holds all sample points (q₀, the sets' values) and its share of the states, rank 0 the whole
    checkpoint as well.  Checked before any point is sampled or any file is written."""
    free = available_memory()
    if free is None:
        return
    n, d = scene.n_points, system.d
    s = scene.max_stages
    local = _local_ranks()
    per_point, state = memory_per_point(d, s, scene.precision, factors=bool(scene.tableaus))
    # every local rank holds all points' samples and set values (~16 arrays of d doubles) and
    # advances its share; rank 0 also gathers every point's state for a checkpoint
    need = local * (MEMORY_BASE + 8 * 16 * d * n) + (per_point + state) * n
    # a refining set's new points (up to refine_to) are advanced by one rank, its whole finest grid
    # held while its invariants are taken
    new = {spec.name: spec.at_level(spec.levels).count - spec.count for spec, _ in scene.sample_sets}
    need += sum((per_point + 8 * 16 * d) * m for m in new.values())
    if need <= free:
        return
    big = max((sp for sp, _ in scene.sample_sets), key=lambda sp: sp.count + new[sp.name])
    if new[big.name]:
        key = f"{big.name}.refine_to = {big.refine_to:,} (up to {big.at_level(big.levels).count:,} points)"
        raise SceneError(f"{key} needs about {need / 2**30:,.1f} GiB of memory; this node has "
                         f"{free / 2**30:,.1f} GiB available: give a smaller refine_to")
    key = ("loop.points = " if big.name == "loop" else
           f"surface.n_sigma × surface.n_tau = {big.n_sigma} × {big.n_tau} = ") + f"{big.count:,}"
    raise SceneError(f"{key} needs about {need / 2**30:,.1f} GiB of memory for {n:,} points "
                     f"({per_point / 1024:.1f} KiB a point{f' on {local} ranks' if local > 1 else ''}); "
                     f"this node has {free / 2**30:,.1f} GiB available: use fewer points")


def _check_points(scene, system):
    specs = [(spec, spec.name) for spec, _ in scene.sample_sets]
    specs += [(spec.at_level(spec.levels), f"{spec.name} refined to {spec.at_level(spec.levels).count:,} points")
              for spec, _ in scene.sample_sets if spec.levels]        # the finest level a refinement may reach
    for spec, what in specs:
        try:
            q = np.asarray(spec.sample(scene.base), dtype=float)
        except SceneError:
            raise
        except Exception as exc:      # a user shape function may raise anything: one line naming it
            if ":" not in spec.shape:
                msg = str(exc)
                raise SceneError(f"{what}.{msg}" if msg.startswith("params") else f"{what}: {msg}") from None
            contract = ("f(tau, **params) with tau the (N,) array j/N in [0, 1), returning (N, d)"
                        if spec.name == "loop" else "f(sigma, tau, **params) with two (n_sigma, n_tau) arrays of "
                        "Chebyshev points in [0, 1], returning (n_sigma, n_tau, d)")
            raise SceneError(f"{what}.shape '{spec.shape}' failed: {type(exc).__name__}: {exc} (a {what} shape "
                             f"is called as {contract})") from None
        want = spec.grid + (system.d,)
        if q.shape[-1:] == (system.d,) and q.shape != want:
            raise SceneError(f"{what}: the shape gives points of shape {q.shape}, the scene needs {want}")
        q = q.reshape(-1, q.shape[-1])
        if q.shape[1] != system.d:
            raise SceneError(f"{what}: points have dimension {q.shape[1]}, system {system.name} needs {system.d}")
        bad = ~system.in_domain(q)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise SceneError(f"{what}: point {k} = {q[k].tolist()} is not finite or outside the domain of {system.name}")
        if np.all(q == q[0]):             # every point the same: the invariant is 0, no relative error exists
            raise SceneError(f"{what}: all {q.shape[0]:,} points are the same point {q[0].tolist()} (a set of zero "
                             "extent: its invariant is 0 and no relative error of it can be measured); give the "
                             "shape radii or a size > 0")
        if getattr(system, "black_box", False):
            _check_energy(system, q, what)
            _check_one_form(system, q, what)
            continue
        with np.errstate(all="ignore"):
            for key, values in (("H", system.H(q)), ("theta", system.theta(q)), ("H's gradient", system.dH(q))):
                bad = ~np.isfinite(values).reshape(q.shape[0], -1).all(axis=1)
                if bad.any():
                    k = int(np.flatnonzero(bad)[0])
                    raise SceneError(f"{what}: system.{key} is not finite at point {k} = {q[k].tolist()} "
                                     f"(outside where the expression is defined?)")
            cond = np.linalg.cond(system.Omega(q))
        bad = ~(cond < 1e12)
        if bad.any():                     # the equations of motion need Ω̄ invertible (eq:euler_lagrange_equations_matrix)
            k = int(np.flatnonzero(bad)[0])
            raise SceneError(f"{what}: Ω̄ = dϑ is singular at point {k} = {q[k].tolist()} (condition number "
                             f"{cond[k]:.1e}); check system.theta")


def _check_one_form(system, q, what):
    """A system of step maps with a one-form of code: system.one_form at a set's points, (n, d) finite
    values, or a one-line error naming it (the maps' runs would all fail with no word of why)."""
    if getattr(system, "one_form", None) is None:
        return
    try:
        with np.errstate(all="ignore"):
            t = system.theta(q)
    except ValueError as exc:         # OneFormSpace.theta's own check names system.one_form
        raise SceneError(f"{what}: {exc}") from None
    except Exception as exc:          # the user's function may raise anything: one line naming it
        raise SceneError(f"{what}: system.one_form failed: {type(exc).__name__}: {exc}") from None
    bad = ~np.isfinite(t).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise SceneError(f"{what}: system.one_form is not finite at {int(bad.sum())} of {q.shape[0]} points (the first, "
                         f"point {k} = {q[k].tolist()})")


def _check_energy(system, q, what):
    """A canonical phase space's system.energy at a set's points: (n,) finite values, or a one-line error."""
    if system.energy is None:
        return
    try:
        with np.errstate(all="ignore"):
            e = system.H(q)
    except Exception as exc:          # the user's function may raise anything: one line naming it
        raise SceneError(f"{what}: system.energy failed: {type(exc).__name__}: {exc}") from None
    bad = ~np.isfinite(e)
    if bad.any():
        raise SceneError(f"{what}: system.energy is not finite at point {int(np.flatnonzero(bad)[0])}")
