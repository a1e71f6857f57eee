"""The run file's layout and writes (integrators.service.output): what `create` lays out for a scene,
rows appended and read back, pair names, and the refusals, without running an engine."""
import h5py
import numpy as np
import pytest

from integrators import TABLEAU_NAMES, PROJECTIONS
from integrators.engine import State
from integrators.service import output
from integrators.service.files import BusyFile
from integrators.service.reader import read_run
from integrators.service.scene import load_scene
from invariants import UNDER_RESOLVED


def _create(path, name="lotka_volterra"):
    scene = load_scene(name)
    n = scene.n_points
    f = output.create(path, scene, "test", n, State.schema(n, scene.system().d, scene.max_stages, scene.precision),
                      UNDER_RESOLVED)
    return scene, f


def test_create_lays_out_every_series_of_every_pair(tmp_path):
    """For the lotka_volterra scene (3 tableaus × 5 projections, a loop and a refining surface, three
    forms, energy and constraint): every pair's group holds the series its rows will fill, empty;
    breakdown times of every point at inf; both checkpoint slots with step −1 and the state's shapes;
    the root says the format, the scene's text and steps."""
    scene, f = _create(tmp_path / "r.h5")
    with f:
        assert f.attrs["format"] == output.FORMAT and f.attrs["scene"] == scene.text
        assert f.attrs["steps"] == scene.steps and f.attrs["resolution_threshold"] == UNDER_RESOLVED
        assert sorted(f["runs"]) == sorted(p.name for p in scene.pairs) and len(scene.pairs) == 15
        schema = State.schema(scene.n_points, 2, scene.max_stages, scene.precision)
        for pair in scene.pairs:
            g = f["runs"][pair.name]
            assert g.attrs["status"] == "pending"
            series = {"t"} | {f"{i}/{form}" for i in ("I1", "I2") for form in scene.forms} | \
                {f"resolution/{i}" for i in ("I1", "I2")} | {f"resolved/{i}" for i in ("I1", "I2")} | \
                {f"{d}_error" for d in scene.diagnostics} | {"points_used/I2"}
            for name in series:
                assert g[name].shape == (0,) and g[name].maxshape == (None,), name
            assert g["points_used/I2"].attrs["refine_to"] == scene.surface.refine_to
            assert np.all(np.isinf(g["breakdown_time"][()])) and g["breakdown_time"].shape == (scene.n_points,)
            for slot in ("a", "b"):
                assert g[f"checkpoint/{slot}/step"][()] == -1
                for field, (shape, dtype) in schema.items():
                    assert g[f"checkpoint/{slot}/{field}"].shape == shape and g[f"checkpoint/{slot}/{field}"].dtype == dtype


def test_rows_written_read_back_and_a_second_create_is_refused(tmp_path):
    """write_rows appends rows (the last at its step) that read_run returns as written, sets the
    breakdown times, and `create` on a path that exists is refused in one line (BusyFile)."""
    path = tmp_path / "r.h5"
    scene, f = _create(path)
    rows = [{"t": 0.1 * k, "I1/canonical": 1.0 + k, "I1/noncanonical": 2.0 + k, "I1/corrected": 3.0 + k,
             "I2/canonical": -k, "I2/noncanonical": -2.0 * k, "I2/corrected": 0.5 * k,
             "resolution/I1": 1e-15 * k, "resolution/I2": 2e-15 * k, "resolved/I1": 1, "resolved/I2": k % 2,
             "points_used/I2": 576, "energy_error": 1e-16 * k, "constraint_error": 0.0} for k in range(3)]
    name = scene.pairs[4].name
    bt = np.full(scene.n_points, np.inf)
    bt[7] = 0.2
    with f:
        output.write_rows(f, output.pair_group(f, name), 2, rows, breakdown_time=bt)
        output.wall_clock(output.pair_group(f, name), 1.5)
    run = read_run(path)[name]
    assert np.array_equal(run.t, [0.0, 0.1, 0.2])
    assert np.array_equal(run.I1["noncanonical"], [2.0, 3.0, 4.0]) and np.array_equal(run.I2["corrected"], [0, 0.5, 1])
    assert np.array_equal(run.resolved["I2"], [0, 1, 0]) and np.array_equal(run.errors["energy"], [0, 1e-16, 2e-16])
    assert np.array_equal(run.breakdown_time, bt) and run.wall_time == 1.5 and run.status == "pending"
    with pytest.raises(BusyFile, match="give each run its own -o"):
        _create(path)
    with h5py.File(path) as g:                    # the refusal changed no byte of the first run's rows
        assert np.array_equal(g["runs"][name]["t"][()], [0.0, 0.1, 0.2])


def test_pair_names_split_back_for_every_builtin_pair_and_map():
    """'GLRK2-symmetric' ↔ ('GLRK2', 'symmetric') for every built-in tableau and projection; a name
    whose tableau holds '-' (a TOML tableau 'My-GL2') and a step map ('rk4-map') split at the last '-'."""
    for tab in TABLEAU_NAMES:
        for proj in PROJECTIONS:
            assert output.split_pair_name(output.pair_name(tab, proj)) == (tab, proj)
    assert output.split_pair_name(output.pair_name("My-GL2", "none")) == ("My-GL2", "none")
    assert output.split_pair_name(output.pair_name("rk4", "map")) == ("rk4", "map")


def test_the_energy_scale_note_says_where_the_error_is_absolute(tmp_path):
    """note_energy_scale: relative everywhere, or absolute at the points where H₀ = 0, in words."""
    with h5py.File(tmp_path / "a.h5", "w") as f:
        output.note_energy_scale(f, 0, 10)
        assert f.attrs["energy_absolute_points"] == 0 and "absolute" not in f.attrs["energy_error"]
        output.note_energy_scale(f, 3, 10)
        assert f.attrs["energy_absolute_points"] == 3 and "at the 3 of 10 points where H0 = 0" in f.attrs["energy_error"]
