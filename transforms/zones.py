"""Outlines and curves drawn on the map, measured on the surface (docs/math.md, section 12).

A zone is a polygon of the map (an outer ring and holes, straight edges). Inside each region
triangle the map is linear, so the surface area of the zone's part of a triangle is the
triangle's surface area times the share of its map area the zone covers; a curve's surface
length is the sum, over its pieces in each triangle, of the lifted pieces' lengths.

The share is exact for every triangle: for a triangle ``T`` and a point ``O`` inside it,

    area(zone & T) = w(O) area(T) + sum_e s_e area(T & beyond_O(e))

over the zone's edges ``e`` that meet ``T`` (eq. 12.2), where ``w`` is the winding number
of the zone's rings, ``beyond_O(e)`` the points of the plane whose segment from ``O``
crosses ``e``, and ``s_e`` +1 when ``O`` lies on the right of ``e``. Each term is continuous
in the outline, so outlines through vertices or along edges need no special case. A uniform
grid (:mod:`.cellgrid`) finds the triangles an edge may meet; every other triangle is wholly
in or out, read off the winding numbers of the cell centres. The same sum of first moments
about ``O`` gives the centroid of the zone's part of each cut triangle (eq. 12.3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .cellgrid import Boxes, CellGrid, CellIndex
from .clipping import clip_ring, map_box
from .fans import beyond, cross, part_centroids
from .mapping import MapTriangles
from .segments import Cut, blocks, cut_pieces, within_map

#: Points of a triangle tried as the reference ``O`` (barycentric weights), the one furthest
#: from the outline's edges in the triangle kept.
REFERENCE_WEIGHTS = np.array(
    [
        [1 / 3, 1 / 3, 1 / 3],
        [0.5, 0.25, 0.25],
        [0.25, 0.5, 0.25],
        [0.25, 0.25, 0.5],
        [0.2, 0.4, 0.4],
        [0.4, 0.2, 0.4],
        [0.4, 0.4, 0.2],
    ]
)
#: A reference point closer than this share of its triangle's size (the square root of twice
#: its area) to an edge of the outline is replaced.
REFERENCE_CLEARANCE = 0.05
#: Shares within this of 0 or 1 count as out or wholly in (rounding of the sums).
SHARE_SLACK = 1e-12


def ring_area(ring: np.ndarray) -> float:
    """The signed area of a closed ring ((n, 2) float, last point not repeated):
    counter-clockwise positive (the shoelace formula)."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def ring_edges(rings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The edges of a zone with the outer ring counter-clockwise and the holes clockwise, so
    that the winding number is 1 inside the zone and 0 outside.

    Parameters
    ----------
    rings : sequence of (n_i, 2) float, the outer ring first; none closed by repeating its
        first point

    Returns
    -------
    a, b : (E, 2) float, each edge's start and end
    ring : (E,) int, the ring each edge belongs to
    """
    starts, ends, owner = [], [], []
    for number, ring in enumerate(rings):
        ring = np.asarray(ring, dtype=np.float64)
        if (ring_area(ring) < 0) == (number == 0):
            ring = ring[::-1]
        starts.append(ring)
        ends.append(np.roll(ring, -1, axis=0))
        owner.append(np.full(len(ring), number))
    return np.concatenate(starts), np.concatenate(ends), np.concatenate(owner)


@dataclass(frozen=True)
class Trace:
    """Segments of the map over a region's triangles: every (triangle, piece) where a piece
    of a segment runs through a triangle.

    Attributes
    ----------
    grid : CellGrid, over the segments
    index : CellIndex, the pieces by cell
    piece_a, piece_b : (P, 2) float, the pieces (segments cut to at most a cell)
    segment : (P,) int, the segment each piece is part of
    s0, s1 : (P,) float, where the piece starts and ends along its segment, in [0, 1]
    candidates : (j,) int, the triangles whose box meets the segments' box
    boxes : Boxes, the candidates' cell rectangles
    near : (j,) bool, candidates whose rectangle shares a cell with a piece
    owner : (p,) int, the pairs' triangle, as a position in ``candidates[near]``
    piece : (p,) int, the pairs' piece
    t0, t1 : (p,) float, the part of the piece inside the triangle (empty when t0 >= t1)
    """

    grid: CellGrid
    index: CellIndex
    piece_a: np.ndarray
    piece_b: np.ndarray
    segment: np.ndarray
    s0: np.ndarray
    s1: np.ndarray
    candidates: np.ndarray
    boxes: Boxes
    near: np.ndarray
    owner: np.ndarray
    piece: np.ndarray
    t0: np.ndarray
    t1: np.ndarray

    @classmethod
    def of(
        cls, triangles: MapTriangles, a: np.ndarray, b: np.ndarray, cut: Cut | None = None
    ) -> Trace:
        """Trace the segments ``a -> b`` ((E, 2) float each) over ``triangles``; with
        ``cut``, on the grid and into the pieces of a trace of more segments that these are
        a block of (the same pieces and pairs as that trace's)."""
        points = np.concatenate([a, b])
        low, high = points.min(0), points.max(0)
        if cut is None:
            cut = Cut.of(triangles, a, b)
        grid = cut.grid
        piece_a, piece_b, segment, s0, s1 = cut_pieces(a, b, cut.piece)
        index = CellIndex.of(
            grid,
            grid.boxes(
                np.minimum(piece_a[:, 0], piece_b[:, 0]),
                np.maximum(piece_a[:, 0], piece_b[:, 0]),
                np.minimum(piece_a[:, 1], piece_b[:, 1]),
                np.maximum(piece_a[:, 1], piece_b[:, 1]),
            ),
        )
        candidates = triangles.meeting(low, high)
        boxes = triangles.cell_boxes(grid, candidates)
        near = index.any_in(boxes)
        owner, piece = index.pairs(boxes.take(np.flatnonzero(near)))
        triangle = candidates[near][owner]
        corners = counter_clockwise(triangles.corners(triangle))
        t0, t1, ceded = clip_to_triangles(corners, piece_a[piece], piece_b[piece])
        flat = triangles.signed_map_area[triangle] == 0
        t1[flat] = t0[flat]
        # Along the region's border no triangle lies across the edge to take the piece.
        t1[(ceded >= 0) & ~_unclaimed(piece, corners, ceded, t0 < t1)] = -1.0
        return cls(
            grid, index, piece_a, piece_b, segment, s0, s1, candidates, boxes, near, owner,
            piece, t0, t1,
        )  # fmt: skip

    @property
    def near_triangles(self) -> np.ndarray:
        """(q,) int: the triangles a piece may run through."""
        return self.candidates[self.near]


def counter_clockwise(corners: np.ndarray) -> np.ndarray:
    """(p, 3, 2) float: the triangles' corners ((p, 3, 2)) in counter-clockwise order."""
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    clockwise = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    ordered = corners.copy()
    ordered[clockwise, 1], ordered[clockwise, 2] = corners[clockwise, 2], corners[clockwise, 1]
    return ordered


def clip_to_triangles(corners: np.ndarray, a: np.ndarray, b: np.ndarray):
    """The part of each segment ``a -> b`` inside its counter-clockwise triangle (the
    Liang-Barsky clip against the three edges' half-planes).

    A segment along an edge's line belongs to the triangle on the side the outline would
    move to if shifted by ``(eps, eps^2)``: of two triangles sharing the edge, exactly one.

    Parameters
    ----------
    corners : (p, 3, 2) float, counter-clockwise
    a, b : (p, 2) float

    Returns
    -------
    t0, t1 : (p,) float, the inside part is ``a + t (b - a)`` for ``t0 <= t <= t1`` (empty
        when ``t0 >= t1``)
    ceded : (p,) int, the corner ``i`` whose edge ``i -> i + 1`` the segment runs along
        while the tie-break gives it to the other side (-1 for none); ``t0``, ``t1`` are
        then the part the triangle would have without that rule
    """
    t0, t1 = np.zeros(len(a)), np.ones(len(a))
    ceded = np.full(len(a), -1)
    for i in range(3):
        start, edge = corners[:, i], corners[:, (i + 1) % 3] - corners[:, i]
        fa, fb = cross(edge, a - start), cross(edge, b - start)
        along = fa == fb
        shifted = np.where(edge[:, 1] != 0, -edge[:, 1], edge[:, 0])
        t1[along & (fa < 0)] = -1.0
        ceded[along & (fa == 0) & (shifted <= 0)] = i
        with np.errstate(divide="ignore", invalid="ignore"):
            crossing = fa / (fa - fb)
        entering = ~along & (fb > fa)
        leaving = ~along & (fb < fa)
        t0 = np.where(entering, np.maximum(t0, crossing), t0)
        t1 = np.where(leaving, np.minimum(t1, crossing), t1)
    return t0, t1, ceded


def _unclaimed(piece, corners, ceded, inside) -> np.ndarray:
    """(p,) bool: the pairs whose piece runs along their ceded edge (``ceded``, as from
    :func:`clip_to_triangles`) while no other triangle over the same piece has that edge
    and a part of the piece (``inside``): the edge is on the region's border.

    ``piece`` : (p,) int; ``corners`` : (p, 3, 2) float, counter-clockwise; ``inside`` :
    (p,) bool.
    """
    found = np.zeros(len(piece), dtype=bool)
    tied = np.flatnonzero(ceded >= 0)
    if len(tied) == 0:
        return found
    rivals = np.flatnonzero(np.isin(piece, piece[tied]) & (ceded < 0) & inside)
    keys = [_edge_keys(piece[tied], corners[tied], ceded[tied])]
    keys += [_edge_keys(piece[rivals], corners[rivals], np.full(len(rivals), i)) for i in range(3)]
    _, label = np.unique(np.concatenate(keys), axis=0, return_inverse=True)
    label = label.ravel()
    found[tied] = ~np.isin(label[: len(tied)], label[len(tied) :])
    return found


def _edge_keys(piece, corners, corner) -> np.ndarray:
    """(p, 5) float: ``(piece, x, y, x', y')`` for the edge ``corner -> corner + 1`` of each
    triangle (``corners`` (p, 3, 2)), its ends in lexicographic order."""
    rows = np.arange(len(piece))
    p, q = corners[rows, corner], corners[rows, (corner + 1) % 3]
    swap = (p[:, 0] > q[:, 0]) | ((p[:, 0] == q[:, 0]) & (p[:, 1] > q[:, 1]))
    low, high = np.where(swap[:, None], q, p), np.where(swap[:, None], p, q)
    return np.column_stack([piece.astype(np.float64), low, high])


@dataclass(frozen=True)
class Polyline:
    """A map polyline lifted onto the surface, through its own points and every crossing of
    a triangle edge.

    Attributes
    ----------
    map_points : (k, 2) float
    surface_points : (k, 3) float
    faces : (k - 1,) int, the triangle (position in the region's faces) each piece runs
        over; -1 where the polyline leaves the region (that piece is not on the surface)
    length : float, the surface length of the pieces on the region
    """

    map_points: np.ndarray
    surface_points: np.ndarray
    faces: np.ndarray
    length: float


#: The lift of a line wholly off the map.
_NO_LINE = Polyline(np.empty((0, 2)), np.empty((0, 3)), np.empty(0, dtype=np.int64), 0.0)


def lift_polyline(triangles: MapTriangles, trace: Trace, segments: np.ndarray) -> Polyline:
    """The pieces of ``trace`` on the ``segments`` ((S,) int, consecutive and ascending) of
    its segments, lifted and joined in order along them."""
    origin = _segment_starts(trace)
    direction = _segment_ends(trace) - origin
    runs = _runs(triangles, trace, segments, direction)
    return _joined(triangles, origin, direction, *runs)


def _runs(triangles: MapTriangles, trace: Trace, segments: np.ndarray, direction: np.ndarray):
    """The parts of the ``segments`` of ``trace`` inside its triangles, a corner grazed left
    out: ``(segment, start, stop, triangle)``, (r,) each, ``start`` and ``stop`` along the
    segment (of map vector ``direction[segment]``) in [0, 1]."""
    s_piece = trace.segment[trace.piece]
    keep = (trace.t1 > trace.t0) & np.isin(s_piece, segments)
    piece, t0, t1 = trace.piece[keep], trace.t0[keep], trace.t1[keep]
    triangle = trace.near_triangles[trace.owner[keep]]
    s0, s1 = trace.s0[piece], trace.s1[piece]
    start = np.where(t0 == 0, s0, s0 + t0 * (s1 - s0))
    stop = np.where(t1 == 1, s1, s0 + t1 * (s1 - s0))
    # A triangle that the segment only grazes (at a corner) would be sorted out of turn.
    length = np.linalg.norm(direction, axis=1)[trace.segment[piece]]
    kept = (stop - start) * length > GRAZE * triangles.typical_size
    piece, triangle, start, stop = piece[kept], triangle[kept], start[kept], stop[kept]
    return trace.segment[piece], start, stop, triangle


def _joined(triangles: MapTriangles, origin, direction, segment, start, stop, triangle):
    """The polyline of the runs (as :func:`_runs` gives them) on the segments from
    ``origin`` along ``direction`` ((S, 2) float each), lifted and joined in order."""
    if len(segment) == 0:
        return _NO_LINE
    order = np.lexsort((start, segment))
    segment, start, stop, triangle = segment[order], start[order], stop[order], triangle[order]
    # Pieces of one segment in one triangle cut by cell borders are one piece.
    joined = (segment[1:] == segment[:-1]) & (triangle[1:] == triangle[:-1])
    joined &= start[1:] == stop[:-1]
    first = np.r_[True, ~joined]
    last = np.r_[~joined, True]
    segment, triangle = segment[first], triangle[first]
    start, stop = start[first], stop[last]
    map_start = origin[segment] + start[:, None] * direction[segment]
    map_stop = origin[segment] + stop[:, None] * direction[segment]
    lifted_start = triangles.lift(triangle, triangles.barycentric(triangle, map_start))
    lifted_stop = triangles.lift(triangle, triangles.barycentric(triangle, map_stop))
    length = float(np.linalg.norm(lifted_stop - lifted_start, axis=1).sum())
    joints = _joints(segment, start, stop)
    map_points = _interleave(joints, map_start, map_stop)
    surface_points = _interleave(joints, lifted_start, lifted_stop)
    faces = _interleave(joints, np.full(len(triangle), -1), triangle)
    return Polyline(map_points, surface_points, faces[1:], length)


def lift_curve(triangles: MapTriangles, points) -> Polyline:
    """A map polyline lifted onto the surface (section 12).

    Parameters
    ----------
    triangles : MapTriangles
    points : (n, 2) float, n >= 2, the polyline's points on the map

    Returns
    -------
    Polyline
    """
    points = np.asarray(points, dtype=np.float64)
    a, b = within_map(triangles, points[:-1], points[1:])
    # Traced a block of segments at a time: the pairs of pieces and triangles, some 30 a
    # piece, are held for one block only.
    cut = Cut.of(triangles, a, b)
    runs = []
    for first, last in blocks(cut.pieces(a, b)):
        block = slice(first, last)
        trace = Trace.of(triangles, a[block], b[block], cut)
        segment, *rest = _runs(triangles, trace, np.arange(last - first), b[block] - a[block])
        runs.append((segment + first, *rest))
    joined = [np.concatenate(column) for column in zip(*runs, strict=True)]
    return _joined(triangles, a, b - a, *joined)


def _segment_starts(trace: Trace) -> np.ndarray:
    """(S, 2) float: each segment's start (its first piece's start)."""
    first = np.r_[True, trace.segment[1:] != trace.segment[:-1]]
    starts = np.empty((int(trace.segment[-1]) + 1, 2))
    starts[trace.segment[first]] = trace.piece_a[first]
    return starts


def _segment_ends(trace: Trace) -> np.ndarray:
    """(S, 2) float: each segment's end (its last piece's end)."""
    last = np.r_[trace.segment[1:] != trace.segment[:-1], True]
    ends = np.empty((int(trace.segment[-1]) + 1, 2))
    ends[trace.segment[last]] = trace.piece_b[last]
    return ends


#: Parts of a segment shorter than this share of the triangles' typical size on the map are
#: a corner grazed, not a piece.
GRAZE = 1e-9

#: Pieces whose ends are this close along their segments are joined (a crossing of a
#: triangle edge, found from the triangles on both sides of it).
JOIN_SLACK = 1e-9


def _joints(segment: np.ndarray, start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """(n,) bool: the pieces (in order along the segments) that do not continue the piece
    before them, the first always."""
    same = (segment[1:] == segment[:-1]) & (np.abs(start[1:] - stop[:-1]) <= JOIN_SLACK)
    following = (segment[1:] == segment[:-1] + 1) & (start[1:] <= JOIN_SLACK)
    following &= stop[:-1] >= 1.0 - JOIN_SLACK
    return np.r_[True, ~(same | following)]


def _interleave(gaps: np.ndarray, at_start: np.ndarray, at_stop: np.ndarray) -> np.ndarray:
    """The polyline's values: each piece's ``at_stop``, preceded by its ``at_start`` where
    the piece opens a gap (``gaps``)."""
    slots = np.cumsum(gaps.astype(np.int64) + 1) - 1  # where each piece's stop goes
    out = np.empty((int(slots[-1]) + 1, *at_stop.shape[1:]), dtype=at_stop.dtype)
    out[slots] = at_stop
    out[slots[gaps] - 1] = at_start[gaps]
    return out


@dataclass(frozen=True)
class ZoneCover:
    """How a zone covers a region's triangles.

    Attributes
    ----------
    inside : (j,) int, the triangles (positions in the region's faces) wholly inside
    partial : (p,) int, the triangles the outline cuts
    share : (p,) float in (0, 1), the share of each one's area inside
    partial_centroid : (p, 2) float, the map centroid of each one's part inside (eq. 12.3)
    map_area : float, the zone's area on the map
    covered_map_area : float, the zone's map area the triangles cover, front-facing ones
        counted positive and back-facing ones negative (its area for a fold-free map)
    outline : tuple of Polyline, the rings lifted, the outer one first
    trace, centre_windings : the rings over the triangles, for :meth:`winding`
    """

    inside: np.ndarray
    partial: np.ndarray
    share: np.ndarray
    partial_centroid: np.ndarray
    map_area: float
    covered_map_area: float
    outline: tuple[Polyline, ...]
    trace: Trace | None = field(default=None, repr=False)
    centre_windings: np.ndarray | None = field(default=None, repr=False)

    def winding(self, points) -> np.ndarray:
        """(q,) int: the winding number of the zone's rings about map ``points`` ((q, 2)):
        1 inside the zone, 0 outside (outer ring counter-clockwise, holes clockwise; a point
        on a ring's edge counts by the half-open rule of eq. 12.2's ``w``)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if self.trace is None:  # the zone misses the map
            return np.zeros(len(points), dtype=np.int64)
        grid = self.trace.grid
        low = np.array([grid.x0, grid.y0])
        high = low + grid.size * np.array([grid.n_columns, grid.n_rows])
        near = np.all((points >= low) & (points < high), axis=1)
        winding = np.zeros(len(points), dtype=np.int64)
        if near.any():
            found = _windings(self.trace, points[near], self.centre_windings)
            winding[near] = np.rint(found).astype(np.int64)
        return winding

    def total(self, per_triangle: np.ndarray) -> float:
        """The sum of a per-triangle quantity ((m,) float, such as the surface area) over
        the zone: the triangles inside wholly, the cut ones by their share."""
        return float(
            np.sum(per_triangle[self.inside]) + np.dot(per_triangle[self.partial], self.share)
        )

    def parts(self, triangles: MapTriangles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The zone's part of each triangle it holds any of (docs/math.md, section 12,
        eq. 12.3): the triangles wholly inside, then the cut ones.

        A function linear on a triangle has, over a part of it, the mean of its value at
        the part's centroid: the mean over the zone of a per-vertex quantity is the sum of
        ``share * area * value(centroid)`` over the sum of ``share * area``.

        Parameters
        ----------
        triangles : MapTriangles, those the cover was made of

        Returns
        -------
        faces : (k,) int, positions in the region's faces: ``inside`` then ``partial``
        share : (k,) float in (0, 1], the share of each one's area inside (1 when whole)
        centroid : (k, 2) float, the map centroid of each one's part inside (the
            triangle's own when whole)
        """
        faces = np.concatenate([self.inside, self.partial])
        share = np.concatenate([np.ones(len(self.inside)), self.share])
        whole = triangles.corners(self.inside).mean(axis=1)
        return faces, share, np.concatenate([whole, self.partial_centroid])

    @property
    def perimeter(self) -> float:
        """The surface length of the rings where they run over the region."""
        return float(sum(ring.length for ring in self.outline))


def cover_zone(triangles: MapTriangles, rings) -> ZoneCover:
    """How the zone bounded by ``rings`` covers ``triangles`` (eq. 12.2).

    Parameters
    ----------
    triangles : MapTriangles
    rings : sequence of (n_i, 2) float, the outer ring then the holes: simple, the holes
        inside the outer ring and apart, none closed by repeating its first point (the
        service checks this)

    Returns
    -------
    ZoneCover

    The rings are first clipped to the map's box (:func:`.clipping.clip_ring`, grown by
    :func:`map_box`): the numbers do not depend on how far off the map a vertex lies.
    """
    rings = [np.asarray(r, dtype=np.float64) for r in rings]
    map_area = abs(ring_area(rings[0])) - float(sum(abs(ring_area(r)) for r in rings[1:]))
    box = map_box(triangles)
    clipped = [clip_ring(r, *box) for r in rings]
    kept = [k for k, r in enumerate(clipped) if len(r)]
    if not len(clipped[0]):
        missed = np.empty(0, dtype=np.int64)
        nothing = (missed, missed, np.empty(0), np.empty((0, 2)))
        return ZoneCover(*nothing, map_area, 0.0, (_NO_LINE,) * len(rings))
    a, b, ring = ring_edges([clipped[k] for k in kept])
    trace = Trace.of(triangles, a, b)
    winding = _centre_windings(trace)
    # Far from the outline, a triangle is wholly in or out: its box's first cell says which.
    inside = winding[trace.boxes.r0, trace.boxes.c0] != 0
    near = trace.near_triangles
    share, centroid = _shares(triangles, trace, near, winding)
    whole = share >= 1.0 - SHARE_SLACK
    cut = (share > SHARE_SLACK) & ~whole
    inside[trace.near] = whole
    inside = trace.candidates[inside]
    partial, share, centroid = near[cut], share[cut], centroid[cut]
    covered = ZoneCover(inside, partial, share, centroid, 0.0, 0.0, ()).total(
        triangles.front_map_area
    )
    edges = np.arange(len(ring))
    lifted = {k: lift_polyline(triangles, trace, edges[ring == n]) for n, k in enumerate(kept)}
    outline = tuple(lifted.get(k, _NO_LINE) for k in range(len(rings)))
    return ZoneCover(inside, partial, share, centroid, map_area, covered, outline, trace, winding)


def _centre_windings(trace: Trace) -> np.ndarray:
    """(n_rows, n_columns) int: the winding number of the outline about each cell centre
    (exact for the cells no piece touches), from the crossings of a ray to +x."""
    grid, a, b = trace.grid, trace.piece_a, trace.piece_b
    low, high = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    first = np.clip(np.ceil((low - grid.y0) / grid.size - 0.5), 0, grid.n_rows).astype(np.int64)
    stop = np.clip(np.ceil((high - grid.y0) / grid.size - 0.5), 0, grid.n_rows).astype(np.int64)
    counts = np.maximum(stop - first, 0)
    piece = np.repeat(np.arange(len(a)), counts)
    row = first[piece] + np.arange(len(piece)) - np.repeat(np.cumsum(counts) - counts, counts)
    y = grid.y0 + (row + 0.5) * grid.size
    pa, pb = a[piece], b[piece]
    x = pa[:, 0] + (y - pa[:, 1]) * (pb[:, 0] - pa[:, 0]) / (pb[:, 1] - pa[:, 1])
    column = np.clip(np.ceil((x - grid.x0) / grid.size - 0.5), 0, grid.n_columns).astype(np.int64)
    sign = np.where(pb[:, 1] > pa[:, 1], 1.0, -1.0)
    width = grid.n_columns + 1
    size = grid.n_rows * width
    steps = np.bincount(row * width, sign, size) - np.bincount(row * width + column, sign, size)
    return np.cumsum(steps.reshape(grid.n_rows, width), axis=1)[:, :-1].round().astype(np.int64)


def _shares(
    triangles: MapTriangles, trace: Trace, near: np.ndarray, centre_windings: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The share ((q,) float) of each of the ``near`` triangles' map area inside the zone
    (eq. 12.2), and the map centroid ((q, 2) float) of that part (the triangle's own where
    the part has no area to speak of)."""
    if len(near) == 0:
        return np.empty(0), np.empty((0, 2))
    corners = counter_clockwise(triangles.corners(near))
    owner, piece = trace.owner, trace.piece
    a, b = trace.piece_a[piece], trace.piece_b[piece]
    reference = _reference_points(corners, owner, a, b)
    winding = _windings(trace, reference, centre_windings)
    t0, t1 = trace.t0, trace.t1
    # Most pairs are a piece near a triangle, not in it: their terms are 0.
    live = t1 > t0
    start, d = a[live], b[live] - a[live]
    ends = start + t0[live, None] * d, start + t1[live, None] * d
    terms, moments = np.zeros(len(owner)), np.zeros((len(owner), 2))
    terms[live], moments[live] = beyond(corners[owner[live]], reference[owner[live]], *ends)
    area = np.abs(triangles.signed_map_area[near])
    inside = winding * area + np.bincount(owner, terms, len(near))
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(area > 0, inside / area, winding != 0)
    # The same sum for the first moments about O: the whole triangle's is its area times
    # its centroid's offset from O.
    centre = corners.sum(axis=1) / 3.0
    moment = (winding * area)[:, None] * (centre - reference)
    moment[:, 0] += np.bincount(owner, moments[:, 0], len(near))
    moment[:, 1] += np.bincount(owner, moments[:, 1], len(near))
    centroid = part_centroids(corners, centre, reference, moment, inside, SHARE_SLACK * area)
    return np.clip(share, 0.0, 1.0), centroid


def _reference_points(corners, owner, a, b) -> np.ndarray:
    """(q, 2) float: for each triangle, its centroid, or where a piece paired with it passes
    closer than ``REFERENCE_CLEARANCE`` of its size, the candidate of ``REFERENCE_WEIGHTS``
    furthest from those pieces."""
    points = corners.mean(axis=1)
    clearance = _clearance(points[owner][:, None, :], a, b)[:, 0]
    size = np.abs(cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    tight = np.zeros(len(corners), dtype=bool)
    tight[owner[clearance < REFERENCE_CLEARANCE**2 * size[owner]]] = True
    pairs = tight[owner]
    if not pairs.any():
        return points
    tried = np.einsum("kc,qcd->qkd", REFERENCE_WEIGHTS, corners[tight])
    rank = np.cumsum(tight) - 1
    distance = _clearance(tried[rank[owner[pairs]]], a[pairs], b[pairs])
    kept = owner[pairs]
    starts = np.flatnonzero(np.r_[True, kept[1:] != kept[:-1]])
    best = np.argmax(np.minimum.reduceat(distance, starts, axis=0), axis=1)
    points[tight] = tried[np.arange(len(tried)), best]
    return points


def _clearance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(p, k) float: the squared distance from each of ``points`` ((p, k, 2)) to the
    segment ``a -> b`` ((p, 2) each) of its row."""
    d = b - a
    p = points - a[:, None, :]
    length2 = np.einsum("pd,pd->p", d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("pkd,pd->pk", p, d) / length2[:, None]
    t = np.clip(np.nan_to_num(t), 0.0, 1.0)
    gap = p - t[:, :, None] * d[:, None, :]
    return np.einsum("pkd,pkd->pk", gap, gap)


def _windings(trace: Trace, points: np.ndarray, centre_windings: np.ndarray) -> np.ndarray:
    """(q,) float: the winding number of the outline about ``points`` ((q, 2)): that of the
    first cell to the right in the point's row that no piece touches, plus the signed
    crossings of the ray to +x before it (half-open in y, so a ray through a vertex counts
    once)."""
    grid = trace.grid
    row, column = grid.rows(points[:, 1]), grid.columns(points[:, 0])
    free = trace.index.free_to_the_right()[row, column]
    start = row * grid.n_columns
    owner, piece, cell_column = trace.index.entries_between(start + column, start + free)
    a, b, p = trace.piece_a[piece], trace.piece_b[piece], points[owner]
    upward = (a[:, 1] <= p[:, 1]) & (p[:, 1] < b[:, 1])
    downward = (b[:, 1] <= p[:, 1]) & (p[:, 1] < a[:, 1])
    crossing = upward | downward
    with np.errstate(divide="ignore", invalid="ignore"):
        x = a[:, 0] + (p[:, 1] - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    crossing &= (x > p[:, 0]) & (grid.columns(np.where(crossing, x, 0.0)) == cell_column)
    sign = np.where(upward, 1.0, -1.0) * crossing
    return centre_windings[row, free] + np.bincount(owner, sign, len(points))
