"""The batch-run driver: every (tableau, projection) pair of a scene, distributed over MPI ranks.

The sample points (loop first, then the surface row by row) are split into contiguous
blocks, one per rank; from the second pair on, the blocks are sized from each rank's measured
advance rate and rank 0's is smaller by the cost of its output work (see ``_split``).  Each rank advances its block with each pair; at every output
time rank 0 gathers the points, computes the invariants and diagnostics and appends
one row to the HDF5 file (see :mod:`integrators.output`), plus a checkpoint of the
full integrator state.  Because a point's trajectory does not depend on its batch,
the file's numbers are bitwise the same for any number of ranks.  Without mpiexec
(or without mpi4py) it runs as a single process.
"""
from __future__ import annotations

import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import output
from .engine import Engine, MapEngine, State, march, set_threads


STOP = []      # exceptions left by a signal handler (integrators.cli); raised before the next step


def _check_stop():
    if STOP:
        raise STOP.pop()


class _Serial:
    """The part of an MPI communicator the driver uses, for one process."""

    rank, size = 0, 1

    def gather(self, obj, root=0):
        return [obj]

    def bcast(self, obj, root=0):
        return obj

    def Barrier(self):
        pass


def communicator():
    """MPI.COMM_WORLD when running under mpiexec with more than one rank, else a serial stand-in."""
    if not any(k in os.environ for k in ("PMI_RANK", "PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "HYDRA_CONTROL_FD",
                                         "PMI_FD", "MPI_LOCALNRANKS")):
        return _Serial()
    try:
        from mpi4py import MPI
    except ImportError:
        return _Serial()
    comm = MPI.COMM_WORLD
    return comm if comm.Get_size() > 1 else _Serial()


@dataclasses.dataclass
class PairSummary:
    pair: str
    status: str
    breakdowns: int
    max_errors: dict
    wall_time: float
    timings: dict = dataclasses.field(default_factory=dict)
    unresolved_from: dict = dataclasses.field(default_factory=dict)   # {'I1': first t the set was under-resolved}


class Progress:
    """A one-line progress bar with ETA on stderr (rank 0 only; silent when not a terminal unless forced)."""

    def __init__(self, total, enabled):
        self.total, self.done, self.enabled = total, 0, enabled
        self.start = time.perf_counter()
        self.last = 0.0

    def update(self, n, label):
        self.done += n
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.last < 0.2 and self.done < self.total:
            return
        self.last = now
        frac = self.done / self.total
        eta = (now - self.start) * (1 - frac) / frac if frac > 0 else float("nan")
        bar = "#" * int(30 * frac)
        sys.stderr.write(f"\r[{bar:<30s}] {100 * frac:5.1f}%  {label:<22s} ETA {eta:6.0f} s ")
        if self.done >= self.total:
            sys.stderr.write("\n")
        sys.stderr.flush()


def _split(n, size, offload=0.0, speed=None):
    """Contiguous blocks of n points, one per rank: [(lo, hi), ...].

    Rank 0 also gathers, computes the invariants and writes the file at every output.  With
    ``speed[r]`` rank r's points per second (measured on the previous pair; equal if None) and
    ``offload`` rank 0's output work in its own points' worth (S/c₀), every rank reaches the next
    output at the same time T: c₀·n₀ + S = c_r·n_r = T with Σ n_r = n, i.e.
    n_r ∝ speed[r] and n₀ = (n + offload)·speed[0]/Σ speed − offload.  Rank 0's block never
    drops below a quarter of an even share, and no rank's speed counts as more than twice or
    less than half the median (a noisy pair must not starve a rank).  Any split gives the same numbers: a point's
    trajectory does not depend on its batch.
    """
    if size == 1:
        return [(0, n)]
    w = np.ones(size) if speed is None else np.asarray(speed, dtype=float)
    if w.shape != (size,) or not np.all(np.isfinite(w) & (w > 0)):
        w = np.ones(size)
    w = np.clip(w, np.median(w) / 2, np.median(w) * 2)     # one noisy measurement must not starve a rank
    w = w / w.sum()
    n0 = min(max((n + offload) * w[0] - offload, n / (4 * size)), n)
    rest = np.cumsum(w[1:]) / w[1:].sum() * (n - n0)          # ends of ranks 1.. after n0
    bounds = np.concatenate([[0.0, n0], n0 + rest]).round().astype(int)
    bounds[-1] = n
    return [(int(bounds[k]), int(bounds[k + 1])) for k in range(size)]


def _balance(stats, clock):
    """(offload, speed) for the next pair's ``_split`` from this pair's per-rank (advance s, points)."""
    speed = [pts / adv if adv > 0 and pts > 0 else np.nan for adv, pts in stats]
    adv0, n0 = stats[0]
    if n0 == 0 or adv0 <= 0.0:
        return 0.0, None
    offload = (clock["invariants"] + clock["hdf5"]) / (adv0 / n0)
    return offload, (speed if np.all(np.isfinite(speed)) else None)


def _concat(parts):
    return {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}


class Diagnostics:
    """Invariants and conserved-quantity errors of the gathered points at one output time (rank 0)."""

    def __init__(self, scene, system, q0):
        self.scene, self.system = scene, system
        self.n_loop = scene.loop["points"] if scene.loop else 0
        self.surf_shape = (scene.surface["n_sigma"], scene.surface["n_tau"]) if scene.surface else None
        self.H0 = system.H(q0)
        self.P0 = system.momentum(q0) if "momentum" in scene.diagnostics else None

    def _invariant(self, row, name, fn, q, p, lam, live):
        """All forms of one invariant of one sample set, with its resolution, into ``row``.

        A set with a broken-down (frozen) point is no longer an advected set: its values are NaN.
        ``resolved/<set>`` is 1 when the monitor (largest over the forms) is at most
        invariants.UNDER_RESOLVED, else 0 (also when it is NaN).
        """
        from invariants import UNDER_RESOLVED
        res = 0.0 if live.all() else np.nan
        for form in self.scene.forms:
            value = np.nan
            if live.all():
                try:
                    v = fn(q, form, system=self.system, p=p, lam=lam, h=self.scene.h)
                    value, res = v.value, max(res, v.resolution)
                except ValueError:          # non-finite values
                    res = np.nan
            row[f"{name}/{form}"] = value
        row[f"resolution/{name}"] = res
        row[f"resolved/{name}"] = 1 if res <= UNDER_RESOLVED else 0

    def row(self, t, q, p, lam, live):
        import invariants
        sc, sy = self.scene, self.system
        row = {"t": t}
        nl = self.n_loop
        with np.errstate(all="ignore"):
            if nl:
                self._invariant(row, "I1", invariants.first_invariant, q[:nl], p[:nl], lam[:nl], live[:nl])
            if self.surf_shape:
                shp = self.surf_shape + (sy.d,)
                self._invariant(row, "I2", invariants.second_invariant, q[nl:].reshape(shp), p[nl:].reshape(shp),
                                lam[nl:].reshape(shp), live[nl:])
            if "energy" in sc.diagnostics:
                row["energy_error"] = float(np.max(np.abs((sy.H(q) - self.H0) / self.H0)[live], initial=0.0))
            if "momentum" in sc.diagnostics:
                row["momentum_error"] = float(np.max(np.abs(sy.momentum(q) - self.P0)[live], initial=0.0))
            if "constraint" in sc.diagnostics:
                row["constraint_error"] = float(np.max(np.abs(p - sy.theta(q))[live], initial=0.0))
        return row


def _check_output(path, resume, force):
    """One-line reasons why ``path`` cannot be the output, or None."""
    if resume and force:
        return "--resume and --force contradict each other: --resume continues the file, --force replaces it"
    if path.is_dir():
        return f"output '{path}' is a directory; give a file name, e.g. -o {path / 'run.h5'}"
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        return f"output directory '{parent}' does not exist"
    if path.exists() and not (resume or force):
        return f"output '{path}' exists; use --resume to continue it or --force to overwrite it"
    if resume and not path.exists():
        return f"cannot resume: '{path}' does not exist"
    return None


def _resume_plan(path, scene):
    """Check that ``path`` was written by ``scene`` (or by the same scene with fewer steps)."""
    from .scene import parse_scene, scene_differences
    text, steps = output.read_scene_text(path)
    old = parse_scene(text, origin=str(path))
    if steps is not None:
        old = dataclasses.replace(old, steps=steps)
    diff = scene_differences(old, scene)
    for label, digest in output.read_tableau_digests(path).items():
        if label in scene.tableau_files and scene.tableau(label).digest != digest:
            raise ValueError(f"cannot resume '{path}': tableau file '{scene.tableau_files[label]}' ({label}) "
                             "has other coefficients than the run was started with")
    if diff == ["run.steps"] and scene.steps > old.steps:
        return old.steps                      # extend a run to more steps
    if diff == ["run.steps"]:
        raise ValueError(f"cannot resume '{path}' with fewer steps ({scene.steps}) than it was run for ({old.steps})")
    if diff:
        raise ValueError(f"cannot resume '{path}': the scene differs in {', '.join(diff)} "
                         "(only run.steps may grow; everything else must match)")
    return None


def default_threads(comm) -> int:
    """Threads per rank: the cores of this node shared among its ranks (MPICH's MPI_LOCALNRANKS, else
    every rank counts as local)."""
    local = int(os.environ.get("MPI_LOCALNRANKS", comm.size) or comm.size)
    return max(1, (os.cpu_count() or 1) // max(1, local))


def run(scene, path, *, resume=False, force=False, comm=None, progress=None, version="0", after_output=None,
        threads=None):
    """Run every pair of ``scene`` and write ``path``; returns a list of PairSummary (rank 0) or None.

    threads : threads over points on each rank (default: :func:`default_threads`); the numbers are
        bitwise the same for any count.

    resume : continue the pairs of an interrupted file, or extend a finished one when only
        ``run.steps`` grew (the result is bitwise the run of the longer scene).
    after_output : optional callback(pair, step) on rank 0 after each flushed output (tests use it).
    """
    from invariants import UNDER_RESOLVED
    comm = comm or communicator()
    rank = comm.rank
    path = Path(path)
    set_threads(threads or default_threads(comm))
    error, grown_from = None, None
    if rank == 0:
        error = _check_output(path, resume, force)
        if error is None and resume:
            try:
                grown_from = _resume_plan(path, scene)
            except ValueError as exc:
                error = str(exc)
    error = comm.bcast(error, root=0)
    if error:
        raise ValueError(error)

    system = scene.system()
    pts = [a.reshape(-1, system.d) for a in (scene.loop_points(), scene.surface_points()) if a is not None]
    q0 = np.concatenate(pts)
    n = q0.shape[0]
    offload, speed = 0.0, None     # rebalanced after every pair from the measured advance and output work

    f = None
    diagnostics = None
    todo = []
    if rank == 0:
        try:
            diagnostics = Diagnostics(scene, system, q0)
            if resume:
                f = output.open_for_resume(path)
                output.verify(f, path)
                f.attrs["scene"] = scene.text          # a grown run.steps is now the file's scene
                f.attrs["steps"] = scene.steps
            else:
                max_s = max([scene.tableau(t).s for t in scene.tableaus] + [1])
                f = output.create(path, scene, version, n, State.schema(n, system.d, max_s), UNDER_RESOLVED)
            for tab, proj in scene.pairs:
                g = f["runs"][output.pair_name(tab, proj)]
                step, state = output.read_checkpoint(g)
                if g.attrs["status"] in output.FINISHED and grown_from is None:
                    todo.append(None)
                    continue
                g.attrs["status"] = "pending"
                if step is None:
                    output.truncate(g, 0)
                    todo.append((0, None))
                else:
                    output.truncate(g, step // scene.output_every + 1)
                    todo.append((step, state))
            f.flush()
        except (OSError, ValueError) as exc:
            todo = exc if isinstance(exc, (ValueError, output.OutputError)) else \
                output.OutputError(f"cannot write output '{path}': {output.plain_error(exc)}")
            if f is not None:
                _close_quietly(f)
    todo = comm.bcast(todo if rank == 0 else None, root=0)
    if isinstance(todo, Exception):
        raise todo

    timings = {}
    steps_total = sum(scene.steps - (t[0] if t else scene.steps) for t in todo) or 1
    bar = Progress(steps_total, enabled=(rank == 0 and progress is not False and (progress or sys.stderr.isatty())))
    try:
        for (tab_name, proj), job in zip(scene.pairs, todo):
            if job is None:
                continue
            _check_stop()
            offload, speed = _run_pair(comm, f, scene, system, q0, tab_name, proj, job, offload, speed, diagnostics,
                                       after_output, bar, timings, UNDER_RESOLVED)
        comm.Barrier()
    except output.OutputError:
        if f is not None:
            _close_quietly(f)
        raise
    except (OSError, RuntimeError) as exc:      # h5py raises RuntimeError for some failed writes
        if f is not None:
            _close_quietly(f)
        raise output.OutputError(f"writing '{path}' failed: {output.plain_error(exc)}; every output before "
                                 "the failure is in the file (free space, then --resume)") from None
    except BaseException:
        if f is not None:
            _close_quietly(f)
        raise
    if rank != 0:
        return None
    f.close()
    summaries = finalize(path, scene)
    for s_ in summaries:
        s_.timings = timings.get(s_.pair, {})
    return summaries


def _close_quietly(f):
    try:
        f.flush()
    except Exception:
        pass
    try:
        f.close()
    except Exception:
        pass


def _run_pair(comm, f, scene, system, q0, tab_name, proj, job, offload, speed, diagnostics, after_output, bar,
              timings, threshold):
    """Advance one pair from its start (or checkpoint) to scene.steps, writing every output; rank 0
    writes the pair's status when it finishes.  Returns the next pair's (offload, speed)."""
    rank, size = comm.rank, comm.size
    n, h = q0.shape[0], scene.h
    name = output.pair_name(tab_name, proj)
    start_step, saved = job
    if proj == "map":                          # a user's step map (run.step_maps)
        engine, s_tab = MapEngine(scene.step_map(tab_name), system, h, tab_name), 1
    else:
        engine, s_tab = Engine(system, scene.tableau(tab_name), proj, h), scene.tableau(tab_name).s
    blocks = comm.bcast(_split(n, size, offload, speed) if rank == 0 else None, root=0)
    lo, hi = blocks[rank]
    if saved is None:
        st = engine.state(q0[lo:hi])
    else:
        saved = comm.bcast(saved if rank == 0 else None, root=0)
        st = State.from_checkpoint({k: v[lo:hi] for k, v in _unpad(saved, s_tab).items()}, h)
    g = f["runs"][name] if rank == 0 else None
    wall0 = float(g["wall_clock"][0]) if rank == 0 else 0.0
    t_start = time.perf_counter()
    clock = {"advance": 0.0, "gather": 0.0, "invariants": 0.0, "hdf5": 0.0}
    if start_step == 0:
        _output(comm, f, g, scene, diagnostics, st, 0, h, s_tab, after_output, name, clock)

    def on_output(step):
        if rank == 0:
            g["wall_clock"][0] = wall0 + time.perf_counter() - t_start
        _output(comm, f, g, scene, diagnostics, st, step, h, s_tab, after_output, name, clock)

    done = [start_step]

    def progress(step):
        if rank == 0:
            bar.update(step - done[0], name)
        done[0] = step

    clock["advance"] += march(engine, st, start_step, scene.steps, scene.output_every, on_output, progress,
                              _check_stop)
    timings[name] = clock
    stats = comm.gather((clock["advance"], hi - lo), root=0)
    if rank != 0:
        return offload, speed
    g["wall_clock"][0] = wall0 + time.perf_counter() - t_start
    status, _, _, unresolved = output.pair_summary(g, scene.n_outputs, threshold)
    output.set_status(g, status, unresolved)
    f.flush()
    return _balance(stats, clock)


def _pad(state, s_max):
    """Stage arrays padded to the file's largest s."""
    Y = state["Y"]
    if Y.shape[1] < s_max:
        pad = np.zeros((Y.shape[0], s_max - Y.shape[1], Y.shape[2]))
        state = dict(state, Y=np.concatenate([Y, pad], axis=1))
    return state


def _unpad(state, s):
    return dict(state, Y=state["Y"][:, :s])


def _output(comm, f, g, scene, diagnostics, st, step, h, s, after_output, name, clock):
    # every output is a checkpoint: the next step starts from fresh Jacobians on every rank, so
    # a resumed run (which has no Jacobians to carry) is bitwise the uninterrupted one
    st.forget_jacobians()
    t0 = time.perf_counter()
    parts = comm.gather(st.checkpoint(), root=0)
    if comm.rank != 0:
        clock["gather"] += time.perf_counter() - t0
        return
    full = _concat(parts)
    t1 = time.perf_counter()
    clock["gather"] += t1 - t0
    q, p, lam, live = full["q"], full["p"], full["Lam"] / h, full["live"]
    row = diagnostics.row(step * h, q, p, lam, live)
    t2 = time.perf_counter()
    clock["invariants"] += t2 - t1
    if scene.store_points:
        nl = diagnostics.n_loop
        if scene.loop is not None:
            row["points/loop"] = q[:nl]
        if scene.surface is not None:
            row["points/surface"] = q[nl:].reshape(diagnostics.surf_shape + (q.shape[1],))
    need = sum(np.asarray(v).nbytes for v in row.values()) + sum(v.nbytes for v in full.values())
    last = f"{name} t = {g['t'][-1]:g}" if g["t"].shape[0] else f"the pair before {name}"
    output.ensure_space(f.filename, need, last)
    output.append(g, row)
    g["breakdown_time"][...] = full["breakdown_time"]
    output.write_checkpoint(f, g, step, _pad(full, g["checkpoint/a/Y"].shape[1]))
    clock["hdf5"] += time.perf_counter() - t2
    if after_output is not None:
        after_output(name, step)


def finalize(path, scene):
    """Each pair's status and wall_time attributes, written, and the summaries."""
    import h5py
    summaries = []
    with h5py.File(path, "r+") as f:
        threshold = float(f.attrs.get("resolution_threshold", np.inf))
        for tab, proj in scene.pairs:
            name = output.pair_name(tab, proj)
            g = f["runs"][name]
            status, broke, errs, unresolved = output.pair_summary(g, scene.n_outputs, threshold)
            output.set_status(g, status, unresolved)
            g.attrs["wall_time"] = float(g["wall_clock"][0])
            summaries.append(PairSummary(name, status, broke, errs, float(g["wall_clock"][0]),
                                         unresolved_from=unresolved))
    return summaries
