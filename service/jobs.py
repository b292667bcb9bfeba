"""Backpressure and time limits for mesh jobs.

A job is admitted when its request arrives, before its body is read, so that uploads count
too: at most ``max_jobs`` compute at once and ``max_waiting`` more upload or wait for a slot.
A request beyond that is refused at once with a 503 and ``Retry-After``; the queue never
grows past the bound, so memory stays bounded under any load.

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
from typing import TypeVar

from .observability import JOBS_COMPUTING, JOBS_IN_FLIGHT
from .problems import Problem

T = TypeVar("T")

#: The deadline of the job computing in this thread (None outside a job, as in the CLI).
current_deadline: ContextVar[Deadline | None] = ContextVar("current_deadline", default=None)


class Busy(Problem):
    def __init__(self, limit: int, retry_after: int) -> None:
        super().__init__(
            503,
            f"the service is busy: {limit} jobs are in flight in this process (MESHFLAT_MAX_JOBS "
            f"+ MESHFLAT_MAX_WAITING); retry after {retry_after} s",
            "busy",
            headers={"Retry-After": str(retry_after)},
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


class JobGate:
    """Admission and compute slots of one process; thread-safe.

    Parameters
    ----------
    max_jobs : jobs computing at once
    max_waiting : jobs admitted beyond those
    on_idle : called (in a timer thread) once no job has been in flight for ``idle_seconds``
    """

    def __init__(
        self,
        max_jobs: int,
        max_waiting: int,
        on_idle: Callable[[], object] | None = None,
        idle_seconds: float = 1.0,
    ) -> None:
        self.max_jobs, self.limit = max_jobs, max_jobs + max_waiting
        self._lock = threading.Lock()
        self._slots = threading.BoundedSemaphore(max_jobs)
        self._admitted = 0
        self._changes = 0  # admissions and departures, to tell a quiet second from a busy one
        self._on_idle, self._idle_seconds = on_idle, idle_seconds
        self._seconds = 1.0  # running mean of a job's compute time, for Retry-After

    @property
    def in_flight(self) -> int:
        return self._admitted

    def admit(self) -> Ticket:
        """A ticket for one job, or the 503 :class:`Busy` problem when ``limit`` are in
        flight."""
        with self._lock:
            if self._admitted >= self.limit:
                raise Busy(self.limit, self._retry_after())
            self._admitted += 1
            self._changes += 1
        JOBS_IN_FLIGHT.inc()
        return Ticket(self)

    def _retry_after(self) -> int:
        # The time for the jobs ahead to clear the slots, at the recent pace: a client that
        # waits that long finds room; at least 1 s, at most a minute.
        return int(min(60, max(1, math.ceil(self._seconds * self.limit / self.max_jobs))))

    def _leave(self) -> None:
        with self._lock:
            self._admitted -= 1
            self._changes += 1
            idle, changes = self._admitted == 0, self._changes
        JOBS_IN_FLIGHT.dec()
        if idle and self._on_idle is not None:
            timer = threading.Timer(self._idle_seconds, self._if_still_idle, args=(changes,))
            timer.daemon = True
            timer.start()

    def _if_still_idle(self, changes: int) -> None:
        with self._lock:
            if self._changes != changes:  # a job came (and maybe went) since
                return
        self._on_idle()

    def _record(self, seconds: float) -> None:
        with self._lock:
            self._seconds += 0.2 * (seconds - self._seconds)


class Ticket:
    """One admitted job: :meth:`run` computes it in a slot; the admission ends once, when
    the computation ends or (if it never starts) when :meth:`release` is called."""

    def __init__(self, gate: JobGate) -> None:
        self._gate, self._released = gate, False
        self._lock = threading.Lock()

    def release(self) -> None:
        with self._lock:
            if self._released:
                return
            self._released = True
        self._gate._leave()

    def run(self, work: Callable[..., T], deadline: Deadline, *args) -> T:
        """``work(*args)`` in a compute slot (blocking: call it from a worker thread), unless
        the deadline passes first."""
        try:
            # Wait for a slot no longer than the deadline; a job whose client has already had
            # its 504 does not start at all.
            if not self._gate._slots.acquire(timeout=max(0.0, deadline.remaining())):
                raise TimeLimit(deadline.seconds, while_reading=False)
            JOBS_COMPUTING.inc()
            try:
                deadline.check()
                started = time.monotonic()
                current_deadline.set(deadline)  # this thread's context: seen by Timings
                result = work(*args)
                self._gate._record(time.monotonic() - started)
                return result
            finally:
                JOBS_COMPUTING.dec()
                self._gate._slots.release()
        finally:
            self.release()
