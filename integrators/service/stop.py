"""Stopping a run: the request passed into :func:`integrators.service.driver.run` (no module global),
and what a signal may interrupt at once.

A signal handler may not raise wherever Python happens to be (inside h5py's destructors the
exception is swallowed), so it leaves the exception with a :class:`StopRequest`, which the driver
raises between the engine's calls.  Two places never reach such a call by themselves:

* **the user's code** (a step map, a shape, a system function: :func:`guarded` wraps each as it is
  loaded): while it runs, :func:`in_user_code` is true and the handler raises at once, so a map that
  sleeps or spins is interrupted where it is (integrators.cli);
* **a blocking call** that does not return (an MPI receive waiting for a rank stuck in user code,
  user code stuck in C): the CLI's watchdog ends the process :data:`GRACE` seconds after the signal
  if the run has not stopped by then, never inside :func:`critical` (a write to the file), so the
  file keeps every output flushed before it, as after SIGKILL.
"""
from __future__ import annotations

import contextlib
import functools
import os
import threading

GRACE = float(os.environ.get("POINCARE_STOP_GRACE", "3"))   # seconds a run has to stop by itself after a signal

_user = threading.local()            # depth of user code on this thread
_critical = [0]                      # depth of file writes on the main thread
_lock = threading.Lock()


class StopRequest:
    """A request to stop a run, passed in (``run(..., stop=...)``): ``set(exc)`` leaves an exception
    (a signal handler does, integrators.cli), which the run raises before its next engine
    call; calling the request raises it.  Raising in the handler itself would land wherever Python
    happens to be, including inside h5py's destructors, where it is swallowed."""

    def __init__(self):
        self.pending = []

    def set(self, exc):
        self.pending.append(exc)

    def clear(self):
        self.pending.clear()

    def __call__(self):
        if self.pending:
            raise self.pending.pop()


class UserCodeExit(ValueError):
    """The user's code called ``sys.exit`` (or raised SystemExit): a failure of that code, reported in
    one line like any exception it raises, never the end of the run."""


def in_user_code() -> bool:
    """Whether this thread is running the user's code (a step map, shape or system function)."""
    return getattr(_user, "depth", 0) > 0


def guarded(fn, label):
    """``fn`` (the user's code named ``label``) marked as user code while it runs, with its
    ``sys.exit`` turned into :class:`UserCodeExit`."""
    @functools.wraps(fn)
    def call(*args, **kwargs):
        _user.depth = getattr(_user, "depth", 0) + 1
        try:
            return fn(*args, **kwargs)
        except SystemExit as exc:
            raise UserCodeExit(f"{label} called sys.exit({exc.code!r})") from None
        except KeyboardInterrupt as exc:
            if getattr(exc, "from_signal", False):      # SIGINT/SIGTERM raised into it: a real stop
                raise
            raise UserCodeExit(f"{label} raised KeyboardInterrupt itself (no signal was sent)") from None
        finally:
            _user.depth -= 1
    call.__wrapped_user_code__ = fn
    return call


@contextlib.contextmanager
def critical():
    """A stretch (a write to the run file) that the watchdog must not cut short."""
    with _lock:
        _critical[0] += 1
    try:
        yield
    finally:
        with _lock:
            _critical[0] -= 1


def in_critical() -> bool:
    return _critical[0] > 0
