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
    on_idle : called (in the gate's watcher thread) once no job has been in flight for
        ``idle_seconds`` since the last one left; once per quiet spell
    """

    def __init__(
        self,
        max_jobs: int,
        max_waiting: int,
        on_idle: Callable[[], object] | None = None,
        idle_seconds: float = 1.0,
    ) -> None:
        self.max_jobs, self.limit = max_jobs, max_jobs + max_waiting
        self._lock = threading.Condition()
        self._slots = threading.BoundedSemaphore(max_jobs)
        self._admitted = 0
        self._last_departure = 0.0
        self._idle_due = False  # a job has left since on_idle last ran
        self._on_idle, self._idle_seconds = on_idle, idle_seconds
        self._watcher: threading.Thread | None = None
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
        JOBS_IN_FLIGHT.inc()
        return Ticket(self)

    def _retry_after(self) -> int:
        # The time for the jobs ahead to clear the slots, at the recent pace: a client that
        # waits that long finds room; at least 1 s, at most a minute.
        return int(min(60, max(1, math.ceil(self._seconds * self.limit / self.max_jobs))))

    def _leave(self) -> None:
        with self._lock:
            self._admitted -= 1
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
    """One admitted job. Its admission ends exactly once: when :meth:`run` ends, or, for a job
    whose computation never started (its client left, or its time ran out first), when
    :meth:`release` is called; a :meth:`run` after that does nothing."""

    def __init__(self, gate: JobGate) -> None:
        self._gate, self._released, self._started = gate, False, False
        self._lock = threading.Lock()

    def release(self) -> None:
        """End the admission unless :meth:`run` has started (then it ends it itself)."""
        with self._lock:
            if self._released or self._started:
                return
            self._released = True
        self._gate._leave()

    def run(self, work: Callable[..., T], deadline: Deadline, *args) -> T:
        """``work(*args)`` in a compute slot (blocking: call it from a worker thread), unless
        the deadline passes first."""
        with self._lock:
            if self._released:  # abandoned before this thread got to it
                raise TimeLimit(deadline.seconds, while_reading=False)
            self._started = True
        token = None
        try:
            # Wait for a slot no longer than the deadline; a job whose client has already had
            # its 504 does not start at all.
            if not self._gate._slots.acquire(timeout=max(0.0, deadline.remaining())):
                raise TimeLimit(deadline.seconds, while_reading=False)
            JOBS_COMPUTING.inc()
            try:
                deadline.check()
                started = time.monotonic()
                token = current_deadline.set(deadline)  # seen by Timings in this thread
                result = work(*args)
                self._gate._record(time.monotonic() - started)
                return result
            finally:
                if token is not None:
                    current_deadline.reset(token)
                JOBS_COMPUTING.dec()
                self._gate._slots.release()
        finally:
            with self._lock:
                self._released = True
            self._gate._leave()
