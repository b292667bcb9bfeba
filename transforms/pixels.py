"""Triangles on a pixel grid, exactly: which triangle holds each pixel's centre, its weights
there, and values carried between pixels and triangles both ways (docs/math.md, section 16).

The convention is the PNG answer's: pixel ``(row, column)`` covers ``[column, column + 1) x
[row, row + 1)`` in pixel units, its centre at ``(column + 0.5, row + 0.5)``. A triangle holds
the centres ``(x, y)`` with ``y`` in its half-open span of rows and ``x`` in the half-open span
``[left, right)`` of the triangle at that ``y``: triangles that share an edge share none of
its centres and leave none out, so a tiling of the plane covers every centre once. Where
triangles overlap (a folded map) the later one in the list holds the centre.

Work is scanline by scanline and vectorised: each triangle's runs of pixel centres, one a
row, found a chunk of ``CHUNK_PAIRS`` (triangle, row) pairs at a time; then what is asked of
the pixels costs a few passes over the image (running sums), not one per pixel of a run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .parallel import run_all

#: (triangle, row) pairs handled at once (some 150 bytes of temporaries each).
CHUNK_PAIRS = 1 << 16


_COLUMNS = ("triangle", "start", "length")


@dataclass(frozen=True)
class Runs:
    """The runs of pixel centres the triangles hold: run ``k`` is triangle ``triangle[k]``
    on the ``length[k]`` pixels from flat index ``start[k]`` (``row * width + column``) on,
    in ascending order of triangles, on a ``height`` x ``width`` grid."""

    triangle: np.ndarray
    start: np.ndarray
    length: np.ndarray
    height: int
    width: int

    @classmethod
    def of(cls, corners: np.ndarray, height: int, width: int, threads: int = 1) -> Runs:
        """All the runs of ``corners`` ((m, 3, 2) float: ``(x, y)`` = ``(column, row)`` in
        pixel units) at once (:meth:`chunks` bounds the memory instead)."""
        parts = list(cls.chunks(corners, height, width, threads))
        if not parts:
            empty = np.zeros(0, dtype=np.int32)
            return cls(empty, empty.astype(np.int64), empty, height, width)
        columns = [np.concatenate([getattr(p, k) for p in parts]) for k in _COLUMNS]
        return cls(*columns, height, width)

    @classmethod
    def chunks(
        cls,
        corners: np.ndarray,
        height: int,
        width: int,
        threads: int = 1,
        *,
        chunk_pairs: int = CHUNK_PAIRS,
    ):
        """The runs of ``corners``, a chunk of about ``chunk_pairs`` (triangle, row) pairs at
        a time, in ascending order of triangles, ``threads`` chunks found at once: what is
        held stays bounded, however large the triangles are on the grid."""
        corners = np.asarray(corners, dtype=np.float64)
        y = [corners[:, k, 1] for k in range(3)]
        low, high = np.minimum(np.minimum(*y[:2]), y[2]), np.maximum(np.maximum(*y[:2]), y[2])
        first_row = np.clip(np.ceil(low - 0.5), 0, height)
        rows = np.maximum(np.clip(np.ceil(high - 0.5), 0, height) - first_row, 0)
        ends = np.cumsum(rows)
        cuts, start = [], 0
        while start < len(corners):
            budget = (ends[start - 1] if start else 0) + chunk_pairs
            stop = max(int(np.searchsorted(ends, budget, side="right")), start + 1)
            cuts.append((start, stop))
            start = stop
        step = max(threads, 1)
        for group in range(0, len(cuts), step):
            found = run_all(
                [
                    lambda start=start, stop=stop: _spans(corners[start:stop], height, width, start)
                    for start, stop in cuts[group : group + step]
                ],
                threads,
            )
            for triangle, begin, length in found:
                yield cls(triangle, begin, length, height, width)

    @property
    def stop(self) -> np.ndarray:
        return self.start + self.length

    def summed(self, prefix: np.ndarray, out: np.ndarray) -> None:
        """Add to ``out`` ((m,) float, by triangle) each triangle's sum of an image over its
        pixel centres, from the image's running sums ``prefix`` (:func:`_prefix`): a
        subtraction a run, however long."""
        self._add(out, prefix[self.stop] - prefix[self.start])

    def counted(self, out: np.ndarray) -> None:
        """Add to ``out`` ((m,), by triangle) the pixel centres each triangle holds."""
        self._add(out, self.length)

    def centres(self, count: int) -> np.ndarray:
        """(count,) int: the pixel centres each of ``count`` triangles holds."""
        out = np.zeros(count)
        self.counted(out)
        return out.astype(np.int64)

    def _add(self, out: np.ndarray, values: np.ndarray) -> None:
        """``out[t] += `` the sum of ``values`` over the runs of triangle ``t``, over this
        chunk's own span of triangles (ascending) only."""
        if len(self.triangle):
            low, high = int(self.triangle[0]), int(self.triangle[-1]) + 1
            weights = np.asarray(values, dtype=np.float64)
            out[low:high] += np.bincount(self.triangle - low, weights, minlength=high - low)

    def pixels(self, *, chunk_pairs: int = CHUNK_PAIRS):
        """Chunks of (flat pixels, their triangles), run after run in order, ``chunk_pairs``
        runs a chunk."""
        for part in range(0, len(self.start), chunk_pairs):
            yield self._pixels(np.arange(part, min(part + chunk_pairs, len(self.start))))

    def _pixels(self, runs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The flat pixels of ``runs`` and their triangles."""
        length = self.length[runs].astype(np.int64)
        run = np.repeat(runs, length)
        offset = np.arange(len(run)) - np.repeat(np.cumsum(length) - length, length)
        return self.start[run] + offset, self.triangle[run]


def _prefix(image: np.ndarray) -> np.ndarray:
    """(h * w + 1,) float: the running sums of the image's pixels, row after row, from 0."""
    prefix = np.zeros(image.size + 1)
    np.cumsum(image.ravel(), out=prefix[1:])
    return prefix


def face_ids(
    corners: np.ndarray,
    height: int,
    width: int,
    threads: int = 1,
    *,
    chunk_pairs: int = CHUNK_PAIRS,
) -> np.ndarray:
    """(height, width) int32: the triangle holding each pixel's centre, -1 where none does
    (the later one where several do).

    Parameters
    ----------
    corners : (m, 3, 2) float, the triangles' corners ``(x, y)`` = ``(column, row)`` in pixel
        units
    chunk_pairs : int, (triangle, row) pairs found at once, and runs painted at once
        (:meth:`Runs.chunks`, :meth:`Runs.pixels`): it bounds the memory held, never the
        answer
    """
    ids = np.full(height * width, -1, dtype=np.int32)
    # Later triangles paint over earlier ones.
    for runs in Runs.chunks(corners, height, width, threads, chunk_pairs=chunk_pairs):
        for pixel, triangle in runs.pixels(chunk_pairs=chunk_pairs):
            ids[pixel] = triangle
    return ids.reshape(height, width)


def _spans(corners, height: int, width: int, offset: int):
    """(triangle, flat start, length) of the row runs of one chunk of triangles (their ids
    from ``offset``), empty runs left out.

    Each triangle's corners sorted by ``y`` (top ``0``, middle ``1``, bottom ``2``), it is
    cut at ``y1`` into two trapezoids, each between the long edge ``0-2`` and a short one
    (``0-1`` above, ``1-2`` below). An edge's ``x`` at a row's centre ``c`` is ``a + c s``,
    with ``s`` its slope and ``a`` from its upper end: the same numbers in both triangles that
    share it, so a centre on it goes to exactly one (``left <= x < right``)."""
    (x0, y0), (x1, y1), (x2, y2) = _sorted_by_y(corners)
    with np.errstate(divide="ignore", invalid="ignore"):  # a level edge is never crossed
        edges = [(x0, y0, (x2 - x0) / (y2 - y0)), (x0, y0, (x1 - x0) / (y1 - y0))]
        edges.append((x1, y1, (x2 - x1) / (y2 - y1)))
        lines = [(x - y * slope, slope) for x, y, slope in edges]  # x = a + c s
    top, middle, bottom = (np.ceil(y - 0.5) for y in (y0, y1, y2))
    # The trapezoids, interleaved (a triangle's upper one, then its lower one), so that the
    # runs come in ascending order of triangles.
    begin = np.stack([top, middle], axis=1).ravel()
    end = np.stack([middle, bottom], axis=1).ravel()
    a_long, s_long = np.repeat(lines[0][0], 2), np.repeat(lines[0][1], 2)
    a_short = np.stack([lines[1][0], lines[2][0]], axis=1).ravel()
    s_short = np.stack([lines[1][1], lines[2][1]], axis=1).ravel()
    first = np.clip(begin, 0, height).astype(np.int64)
    rows = np.maximum(np.clip(end, 0, height).astype(np.int64) - first, 0)
    # Which edge is on the left: the one further left at the trapezoid's middle.
    probe = 0.5 * (begin + end)
    with np.errstate(invalid="ignore"):
        long_left = a_long + probe * s_long <= a_short + probe * s_short
    a_left, s_left = np.where(long_left, a_long, a_short), np.where(long_left, s_long, s_short)
    a_right, s_right = np.where(long_left, a_short, a_long), np.where(long_left, s_short, s_long)
    start, length, kept = _trapezoid_runs(first, rows, a_left, s_left, a_right, s_right, width)
    ids = np.repeat(np.arange(offset, offset + len(x0), dtype=np.int32), 2)
    return np.repeat(ids, rows)[kept], start, length


def _sorted_by_y(corners: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The corners ((m, 3, 2)) of each triangle as three ``(x, y)`` columns, top to bottom
    (three compare-and-swaps; ties keep their order)."""
    points = [(corners[:, k, 0], corners[:, k, 1]) for k in range(3)]
    for i, j in ((0, 1), (1, 2), (0, 1)):
        (xi, yi), (xj, yj) = points[i], points[j]
        swap = yj < yi
        points[i] = (np.where(swap, xj, xi), np.where(swap, yj, yi))
        points[j] = (np.where(swap, xi, xj), np.where(swap, yi, yj))
    return points


def _trapezoid_runs(first, rows, a_left, s_left, a_right, s_right, width: int):
    """(flat start, length, kept) of the rows of centres between two edges ``a + c s``: per
    trapezoid ``rows`` rows from ``first``; ``kept`` the pairs with a run."""
    pairs = int(rows.sum())
    row = np.repeat(first - (np.cumsum(rows) - rows), rows)
    row += np.arange(pairs)
    centre = row + 0.5
    with np.errstate(invalid="ignore"):
        left = np.repeat(a_left, rows) + centre * np.repeat(s_left, rows)
        right = np.repeat(a_right, rows) + centre * np.repeat(s_right, rows)
    begin = np.clip(np.ceil(left - 0.5), 0, width)  # left <= x < right
    stop = np.clip(np.ceil(right - 0.5), 0, width)
    kept = stop > begin  # a NaN (no area) is no run
    begin = begin[kept].astype(np.int64)
    return row[kept] * width + begin, (stop[kept].astype(np.int64) - begin).astype(np.int32), kept


def barycentric(corners: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """(height, width, 3) float32: the weights of each pixel's centre in its triangle's
    corners (0 where ``ids`` is -1): each weight is affine over the triangle
    (:func:`planes`), so a pixel's costs three products.

    Parameters
    ----------
    corners : (m, 3, 2) float, as for :func:`face_ids`
    ids : (height, width) int, from :func:`face_ids`
    """
    height, width = ids.shape
    weights = np.zeros((height, width, 3), dtype=np.float32)
    held = ids >= 0
    rows, columns = np.nonzero(held)
    triangle = ids[held]
    for k in range(3):
        values = np.zeros((len(corners), 3))
        values[:, k] = 1.0
        plane = planes(corners, values)[triangle]
        weights[rows, columns, k] = plane[:, 0] + plane[:, 1] * (columns + 0.5)
        weights[rows, columns, k] += plane[:, 2] * (rows + 0.5)
    return weights


def planes(corners: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(m, 3) float ``(a, b, c)``: the affine function ``a + b x + c y`` taking each
    triangle's corner values ``values`` ((m, 3)) at its corners ((m, 3, 2)); a degenerate
    triangle gets the constant of its corners' mean."""
    corners = np.asarray(corners, dtype=np.float64)
    (x0, y0), (x1, y1), (x2, y2) = (corners[:, k].T for k in range(3))
    v0, v1, v2 = values[:, 0], values[:, 1], values[:, 2]
    det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    with np.errstate(divide="ignore", invalid="ignore"):
        b = ((v1 - v0) * (y2 - y0) - (v2 - v0) * (y1 - y0)) / det
        c = ((x1 - x0) * (v2 - v0) - (x2 - x0) * (v1 - v0)) / det
    flat = ~(np.isfinite(b) & np.isfinite(c))
    b[flat], c[flat] = 0.0, 0.0
    a = v0 - b * x0 - c * y0
    a[flat] = values[flat].mean(axis=1)
    return np.column_stack([a, b, c])


def weights_at(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 3) float: the barycentric weights of ``points`` ((n, 2)) in ``triangles`` ((n, 3,
    2)); a degenerate triangle gives its first corner all the weight."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2, p = b - a, c - a, points - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (p[:, 0] * e2[:, 1] - p[:, 1] * e2[:, 0]) / det
        v = (e1[:, 0] * p[:, 1] - e1[:, 1] * p[:, 0]) / det
    flat = ~np.isfinite(u) | ~np.isfinite(v)
    u, v = np.where(flat, 0.0, u), np.where(flat, 0.0, v)
    return np.column_stack([1.0 - u - v, u, v])


def bilinear(
    image: np.ndarray, points: np.ndarray, weight: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The values of ``image`` ((h, w) float) at ``points`` ((n, 2) float, pixel units),
    interpolated between the four nearest pixel centres (clamped at the border), and which
    points lie on the image (within ``[0, w] x [0, h]``). With ``weight`` ((h, w) >= 0) the
    four are weighed by it too (normalised: a pixel of weight 0 takes no part), and a point
    whose four all weigh 0 is not on the image."""
    if weight is not None:
        weight = np.asarray(weight, dtype=np.float64)
        total, on = bilinear(weight, points)
        product, _ = bilinear(image * weight, points)
        with np.errstate(divide="ignore", invalid="ignore"):
            values = np.where(total > 0, product / total, 0.0)
        return values, on & (total > 0)
    height, width = image.shape
    x, y = points[:, 0] - 0.5, points[:, 1] - 0.5
    on = (points[:, 0] >= 0) & (points[:, 0] <= width) & (points[:, 1] >= 0)
    on &= points[:, 1] <= height
    x0 = np.clip(np.floor(x), 0, width - 1).astype(np.int64)
    y0 = np.clip(np.floor(y), 0, height - 1).astype(np.int64)
    x1, y1 = np.minimum(x0 + 1, width - 1), np.minimum(y0 + 1, height - 1)
    fx, fy = np.clip(x - x0, 0.0, 1.0), np.clip(y - y0, 0.0, 1.0)
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    values = top * (1 - fy) + bottom * fy
    return np.where(on, values, 0.0), on


#: Sample points of a triangle too small to hold ``MIN_CENTRES`` pixel centres: the
#: barycentric lattice of order 3 inside it (its 10 points, corners included).
_LATTICE = np.array(
    [(i / 3, j / 3, 1 - (i + j) / 3) for i in range(4) for j in range(4 - i)], dtype=np.float64
)
MIN_CENTRES = 4


def face_means(
    corners: np.ndarray,
    image: np.ndarray,
    weight: np.ndarray | None = None,
    threads: int = 1,
    held: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's mean of ``image`` over its area, and the share of it covered.

    A triangle holding at least ``MIN_CENTRES`` pixel centres takes the mean of those
    pixels (each centre standing for a pixel's area; by :meth:`Runs.sums`); a smaller one the
    mean of ``image`` interpolated (:func:`bilinear`) at the 10 points of its order-3
    barycentric lattice. ``weight`` ((h, w) in [0, 1], an alpha) weighs the pixels. The
    coverage is the share of the triangle on the image (:func:`on_image`) times the mean of
    ``weight`` over its part on it.

    Parameters
    ----------
    corners : (m, 3, 2) float, pixel units
    image : (h, w) float
    held : (h * w,) bool or None, set where a triangle holds the pixel's centre, from the
        same runs (what :func:`face_ids` would find, without finding the runs again)

    Returns
    -------
    means : (m,) float, NaN where the coverage is 0
    coverage : (m,) float in [0, 1]
    """
    height, width = image.shape
    count = len(corners)
    image = np.asarray(image, dtype=np.float64)
    planes = [image] if weight is None else [np.asarray(weight, dtype=np.float64)]
    if weight is not None:
        planes.append(planes[0] * image)
    prefixes = [_prefix(plane) for plane in planes]  # running sums along the image
    centres = np.zeros(count)
    totals = [np.zeros(count) for _ in prefixes]
    for runs in Runs.chunks(corners, height, width, threads):
        runs.counted(centres)
        for total, prefix in zip(totals, prefixes, strict=True):
            runs.summed(prefix, total)
        for pixel, _ in runs.pixels() if held is not None else ():
            held[pixel] = True
    if weight is None:
        covered, weighted = centres.copy(), totals[0]
    else:
        covered, weighted = totals
    small = np.flatnonzero(centres < MIN_CENTRES)
    if len(small):
        points = np.einsum("kc,mcd->mkd", _LATTICE, np.asarray(corners)[small]).reshape(-1, 2)
        sampled, on = bilinear(image, points)
        shade = on * (1.0 if weight is None else bilinear(weight, points)[0])
        k = len(_LATTICE)
        weighted[small] = (sampled * shade).reshape(-1, k).sum(axis=1)
        covered[small] = shade.reshape(-1, k).sum(axis=1)
        centres[small] = on.reshape(-1, k).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        means = np.where(covered > 0, weighted / covered, np.nan)
        alpha = np.where(centres > 0, covered / centres, 0.0)
    coverage = np.clip(on_image(corners, height, width) * alpha, 0.0, 1.0)
    return means, coverage


def onto_mesh(
    points: np.ndarray,
    faces: np.ndarray,
    image: np.ndarray,
    weight: np.ndarray | None = None,
    threads: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An image painted over a map carried onto the mesh (docs/math.md, section 16).

    A face takes its mean and coverage (:func:`face_means`). A vertex reads the image
    bilinearly at its map position from the pixels the map holds only (a border vertex's
    neighbours off the map are no part of it), weighed by ``weight``; a vertex whose four
    nearest centres are all off the map (the tip of a sliver on the border) takes the mean
    of its faces' values.

    Parameters
    ----------
    points : (k, 2) float, the vertices on the map, pixel units
    faces : (m, 3) int, indices into ``points``
    image : (h, w) float; ``weight`` (h, w) in [0, 1] or None, an alpha

    Returns
    -------
    vertex_values : (k,) float, NaN where the image reaches neither the vertex nor its faces
    means, coverage : (m,) float, as :func:`face_means`
    """
    height, width = image.shape
    held = np.zeros(height * width, dtype=bool)
    means, coverage = face_means(points[faces], image, weight, threads, held)
    on_map = held.reshape(height, width)
    sampled, on = bilinear(image, points, on_map if weight is None else on_map * weight)
    known = np.isfinite(means)
    corners = faces[known].ravel()
    count = np.bincount(corners, minlength=len(points))
    total = np.bincount(corners, np.repeat(means[known], 3), minlength=len(points))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(on, sampled, total / count), means, coverage


def on_image(corners: np.ndarray, height: int, width: int) -> np.ndarray:
    """(m,) float: the share of each triangle's area on the image ``[0, width] x [0,
    height]``: 1 with its corners on it, else its polygon clipped to the image (Sutherland
    and Hodgman's clipping, one side of the image at a time, vectorised) over its area."""
    corners = np.asarray(corners, dtype=np.float64)
    x, y = corners[:, :, 0], corners[:, :, 1]
    inside = ((x >= 0) & (x <= width) & (y >= 0) & (y <= height)).all(axis=1)
    share = np.ones(len(corners))
    crossing = np.flatnonzero(~inside)
    if len(crossing):
        polygon, count = corners[crossing], np.full(len(crossing), 3)
        whole = np.abs(_shoelace(polygon, count))
        for axis, bound, keep_above in (
            (0, 0.0, True),
            (0, float(width), False),
            (1, 0.0, True),
            (1, float(height), False),
        ):
            polygon, count = _clip(polygon, count, axis, bound, keep_above)
        with np.errstate(divide="ignore", invalid="ignore"):
            clipped = np.abs(_shoelace(polygon, count))
            share[crossing] = np.where(whole > 0, clipped / whole, 0.0)
    return np.clip(share, 0.0, 1.0)


def _clip(polygon: np.ndarray, count: np.ndarray, axis: int, bound: float, keep_above: bool):
    """Polygons ((k, s, 2), the first ``count`` (k,) points of each) clipped to the side of
    ``coordinate[axis] = bound`` kept: (k, s + 1, 2) and their counts."""
    slots = polygon.shape[1]
    slot = np.arange(slots)[None, :]
    real = slot < count[:, None]
    ahead_index = np.where(real, (slot + 1) % np.maximum(count[:, None], 1), 0)
    ahead = np.take_along_axis(polygon, ahead_index[:, :, None], axis=1)
    side = polygon[:, :, axis] - bound
    ahead_side = ahead[:, :, axis] - bound
    if not keep_above:
        side, ahead_side = -side, -ahead_side
    kept = real & (side >= 0)
    crosses = real & ((side >= 0) != (ahead_side >= 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.nan_to_num(side / (side - ahead_side)), 0.0, 1.0)
    meet = polygon + t[:, :, None] * (ahead - polygon)
    # Each edge gives its start when kept, then where it crosses the line.
    points = np.stack([polygon, meet], axis=2).reshape(len(polygon), -1, 2)
    valid = np.stack([kept, crosses], axis=2).reshape(len(polygon), -1)
    order = np.argsort(~valid, axis=1, kind="stable")[:, : slots + 1]
    return np.take_along_axis(points, order[:, :, None], axis=1), valid.sum(axis=1)


def _shoelace(polygon: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(k,) float: the signed areas of the polygons (k, s, 2), each its first ``count``
    points."""
    slot = np.arange(polygon.shape[1])[None, :]
    real = slot < count[:, None]
    ahead_index = np.where(real, (slot + 1) % np.maximum(count[:, None], 1), 0)
    ahead = np.take_along_axis(polygon, ahead_index[:, :, None], axis=1)
    cross = polygon[:, :, 0] * ahead[:, :, 1] - ahead[:, :, 0] * polygon[:, :, 1]
    return 0.5 * np.where(real, cross, 0.0).sum(axis=1)


def vertex_image(
    corners: np.ndarray, values: np.ndarray, height: int, width: int, threads: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Per-corner values drawn on the grid, linear inside each triangle (:func:`planes`).

    Parameters
    ----------
    corners : (m, 3, 2) float, pixel units
    values : (m, 3) float, each triangle's values at its corners

    Returns
    -------
    image : (height, width) float, 0 where no triangle holds the centre
    ids : (height, width) int32, :func:`face_ids`
    """
    plane = planes(corners, values)
    image = np.zeros(height * width)
    ids = np.full(height * width, -1, dtype=np.int32)
    for runs in Runs.chunks(corners, height, width, threads):
        start, length = runs.start, runs.length.astype(np.int64)
        triangle = runs.triangle
        # Along a run the value grows by b a pixel: v + b j at its j-th pixel, j counted
        # here from the chunk's first pixel (g) less the run's first one.
        row, column = np.divmod(start, width)
        a, b, c = plane[triangle].T
        before = np.cumsum(length) - length
        first = a + b * (column + 0.5) + c * (row + 0.5) - b * before
        pixel = np.repeat(start - before, length)
        counted = np.arange(len(pixel), dtype=np.float64)
        pixel += counted.astype(np.int64)
        ids[pixel] = np.repeat(triangle, length)
        image[pixel] = np.repeat(first, length) + counted * np.repeat(b, length)
    return image.reshape(height, width), ids.reshape(height, width)
