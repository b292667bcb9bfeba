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
  root, ``0`` before), or behind it, is put back on the floor from its nearest surface point
  (:class:`SurfaceGuard`: exact nearest points, the side by the pseudonormal there), before
  the next segment starts from it;
* with a curl, the path is grown a radius higher and the strand turns about it (eq. 20.2),
  its arc length still ``L``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import igl
import numpy as np

from .arrays import combine, cross_rows, face_cross, solve_2x2, unit_rows
from .checkpoints import checkpoint
from .growth import GrowthField, triangle_edges
from .mapping import MapTriangles, TriangleCells


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
    """The nearest points of a triangle mesh and which side of it a point is on, for keeping
    points out of it: libigl's axis-aligned bounding-box tree (exact nearest points, in C++)
    and the angle-weighted pseudonormal at the nearest point (Baerentzen and Aanaes, 2005:
    the face's normal inside a face, the sum of the two faces' on an edge, the sum of the
    faces' weighted by their angles at a corner), which tells the side right at any edge and
    corner of a closed surface, sharp creases included.

    Parameters
    ----------
    vertices : (k, 3) float
    faces : (m, 3) int; those of no area are left out (they bound nothing)
    outward : +1 or -1, the sign that turns the faces' winding normals outwards
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, outward: int) -> None:
        self._vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        cross = face_cross(self._vertices, faces)
        normals, flat = unit_rows(cross)
        kept = ~flat
        self._faces = np.ascontiguousarray(np.asarray(faces)[kept], dtype=np.int64)
        self._normals = outward * normals[kept]
        # libigl's adjacency: TT[f, j] is across the edge from corner j to corner j + 1, the
        # one opposite corner j + 2 (-1 on a border); here by the corner opposite.
        self._across = np.roll(igl.triangle_triangle_adjacency(self._faces)[0], -1, axis=1)
        self._at_vertices = outward * igl.per_vertex_normals(self._vertices, self._faces, ANGLE)
        self._tree = igl.AABB()
        if len(self._faces):
            self._tree.init(self._vertices, self._faces)

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (p, 3) ``points``: the nearest surface points (p, 3), the outward unit
        pseudonormals there (p, 3) and the signed heights of the points above them (p,): the
        distance, negative behind the surface."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        if not len(self._faces) or not len(points):
            return points.copy(), np.zeros_like(points), np.full(len(points), np.inf)
        _, face, foot = self._tree.squared_distance(self._vertices, self._faces, points)
        normal = self._pseudonormals(face, foot)
        gap = np.linalg.norm(points - foot, axis=1)
        side = np.einsum("pd,pd->p", points - foot, normal)
        return foot, normal, np.where(side < 0, -gap, gap)

    def _pseudonormals(self, face: np.ndarray, foot: np.ndarray) -> np.ndarray:
        """(p, 3) unit: the pseudonormal at each ``foot`` ((p, 3)) on its ``face`` ((p,))."""
        corners = self._vertices[self._faces[face]]  # (p, 3, 3)
        low = _weights_on_triangles(corners, foot) <= PSEUDONORMAL_EDGE
        normal = self._normals[face]
        # On an edge: one weight 0 (the corner across); at a corner: two, the third 1.
        zeros = low.sum(axis=1)
        edge = np.flatnonzero(zeros == 1)
        if len(edge):
            across = self._across[face[edge], np.argmax(low[edge], axis=1)]
            both = across >= 0
            normal[edge[both]] += self._normals[across[both]]
        corner = np.flatnonzero(zeros >= 2)
        if len(corner):
            vertex = self._faces[face[corner], np.argmin(low[corner], axis=1)]
            normal[corner] = self._at_vertices[vertex]
        unit, zero = unit_rows(normal)
        unit[zero] = self._normals[face[zero]]  # a crease folded flat: the face's own
        return unit


#: Vertex normals weighted by the faces' angles: the pseudonormals at corners.
ANGLE = igl.PerVertexNormalsWeightingType.PER_VERTEX_NORMALS_WEIGHTING_TYPE_ANGLE
#: A weight of the nearest point this small puts it on the edge across that corner.
PSEUDONORMAL_EDGE = 1e-9


def _weights_on_triangles(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(p, 3): the barycentric weights of ``points`` (p, 3), on their triangles' planes, in
    the triangles ``corners`` (p, 3, 3)."""
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    d = points - corners[:, 0]
    d00, d01, d11 = (np.einsum("pd,pd->p", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    d20, d21 = np.einsum("pd,pd->p", d, e1), np.einsum("pd,pd->p", d, e2)
    denominator = d00 * d11 - d01 * d01  # > 0: the guard's faces have area
    v = (d11 * d20 - d01 * d21) / denominator
    w = (d00 * d21 - d01 * d20) / denominator
    return np.column_stack([1.0 - v - w, v, w])


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
    lengths = np.asarray(lengths, dtype=np.float64)
    if not len(roots.points):
        return np.empty((0, shape.points, 3))
    # Strands near each other grown next to each other: the guard's queries then walk
    # nearby branches of its tree one after another (a third faster than in site order).
    order = _spatial_order(roots.points)
    roots = Roots(*(getattr(roots, part.name)[order] for part in fields(roots)))
    lengths = lengths[order]
    curl = shape.curl if shape.points > 2 else None  # a strand of one segment is straight
    if curl is None:
        grown = _paths(triangles, field, normals, roots, lengths, shape, guard)
    else:
        # The helix's axis runs a radius higher, so that its lowest points keep the
        # clearance, and bends over a length as much longer (the same shape, scaled).
        high = shape.clearance + curl.radius
        axis = replace(shape, clearance=high, bend=shape.bend * high / shape.clearance)
        paths = _paths(triangles, field, normals, roots, lengths, axis, guard)
        grown = _curled(paths, roots.normals, lengths, shape, axis.bend, guard)
    strands = np.empty_like(grown)
    strands[order] = grown
    return strands


#: Cells a side of the box the roots are sorted by (:func:`_spatial_order`).
ORDER_CELLS = 64


def _spatial_order(points: np.ndarray) -> np.ndarray:
    """(n,) int: an order of ``points`` ((n, 3)) by the cells of a grid over their box,
    cell row after cell row."""
    low, high = points.min(axis=0), points.max(axis=0)
    size = max(float(np.max(high - low)) / ORDER_CELLS, 1e-300)
    cells = np.floor((points - low) / size).astype(np.int64)
    return np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0]))


def _paths(triangles, field, normals, roots: Roots, lengths, shape: StrandShape, guard):
    """(n, m, 3): the strands without curl (eq. 20.1), each point kept out of the head."""
    n, m = len(roots.points), shape.points
    first, step = _steps(lengths, m, shape.free)
    strands = np.empty((n, m, 3))
    strands[:, 0] = roots.points
    # Out of the head too: on a concave scalp a low exit angle could take it under the skin
    # (and a strand of one segment keeps the clearance at its end, past ``free``).
    aim = roots.points + first[:, None] * roots.directions
    strands[:, 1] = _next_point(guard, roots.points, aim, first, _floor(first, shape))
    rise = np.einsum("pd,pd->p", roots.directions, roots.normals)
    height = first * rise
    cells = triangles.cell_index()
    foot, triangle, _ = _marched(cells, field, roots.map_points, roots.triangles,
                                 first * np.sqrt(np.clip(1.0 - rise**2, 0.0, 1.0)))  # fmt: skip
    for k in range(2, m):
        checkpoint()
        arc = first + (k - 1) * step
        settled = np.exp(-(arc - first) / shape.bend)
        target = shape.clearance + (first * rise - shape.clearance) * settled
        along = step * np.sqrt(np.clip(1.0 - ((target - height) / step) ** 2, 0.0, 1.0))
        foot, triangle, weights = _marched(cells, field, foot, triangle, along)
        ground, up = _lifted(triangles, normals, triangle, weights)
        strands[:, k] = _next_point(guard, strands[:, k - 1], ground + target[:, None] * up,
                                    step, _floor(arc, shape))  # fmt: skip
        height = target
    return strands


def _floor(arc: np.ndarray, shape: StrandShape) -> np.ndarray:
    """(...,): how near the scalp a point may lie at ``arc`` from its root: half the
    clearance past ``free``, 0 (outside) before."""
    return np.where(arc > shape.free, 0.5 * shape.clearance, 0.0)


#: Rounds of the search for the length of path whose helix has the strand's length.
CURL_ROUNDS = 24
#: A helix's search stops once its arc is this near its length (relative).
CURL_TOLERANCE = 1e-6
#: A helix whose search ends further than this from its length (relative) is walked to it.
CURL_MISS = 1e-3


def _curled(paths: np.ndarray, normals, lengths, shape: StrandShape, bend: float, guard):
    """(n, m, 3): a helix about each path (eq. 20.2), on a length of path chosen so that the
    helix's arc length is the strand's; a strand with a point nearer the scalp than its
    floor, or whose search ended off its length, is walked again to its length
    (:func:`_walked`). ``normals`` (n, 3): the roots', where each frame starts; ``bend``:
    the paths'."""
    along = _Along.of(paths, normals)
    helix, miss = _helix_of_length(along, lengths, shape.curl, bend)
    n, m, _ = helix.shape
    floor = _floor(np.cumsum(_segments(helix), axis=1), shape)
    kept = _kept_out(guard, helix[:, 2:].reshape(-1, 3), floor[:, 1:].reshape(-1))
    again = np.any(kept.reshape(n, m - 2, 3) != helix[:, 2:], axis=(1, 2))
    again |= miss > CURL_MISS * lengths
    if again.any():
        helix[again] = _walked(guard, helix[again], floor[again], lengths[again])
    return helix


def _helix_of_length(along: _Along, lengths, curl: Curl, bend: float):
    """(n, m, 3): the helices about ``along``'s paths whose arc lengths are ``lengths``, each
    the nearest of its search's rounds, and (n,) how far each is from its length.

    Each helix's search is its own: a row stops once near enough, so its strand does not
    depend on the others asked with it."""
    first = along.at[:, 1]  # the first segment, kept as it is
    rest = lengths - first
    # Start from a smooth helix's length, sqrt(1 + (2 pi r / p)^2) a unit of its axis; the
    # polyline's chords are shorter, so the ratio of arcs refines it (nearly proportional),
    # within a bracket that halves where the ratio would leave it.
    axis = rest / np.hypot(1.0, 2.0 * np.pi * curl.radius / curl.period)
    low, high = np.zeros_like(axis), np.full_like(axis, np.inf)
    best = np.full((*along.paths.shape[:2], 3), np.nan)  # every row set by the first round
    miss = np.full_like(axis, np.inf)
    rows = np.arange(len(axis))
    for _ in range(CURL_ROUNDS):
        checkpoint()
        helix = along.helix(first[rows], axis[rows], curl, bend, rows)
        arc = _segments(helix)[:, 1:].sum(axis=1)
        off = np.abs(arc - rest[rows])
        nearer = off < miss[rows]
        best[rows[nearer]], miss[rows[nearer]] = helix[nearer], off[nearer]
        short = arc < rest[rows]
        low[rows] = np.where(short, axis[rows], low[rows])
        high[rows] = np.where(short, high[rows], axis[rows])
        guess = axis[rows] * rest[rows] / np.where(arc > 0, arc, rest[rows])
        halved = np.where(np.isfinite(high[rows]), 0.5 * (low[rows] + high[rows]), 2.0 * low[rows])
        inside = (guess > low[rows]) & (guess < high[rows])
        axis[rows] = np.where(inside, guess, halved)
        rows = rows[miss[rows] > CURL_TOLERANCE * lengths[rows]]
        if not len(rows):
            break
    return best, miss


def _walked(guard: SurfaceGuard, strands: np.ndarray, floor: np.ndarray, lengths) -> np.ndarray:
    """(n, m, 3): ``strands`` walked point by point, each segment towards the strand's next
    point, of its length scaled so that the segments past the first add up to the rest of
    ``lengths`` ((n,)), and kept at its ``floor`` ((n, m - 1), the points past the root) as
    the paths' points are (:func:`_next_point`)."""
    out = strands.copy()
    steps = _segments(strands)
    past = steps[:, 1:].sum(axis=1)
    steps[:, 1:] *= ((lengths - steps[:, 0]) / np.where(past > 0, past, 1.0))[:, None]
    for k in range(2, strands.shape[1]):
        checkpoint()
        out[:, k] = _next_point(guard, out[:, k - 1], strands[:, k], steps[:, k - 1],
                                floor[:, k - 1])  # fmt: skip
    return out


def _segments(strands: np.ndarray) -> np.ndarray:
    """(n, m - 1): the lengths of the segments of ``strands`` (n, m, 3)."""
    return np.linalg.norm(np.diff(strands, axis=1), axis=2)


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
    rounds; then put back alone until none is low (the segment then a little off its
    length), at most twice as many rounds."""
    point = last + step[:, None] * unit_rows(aim - last)[0]
    todo = np.arange(len(point))  # a point not put back stays where it is: checked once
    for _ in range(KEEP_OUT_ROUNDS):
        kept = _kept_out(guard, point[todo], floor[todo])
        moved = np.any(kept != point[todo], axis=1)
        todo, kept = todo[moved], kept[moved]
        if not len(todo):
            return point
        point[todo] = last[todo] + step[todo, None] * unit_rows(kept - last[todo])[0]
    # The last put-back wins; in a crease narrower than the floor, a point put back from one
    # wall can land behind the other: put back again until none is low.
    for _ in range(KEEP_OUT_ROUNDS * 2):
        kept = _kept_out(guard, point[todo], floor[todo])
        moved = np.any(kept != point[todo], axis=1)
        point[todo] = kept
        todo = todo[moved]
        if not len(todo):
            break
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
    # nearest along it, so the distance is the floor), along the pseudonormal there inside.
    away, at_foot = unit_rows(points[low] - foot[low])
    outside = (above[low] > 0) & ~at_foot
    way = np.where(outside[:, None], away, normal[low])
    out[low] = foot[low] + floor[low, None] * way
    return out


def _marched(cells: TriangleCells, field: GrowthField, points, faces, distances):
    """The map points ``distances`` ((p,) surface length) on from ``points`` ((p, 2), in
    ``faces``) along the field, their triangles and their weights there (a point off the
    region keeps its last triangle, whose linear map is carried on: weights outside [0, 1])."""
    triangles = cells.triangles
    directions = field.map_directions(points, faces)
    # The surface length of a unit map step along d: |J d|, J = E3 E2^-1 the triangle's.
    e2, e3 = triangle_edges(triangles, faces)
    stretch = np.linalg.norm(np.einsum("pij,pj->pi", e3, solve_2x2(e2, directions)), axis=1)
    stretch = np.where(np.isfinite(stretch) & (stretch > 0), stretch, 1.0)
    moved = points + (distances / stretch)[:, None] * directions
    found, weights = cells.locate(moved)
    off = np.flatnonzero(found < 0)
    found[off] = faces[off]
    weights[off] = triangles.barycentric(faces[off], moved[off])
    return moved, found, np.where(np.isfinite(weights), weights, 1.0 / 3.0)


def _lifted(triangles: MapTriangles, normals: np.ndarray, faces, weights):
    """The surface points with ``weights`` ((p, 3)) in ``faces`` ((p,)) by their triangles'
    linear maps (carried on beyond a triangle for a point off the region), and the unit
    vertex ``normals`` interpolated there (the weights clipped to the triangle)."""
    ground = combine(triangles.surface_points, triangles.faces, faces, weights)
    inside = np.clip(weights, 0.0, None)
    inside /= np.maximum(inside.sum(axis=1, keepdims=True), 1e-300)
    return ground, unit_rows(combine(normals, triangles.faces, faces, inside))[0]


@dataclass(frozen=True)
class _Along:
    """Polylines ``paths`` (n, m, 3) with the arc length at each point ``at`` (n, m), their
    unit ``tangents`` (n, m, 3: the mean of the segments' directions at a point) and a
    rotation-minimising frame's first axis ``frames`` (n, m, 3, unit, across the tangent),
    and each point's place on one line for the search."""

    paths: np.ndarray
    tangents: np.ndarray
    frames: np.ndarray
    at: np.ndarray
    keys: np.ndarray
    spread: np.ndarray

    @classmethod
    def of(cls, paths: np.ndarray, normals: np.ndarray) -> _Along:
        """``paths`` (n, m, 3), the frames starting from ``normals`` (n, 3) at the first
        segment's end."""
        n, m, _ = paths.shape
        segments = np.diff(paths, axis=1)
        at = np.zeros((n, m))
        np.cumsum(np.linalg.norm(segments, axis=2), axis=1, out=at[:, 1:])
        way = _unit(segments)
        tangents = _unit(np.concatenate([way[:, :1], way[:, :-1] + way[:, 1:], way[:, -1:]],
                                        axis=1))  # fmt: skip
        frames = _rotation_minimising(paths, tangents, normals)
        # The rows one after another on one line: a row's arc lengths (from 0) shifted past
        # the one before's, so one sorted search finds every sample's segment.
        spread = np.arange(n) * (2.0 * float(at[:, -1].max()) + 1.0)
        return cls(paths, tangents, frames, at, (at + spread[:, None]).ravel(), spread)

    def helix(self, first, axis, curl: Curl, bend: float, rows=None) -> np.ndarray:
        """(r, m, 3): the points of eq. 20.2 on the paths of ``rows`` (default all): at the
        first segment's end (``first``, (r,)), then past it by ``axis`` ((r,)) of path in
        even steps (the last segment carried on beyond a path's end). The frame is
        interpolated along the path, so a point moves continuously with ``axis``."""
        rows = np.arange(len(self.paths)) if rows is None else rows
        m = self.paths.shape[1]
        past = _sampled(axis, m)
        t = np.where(np.arange(m) >= 1, first[:, None] + past, 0.0)
        row = rows[:, None]
        found = np.searchsorted(self.keys, (t + self.spread[row]).ravel(), side="right")
        start = np.clip(found.reshape(len(rows), m) - 1 - row * m, 0, m - 2)
        end = start + 1
        s0 = self.at[row, start]
        size = self.at[row, end] - s0
        share = np.where(size > 0, (t - s0) / np.where(size > 0, size, 1.0), 0.0)[..., None]
        base, reach = self.paths[row, start], self.paths[row, end]
        centre = base + share * (reach - base)
        within = np.clip(share, 0.0, 1.0)
        tangent = _unit((1.0 - within) * self.tangents[row, start]
                        + within * self.tangents[row, end])  # fmt: skip
        up = (1.0 - within) * self.frames[row, start] + within * self.frames[row, end]
        up = _unit(up - np.einsum("pkd,pkd->pk", up, tangent)[..., None] * tangent)
        side = cross_rows(tangent, up)
        radius = curl.radius * -np.expm1(-past / bend)
        angle = 2.0 * np.pi * past / curl.period
        turn = np.cos(angle)[..., None] * up + np.sin(angle)[..., None] * side
        return centre + radius[..., None] * turn


def _rotation_minimising(paths, tangents, normals) -> np.ndarray:
    """(n, m, 3) unit: a rotation-minimising frame's first axis along each path, by double
    reflection (Wang, Juettler, Zheng and Liu, 2008), from ``normals`` (n, 3) made
    orthogonal to the tangent at the first segment's end (point 1; point 0 takes the same).
    It turns with the path and never about it, so it cannot flip where the path turns
    towards it, as the scalp's normal seen across the tangent would where a strand rises."""
    n, m, _ = paths.shape
    frames = np.empty((n, m, 3))
    start = normals - np.einsum("pd,pd->p", normals, tangents[:, 1])[:, None] * tangents[:, 1]
    start, along_tangent = unit_rows(start)
    if along_tangent.any():  # a strand leaving along the normal: any direction across it
        other = np.where(np.abs(tangents[:, 1, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        start[along_tangent] = unit_rows(cross_rows(tangents[along_tangent, 1],
                                                    other[along_tangent]))[0]  # fmt: skip
    frames[:, 0] = frames[:, 1] = start
    for k in range(1, m - 1):  # along each strand's points, all strands at once
        step = paths[:, k + 1] - paths[:, k]
        frames[:, k + 1] = _reflected(
            _reflected(frames[:, k], step), _reflected(tangents[:, k], step) - tangents[:, k + 1]
        )
    return frames


def _reflected(vectors: np.ndarray, mirror: np.ndarray) -> np.ndarray:
    """(p, 3): ``vectors`` reflected in the planes across ``mirror`` ((p, 3)); unchanged
    where ``mirror`` is zero."""
    size = np.einsum("pd,pd->p", mirror, mirror)
    scale = 2.0 * np.einsum("pd,pd->p", mirror, vectors) / np.where(size > 0, size, 1.0)
    return vectors - np.where(size > 0, scale, 0.0)[:, None] * mirror


def _unit(vectors: np.ndarray) -> np.ndarray:
    """``vectors`` (..., 3) scaled to unit length (zero ones stay zero)."""
    return unit_rows(vectors.reshape(-1, 3))[0].reshape(vectors.shape)
