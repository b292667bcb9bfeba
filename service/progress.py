"""A one-line progress bar on stderr, for the command line and the batch."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager


class Progress:
    """A one-line progress bar on stderr (only on a terminal, or when asked)."""

    def __init__(self, steps: list[str], enabled: bool) -> None:
        self.steps, self.enabled, self.done = steps, enabled, 0
        self._shown = ""  # the bar as last drawn (without its carriage return)

    def begin(self, name: str) -> None:
        """The bar before the first step is done."""
        self._draw(name)

    @contextmanager
    def step(self, name: str) -> Iterator[None]:
        self._draw(name)
        yield
        self.advance(name)

    def advance(self, name: str) -> None:
        """One more step done (steps may finish in any order, as a batch's scans do)."""
        self.done += 1
        self._draw(name if self.done < len(self.steps) else "done")
        if self.enabled and self.done == len(self.steps):
            sys.stderr.write("\n")
            self._shown = ""

    @contextmanager
    def above(self) -> Iterator[None]:
        """Lines written to stderr inside go above the bar: it is wiped, then drawn again."""
        if self._shown:
            sys.stderr.write("\r" + " " * len(self._shown) + "\r")
        yield
        if self._shown:
            sys.stderr.write("\r" + self._shown)
            sys.stderr.flush()

    def _draw(self, name: str) -> None:
        if not self.enabled:
            return
        width = 24
        filled = width * self.done // len(self.steps)
        bar = "#" * filled + "-" * (width - filled)
        # Padded to the last one's length, so that a shorter name leaves nothing behind.
        shown = f"[{bar}] {self.done}/{len(self.steps)} {name:<12}".ljust(len(self._shown))
        sys.stderr.write("\r" + shown)
        sys.stderr.flush()
        self._shown = shown
