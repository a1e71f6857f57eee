"""The layers of docs/architecture.md hold: the numerical core and the invariants import neither the
service nor the audit, and importing the core loads no service module."""
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _report(*added):
    """scripts/tools/architecture.py --report, run (tests import nothing from scripts/): its JSON, with
    the imports ``added`` (pairs A, B: A imports B) put into the graph before the checks."""
    cmd = [sys.executable, str(ROOT / "scripts" / "tools" / "architecture.py"), "--report"]
    for a, b in added:
        cmd += ["--add-import", a, b]
    return json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout)


def test_no_import_goes_against_the_layers():
    rep = _report()
    assert {"integrators.service.driver", "integrators.audit.defect", "integrators.kernel"} <= set(rep["graph"])
    assert rep["violations"] == []
    # the check itself fires: a core module importing the service is reported
    bad = _report(("integrators.engine", "integrators.service.output"))
    assert bad["violations"] == ["integrators.engine imports integrators.service.output"]


def test_no_modules_import_one_another_in_a_circle():
    """No import circle (engine ↔ systems was one: the generated code lives in integrators.codegen
    now, its printer too); and the check fires on one."""
    rep = _report()
    assert rep["circles"] == []
    assert "integrators.engine" not in rep["graph"]["integrators.systems"]
    looped = _report(("integrators.codegen", "integrators.systems"))
    assert looped["circles"] == [["integrators.codegen", "integrators.systems"]]


def test_importing_the_core_loads_neither_service_nor_audit():
    code = ("import sys, integrators, invariants; "
            "print(sorted(m for m in sys.modules if m.startswith(('integrators.service', 'integrators.audit', "
            "'h5py', 'mpi4py', 'matplotlib', 'chebpy'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"      # (importing chebpy loads matplotlib.pyplot: 0.43 s of every rank's start)


# the import names of the third-party packages the code imports, and the distributions that provide them
DISTRIBUTION = {"chebpy": "chebfun", "pyfftw": "pyfftw", "mpi4py": "mpi4py", "h5py": "h5py", "numpy": "numpy",
                "scipy": "scipy", "sympy": "sympy", "mpmath": "mpmath", "numba": "numba", "llvmlite": "llvmlite",
                "matplotlib": "matplotlib", "xarray": "xarray", "tqdm": "tqdm", "ipywidgets": "ipywidgets",
                "freeqdsk": "freeqdsk"}


def _top_imports(folder):
    import ast
    names = set()
    for path in (ROOT / folder).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names


def test_every_package_the_code_imports_is_a_runtime_dependency_and_test_tools_are_not():
    """pyproject.toml: what integrators/ and invariants/ import is declared (llvmlite was not), the
    test and docs tools are extras, numba is bounded, and the version is integrators.__version__."""
    import re
    import tomllib
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    runtime = {re.split(r"[\[<>=!~ ]", d, maxsplit=1)[0] for d in project["dependencies"]}
    third = (_top_imports("integrators") | _top_imports("invariants")) - set(sys.stdlib_module_names) \
        - {"integrators", "invariants"}
    assert third <= set(DISTRIBUTION), third - set(DISTRIBUTION)
    assert {DISTRIBUTION[n] for n in third} <= runtime, {DISTRIBUTION[n] for n in third} - runtime
    assert not runtime & {"pytest", "nbclient", "nbformat", "ipykernel", "mkdocs", "mkdocstrings"}
    assert {"pytest", "nbclient", "mkdocs"} <= {re.split(r"[\[<>= ]", d, maxsplit=1)[0]
                                                 for d in project["optional-dependencies"]["test"]}
    numba = next(d for d in project["dependencies"] if d.startswith("numba"))
    assert "<" in numba, numba
    assert project["dynamic"] == ["version"] and "version" not in project


def test_no_code_branches_on_a_projection_name():
    """The projections are the records of integrators/projections.py: no other module of the package
    compares a projection variable with a projection's name or keys a table by the names (the
    reference engine did, reading σ and the coupling off string tests)."""
    import ast
    from integrators.projections import PROJECTIONS
    names = set(PROJECTIONS)

    def strings(node):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return {node.value}
        if isinstance(node, (ast.Tuple, ast.Set, ast.List)):
            return set().union(*(strings(e) for e in node.elts)) if node.elts else set()
        return set()

    def is_projection(node):
        ident = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
        return "proj" in ident.lower()

    found = []
    for path in (ROOT / "integrators").rglob("*.py"):
        if path.name == "projections.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Compare):
                operands = [node.left, *node.comparators]
                if any(strings(o) & names for o in operands) and any(is_projection(o) for o in operands):
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
            elif isinstance(node, ast.Dict):
                keys = set().union(*(strings(k) for k in node.keys if k is not None)) if node.keys else set()
                if len(keys & names) >= 2:
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert found == [], found


def test_the_architecture_page_is_what_the_source_gives():
    """docs/architecture.md is generated (scripts/tools/architecture.py): a changed import that was not
    regenerated is caught here (engine's imports of systems and tableaus were missing from it)."""
    rep = _report()
    assert "integrators.kernel" in rep["graph"] and len(rep["graph"]) > 20
    assert "| `integrators.kernel` |" in (ROOT / "docs" / "architecture.md").read_text()
    assert rep["page_is_current"], "run python scripts/tools/architecture.py"


def test_tests_and_scripts_import_nothing_of_one_another():
    """tests/ imports nothing from scripts/ (a test that needs a count the scripts use finds it in the
    package: integrators.costmodel) and scripts/ nothing from tests/; a test runs a script as a
    command.  Checked by the import names each tree's files use against the modules of the other,
    and by any path either puts on sys.path or loads a file from."""
    import ast
    import re

    def stems(folder):
        return {p.stem for p in (ROOT / folder).rglob("*.py")}

    def offences(folder, other, other_word):
        own, theirs = stems(folder), stems(other) - stems(folder)
        found = []
        for path in (ROOT / folder).rglob("*.py"):
            text = path.read_text()
            for node in ast.walk(ast.parse(text)):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                    [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else []
                found += [f"{path.relative_to(ROOT)} imports {n}" for n in names
                          if n.split(".")[0] in theirs and n.split(".")[0] not in own]
            for ln in text.splitlines():
                if re.search(r"sys\.path|spec_from_file_location", ln) and re.search(rf"[\"']{other_word}[\"/']", ln):
                    found.append(f"{path.relative_to(ROOT)}: {ln.strip()}")
        return found
    assert offences("tests", "scripts", "scripts") == []
    assert offences("scripts", "tests", "tests") == []


def test_pages_and_docstrings_state_today():
    """docs/benchmarks.md states today's figures on at most 300 lines with no commit hash or issue
    number (how they came about is in docs/benchmarks-history.md), and no module or built-in scene of
    the two packages cites an issue number or a constant named after one: docstrings state contracts and reasons."""
    import re
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    assert len(page.splitlines()) <= 300
    assert re.findall(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b", page) == []
    assert re.findall(r"[Ii]ssue \d+", page) == []
    cited = [f"{p.relative_to(ROOT)}: {m}" for folder in ("integrators", "invariants")
             for p in [*(ROOT / folder).rglob("*.py"), *(ROOT / folder).rglob("*.toml")]
             for m in re.findall(r"[Ii]ssue[ _]\d+|ISSUE_\d+", p.read_text())]
    assert cited == []


def test_no_function_of_the_kernel_takes_more_than_ten_arguments():
    """What crosses into the kernel travels as named records (integrators.kernel.records: Pair, Span,
    Shape, Outputs, Step, Group), not as long positional lists: no function of integrators/kernel/,
    of the engine (integrators/engine.py: its time loop takes its callbacks as one Hooks record) or of
    the driver, and no method of their classes, takes more than 10 arguments (self not counted); and
    the kernel and the lanes (integrators/simd/) are one module per role, none over 800 lines, as is
    the scene reader."""
    import ast
    over = []
    files = sorted((ROOT / "integrators" / "kernel").glob("*.py"))
    for path in files + [ROOT / "integrators" / "engine.py", ROOT / "integrators" / "service" / "driver.py"]:
        tree = ast.parse(path.read_text())
        scopes = tree.body + [n for c in tree.body if isinstance(c, ast.ClassDef) for n in c.body]
        for fn in scopes:
            if isinstance(fn, ast.FunctionDef):
                a = fn.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)
                n -= bool(a.args) and a.args[0].arg in ("self", "cls")
                if n > 10:
                    over.append(f"{path.relative_to(ROOT)}: {fn.name} ({n})")
    assert len(files) >= 8 and over == []
    lanes = sorted((ROOT / "integrators" / "simd").glob("*.py"))             # the lanes likewise, and scenes
    sizes = {p.name: len(p.read_text().splitlines()) for p in files + lanes + [ROOT / "integrators" / "service" / "scene.py"]}
    assert len(lanes) >= 5 and max(sizes.values()) <= 800, sizes            # one module per role


def test_the_engine_imports_at_its_top():
    """integrators/engine.py imports what it uses once, at the top (the kernel costs nothing to import
    once numba is loaded, and the package loads numba on import): no function of it imports."""
    import ast
    tree = ast.parse((ROOT / "integrators" / "engine.py").read_text())
    inside = [f"{fn.name}: line {n.lineno}" for fn in ast.walk(tree) if isinstance(fn, ast.FunctionDef)
              for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))]
    assert inside == []


def test_no_driver_function_is_long():
    """The driver's functions fit on a page: none over 80 lines (a pair's run is a class, _PairRun,
    whose parts are named: its set-up, its first interval, what an output does)."""
    import ast
    tree = ast.parse((ROOT / "integrators" / "service" / "driver.py").read_text())
    long = [f"{fn.name} ({fn.end_lineno - fn.lineno + 1})" for fn in ast.walk(tree)
            if isinstance(fn, ast.FunctionDef) and fn.end_lineno - fn.lineno + 1 > 80]
    assert long == []


def test_every_package_folder_is_installed():
    """pyproject.toml lists the packages a (non-editable) install copies: every folder of the two
    packages that holds an __init__.py is among them (a new subpackage left out installs without it,
    and only a clean install, as CI's, would notice)."""
    import tomllib
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for top in ("integrators", "invariants")
             for p in (ROOT / top).rglob("__init__.py")}
    assert found <= listed, sorted(found - listed)
