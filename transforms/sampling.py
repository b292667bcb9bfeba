"""Area-weighted samples of a region's faces, for the searches that try many parameters
(the answer is always evaluated on every face)."""

from __future__ import annotations

import numpy as np


def area_sample(areas: np.ndarray, count: int) -> np.ndarray:
    """Positions of up to ``count`` faces, each picked with probability proportional to its
    area, ascending and without repeats.

    Systematic: the picks sit at evenly spaced points of the faces' cumulative area, so the
    sample depends only on the faces' areas and order, never on how the mesh is posed, and
    repeated calls agree.

    Parameters
    ----------
    areas : (m,) float, >= 0
    count : int, > 0

    Returns
    -------
    (k,) int, k <= count
    """
    m = len(areas)
    if count >= m:
        return np.arange(m)
    cumulative = np.cumsum(areas, dtype=np.float64)
    total = cumulative[-1]
    if not total > 0:
        return np.linspace(0, m - 1, count).astype(np.int64)
    picks = (np.arange(count) + 0.5) * (total / count)
    return np.unique(np.searchsorted(cumulative, picks, side="right").clip(0, m - 1))
