"""A request to stop a run, passed into :func:`integrators.service.driver.run` (no module global)."""


class StopRequest:
    """A request to stop a run, passed in (``run(..., stop=...)``): ``set(exc)`` leaves an exception
    (a signal handler does, integrators.service.cli), which the run raises before its next engine
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
