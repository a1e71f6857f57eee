"""The layers of docs/architecture.md hold: the numerical core and the invariants import neither the
service nor the audit, and importing the core loads no service module."""
import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _architecture():
    spec = importlib.util.spec_from_file_location("architecture", ROOT / "scripts" / "architecture.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_no_import_goes_against_the_layers():
    arch = _architecture()
    graph = arch.graph_of_source()
    assert {"integrators.service.driver", "integrators.audit.defect", "integrators.kernel"} <= set(graph)
    assert arch.violations(graph) == []
    # the check itself fires: a core module importing the service is reported
    bad = dict(graph, **{"integrators.engine": graph["integrators.engine"] + ["integrators.service.output"]})
    assert arch.violations(bad) == ["integrators.engine imports integrators.service.output"]


def test_importing_the_core_loads_neither_service_nor_audit():
    code = ("import sys, integrators, invariants; "
            "print(sorted(m for m in sys.modules if m.startswith(('integrators.service', 'integrators.audit', "
            "'h5py', 'mpi4py', 'matplotlib', 'chebpy'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"      # (importing chebpy loads matplotlib.pyplot: 0.43 s of every rank's start)


# the import names of the third-party packages the code imports, and the distributions that provide them
DISTRIBUTION = {"chebpy": "chebfun", "pyfftw": "pyfftw", "mpi4py": "mpi4py", "h5py": "h5py", "numpy": "numpy",
                "scipy": "scipy", "sympy": "sympy", "mpmath": "mpmath", "numba": "numba", "llvmlite": "llvmlite",
                "matplotlib": "matplotlib", "xarray": "xarray", "tqdm": "tqdm", "ipywidgets": "ipywidgets"}


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
