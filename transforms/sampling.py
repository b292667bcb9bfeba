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
    if not np.sum(areas) > 0:
        return np.linspace(0, m - 1, count).astype(np.int64)
    faces, _ = systematic_picks(areas, count)
    return np.unique(faces)


def systematic_picks(areas: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points at evenly spaced places of the faces' cumulative area ``areas`` ((m,),
    total > 0): the face each falls in ((count,) int) and how far into that face's area, as a
    share in [0, 1] ((count,) float). They depend on the areas and their order alone."""
    cumulative = np.cumsum(areas, dtype=np.float64)
    picks = (np.arange(count) + 0.5) * (cumulative[-1] / count)
    faces = np.searchsorted(cumulative, picks, side="right").clip(0, len(areas) - 1)
    start = cumulative[faces] - areas[faces]
    share = (picks - start) / np.maximum(areas[faces], 1e-300)
    return faces, np.clip(share, 0.0, 1.0)
