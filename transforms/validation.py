"""Per-triangle validation of a region and its margins (MATH.md, "Validation a region needs").

For each face, by its position in the region's face list (the measurements come from
:mod:`.faces`):

* **contains a singular point**: the ray from the centre through a singular point hits the
  closed triangle, decided with exact orientation signs (:mod:`.predicates`);
* **crosses the seam**: its vertices' ``phi`` span more than ``pi``;
* **folded**: its orientation in the ``(phi, theta)`` layout is opposite to the orientation
  its outward side has seen from the centre, that is a flipped triangle in the 2D map (an
  overhang or a non-star-shaped spot); faces with zero layout area are not called folded;
* **back-facing**: ``dot(centroid - c, outward normal) <= 0``, exactly;
* **degenerate**: zero area in 3D or in the layout (relative to the longest edge,
  :data:`.faces.DEGENERATE_RTOL`).

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

from .chart import LAYOUT_ORIENTATION
from .faces import FaceMeasures
from .margins import arcs_to_point, arcs_to_seam
from .topology import region_edges


@dataclass(frozen=True)
class RegionValidation:
    """What :func:`validate` found. Face lists hold positions in the region's face list,
    ascending.

    Attributes
    ----------
    singular_point_faces, seam_faces, folded_faces, backfacing_faces, degenerate_faces :
        (j,) int arrays
    margin_deg_seam, margin_deg_north, margin_deg_south : float, degrees in [0, 180]
    boundary_loops : int
    winding : int, +1 when the file's winding is outward, -1 when it was flipped
    """

    singular_point_faces: np.ndarray
    seam_faces: np.ndarray
    folded_faces: np.ndarray
    backfacing_faces: np.ndarray
    degenerate_faces: np.ndarray
    margin_deg_seam: float
    margin_deg_north: float
    margin_deg_south: float
    boundary_loops: int
    winding: int

    @property
    def seam_free(self) -> bool:
        """No face contains a singular point or crosses the seam."""
        return len(self.singular_point_faces) == 0 and len(self.seam_faces) == 0

    @property
    def star_shaped(self) -> bool:
        """No face is folded or back-facing."""
        return len(self.folded_faces) == 0 and len(self.backfacing_faces) == 0


def validate(
    measures: FaceMeasures, winding: int | None = None, threads: int = 1
) -> RegionValidation:
    """Validate a region from its face measurements.

    Parameters
    ----------
    measures : FaceMeasures, from :func:`.faces.measure_faces` (which tested the singular
        points of the chart's cap)
    winding : +1 or -1 to fix which way normals point; ``None`` decides from the region's
        signed solid angle (the sum of its faces' orientations seen from the centre)
    threads : int, threads to share the edge classification

    Returns
    -------
    RegionValidation
    """
    orientation = measures.orientation
    if winding is None:
        winding = -1 if int(orientation.sum(dtype=np.int64)) < 0 else 1
    seam = measures.crosses_seam
    folded = (LAYOUT_ORIENTATION * winding) * measures.layout_double_area < 0
    folded &= ~measures.degenerate
    backfacing = orientation != winding  # winding * orientation <= 0, orientation in {-1, 0, 1}

    edges = region_edges(measures.faces, orientation, measures.vertices.shape[1], threads)
    north_deg, south_deg, seam_deg = _margins_deg(
        measures,
        edges.outline,
        measures.contains_north.any(),
        measures.contains_south.any(),
        seam.any(),
    )
    return RegionValidation(
        singular_point_faces=np.flatnonzero(measures.contains_north | measures.contains_south),
        seam_faces=np.flatnonzero(seam),
        folded_faces=np.flatnonzero(folded),
        backfacing_faces=np.flatnonzero(backfacing),
        degenerate_faces=np.flatnonzero(measures.degenerate),
        margin_deg_seam=seam_deg,
        margin_deg_north=north_deg,
        margin_deg_south=south_deg,
        boundary_loops=edges.boundary_loops(),
        winding=winding,
    )


def _margins_deg(
    measures: FaceMeasures,
    outline: np.ndarray,
    touches_north: bool,
    touches_south: bool,
    touches_seam: bool,
) -> tuple[float, float, float]:
    """Degrees from the region's outline to the north and south singular points and the seam.

    The distance from a closed set to a point or arc outside it is reached on the set's
    boundary, and seen from the centre the region's boundary lies on its outline edges; when a
    face contains the point (or crosses the seam) the margin is 0.
    """
    if len(outline) == 0:
        # A closed region around the centre covers every direction.
        return 0.0, 0.0, 0.0
    cap = measures.cap
    ends = _unit_directions(measures.vertices, outline)
    a, b = ends[:, 0], ends[:, 1]
    north = 0.0 if touches_north else float(arcs_to_point(a, b, cap.north).min())
    south = 0.0 if touches_south else float(arcs_to_point(a, b, cap.south).min())
    if touches_north or touches_south or touches_seam:
        seam = 0.0
    else:
        seam = float(arcs_to_seam(a, b, cap).min())
    return math.degrees(north), math.degrees(south), math.degrees(seam)


def _unit_directions(vertices: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(k, 2, 3) float: unit directions of the ends of vertex-index ``edges`` (k, 2), from
    vertex rows (3, n)."""
    points = vertices[:, edges].transpose(1, 2, 0)
    return points / np.linalg.norm(points, axis=2, keepdims=True)
