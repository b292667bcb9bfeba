"""Lines and whitespace-separated tokens of the text formats (OBJ, ASCII PLY), found in
whole-buffer numpy passes: no Python loop over lines."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SPACE, TAB, CR, LF = 32, 9, 13, 10


def is_blank(values: np.ndarray) -> np.ndarray:
    """Where bytes are spaces, tabs, carriage returns or line feeds."""
    return (values == SPACE) | (values == TAB) | (values == CR) | (values == LF)


def parse_numbers(text: bytes, dtype, expected: int) -> np.ndarray | None:
    """The whitespace-separated numbers of ``text``, or None unless every one of its
    ``expected`` tokens is a number of ``dtype``."""
    try:
        values = np.fromstring(text, dtype=dtype, sep=" ")
    except ValueError:
        return None
    return values if len(values) == expected else None


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
        if len(starts) == 0:
            return cls(starts, ends, starts.copy(), np.zeros(0, dtype=np.int64))
        blank = is_blank(buffer)
        # Most lines start with their keyword: search only those that do not (a search of
        # every line among all non-blank bytes costs more than the rest of the reading).
        first = starts.copy()
        indented = np.flatnonzero(blank[starts])
        if indented.size:
            filled = np.flatnonzero(~blank)
            first[indented] = np.append(filled, len(buffer))[
                np.searchsorted(filled, starts[indented])
            ]
        token_start = ~blank
        token_start[1:] &= blank[:-1]
        # Tokens per line: a sum over each line's bytes (its line feed is never a token).
        tokens = np.add.reduceat(token_start, starts, dtype=np.int64)
        return cls(starts, ends, np.minimum(first, ends), tokens)
