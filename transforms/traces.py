"""Where planes cut a region, drawn on its map: a reference grid that shows how straight
lines on the head bend on the map (docs/math.md, section 17).

A plane ``n . p = d`` cuts a triangle whose corners lie on both sides of it along a segment
between two of its edges; each end is where its edge crosses the plane, at the fraction
``t = f_a / (f_a - f_b)`` of the edge (``f = n . p - d`` at its corners), and on the map at
the same fraction of the edge's image. A corner on the plane counts on its positive side; a
triangle the plane only touches at a corner gives no segment.
"""

from __future__ import annotations

import numpy as np


def plane_traces(
    points: np.ndarray, faces: np.ndarray, map_points: np.ndarray, normal, offsets
) -> np.ndarray:
    """(s, 2, 2) float: the segments on the map where the planes ``normal . p = offset``
    (one an offset) cut the triangles.

    Parameters
    ----------
    points : (k, 3) float, the region's vertices on the surface
    faces : (m, 3) int, indices into ``points``
    map_points : (k, 2) float, the same vertices on the map
    normal : (3,) float, the planes' common normal (unit or not: offsets are in its units)
    offsets : (n,) float
    """
    along = np.asarray(points, dtype=np.float64) @ np.asarray(normal, dtype=np.float64)
    corners_along = along[faces]
    low, high = corners_along.min(axis=1), corners_along.max(axis=1)
    pieces = []
    for offset in np.asarray(offsets, dtype=np.float64):
        cut = np.flatnonzero((low < offset) & (high >= offset))
        if not len(cut):
            continue
        side = corners_along[cut] - offset  # (c, 3)
        above = side >= 0
        ends = []
        for a, b in ((0, 1), (1, 2), (2, 0)):
            crosses = above[:, a] != above[:, b]
            gap = np.where(crosses, side[:, a] - side[:, b], 1.0)
            t = np.where(crosses, side[:, a] / gap, 0.0)
            start, stop = map_points[faces[cut, a]], map_points[faces[cut, b]]
            ends.append((crosses, start + t[:, None] * (stop - start)))
        # Exactly two edges of a cut triangle cross: take them in edge order.
        crossing = np.stack([c for c, _ in ends], axis=1)
        at = np.stack([p for _, p in ends], axis=1)  # (c, 3, 2)
        order = np.argsort(~crossing, axis=1, kind="stable")[:, :2]
        segments = np.take_along_axis(at, order[:, :, None], axis=1)
        # A corner on the plane: a point, where the next triangle has the segment.
        pieces.append(segments[(segments[:, 0] != segments[:, 1]).any(axis=1)])
    return np.concatenate(pieces) if pieces else np.zeros((0, 2, 2))


def grid_offsets(points: np.ndarray, normal, count: int) -> np.ndarray:
    """(count,) float: offsets of ``count`` planes of ``normal`` evenly spaced across the
    points' extent along it, none at its ends (``(i + 1/2) / count`` of the way)."""
    along = np.asarray(points, dtype=np.float64) @ np.asarray(normal, dtype=np.float64)
    low, high = float(along.min()), float(along.max())
    return low + (np.arange(count) + 0.5) / count * (high - low)
