"""The chart switch at the axis, SIMPLE's way, against the axis chart (docs/stellarators.md, "The chart switch").

On simsopt's circular tokamak file (or ``--file``, any boozmn file: li383 for the shipped NCSX-like one): 64 trapped guiding centres started on an arc of 0.02 r₁ about the
magnetic axis (their orbits pass it at distances down to 1e-5 r₁), ``--steps`` steps of GLRK2-symmetric at the
file's default h, in the axis chart (x, y, ζ, ρ) and in the polar chart (r, θ, ζ, ρ) with the switch
(r, θ) → (−r, θ + π) after a step that ends at r < 0 (integrators/audit/chart_switch.py): the energy error of
each, the switches and the breakdowns; then the audit of both maps on a loop about the orbit that comes
closest to the axis (``audit_map``: the drift of I₁, the energy, the one-step defect).

    python scripts/studies/chart_switch.py            # about a minute after compilation
    python scripts/studies/chart_switch.py --file li383   # the same in the NCSX-like field (nfp 3)
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from integrators.audit.chart_switch import axis_family, axis_step, boozmn_path, polar_system, switch_step, to_polar
from integrators.audit.maps import audit_map
from integrators.audit.report import text_report



def energies(axis, polar, steps):
    """Max relative energy error a point over ``steps`` steps in both charts, the switches, the breakdowns."""
    h = axis.defaults["h"]
    qa = axis_family(axis)
    qp = to_polar(qa)
    ax, sw = axis_step(axis), switch_step(polar)
    Ea0, Ep0 = axis.H(qa), polar.H(qp)
    ea, ep = np.zeros(len(qa)), np.zeros(len(qa))
    closest = np.full(len(qa), np.inf)
    for _ in range(steps):
        qa, qp = ax(qa, h), sw(qp, h)
        ea = np.fmax(ea, np.abs(axis.H(qa) / Ea0 - 1))
        ep = np.fmax(ep, np.abs(polar.H(qp) / Ep0 - 1))
        closest = np.fmin(closest, np.hypot(qa[:, 0], qa[:, 1]))
    return dict(axis_energy=ea, polar_energy=ep, switches=sw.switches, axis_broke=int(np.isnan(qa[:, 0]).sum()),
                polar_broke=int(np.isnan(qp[:, 0]).sum()), closest=closest)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", default="circular",
                    help="a boozmn file, or 'circular' / 'li383' for the shipped ones (default circular)")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--audit-steps", type=int, default=400)
    args = ap.parse_args(argv)
    path = boozmn_path(args.file)
    polar, axis = polar_system(path)
    print(f"{Path(path).name}: {len(polar.fields) - 3} modes in the polar chart")
    t0 = time.perf_counter()
    e = energies(axis, polar, args.steps)
    r1 = np.sqrt(2 * axis.param_values["psi_edge"])
    print(f"{len(e['closest'])} guiding centres, {args.steps} steps of h = {axis.defaults['h']} "
          f"({time.perf_counter() - t0:.1f} s): closest approach to the axis {e['closest'].min() / r1:.1e} r1")
    print(f"  axis chart:            energy error max {np.nanmax(e['axis_energy']):.1e}, median "
          f"{np.median(e['axis_energy']):.1e}; {e['axis_broke']} broke down")
    top = np.sort(e["polar_energy"])[::-1][:4]
    print(f"  polar chart + switch:  energy error max {top[0]:.1e} (then {', '.join(f'{x:.1e}' for x in top[1:])}), "
          f"median {np.median(e['polar_energy']):.1e}; {e['switches']} switches, {e['polar_broke']} broke down")
    i = int(np.nanargmax(e["polar_energy"]))
    z = axis_family(axis)[i]
    for name, sy, step, z0, period in [("axis chart", axis, axis_step(axis), z, None),
                                       ("polar chart + switch", polar, switch_step(polar), to_polar(z[None])[0],
                                        [0, 2 * np.pi, 0, 0])]:
        rep = audit_map(step, z0, axis.defaults["h"], steps=args.audit_steps, output_every=4, loop_points=256,
                        radius=1e-3 * r1, plane=(0, 1), theta=sy.theta, period=period, energy=sy.H,
                        defect_points=2, levels=2, name=name)
        print()
        print(text_report(rep))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
