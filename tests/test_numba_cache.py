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


def _race(folder, locked):
    folder.mkdir()
    (folder / "kernelmod.py").write_text(textwrap.dedent(MODULE))
    (folder / "child.py").write_text(textwrap.dedent(CHILD))
    (folder / "reader.py").write_text(textwrap.dedent(READER))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(folder / "cache"))
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
