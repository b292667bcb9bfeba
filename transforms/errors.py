"""The one exception type the transform core raises for bad input."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: How many offending row indices an error message lists before it summarises.
MAX_LISTED = 5


class TransformInputError(ValueError):
    """Input the transforms cannot work with, said so a person can fix it.

    Attributes
    ----------
    field : str
        The argument at fault (``"points"``, ``"sigma"``, ``"rotation"``, ...).
    indices : tuple of int
        The first offending rows (vertices, faces, points), if the fault is per row.
    """

    def __init__(self, field: str, message: str, indices: Sequence[int] = ()) -> None:
        self.field = field
        self.indices = tuple(int(i) for i in indices[:MAX_LISTED])
        self.message = message
        super().__init__(f"{field}: {message}")


_PLURALS = {"vertex": "vertices", "index": "indices"}


def listed_rows(mask: np.ndarray, noun: str = "row") -> tuple[str, list[int]]:
    """Describe the rows where ``mask`` is true: ``("rows 3, 9 (2 in all)", [3, 9])``.

    Parameters
    ----------
    mask : (n,) bool
    noun : what a row is called in the message ("row", "vertex", "face").
    """
    rows = np.flatnonzero(mask)
    shown = [int(i) for i in rows[:MAX_LISTED]]
    plural = _PLURALS.get(noun, noun + "s")
    text = f"{noun if len(rows) == 1 else plural} {', '.join(map(str, shown))}"
    if len(rows) > len(shown):
        text += f" ({len(rows)} in all)"
    return text, shown
