"""The chart switch at the axis (integrators/audit/chart_switch.py; docs/stellarators.md, "The chart switch").

On the circular tokamak file, 64 trapped guiding centres whose orbits pass the magnetic axis closely,
2,000 steps of GLRK2-symmetric: in the axis chart every energy stays at round-off and none breaks
down (measured ≤ 1.4e-14); in the polar chart with SIMPLE's switch (r, θ) → (−r, θ + π) the orbits
that reach the axis switch or break down and the energy moves far above round-off (measured 4.8e-5).
The audit tells the two maps apart on a loop about the closest orbit: round-off drift and a
symplectic defect for the axis chart, a breakdown or a defect above the floor for the switch.
"""
from pathlib import Path

import numpy as np
import pytest

import integrators
from integrators.audit.chart_switch import axis_family, axis_step, polar_system, switch_step, to_polar
from integrators.audit.maps import audit_map

CIRCULAR = Path(integrators.__file__).parent / "service" / "scenes" / "boozmn_circular_tokamak.nc"


@pytest.mark.slow
def test_the_audit_tells_the_chart_switch_from_the_axis_chart():
    polar, axis = polar_system(CIRCULAR)
    h = axis.defaults["h"]
    qa = axis_family(axis)
    qp = to_polar(qa)
    assert np.max(np.abs(polar.H(qp) / axis.H(qa) - 1)) < 2e-6      # the same field, another chart (3.7e-7)
    ax, sw = axis_step(axis), switch_step(polar)
    Ea0, Ep0 = axis.H(qa), polar.H(qp)
    ea, ep = np.zeros(len(qa)), np.zeros(len(qa))
    for _ in range(2000):
        qa, qp = ax(qa, h), sw(qp, h)
        ea = np.fmax(ea, np.abs(axis.H(qa) / Ea0 - 1))
        ep = np.fmax(ep, np.abs(polar.H(qp) / Ep0 - 1))
    assert not np.isnan(qa).any() and ea.max() < 1e-13, ea.max()
    assert sw.switches + np.isnan(qp[:, 0]).sum() >= 1
    assert ep.max() > 1e-7, ep.max()
    r1 = np.sqrt(2 * axis.param_values["psi_edge"])
    z = axis_family(axis)[int(np.nanargmax(ep))]
    verdicts = {}
    for name, sy, step, z0, period in [("axis", axis, axis_step(axis), z, None),
                                       ("switch", polar, switch_step(polar), to_polar(z[None])[0], [0, 2 * np.pi, 0, 0])]:
        rep = audit_map(step, z0, h, steps=400, output_every=4, loop_points=256, radius=1e-3 * r1, plane=(0, 1),
                        theta=sy.theta, period=period, energy=sy.H, defect_points=2, levels=2, name=name)
        c = rep["candidates"][0]
        verdicts[name] = (c["drift"]["I1/noncanonical"]["verdict"], c["defect"]["noncanonical"]["verdict"])
    assert verdicts["axis"] == ("round-off", "symplectic"), verdicts
    assert verdicts["switch"][0] == "broke down" or verdicts["switch"][1] != "symplectic", verdicts


@pytest.mark.slow
def test_the_chart_switch_audit_runs_from_the_command_line(tmp_path):
    """scripts/examples/chart_switch_maps.py through ``poincare audit --map``, as its docstring gives
    the commands: the axis chart reads round-off and symplectic, the switching map broke down or
    not symplectic (the same verdicts as the Python audit above)."""
    import json
    import subprocess
    import sys
    root = Path(__file__).parents[1]
    m = "scripts/examples/chart_switch_maps.py"
    tail = ["--h", "2.7", "--steps", "400", "--output-every", "4", "--loop-points", "256", "--radius", "0.00465",
            "--plane", "0", "1", "--points", "2", "--levels", "2", "--quiet"]
    verdicts = {}
    for name, chart in (("axis", "axis"), ("switch", "polar")):
        out = tmp_path / f"{name}.json"
        cmd = [sys.executable, "-m", "integrators.cli", "audit", "--map", f"{m}:{name}_step", "--theta",
               f"{m}:{chart}_theta", "--point", f"{m}:{chart}_point", "--energy", f"{m}:{chart}_energy",
               *(["--period", "0", str(2 * np.pi), "0", "0"] if name == "switch" else []), *tail, "--json", str(out)]
        p = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
        assert p.returncode in (0, 1), p.stderr[-2000:]
        c = json.loads(out.read_text())["candidates"][0]
        verdicts[name] = (c["drift"]["I1/noncanonical"]["verdict"], c["defect"]["noncanonical"]["verdict"])
    assert verdicts["axis"] == ("round-off", "symplectic"), verdicts
    assert verdicts["switch"][0] == "broke down" or verdicts["switch"][1] != "symplectic", verdicts
