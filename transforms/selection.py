"""Which faces a region is, and the centre it is seen from: faces, vertices or groups the
caller lists, or a cone of directions around an axis (``docs/math.md``, "Regions and
centres").

Every id is the file's own: nothing here renumbers. Errors name the field of the request the
selection came from (``region.faces``, ``center``, ...), so the service can place them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from .arrays import as_direction, triangle_areas, unit_rows
from .errors import TransformInputError

#: The named centres: the area-weighted centroid or the bounding-box centre of the faces.
NAMED_CENTERS = ("centroid", "bbox_center")


class EmptyRegionError(TransformInputError):
    """The selection holds no face (a region must have at least one)."""


def listed_ids(values: Sequence[int], limit: int, field: str, noun: str) -> np.ndarray:
    """``values`` as an int64 array of ids in ``[0, limit)``, each listed once.

    Parameters
    ----------
    values : (k,) int
    limit : int, how many faces or vertices the mesh has
    field : the request field named in errors (``region.faces``)
    noun : ``face`` or ``vertex``

    Raises
    ------
    TransformInputError
        An id out of range (the first, with up to five listed) or repeated.
    """
    try:
        ids = np.asarray(values, dtype=np.int64)
    except OverflowError:
        # Only an id beyond 64 bits gets here; find it for the message.
        huge = next(value for value in values if not -(2**63) <= value < 2**63)
        raise _outside(field, noun, huge, limit, []) from None
    bad = np.flatnonzero((ids < 0) | (ids >= limit))
    if bad.size:
        raise _outside(field, noun, int(ids[bad[0]]), limit, ids[bad[:5]].tolist())
    unique, counts = np.unique(ids, return_counts=True)
    if (counts > 1).any():
        repeated = unique[counts > 1]
        raise TransformInputError(
            field,
            f"{noun} id {int(repeated[0])} is listed more than once ({len(repeated)} ids repeat)",
            repeated[:5].tolist(),
        )
    return ids


def _outside(field: str, noun: str, value: int, limit: int, indices: list[int]):
    plural = {"vertex": "vertices", "face": "faces"}[noun]
    return TransformInputError(
        field,
        f"{noun} id {value} is outside [0, {limit:,}) (the mesh has {limit:,} "
        f"{noun if limit == 1 else plural})",
        indices,
    )


def faces_listed(ids: Sequence[int], n_faces: int) -> np.ndarray:
    """(k,) int: the listed face ids, ascending (``region.faces``)."""
    return np.sort(listed_ids(ids, n_faces, "region.faces", "face"))


def faces_of_vertices(faces: np.ndarray, ids: Sequence[int], n_vertices: int) -> np.ndarray:
    """(k,) int: ascending ids of the faces whose three vertices are all listed
    (``region.vertices``).

    Parameters
    ----------
    faces : (m, 3) int, the whole mesh's faces
    ids : the listed vertex ids
    n_vertices : int
    """
    listed = np.zeros(n_vertices, dtype=bool)
    listed[listed_ids(ids, n_vertices, "region.vertices", "vertex")] = True
    return np.flatnonzero(listed[faces].all(axis=1))


def faces_of_groups(
    groups: Mapping[str, np.ndarray], names: Sequence[str], n_faces: int
) -> np.ndarray:
    """(k,) int: ascending ids of the faces in any of the groups ``names``
    (``region.groups``).

    Parameters
    ----------
    groups : name -> (g, 2) int ranges ``[start, stop)`` of face ids
    names : the groups asked for
    n_faces : int

    Raises
    ------
    TransformInputError
        A name the mesh has no group of (the message lists up to 20 it has).
    """
    missing = [name for name in names if name not in groups]
    if missing:
        known = ", ".join(repr(name) for name in sorted(groups)[:20]) or "none"
        raise TransformInputError(
            "region.groups", f"no group named {missing[0]!r}; the file's groups: {known}"
        )
    ranges = np.concatenate([groups[name] for name in names]).reshape(-1, 2)
    # +1 at each start, -1 at each stop: faces with a positive running sum are covered.
    marks = np.zeros(n_faces + 1, dtype=np.int64)
    np.add.at(marks, ranges[:, 0], 1)
    np.add.at(marks, ranges[:, 1], -1)
    return np.flatnonzero(np.cumsum(marks[:-1]) > 0)


def bbox_center(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(3,) float: the middle of the bounding box of the vertices ``faces`` use.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    """
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    points = vertices[used]
    # Column by column: a reduction down the rows of an (n, 3) array is ten times slower.
    low = np.array([points[:, k].min() for k in range(3)])
    high = np.array([points[:, k].max() for k in range(3)])
    return (low + high) / 2.0


def area_centroid(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(3,) float: the area-weighted centroid of the triangles ``faces``.

    Raises
    ------
    TransformInputError
        (``center``) The triangles have no area.
    """
    areas = triangle_areas(vertices, faces)
    if not areas.sum() > 0:
        raise TransformInputError("center", "'centroid' needs faces with area")
    return (vertices[faces].mean(axis=1) * areas[:, None]).sum(axis=0) / areas.sum()


def named_center(vertices: np.ndarray, faces: np.ndarray, name: str) -> np.ndarray:
    """(3,) float: the centre :data:`NAMED_CENTERS` names, of the triangles ``faces``."""
    if name == "centroid":
        return area_centroid(vertices, faces)
    return bbox_center(vertices, faces)


def cone_faces(
    vertices: np.ndarray,
    faces: np.ndarray,
    apex: np.ndarray,
    axis: Sequence[float],
    half_angle_deg: float,
) -> np.ndarray:
    """(k,) int: ascending ids of the faces whose centroid, seen from ``apex``, lies within
    ``half_angle_deg`` of ``axis`` (``region.cone``); a centroid at the apex is in none.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int, the whole mesh's faces
    apex : (3,) float
    axis : (3,) float, non-zero
    half_angle_deg : float in (0, 180]

    Raises
    ------
    TransformInputError
        (``region.cone.axis``) A zero axis.
    """
    axis = as_direction(axis, "region.cone.axis")
    # The centroids' directions by the same rule as the axis: scale-free, so a tiny mesh's
    # cone is the cone of the mesh scaled up.
    directions, at_apex = unit_rows(vertices[faces].mean(axis=1) - apex)
    inside = directions @ axis >= math.cos(math.radians(half_angle_deg)) - 1e-15
    return np.flatnonzero(inside & ~at_apex)


def nonempty(faces: np.ndarray) -> np.ndarray:
    """``faces`` (ids), unless there are none.

    Raises
    ------
    EmptyRegionError
        (``region``) No face was selected.
    """
    if len(faces) == 0:
        raise EmptyRegionError("region", "selects no faces")
    return faces
