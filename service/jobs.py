"""Backpressure, memory and time limits for mesh jobs.

A request passes three stages, each bounded per process:

1. **uploading**: admitted as soon as its headers are in, when fewer than ``max_uploads``
   bodies are arriving and fewer than ``max_jobs + max_waiting`` jobs are queued or
   computing; otherwise refused at once with a 503, ``Retry-After`` and ``Connection: close``
   (its body is never read). An upload holds no compute slot, so slow clients cannot starve
   the computations, and its bytes are charged to the memory budget as they arrive;
2. **queued**: the body is in; the job waits for a compute slot;
3. **computing**: at most ``max_jobs`` at once. When the body is in, the job is charged what
   a reader may allocate beside its mesh (``READER_BYTES_PER_BYTE``); when the reader has
   counted the vertices and faces, before it builds their arrays, what the mesh and its
   computation may take (:func:`charge_mesh`, :func:`job_bytes`); once the picture asked for
   is known, what drawing it takes (:func:`picture_bytes`, :func:`charge`).

The memory budget (:class:`MemoryBudget`) is the bytes a process may hold for its jobs; a
charge that does not fit is a 503 (a job that could never fit, a 413), so no mix of valid
requests takes a worker past it.

The time limit runs from admission. A body still arriving at the limit gets a 408; a job
still computing gets a 504 at the limit. Its thread cannot be stopped, so it stops at its
next stage (see :class:`~service.encoding.Timings`) and holds its slot until then: the limit
bounds how long a client waits, and admission keeps counting the work that is still running.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass
from enum import Enum
from typing import TypeVar

from .observability import (
    COMPUTE_SECONDS,
    JOBS_COMPUTING,
    JOBS_IN_FLIGHT,
    MEMORY_RESERVED,
    UPLOADS_IN_PROGRESS,
)
from .problems import Problem

T = TypeVar("T")

#: The deadline of the job computing in this thread (None outside a job, as in the CLI).
current_deadline: ContextVar[Deadline | None] = ContextVar("current_deadline", default=None)
#: The ticket of the job computing in this thread (None outside a job).
current_ticket: ContextVar[Ticket | None] = ContextVar("current_ticket", default=None)

MiB = 2**20
#: What a reader may allocate per byte of its file beside its mesh (the readers keep within
#: it: see tests/test_meshio.py), charged when the body is in, on top of the body itself.
READER_BYTES_PER_BYTE = 7
#: What parsing a JSON body may take per byte (pydantic's objects, then the arrays): about
#: 20 measured for a /v1/points body, with room.
JSON_BYTES_PER_BYTE = 32
#: A computation's memory, an upper bound measured by ``make attack`` (docs/benchmarks.md):
#: a constant plus bytes per vertex and per face of the mesh; a picture (SVG or PNG) adds its
#: own raster, per pixel and per face.
JOB_BASE_BYTES = 64 * MiB
JOB_BYTES_PER_VERTEX = 200
JOB_BYTES_PER_FACE = 700
PICTURE_BASE_BYTES = 128 * MiB
PICTURE_BYTES_PER_PIXEL = 24
PICTURE_BYTES_PER_FACE = 400
#: What the map's triangles and the measuring of one zone add per region face (/v1/measure,
#: /v1/locate via the map): 308 at the peak of building them and 66 for a zone over most of a
#: million-face map, measured with tracemalloc, with room.
MAP_BYTES_PER_FACE = 450
#: What placing a site may take: its candidates and trees while placing, its values and their
#: JSON after (about 330 bytes of JSON a site).
SITE_BYTES = 2_000


class Stage(Enum):
    UPLOADING = "uploading"
    QUEUED = "queued"
    COMPUTING = "computing"
    DONE = "done"


class Busy(Problem):
    """503: no room now. ``Connection: close``, since the body (if any is still coming) is
    not read: the client reconnects after ``Retry-After``."""

    def __init__(self, what: str, retry_after: int) -> None:
        super().__init__(
            503,
            f"the service is busy: {what}; retry after {retry_after} s",
            "busy",
            headers={"Retry-After": str(retry_after), "Connection": "close"},
        )


class TooMuchMemory(Problem):
    def __init__(self, needed: int, budget: int) -> None:
        super().__init__(
            413,
            f"the job needs an estimated {needed / MiB:,.0f} MiB, more than this process's "
            f"memory budget of {budget / MiB:,.0f} MiB (MESHFLAT_MEMORY_BUDGET): send a smaller "
            "mesh or a smaller picture",
            "body-too-large",
            headers={"Connection": "close"},  # it may come while the body still arrives
        )


class TimeLimit(Problem):
    def __init__(self, seconds: float, while_reading: bool) -> None:
        if while_reading:
            status, what = 408, "the request body did not arrive"
        else:
            status, what = 504, "the job did not finish"
        super().__init__(
            status,
            f"{what} within the time limit of {seconds:g} s (MESHFLAT_REQUEST_TIMEOUT)",
            "time-limit",
            # The rest of a body is not read: the connection ends with the answer.
            headers={"Connection": "close"} if while_reading else None,
        )


class TooSlow(Problem):
    def __init__(self, rate: int, grace: float, received: int) -> None:
        super().__init__(
            408,
            f"the request body arrived slower than {rate:,} bytes/s after {grace:g} s "
            f"(MESHFLAT_MIN_UPLOAD_RATE, MESHFLAT_UPLOAD_GRACE); {received:,} bytes came",
            "time-limit",
            headers={"Connection": "close"},
        )


@dataclass(frozen=True)
class Deadline:
    """The moment (``time.monotonic``) a job must be done by."""

    at: float
    seconds: float

    @classmethod
    def after(cls, seconds: float) -> Deadline:
        return cls(time.monotonic() + seconds, seconds)

    def remaining(self) -> float:
        return self.at - time.monotonic()

    def check(self) -> None:
        """Raise the 504 problem if the deadline has passed."""
        if self.remaining() <= 0:
            raise TimeLimit(self.seconds, while_reading=False)


def job_bytes(vertices: int, faces: int) -> int:
    """The memory a computation on a mesh of that size may take (an upper bound)."""
    return JOB_BASE_BYTES + JOB_BYTES_PER_VERTEX * vertices + JOB_BYTES_PER_FACE * faces


def picture_bytes(width: int, height: int, faces: int) -> int:
    """What drawing a picture of ``width`` x ``height`` pixels of ``faces`` faces adds."""
    return (
        PICTURE_BASE_BYTES
        + PICTURE_BYTES_PER_PIXEL * width * height
        + (PICTURE_BYTES_PER_FACE * faces)
    )


def charge_mesh(vertices: int, faces: int) -> None:
    """Charge the job computing in this thread what computing on a mesh of that size may
    take (:func:`job_bytes`), when its reader has counted it and before it builds the arrays
    (``Limits.on_counts``); a second count charges only the growth."""
    ticket = current_ticket.get()
    if ticket is not None:
        ticket.charge_mesh(job_bytes(vertices, faces))


def charge(nbytes: int) -> None:
    """Charge the job computing in this thread ``nbytes`` more of its process's memory
    budget (nothing outside a job, as in the CLI).

    Raises
    ------
    Busy
        The budget has no room for it now.
    TooMuchMemory
        It is more than the whole budget.
    """
    ticket = current_ticket.get()
    if ticket is not None:
        ticket.charge(nbytes)


class MemoryBudget:
    """Bytes a process may hold for its jobs (bodies, readers, computations); thread-safe.

    ``total`` None is no limit."""

    def __init__(self, total: int | None) -> None:
        self.total, self.reserved = total, 0
        self._lock = threading.Lock()

    def take(self, nbytes: int) -> bool:
        with self._lock:
            if self.total is not None and self.reserved + nbytes > self.total:
                return False
            self.reserved += nbytes
        MEMORY_RESERVED.inc(nbytes)
        return True

    def give(self, nbytes: int) -> None:
        with self._lock:
            self.reserved -= nbytes
        MEMORY_RESERVED.dec(nbytes)


class JobGate:
    """Admission, compute slots and the memory budget of one process; thread-safe.

    Parameters
    ----------
    max_jobs : jobs computing at once
    max_waiting : jobs queued for a slot beyond those (their bodies are in)
    max_uploads : bodies arriving at once
    memory_budget : bytes for all jobs together (None: no limit)
    on_idle : called (in the gate's watcher thread) once no job has been in flight for
        ``idle_seconds`` since the last one left; once per quiet spell
    """

    def __init__(
        self,
        max_jobs: int,
        max_waiting: int,
        max_uploads: int = 256,
        memory_budget: int | None = None,
        on_idle: Callable[[], object] | None = None,
        idle_seconds: float = 1.0,
    ) -> None:
        self.max_jobs, self.limit, self.max_uploads = max_jobs, max_jobs + max_waiting, max_uploads
        self.memory = MemoryBudget(memory_budget)
        self._lock = threading.Condition()
        self._slots = threading.BoundedSemaphore(max_jobs)
        self._admitted = 0  # in any stage
        self._uploads = 0
        self._jobs = 0  # queued or computing
        self._last_departure = 0.0
        self._idle_due = False  # a job has left since on_idle last ran
        self._on_idle, self._idle_seconds = on_idle, idle_seconds
        self._watcher: threading.Thread | None = None
        self._seconds = 1.0  # running mean of a job's compute time, for Retry-After

    @property
    def in_flight(self) -> int:
        """Requests admitted and not finished, in any stage."""
        return self._admitted

    def admit(self) -> Ticket:
        """A ticket for one request whose body is about to arrive, or the 503 :class:`Busy`
        problem when the jobs or the uploads are at their bounds."""
        with self._lock:
            if self._jobs >= self.limit:
                raise self._busy(self._jobs_full())
            if self._uploads >= self.max_uploads:
                raise self._busy(
                    f"{self.max_uploads} request bodies are arriving in this process, the most "
                    "it takes (MESHFLAT_MAX_UPLOADS)"
                )
            self._admitted += 1
            self._uploads += 1
        JOBS_IN_FLIGHT.inc()
        UPLOADS_IN_PROGRESS.inc()
        return Ticket(self)

    def _jobs_full(self) -> str:
        return (
            f"{self.limit} jobs are queued or computing in this process, the most it takes "
            "(MESHFLAT_MAX_JOBS + MESHFLAT_MAX_WAITING)"
        )

    def _busy(self, what: str) -> Busy:
        # The time for the jobs ahead to clear the slots, at the recent pace: a client that
        # waits that long finds room; at least 1 s, at most a minute.
        retry = math.ceil(self._seconds * max(1, self._jobs) / self.max_jobs)
        return Busy(what, int(min(60, max(1, retry))))

    def _enqueue(self) -> None:
        with self._lock:
            if self._jobs >= self.limit:  # still uploading, for _leave to undo
                raise self._busy(self._jobs_full())
            self._uploads, self._jobs = self._uploads - 1, self._jobs + 1
        UPLOADS_IN_PROGRESS.dec()

    def _leave(self, stage: Stage, reserved: int) -> None:
        if reserved:
            self.memory.give(reserved)
        with self._lock:
            self._admitted -= 1
            if stage is Stage.UPLOADING:
                self._uploads -= 1
                UPLOADS_IN_PROGRESS.dec()
            else:
                self._jobs -= 1
            self._last_departure, self._idle_due = time.monotonic(), True
            if self._on_idle is not None and self._watcher is None:
                self._watcher = threading.Thread(target=self._watch, daemon=True)
                self._watcher.start()
            self._lock.notify()
        JOBS_IN_FLIGHT.dec()

    def _watch(self) -> None:
        """One thread per gate, for its life: waits for a quiet spell, then calls on_idle."""
        while True:
            with self._lock:
                while True:
                    if self._admitted or not self._idle_due:
                        self._lock.wait()
                        continue
                    quiet_for = self._last_departure + self._idle_seconds - time.monotonic()
                    if quiet_for > 0:
                        self._lock.wait(quiet_for)
                        continue
                    self._idle_due = False
                    break
            self._on_idle()

    def _record(self, seconds: float) -> None:
        with self._lock:
            self._seconds += 0.2 * (seconds - self._seconds)


class Ticket:
    """One admitted request: uploading, then queued (:meth:`uploaded`), then computing
    (:meth:`run`). Its admission ends exactly once: when :meth:`run` ends, or, for a job
    whose computation never started (its client left, its time ran out, it was refused),
    when :meth:`release` is called; a :meth:`run` after that does nothing. Its memory
    charges are given back then."""

    def __init__(self, gate: JobGate) -> None:
        self._gate, self._stage, self._released = gate, Stage.UPLOADING, False
        self._reserved, self._mesh_charge = 0, 0
        self._lock = threading.Lock()

    def charge(self, nbytes: int) -> None:
        """Hold ``nbytes`` more of the memory budget until the admission ends.

        Raises
        ------
        Busy
            The budget has no room for it now.
        TooMuchMemory
            The job's charges come to more than the whole budget.
        """
        memory = self._gate.memory
        if memory.total is not None and self._reserved + nbytes > memory.total:
            raise TooMuchMemory(self._reserved + nbytes, memory.total)
        if not memory.take(nbytes):
            raise self._gate._busy(
                f"the memory budget of this process ({memory.total / MiB:,.0f} MiB, "
                "MESHFLAT_MEMORY_BUDGET) is taken by the jobs in flight"
            )
        with self._lock:
            self._reserved += nbytes

    def charge_mesh(self, nbytes: int) -> None:
        """Hold ``nbytes`` for the mesh's computation, or the growth over what an earlier
        count of the same mesh held."""
        growth = nbytes - self._mesh_charge
        if growth > 0:
            self.charge(growth)
            self._mesh_charge = nbytes

    def uploaded(self) -> None:
        """The body is in: queue the job (the 503 :class:`Busy` problem when the queue is
        full)."""
        self._gate._enqueue()
        self._stage = Stage.QUEUED

    def release(self) -> None:
        """End the admission unless :meth:`run` has started (then it ends it itself)."""
        with self._lock:
            if self._released or self._stage is Stage.COMPUTING:
                return
            self._released = True
        self._gate._leave(self._stage, self._reserved)

    def run(self, work: Callable[..., T], deadline: Deadline, *args) -> T:
        """``work(*args)`` in a compute slot (blocking: call it from a worker thread), unless
        the deadline passes first."""
        with self._lock:
            if self._released:  # abandoned before this thread got to it
                raise TimeLimit(deadline.seconds, while_reading=False)
            self._stage = Stage.COMPUTING
        tokens = []
        try:
            # Wait for a slot no longer than the deadline; a job whose client has already had
            # its 504 does not start at all.
            if not self._gate._slots.acquire(timeout=max(0.0, deadline.remaining())):
                raise TimeLimit(deadline.seconds, while_reading=False)
            JOBS_COMPUTING.inc()
            started = time.monotonic()
            try:
                deadline.check()
                # Seen by Timings and charge() in this thread.
                tokens = [current_deadline.set(deadline), current_ticket.set(self)]
                result = work(*args)
                self._gate._record(time.monotonic() - started)
                return result
            finally:
                if tokens:
                    current_ticket.reset(tokens[1])
                    current_deadline.reset(tokens[0])
                COMPUTE_SECONDS.inc(time.monotonic() - started)
                JOBS_COMPUTING.dec()
                self._gate._slots.release()
        finally:
            with self._lock:
                self._released = True
            self._gate._leave(Stage.COMPUTING, self._reserved)
