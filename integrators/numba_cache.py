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

It also makes processes that need the *same* signature compile it once: :func:`install` wraps
``Dispatcher.compile`` of every cached function in an exclusive ``flock`` on a file named by the
function's cache index and the signature (``poincare-compile/<hash>.lock`` in the cache folder).
The first process compiles and saves; the others wait on the lock and then find the code in the
cache (numba looks there first).  Without it every MPI rank of a run on a fresh machine compiled
the step kernel at the same time (a few minutes each, one per core), and so did the test suite's
workers.  Functions compile callee first-to-last in one order (the call graph has no cycles), so
two processes never wait on each other; within a process the lock is taken under numba's compiler
lock and at most once per signature (a nested compile of a held signature goes on without it).

And it keeps a cached function from outliving a change to the code it calls.  numba checks a
cached function against its own file's time stamp only, but its machine code holds every compiled
function it calls, inlined or not, from whichever module.  The kernel is split by role over
integrators/kernel/*.py and calls integrators/simd/*.py and ddouble.py: editing the Newton module
alone would leave ``advance`` cached with the old Newton in it.  So :func:`install` makes the source
stamp of every cached function of this package the stamps of all the package's modules that
compile code (:func:`compiled_sources`): a change to any of them recompiles all of them.
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
        if "PostTerm(" in str(key[0]):         # a kernel function specialised to a projection's own post
            return None                         # term: its code is cached in the generated entry that
        try:                                    # holds it (integrators.codegen.post_entry), not here
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
    _install_compile_lock()
    _install_package_stamp()
    return True


PACKAGE = os.path.dirname(os.path.abspath(__file__))
_COMPILES = ("@njit", "@overload", "@intrinsic", "@register_jitable", "@generated_jit")


def compiled_sources(root=None):
    """The package's modules that define compiled functions (a decorator of numba's in their text),
    sorted (this one only names them): what a cached function of the package may carry the machine
    code of."""
    found = []
    for folder, dirs, files in os.walk(root or PACKAGE):
        dirs[:] = sorted(x for x in dirs if not x.startswith((".", "__")))
        for name in sorted(files):
            path = os.path.join(folder, name)
            if name.endswith(".py") and path != os.path.abspath(__file__):
                with open(path, encoding="utf-8") as fh:
                    if any(mark in fh.read() for mark in _COMPILES):
                        found.append(path)
    return found


_stamps = {}


def package_stamp():
    """(path, mtime, size) of every module :func:`compiled_sources` lists, once per process."""
    if PACKAGE not in _stamps:
        _stamps[PACKAGE] = tuple((os.path.relpath(p, PACKAGE), os.stat(p).st_mtime, os.stat(p).st_size)
                                 for p in compiled_sources())
    return _stamps[PACKAGE]


def _install_package_stamp():
    from numba.core import caching
    mixin = getattr(caching, "_SourceFileBackedLocatorMixin", None)
    if mixin is None or getattr(mixin, "_poincare_stamped", False) or not hasattr(mixin, "get_source_stamp"):
        return
    own = mixin.get_source_stamp

    def get_source_stamp(self):
        stamp = own(self)
        path = os.path.abspath(getattr(self, "_py_file", ""))
        if path.startswith(PACKAGE + os.sep):
            return stamp, package_stamp()
        return stamp

    get_source_stamp.__doc__ = own.__doc__
    mixin.get_source_stamp = get_source_stamp
    mixin._poincare_stamped = True


COMPILE_LOCKS = "poincare-compile"
_held = set()                       # the compile locks this process holds (under numba's compiler lock)


def compile_lock_path(dispatcher, sig):
    """The lock file of (cached function, signature), or None for a function without a disk cache."""
    import hashlib
    from numba.core import sigutils
    cache = getattr(dispatcher, "_cache", None)
    folder = getattr(cache, "_cache_path", None)
    index = getattr(getattr(cache, "_cache_file", None), "_index_name", None)
    if folder is None or index is None:
        return None
    args, _ = sigutils.normalize_signature(sig)
    key = hashlib.sha256(f"{index}|{tuple(args)}".encode()).hexdigest()[:32]
    return os.path.join(folder, COMPILE_LOCKS, key + ".lock")


@contextlib.contextmanager
def compile_locked(path):
    """Holds the exclusive lock ``path`` (once per process: nested, or where the file cannot be
    made, the block runs without it)."""
    if path is None or path in _held:
        yield
        return
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:             # a file system without locks (some NFS mounts): compile unlocked
            yield
            return
        _held.add(path)
        yield
    finally:
        _held.discard(path)
        os.close(fd)


def _install_compile_lock():
    from numba.core import sigutils
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.dispatcher import Dispatcher
    if getattr(Dispatcher, "_poincare_compile_locked", False):
        return
    compile_ = Dispatcher.compile

    def compile(self, sig):
        args, _ = sigutils.normalize_signature(sig)
        if tuple(args) in self.overloads:       # compiled or loaded in this process already
            return compile_(self, sig)
        with global_compiler_lock:              # the file lock inside numba's: threads never wait crosswise
            with compile_locked(compile_lock_path(self, sig)):
                return compile_(self, sig)

    compile.__doc__ = compile_.__doc__
    Dispatcher.compile = compile
    Dispatcher._poincare_compile_locked = True
