"""A surface's own frame: an origin, axes and a length that move, turn and scale with it
(docs/math.md, section 8).

Whatever is derived from a surface in its own frame (a fit's starts, a sampler's grid, a
random stream's directions) does not depend on the pose or the unit the surface was stored
in: the same surface moved, turned and scaled gives the same result, moved, turned and
scaled.

The moments are those of the triangles' surfaces (uniform density per unit area), exact for
triangles, so that a finer or coarser triangulation of the same surface gives nearly the
same frame and a mesh of unequal triangles is not pulled towards its dense parts.
"""

from __future__ import annotations

import math

import numpy as np

from .arrays import triangle_areas
from .checkpoints import checkpoint

#: Relative size of a third moment below which its sign is taken as undecided (a symmetric
#: surface): the axis then keeps the sign the eigen-solver gave it.
SKEW_RTOL = 1e-9

#: Coordinates up to 2 to this power are taken as they are (their moments stay finite and
#: normal); beyond it, :meth:`OwnFrame.of_triangles` works on them divided by a power of two.
UNSCALED_EXPONENT = 64


class OwnFrame:
    """Where a surface is, how it is turned and how large it is.

    Immutable; build one with :meth:`of_triangles`:

    >>> import numpy as np
    >>> v = np.array([[0, 0, 0], [4, 0, 0], [0, 1, 0], [0, 0, 0.1]], float)
    >>> f = np.array([[0, 1, 2], [0, 1, 3]])
    >>> frame = OwnFrame.of_triangles(v, f)
    >>> bool(abs(frame.axes[0] @ [1, 0, 0]) > 0.99)   # the long side is the first axis
    True

    Attributes
    ----------
    origin : (3,) float
        The area-weighted centroid of the triangles, world coordinates.
    axes : (3, 3) float
        A proper rotation whose rows are the principal axes of the surface's second
        moments, largest first; each of the first two points where the surface's third
        moment along it is positive, the third is their cross product.
    scale : float
        The surface's RMS distance from its centroid (> 0), in the mesh's unit.
    """

    __slots__ = ("_axes", "_origin", "_scale")

    def __init__(self, origin: np.ndarray, axes: np.ndarray, scale: float) -> None:
        self._origin = np.array(origin, dtype=np.float64)
        self._axes = np.array(axes, dtype=np.float64)
        self._scale = float(scale)
        self._origin.flags.writeable = False
        self._axes.flags.writeable = False

    @classmethod
    def of_triangles(cls, vertices: np.ndarray, faces: np.ndarray) -> OwnFrame:
        """The frame of the surface of ``faces`` ((m, 3) int) over ``vertices`` ((n, 3)).

        Triangles of no area in all: the vertices' mean, the world axes and their RMS
        distance from it (a scale of 1 when they coincide). Coordinates far from 1 (beyond
        2^±64: the fourth powers the moments hold would overflow near 1e77) are first
        divided by a power of two, exactly, and the frame scaled back.
        """
        largest = float(np.abs(vertices).max()) if len(vertices) else 0.0
        exponent = int(np.frexp(largest)[1]) if largest > 0 else 0
        if abs(exponent) > UNSCALED_EXPONENT:
            unit = cls.of_triangles(np.ldexp(vertices, -exponent), faces)
            return cls(np.ldexp(unit.origin, exponent), unit.axes, math.ldexp(unit.scale, exponent))
        checkpoint()
        areas = triangle_areas(vertices, faces)
        total = areas.sum()
        if not total > 0:
            points = vertices[faces.ravel()]
            origin = points.mean(axis=0)
            spread = float(np.sqrt(((points - origin) ** 2).sum(axis=1).mean()))
            return cls(origin, np.eye(3), spread if spread > 0 else 1.0)
        sums = vertices[faces[:, 0]] + vertices[faces[:, 1]] + vertices[faces[:, 2]]
        origin = (areas @ sums) / (3.0 * total)
        # Over a triangle, the integral of x x^T is area/12 (a a^T + b b^T + c c^T + s s^T):
        # the corners' squares gathered per vertex (each weighed by its faces' areas), the
        # sums' squares per face; (n, 3) and (m, 3) temporaries, no (m, 3, 3).
        weights = np.bincount(faces.ravel(), np.repeat(areas, 3), len(vertices))
        offsets = vertices - origin
        sums -= 3.0 * origin
        moment = (offsets * weights[:, None]).T @ offsets + (sums * areas[:, None]).T @ sums
        checkpoint()
        variances, vectors = np.linalg.eigh(moment / (12.0 * total))
        axes = vectors[:, ::-1].T.copy()  # rows, largest variance first
        scale = float(np.sqrt(max(variances.sum(), 0.0)))
        for row in range(2):  # two axes, not a loop over the mesh
            checkpoint()
            skew = _third_moment(offsets @ axes[row], faces, areas)
            if skew < -SKEW_RTOL * scale**3 * total:
                axes[row] = -axes[row]
        axes[2] = np.cross(axes[0], axes[1])
        return cls(origin, axes, scale if scale > 0 else 1.0)

    @property
    def origin(self) -> np.ndarray:
        return self._origin

    @property
    def axes(self) -> np.ndarray:
        return self._axes

    @property
    def scale(self) -> float:
        return self._scale

    def to_own(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) world points into the frame: centred, turned, and divided by the scale."""
        return (np.asarray(points, dtype=np.float64) - self._origin) @ self._axes.T / self._scale

    def from_own(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) points of the frame back into world coordinates."""
        return np.asarray(points, dtype=np.float64) * self._scale @ self._axes + self._origin

    def box(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The box of ``points`` ((k, 3), world) along the frame's axes: its lowest and
        highest corner ((3,) each) in turned coordinates about the origin, mesh units."""
        # (3, k): each axis a contiguous row (a reduction down the rows of a (k, 3) array
        # is ten times slower).
        along = self._axes @ (np.asarray(points, dtype=np.float64) - self._origin).T
        return along.min(axis=1), along.max(axis=1)

    def box_middle(self, points: np.ndarray) -> np.ndarray:
        """(3,) world point: the middle of :meth:`box`."""
        low, high = self.box(points)
        return self._origin + (low + high) / 2.0 @ self._axes

    def directions_to_own(self, directions: np.ndarray) -> np.ndarray:
        """(k, 3) world directions turned into the frame (lengths kept)."""
        return np.asarray(directions, dtype=np.float64) @ self._axes.T

    def directions_from_own(self, directions: np.ndarray) -> np.ndarray:
        """(k, 3) directions of the frame turned back into world coordinates."""
        return np.asarray(directions, dtype=np.float64) @ self._axes

    def __repr__(self) -> str:
        return f"OwnFrame(origin={self._origin.tolist()}, scale={self._scale:.6g})"


def _third_moment(values: np.ndarray, faces: np.ndarray, areas: np.ndarray) -> float:
    """The integral of f^3 over the triangles ``faces`` ((m, 3) int) of ``areas`` ((m,)),
    f linear with the vertex values ``values`` ((n,)). Over one triangle it is area/10 times
    the complete homogeneous polynomial h3 of its corner values."""
    a, b, c = (values[faces[:, k]] for k in range(3))
    h3 = a**3 + b**3 + c**3 + a * a * (b + c) + b * b * (a + c) + c * c * (a + b) + a * b * c
    return float(areas @ h3) / 10
