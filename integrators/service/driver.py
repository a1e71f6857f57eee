"""The batch-run driver: every (tableau, projection) pair of a scene, distributed over MPI ranks.

The sample points (loop first, then the surface row by row) are split into contiguous
blocks, one per rank; from the second pair on, the blocks are sized from each rank's measured
advance rate and rank 0's is smaller by the cost of its output work (see ``_split``).  Each rank
advances its block with each pair.  At every output each rank keeps the per-point errors of its
points and its part of each sample set; once a batch of outputs (about two seconds of advancing,
``_Outputs``) the sets' parts are gathered to the ranks that were given their invariant tasks, the
tasks run there, and the other ranks hand their pieces to rank 0 without waiting for it, which
appends the rows to the HDF5 file (see :mod:`integrators.service.output`); about every
``output.checkpoint_seconds`` and at a pair's end the full integrator state comes with them, as a
checkpoint.  Because a point's trajectory does not depend on its batch,
the file's numbers are bitwise the same for any number of ranks.  Without mpiexec
(or without mpi4py) it runs as a single process.
"""
from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from . import output
from ..engine import Engine, MapEngine, State, march, set_threads
from .diagnostics import Diagnostics, assign
from .ranks import _balance, _split, communicator, default_threads


STOP = []      # exceptions left by a signal handler (integrators.service.cli); raised before the next step


def _check_stop():
    if STOP:
        raise STOP.pop()


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


def _concat(parts):
    return {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}


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
    q0 = scene.points(system)
    n = q0.shape[0]
    offload, speed = 0.0, None     # rebalanced after every pair from the measured advance and output work

    f = None
    todo = []
    if rank == 0:
        try:
            if resume:
                f = output.reopen(path, scene)
            else:
                max_s = max([scene.tableau(t).s for t in scene.tableaus] + [1])
                f = output.create(path, scene, version, n, State.schema(n, system.d, max_s), UNDER_RESOLVED)
            for tab, proj in scene.pairs:
                todo.append(output.restart_pair(f, output.pair_name(tab, proj), scene.output_every,
                                                finished_too=grown_from is not None))
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
            offload, speed = _run_pair(comm, f, scene, system, q0, tab_name, proj, job, offload, speed,
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


def _run_pair(comm, f, scene, system, q0, tab_name, proj, job, offload, speed, after_output, bar, timings,
              threshold):
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
    g = output.pair_group(f, name) if rank == 0 else None
    wall0 = output.wall_clock(g) if rank == 0 else 0.0
    t_start = time.perf_counter()
    clock = {"advance": 0.0, "gather": 0.0, "invariants": 0.0, "hdf5": 0.0}
    out = _Outputs(comm, scene, Diagnostics(scene, system, q0[lo:hi]), (lo, hi), assign(scene, size), f, g,
                   clock, after_output, name, lambda: wall0 + time.perf_counter() - t_start)
    if start_step == 0:
        out.take(st, 0, checkpoint=False, flush=False)

    def on_output(step):
        j = (step - start_step) // scene.output_every
        if j == 1:        # rank 0's first interval sets the batches of outputs and how often the state is written
            w0 = time.perf_counter()
            out.batch, out.cadence = comm.bcast(
                (_batch(w0 - t_start, hi - lo), _cadence(w0 - t_start, scene.checkpoint_seconds))
                if rank == 0 else None, root=0)
            clock["gather"] += time.perf_counter() - w0
        last = step == scene.steps
        out.take(st, step, checkpoint=last or j % out.cadence == 0, flush=last or j % out.batch == 0)

    done = [start_step]

    def progress(step):
        if rank == 0:
            bar.update(step - done[0], name)
        done[0] = step

    clock["advance"] += march(engine, st, start_step, scene.steps, scene.output_every, on_output, progress,
                              _check_stop)
    out.finish_sending()
    timings[name] = clock
    clocks = comm.gather(dict(clock, points=hi - lo), root=0)
    if rank != 0:
        return offload, speed
    clock["per_rank"] = clocks                 # every rank's phases, for the cost model (scripts/scaling.py)
    stats = [(c["advance"], c["points"], c["invariants"] + c["hdf5"]) for c in clocks]
    output.wall_clock(g, wall0 + time.perf_counter() - t_start)
    output.close_pair(g, scene.n_outputs, threshold)
    f.flush()
    return _balance(stats)


def _unpad(state, s):
    return dict(state, Y=state["Y"][:, :s])


BATCH_SECONDS = 2.0          # outputs are taken together in batches of about this much advancing
BATCH_BYTES = 1 << 28        # ... holding no more than this of a rank's points


def _batch(seconds_per_output, points) -> int:
    """Outputs a rank holds before the ranks meet: about BATCH_SECONDS of advancing, within BATCH_BYTES."""
    by_time = int(BATCH_SECONDS / max(seconds_per_output, 1e-6))
    return max(1, min(by_time, BATCH_BYTES // (128 * max(points, 1))))


def _cadence(seconds_per_output, checkpoint_seconds) -> int:
    """Outputs between two checkpoints: as many as take about ``checkpoint_seconds`` (1 for 0)."""
    if checkpoint_seconds <= 0:
        return 1
    return max(1, int(checkpoint_seconds / max(seconds_per_output, 1e-6)))


OUTPUT_TAG = 7


@dataclasses.dataclass
class _Output:
    """What a rank keeps of one output until its batch is taken: its points' errors, its part of
    each sample set (q, p, λ, live), and what rank 0 writes of its points."""

    step: int
    checkpoint: bool
    errors: dict
    parts: list
    piece: dict


@dataclasses.dataclass
class _Outputs:
    """One rank's outputs of one pair.

    The outputs are taken in batches (:func:`_batch`: about two seconds of advancing; a batch also
    ends at a checkpoint and at the pair's last output), so the ranks meet once a batch, not at
    every output, and what one rank's advance gains or loses on the other's in one interval evens
    out over the batch.  At a batch's end the sets' parts are gathered to the ranks that hold one
    of the set's tasks, the tasks run, the other ranks hand their pieces to rank 0 without waiting
    for it (:meth:`send`), and rank 0 writes the rows in order, each flushed.
    """

    comm: object
    scene: object
    diagnostics: Diagnostics
    block: tuple                    # (lo, hi): the rows this rank advances
    tasks: dict                     # {(invariant, form): rank}, the same on every rank
    f: object                       # rank 0: the file and the pair's group
    g: object
    clock: dict
    after_output: object
    name: str
    wall: object                    # rank 0: the pair's wall time so far, for its row
    batch: int = 1                  # outputs a batch (from the pair's first interval, on every rank)
    cadence: int = 1                # outputs between checkpoints
    held: list = dataclasses.field(default_factory=list)
    sending: list = dataclasses.field(default_factory=list)   # this rank's unfinished send to rank 0
    breakdown_written: np.ndarray | None = None               # rank 0: the breakdown times in the file

    def take(self, st, step, checkpoint, flush):
        """Keep this output's errors and parts (copies: the state moves on); with ``flush`` (always
        with ``checkpoint``), take the batch."""
        t0 = time.perf_counter()
        lo, hi = self.block
        h = self.scene.h
        mine = (st.q, st.p, st.Lam / h, st.live)
        parts = []
        for _, rows in self.scene.sample_sets:
            a, b = max(lo, rows.start), min(hi, rows.stop)
            parts.append(tuple(np.array(x[max(a - lo, 0):max(b - lo, 0)]) for x in mine))
        flush = flush or checkpoint
        if checkpoint:           # a batch's last output: sent or written before the state moves
            piece = st.checkpoint()
        else:                    # what rows need of the points (breakdown times only at a batch's end)
            piece = ({"breakdown_time": st.breakdown_time.copy()} if flush else {}) | \
                ({"q": st.q.copy()} if self.scene.store_points else {})
        self.held.append(_Output(step, checkpoint, self.diagnostics.point_errors(st.q, st.p, st.live), parts, piece))
        self.clock["invariants"] += time.perf_counter() - t0
        if flush:
            self.flush()

    def flush(self):
        """Take the held outputs: gathers, tasks, the pieces to rank 0, and there the rows."""
        comm, scene, rank = self.comm, self.scene, self.comm.rank
        t0 = time.perf_counter()
        held, wait, gathered = self.held, 0.0, {}
        for k, (spec, _) in enumerate(scene.sample_sets):   # every gather first: then the ranks work at once
            for owner in sorted({r for (inv, _), r in self.tasks.items() if inv == spec.invariant}):
                w0 = time.perf_counter()
                parts = comm.gather([x.parts[k] for x in held], root=owner)
                wait += time.perf_counter() - w0
                if rank == owner:
                    gathered[k] = parts              # parts[r][i]: rank r's part at the batch's i-th output
        values = [{} for _ in held]
        for k, parts in gathered.items():
            spec = scene.sample_sets[k][0]
            forms = [fm for fm in scene.forms if self.tasks[(spec.invariant, fm)] == rank]
            for i, v in enumerate(values):
                q, p, lam, live = (np.concatenate([r[i][c] for r in parts]) for c in range(4))
                shp = spec.grid + (q.shape[1],)
                v.update(self.diagnostics.set_values(spec, forms, q.reshape(shp), p.reshape(shp), lam.reshape(shp),
                                                     live))
        mine = [(x.errors, v, x.piece) for x, v in zip(held, values)]
        t1 = time.perf_counter()
        if rank != 0:            # pickled at once: the state may move on while the message travels
            self.send(mine)
        else:
            batches = [mine] + [comm.recv(source=r, tag=OUTPUT_TAG) for r in range(1, comm.size)]
        t2 = time.perf_counter()
        self.clock["invariants"] += t1 - t0 - wait
        self.clock["gather"] += wait + t2 - t1
        self.clock["wait_gather"] = self.clock.get("wait_gather", 0.0) + wait      # of which at the sets' gathers
        self.clock["wait_recv"] = self.clock.get("wait_recv", 0.0) + t2 - t1       # ... and handing pieces to rank 0
        self.clock["meetings"] = self.clock.get("meetings", 0) + 1
        self.held = []
        if rank == 0:
            self.write(held, batches)

    def write(self, held, batches):
        """Rank 0: the batch's rows from every rank's (errors, values, piece) at each output, written
        together and flushed; the breakdown times when they changed, the state at a checkpoint."""
        scene, t0 = self.scene, time.perf_counter()
        rows = []
        for i, x in enumerate(held):
            parts = [b[i] for b in batches]
            rows.append(self.diagnostics.combine(x.step * scene.h, [p[0] for p in parts],
                                                 {k: v for p in parts for k, v in p[1].items()}))
            if scene.store_points:
                q = np.concatenate([p[2]["q"] for p in parts])
                for spec, sl in scene.sample_sets:
                    rows[-1][f"points/{spec.name}"] = q[sl].reshape(spec.grid + (q.shape[1],))
        last = held[-1]
        full = _concat([b[-1][2] for b in batches])
        bt = full["breakdown_time"]
        changed = self.breakdown_written is None or not np.array_equal(bt, self.breakdown_written)
        t1 = time.perf_counter()
        output.wall_clock(self.g, self.wall())
        output.write_rows(self.f, self.g, last.step, rows, bt if changed else None, full if last.checkpoint else None)
        self.breakdown_written = bt
        self.clock["invariants"] += t1 - t0
        self.clock["hdf5"] += time.perf_counter() - t1
        if self.after_output is not None:
            for x in held:
                self.after_output(self.name, x.step)

    def send(self, payload):
        """Hand a batch's pieces to rank 0 without waiting for it to take them (it may still be on
        its own tasks or writing): the rank goes on advancing; the last batch's send is finished
        first (by then rank 0 has received it)."""
        self.finish_sending()
        self.sending.append(self.comm.isend(payload, dest=0, tag=OUTPUT_TAG))

    def finish_sending(self):
        while self.sending:
            self.sending.pop().wait()


def finalize(path, scene):
    """Each pair's status and wall_time attributes, written, and the summaries."""
    return [PairSummary(name, status, broke, errs, wall, unresolved_from=unresolved)
            for name, status, broke, errs, wall, unresolved in
            output.finish(path, [output.pair_name(t, p) for t, p in scene.pairs], scene.n_outputs)]
