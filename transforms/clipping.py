"""Rings cut to a box of the map: a zone's outline clipped to a little more than the map
before it is measured (docs/math.md, section 12).

A zone's part of the map is the part of its polygon inside any box that holds the map, so a
ring clipped to such a box (Sutherland-Hodgman, one half-plane at a time) is measured as
the ring itself. The clipped ring keeps the measurement within the map's scale: a vertex
drawn 1e15 away would otherwise stretch the cell grid and the pieces over the whole of its
edges, where the map's part of them is too small a share to be told apart.

The clipped ring may run along the box's sides, there and back, where the polygon leaves
the box and comes back: such runs lie outside the map and cancel in the winding number.
"""

from __future__ import annotations

import numpy as np

from .mapping import MapTriangles


def map_box(triangles: MapTriangles) -> tuple[np.ndarray, np.ndarray]:
    """``low, high`` ((2,) float each): the triangles' box on the map grown by their typical
    size, so that nothing on the box's sides meets a triangle."""
    xmin, xmax, ymin, ymax = triangles.bounds
    low = np.array([xmin.min(), ymin.min()])
    high = np.array([xmax.max(), ymax.max()])
    margin = max(triangles.typical_size, 1e-9 * float(np.max(high - low)))
    return low - margin, high + margin


def clip_ring(ring: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """A ring clipped to the box ``[low, high]`` (Sutherland-Hodgman).

    Parameters
    ----------
    ring : (n, 2) float, a closed ring (its first point not repeated)
    low, high : (2,) float, the box's corners

    Returns
    -------
    (k, 2) float: the clipped ring in the ring's own direction, no point repeating the one
    before it (the last compared with the first); empty when the ring misses the box. Its
    signed area is that of the ring's part of the box, and every point inside the box has
    the same winding number about it as about ``ring``.
    """
    points = np.asarray(ring, dtype=np.float64).reshape(-1, 2)
    for axis, bound, side in ((0, low[0], -1.0), (0, high[0], 1.0), (1, low[1], -1.0),
                              (1, high[1], 1.0)):  # fmt: skip
        if len(points) == 0:
            break
        points = _clip_half_plane(points, axis, float(bound), side)
    return _without_repeats(points)


def _clip_half_plane(points: np.ndarray, axis: int, bound: float, side: float) -> np.ndarray:
    """(k, 2) float: the ring ``points`` ((n, 2)) cut to ``side * (p[axis] - bound) <= 0``.

    Each edge that crosses the line gives the crossing, reckoned from the edge's end nearer
    to the line, so that it keeps the precision of the map's scale however far the other end
    lies."""
    following = np.roll(points, -1, axis=0)
    kept = side * (points[:, axis] - bound) <= 0
    crossing = kept != np.roll(kept, -1)
    p, q = points[crossing], following[crossing]
    near = np.abs(p[:, axis] - bound) <= np.abs(q[:, axis] - bound)
    start, end = np.where(near[:, None], p, q), np.where(near[:, None], q, p)
    t = (bound - start[:, axis]) / (end[:, axis] - start[:, axis])
    cut = start + t[:, None] * (end - start)
    cut[:, axis] = bound
    # Each edge gives its start when kept, then its crossing: (n, 2) slots, in order.
    slots = np.zeros((len(points), 2, 2))
    slots[:, 0] = points
    slots[crossing, 1] = cut
    return slots[np.column_stack([kept, crossing])]


def _without_repeats(points: np.ndarray) -> np.ndarray:
    """(k, 2) float: ``points`` without those equal to the one before them (cyclically);
    empty when fewer than three remain."""
    if len(points) == 0:
        return points
    points = points[np.any(points != np.roll(points, 1, axis=0), axis=1)]
    return points if len(points) >= 3 else np.empty((0, 2))
