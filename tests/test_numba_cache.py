"""integrators/numba_cache.py: processes that compile two signatures of one cached function at the
same moment leave an index that sends each signature to its own machine code."""
import os
import subprocess
import sys
import textwrap

import pytest

MODULE = """
from numba import njit

@njit(cache=True)
def add_one(x):
    return x + 1
"""

# One compiling process.  The pauses stretch numba's save (read the index, write the index, write
# the data file) so that the two processes' steps interleave in a fixed order: both read the empty
# index; A writes index {int64: 1} at 1 s, B writes {float64: 1} at 2 s and its data file 1 at
# once; A writes its data file 1 at 4 s.  Unlocked, B's index entry ends up naming A's code (the
# order holds while the two compilations end within a second of each other).
CHILD = """
import os, sys, time
role, locked = sys.argv[1], sys.argv[2] == "locked"
if locked:
    import integrators                                   # installs the lock on import
    assert integrators.numba_cache.install()
from numba.core import caching
cls = caching.IndexDataCacheFile
save_index, save_data = cls._save_index, cls._save_data
pause = {"A": (1.0, 3.0), "B": (2.0, 0.0)}[role]

def slow_save_index(self, overloads):
    time.sleep(pause[0])
    save_index(self, overloads)

def slow_save_data(self, name, data):
    time.sleep(pause[1])
    save_data(self, name, data)

cls._save_index, cls._save_data = slow_save_index, slow_save_data
import kernelmod
open(f"ready-{role}", "w").close()
while not (os.path.exists("ready-A") and os.path.exists("ready-B")):
    time.sleep(0.002)
print(kernelmod.add_one(1 if role == "A" else 1.5))
"""

# A later process that loads both signatures from the cache.
READER = """
import kernelmod
print(kernelmod.add_one(1.5), kernelmod.add_one(1), sum(kernelmod.add_one.stats.cache_hits.values()))
"""


def _folder(folder, **scripts):
    """The module and the scripts in a fresh folder; the environment of a cache of its own."""
    folder.mkdir()
    (folder / "kernelmod.py").write_text(textwrap.dedent(MODULE))
    for name, text in scripts.items():
        (folder / f"{name}.py").write_text(textwrap.dedent(text))
    return dict(os.environ, NUMBA_CACHE_DIR=str(folder / "cache"))


def _race(folder, locked):
    env = _folder(folder, child=CHILD, reader=READER)
    mode = "locked" if locked else "plain"
    children = [subprocess.Popen([sys.executable, "child.py", role, mode], cwd=folder, env=env,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for role in "AB"]
    outs = [c.communicate(timeout=120) for c in children]
    assert [c.returncode for c in children] == [0, 0], outs
    assert [o[0].split() for o in outs] == [["2"], ["2.5"]]
    r = subprocess.run([sys.executable, "reader.py"], cwd=folder, env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout.split()


@pytest.mark.slow
def test_two_processes_saving_two_signatures_at_once_keep_each_signatures_code(tmp_path):
    # the scenario is a real race: without the lock the float64 entry loads the int64 code
    assert _race(tmp_path / "plain", locked=False)[0] == "2"
    # with it, both signatures load from the cache and give their own results
    assert _race(tmp_path / "locked", locked=True) == ["2.5", "2", "2"]


FULL = """
import resource, sys
if sys.argv[1] == "locked":
    import integrators                                   # installs the wrapper on import
resource.setrlimit(resource.RLIMIT_FSIZE, (200, 200))   # no room for numba's index or data file
import kernelmod
print(kernelmod.add_one(1.5))
"""


@pytest.mark.parametrize("mode", ["plain", "locked"])
def test_a_cache_that_cannot_be_written_does_not_fail_the_compilation(tmp_path, mode):
    (tmp_path / "kernelmod.py").write_text(textwrap.dedent(MODULE))
    (tmp_path / "full.py").write_text(textwrap.dedent(FULL))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    r = subprocess.run([sys.executable, "full.py", mode], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=120)
    if mode == "plain":                                  # numba alone: the failed save fails the call
        assert r.returncode != 0 and "File too large" in r.stderr
    else:
        assert r.returncode == 0 and r.stdout.split() == ["2.5"], r.stderr


# The same signature needed by two processes at once (MPI ranks on a fresh machine, the suite's
# workers): A holds the signature's compile lock, lets B start, waits 5 s (room for a loaded machine)
# and only then compiles and saves; B asks for the same function meanwhile.
HOLDER = """
import os, time
import integrators
from integrators import numba_cache
from numba.core import types
import kernelmod
with numba_cache.compile_locked(numba_cache.compile_lock_path(kernelmod.add_one, (types.int64,))):
    open("locked", "w").close()
    while not os.path.exists("asking"):
        time.sleep(0.002)
    time.sleep(5.0)
    print(kernelmod.add_one(1))
"""

ASKER = """
import os, sys, time
if sys.argv[1] == "locked":
    import integrators                                   # installs the locks on import
while not os.path.exists("locked"):
    time.sleep(0.002)
import kernelmod
open("asking", "w").close()
print(kernelmod.add_one(1), sum(kernelmod.add_one.stats.cache_hits.values()),
      sum(kernelmod.add_one.stats.cache_misses.values()))
"""


def _same_signature(folder, locked):
    env = _folder(folder, holder=HOLDER, asker=ASKER)
    run = [subprocess.Popen([sys.executable, *args], cwd=folder, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
           for args in (["holder.py"], ["asker.py", "locked" if locked else "plain"])]
    outs = [c.communicate(timeout=120) for c in run]
    assert [c.returncode for c in run] == [0, 0], outs
    assert outs[0][0].split() == ["2"]
    return outs[1][0].split()


def test_a_signature_two_processes_need_at_once_is_compiled_once(tmp_path):
    # unlocked, the second process compiles it too (a cache miss: nothing was saved yet)
    assert _same_signature(tmp_path / "plain", locked=False) == ["2", "0", "1"]
    # locked, it waits for the first one's compilation and loads it from the cache
    assert _same_signature(tmp_path / "locked", locked=True) == ["2", "1", "0"]


CALLER = """
from numba import njit
from callee import value

@njit(cache=True)
def outer():
    return value() + 1
"""

RUN_CALLER = """
import sys
import integrators
from integrators import numba_cache
numba_cache.PACKAGE = sys.argv[1]
sys.path.insert(0, sys.argv[1])
import caller
print(caller.outer())
"""


def test_a_change_to_a_module_a_cached_function_calls_recompiles_it(tmp_path):
    """numba checks a cached function against its own file only, but its machine code holds its
    callees': the package's stamp (every module of the package that compiles code) makes a change to
    the callee's module alone recompile the caller, which numba would load stale."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "caller.py").write_text(CALLER)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))

    def outer(body):
        (pkg / "callee.py").write_text("from numba import njit\n\n@njit\ndef value():\n    return %s\n" % body)
        out = subprocess.run([sys.executable, "-c", RUN_CALLER, str(pkg)], env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        return int(out.stdout.split()[-1])

    assert outer("1") == 2
    assert any(p.suffix == ".nbi" for p in (tmp_path / "cache").rglob("*"))     # the caller was cached
    assert outer("41") == 42                     # numba alone loads the cached caller: 2
