"""Lines and whitespace-separated tokens of the text formats (OBJ, ASCII PLY), found in
whole-buffer numpy passes: no Python loop over lines."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SPACE, TAB, CR, LF = 32, 9, 13, 10


def is_blank(values: np.ndarray) -> np.ndarray:
    """Where bytes are spaces, tabs, carriage returns or line feeds."""
    return (values == SPACE) | (values == TAB) | (values == CR) | (values == LF)


@dataclass(frozen=True)
class TextLines:
    """Line ``i`` spans bytes ``[starts[i], ends[i])`` (its line feed excluded); its first
    non-blank byte is at ``first[i]`` (``ends[i]`` on a blank line); it holds ``tokens[i]``
    whitespace-separated tokens. An empty last line after a final line feed is not a line."""

    starts: np.ndarray
    ends: np.ndarray
    first: np.ndarray
    tokens: np.ndarray

    @classmethod
    def of(cls, buffer: np.ndarray) -> TextLines:
        """The lines of ``buffer`` (uint8)."""
        newlines = np.flatnonzero(buffer == LF)
        starts = np.concatenate(([0], newlines + 1))
        ends = np.concatenate((newlines, [len(buffer)]))
        if starts[-1] == len(buffer):
            starts, ends = starts[:-1], ends[:-1]
        blank = is_blank(buffer)
        filled = np.flatnonzero(~blank)
        first = np.append(filled, len(buffer))[np.searchsorted(filled, starts)]
        token_start = ~blank
        token_start[1:] &= blank[:-1]
        token_starts = np.flatnonzero(token_start)
        tokens = np.searchsorted(token_starts, ends) - np.searchsorted(token_starts, starts)
        return cls(starts, ends, np.minimum(first, ends), tokens)
