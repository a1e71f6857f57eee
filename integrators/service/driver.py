"""The batch-run driver: every (tableau, projection) pair of a scene, distributed over MPI ranks.

The sample points (loop first, then the surface row by row) are split into contiguous
blocks, one per rank; from the second pair on, the blocks are sized from each rank's measured
advance rate and rank 0's is smaller by the cost of its output work (see ``ranks.split``).  Each rank
advances its block with each pair.  At every output each rank keeps the per-point errors of its
points and its part of each sample set; once a batch of outputs (about two seconds of advancing)
it sends the sets' parts to the ranks that own their invariant tasks in that batch (a set's forms
on one rank, each batch's sets to the ranks given the least task work so far: ``tasks.Tasks.assign``)
and goes on, without
waiting for anyone (``_Stream``).  A task owner runs a batch's tasks once the parts have arrived,
and every rank sends its pieces to rank 0, which appends the rows to the HDF5 file in order (see
:mod:`integrators.service.output`); about every ``output.checkpoint_seconds`` and at a pair's end
the full integrator state comes with them, as a checkpoint (or, with ``output.checkpoints =
"per-rank"``, each rank writes its state as a file of its own and rank 0 links them: ``write_slab``).
Because a point's trajectory does
not depend on its batch, the file's numbers are bitwise the same for any number of ranks.
Without mpiexec (or without mpi4py) it runs as a single process.

This module runs the pairs and joins the parts, each with one job (docs/architecture.md, "The
driver's parts"): :mod:`.transport` (messages between ranks), :mod:`.tasks` (what an output
computes, and which rank), :mod:`.writer` (rank 0's file), :mod:`.ranks` (who advances which
points), :mod:`.clocks` (the phases' seconds) and :mod:`.stop` (a stop request, passed in).
"""
from __future__ import annotations

import dataclasses
import secrets
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from . import checkpoints, files, output, resumable, statuses
from ..engine import Engine, Hooks, MapEngine, State, Tolerances, march, set_threads
from .clocks import Spent, pair_clock
from .diagnostics import Diagnostics
from .ranks import Planner, communicator, default_threads, split
from .refine import Refiner
from .stop import StopRequest, critical  # noqa: F401  (run's stop argument; tests make one)
from .tasks import Batch, Output, Tasks
from .transport import PARTS, PIECES, Transport
from .writer import Piece, Pieces, Replacement, Writer, close_quietly


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


def _check_output(path, resume, force):
    """One-line reasons why ``path`` cannot be the output, or None."""
    if resume and force:
        return "--resume and --force contradict each other: --resume continues the file, --force replaces it"
    if not str(path).isprintable():
        return f"output {str(path)!r} holds control characters (a newline or a terminal escape); give a plain name"
    if path.is_symlink() and not path.exists():
        return (f"output '{path}' is a symbolic link to '{os.readlink(path)}', which does not exist; remove the link "
                "or give another -o")
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
    if resume:                           # the damage check plot and read_run apply: never rewrite damage
        from .reader import read_run
        try:
            read_run(path)
        except files.BusyFile as exc:
            return str(exc)
        except (ValueError, OSError) as exc:
            return f"cannot resume: {exc}; --force replaces it"
    if force and path.exists():          # never replace a file another run is still writing
        why = files.not_ours(path)
        if why:
            return (f"output '{path}'{' (a symbolic link to ' + repr(str(path.resolve())) + ')' if path.is_symlink() else ''}"
                    f" is not a run file of this tool ({why}): --force replaces only those; give another -o or "
                    "move it away")
        try:
            files.open_file(path).close()
        except files.BusyFile as exc:
            return str(exc)
        except (ValueError, OSError):    # damaged or not HDF5: --force is for that
            pass
    return None


def _nothing_left(path, scene) -> bool:
    """Whether every pair of ``scene`` is finished in the file ``path`` (a resume with nothing to do)."""
    from .output import FINISHED
    with files.open_file(path) as f:
        runs = f["runs"] if "runs" in f else {}
        return all(p.name in runs and str(runs[p.name].attrs.get("status", "pending")) in FINISHED
                   for p in scene.pairs)


def _trial_output(scene, system, q0):
    """The first output's row computed once on the scene's own values before any file is opened
    (README: a scene that fails, fails before the file): a one-line reason, or None.  Non-finite
    values are a run's business (breakdowns, NaN rows); an exception here is a scene the run could
    not record (an overflow in a form's h², a user's function that raises)."""
    try:
        with np.errstate(all="ignore"):
            Diagnostics(scene, system, q0).row(0.0, q0, system.theta(q0), np.zeros_like(q0),
                                               np.ones(q0.shape[0], dtype=bool))
    except Exception as exc:
        return f"scene '{scene.name}': its first output cannot be computed ({type(exc).__name__}: " \
            f"{str(exc).splitlines()[0] if str(exc) else ''}); nothing was written"
    return None


def _resume_plan(path, scene):
    """Check that ``path`` was written by ``scene`` (or by the same scene with fewer steps)."""
    from .scene import parse_scene, scene_differences
    text, steps = resumable.read_scene_text(path)
    try:
        old = parse_scene(text, origin=str(path))
    except ValueError as exc:
        raise files.DamagedFile(f"cannot resume '{path}': the scene stored in it does not read ({exc})") from None
    if steps is not None:
        old = dataclasses.replace(old, steps=steps)
    diff = scene_differences(old, scene)
    tableaus, equilibrium = resumable.read_input_digests(path)
    if equilibrium is not None and scene.system_spec.get("sha256") != equilibrium:
        raise ValueError(f"cannot resume '{path}': the scene's [system] equilibrium file "
                         f"'{scene.system_spec.get('equilibrium')}' is not the file the run was started with "
                         "(its sha256 differs)")
    for label, digest in tableaus.items():
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

    The steps, each its own function: check everything that can be checked before a file is
    touched (:func:`_preflight`), open the output and list the pairs to run (:func:`_open_output`),
    advance them (:func:`_advance_pairs`), close the file and summarise it (:func:`_finish`).
    """
    check = stop if stop is not None else (lambda: None)
    comm = comm or communicator()
    path = Path(path)
    set_threads(threads or default_threads(comm))
    system, q0, grown_from = _preflight(comm, scene, path, resume, force)
    opened = _open_output(comm, scene, path, system, q0, resume, grown_from, version)
    timings = _advance_pairs(comm, scene, system, q0, path, opened, resume, after_output, progress, check)
    return _finish(path, scene, opened, timings) if comm.rank == 0 else None


def _agree(comm, error):
    """Rank 0's one-line error (or None) on every rank, raised there as a ValueError."""
    error = comm.bcast(error if comm.rank == 0 else None, root=0)
    if error:
        raise ValueError(error)


def _preflight(comm, scene, path, resume, force):
    """What can fail before any file is touched, checked on rank 0 and agreed by every rank: the
    output (exists, --force, --resume and what it may continue), the engine's code for the system
    (compiled now), the first output's row.  Returns (system, the points q0, the run's step count
    before an extension or None)."""
    error, grown_from = None, None
    if comm.rank == 0:
        error = _check_output(path, resume, force)
        if error is None and resume:
            try:
                grown_from = _resume_plan(path, scene)
                resumable.check_resumable(path, scene)       # read-only: a refused resume changes no byte
            except ValueError as exc:
                error = str(exc)
    _agree(comm, error)
    system = scene.system()
    error = None
    from ..codegen import CacheError, point_functions
    try:                               # the engine's code for this system, compiled before any file is touched
        if not getattr(system, "black_box", False):
            point_functions(system)
    except CacheError as exc:
        error = str(exc)
    except Exception as exc:
        error = f"system {system.name}: the step engine cannot be compiled for it: {type(exc).__name__}: " \
            f"{str(exc).splitlines()[0] if str(exc) else ''}"
    _agree(comm, error)
    q0 = scene.points(system)
    _agree(comm, _trial_output(scene, system, q0) if comm.rank == 0 else None)
    _warm(comm, scene, system, q0)
    return system, q0, grown_from


def _warm(comm, scene, system, q0):
    """Compile (or load) every kernel specialisation this rank's points will take before the first
    pair, so that no pair's wall time holds a compilation: a scene whose pairs need 16 lanes and 8
    lanes (Engine.width) would otherwise compile the second width inside the first pair that needs it.
    On a machine that has compiled no kernel yet, rank 0 first compiles the ones the scene needs at
    the same time, one process each (engine.compile_kernels); every rank then loads them."""
    lo, hi = split(q0.shape[0], comm.size)[comm.rank]
    mine = q0[lo:hi] if hi > lo else q0[:1]
    engines = _kernel_engines(scene, system, mine.shape[0])
    if comm.rank == 0:
        compile_first(scene, system, q0.shape[0], comm.size)
    comm.bcast(None, root=0)            # the other ranks load what rank 0's children compiled
    for engine in engines.values():
        engine.warm(mine)


def _kernel_engines(scene, system, n):
    """{(precision, W): an engine of the scene} for the kernel specialisations n points take."""
    engines = {}
    for pair in scene.pairs:
        if not pair.step_map:
            engine = _engine_maker(scene, system, pair)[0]()
            engines.setdefault((engine.precision, engine.lanes_for(n, engine.precision == "double-double")), engine)
    return engines


def compile_first(scene, system, n, ranks=1):
    """On a machine that has compiled no kernel yet, compile the specialisations a run of the scene
    on ``ranks`` ranks will take at the same time, one process each (engine.compile_kernels); they
    then load from numba's cache.  Does nothing once any kernel is cached."""
    from ..engine import compile_kernels, kernel_cached
    if kernel_cached():
        return
    keys = set()
    for lo, hi in split(n, ranks):
        keys |= set(_kernel_engines(scene, system, max(hi - lo, 1)))
    if len(keys) > 1:
        compile_kernels([(system.d, W, precision) for precision, W in sorted(keys)])


@dataclasses.dataclass
class _Opened:
    """The output as :func:`_open_output` leaves it: the file (rank 0's; None elsewhere), the pairs'
    jobs in scene order (None: finished; else a :class:`resumable.Job`), the file being
    replaced (--force, an extension) and the token naming this run's checkpoint slabs."""
    f: object
    todo: list
    replacing: object
    token: str


def _open_output(comm, scene, path, system, q0, resume, grown_from, version) -> _Opened:
    """Rank 0 creates, reopens or copies the output (inside a critical section: a stop signal waits)
    and lists what each pair has left to do; every rank gets the list (without the saved states:
    each rank gets its own rows of one when its pair begins) and the slab token."""
    from invariants import UNDER_RESOLVED
    rank, n = comm.rank, q0.shape[0]
    f, todo, replacing, error = None, [], None, None
    token = secrets.token_hex(4)       # names this run's checkpoint slabs (rank 0's, sent with the pairs to run)
    if rank == 0:
        with critical():
            try:
                if scene.checkpoints == "per-rank":
                    folder = checkpoints.state_dir(path)
                    try:
                        folder.mkdir(exist_ok=True)
                    except OSError as exc:
                        raise files.OutputError(f"cannot make the checkpoint folder '{folder}' (output.checkpoints "
                                                 f"= \"per-rank\"): {files.plain_error(exc)}") from None
                if resume and grown_from is not None:
                    # an extension works on a copy, which replaces the file once its first new rows are
                    # written: a failure before that leaves the finished file byte for byte as it was
                    replacing = Replacement(path.resolve())
                    try:
                        shutil.copyfile(path, replacing.new)
                        shutil.copymode(path, replacing.new)
                    except OSError as exc:
                        replacing.abandon()
                        raise files.OutputError(f"cannot extend '{path}': its working copy cannot be written "
                                                 f"({files.plain_error(exc)}); the file is as it was") from None
                    f = resumable.reopen(replacing.new, scene)
                elif resume and _nothing_left(path, scene):
                    f = files.open_file(path, "r")     # every pair finished: read, never rewrite (byte for byte)
                elif resume:
                    f = resumable.reopen(path, scene)
                else:
                    target = path
                    if path.exists():
                        replacing = Replacement(path.resolve())      # (through a symlink: its target)
                        target = replacing.new
                    f = output.create(target, scene, version, n,
                                      State.schema(n, system.d, scene.max_stages, scene.precision), UNDER_RESOLVED)
                if f.mode == "r":
                    todo = [None] * len(scene.pairs)
                else:
                    if "energy" in scene.diagnostics:       # where a relative energy error has no scale
                        from .diagnostics import _scalars
                        output.note_energy_scale(f, int(np.count_nonzero(_scalars(system, q0)[0] == 0)), n)
                    from .diagnostics import zero_invariants         # where a relative invariant error has none
                    output.note_absolute_invariants(f, zero_invariants(scene, system, q0))
                    for pair in scene.pairs:
                        todo.append(resumable.restart_pair(f, pair.name, scene.output_every,
                                                        finished_too=grown_from is not None))
                    f.flush()
                    if replacing is None:          # slabs no slot links (a stopped run's, a deleted file's)
                        checkpoints.prune_slabs(f, path, token)
            except (OSError, ValueError) as exc:
                error = exc if isinstance(exc, (ValueError, files.OutputError)) else \
                    files.OutputError(f"cannot write output '{path}': {files.plain_error(exc)}")
                todo = []
                if f is not None:
                    close_quietly(f)
    # the pairs to run go to every rank without their saved states (a state is every point's:
    # 314 bytes a point and pair); each rank gets its own rows of one when its pair begins
    sent = None if rank != 0 else \
        (error, [None if t is None else t._replace(state=None if t.state is None else True) for t in todo])
    (error, sent), token = comm.bcast((sent, token) if rank == 0 else None, root=0)
    if rank != 0:
        todo = sent
    if error is not None:
        if replacing is not None:
            replacing.abandon()
        raise error
    return _Opened(f, todo, replacing, token)


def _advance_pairs(comm, scene, system, q0, path, opened, resume, after_output, progress, check) -> dict:
    """Every pair with work left, in scene order, through :func:`_run_pair`; then the last batches.
    Returns the pairs' clocks ({pair: timings}, rank 0).  A failed write leaves the file readable
    up to its last output, or — for --force and an extension that had not yet replaced it — the
    old file as it was; the one-line error says which and what to run next."""
    from invariants import UNDER_RESOLVED
    rank, f, replacing = comm.rank, opened.f, opened.replacing
    retry = "the same command (--resume)" if resume else "--force"   # after a failure before the file was replaced
    timings = {}
    steps_total = sum(scene.steps - (t.start if t else scene.steps) for t in opened.todo) or 1
    bar = Progress(steps_total, enabled=(rank == 0 and progress is not False and (progress or _interactive())))
    try:
        stream = _Stream(comm, scene, f, after_output, timings, UNDER_RESOLVED, checkpoints.state_dir(path), opened.token)
        if replacing is not None:      # the old file goes once the new run has written its first rows
            def started():             # ... and with it the old run's checkpoint slabs
                replacing.commit()
                checkpoints.prune_slabs(f, path, opened.token)
            stream.writer.started = started
        jobs = [(pair, job) for pair, job in zip(scene.pairs, opened.todo) if job is not None]
        for i, (pair, job) in enumerate(jobs):
            check()
            _run_pair(comm, stream, scene, (system, q0, pair), job, (i == 0, i + 1 < len(jobs)), bar, check)
        w0 = time.perf_counter()
        stream.drain()
        ends = comm.gather(time.perf_counter() - w0, root=0)
        if rank == 0 and jobs:               # what each rank spent finishing the last batches, with the last pair
            last = timings[jobs[-1][0].name]
            for c, s in zip(last["per_rank"], ends):
                c["wait_end"] = s
        comm.Barrier()
    except (OSError, RuntimeError) as exc:      # h5py raises RuntimeError for some failed writes
        if f is not None:
            close_quietly(f)
        kept = replacing is not None and not replacing.done
        if replacing is not None:
            replacing.abandon()
        reason = getattr(exc, "reason", None) or files.plain_error(exc)
        if kept:                  # --force or an extension that never replaced the file: it is as it was
            raise files.OutputError(f"writing '{path}' failed: {reason}; '{path}' is as it was before this run: "
                                     f"free space, then run {retry} again") from None
        if isinstance(exc, files.OutputError):
            raise
        raise files.OutputError(f"writing '{path}' failed: {reason}; every output before "
                                 "the failure is in the file (free space, then --resume)") from None
    except BaseException:
        if f is not None:
            close_quietly(f)
        if replacing is not None:
            replacing.abandon()
        raise
    finally:
        bar.close()
    return timings


def _finish(path, scene, opened, timings) -> list:
    """Rank 0: close the file (replacing the old one if it has not been yet: a scene with no pair to
    run writes no rows), read the summaries back, attach the pairs' clocks."""
    with critical():
        write = opened.f.mode != "r"          # (read only: a resume with nothing left to do)
        opened.f.close()
        if opened.replacing is not None:
            opened.replacing.commit()
        summaries = finalize(path, scene, write)
    for s_ in summaries:
        s_.timings = timings.get(s_.pair, {})
    return summaries


def _run_pair(comm, stream, scene, inputs, job, place, bar, check):
    """Advance one pair on this rank from its start (or checkpoint) to scene.steps, handing each
    batch of outputs to ``stream``; the pair's tasks and rows may finish during the next pair.
    ``inputs``: (system, q0, the scene's pair); ``place``: (whether it is the run's first pair, whether
    another follows)."""
    run = _PairRun(comm, stream, scene, inputs, job, place, check)
    clock = run.pair.clock
    done = [run.start]

    def progress(step):
        if comm.rank == 0:
            bar.update(step - done[0], run.pair.name)
        done[0] = step

    clock["advance"] += march(run.engine, run.st, run.start, scene.steps, scene.output_every,
                              Hooks(run.on_output, progress, check, run.light))
    if not run.measured:
        run.first_interval()
    stream.take(run.pair, run.st, scene.steps, checkpoint=scene.steps == run.final, flush=True, last=True)
    run.pair.t_end = time.perf_counter()


class _PairRun:
    """One pair's advance on this rank: its engine and state, its :class:`_Pair` record, and what the
    time loop calls back at outputs (:meth:`on_output`, :meth:`light`)."""

    def __init__(self, comm, stream, scene, inputs, job, place, check):
        system, q0, pair_ = inputs
        first, self.has_next = place
        self.comm, self.stream, self.scene = comm, stream, scene
        rank, size, h = comm.rank, comm.size, scene.h
        self.n, self.start = q0.shape[0], job.start
        make_engine, s_tab = _engine_maker(scene, system, pair_)
        self.engine = make_engine()
        clock = pair_clock()
        w0 = time.perf_counter()
        if first:                              # the run's first pair: an even split, batches from its first interval
            plan = (comm.bcast(split(self.n, size) if rank == 0 else None, root=0), None, None)
        else:
            plan = stream.planner.receive(rank, stream.transport)
        clock["wait_plan"] = clock["gather"] = time.perf_counter() - w0
        blocks, self.batch, cadence = plan
        self.lo, self.hi = blocks[rank]
        self.st = _starting_state(comm, self.engine, q0, blocks, job.state, s_tab, h)
        self.t_start = t_start = time.perf_counter()
        self.pair = pair = _Pair(
            name=pair_.name, block=(self.lo, self.hi), diagnostics=Diagnostics(scene, system, q0[self.lo:self.hi]),
            clock=clock, batch=self.batch or 1, cadence=cadence or 1, t_start=t_start,
            spent0=stream.spent.snapshot(), start=self.start, middle=(self.start + scene.steps) // 2,
            refiners={spec.name: Refiner(spec, make_engine, scene.base, h, scene.output_every, check)
                      for spec, _ in scene.sample_sets if spec.levels})
        if rank == 0:
            pair.g = output.pair_group(stream.writer.f, pair.name)
            wall0 = output.wall_clock(pair.g)
            pair.wall = lambda: wall0 + (pair.t_end or time.perf_counter()) - t_start
        self.final = last_checkpoint_step(scene.steps, scene.output_every)
        if self.start < scene.steps:   # the output at the start (a resume's checkpoint row was dropped: same bits)
            stream.take(pair, self.st, self.start, checkpoint=False, flush=False)
        self.measured = []

    def first_interval(self):
        """Rank 0's first interval sets the batches and how often the state is written (at the
        pair's end when this run of the pair holds no whole interval)."""
        comm, scene, pair = self.comm, self.scene, self.pair
        w0 = time.perf_counter()
        per_output = w0 - self.t_start
        self.measured.append(per_output)
        cap = turns(scene.n_outputs * len(scene.pairs), comm.size)
        if self.batch is None:
            pair.batch, pair.cadence = comm.bcast(
                (min(_batch(per_output, self.hi - self.lo), cap), _cadence(per_output, scene.checkpoint_seconds))
                if comm.rank == 0 else None, root=0)
        if comm.rank == 0 and self.has_next:     # sent from about the pair's middle (ranks.Planner)
            self.stream.planner.next_pair = (self.n, min(_batch(per_output, self.hi - self.lo), cap),
                                             _cadence(per_output, scene.checkpoint_seconds))
        self.stream.spent.charge(pair.clock, "gather", time.perf_counter() - w0)

    def _checkpoint_at(self, step, j):
        return j % self.pair.cadence == 0 or step == self.final

    def on_output(self, step, out=None):
        """The output at ``step``: of the state, or of an engine.Output taken inside a longer call."""
        j = (step - self.start) // self.scene.output_every
        if j == 1:
            self.first_interval()
        if step < self.scene.steps:    # the last output is taken below, once the pair's advance is on its clock
            self.stream.take(self.pair, self.st if out is None else out, step,
                             checkpoint=self._checkpoint_at(step, j), flush=j % self.pair.batch == 0)

    def light(self, step):
        """Whether the output at ``step`` needs no more than q, p, Λ, live and breakdown times: not the
        first interval's end (rank 0 times it), not a checkpoint, not the pair's end."""
        j = (step - self.start) // self.scene.output_every
        return j > 1 and step < self.scene.steps and not self._checkpoint_at(step, j)


def _engine_maker(scene, system, pair):
    """(a function making a fresh engine of the pair, its stage count s): the compiled engine in the
    scene's precision, or a user's step map (run.step_maps) behind the same interface."""
    h = scene.h
    if pair.step_map:
        return (lambda: MapEngine(scene.step_map(pair.label), system, h, pair.label)), 1
    tolerances = Tolerances(refresh=scene.jacobian_refresh)
    return (lambda: Engine(system, scene.tableau(pair.label), pair.projection, h, precision=scene.precision,
                           tolerances=tolerances)), \
        scene.tableau(pair.label).s


def _starting_state(comm, engine, q0, blocks, saved, s_tab, h):
    """This rank's points' state where its pair begins: from q0, or its rows of the saved checkpoint
    (rank 0 holds it and scatters the rows)."""
    lo, hi = blocks[comm.rank]
    if saved is None:
        return engine.state(q0[lo:hi])
    rows = None
    if comm.rank == 0:
        saved = checkpoints.unpad_stages(saved, s_tab)
        rows = [{k: v[a:b] for k, v in saved.items()} for a, b in blocks]
    return State.from_checkpoint(comm.scatter(rows, root=0), h)


def last_checkpoint_step(steps, every) -> int:
    """The step of a finished pair's checkpoint: the last multiple of ``every`` (run.output_every).

    A state continues bitwise as the uninterrupted run would from any step (it notes where its
    Newton factors were taken, and they are rebuilt from that); when ``steps`` is not a multiple, the last output (at ``steps``) is a real output but the
    state kept is the one at the last multiple, from which a resume or a longer run continues (it
    recomputes that last partial interval, or goes on past it: on the cadence's grid)."""
    return steps - steps % every


BATCH_SECONDS = 2.0          # outputs are taken together in batches of about this much advancing
BATCH_BYTES = 1 << 28        # ... holding no more than this of a rank's points


def _batch(seconds_per_output, points) -> int:
    """Outputs a rank holds before it hands them on: about BATCH_SECONDS of advancing, within BATCH_BYTES."""
    by_time = int(BATCH_SECONDS / max(seconds_per_output, 1e-6))
    return max(1, min(by_time, BATCH_BYTES // (128 * max(points, 1))))


TURNS = 4                    # batches a run holds per rank, at least: how evenly the tasks can be shared


def turns(outputs, ranks) -> int:
    """The most outputs a batch may hold so that the run has about TURNS batches a rank: a batch's
    set goes to one rank (tasks.Tasks.assign), so with fewer batches than ranks some ranks would
    never take a set's tasks and one batch's owner would take a whole pair's (on many ranks a pair
    is a few seconds, and two seconds of advancing would be the whole pair)."""
    return max(1, outputs // (TURNS * ranks))


def _cadence(seconds_per_output, checkpoint_seconds) -> int:
    """Outputs between two checkpoints: as many as take about ``checkpoint_seconds`` (1 for 0)."""
    if checkpoint_seconds <= 0:
        return 1
    return max(1, int(checkpoint_seconds / max(seconds_per_output, 1e-6)))


LAG = 2                              # batches a task owner may hold before it waits for another rank's parts


@dataclasses.dataclass
class _Pair:
    """One pair as one rank runs it; on rank 0 also the pair's group of the file and its wall time."""

    name: str
    block: tuple                    # (lo, hi): the rows this rank advances
    diagnostics: Diagnostics
    clock: dict                     # this rank's seconds in each phase of the pair (clocks.pair_clock)
    batch: int                      # outputs a batch
    cadence: int                    # outputs between checkpoints
    t_start: float
    spent0: dict                    # the rank's seconds outside the advance (clocks.Spent) when the pair began
    start: int                      # the step the pair began at on this run
    middle: int                     # from this step on, rank 0 may send the next pair's plan
    held: list = dataclasses.field(default_factory=list)
    g: object = None
    wall: object = None
    t_end: float | None = None
    at: int = 0                     # the step of the latest output taken
    refiners: dict = dataclasses.field(default_factory=dict)  # {set name: Refiner}: its finer levels' new points
    breakdown_written: np.ndarray | None = None               # rank 0: the breakdown times in the file


class _Stream:
    """One rank's outputs over the whole run, handed on without making the ranks meet; the parts
    it joins: :class:`Transport` (messages), :class:`Tasks` (what an output computes, and who),
    :class:`Writer` (rank 0's file), :class:`Planner` (who advances which points), :class:`Spent`
    (clocks).

    The outputs of a pair are taken in batches (:func:`_batch`: about two seconds of advancing; a
    batch also ends at a checkpoint and at the pair's last output).  At a batch's end a rank sends
    its parts of the sample sets to the ranks that hold one of their invariant tasks (non-blocking)
    and goes on advancing.  A task owner runs a batch's tasks once every rank's parts of it have
    arrived, checked at each of its own batch ends; it waits only when it holds more than
    :data:`LAG` batches, or at the run's end.  Then the rank sends its errors, task values and
    pieces of the batch to rank 0, which writes the batches in order as they become complete.  So a
    rank that is slower for a batch or two costs the others nothing; only drift over more than
    :data:`LAG` batches, or about half a pair, makes a rank wait.  Rank 0 sends the next pair's
    split from about the middle of a pair, sized from the ranks' rates on it, which come with their
    pieces.
    """

    def __init__(self, comm, scene, f, after_output, timings, threshold, folder=None, token=""):
        self.comm, self.scene = comm, scene
        self.slabs = folder if scene.checkpoints == "per-rank" else None     # where each rank writes its state
        self.token = token
        self.transport = Transport(comm)
        self.tasks = Tasks(scene, comm.size, threshold)
        self.spent = Spent()
        self.planner = Planner(comm.size)
        self.writer = Writer(f, scene, self.spent, after_output, timings, threshold, self.slabs) \
            if comm.rank == 0 else None
        self.batches = 0                   # batches closed so far, any pair's: the same count on every rank
        self.pending, self.writing = [], []
        self.current = None                # the pair this rank advances

    def rates_of(self, pair):
        """(seconds advancing, points, seconds of output work), each a step, of this rank since it
        began ``pair`` (as ranks.balance takes them)."""
        return self.spent.rates(pair.spent0, pair.t_start, pair.at - pair.start, pair.block[1] - pair.block[0])

    # -- a rank's batches -------------------------------------------------------------------------
    def take(self, pair, st, step, checkpoint, flush, last=False):
        """Keep this output's errors and parts (copies: the state moves on); with ``flush`` (always
        with ``checkpoint``), hand the batch on."""
        t0 = time.perf_counter()
        pair.at = step
        parts = self.tasks.parts(pair.block, st)
        flush = flush or checkpoint
        if checkpoint and self.slabs is not None:     # per-rank: this rank's state, written by it now
            piece = self.write_slab(pair, st, step)
        elif checkpoint:         # a batch's last output: copied, the state moves on before rank 0 writes it
            piece = {k: np.array(v) for k, v in st.checkpoint().items()}
        else:                    # what rows need of the points (breakdown times only at a batch's end)
            piece = ({"breakdown_time": st.breakdown_time.copy()} if flush else {}) | \
                ({"q": st.nearest()[0].copy()} if self.scene.store_points else {})
        pair.held.append(Output(step, checkpoint, pair.diagnostics.point_errors(st.q, st.p, st.live), parts, piece))
        self.spent.charge(pair.clock, "invariants", time.perf_counter() - t0)
        if flush:
            self.close_batch(pair, step, last)

    def write_slab(self, pair, st, step):
        """output.checkpoints = "per-rank": this rank's points' state at ``step`` as its own file
        (checkpoints.write_slab), and what rank 0 needs to link it: {"slab": [(name, lo, hi)], ...}."""
        t0 = time.perf_counter()
        lo, hi = pair.block
        piece = {"breakdown_time": st.breakdown_time.copy(), "slab": []}
        if hi > lo:
            name = checkpoints.slab_name(pair.name, step, self.token, lo, hi)
            checkpoints.write_slab(self.slabs, name, st.checkpoint(), self.scene.max_stages)
            piece["slab"] = [(name, lo, hi)]
        if self.scene.store_points:
            piece["q"] = st.nearest()[0].copy()
        self.spent.charge(pair.clock, "hdf5", time.perf_counter() - t0)
        return piece

    def close_batch(self, pair, step, last):
        """Send the batch's parts to the task owners, queue its tasks, and run (rank 0: write) what is ready."""
        comm, t0 = self.comm, time.perf_counter()
        held, pair.held = pair.held, []
        j, self.batches = self.batches, self.batches + 1
        batch = Batch(pair, held, last, j, self.tasks.assign(len(held), self.tasks.pair_index(pair)))
        for o, sets in self.tasks.needs(batch.owners).items():
            if o != comm.rank:
                self.transport.send({k: self.tasks.stack(held, k) for k in sets}, o, PARTS)
        self.current = pair
        self.pending.append(batch)
        self.transport.settle()
        self.spent.charge(pair.clock, "gather", time.perf_counter() - t0)
        pair.clock["batches"] += 1
        self.work(block=False)
        if comm.rank == 0:
            self.write_ready(block=False)
            self.planner.maybe_send(pair.name, pair.middle, step, last, lambda: self.rates_of(pair), self.transport)

    def _ready(self):
        """Whether every other rank's parts of the oldest queued batch have arrived (a rank's parts
        come in its batches' order, and only for the batches whose tasks this rank owns)."""
        return self.transport.arrived(self.tasks.others(self.comm.rank, self.pending[0].owners), PARTS)

    def work(self, block):
        """Run the tasks of the queued batches in order: those whose parts are here; with ``block``,
        or while more than LAG are queued, waiting for the parts."""
        while self.pending and (block or len(self.pending) > LAG or self._ready()):
            self._run_tasks(self.pending.pop(0))

    def _run_tasks(self, b):
        rank, clock = self.comm.rank, b.pair.clock
        t0 = time.perf_counter()
        got = {r: self.transport.receive(r, PARTS) for r in self.tasks.others(rank, b.owners)}
        wait = time.perf_counter() - t0
        values = self.tasks.run(rank, b, got)      # got[r][k]: rank r's set k, stacked over the outputs
        mine = [Piece(x.errors, v, x.piece) for x, v in zip(b.held, values)]
        t1 = time.perf_counter()
        refine = sum(r.seconds for r in b.pair.refiners.values())
        clock["refine_point_steps"] = sum(r.point_steps for r in b.pair.refiners.values())
        spent, clock["refine"] = refine - clock["refine"], refine
        self.spent.charge(clock, "invariants", t1 - t0 - wait - spent)
        clock["wait_gather"] += wait
        self.spent.charge(clock, "gather", wait)
        if rank == 0:
            self.writing.append((b, mine))
            return
        if b.last:
            clock["points"] = b.pair.block[1] - b.pair.block[0]
        rates = (self.current.name, self.rates_of(self.current))
        self.transport.send(Pieces(mine, rates, dict(clock) if b.last else None), 0, PIECES)
        self.spent.charge(clock, "gather", time.perf_counter() - t1)

    # -- rank 0: the file ---------------------------------------------------------------------------
    def write_ready(self, block):
        """Rank 0: write the queued batches in order, each once every rank's pieces of it are here
        (with ``block``, waiting for them)."""
        others = range(1, self.comm.size)
        while self.writing and (block or self.transport.arrived(others, PIECES)):
            b, mine = self.writing.pop(0)
            w0 = time.perf_counter()
            msgs = [self.transport.receive(r, PIECES) for r in others]
            wait = time.perf_counter() - w0
            self.planner.rates.update((r, m.rates) for r, m in zip(others, msgs))
            b.pair.clock["wait_recv"] += wait
            self.spent.charge(b.pair.clock, "gather", wait)
            with critical():            # (the stop watchdog never ends the process mid-write)
                self.writer.write(b, [mine] + [m.rows for m in msgs])
                if b.last:
                    self.planner.after_pair(self.writer.finish_pair(b.pair, [m.clock for m in msgs]))

    def drain(self):
        """At the run's end: every queued task run, every batch written, every message delivered."""
        self.work(block=True)
        if self.comm.rank == 0:
            self.write_ready(block=True)
        self.transport.finish()


def finalize(path, scene, write=True):
    """Each pair's status and wall_time attributes, written (unless ``write`` is False), and the summaries."""
    return [PairSummary(name, status, broke, errs, wall, unresolved_from=unresolved, breakdown=breakdown,
                        laws={k: v.law for k, v in laws.items()}, refined=refined)
            for name, status, broke, errs, wall, unresolved, breakdown, laws, refined in
            statuses.finish(path, [p.name for p in scene.pairs], scene.n_outputs, write)]
