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

import numpy as np

from .arrays import cross_rows

#: Relative size of a third moment below which its sign is taken as undecided (a symmetric
#: surface): the axis then keeps the sign the eigen-solver gave it.
SKEW_RTOL = 1e-9


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

        The triangles must have some area (a region's faces do: selection refuses none).
        """
        corners = vertices[faces]  # (m, 3, 3)
        shift = corners.reshape(-1, 3).mean(axis=0)  # a first guess, for rounding only
        corners = corners - shift
        doubled = np.linalg.norm(cross_rows(corners[:, 1] - corners[:, 0],
                                            corners[:, 2] - corners[:, 0]), axis=1)  # fmt: skip
        area = doubled.sum() / 2
        sums = corners.sum(axis=1)  # (m, 3): a + b + c
        centroid = (doubled @ sums) / (6 * area)
        # Over a triangle, the integral of x x^T is area/12 (a a^T + b b^T + c c^T + s s^T).
        # As matrix products (a three-operand einsum runs several times slower).
        flat = corners.reshape(-1, 3)
        second = (flat * np.repeat(doubled, 3)[:, None]).T @ flat
        second += (sums * doubled[:, None]).T @ sums
        covariance = second / (24 * area) - np.outer(centroid, centroid)
        variances, vectors = np.linalg.eigh((covariance + covariance.T) / 2)
        axes = vectors[:, ::-1].T  # rows, largest variance first
        scale = float(np.sqrt(max(variances.sum(), 0.0)))
        relative = corners - centroid
        for row in range(2):
            skew = _third_moment(relative @ axes[row], doubled)
            if abs(skew) > SKEW_RTOL * max(scale, np.finfo(float).tiny) ** 3 * area and skew < 0:
                axes[row] = -axes[row]
        axes[2] = np.cross(axes[0], axes[1])
        return cls(centroid + shift, axes, scale)

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

    def directions_to_own(self, directions: np.ndarray) -> np.ndarray:
        """(k, 3) world directions turned into the frame (lengths kept)."""
        return np.asarray(directions, dtype=np.float64) @ self._axes.T

    def directions_from_own(self, directions: np.ndarray) -> np.ndarray:
        """(k, 3) directions of the frame turned back into world coordinates."""
        return np.asarray(directions, dtype=np.float64) @ self._axes

    def __repr__(self) -> str:
        return f"OwnFrame(origin={self._origin.tolist()}, scale={self._scale:.6g})"


def _third_moment(values: np.ndarray, doubled: np.ndarray) -> float:
    """The integral of f^3 over the triangles, f linear with corner values ``values``
    ((m, 3)); ``doubled``: (m,) twice their areas. Over one triangle it is area/10 times
    the complete homogeneous polynomial h3 of the corner values."""
    # h3 from the power sums p_k = a^k + b^k + c^k: (p1^3 + 3 p1 p2 + 2 p3) / 6.
    p1 = values.sum(axis=1)
    squares = values * values
    p2 = squares.sum(axis=1)
    p3 = (squares * values).sum(axis=1)
    h3 = (p1 * (p1 * p1 + 3.0 * p2) + 2.0 * p3) / 6.0
    return float(doubled @ h3) / 20
