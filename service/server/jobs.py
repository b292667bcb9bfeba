"""Backpressure, memory and time limits for mesh jobs.

A request passes three stages, each bounded per process:

1. **uploading**: admitted as soon as its headers are in, when fewer than ``max_uploads``
   bodies are arriving and fewer than ``max_jobs + max_waiting`` jobs are queued or
   computing; otherwise refused at once with a 503, ``Retry-After`` and ``Connection: close``
   (its body is never read). An upload holds no compute slot, so slow clients cannot starve
   the computations, and its bytes are charged to the memory budget as they arrive;
2. **queued**: the body is in; the job waits for a compute slot;
3. **computing**: at most ``max_jobs`` at once. When the body is in, the job is charged what
   parsing it may allocate (the row's ``parse_bytes_per_byte``); then the use-case charges
   its :class:`Ticket` what each step will take before it allocates it (the mesh once its
   reader has counted it, a picture's raster, sites: the memory model of
   :mod:`service.capabilities.context`).

The memory budget (:class:`MemoryBudget`) is the bytes a process may hold for its jobs; a
charge that does not fit is a 503 (a job that could never fit, a 413), so no mix of valid
requests takes a worker past it.

The time limit runs from admission. A body still arriving at the limit gets a 408; a job
still computing gets a 504 at the limit. Its thread cannot be stopped from outside, so it
stops itself: at its next stage (see :class:`~service.timings.Timings`) or at the next
:func:`~transforms.checkpoints.checkpoint` of a long loop, whichever comes first, and holds
its slot until then (well under a second: ``make attack`` measures it). Admission keeps
counting the work that is still running.

Times are read from a clock given to the gate (``time.monotonic`` by default), so that the
idle timer and the deadlines can be tested without waiting.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import TypeVar

from transforms.checkpoints import checked

from ..observability import (
    COMPUTE_SECONDS,
    JOBS_COMPUTING,
    JOBS_IN_FLIGHT,
    MEMORY_RESERVED,
    UPLOADS_IN_PROGRESS,
)
from ..problems import Problem

T = TypeVar("T")
Clock = Callable[[], float]

MiB = 2**20


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
    """The moment (on ``clock``) a job must be done by."""

    at: float
    seconds: float
    clock: Clock = time.monotonic

    @classmethod
    def after(cls, seconds: float, clock: Clock = time.monotonic) -> Deadline:
        return cls(clock() + seconds, seconds, clock)

    def remaining(self) -> float:
        return self.at - self.clock()

    def check(self) -> None:
        """Raise the 504 problem if the deadline has passed."""
        if self.remaining() <= 0:
            raise TimeLimit(self.seconds, while_reading=False)


class MemoryBudget:
    """Bytes a process may hold for its jobs (bodies, readers, computations) and for the
    meshes it keeps (:mod:`service.meshcache`); thread-safe.

    ``total`` None is no limit. ``reclaim(nbytes)``, when set, is asked to give back at least
    ``nbytes`` (what it kept: the mesh cache) before a charge is refused; it answers the
    bytes it gave back."""

    def __init__(self, total: int | None) -> None:
        self.total, self.reserved = total, 0
        self.reclaim: Callable[[int], int] | None = None
        self._lock = threading.Lock()

    def take(self, nbytes: int, reclaiming: bool = True) -> bool:
        """Hold ``nbytes`` if they fit, after what ``reclaim`` gives back (unless not
        ``reclaiming``: the cache itself takes that way); whether they were held."""
        while True:
            with self._lock:
                short = 0 if self.total is None else self.reserved + nbytes - self.total
                if short <= 0:
                    self.reserved += nbytes
                    break
            # Outside the lock: reclaim gives back through give().
            if not reclaiming or self.reclaim is None or self.reclaim(short) <= 0:
                return False
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
    clock : the seconds of a monotonic clock (``time.monotonic``)
    watch_idle : whether a watcher thread calls :meth:`idle_check` when it is due; without
        one, the owner calls it (a test, moving its own clock)
    """

    def __init__(
        self,
        max_jobs: int,
        max_waiting: int,
        max_uploads: int = 256,
        memory_budget: int | None = None,
        on_idle: Callable[[], object] | None = None,
        idle_seconds: float = 1.0,
        clock: Clock = time.monotonic,
        watch_idle: bool = True,
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
        self.clock = clock
        self._watch_idle = watch_idle and on_idle is not None
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
            self._last_departure, self._idle_due = self.clock(), True
            if self._watch_idle and self._watcher is None:
                self._watcher = threading.Thread(target=self._watch, daemon=True)
                self._watcher.start()
            self._lock.notify()
        JOBS_IN_FLIGHT.dec()

    def _idle_left(self) -> float | None:
        """Seconds until on_idle is due (0 or less: now), or None when nothing is due (a job
        is in flight, or none has left since on_idle last ran). Call under the lock."""
        if self._on_idle is None or self._admitted or not self._idle_due:
            return None
        return self._last_departure + self._idle_seconds - self.clock()

    def idle_check(self) -> bool:
        """Call on_idle if the quiet spell since the last departure has lasted
        ``idle_seconds`` (once per spell); whether it was called."""
        with self._lock:
            left = self._idle_left()
            if left is None or left > 0:
                return False
            self._idle_due = False
        self._on_idle()
        return True

    def _watch(self) -> None:
        """One thread per gate, for its life: waits for a quiet spell, then calls on_idle."""
        while True:
            with self._lock:
                while (left := self._idle_left()) is None or left > 0:
                    self._lock.wait(left)  # None: until a job leaves
            self.idle_check()

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

    @property
    def charged(self) -> int:
        """The bytes of the memory budget charged so far (given back when the admission
        ends; this stays the total)."""
        return self._reserved

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
        try:
            # Wait for a slot no longer than the deadline; a job whose client has already had
            # its 504 does not start at all.
            if not self._gate._slots.acquire(timeout=max(0.0, deadline.remaining())):
                raise TimeLimit(deadline.seconds, while_reading=False)
            JOBS_COMPUTING.inc()
            clock = self._gate.clock
            started = clock()
            try:
                deadline.check()
                with checked(deadline.check):
                    result = work(*args)
                self._gate._record(clock() - started)
                return result
            finally:
                COMPUTE_SECONDS.inc(clock() - started)
                JOBS_COMPUTING.dec()
                self._gate._slots.release()
        finally:
            with self._lock:
                self._released = True
            self._gate._leave(Stage.COMPUTING, self._reserved)
