"""Service benchmarks (docs/scaling.md): what skipping saves, and MPI scaling.

    python scripts/studies/scaling_service.py [--steps 100] [--out docs/figures/benchmark_service.json]

A. Skip what the scene does not need: GLRK2-symmetric on guiding_centre_symmetric,
   h = 10, `--steps` steps, output every 10: loop only (2,000 points), loop + surface
   (2,000 + 100×100), and loop + surface without the corrected form.  Wall time and
   peak resident memory of each run, every run in a fresh process.
B. MPI: the paper's Poincaré scene cut to `--steps` steps, on 1 and 2 ranks (strong
   scaling) and with the points doubled on 2 ranks (weak scaling: loop 4,000, surface
   141×142), with the time per phase on rank 0 (advection, gather, invariants, HDF5).

C. ``--paper``: the built-in paper_poincare scene itself (1,000 steps) on 1 and 2 ranks, with the
   time per phase, and a check that the two HDF5 files are bitwise identical; written to
   docs/figures/benchmark_paper_mpi.json.

D. ``--scale``: throughput at scale, a loop of 10³ (baseline), 10⁵ and 10⁶ points, GLRK2-symmetric,
   10 steps with one output, on 1 and 2 ranks: point-steps per second of the advance phase and
   peak resident memory per point ((peak − peak of the 10³-point run) / points); written to
   docs/figures/benchmark_scale.json.

E. ``--contention``: what two busy cores cost each other on this machine.  The paper scene cut to
   ``--steps`` steps runs as one serial process alone, then as two identical serial processes
   started together, ``--repeat`` times alternately; no MPI, no communication.  The ceiling of
   any 2-rank speed-up here is 2 · T_alone / T_together; written to
   docs/figures/benchmark_contention.json.

Each measurement is a child process: ``[mpiexec -n K] python scripts/studies/scaling_service.py
--child SCENE OUT``, which runs the driver and prints one JSON line from rank 0.
"""
import argparse
import json
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

BASE = """
name = "{name}"
[system]
name = "guiding_centre_symmetric"
{loop}
{surface}
[run]
tableaus = {tableaus}
projections = {projections}
h = 10.0
steps = {steps}
output_every = 10
forms = {forms}
"""
LOOP = "[loop]\nshape = \"guiding_centre\"\npoints = {n}\n"
SURF = "[surface]\nshape = \"guiding_centre\"\nn_sigma = {ns}\nn_tau = {nt}\n"


def scene_text(name, steps, loop=2000, surf=(100, 100), tableaus=("GLRK2",), projections=("symmetric",),
               forms=("canonical", "noncanonical", "corrected")):
    return BASE.format(name=name, loop=LOOP.format(n=loop) if loop else "",
                       surface=SURF.format(ns=surf[0], nt=surf[1]) if surf else "",
                       tableaus=json.dumps(list(tableaus)), projections=json.dumps(list(projections)),
                       steps=steps, forms=json.dumps(list(forms)))


def child(scene_path, out, threads=None):
    from integrators.service import driver
    from integrators.service.scene import load_scene
    from integrators.service.ranks import communicator, default_threads
    comm = communicator()
    threads = threads or default_threads(comm)
    scene = load_scene(scene_path)
    t0 = time.perf_counter()
    summaries = driver.run(scene, out, force=True, comm=comm, progress=False, threads=threads)
    wall = time.perf_counter() - t0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # MiB (Linux reports KiB)
    rss_all = comm.gather(rss, root=0)
    if comm.rank == 0:
        phases, per_rank = {}, [{} for _ in range(comm.size)]
        for s in summaries:
            for k, v in s.timings.items():
                if k != "per_rank":
                    phases[k] = phases.get(k, 0.0) + v
            for r, c in enumerate(s.timings.get("per_rank", [])):
                for k, v in c.items():
                    per_rank[r][k] = per_rank[r].get(k, 0) + v
        print(json.dumps(dict(wall=wall, ranks=comm.size, threads=threads, peak_rss_mib=rss_all, phases=phases,
                              per_rank=per_rank, pairs={s.pair: s.timings for s in summaries})))


def _command(text, ranks, tmp, out_name, threads=None):
    path = Path(tmp) / f"{out_name}.toml"
    path.write_text(text)
    cmd = [sys.executable, __file__, "--child", str(path), str(Path(tmp) / out_name)]
    cmd += ["--threads", str(threads)] if threads else []
    if ranks > 1:
        mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).parent / "mpiexec")
        cmd = [mpiexec, "-n", str(ranks)] + cmd
    return cmd


def _result(stdout):
    return json.loads(stdout.strip().splitlines()[-1])


def measure(text, ranks, tmp, out_name="out.h5", threads=None):
    r = subprocess.run(_command(text, ranks, tmp, out_name, threads), capture_output=True, text=True, check=True)
    return _result(r.stdout)


def measure_together(text, copies, tmp):
    """``copies`` identical serial runs started at once; their results in start order."""
    procs = [subprocess.Popen(_command(text, 1, tmp, f"c{k}.h5"), stdout=subprocess.PIPE, text=True)
             for k in range(copies)]
    outs = [p.communicate()[0] for p in procs]
    if any(p.returncode for p in procs):
        raise RuntimeError("a concurrent child failed")
    return [_result(o) for o in outs]


def contention(out, steps, repeat):
    """One serial paper-scene run alone against two run together (see E in the module docstring)."""
    import statistics
    paper = dict(tableaus=("GLRK1", "GLRK2", "SRK3"),
                 projections=("none", "standard", "symmetric", "symplectic", "midpoint"))
    text = scene_text("p", steps, **paper)
    res = {"meta": dict(machine=platform.platform(), python=platform.python_version(), steps=steps,
                        scene="paper_poincare cut to --steps steps", repeat=repeat), "alone": [], "together": []}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeat):
            res["alone"].append(measure(text, 1, tmp))
            print("alone", res["alone"][-1], flush=True)
            res["together"].append(measure_together(text, 2, tmp))
            print("together", res["together"][-1], flush=True)
    t1 = statistics.median(r["wall"] for r in res["alone"])
    t2 = statistics.median(max(a["wall"], b["wall"]) for a, b in res["together"])
    adv1 = statistics.median(r["phases"]["advance"] for r in res["alone"])
    adv2 = statistics.median(sum(x["phases"]["advance"] for x in pair) / 2 for pair in res["together"])
    res["summary"] = dict(wall_alone=t1, wall_together=t2, slowdown=t2 / t1, ceiling_2_ranks=2 * t1 / t2,
                          advance_alone=adv1, advance_together=adv2, advance_slowdown=adv2 / adv1)
    print(json.dumps(res["summary"]), flush=True)
    Path(out).write_text(json.dumps(res, indent=1))


def identical_files(a, b):
    """Names of the datasets that differ (bitwise) between two HDF5 files, and the count compared.

    Each pair's ``wall_clock`` (its run time) differs by nature and is left out of the count.
    """
    import h5py
    import numpy as np
    names, differ = [], []
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        fa.visit(lambda n: names.append(n) if isinstance(fa[n], h5py.Dataset) and not n.endswith("wall_clock") else None)
        for n in names:
            x, y = fa[n][()], fb[n][()] if n in fb else None
            if y is None or np.asarray(x).tobytes() != np.asarray(y).tobytes():
                differ.append(n)
    return differ, len(names)


def paper_experiment(out, ranks_list=(1, 2)):
    text = (ROOT / "integrators" / "service" / "scenes" / "paper_poincare.toml").read_text()
    res = {"meta": dict(machine=platform.platform(), python=platform.python_version(), scene="paper_poincare")}
    with tempfile.TemporaryDirectory() as tmp:
        for ranks in ranks_list:
            res[f"{ranks} rank(s)"] = measure(text, ranks, tmp, out_name=f"r{ranks}.h5")
            print(ranks, res[f"{ranks} rank(s)"], flush=True)
        for other in ranks_list[1:]:          # every rank count against the first, bit for bit
            differ, n = identical_files(Path(tmp) / f"r{ranks_list[0]}.h5", Path(tmp) / f"r{other}.h5")
            res[f"datasets compared {ranks_list[0]} vs {other}"] = n
            res[f"datasets differing {ranks_list[0]} vs {other}"] = differ
            print(f"{ranks_list[0]} vs {other} ranks: {n} datasets compared, {len(differ)} differ", flush=True)
    Path(out).write_text(json.dumps(res, indent=1))


def scale(out):
    res = {"meta": dict(machine=platform.platform(), python=platform.python_version(), steps=10,
                        pair="GLRK2-symmetric", system="guiding_centre_symmetric")}
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in (1000, 100_000, 1_000_000):
            for ranks in (1, 2):
                text = scene_text("s", 10, loop=n, surf=None)
                r = measure(text, ranks, tmp)
                r.update(points=n, point_steps_per_s=n * 10 / r["phases"]["advance"])
                runs.append(r)
                print(n, ranks, json.dumps(r), flush=True)
                res["runs"] = runs
                Path(out).write_text(json.dumps(res, indent=1))
    base = {r["ranks"]: r for r in runs if r["points"] == 1000}
    for r in runs:
        if r["points"] > 1000:
            b = base[r["ranks"]]["peak_rss_mib"]
            r["rss_per_point_kib"] = [(x - y) * 1024 / (r["points"] / r["ranks"]) for x, y in zip(r["peak_rss_mib"], b)]
    Path(out).write_text(json.dumps(res, indent=1))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--child", nargs=2)
    ap.add_argument("--threads", type=int, default=None, help="threads per rank (default: the cores shared)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "figures" / "benchmark_service.json"))
    ap.add_argument("--scale", action="store_true", help="10^5 and 10^6 loop points on 1 and 2 ranks")
    ap.add_argument("--paper", action="store_true", help="the full paper scene on 1 and 2 ranks (about 30 min)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2], help="rank counts for --paper")
    ap.add_argument("--paper-out", default="benchmark_paper_mpi.json", help="file name under docs/figures for --paper")
    ap.add_argument("--contention", action="store_true", help="one serial run alone against two together")
    ap.add_argument("--repeat", type=int, default=2, help="rounds for --contention")
    args = ap.parse_args()
    if args.child:
        return child(*args.child, threads=args.threads)
    if args.scale:
        return scale(ROOT / "docs" / "figures" / "benchmark_scale.json")
    if args.contention:
        return contention(ROOT / "docs" / "figures" / "benchmark_contention.json", args.steps, args.repeat)
    if args.paper:
        return paper_experiment(ROOT / "docs" / "figures" / args.paper_out, args.ranks)
    res = {"meta": dict(machine=platform.platform(), python=platform.python_version(), steps=args.steps)}
    with tempfile.TemporaryDirectory() as tmp:
        skip = {}
        for label, text in [
            ("loop only", scene_text("a", args.steps, surf=None)),
            ("loop + surface", scene_text("b", args.steps)),
            ("loop + surface, no corrected form", scene_text("c", args.steps, forms=("canonical", "noncanonical"))),
        ]:
            skip[label] = measure(text, 1, tmp)
            print(label, skip[label], flush=True)
        res["skip"] = skip
        paper = dict(tableaus=("GLRK1", "GLRK2", "SRK3"),
                     projections=("none", "standard", "symmetric", "symplectic", "midpoint"))
        mpi = {}
        for label, text, ranks in [
            ("1 rank", scene_text("p", args.steps, **paper), 1),
            ("2 ranks", scene_text("p", args.steps, **paper), 2),
            ("2 ranks, points doubled", scene_text("p", args.steps, loop=4000, surf=(141, 142), **paper), 2),
        ]:
            mpi[label] = measure(text, ranks, tmp)
            print(label, mpi[label], flush=True)
        res["mpi"] = mpi
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
