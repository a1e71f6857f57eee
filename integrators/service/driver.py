"""The batch-run driver: every (tableau, projection) pair of a scene, distributed over MPI ranks.

The sample points (loop first, then the surface row by row) are split into contiguous
blocks, one per rank; from the second pair on, the blocks are sized from each rank's measured
advance rate and rank 0's is smaller by the cost of its output work (see ``_split``).  Each rank
advances its block with each pair.  At every output each rank keeps the per-point errors of its
points and its part of each sample set; once a batch of outputs (about two seconds of advancing)
it sends the sets' parts to the ranks that own their invariant tasks in that batch (a set's forms
on one rank, the owners turned by one rank a batch: ``_Stream.owners``) and goes on, without
waiting for anyone (``_Stream``).  A task owner runs a batch's tasks once the parts have arrived,
and every rank sends its pieces to rank 0, which appends the rows to the HDF5 file in order (see
:mod:`integrators.service.output`); about every ``output.checkpoint_seconds`` and at a pair's end
the full integrator state comes with them, as a checkpoint.  Because a point's trajectory does
not depend on its batch, the file's numbers are bitwise the same for any number of ranks.
Without mpiexec (or without mpi4py) it runs as a single process.
"""
from __future__ import annotations

import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import output
from ..engine import Engine, MapEngine, State, march, set_threads
from .diagnostics import Diagnostics, assign_sets
from .refine import Refiner, refined_values
from .stop import StopRequest  # noqa: F401  (run's stop argument; tests make one)
from .ranks import _balance, _split, communicator, default_threads


@dataclasses.dataclass
class PairSummary:
    pair: str
    status: str
    breakdowns: int
    max_errors: dict
    wall_time: float
    timings: dict = dataclasses.field(default_factory=dict)
    unresolved_from: dict = dataclasses.field(default_factory=dict)   # {'I1': first t the set was under-resolved}
    breakdown: tuple = (None, 0)     # (first breakdown time or None, points of the run)
    laws: dict = dataclasses.field(default_factory=dict)   # {'I1 form' | 'energy' | …: growth law}
    refined: dict = dataclasses.field(default_factory=dict)  # {'I1'|'I2': (first t refined, points, most used)}


class Progress:
    """The run's progress bar (tqdm.auto: a text bar in a terminal, a widget in a notebook), on rank 0
    only, over the steps of every pair still to run.  ``enabled`` False (``-q``, or not interactive)
    counts without drawing."""

    def __init__(self, total, enabled):
        self.total, self.done, self.enabled = total, 0, enabled
        self.bar = None
        if enabled:
            import shutil
            from tqdm.auto import tqdm
            ncols = None if "ipykernel" in sys.modules else min(shutil.get_terminal_size().columns, 120)
            self.bar = tqdm(total=total, unit="step", unit_scale=True, leave=True, ncols=ncols,
                            mininterval=0.2, smoothing=0.1)   # (a terminal that reports no width: 80)

    def update(self, n, label):
        self.done += n
        if self.bar is not None:
            if self.bar.desc != label:
                self.bar.set_description_str(label, refresh=False)
            self.bar.update(n)
            if self.done >= self.total:
                self.close()

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _interactive():
    """Whether a bar is wanted by default: stderr is a terminal, or this is a notebook kernel."""
    return sys.stderr.isatty() or "ipykernel" in sys.modules


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
    if path.exists() and not path.is_file():      # a device, a FIFO: never written, never replaced
        return f"output '{path}' is not a regular file"
    if path.exists() and not (resume or force):
        return f"output '{path}' exists; use --resume to continue it or --force to overwrite it"
    if resume and not path.exists():
        return f"cannot resume: '{path}' does not exist"
    if force and path.exists():          # never replace a file another run is still writing
        try:
            output.open_file(path).close()
        except output.BusyFile as exc:
            return str(exc)
        except (ValueError, OSError):    # damaged or not HDF5: --force is for that
            pass
    return None


def _resume_plan(path, scene):
    """Check that ``path`` was written by ``scene`` (or by the same scene with fewer steps)."""
    from .scene import parse_scene, scene_differences
    text, steps = output.read_scene_text(path)
    try:
        old = parse_scene(text, origin=str(path))
    except ValueError as exc:
        raise output.DamagedFile(f"cannot resume '{path}': the scene stored in it does not read ({exc})") from None
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
        if scene.steps > old.steps:           # growing run.steps is allowed: not a difference to name
            diff = [k for k in diff if k != "run.steps"]
        raise ValueError(f"cannot resume '{path}': the scene differs in {', '.join(diff)} "
                         "(only run.steps may grow; everything else must match)")
    return None


def run(scene, path, *, resume=False, force=False, comm=None, progress=None, version="0", after_output=None,
        threads=None, stop=None):
    """Run every pair of ``scene`` and write ``path``; returns a list of PairSummary (rank 0) or None.

    threads : threads over points on each rank (default: :func:`default_threads`); the numbers are
        bitwise the same for any count.

    resume : continue the pairs of an interrupted file, or extend a finished one when only
        ``run.steps`` grew (the result is bitwise the run of the longer scene).
    after_output : optional callback(pair, step) on rank 0 after each flushed output (tests use it).
    stop : a :class:`StopRequest` (or any callable that raises to stop), checked before each pair
        and between the engine's calls: the file stays readable up to its last output.
    """
    check = stop if stop is not None else (lambda: None)
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
        if error is None and resume:
            try:
                output.check_resumable(path, scene)       # read-only: a refused resume changes no byte
            except ValueError as exc:
                error = str(exc)
    error = comm.bcast(error, root=0)
    if error:
        raise ValueError(error)

    system = scene.system()
    error = None
    try:                               # the engine's code for this system, compiled before any file is touched
        from ..engine import point_functions
        point_functions(system)
    except Exception as exc:
        error = f"system {system.name}: the step engine cannot be compiled for it: {type(exc).__name__}: " \
            f"{str(exc).splitlines()[0] if str(exc) else ''}"
    error = comm.bcast(error if rank == 0 else None, root=0)
    if error:
        raise ValueError(error)
    q0 = scene.points(system)
    n = q0.shape[0]

    f = None
    todo = []
    replacing = None                   # --force over an existing file: written beside it, renamed over it once started
    if rank == 0:
        try:
            if resume:
                f = output.reopen(path, scene)
            else:
                max_s = max([scene.tableau(t).s for t in scene.tableaus] + [1])
                target = path
                if path.exists():
                    replacing = _Replacement(path.resolve())      # (through a symlink: its target)
                    target = replacing.new
                f = output.create(target, scene, version, n, State.schema(n, system.d, max_s), UNDER_RESOLVED)
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
        if replacing is not None:
            replacing.abandon()
        raise todo

    timings = {}
    steps_total = sum(scene.steps - (t[0] if t else scene.steps) for t in todo) or 1
    bar = Progress(steps_total, enabled=(rank == 0 and progress is not False and (progress or _interactive())))
    try:
        stream = _Stream(comm, scene, f, after_output, timings, UNDER_RESOLVED)
        if replacing is not None:      # the old file goes once the new run has written its first rows
            stream.started = replacing.commit
        jobs = [(tab, proj, job) for (tab, proj), job in zip(scene.pairs, todo) if job is not None]
        for i, (tab_name, proj, job) in enumerate(jobs):
            check()
            _run_pair(comm, stream, scene, system, q0, tab_name, proj, job, i == 0, i + 1 < len(jobs), bar, check)
        w0 = time.perf_counter()
        stream.drain()
        ends = comm.gather(time.perf_counter() - w0, root=0)
        if rank == 0 and jobs:               # what each rank spent finishing the last batches, with the last pair
            last = timings[output.pair_name(*jobs[-1][:2])]
            for c, s in zip(last["per_rank"], ends):
                c["wait_end"] = s
        comm.Barrier()
    except output.OutputError:
        if f is not None:
            _close_quietly(f)
        if replacing is not None:
            replacing.abandon()
        raise
    except (OSError, RuntimeError) as exc:      # h5py raises RuntimeError for some failed writes
        if f is not None:
            _close_quietly(f)
        raise output.OutputError(f"writing '{path}' failed: {output.plain_error(exc)}; every output before "
                                 "the failure is in the file (free space, then --resume)") from None
    except BaseException:
        if f is not None:
            _close_quietly(f)
        if replacing is not None:
            replacing.abandon()
        raise
    finally:
        bar.close()
    if rank != 0:
        return None
    f.close()
    if replacing is not None:      # (a scene with no pair to run has written no rows)
        replacing.commit()
    summaries = finalize(path, scene)
    for s_ in summaries:
        s_.timings = timings.get(s_.pair, {})
    return summaries


class _Replacement:
    """``--force`` over an existing file: the new run writes ``.NAME.PID.new`` beside it, which
    replaces the old file (an atomic rename) once its first rows are written; a run that stops
    before that removes its new file and leaves the old one as it was."""

    def __init__(self, path):
        self.path, self.new, self.done = path, path.with_name(f".{path.name}.{os.getpid()}.new"), False

    def commit(self):
        if not self.done:
            os.replace(self.new, self.path)
            self.done = True

    def abandon(self):
        if not self.done:
            try:
                os.remove(self.new)
            except OSError:
                pass


def _close_quietly(f):
    try:
        f.flush()
    except Exception:
        pass
    try:
        f.close()
    except Exception:
        pass


def _run_pair(comm, stream, scene, system, q0, tab_name, proj, job, first, has_next, bar, check):
    """Advance one pair on this rank from its start (or checkpoint) to scene.steps, handing each
    batch of outputs to ``stream``; the pair's tasks and rows may finish during the next pair."""
    rank, size = comm.rank, comm.size
    n, h = q0.shape[0], scene.h
    name = output.pair_name(tab_name, proj)
    start_step, saved = job
    if proj == "map":                          # a user's step map (run.step_maps)
        def make_engine():
            return MapEngine(scene.step_map(tab_name), system, h, tab_name)
        s_tab = 1
    else:
        def make_engine():
            return Engine(system, scene.tableau(tab_name), proj, h)
        s_tab = scene.tableau(tab_name).s
    engine = make_engine()
    clock = {"advance": 0.0, "gather": 0.0, "invariants": 0.0, "hdf5": 0.0, "wait_plan": 0.0, "wait_gather": 0.0,
             "wait_recv": 0.0, "refine": 0.0, "refine_point_steps": 0, "batches": 0}
    w0 = time.perf_counter()
    if first:                                  # the run's first pair: an even split, batches from its first interval
        plan = (comm.bcast(_split(n, size) if rank == 0 else None, root=0), None, None)
    else:
        plan = stream.receive_plan()
    clock["wait_plan"] = clock["gather"] = time.perf_counter() - w0
    blocks, batch, cadence = plan
    lo, hi = blocks[rank]
    if saved is None:
        st = engine.state(q0[lo:hi])
    else:
        saved = comm.bcast(saved if rank == 0 else None, root=0)
        st = State.from_checkpoint({k: v[lo:hi] for k, v in _unpad(saved, s_tab).items()}, h)
    t_start = time.perf_counter()
    pair = _Pair(name, (lo, hi), Diagnostics(scene, system, q0[lo:hi]), clock, batch or 1, cadence or 1, t_start,
                 dict(stream.spent), start_step, (start_step + scene.steps) // 2,
                 refiners={spec.name: Refiner(spec, make_engine, scene.base, h, scene.output_every, check)
                           for spec, _ in scene.sample_sets if spec.levels})
    if rank == 0:
        pair.g = output.pair_group(stream.f, name)
        wall0 = output.wall_clock(pair.g)
        pair.wall = lambda: wall0 + (pair.t_end or time.perf_counter()) - t_start
    final = last_checkpoint_step(scene.steps, scene.output_every)
    if start_step < scene.steps:   # the output at the start (a resume's checkpoint row was dropped: same bits)
        stream.take(pair, st, start_step, checkpoint=False, flush=False)
    measured = []

    def first_interval():
        """Rank 0's first interval sets the batches and how often the state is written (at the
        pair's end when this run of the pair holds no whole interval)."""
        w0 = time.perf_counter()
        per_output = w0 - t_start
        measured.append(per_output)
        if batch is None:
            pair.batch, pair.cadence = comm.bcast(
                (_batch(per_output, hi - lo), _cadence(per_output, scene.checkpoint_seconds))
                if rank == 0 else None, root=0)
        if rank == 0 and has_next:     # sent from about the pair's middle (_Stream.plan_next)
            stream.next_pair = (n, _batch(per_output, hi - lo), _cadence(per_output, scene.checkpoint_seconds))
        stream.charge(clock, "gather", time.perf_counter() - w0)

    def on_output(step):
        j = (step - start_step) // scene.output_every
        if j == 1:
            first_interval()
        if step < scene.steps:    # the last output is taken below, once the pair's advance is on its clock
            stream.take(pair, st, step, checkpoint=j % pair.cadence == 0 or step == final,
                        flush=j % pair.batch == 0)

    done = [start_step]

    def progress(step):
        if rank == 0:
            bar.update(step - done[0], name)
        done[0] = step

    clock["advance"] += march(engine, st, start_step, scene.steps, scene.output_every, on_output, progress,
                              check)
    if not measured:
        first_interval()
    stream.take(pair, st, scene.steps, checkpoint=scene.steps == final, flush=True, last=True)
    pair.t_end = time.perf_counter()


def last_checkpoint_step(steps, every) -> int:
    """The step of a finished pair's checkpoint: the last multiple of ``every`` (run.output_every).

    Newton's factors are dropped at every multiple of the cadence, so a state there continues
    bitwise as the uninterrupted run would; when ``steps`` is not a multiple, the last output (at
    ``steps``) is a real output but the state kept is the one before it, from which a resume or a
    longer run continues (it recomputes that last partial interval, or goes on past it)."""
    return steps - steps % every


def _unpad(state, s):
    return dict(state, Y=state["Y"][:, :s])


BATCH_SECONDS = 2.0          # outputs are taken together in batches of about this much advancing
BATCH_BYTES = 1 << 28        # ... holding no more than this of a rank's points


def _batch(seconds_per_output, points) -> int:
    """Outputs a rank holds before it hands them on: about BATCH_SECONDS of advancing, within BATCH_BYTES."""
    by_time = int(BATCH_SECONDS / max(seconds_per_output, 1e-6))
    return max(1, min(by_time, BATCH_BYTES // (128 * max(points, 1))))


def _cadence(seconds_per_output, checkpoint_seconds) -> int:
    """Outputs between two checkpoints: as many as take about ``checkpoint_seconds`` (1 for 0)."""
    if checkpoint_seconds <= 0:
        return 1
    return max(1, int(checkpoint_seconds / max(seconds_per_output, 1e-6)))


LAG = 2                              # batches a task owner may hold before it waits for another rank's parts
PARTS_TAG, OUTPUT_TAG, PLAN_TAG = 5, 7, 9


@dataclasses.dataclass
class _Output:
    """What a rank keeps of one output until its batch's tasks have run: its points' errors, its
    part of each sample set (q, p, λ, live), and what rank 0 writes of its points."""

    step: int
    checkpoint: bool
    errors: dict
    parts: list
    piece: dict


@dataclasses.dataclass
class _Pair:
    """One pair as one rank runs it; on rank 0 also the pair's group of the file and its wall time."""

    name: str
    block: tuple                    # (lo, hi): the rows this rank advances
    diagnostics: Diagnostics
    clock: dict                     # this rank's seconds in each phase of the pair
    batch: int                      # outputs a batch
    cadence: int                    # outputs between checkpoints
    t_start: float
    spent0: dict                    # the rank's seconds outside the advance (_Stream.spent) when the pair began
    start: int                      # the step the pair began at on this run
    middle: int                     # from this step on, rank 0 may send the next pair's plan
    held: list = dataclasses.field(default_factory=list)
    g: object = None
    wall: object = None
    t_end: float | None = None
    at: int = 0                     # the step of the latest output taken
    refiners: dict = dataclasses.field(default_factory=dict)  # {set name: Refiner}: its finer levels' new points
    breakdown_written: np.ndarray | None = None               # rank 0: the breakdown times in the file


@dataclasses.dataclass
class _Batch:
    pair: _Pair
    held: list                      # an _Output per output
    last: bool                      # the pair's last batch
    index: int = 0                  # its place among the run's batches (whose turn each task is)


class _Stream:
    """One rank's outputs over the whole run, handed on without making the ranks meet.

    The outputs of a pair are taken in batches (:func:`_batch`: about two seconds of advancing; a
    batch also ends at a checkpoint and at the pair's last output).  At a batch's end a rank sends
    its parts of the sample sets to the ranks that hold one of their invariant tasks (non-blocking)
    and goes on advancing.  A task owner runs a batch's tasks once every rank's parts of it have
    arrived, checked at each of its own batch ends; it waits only when it holds more than
    :data:`LAG` batches, or at the run's end.  Then the rank sends its errors, task values and
    pieces of the batch to rank 0, which writes the batches in order as they become complete.  So a
    rank that is slower for a batch or two costs the others nothing; only drift over more than
    :data:`LAG` batches, or about half a pair, makes a rank wait.  Rank 0 sends the next pair's
    split from about the middle of a pair (:meth:`plan_next`), sized from the ranks' rates on it,
    which come with their pieces.
    """

    def __init__(self, comm, scene, f, after_output, timings, threshold):
        self.comm, self.scene, self.f = comm, scene, f
        self.after_output, self.timings, self.threshold = after_output, timings, threshold
        self.tasks = assign_sets(scene, comm.size)   # turned by one rank a batch: owners()
        self.refining = {spec.invariant for spec, _ in scene.sample_sets if spec.levels}
        self.order = {output.pair_name(t, p): k for k, (t, p) in enumerate(scene.pairs)}
        self.batches = 0                   # batches closed so far, any pair's: the same count on every rank
        self.pending, self.writing, self.sending = [], [], []
        self.balance = (0.0, None)         # rank 0: (offload, speed) of the latest pair with every rank's clocks
        self.plan = None
        self.next_pair = None              # rank 0: (points, batch, cadence) of the next pair, until its plan is sent
        self.current = None                # the pair this rank advances
        self.rates = {}                    # rank 0: {rank: (pair, rates)}: the latest each rank sent
        self.spent = {"invariants": 0.0, "hdf5": 0.0, "gather": 0.0}   # seconds outside the advance, any pair's
        self.started = None                # rank 0, --force: called once the first rows are written

    def owners(self, j, k=0):
        """{(invariant, form): rank} of batch ``j`` of the run's ``k``-th pair: the assignment
        (:func:`assign_sets`: a set's forms on one rank, longest set first to the least loaded)
        turned by j ranks, so that over any R consecutive batches every rank runs every task once:
        the largest task bounds how late a batch's values come, not how many outputs a second the
        ranks get through (docs/benchmarks.md, "Distributed output").  A set that refines itself
        turns by pair instead (k ranks): its new points are advanced by the rank that takes its
        tasks (integrators.service.refine), once a pair rather than once per rank.  A task is the
        same function of the same points on any rank: no bit changes."""
        size, refining = self.comm.size, self.refining
        return {key: (r + (k if key[0] in refining else j)) % size for key, r in self.tasks.items()}

    def needs(self, j, k=0):
        """{owner: [set index]} of batch ``j`` of the ``k``-th pair: which ranks need which sets' parts."""
        own = self.owners(j, k)
        sets = list(enumerate(s for s, _ in self.scene.sample_sets))
        return {o: [k for k, spec in sets if any(own[(spec.invariant, fm)] == o for fm in self.scene.forms)]
                for o in sorted(set(own.values()))}

    def others(self, j, k=0):
        """The ranks whose parts of batch ``j`` (of the ``k``-th pair) this rank waits for (none
        unless it owns a task)."""
        rank = self.comm.rank
        return [r for r in range(self.comm.size) if r != rank] if rank in self.needs(j, k) else []

    def charge(self, clock, phase, seconds):
        """Book seconds of output work or exchange to a pair's clock and to the rank's running total."""
        clock[phase] += seconds
        self.spent[phase] += seconds

    def rates_of(self, pair):
        """(seconds advancing, points, seconds of output work), each a step, of this rank since it
        began ``pair`` (as :func:`_balance` takes them): the other pairs' lagged tasks and rows
        count as work done meanwhile, not as advance."""
        d = {k: v - pair.spent0[k] for k, v in self.spent.items()}
        work, steps = d["invariants"] + d["hdf5"], max(pair.at - pair.start, 1)
        return (time.perf_counter() - pair.t_start - work - d["gather"]) / steps, pair.block[1] - pair.block[0], \
            work / steps

    # -- a rank's batches -------------------------------------------------------------------------
    def take(self, pair, st, step, checkpoint, flush, last=False):
        """Keep this output's errors and parts (copies: the state moves on); with ``flush`` (always
        with ``checkpoint``), hand the batch on."""
        t0 = time.perf_counter()
        lo, hi = pair.block
        pair.at = step
        mine = (st.q, st.p, st.Lam / self.scene.h, st.live)
        parts = []
        for _, rows in self.scene.sample_sets:
            a, b = max(lo, rows.start), min(hi, rows.stop)
            parts.append(tuple(np.array(x[max(a - lo, 0):max(b - lo, 0)]) for x in mine))
        flush = flush or checkpoint
        if checkpoint:           # a batch's last output: copied, the state moves on before rank 0 writes it
            piece = {k: np.array(v) for k, v in st.checkpoint().items()}
        else:                    # what rows need of the points (breakdown times only at a batch's end)
            piece = ({"breakdown_time": st.breakdown_time.copy()} if flush else {}) | \
                ({"q": st.q.copy()} if self.scene.store_points else {})
        pair.held.append(_Output(step, checkpoint, pair.diagnostics.point_errors(st.q, st.p, st.live), parts, piece))
        self.charge(pair.clock, "invariants", time.perf_counter() - t0)
        if flush:
            self.close_batch(pair, step, last)

    def close_batch(self, pair, step, last):
        """Send the batch's parts to the task owners, queue its tasks, and run (rank 0: write) what is ready."""
        comm, t0 = self.comm, time.perf_counter()
        held, pair.held = pair.held, []
        j, self.batches = self.batches, self.batches + 1
        for o, sets in self.needs(j, self.order[pair.name]).items():
            if o != comm.rank:         # pickled at once: the state may move on while the message travels
                self.sending.append(comm.isend({k: [x.parts[k] for x in held] for k in sets}, dest=o, tag=PARTS_TAG))
        self.current = pair
        self.pending.append(_Batch(pair, held, last, j))
        self.sending = [r for r in self.sending if not r.Test()]
        self.charge(pair.clock, "gather", time.perf_counter() - t0)
        pair.clock["batches"] += 1
        self.work(block=False)
        if comm.rank == 0:
            self.write_ready(block=False)
            self.plan_next(pair, step, last)

    def _ready(self):
        """Whether every other rank's parts of the oldest queued batch have arrived (a rank's parts
        come in its batches' order, and only for the batches whose tasks this rank owns)."""
        b = self.pending[0]
        return all(self.comm.iprobe(source=r, tag=PARTS_TAG) for r in self.others(b.index, self.order[b.pair.name]))

    def work(self, block):
        """Run the tasks of the queued batches in order: those whose parts are here; with ``block``,
        or while more than LAG are queued, waiting for the parts."""
        while self.pending and (block or len(self.pending) > LAG or self._ready()):
            self._tasks(self.pending.pop(0))

    def _tasks(self, b):
        comm, scene, rank, clock = self.comm, self.scene, self.comm.rank, b.pair.clock
        t0 = time.perf_counter()
        got = {}
        k_pair = self.order[b.pair.name]
        for r in self.others(b.index, k_pair):
            got[r] = comm.recv(source=r, tag=PARTS_TAG)      # parts[k][i]: set k at the batch's i-th output
        wait = time.perf_counter() - t0
        values = [{} for _ in b.held]
        own = self.owners(b.index, k_pair)
        for k in self.needs(b.index, k_pair).get(rank, []):
            spec = scene.sample_sets[k][0]
            forms = [fm for fm in scene.forms if own[(spec.invariant, fm)] == rank]
            for i, v in enumerate(values):
                parts = [got[r][k][i] if r != rank else b.held[i].parts[k] for r in range(comm.size)]
                q, p, lam, live = (np.concatenate([x[c] for x in parts]) for c in range(4))
                shp = spec.grid + (q.shape[1],)
                args = (spec, forms, q.reshape(shp), p.reshape(shp), lam.reshape(shp), live.reshape(spec.grid))
                if spec.levels:       # a set that refines itself: the coarsest level that resolves it
                    v.update(refined_values(b.pair.diagnostics, b.pair.refiners[spec.name], *args,
                                            b.held[i].step, self.threshold))
                else:
                    v.update(b.pair.diagnostics.set_values(*args[:5], live))
        mine = [(x.errors, v, x.piece) for x, v in zip(b.held, values)]
        t1 = time.perf_counter()
        refine = sum(r.seconds for r in b.pair.refiners.values())
        clock["refine_point_steps"] = sum(r.point_steps for r in b.pair.refiners.values())
        spent, clock["refine"] = refine - clock["refine"], refine
        self.charge(clock, "invariants", t1 - t0 - wait - spent)
        clock["wait_gather"] += wait
        self.charge(clock, "gather", wait)
        if rank == 0:
            self.writing.append((b, mine))
            return
        if b.last:
            clock["points"] = b.pair.block[1] - b.pair.block[0]
        rates = (self.current.name, self.rates_of(self.current))
        self.sending.append(comm.isend((mine, rates, dict(clock) if b.last else None), dest=0, tag=OUTPUT_TAG))
        self.charge(clock, "gather", time.perf_counter() - t1)

    # -- rank 0: the plan of the next pair, and the file ------------------------------------------
    def plan_next(self, pair, step, last):
        """Rank 0: send the next pair's (blocks, batch, cadence) to every rank without waiting, once
        past the pair's middle with every rank's rates on this pair (at its last batch in any case).
        The blocks follow those rates (:func:`_split`), else the latest finished pair's."""
        if self.next_pair is None or step < pair.middle:
            return
        sent = (self.rates.get(r, (None, None)) for r in range(1, self.comm.size))
        rates = [self.rates_of(pair)] + [x for name, x in sent if name == pair.name]
        if len(rates) < self.comm.size and not last:
            return
        n, batch, cadence = self.next_pair
        balance = _balance(rates) if len(rates) == self.comm.size else (0.0, None)
        balance = balance if balance[1] is not None else self.balance
        self.plan, self.next_pair = (_split(n, self.comm.size, *balance), batch, cadence), None
        for r in range(1, self.comm.size):
            self.sending.append(self.comm.isend(self.plan, dest=r, tag=PLAN_TAG))

    def receive_plan(self):
        """This rank's copy of the plan rank 0 sent for the pair it begins (waits only if rank 0 has not sent it)."""
        return self.plan if self.comm.rank == 0 else self.comm.recv(source=0, tag=PLAN_TAG)

    def write_ready(self, block):
        """Rank 0: write the queued batches in order, each once every rank's pieces of it are here
        (with ``block``, waiting for them)."""
        comm = self.comm
        while self.writing and (block or all(comm.iprobe(source=r, tag=OUTPUT_TAG) for r in range(1, comm.size))):
            b, mine = self.writing.pop(0)
            w0 = time.perf_counter()
            msgs = [comm.recv(source=r, tag=OUTPUT_TAG) for r in range(1, comm.size)]
            wait = time.perf_counter() - w0
            self.rates.update((r, m[1]) for r, m in zip(range(1, comm.size), msgs))
            b.pair.clock["wait_recv"] += wait
            self.charge(b.pair.clock, "gather", wait)
            self.write(b, [mine] + [m[0] for m in msgs])
            if b.last:
                self.finish_pair(b.pair, [m[2] for m in msgs])

    def write(self, b, batches):
        """Rank 0: the batch's rows from every rank's (errors, values, piece) at each output, written
        together and flushed; the breakdown times when they changed, the state at a checkpoint."""
        scene, pair, t0 = self.scene, b.pair, time.perf_counter()
        rows = []
        for i, x in enumerate(b.held):
            parts = [r[i] for r in batches]
            rows.append(pair.diagnostics.combine(x.step * scene.h, [p[0] for p in parts],
                                                 {k: v for p in parts for k, v in p[1].items()}))
            if scene.store_points:
                q = np.concatenate([p[2]["q"] for p in parts])
                for spec, sl in scene.sample_sets:
                    rows[-1][f"points/{spec.name}"] = q[sl].reshape(spec.grid + (q.shape[1],))
        last = b.held[-1]
        full = _concat([r[-1][2] for r in batches])
        bt = full["breakdown_time"]
        changed = pair.breakdown_written is None or not np.array_equal(bt, pair.breakdown_written)
        t1 = time.perf_counter()
        output.wall_clock(pair.g, pair.wall())
        output.write_rows(self.f, pair.g, last.step, rows, bt if changed else None, full if last.checkpoint else None)
        pair.breakdown_written = bt
        if self.started is not None:
            self.started()
            self.started = None
        self.charge(pair.clock, "invariants", t1 - t0)
        self.charge(pair.clock, "hdf5", time.perf_counter() - t1)
        if self.after_output is not None:
            for x in b.held:
                self.after_output(pair.name, x.step)

    def finish_pair(self, pair, clocks):
        """Rank 0, once a pair's last rows are written: its status, its clocks (every rank's, for the
        cost model, scripts/scaling.py) and the balance of the pairs to come."""
        clock = pair.clock
        clocks = [dict(clock, points=pair.block[1] - pair.block[0])] + clocks
        clock["per_rank"] = clocks
        self.timings[pair.name] = clock
        output.wall_clock(pair.g, pair.wall())
        output.close_pair(pair.g, self.scene.n_outputs, self.threshold)
        self.f.flush()
        self.balance = _balance([(c["advance"], c["points"], c["invariants"] + c["hdf5"]) for c in clocks])

    def drain(self):
        """At the run's end: every queued task run, every batch written, every message delivered."""
        self.work(block=True)
        if self.comm.rank == 0:
            self.write_ready(block=True)
        while self.sending:
            self.sending.pop().wait()


def finalize(path, scene):
    """Each pair's status and wall_time attributes, written, and the summaries."""
    return [PairSummary(name, status, broke, errs, wall, unresolved_from=unresolved, breakdown=breakdown,
                        laws={k: v.law for k, v in laws.items()}, refined=refined)
            for name, status, broke, errs, wall, unresolved, breakdown, laws, refined in
            output.finish(path, [output.pair_name(t, p) for t, p in scene.pairs], scene.n_outputs)]
