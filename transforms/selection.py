"""Which faces a region is, and the centre it is seen from: faces, vertices or groups the
caller lists, or a cone of directions around an axis (``docs/math.md``, "Regions and
centres").

Every id is the file's own: nothing here renumbers. Errors name the field of the request the
selection came from (``region.faces``, ``center``, ...), so the service can place them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from .arrays import as_direction, triangle_areas, unit_rows
from .errors import TransformInputError
from .ownframe import OwnFrame
from .pixels import face_means
from .topology import face_components, largest_piece, piece_sizes

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
    """(3,) float: the middle of the box of the vertices ``faces`` use, along the triangles'
    own axes (:class:`~transforms.ownframe.OwnFrame`): it moves and turns with the mesh,
    where the middle of the world axes' box would depend on the pose (docs/math.md,
    section 8).

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    """
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    points = vertices if used.all() else vertices[used]
    return OwnFrame.of_triangles(vertices, faces).box_middle(points)


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


class Pieces(StrEnum):
    """Which connected pieces of the selected faces a region keeps (``region.pieces``)."""

    ALL = "all"
    LARGEST = "largest"


@dataclass(frozen=True)
class RegionPieces:
    """The connected pieces of a region (docs/math.md, section 8: welding and pieces).

    Attributes
    ----------
    sizes : (p,) int, each piece's face count, largest first
    stray : (j,) int, ascending: the ids of the faces outside the largest piece
    """

    sizes: np.ndarray
    stray: np.ndarray

    @property
    def count(self) -> int:
        """How many pieces the region is."""
        return len(self.sizes)


def region_pieces(links: np.ndarray, face_ids: np.ndarray) -> tuple[RegionPieces, np.ndarray]:
    """The pieces of a region: faces sharing an edge are in one piece
    (:func:`.topology.face_components`); and which of its faces are its largest piece
    ((k,) bool).

    Parameters
    ----------
    links : (k, 3) int, the region's faces welded (:func:`.topology.representatives`:
        corners at one position are one vertex), in the order of ``face_ids``
    face_ids : (k,) int, ascending, at least one: the region's face ids
    """
    labels = face_components(links)
    largest = largest_piece(labels)
    return RegionPieces(sizes=piece_sizes(labels), stray=face_ids[~largest]), largest


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


# -- regions painted on the file: colours, ids, a texture mask (docs/math.md, section 16) --


class Channel(StrEnum):
    """What of a vertex's colour a threshold reads."""

    R = "r"
    G = "g"
    B = "b"
    A = "a"
    LUMINANCE = "luminance"

    def of(self, colors: np.ndarray) -> np.ndarray:
        """(n,) float: the channel of ``colors`` ((n, 4) RGBA in [0, 1]); the luminance is
        Rec. 709's weighted sum of the stored red, green and blue."""
        if self is Channel.LUMINANCE:
            return colors[:, :3] @ np.array([0.2126, 0.7152, 0.0722])
        return colors[:, "rgba".index(self.value)].astype(np.float64)


class CornerRule(StrEnum):
    """How many of a face's three vertices must pass for the face to be in."""

    ALL = "all"
    ANY = "any"
    MAJORITY = "majority"

    def faces(self, faces: np.ndarray, passes: np.ndarray) -> np.ndarray:
        """(j,) int: the ids of ``faces`` ((m, 3) int) whose corners pass by this rule
        (``passes``: (n,) bool a vertex)."""
        count = passes[faces].sum(axis=1)
        need = {CornerRule.ALL: 3, CornerRule.ANY: 1, CornerRule.MAJORITY: 2}[self]
        return np.flatnonzero(count >= need)


def faces_by_color(
    faces: np.ndarray,
    colors: np.ndarray,
    channel: Channel,
    minimum: float,
    rule: CornerRule,
    field: str = "region.vertex_color",
) -> np.ndarray:
    """(j,) int: the faces whose vertices' ``channel`` is at least ``minimum``, by ``rule``.

    Raises
    ------
    EmptyRegionError
        No face passes; the message gives the channel's range over the vertices.
    """
    values = channel.of(colors)
    found = rule.faces(faces, values >= minimum)
    if len(found) == 0:
        raise EmptyRegionError(
            field,
            f"no face has {rule.value} of its vertices with {channel.value} >= {minimum:g}; "
            f"the vertices' {channel.value} runs from {values.min():.4g} to {values.max():.4g}",
        )
    return found


def faces_by_ids(
    faces: np.ndarray,
    values: np.ndarray,
    wanted: Sequence[float],
    per_face: bool,
    rule: CornerRule = CornerRule.ALL,
    field: str = "region.feature_id",
) -> np.ndarray:
    """(j,) int: the faces whose id (``values``: (m,) a face when ``per_face``, else (n,) a
    vertex, taken by ``rule``) is one of ``wanted``.

    Raises
    ------
    EmptyRegionError
        None is; the message lists some of the ids the attribute holds.
    """
    listed = np.isin(values, np.asarray(wanted, dtype=np.float64))
    found = np.flatnonzero(listed) if per_face else rule.faces(faces, listed)
    if len(found) == 0:
        present = np.unique(values[np.isfinite(values)])
        shown = ", ".join(f"{v:g}" for v in present[:10]) + (", ..." if len(present) > 10 else "")
        raise EmptyRegionError(
            field, f"no face has one of the ids {list(wanted)}; the attribute holds {shown}"
        )
    return found


def faces_by_mask(
    uv: np.ndarray,
    uv_faces: np.ndarray,
    mask: np.ndarray,
    minimum: float,
    field: str = "region.texture_mask",
) -> np.ndarray:
    """(j,) int: the faces whose mean of ``mask`` ((h, w) in [0, 1]) over their triangle in
    texture space is at least ``minimum`` (:func:`pixels.face_means`; the mask is 0 off the
    image, and a face with a corner without texture coordinates, or with non-finite ones, is
    out).

    ``uv`` ((k, 2)) has ``(0, 0)`` at the image's top-left corner and ``(1, 1)`` at its
    bottom-right; ``uv_faces`` ((m, 3) int) its row at each face corner, -1 for none.

    Raises
    ------
    EmptyRegionError
        No face passes; the message gives the range of the faces' means.
    """
    height, width = mask.shape
    given = (uv_faces >= 0).all(axis=1)
    given[given] = np.isfinite(uv[uv_faces[given]]).all(axis=(1, 2))  # NaN: none given
    textured = np.flatnonzero(given)
    corners = uv[uv_faces[textured]] * np.array([width, height], dtype=np.float64)
    means, coverage = face_means(corners, mask)
    means = np.where(np.isnan(means), 0.0, means * coverage)  # 0 off the image
    found = textured[means >= minimum]
    if len(found) == 0:
        top = float(means.max()) if len(means) else 0.0
        raise EmptyRegionError(
            field,
            f"no face's mean of the mask reaches {minimum:g} (the largest is {top:.4g}, over "
            f"{len(textured):,} faces with texture coordinates)",
        )
    return found
