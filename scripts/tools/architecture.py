"""docs/architecture.md: the package's import graph and, for each label of the paper cited in a
docstring, the functions that implement it (both read from the source with ``ast``).

    python scripts/tools/architecture.py [--paper ../shared/seeds/000_30d821025a250898.txt]
    python scripts/tools/architecture.py --report [--add-import A B ...]   # the checks as JSON, nothing written

With ``--paper`` every cited label is checked against the paper's ``\\label{...}`` (an unknown one is
listed and the exit code is 1).  ``--report`` prints the graph, the imports against the layers, the
circles and whether docs/architecture.md is current, as JSON (tests/test_architecture.py runs it);
``--add-import A B`` adds an import of B to A first, to see a check fire.
"""
import argparse
import ast
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("integrators", "invariants")
LABEL = re.compile(r"\b((?:eq|sec|app|tab|fig):[A-Za-z_0-9]+)")


LAYERS = (("integrators.cli", "cli"), ("integrators.service.scenes", "scene code"), ("integrators.service", "service"), ("integrators.audit", "audit"), ("integrators", "core"),
          ("invariants", "invariants"))
ALLOWED = {"core": {"core"}, "invariants": {"core", "invariants"},   # (the compiled point functions)
           "service": {"core", "invariants", "service"},
           "audit": {"core", "invariants", "service", "audit"},
           "cli": {"core", "invariants", "service", "audit", "cli"},     # who may import whom
           # the built-in scenes' own code, loaded as a scene loads a user's file.py (never imported)
           "scene code": {"core", "invariants", "service"}}


def layer(module):
    return next(tag for prefix, tag in LAYERS if module == prefix or module.startswith(prefix + "."))


def modules():
    """(dotted name, path, is a package) of every module of the two packages, subpackages included."""
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            yield ".".join(parts[:-1] if is_pkg else parts), path, is_pkg


def imports(name, tree, known, is_pkg=False):
    """Modules of the two packages that module ``name`` imports (``known``: every module's name)."""
    here = name if is_pkg else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:                                   # from .x import y / from ..x import y
                pkg = here.rsplit(".", node.level - 1)[0] if node.level > 1 else here
                base = node.module or ""
                targets = [f"{pkg}.{base}"] if base else [f"{pkg}.{a.name}" for a in node.names]
            else:
                targets = [node.module or ""]
            out.update(t for t in targets if t.split(".")[0] in PACKAGES)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] in PACKAGES)
    out = {t if t in known else t.rsplit(".", 1)[0] for t in out}     # from . import name → the package
    out.discard(name)
    return sorted(out)


def graph_of_source() -> dict:
    """{module: [modules of the two packages it imports]} for the whole source tree."""
    mods = list(modules())
    known = {name for name, _, _ in mods}
    return {name: imports(name, ast.parse(path.read_text()), known, is_pkg) for name, path, is_pkg in mods}


def violations(graph) -> list:
    """'a imports b' for every import that goes against the layers (ALLOWED)."""
    return [f"{m} imports {d}" for m, deps in graph.items() for d in deps if layer(d) not in ALLOWED[layer(m)]]


def circles(graph) -> list:
    """The import circles: every set of two or more modules that reach one another through imports
    (Tarjan's strongly connected components), each as a sorted list."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def citations(name, tree):
    """{label: [qualified names whose docstring cites it]} of one module."""
    found = {}

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)):
                qual = f"{prefix}.{child.name}"
                for label in LABEL.findall(ast.get_docstring(child) or ""):
                    found.setdefault(label, []).append(qual)
                visit(child, qual)
    for label in LABEL.findall(ast.get_docstring(tree) or ""):
        found.setdefault(label, []).append(name)
    visit(tree, name)
    return found


DRIVER_PARTS = ("transport", "tasks", "refine", "writer", "ranks", "clocks", "diagnostics", "output", "checkpoints",
                "statuses", "resumable", "files", "reader", "stop")


def driver_parts(graph) -> list:
    """The batch-run driver's parts: each module's one job (its docstring's first line) and who
    imports it, read from the source; then the path of one batch through them."""
    lines = ["", "## The driver's parts, and who calls whom", "",
             "`integrators.service.driver` runs the pairs and joins these parts; each has one job:", "",
             "| part | its job | used by |", "|---|---|---|"]
    for part in DRIVER_PARTS:
        name = f"integrators.service.{part}"
        doc = ast.get_docstring(ast.parse((ROOT / "integrators" / "service" / f"{part}.py").read_text())) or ""
        users = sorted(m for m, deps in graph.items() if name in deps)
        lines.append(f"| `{part}` | {doc.splitlines()[0] if doc else ''} | "
                     f"{', '.join(f'`{u.rsplit(chr(46), 1)[-1]}`' for u in users) or '—'} |")
    lines += ["", "One batch of outputs on one rank (driver `_run_pair` → `_Stream`):", "",
              "1. `engine.march` advances the rank's block; at each output `_Stream.take` keeps the points' "
              "errors (`diagnostics`) and the rank's part of each set (`tasks.Tasks.parts`); at a checkpoint "
              "its points' state, copied for rank 0 or, with `output.checkpoints = \"per-rank\"`, written "
              "as its own slab file (`_Stream.write_slab` → `checkpoints.write_slab`).",
              "2. At the batch's end `_Stream.close_batch` sends the parts to the batch's task owners "
              "(`tasks.Tasks.assign`: each set to the rank given the least task work so far; `transport.Transport.send`) "
              "and goes on advancing.",
              "3. A task owner, once the parts are here (`transport.Transport.arrived`), computes the sets' "
              "values (`tasks.Tasks.run`; a refining set through `refine`) and sends them with its errors "
              "and pieces to rank 0.",
              "4. Rank 0 writes the batch's rows in order (`writer.Writer.write` → `output.write_rows`), the "
              "state or the links to the ranks' slabs (`checkpoints.link_checkpoint`), a pair's "
              "status and clocks at its end (`writer.Writer.finish_pair` → `statuses.close_pair`), and from "
              "about each pair's middle "
              "sends the next pair's split (`ranks.Planner`, from the rates every rank sent; `clocks.Spent` "
              "keeps them net of output work).",
              "5. `stop.StopRequest`, passed in, is checked between the engine's calls."]
    return lines


def render() -> tuple:
    """(the text of docs/architecture.md, the import graph, the cited labels) from the source."""
    graph, cited = {}, {}
    mods = list(modules())
    known = {name for name, _, _ in mods}
    for name, path, is_pkg in mods:
        tree = ast.parse(path.read_text())
        graph[name] = imports(name, tree, known, is_pkg)
        for label, where in citations(name, tree).items():
            cited.setdefault(label, []).extend(where)
    lines = ["# Architecture", "",
             "Generated by `python scripts/tools/architecture.py` from the source (`ast`): what imports what, and "
             "where each equation or section of the paper that a docstring cites is implemented.", "",
             "Four layers: the numerical **core** (`integrators`: tableaus, systems, projections, the compiled "
             "kernel and its engine, `integrate`), **invariants** (`invariants`), the **service** "
             "(`integrators.service`: scenes, ranks, driver, diagnostics, the run file — output, checkpoints, "
             "statuses, resumable, files, reader — plots, plugins) and the "
             "**audit** (`integrators.audit`), with the command line (`integrators.cli`) on top of "
             "both.  A layer imports only itself and the layers before it "
             "(core and invariants import neither the service nor the audit, the service not the audit), "
             "and no modules import one another in a circle; the script exits 1 when an "
             "import breaks that, and `tests/test_architecture.py` runs the same check.", "",
             "## Import graph (within the two packages)", "",
             "| module | layer | imports |", "|---|---|---|"]
    for name, deps in graph.items():
        lines.append(f"| `{name}` | {layer(name)} | {', '.join(f'`{d}`' for d in deps) or '—'} |")
    lines += driver_parts(graph)
    lines += ["", "## Paper labels and the code that implements them", "",
              "| label | cited in |", "|---|---|"]
    order = {"eq": 0, "tab": 1, "sec": 2, "app": 3, "fig": 4}
    for label in sorted(cited, key=lambda x: (order[x.split(":")[0]], x)):
        where = sorted(set(cited[label]))
        lines.append(f"| `{label}` | {', '.join(f'`{w}`' for w in where)} |")
    return "\n".join(lines) + "\n", graph, cited


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paper", help="the paper's LaTeX, to check the cited labels")
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 if docs/architecture.md is not "
                                                         "what the source gives")
    ap.add_argument("--report", action="store_true", help="print the checks as JSON; write nothing")
    ap.add_argument("--add-import", nargs=2, action="append", default=[], metavar=("A", "B"),
                    help="with --report: module A imports B besides what the source says")
    args = ap.parse_args()
    text, graph, cited = render()
    target = ROOT / "docs" / "architecture.md"
    if args.report:
        current = target.read_text() == text
        for a, b in args.add_import:
            graph[a] = graph.get(a, []) + [b]
        print(json.dumps({"graph": graph, "violations": violations(graph), "circles": circles(graph),
                          "page_is_current": current}))
        return 0
    if args.check:
        if target.read_text() != text:
            print("docs/architecture.md is out of date: run python scripts/tools/architecture.py")
            return 1
    else:
        target.write_text(text)
        print(f"wrote docs/architecture.md: {len(graph)} modules, {len(cited)} labels")
    bad = violations(graph)
    if bad:
        print("imports across layers the wrong way:", "; ".join(bad))
        return 1
    loops = circles(graph)
    if loops:
        print("import circles:", "; ".join(" ↔ ".join(c) for c in loops))
        return 1
    if args.paper:
        known = set(re.findall(r"\\label\{([^}]*)\}", Path(args.paper).read_text()))
        unknown = sorted(set(cited) - known)
        if unknown:
            print("labels cited in the code but not in the paper:", ", ".join(unknown))
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
