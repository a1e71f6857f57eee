"""numba's on-disk cache, made safe for processes that compile at the same time.

numba keeps one index per cached function (``name-<line>.py311.nbi``: signature → data file) and
one data file per compiled signature (``… .<n>.nbc``).  Saving an entry reads the index, picks the
first free number, writes the index, then writes the data file, with nothing held across the four
steps.  Two processes that finish compiling two *different* signatures of one function at the same
moment can both pick number n; when the second one's index lands before the first one's data, the
index sends signature B to signature A's machine code, and every later process that loads B from
the cache calls code compiled for A's types (numba/numba#10128 reports the segfaults).  The step
kernel is one function compiled for every (dtype, dimension, lane count), so this happens when two
runs on one machine compile two different systems' kernels together: MPI ranks of different scenes,
a parameter sweep started as separate processes, the test suite's workers.

:func:`install` wraps the index's ``save`` and ``load`` in an advisory lock (``flock``) on one file
per cache folder, ``poincare-numba.lock``: a save holds it exclusively from reading the index to
writing the data, a load shares it from reading the index to reading the data.  A save takes a few
milliseconds, so a compilation waits for nothing measurable.  Where the lock file cannot be created
(a cache folder this user may only read) or ``fcntl`` does not exist (Windows), numba's own
behaviour is kept.  A save that cannot be written (a full disk, a file-size limit) is dropped
instead of failing the compilation it follows: the code is compiled and runs, and the next
process compiles it again.  The package installs both on import (``integrators/__init__.py``).
"""
from __future__ import annotations

import contextlib
import os

try:
    import fcntl
except ImportError:                 # Windows: numba's behaviour as it is
    fcntl = None

LOCK_NAME = "poincare-numba.lock"


@contextlib.contextmanager
def _locked(folder: str, exclusive: bool):
    """Holds the folder's lock (exclusive or shared) while the block runs; nothing when it cannot."""
    try:
        fd = os.open(os.path.join(folder, LOCK_NAME), os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        yield
    finally:
        os.close(fd)                # closing the descriptor releases the lock


def install() -> bool:
    """Wraps numba's index ``save`` and ``load`` in the cache folder's lock (once).  Returns whether
    the lock is in place."""
    if fcntl is None:
        return False
    from numba.core import caching
    cls = caching.IndexDataCacheFile
    if getattr(cls, "_poincare_locked", False):
        return True
    if not (hasattr(cls, "save") and hasattr(cls, "load")):     # a numba whose cache is laid out otherwise
        return False
    save, load = cls.save, cls.load

    def locked_save(self, key, data):
        try:
            os.makedirs(self._cache_path, exist_ok=True)
            with _locked(self._cache_path, exclusive=True):
                return save(self, key, data)
        except OSError:             # a full disk, a file-size limit: the code compiled is in memory and
            return None             # runs; only the next process compiles it again (numba would raise)

    def locked_load(self, key):
        with _locked(self._cache_path, exclusive=False):
            return load(self, key)

    locked_save.__doc__, locked_load.__doc__ = save.__doc__, load.__doc__
    cls.save, cls.load = locked_save, locked_load
    cls._poincare_locked = True
    return True
