"""Per-triangle validation of a region and its margins (docs/math.md, section 6).

For each face, by its position in the region's face list (the measurements come from
:mod:`.faces`):

* **contains a singular point**: the ray from the centre through a singular point hits the
  closed triangle, decided with exact orientation signs (:mod:`.predicates`);
* **crosses the seam**: its vertices' ``phi`` span more than ``pi`` (the brief's test), or one
  of its edges, seen from the centre, meets the seam arc: with ``rho < 90`` degrees an edge
  between two corners outside the cap can dip into it and cross the seam twice, which the
  span test cannot see;
* **folded**: its orientation in the ``(phi, theta)`` layout is opposite to the orientation
  its outward side has seen from the centre, that is a flipped triangle in the 2D map (an
  overhang or a non-star-shaped spot); faces with zero layout area are not called folded.
  The brief's "its orientation seen from the centre" is read as the orientation of the face's
  outward side: compared with the raw winding instead, an overhang's triangles, which the
  map shows flipped over their neighbours, would not count as folded. Back-facing is the
  3D cause, folded the 2D effect; folded also catches flips the layout makes by itself
  (large triangles next to the cap);
* **back-facing**: ``dot(centroid - c, outward normal) <= 0``, exactly;
* **degenerate**: zero area in 3D or in the layout (relative to its edges,
  :data:`.faces.DEGENERATE_RTOL`);
* **stretched**: not degenerate, and its isometric energy (docs/math.md, section 7, the
  layout scaled to the region's area) is above :data:`STRETCHED_ENERGY`: the map is one to
  one there, but stretches the triangle so far that its picture misleads and a mean over
  the region is dominated by it (section 6, "stretched").

"Outward" is the file's winding, unless the region as a whole winds the other way round the
centre (its signed solid angle is negative), in which case every normal is flipped and
``winding`` reports -1.

For the region: the angular margins from its outline seen from the centre to the seam and to
each singular point (0 when a face touches them), and its number of boundary loops.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .arrays import blocks, unit_rows
from .enclosure import encloses_centre
from .errors import TransformInputError
from .faces import FaceMeasures
from .layouts import LAYOUT_ORIENTATION
from .margins import arcs_to_point, arcs_to_seam
from .metrics import stretched_faces
from .parallel import run_all
from .topology import region_edges

#: A triangle whose isometric energy is above this is stretched (docs/math.md, section 6):
#: 10 is a triangle drawn about 6.2 times too long in one direction (``s1 = 6.2``,
#: ``s2 = 1``), or about 4.5 times too large in both (``s1 = s2 = 4.5``).
STRETCHED_ENERGY = 10.0

#: An edge that comes within this angle (radians) of the seam counts as meeting it.
_SEAM_TOUCH = 1e-12
_EDGES = ((0, 1), (1, 2), (2, 0))


def _dot(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Column-wise dot product of (3, k) arrays."""
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]


@dataclass(frozen=True)
class RegionValidation:
    """What :func:`validate` found. Face lists hold positions in the region's face list,
    ascending.

    Attributes
    ----------
    singular_point_faces, seam_faces, folded_faces, backfacing_faces, degenerate_faces,
    stretched_faces : (j,) int arrays
    margin_deg_seam, margin_deg_north, margin_deg_south : float, degrees in [0, 180]
    boundary_loops : int
    boundary_edges : (k, 2) int, vertex pairs (indices as in the measured faces) of the edges
        only one region face uses
    winding : int, +1 when the file's winding is outward, -1 when it was flipped
    encloses_centre : bool, seen from the centre the region closes round it and covers every
        direction, so no cap of directions is free of it: it has no outline edge, or its
        faces close up and a ray from the centre crosses them an odd number of times
        (:func:`.enclosure.encloses_centre`); False claims nothing
    """

    singular_point_faces: np.ndarray
    seam_faces: np.ndarray
    folded_faces: np.ndarray
    backfacing_faces: np.ndarray
    degenerate_faces: np.ndarray
    stretched_faces: np.ndarray
    margin_deg_seam: float
    margin_deg_north: float
    margin_deg_south: float
    boundary_loops: int
    boundary_edges: np.ndarray
    winding: int
    encloses_centre: bool = False

    @property
    def seam_free(self) -> bool:
        """No face contains a singular point or crosses the seam."""
        return len(self.singular_point_faces) == 0 and len(self.seam_faces) == 0

    @property
    def wrapping_faces(self) -> np.ndarray:
        """(j,) int: the faces that wrap round the map (they cross the seam or hold a
        singular point): their corners lie on both sides of the cut, and the triangle
        between them on the map is not where the face lies on the surface."""
        return np.union1d(self.singular_point_faces, self.seam_faces)

    def drawn_faces(self, count: int) -> np.ndarray:
        """(k,) int: the positions, among the region's ``count`` faces, of those that do not
        wrap round the map (:attr:`wrapping_faces`), ascending: the triangles a map has."""
        keep = np.ones(count, dtype=bool)
        keep[self.wrapping_faces] = False
        return np.flatnonzero(keep)

    @property
    def star_shaped(self) -> bool:
        """No face is folded or back-facing (a stretched face may be: it is not flipped)."""
        return len(self.folded_faces) == 0 and len(self.backfacing_faces) == 0


def validate(
    measures: FaceMeasures,
    winding: int | None = None,
    threads: int = 1,
    links: np.ndarray | None = None,
) -> RegionValidation:
    """Validate a region from its face measurements.

    Parameters
    ----------
    measures : FaceMeasures, from :func:`.faces.measure_faces` (which tested the singular
        points of the chart's cap)
    winding : +1 or -1 to fix which way normals point; ``None`` decides from the region's
        signed solid angle (the sum of its faces' orientations seen from the centre)
    threads : int, threads for the independent parts
    links : (m, 3) int or None, the faces welded (vertices at one position made one,
        docs/math.md section 8), whose edges give the boundary, its loops and the outline;
        None: the measured faces'

    Returns
    -------
    RegionValidation
    """
    orientation = measures.orientation
    if winding is None:
        winding = -1 if int(orientation.sum(dtype=np.int64)) < 0 else 1
    elif isinstance(winding, bool) or winding not in (1, -1):
        raise TransformInputError("winding", f"must be +1, -1 or None, got {winding!r}")
    seam = measures.crosses_seam
    folded = (LAYOUT_ORIENTATION * winding) * measures.layout_double_area < 0
    folded &= ~measures.degenerate
    backfacing = orientation != winding  # winding * orientation <= 0, orientation in {-1, 0, 1}

    contains_north, contains_south = measures.contains_north.any(), measures.contains_south.any()
    flagged = seam.any() or contains_north or contains_south
    # Where the region meets the seam, also find the faces an edge of which dips across it
    # while their corners' phi do not straddle the cut (the brief's span test misses those).
    # When faces are flagged already that search runs beside the edge classification.
    edges, dipping = run_all(
        [
            lambda: region_edges(
                measures.faces if links is None else links,
                orientation,
                measures.vertices.shape[1],
            ),
            lambda: _faces_meeting_seam(measures) if flagged else None,
        ],
        threads,
    )
    north, south, seam_distance = _outline_distances(
        measures, edges.outline, not contains_north, not contains_south, not flagged
    )
    if dipping is None and seam_distance == 0.0:
        dipping = _faces_meeting_seam(measures)
    if dipping is not None:
        seam = seam | dipping
    touches_seam = seam.any() or contains_north or contains_south
    return RegionValidation(
        singular_point_faces=np.flatnonzero(measures.contains_north | measures.contains_south),
        seam_faces=np.flatnonzero(seam),
        folded_faces=np.flatnonzero(folded),
        backfacing_faces=np.flatnonzero(backfacing),
        degenerate_faces=np.flatnonzero(measures.degenerate),
        stretched_faces=stretched_faces(measures, STRETCHED_ENERGY),
        margin_deg_seam=0.0 if touches_seam else math.degrees(seam_distance),
        margin_deg_north=0.0 if contains_north else math.degrees(north),
        margin_deg_south=0.0 if contains_south else math.degrees(south),
        boundary_loops=edges.boundary_loops(),
        boundary_edges=edges.boundary,
        winding=winding,
        encloses_centre=encloses_centre(measures, len(edges.outline), edges.odd_edges),
    )


def _outline_distances(
    measures: FaceMeasures, outline: np.ndarray, north: bool, south: bool, seam: bool
) -> tuple[float, float, float]:
    """Radians from the region's outline to the north and south singular points and the seam
    (only those asked for; the others are 0).

    The distance from a closed set to a point or arc outside it is reached on the set's
    boundary, and seen from the centre the region's boundary lies on its outline edges. A
    region with no outline is closed around the centre and covers every direction (0).
    """
    if len(outline) == 0:
        return 0.0, 0.0, 0.0
    cap = measures.cap
    ends = _unit_directions(measures.vertices, outline)
    a, b = ends[:, 0], ends[:, 1]
    return (
        float(arcs_to_point(a, b, cap.north).min()) if north else 0.0,
        float(arcs_to_point(a, b, cap.south).min()) if south else 0.0,
        float(arcs_to_seam(a, b, cap).min()) if seam else 0.0,
    )


def _faces_meeting_seam(measures: FaceMeasures) -> np.ndarray:
    """(m,) bool: faces one of whose edges, seen from the centre, meets the seam arc (within
    ``_SEAM_TOUCH`` radians).

    Where an edge meets the seam, the meeting point lies within half the edge's angle of the
    nearer end ``v``, and the edge's angle is at most ``2 asin(L / r_v)`` (directions of points
    at least ``r_v`` from the centre and ``L`` apart differ by a chord of at most ``2 L / r_v``).
    The seam lies on the circle at ``rho`` from ``+Y``, at ``x <= 0``. So only faces with a
    corner ``v`` within ``asin(L / r_v)`` of that circle and of that side need the exact arc
    test: found first with ``L`` a bound on every edge, per vertex, then with each candidate
    face's own longest edge. Faces the span test flagged need no test.
    """
    faces, cap = measures.faces, measures.cap
    rows = measures.vertices
    cos_rho, sin_rho = math.cos(cap.rho), math.sin(cap.rho)

    def near(vertex_ids, longest) -> np.ndarray:
        # With h = sqrt(x^2 + z^2) and a the angle from +Y: r sin|a - rho| = |h cos rho -
        # y sin rho| and r cos(a - rho) = y cos rho + h sin rho. "|a - rho| <= asin(L / r)"
        # is then "|h cos rho - y sin rho| <= L, cos(a - rho) >= 0" (no trigonometry).
        # The touch tolerance is an angle: at most _SEAM_TOUCH * r, and r < 2 in scaled units.
        x, y, z = rows[:, vertex_ids]
        reach = longest * (1.0 + 1e-9) + 2.0 * _SEAM_TOUCH
        h = x * x
        h += z * z
        np.sqrt(h, out=h)
        off_circle = h * cos_rho
        off_circle -= y * sin_rho
        close = np.abs(off_circle, out=off_circle) <= reach
        ahead = y * cos_rho
        ahead += h * sin_rho
        close &= ahead >= -reach
        close &= x <= reach
        return close

    vertex_near = np.empty(rows.shape[1], dtype=bool)
    for block in blocks(len(vertex_near)):  # temporaries that stay in cache
        vertex_near[block] = near(block, measures.edge_bound)
    vertex_near = np.take(vertex_near, faces.ravel())
    corner_near = vertex_near.reshape(-1, 3)
    candidates = corner_near[:, 0] | corner_near[:, 1] | corner_near[:, 2]
    candidates &= ~measures.crosses_seam
    candidates = np.flatnonzero(candidates)
    if candidates.size:
        c = faces[candidates]
        corner = [rows[:, c[:, i]] for i in range(3)]
        own = np.sqrt(
            np.maximum.reduce(
                [_dot(corner[i] - corner[j], corner[i] - corner[j]) for i, j in _EDGES]
            )
        )
        candidates = candidates[near(c[:, 0], own) | near(c[:, 1], own) | near(c[:, 2], own)]
    meets = np.zeros(len(faces), dtype=bool)
    if candidates.size:
        c = faces[candidates]
        starts = unit_rows(np.ascontiguousarray(rows[:, c.T.ravel()].T))[0]  # edges 0, 1, 2
        ends = np.concatenate([starts[c.shape[0] :], starts[: c.shape[0]]])  # corners 1, 2, 0
        touch = (arcs_to_seam(starts, ends, cap) <= _SEAM_TOUCH).reshape(3, -1)
        meets[candidates] = touch[0] | touch[1] | touch[2]
    return meets


def _unit_directions(vertices: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(k, 2, 3) float: unit directions of the ends of vertex-index ``edges`` (k, 2), from
    vertex rows (3, n)."""
    points = vertices[:, edges].transpose(1, 2, 0)
    return points / np.linalg.norm(points, axis=2, keepdims=True)
