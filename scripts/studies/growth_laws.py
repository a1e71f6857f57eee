"""The growth-law classifier (invariants.growth) validated: synthetic series and the known results.

    python scripts/studies/growth_laws.py [--series 1000] [--out docs/figures/growth_laws.json]

* **Synthetic series**, ``--series`` of each law, each with random parameters and noise:
  - round-off: a random walk of round-off, |Σ ε_k| with ε_k ~ N(0, (1e-16…1e-15)²), or a bounded
    oscillation of 1e-15…1e-12;
  - bounded: A·|sin(ωt + φ)| (+ a second incommensurate frequency), periods from 2 samples to a
    third of the run, A from 1e-10 to 1e-2, multiplicative noise 0–30 %;
  - random walk: |Σ ε_k| with ε_k ~ N(0, σ²), σ from 1e-10 to 1e-5 (max well above round-off);
  - linear: a·t + b·sin(ωt) with b up to 0.3 × a·T, noise 0–30 %;
  - faster: ε·(exp(λt) − 1) with λT from 4 to 20, or a·t³ (+ oscillation); noise 0–30 %.
  Each series has 200–4,000 samples at equal times.  The confusion matrix (rows: the law drawn,
  columns: the law found) goes to docs/growth.md.
* **Known results** from the project's stored runs (no rerun needed): the stability campaign's
  energy envelopes (docs/figures/stability/*.jsonl, 40 log windows each), the energy drift study
  (docs/figures/energy_drift.json, 10 interval maxima) and the paper scene's invariants on the
  engine (run here, 2,000 steps: GLRK1-standard drifts linearly, GLRK2-symmetric stays at
  round-off).
"""
import argparse
import json
from pathlib import Path

import numpy as np

from invariants.growth import DRAWN, LAWS, confusion, growth_law, growth_law_of_maxima

ROOT = Path(__file__).resolve().parents[2]
def _r(x):
    return float(f"{x:.3g}")


def known_stability():
    """(case, pair, law, α, onset step) for the stored envelopes of the stability campaign."""
    out = []
    for f in sorted((ROOT / "docs/figures/stability").glob("*.jsonl")):
        for line in f.read_text().splitlines():
            r = json.loads(line)
            if r["status"] != "completed":
                continue
            env = r["energy"]
            g = growth_law_of_maxima(env["envelope_steps"], env["envelope"])
            out.append(dict(case=r["case"], pair=f"{r['tableau']}-{r['projection']}", steps=r["steps"],
                            file=f.name, law=g.law, exponent=_r(g.exponent), exponent_error=_r(g.exponent_error),
                            onset_step=g.onset, max_error=g.max_error))
    return out


def known_energy_drift():
    out = []
    for r in json.loads((ROOT / "docs/figures/energy_drift.json").read_text()):
        m = np.asarray(r["intervals"], dtype=float)
        ends = np.arange(1, m.size + 1) * r["steps"] / m.size
        g = growth_law_of_maxima(ends, m)
        out.append(dict(tableau=r["tableau"], coefficients=r["coefficients"], steps=r["steps"], law=g.law,
                        exponent=g.exponent, exponent_error=g.exponent_error, growth_script=r["growth"]))
    return out


def known_paper(steps=2000, every=10):
    """I₁, I₂ (noncanonical) relative errors of the paper's sets on the engine, GLRK1-standard and
    GLRK2-symmetric at the paper scene's step."""
    import integrators
    import invariants
    from integrators.service.scene import load_scene
    from invariants.forms import first_invariants, second_invariants
    scene = load_scene("paper_poincare")
    sy = integrators.system("guiding_centre_symmetric")
    loop, surf = invariants.loop("guiding_centre", 200), invariants.surface("guiding_centre", 30, 30)
    pts = np.concatenate([loop, surf.reshape(-1, 4)])
    out = []
    for tab, proj in (("GLRK1", "standard"), ("GLRK2", "symmetric")):
        eng = integrators.Engine(sy, integrators.tableau(tab), proj, scene.h)
        st = eng.state(pts)
        t, i1, i2 = [0.0], [], []

        def inv():
            q = st.q
            i1.append(first_invariants(q[:200], ["noncanonical"], system=sy)["noncanonical"].value)
            i2.append(second_invariants(q[200:].reshape(surf.shape), ["noncanonical"], system=sy)["noncanonical"].value)
        inv()
        for k in range(every, steps + 1, every):
            eng.advance(st, k - every + 1, every)
            t.append(k * scene.h)
            inv()
        for name, v in (("I1", i1), ("I2", i2)):
            v = np.asarray(v)
            g = growth_law(np.asarray(t), np.abs(v - v[0]) / abs(v[0]))
            out.append(dict(pair=f"{tab}-{proj}", series=name, steps=steps, law=g.law, exponent=g.exponent,
                            exponent_error=g.exponent_error, onset=g.onset, max_error=g.max_error))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--series", type=int, default=1000)
    ap.add_argument("--out", default=str(ROOT / "docs/figures/growth_laws.json"))
    ap.add_argument("--no-paper", action="store_true", help="skip the engine runs of the paper's sets")
    ap.add_argument("--samples", type=int, default=None, help="every series this many samples (default 200-4,000)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    M = confusion(args.series, args.seed, args.samples)
    print("| drawn \\ found | " + " | ".join(LAWS) + " | correct |")
    print("|---|" + "---:|" * (len(LAWS) + 1))
    for d in DRAWN:
        print(f"| {d} | " + " | ".join(str(M[d][f]) for f in LAWS) + f" | {100 * M[d][d] / args.series:.1f} % |")
    stab = known_stability()
    drift = known_energy_drift()
    paper = [] if args.no_paper else known_paper()
    for r in paper:
        print(f"paper sets {r['pair']} {r['series']}: {r['law']} α = {r['exponent']:.2f} ± {r['exponent_error']:.2f}, "
              f"max {r['max_error']:.1e}")
    for r in drift:
        print(f"energy drift {r['tableau']} {r['coefficients']}: {r['law']} α = {r['exponent']:.2f} ± "
              f"{r['exponent_error']:.2f} (script's growth {r['growth_script']:+.2f})")
    Path(args.out).write_text(json.dumps(dict(series_per_law=args.series, confusion=M, paper=paper,
                                              energy_drift=drift, stability=stab), indent=1) + "\n")
    laws = {}
    for r in stab:
        laws[r["law"]] = laws.get(r["law"], 0) + 1
    print("stability campaign energy laws:", laws)
    for r in stab:
        if r["case"] == "lotka_volterra" and r["pair"] in ("GLRK5-none", "GLRK4-none", "GLRK2-symmetric",
                                                           "GLRK1-none", "GLRK6-none", "GLRK5-standard"):
            print(f"  {r['file']} {r['case']} {r['pair']} {r['steps']}: {r['law']} α = {r['exponent']:.2f} ± "
                  f"{r['exponent_error']:.2f} from step {r['onset_step']:.0f}, max {r['max_error']:.1e}")


if __name__ == "__main__":
    main()
