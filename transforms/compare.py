"""Change between two scans of a head: values on each scan's surface, averaged over zones
drawn on one map, read at spots, and the spots found again on the other scan
(docs/math.md, section 22).

Each scan's values are given at its vertices and taken linear inside its triangles (the
values a picture gives are read at the vertices first). A zone's mean on a scan is the
integral of those values over the part of the scan's surface the zone covers on the map,
divided by that part's area: exact, since a triangle's map and surface are affine images of
each other and a linear function's mean over a piece of a triangle is its value at the
piece's centroid (:attr:`transforms.zones.ZoneCover.partial_centroid`). Triangles with a
corner of no value (NaN: off a picture, or transparent there) count towards neither sum,
and the share of the zone they leave without values is reported beside the mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np

from .arrays import triangle_boxes
from .mapping import MapTriangles
from .zones import ZoneCover


@dataclass(frozen=True)
class ZoneMean:
    """The mean of a scan's values over a zone (22.1).

    Attributes
    ----------
    mean : float, NaN where no part of the zone on this scan has values
    area : float, the surface area the zone covers on the scan (its units squared)
    valued_area : float, the part of ``area`` whose triangles have values at every corner
    map_area, valued_map_area : float, the same two on the map (the layout's units squared):
        what two scans on one map are compared by, since a rougher surface has more area
    """

    mean: float
    area: float
    valued_area: float
    map_area: float
    valued_map_area: float


def zone_mean(triangles: MapTriangles, cover: ZoneCover, values: np.ndarray) -> ZoneMean:
    """The area-weighted mean on the surface of ``values``, linear inside each triangle,
    over the part of ``triangles`` a zone covers (eq. 22.1).

    Parameters
    ----------
    triangles : MapTriangles, a scan's region on the map and on its surface
    cover : ZoneCover, the zone over those triangles (:func:`transforms.cover_zone`)
    values : (k,) float, a value at each of the triangles' vertices (NaN: none)
    """
    values = np.asarray(values, dtype=np.float64)
    whole, cut = cover.inside, cover.partial
    means = values[triangles.faces[whole]].mean(axis=1)
    # A piece's mean is the value at its centroid (its weights in its triangle).
    weights = np.nan_to_num(triangles.barycentric(cut, cover.partial_centroid))
    at_centroid = np.einsum("pc,pc->p", weights, values[triangles.faces[cut]])
    piece_mean = np.concatenate([means, at_centroid])
    share = np.concatenate([np.ones(len(whole)), cover.share])
    pieces = np.concatenate([whole, cut])
    surface = share * triangles.surface_area[pieces]
    on_map = share * np.abs(triangles.signed_map_area[pieces])
    valued = np.isfinite(piece_mean)
    valued_area = float(surface[valued].sum())
    total = float(piece_mean[valued] @ surface[valued])
    mean = total / valued_area if valued_area > 0 else float("nan")
    return ZoneMean(
        mean, float(surface.sum()), valued_area, float(on_map.sum()), float(on_map[valued].sum())
    )


def values_at(triangles: MapTriangles, points: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(p,) float: ``values`` ((k,), at the triangles' vertices) at map ``points`` ((p, 2)),
    linear inside the triangle that holds each (:meth:`MapTriangles.locate`); NaN where no
    triangle holds the point or a corner has no value."""
    triangle, weights = triangles.locate(points)
    found = np.full(len(triangle), np.nan)
    held = triangle >= 0
    corners = np.asarray(values, dtype=np.float64)[triangles.faces[triangle[held]]]
    found[held] = np.einsum("pc,pc->p", weights[held], corners)
    return found


def relative_change(before, after) -> tuple[np.ndarray, np.ndarray]:
    """The change ``after - before`` and its percentage of ``before`` (22.2): (n,) float
    each, NaN where either value is NaN, the percentage NaN where ``before`` is 0."""
    before, after = np.asarray(before, np.float64), np.asarray(after, np.float64)
    change = after - before
    with np.errstate(divide="ignore", invalid="ignore"):
        percent = np.where(before != 0, 100.0 * change / np.abs(before), np.nan)
    return change, percent


@dataclass(frozen=True)
class Nearest:
    """The nearest surface points to query points.

    Attributes
    ----------
    points : (p, 3) float, on the surface
    faces : (p,) int, the face each lies on (a row of the faces given)
    distance : (p,) float, from each query point
    """

    points: np.ndarray
    faces: np.ndarray
    distance: np.ndarray


def nearest_on_surface(
    vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, reach: float = np.inf
) -> Nearest:
    """The nearest point of the triangles ``faces`` ((m, 3) int) of ``vertices`` ((k, 3))
    to each of ``points`` ((p, 3)), found exactly by libigl's bounding-box tree (22.3)
    over the triangles whose boxes come within ``reach`` of a point: a point with none
    within ``reach`` may be answered farther than its true nearest (its distance is then
    above ``reach`` all the same), or with face -1 and an infinite distance."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    faces = np.asarray(faces, dtype=np.int64)
    candidates = np.arange(len(faces))
    if np.isfinite(reach) and len(points):
        low, high = triangle_boxes(vertices, faces, reach)
        near = np.zeros(len(faces), dtype=bool)
        for point in points:  # a few spots: one pass over the boxes each
            near |= np.all((low <= point) & (point <= high), axis=1)
        candidates = np.flatnonzero(near)
    if not len(points) or not len(candidates):
        count = len(points)
        return Nearest(np.full((count, 3), np.nan), np.full(count, -1), np.full(count, np.inf))
    kept = np.ascontiguousarray(faces[candidates])
    tree = igl.AABB()
    tree.init(vertices, kept)
    squared, face, foot = tree.squared_distance(vertices, kept, points)
    distance = np.sqrt(np.maximum(squared, 0.0))
    return Nearest(foot, candidates[np.asarray(face, dtype=np.int64)], distance)


def moved(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(p, 3) float: ``points`` ((p, 3)) under the 4x4 affine ``matrix``."""
    matrix = np.asarray(matrix, dtype=np.float64)
    return np.asarray(points, dtype=np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
