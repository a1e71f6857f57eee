"""The cheap end of the stability campaign (scripts/stability.py, docs/benchmarks.md "Stability").

Behaviours sec:app_lotka_volterra_2d reports for the Lotka–Volterra model at q0 = (1, 1) that a
short run can check: the Lobatto IIIA–IIIB pair without projection breaks down after tens of
steps at h = 0.1 and after hundreds at h = 0.01, Gauss–Legendre with one stage runs without a
drift, and Radau IIA keeps the Dirac constraint to round-off while its energy drifts one way.
The long runs (10⁴–10⁶ steps, every pair) are in the campaign, not here.
"""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import integrators
from integrators.integrate import integrate

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def lv():
    return integrators.system("lotka_volterra_2d")


def breakdown_step(sol):
    return sol.breakdown_time[0] / sol.h


def test_lobatto_IIIA_IIIB_breaks_down_within_tens_of_steps(lv):
    # paper: "the simulation crashes after about 25 time steps" (two stages, h = 0.1)
    sol = integrate(lv, [1.0, 1.0], "LobIIIA2", "none", 0.1, steps=200)
    assert 10 <= breakdown_step(sol) <= 100


@pytest.mark.parametrize("tab, paper", [("LobIIIA2", 350), ("LobIIIA3", 1000)])
def test_lobatto_at_smaller_step_runs_longer_then_breaks_down(lv, tab, paper):
    # paper: at h = 0.01 "the integrator with two stages crashes after about 350 time steps
    # and the integrator with three stages after about 1.000"; we ask for the same order of magnitude
    sol = integrate(lv, [1.0, 1.0], tab, "none", 0.01, steps=3 * paper, save_every=3 * paper)
    assert paper / 3 <= breakdown_step(sol) <= 3 * paper


def test_glrk1_unprojected_energy_error_bounded(lv):
    # paper: odd-stage Gauss–Legendre methods are stable without projection; the energy error
    # oscillates without growing
    sol = integrate(lv, [1.0, 1.0], "GLRK1", "none", 0.1, steps=4000, save_every=10)
    assert math.isinf(sol.breakdown_time[0])
    H = lv.H(sol.q[:, 0])
    err = np.abs(H - H[0])
    quarter = len(err) // 4
    assert err.max() < 1e-2
    assert err[-quarter:].max() <= 1.5 * err[:quarter].max()


def test_radau_keeps_constraint_energy_drifts(lv):
    # paper: Radau methods preserve the Dirac constraint exactly but dissipate energy
    sol = integrate(lv, [1.0, 1.0], "RadIIA2", "none", 0.1, steps=2000, save_every=100)
    q, p = sol.q[:, 0], sol.p[:, 0]
    assert np.abs(p - lv.theta(q)).max() <= 1e-14
    H = lv.H(q)
    assert np.all(np.diff(H) > 0)            # one way, not an oscillation
    assert H[-1] - H[0] > 1e-3


def test_stability_script_records_and_resumes(tmp_path):
    out = tmp_path / "a.jsonl"
    cmd = [sys.executable, str(ROOT / "scripts" / "stability.py"), "run", "--case", "lotka_volterra",
           "--steps", "40", "--pairs", "LobIIIA2:none", "GLRK1:symmetric", "--out", str(out)]
    subprocess.run(cmd, check=True, capture_output=True)
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    assert [(r["tableau"], r["status"]) for r in recs] == [("LobIIIA2", "broke down"), ("GLRK1", "completed")]
    assert 10 <= recs[0]["breakdown_step"] <= 40            # paper: about 25
    assert recs[1]["energy"]["max"] > 0 and len(recs[1]["energy"]["envelope"]) > 5
    r = subprocess.run(cmd, check=True, capture_output=True, text=True)     # resumed: nothing left to run
    assert r.stdout == "" and len(out.read_text().splitlines()) == 2
