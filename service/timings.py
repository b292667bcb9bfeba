"""Named durations of a request's stages, for its ``Server-Timing`` header."""

from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Protocol


class Checkpoint(Protocol):
    """A moment a stage may not start after (a served job's deadline)."""

    def check(self) -> None:
        """Raise the time-limit problem if the moment has passed."""


class Timings:
    """Named durations for a ``Server-Timing`` header (RFC-style ``name;dur=ms``).

    With a ``deadline`` (a served job's, :class:`service.server.jobs.Deadline`), each stage
    starts only before it: a job past its time limit stops at its next stage instead of
    running on unseen. Without one (the command line) stages are only timed.
    """

    def __init__(self, deadline: Checkpoint | None = None) -> None:
        self.durations: dict[str, float] = {}
        self.deadline = deadline

    @contextmanager
    def measure(self, name: str):
        if self.deadline is not None:
            self.deadline.check()
        start = time.perf_counter()
        try:
            yield
        finally:
            self.durations[name] = self.durations.get(name, 0.0) + time.perf_counter() - start

    def header(self) -> str:
        return ", ".join(
            f"{name};dur={seconds * 1e3:.1f}" for name, seconds in self.durations.items()
        )
