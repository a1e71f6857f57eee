"""The run file as a file: opening it (HDF5 locks told from damage), its errors, the size a
dataset may claim, and the disk space an output needs."""
from __future__ import annotations

import errno
import os
import re

import h5py

class OutputError(OSError):
    """The output file could not be created or written (disk full, no permission, ...): one line."""


class DamagedFile(ValueError):
    """A run file whose metadata or data is damaged (failed checksum, missing groups)."""


class BusyFile(ValueError):
    """A run file that another process holds open for writing (HDF5's file lock)."""


def open_file(path, mode="r"):
    """h5py.File(path, mode) with one-line errors: a file locked by a run that is still writing it
    is :class:`BusyFile`, anything else that cannot be opened as HDF5 :class:`DamagedFile`."""
    if not os.path.exists(path):
        raise FileNotFoundError(f"'{path}' does not exist")
    try:
        return h5py.File(path, mode)
    except OSError as exc:
        if is_lock_error(exc):
            raise BusyFile(f"'{path}' is open for writing by another process (a run still going?): wait for it "
                           "to finish or stop it first") from None
        raise DamagedFile(f"cannot read '{path}': damaged or not an HDF5 run file ({plain_error(exc)})") from None


def is_lock_error(exc) -> bool:
    """Whether an error from opening an HDF5 file is its lock, held by another process (EAGAIN from
    HDF5's flock), and not a damaged file: HDF5's message for a bad superblock names the 'sblock'
    (a substring test for 'lock' once took a truncated file for a locked one)."""
    if isinstance(exc, BlockingIOError) or getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
        return True
    text = str(exc)
    return bool(re.search(r"unable to lock file|errno = (11|35)\b|Resource temporarily unavailable", text))


def check_size(ds, limit):
    """DamagedFile unless dataset ``ds`` claims at most ``limit`` bytes: damaged metadata can claim
    petabytes, and reading it would try to allocate them."""
    nbytes = ds.size * ds.dtype.itemsize if ds.shape is not None else 0
    if nbytes > limit:
        raise DamagedFile(f"'{ds.file.filename}' is damaged: {ds.name} claims {nbytes / 2**20:,.0f} MiB, more "
                          "than the file can hold")


def size_limit(path) -> int:
    """The most bytes a dataset of the run file ``path`` can hold: twice the file (a slot never written
    reads as zeros without taking space), and at least 16 MiB."""
    import os
    return max(2 * os.path.getsize(path), 1 << 24)


def plain_error(exc) -> str:
    """The useful part of an h5py/OS error: 'Permission denied', 'No space left on device', ..."""
    text = str(exc)
    m = re.search(r"error message = '([^']*)'", text)
    if m:
        return m.group(1)
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    m = re.search(r"\(([^()]*)\)\s*$", text)
    return m.group(1) if m else text


SPACE_MARGIN = 1 << 18      # bytes kept free beyond an output's own size (HDF5 metadata, chunk slack)


def available_bytes(path) -> float:
    """Bytes the run may still add to ``path``: the free space of its file system, and no more than
    the process's file-size limit (``ulimit -f``, which batch systems set) allows."""
    import os
    import resource
    import shutil
    from pathlib import Path
    path = Path(path)
    free = float(shutil.disk_usage(path.parent if str(path.parent) else ".").free)
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY:
        size = os.path.getsize(path) if path.exists() else 0
        free = min(free, float(soft - size))
    return free


def ensure_space(path, nbytes, where):
    """OutputError before writing when fewer than ``nbytes`` + SPACE_MARGIN bytes are available: HDF5
    reports a failed write only from object destructors (and may then crash), so the driver checks
    first and stops with the file intact up to its last output."""
    free = available_bytes(path)
    if free < nbytes + SPACE_MARGIN:
        held = f"the file holds every output up to {where}" if where else "the file holds no output yet"
        reason = (f"no space left ({free / 2**20:.2f} MiB available, the next output needs about "
                  f"{(nbytes + SPACE_MARGIN) / 2**20:.2f} MiB)")
        err = OutputError(f"{reason.replace('no space left', f'no space left for {str(path)!r}', 1)}; {held}: "
                          "free space, then run again with --resume")
        err.reason = reason
        raise err


def _read(g, name, limit=None):
    """A dataset's values; a failed checksum, a missing dataset or one that claims more bytes than
    ``limit`` is a DamagedFile naming it."""
    try:
        ds = g[name]
        if limit is not None:
            check_size(ds, limit)
        return ds[...]
    except DamagedFile:
        raise
    except (OSError, KeyError, ValueError, RuntimeError, MemoryError) as exc:
        raise DamagedFile(f"'{g.file.filename}' is damaged: cannot read {g.name}/{name} "
                          f"({plain_error(exc)})") from None


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def not_ours(path):
    """Why the existing ``path`` is not a run file of this tool (so --force may not replace it), or
    None.  A file that is HDF5 by its signature but cannot be opened (damaged: what --force is for)
    or is locked counts as ours; an HDF5 file that opens is ours when it carries the run file's
    ``format`` attribute (service/output.py)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        return f"it cannot be read ({plain_error(exc)})"
    if head != HDF5_SIGNATURE:
        return "it is not an HDF5 file"
    try:
        with h5py.File(path, "r") as f:
            if "format" not in f.attrs:
                return "it is an HDF5 file without a run file's 'format' attribute"
    except OSError:
        return None
    return None
