"""Strands: guide hairs grown from sites along the growth field, kept out of the head
(docs/math.md, section 20).

A strand of length ``L`` is a polyline of ``m`` points, each segment ``L / (m - 1)`` long (the
first no longer than ``free``, the others sharing the rest).
It leaves its root along the site's direction (the exit angle), bends over towards the
field's tangent, and runs on at a clearance ``c`` above the scalp, following the field:

* ``P_0`` is the root, ``P_1 = P_0 + delta d`` (``d`` the site's direction);
* its height above the scalp then goes from ``h_1 = delta sin(a)`` towards ``c``,
  ``h_k = c + (h_1 - c) exp(-(k - 1) delta / bend)``;
* its foot on the scalp is marched on the map along the field (the map is seam-free: one
  plane, no chart to change), by the surface length the segment leaves for it, and lifted
  (the map is linear in each triangle), with the vertex normals interpolated there;
* ``P_k`` is the point ``delta`` from ``P_{k-1}`` towards ``foot + h_k n``: every segment
  keeps its length, so the arc length is ``L`` to rounding;
* a point nearer the surface than its floor (``c / 2`` past an arc length ``free`` from the
  root, ``0`` before), or behind it, is put back on the floor along the nearest surface
  point's normal (:class:`SurfaceGuard`), before the next segment starts from it.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import igl
import numpy as np

from .arrays import combine, face_cross, solve_2x2, unit_rows
from .cellgrid import CellGrid, CellIndex
from .checkpoints import checkpoint
from .growth import GrowthField, triangle_edges
from .mapping import BARYCENTRIC_SLACK, MapTriangles


@dataclass(frozen=True)
class Roots:
    """Where strands start: ``points`` (n, 3) on the surface, ``directions`` (n, 3) unit,
    ``normals`` (n, 3) unit, ``triangles`` (n,) int (positions in the region's faces) and
    ``map_points`` (n, 2)."""

    points: np.ndarray
    directions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    map_points: np.ndarray


@dataclass(frozen=True)
class Curl:
    """A helix about a strand's path: its ``radius`` and its ``period``, the length of path
    a turn takes; mesh units."""

    radius: float
    period: float


@dataclass(frozen=True)
class StrandShape:
    """How strands lie: ``points`` a strand (2 or more), the ``clearance`` above the scalp
    once bent over, the ``bend``, the arc length over which the height settles, and
    ``free``, the arc length from the root within which a strand may lie nearer the scalp
    than half the clearance (it leaves the skin there); mesh units all. With a ``curl``
    the strand turns about a path at ``clearance + curl.radius``."""

    points: int
    clearance: float
    bend: float
    free: float
    curl: Curl | None = None


class SurfaceGuard:
    """The nearest points of a triangle mesh and its outward normals there, for keeping
    points out of it: libigl's axis-aligned bounding-box tree (exact nearest points, in C++).

    Parameters
    ----------
    vertices : (k, 3) float
    faces : (m, 3) int; those of no area are left out (they bound nothing)
    outward : +1 or -1, the sign that turns the faces' winding normals outwards
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, outward: int) -> None:
        self._vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        normals, flat = unit_rows(face_cross(self._vertices, faces))
        kept = ~flat
        self._faces = np.ascontiguousarray(np.asarray(faces)[kept], dtype=np.int64)
        self._normals = outward * normals[kept]
        self._tree = igl.AABB()
        if len(self._faces):
            self._tree.init(self._vertices, self._faces)

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (p, 3) ``points``: the nearest surface points (p, 3), the outward unit normals
        of their triangles (p, 3) and the signed heights of the points above them (p,)."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        if not len(self._faces) or not len(points):
            return points.copy(), np.zeros_like(points), np.full(len(points), np.inf)
        _, face, foot = self._tree.squared_distance(self._vertices, self._faces, points)
        normal = self._normals[face]
        return foot, normal, np.einsum("pd,pd->p", points - foot, normal)


def grow_strands(
    triangles: MapTriangles,
    field: GrowthField,
    normals: np.ndarray,
    roots: Roots,
    lengths: np.ndarray,
    shape: StrandShape,
    guard: SurfaceGuard,
) -> np.ndarray:
    """(n, m, 3) float: the strands of ``roots`` (docs/math.md, section 20).

    Parameters
    ----------
    triangles : MapTriangles, the region's map and surface
    field : GrowthField, the growth field on that map
    normals : (k, 3) float, unit, the region's vertex normals, outwards
    roots : Roots
    lengths : (n,) float > 0, each strand's arc length
    shape : StrandShape
    guard : SurfaceGuard, of the whole mesh
    """
    # Strands near each other grown next to each other: the guard's queries then walk
    # nearby branches of its tree one after another (a third faster than in site order).
    order = _spatial_order(roots.points)
    roots = Roots(*(getattr(roots, part.name)[order] for part in fields(roots)))
    lengths = np.asarray(lengths, dtype=np.float64)[order]
    curl = shape.curl if shape.points > 2 else None  # a strand of one segment is straight
    if curl is None:
        grown = _paths(triangles, field, normals, roots, lengths, shape, guard)[0]
    else:
        # The helix's axis runs a radius higher, so that its lowest points keep the clearance.
        axis = replace(shape, clearance=shape.clearance + curl.radius)
        paths, ups = _paths(triangles, field, normals, roots, lengths, axis, guard)
        grown = _curled(paths, ups, lengths, shape, guard)
    strands = np.empty_like(grown)
    strands[order] = grown
    return strands


#: Cells a side of the box the roots are sorted by (:func:`_spatial_order`).
ORDER_CELLS = 64


def _spatial_order(points: np.ndarray) -> np.ndarray:
    """(n,) int: an order of ``points`` ((n, 3)) by the cells of a grid over their box,
    cell row after cell row."""
    if not len(points):
        return np.arange(0)
    low, high = points.min(axis=0), points.max(axis=0)
    size = max(float(np.max(high - low)) / ORDER_CELLS, 1e-300)
    cells = np.floor((points - low) / size).astype(np.int64)
    return np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0]))


def _paths(triangles, field, normals, roots: Roots, lengths, shape: StrandShape, guard):
    """The strands without curl, (n, m, 3), and the scalp's normal under each point (n, m,
    3), unit (the root's for the first two)."""
    n, m = len(roots.points), shape.points
    first, step = _steps(lengths, m, shape.free)
    strands = np.empty((n, m, 3))
    ups = np.empty((n, m, 3))
    strands[:, 0] = roots.points
    ups[:, :2] = roots.normals[:, None, :]
    if n == 0:
        return strands, ups
    # Out of the head too: on a concave scalp a low exit angle could take it under the skin.
    aim = roots.points + first[:, None] * roots.directions
    strands[:, 1] = _next_point(guard, roots.points, aim, first, np.zeros(n))
    rise = np.einsum("pd,pd->p", roots.directions, roots.normals)
    height = first * rise
    cells = _MapCells.of(triangles)
    foot, triangle = _marched(cells, field, roots.map_points, roots.triangles,
                              first * np.sqrt(np.clip(1.0 - rise**2, 0.0, 1.0)))  # fmt: skip
    for k in range(2, m):
        checkpoint()
        arc = first + (k - 1) * step
        settled = np.exp(-(arc - first) / shape.bend)
        target = shape.clearance + (first * rise - shape.clearance) * settled
        along = step * np.sqrt(np.clip(1.0 - ((target - height) / step) ** 2, 0.0, 1.0))
        foot, triangle = _marched(cells, field, foot, triangle, along)
        ground, ups[:, k] = _lifted(triangles, normals, foot, triangle)
        floor = np.where(arc > shape.free, 0.5 * shape.clearance, 0.0)
        strands[:, k] = _next_point(guard, strands[:, k - 1], ground + target[:, None] * ups[:, k],
                                    step, floor)  # fmt: skip
        height = target
    return strands, ups


#: Rounds of the search for the length of path whose helix has the strand's length.
CURL_ROUNDS = 12
#: The search stops once every helix's arc is this near its length (relative).
CURL_TOLERANCE = 1e-6


def _curled(paths: np.ndarray, ups: np.ndarray, lengths, shape: StrandShape, guard):
    """(n, m, 3): a helix about each path (eq. 20.2), on a length of path chosen so that the
    helix's arc length is the strand's; a strand with a point nearer the scalp than its
    floor is walked again, its segments' lengths kept (:func:`_walked`)."""
    helix = _helix_of_length(paths, ups, lengths, shape)
    n, m, _ = helix.shape
    arc = np.cumsum(np.linalg.norm(np.diff(helix, axis=1), axis=2), axis=1)
    floor = np.where(arc > shape.free, 0.5 * shape.clearance, 0.0)
    kept = _kept_out(guard, helix[:, 2:].reshape(-1, 3), floor[:, 1:].reshape(-1))
    low = np.any(kept.reshape(n, m - 2, 3) != helix[:, 2:], axis=(1, 2))
    if low.any():
        helix[low] = _walked(guard, helix[low], floor[low])
    return helix


def _helix_of_length(paths, ups, lengths, shape: StrandShape) -> np.ndarray:
    """(n, m, 3): the helices about ``paths`` whose arc lengths are ``lengths``, each the
    nearest of the search's rounds."""
    along = _Along.of(paths, ups)
    first = along.at[:, 1]  # the first segment, kept as it is
    rest = lengths - first
    # Start from a smooth helix's length, sqrt(1 + (2 pi r / p)^2) a unit of its axis; the
    # polyline's chords are shorter, so the ratio of arcs refines it (nearly proportional),
    # within a bracket that halves where the ratio would leave it (the arc grows with the
    # axis, but not quite in proportion: the frame turns with the path).
    axis = rest / np.hypot(1.0, 2.0 * np.pi * shape.curl.radius / shape.curl.period)
    low, high = np.zeros_like(axis), np.full_like(axis, np.inf)
    best, miss = None, np.full_like(axis, np.inf)
    for _ in range(CURL_ROUNDS):
        checkpoint()
        helix = along.helix(first, axis, shape)
        arc = np.linalg.norm(np.diff(helix[:, 1:], axis=1), axis=2).sum(axis=1)
        nearer = np.abs(arc - rest) < miss
        best = helix if best is None else np.where(nearer[:, None, None], helix, best)
        miss = np.where(nearer, np.abs(arc - rest), miss)
        if np.all(miss <= CURL_TOLERANCE * lengths):
            break
        short = arc < rest
        low, high = np.where(short, axis, low), np.where(short, high, axis)
        guess = axis * rest / np.where(arc > 0, arc, rest)
        halved = np.where(np.isfinite(high), 0.5 * (low + high), 2.0 * low)
        axis = np.where((guess > low) & (guess < high), guess, halved)
    return best


def _walked(guard: SurfaceGuard, strands: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """(n, m, 3): ``strands`` walked point by point, each segment of its own length towards
    the strand's next point and kept at its ``floor`` ((n, m - 1), the points past the root)
    as the paths' points are (:func:`_next_point`)."""
    out = strands.copy()
    steps = np.linalg.norm(np.diff(strands, axis=1), axis=2)
    for k in range(2, strands.shape[1]):
        checkpoint()
        out[:, k] = _next_point(guard, out[:, k - 1], strands[:, k], steps[:, k - 1],
                                floor[:, k - 1])  # fmt: skip
    return out


def _sampled(axis: np.ndarray, m: int) -> np.ndarray:
    """(n, m): the arc lengths past the first segment at which a strand's points lie on a
    path: 0 for the root and the first point, then ``axis`` ((n,)) in even steps."""
    share = np.maximum(np.arange(m, dtype=np.float64) - 1.0, 0.0) / (m - 2)
    return share[None, :] * axis[:, None]


def _steps(lengths: np.ndarray, points: int, free: float) -> tuple[np.ndarray, np.ndarray]:
    """(n,) each: the first segment's length and the others': even, but the first no longer
    than ``free`` (so that it ends where a strand may still lie low), the others sharing the
    rest. A strand of two points is one segment."""
    if points == 2:
        return lengths, lengths
    even = lengths / (points - 1)
    first = np.minimum(even, free) if free > 0 else even
    return first, (lengths - first) / (points - 2)


#: Times a point put back on its floor is brought back to its segment's length, and put back
#: again if that took it below.
KEEP_OUT_ROUNDS = 4


def _next_point(guard: SurfaceGuard, last: np.ndarray, aim: np.ndarray, step, floor):
    """(p, 3): the point ``step`` from ``last`` towards ``aim``, kept at its ``floor`` or above
    the surface: put back on it, and again ``step`` from ``last`` towards that, a few
    rounds; the last put back wins (the segment then a little off its length)."""
    point = last + step[:, None] * unit_rows(aim - last)[0]
    todo = np.arange(len(point))  # a point not put back stays where it is: checked once
    for _ in range(KEEP_OUT_ROUNDS):
        kept = _kept_out(guard, point[todo], floor[todo])
        moved = np.any(kept != point[todo], axis=1)
        todo, kept = todo[moved], kept[moved]
        if not len(todo):
            return point
        point[todo] = last[todo] + step[todo, None] * unit_rows(kept - last[todo])[0]
    point[todo] = _kept_out(guard, point[todo], floor[todo])
    return point


def _kept_out(guard: SurfaceGuard, points: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """``points`` with those nearer the surface than ``floor`` ((p,)), or behind it, put at
    ``floor`` from their nearest surface point."""
    foot, normal, above = guard.nearest(points)
    low = above < floor
    out = points.copy()
    if not low.any():
        return out
    # Out along the way from the nearest point when outside (the nearest point stays the
    # nearest along it, so the distance is the floor), along its triangle's normal inside.
    away, at_foot = unit_rows(points[low] - foot[low])
    outside = (above[low] > 0) & ~at_foot
    way = np.where(outside[:, None], away, normal[low])
    out[low] = foot[low] + floor[low, None] * way
    return out


def _marched(cells: _MapCells, field: GrowthField, points, faces, distances):
    """The map points ``distances`` ((p,) surface length) on from ``points`` ((p, 2), in
    ``faces``) along the field, and their triangles (a point off the region keeps its last
    triangle: the map's linear piece there is carried on)."""
    triangles = cells.triangles
    directions = field.map_directions(points, faces)
    # The surface length of a unit map step along d: |J d|, J = E3 E2^-1 the triangle's.
    e2, e3 = triangle_edges(triangles, faces)
    stretch = np.linalg.norm(np.einsum("pij,pj->pi", e3, solve_2x2(e2, directions)), axis=1)
    stretch = np.where(np.isfinite(stretch) & (stretch > 0), stretch, 1.0)
    moved = points + (distances / stretch)[:, None] * directions
    found = cells.locate(moved)
    return moved, np.where(found >= 0, found, faces)


@dataclass(frozen=True)
class _MapCells:
    """The region's triangles filed by the cells of a grid over the map that their boxes
    meet (:class:`transforms.cellgrid.CellIndex`; cells half the triangles' typical size,
    where a point's cell holds fewest candidates for the entries filed), built once for a
    whole march: a point's triangle is among those of its cell."""

    triangles: MapTriangles
    index: CellIndex

    @classmethod
    def of(cls, triangles: MapTriangles) -> _MapCells:
        low, high = triangles.map_points.min(axis=0), triangles.map_points.max(axis=0)
        grid = CellGrid.covering(low, high, 0.5 * triangles.typical_size)
        boxes = triangles.cell_boxes(grid, np.arange(len(triangles)))
        return cls(triangles, CellIndex.of(grid, boxes))

    def locate(self, points: np.ndarray) -> np.ndarray:
        """(p,) int: a triangle holding each map point ((p, 2)), -1 where none does."""
        grid = self.index.grid
        x, y = points[:, 0], points[:, 1]
        cell = grid.rows(y) * grid.n_columns + grid.columns(x)
        point, triangle, _ = self.index.entries_between(cell, cell + 1)
        # The pairs' weights, corner by corner: the signed areas of the point with each
        # edge, of the sign of the triangle's (a triangle of no area holds nothing).
        cx, cy = self.triangles.corner_x[:, triangle], self.triangles.corner_y[:, triangle]
        px, py = x[point], y[point]
        area = (cx[1] - cx[0]) * (cy[2] - cy[0]) - (cy[1] - cy[0]) * (cx[2] - cx[0])
        slack = -BARYCENTRIC_SLACK * np.abs(area)
        inside = area != 0
        for i, j in ((1, 2), (2, 0), (0, 1)):
            part = (cx[j] - cx[i]) * (py - cy[i]) - (cy[j] - cy[i]) * (px - cx[i])
            inside &= np.where(area > 0, part, -part) >= slack
        found = np.full(len(points), -1, dtype=np.int64)
        found[point[inside]] = triangle[inside]  # any of those that hold it
        return found


def _lifted(triangles: MapTriangles, normals: np.ndarray, points, faces):
    """The surface points of map ``points`` by their triangles' linear maps (carried on
    beyond a triangle for a point off the region) and the unit normals there."""
    weights = triangles.barycentric(faces, points)
    weights = np.where(np.isfinite(weights), weights, 1.0 / 3.0)
    ground = combine(triangles.surface_points, triangles.faces, faces, weights)
    return ground, _surface_normals(triangles, normals, points, faces, weights)


def _surface_normals(triangles, normals, points, faces, weights=None) -> np.ndarray:
    """(p, 3) unit: the vertex ``normals`` interpolated at map ``points`` in ``faces``
    (weights clipped to the triangle)."""
    if weights is None:
        weights = triangles.barycentric(faces, points)
        weights = np.where(np.isfinite(weights), weights, 1.0 / 3.0)
    inside = np.clip(weights, 0.0, None)
    inside /= np.maximum(inside.sum(axis=1, keepdims=True), 1e-300)
    return unit_rows(combine(normals, triangles.faces, faces, inside))[0]


@dataclass(frozen=True)
class _Along:
    """Polylines ``paths`` (n, m, 3) with the arc length at each point ``at`` (n, m), their
    unit ``tangents`` (n, m, 3: the mean of the segments' directions at a point) and scalp
    normals ``ups`` (n, m, 3), and each point's place on one line for the search."""

    paths: np.ndarray
    tangents: np.ndarray
    ups: np.ndarray
    at: np.ndarray
    keys: np.ndarray
    spread: np.ndarray

    @classmethod
    def of(cls, paths: np.ndarray, ups: np.ndarray) -> _Along:
        n, m, _ = paths.shape
        segments = np.diff(paths, axis=1)
        at = np.zeros((n, m))
        np.cumsum(np.linalg.norm(segments, axis=2), axis=1, out=at[:, 1:])
        way = unit_rows(segments.reshape(-1, 3))[0].reshape(n, m - 1, 3)
        tangents = np.concatenate([way[:, :1], way[:, :-1] + way[:, 1:], way[:, -1:]], axis=1)
        # The rows one after another on one line: a row's arc lengths (from 0) shifted past
        # the one before's, so one sorted search finds every sample's segment.
        spread = np.arange(n) * (2.0 * float(at[:, -1].max()) + 1.0)
        return cls(paths, tangents, ups, at, (at + spread[:, None]).ravel(), spread)

    def helix(self, first: np.ndarray, axis: np.ndarray, shape: StrandShape) -> np.ndarray:
        """(n, m, 3): the points of eq. 20.2 at the first segment's end, then past it by
        ``axis`` ((n,)) of path in even steps (the last segment carried on beyond a path's
        end). The frame turns with the tangent and the normal interpolated along the path,
        so a point moves smoothly with ``axis``."""
        n, m, _ = self.paths.shape
        past = _sampled(axis, m)
        t = np.where(np.arange(m) >= 1, first[:, None] + past, 0.0)
        rows = np.arange(n)[:, None]
        found = np.searchsorted(self.keys, (t + self.spread[:, None]).ravel(), side="right")
        start = np.clip(found.reshape(n, m) - 1 - rows * m, 0, m - 2)
        end = start + 1
        s0 = self.at[rows, start]
        size = self.at[rows, end] - s0
        share = np.where(size > 0, (t - s0) / np.where(size > 0, size, 1.0), 0.0)[..., None]
        centre = self.paths[rows, start] + share * (self.paths[rows, end] - self.paths[rows, start])
        inside = np.clip(share, 0.0, 1.0)
        tangent = _unit(
            (1.0 - inside) * self.tangents[rows, start] + inside * self.tangents[rows, end]
        )
        up = (1.0 - inside) * self.ups[rows, start] + inside * self.ups[rows, end]
        up = _unit(up - np.einsum("pkd,pkd->pk", up, tangent)[..., None] * tangent)
        side = np.cross(tangent, up)
        curl = shape.curl
        radius = curl.radius * -np.expm1(-past / shape.bend)
        angle = 2.0 * np.pi * past / curl.period
        turn = np.cos(angle)[..., None] * up + np.sin(angle)[..., None] * side
        return centre + radius[..., None] * turn


def _unit(vectors: np.ndarray) -> np.ndarray:
    """``vectors`` (..., 3) scaled to unit length (zero ones stay zero)."""
    return unit_rows(vectors.reshape(-1, 3))[0].reshape(vectors.shape)
