"""A polyline's segments on the map, before they are traced over the triangles (docs/math.md,
section 12): cut to the triangles' box, their crossings of triangle edges counted, cut into
pieces a cell long, and taken a block of pieces at a time."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from .cellgrid import MAX_CELLS_PER_SIDE, CellGrid
from .clipping import map_box
from .mapping import MapTriangles

#: Cells are this many typical triangles wide.
CELL_TRIANGLES = 2.0
#: A curve is traced this many pieces at a time (a block's pairs with the triangles, some
#: 30 a piece and 220 bytes a pair at their peak, are let go before the next).
BLOCK_PIECES = 2048
#: Outlines are cut into at most this many pieces (longer pieces past it).
MAX_PIECES = 1 << 20


@dataclass(frozen=True)
class Cut:
    """The grid a trace files segments on, and the length they are cut into pieces of.

    Attributes
    ----------
    grid : CellGrid, over the segments, cells ``CELL_TRIANGLES`` typical triangles wide
    piece : float, the cell size, or longer when there would be more than ``MAX_PIECES``
    """

    grid: CellGrid
    piece: float

    @classmethod
    def of(cls, triangles: MapTriangles, a: np.ndarray, b: np.ndarray) -> Cut:
        """The grid and the pieces' length of the segments ``a -> b`` ((E, 2) float each)."""
        points = np.concatenate([a, b])
        grid = CellGrid.covering(
            points.min(0), points.max(0), CELL_TRIANGLES * triangles.typical_size
        )
        lengths = np.linalg.norm(b - a, axis=1)
        return cls(grid, max(grid.size, float(lengths.sum()) / MAX_PIECES))

    def pieces(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(E,) int64: the pieces each segment ``a -> b`` is cut into."""
        return _piece_counts(a, b, self.piece)


def _piece_counts(a: np.ndarray, b: np.ndarray, size: float) -> np.ndarray:
    """(E,) int64: how many pieces no longer than ``size`` each segment ``a -> b`` takes."""
    return np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / size)).astype(np.int64)


def cut_pieces(a: np.ndarray, b: np.ndarray, size: float):
    """Segments ``a -> b`` cut into pieces no longer than ``size``: ``(piece_a, piece_b,
    segment, s0, s1)``."""
    counts = _piece_counts(a, b, size)
    segment = np.repeat(np.arange(len(a)), counts)
    rank = np.arange(len(segment)) - np.repeat(np.cumsum(counts) - counts, counts)
    n = counts[segment]
    s0, s1 = rank / n, (rank + 1) / n
    d = (b - a)[segment]
    piece_a = np.where((rank == 0)[:, None], a[segment], a[segment] + s0[:, None] * d)
    piece_b = np.where((rank + 1 == n)[:, None], b[segment], a[segment] + s1[:, None] * d)
    return piece_a, piece_b, segment, s0, s1


def blocks(pieces: np.ndarray, most: int = BLOCK_PIECES) -> list[tuple[int, int]]:
    """The segments, of ``pieces`` ((E,) int) pieces each, in runs ``first:last`` of at most
    ``most`` pieces (a longer segment alone)."""
    ends = np.cumsum(pieces)
    cuts = np.searchsorted(ends, np.arange(most, ends[-1], most), "right")
    bounds = np.unique(np.r_[0, cuts, len(pieces)]).tolist()
    return list(pairwise(bounds))


#: Triangle edges a segment crosses per unit of its length, over the sum of the box sides of
#: the triangles per unit of the map's area about it: about 0.88 on a scalp's even triangles
#: (1.76 edges per typical triangle size), so the count below errs high: by 1.1 to 2.6 times
#: for curves over scalps of 1.5k and 25k faces, in their denser middle and at their rims.
CROSSINGS_PER_SIDE = 1.0
#: The map's density of triangles is read on a grid of this many cells a side.
DENSITY_CELLS = 64


def curve_crossings(triangles: MapTriangles, points) -> int:
    """How many triangle edges the map polyline ``points`` ((n, 2) float, n >= 2) crosses,
    counted cheaply before :func:`transforms.lift_curve` builds them (the lifted polyline
    has a point at each, and tracing it takes memory in proportion): each segment's length
    within the triangles' box, cell by cell of a coarse grid, times ``CROSSINGS_PER_SIDE``
    times the sum of the box sides of the triangles per unit area in that cell (at least as
    much as the map's typical triangle gives), rounded up, and one a segment. An estimate
    on the high side, where the triangles are small as where they are large."""
    points = np.asarray(points, dtype=np.float64)
    a, b = within_map(triangles, points[:-1], points[1:])
    grid, density = _density(triangles)
    lengths = np.linalg.norm(b - a, axis=1)
    samples = np.maximum(1, np.ceil(lengths / grid.size)).astype(np.int64)
    total = 0.0
    for first, last in blocks(samples, BLOCK_PIECES * 64):
        count = samples[first:last]
        segment = np.repeat(np.arange(first, last), count)
        rank = np.arange(len(segment)) - np.repeat(np.cumsum(count) - count, count)
        t = (rank + 0.5) / count[segment - first]
        at = a[segment] + t[:, None] * (b - a)[segment]
        found = density[grid.rows(at[:, 1]), grid.columns(at[:, 0])]
        per_segment = np.bincount(segment - first, found, last - first) * lengths[first:last]
        total += float(np.ceil(per_segment / count).sum())
    return int(min(total, 2.0**62)) + len(a)


def _density(triangles: MapTriangles) -> tuple[CellGrid, np.ndarray]:
    """A coarse grid over the map and, in each of its cells, the triangle edges a unit of
    length crosses there: ``CROSSINGS_PER_SIDE`` times the box sides of the triangles whose
    box centres lie in the cell over its area, or twice that over the typical triangle size
    where that is more."""
    xmin, xmax, ymin, ymax = triangles.bounds
    low, high = np.array([xmin.min(), ymin.min()]), np.array([xmax.max(), ymax.max()])
    extent = float(np.max(high - low))
    # A map of mostly degenerate triangles: the trace's cells are at least this wide.
    typical = max(triangles.typical_size, extent / (2 * MAX_CELLS_PER_SIDE), 1e-300)
    grid = CellGrid.covering(low, high, extent / (DENSITY_CELLS - 3))
    cell = grid.rows((ymin + ymax) / 2) * grid.n_columns + grid.columns((xmin + xmax) / 2)
    sides = np.bincount(cell, np.maximum(xmax - xmin, ymax - ymin), grid.n_cells)
    density = CROSSINGS_PER_SIDE * sides / max(grid.size**2, 1e-300)
    density = np.maximum(density, 2 * CROSSINGS_PER_SIDE / typical)
    return grid, density.reshape(grid.n_rows, grid.n_columns)


def within_map(triangles: MapTriangles, a: np.ndarray, b: np.ndarray):
    """The segments ``a -> b`` ((E, 2) float each) cut to the triangles' box on the map,
    grown by their typical size; a segment that misses it becomes a point at its corner.

    A point far off the map (1e12 away, say) would stretch the cell grid and leave the
    region's stretch of the segment too small a share of it to be told apart. Each cut end
    is reckoned from the segment's end nearer to it, so that it keeps its precision."""
    low, high = map_box(triangles)
    d = b - a
    enter_t, enter_u = [np.zeros(len(a))], [np.ones(len(a))]  # not cut: t = 0, u = 1 - t
    leave_t, leave_u = [np.ones(len(a))], [np.zeros(len(a))]
    missed = np.zeros(len(a), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(2):
            t_low, u_low = (low[k] - a[:, k]) / d[:, k], (b[:, k] - low[k]) / d[:, k]
            t_high, u_high = (high[k] - a[:, k]) / d[:, k], (b[:, k] - high[k]) / d[:, k]
            up, down = d[:, k] > 0, d[:, k] < 0
            enter_t.append(np.where(up, t_low, np.where(down, t_high, -np.inf)))
            enter_u.append(np.where(up, u_low, u_high))
            leave_t.append(np.where(up, t_high, np.where(down, t_low, np.inf)))
            leave_u.append(np.where(up, u_high, u_low))
            missed |= ~up & ~down & ((a[:, k] < low[k]) | (a[:, k] > high[k]))
    rows = np.arange(len(a))
    enter = np.argmax(np.column_stack(enter_t), axis=1)
    leave = np.argmin(np.column_stack(leave_t), axis=1)
    t0, u0 = np.column_stack(enter_t)[rows, enter], np.column_stack(enter_u)[rows, enter]
    t1, u1 = np.column_stack(leave_t)[rows, leave], np.column_stack(leave_u)[rows, leave]
    start = np.where((t0 <= u0)[:, None], a + t0[:, None] * d, b - u0[:, None] * d)
    stop = np.where((t1 <= u1)[:, None], a + t1[:, None] * d, b - u1[:, None] * d)
    missed |= t0 > t1
    start[missed] = stop[missed] = low
    return start, stop
