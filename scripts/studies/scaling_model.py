"""A per-phase cost model of `poincare run`, measured here and used to predict 1 to 1,024 ranks.

    python scripts/studies/scaling_model.py measure [--steps 1000] [--hybrid]   # ~17 min on 2 cores: docs/figures/scaling.json
    python scripts/studies/scaling_model.py measure --again 2x1                 # one run again, the rest of the file kept
    python scripts/studies/scaling_model.py measure --again checkpoints         # per-rank checkpoints: costs, 2 ranks side by side
    python scripts/studies/scaling_model.py predict                 # the model: tables for docs/scaling.md and a PNG

measure:
  A. the paper scene (paper_poincare: loop 2,000, surface 100 × 100, 15 pairs; ``--steps`` steps),
     on 1 rank × 1 thread, 2 ranks × 1 thread (and with ``--hybrid`` 1 rank × 2 threads): wall time, every
     rank's phases (advance, gather, invariants, HDF5) and a bitwise comparison of the files;
  B. the cost of each invariant task (set, form) at the scene's size and at larger sizes (the
     exponent of its growth), and of the per-point diagnostics;
  C. the rate of a pickled gather between 2 ranks (bytes per second) and the cost of writing one
     checkpoint per byte (``--again costs`` measures B and C alone).

predict: per pair, an output interval of k steps costs
    T = max((N·k·c + Σ_r W_r) / R, max_r W_r) + G(R),
with c the pair's advance per point-step (A, one thread), W_r rank r's output work (its invariant
tasks as :func:`integrators.service.diagnostics.assign` gives them, its points' diagnostics, and on
rank 0 the rows' HDF5 write) and G the sets' parts gathered to the busiest task owner (each set's
q, p, λ and live flags, 97 bytes a point, × (R − 1)/R, over the gather rate).  On top, each pair
writes its state 1 + ⌊pair time / 60 s⌋ times (output.checkpoint_seconds): 314 bytes a point
gathered to rank 0 and written there.  The balance of points against output work is what the
driver's split does; the max is a rank whose output work alone exceeds an even share.  Validated
against A's 1- and 2-rank walls.

predict also runs the batch-by-batch model (:func:`predict_schedule`): the driver's schedule
itself (batch sizes with the cap of driver.turns, each batch's set tasks on the ranks the rotation
gives them, rank 0's rows and checkpoints), for the driver as built, with checkpoints written by every rank
(output.checkpoints = "per-rank", costs from ``--again checkpoints``) and for a design not built
(a set's task split over a group of ranks), strong and weak scaling.  That is the model docs/scaling.md quotes now; the even-spread one above is kept for
the record of how the first predictions were made.
"""
import argparse
import json
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts" / "studies"))
import scaling_service as bs  # noqa: E402

OUT = ROOT / "docs" / "figures" / "scaling.json"
FORMS = ("canonical", "noncanonical", "corrected")
PAIRS = dict(tableaus=("GLRK1", "GLRK2", "SRK3"), projections=("none", "standard", "symmetric", "symplectic", "midpoint"))


def task_costs(sizes_loop=(2000, 20000, 200000), sizes_surf=(100, 200, 400)):
    """Seconds of each (set, form) task on guiding_centre_symmetric at several sizes (median of 3)."""
    import integrators
    import invariants
    from invariants.forms import first_invariants, second_invariants
    sy = integrators.system("guiding_centre_symmetric", B0=1.0, mu=0.01)
    out = []
    for inv, sizes in (("I1", sizes_loop), ("I2", sizes_surf)):
        for n in sizes:
            x = invariants.loop("guiding_centre", n) if inv == "I1" else invariants.surface("guiding_centre", n, n)
            fn = invariants.first_invariant if inv == "I1" else invariants.second_invariant
            p = sy.theta(x.reshape(-1, 4)).reshape(x.shape)
            lam = np.zeros_like(x)
            together = first_invariants if inv == "I1" else second_invariants
            for form in FORMS + ("all",):     # each form alone, and the three together as a rank that owns them
                ts = []
                for _ in range(3):
                    t0 = time.perf_counter()
                    if form == "all":
                        together(x, list(FORMS), system=sy, p=p, lam=lam, h=10.0)
                    else:
                        fn(x, form, system=sy, p=p, lam=lam, h=10.0)
                    ts.append(time.perf_counter() - t0)
                out.append(dict(set=inv, form=form, points=int(x.size // 4), seconds=float(np.median(ts))))
                print(out[-1], flush=True)
    from types import SimpleNamespace
    from integrators.service.diagnostics import Diagnostics
    q = invariants.surface("guiding_centre", 300, 300).reshape(-1, 4)
    dg = Diagnostics(SimpleNamespace(diagnostics=("energy", "momentum", "constraint")), sy, q)
    p, live = sy.theta(q), np.ones(q.shape[0], dtype=bool)
    dg.point_errors(q, p, live)
    t0 = time.perf_counter()
    for _ in range(5):
        dg.point_errors(q, p, live)          # as the driver takes them: one compiled pass
    diag = (time.perf_counter() - t0) / 5 / q.shape[0]
    return out, diag


GATHER_CHILD = """
import sys, time, numpy as np
from mpi4py import MPI
from integrators import State
comm = MPI.COMM_WORLD
n = int(sys.argv[1]) // comm.size
part = {k: np.ones(shape, dtype) for k, (shape, dtype) in State.schema(n, 4, 3).items()}   # a rank's checkpoint
nbytes = sum(v.nbytes for v in part.values())
comm.gather(part, root=0)
t0 = time.perf_counter()
for _ in range(20):
    comm.gather(part, root=0)
dt = (time.perf_counter() - t0) / 20
if comm.rank == 0:
    print(nbytes * (comm.size - 1), dt)
"""


TRANSPORT_CHILD = """
import sys, time, numpy as np
from mpi4py import MPI
from integrators.service.ranks import communicator
from integrators.service.transport import PARTS, Transport
comm = communicator()
t = Transport(comm)
n, outputs, before = int(sys.argv[1]) // comm.size, int(sys.argv[2]), sys.argv[3] == "before"
if before:        # the driver before: plain pickles, four arrays an output
    t.comm = MPI.COMM_WORLD
    part = lambda m: [(np.ones((m, 4)), np.ones((m, 4)), np.ones((m, 4)), np.ones(m, bool)) for _ in range(outputs)]
else:             # now: pkl5, the outputs stacked (tasks.Tasks.stack)
    part = lambda m: (np.ones((outputs, m, 4)), np.ones((outputs, m, 4)), np.ones((outputs, m, 4)),
                      np.ones((outputs, m), bool))
msg = {0: part(n // 6), 1: part(n - n // 6)}          # the loop's and the surface's parts (q, p, λ, live)
size = lambda x: x.nbytes if isinstance(x, np.ndarray) else sum(size(y) for y in x)
nbytes = size(list(msg.values()))
for rep in range(6):
    comm.Barrier()
    t0 = time.perf_counter()
    if comm.rank == 1:
        t.send(msg, 0, PARTS)
        t.finish()
    else:
        t.receive(1, PARTS)
    dt = time.perf_counter() - t0
if comm.rank == 0:
    print(nbytes, dt)
"""


def transport_cost(points=12000, outputs=10, before=False):
    """Bytes a second of the driver's own messages (transport.Transport: mpi4py pkl5) between 2
    ranks: one rank's parts of a loop and a surface (q, p, λ, live of points/2 points) stacked over
    ``outputs`` outputs as tasks.Tasks.stack does, the last of 6 sends (``before``: as the driver
    sent them before, plain pickles of four arrays an output)."""
    exe = shutil.which("mpiexec") or str(Path(sys.executable).parent / "mpiexec")
    r = subprocess.run([exe, "-n", "2", sys.executable, "-c", TRANSPORT_CHILD, str(points), str(outputs),
                        "before" if before else "now"],
                       capture_output=True, text=True, check=True)
    nbytes, dt = r.stdout.split()
    return dict(bytes=int(nbytes), seconds=float(dt), bytes_per_second=int(nbytes) / float(dt),
                points=points, outputs=outputs)


def gather_cost(points=12000):
    exe = shutil.which("mpiexec") or str(Path(sys.executable).parent / "mpiexec")
    r = subprocess.run([exe, "-n", "2", sys.executable, "-c", GATHER_CHILD, str(points)], capture_output=True,
                       text=True, check=True)
    nbytes, dt = r.stdout.split()
    return dict(bytes=int(nbytes), seconds=float(dt), bytes_per_second=int(nbytes) / float(dt))


def _slots(f, schema):
    """A pair group with two checkpoint slots of ``schema``, as output.create makes them."""
    g = f.create_group("p")
    for slot in ("a", "b"):
        c = g.create_group(f"checkpoint/{slot}")
        c.create_dataset("step", data=np.array(-1, dtype=np.int64))
        for name, (shape, dtype) in schema.items():
            c.create_dataset(name, shape=shape, dtype=dtype, chunks=True, fletcher32=True)
    return g


def write_cost(points=12000, repeat=5):
    """Seconds a byte of one checkpoint of ``points`` points takes to write (as the driver does:
    fletcher32 chunks, slot invalidated, written, validated, three flushes); median of ``repeat``."""
    import h5py
    from integrators import State
    from integrators.service import checkpoints
    schema = State.schema(points, 4, 3)
    state = {k: np.ones(shape, dtype) for k, (shape, dtype) in schema.items()}
    nbytes = sum(v.nbytes for v in state.values())
    with tempfile.TemporaryDirectory() as tmp, h5py.File(Path(tmp) / "w.h5", "w") as f:
        g = _slots(f, schema)
        ts = []
        for k in range(repeat):
            t0 = time.perf_counter()
            checkpoints.write_checkpoint(f, g, k, state)
            ts.append(time.perf_counter() - t0)
    return dict(bytes=nbytes, seconds=float(np.median(ts)), seconds_per_byte=float(np.median(ts)) / nbytes)


def slab_cost(points=12000, ranks=2, repeat=5):
    """Seconds a byte of one rank's checkpoint slab takes to write with output.checkpoints =
    "per-rank" (checkpoints.write_slab: a file of its own, fletcher32 chunks, closed); median of ``repeat``."""
    from integrators import State
    from integrators.service import checkpoints
    state = {k: np.ones(shape, dtype) for k, (shape, dtype) in State.schema(points // ranks, 4, 3).items()}
    nbytes = sum(v.nbytes for v in state.values())
    ts = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(repeat):
            t0 = time.perf_counter()
            checkpoints.write_slab(Path(tmp), f"s{k}.h5", state, 3)
            ts.append(time.perf_counter() - t0)
    return dict(bytes=nbytes, seconds=float(np.median(ts)), seconds_per_byte=float(np.median(ts)) / nbytes)


def link_cost(points=1_000_000, slabs=(16, 128, 1024), repeat=3):
    """Rank 0's seconds to link one per-rank checkpoint of ``points`` points written as R slabs
    (checkpoints.link_checkpoint: a virtual dataset a field, R mappings each), for each R; and the fit
    seconds = a + b·R."""
    import h5py
    from integrators import State
    from integrators.service import checkpoints
    schema = State.schema(points, 4, 3)
    res = {}
    with tempfile.TemporaryDirectory() as tmp, h5py.File(Path(tmp) / "w.h5", "w") as f:
        g = _slots(f, schema)
        folder = Path(tmp) / "w.h5.checkpoints"
        folder.mkdir()
        for r in slabs:
            b = np.linspace(0, points, r + 1).astype(int)
            links = [(f"{r}-{i}.h5", int(b[i]), int(b[i + 1])) for i in range(r)]
            ts = []
            for k in range(repeat):
                t0 = time.perf_counter()
                checkpoints.link_checkpoint(f, g, k, links, folder)
                ts.append(time.perf_counter() - t0)
            res[r] = float(np.median(ts))
    R = np.array(list(res), float)
    b, a = np.polyfit(R, np.array(list(res.values())), 1)
    return dict(seconds=res, fixed=float(a), per_slab=float(b))


CK_SCENE = dict(loop=100_000, surf=None, tableaus=("GLRK2",), projections=("symmetric",), forms=("canonical",))


def checkpoint_runs(repeat=3, steps=100):
    """Side by side on 2 ranks: a scene whose checkpoints weigh (a loop of 100,000 points, its state
    written at every one of its 21 outputs: output.checkpoint_seconds = 0) with the state gathered to
    rank 0 and written into the file, and with every rank writing its own slab; alternated
    ``repeat`` times; wall and every rank's HDF5 seconds, and whether the two files hold the same values."""
    runs = {"in-file": [], "per-rank": []}
    text = bs.scene_text("ck", steps, **CK_SCENE).replace("output_every = 10", "output_every = 5")
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeat):
            for mode in runs:
                r = bs.measure(text + f'[output]\ncheckpoint_seconds = 0.0\ncheckpoints = "{mode}"\n', 2, tmp,
                               out_name=f"{mode}.h5", threads=1)
                runs[mode].append({k: ([c.get(k, 0.0) for c in r["per_rank"]] if k != "wall" else r["wall"])
                                   for k in ("wall", "advance", "gather", "hdf5", "wait_recv", "wait_end")})
                print(mode, r["wall"], runs[mode][-1]["hdf5"], flush=True)
        differ, n = bs.identical_files(Path(tmp) / "in-file.h5", Path(tmp) / "per-rank.h5")
    return dict(runs=runs, scene=f"{CK_SCENE}, {steps} steps, output every 5, a checkpoint at each output",
                datasets_differing=[differ, n])


def costs():
    """B and C: the invariant tasks, the per-point diagnostics, the gather rate and the write rate."""
    tasks, diag = task_costs()
    return dict(tasks=tasks, diag_per_point=diag, gather=gather_cost(), write=write_cost())


def measure(steps, hybrid=False, again=None):
    """Every run, the task costs and the gather rate; with ``again`` (a run label, e.g. '2x1') only
    that run, the rest of the file kept and its previous entry moved to 'earlier'."""
    if again == "transport":      # the driver's messages (pkl5), as the model's exchange rate
        res = json.loads(OUT.read_text())
        res["transport"] = dict(transport_cost(), measured=time.strftime("%Y-%m-%d %H:%M") +
                                " by python scripts/studies/scaling_model.py measure --again transport",
                                before={f"{p} points, {k} outputs": transport_cost(p, k, before=True)["bytes_per_second"]
                                        for p, k in ((12000, 10), (12000, 60), (100000, 10))},
                                now={f"{p} points, {k} outputs": transport_cost(p, k)["bytes_per_second"]
                                     for p, k in ((12000, 10), (12000, 60), (100000, 10))})
        print(res["transport"])
        OUT.write_text(json.dumps(res, indent=1))
        return
    if again == "checkpoints":    # per-rank checkpoints: their costs, and 2 ranks side by side
        res = json.loads(OUT.read_text())
        res["checkpoints"] = dict(slab=slab_cost(), link=link_cost(), side_by_side=checkpoint_runs(),
                                  measured=time.strftime("%Y-%m-%d %H:%M") +
                                  " by python scripts/studies/scaling_model.py measure --again checkpoints")
        OUT.write_text(json.dumps(res, indent=1))
        return
    if again == "costs":
        res = json.loads(OUT.read_text())
        res.update(costs())
        OUT.write_text(json.dumps(res, indent=1))
        return
    if again == "1x1-busy":       # one rank with the other core kept busy: the 2-rank run's per-core speed
        res = json.loads(OUT.read_text())
        hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        try:
            with tempfile.TemporaryDirectory() as tmp:
                run = bs.measure(bs.scene_text("p", steps, **PAIRS), 1, tmp, out_name="busy.h5", threads=1)
        finally:
            hog.kill()
        run["measured"] = time.strftime("%Y-%m-%d %H:%M") + " by python scripts/studies/scaling_model.py measure --again 1x1-busy"
        res.setdefault("1x1-busy", []).append(run)
        print(again, run["wall"], flush=True)
        OUT.write_text(json.dumps(res, indent=1))
        return
    if again:
        res = json.loads(OUT.read_text())
        if again in res:
            res["earlier"] = res.get("earlier", []) + [{again: {"wall": res[again]["wall"],
                                                                  "per_rank": res[again].get("per_rank")},
                                                          "meta": res["meta"]}]
        ranks, threads = map(int, again.split("x"))
        with tempfile.TemporaryDirectory() as tmp:
            res[again] = bs.measure(bs.scene_text("p", steps, **PAIRS), ranks, tmp, out_name=f"{again}.h5",
                                    threads=threads)
        res[again]["measured"] = time.strftime("%Y-%m-%d %H:%M") + f" by python scripts/studies/scaling_model.py measure --again {again}"
        print(again, res[again]["wall"], flush=True)
        OUT.write_text(json.dumps(res, indent=1))
        return
    text = bs.scene_text("p", steps, **PAIRS)
    res = {"meta": dict(machine=platform.platform(), python=platform.python_version(), steps=steps,
                        scene=f"paper_poincare cut to {steps} steps", cores=2,
                        command=f"python scripts/studies/scaling_model.py measure --steps {steps}" + (" --hybrid" if hybrid else ""),
                        date=time.strftime("%Y-%m-%d %H:%M"))}
    with tempfile.TemporaryDirectory() as tmp:
        runs = (("1x1", 1, 1), ("2x1", 2, 1)) + ((("1x2", 1, 2),) if hybrid else ())
        for label, ranks, threads in runs:
            res[label] = bs.measure(text, ranks, tmp, out_name=f"{label}.h5", threads=threads)
            print(label, res[label]["wall"], flush=True)
        for other in [r[0] for r in runs[1:]]:
            differ, n = bs.identical_files(Path(tmp) / "1x1.h5", Path(tmp) / f"{other}.h5")
            res[f"datasets differing 1x1 vs {other}"] = [len(differ), n]
            print(other, "differ:", len(differ), "of", n, flush=True)
    res.update(costs())
    if OUT.exists():          # earlier measurements stay in the file: wall, per-rank phases, command
        old = json.loads(OUT.read_text())
        keep = {k: {"wall": v["wall"], "per_rank": v.get("per_rank")} for k, v in old.items()
                if isinstance(v, dict) and "wall" in v}
        res["earlier"] = old.get("earlier", []) + [dict(keep, meta=old.get("meta"))]
    OUT.write_text(json.dumps(res, indent=1))
    print("wrote", OUT)


# -- the model -------------------------------------------------------------------------------

def fit_tasks(tasks):
    """{(set, form): (a, alpha)}: seconds = a · points^alpha, fitted over the measured sizes."""
    fits = {}
    for inv in ("I1", "I2"):
        for form in FORMS + (("all",) if any(t["form"] == "all" for t in tasks) else ()):
            rows = [t for t in tasks if t["set"] == inv and t["form"] == form]
            x = np.log([t["points"] for t in rows])
            y = np.log([t["seconds"] for t in rows])
            alpha, loga = np.polyfit(x, y, 1)
            fits[(inv, form)] = (float(np.exp(loga)), float(alpha))
    return fits


def lpt(costs, ranks):
    """Per-rank load of tasks given longest first to the least loaded rank (as diagnostics.assign)."""
    load = np.zeros(ranks)
    for c in sorted(costs, reverse=True):
        load[np.argmin(load)] += c
    return load


PART_BYTES = 3 * 8 * 4 + 1      # a sample point's q, p, λ (d = 4) and live flag, as the sets are gathered


def predict_wall(model, ranks, n_loop, n_surf, steps, every, pair_costs, startup, checkpoints=False, rotate=False):
    """Predicted wall [s] of the scene on ``ranks`` ranks × 1 thread (with ``checkpoints``, also the
    seconds of it that the checkpoints take: the state sent to rank 0 and written there).

    ``rotate``: a set's forms on one rank (diagnostics.assign_sets), the owners turned by one rank a
    batch (the driver of that time; now tasks.Tasks.assign), so over R batches
    every rank runs every task once and receives every set's parts once: an interval costs
    max((N·k·c + Σ_r W_r)/R, rank 0's row write) + Σ_sets G/R, the largest task no longer a floor
    (it must only fit in the R intervals of its turn, which Σ W/R ≥ max W guarantees)."""
    fits, diag, bw, row_write, ck_write, ck_bytes = (
        model[k] for k in ("fits", "diag", "bw", "row_write", "ck_write_per_byte", "ck_bytes_per_point"))
    n = n_loop + n_surf
    size = {"I1": n_loop, "I2": n_surf}
    def cost(inv, f):
        return fits[(inv, f)][0] * size[inv] ** fits[(inv, f)][1]
    if rotate and ("I1", "all") in fits:                 # diagnostics.assign_sets: a set's forms on one rank
        tasks = [(cost(inv, "all"), inv, f) for inv in ("I1", "I2") for f in ("all",)]
    else:                                                # diagnostics.assign: one form a task
        tasks = [(cost(inv, f), inv, f) for inv in ("I1", "I2") for f in FORMS]
    load, owned = np.zeros(ranks), [dict() for _ in range(ranks)]
    for c, inv, f in sorted(tasks, reverse=True):        # longest first, least loaded
        r = int(np.argmin(load))
        load[r] += c
        owned[r].setdefault(inv, []).extend(FORMS if f == "all" else [f])   # a set's points go once to each owner
    received = [set(o) for o in owned]
    if ("I1", "all") in fits:     # a rank computes its forms of a set together (invariants.forms): the
        # transforms of q they share once.  shared = (Σ alone − together)/(forms − 1), so one form
        # costs its own time and all of them the measured together time (linear in between)
        load = np.zeros(ranks)
        for r in range(ranks):
            for inv, fs in owned[r].items():
                alone = [cost(inv, f) for f in FORMS]
                shared = max((sum(alone) - cost(inv, "all")) / (len(FORMS) - 1), 0.0)
                load[r] += shared + sum(cost(inv, f) - shared for f in fs)
    W = load + diag * n / ranks
    W[0] += row_write
    G = max(sum(size[inv] for inv in received[r]) for r in range(ranks)) * PART_BYTES * (ranks - 1) / ranks / bw
    ck = ck_bytes * n * ((ranks - 1) / ranks / bw + ck_write)    # one checkpoint: to rank 0, then written
    outputs = steps // every
    total, ck_total = startup, 0.0
    G_all = (n_loop + n_surf) * PART_BYTES * (ranks - 1) / ranks / bw      # every set's parts, once
    for c in pair_costs:
        if rotate:
            interval = max((n * every * c + W.sum()) / ranks, row_write) + G_all / ranks
        else:
            interval = max((n * every * c + W.sum()) / ranks, W.max()) + G
        pair = outputs * interval + W.max() + G          # the outputs, plus the one at t = 0
        ck_total += (1 + int(pair // 60.0)) * ck
        total += pair + (1 + int(pair // 60.0)) * ck
    return (total, ck_total) if checkpoints else total


BATCH_SECONDS, TURNS = 2.0, 4          # as integrators.service.driver (_batch, turns)


def predict_schedule(model, ranks, n_loop, n_surf, steps, every, pair_costs, startup, ck_per_rank=False,
                     split=1, batch_cap=True, parts=False, rotate_by_index=False):
    """Predicted wall [s] of the driver as it schedules the work: every batch of every pair with
    its size (about BATCH_SECONDS of advancing, capped at outputs/(TURNS·R) with ``batch_cap``, as
    driver.turns does), each set's task of a batch on the rank given the least task work so far
    (tasks.Tasks.assign; ``rotate_by_index``: the driver before, the owners turned by the batch's
    index), that rank also receiving the set's parts; rank 0 writes every row and (unless ``ck_per_rank``) gathers and writes every
    checkpoint.  The ranks do not meet and the split follows their measured rates, so the points'
    advance fills in around the fixed work: wall = max(Σ work / R, max_r fixed_r) + the last batch's
    largest task (the run's end) + start-up.

    ``ck_per_rank``: each rank writes its own slab of the state (output.checkpoints = "per-rank"):
    a slab file per rank at the measured slab rate, and on rank 0 the links, a + b·R seconds a
    checkpoint (measured: ``measure --again checkpoints``).  ``split`` = g: a set's task split over a group of g ranks (not built): each
    does 1/g of the transforms, and the set's data crosses the group twice (rows, then columns) at
    the gather rate.  With ``parts`` returns (wall, {what: seconds}) as well."""
    fits, diag, bw, row_write, ck_write, ck_bytes = (
        model[k] for k in ("fits", "diag", "bw", "row_write", "ck_write_per_byte", "ck_bytes_per_point"))
    n = n_loop + n_surf
    size = {"I1": n_loop, "I2": n_surf}
    task = {inv: fits[(inv, "all")][0] * size[inv] ** fits[(inv, "all")][1] for inv in ("I1", "I2")}
    recv = {inv: size[inv] * PART_BYTES * (ranks - 1) / ranks / bw for inv in ("I1", "I2")}
    g = min(split, ranks)
    if g > 1:
        task = {inv: (task[inv] + 2 * size[inv] * PART_BYTES * (g - 1) / g / bw) / g for inv in task}   # a share
    base = {"I2": 0, "I1": 1 % ranks}                   # diagnostics.assign_sets: the surface first
    outputs = steps // every + 1
    fixed, given = np.zeros(ranks), np.zeros(ranks)
    advance = diag_total = 0.0
    ck = ck_bytes * n * ((ranks - 1) / ranks / bw + ck_write)
    j, largest = 0, 0.0
    for c in pair_costs:
        per_output = n * every * c / ranks              # one rank's advance between outputs, evenly split
        b = max(1, int(BATCH_SECONDS / max(per_output, 1e-6)))
        if batch_cap:
            b = min(b, max(1, outputs * len(pair_costs) // (TURNS * ranks)))
        done = 0
        while done < outputs:
            k = min(b, outputs - done)
            for inv in ("I2", "I1"):
                if rotate_by_index:                # the driver before: owners turned by the batch's index
                    r = (base[inv] + j) % ranks
                else:                              # tasks.Tasks.assign: to the least task work so far
                    r = int(np.argmin(given))
                    given[r] += k * task[inv]
                fixed[r] += k * recv[inv]
                for m in range(g):                 # a split task: its g shares on g consecutive ranks
                    fixed[(r + m) % ranks] += k * task[inv]
                largest = max(largest, k * task[inv])
            fixed[0] += k * row_write
            done, j = done + k, j + 1
        advance += n * every * c * (outputs - 1)
        diag_total += diag * n * outputs
        pair_time = advance / ranks                     # (for the count of checkpoints only)
        count = 1 + int(n * every * c * (outputs - 1) / ranks // 60.0)
        if ck_per_rank:
            fixed += count * ck_bytes * n / ranks * model.get("slab_per_byte", ck_write)
            fixed[0] += count * (model.get("link_fixed", 0.0) + model.get("link_per_slab", 0.0) * ranks)
        else:
            fixed[0] += count * ck
    total = advance + diag_total + fixed.sum()
    wall = max(total / ranks, fixed.max()) + largest + startup
    if parts:
        return wall, {"advance": advance / ranks, "fixed_max": fixed.max(), "rank0_fixed": fixed[0],
                      "even": total / ranks, "tail": largest, "fixed": fixed.tolist()}
    return wall


DESIGNS = (("the driver now: owners by least task work, batches capped", {}),
           ("… owners turned by batch index (the driver before)", dict(rotate_by_index=True)),
           ("… and before the cap (one batch a pair on many ranks)", dict(batch_cap=False, rotate_by_index=True)),
           ("+ checkpoints written by every rank (output.checkpoints = \"per-rank\")", dict(ck_per_rank=True)),
           ("+ the sets' tasks split over 8 ranks (not built)", dict(ck_per_rank=True, split=8)))


def oversubscribed(model, pair_costs, startup, factor):
    """The model of R ranks sharing C < R cores: every cost of a rank's work × R/C (each rank gets
    C/R of a core while all are busy), the gather rate ÷ R/C."""
    m = dict(model, fits={k: (a * factor, b) for k, (a, b) in model["fits"].items()},
             bw=model["bw"] / factor)
    for k in ("diag", "row_write", "ck_write_per_byte", "slab_per_byte", "link_fixed", "link_per_slab"):
        if k in m:
            m[k] = m[k] * factor
    return m, [c * factor for c in pair_costs], startup * factor


def schedule_tables(model, pair_costs, startup, steps, every, res):
    """The batch-by-batch model (:func:`predict_schedule`): validation, strong scaling for each
    design, weak scaling; printed as Markdown tables for docs/scaling.md."""
    print("| ranks | measured wall [s] | predicted, batch by batch [s] |\n|---:|---:|---:|")
    for label, r in (("1x1", 1), ("2x1", 2)):
        walls = [e[label]["wall"] for e in res.get("earlier", []) if label in e      # the runs since this
                 and (e.get("meta") or {}).get("date") == res["meta"]["date"]] + [res[label]["wall"]]  # file's costs
        pred = predict_schedule(model, r, 2000, 10000, steps, every, pair_costs, startup)
        print(f"| {r} | {', '.join(f'{w:.1f}' for w in walls)} | {pred:.1f} |")
    print()
    cores = res["meta"].get("cores", 2)
    over = [(k, int(k.split("x")[0])) for k in ("3x1", "4x1") if k in res]
    if over:            # more ranks than cores: the schedule's structure, each rank on a share of a core
        print(f"oversubscribed, {cores} cores: wall, and each rank's output work (its tasks' and rows' "
              "seconds: the invariants and HDF5 clocks)")
        print("| ranks | measured wall [s] | predicted [s] | output work a rank, measured [s] | predicted [s] |\n"
              "|---:|---:|---:|---|---|")
        for label, r in over:
            m, pc, st = oversubscribed(model, pair_costs, startup, r / cores)
            pred, parts = predict_schedule(m, r, 2000, 10000, steps, every, pc, st, parts=True)
            work = [c.get("invariants", 0.0) + c.get("hdf5", 0.0) for c in res[label]["per_rank"]]
            print(f"| {r} | {res[label]['wall']:.1f} | {pred:.1f} | {', '.join(f'{w:.1f}' for w in work)} | "
                  f"{', '.join(f'{w:.1f}' for w in parts['fixed'])} |")
        print()
    sizes = (("paper scene", 2000, 10000), ("10⁶ points", 166_000, 913 * 913))
    ranks = (1, 2, 8, 16, 64, 256, 1024)
    head = "| design | set | " + " | ".join(f"{r}" for r in ranks) + " |"
    print(head + "\n|---|---|" + "---:|" * len(ranks))
    for label, kw in DESIGNS:
        for name, nl, ns in sizes:
            one = predict_schedule(model, 1, nl, ns, 1000, every, pair_costs, startup, **kw)
            cells = [f"{one / predict_schedule(model, r, nl, ns, 1000, every, pair_costs, startup, **kw) / r:.0%}"
                     for r in ranks]
            print(f"| {label} | {name} | " + " | ".join(cells) + " |")
    print()
    print("weak scaling, 10⁴ points a rank (loop : surface = 1 : 5), wall relative to 1 rank:")
    print("| design | " + " | ".join(f"{r}" for r in ranks) + " |\n|---|" + "---:|" * len(ranks))
    for label, kw in DESIGNS:
        walls = []
        for r in ranks:
            n = 10_000 * r
            side = int(round((n * 5 / 6) ** 0.5))
            walls.append(predict_schedule(model, r, n - side * side, side * side, 1000, every, pair_costs,
                                          startup, **kw))
        print(f"| {label} | " + " | ".join(f"{w / walls[0]:.2f}" for w in walls) + " |")


def build_model(res):
    one = res["1x1"]
    steps, every = res["meta"]["steps"], 10
    n = 12000
    pair_costs = [v["advance"] / (n * steps) for v in one["pairs"].values()]
    outputs = len(pair_costs) * (steps // every + 1)
    from integrators import State
    ck_bytes = sum(int(np.prod(shape)) * np.dtype(dt).itemsize for shape, dt in State.schema(1, 4, 3).values())
    ck_write = res["write"]["seconds_per_byte"]
    # the 1-rank run's HDF5 phase is its rows and one checkpoint a pair (every pair is under 60 s)
    row_write = (one["phases"]["hdf5"] - len(pair_costs) * ck_write * ck_bytes * n) / outputs
    bw = res.get("transport", res["gather"])["bytes_per_second"]     # the driver's messages, as measured last
    model = dict(fits=fit_tasks(res["tasks"]), diag=res["diag_per_point"], bw=bw,
                 row_write=max(row_write, 0.0), ck_write_per_byte=ck_write, ck_bytes_per_point=ck_bytes)
    if "checkpoints" in res:      # per-rank checkpoints: a slab's write rate, rank 0's links
        ck = res["checkpoints"]
        model.update(slab_per_byte=ck["slab"]["seconds_per_byte"], link_fixed=max(ck["link"]["fixed"], 0.0),
                     link_per_slab=ck["link"]["per_slab"])
    # start-up: what the 1-rank run spent outside its phases (imports, code generation, compile cache)
    ph = one["phases"]
    startup = one["wall"] - (ph["advance"] + ph["gather"] + ph["invariants"] + ph["hdf5"])
    return model, pair_costs, startup, steps, every


def predict(args):
    res = json.loads(OUT.read_text())
    model, pair_costs, startup, steps, every = build_model(res)
    lines = ["| ranks | measured wall [s] | predicted wall [s] |", "|---:|---:|---:|"]
    for label, r in (("1x1", 1), ("2x1", 2)):           # the driver as it is: rotating owners, sets together
        pred = predict_wall(model, r, 2000, 10000, steps, every, pair_costs, startup, rotate=True)
        lines.append(f"| {r} | {res[label]['wall']:.1f} | {pred:.1f} |")
    print("\n".join(lines))
    print()
    # the paper scene at 1,000 steps, and at 10^6 points (loop 166,000, surface 913 x 913)
    big = dict(n_loop=166_000, n_surf=913 * 913)
    lines = ["| ranks | paper scene, 12,000 points: wall [s] | speed-up | 10⁶ points: wall [s] | speed-up | "
             "largest task share at 10⁶ | checkpoints' share at 10⁶ | rotating owners: paper scene speed-up "
             "(efficiency) | rotating owners: 10⁶ points speed-up (efficiency) | rotating: checkpoints' share at 10⁶ |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    base_rs = predict_wall(model, 1, 2000, 10000, 1000, every, pair_costs, startup, rotate=True)
    base_rb = predict_wall(model, 1, 166_000, 913 * 913, 1000, every, pair_costs, startup, rotate=True)
    base_s = predict_wall(model, 1, 2000, 10000, 1000, every, pair_costs, startup)
    base_b = predict_wall(model, 1, big["n_loop"], big["n_surf"], 1000, every, pair_costs, startup)
    curve = []
    fits = model["fits"]
    biggest = max(fits[("I2", f)][0] * big["n_surf"] ** fits[("I2", f)][1] for f in FORMS)   # one form alone
    for r in (1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024):
        ws = predict_wall(model, r, 2000, 10000, 1000, every, pair_costs, startup)
        wb, ck = predict_wall(model, r, big["n_loop"], big["n_surf"], 1000, every, pair_costs, startup, True)
        share = biggest * (1000 // every + 1) * len(pair_costs) / wb
        rs_ = predict_wall(model, r, 2000, 10000, 1000, every, pair_costs, startup, rotate=True)
        rb_, rck = predict_wall(model, r, big["n_loop"], big["n_surf"], 1000, every, pair_costs, startup, True,
                                rotate=True)
        curve.append((r, ws, wb, rs_, rb_))
        lines.append(f"| {r} | {ws:,.0f} | {base_s / ws:.1f} | {wb:,.0f} | {base_b / wb:.1f} | {100 * share:.0f} % "
                     f"| {100 * ck / wb:.1f} % | {base_rs / rs_:.1f} ({100 * base_rs / rs_ / r:.0f} %) "
                     f"| {base_rb / rb_:.1f} ({100 * base_rb / rb_ / r:.0f} %) | {100 * rck / rb_:.1f} % |")
    print("\n".join(lines))
    print()
    schedule_tables(model, pair_costs, startup, steps, every, res)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rs = np.array([c[0] for c in curve])
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for (label, kw), style in zip(DESIGNS, ("-", ":", "--", "-.")):
        for (name, nl, ns), marker in ((("paper scene", 2000, 10000), "o"), (("10⁶ points", 166_000, 913 * 913), "s")):
            one = predict_schedule(model, 1, nl, ns, 1000, every, pair_costs, startup, **kw)
            sp = [one / predict_schedule(model, r, nl, ns, 1000, every, pair_costs, startup, **kw) for r in rs]
            ax.loglog(rs, sp, marker + style, ms=3, lw=1, label=f"{name}: {label}")
    ax.loglog(rs, rs, "k:", lw=0.8, label="ideal")
    ax.plot([1, 2], [1, res["1x1"]["wall"] / res["2x1"]["wall"]], "r*", ms=10,
            label="measured (paper scene, this file's 1x1 and 2x1)")
    ax.set_xlabel("ranks (1 thread each)")
    ax.set_ylabel("predicted speed-up")
    ax.legend(fontsize=5.5)
    ax.grid(True, which="both", lw=0.3)
    ax.set_title("strong scaling predicted batch by batch (scripts/studies/scaling_model.py predict)", fontsize=10)
    fig.tight_layout()
    png = ROOT / "docs" / "figures" / "scaling_model.png"
    fig.savefig(png, dpi=80)
    print("wrote", png)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("measure", "predict"))
    ap.add_argument("--steps", type=int, default=1000, help="steps of the paper scene (its own: 1,000)")
    ap.add_argument("--hybrid", action="store_true", help="also 1 rank x 2 threads")
    ap.add_argument("--again", help="measure only this run (e.g. 2x1) again, or 'costs' (B and C), keeping the "
                    "rest of the file; '1x1-busy': one rank while another process keeps the second core busy; "
                    "'checkpoints': per-rank checkpoints' costs and 2 ranks side by side, in-file against per-rank")
    args = ap.parse_args()
    if args.what == "measure":
        measure(args.steps, args.hybrid, args.again)
    else:
        predict(args)


if __name__ == "__main__":
    main()
