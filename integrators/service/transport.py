"""Transport: the messages between ranks during a run, and nothing else.

Three kinds, each with its tag: a batch's parts of the sample sets (to the ranks that take the
sets' tasks), a batch's pieces (errors, task values, points' states: to rank 0, which writes
them), and the next pair's plan (from rank 0).  Every send is non-blocking; a receive waits, and
:meth:`Transport.arrived` asks without waiting.  On one process nothing is sent.

Messages go through mpi4py's ``util.pkl5``: pickle protocol 5, with large arrays sent as their own
buffers instead of copied into the pickle; with the parts stacked over a batch
(tasks.Tasks.stack), 2.2–2.5 GB/s between 2 ranks here against 0.49–0.70 GB/s before
(``scripts/studies/scaling_model.py measure --again transport``; docs/scaling.md).  Those buffers are the sender's own arrays until the send
completes, so everything sent must be a copy that nobody changes afterwards: the sets' parts and
the pieces are (tasks.Tasks.parts, driver._Stream.take).
"""
from __future__ import annotations

PARTS, PIECES, PLAN = 5, 7, 9          # message tags


class Transport:
    """Non-blocking sends and probed receives over ``comm`` (MPI.COMM_WORLD or the serial stand-in)."""

    def __init__(self, comm):
        if getattr(comm, "size", 1) > 1:
            from mpi4py.util import pkl5
            comm = pkl5.Intracomm(comm)
        self.comm = comm
        self.sending = []              # requests of sends not known to be complete

    def send(self, obj, dest, tag):
        """Send ``obj`` to rank ``dest`` without waiting (pickled now)."""
        self.sending.append(self.comm.isend(obj, dest=dest, tag=tag))

    def arrived(self, sources, tag) -> bool:
        """Whether a message with ``tag`` is waiting from every rank in ``sources``."""
        return all(self.comm.iprobe(source=r, tag=tag) for r in sources)

    def receive(self, source, tag):
        """The next message with ``tag`` from ``source`` (waits for it)."""
        return self.comm.recv(source=source, tag=tag)

    def settle(self):
        """Forget the sends that have completed."""
        self.sending = [r for r in self.sending if not r.test()[0]]

    def finish(self):
        """Wait until every send has completed (at the run's end)."""
        while self.sending:
            self.sending.pop().wait()
