"""The `poincare` command line: run | scenes | plot | list.

    poincare run [SCENE] [-o OUT] [--resume] [--force]     (mpiexec -n K poincare run … to distribute)
    poincare scenes
    poincare plot OUT.h5 [-o DIR]
    poincare list tableaus|systems

Bad input exits with status 2 and one line on stderr naming the problem.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def _print_summary(summaries, out):
    keys = sorted({k for s in summaries for k in s.max_errors})
    head = f"{'pair':22s} {'status':8s} {'broke':>5s} " + " ".join(f"{k:>17s}" for k in keys) + f" {'wall [s]':>9s}"
    print(f"\nwrote {out}\nmax relative invariant error |I(t) − I(0)|/|I(0)|:")
    print(head)
    for s in summaries:
        errs = " ".join(f"{s.max_errors.get(k, np.nan):17.3e}" for k in keys)
        print(f"{s.pair:22s} {s.status:8s} {s.breakdowns:5d} {errs} {s.wall_time:9.1f}")


def cmd_run(args) -> int:
    from . import __version__
    from .driver import communicator, run
    from .scene import load_scene
    comm = communicator()
    scene = load_scene(args.scene)
    out = args.output or scene.output
    if comm.rank == 0:
        npts = (scene.loop["points"] if scene.loop else 0) + (
            scene.surface["n_sigma"] * scene.surface["n_tau"] if scene.surface else 0)
        print(f"scene '{scene.name}': {scene.system_name}, {npts} points, {len(scene.pairs)} pairs, "
              f"h = {scene.h:g}, {scene.steps} steps, output every {scene.output_every}, "
              f"{comm.size} rank{'s' if comm.size > 1 else ''}", flush=True)
    summaries = run(scene, out, resume=args.resume, force=args.force, comm=comm,
                    progress=False if args.quiet else None, version=__version__)
    if comm.rank == 0:
        _print_summary(summaries, out)
    return 0


def cmd_scenes(args) -> int:
    from .scene import builtin_scenes, load_scene
    for name, path in builtin_scenes().items():
        s = load_scene(name)
        npts = (s.loop["points"] if s.loop else 0) + (s.surface["n_sigma"] * s.surface["n_tau"] if s.surface else 0)
        print(f"{name:24s} {s.system_name:26s} {npts:6d} points  {len(s.pairs):2d} pairs  h = {s.h:<5g} "
              f"steps = {s.steps:<5d} {path}")
    return 0


def cmd_plot(args) -> int:
    from .plots import plot_file
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
    sub = ap.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scene (a built-in name or a TOML file; default: the 'default' scene)",
                         description="Run every (tableau, projection) pair of a scene and write one HDF5 file. "
                                     "Distribute with: mpiexec -n K poincare run SCENE")
    run.add_argument("scene", nargs="?", default=None, help="built-in scene name or path to a TOML scene")
    run.add_argument("-o", "--output", help="HDF5 output path (default: the scene's output.path)")
    run.add_argument("--resume", action="store_true", help="continue an interrupted run of the same scene")
    run.add_argument("--force", action="store_true", help="overwrite an existing output file")
    run.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    run.set_defaults(func=cmd_run)
    sc = sub.add_parser("scenes", help="list the built-in scenes")
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
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        print(f"poincare: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("poincare: interrupted (the output file is readable up to its last output; use --resume)",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
