"""The run file as a file (integrators/service/files.py, checkpoints.py, resumable.py, reader.py): damaged,
truncated, busy and locked files told apart, a full disk and a read-only file system in one line, --force
that replaces a file only once the new run has started, and files that are never changed by a refusal."""
import os
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from integrators.cli import main as cli_main
from integrators.service import driver, files, output
from integrators.service.scene import parse_scene

from helpers import BIN, GC, LV, USER, _claim_petabytes, _finished_then_on_a_full_disk, _flip_chunk, one_line, poincare, scene


def test_a_full_disk_is_one_line_and_leaves_a_readable_file(tmp_path):
    import resource
    import signal
    scene = tmp_path / "gc.toml"
    scene.write_text(GC)
    out = tmp_path / "gc.h5"

    def limit():                              # ulimit -f: writes past 600 kB fail as on a full disk
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (600_000, 600_000))

    r = subprocess.run([str(BIN / "poincare"), "run", str(scene), "-o", str(out), "-q"], preexec_fn=limit,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 3, r.stderr[-2000:]
    assert r.stderr.count("\n") == 1 and "no space left" in r.stderr and "--resume" in r.stderr
    with h5py.File(out) as f:                 # every flushed output is there
        rows = [f["runs"][k]["t"].shape[0] for k in ("GLRK2-symmetric", "GLRK2-symplectic")]
        assert rows[0] >= 1 and all(f["runs"][k]["I1/canonical"].shape[0] == n
                                    for k, n in zip(("GLRK2-symmetric", "GLRK2-symplectic"), rows))


@pytest.mark.parametrize("make,args,msg", [
    (lambda d: None, ["-o", "{d}/missing/x.h5"], "output directory '{d}/missing' does not exist"),
    (lambda d: (d / "adir").mkdir(), ["-o", "{d}/adir", "--force"], "is a directory"),
    (lambda d: None, ["-o", "/proc/poincare-test.h5"], "cannot create output '/proc/poincare-test.h5'"),
    (lambda d: (d / "x.h5").write_text(""), ["-o", "{d}/x.h5", "--resume", "--force"], "contradict"),
])
def test_unusable_outputs_are_one_plain_line(tmp_path, capsys, make, args, msg):
    make(tmp_path)
    scene = tmp_path / "gc.toml"
    scene.write_text(GC)
    rc = cli_main(["run", str(scene), "-q", *[a.format(d=tmp_path) for a in args]])
    err = capsys.readouterr().err
    assert rc in (2, 3) and err.count("\n") == 1 and msg.format(d=tmp_path) in err, err
    assert "flags =" not in err and "errno" not in err.lower()


def test_damaged_data_and_metadata_are_reported_not_plotted(tmp_path, scene_file, capsys):
    out = tmp_path / "gc.h5"
    driver.run(parse_scene(GC), out, progress=False)
    _flip_chunk(out, "runs/GLRK2-symplectic/I1/noncanonical")
    assert cli_main(["plot", str(out), "-o", str(tmp_path / "png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and "I1/noncanonical" in err
    # a resume of the damaged file is one line too
    scene_file("gc")
    assert cli_main(["run", str(tmp_path / "gc.toml"), "-o", str(out), "--resume", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and "--force" in err
    # missing metadata (a group gone) is one line, not a KeyError traceback
    out2 = tmp_path / "gc2.h5"
    driver.run(parse_scene(GC), out2, progress=False)
    with h5py.File(out2, "r+") as f:
        del f["runs/GLRK2-symmetric/t"]
    assert cli_main(["plot", str(out2), "-o", str(tmp_path / "png2")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and "Traceback" not in err


def test_force_replaces_the_old_file_only_once_the_new_run_has_started(tmp_path):
    old = tmp_path / "a.h5"
    driver.run(scene(20), old, progress=False)
    before = old.read_bytes()

    class Kill(Exception):
        pass

    def kill(pair, step):
        raise Kill

    with pytest.raises(Kill):          # killed at its first written rows: the new file has replaced the old
        driver.run(scene(30), old, force=True, progress=False, after_output=kill)
    with h5py.File(old) as f:
        assert int(f.attrs["steps"]) == 30
    old.write_bytes(before)
    stop = driver.StopRequest()
    stop.set(KeyboardInterrupt())                 # stopped before its first step: the old file stays
    with pytest.raises(KeyboardInterrupt):
        driver.run(scene(30), old, force=True, progress=False, stop=stop)
    assert old.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["a.h5"]


def test_a_dataset_that_claims_petabytes_is_one_line_and_resume_changes_no_byte(tmp_path):
    (tmp_path / "lv.toml").write_text(LV.replace("steps = 20", "steps = 40"))
    assert poincare("run", "lv.toml", "-o", "lv.h5", "-q", cwd=tmp_path).returncode == 0
    _claim_petabytes(tmp_path / "lv.h5")
    before = (tmp_path / "lv.h5").read_bytes()
    r = poincare("plot", "lv.h5", "-o", "png", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "damaged")
    (tmp_path / "lv.toml").write_text(LV.replace("steps = 20", "steps = 60"))
    r = poincare("run", "lv.toml", "-o", "lv.h5", "-q", "--resume", cwd=tmp_path)
    assert r.returncode == 2
    one_line(r, "damaged", "--force")
    assert (tmp_path / "lv.h5").read_bytes() == before


@pytest.mark.slow
def test_a_few_flipped_bits_never_give_a_traceback_or_change_a_refused_file():
    script = Path(__file__).parents[1] / "scripts" / "studies" / "guide_damaged_files.py"
    r = subprocess.run([sys.executable, str(script), "--flips", "4", "--seed", "3", "--below", "40000",
                        "--offsets", "15062", "39781:5"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "6 flips in a" in r.stdout and ": 0 broke a rule" in r.stdout


def test_a_file_another_run_is_writing_is_called_busy_not_damaged(tmp_path):
    out = tmp_path / "lv.h5"
    driver.run(scene(20), out, progress=False)
    code = "import h5py, sys, time; f = h5py.File(sys.argv[1], 'r+'); print('open', flush=True); time.sleep(60)"
    holder = subprocess.Popen([sys.executable, "-c", code, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "open"
        r = poincare("plot", str(out), "-o", str(tmp_path / "png"))
        assert r.returncode == 2
        one_line(r, "open for writing by another process")
        (tmp_path / "lv.toml").write_text(LV.replace("steps = 20", "steps = 30"))
        r = poincare("run", "lv.toml", "-o", str(out), "--resume", "-q", cwd=tmp_path)
        assert r.returncode == 2
        one_line(r, "another process")
        before = out.read_bytes()
        r = poincare("run", "lv.toml", "-o", str(out), "--force", "-q", cwd=tmp_path)
        assert r.returncode == 2 and out.read_bytes() == before
        one_line(r, "another process")
    finally:
        holder.kill()
        holder.wait()


def test_resume_on_a_read_only_file_system_exits_3_and_changes_nothing(tmp_path, scene_file, monkeypatch, capsys):
    from integrators.service import output
    out = tmp_path / "lv.h5"
    scene_file("lv")
    driver.run(scene(20), out, progress=False)
    before = out.read_bytes()
    real = output.h5py.File

    def read_only(name, mode="r", *a, **k):
        if mode != "r":
            raise OSError(30, "Read-only file system")
        return real(name, mode, *a, **k)

    monkeypatch.setattr(output.h5py, "File", read_only)
    assert cli_main(["run", str(tmp_path / "lv.toml"), "-o", str(out), "--resume", "--steps", "30", "-q"]) == 3
    assert "Read-only file system" in capsys.readouterr().err and out.read_bytes() == before


def test_a_full_disk_before_any_row_says_nothing_was_written(tmp_path, monkeypatch):
    from integrators.service import files
    monkeypatch.setattr(files, "available_bytes", lambda path: 0.0)
    with pytest.raises(files.OutputError, match="the file holds no output yet"):
        driver.run(scene(20), tmp_path / "a.h5", progress=False)


def test_a_run_and_its_pairs_have_a_short_repr(tmp_path):
    from integrators.service import read_run
    driver.run(scene(20), tmp_path / "a.h5", progress=False)
    run = read_run(tmp_path / "a.h5")
    assert "\n" not in repr(run) and len(repr(run)) < 200 and "2 ok" in repr(run)
    assert "\n" not in repr(run["GLRK2-none"]) and "3 outputs" in repr(run["GLRK2-none"])


def test_force_never_replaces_what_is_not_a_regular_file(tmp_path):
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="is not a regular file"):
        driver.run(scene(20), fifo, force=True, progress=False)
    assert not fifo.is_file() and fifo.exists()


def test_force_through_a_symlink_replaces_its_target(tmp_path):
    target, link = tmp_path / "data" / "a.h5", tmp_path / "a.h5"
    target.parent.mkdir()
    driver.run(scene(20), target, progress=False)
    link.symlink_to(target)
    driver.run(scene(30), link, force=True, progress=False)
    assert link.is_symlink()
    with h5py.File(target) as f:
        assert int(f.attrs["steps"]) == 30


@pytest.mark.slow
def test_a_truncated_file_is_called_damaged_not_locked(tmp_path, scene_file):
    out = tmp_path / "lv.h5"
    driver.run(parse_scene(LV), out, progress=False)
    clean = out.read_bytes()
    scene_file("lv")
    for size in (512, 1024, 2048, 4096, len(clean) // 2):
        out.write_bytes(clean[:size])
        for args in (("plot", str(out), "-o", str(tmp_path / "png")),
                     ("run", "lv.toml", "-o", str(out), "--resume", "-q")):
            r = poincare(*args, cwd=tmp_path)
            assert r.returncode == 2, (size, r.stderr)
            one_line(r, "damaged")
            assert "another process" not in r.stderr and "lock" not in r.stderr.replace("sblock", ""), r.stderr
        assert out.read_bytes() == clean[:size]


def test_lock_errors_are_told_from_damage():
    assert files.is_lock_error(BlockingIOError(11, "Resource temporarily unavailable"))
    assert files.is_lock_error(OSError("Unable to open file (unable to lock file, errno = 11, error message = "
                                        "'Resource temporarily unavailable')"))
    assert not files.is_lock_error(OSError("Unable to open file (bad object header version number)"))
    assert not files.is_lock_error(OSError("Unable to open file (truncated file: eof = 512, sblock->base_addr "
                                            "= 0, stored_eof = 96000)"))


def test_two_runs_creating_one_file_at_once(tmp_path):
    """The second of two runs that both found no file is refused as busy (exit 2), never writing
    over the first run's new file."""
    sc = parse_scene(LV)
    out = tmp_path / "a.h5"
    first = h5py.File(out, "w")                   # another run created it after our check
    try:
        with pytest.raises(files.BusyFile, match="another process"):
            output.create(out, sc, "0", 64, {}, 1e-10)
    finally:
        first.close()


@pytest.mark.parametrize("room", [1000, 20000])      # no room for the copy / for the first new output
def test_a_failed_extension_leaves_the_finished_file_byte_for_byte(tmp_path, room):
    out = tmp_path / "lv.h5"
    before, r = _finished_then_on_a_full_disk(tmp_path, room, "--resume")
    assert r.returncode == 3, r.stderr
    one_line(r, "lv.h5", "as it was")
    assert ".new" not in r.stderr
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lv.h5", "lv.toml"]     # no working copy left
    r = poincare("run", "lv.toml", "-o", "lv.h5", "--resume", "--steps", "40", "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    with h5py.File(out) as f:
        assert f["runs/GLRK2-symmetric/t"].shape[0] == 5 and f.attrs["steps"] == 40


def test_a_failed_force_names_the_file_and_says_force(tmp_path):
    out = tmp_path / "lv.h5"
    before, r = _finished_then_on_a_full_disk(tmp_path, 30000, "--force")
    assert r.returncode == 3, r.stderr
    one_line(r, "'lv.h5' failed", "as it was", "--force")
    assert ".new" not in r.stderr and "--resume" not in r.stderr
    assert out.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["lv.h5", "lv.toml"]


def test_an_os_error_during_force_abandons_the_replacement(tmp_path, monkeypatch):
    out = tmp_path / "a.h5"
    driver.run(parse_scene(LV), out, progress=False)
    before = out.read_bytes()

    def broken(*a, **k):
        raise OSError(5, "Input/output error")
    monkeypatch.setattr(output, "write_rows", broken)
    with pytest.raises(files.OutputError, match="Input/output error.*as it was.*--force"):
        driver.run(parse_scene(LV), out, force=True, progress=False)
    assert out.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["a.h5"]


def test_an_unwritable_cache_is_named(tmp_path):
    (tmp_path / "file").write_text("")
    (tmp_path / "s.toml").write_text(USER.replace("x^2 + y^2", "x^2 + y^2 + 0.125"))   # a system not yet cached
    r = poincare("run", "s.toml", "-o", "s.h5", "-q", cwd=tmp_path, env={"POINCARE_CACHE": str(tmp_path / "file/x")})
    assert r.returncode == 2 and not (tmp_path / "s.h5").exists()
    one_line(r, "$POINCARE_CACHE", str(tmp_path / "file/x"))


def test_force_replaces_only_a_run_file_of_this_tool(tmp_path):
    """--force over a text file, over an HDF5 file that is not a run file, or through a link the user
    named to a text file: refused in one line, nothing changed; a dangling -o link is named as such;
    a control character in -o is refused (issue 56)."""
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = [1.0]
    link = tmp_path / "link.h5"
    link.symlink_to(notes)
    for path, say in ((notes, "it is not an HDF5 file"), (tmp_path / "other.h5", "without a run file's 'format'"),
                      (link, "(a symbolic link to")):
        before = Path(path).read_bytes()
        with pytest.raises(ValueError, match=r"is not a run file of this tool|a symbolic link to") as e:
            driver.run(scene(20), path, force=True, progress=False)
        assert say in str(e.value) and "is not a run file of this tool" in str(e.value), str(e.value)
        assert Path(path).read_bytes() == before
    dangling = tmp_path / "dangling.h5"
    dangling.symlink_to(tmp_path / "nowhere.h5")
    with pytest.raises(ValueError, match=r"is a symbolic link to '.*nowhere.h5', which does not exist"):
        driver.run(scene(20), dangling, progress=False)
    assert not (tmp_path / "nowhere.h5").exists()
    with pytest.raises(ValueError, match="holds control characters"):
        driver.run(scene(20), tmp_path / "a\nb.h5", progress=False)
    ours = tmp_path / "ours.h5"
    driver.run(scene(20), ours, progress=False)
    driver.run(scene(30), ours, force=True, progress=False)          # a run file of this tool: replaced
    with h5py.File(ours) as f:
        assert int(f.attrs["steps"]) == 30


def test_a_resume_with_nothing_to_do_changes_no_byte_and_damage_is_refused(tmp_path):
    """A finished run resumed: the file is byte for byte what it was; a damaged file (a flipped byte
    in its superblock's area that read_run reports) is refused by --resume as by read_run (issue 56)."""
    out = tmp_path / "lv.h5"
    driver.run(scene(20), out, progress=False)
    before = out.read_bytes()
    summaries = driver.run(scene(20), out, resume=True, progress=False)
    assert out.read_bytes() == before and all(s.status == "ok" for s in summaries)
    from integrators.service.reader import read_run
    damaged = tmp_path / "damaged.h5"
    _flip_chunk(out, "runs/GLRK2-symmetric/I1/canonical")
    with pytest.raises(ValueError):
        read_run(out)
    damaged_bytes = out.read_bytes()
    with pytest.raises(ValueError, match=r"cannot resume: .*--force replaces it"):
        driver.run(scene(20), out, resume=True, progress=False)
    assert out.read_bytes() == damaged_bytes


def test_a_scene_name_is_no_path_and_plots_are_not_written_through_links(tmp_path):
    """name = "../escape" with no [output] writes _escape.h5 here, not escape.h5 in the parent;
    `poincare plot` replaces a symbolic link in the figure folder instead of writing into its
    target (issue 56)."""
    work = tmp_path / "work"
    work.mkdir()
    text = LV.replace('name = "lv"', 'name = "../escape"')
    assert text != LV
    (work / "s.toml").write_text(text.replace("steps = 20", "steps = 10"))
    r = poincare("run", "s.toml", "-q", cwd=work)
    assert r.returncode == 0, r.stderr
    assert (work / "_escape.h5").is_file() and not (tmp_path / "escape.h5").exists()
    figs = work / "figs"
    figs.mkdir()
    secret = work / "secret.txt"
    secret.write_text("keep me\n")
    (figs / "_escape_diagnostics.png").symlink_to(secret)
    r = poincare("plot", "_escape.h5", "-o", "figs", cwd=work)
    assert r.returncode == 0, r.stderr
    assert secret.read_text() == "keep me\n" and not (figs / "_escape_diagnostics.png").is_symlink()
    assert (figs / "_escape_diagnostics.png").stat().st_size > 1000
