"""The largest spherical cap that holds none of a set of directions: where the warp's pole
goes (docs/math.md, section 9: put ``+Y`` in the middle of the part of the sphere the region
does not cover).

Every facet of the convex hull of unit directions cuts off a cap that holds none of them
(all lie on the facet's inner side), and the largest empty cap is one of these: its boundary
circle passes through at least three directions. So the pole is the outward normal of the
facet whose plane lies nearest the origin (the smaller that distance, the larger the cap it
cuts off), and the cap's angular radius is ``acos`` of that distance.

A hull of every direction of a large region is slow (every direction on a sphere is a hull
vertex), so :func:`exact_empty_cap` builds it on a subset first and adds the directions its
cap holds until it holds none: a subset's largest empty cap is at least as large as the whole
set's, so one that holds none of the whole set is the whole set's.

:func:`free_cap` is the cap free of the region itself, not only of its vertices: a face
whose corners lie round the pole covers it (radius 0), and a long edge may dip into the cap
between its ends (the radius is then the arc's distance, :func:`transforms.margins.arcs_to_point`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from ..arrays import INDEX, unit_rows
from ..checkpoints import checkpoint
from ..margins import _POINT_ARC
from . import fused

#: Rounds of :func:`exact_empty_cap`, and the most directions a round adds (a region that
#: covers nearly every direction has only gaps between its vertices, which take many rounds
#: to close: after the last, the hull of every direction, at most FULL_HULL, gives it).
_ROUNDS = 4
_ADDED = 2048
#: The most directions whose hull is built at once (50,000 take about 0.25 s and 40 MB).
FULL_HULL = 50_000
#: The boundary loops whose two sides :func:`free_cap` also measures (the longest).
_FREE_TRIES = 3


def largest_empty_cap(directions: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and angular radius of the largest cap holding none of ``directions``.

    Parameters
    ----------
    directions : (k, 3) float, non-zero (normalised here)

    Returns
    -------
    pole : (3,) float, unit
    radius : float, radians in ``[0, pi]``
    """
    units = unit_rows(np.asarray(directions, dtype=np.float64))[0]
    try:
        hull = ConvexHull(units)
    except (QhullError, ValueError):
        # Too few or coplanar directions: the cap opposite their mean.
        mean = units.sum(axis=0)
        norm = float(np.linalg.norm(mean))
        pole = -mean / norm if norm > 0 else np.array([0.0, 1.0, 0.0])
        return pole, cap_radius(units, pole)
    # Qhull's facets: normal . x + offset <= 0 inside, normals outward and unit.
    # The plane nearest the origin cuts off the largest cap (radius acos of its distance).
    nearest = int(np.argmin(-hull.equations[:, 3]))
    pole = hull.equations[nearest, :3] / np.linalg.norm(hull.equations[nearest, :3])
    return pole, cap_radius(units, pole)


def cap_radius(directions: np.ndarray, pole: np.ndarray) -> float:
    """Angular radius (radians) of the largest cap around unit ``pole`` that holds none of
    the unit ``directions`` (k, 3): the angle to the nearest one."""
    cosine = float(np.clip((directions @ pole).max(), -1.0, 1.0))
    return math.acos(cosine)


def exact_empty_cap(
    directions: np.ndarray, rows: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """The largest cap holding none of ``directions`` (k, 3), non-zero: the hull of the
    ``rows`` first (None: all), then of those and the directions its cap holds, until it holds
    none (docs/math.md, section 9). After ``_ROUNDS`` rounds without that (a region that
    covers nearly every direction), the hull of every direction, or of ``FULL_HULL`` spread
    evenly over a larger set (then a gap near the largest, with its true radius).

    Returns
    -------
    pole : (3,) float, unit
    radius : float, radians in ``[0, pi]``, the angle from ``pole`` to the nearest direction
    """
    return _exact_empty_cap(unit_rows(np.asarray(directions, dtype=np.float64))[0], rows)


def _exact_empty_cap(units: np.ndarray, rows: np.ndarray | None) -> tuple[np.ndarray, float]:
    """:func:`exact_empty_cap` of directions already unit."""
    subset = np.arange(len(units)) if rows is None else np.unique(rows)
    for _ in range(_ROUNDS):
        checkpoint()
        pole, _ = largest_empty_cap(units[subset])
        cosine = units @ pole
        held = np.flatnonzero(cosine > cosine[subset].max())
        if len(held) == 0:
            break
        held = held[np.argsort(-cosine[held], kind="stable")[:_ADDED]]
        subset = np.union1d(subset, held)
    else:
        spread = np.linspace(0, len(units) - 1, min(len(units), FULL_HULL)).astype(np.int64)
        pole, _ = largest_empty_cap(units[np.union1d(subset, spread)])
    return pole, cap_radius(units, pole)


def free_cap(
    directions: np.ndarray,
    faces: np.ndarray,
    rows: np.ndarray | None = None,
    boundary: np.ndarray | None = None,
    loops: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, float, float]:
    """A cap free of a region seen from its centre, as large as found, and the largest gap
    between the region's vertices' directions (docs/math.md, section 9).

    The candidates for its middle: that of the largest cap free of every vertex direction
    (:func:`exact_empty_cap`, its hull started on ``rows``), and those of caps free of the
    ``boundary``'s directions (:func:`_boundary_poles`: the region's edge bounds the
    directions it leaves free, where no fold does). Each is measured exactly
    (:func:`_clearances`) and the clearest kept.

    Parameters
    ----------
    directions : (n, 3) float, non-zero, from the centre to each of the region's vertices
    faces : (m, 3) int, the region's faces, indices into ``directions``
    rows : (k,) int or None, the rows the hull starts from (:func:`exact_empty_cap`)
    boundary : (b, 2) int or None, the region's boundary edges (rows of ``directions``)
    loops : :func:`boundary_loops` of ``boundary`` when already known

    Returns
    -------
    pole : (3,) float, unit, the cap's middle
    free : float, radians: the angle from ``pole`` to the nearest point of the region seen
        from the centre; 0 when every candidate is covered by a face (the region closes
        round the centre)
    vertex_gap : float, radians: the radius of the largest cap free of vertex directions
    """
    units = unit_rows(np.asarray(directions, dtype=np.float64))[0]
    edge, loops = boundary_loops(len(units), boundary) if loops is None else loops
    edge_pole = largest_empty_cap(units[edge])[0] if len(edge) else None
    pole, vertex_gap = _exact_empty_cap(units, rows)
    checkpoint()
    poles = [pole, *_boundary_poles(units, edge, loops, edge_pole)]
    clear = _clearances(units, faces, np.array(poles))
    best = int(np.argmax(clear))
    return poles[best], float(clear[best]), vertex_gap


def boundary_loops(n: int, boundary: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The boundary's vertices (rows of the ``n`` directions, ascending) and each one's loop
    label; both empty without a boundary. ``boundary``: (k, 2) int, the boundary edges."""
    if boundary is None or len(boundary) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    ends = np.asarray(boundary, dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(ends)), (ends[:, 0], ends[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    vertices = np.unique(ends)
    return vertices, labels[vertices]


def _boundary_poles(
    units: np.ndarray, vertices: np.ndarray, labels: np.ndarray, edge_pole: np.ndarray | None
) -> list[np.ndarray]:
    """Middles of caps free of the boundary's directions: for each of the ``_FREE_TRIES``
    longest loops, the mean of its directions and its opposite (the two sides of the loop),
    and ``edge_pole``, the largest cap free of every boundary direction
    (:func:`largest_empty_cap`).

    ``vertices``, ``labels``: the boundary's vertices and their loops (:func:`boundary_loops`).
    """
    if edge_pole is None:
        return []
    loops, sizes = np.unique(labels, return_counts=True)
    poles = [edge_pole]
    for loop in loops[np.argsort(-sizes, kind="stable")[:_FREE_TRIES]]:
        mean = units[vertices[labels == loop]].sum(axis=0)
        length = float(np.linalg.norm(mean))
        if length > 0:
            poles += [mean / length, -mean / length]
    return poles


def _clearances(units: np.ndarray, faces: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """(k,) radians from each unit row of ``poles`` (k, 3) to the nearest point of the region
    seen from the centre: 0 when a face's spherical triangle holds it (the same side of its
    three great circles, on the triangle's side of the sphere), else the nearest vertex or
    edge arc (:func:`transforms.margins.arcs_to_point`'s formula): one compiled pass for
    all the candidates (:func:`.fused.clearances`)."""
    checkpoint()
    return fused.clearances(
        np.ascontiguousarray(units, dtype=np.float64),
        np.ascontiguousarray(faces, dtype=INDEX),
        np.ascontiguousarray(poles, dtype=np.float64),
        _POINT_ARC,
    )


def region_free_cap(
    points: np.ndarray, faces: np.ndarray, center: np.ndarray, boundary: np.ndarray, spread: int
) -> tuple[np.ndarray, float, float]:
    """:func:`free_cap` of a region seen from ``center``: its hull started on the
    ``boundary`` vertices and ``spread`` others, both thinned evenly to ``spread`` at most.

    Parameters
    ----------
    points : (n, 3) float, the region's vertices (every one used by ``faces``)
    faces : (m, 3) int, indices into ``points``
    center : (3,) float, not one of ``points``
    boundary : (b, 2) int, the region's boundary edges (rows of ``points``)
    spread : int >= 1

    Returns
    -------
    as :func:`free_cap`
    """
    directions = np.asarray(points, dtype=np.float64) - center  # made unit by free_cap
    n = len(directions)
    rows = np.linspace(0, n - 1, min(spread, n)).astype(np.int64)
    edge = np.unique(boundary)
    if len(edge) > spread:
        edge = edge[np.linspace(0, len(edge) - 1, spread).astype(np.int64)]
    return free_cap(directions, faces, np.union1d(rows, edge), boundary)
