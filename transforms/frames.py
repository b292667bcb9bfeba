"""The local frame every formula works in: ``q = R (p - c)`` (docs/math.md, section 1).

``c`` is the centre the region is star-shaped from; ``R`` is a proper rotation whose rows
are the local axes written in world coordinates. Local ``+Y`` is the warp's fixed pole, the
centre of the forbidden cap. Where the face looks (``facing``) fixes the roll about the pole
(:func:`facing_across`, :func:`facing_disagreement_deg`; docs/math.md, section 18).
"""

from __future__ import annotations

import math

import numpy as np

from .arrays import as_direction, as_points, as_vector, numeric_array
from .errors import TransformInputError

#: How far from orthonormal with determinant +1 a matrix may be and still count as a rotation.
ROTATION_TOLERANCE = 1e-9

#: Smallest sine of the angle between ``pole`` and ``up`` that still fixes the roll.
MIN_POLE_UP_SINE = 1e-9

#: Least angle, degrees, between ``facing`` and the pole or its opposite: nearer, the front
#: lies in the middle of the cap or of the map, where no roll moves it, and the roll would
#: swing with the least change of the pole (docs/math.md, section 18).
MIN_FACING_DEG = 1.0

#: Largest angle, degrees, between a given rotation's local ``+Z`` and ``facing``'s part
#: across its pole for the two to agree (an answer's params, sent back, agree to rounding).
FACING_AGREEMENT_DEG = 1e-6


class Frame:
    """A rigid change of coordinates from the world frame to the local frame.

    Immutable; build one with a named constructor:

    >>> frame = Frame.from_pole_up(pole=[0, 0, -1], up=[0, 1, 0], center=[0, 1.5, 0])
    >>> frame.to_local([[0, 1.5, -2]])        # the pole direction lands on local +Y
    array([[0., 2., 0.]])

    Attributes
    ----------
    rotation : (3, 3) float
        World-to-local rotation ``R`` (rows are the local axes in world coordinates).
    center : (3,) float
        The centre ``c`` in world coordinates.
    """

    __slots__ = ("_center", "_rotation")

    def __init__(self, rotation: np.ndarray, center: np.ndarray) -> None:
        # Private: the named constructors check their input before calling this.
        self._rotation = np.array(rotation, dtype=np.float64)
        self._center = np.array(center, dtype=np.float64)
        self._rotation.flags.writeable = False
        self._center.flags.writeable = False

    # -- named constructors ------------------------------------------------------------

    @classmethod
    def identity(cls, center=(0.0, 0.0, 0.0)) -> Frame:
        """The world axes, moved to ``center``."""
        return cls(np.eye(3), as_vector(center, "center"))

    @classmethod
    def from_matrix(cls, rotation, center=(0.0, 0.0, 0.0)) -> Frame:
        """A frame from a world-to-local rotation matrix (rows = local axes).

        Parameters
        ----------
        rotation : (3, 3) float
            Must be orthonormal and have determinant +1, each within ``ROTATION_TOLERANCE``.
        center : (3,) float

        Raises
        ------
        TransformInputError
            Not a 3x3 finite matrix, not orthonormal, or a reflection (determinant -1).
        """
        return cls(check_rotation(rotation), as_vector(center, "center"))

    @classmethod
    def from_pole_up(cls, pole, up, center=(0.0, 0.0, 0.0)) -> Frame:
        """A frame whose local ``+Y`` is the world direction ``pole``.

        The part of ``up`` orthogonal to ``pole`` becomes local ``+Z``; local ``+X`` completes
        a right-handed frame.

        Parameters
        ----------
        pole : (3,) float, non-zero world direction
        up : (3,) float, non-zero world direction not parallel to ``pole``
        center : (3,) float

        Raises
        ------
        TransformInputError
            A zero vector, or ``up`` parallel to ``pole``.
        """
        y_axis, up_unit = as_direction(pole, "pole"), as_direction(up, "up")
        x_axis = np.cross(y_axis, up_unit)  # y x up: its length is the sine of their angle
        sine = float(np.linalg.norm(x_axis))
        if not sine > MIN_POLE_UP_SINE:
            raise TransformInputError(
                "up",
                f"must not be parallel to pole (sine of their angle {sine:.3g} "
                f"<= {MIN_POLE_UP_SINE:g})",
            )
        # For nearly parallel pole and up the cross product's rounding is large relative to
        # its length; a second pass of Gram-Schmidt makes the axes orthonormal to ~1e-16.
        x_axis /= sine
        x_axis -= np.dot(x_axis, y_axis) * y_axis
        x_axis /= np.linalg.norm(x_axis)
        z_axis = np.cross(x_axis, y_axis)
        rotation = check_rotation(np.stack([x_axis, y_axis, z_axis]))
        return cls(rotation, as_vector(center, "center"))

    # -- views -------------------------------------------------------------------------

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) float, read-only: world-to-local rotation ``R`` (rows are the local axes)."""
        return self._rotation

    @property
    def center(self) -> np.ndarray:
        """(3,) float, read-only: the centre ``c`` in world coordinates."""
        return self._center

    @property
    def pole(self) -> np.ndarray:
        """(3,) float: the world direction of local ``+Y``."""
        return self._rotation[1]

    def __repr__(self) -> str:
        return f"Frame(rotation={self._rotation.tolist()}, center={self._center.tolist()})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Frame):
            return NotImplemented
        return bool(
            np.array_equal(self._rotation, other._rotation)
            and np.array_equal(self._center, other._center)
        )

    __hash__ = None  # mutable-looking arrays inside; equality is by value

    # -- maps --------------------------------------------------------------------------

    def to_local(self, points) -> np.ndarray:
        """World points to local coordinates, ``q = R (p - c)``.

        Parameters
        ----------
        points : (n, 3) float, world frame

        Returns
        -------
        (n, 3) float, local frame
        """
        # (p - c) R^T: one matrix product straight into (n, 3) rows, no transposed copy.
        return (as_points(points) - self._center) @ self._rotation.T

    def local_rows(self, points: np.ndarray) -> np.ndarray:
        """Local coordinates of already checked ``(n, 3)`` points as rows ``x, y, z`` (3, n).

        The centre is subtracted before rotating, so points near it keep their precision.
        """
        return self._rotation @ (points - self._center).T

    def to_world(self, points_local) -> np.ndarray:
        """Local points back to the world frame, ``p = R^T q + c``.

        Parameters
        ----------
        points_local : (n, 3) float

        Returns
        -------
        (n, 3) float, world frame
        """
        q = as_points(points_local, "points_local")
        return q @ self._rotation + self._center


def check_rotation(rotation) -> np.ndarray:
    """Return ``rotation`` as a (3, 3) float64 array if it is a proper rotation.

    Raises
    ------
    TransformInputError
        Not 3x3 and finite, ``R R^T`` differs from ``I`` by more than ``ROTATION_TOLERANCE``,
        or the determinant is not +1 within that tolerance (a reflection).
    """
    matrix = numeric_array(rotation, "rotation", "a 3x3 matrix of numbers").astype(np.float64)
    if matrix.shape != (3, 3):
        raise TransformInputError("rotation", f"must be a 3x3 matrix, got shape {matrix.shape}")
    if not np.isfinite(matrix).all():
        raise TransformInputError("rotation", "has a NaN or Inf entry")
    largest = float(np.abs(matrix).max())
    if largest > 1.0 + ROTATION_TOLERANCE:  # checked first: R R^T could overflow
        raise TransformInputError(
            "rotation", f"has an entry of magnitude {largest:.10g}; a rotation's lie in [-1, 1]"
        )
    deviation = float(np.abs(matrix @ matrix.T - np.eye(3)).max())
    if deviation > ROTATION_TOLERANCE:
        raise TransformInputError(
            "rotation",
            f"is not orthonormal: R R^T differs from I by {deviation:.3g} "
            f"(limit {ROTATION_TOLERANCE:g})",
        )
    determinant = float(np.linalg.det(matrix))
    if abs(determinant - 1.0) > ROTATION_TOLERANCE:
        raise TransformInputError(
            "rotation",
            f"has determinant {determinant:.6g}, not +1: a reflection, not a rotation",
        )
    return matrix


def facing_across(pole, facing) -> np.ndarray:
    """The local ``+Z`` that puts the front at the top of the map (docs/math.md, section
    18): the part of ``facing`` orthogonal to ``pole``, made unit.

    Parameters
    ----------
    pole : (3,) float, non-zero world direction (local ``+Y``)
    facing : (3,) float, non-zero world direction: where the face looks

    Returns
    -------
    (3,) float, unit, orthogonal to ``pole``

    Raises
    ------
    TransformInputError
        ``facing`` zero, or within ``MIN_FACING_DEG`` of ``pole`` or of its opposite.
    """
    y_axis, front = as_direction(pole, "pole"), as_direction(facing, "facing")
    along = float(np.dot(front, y_axis))
    across = front - along * y_axis
    sine = float(np.linalg.norm(across))
    angle = math.degrees(math.atan2(sine, abs(along)))
    if not angle >= MIN_FACING_DEG:
        side = "the pole" if along > 0 else "the pole's opposite"
        raise TransformInputError(
            "facing",
            f"lies {angle:.3g} degrees from {side} (at least {MIN_FACING_DEG:g} needed): the "
            "front is then in the middle of the cap or of the map, and no roll puts it at the "
            "top; give a rotation whose pole is further from where the face looks",
        )
    across /= sine
    across -= np.dot(across, y_axis) * y_axis  # a second pass, as Frame.from_pole_up does
    return across / np.linalg.norm(across)


def facing_disagreement_deg(rotation: np.ndarray, facing) -> float:
    """Degrees between the local ``+Z`` of ``rotation`` (3, 3) (rows: local axes) and the
    one :func:`facing_across` gives for its pole: 0 when the rotation puts the front at the
    top (docs/math.md, section 18).

    Raises
    ------
    TransformInputError
        As :func:`facing_across`.
    """
    wanted = facing_across(rotation[1], facing)
    z_axis = np.asarray(rotation[2], dtype=np.float64)
    return math.degrees(
        math.atan2(float(np.linalg.norm(np.cross(z_axis, wanted))), float(np.dot(z_axis, wanted)))
    )
