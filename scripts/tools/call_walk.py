"""The walk of a `poincare run` argument through the package: which files the calls that carry it
visit, in order, and how often the walk returns to a file it had left (issue 42's measure).

    python scripts/tools/call_walk.py [scene]          # default: the built-in lotka_volterra scene

The run is made in this process with ``--steps 40`` into a temporary file, under ``sys.setprofile``.
A call is on the walk when one of its arguments is the parsed command line (an argparse Namespace)
or a Scene (the object the command line becomes), not counting the scene's own methods; the first
call of each function is recorded (not its repeats, once a pair), and consecutive calls in one file
are one *stay*. A *return* is a stay in a file the walk had already left; the script also counts the
returns to a file none of whose calls is under way (a composition calling its next step is not one). Works on
checkouts that have the command line in ``integrators/cli.py`` or ``integrators/service/cli.py``.
"""
import argparse
import sys
import tempfile
from pathlib import Path

import integrators

ROOT = Path(integrators.__file__).resolve().parents[1]


def walk(scene):
    if (ROOT / "integrators" / "cli.py").exists():
        from integrators.cli import main
    else:                                               # before issue 42
        from integrators.service.cli import main
    from integrators.service.scene import Scene
    calls, seen, stack = [], set(), []          # stack: (frame, file) of the carrying calls under way

    def carries(frame):
        code = frame.f_code
        names = code.co_varnames[:code.co_argcount + code.co_kwonlyargcount]
        if names and names[0] == "self" and isinstance(frame.f_locals.get("self"), Scene):
            return False                                # the scene reading its own fields
        return any(isinstance(frame.f_locals.get(n), (argparse.Namespace, Scene)) for n in names)

    def profile(frame, event, arg):
        if event == "call":
            path = Path(frame.f_code.co_filename)
            if ROOT in path.parents and "integrators" in path.parts and carries(frame):
                call = (str(path.relative_to(ROOT)), frame.f_code.co_name)
                if call not in seen:                    # a function's first call (not once a pair)
                    seen.add(call)
                    calls.append((*call, {f for _, f in stack}))
                stack.append((frame, call[0]))
        elif event == "return" and stack and stack[-1][0] is frame:
            stack.pop()

    with tempfile.TemporaryDirectory() as tmp:
        sys.setprofile(profile)
        try:
            code = main(["run", scene, "-o", str(Path(tmp) / "walk.h5"), "--steps", "40", "-q"])
        finally:
            sys.setprofile(None)
    return code, calls


def stays(calls):
    """[(file, [functions], files of the callers under way)]: consecutive calls in one file merged."""
    out = []
    for path, name, callers in calls:
        if out and out[-1][0] == path:
            out[-1][1].append(name)
        else:
            out.append((path, [name], callers))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="lotka_volterra")
    ap.add_argument("--list", action="store_true", help="print every stay and the functions in it")
    args = ap.parse_args()
    code, calls = walk(args.scene)
    walk_ = stays(calls)
    left, returns, back = set(), 0, 0
    for i, (path, _, callers) in enumerate(walk_):
        if path in left:
            returns += 1
            back += path not in callers                 # not a call back into a caller under way
        if i:
            left.add(walk_[i - 1][0])
    if args.list:
        for path, names, _ in walk_:
            print(f"{path:45s} {', '.join(dict.fromkeys(names))}")
    files = {p for p, *_ in walk_}
    print(f"exit {code}: {len(calls)} functions carry the argument; {len(walk_)} stays in {len(files)} files, "
          f"{returns} returns to a file it had left, {back} of them to a file that is not a caller under way")


if __name__ == "__main__":
    main()
