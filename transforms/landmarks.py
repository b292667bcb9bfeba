"""A frame that belongs to the head: centre, pole and roll from anatomical landmarks, and the
scalp above a boundary through them (docs/math.md, section 14).

The nasion, the inion and the two tragi fix three axes: ``right`` from the left tragus to the
right one, ``forward`` from the inion towards the nasion (made square to ``right``) and
``up = right x forward``. The centre lies above the tragi's midpoint by a quarter of their
distance; the pole points down the neck and local ``+Z`` forward, so the nasion always sits at
the same azimuth. The rule uses the landmarks alone: the same head scanned twice, in any pose,
gets the same frame, and a fixed sigma the same map.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .arrays import as_points, triangle_boxes
from .errors import TransformInputError
from .frames import Frame
from .topology import face_components

#: The landmarks, in the order they are checked; the vertex is optional.
LANDMARK_NAMES = ("nasion", "inion", "left_tragus", "right_tragus", "vertex")
#: The centre's height above the tragi's midpoint, as a share of the tragi's distance.
CENTER_RAISE = 0.25
#: Landmarks closer than this share of the tragi's distance coincide; the nasion and inion
#: closer than this to the tragi's line (as a share of their distance) are collinear with it.
COINCIDE = 0.05
#: The farthest a landmark may lie from the surface, as a share of the tragi's distance.
OFF_SURFACE = 0.05


@dataclass(frozen=True)
class Landmarks:
    """The landmarks of a head, world points ((3,) float each; ``vertex`` may be None)."""

    nasion: np.ndarray
    inion: np.ndarray
    left_tragus: np.ndarray
    right_tragus: np.ndarray
    vertex: np.ndarray | None = None
    field: str = "landmarks"

    @classmethod
    def of(cls, points: Mapping[str, object], field: str = "landmarks") -> Landmarks:
        """The landmarks named in ``points`` (name -> (3,) float), checked: none missing but
        the vertex, none coinciding, the nasion and inion off the tragi's line, the vertex
        above the tragi (so that left and right are not swapped).

        Raises
        ------
        TransformInputError
            Naming the landmark (``field.name``) and the limit.
        """
        found = {}
        for name in LANDMARK_NAMES:
            if points.get(name) is None:
                if name == "vertex":
                    continue
                raise TransformInputError(f"{field}.{name}", "missing")
            found[name] = as_points(np.reshape(points[name], (1, 3)), f"{field}.{name}")[0]
        landmarks = cls(**found, field=field)
        landmarks._check()
        return landmarks

    @property
    def width(self) -> float:
        """The tragi's distance: the head's scale for every tolerance."""
        return float(np.linalg.norm(self.right_tragus - self.left_tragus))

    def named(self) -> dict[str, np.ndarray]:
        """The landmarks given, by name."""
        values = (self.nasion, self.inion, self.left_tragus, self.right_tragus, self.vertex)
        return {n: v for n, v in zip(LANDMARK_NAMES, values, strict=True) if v is not None}

    def _check(self) -> None:
        named = self.named()
        names = list(named)
        scale = max(float(np.linalg.norm(a - b)) for a in named.values() for b in named.values())
        if not scale > 0:
            raise TransformInputError(f"{self.field}.inion", "all the landmarks coincide")
        for i, first in enumerate(names):
            for second in names[i + 1 :]:
                gap = float(np.linalg.norm(named[first] - named[second]))
                if gap < COINCIDE * scale:
                    raise TransformInputError(
                        f"{self.field}.{second}",
                        f"coincides with {first} ({gap:.4g} apart; landmarks must be at least "
                        f"{COINCIDE:.0%} of the largest distance between two of them apart)",
                    )
        right = _unit(self.right_tragus - self.left_tragus)
        for name in ("nasion", "inion"):
            offset = named[name] - self.left_tragus
            off_line = float(np.linalg.norm(offset - np.dot(offset, right) * right))
            if off_line < COINCIDE * self.width:
                raise TransformInputError(
                    f"{self.field}.{name}",
                    f"lies on the line through the tragi ({off_line:.4g} from it; at least "
                    f"{COINCIDE:.0%} of the tragi's distance, {COINCIDE * self.width:.4g})",
                )
        along = self.nasion - self.inion
        square = along - np.dot(along, right) * right
        if float(np.linalg.norm(square)) < COINCIDE * self.width:
            raise TransformInputError(
                f"{self.field}.nasion",
                "the nasion and the inion lie along the tragi's line: no forward direction",
            )
        if self.vertex is not None:
            height = float(np.dot(self.vertex - self.midpoint, self.axes()[2]))
            if height <= 0:
                raise TransformInputError(
                    f"{self.field}.vertex",
                    "lies below the tragi with the nasion in front: left_tragus and "
                    "right_tragus may be swapped",
                )

    @property
    def midpoint(self) -> np.ndarray:
        """(3,) float: halfway between the tragi."""
        return (self.left_tragus + self.right_tragus) / 2.0

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``right``, ``forward``, ``up``: (3,) float each, orthonormal, right-handed (eq. 14.1)."""
        right = _unit(self.right_tragus - self.left_tragus)
        along = self.nasion - self.inion
        forward = _unit(along - np.dot(along, right) * right)
        return right, forward, np.cross(right, forward)

    def frame(self) -> Frame:
        """The head's frame (eq. 14.2): centre ``CENTER_RAISE`` of the tragi's distance above
        their midpoint, the pole down (``-up``), local ``+Z`` towards the nasion."""
        _, forward, up = self.axes()
        center = self.midpoint + CENTER_RAISE * self.width * up
        return Frame.from_pole_up(-up, forward, center)

    def check_on_surface(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        """Refuse a landmark farther than ``OFF_SURFACE`` of the tragi's distance from the
        triangles ``faces`` ((m, 3) int) of ``vertices`` ((k, 3) float).

        Raises
        ------
        TransformInputError
            Naming the landmark, its distance and the tolerance.
        """
        limit = OFF_SURFACE * self.width
        low, high = triangle_boxes(vertices, faces, limit)
        for name, point in self.named().items():
            # Only a triangle whose box reaches within the limit can be that near.
            near = np.all((low <= point) & (point <= high), axis=1)
            distance = distance_to_triangles(point, vertices, faces[near])
            if distance > limit:
                distance = distance_to_triangles(point, vertices, faces)  # for the words
                raise TransformInputError(
                    f"{self.field}.{name}",
                    f"lies {distance:.4g} from the surface; at most {limit:.4g} "
                    f"({OFF_SURFACE:.0%} of the tragi's distance)",
                )

    def scalp_faces(self, vertices: np.ndarray, faces: np.ndarray, offset: float) -> np.ndarray:
        """(j,) int: the faces whose centroid lies above the scalp's boundary plane (eq. 14.3),
        through the nasion and the inion raised by ``offset`` (mesh units) and level from left
        to right, and that are joined by shared edges (vertices at one position count as one)
        to the one farthest along ``up`` (the top of the head: the eye sockets' and the ears'
        tops are left out)."""
        right, _, up = self.axes()
        brow, back = self.nasion + offset * up, self.inion + offset * up
        normal = _unit(np.cross(brow - back, right))
        if np.dot(normal, up) < 0:
            normal = -normal
        centroids = vertices[faces].mean(axis=1)
        above = np.flatnonzero((centroids - brow) @ normal > 0)
        if len(above) == 0:
            return above
        pieces = face_components(faces[above], vertices)
        return above[pieces == pieces[np.argmax(centroids[above] @ up)]]


def _unit(vector: np.ndarray) -> np.ndarray:
    return vector / np.linalg.norm(vector)


def distance_to_triangles(point: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> float:
    """The least distance from ``point`` ((3,) float) to the triangles ``faces`` ((m, 3)
    int) of ``vertices`` ((k, 3) float), vectorised over the triangles: the point's foot on a
    triangle's plane when it falls inside the triangle, else the nearest point of its edges."""
    if len(faces) == 0:
        return float("inf")
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    best = np.full(len(faces), np.inf)
    for start, end in ((a, b), (b, c), (c, a)):
        edge, offset = end - start, point - start
        length2 = np.einsum("md,md->m", edge, edge)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(np.nan_to_num(np.einsum("md,md->m", offset, edge) / length2), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(offset - t[:, None] * edge, axis=1))
    # The foot on the plane, by its barycentric weights (Cramer's rule on the Gram matrix).
    u, v, w = b - a, c - a, point - a
    uu, uv, vv = (np.einsum("md,md->m", p, q) for p, q in ((u, u), (u, v), (v, v)))
    wu, wv = np.einsum("md,md->m", w, u), np.einsum("md,md->m", w, v)
    det = uu * vv - uv * uv
    with np.errstate(divide="ignore", invalid="ignore"):
        beta, gamma = (vv * wu - uv * wv) / det, (uu * wv - uv * wu) / det
    inside = (det > 0) & (beta >= 0) & (gamma >= 0) & (beta + gamma <= 1)
    foot = u[inside] * beta[inside, None] + v[inside] * gamma[inside, None]
    best[inside] = np.minimum(best[inside], np.linalg.norm(w[inside] - foot, axis=1))
    return float(best.min())
