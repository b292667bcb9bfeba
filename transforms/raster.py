"""Triangles and segments of a 2D layout drawn into a label image, vectorised: what a picture
of a flattened region (service.outputs) is painted from.

Pixel ``(row, column)`` covers ``[column, column + 1) x [row, row + 1)`` in pixel units; a
triangle paints the pixels whose centres it holds, and, so that a region of triangles smaller
than a pixel still shows as a filled area, the pixel of its centroid. Where several labels
fall on one pixel the largest wins (callers number what must stay visible highest).

The work is bounded: candidate (triangle, pixel) pairs are processed in chunks of at most
``CHUNK_PAIRS``; triangles whose bounding box is far larger than their area (long slivers)
only paint their centroid; and once ``budget`` pairs are spent the remaining triangles only
paint their centroid too (the picture is then a decimated fill).
"""

from __future__ import annotations

import numpy as np

#: Candidate pairs handled at once (bounds the temporaries: about 40 bytes a pair).
CHUNK_PAIRS = 1 << 21
#: A triangle whose box holds more than this many times its area (plus a few pixels) is a
#: sliver: the pixel centres inside it are a matter of luck, its centroid says enough.
_SLIVER_RATIO = 16.0
_SLIVER_PIXELS = 16.0


def paint_triangles(
    image: np.ndarray, corners: np.ndarray, labels: np.ndarray, budget: int = 1 << 22
) -> None:
    """Paint triangles into ``image`` in place (the largest label wins on each pixel).

    Parameters
    ----------
    image : (h, w) uint8, the label image
    corners : (m, 3, 2) float, triangle corners ``(column, row)`` in pixel units
    labels : (m,) uint8, each triangle's label (> 0)
    budget : int, candidate pairs to test in all (see the module docstring)
    """
    height, width = image.shape
    centroid = corners.mean(axis=1)
    paint_points(image, centroid, labels)
    low = np.floor(corners.min(axis=1) - 0.5).astype(np.int64) + 1  # first centre >= min
    high = np.ceil(corners.max(axis=1) - 0.5).astype(np.int64)  # last centre <= max
    np.clip(low, 0, [width, height], out=low)
    np.clip(high, -1, [width - 1, height - 1], out=high)
    spans = np.maximum(high - low + 1, 0)
    pairs = spans[:, 0] * spans[:, 1]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    filled = (pairs > 0) & (pairs <= _SLIVER_RATIO * area + _SLIVER_PIXELS)
    chosen = np.flatnonzero(filled)
    chosen = chosen[np.cumsum(pairs[chosen]) <= budget]
    for part in _chunks(pairs[chosen]):
        _paint_filled(image, corners, labels, chosen[part], low, spans, pairs)


def paint_segments(image: np.ndarray, ends: np.ndarray, label: int, budget: int = 1 << 24) -> None:
    """Draw segments one pixel wide into ``image`` in place (``np.maximum`` with ``label``).

    Parameters
    ----------
    image : (h, w) uint8
    ends : (k, 2, 2) float, each segment's two ends ``(column, row)`` in pixel units
    label : int, > 0
    budget : int, sample points to draw in all; segments beyond it are left out
    """
    steps = np.ceil(np.abs(ends[:, 1] - ends[:, 0]).max(axis=1)).astype(np.int64) + 1
    chosen = np.flatnonzero(np.cumsum(steps) <= budget)
    for part in _chunks(steps[chosen]):
        rows = chosen[part]
        count = steps[rows]
        segment = np.repeat(np.arange(len(rows)), count)
        start = np.cumsum(count) - count
        t = (np.arange(int(count.sum())) - np.repeat(start, count)) / np.maximum(
            np.repeat(count, count) - 1, 1
        )
        a, b = ends[rows, 0][segment], ends[rows, 1][segment]
        points = a + (b - a) * t[:, None]
        paint_points(image, points, np.full(len(points), label, dtype=image.dtype))


def paint_points(image: np.ndarray, points: np.ndarray, labels: np.ndarray) -> None:
    """The pixels holding ``points`` (k, 2) ``(column, row)`` take ``max(pixel, label)``,
    with ``labels`` (k,) uint8, one per point; points outside the image are left out."""
    height, width = image.shape
    column = np.floor(points[:, 0]).astype(np.int64)
    row = np.floor(points[:, 1]).astype(np.int64)
    inside = (column >= 0) & (column < width) & (row >= 0) & (row < height)
    np.maximum.at(image.ravel(), row[inside] * width + column[inside], labels[inside])


def _chunks(pairs: np.ndarray):
    """Index slices of ``pairs`` whose sums stay near ``CHUNK_PAIRS``."""
    total = np.cumsum(pairs)
    start = 0
    while start < len(pairs):
        before = total[start - 1] if start else 0
        stop = int(np.searchsorted(total, before + CHUNK_PAIRS, side="right"))
        stop = max(stop, start + 1)
        yield slice(start, stop)
        start = stop


def _paint_filled(image, corners, labels, rows, low, spans, pairs) -> None:
    """Test every pixel centre in the boxes of triangles ``rows`` and paint those inside."""
    width = image.shape[1]
    count = pairs[rows]
    owner = np.repeat(rows, count)
    offset = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    span_x = spans[owner, 0]
    column = low[owner, 0] + offset % span_x
    row = low[owner, 1] + offset // span_x
    cx, cy = column + 0.5, row + 0.5
    a, b, c = corners[owner, 0], corners[owner, 1], corners[owner, 2]

    def edge(p, q):  # twice the signed area of (p, q, centre)
        return (q[:, 0] - p[:, 0]) * (cy - p[:, 1]) - (q[:, 1] - p[:, 1]) * (cx - p[:, 0])

    w0, w1, w2 = edge(b, c), edge(c, a), edge(a, b)
    inside = ((w0 >= 0) & (w1 >= 0) & (w2 >= 0)) | ((w0 <= 0) & (w1 <= 0) & (w2 <= 0))
    np.maximum.at(image.ravel(), row[inside] * width + column[inside], labels[owner[inside]])
