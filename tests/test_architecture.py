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
