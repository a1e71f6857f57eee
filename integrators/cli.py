"""The `poincare` command line: run | audit | scenes | plot | list.

    poincare run [SCENE] [-o OUT] [--resume] [--force]     (mpiexec -n K poincare run … to distribute)
    poincare audit CANDIDATE [--projection P …] [--scene SCENE] [--reference TAB-PROJ …] [--json F] [--plots DIR]
    poincare audit --map MAP … [--point P] [--h H] [--steps N] [--period P …] [--loop-points N] [--json F] [--plots DIR]
    poincare scenes [--keys]
    poincare plot OUT.h5 [-o DIR]
    poincare list tableaus|systems
    poincare --version

Exit status (README, "Statuses and exit codes"):

    0    done, every pair `ok`
    1    done, but some pair is `under-resolved`, `partial` or `failed` (the summary says which)
    2    bad input (scene, options, files): one line on stderr naming the problem
    3    the output could not be written (disk full, no permission): one line; what was flushed stays readable
    130  interrupted by SIGINT (Ctrl-C), 143 by SIGTERM: one line saying how to resume
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import sys
import threading
import warnings
import time

import numpy as np

from .service.stop import GRACE, StopRequest, in_critical, in_user_code

EXIT_OK, EXIT_NOT_OK, EXIT_INPUT, EXIT_OUTPUT = 0, 1, 2, 3


class Terminated(BaseException):
    """SIGTERM (what batch schedulers send), raised in the main thread like KeyboardInterrupt."""


STOP = StopRequest()      # what the signal handlers set and cmd_run passes to the run


def _on_signal(signum, frame):
    """Leave the exception with the driver, which raises it before its next step.  Raising here
    instead would land wherever Python happens to be, including inside object destructors and
    weakref callbacks (h5py's), where the exception is swallowed with a printed traceback; but
    inside the user's code (a step map, a shape: stop.guarded), which may never return, it is
    raised at once."""
    exc = Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()
    exc.from_signal = True               # (stop.guarded tells it from a KeyboardInterrupt the code raised)
    if in_user_code():
        raise exc
    STOP.set(exc)


_STOPPED = [threading.Lock()]    # held by whoever reports this run's stop: the main thread or the watchdog
_HINT = []                       # the resume command, once the run knows its output


def _interrupted_message(signum):
    sig = "SIGTERM" if signum == signal.SIGTERM else "SIGINT"
    if not _HINT:
        return f"interrupted by {sig} before the run began; no file was written"
    return f"interrupted by {sig}; the output file is readable up to its last output; continue with: {_HINT[0]}"


def _watchdog(sock, rank, stopped):
    """Rank 0's guard against a run that cannot act on a signal (a rank stuck in user code that
    keeps rank 0 waiting in an MPI receive, user code stuck in C): the C-level handler wakes this
    thread through ``signal.set_wakeup_fd``; if the run has not stopped stop.GRACE seconds later,
    and rank 0 is not writing the file (stop.critical), it says how to resume and ends every rank
    (MPI Abort) or this process.  The file keeps every output flushed before, as after SIGKILL."""
    while True:
        try:
            data = sock.recv(64)
        except OSError:
            return
        if not data:                     # the run is over (its end closed the other side)
            return
        signums = [b for b in data if b in (signal.SIGTERM, signal.SIGINT)]
        if not signums:
            continue
        time.sleep(GRACE)
        while in_critical():
            time.sleep(0.05)
        if not stopped.acquire(blocking=False):
            return                       # the run stopped by itself and is reporting it
        code = 143 if signums[0] == signal.SIGTERM else 130
        if rank == 0:
            try:
                print(f"poincare: {_interrupted_message(signums[0])} (the run did not stop within {GRACE:g} s: "
                      "user code that does not return?)", file=sys.stderr, flush=True)
            except Exception:
                pass
        _abort_other_ranks(code)
        os._exit(code)


def _start_watchdog(rank, stopped):
    """Let the C-level signal handler wake :func:`_watchdog` (main thread only); returns an undo."""
    import socket
    r, w = socket.socketpair()
    w.setblocking(False)
    try:
        old = signal.set_wakeup_fd(w.fileno(), warn_on_full_buffer=False)
    except ValueError:                   # not the main thread (a caller's own thread): no watchdog
        r.close()
        w.close()
        return lambda: None
    threading.Thread(target=_watchdog, args=(r, rank, stopped), daemon=True, name="poincare-watchdog").start()

    def undo():
        signal.set_wakeup_fd(old)
        w.close()
    return undo


def _rank() -> int:
    """This process's MPI rank from the launcher's environment (0 when not under mpiexec)."""
    for key in ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "MPI_LOCALRANKID"):
        if key in os.environ:
            try:
                return int(os.environ[key])
            except ValueError:
                pass
    return 0


def _abort_other_ranks(code):
    """Under mpiexec, stop every rank: the others may sit in a collective this rank will never join
    (a signal reaches Python only between bytecodes, not inside a blocking MPI call).  The file was
    closed by the driver before this point (or, from the watchdog, flushed at its last output)."""
    if "mpi4py.MPI" not in sys.modules:
        return
    from mpi4py import MPI
    if MPI.Is_initialized() and not MPI.Is_finalized() and MPI.COMM_WORLD.Get_size() > 1:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except Exception:
            pass
        time.sleep(0.5)        # let mpiexec forward this rank's last lines before Abort tears it down
        MPI.COMM_WORLD.Abort(code)


def _printable(text) -> str:
    """``text`` with control characters (ANSI escapes, newlines) shown escaped, not sent to the terminal."""
    text = str(text)
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


SHORT_SERIES = 200      # outputs below which bounded and random walk are not told apart (docs/growth.md)


def _print_summary(summaries, out, n_outputs=None):
    keys = sorted({k for s in summaries for k in s.max_errors})
    W = 24
    head = f"{'pair':22s} {'status':14s} {'broke':>5s} " + " ".join(f"{k:>{W}s}" for k in keys) + f" {'wall [s]':>9s}"
    print(f"\nwrote {_printable(out)}\nmax relative invariant error |I(t) − I(0)|/|I(0)| over the outputs where the set was "
          "resolved, and how it grows (invariants.growth):")
    print(head)
    notes = []
    for s in summaries:
        cells = []
        for k in keys:
            v = s.max_errors.get(k, np.nan)
            if s.status == "failed":
                cell = "failed"
            elif not np.isfinite(v):
                cell = "—"
            else:
                law = s.laws.get(k, "")
                cell = f"{v:.3e}" + ("*" if k.split()[0] in s.unresolved_from else "") + (f" {law}" if law else "")
            cells.append(f"{cell:>{W}s}")
        print(f"{_printable(s.pair):22s} {s.status:14s} {s.breakdowns:5d} {' '.join(cells)} {s.wall_time:9.1f}")
        if s.status == "partial":
            first, total = s.breakdown
            notes.append(f"  {_printable(s.pair)}: {s.breakdowns} of {total} points broke down (the first at t = "
                         f"{first:g}); a set's errors are over its outputs before its first broken point "
                         "(— where there are none after t = 0)")
        clocks = s.timings.get("per_rank") or [s.timings]
        catch_up = sum(c.get("refine", 0.0) for c in clocks)
        if s.refined:
            sets = [f"the {'loop' if inv == 'I1' else 'surface'} from {base:,} to {most:,} points (from t = {t:g})"
                    for inv, (t, base, most) in s.refined.items()]
            notes.append(f"  {_printable(s.pair)}: refined {' and '.join(sets)}; the new points, started at t = 0, "
                         f"took {catch_up:.1f} s to advance")
        for inv, (t, bad, total, why) in s.unresolved_from.items():
            at_most = s.refined.get(inv, (None, None, None))[2]
            notes.append(f"  * {s.pair}: the {'loop' if inv == 'I1' else 'surface'} was under-resolved at {bad} of "
                         f"{total} outputs (first at t = {t:g}); its {inv} errors are over the others only "
                         + (f"(why: {_printable(why)})" if why else
                            f"(on {at_most:,} points, its refine_to: raise it or shorten the run)" if at_most else
                            "(refine the set, or let it refine itself with refine_to, or shorten the run)"))
    if n_outputs is not None and n_outputs < SHORT_SERIES and any(s.laws for s in summaries):
        notes.append(f"  growth laws from {n_outputs} outputs: round-off, linear and faster hold (94-100 % right on "
                     f"synthetic series this short), but bounded and random walk are told apart only from about "
                     f"{SHORT_SERIES} outputs (32-50 % right; 4-9 % of bounded series read as linear): "
                     "more outputs for those verdicts (docs/growth.md)")
    if notes:
        print("\n".join(notes))
    bad = [s for s in summaries if s.status != "ok"]
    if bad:
        counts = {}
        for s in bad:
            counts[s.status] = counts.get(s.status, 0) + 1
        print("not ok: " + ", ".join(f"{v} {k}" for k, v in counts.items()) + f" of {len(summaries)} pairs "
              "(exit status 1)")
    return EXIT_NOT_OK if bad else EXIT_OK


def cmd_run(args) -> int:
    from . import __version__
    from .service.driver import run
    from .service.ranks import communicator
    from .service.scene import load_scene
    from .service.plugins import LOADED
    LOADED.clear()                  # the summary lists the code this scene loads
    comm = communicator()
    scene = load_scene(args.scene)
    if args.output is not None and not args.output.strip():
        raise ValueError("-o/--output is empty: give a file name (or leave -o out for the scene's output.path)")
    out = args.output or scene.output
    if args.steps is not None:
        if args.steps < 1:
            raise ValueError(f"--steps must be a positive integer, got {args.steps}")
        scene = scene.with_steps(args.steps)
    if args.threads is not None:
        from .engine import max_threads
        if not 1 <= args.threads <= max_threads():
            raise ValueError(f"--threads must be between 1 and {max_threads()} (the cores numba can use here), "
                             f"got {args.threads}")
    from .service.ranks import default_threads
    threads = args.threads or default_threads(comm)
    if comm.rank == 0:
        print(f"scene '{_printable(scene.name)}': {_printable(scene.system_name)}, {scene.n_points} points, {len(scene.pairs)} pairs, "
              f"h = {scene.h:g}, {scene.steps} steps, output every {scene.output_every}, "
              f"{comm.size} rank{'s' if comm.size > 1 else ''} × {threads} thread{'s' if threads > 1 else ''}",
              flush=True)
        if scene.checkpoints == "per-rank":
            from .service.checkpoints import state_dir
            print(f"checkpoints: every rank writes its points' state into '{_printable(state_dir(out))}' "
                  "(keep that folder beside the file to resume it)", flush=True)
        from .engine import Tolerances
        if scene.jacobian_refresh != Tolerances.refresh:
            print(f"Newton: a fresh Jacobian after an iteration that contracted by less than "
                  f"{scene.jacobian_refresh:g} (run.jacobian_refresh; default {Tolerances.refresh:g}): "
                  "results differ from the default's in their last bits", flush=True)
        from .engine import kernel_cached
        if not kernel_cached():
            print("compiling the step engine (once per machine: 1-4 minutes on 2 cores, before the first pair; "
                  "the pairs' wall times below do not include it) ...", flush=True)
            from .service.driver import compile_first
            try:                        # only a head start: whatever fails here, the preflight reports
                system = scene.system()
                compile_first(scene, system, scene.points(system).shape[0], comm.size)
            except Exception:
                pass
    note = None
    if comm.rank == 0 and len(scene.projections) > 1:      # the scene compares projections: can it?
        from .audit.discrimination import discrimination
        system = scene.system()
        note = discrimination(system, scene.points(system), scene.h)      # said once, with the summary
    args._resume_hint = (f"poincare run {args.scene or 'default'} -o {out} --resume"
                         + (f" --steps {args.steps}" if args.steps is not None else ""))
    _HINT[:] = [_printable(args._resume_hint)]
    summaries = run(scene, out, resume=args.resume, force=args.force, comm=comm,
                    progress=False if args.quiet else None, version=__version__, threads=threads,
                    stop=STOP)
    if comm.rank == 0:
        code = _print_summary(summaries, out, scene.n_outputs)
        zero = _absolute_invariants(out)
        if zero:
            print(f"note: {', '.join(zero)} {'is' if len(zero) == 1 else 'are'} zero at t = 0 within {'its' if len(zero) == 1 else 'their'} "
                  "error (a closed one-form?): the error shown is the absolute |I(t) − I(0)|, a relative one has no scale")
        absolute = _energy_absolute_points(out)
        if absolute:
            print(f"note: energy is the absolute error |H − H0| at the {absolute} point{'s' if absolute > 1 else ''} "
                  "where H0 = 0 (a relative error has no scale there), |H − H0|/|H0| elsewhere")
        if note:
            print(f"note: {note}")
        if scene.system_spec.get("equilibrium"):
            print(_equilibrium_note(scene))
        if scene.system_spec.get("boozer"):
            print(_boozer_note(scene))
        if scene.precision == "double-double":
            print("note: run in double-double (run.precision): the states, checkpoints and the energy, momentum and "
                  "constraint errors are double-double; the invariants are computed from the states rounded to "
                  "double, so their floor is double's quadrature round-off (docs/invariants.md)")
        _print_user_code()
        return code
    return EXIT_OK


def _equilibrium_note(scene) -> str:
    """What the summary says of a system read from an equilibrium file: the file, its digest, the
    conventions assumed and the check against the file's q (docs/equilibria.md)."""
    sy = scene.system()
    spec = scene.system_spec
    q = sy.defaults.get("q_check")
    qtext = (f"|q(ψ_N = 0.5)| {q[0]:.4g} from the field against {q[1]:.4g} in the file" if q
             else "the file has no q to check against")
    cocos = sy.defaults.get("cocos")
    how = "as given" if spec.get("cocos") is not None else "identified from the file"
    notes = "".join(f"\nnote: {_printable(n)}" for n in sy.defaults.get("notes", ()))
    return (f"note: the field is the quintic-spline interpolant of {_printable(spec['equilibrium'])} "
            f"(sha256 {spec['sha256'][:12]}…), read as COCOS {cocos} ({how}); {qtext}; points leaving ψ_N < 1 break "
            f"down (docs/equilibria.md){notes}")


def _boozer_note(scene) -> str:
    """What the summary says of a system read from a boozmn file: the file, its digest, the modes and
    grid kept, the model (docs/stellarators.md)."""
    sy = scene.system()
    spec = scene.system_spec
    notes = "".join(f"\nnote: {_printable(n)}" for n in sy.defaults.get("notes", ()))
    return (f"note: the field is read from {_printable(spec['boozer'])} (sha256 {spec['sha256'][:12]}…) in the axis "
            f"chart (x, y) = √(2|ψ|)(cos θ, σ sin θ), σ the sign of Φ; points leaving s < 1 break down (docs/stellarators.md){notes}")


def _absolute_invariants(path) -> list:
    """The invariants whose I(0) the file records as zero within its error: their error is absolute."""
    try:
        import h5py
        from .service.statuses import absolute_invariants
        with h5py.File(path, "r") as f:
            return sorted(absolute_invariants(f))
    except (OSError, ValueError):
        return []


def _energy_absolute_points(path) -> int:
    """How many points' energy error the file records as absolute (H0 = 0): its root attribute."""
    try:
        import h5py
        with h5py.File(path, "r") as f:
            return int(f.attrs.get("energy_absolute_points", 0))
    except (OSError, ValueError):
        return 0


def _print_user_code():
    """Say which of the user's code the scene ran (README: a scene that names code runs it)."""
    from .service.plugins import LOADED
    if LOADED:
        print("the scene ran this Python code of yours (like a script):")
        for (what, spec), where in LOADED.items():
            print(f"  {what} = {_printable(spec)}: {_printable(where)}")


def _map_audit(args):
    """``poincare audit --map``: canonical black-box maps by integrators.audit.audit_map."""
    import numpy as np
    from .audit import examples
    from .audit.maps import audit_map, check_arguments
    from .service.plugins import load_callable
    if args.candidate is not None:
        raise ValueError("give either a CANDIDATE (tableau or step(q, p, lam, h, system) map on a scene) or --map, "
                         "not both")
    for name in ("projection",):
        if getattr(args, name) is not None:
            raise ValueError(f"--{name} applies to tableaus, not to --map")
    shipped = [spec for spec in args.map if spec in examples.EXAMPLES]
    if shipped and args.theta is not None:
        raise ValueError(f"--theta takes noncanonical maps step(q, h) -> q of your own; '{shipped[0]}' is a "
                         "shipped canonical example")
    if args.poisson is not None and not any(sp.startswith("pic") for sp in shipped):
        raise ValueError("--poisson applies to the shipped PIC examples (pic-…, pic1-…, pic2-…)")
    if args.k is not None and not shipped:
        raise ValueError("--k sizes the shipped examples (" + ", ".join(_EXAMPLE_NAMES) + "), not a map of your own")
    ex = examples.defaults(shipped[0], args.k) if shipped else None
    theta = None if args.theta is None else load_callable(args.theta, "--theta", confined=False)
    if args.point is not None:
        point = _read_point(args.point, theta is not None)
    elif ex is None:
        raise ValueError("--map of your own needs --point: a .npz file with arrays x0 and v0 (with --theta: q0), "
                         "or file.py:function returning (x0, v0) (with --theta: q0)")
    h = (args.h[0] if len(args.h) == 1 else list(args.h)) if args.h is not None else (None if ex is None else ex["h"])
    if h is None:
        raise ValueError("--map of your own needs --h, the step size")
    if args.every_coordinate and args.plane is not None:
        raise ValueError("give --plane or --every-coordinate, not both")
    radius = args.radius if args.radius is not None else (0.1 if ex is None else ex["radius"])
    kw = dict(steps=args.steps if args.steps is not None else 100, loop_points=args.loop_points,
              radius=radius, surface=args.surface, defect_points=args.points,
              levels=args.levels if args.levels is not None else 3, probes=args.probes)
    if args.output_every is not None:
        kw["output_every"] = args.output_every
    # every size judged before an example or a set is built (an example's point alone is 16 bytes × k)
    n = 2 * max(examples.defaults(s, args.k)["k"] for s in shipped) if args.point is None else (np.size(point) if theta is not None else 2 * np.size(point[0]))
    for hk in (h if isinstance(h, list) else [h]):
        check_arguments(n, hk, noncanonical=theta is not None, names=MAP_OPTIONS, **kw)
    maps, info = {}, None
    for spec in args.map:
        if spec in examples.EXAMPLES:
            step, info_k = examples.example(spec, args.k, **({"poisson": args.poisson}
                                                              if args.poisson and spec.startswith("pic") else {}))
            info = info or info_k
        else:
            step = load_callable(spec, "step map", confined=False)
        maps[spec] = step
    if args.point is None:
        point = info["point"]
    period = args.period if args.period is not None else (None if info is None else [info["period"]])
    if period is not None and len(period) == 1:
        period = period[0]
    kw.update(plane="every" if args.every_coordinate else args.plane, period=period)
    say = None if args.quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))
    energy = None if args.energy is None else load_callable(args.energy, "--energy", confined=False)
    return audit_map(maps, point, h, progress=say, theta=theta, energy=energy, **kw)


MAP_OPTIONS = {"h": "--h", "steps": "--steps", "output_every": "--output-every", "loop_points": "--loop-points",
               "radius": "--radius", "surface": "--surface", "defect_points": "--points", "levels": "--levels",
               "probes": "--probes", "period": "--period", "k": "--k"}   # audit_map's arguments as the command names them


def _read_point(spec, noncanonical=False):
    """(x0, v0) from a .npz file (arrays x0, v0) or a file.py:function returning them; a
    noncanonical map's q0 (array q0, or the function's return value)."""
    import numpy as np
    from .service.plugins import is_spec, load_callable
    names = ("q0",) if noncanonical else ("x0", "v0")
    if spec.endswith(".npz"):
        try:
            with np.load(spec) as f:
                got = tuple(np.asarray(f[n], dtype=float) for n in names)
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"--point '{spec}': cannot read array{'s' if len(names) > 1 else ''} "
                             f"{' and '.join(names)} ({type(exc).__name__}: {exc})") from None
        return got[0] if noncanonical else got
    if is_spec(spec):
        got = load_callable(spec, "--point", confined=False)()
        if not noncanonical and (not isinstance(got, (tuple, list)) or len(got) != 2):
            raise ValueError(f"--point '{spec}' must return (x0, v0)")
        return got
    raise ValueError(f"--point must be a .npz file with arrays x0 and v0, or file.py:function, got '{spec}'")


def cmd_audit(args) -> int:
    import json
    from . import audit
    from .service.scene import load_scene
    if args.map:
        _check_writable(args.json, "--json", file=True)
        _check_writable(args.plots, "--plots", file=False)
        return _audit_outputs(_map_audit(args), args)
    if args.candidate is None:
        raise ValueError("give a CANDIDATE (a tableau, or a step(q, p, lam, h, system) map with --scene), or "
                         "--map for a canonical step(x, v, h) map")
    if args.levels is None:
        args.levels = 5
    scene = load_scene(args.scene)
    if args.steps is not None:
        if args.steps < 1:
            raise ValueError(f"--steps must be a positive integer, got {args.steps}")
        scene = dataclasses.replace(scene, steps=args.steps)
    if args.points < 1:
        raise ValueError(f"--points must be a positive integer, got {args.points}")
    if args.levels < 1:
        raise ValueError(f"--levels must be a positive integer, got {args.levels}")
    cands = audit.candidates_from(args.candidate, args.projection)
    refs = []
    for ref in ([] if args.reference == ["none"] else args.reference):
        tab, sep, proj = ref.rpartition("-")
        if not sep or ":" in tab:
            raise ValueError(f"reference '{ref}' must be TABLEAU-projection, e.g. GLRK2-symmetric")
        refs += audit.candidates_from(tab, [proj], what=f"reference '{ref}': tableau")
    _check_writable(args.json, "--json", file=True)      # before the audit, not after it
    _check_writable(args.plots, "--plots", file=False)
    say = None if args.quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))
    report = audit.audit(cands, scene, references=refs, defect_points=args.points, levels=args.levels, progress=say)
    return _audit_outputs(report, args)


def _audit_outputs(report, args) -> int:
    """The text report on stdout, and the JSON and plots asked for."""
    import json
    from . import audit
    print(audit.text_report(report))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(report, fh, indent=1)
        print(f"wrote {args.json}")
    if args.plots:
        for path in audit.plot_report(report, args.plots):
            print(f"wrote {path}")
    return 0


_EXAMPLE_NAMES = ("pendula-strang", "pendula-rk2", "pic-strang", "pic-rk2", "pic-heun", "pic1-strang", "pic1-rk2",
                  "pic1-heun", "pic2-strang", "pic2-rk2", "pic2-heun")   # audit.examples.EXAMPLES


def _check_writable(path, option, file):
    """ValueError naming ``option`` unless ``path`` (a file, or a directory for PNGs) can be written."""
    if not path:
        return
    from pathlib import Path
    p = Path(path)
    folder = p.parent if file else p
    if file and p.is_dir():
        raise ValueError(f"{option} '{path}' is a directory; give a file name")
    if not file and p.exists() and not p.is_dir():
        raise ValueError(f"{option} '{path}' is a file, not a directory")
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if file and not folder.is_dir():
        raise ValueError(f"{option}: directory '{folder}' does not exist")
    if not os.access(probe if str(probe) else ".", os.W_OK | os.X_OK):
        raise ValueError(f"{option}: cannot write in '{probe}' (permission denied)")


def cmd_scenes(args) -> int:
    from .service import scene as scene_module
    from .service.scene import builtin_scenes, load_scene
    if args.keys:
        import re
        text = scene_module.__doc__.strip()
        text = re.sub(r":(?:class|func|data|mod|meth):`~?([^`]+)`", r"\1", text).replace("``", "")
        print(text.replace("::\n", ":\n"))
        return EXIT_OK
    for name, path in builtin_scenes().items():
        s = load_scene(name)
        print(f"{name:24s} {s.system_name:26s} {s.n_points:6d} points  {len(s.pairs):2d} pairs  h = {s.h:<5g} "
              f"steps = {s.steps:<5d} {path}")
    print("(every scene key: poincare scenes --keys)")
    return EXIT_OK


def cmd_plot(args) -> int:
    from .service.plots import plot_file
    for path in plot_file(args.file, args.output):
        print(path)
    return 0


def cmd_list(args) -> int:
    import integrators
    if args.what == "tableaus":
        for name in integrators.TABLEAU_NAMES:
            print(integrators.tableau(name))
    else:
        for name in integrators.SYSTEM_NAMES:
            print(integrators.system(name))
    return 0


def build_parser():
    ap = argparse.ArgumentParser(prog="poincare",
                                 description="Poincaré integral invariant diagnostics of projected variational integrators.")
    from . import __version__
    ap.add_argument("--version", action="version", version=f"poincare {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scene (a built-in name or a TOML file; default: the 'default' scene)",
                         description="Run every (tableau, projection) pair of a scene and write one HDF5 file. "
                                     "Distribute with: mpiexec -n K poincare run SCENE")
    run.add_argument("scene", nargs="?", default=None, help="built-in scene name or path to a TOML scene")
    run.add_argument("-o", "--output", help="HDF5 output path (default: the scene's output.path)")
    run.add_argument("--resume", action="store_true", help="continue an interrupted run of the same scene")
    run.add_argument("--force", action="store_true", help="overwrite an existing output file")
    run.add_argument("--steps", type=int, default=None,
                     help="override the scene's run.steps (with --resume: extend a finished run)")
    run.add_argument("--threads", type=int, default=None,
                     help="threads over points per rank (default: the node's cores shared among its ranks; "
                          "the numbers are bitwise the same for any count)")
    run.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    run.set_defaults(func=cmd_run)
    au = sub.add_parser("audit", help="which symplectic forms does an integrator preserve?",
                        description="Invariant drift on a scene's loop and surface, and the one-step "
                                    "symplecticity defect with its order in h, for a tableau (built-in name or "
                                    "TOML file, with each projection it admits) or a batched step map "
                                    "module:function / file.py:function with signature "
                                    "step(q, p, lam, h, system) -> (q, p, lam). Thresholds: docs/audit.md.")
    au.add_argument("candidate", nargs="?", help="built-in tableau, tableau .toml file, or module:function")
    au.add_argument("--projection", nargs="+", default=None,
                    help="projections to audit a tableau with (default: every one it admits)")
    au.add_argument("--scene", default="point_vortices",
                    help="scene giving system, h, steps, loop and surface (default: point_vortices, on which "
                         "the defect and drift halves tell methods apart; the symmetric guiding centre hides them)")
    au.add_argument("--steps", type=int, default=None, help="override the scene's number of steps")
    au.add_argument("--reference", nargs="+", default=["GLRK2-symmetric", "GLRK2-standard"],
                    help="built-in pairs run side by side ('none' for no references)")
    au.add_argument("--points", type=int, default=4, help="sample points of the one-step defect")
    au.add_argument("--levels", type=int, default=None,
                    help="step sizes h, h/2, … of the defect study (default 5; 3 with --map)")
    mp = au.add_argument_group("canonical step maps in any dimension (docs/audit.md, 'Step maps in any dimension')")
    mp.add_argument("--map", nargs="+", metavar="MAP",
                    help="canonical maps step(x, v, h) -> (x, v) on (n, k) arrays: file.py:function, "
                         "module:function, or a shipped example (" + ", ".join(_EXAMPLE_NAMES) + ")")
    mp.add_argument("--point", help="the phase-space point (x0, v0) the sets are built around: a .npz file with "
                                    "arrays x0 and v0, or file.py:function returning them (examples: their own)")
    mp.add_argument("--k", type=int, default=None,
                    help="size of a shipped example: pendula (default 1024) or particles (default 10000)")
    mp.add_argument("--poisson", choices=("spectral", "fem"), default=None,
                    help="the PIC examples' Poisson solve: spectral (default) or fem, the finite-element "
                         "Laplacian of Barham & Burby's study")
    mp.add_argument("--h", type=float, nargs="+", default=None,
                    help="step size (examples: theirs); several: a sweep, one report over all of them")
    mp.add_argument("--period", type=float, nargs="+", default=None,
                    help="period of the positions: one number for all, or one per coordinate (0: not periodic)")
    mp.add_argument("--loop-points", type=int, default=1024, help="points of the loop (default 1024)")
    mp.add_argument("--radius", type=float, default=None,
                    help="radius of the loop in phase space (default 0.1; the examples' own: pendula 0.01)")
    mp.add_argument("--plane", type=int, nargs=2, default=None, metavar=("I", "J"),
                    help="phase-space coordinates (x_0 … x_{k-1}, v_0 … v_{k-1}) the loop turns in "
                         "(default: all x against all v, radius/√k in each)")
    mp.add_argument("--every-coordinate", action="store_true",
                    help="the loop's radius in every coordinate: x_i = x0_i + r cos 2πτ, v_i = v0_i + r sin 2πτ")
    mp.add_argument("--surface", type=int, nargs=2, default=None, metavar=("NS", "NT"),
                    help="also a surface of NS × NT Chebyshev points in the same plane (I₂)")
    mp.add_argument("--probes", type=int, default=8, help="probe pairs of the matrix-free defect (default 8)")
    mp.add_argument("--energy", metavar="FILE.py:FUNCTION", default=None,
                    help="a batched energy(x, v) -> (n,) (with --theta: energy(q)): the energy error in the report")
    mp.add_argument("--theta", metavar="FILE.py:FUNCTION", default=None,
                    help="a batched one-form theta(q) -> (n, d): the maps are then noncanonical step(q, h) -> q on "
                         "(n, d) arrays and --point gives q0 (a .npz array q0, or a function returning it)")
    mp.add_argument("--output-every", type=int, default=None, help="steps between invariant outputs (default steps/50)")
    au.add_argument("--json", help="write the full report as JSON")
    au.add_argument("--plots", help="directory for the PNG plots")
    au.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    au.set_defaults(func=cmd_audit)
    sc = sub.add_parser("scenes", help="list the built-in scenes (--keys: every scene key, documented)")
    sc.add_argument("--keys", action="store_true", help="print the reference of every scene key")
    sc.set_defaults(func=cmd_scenes)
    pl = sub.add_parser("plot", help="PNG plots of a run file")
    pl.add_argument("file", help="HDF5 file written by 'poincare run'")
    pl.add_argument("-o", "--output", default=None, help="directory for the PNGs (default: next to the file)")
    pl.set_defaults(func=cmd_plot)
    ls = sub.add_parser("list", help="list built-in tableaus or systems")
    ls.add_argument("what", choices=["tableaus", "systems"])
    ls.set_defaults(func=cmd_list)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    rank = _rank()
    from .service.files import OutputError

    def say(msg):
        # input errors are the same on every rank: print them once; say which rank otherwise
        if rank == 0:
            print(f"poincare: {_printable(msg)}", file=sys.stderr, flush=True)

    previous = {}
    if args.func is cmd_run:
        # Rank 0 stops at once: it owns the file, says how to resume and stops the other ranks
        # (MPI Abort).  The other ranks ignore SIGTERM and SIGINT (mpiexec forwards both to every
        # rank): left alone they would quit while rank 0 may be blocked in a collective waiting for
        # them, and rank 0 can only act on a signal once that collective returns.
        handler = _on_signal if rank == 0 else (lambda signum, frame: None)
        for signum in (signal.SIGTERM, signal.SIGINT):
            previous[signum] = signal.signal(signum, handler)
        _HINT.clear()
        _STOPPED[0] = threading.Lock()
        undo_watchdog = _start_watchdog(rank, _STOPPED[0]) if rank == 0 else (lambda: None)
    try:
        # no numpy warning reaches the terminal: an overflow or a NaN in a user's map, a tableau or a
        # set is reported where it matters (a breakdown, a failed step, an under-resolved set)
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return args.func(args)
    except OutputError as exc:
        print(f"poincare: error: {_printable(exc)}" + (f" (rank {rank})" if rank else ""), file=sys.stderr, flush=True)
        sys.stdout.flush()
        _abort_other_ranks(EXIT_OUTPUT)
        if argv is None:
            # the console script: HDF5 reports a failed write again from every object destructor at
            # shutdown (pages of tracebacks, then sometimes a crash); the file is flushed and closed,
            # so leave at once
            os._exit(EXIT_OUTPUT)
        return EXIT_OUTPUT
    except BrokenPipeError:             # the reader went away (poincare plot … | head): nothing to say
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return EXIT_OK
    except (ValueError, OSError) as exc:
        say(f"error: {exc}")
        return EXIT_INPUT
    except (KeyboardInterrupt, Terminated) as exc:
        signum, code = (signal.SIGTERM, 143) if isinstance(exc, Terminated) else (signal.SIGINT, 130)
        if not _STOPPED[0].acquire(blocking=False):  # the watchdog is ending the process
            time.sleep(3600)
        say(_interrupted_message(signum))
        _abort_other_ranks(code)
        return code
    finally:
        if previous:
            undo_watchdog()
            _STOPPED[0].acquire(blocking=False)       # a watchdog still waiting acts no more
        for signum, old_handler in previous.items():
            signal.signal(signum, old_handler)
        STOP.clear()


if __name__ == "__main__":
    sys.exit(main())
